"""Stage 4b: sensitivities along the reference shift (thesis 3.2–3.4, Figures 3.4–3.8).

The 2↔3 shift model (2.55)–(2.58) is driven open-loop by the signals the reference simulation
(:mod:`gearsym.validation.sim.simulate`) recorded, from the recorded initial state, and integrated
together with its sensitivity ODE (3.7) (:mod:`gearsym.symbolic.sensitivity`).

How the recorded element torques drive the shift model (the *driven* shift model): each
swapping element's torque is the recorded transmitted torque T_e (sign of 2.36), split in two
inputs so that μ enters exactly where it acts physically (3.14)–(3.15):

* while the element **slides** its torque is sliding friction, k_sign 2 N_disc r_m μ_e F_N,e
  (3.14), with the *effective* normal force F_N,e = T_e / (k_sign 2 N_disc r_m μ_e0) that
  reproduces the recorded torque at the nominal μ_e0: ∂T_e/∂μ_e = T_e/μ_e0, i.e. a 1 % change of
  μ changes the friction torque by 1 %;
* while it **sticks** its torque is a constraint force, an input ``T_<element>`` that does not
  depend on μ (the thesis: (3.15) holds only while Δω ≠ 0).

Sliding is either ``"detected"`` from the record (the element is pressed and transmits at least
``capacity_fraction`` of its capacity 2 N_disc r_m μ F_N, the elasto-plastic model's sliding
condition) or taken from the ``"phases"`` as the thesis assumes in 3.1 (both swapping elements
slide from the start of the torque phase to the end of the speed phase).

The road grade: the reference simulation records ζ(t) (the scenario's ``[grade]`` profile, or
the description's constant ζ0). The driven model keeps ζ as a *parameter* and gets the recorded
deviation Δζ(t) = ζ_rec(t) − ζ0 as a further input ``zeta_dev``: its road load (2.49) sees
ζ + Δζ(t), which is ζ_rec(t) at the nominal ζ = ζ0, and ∂/∂ζ is the sensitivity to a constant
offset of the whole grade profile. That keeps (3.7), Ṡ = ∂f/∂x S + ∂f/∂p, correct: p must be
constant in time for S = ∂x/∂p to be a derivative with respect to a finite set of numbers, and
a constant offset of an otherwise recorded (known) profile is exactly what the FIM (3.25) can
ask about. Making ζ an input instead would drop it from the parameters (inputs are known), so
the FIM could no longer tell how well the grade is estimable; and evaluating ∂f/∂ζ at the
constant ζ0 while the reference drove ζ(t) would linearise at the wrong point. Without a
profile Δζ ≡ 0 and nothing changes. ``--set zeta=…`` shifts the whole profile by the same
offset.

Also here, as independent checks of the sensitivities (tests, benchmark): central finite
differences of the integrated model, and CasADi forward-mode derivatives through a CVODES
integrator of a CasADi SX build of the same right-hand side.
"""

from __future__ import annotations

import csv
import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import SLIDING_MODES, SLIDING_PHASES
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name, power_on_slip_signs, shift_model
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.numeric import casadi_function, to_casadi
from gearsym.symbolic.parameters import symbol, zero_scale
from gearsym.symbolic.sensitivity import (
    SensitivityEquations,
    sensitivity_equations,
    stationary_initial_sensitivity,
)
from gearsym.symbolic.shifts import ShiftSpec, shift_spec
from gearsym.validation.sim.phases import Phase

#: The phases in which the thesis takes both swapping elements as sliding (3.1).

#: Progress callback: a message for stderr.
Progress = Callable[[str], None]


# ----------------------------------------------------------------------------- reference data


@dataclass(frozen=True)
class ReferenceData:
    """The recorded signals the shift model is driven with (``SimulationResult`` subset)."""

    t: np.ndarray
    signals: dict[str, np.ndarray]
    phases: tuple[Phase, ...]
    shift: str
    source: str

    def window(self, t_start: float, t_end: float) -> ReferenceData:
        """The record restricted to [t_start, t_end] (both ends kept as samples)."""
        inside = (self.t > t_start) & (self.t < t_end)
        t = np.concatenate([[t_start], self.t[inside], [t_end]])
        signals = {k: np.interp(t, self.t, v) for k, v in self.signals.items()}
        phases = tuple(
            Phase(p.name, max(p.t_start, t_start), min(p.t_end, t_end), p.criterion)
            for p in self.phases
            if p.t_end > t_start and p.t_start < t_end
        )
        return ReferenceData(t, signals, phases, self.shift, self.source)


def reference_data(
    d: GearboxDescription,
    scenario: Any = None,
    progress: Progress | None = None,
) -> ReferenceData:
    """Run the reference simulation (:func:`gearsym.validation.sim.simulate.simulate`) and keep its
    record.

    ``scenario`` is a :class:`gearsym.validation.sim.scenario.Scenario` (default: the built-in one).
    """
    from gearsym.validation.sim.simulate import simulate

    kwargs: dict[str, Any] = {}
    if progress is not None:
        kwargs["progress"] = lambda *args: progress(str(args[-1]))
    if "check_models" in inspect.signature(simulate).parameters:
        kwargs["check_models"] = False  # the model checks are not needed here
    return reference_from_result(simulate(d, scenario, **kwargs))


def reference_from_result(result: Any) -> ReferenceData:
    """The record of a :class:`gearsym.validation.sim.simulate.SimulationResult` (t, signals,
    phases)."""
    shift = getattr(getattr(result, "scenario", None), "shift", None)
    return ReferenceData(
        t=np.asarray(result.t, dtype=float),
        signals={k: np.asarray(v, dtype=float) for k, v in result.signals.items()},
        phases=tuple(result.phases),
        shift=shift.name if shift is not None else "2-3",
        source="gearsym.validation.sim.simulate",
    )


# ----------------------------------------------------------------------------- driven model


@dataclass(frozen=True)
class DrivenShift:
    """The shift model with sliding-friction and sticking-torque inputs per swapping element.

    ``gain[e]`` is k_sign 2 N_disc r_m (torque per unit μ and unit normal force, 3.14).
    """

    model: Model
    spec: ShiftSpec
    elements: tuple[str, ...]
    gain: dict[str, float]
    mu: dict[str, str]  # element -> μ parameter name
    normal_force: dict[str, str]  # element -> effective normal-force input name
    stick_torque: dict[str, str]  # element -> sticking-torque input name


def driven_shift_model(
    d: GearboxDescription, shift: str = "2-3", with_wheel_acceleration: bool = False
) -> DrivenShift:
    """ẋ = f(x, p) + B(p) u of the shift model (2.55–2.58, 3.5) with
    u = [T_In, F_N,off, F_N,on, T_off, T_on, Δζ]: element torque = k_sign 2 N r μ F_N + T_stick,
    and the road load (2.49) at the grade ζ + Δζ(t) (see the module docstring: ζ stays a
    parameter, a constant offset of the recorded profile)."""
    spec = shift_spec(d, shift)
    friction = shift_model(d, shift, with_wheel_acceleration, friction_inputs=True)
    torque = shift_model(d, shift, with_wheel_acceleration, friction_inputs=False)
    elements = (spec.off_going, spec.on_coming)
    by_name = {v.name: v for v in torque.inputs}
    rhs = friction.rhs
    stick: list[Variable] = []
    for e in elements:
        v = by_name[naming.torque(e)]
        column = torque.rhs.diff(v.symbol)
        if column.free_symbols & set(torque.input_symbols):
            raise AssertionError(f"shift model is not affine in T_{e}")
        rhs = rhs + column * v.symbol
        stick.append(
            Variable(v.name, v.symbol, "N*m", f"{e} torque while it sticks (sign of 2.36)")
        )
    signs = power_on_slip_signs(d, spec)
    gain = {}
    for e in elements:
        element = d.element(e)
        assert element.n_disc is not None and element.r_m is not None
        gain[e] = float(signs[e] * 2 * element.n_disc * element.r_m.value)
    short = {e: element_short_name(d, e) for e in elements}
    (zeta,) = (v.symbol for v in friction.parameters if v.name == naming.GRADE)
    deviation = Variable(
        naming.GRADE_DEVIATION,
        sp.Symbol(naming.GRADE_DEVIATION, real=True),
        "rad",
        "recorded grade minus the parameter's nominal value, zeta_rec(t) - zeta0 (2.49)",
    )
    rhs = rhs.xreplace({zeta: zeta + deviation.symbol})
    model = Model(
        name=f"{friction.name.removesuffix('_mu')}_driven",
        states=friction.states,
        inputs=(*friction.inputs, *stick, deviation),
        parameters=friction.parameters,
        outputs=friction.outputs,
        rhs=rhs,
        output_expressions=friction.output_expressions,
        metadata={**friction.metadata, "driven": "sliding friction (3.14) + sticking torque"},
    )
    return DrivenShift(
        model=model,
        spec=spec,
        elements=elements,
        gain=gain,
        mu={e: naming.friction_coefficient(short[e]) for e in elements},
        normal_force={e: naming.normal_force(short[e]) for e in elements},
        stick_torque={e: naming.torque(e) for e in elements},
    )


def thesis_parameters(driven: DrivenShift) -> tuple[str, ...]:
    """The thesis' parameter set (3.2) for this shift: m_veh, k_ss, d_ss, μ of the off-going
    element (μ38 for the 2-3 shift of the built-in gearbox), ζ."""
    return ("m_veh", "k_ss", "d_ss", driven.mu[driven.spec.off_going], "zeta")


def sliding_masks(
    d: GearboxDescription,
    driven: DrivenShift,
    data: ReferenceData,
    mode: str = "detected",
    capacity_fraction: float = 0.98,
) -> dict[str, np.ndarray]:
    """Per element, the samples at which it slides (see the module docstring)."""
    if mode not in SLIDING_MODES:
        raise GearsymError(d.file, "sliding", f"expected one of {SLIDING_MODES}, got {mode!r}")
    masks = {}
    for e in driven.elements:
        short = element_short_name(d, e)
        force = data.signals[naming.normal_force(short)]
        if mode == "phases":
            inside = np.zeros(len(data.t), dtype=bool)
            for p in data.phases:
                if p.name in SLIDING_PHASES:
                    inside |= (data.t >= p.t_start) & (data.t < p.t_end)
            masks[e] = inside & (force > 0)
            continue
        element = d.element(e)
        assert element.n_disc is not None and element.r_m is not None
        mu = data.signals[naming.friction_coefficient(short)]
        capacity = 2 * element.n_disc * element.r_m.value * mu * force
        torque = np.abs(data.signals[naming.torque(e)])
        masks[e] = (force > 0) & (torque >= capacity_fraction * capacity)
    return masks


def driving_inputs(
    driven: DrivenShift,
    data: ReferenceData,
    masks: Mapping[str, np.ndarray],
    values: Mapping[str, float],
) -> np.ndarray:
    """Input samples (N, n_u) of the driven model in its input order, from the record."""
    columns: dict[str, np.ndarray] = {"T_In": data.signals["T_In"]}
    for e in driven.elements:
        torque = data.signals[naming.torque(e)]
        slide = masks[e]
        mu0 = values[driven.mu[e]]
        columns[driven.normal_force[e]] = np.where(slide, torque / (driven.gain[e] * mu0), 0.0)
        columns[driven.stick_torque[e]] = np.where(slide, 0.0, torque)
    # Δζ = ζ_rec(t) − ζ0 with ζ0 the description's value, the one the reference used when it
    # had no profile (a record without the ζ column: a level road at ζ0, Δζ = 0)
    zeta0 = driven.model.variable(naming.GRADE).default
    assert zeta0 is not None
    recorded = data.signals.get(naming.GRADE)
    columns[naming.GRADE_DEVIATION] = (
        np.zeros(len(data.t)) if recorded is None else recorded - float(zeta0)
    )
    return np.column_stack([columns[v.name] for v in driven.model.inputs])


def initial_state(model: Model, data: ReferenceData) -> np.ndarray:
    """The recorded state at the first sample (states are named like the signals)."""
    missing = [v.name for v in model.states if v.name not in data.signals]
    if missing:
        raise GearsymError(data.source, "signals", f"no recorded signal for states {missing}")
    return np.array([data.signals[v.name][0] for v in model.states], dtype=float)


# ----------------------------------------------------------------------------- numerics


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


def finite_difference_sensitivities(
    model: Model,
    names: Sequence[str],
    inputs: Interpolated,
    x0: np.ndarray,
    values: Mapping[str, float],
    t_eval: np.ndarray,
    relative_step: float = 1e-4,
    max_step: float = 5e-4,
    compiled: CompiledModel | None = None,
) -> np.ndarray:
    """Central differences (x(p + h e_j) − x(p − h e_j)) / 2h, (N, n, m): the peer of (3.7).

    h_j = ``relative_step`` · p_j0 (p_j0 from :func:`nominal_scales`); 2 m integrations.
    """
    compiled = compiled or CompiledModel(model)
    scales = nominal_scales(names, values)
    result = []
    for name, scale in zip(names, scales, strict=True):
        h = relative_step * scale
        plus = integrate(compiled, inputs, x0, {**values, name: values[name] + h}, t_eval, max_step)
        minus = integrate(
            compiled, inputs, x0, {**values, name: values[name] - h}, t_eval, max_step
        )
        result.append((plus - minus) / (2 * h))
    return np.stack(result, axis=2)


# ----------------------------------------------------------------------------- CasADi peer


def casadi_sensitivities(
    model: Model,
    names: Sequence[str],
    t: np.ndarray,
    u: np.ndarray,
    x0: np.ndarray,
    values: Mapping[str, float],
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> tuple[np.ndarray, np.ndarray]:
    """x and ∂x/∂p at the samples ``t`` by CasADi: CVODES over every sample interval with the
    inputs linear in time (as :class:`Interpolated`), chained with ``mapaccum``, and the
    Jacobian with respect to the parameters by forward-mode AD through the integrators.

    Independent of :mod:`gearsym.symbolic.sensitivity`: it uses only ``model.rhs``. Returns
    (x (N, n), S (N, n, m)) with S(t0) = 0.
    """
    import casadi as ca

    nx, nu = len(model.states), len(model.inputs)
    x = ca.SX.sym("x", nx)
    p = ca.SX.sym("p", len(model.parameters))
    u0 = ca.SX.sym("u0", nu)
    u1 = ca.SX.sym("u1", nu)
    h = ca.SX.sym("h")
    tau = ca.SX.sym("tau")
    ut = u0 + tau * (u1 - u0)
    mapping: dict[sp.Symbol, Any] = {}
    mapping.update({s: x[i] for i, s in enumerate(model.state_symbols)})
    mapping.update({s: ut[i] for i, s in enumerate(model.input_symbols)})
    mapping.update({s: p[i] for i, s in enumerate(model.parameter_symbols)})
    rhs = ca.vertcat(*[to_casadi(e, mapping) for e in model.rhs])
    step = ca.integrator(
        "step",
        "cvodes",
        {"x": x, "p": ca.vertcat(p, u0, u1, h), "t": tau, "ode": h * rhs},
        0.0,
        1.0,
        {"abstol": atol, "reltol": rtol, "max_num_steps": 100000},
    )
    xk = ca.MX.sym("xk", nx)
    pk = ca.MX.sym("pk", step.size1_in(2))
    one = ca.Function("one", [xk, pk], [step(x0=xk, p=pk)["xf"]])
    intervals = len(t) - 1
    chain = one.mapaccum("chain", intervals)
    pm = ca.MX.sym("pm", len(model.parameters))
    per_interval = ca.vertcat(
        ca.repmat(pm, 1, intervals),
        ca.DM(u[:-1].T),
        ca.DM(u[1:].T),
        ca.DM(np.diff(t)).T,
    )
    states = chain(ca.DM(x0), per_interval)  # nx × intervals
    jac = ca.jacobian(ca.vec(states), pm)
    evaluate = ca.Function("evaluate", [pm], [states, jac])
    pvals = [float(values[v.name]) for v in model.parameters]
    xs, jv = evaluate(pvals)
    xs = np.asarray(xs).T  # intervals × nx
    jv = np.asarray(jv).reshape(intervals, nx, len(model.parameters), order="C")
    # vec() is column-major: row index = k * nx + i
    index = [[v.name for v in model.parameters].index(nm) for nm in names]
    S = np.zeros((len(t), nx, len(names)))
    S[1:] = jv[:, :, index]
    return np.vstack([x0, xs]), S


# ----------------------------------------------------------------------------- the run


@dataclass(frozen=True)
class SensitivityRun:
    """Sensitivities of the driven shift model along the reference shift (3.2–3.4)."""

    trajectory: SensitivityTrajectory
    phases: tuple[Phase, ...]
    values: dict[str, float]  # parameter values used
    scales: np.ndarray  # p_j0 (3.3) per chosen parameter
    nominal_states: np.ndarray  # x_i0 = max |x_i(t)| (3.4)
    reference_states: np.ndarray  # recorded x at the same samples
    sliding: dict[str, np.ndarray]  # element -> sliding mask at the samples
    mode: str
    source: str
    timings: dict[str, float]

    @property
    def normalised(self) -> np.ndarray:
        """S_N,ij = S_ij p_j0 / x_i0 (3.3), (N, n, m)."""
        tr = self.trajectory
        return tr.S * self.scales[None, None, :] / self.nominal_states[None, :, None]

    @property
    def normalised_rate(self) -> np.ndarray:
        """d S_N,ij / dt = Ṡ_ij p_j0 / x_i0, (N, n, m)."""
        tr = self.trajectory
        return tr.dS * self.scales[None, None, :] / self.nominal_states[None, :, None]

    def drift(self) -> dict[str, float]:
        """max |x_driven − x_recorded| / x_i0 per state: how well the open-loop driven shift
        model reproduces the reference."""
        error = np.max(np.abs(self.trajectory.x - self.reference_states), axis=0)
        return {
            name: float(e / s)
            for name, e, s in zip(
                self.trajectory.state_names, error, self.nominal_states, strict=True
            )
        }


def run_sensitivities(
    d: GearboxDescription,
    parameters: Sequence[str] | None = None,
    data: ReferenceData | None = None,
    overrides: Mapping[str, float] | None = None,
    with_wheel_acceleration: bool = False,
    mode: str = "detected",
    t_eval: np.ndarray | None = None,
    max_step: float = 5e-4,
    initial: str = "stationary",
    progress: Progress | None = None,
) -> SensitivityRun:
    """Derive and integrate the sensitivities of the driven shift model along the reference.

    ``t_eval`` defaults to the record's samples; the integration starts at the first record
    sample whatever ``t_eval`` is. ``initial`` chooses S(t0) (:func:`initial_sensitivities`).
    """
    import time

    say = progress or (lambda message: None)
    timings = {}
    if data is None:
        say("simulating the reference shift")
        start = time.perf_counter()
        data = reference_data(d, progress=progress)
        timings["reference_s"] = time.perf_counter() - start
    start = time.perf_counter()
    driven = driven_shift_model(d, data.shift, with_wheel_acceleration)
    if parameters is None:
        parameters = thesis_parameters(driven)
    eqs = sensitivity_equations(driven.model, parameters, file=d.file)
    compiled = CompiledModel(eqs.augmented)
    timings["derive_s"] = time.perf_counter() - start
    values = parameter_values(driven.model, overrides)
    masks = sliding_masks(d, driven, data, mode)
    u = driving_inputs(driven, data, masks, values)
    inputs = Interpolated(data.t, u)
    x0 = initial_state(driven.model, data)
    samples = data.t if t_eval is None else np.asarray(t_eval, dtype=float)
    if samples[0] != data.t[0]:
        samples = np.concatenate([[data.t[0]], samples])
    say(
        f"integrating x and {len(eqs.parameters)} sensitivity columns "
        f"({len(eqs.augmented.states)} states) over {data.t[-1] - data.t[0]:.3g} s"
    )
    start = time.perf_counter()
    s0 = initial_sensitivities(eqs, x0, u[0], values, initial)
    trajectory = integrate_sensitivities(eqs, inputs, x0, values, samples, max_step, compiled, s0)
    timings["integrate_s"] = time.perf_counter() - start
    reference = np.column_stack(
        [np.interp(samples, data.t, data.signals[name]) for name in trajectory.state_names]
    )
    nominal = np.max(np.abs(trajectory.x), axis=0)  # (3.4)
    nominal[nominal == 0] = 1.0
    index = np.clip(np.searchsorted(data.t, samples), 0, len(data.t) - 1)
    return SensitivityRun(
        trajectory=trajectory,
        phases=data.phases,
        values=values,
        scales=nominal_scales(trajectory.parameter_names, values),
        nominal_states=nominal,
        reference_states=reference,
        sliding={e: m[index] for e, m in masks.items()},
        mode=mode,
        source=data.source,
        timings=timings,
    )


# ----------------------------------------------------------------------------- output


def write_csv(run: SensitivityRun, path: Path) -> Path:
    """One row per sample: t, phase, x, and S, S_N, Ṡ for every state and parameter."""
    tr = run.trajectory
    norm = run.normalised
    header = ["t", "phase", *tr.state_names]
    for p in tr.parameter_names:
        for x in tr.state_names:
            header += [f"S_{x}__{p}", f"SN_{x}__{p}", f"dS_{x}__{p}"]
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for k, t in enumerate(tr.t):
            row: list[Any] = [f"{t:.6g}", phase_of(run.phases, t), *(f"{v:.9g}" for v in tr.x[k])]
            for j in range(len(tr.parameter_names)):
                for i in range(len(tr.state_names)):
                    row += [f"{tr.S[k, i, j]:.9g}", f"{norm[k, i, j]:.9g}", f"{tr.dS[k, i, j]:.9g}"]
            writer.writerow(row)
    return path


def phase_of(phases: Sequence[Phase], t: float) -> str:
    """Name of the phase containing t (the last phase includes its end)."""
    for k, p in enumerate(phases):
        if p.t_start <= t < p.t_end or (k == len(phases) - 1 and t <= p.t_end):
            return p.name
    return ""


# plain Unicode labels: mathtext parsing and rendering was a large share of the plotting time
STATE_LABELS = {
    "omega_1": "ω₁",
    "omega_2": "ω₂",
    "phi": "φ",
    "omega_C": "ω_C",
}


def plot_sensitivities(run: SensitivityRun, out_dir: Path) -> list[Path]:
    """One PNG per parameter like Figures 3.4–3.8: normalised sensitivities S_N (3.3) of every
    state (left) and their time derivatives (right), phases marked."""
    from gearsym.validation.drawing.figures import save, subplots

    out_dir.mkdir(parents=True, exist_ok=True)
    tr = run.trajectory
    norm, rate = run.normalised, run.normalised_rate
    paths = []
    margins = {"left": 0.09, "right": 0.98, "bottom": 0.07, "top": 0.88, "hspace": 0.15}
    for j, p in enumerate(tr.parameter_names):
        fig, axes = subplots(
            len(tr.state_names), 2, (10, 8), margins | {"wspace": 0.28}, sharex=True, squeeze=False
        )
        for i, x in enumerate(tr.state_names):
            label = STATE_LABELS.get(x, x)
            for col, (data, what) in enumerate(
                ((norm[:, i, j], "S_N"), (rate[:, i, j], "dS_N/dt in 1/s"))
            ):
                ax = axes[i, col]
                ax.plot(tr.t, data, lw=1.0)
                ax.set_ylabel(f"{what} {label}")
                for phase in run.phases[1:]:
                    ax.axvline(phase.t_start, color="0.5", lw=0.6, ls="--")
        for col in range(2):
            axes[-1, col].set_xlabel("t in s")
        for k, phase in enumerate(run.phases):
            for col in range(2):
                axes[0, col].annotate(
                    phase.name,
                    ((phase.t_start + phase.t_end) / 2, 1.03 + 0.12 * (k % 2)),
                    xycoords=("data", "axes fraction"),
                    ha="center",
                    fontsize=7,
                )
        fig.suptitle(
            f"Normalised sensitivities of the states and their derivatives with respect to "
            f"{symbol(p)} (p0 = {run.scales[j]:g})",
            fontsize=10,
        )
        paths.append(save(fig, out_dir / f"sensitivity_{p}.png", dpi=120))
    return paths
