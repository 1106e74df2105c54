"""The fast gear segment of a drive (:mod:`gearsym.validation.sim.drive`): the whole closed
loop in one gear — driver, torque split, the vehicle's true engine and machine torque, the
brake, the gear mode's right-hand side and the works — as one CasADi expression, integrated by
a fixed-step classical Runge–Kutta method (RK4) chained over the TCU's ticks by one CasADi
call (``mapaccum``), the shift schedule's thresholds located afterwards.

Why: the reference integrates the same loop with SciPy's ``solve_ivp`` (RK45, a Python call
per right-hand side); on this three-state model Python's overhead per call, not arithmetic,
is the drive's cost. Here Python runs once per stretch between two of the cycle's points.

What differs from the reference, stated:

* the integrator: RK4 with :data:`SUBSTEPS` steps per TCU tick (a 10 ms tick: 2.5 ms steps),
  against RK45 with error control. The gear modes' fastest eigenvalues (the side shafts'
  twist, about −40 ± 136i 1/s in the top gears) give |λ h| ≤ 0.36, where RK4's error per step
  is about (λ h)⁵/120 ≈ 5·10⁻⁵ of the oscillation's own (small) amplitude and the slow states
  (vehicle speed, the driver's integral) are smooth; the drive's comparison test states what
  that leaves in the records.
* the events: the schedule's thresholds are checked at the grid's points (every tick, every
  record sample) and a crossing is located inside its step by Brent's method on the RK4 step
  of variable length, as SciPy locates an event on its dense output between its steps. A
  threshold crossed and left again within one tick is missed; RK45's steps in these gears
  are about as long (10 ms on the WLTC), so the reference has the same blind spot.
* the grade of a profile is the same piecewise-linear function of the distance (a state), in
  CasADi instead of NumPy.

The records and the TCU's log are read at the grid's points (the same times as the reference
reads its dense output).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.validation.sim.drive_powertrain import Powertrain
from scipy.optimize import brentq

__all__ = ["SUBSTEPS", "FastGearLoop", "FastSegment", "piecewise_linear"]

#: RK4 steps per TCU tick (module docstring: |λ h| ≤ 0.36 at a 10 ms tick).
SUBSTEPS = 4
#: Steps per CasADi call (a second of 10 ms ticks and the record samples fit in one call).
HORIZON = 128
#: Output rows of :attr:`FastGearLoop.out`.
OUTPUTS = ("omega_in", "up", "down", "engine", "e_machine", "brake", "pedal", "zeta")


def piecewise_linear(x: Any, xs: Sequence[float], ys: Sequence[float]) -> Any:
    """Linear interpolation of (xs, ys) at x, held at the ends, as a CasADi expression: the
    same function as NumPy's ``interp`` and the schedule's interpolation, written as a sum of
    clamped ramps so that it is exact between the points."""
    import casadi as ca

    value = ys[0] + 0 * x
    for x0, x1, y0, y1 in zip(xs[:-1], xs[1:], ys[:-1], ys[1:], strict=True):
        if x1 > x0:
            value += (y1 - y0) / (x1 - x0) * (ca.fmin(ca.fmax(x, x0), x1) - x0)
    return value


class FastGearLoop:
    """The closed loop of one gear as CasADi functions of y = [x, ∫(v_ref − v), s, W_in,
    W_friction, W_damper, W_road, W_brake] (the reference's state, :class:`_GearSegment`)
    and q = [v_ref at the step's start, a_ref, step length]: ``step`` (one RK4 step of
    :data:`SUBSTEPS` substeps), ``ticks`` (``HORIZON`` chained steps) and ``out`` (the
    records' and the schedule's values, :data:`OUTPUTS`)."""

    def __init__(
        self,
        *,
        fused: Any,
        n: int,
        wheel: int,
        input_row: np.ndarray,
        p: np.ndarray,
        line: Sequence[float],
        wheel_inertia: float,
        powertrain: Powertrain,
        ratio: float,
        schedule: Any,
        actuators: Any,
        r_dyn: float,
        brake_speed: float,
        zeta0: float,
        grade: Any = None,
        substeps: int | None = None,
    ) -> None:
        import casadi as ca

        self.n = n
        substeps = SUBSTEPS if substeps is None else substeps
        self.substeps = substeps
        size = n + 7
        y = ca.SX.sym("y", size)
        v_ref = ca.SX.sym("v_ref")
        a_ref = ca.SX.sym("a_ref")
        pt = powertrain

        def loop(y: Any, v_ref: Any, a_ref: Any, moving: Any) -> tuple[Any, Any]:
            """(ẏ, outputs) at (y, v_ref, a_ref): _GearSegment.rhs and .control in CasADi;
            ``moving``: 1 where the cycle moves (v_ref > 0), which switches the road-load
            feed-forward."""
            x = y[:n]
            omega_in = ca.dot(ca.DM(input_row), x)
            omega_c = x[wheel]
            v = omega_c * r_dyn
            force = (
                pt.mass * a_ref
                + (pt.rolling + pt.air * v_ref * v_ref) * moving
                + pt.k_p * (v_ref - v)
                + pt.k_i * y[n]
            )
            overall = ratio * pt.i_d
            demand = force * pt.r_dyn / overall
            coupled = omega_in >= pt.idle
            # the divisions are guarded: if_else evaluates both branches
            engine_max = ca.if_else(
                coupled,
                ca.fmin(pt.engine_torque, pt.engine_power / ca.fmax(omega_in, pt.idle)),
                0.0,
            )
            w = ca.fabs(omega_in)
            machine_max = ca.if_else(
                w * pt.machine_torque <= pt.machine_power,
                pt.machine_torque,
                pt.machine_power / ca.fmax(w, 1e-300),
            )
            positive = demand >= 0
            engine = ca.if_else(positive, ca.fmin(demand, engine_max), 0.0)
            machine = ca.if_else(
                positive, ca.fmin(demand - engine, machine_max), ca.fmax(demand, -machine_max)
            )
            brake = ca.if_else(positive, 0.0, (machine - demand) * overall)
            pedal = ca.if_else(positive, ca.fmin(1.0, demand / (engine_max + machine_max)), 0.0)
            true_engine = ca.if_else(coupled, actuators.engine(engine), 0.0)
            torque = true_engine + actuators.e_machine(machine)
            s = y[n + 1]
            if grade is None:
                zeta = zeta0 + 0 * s
            else:
                zeta = ca.atan(piecewise_linear(s, list(grade.s), list(grade.percent)) / 100.0)
            u = ca.vertcat(torque, *line, zeta - zeta0)
            both = fused(x, u, p)
            xdot, powers = both[:n], both[n:]
            braking = brake * ca.tanh(omega_c / brake_speed)
            xdot[wheel] -= braking / wheel_inertia
            ydot = ca.vertcat(xdot, v_ref - v, v, powers, braking * omega_c)
            up = omega_in - piecewise_linear(pedal, schedule.pedal, schedule.upshift)
            down = omega_in - piecewise_linear(pedal, schedule.pedal, schedule.downshift)
            out = ca.vertcat(omega_in, up, down, engine, machine, brake, pedal, zeta)
            return ydot, out

        # q: v_ref at the step's start, a_ref, step length; the step lies on one linear
        # piece of the cycle, where v_ref is 0 at most at an end: whether the cycle moves
        # is its sign at the step's middle, for every stage (the left limit at a launch, a
        # jump in the driver's force, would cost RK4 its order on that step)
        q = ca.SX.sym("q", 3)
        h = q[2] / substeps
        moving = ca.if_else(q[0] + q[1] * q[2] / 2 > 0, 1, 0)
        state = y
        tau = 0 * q[2]
        for _ in range(substeps):
            k1 = loop(state, q[0] + q[1] * tau, q[1], moving)[0]
            k2 = loop(state + h / 2 * k1, q[0] + q[1] * (tau + h / 2), q[1], moving)[0]
            k3 = loop(state + h / 2 * k2, q[0] + q[1] * (tau + h / 2), q[1], moving)[0]
            k4 = loop(state + h * k3, q[0] + q[1] * (tau + h), q[1], moving)[0]
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            tau = tau + h
        self.step = ca.Function("gear_step", [y, q], [state])
        self.ticks = self.step.mapaccum("gear_ticks", HORIZON)
        _, out = loop(y, v_ref, a_ref, ca.if_else(v_ref > 0, 1, 0))
        self.out = ca.Function("gear_out", [y, v_ref, a_ref], [out])
        self.out_many = self.out.map(HORIZON)

    def advance(self, y0: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The states after each step of ``q`` (3 × steps) from ``y0``: (steps, size)."""
        steps = q.shape[1]
        rows = []
        y = y0
        for start in range(0, steps, HORIZON):
            chunk = q[:, start : start + HORIZON]
            width = chunk.shape[1]
            if width < HORIZON:  # padded with steps of length zero: RK4 leaves y as it is
                pad = np.zeros((3, HORIZON - width))
                chunk = np.hstack([chunk, pad])
            states = np.asarray(self.ticks(y, chunk).full())[:, :width]
            rows.append(states.T)
            y = states[:, -1]
        return np.vstack(rows)

    def outputs(self, states: np.ndarray, v_ref: np.ndarray, a_ref: np.ndarray) -> np.ndarray:
        """:data:`OUTPUTS` at each row of ``states``: (rows, outputs)."""
        rows = []
        for start in range(0, len(states), HORIZON):
            chunk = slice(start, start + HORIZON)
            width = len(states[chunk])
            pad = HORIZON - width
            y = np.pad(states[chunk], ((0, pad), (0, 0))).T
            v = np.pad(v_ref[chunk], (0, pad))[None, :]
            a = np.pad(a_ref[chunk], (0, pad))[None, :]
            rows.append(np.asarray(self.out_many(y, v, a).full()).T[:width])
        return np.vstack(rows)


@dataclass
class FastSegment:
    """A gear segment integrated by :class:`FastGearLoop`: the grid's times, the states and
    :data:`OUTPUTS` there (the last row is the end, not part of the record), the event that
    ended it (``""``, ``"upshift"``, ``"downshift"``) and the state at the end."""

    t: np.ndarray
    y: np.ndarray
    out: np.ndarray
    t_end: float
    y_end: np.ndarray
    event: str


def segment_grid(t0: float, t1: float, points: Sequence[np.ndarray]) -> np.ndarray:
    """t0, every point of ``points`` strictly inside (t0, t1) (the TCU's ticks, the record's
    samples), t1; points closer than 1 ns merged (the same instant computed two ways)."""
    inside = np.sort(np.concatenate([np.asarray(p, dtype=float) for p in points]))
    inside = inside[(inside > t0 + 1e-9) & (inside < t1 - 1e-9)]
    if len(inside):
        keep = np.concatenate([[True], np.diff(inside) > 1e-9])
        inside = inside[keep]
    return np.concatenate([[t0], inside, [t1]])


def accelerations(cycle: Any, times: np.ndarray) -> np.ndarray:
    """``cycle.acceleration`` at every time of ``times`` (the same arithmetic: the slope of
    the piece holding each time, 0 outside the cycle), without a Python call per time."""
    t, v = np.asarray(cycle.t, dtype=float), np.asarray(cycle.v_kmh, dtype=float)
    k = np.searchsorted(t, np.asarray(times, dtype=float), side="right") - 1
    inside = (k >= 0) & (k < len(t) - 1)
    j = np.clip(k, 0, len(t) - 2)
    slope = (v[j + 1] - v[j]) / 3.6 / (t[j + 1] - t[j])
    return np.where(inside, slope, 0.0)


def integrate_segment(
    loop: FastGearLoop,
    cycle: Any,
    grid: np.ndarray,
    y0: np.ndarray,
    up: bool,
    down: bool,
) -> FastSegment:
    """Integrate the loop over ``grid`` (one piece of the cycle's speed, linear in it) from
    ``y0``; stop at the first armed threshold crossed (upshift: the input speed rises through
    the upshift speed, downshift: falls through the downshift speed, the crossing rules of
    SciPy's events)."""
    v_start = np.asarray(cycle.speed(grid[:-1]), dtype=float)
    slope = accelerations(cycle, (grid[:-1] + grid[1:]) / 2)
    q = np.vstack([v_start, slope, np.diff(grid)])
    states = np.vstack([y0[None, :], loop.advance(y0, q)])
    v_ref = np.asarray(cycle.speed(grid), dtype=float)
    a_ref = accelerations(cycle, grid)
    out = loop.outputs(states, v_ref, a_ref)
    crossings: list[tuple[int, str, int]] = []  # (step, name, row of OUTPUTS)
    for armed, name, row, direction in ((up, "upshift", 1, 1), (down, "downshift", 2, -1)):
        if not armed:
            continue
        g = out[:, row] * direction
        hit = np.flatnonzero((g[:-1] <= 0) & (g[1:] >= 0))
        if len(hit):
            crossings.append((int(hit[0]), name, row))
    if not crossings:
        return FastSegment(grid, states, out, float(grid[-1]), states[-1], "")
    first = min(i for i, _, _ in crossings)
    best: tuple[float, str] | None = None
    for i, name, row in crossings:
        if i != first:
            continue
        delta = _locate(loop, states[i], q[:, i], out[i, row], out[i + 1, row], row)
        if best is None or delta < best[0]:
            best = (delta, name)
    assert best is not None
    delta, name = best
    if delta == q[2, first]:
        # at the step's end (:func:`_locate`: the threshold jumped there, at a point of the
        # cycle); the drive reads the driver there after the jump, as the reference does
        t_end = float(grid[first + 1])
        y_end = states[first + 1]
    else:
        q_end = np.array([q[0, first], q[1, first], delta])
        y_end = np.asarray(loop.step(states[first], q_end).full()).ravel()
        t_end = float(grid[first] + delta)
    keep = grid < t_end - 1e-12
    return FastSegment(grid[keep], states[keep], out[keep], t_end, y_end, name)


def _locate(
    loop: FastGearLoop, y: np.ndarray, q: np.ndarray, g0: float, g1: float, row: int
) -> float:
    """The step length δ at which the threshold ``row`` crosses zero inside the step ``q``
    from ``y`` (Brent's method on the RK4 step of length δ; g0, g1 at its ends)."""
    if g0 == 0.0:
        return 0.0
    if g1 == 0.0:
        return float(q[2])
    v0, a = float(q[0]), float(q[1])

    def g(delta: float) -> float:
        y_delta = loop.step(y, [v0, a, delta])
        return float(loop.out(y_delta, v0 + a * delta, a)[row])

    if g(float(q[2])) * g0 > 0:
        # the threshold jumped at the step's end, a point of the cycle where a_ref (the
        # driver's feed-forward, so the pedal) steps: the crossing is that point, where
        # SciPy's root search on the reference's dense output ends too
        return float(q[2])
    # SciPy locates its events to 4 machine epsilons of the time; 1e-12 s is as fine for
    # a drive's clock (its samples are 1 ms apart at the finest)
    return float(brentq(g, 0.0, float(q[2]), xtol=1e-12, rtol=4 * np.finfo(float).eps))


def sample_rows(grid: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The grid's row of each of ``times`` (each is a grid point, computed another way)."""
    rows = np.searchsorted(grid, np.asarray(times, dtype=float) - 1e-9)
    return np.minimum(rows, len(grid) - 1)


def records_of(
    segment: FastSegment,
    times: np.ndarray,
    cycle: Any,
    gear: int,
    wheel: int,
    n: int,
    r_dyn: float,
) -> list[dict[str, float]]:
    """The drive's records at ``times`` (points of the segment's grid), the columns of the
    reference's ``_record_dense``."""
    rows = sample_rows(segment.t, times)
    y, out = segment.y[rows], segment.out[rows]
    v_ref = np.asarray(cycle.speed(times), dtype=float)
    column = {name: out[:, j] for j, name in enumerate(OUTPUTS)}
    return [
        {
            "t": float(t),
            "v_ref": float(v_ref[i]),
            "v": float(y[i, wheel] * r_dyn),
            "gear": float(gear),
            "T_engine": float(column["engine"][i]),
            "T_e_machine": float(column["e_machine"][i]),
            "T_brake": float(column["brake"][i]),
            "pedal": float(column["pedal"][i]),
            "omega_in": float(column["omega_in"][i]),
            "s": float(y[i, n + 1]),
        }
        for i, t in enumerate(times)
    ]


def log_segment(
    log: Any,
    segment: FastSegment,
    ticks: np.ndarray,
    speeds: np.ndarray,
    twist: int,
    wheel: int,
    pressures: dict[str, float],
    gear: int,
) -> None:
    """The TCU's samples of the segment at ``ticks`` (points of its grid), the columns of the
    reference's ``_log_gear``; ``speeds``: the gear's matrix x → every shaft's speed."""
    if not len(ticks):
        return
    rows = sample_rows(segment.t, ticks)
    n = speeds.shape[1]
    y, out = segment.y[rows], segment.out[rows]
    column = {name: out[:, j] for j, name in enumerate(OUTPUTS)}
    log.add_many(
        ticks,
        y[:, :n] @ speeds.T,
        y[:, twist],
        y[:, wheel],
        column["engine"] + column["e_machine"],
        column["brake"],
        pressures,
        gear,
        column["zeta"],
        column["engine"],
    )
