"""The closed-loop shift's fast path (the plant's modes as emitted C, the record sampled once
after the last tick) against its reference (CasADi's calls, each tick's record sampled in its
own run): the same 2-3 upshift, controller, actuators and tolerances both ways.

The tolerances come from the integrator's, not from a run's output. Both paths integrate the
same equations with DOP853 at rtol = atol = ``TOLERANCE`` and accept a step when the RMS of its
error estimate over the n states, each scaled by atol + rtol |y|, is below 1: one component's
local error is at most √n (rtol max|y| + atol). Over N steps (one or more per piece: the
plant restarts at every input knot; DOP853 evaluates the right-hand side at least 11 times a
step, so N ≤ nfev / 11) the global errors add up to at most N times that, each
path's from the exact solution; the paths differ by at most twice it. The fast path changes
the arithmetic by rounding (the same C operations as CasADi's, the inputs' line evaluated as
u(ta) + (t − ta) u̇) and, where SciPy's first-step estimate falls short of a segment, the step
sequence (it tries the whole segment first, under the same error control); both far below
that bound. An event located on a slip that is off by δσ
moves by δσ / |σ̇|: the lock-up time's tolerance, σ̇ the slip rate into lock-up (the reference
record's, its smallest over the last 5 ms before lock-up).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from gearsym.symbolic import naming
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.actuator import ClutchActuator
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import load_scenario
from gearsym.validation.studies.control.closed_loop import TOLERANCE, ClosedLoopShift
from gearsym.validation.studies.control.strategies import calibration_knowledge
from gearsym.validation.studies.control.study import (
    SHIFT_DURATION,
    OperatingPoint,
    make_controller,
)


@pytest.fixture(scope="module")
def runs():  # noqa: ANN201
    """One 2-3 upshift with the calibration's knowledge and nominal actuators, run the
    reference way and the fast way (each with a fresh controller: it keeps state)."""
    d = load_description(None)
    point = OperatingPoint.from_scenario(load_scenario(d))
    plant = ClosedLoopShift(d, "2-3", point.vehicle_speed)
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, "2-3"))
    spec = plant.spec
    actuator = ClutchActuator.from_calibration(d.control)
    actuators = {spec.off_going: actuator, spec.on_coming: actuator}
    knowledge = calibration_knowledge(d, tuple(model.hybrid.friction_elements))
    out = {}
    for reference in (True, False):
        controller = make_controller(d, model, knowledge, point.torque)
        out[reference] = plant.run(
            controller,
            point.torque,
            point.torque,
            actuators,
            actuators,
            t_end=SHIFT_DURATION,
            reference=reference,
        )
    n = max(m.n for m in plant.simulator.modes.values())
    return d, out[True], out[False], n


def _bound(values: np.ndarray, steps: int, n: int) -> float:
    """Twice the summed local error bound of ``steps`` steps on a signal of size ``values``
    (module docstring)."""
    return 2 * steps * math.sqrt(n) * (TOLERANCE * float(np.max(np.abs(values))) + TOLERANCE)


def test_the_fast_path_takes_the_same_decisions(runs) -> None:  # noqa: ANN001
    """The same events in the same order, the controller in the same phase at every tick, and
    both shifts end locked in the to-gear."""
    _, ref, fast, _ = runs
    assert ref.completed and fast.completed
    assert [(e.kind, e.element, e.source, e.target) for e in ref.events] == [
        (e.kind, e.element, e.source, e.target) for e in fast.events
    ]
    assert ref.phases == fast.phases
    assert np.array_equal(ref.t, fast.t)


def test_the_fast_path_records_the_same_shift(runs) -> None:  # noqa: ANN001
    """Speeds, slips and twist (what the integrator's tolerance governs; the pressures follow
    from the commands, whose decisions the test above compares) within twice the integrator's
    summed error bound (module docstring), N the number of steps taken (at least one per
    piece), and the lock-up and every event within that bound on the slip over the slip's
    rate into lock-up."""
    d, ref, fast, n = runs
    steps = max(ref.nfev, fast.nfev) // 11
    keys = [naming.speed(s.name) for s in d.shafts] + [naming.TWIST, naming.WHEEL_SPEED]
    keys += [k for k in ref.signals if k.startswith("slip_")]
    for key in keys:
        bound = _bound(ref.signals[key], steps, n)
        assert np.max(np.abs(fast.signals[key] - ref.signals[key])) <= bound, key
    on = ref.spec.on_coming
    slip = ref.signals[naming.slip_column(on)]
    before = (ref.t < ref.t_lockup) & (ref.t >= ref.t_lockup - 0.005)
    rate = float(np.min(np.abs(np.gradient(slip, ref.t)[before])))
    slip_bound = _bound(slip, steps, n)
    assert abs(fast.t_lockup - ref.t_lockup) <= slip_bound / rate
    for a, b in zip(ref.events, fast.events, strict=True):
        assert abs(a.t - b.t) <= slip_bound / rate


def test_a_simulator_without_a_compiler_keeps_casadis_calls(monkeypatch) -> None:  # noqa: ANN001
    """``compiled=True`` without a C compiler: no C is built and the run is the reference's,
    value for value (the same CasADi calls); with one, the built-in 2-3 agrees with the
    reference within the integrator's bound (module docstring)."""
    from gearsym.validation.sim import hybrid_simulation

    d = load_description(None)
    reference = HybridSimulator(d).run(rtol=TOLERANCE, atol=TOLERANCE)
    monkeypatch.setattr(hybrid_simulation, "compiler_available", lambda: False)
    without = HybridSimulator(d, compiled=True)
    assert without.compiled_functions() is None
    fallback = without.run(rtol=TOLERANCE, atol=TOLERANCE)
    for key, values in reference.signals.items():
        assert np.array_equal(fallback.signals[key], values, equal_nan=True), key
    monkeypatch.undo()
    if not hybrid_simulation.compiler_available():
        pytest.skip("no C compiler")
    compiled = HybridSimulator(d, compiled=True).run(rtol=TOLERANCE, atol=TOLERANCE)
    assert [e.kind for e in compiled.events] == [e.kind for e in reference.events]
    steps = int(reference.stats["nfev"]) // 11
    n = max(m.n for m in without.modes.values())
    for key in [naming.speed(s.name) for s in d.shafts] + [naming.TWIST, naming.WHEEL_SPEED]:
        bound = _bound(reference.signals[key], steps, n)
        assert np.max(np.abs(compiled.signals[key] - reference.signals[key])) <= bound, key


def test_pieces_evaluated_together_are_each_pieces_own_values() -> None:
    """The record's states of many one-step pieces of a mode evaluated in one expression are,
    value for value, what each piece's dense output gives (the same operations in the same
    order); pieces of several steps go piece by piece."""
    from gearsym.validation.sim.hybrid_result import Piece, states_of
    from scipy.integrate import OdeSolution

    d = load_description(None)
    result = HybridSimulator(d).run(rtol=TOLERANCE, atol=TOLERANCE)
    modes = [p.mode for p in result.pieces]
    mode = max(set(modes), key=modes.count)
    pieces = [p for p in result.pieces if p.t_end > p.t_start and p.mode == mode]
    # every step of those pieces as a one-step piece, as a closed loop's pieces mostly are
    steps = [
        Piece(mode, s.t_old, s.t, OdeSolution([s.t_old, s.t], [s]), p.x_start)
        for p in pieces
        for s in p.solution.interpolants
    ]
    for group in (steps, pieces):
        times = [np.linspace(p.t_start, p.t_end, 3) for p in group]
        expected = np.concatenate([p.state(t) for p, t in zip(group, times, strict=True)])
        assert np.array_equal(states_of(group, times), expected)
