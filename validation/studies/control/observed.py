"""What the TCU itself sees of a shift it just made: the strategies learn from this, never from
the truth's record (which scores them, :mod:`.quality`).

From its log (:class:`~gearsym.validation.sim.drive_log.TcuLog`) the TCU has the input and
output speeds every tick and its own phases. The two swapping elements' slips follow from those
two speeds through the calibration's kinematics (the shift's mode with both elements open has
two degrees of freedom: the state is rebuilt from the two speeds, as the controller does).
From them:

* **flare**: a slip reversal beyond 50 rpm on either element (:func:`.quality.flare`);
* **duration error** of the inertia phase against its target, measured on the slip as the
  truth's is (:func:`.quality.inertia_phase`, the same 2 % start, lock-up at the
  controller's ``lockup_slip`` since a 10 ms sample rarely lands on zero);
* **tie-up** (power-on upshifts): the input speed pulled down by more than :data:`PULL_DOWN`
  below its running maximum before the inertia phase starts. Until then the off-going element
  is locked and the input turns with the vehicle, which a power-on upshift accelerates: a fall
  is the on-coming element pressed against the off-going one. A downshift's torque phase comes at
  synchronism, and in coast the input slows with the vehicle, where the same test does not
  apply: their tie-up is not detected.

The speeds are the plant's (the controller's view too; sensor noise and quantisation are not
modelled here).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from gearsym.symbolic.description import GearboxDescription
from gearsym.validation.sim.drive_shift import state_from_speeds
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.studies.control.controller import TargetSlip
from gearsym.validation.studies.control.quality import INERTIA_FRACTION, flare, inertia_phase

__all__ = ["PULL_DOWN", "Observed", "observe_shift"]

#: The input speed's fall before the inertia phase that counts as a tie-up (rad/s, 30 rpm).
PULL_DOWN = 30.0 * np.pi / 30.0


@dataclass(frozen=True)
class Observed:
    """The TCU's own verdict on a shift (module docstring)."""

    flare: bool
    tie_up: bool
    duration_error: float

    def to_dict(self) -> dict[str, object]:
        return {
            "flare": self.flare,
            "tie_up": self.tie_up,
            "duration_error": self.duration_error,
        }


def observe_shift(
    d: GearboxDescription,
    model: HybridSimulator,
    log: Mapping[str, np.ndarray],
    phases: Sequence[str],
    power_on_upshift: bool,
) -> Observed:
    """The verdict from the log's input and output speeds and the controller's ``phases``
    (one per tick); ``model`` is the calibration's hybrid model of the shift. The duration's
    target is the controller's target trajectory measured the same way (from its 2 % fall to
    ``lockup_slip``)."""
    hybrid = model.hybrid
    spec = hybrid.spec
    shafts = [s.name for s in d.shafts]
    measured = [shafts.index(d.input_shaft), shafts.index(d.output_shaft)]
    open_mode = hybrid.mode_of({e: ("open", 0) for e in hybrid.elements}).name
    compiled = model.modes[open_mode]
    speeds = np.column_stack([log[f"omega_{s}"] for s in shafts])
    j_on = hybrid.elements.index(spec.on_coming)
    j_off = hybrid.elements.index(spec.off_going)
    u = np.zeros(len(hybrid.elements) + 2)
    p = model.parameter_vector(model.values())
    slips = np.array(
        [
            compiled.value(
                compiled.slips,
                state_from_speeds(model, open_mode, row, 0.0, 0.0, shafts=measured),
                u,
                p,
            )
            for row in speeds
        ]
    )
    slip_on, slip_off = slips[:, j_on], slips[:, j_off]
    t = np.asarray(log["t"], dtype=float)
    lockup = d.control.si("shift", "lockup_slip")
    start, end = inertia_phase(t, slip_on, lockup, fraction=INERTIA_FRACTION)
    sigma0 = abs(float(slip_on[0]))
    target = TargetSlip(1.0, d.control.si("shift", "inertia_phase"))
    wanted = target.time_at(min(lockup / sigma0, 1.0)) - target.time_at(1.0 - INERTIA_FRACTION)
    error = (end - start - wanted) / wanted
    tied = False
    if power_on_upshift and "inertia" in phases:
        before = speeds[: list(phases).index("inertia"), measured[0]]
        if len(before):
            tied = bool(np.max(np.maximum.accumulate(before) - before) > PULL_DOWN)
    return Observed(flare(slip_on, slip_off), tied, float(error))
