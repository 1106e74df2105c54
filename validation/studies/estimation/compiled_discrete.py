"""The filter's discrete model (:class:`~gearsym.symbolic.estimators.ekf.DiscreteModel`: the
RK4 step (4.3), its exact Jacobian, ∂Φ/∂u, ∂Φ/∂p and the outputs with ∂h/∂z) emitted as C by
CasADi and called through ``ctypes`` (:mod:`~gearsym.validation.sim.compiled_c`).

Why: the drive's EKF calls these functions some ten times per TCU sample, 180 000 samples over
a WLTC drive; a CasADi call from Python costs 30-50 µs, nearly all of it converting arrays,
against a few µs through ``ctypes``. The arithmetic is CasADi's own emitted without fast-math,
the same values to rounding (tests/test_drive_ekf.py compares a drive's estimates both ways:
5e-15 relative)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gearsym.validation.sim.compiled_c import CompiledFunctions, compiler_available

__all__ = ["CompiledDiscrete", "compiled_or_casadi"]


class CompiledDiscrete:
    """:class:`~gearsym.symbolic.estimators.ekf.DiscreteModel`'s interface (``step``,
    ``step_du``, ``step_dp``, ``outputs``, ``rhs``, ``aug``) on its functions compiled; each
    function's outputs stacked into one vector (matrices column by column, CasADi's order)."""

    def __init__(self, discrete: Any) -> None:
        import casadi as ca

        self.discrete = discrete
        self.aug = discrete.aug
        model = discrete.aug.model
        self.n = len(model.states)
        self.n_u = len(model.inputs)
        self.n_p = len(model.parameters)
        self.n_y = len(model.output_expressions)
        z = ca.SX.sym("z", self.n)
        u = ca.SX.sym("u", self.n_u)
        p = ca.SX.sym("p", self.n_p)
        h = ca.SX.sym("h")
        z_next, jac = discrete.step_fn(z, u, h, p)
        stacked = {
            "step": ([z, u, h, p], [z_next, ca.vec(jac)]),
            "du": ([z, u, h, p], [ca.vec(discrete.step_du_fn(z, u, h, p))]),
            "dp": ([z, u, h, p], [ca.vec(discrete.step_dp_fn(z, u, h, p))]),
            "outputs": ([z, u, p], [discrete.h_fn(z, u, p), ca.vec(discrete.H_fn(z, u, p))]),
            "rhs": ([z, u, p], [discrete.f(z, u, p)]),
        }
        compiled = CompiledFunctions(
            {
                name: ca.Function(name, inputs, [ca.vertcat(*outputs)])
                for name, (inputs, outputs) in stacked.items()
            }
        )
        self._step, self._du, self._dp = compiled["step"], compiled["du"], compiled["dp"]
        self._outputs, self._rhs = compiled["outputs"], compiled["rhs"]

    def step(
        self, z: Sequence[float], u: Sequence[float], h: float, p: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """(z_{k+1}, F) of one RK4 step of size h with u held."""
        out = self._step(z, u, h, p)
        return out[: self.n], out[self.n :].reshape((self.n, self.n), order="F")

    def step_du(
        self, z: Sequence[float], u: Sequence[float], h: float, p: Sequence[float]
    ) -> np.ndarray:
        """∂z_{k+1}/∂u of one RK4 step of size h with u held."""
        return self._du(z, u, h, p).reshape((self.n, self.n_u), order="F")

    def step_dp(
        self, z: Sequence[float], u: Sequence[float], h: float, p: Sequence[float]
    ) -> np.ndarray:
        """∂z_{k+1}/∂p of one RK4 step of size h with u held."""
        return self._dp(z, u, h, p).reshape((self.n, self.n_p), order="F")

    def outputs(
        self, z: Sequence[float], u: Sequence[float], p: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """(y, ∂y/∂z) at z."""
        out = self._outputs(z, u, p)
        return out[: self.n_y], out[self.n_y :].reshape((self.n_y, self.n), order="F")

    def rhs(self, z: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        """ż = f(z, u, p)."""
        return self._rhs(z, u, p)

    def __getattr__(self, name: str) -> Any:
        # anything else (CasADi's own functions, the AD check of the step) from the model
        return getattr(self.discrete, name)


def compiled_or_casadi(discrete: Any) -> Any:
    """``discrete`` compiled (:class:`CompiledDiscrete`) where a C compiler is there, else
    ``discrete`` itself (CasADi's calls: the same values to rounding)."""
    return CompiledDiscrete(discrete) if compiler_available() else discrete
