"""The augmented system (4.1) and the excitation models of its inputs.

Parameters to be estimated are appended to the state vector as random walks; in the Lie
derivatives (4.4) their drift is zero (``dp/dt = 0``), exactly as the thesis does for
``p = [m_veh, mu38, mu05, zeta]``. Model numbers are made exact (:func:`.exact.exact_rational`).

Non-rational functions: ``sin(s)``/``cos(s)`` of a single symbol ``s`` (road grade ``zeta`` in
(2.49)) are supported; such ``s`` must not appear outside ``sin``/``cos`` (the rank test draws
it on the rational parametrisation ``s = 2 atan(t)``, :mod:`.exact`). ``tan`` is rewritten as
``sin/cos``; ``sin(2s)``, ``sin(s + w)`` are expanded. Anything else (``exp``, ``sqrt``, ``Abs``,
``sign``, ``tanh``, ``Piecewise``, ``pi``) raises :class:`.UnsupportedExpressionError`: replace
it by its value on the operating region (e.g. ``sign(slip) = 1`` during a shift phase) first.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.model import Model
from gearsym.symbolic.observability.errors import UnsupportedExpressionError
from gearsym.symbolic.observability.exact import exact_rational, rationalize


@dataclass(frozen=True)
class InputModel:
    """How an input may vary over the observation window.

    ``generic``: all derivatives ``u', u'', ...`` are free variables (thesis 4.4, "for all
    inputs"). ``constant``: ``u' = 0``. ``poly:K``: ``u`` is a polynomial of degree ``K`` in
    time, so derivatives above ``K`` vanish (``poly:0`` is ``constant``).
    """

    kind: str = "generic"
    degree: int | None = None

    @classmethod
    def parse(cls, spec: str | InputModel) -> InputModel:
        """Parse ``"generic"``, ``"constant"`` or ``"poly:K"``."""
        if isinstance(spec, InputModel):
            return spec
        text = spec.strip().lower()
        if text == "generic":
            return cls("generic", None)
        if text == "constant":
            return cls("constant", 0)
        if text.startswith("poly:"):
            degree = int(text[5:])
            if degree < 0:
                raise ValueError(f"negative polynomial degree in input model {spec!r}")
            return cls("constant", 0) if degree == 0 else cls("poly", degree)
        raise ValueError(f"unknown input model {spec!r}; use generic, constant or poly:K")

    @property
    def max_derivative(self) -> int | None:
        """Highest derivative order that may be nonzero (``None``: unbounded)."""
        return self.degree

    def __str__(self) -> str:
        if self.kind == "poly":
            return f"poly:{self.degree}"
        return self.kind


_TRIG_ALLOWED = (sp.sin, sp.cos)


@dataclass(frozen=True)
class AugmentedSystem:
    """The augmented system (4.1): ``d[x; p]/dt = [f(x, u, p); 0]``, ``y = h(x, u, p)``.

    ``unknowns`` are the states followed by the estimated parameters (the random-walk states).
    ``generic_parameters`` are known parameters kept symbolic; the rank test samples them like
    every other variable (generic values). ``substituted`` maps the names of parameters fixed
    at their defaults to the exact rational used.
    """

    model_name: str
    state_names: tuple[str, ...]
    parameter_names: tuple[str, ...]
    unknowns: tuple[sp.Symbol, ...]
    dynamics: tuple[sp.Expr, ...]
    output_names: tuple[str, ...]
    outputs: tuple[sp.Expr, ...]
    input_names: tuple[str, ...]
    inputs: tuple[sp.Symbol, ...]
    generic_parameter_names: tuple[str, ...]
    generic_parameters: tuple[sp.Symbol, ...]
    substituted: Mapping[str, sp.Rational]
    angle_symbols: frozenset[sp.Symbol]

    @property
    def unknown_names(self) -> tuple[str, ...]:
        return self.state_names + self.parameter_names

    @property
    def n_unknowns(self) -> int:
        return len(self.unknowns)


def normalize_trig(expr: sp.Expr) -> sp.Expr:
    """Rewrite tan/cot/sec/csc with sin/cos and expand multiple angles and sums."""
    if not expr.has(sp.sin, sp.cos, sp.tan, sp.cot, sp.sec, sp.csc):
        return expr
    expr = expr.replace(sp.tan, lambda a: sp.sin(a) / sp.cos(a))
    expr = expr.replace(sp.cot, lambda a: sp.cos(a) / sp.sin(a))
    expr = expr.replace(sp.sec, lambda a: 1 / sp.cos(a))
    expr = expr.replace(sp.csc, lambda a: 1 / sp.sin(a))
    if any(not a.args[0].is_Symbol for a in expr.atoms(sp.sin, sp.cos)):
        expr = sp.expand_trig(expr)
    return expr


def _check_supported(expr: sp.Expr, where: str) -> set[sp.Symbol]:
    """Raise unless ``expr`` is exactly evaluable; return the symbols used as trig angles."""
    angles: set[sp.Symbol] = set()
    for node in sp.preorder_traversal(expr):
        if node.is_Symbol or node.is_Rational or node.is_Add or node.is_Mul:
            continue
        if node.is_Pow:
            if not node.exp.is_Integer:
                raise UnsupportedExpressionError(
                    f"{where}: non-integer power {node} cannot be evaluated exactly"
                )
            continue
        if isinstance(node, _TRIG_ALLOWED):
            if not node.args[0].is_Symbol:
                raise UnsupportedExpressionError(
                    f"{where}: {node} — only sin/cos of a single symbol are supported"
                )
            angles.add(node.args[0])
            continue
        if isinstance(node, sp.Float):
            raise UnsupportedExpressionError(f"{where}: float {node} left after rationalizing")
        raise UnsupportedExpressionError(
            f"{where}: {type(node).__name__} ({node}) cannot be evaluated exactly at a rational "
            "point; replace it by its value on the operating region"
        )
    return angles


def augment(
    model: Model,
    estimate: Iterable[str] = (),
    *,
    substitute_defaults: bool | Iterable[str] = False,
) -> AugmentedSystem:
    """Build the augmented system (4.1) of ``model``.

    ``estimate`` names the parameters appended as random-walk states. ``substitute_defaults``
    fixes other parameters at their defaults (``True``: every non-estimated parameter that has
    one; or an explicit list of names), converted with :func:`exact_rational`. All remaining
    parameters stay symbolic and are treated as *known, generic* values. Floats in the model
    equations are made exact the same way.
    """
    estimate = list(estimate)
    params = {v.name: v for v in model.parameters}
    unknown = [name for name in estimate if name not in params]
    if unknown:
        raise KeyError(f"not parameters of model {model.name!r}: {unknown}")
    if len(set(estimate)) != len(estimate):
        raise ValueError(f"parameter listed twice in estimate: {estimate}")
    if substitute_defaults is True:
        fixed = [n for n, v in params.items() if n not in estimate and v.default is not None]
    elif substitute_defaults is False:
        fixed = []
    else:
        fixed = list(substitute_defaults)
        clash = sorted(set(fixed) & set(estimate))
        if clash:
            raise ValueError(f"parameters both estimated and substituted: {clash}")
        missing = [n for n in fixed if n not in params or params[n].default is None]
        if missing:
            raise ValueError(f"parameters without a default cannot be substituted: {missing}")
    substituted = {n: exact_rational(params[n].default) for n in fixed}
    subs = {params[n].symbol: value for n, value in substituted.items()}

    def prepare(expr: sp.Expr, where: str) -> sp.Expr:
        expr = rationalize(sp.sympify(expr).xreplace(subs))
        return normalize_trig(expr)

    dynamics = [prepare(e, f"d{v.name}/dt") for v, e in zip(model.states, model.rhs, strict=True)]
    outputs = [
        prepare(e, f"output {v.name}")
        for v, e in zip(model.outputs, model.output_expressions, strict=True)
    ]
    angles: set[sp.Symbol] = set()
    for v, e in zip(model.states, dynamics, strict=True):
        angles |= _check_supported(e, f"d{v.name}/dt")
    for v, e in zip(model.outputs, outputs, strict=True):
        angles |= _check_supported(e, f"output {v.name}")
    # An angle used in one equation must not appear bare in another one either.
    for e in (*dynamics, *outputs):
        masked = e.xreplace({t: sp.Dummy() for t in e.atoms(sp.sin, sp.cos)})
        bare = masked.free_symbols & angles
        if bare:
            raise UnsupportedExpressionError(
                f"{sorted(map(str, bare))} appear inside sin/cos and also outside them"
            )
    est_vars = [params[n] for n in estimate]
    generic = [v for v in model.parameters if v.name not in estimate and v.name not in fixed]
    return AugmentedSystem(
        model_name=model.name,
        state_names=tuple(v.name for v in model.states),
        parameter_names=tuple(estimate),
        unknowns=tuple(model.state_symbols) + tuple(v.symbol for v in est_vars),
        dynamics=tuple(dynamics) + tuple(sp.S.Zero for _ in est_vars),
        output_names=tuple(v.name for v in model.outputs),
        outputs=tuple(outputs),
        input_names=tuple(v.name for v in model.inputs),
        inputs=tuple(model.input_symbols),
        generic_parameter_names=tuple(v.name for v in generic),
        generic_parameters=tuple(v.symbol for v in generic),
        substituted=substituted,
        angle_symbols=frozenset(angles),
    )


def parse_input_models(
    system: AugmentedSystem, input_models: Mapping[str, str | InputModel] | None, default: str
) -> dict[str, InputModel]:
    """One :class:`InputModel` per input of ``system``; unnamed inputs get ``default``."""
    given = dict(input_models or {})
    stray = sorted(set(given) - set(system.input_names))
    if stray:
        raise KeyError(f"input models for unknown inputs: {stray}")
    return {name: InputModel.parse(given.get(name, default)) for name in system.input_names}
