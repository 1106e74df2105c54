"""Integrate with the emitted step functions and the emitted CasADi integrator, against SciPy.

Three studies, all on the code as emitted (C compiled with the strict flags and called through
ctypes; the CasADi module imported from its file):

1. **RK4 convergence** of ``gearsym_shift_2_3_mu_rk4_step`` (the thesis' default 2→3 shift, normal
   forces as inputs), driven by smooth known inputs (engine torque oscillating, K38 released and
   B05 applied with cosine ramps) from 15 m/s in 2nd gear. A TCU samples its inputs once per
   step and holds them (the emitted step takes one ``u``), so the reference is the same ODE with
   the same sample-and-hold inputs, integrated by SciPy's Radau (rtol 1e-10, analytic Jacobian)
   interval by interval. The maximum state error over the horizon falls as h⁴ (observed order
   ≈ 4) until float rounding takes over in the single build. How far the sampled-input
   trajectory is from the one with the smooth inputs themselves is reported too (order 1: the
   price of the sample-and-hold, which is the TCU's sample time, not the integrator's).
2. **Linearly implicit Euler** (``gearsym_full_linearly_implicit_euler_step``) on the full model
   with the same kind of inputs: order 1, stable at every step size.
3. **CVODES** (the emitted ``held_input_simulator()``: the emitted ``integrator(h)`` chained over
   the held samples) on the same problem as 1, against the same Radau reference.

And, when a reference simulation is available (:func:`gearsym.validation.sim.simulate.simulate`), a
**replay**: the emitted ``gearsym_shift_2_3_rk4_step`` (element torques as inputs) driven through
the speed phase of the simulated shift by the recorded engine and element torques (held at each
step's midpoint), compared with the recorded speeds; this measures the shift model (2.55)–(2.58)
plus the step against the full reference model with friction states.

:func:`integration_check` runs 1–3 (and 4 with ``replay=True``) and returns an
:class:`IntegrationReport`; ``python -m gearsym.validation.checks.integration_check`` prints it.
"""

from __future__ import annotations

import math
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.codegen import file_names
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import full_model, shift_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.model import Model
from gearsym.validation.checks import c_check
from scipy.integrate import solve_ivp

#: The emitted tree checked by default: ``generated/`` of the folder it is run from (the
#: repository's, run from a checkout; an installed gearsym has none of its own).
GENERATED = Path("generated")

T_END = 0.256  # s; a multiple of every step size below
RK4_STEPS = (0.016, 0.008, 0.004, 0.002, 0.001)
LIE_STEPS = (0.002, 0.001, 0.0005, 0.00025)
CVODES_STEP = 0.001
CVODES_TOLERANCES = (1e-8, 1e-10, 1e-12)  # 1e-10 is the emitted module's default
REFERENCE_RTOL = 1e-10
#: Scale of each state for the error norm and the reference's absolute tolerance.
STATE_SCALE = {"phi": 0.01, "omega_C": 10.0}
DEFAULT_SPEED_SCALE = 100.0  # rad/s, every omega_<shaft>


@dataclass
class ConvergenceRow:
    """Maximum state error over the horizon at one step size (scaled: error / state scale)."""

    h: float
    n_steps: int
    error_double: float
    error_single: float | None = None
    error_vs_smooth: float | None = None  # sample-and-hold trajectory vs smooth inputs
    worst_state: str = ""


@dataclass
class ReplayReport:
    """The emitted shift model driven by the reference simulation's recorded inputs."""

    phase: str
    t_start: float
    t_end: float
    h: float
    max_abs_error: dict[str, float]
    max_relative_speed_error: float  # largest speed error / largest speed in the phase


@dataclass
class IntegrationReport:
    """Everything :func:`integration_check` measured."""

    shift_model: str
    full_model: str
    scales: dict[str, float]
    rk4: list[ConvergenceRow] = field(default_factory=list)
    lie: list[ConvergenceRow] = field(default_factory=list)
    cvodes: dict[float, float] = field(default_factory=dict)  # tolerance -> error
    replay: ReplayReport | None = None

    @staticmethod
    def orders(rows: Sequence[ConvergenceRow], single: bool = False) -> list[float]:
        """Observed order log2(e(h) / e(h/2)) between neighbouring rows."""
        values = [r.error_single if single else r.error_double for r in rows]
        return [
            math.log2(a / b) if a and b else math.nan
            for a, b in zip(values[:-1], values[1:], strict=True)
        ]

    def lines(self) -> list[str]:
        scale_text = ", ".join(f"{k} {v:g}" for k, v in self.scales.items())
        out = [
            f"errors are max over t in [0, {T_END:g}] s of |x - x_ref| / scale ({scale_text})",
            f"RK4 ({self.shift_model}_rk4_step) vs Radau rtol {REFERENCE_RTOL:g}, same "
            "sample-and-hold inputs:",
            f"  {'h [s]':>8} {'steps':>6} {'C double':>10} {'order':>6} {'C single':>10} "
            f"{'order':>6} {'vs smooth u':>12}",
        ]
        orders_d = [math.nan, *self.orders(self.rk4)]
        orders_s = [math.nan, *self.orders(self.rk4, single=True)]
        for row, od, os_ in zip(self.rk4, orders_d, orders_s, strict=True):
            out.append(
                f"  {row.h:8.5f} {row.n_steps:6d} {row.error_double:10.3e} {od:6.2f} "
                f"{row.error_single or math.nan:10.3e} {os_:6.2f} "
                f"{row.error_vs_smooth or math.nan:12.3e}"
            )
        out.append(f"linearly implicit Euler ({self.full_model}) vs Radau, same inputs:")
        orders_l = [math.nan, *self.orders(self.lie)]
        for row, order in zip(self.lie, orders_l, strict=True):
            out.append(f"  {row.h:8.5f} {row.n_steps:6d} {row.error_double:10.3e} {order:6.2f}")
        out.append(
            f"CasADi CVODES (emitted held_input_simulator, h = {CVODES_STEP:g}) vs Radau: "
            + ", ".join(f"tol {tol:g}: {err:.3e}" for tol, err in self.cvodes.items())
        )
        if self.replay is not None:
            r = self.replay
            errors = ", ".join(f"{k} {v:.3e}" for k, v in r.max_abs_error.items())
            out.append(
                f"replay of the reference simulation, {r.phase} [{r.t_start:.4f}, "
                f"{r.t_end:.4f}] s, RK4 h = {r.h:g} s: max |error| {errors}; largest speed "
                f"error {100 * r.max_relative_speed_error:.3f} % of the largest speed"
            )
        return out


# ---------------------------------------------------------------------------------------------
# Inputs and reference
# ---------------------------------------------------------------------------------------------


def smooth_inputs(model: Model, t_ramp: float = T_END) -> Callable[[float], np.ndarray]:
    """u(t) for a shift or full model: T_In = 180 + 40 sin(2π t / 0.4 s) N m; in a shift model
    with normal-force inputs the off-going element's force ramps from 1000 N to 0 and the
    on-coming one's from 0 to 1700 N (cosine ramps over ``t_ramp``: for the built-in 2-3 shift
    the input speed falls from 2nd- to about 3rd-gear speed); element torques (full or
    torque-input models) ramp likewise between 0 and ±150 N m. All C∞ on [0, t_ramp]."""
    names = [v.name for v in model.inputs]

    def u(t: float) -> np.ndarray:
        s = min(max(t / t_ramp, 0.0), 1.0)
        rise = 0.5 * (1.0 - math.cos(math.pi * s))
        values = []
        for k, name in enumerate(names):
            if name == "T_In":
                values.append(180.0 + 40.0 * math.sin(2.0 * math.pi * t / 0.4))
            elif name.startswith("F_N"):
                values.append(1700.0 * rise if k == len(names) - 1 else 1000.0 * (1.0 - rise))
            else:  # element torques
                values.append(150.0 * (rise if k % 2 else -(1.0 - rise)))
        return np.array(values)

    return u


def initial_state(d: GearboxDescription, model: Model, gear: str, speed: float) -> np.ndarray:
    """Every shaft state at the speeds of ``gear`` at vehicle speed ``speed`` [m/s]."""
    from gearsym.symbolic.ratios import gear_motion

    r_dyn = float(d.vehicle["r_dyn"].value)
    i_d = float(d.drivetrain["i_D"].value)
    omega_c = speed / r_dyn
    omega_out = omega_c * i_d
    motion = gear_motion(d, d.gear(gear))
    speeds = dict(zip(d.shaft_names, motion, strict=True))
    per_out = {s: float(v / speeds[d.output_shaft]) for s, v in speeds.items()}
    values = []
    for v in model.states:
        if v.name == "omega_C":
            values.append(omega_c)
        elif v.name.startswith("omega_"):
            values.append(per_out[v.name.removeprefix("omega_")] * omega_out)
        else:
            values.append(0.0)
    return np.array(values)


def _scales(model: Model) -> np.ndarray:
    return np.array([STATE_SCALE.get(v.name, DEFAULT_SPEED_SCALE) for v in model.states])


class _Reference:
    """The model with default parameters, lambdified, integrated by Radau (rtol 1e-10)."""

    def __init__(self, model: Model) -> None:
        params = {v.symbol: sp.Float(v.default) for v in model.parameters}
        rhs = model.rhs.xreplace(params)
        args = [model.state_symbols, model.input_symbols]
        self._f = sp.lambdify(args, list(rhs), "numpy")
        self._jac = sp.lambdify(args, rhs.jacobian(model.state_symbols), "numpy")
        self.atol = REFERENCE_RTOL * _scales(model)

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.asarray(self._f(x, u), dtype=float)

    def solve(
        self,
        x0: np.ndarray,
        t0: float,
        t1: float,
        u: Callable[[float], np.ndarray],
    ) -> np.ndarray:
        sol = solve_ivp(
            lambda t, x: self.f(x, u(t)),
            (t0, t1),
            x0,
            method="Radau",
            rtol=REFERENCE_RTOL,
            atol=self.atol,
            jac=lambda t, x: np.asarray(self._jac(x, u(t)), dtype=float),
        )
        if not sol.success:
            raise RuntimeError(f"reference integration failed: {sol.message}")
        return sol.y[:, -1]

    def held(
        self, x0: np.ndarray, h: float, n: int, u: Callable[[float], np.ndarray]
    ) -> np.ndarray:
        """States at t = h, 2h, ..., nh with u held at u(k h) on [k h, (k+1) h]."""
        out = np.zeros((n, len(x0)))
        x = x0
        for k in range(n):
            uk = u(k * h)
            x = self.solve(x, k * h, (k + 1) * h, lambda t, uk=uk: uk)
            out[k] = x
        return out

    def smooth(self, x0: np.ndarray, times: np.ndarray, u: Callable[[float], np.ndarray]) -> Any:
        sol = solve_ivp(
            lambda t, x: self.f(x, u(t)),
            (0.0, float(times[-1])),
            x0,
            method="Radau",
            rtol=REFERENCE_RTOL,
            atol=self.atol,
            t_eval=times,
            jac=lambda t, x: np.asarray(self._jac(x, u(t)), dtype=float),
        )
        return sol.y.T


def _scaled_error(a: np.ndarray, b: np.ndarray, scale: np.ndarray) -> tuple[float, int]:
    err = np.abs(a - b) / scale
    flat = int(np.argmax(err))
    return float(err.max()), flat % a.shape[1]


def _c_library(model: Model, c_dir: Path, build_dir: Path, single: bool) -> c_check.CFunctions:
    names = file_names(model)
    files = {n: (c_dir / n).read_text(encoding="utf-8") for n in (names["header"], names["source"])}
    lib = c_check.compile_shared(files, build_dir / model.name, single=single)
    return c_check.load_functions(lib, model, single=single)


def _c_trajectory(
    lib: c_check.CFunctions,
    name: str,
    x0: np.ndarray,
    h: float,
    n: int,
    u: Callable[[float], np.ndarray],
    params: Sequence[float],
) -> np.ndarray:
    out = np.zeros((n, len(x0)))
    x = x0
    p = lib.params(params)
    for k in range(n):
        x = lib.step(name, x, u(k * h), p, h)
        out[k] = x
    return out


# ---------------------------------------------------------------------------------------------
# The studies
# ---------------------------------------------------------------------------------------------


def integration_check(
    d: GearboxDescription | None = None,
    root: Path = GENERATED,
    build_dir: Path | None = None,
    shift: str = "2-3",
    replay: bool = False,
    rk4_steps: Sequence[float] = RK4_STEPS,
    lie_steps: Sequence[float] = LIE_STEPS,
) -> IntegrationReport:
    """Run the studies of the module docstring on the code under ``root`` (``c/`` and
    ``python/`` as written by ``gearsym generate``) for gearbox ``d`` (default: built-in)."""
    d = d if d is not None else load_description(None)
    own_build = build_dir is None
    build = Path(tempfile.mkdtemp(prefix="gearsym-integration-")) if own_build else build_dir
    try:
        return _run(d, root, build, shift, replay, rk4_steps, lie_steps)
    finally:
        if own_build:
            import shutil

            shutil.rmtree(build, ignore_errors=True)


def _run(
    d: GearboxDescription,
    root: Path,
    build: Path,
    shift: str,
    replay: bool,
    rk4_steps: Sequence[float],
    lie_steps: Sequence[float],
) -> IntegrationReport:
    from_gear, to_gear = shift.split("-")
    mu_name = naming.shift_model_name(from_gear, to_gear, friction_inputs=True)
    # no friction data or a double swap: the torque-input model
    with_mu = (root / "c" / naming.model_file_names(mu_name)["source"]).is_file()
    sm = shift_model(d, shift, friction_inputs=with_mu)
    fm = full_model(d)
    scales = _scales(sm)
    report = IntegrationReport(
        sm.name, fm.name, {v.name: float(s) for v, s in zip(sm.states, scales, strict=True)}
    )
    params = [float(v.default) for v in sm.parameters]
    u = smooth_inputs(sm)
    x0 = initial_state(d, sm, from_gear, 15.0)
    ref = _Reference(sm)
    libs = {single: _c_library(sm, root / "c", build, single) for single in (False, True)}
    for h in rk4_steps:
        n = round(T_END / h)
        expected = ref.held(x0, h, n, u)
        times = h * np.arange(1, n + 1)
        row = ConvergenceRow(h, n, 0.0)
        c_double = _c_trajectory(libs[False], "rk4_step", x0, h, n, u, params)
        row.error_double, worst = _scaled_error(c_double, expected, scales)
        row.worst_state = sm.states[worst].name
        c_single = _c_trajectory(libs[True], "rk4_step", x0, h, n, u, params)
        row.error_single = _scaled_error(c_single, expected, scales)[0]
        row.error_vs_smooth = _scaled_error(expected, ref.smooth(x0, times, u), scales)[0]
        report.rk4.append(row)

    # CVODES: the emitted sample-and-hold simulator (one integrator call per held sample).
    module = c_check.load_casadi_module(root / "python" / file_names(sm)["casadi"])
    n = round(T_END / CVODES_STEP)
    controls = np.column_stack([u(k * CVODES_STEP) for k in range(n)])
    expected = ref.held(x0, CVODES_STEP, n, u)
    for tol in CVODES_TOLERANCES:
        options = {} if tol == 1e-10 else {"abstol": tol, "reltol": tol}  # 1e-10: the default
        simulator = module.held_input_simulator(CVODES_STEP, n, options)
        cvodes = np.asarray(simulator(x0=x0, u=controls, p=params)["xf"]).T
        report.cvodes[tol] = _scaled_error(cvodes, expected, scales)[0]

    # Linearly implicit Euler on the full model.
    fscales = _scales(fm)
    fref = _Reference(fm)
    fu = smooth_inputs(fm)
    fx0 = initial_state(d, fm, from_gear, 15.0)
    flib = _c_library(fm, root / "c", build, False)
    fparams = [float(v.default) for v in fm.parameters]
    for h in lie_steps:
        n = round(T_END / h)
        expected = fref.held(fx0, h, n, fu)
        got = _c_trajectory(flib, "linearly_implicit_euler_step", fx0, h, n, fu, fparams)
        err, worst = _scaled_error(got, expected, fscales)
        report.lie.append(ConvergenceRow(h, n, err, worst_state=fm.states[worst].name))

    if replay:
        report.replay = replay_reference(d, root, build, shift)
    return report


def replay_reference(
    d: GearboxDescription, root: Path, build: Path, shift: str = "2-3"
) -> ReplayReport:
    """Drive the emitted ``shift_<a>_<b>`` (torque inputs) through the speed phase of the
    reference simulation with its recorded torques; compare with its recorded states."""
    from gearsym.validation.sim.simulate import simulate

    result = simulate(d, check_models=False)
    phase = next(p for p in result.phases if p.name == "speed phase")
    model = shift_model(d, shift)
    lib = _c_library(model, root / "c", build, False)
    t = result.t
    signals = result.signals
    input_names = [v.name for v in model.inputs]
    state_names = [v.name for v in model.states]
    h = float(t[1] - t[0])
    start = int(np.searchsorted(t, phase.t_start))
    stop = int(np.searchsorted(t, phase.t_end))
    x = np.array([signals[name][start] for name in state_names])
    p = lib.params([float(v.default) for v in model.parameters])
    errors = np.zeros(len(state_names))
    for k in range(start, stop):
        step = float(t[k + 1] - t[k])  # the sample grid also holds the scenario's breakpoints
        midpoint = t[k] + 0.5 * step
        uk = [float(np.interp(midpoint, t, signals[name])) for name in input_names]
        x = lib.step("rk4_step", x, uk, p, step)
        recorded = np.array([signals[name][k + 1] for name in state_names])
        errors = np.maximum(errors, np.abs(x - recorded))
    speeds = [i for i, name in enumerate(state_names) if name.startswith("omega_")]
    largest = max(float(np.max(np.abs(signals[state_names[i]][start:stop]))) for i in speeds)
    return ReplayReport(
        phase=phase.name,
        t_start=float(t[start]),
        t_end=float(t[stop]),
        h=h,
        max_abs_error=dict(zip(state_names, map(float, errors), strict=True)),
        max_relative_speed_error=max(float(errors[i]) for i in speeds) / largest,
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Print the report for the committed ``generated/`` (or ``--root DIR``)."""
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", help="gearbox description (default: built-in)")
    parser.add_argument("--root", default=str(GENERATED), help="output of gearsym generate")
    parser.add_argument("--replay", action="store_true", help="also replay the reference")
    args = parser.parse_args(argv)
    report = integration_check(load_description(args.config), Path(args.root), replay=args.replay)
    print("\n".join(report.lines()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
