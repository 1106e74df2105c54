"""The driven shift model integrated with its sensitivities (thesis 3.2–3.7): parameter values
and nominal scales (3.3), the model's f and h compiled to CasADi, the recorded inputs
interpolated, the fixed-step order-8 integration of ẋ = f(x, u(t), p) (3.5) and of the
augmented system [x; S] (3.7), and S(t0)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.model import Model
from gearsym.symbolic.numeric import casadi_function
from gearsym.symbolic.parameters import zero_scale
from gearsym.symbolic.sensitivity import SensitivityEquations, stationary_initial_sensitivity


def parameter_values(
    model: Model, overrides: Mapping[str, float] | None = None
) -> dict[str, float]:
    """Every parameter's value: its default, or the override."""
    values = {v.name: float(v.default) for v in model.parameters if v.default is not None}
    for name, value in (overrides or {}).items():
        if name not in {v.name for v in model.parameters}:
            raise GearsymError(
                model.metadata.get("gearbox", model.name), "set", f"unknown parameter {name!r}"
            )
        values[name] = float(value)
    missing = [v.name for v in model.parameters if v.name not in values]
    if missing:
        raise GearsymError(model.name, "set", f"no value for parameters {missing}")
    return values


def nominal_scales(names: Sequence[str], values: Mapping[str, float]) -> np.ndarray:
    """p_j0 of (3.3), (3.27); a parameter at zero uses its record's scale (:func:`zero_scale`)."""
    scales = []
    for name in names:
        value = abs(values[name])
        scales.append(value if value > 0 else zero_scale(name))
    return np.array(scales)


class CompiledModel:
    """f(x, u, p) and h(x, u, p) of a model as CasADi functions (one translation through
    :func:`gearsym.symbolic.numeric.casadi_function`), and the fixed-step integrator built on
    them."""

    def __init__(self, model: Model) -> None:
        self.model = model
        groups = [
            ("x", model.state_symbols),
            ("u", model.input_symbols),
            ("p", model.parameter_symbols),
        ]
        self._f = casadi_function("f", groups, [("xdot", model.rhs)])
        self._h = casadi_function("h", groups, [("y", model.output_expressions)])
        self.parameter_names = [v.name for v in model.parameters]
        self._step: Any = None

    def parameters(self, values: Mapping[str, float]) -> list[float]:
        return [float(values[n]) for n in self.parameter_names]

    def f(self, x: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        return np.asarray(self._f(x, u, p).full(), dtype=float).ravel()

    def h(self, x: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        return np.asarray(self._h(x, u, p).full(), dtype=float).ravel()

    def f_many(self, x: np.ndarray, u: np.ndarray, p: Sequence[float]) -> np.ndarray:
        """f at N points (x: N × n, u: N × nu): N × n."""
        out = self._f.map(len(x))(x.T, u.T, np.asarray(p, dtype=float))
        return np.asarray(out.full(), dtype=float).T

    def h_many(self, x: np.ndarray, u: np.ndarray, p: Sequence[float]) -> np.ndarray:
        out = self._h.map(len(x))(x.T, u.T, np.asarray(p, dtype=float))
        return np.asarray(out.full(), dtype=float).T

    def rk8_step(self) -> Any:
        """One step of the 8th-order Dormand–Prince method (SciPy's public ``DOP853``
        tableau) with u linear over the step: (x, u_start, u_end, h, p) → x_next."""
        if self._step is None:
            import casadi as ca
            from scipy.integrate import DOP853

            a, b, c = DOP853.A, DOP853.B, DOP853.C
            n, nu, npar = self._f.size1_in(0), self._f.size1_in(1), self._f.size1_in(2)
            x, ua, ub = ca.SX.sym("x", n), ca.SX.sym("ua", nu), ca.SX.sym("ub", nu)
            h, p = ca.SX.sym("h"), ca.SX.sym("p", npar)
            stages: list[Any] = []
            for i in range(len(b)):
                xi = x + h * sum((float(a[i, j]) * stages[j] for j in range(i)), ca.SX(n, 1))
                stages.append(self._f(xi, ua + float(c[i]) * (ub - ua), p))
            x_next = x + h * sum((float(b[i]) * stages[i] for i in range(len(b))), ca.SX(n, 1))
            self._step = ca.Function("rk8_step", [x, ua, ub, h, p], [x_next])
        return self._step


class Interpolated:
    """Inputs u(t) linearly interpolated between samples (held outside the record)."""

    def __init__(self, t: np.ndarray, u: np.ndarray) -> None:
        self.t = np.asarray(t, dtype=float)
        self.u = np.asarray(u, dtype=float).reshape(len(self.t), -1)
        self._slope = np.diff(self.u, axis=0) / np.diff(self.t)[:, None]

    def __call__(self, t: float) -> np.ndarray:
        k = int(np.searchsorted(self.t, t, side="right")) - 1
        if k < 0:
            return self.u[0]
        if k >= len(self.t) - 1:
            return self.u[-1]
        return self.u[k] + (t - self.t[k]) * self._slope[k]

    def many(self, times: np.ndarray) -> np.ndarray:
        """u at many times (N × nu), the same interpolation, vectorised."""
        columns = [np.interp(times, self.t, self.u[:, k]) for k in range(self.u.shape[1])]
        return np.column_stack(columns) if columns else np.zeros((len(times), 0))


def integrate(
    compiled: CompiledModel,
    inputs: Interpolated,
    x0: np.ndarray,
    values: Mapping[str, float],
    t_eval: np.ndarray,
    max_step: float = 5e-4,
) -> np.ndarray:
    """States (len(t_eval), n) of ``ẋ = f(x, u(t), p)`` (3.5) from ``x0`` at ``t_eval[0]``.

    Fixed-step explicit Runge–Kutta of order 8 (the Dormand–Prince 8 tableau) on a grid that
    contains every input sample and every ``t_eval`` point, subdivided to steps ≤ ``max_step``:
    the piecewise-linear inputs are smooth inside every step, so the method keeps its order
    (an adaptive solver stepping across the input kinks loses it). Applied to the augmented
    system [x; S] the steps are the exact derivative of the same steps applied to x, so finite
    differences of :func:`integrate` converge to the integrated sensitivities. The steps run
    in CasADi (one step function, chained with ``mapaccum``), not in a Python loop.
    """
    p = compiled.parameters(values)
    t_eval = np.asarray(t_eval, dtype=float)
    nodes = inputs.t[(inputs.t > t_eval[0]) & (inputs.t < t_eval[-1])]
    grid = np.union1d(t_eval, nodes)
    wanted = np.searchsorted(grid, t_eval)
    starts, widths, ends = [], [], np.zeros(len(grid), dtype=int)
    for k in range(len(grid) - 1):
        t0, t1 = grid[k], grid[k + 1]
        steps = max(1, int(np.ceil((t1 - t0) / max_step - 1e-9)))
        h = (t1 - t0) / steps
        starts.extend(t0 + s * h for s in range(steps))
        widths.extend([h] * steps)
        ends[k + 1] = len(starts)
    x0 = np.asarray(x0, dtype=float)
    out = np.empty((len(grid), len(x0)))
    out[0] = x0
    if starts:
        t_start, h = np.array(starts), np.array(widths)
        chain = compiled.rk8_step().mapaccum("rk8_chain", len(t_start))
        states = chain(
            x0, inputs.many(t_start).T, inputs.many(t_start + h).T, h[None, :], np.asarray(p)
        )
        states = np.asarray(states.full(), dtype=float).T  # after each step
        out[1:] = states[ends[1:] - 1]
    if not np.all(np.isfinite(out[wanted])):
        raise RuntimeError("integration diverged (non-finite state)")
    return out[wanted]


@dataclass(frozen=True)
class SensitivityTrajectory:
    """x, S (3.2) and Ṡ (3.7) at ``t``; y and ∂y/∂p for the Fisher information (3.25)."""

    t: np.ndarray
    state_names: tuple[str, ...]
    parameter_names: tuple[str, ...]
    output_names: tuple[str, ...]
    x: np.ndarray  # (N, n)
    S: np.ndarray  # (N, n, m)
    dS: np.ndarray  # (N, n, m)
    y: np.ndarray  # (N, ny)
    dy: np.ndarray  # (N, ny, m)


def integrate_sensitivities(
    eqs: SensitivityEquations,
    inputs: Interpolated,
    x0: np.ndarray,
    values: Mapping[str, float],
    t_eval: np.ndarray,
    max_step: float = 5e-4,
    compiled: CompiledModel | None = None,
    s0: np.ndarray | None = None,
) -> SensitivityTrajectory:
    """Integrate the augmented system [x; S] (3.5), (3.7) from S(t0) = ``s0`` (n × m, default
    0) and evaluate Ṡ and the output sensitivities at ``t_eval``."""
    compiled = compiled or CompiledModel(eqs.augmented)
    n, m = len(eqs.model.states), len(eqs.parameters)
    s0 = np.zeros((n, m)) if s0 is None else np.asarray(s0, dtype=float)
    z0 = np.concatenate([x0, s0.T.reshape(-1)])
    z = integrate(compiled, inputs, z0, values, t_eval, max_step)
    p = compiled.parameters(values)
    u_eval = inputs.many(np.asarray(t_eval, dtype=float))
    zdot = compiled.f_many(z, u_eval, p)
    out = compiled.h_many(z, u_eval, p)
    ny = len(eqs.model.outputs)

    def columns(a: np.ndarray, rows: int) -> np.ndarray:
        # stacked parameter by parameter: [S_1; S_2; ...] -> (N, rows, m)
        return a.reshape(len(t_eval), m, rows).transpose(0, 2, 1)

    return SensitivityTrajectory(
        t=np.asarray(t_eval, dtype=float),
        state_names=tuple(v.name for v in eqs.model.states),
        parameter_names=tuple(eqs.parameter_names),
        output_names=tuple(v.name for v in eqs.model.outputs),
        x=z[:, :n],
        S=columns(z[:, n:], n),
        dS=columns(zdot[:, n:], n),
        y=out[:, :ny],
        dy=columns(out[:, ny:], ny),
    )


def initial_sensitivities(
    eqs: SensitivityEquations,
    x0: np.ndarray,
    u0: np.ndarray,
    values: Mapping[str, float],
    initial: str = "stationary",
) -> np.ndarray:
    """S(t0), n × m: zero (``"zero"``: x(t0) known independently of p), or consistent with the
    quasi-static start of the reference (``"stationary"``: φ solves φ̈ = 0, the speeds are
    given; :func:`gearsym.symbolic.sensitivity.stationary_initial_sensitivity`)."""
    n, m = len(eqs.model.states), len(eqs.parameters)
    if initial == "zero":
        return np.zeros((n, m))
    if initial != "stationary":
        raise ValueError(f"initial must be 'stationary' or 'zero', got {initial!r}")
    free = [v.name for v in eqs.model.states if v.name == "phi"]
    if not free:
        return np.zeros((n, m))
    expr = stationary_initial_sensitivity(eqs, free)
    model = eqs.model
    subs = {s: float(v) for s, v in zip(model.state_symbols, x0, strict=True)}
    subs.update({s: float(v) for s, v in zip(model.input_symbols, u0, strict=True)})
    subs.update({v.symbol: float(values[v.name]) for v in model.parameters})
    return np.array(expr.xreplace(subs).evalf(), dtype=float)
