"""The phases of a simulated shift (thesis 3.1), detected from its signals, never from the
scenario's times: from-gear, torque phase (the on-coming element takes over the load), speed
phase (the input speed moves to the new ratio), to-gear.

Used by the reference simulation (:func:`gearsym.validation.sim.simulate.simulate`), whose
result carries them, and by the hybrid simulation and the studies that work phase by phase.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.ratios import gear_ratio
from gearsym.validation.sim.scenario import Scenario

__all__ = ["Phase", "detect_phases", "phase_of"]


@dataclass(frozen=True)
class Phase:
    """One phase of the shift, detected from the simulated slips and torques."""

    name: str
    t_start: float
    t_end: float
    criterion: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "criterion": self.criterion,
        }


def detect_phases(
    d: GearboxDescription,
    scenario: Scenario,
    t: np.ndarray,
    signals: dict[str, np.ndarray],
    torque_fraction: float = 0.05,
    ratio_fraction: float = 0.02,
    sync_fraction: float = 0.01,
    capacity_fraction: float = 0.98,
) -> tuple[Phase, ...]:
    """The four phases of a power-on upshift from the simulated signals (thesis 3.1).

    * torque phase starts when the on-coming element carries ``torque_fraction`` of the torque
      it carries at the end, or earlier when the off-going element starts to slide (its torque
      reaches ``capacity_fraction`` of its capacity 2 N_disc r_m μ F_N);
    * speed phase starts when the ratio ω_in/ω_out has moved ``ratio_fraction`` of the way from
      the from-gear ratio to the to-gear ratio;
    * the to-gear starts when the on-coming element's slip has fallen below ``sync_fraction``
      of its slip at the start of the torque phase and stays there.
    """
    spec = scenario.shift
    on, off = spec.on_coming, spec.off_going
    t_on = np.abs(signals[naming.torque(on)])
    slip_on = np.abs(signals[naming.slip_column(on)])
    ratio = signals[naming.RATIO]
    r_from = d.gear(spec.from_gear)
    r_to = d.gear(spec.to_gear)
    ratio_from = float(gear_ratio(d, r_from).ratio)
    ratio_to = float(gear_ratio(d, r_to).ratio)

    def fail(reason: str) -> GearsymError:
        return GearsymError(scenario.file, "scenario", f"shift {spec.name} not completed: {reason}")

    final = t_on[-1]
    if final <= 0:
        raise fail(f"{on} carries no torque at the end")
    takes_load = _first(t_on > torque_fraction * final)
    if takes_load is None:
        raise fail(f"{on} never takes over the load")
    # the off-going element brought to slip also ends the from-gear (3.1): it slides once its
    # torque reaches the capacity 2 N_disc r_m μ F_N (2.69)
    # (a one-way clutch never slides: it carries torque until it overruns by itself)
    element, short = d.element(off), element_short_name(d, off)
    slides = None
    if not element.one_way:
        assert element.n_disc is not None and element.r_m is not None
        force = signals[naming.normal_force(short)]
        mu = signals[naming.friction_coefficient(short)]
        capacity = 2 * element.n_disc * element.r_m.value * mu * force
        slides = _first(
            (force > 0) & (np.abs(signals[naming.torque(off)]) >= capacity_fraction * capacity)
        )
    i1 = takes_load if slides is None else min(takes_load, slides)
    progress = (ratio_from - ratio) / (ratio_from - ratio_to)
    i2 = _first(progress > ratio_fraction, i1)
    if i2 is None:
        raise fail(f"the ratio never leaves {ratio_from:.3f}")
    reference_slip = slip_on[i1]
    below = slip_on < sync_fraction * reference_slip
    i3 = None
    for i in range(i2, len(t)):
        if below[i] and np.all(below[i:]):
            i3 = i
            break
    if i3 is None:
        raise fail(f"{on} does not synchronise before t_end = {scenario.t_end:g} s")
    t1, t2, t3 = float(t[i1]), float(t[i2]), float(t[i3])
    return (
        Phase(
            f"gear {spec.from_gear}",
            float(t[0]),
            t1,
            f"until {off} slides or T_{on} exceeds {torque_fraction:.0%} of its final value",
        ),
        Phase(
            "torque phase",
            t1,
            t2,
            f"{on} takes over the load from {off}; the ratio has moved < {ratio_fraction:.0%}",
        ),
        Phase(
            "speed phase",
            t2,
            t3,
            f"ratio moves to gear {spec.to_gear}; ends when |slip_{on}| < {sync_fraction:.0%} "
            "of its initial value",
        ),
        Phase(f"gear {spec.to_gear}", t3, float(t[-1]), f"{on} synchronised"),
    )


def _first(mask: np.ndarray, start: int = 0) -> int | None:
    hits = np.flatnonzero(mask[start:])
    return None if hits.size == 0 else int(start + hits[0])


def phase_of(phases: Sequence[Phase], t: float) -> str:
    """Name of the phase containing t (the last phase includes its end)."""
    for k, p in enumerate(phases):
        if p.t_start <= t < p.t_end or (k == len(phases) - 1 and t <= p.t_end):
            return p.name
    return ""
