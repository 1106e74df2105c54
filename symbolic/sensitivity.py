"""Stage 4a: parameter sensitivity equations (thesis 3.1–3.15).

For a model ``ẋ = f(x, u, p)`` (3.1), (3.5) — the thesis writes f + B(p) u, which is the same
right-hand side — the absolute sensitivities ``S_ij = ∂x_i/∂p_j`` (3.2) obey the linear,
inhomogeneous sensitivity ODE (3.6)–(3.7)

    Ṡ_j = ∂f/∂x · S_j + ∂f/∂p_j,        S_j(0) = ∂x(0)/∂p_j = 0,

with ∂f/∂x (3.8) common to every parameter and the inhomogeneous term ∂f/∂p_j (∂B/∂p_j u
included) per parameter (3.9)–(3.15). Outputs ``y = h(x, u, p)`` get the sensitivities
``∂y/∂p_j = ∂h/∂x · S_j + ∂h/∂p_j`` that the Fisher information (3.25) needs.

:func:`sensitivity_equations` derives all of this for any :class:`~gearsym.symbolic.model.Model` and
any subset of its parameters, and returns the augmented system ``[x; S_1; …; S_m]`` as a new
``Model``, so the code emitters (C, CasADi) and the integrators consume it like any other model.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic import naming

#: The parameters the thesis studies (3.2): vehicle mass, side-shaft stiffness and damping,
#: friction coefficient of the off-going clutch K38, road grade.
from gearsym.symbolic.defaults import SENSITIVITY_PARAMETERS as DEFAULT_PARAMETERS
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.sympy_utils import smart_jacobian


def sensitivity_name(state: str, parameter: str) -> str:
    """Name of the sensitivity state ``S_ij = ∂x_i/∂p_j`` (3.2): ``S_<state>__<parameter>``."""
    return f"S_{state}__{parameter}"


def output_sensitivity_name(output: str, parameter: str) -> str:
    """Name of the output sensitivity ``∂y_i/∂p_j``: ``dy_<output>__<parameter>``."""
    return f"dy_{output}__{parameter}"


def select_parameters(
    model: Model, names: Sequence[str] | None = None, file: str | None = None
) -> tuple[Variable, ...]:
    """The model parameters named in ``names`` (default :data:`DEFAULT_PARAMETERS`), in order.

    Raises :class:`GearsymError` (``file``, key ``params``) for an unknown name, a name given
    twice, an empty list, or a parameter on which neither the right-hand side nor the outputs
    depend (its sensitivities would be identically zero, 3.7).
    """
    file = file or model.metadata.get("gearbox", model.name)
    names = list(DEFAULT_PARAMETERS if names is None else names)
    if not names:
        raise GearsymError(file, "params", "no parameters given")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise GearsymError(file, "params", f"parameter given twice: {', '.join(twice)}")
    known = {v.name: v for v in model.parameters}
    used = model.rhs.free_symbols | model.output_expressions.free_symbols
    chosen = []
    for name in names:
        if name not in known:
            raise GearsymError(
                file,
                "params",
                f"unknown parameter {name!r} of model {model.name!r} (known: {', '.join(known)})",
            )
        if known[name].symbol not in used:
            raise GearsymError(
                file,
                "params",
                f"model {model.name!r} does not depend on parameter {name!r}: its "
                "sensitivities are identically zero",
            )
        chosen.append(known[name])
    return tuple(chosen)


@dataclass(frozen=True)
class SensitivityEquations:
    """The sensitivity ODE (3.7) of a model for a chosen parameter vector.

    ``jac_x`` is ∂f/∂x (3.8), ``jac_p`` the inhomogeneous terms ∂f/∂p (one column per
    parameter, 3.9–3.15), ``output_jac_x``/``output_jac_p`` the same for the outputs.
    ``symbols[i, j]`` is the symbol of S_ij (3.2). ``augmented`` is the model with states
    ``[x; S_1; …; S_m]`` and outputs ``[y; ∂y/∂p_1; …; ∂y/∂p_m]``.
    """

    model: Model
    parameters: tuple[Variable, ...]
    jac_x: sp.Matrix
    jac_p: sp.Matrix
    output_jac_x: sp.Matrix
    output_jac_p: sp.Matrix
    symbols: sp.Matrix
    augmented: Model

    @property
    def parameter_names(self) -> list[str]:
        return [v.name for v in self.parameters]

    def inhomogeneous_term(self, parameter: str) -> sp.Matrix:
        """∂f/∂p_j (+ ∂B/∂p_j u) of one parameter, the last terms of (3.7)."""
        return self.jac_p[:, self.parameter_names.index(parameter)]


def sensitivity_equations(
    model: Model, parameters: Sequence[str] | None = None, file: str | None = None
) -> SensitivityEquations:
    """Derive (3.5)–(3.7) symbolically for ``model`` and ``parameters`` (default: thesis set).

    The augmented model keeps the inputs and all parameters of ``model`` (with defaults) and
    stacks the sensitivity columns after the states, parameter by parameter:
    ``Ṡ_j = ∂f/∂x S_j + ∂f/∂p_j`` (3.7). Its outputs are ``y`` followed by
    ``∂y/∂p_j = ∂h/∂x S_j + ∂h/∂p_j`` for every j. Initial sensitivities are zero when the
    initial state does not depend on the parameters (the caller's choice).
    """
    chosen = select_parameters(model, parameters, file)
    x = model.state_symbols
    p = [v.symbol for v in chosen]
    # by_rules: the same expressions as diff, without SymPy's per-node dispatch (generate
    # derives eight of these systems)
    jac_x = smart_jacobian(model.rhs, x, by_rules=True)
    jac_p = smart_jacobian(model.rhs, p, by_rules=True)
    h_x = smart_jacobian(model.output_expressions, x, by_rules=True)
    h_p = smart_jacobian(model.output_expressions, p, by_rules=True)
    n, m = len(x), len(p)

    s_vars = [
        [
            Variable(
                sensitivity_name(xv.name, pv.name),
                sp.Symbol(sensitivity_name(xv.name, pv.name), real=True),
                _unit_ratio(xv.unit, pv.unit),
                f"sensitivity d{xv.name}/d{pv.name} (3.2)",
            )
            for pv in chosen
        ]
        for xv in model.states
    ]
    symbols = sp.Matrix(n, m, lambda i, j: s_vars[i][j].symbol)
    rhs_s = jac_x * symbols + jac_p  # (3.7), one column per parameter
    states = tuple(model.states) + tuple(s_vars[i][j] for j in range(m) for i in range(n))
    rhs = sp.Matrix([*model.rhs, *[rhs_s[i, j] for j in range(m) for i in range(n)]])

    dy = h_x * symbols + h_p
    outputs = tuple(model.outputs) + tuple(
        Variable(
            output_sensitivity_name(yv.name, pv.name),
            sp.Symbol(output_sensitivity_name(yv.name, pv.name), real=True),
            _unit_ratio(yv.unit, pv.unit),
            f"output sensitivity d{yv.name}/d{pv.name} (3.25)",
        )
        for pv in chosen
        for yv in model.outputs
    )
    output_exprs = sp.Matrix(
        [*model.output_expressions, *[dy[i, j] for j in range(m) for i in range(dy.rows)]]
    )
    augmented = Model(
        name=naming.sensitivity_model_name(model.name),
        states=states,
        inputs=model.inputs,
        parameters=model.parameters,
        outputs=outputs,
        rhs=rhs,
        output_expressions=output_exprs,
        metadata={
            **model.metadata,
            "base_model": model.name,
            "sensitivity_parameters": " ".join(v.name for v in chosen),
            "equations": "3.5-3.7 (sensitivity ODE) on " + model.metadata.get("equations", ""),
        },
    )
    return SensitivityEquations(model, chosen, jac_x, jac_p, h_x, h_p, symbols, augmented)


def stationary_initial_sensitivity(eqs: SensitivityEquations, free: Sequence[str]) -> sp.Matrix:
    """S(0) = ∂x(0)/∂p when x(0) is a quasi-static state that depends on the parameters.

    The states named in ``free`` are those the initial condition solves for (in the shift
    model the side-shaft twist φ, which the reference sets so that φ̈ = 0 in the from-gear);
    the others are given (the speeds, by the vehicle speed) and get S(0) = 0. Each free state
    x_s satisfies d(ẋ_s)/dt = (∂f_s/∂x) f = 0 at fixed inputs; differentiating g(x, p) = 0
    with respect to p gives (∂g/∂x_F) S_F(0) = −∂g/∂p. Returns the n × m matrix S(0) as
    expressions in x, u, p.
    """
    model = eqs.model
    names = [v.name for v in model.states]
    unknown = [n for n in free if n not in names]
    if unknown:
        raise ValueError(f"no states {unknown} in model {model.name!r}")
    rows = [names.index(n) for n in free]
    conditions = sp.Matrix([(eqs.jac_x[r, :] * model.rhs)[0] for r in rows])
    x_free = [model.state_symbols[r] for r in rows]
    lhs = smart_jacobian(conditions, x_free)
    rhs = -smart_jacobian(conditions, [v.symbol for v in eqs.parameters])
    solution = lhs.LUsolve(rhs)
    result = sp.zeros(len(names), len(eqs.parameters))
    for k, r in enumerate(rows):
        result[r, :] = solution[k, :]
    return result


def sensitivity_model(model: Model, parameters: Sequence[str] | None = None) -> Model:
    """The augmented model [x; S] of (3.5)–(3.7); see :func:`sensitivity_equations`."""
    return sensitivity_equations(model, parameters).augmented


def _unit_ratio(numerator: str, denominator: str) -> str:
    if denominator in ("1", ""):
        return numerator
    return f"({numerator})/({denominator})"
