"""The phases of a simulated shift (thesis 3.1), detected from its signals, never from the
scenario's times: from-gear, torque phase (the on-coming element takes over the load) and
speed phase (the input speed moves to the new ratio) in the order they happen, to-gear.

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
    """The four phases of a single-swap shift from the simulated signals (thesis 3.1), in the
    order they happen: from-gear, then the torque and the speed phase in either order, then
    the to-gear.

    What is read from the signals: which element carries torque, which slides and whether the
    ratio ω_in/ω_out moves.

    * The on-coming element *carries load* once its torque has the sign it has at the end (the
      to-gear's) and exceeds ``torque_fraction`` of that final value. Before synchronism its
      friction torque has that sign only when its slip is the one the load would drive (a
      power-on upshift, a coast downshift): then it can take the load first. Otherwise (a
      power-on downshift, a coast upshift) its friction opposes the load's direction: it drags
      at most, and the load moves to it only at synchronism.
    * The off-going element *slides* once its torque reaches ``capacity_fraction`` of its
      capacity 2 N_disc r_m μ F_N (2.69) with F_N > 0 (a one-way clutch never slides: it
      carries torque until it overruns by itself).
    * The ratio *moves* once it has gone ``ratio_fraction`` of the way from the from-gear
      ratio towards the to-gear ratio (a flare away from the to-gear does not count).
    * The from-gear (its elements alone carry the load, its rigid model holds) ends at the
      first of: the off-going element slides, the on-coming element carries torque of either
      sign above ``torque_fraction`` of its final value (a drag against the load's direction
      too), the ratio moves.

    Torque phase first (the ratio does not move before the on-coming element carries load):
    the torque phase starts when the from-gear ends; the speed phase when the ratio moves; the
    to-gear when the on-coming element's slip has fallen below ``sync_fraction`` of its slip
    at the start of the torque phase and stays there.

    Speed phase first (the ratio moves before the on-coming element carries load, e.g. the
    off-going element released first in a power-on downshift): the speed phase starts when
    the from-gear ends; the torque phase when the on-coming element carries load or reaches
    synchronism (slip below ``sync_fraction`` of its slip at the start of the speed phase);
    the to-gear when, from then on, the on-coming element stays synchronised and the
    off-going element carries less than ``torque_fraction`` of the largest torque it carried
    in the from-gear. When the off-going element has let go of all its load before
    synchronism (a coast upshift that empties it early), the load moves at the lock-up
    itself and the torque phase is empty (t_start = t_end).
    """
    spec = scenario.shift
    on, off = spec.on_coming, spec.off_going
    t_on = signals[naming.torque(on)]
    t_off = np.abs(signals[naming.torque(off)])
    slip_on = np.abs(signals[naming.slip_column(on)])
    ratio = signals[naming.RATIO]
    ratio_from = float(gear_ratio(d, d.gear(spec.from_gear)).ratio)
    ratio_to = float(gear_ratio(d, d.gear(spec.to_gear)).ratio)

    def fail(reason: str) -> GearsymError:
        return GearsymError(scenario.file, "scenario", f"shift {spec.name} not completed: {reason}")

    final = abs(float(t_on[-1]))
    if final <= 0:
        raise fail(f"{on} carries no torque at the end")
    carries = np.sign(t_on[-1]) * t_on > torque_fraction * final
    takes_load = _first(carries)
    if takes_load is None:
        raise fail(f"{on} never takes over the load")
    # carrying torque of either sign, a drag against the load's direction included: the
    # from-gear (its elements alone carry the load) has ended
    engages = _first(np.abs(t_on) > torque_fraction * final)
    assert engages is not None and engages <= takes_load
    slides = _sliding_from(d, off, signals, capacity_fraction)
    progress = (ratio_from - ratio) / (ratio_from - ratio_to)
    moves = _first(progress > ratio_fraction)
    if moves is None:
        raise fail(f"the ratio never leaves {ratio_from:.3f}")
    from_gear = f"gear {spec.from_gear}"
    to_gear = f"gear {spec.to_gear}"
    if moves < takes_load:
        i1 = min(i for i in (engages, slides, moves) if i is not None)
        synced = slip_on < sync_fraction * slip_on[i1]
        i2 = _first(carries | synced, i1)
        if i2 is None:
            raise fail(f"{on} does not synchronise before t_end = {scenario.t_end:g} s")
        released = t_off <= torque_fraction * float(np.max(t_off[: i1 + 1]))
        i3 = _first_for_good(released & synced, i2)
        if i3 is None:
            raise fail(
                f"{on} does not stay synchronised with {off} released before "
                f"t_end = {scenario.t_end:g} s"
            )
        t1, t2, t3 = float(t[i1]), float(t[i2]), float(t[i3])
        return (
            Phase(
                from_gear,
                float(t[0]),
                t1,
                f"until {off} slides, |T_{on}| exceeds {torque_fraction:.0%} of its final "
                f"value or the ratio has moved {ratio_fraction:.0%} towards gear {spec.to_gear}",
            ),
            Phase(
                "speed phase",
                t1,
                t2,
                f"ratio moves to gear {spec.to_gear} while {on} carries no load; ends when "
                f"T_{on} exceeds {torque_fraction:.0%} of its final value with its sign or "
                f"|slip_{on}| < {sync_fraction:.0%} of its initial value",
            ),
            Phase(
                "torque phase",
                t2,
                t3,
                f"{on} takes over the load from {off}; ends when |T_{off}| stays below "
                f"{torque_fraction:.0%} of its value in gear {spec.from_gear}",
            ),
            Phase(to_gear, t3, float(t[-1]), f"{on} synchronised, {off} released"),
        )
    i1 = engages if slides is None else min(engages, slides)
    i2 = _first(progress > ratio_fraction, i1)
    if i2 is None:
        raise fail(f"the ratio never leaves {ratio_from:.3f}")
    below = slip_on < sync_fraction * slip_on[i1]
    i3 = _first_for_good(below, i2)
    if i3 is None:
        raise fail(f"{on} does not synchronise before t_end = {scenario.t_end:g} s")
    t1, t2, t3 = float(t[i1]), float(t[i2]), float(t[i3])
    return (
        Phase(
            from_gear,
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
        Phase(to_gear, t3, float(t[-1]), f"{on} synchronised"),
    )


def _sliding_from(
    d: GearboxDescription, off: str, signals: dict[str, np.ndarray], capacity_fraction: float
) -> int | None:
    """The first sample where the off-going friction element slides: its torque at
    ``capacity_fraction`` of its capacity 2 N_disc r_m μ F_N (2.69) with F_N > 0; None for a
    one-way clutch (it never slides: it carries torque until it overruns by itself) or a dog
    element (it never slides either: it carries torque until it opens)."""
    element, short = d.element(off), element_short_name(d, off)
    if element.one_way or element.dog:
        return None
    assert element.n_disc is not None and element.r_m is not None
    force = signals[naming.normal_force(short)]
    mu = signals[naming.friction_coefficient(short)]
    capacity = 2 * element.n_disc * element.r_m.value * mu * force
    return _first(
        (force > 0) & (np.abs(signals[naming.torque(off)]) >= capacity_fraction * capacity)
    )


def _first(mask: np.ndarray, start: int = 0) -> int | None:
    hits = np.flatnonzero(mask[start:])
    return None if hits.size == 0 else int(start + hits[0])


def _first_for_good(mask: np.ndarray, start: int) -> int | None:
    """The first index from ``start`` on after which ``mask`` holds to the end."""
    if not mask[-1]:
        return None
    misses = np.flatnonzero(~mask[start:])
    return start if misses.size == 0 else int(start + misses[-1] + 1)


def phase_of(phases: Sequence[Phase], t: float) -> str:
    """Name of the phase containing t (the last phase includes its end)."""
    for k, p in enumerate(phases):
        if p.t_start <= t < p.t_end or (k == len(phases) - 1 and t <= p.t_end):
            return p.name
    return ""
