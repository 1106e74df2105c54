"""One mode of the hybrid shift model (:mod:`gearsym.symbolic.hybrid`) compiled to CasADi:
right-hand side, guards, slips, element torques and μ as functions of (x, u, p), and the
augmented right-hand side of the sensitivities (3.7) and the guards' gradients that
:class:`gearsym.validation.sim.hybrid_simulation.HybridSimulator` integrates and switches with.

μ of a sliding element with ``mu="map"``: μ_e,eff = μ_e · map(p_e, T_oil, |Δω_e|) / μ_nominal
(the :mod:`gearsym.validation.sim.hybrid_simulation` module docstring); ``mu="constant"`` uses
the parameter alone."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.hybrid import LOCKED, SLIDING, STATE_GUARDS, HybridShift, Mode
from gearsym.symbolic.numeric import bilinear, to_casadi


class CompiledMode:
    """A mode's right-hand side, guards, shaft speeds, slips and element torques as CasADi
    functions of (x, u, p), u = [T_In, F_N per swapping element (0 for a one-way clutch or a
    dog), Δζ], p the hybrid's parameters (μ through the map with ``mu="map"``, module docstring)."""

    def __init__(
        self,
        hybrid: HybridShift,
        mode: Mode,
        d: GearboxDescription,
        mu: str,
        mu_plane: tuple[np.ndarray, np.ndarray, np.ndarray],
    ) -> None:
        import casadi as ca

        self.mode = mode
        model = mode.model
        self.n = len(model.states)
        self.x = ca.SX.sym("x", self.n)
        self.u = ca.SX.sym("u", 1 + len(hybrid.elements) + 1)
        self.p = ca.SX.sym("p", len(hybrid.parameters))
        mapping: dict[sp.Symbol, Any] = {s: self.x[i] for i, s in enumerate(model.state_symbols)}
        mapping[hybrid.inputs[0].symbol] = self.u[0]
        for k, e in enumerate(hybrid.elements):
            if e in hybrid.normal_force:
                mapping[hybrid.normal_force[e]] = self.u[1 + k]
        names = [v.name for v in hybrid.parameters]
        for k, v in enumerate(hybrid.parameters):
            mapping[v.symbol] = self.p[k]
        mapping[hybrid.parameters[names.index(naming.GRADE)].symbol] = (
            self.p[names.index(naming.GRADE)] + self.u[-1]
        )
        if mu == "map":
            p_grid, dw_grid, plane = mu_plane
            mu_nominal = quantity(d, "friction", "mu_nominal").value
            for k, e in enumerate(hybrid.elements):
                if e not in hybrid.friction_coefficient:  # a one-way clutch or a dog
                    continue
                slip = to_casadi(mode.slip[e], mapping)
                area = d.element(e).a_piston
                if area is None:
                    raise GearsymError(
                        d.file,
                        f'shift_element[name="{e}"].a_piston',
                        "missing (needed for the pressure in the mu map)",
                    )
                pressure = self.u[1 + k] / area.value
                shape = bilinear(pressure, ca.fabs(slip), p_grid, dw_grid, plane) / mu_nominal
                symbol = hybrid.friction_coefficient[e]
                mapping[symbol] = self.p[names.index(str(symbol))] * shape
        self.mapping = mapping

        def function(name: str, exprs: Sequence[sp.Expr]) -> Any:
            out = ca.vertcat(*[to_casadi(e, mapping) for e in exprs]) if exprs else ca.SX(0, 1)
            return ca.Function(name, [self.x, self.u, self.p], [out])

        self.rhs_sx = ca.vertcat(*[to_casadi(e, mapping) for e in model.rhs])
        self.f = ca.Function("f", [self.x, self.u, self.p], [self.rhs_sx])
        self.continuous = [g for g in hybrid.guards_from(mode.name) if g.kind in STATE_GUARDS]
        self.guard_sx = [to_casadi(g.expression, mapping) for g in self.continuous]
        self.guard = [ca.Function("g", [self.x, self.u, self.p], [g]) for g in self.guard_sx]
        self._augmented: dict[tuple[int, ...], Any] = {}
        self._gradients: dict[int, Any] = {}
        self.condition = {
            id(g): function("c", [g.condition]) for g in self.continuous if g.condition is not None
        }
        self.torque_exprs = []
        for e in hybrid.elements:
            status, sign = mode.status[e]
            if status == LOCKED:
                self.torque_exprs.append(mode.reaction[e])
            elif status == SLIDING:
                self.torque_exprs.append(sign * mode.capacity[e])
            else:
                self.torque_exprs.append(sp.Integer(0))
        self.torques = function("torques", self.torque_exprs)
        self.slips = function("slips", [mode.slip[e] for e in hybrid.elements])
        # μ as the mode uses it (the map's value scaled by the parameter, or the parameter;
        # 0 for a one-way clutch)
        mus = [
            mapping[hybrid.friction_coefficient[e]] if e in hybrid.friction_coefficient else 0
            for e in hybrid.elements
        ]
        self.mu = ca.Function("mu", [self.x, self.u, self.p], [ca.vertcat(*mus)])

    def rhs(self, x: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
        """ẋ = f(x, u, p) of the mode as a 1-D array."""
        return np.asarray(self.f(x, u, p).full(), dtype=float).ravel()

    def augmented(self, indices: tuple[int | None, ...]) -> Any:
        """(y, u, p) → ẏ of y = [x; S_1; …; S_m] (S_j = ∂x/∂p_j of the parameters at
        ``indices``): ẋ = f, Ṡ = ∂f/∂x S + ∂f/∂p (3.7), by CasADi's AD of the mode's f. An
        index None is an initial state taken as a parameter: no ∂f/∂p term."""
        if indices not in self._augmented:
            import casadi as ca

            sensitivities = ca.SX.sym("S", self.n, len(indices))
            f_x = ca.jacobian(self.rhs_sx, self.x)
            f_p = ca.horzcat(
                *[
                    ca.jacobian(self.rhs_sx, self.p[k]) if k is not None else ca.SX(self.n, 1)
                    for k in indices
                ]
            )
            y = ca.vertcat(self.x, ca.vec(sensitivities))
            out = ca.vertcat(self.rhs_sx, ca.vec(f_x @ sensitivities + f_p))
            self._augmented[indices] = ca.Function("augmented", [y, self.u, self.p], [out])
        return self._augmented[indices]

    def guard_gradient(self, k: int) -> Any:
        """(x, u, p) → (∂g/∂x, ∂g/∂u, ∂g/∂p) of the k-th continuous guard."""
        if k not in self._gradients:
            import casadi as ca

            g = self.guard_sx[k]
            self._gradients[k] = ca.Function(
                "dg",
                [self.x, self.u, self.p],
                [ca.jacobian(g, self.x), ca.jacobian(g, self.u), ca.jacobian(g, self.p)],
            )
        return self._gradients[k]

    def value(self, function: Any, x: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
        """One of the mode's functions at one (x, u, p), as a 1-D array."""
        return np.asarray(function(x, u, p).full(), dtype=float).ravel()

    def many(self, function: Any, x: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
        """One of the mode's functions at N points (x: N × n, u: N × nu): N × outputs."""
        out = function.map(len(x))(x.T, u.T, p)
        return np.asarray(out.full(), dtype=float).T
