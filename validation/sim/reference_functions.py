"""The reference model (:mod:`gearsym.symbolic.reference`, (2.39), (2.42)–(2.53), (2.66)–(2.70))
as compiled CasADi functions, and its inputs u(t, x) along a scenario: T_In, the pressures, μ
from the map at the current slip, and the road grade ζ."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.friction import MuMap
from gearsym.symbolic.numeric import to_casadi
from gearsym.symbolic.reference import ReferenceModel
from gearsym.validation.sim.scenario import Scenario
from scipy.interpolate import RectBivariateSpline


class ArrayFunction:
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


class CompiledReference:
    """Right-hand side, Jacobian and diagnostics of the augmented reference model, as CasADi
    functions (one translation of the SymPy expressions; CasADi differentiates, so no SymPy
    Jacobian of the friction model's Max and Piecewise has to be simplified).

    The road grade ζ, a parameter of the reference model, is the last entry of u here: (2.53)
    and (5.3) treat it as an input, and a scenario may give ζ(t) (``[grade]``); without one
    :class:`ReferenceInputs` feeds the description's constant."""

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

        def xu(name: str, exprs: Any, shape: str = "vector") -> ArrayFunction:
            return ArrayFunction(ca.Function(name, [self.x, self.u], [sx(exprs)]), shape)

        def x_only(name: str, exprs: Any, shape: str = "vector") -> ArrayFunction:
            return ArrayFunction(ca.Function(name, [self.x], [sx(exprs)]), shape)

        powers = [ref.input_power, ref.friction_power, ref.damper_power, ref.road_power]
        self.rhs_sx = sx([*model.rhs, *powers])  # [ẋ; the four powers of the energy audit]
        self.f = ArrayFunction(ca.Function("f", [self.x, self.u], [self.rhs_sx]))
        self.jac = ArrayFunction(
            ca.Function("jac_x", [self.x, self.u], [ca.jacobian(self.rhs_sx, self.x)]), "matrix"
        )
        self.slips_sx = sx([ref.slip[e] for e in self.elements])
        self.slips = ArrayFunction(ca.Function("slips", [self.x], [self.slips_sx]))
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


class ReferenceInputs:
    """u(t, x): T_In from the scenario, pressures, μ from the map at the current slip, and ζ
    (the scenario's ``[grade]`` profile, or the description's constant)."""

    def __init__(
        self,
        scenario: Scenario,
        elements: tuple[str, ...],
        mu_map: MuMap,
        t_oil: float,
        compiled: CompiledReference,
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
        """The scenario's pressure of each pressed element at t."""
        return np.array([self.scenario.pressure[e](t) for e in self.elements])

    def grade(self, t: float) -> float:
        """ζ(t) (2.49): the scenario's profile, or the description's constant ζ."""
        profile = self.scenario.grade
        return self.compiled.zeta_default if profile is None else profile(t)

    def mu(self, p: np.ndarray, slips: np.ndarray) -> np.ndarray:
        mu = self._mu.ev(np.clip(p, *self._p_range), np.clip(np.abs(slips), *self._dw_range))
        return mu * self.mu_scale if np.any(self.mu_scale != 1.0) else mu

    def __call__(self, t: float, x: np.ndarray) -> list[float]:
        """u = [T_In, the pressures, μ of each pressed element, ζ] at (t, x)."""
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
