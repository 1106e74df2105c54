"""Wall time of one closed-loop shift (``ClosedLoopShift.run``, what ``gearsym control`` runs
for every shift of every vehicle and strategy): the built-in gearbox's 2-3 upshift at the
built-in scenario's operating point, the calibration's knowledge, nominal actuators, 1.2 s
(the study's shift) at the TCU's 10 ms ticks. The fast path (the plant's modes as emitted C
through ``ctypes``, the record sampled once after the last tick) against the reference path
(``run(reference=True)``: CasADi's calls from Python, each tick's record sampled in its run)
on the same plant, in the same run, in rotated order; medians with min–max, and the ratio of
each round's pair.

Both paths run on one plant whose models were built by a first, untimed shift of each kind
(a process pays that once per vehicle; the first fast shift, with an empty cache of compiled
C, is reported). Target: the issue's at least 4 times faster, fast / reference ≤ 0.25.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time

from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.actuator import ClutchActuator
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import load_scenario
from gearsym.validation.studies.control.closed_loop import ClosedLoopShift
from gearsym.validation.studies.control.strategies import calibration_knowledge
from gearsym.validation.studies.control.study import (
    SHIFT_DURATION,
    OperatingPoint,
    make_controller,
)
from record import Target, begin, record, row

ROUNDS = 7
BOUND = 0.25


def main() -> int:
    started = begin()
    # an empty cache: the first fast shift compiles its C, as a first process does
    os.environ["GEARSYM_CACHE_DIR"] = tempfile.mkdtemp(prefix="gearsym-bench-closed-loop-")
    d = load_description()
    point = OperatingPoint.from_scenario(load_scenario(d))
    plant = ClosedLoopShift(d, "2-3", point.vehicle_speed)
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, "2-3"))
    actuator = ClutchActuator.from_calibration(d.control)
    actuators = {plant.spec.off_going: actuator, plant.spec.on_coming: actuator}
    knowledge = calibration_knowledge(d, tuple(model.hybrid.friction_elements))

    def shift(reference: bool) -> float:
        """One shift with a fresh controller (it keeps state); its wall time."""
        controller = make_controller(d, model, knowledge, point.torque)
        start = time.perf_counter()
        result = plant.run(
            controller,
            point.torque,
            point.torque,
            actuators,
            actuators,
            t_end=SHIFT_DURATION,
            reference=reference,
        )
        elapsed = time.perf_counter() - start
        if not result.completed:
            raise SystemExit("the shift did not end locked in the to-gear")
        return elapsed

    first_fast = shift(False)
    shift(True)
    names = ["fast", "reference"]
    times: dict[str, list[float]] = {n: [] for n in names}
    for r in range(ROUNDS):
        for name in names[r % 2 :] + names[: r % 2]:
            times[name].append(shift(name == "reference"))
    ratios = [f / ref for f, ref in zip(times["fast"], times["reference"], strict=True)]
    fast, reference = (statistics.median(times[k]) for k in names)
    ratio = statistics.median(ratios)

    def spread(values: list[float]) -> str:
        return f"{statistics.median(values):6.3f} s [{min(values):.3f}–{max(values):.3f}]"

    print(f"closed-loop 2-3 upshift, {SHIFT_DURATION:g} s at 10 ms ticks, {ROUNDS} rounds")
    print(f"  fast       {spread(times['fast'])}")
    print(f"  reference  {spread(times['reference'])}")
    print(f"  fast / reference {ratio:.3f} (pairs, {min(ratios):.3f}–{max(ratios):.3f})")
    print(f"  {reference / fast:.1f}x faster; the first fast shift {first_fast:.2f} s")
    print(f"  target fast / reference <= {BOUND}: {'met' if ratio <= BOUND else 'MISSED'}")
    what = f"one closed-loop 2-3 upshift ({SHIFT_DURATION:g} s, 10 ms ticks)"
    rows = [
        row(
            f"{what}, the fast path",
            unit="s",
            samples=times["fast"],
            peer="the reference path (CasADi calls, each tick sampled)",
            peer_samples=times["reference"],
            pair_ratios=ratios,
            target=Target(f"≤ {BOUND} × the reference (4 times faster)", "ratio", "<=", BOUND),
        ),
        row(
            "the first fast shift of a process, empty cache (the plant's C compiled on first use)",
            first_fast,
            unit="s",
        ),
    ]
    record(__file__, rows, started=started, title="A closed-loop shift: fast against the reference")
    return 0 if ratio <= BOUND else 1


if __name__ == "__main__":
    sys.exit(main())
