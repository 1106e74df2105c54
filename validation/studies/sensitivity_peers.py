"""Independent checks of the integrated sensitivities (3.7) of
:mod:`gearsym.validation.studies.sensitivity_integration` (tests, benchmark): central finite
differences of the integrated model, and CasADi forward-mode derivatives through a CVODES
integrator of a CasADi SX build of the same right-hand side."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic.model import Model
from gearsym.symbolic.numeric import to_casadi
from gearsym.validation.studies.sensitivity_integration import (
    CompiledModel,
    Interpolated,
    integrate,
    nominal_scales,
)


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
