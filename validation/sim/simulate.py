"""Reference simulation of a shift (thesis 3.1), its phases, energy audit and model checks.

The reference model (:mod:`gearsym.symbolic.reference`) is the full gearbox (2.39) with the elastic
drivetrain (2.42–2.53) and one elasto-plastic friction state per pressed element (2.66)–(2.70).
It is integrated with SciPy's Radau (stiff, implicit, order 5) and the analytic Jacobian from
SymPy, restarting at every breakpoint of the scenario's piecewise-linear inputs. μ comes from the
friction map at each element's pressure, the oil temperature and the current slip.

What is derived from the result, never from the scenario's times:

* the phases (:func:`gearsym.validation.sim.phases.detect_phases`): from-gear, torque phase
  (the on-coming element takes over the load), speed phase (the input speed moves to the new
  ratio), to-gear;
* the energy audit (:class:`EnergyAudit`): input work = Δ kinetic + Δ spring + Δ bristle energy
  + friction dissipation + damper dissipation + road work, with the works integrated as extra
  ODE states at the solver's accuracy;
* the model checks (:class:`ModelCheck`): each reduced model (the from- and to-gear with their
  elements locked, the shift model (2.55)–(2.58) with the two swapping elements' torques taken
  from the reference) integrated inside the phase where it is valid and compared.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import (
    drivetrain_model,
    quantity,
    shift_model,
)
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.friction import T_SS_MIN, MuMap, load_mu_map
from gearsym.symbolic.model import Model
from gearsym.symbolic.numeric import bilinear, casadi_function, integrate_linear_inputs, to_casadi
from gearsym.symbolic.reference import ReferenceModel, reference_model
from gearsym.validation.sim.phases import Phase, detect_phases
from gearsym.validation.sim.scenario import SAMPLE_TIME, Scenario, load_scenario
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicHermiteSpline, RectBivariateSpline

#: Progress callback: (fraction done in [0, 1], message).
Progress = Callable[[float, str], None]

ENERGY_TERMS = naming.ENERGY_TERMS

#: Most samples one simulation returns (and writes to timeseries.csv): 100 000 rows are about
#: 75 MB of CSV. The scenario's t_end limit keeps the default sampling at 20 000.
SAMPLES_MAX = 100_000


@dataclass(frozen=True)
class EnergyAudit:
    """W_in = ΔE_kin + ΔE_spring + ΔE_bristle + W_friction + W_damper + W_road (+ residual)."""

    input_work: float
    kinetic_change: float
    spring_change: float
    bristle_change: float
    friction_dissipation: float
    damper_dissipation: float
    road_work: float

    @property
    def residual(self) -> float:
        return self.input_work - (
            self.kinetic_change
            + self.spring_change
            + self.bristle_change
            + self.friction_dissipation
            + self.damper_dissipation
            + self.road_work
        )

    @property
    def scale(self) -> float:
        """The largest term, the reference for the relative residual."""
        return max(
            abs(v)
            for v in (
                self.input_work,
                self.kinetic_change,
                self.spring_change,
                self.friction_dissipation,
                self.damper_dissipation,
                self.road_work,
            )
        )

    @property
    def relative_residual(self) -> float:
        return abs(self.residual) / self.scale

    def to_dict(self) -> dict[str, float]:
        return {
            "input_work_J": self.input_work,
            "kinetic_energy_change_J": self.kinetic_change,
            "spring_energy_change_J": self.spring_change,
            "bristle_energy_change_J": self.bristle_change,
            "friction_dissipation_J": self.friction_dissipation,
            "damper_dissipation_J": self.damper_dissipation,
            "road_work_J": self.road_work,
            "residual_J": self.residual,
            "relative_residual": self.relative_residual,
        }


@dataclass(frozen=True)
class ModelCheck:
    """A reduced model integrated inside one phase against the reference."""

    model: str
    phase: str
    t_start: float
    t_end: float
    max_abs_error: dict[str, float]
    #: max |error| / (max |reference| of that state over the phase), worst state
    max_relative_error: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "phase": self.phase,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "max_abs_error": self.max_abs_error,
            "max_relative_error": self.max_relative_error,
        }


@dataclass(frozen=True)
class SimulationResult:
    """Time series (``signals``, sampled at ``t``), phases, audit and model checks."""

    t: np.ndarray
    signals: dict[str, np.ndarray]
    phases: tuple[Phase, ...]
    audit: EnergyAudit
    checks: tuple[ModelCheck, ...]
    scenario: Scenario
    state_names: tuple[str, ...]
    stats: dict[str, float] = field(default_factory=dict)
    state_at: Callable[[float], np.ndarray] | None = None
    method: str = "cvodes"

    def phase(self, name: str) -> Phase:
        for p in self.phases:
            if p.name == name:
                return p
        raise KeyError(name)


# ----------------------------------------------------------------------------- numerics


class _Function:
    """A CasADi function called with NumPy values: a vector as a 1-D array, a scalar as a
    float, a matrix as a 2-D array."""

    def __init__(self, function: Any, shape: str = "vector") -> None:
        self.function = function
        self.shape = shape

    def __call__(self, *args: Any) -> Any:
        out = self.function(*args)
        if self.shape == "scalar":
            return float(out)
        array = out.full()
        return array.ravel() if self.shape == "vector" else array

    def many(self, *columns: np.ndarray) -> np.ndarray:
        """Evaluate at N points at once (each argument N × size): N × outputs."""
        count = columns[0].shape[0]
        out = self.function.map(count)(*(np.ascontiguousarray(c.T) for c in columns))
        return np.asarray(out.full()).T


class _Compiled:
    """Right-hand side, Jacobian and diagnostics of the augmented reference model, as CasADi
    functions (one translation of the SymPy expressions; CasADi differentiates, so no SymPy
    Jacobian of the friction model's Max and Piecewise has to be simplified).

    The road grade ζ, a parameter of the reference model, is the last entry of u here: (2.53)
    and (5.3) treat it as an input, and a scenario may give ζ(t) (``[grade]``); without one
    :class:`_Inputs` feeds the description's constant."""

    def __init__(
        self,
        ref: ReferenceModel,
        d: GearboxDescription,
        elements: Sequence[str],
        one_way: Sequence[str] = (),
    ):
        import casadi as ca

        model = ref.model
        defaults = model.parameter_defaults()
        self.n = len(model.states)
        self.elements = tuple(elements)  # pressed friction elements: a pressure and a μ input
        self.one_way = tuple(one_way)  # one-way clutches: a wind-up state, no input
        self.x = ca.SX.sym("x", self.n)
        self.u = ca.SX.sym("u", len(model.inputs) + 1)  # + ζ
        mapping: dict[Any, Any] = {s: self.x[i] for i, s in enumerate(model.state_symbols)}
        mapping.update({s: self.u[i] for i, s in enumerate(model.input_symbols)})
        mapping.update({s: float(defaults[s]) for s in model.parameter_symbols})
        (zeta,) = (s for s in model.parameter_symbols if s.name == naming.GRADE)
        mapping[zeta] = self.u[len(model.inputs)]
        self.zeta_default = float(defaults[zeta])

        def sx(exprs: Any) -> Any:
            return ca.vertcat(*[to_casadi(e, mapping) for e in exprs])

        def xu(name: str, exprs: Any, shape: str = "vector") -> _Function:
            return _Function(ca.Function(name, [self.x, self.u], [sx(exprs)]), shape)

        def x_only(name: str, exprs: Any, shape: str = "vector") -> _Function:
            return _Function(ca.Function(name, [self.x], [sx(exprs)]), shape)

        powers = [ref.input_power, ref.friction_power, ref.damper_power, ref.road_power]
        self.rhs_sx = sx([*model.rhs, *powers])  # [ẋ; the four powers of the energy audit]
        self.f = _Function(ca.Function("f", [self.x, self.u], [self.rhs_sx]))
        self.jac = _Function(
            ca.Function("jac_x", [self.x, self.u], [ca.jacobian(self.rhs_sx, self.x)]), "matrix"
        )
        self.slips_sx = sx([ref.slip[e] for e in self.elements])
        self.slips = _Function(ca.Function("slips", [self.x], [self.slips_sx]))
        all_slip = _all_slips(d, ref)
        self.all_slips = x_only("all_slips", list(all_slip.values()))
        self.all_slip_names = tuple(all_slip)
        self.torque_names = self.elements + self.one_way
        self.torques = xu("torques", [ref.element_torque[e] for e in self.torque_names])
        self.speeds = x_only("speeds", [ref.body_speeds[s.name] for s in d.shafts])
        self.shaft_names = tuple(s.name for s in d.shafts)
        self.energies = x_only(
            "energies", [ref.kinetic_energy, ref.spring_energy, ref.bristle_energy]
        )
        self.side_shaft = x_only("side_shaft", [ref.side_shaft_torque], "scalar")
        self.road = xu("road", [ref.road_torque], "scalar")  # depends on ζ (2.49)


def _all_slips(d: GearboxDescription, ref: ReferenceModel) -> dict[Any, sp.Expr]:
    speeds = ref.body_speeds
    return {e: (speeds[e.a] if e.a is not None else 0) - speeds[e.b] for e in d.shift_elements}


class _Inputs:
    """u(t, x): T_In from the scenario, pressures, μ from the map at the current slip, and ζ
    (the scenario's ``[grade]`` profile, or the description's constant)."""

    def __init__(
        self,
        scenario: Scenario,
        elements: tuple[str, ...],
        mu_map: MuMap,
        t_oil: float,
        compiled: _Compiled,
        mu_scale: Mapping[str, float] | None = None,
    ) -> None:
        self.scenario = scenario
        self.elements = elements
        self.compiled = compiled
        # a fleet's truth: each element's μ map scaled (oil temperature, wear); 1 by default
        self.mu_scale = np.array([float((mu_scale or {}).get(e, 1.0)) for e in elements])
        # The oil temperature is constant in a scenario: slice the map once and interpolate
        # bilinearly in (p_N, |Δω|) with a spline of degree 1 (the map's own trilinear
        # interpolation restricted to that plane), clamped to the grid like MuMap.
        p_grid, _, dw_grid = mu_map.grid
        plane = mu_map(p_grid[:, None], t_oil, dw_grid[None, :])
        self._mu = RectBivariateSpline(p_grid, dw_grid, plane, kx=1, ky=1)
        self.map_grid = (p_grid, dw_grid)
        self.map_plane = plane
        self._p_range = (p_grid[0], p_grid[-1])
        self._dw_range = (dw_grid[0], dw_grid[-1])

    def pressures(self, t: float) -> np.ndarray:
        return np.array([self.scenario.pressure[e](t) for e in self.elements])

    def grade(self, t: float) -> float:
        """ζ(t) (2.49): the scenario's profile, or the description's constant ζ."""
        profile = self.scenario.grade
        return self.compiled.zeta_default if profile is None else profile(t)

    def mu(self, p: np.ndarray, slips: np.ndarray) -> np.ndarray:
        mu = self._mu.ev(np.clip(p, *self._p_range), np.clip(np.abs(slips), *self._dw_range))
        return mu * self.mu_scale if np.any(self.mu_scale != 1.0) else mu

    def __call__(self, t: float, x: np.ndarray) -> list[float]:
        p = self.pressures(t)
        mu = self.mu(p, np.asarray(self.compiled.slips(x), dtype=float))
        return [self.scenario.input_torque(t), *p, *mu, self.grade(t)]

    def many(self, times: np.ndarray, states: np.ndarray) -> np.ndarray:
        """u at N times and states (N × n): N × inputs."""
        torque = np.array([self.scenario.input_torque(float(t)) for t in times])
        p = np.array([self.pressures(float(t)) for t in times]).reshape(len(times), -1)
        mu = self.mu(p, self.compiled.slips.many(states))
        zeta = np.array([self.grade(float(t)) for t in times])
        return np.column_stack([torque, p, mu, zeta])


# ----------------------------------------------------------------------------- initial state


def quasi_static_state(
    d: GearboxDescription, ref: ReferenceModel, inputs: _Inputs, compiled: _Compiled
) -> np.ndarray:
    """Initial state in the from-gear: speeds at the scenario's vehicle speed, and the bristle
    deflections and side-shaft twist that make the gearbox accelerate as one rigid gear
    (closed elements' slip accelerations zero, φ̈ = 0). The conditions are affine in (z, φ)
    while every slip is zero, so five evaluations of the right-hand side solve them."""
    scenario = inputs.scenario
    gear = d.gear(scenario.shift.from_gear)
    model = ref.model
    names = [v.name for v in model.states]
    r_dyn = quantity(d, "vehicle", "r_dyn").value
    i_d = quantity(d, "drivetrain", "i_D").value
    omega_c = scenario.vehicle_speed / r_dyn
    omega_out = i_d * omega_c
    speeds = _gear_speeds(d, gear.name, omega_out)
    x0 = np.zeros(compiled.n)
    for i, v in enumerate(model.states):
        if v.name.startswith("omega_") and v.name != "omega_C":
            x0[i] = speeds[v.name.removeprefix("omega_")]
    x0[names.index("omega_C")] = omega_c
    closed = [e for e in gear.closed if e in compiled.elements]
    unknowns = [names.index(f"z_{e}") for e in closed] + [names.index("phi")]
    _sliding_bristles(d, x0, names, inputs, closed)
    # d/dt of each closed element's slip and of φ̇ (all linear in the speeds) must vanish
    phi_dot = model.rhs[names.index("phi")]
    rows = np.array(
        [_linear_row(ref.slip[e], model.state_symbols) for e in closed]
        + [_linear_row(phi_dot, model.state_symbols)]
    )

    def residual(values: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[unknowns] = values
        return rows @ np.asarray(compiled.f(x, inputs(0.0, x)), dtype=float)[: compiled.n]

    scale = np.array([1e-3] * len(closed) + [1e-2])
    base = residual(np.zeros(len(unknowns)))
    columns = [
        (residual(scale * np.eye(len(unknowns))[k]) - base) / scale[k] for k in range(len(unknowns))
    ]
    solution = np.linalg.solve(np.column_stack(columns), -base)
    x0[unknowns] = solution
    return x0


def _sliding_bristles(
    d: GearboxDescription,
    x0: np.ndarray,
    names: Sequence[str],
    inputs: _Inputs,
    closed: Sequence[str],
) -> None:
    """Put the bristles of every slipping element at their steady state z_ss sgn(Δω) (2.68):
    a slipping element starts in steady sliding, not with a relaxed bristle (which would
    add σ1 Δω, a huge damping torque, at t = 0)."""
    compiled = inputs.compiled
    sigma0 = quantity(d, "friction", "sigma0").value
    u = inputs(0.0, x0)
    ne = len(compiled.elements)
    slips = compiled.slips(x0)
    for k, e in enumerate(compiled.elements):
        if e in closed:
            continue
        element = d.element(e)
        assert element.n_disc is not None and element.r_m is not None
        assert element.a_piston is not None
        capacity = 2 * element.n_disc * element.r_m.value * u[1 + ne + k]
        capacity = max(capacity * u[1 + k] * element.a_piston.value, T_SS_MIN)
        x0[names.index(f"z_{e}")] = math.copysign(capacity / sigma0, slips[k])


def _gear_speeds(d: GearboxDescription, gear: str, omega_out: float) -> dict[str, float]:
    """Every shaft's speed in a gear at the given output speed (kinematics only; idle shafts
    at the steady speeds of the drag assumption, :func:`gearsym.symbolic.ratios.gear_motion`)."""
    from gearsym.symbolic.drivetrain import drivetrain_parts

    parts = drivetrain_parts(d, locked=tuple(d.gear(gear).closed), keep=(d.output_shaft,))
    if len(parts.speeds) > 1:  # idle shafts kept as states
        from gearsym.symbolic.ratios import gear_motion

        motion = gear_motion(d, d.gear(gear))
        scale = omega_out / float(motion[d.shaft_names.index(d.output_shaft)])
        return {s: float(w) * scale for s, w in zip(d.shaft_names, motion, strict=True)}
    out = parts.speeds[0]
    return {s.name: float(parts.body_speeds[s.name].subs(out, omega_out)) for s in d.shafts}


def _linear_row(expr: sp.Expr, x: Sequence[sp.Symbol]) -> np.ndarray:
    """Coefficients of an expression linear in the states x."""
    return np.array([float(sp.diff(expr, s)) for s in x], dtype=float)


# ----------------------------------------------------------------------------- simulation


METHODS = ("cvodes", "Radau", "BDF")


def simulate(
    d: GearboxDescription,
    scenario: Scenario | None = None,
    progress: Progress | None = None,
    rtol: float = 1e-8,
    sample_time: float = SAMPLE_TIME,
    check_models: bool = True,
    method: str = "cvodes",
    analytic_jacobian: bool = True,
    phases: bool = True,
    mu_scale: Mapping[str, float] | None = None,
) -> SimulationResult:
    """Integrate the reference model through the scenario (thesis 3.1).

    ``mu_scale``: a factor on the μ map per element name (a fleet's truth: oil temperature,
    wear); elements not named keep the map.

    ``method``: "cvodes" (default; SUNDIALS CVODES through CasADi, BDF with CasADi's exact
    Jacobian, in C) or a stiff SciPy integrator, "Radau" or "BDF" (the cross-checks; the tests
    compare them). Every method restarts at each breakpoint of the scenario's inputs.
    ``sample_time`` is the spacing of the returned time series; between samples the state is a
    cubic Hermite interpolant (values and derivatives at the samples). ``analytic_jacobian``
    False lets SciPy difference the right-hand side instead (SciPy methods only).
    ``phases`` False skips the phase detection and the model checks (a scenario that holds its
    from-gear, e.g. a one-way clutch in drive or coast).

    Every one-way clutch of the description is in the model (it needs no pressure): the
    unilateral spring-damper of :func:`gearsym.symbolic.friction.one_way_sym`, starting
    unwound (z = 0); its wind-up energy is part of the bristle energy of the audit.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    start = time.perf_counter()
    scenario = scenario if scenario is not None else load_scenario(d)
    if not scenario.t_end / sample_time <= SAMPLES_MAX:
        raise GearsymError(
            scenario.file,
            "scenario.t_end",
            f"{scenario.t_end:g} s at {sample_time:g} s per sample is more than {SAMPLES_MAX} "
            "samples, the limit of a simulation",
        )
    report = progress or (lambda fraction, message: None)
    elements = tuple(
        e.name
        for e in d.shift_elements
        if not e.one_way and float(np.max(scenario.pressure[e.name].value)) > 0
    )
    one_way = tuple(e.name for e in d.shift_elements if e.one_way)
    report(0.0, "deriving the reference model")
    ref = reference_model(d, elements + one_way)
    compiled = _Compiled(ref, d, elements, one_way)
    t_oil = quantity(d, "friction", "T_oil").value
    unknown = sorted(set(mu_scale or {}) - {e.name for e in d.shift_elements})
    if unknown:
        raise GearsymError(d.file, "mu_scale", f"{unknown[0]!r} is not a shift element")
    inputs = _Inputs(scenario, elements, load_mu_map(d), t_oil, compiled, mu_scale)
    x0 = quasi_static_state(d, ref, inputs, compiled)
    n = compiled.n
    names = tuple(v.name for v in ref.model.states)
    atol = _absolute_tolerances(names, rtol, x0)
    y0 = np.concatenate([x0, np.zeros(len(ENERGY_TERMS))])
    breakpoints = scenario.breakpoints()
    grid = np.unique(np.concatenate([np.arange(0.0, scenario.t_end, sample_time), breakpoints]))
    report(0.0, f"integrating {len(breakpoints) - 1} segments with {method} (rtol {rtol:g})")
    if method == "cvodes":
        states, stats = _integrate_cvodes(
            compiled, inputs, y0, grid, breakpoints, rtol, atol, report
        )
    else:
        states, stats = _integrate_scipy(
            compiled, inputs, y0, grid, breakpoints, rtol, atol, method, analytic_jacobian, report
        )
    rates = compiled.f.many(states[:, :n], inputs.many(grid, states[:, :n]))
    dense = CubicHermiteSpline(grid, states, rates, axis=0)

    def state_at(t: float) -> np.ndarray:
        return np.asarray(dense(min(max(t, grid[0]), grid[-1])), dtype=float)

    signals = _signals(d, grid, states, names, inputs, compiled, scenario)
    audit = _audit(states, x0, compiled)
    found = detect_phases(d, scenario, grid, signals) if phases else ()
    checks: tuple[ModelCheck, ...] = ()
    if check_models and phases:
        report(1.0, "checking the reduced models phase by phase")
        checks = check_reduced_models(d, scenario, found, names, grid, states, signals, compiled)
    stats["wall_time_s"] = time.perf_counter() - start
    return SimulationResult(
        t=grid,
        signals=signals,
        phases=found,
        audit=audit,
        checks=checks,
        scenario=scenario,
        state_names=names,
        stats=stats,
        state_at=state_at,
        method=method,
    )


def _integrate_scipy(
    compiled: _Compiled,
    inputs: _Inputs,
    y0: np.ndarray,
    grid: np.ndarray,
    breakpoints: Sequence[float],
    rtol: float,
    atol: np.ndarray,
    method: str,
    analytic_jacobian: bool,
    report: Progress,
) -> tuple[np.ndarray, dict[str, float]]:
    """SciPy's Radau or BDF, segment by segment; the states at ``grid`` from its dense output."""
    n = compiled.n
    t_end = breakpoints[-1]

    def fun(t: float, y: np.ndarray) -> np.ndarray:
        return compiled.f(y[:n], inputs(t, y[:n]))

    def jac(t: float, y: np.ndarray) -> np.ndarray:
        out = np.zeros((len(y), len(y)))
        out[:, :n] = compiled.jac(y[:n], inputs(t, y[:n]))
        return out

    y = y0
    states = np.zeros((len(grid), len(y0)))
    states[0] = y0
    stats = {"nfev": 0.0, "njev": 0.0, "nlu": 0.0, "steps": 0.0}
    for t0, t1 in zip(breakpoints[:-1], breakpoints[1:], strict=True):
        sol = solve_ivp(
            fun,
            (t0, t1),
            y,
            method=method,
            jac=jac if analytic_jacobian else None,
            rtol=rtol,
            atol=atol,
            dense_output=True,
        )
        if not sol.success:
            raise GearsymError(
                inputs.scenario.file,
                "scenario",
                f"integration failed at t = {sol.t[-1]:.6g} s: {sol.message}",
            )
        inside = (grid > t0) & (grid <= t1)
        states[inside] = np.asarray(sol.sol(grid[inside])).T
        stats["nfev"] += sol.nfev
        stats["njev"] += sol.njev
        stats["nlu"] += sol.nlu
        stats["steps"] += len(sol.t) - 1
        y = sol.y[:, -1]
        report(t1 / t_end, f"t = {t1:.3f} s of {t_end:g} s")
    return states, stats


def _integrate_cvodes(
    compiled: _Compiled,
    inputs: _Inputs,
    y0: np.ndarray,
    grid: np.ndarray,
    breakpoints: Sequence[float],
    rtol: float,
    atol: np.ndarray,
    report: Progress,
) -> tuple[np.ndarray, dict[str, float]]:
    """CVODES (BDF, CasADi's exact Jacobian) segment by segment. Inside a segment every
    scenario input is linear in time, so T_In, the pressures and ζ enter as a + b (t − t0) with
    (a, b) per segment, and μ as the μ map's bilinear interpolation at the pressure and the
    current |slip| (as :class:`_Inputs`). The states are scaled by atol/rtol so that one scalar
    tolerance means the per-state ``atol``."""
    import casadi as ca

    n, ne = compiled.n, len(compiled.elements)
    size = len(y0)
    scale = atol / rtol
    xi = ca.SX.sym("xi", size)
    t = ca.SX.sym("t")
    nd = 2 + ne  # T_In, the pressures, ζ
    coefficients = ca.SX.sym("c", 2 * nd + 1)  # a (nd), b (nd), t0
    a, b, t0 = coefficients[:nd], coefficients[nd : 2 * nd], coefficients[-1]
    driven = a + b * (t - t0)  # T_In, the pressures and ζ
    x = xi[:n] * scale[:n]
    slip = ca.substitute(compiled.slips_sx, compiled.x, x)
    p_grid, dw_grid = inputs.map_grid
    mu = [
        bilinear(driven[1 + k], ca.fabs(slip[k]), p_grid, dw_grid, inputs.map_plane)
        * float(inputs.mu_scale[k])
        for k in range(ne)
    ]
    u = ca.vertcat(driven[: 1 + ne], *mu, driven[1 + ne])
    rhs = ca.substitute(compiled.rhs_sx, ca.vertcat(compiled.x, compiled.u), ca.vertcat(x, u))
    dae = {"x": xi, "t": t, "p": coefficients, "ode": rhs / scale}
    options = {"abstol": rtol, "reltol": rtol, "max_num_steps": 200000}
    states = np.zeros((len(grid), size))
    states[0] = y0
    y = y0 / scale
    stats = {"nfev": 0.0, "steps": 0.0}
    t_end = breakpoints[-1]
    scenario = inputs.scenario
    for ta, tb in zip(breakpoints[:-1], breakpoints[1:], strict=True):
        inside = np.flatnonzero((grid > ta) & (grid <= tb))
        tout = [float(v) for v in grid[inside]]
        if not tout or tout[-1] < tb:
            tout.append(float(tb))
        ua = np.array([scenario.input_torque(ta), *inputs.pressures(ta), inputs.grade(ta)])
        ub = np.array([scenario.input_torque(tb), *inputs.pressures(tb), inputs.grade(tb)])
        c = np.concatenate([ua, (ub - ua) / (tb - ta), [ta]])
        step = ca.integrator("segment", "cvodes", dae, float(ta), tout, options)
        try:
            out = np.asarray(step(x0=y, p=c)["xf"].full())
        except RuntimeError as err:
            raise GearsymError(
                scenario.file, "scenario", f"integration failed in [{ta:.6g}, {tb:.6g}] s: {err}"
            ) from None
        states[inside] = (out[:, : len(inside)] * scale[:, None]).T
        y = out[:, -1]
        solver_stats = step.stats()
        stats["nfev"] += float(solver_stats.get("nfevals", 0))
        stats["steps"] += float(solver_stats.get("nsteps", 0))
        report(tb / t_end, f"t = {tb:.3f} s of {t_end:g} s")
    return states, stats


def _absolute_tolerances(names: Sequence[str], rtol: float, x0: np.ndarray) -> np.ndarray:
    # Per-state scales: speeds ~ 100 rad/s, twist ~ 1e-2 rad, bristles ~ 1e-4 rad, works ~ 1e3 J.
    scale = []
    for name in names:
        if name.startswith("z_"):
            scale.append(1e-6)
        elif name == "phi":
            scale.append(1e-3)
        else:
            scale.append(1.0)
    scale += [1.0] * len(ENERGY_TERMS)
    return rtol * np.array(scale)


def _signals(
    d: GearboxDescription,
    grid: np.ndarray,
    states: np.ndarray,
    names: Sequence[str],
    inputs: _Inputs,
    compiled: _Compiled,
    scenario: Scenario,
) -> dict[str, np.ndarray]:
    """Every recorded signal at every sample (vectorised over the samples)."""
    n = compiled.n
    x = states[:, :n]
    u = inputs.many(grid, x)
    xdot = compiled.f.many(x, u)
    index = {name: i for i, name in enumerate(names)}
    out: dict[str, np.ndarray] = {}

    def put(key: str, value: np.ndarray) -> None:
        # two signals under one name would lose one column; check_names prevents it
        if key in out:
            raise AssertionError(f"two signals share the column name {key!r}")
        out[key] = np.asarray(value, dtype=float)

    element_names = [e.name for e in d.shift_elements]
    short = {e: naming.element_short_name(e, element_names) for e in compiled.elements}
    speeds = compiled.speeds.many(x)
    for k, s in enumerate(compiled.shaft_names):
        put(naming.speed(s), speeds[:, k])
    put(naming.TWIST, x[:, index[naming.TWIST]])
    put(naming.WHEEL_SPEED, x[:, index[naming.WHEEL_SPEED]])
    for name in names:
        if name.startswith(naming.speed("")):
            put(naming.derivative(name), xdot[:, index[name]])
    # φ̇ = ω_out/i_D − ω_C (2.44), the side-shaft twist rate Fig. 3.2 shows
    put(naming.derivative(naming.TWIST), xdot[:, index[naming.TWIST]])
    put(naming.INPUT_TORQUE, u[:, 0])
    put(naming.ENGINE_TORQUE, np.array([scenario.engine(float(t)) for t in grid]))
    put(naming.E_MACHINE_TORQUE, np.array([scenario.e_machine(float(t)) for t in grid]))
    torques = compiled.torques.many(x, u)
    ne = len(compiled.elements)
    for k, e in enumerate(compiled.elements):
        area = d.element(e).a_piston
        assert area is not None
        put(naming.pressure(e), u[:, 1 + k])
        put(naming.normal_force(short[e]), u[:, 1 + k] * area.value)
        put(naming.friction_coefficient(short[e]), u[:, 1 + ne + k])
        put(naming.bristle(e), x[:, index[naming.bristle(e)]])
    for e in compiled.one_way:
        put(naming.bristle(e), x[:, index[naming.bristle(e)]])
    slips = compiled.all_slips.many(x)
    for k, e in enumerate(compiled.all_slip_names):
        put(naming.slip_column(e.name), slips[:, k])
        carried = compiled.torque_names
        position = carried.index(e.name) if e.name in carried else None
        zero = np.zeros(len(grid))
        put(naming.torque(e.name), torques[:, position] if position is not None else zero)
    t_ss = compiled.side_shaft.many(x)[:, 0]
    put(naming.SIDE_SHAFT_TORQUE, t_ss)
    put(naming.DRIVETRAIN_OUTPUT_TORQUE, 2 * t_ss / quantity(d, "drivetrain", "i_D").value)
    put(naming.ROAD_TORQUE, compiled.road.many(x, u)[:, 0])
    put(naming.GRADE, u[:, -1])
    w_in, w_out = out[naming.speed(d.input_shaft)], out[naming.speed(d.output_shaft)]
    with np.errstate(divide="ignore", invalid="ignore"):
        put(naming.RATIO, np.where(w_out != 0, w_in / np.where(w_out != 0, w_out, 1.0), math.nan))
    r_dyn = quantity(d, "vehicle", "r_dyn").value
    put(naming.VEHICLE_SPEED, x[:, index[naming.WHEEL_SPEED]] * r_dyn)
    for k, term in enumerate(ENERGY_TERMS):
        put(term, states[:, n + k])
    return out


def _audit(states: np.ndarray, x0: np.ndarray, compiled: _Compiled) -> EnergyAudit:
    n = compiled.n
    end = states[-1]
    e0 = np.asarray(compiled.energies(x0), dtype=float)
    e1 = np.asarray(compiled.energies(end[:n]), dtype=float)
    w_in, w_fric, w_damp, w_road = end[n:]
    bristle = e1[2] - e0[2]
    return EnergyAudit(
        input_work=float(w_in),
        kinetic_change=float(e1[0] - e0[0]),
        spring_change=float(e1[1] - e0[1]),
        bristle_change=float(bristle),
        # Σ T_e Δω_e is what the shafts give to the elements; the bristles store part of it.
        friction_dissipation=float(w_fric - bristle),
        damper_dissipation=float(w_damp),
        road_work=float(w_road),
    )


# ----------------------------------------------------------------------------- model checks


def check_reduced_models(
    d: GearboxDescription,
    scenario: Scenario,
    phases: Sequence[Phase],
    names: Sequence[str],
    grid: np.ndarray,
    states: np.ndarray,
    signals: Mapping[str, np.ndarray],
    compiled: _Compiled,
) -> tuple[ModelCheck, ...]:
    """Integrate each reduced model inside its phase from the reference state (CVODES, rtol
    1e-10), with the reference's input torque (and, for the shift model, the swapping elements'
    transmitted torques), linear between the reference's samples, and compare the states they
    share at the reference's own samples (no interpolation of the reference states)."""
    spec = scenario.shift
    index = {name: i for i, name in enumerate(names)}
    element_index = {e: k for k, e in enumerate(compiled.elements)}
    n = compiled.n
    speeds = compiled.speeds.many(states[:, :n])

    def reader(name: str) -> np.ndarray:
        if name in ("phi", "omega_C"):
            return states[:, index[name]]
        return speeds[:, compiled.shaft_names.index(name.removeprefix("omega_"))]

    jobs: list[tuple[Model, Phase, list[str]]] = []
    gear_from, torque_phase, speed_phase, gear_to = phases
    # The rigid to-gear model is valid once the on-coming element has stuck, not merely
    # synchronised to 1 %: start its check at the first sample where the slip is below
    # 1e-4 of the initial one (about 0.02 rad/s here).
    slip_on = np.abs(compiled.slips.many(states[:, :n])[:, element_index[spec.on_coming]])
    stuck_at = np.flatnonzero((grid >= gear_to.t_start) & (slip_on < 1e-4 * slip_on[0]))
    stuck = float(grid[stuck_at[0]]) if stuck_at.size else gear_to.t_start
    locked_to = Phase(gear_to.name, stuck, gear_to.t_end, f"{spec.on_coming} stuck")
    for gear, phase in ((spec.from_gear, gear_from), (spec.to_gear, locked_to)):
        model = drivetrain_model(
            d,
            f"gear_{gear}",
            locked=tuple(d.gear(gear).closed),
            torque_elements=(),
            keep=(d.output_shaft,),
        )
        jobs.append((model, phase, ["T_In"]))
    shift = shift_model(d, spec.name)
    merged = Phase("shift", torque_phase.t_start, speed_phase.t_end, "torque + speed phase")
    jobs.append(
        (
            shift,
            merged,
            ["T_In", f"T_{spec.off_going}", f"T_{spec.on_coming}"],
        )
    )
    checks = []
    for model, phase, input_signals in jobs:
        if phase.t_end - phase.t_start <= 0:
            continue
        params = model.parameter_defaults()
        # ζ(t) as recorded (the scenario's grade profile, or the constant): a further input
        (zeta,) = (s for s in params if s.name == naming.GRADE)
        del params[zeta]
        rhs = model.rhs.xreplace({k: sp.Float(v) for k, v in params.items()})
        f = casadi_function(
            "reduced",
            [("x", model.state_symbols), ("u", (*model.input_symbols, zeta))],
            [("xdot", rhs)],
        )
        # every sample of the phase: the recorded inputs are linear between samples (T_In
        # exactly, its breakpoints are samples; the element torques to the sampling's accuracy)
        inside = np.flatnonzero((grid >= phase.t_start) & (grid <= phase.t_end))
        times = grid[inside]
        u = np.column_stack([signals[name][inside] for name in (*input_signals, naming.GRADE)])
        reference = np.column_stack([reader(v.name)[inside] for v in model.states])
        reduced = integrate_linear_inputs(f, reference[0], times, u)
        errors = np.max(np.abs(reduced - reference), axis=0)
        scales = np.maximum(np.max(np.abs(reference), axis=0), 1e-12)
        checks.append(
            ModelCheck(
                model=model.name,
                phase=phase.name,
                t_start=phase.t_start,
                t_end=phase.t_end,
                max_abs_error={v.name: float(e) for v, e in zip(model.states, errors, strict=True)},
                max_relative_error=float(np.max(errors / scales)),
            )
        )
    return tuple(checks)
