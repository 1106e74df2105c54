"""The valve and piston fill between the shift controller and the plant
(validation/sim/actuator.py). Every expected value is a closed form worked out here from the
model the module states (dead time, linear fill, first-order chamber pressure), never a value
the code computed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gearsym.symbolic.control_calibration import default_control
from gearsym.validation.sim.actuator import ActuatorState, ClutchActuator
from gearsym.validation.sim.fleet import Actuators, FleetDraw

T_D = 0.010  # dead time, s
TAU = 0.030  # chamber time constant, s
T_FILL = 0.100  # fill time at the fast-fill pressure, s
P_FF = 3.0e5  # fast-fill pressure, Pa
P_S = 0.8e5  # return-spring pressure, Pa
#: Pa·s of pressure above the spring over time that stroke the piston once
STROKE = (P_FF - P_S) * T_FILL


def _actuator(**changes: float) -> ClutchActuator:
    values = {
        "dead_time": T_D,
        "time_constant": TAU,
        "fill_time": T_FILL,
        "fast_fill_pressure": P_FF,
        "return_spring": P_S,
        **changes,
    }
    return ClutchActuator(**values)


def _run(
    actuator: ClutchActuator,
    state: ActuatorState,
    commands: list[tuple[float, float, float]],
    per_second: int = 10000,
) -> tuple[ActuatorState, np.ndarray, np.ndarray]:
    """Commands (t0, t1, p_cmd) in turn, sampled at ``per_second``; the samples joined."""
    times, values = [], []
    for t0, t1, command in commands:
        n = max(1, round((t1 - t0) * per_second))
        state, t, p = actuator.advance(state, t0, t1, command, n)
        times.append(t[:-1])
        values.append(p[:-1])
    times.append(t[-1:])
    values.append(p[-1:])
    return state, np.concatenate(times), np.concatenate(values)


def _filled_step(p_cmd: float, t_fill: float, t: np.ndarray) -> np.ndarray:
    """Effective pressure after the fill completed at ``t_fill`` under a constant valve p_cmd:
    p starts at p_s, so p − p_s = (p_cmd − p_s)(1 − exp(−(t − t_fill)/τ)), 0 before."""
    after = (p_cmd - P_S) * (1.0 - np.exp(-(t - t_fill) / TAU))
    return np.where(t >= t_fill, np.maximum(after, 0.0), 0.0)


def test_fast_fill_from_empty_completes_at_dead_time_plus_fill_time():
    a = _actuator()
    empty = a.initial(filled=False)
    t_done = T_D + T_FILL
    # fill: nothing within the dead time, then linear at 1/t_fill
    state, _, p = a.advance(empty, 0.0, T_D + 0.05, P_FF)
    assert state.fill == pytest.approx(0.05 / T_FILL, rel=1e-12) and p[-1] == 0.0
    state, _, p = a.advance(empty, 0.0, t_done - 1e-6, P_FF)
    assert state.fill == pytest.approx(1.0 - 1e-6 / T_FILL, rel=1e-12) and p[-1] == 0.0
    state, _, _ = a.advance(empty, 0.0, t_done, P_FF)
    assert state.fill == pytest.approx(1.0, abs=1e-12)
    # once filled: the first-order rise from the spring pressure
    state, t, p = a.advance(empty, 0.0, 0.4, P_FF, 4000)
    np.testing.assert_allclose(p, _filled_step(P_FF, t_done, t), rtol=0, atol=1e-6)
    assert p[t < t_done].max() == 0.0 and state.fill == 1.0
    assert a.effective(state) == pytest.approx((P_FF - P_S) * (1 - math.exp(-0.29 / TAU)))


def test_fill_at_half_the_pressure_above_the_spring_takes_twice_as_long():
    a = _actuator()
    half = P_S + (P_FF - P_S) / 2
    t_done = T_D + 2 * T_FILL
    state, _, _ = a.advance(a.initial(False), 0.0, t_done - 1e-4, half)
    assert state.fill == pytest.approx(1.0 - 1e-4 / (2 * T_FILL), rel=1e-12)
    state, t, p = a.advance(a.initial(False), 0.0, 0.5, half, 5000)
    np.testing.assert_allclose(p, _filled_step(half, t_done, t), rtol=0, atol=1e-6)
    assert p[t < t_done].max() == 0.0


def test_below_the_spring_the_piston_does_not_move():
    a = _actuator()
    state, _, p = a.advance(a.initial(False), 0.0, 1.0, 0.9 * P_S, 100)
    assert state.fill == 0.0 and not p.any()


def test_a_step_down_decays_exponentially():
    """Held at 10 bar, commanded 5 bar at t = 0: the chamber keeps 10 bar through the dead
    time, then p = 5 bar + 5 bar · exp(−(t − T_d)/τ)."""
    a = _actuator()
    state, t, p = a.advance(a.initial(True, 1.0e6), 0.0, 0.2, 5.0e5, 2000)
    chamber = np.where(t <= T_D, 1.0e6, 5.0e5 + 5.0e5 * np.exp(-(t - T_D) / TAU))
    np.testing.assert_allclose(p, chamber - P_S, rtol=1e-12, atol=1e-6)
    assert state.fill == 1.0


def test_released_the_piston_retracts_once_the_chamber_reaches_the_spring():
    """Commanded 0 from 10 bar: p = 10 bar · exp(−(t − T_d)/τ) reaches p_s at
    t_c = T_d + τ ln(10 bar / p_s); from there dx/dt = −p_s / ((p_ff − p_s) t_fill)."""
    a = _actuator()
    t_c = T_D + TAU * math.log(1.0e6 / P_S)
    rate = P_S / STROKE
    state, t, p = a.advance(a.initial(True, 1.0e6), 0.0, 0.3, 0.0, 3000)
    chamber = np.where(t <= T_D, 1.0e6, 1.0e6 * np.exp(-(t - T_D) / TAU))
    np.testing.assert_allclose(p, np.maximum(chamber - P_S, 0.0), rtol=1e-12, atol=1e-6)
    for dt in (0.01, 0.1, 0.2, 0.3):
        state, _, _ = a.advance(a.initial(True, 1.0e6), 0.0, t_c + dt, 0.0)
        assert state.fill == pytest.approx(max(1.0 - rate * dt, 0.0), rel=1e-9, abs=1e-12)
    assert state.fill == 0.0  # 1 / rate = 0.275 s: empty


def test_a_partial_fill_retracts_and_refills_by_the_same_law():
    a = _actuator(dead_time=0.0)
    up = 1.0 / T_FILL  # at the fast-fill pressure
    down = P_S / STROKE  # valve shut
    state, _, _ = a.advance(a.initial(False), 0.0, 0.06, P_FF)
    assert state.fill == pytest.approx(0.06 * up, rel=1e-12)
    state, _, _ = a.advance(state, 0.06, 0.11, 0.0)
    x = 0.06 * up - 0.05 * down
    assert state.fill == pytest.approx(x, rel=1e-12)
    t_done = 0.11 + (1.0 - x) / up
    state, t, p = a.advance(state, 0.11, 0.4, P_FF, 2900)
    np.testing.assert_allclose(p, _filled_step(P_FF, t_done, t), rtol=0, atol=1e-6)


def test_gain_and_offset_apply_to_the_valve():
    """Valve p = g p_cmd + p_off: held at 15 bar, commanded 15 bar through a valve with
    g = 1.03, p_off = −100 mbar, the chamber moves from 15 bar to 1.03 · 15 bar − 0.1 bar."""
    a = _actuator(pressure_gain=1.03, pressure_offset=-1.0e4)
    v = 1.03 * 1.5e6 - 1.0e4
    assert a.valve_pressure(1.5e6) == pytest.approx(v, rel=1e-15)
    _, t, p = a.advance(a.initial(True, 1.5e6), 0.0, 0.3, 1.5e6, 300)
    chamber = np.where(t <= T_D, 1.5e6, v + (1.5e6 - v) * np.exp(-(t - T_D) / TAU))
    np.testing.assert_allclose(p, chamber - P_S, rtol=1e-12)
    # a fast fill through that valve strokes at (g p_ff + p_off − p_s) / (p_ff − p_s) of the
    # nominal rate
    v_ff = 1.03 * P_FF - 1.0e4
    t_done = T_D + STROKE / (v_ff - P_S)
    state, _, _ = a.advance(a.initial(False), 0.0, t_done - 1e-5, P_FF)
    assert state.fill == pytest.approx(1.0 - 1e-5 * (v_ff - P_S) / STROKE, rel=1e-12)


def test_a_command_of_zero_keeps_the_valve_shut():
    """An offset large enough to stroke the piston on its own does not open a valve commanded
    shut; the smallest positive command opens it to the offset."""
    a = _actuator(pressure_offset=2.0e5)
    assert a.valve_pressure(0.0) == 0.0 and a.valve_pressure(-1.0e5) == 0.0
    state, _, p = a.advance(a.initial(False), 0.0, 1.0, 0.0, 100)
    assert state.fill == 0.0 and not p.any()
    assert a.valve_pressure(1.0) == 2.0e5 + 1.0
    state, _, _ = a.advance(a.initial(False), 0.0, 1.0, 1.0)
    assert state.fill == 1.0
    # a negative offset beyond the command gives 0, never a negative pressure
    assert _actuator(pressure_offset=-2.0e5).valve_pressure(1.0e5) == 0.0


def test_many_small_steps_equal_one_big_step():
    """The same command held: 10 ms controller steps give the one large step's state and
    samples (the laws are solved exactly between events, not integrated)."""
    a = _actuator(pressure_gain=1.02, pressure_offset=3.0e3)
    for state0, command in ((a.initial(False), P_FF), (a.initial(True, 1.0e6), 0.0)):
        big, t_big, p_big = a.advance(state0, 0.0, 0.5, command, 500)
        state = state0
        for k in range(50):
            state, t, p = a.advance(state, k * 0.01, (k + 1) * 0.01, command, 10)
            np.testing.assert_allclose(t, t_big[10 * k : 10 * k + 11], rtol=1e-12)
            np.testing.assert_allclose(p, p_big[10 * k : 10 * k + 11], rtol=1e-12, atol=1e-9)
        assert state.fill == pytest.approx(big.fill, rel=1e-12, abs=1e-12)
        assert state.pressure == pytest.approx(big.pressure, rel=1e-12)


def test_dead_time_shifts_the_response_exactly():
    no_delay = _actuator(dead_time=0.0)
    delayed = _actuator(dead_time=0.05)
    _, t0, p0 = no_delay.advance(no_delay.initial(False), 0.0, 0.3, P_FF, 3000)
    _, t1, p1 = delayed.advance(delayed.initial(False), 0.0, 0.35, P_FF, 3500)
    np.testing.assert_allclose(t1[500:] - 0.05, t0, atol=1e-15)
    np.testing.assert_allclose(p1[500:], p0, rtol=0, atol=1e-6)
    assert not p1[:500].any()


def test_commands_inside_the_dead_time_wait_their_turn():
    """A dead time of 25 ms over 10 ms steps: held at 10 bar, 5 bar commanded at 10 ms and
    10 bar again at 20 ms reach the valve at 35 and 45 ms."""
    a = _actuator(dead_time=0.025)
    state, t, p = _run(
        a,
        a.initial(True, 1.0e6),
        [(0.0, 0.01, 1.0e6), (0.01, 0.02, 5.0e5), (0.02, 0.2, 1.0e6)],
    )
    p1 = 5.0e5 + 5.0e5 * math.exp(-0.01 / TAU)
    chamber = np.where(
        t <= 0.035,
        1.0e6,
        np.where(
            t <= 0.045,
            5.0e5 + 5.0e5 * np.exp(-(t - 0.035) / TAU),
            1.0e6 + (p1 - 1.0e6) * np.exp(-(t - 0.045) / TAU),
        ),
    )
    np.testing.assert_allclose(p, chamber - P_S, rtol=1e-12)
    assert state.pending == () and state.valve == 1.0e6
    # after the second step both commands given still wait, in order
    state, _, _ = a.advance(a.initial(True, 1.0e6), 0.0, 0.01, 1.0e6)
    state, _, _ = a.advance(state, 0.01, 0.02, 5.0e5)
    assert state.pending == (
        (pytest.approx(0.025, abs=1e-15), 1.0e6),
        (pytest.approx(0.035, abs=1e-15), 5.0e5),
    )


def test_initial_states():
    a = _actuator()
    assert a.initial(False) == ActuatorState(0.0, P_S, 0.0)
    assert a.initial(True, 1.5e6) == ActuatorState(1.0, 1.5e6, 1.5e6)
    # a stroked piston balances the spring: its chamber holds at least p_s
    assert a.initial(True) == ActuatorState(1.0, P_S, P_S)
    assert a.effective(a.initial(True, 1.5e6)) == 1.5e6 - P_S


def test_from_calibration_nominal_and_a_vehicle_of_the_fleet():
    control = default_control()
    nominal = ClutchActuator.from_calibration(control)
    assert nominal == _actuator()
    truth = ClutchActuator.from_calibration(
        control, Actuators(pressure_gain=0.97, pressure_offset=5.0e3), fill_time_error=0.03
    )
    assert truth == _actuator(fill_time=0.13, pressure_gain=0.97, pressure_offset=5.0e3)
    draw = FleetDraw(
        1, (("fill_time_error", -0.02), ("pressure_gain", 1.01), ("pressure_offset", -2.0e3))
    )
    assert ClutchActuator.from_draw(control, draw) == _actuator(
        fill_time=0.08, pressure_gain=1.01, pressure_offset=-2.0e3
    )


@pytest.mark.parametrize(
    "changes",
    [{"fill_time": 0.0}, {"time_constant": -0.01}, {"dead_time": -0.001}, {"return_spring": P_FF}],
)
def test_an_impossible_actuator_is_refused(changes):
    with pytest.raises(ValueError):
        _actuator(**changes)


def test_stroke_time_through_a_valve_with_gain_and_offset():
    """What the oracle's fill command must last: STROKE / (g p_cmd + p_off − p_s), here with
    g = 0.97 and p_off = +100 mbar at the fast fill; the nominal valve gives t_fill; a valve
    that gives no more than the spring never strokes. Cross-checked against advancing the
    actuator to that instant (minus the dead time)."""
    a = _actuator(pressure_gain=0.97, pressure_offset=1.0e4)
    expected = STROKE / (0.97 * P_FF + 1.0e4 - P_S)
    assert a.stroke_time(P_FF) == pytest.approx(expected, rel=1e-15)
    assert _actuator().stroke_time(P_FF) == pytest.approx(T_FILL, rel=1e-15)
    assert math.isinf(_actuator().stroke_time(P_S))
    state, _, _ = a.advance(a.initial(False), 0.0, T_D + 0.999 * expected, P_FF)
    assert state.fill == pytest.approx(0.999, rel=1e-12)


def test_tick_means_of_a_first_order_step() -> None:
    """A stroked piston at p0 whose valve steps to p_v (no dead time): over a tick of length
    h starting at the step, the chamber's mean is p_v + (p0 − p_v) τ/h (1 − e^(−h/τ)) (the
    first-order law integrated by hand); the effective pressure is that less the spring. The
    trapezoid on 64 sub-intervals is within h²/(12·64²) of the second derivative's bound."""
    actuator = _actuator(dead_time=0.0)
    p0, p_v, h = 1.5e5, 2.5e5, 0.010
    state = ActuatorState(1.0, p0, p0)
    means = actuator.at_ticks(state, np.array([p_v, p_v]), h, mean_over=64)
    first = p_v + (p0 - p_v) * TAU / h * (1.0 - math.exp(-h / TAU))
    later = p_v + (p0 - p_v) * math.exp(-h / TAU) * TAU / h * (1.0 - math.exp(-h / TAU))
    bound = (p_v - p0) / TAU**2 * h**2 / (12 * 64**2)
    assert means[0] == pytest.approx(first - P_S, abs=bound)
    assert means[1] == pytest.approx(later - P_S, abs=bound)
    # the start values are the law at 0 and h
    starts = actuator.at_ticks(state, np.array([p_v, p_v]), h)
    assert starts[0] == pytest.approx(p0 - P_S, abs=1e-6)
    assert starts[1] == pytest.approx(p_v + (p0 - p_v) * math.exp(-h / TAU) - P_S, rel=1e-12)
