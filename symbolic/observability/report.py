"""Observability of a gearbox's shift model: the analysis behind ``gearsym observability``.

The shift model (2.55–2.58) with the clutch torques written as μ times the known normal force
(2.69) is augmented with the estimated parameters as random-walk states (4.1), default
``p = [m_veh, μ38, μ05, ζ]`` for the 2-3 shift; its outputs are the measured speeds (3.31),
optionally with the wheel acceleration (3.32). :func:`analyze_shift` builds that model from a
description, turns the user's outputs, input models, point conditions and parameters (text,
as the command line and the notebook API take them) into model terms, decides the generic
rank of ``Q`` (4.7), (4.12) with :func:`~gearsym.symbolic.observability.rank.analyze_observability`
and searches the sets where it drops with
:func:`~gearsym.symbolic.observability.search.find_rank_drops`, each followed to higher orders
(4.13). The result is an :class:`ObservabilityReport`; printing it is the CLI's business.

Bad input raises :class:`~gearsym.symbolic.errors.GearsymError` keyed by the command-line option
that carries the value (``--outputs``, ``--at``, ``--params``, ...), so the command and the API
report the same one line.
"""

from __future__ import annotations

import dataclasses
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NoReturn

import sympy as sp
from gearsym.symbolic.defaults import DEFAULT_SHIFT
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.model import Variable
from gearsym.symbolic.observability.drops import RankDrop
from gearsym.symbolic.observability.errors import (
    BudgetExceeded,
    ObservabilityError,
    PartialResult,
)
from gearsym.symbolic.observability.rank import ObservabilityResult, analyze_observability
from gearsym.symbolic.observability.search import find_rank_drops
from gearsym.symbolic.observability.system import InputModel
from sympy.core.function import AppliedUndef
from sympy.parsing.sympy_parser import parse_expr, standard_transformations

if TYPE_CHECKING:
    from gearsym.symbolic.description import GearboxDescription
    from gearsym.symbolic.model import Model

__all__ = [
    "ObservabilityReport",
    "analyze_shift",
    "order_label",
    "parse_conditions",
    "parse_input_models",
    "parse_parameters",
    "partial_text",
    "select_outputs",
]

#: An input derivative named as a variable, ``<input>__d<k>`` (the u^(k) of (4.4)).
_DERIVATIVE = re.compile(r"^(?P<input>.+)__d(?P<k>[0-9]+)$")


# ---------------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ObservabilityReport:
    """Generic verdict (4.12) of one shift model plus the sets where its rank drops."""

    gearbox: str
    file: str
    shift: str
    model: Model = field(repr=False)
    result: ObservabilityResult = field(repr=False)
    output_expressions: dict[str, str]
    drops: tuple[RankDrop, ...]
    implied: tuple[str, ...]
    notes: tuple[str, ...]
    drop_search: bool
    timings: dict[str, float]

    @property
    def confirmed_drops(self) -> tuple[RankDrop, ...]:
        return tuple(d for d in self.drops if d.confirmed)

    def label(self, drop: RankDrop) -> str:
        """The drop's label; an input held at zero says which element that opens."""
        if drop.origin != "input-held-zero" or len(drop.conditions) != 1:
            return drop.label
        (name,) = drop.conditions
        text = next((v.description for v in self.model.inputs if v.name == name), "")
        text = re.sub(r"\s*\([0-9.]+\)$", "", text)  # "normal force on B05 (2.69)"
        return drop.label + (f" [{text}: element open]" if "normal force" in text else "")

    def _drop_dict(self, drop: RankDrop) -> dict[str, Any]:
        return {**drop.to_dict(), "label": self.label(drop)}

    def to_dict(self) -> dict[str, Any]:
        r = self.result
        return {
            "gearbox": self.gearbox,
            "file": self.file,
            "shift": self.shift,
            "model": r.model,
            "equations": "thesis (4.1)-(4.13); model (2.55)-(2.58), (2.69); outputs (3.31)/(3.32)",
            "unknowns": list(r.unknowns),
            "n_unknowns": r.n_unknowns,
            "rank": r.rank,
            "full_rank": r.full_rank,
            "certain": r.certain,
            "max_order": r.max_order,
            "rank_by_order": list(r.rank_by_order),
            "observable": dict(r.observable),
            "unobservable": list(r.unobservable),
            "unobservable_directions": [dict(v) for v in r.unobservable_directions],
            "error_probability_bound": r.error_probability_bound,
            "outputs": dict(self.output_expressions),
            "input_models": dict(r.input_models),
            "conditions": dict(r.conditions),
            "substituted_parameters": dict(r.substituted_parameters),
            "generic_parameters": list(r.generic_parameters),
            "seed": r.seed,
            "drop_search": self.drop_search,
            "rank_drops": [self._drop_dict(d) for d in self.drops if d.confirmed],
            "not_dropping": [self._drop_dict(d) for d in self.drops if not d.confirmed],
            "implied_not_tested": list(self.implied),
            "notes": list(self.notes),
            "result": r.to_dict(),
            "timings": dict(self.timings),
        }


# ---------------------------------------------------------------------------------------------
# Input in model terms (every bad value is a GearsymError naming the option)
# ---------------------------------------------------------------------------------------------


def _fail(d: GearboxDescription, key: str, reason: str) -> NoReturn:
    raise GearsymError(d.file, key, reason)


def _parse_expression(
    d: GearboxDescription, key: str, text: str, local: Mapping[str, sp.Symbol]
) -> sp.Expr:
    """An expression in the model's names; unknown names become fresh symbols (checked later)."""
    allowed = {
        "Symbol": sp.Symbol,
        "Function": sp.Function,
        "Integer": sp.Integer,
        "Float": sp.Float,
        "Rational": sp.Rational,
        "sin": sp.sin,
        "cos": sp.cos,
        "tan": sp.tan,
    }
    try:
        expr = parse_expr(
            text,
            local_dict=dict(local),
            global_dict=allowed,
            transformations=standard_transformations,
        )
    except Exception as exc:  # SyntaxError, TokenError, TypeError, ... from the parser
        _fail(d, key, f"cannot parse {text!r}: {type(exc).__name__}: {exc}".rstrip(": "))
    if not isinstance(expr, sp.Expr):
        _fail(d, key, f"{text!r} is not an expression")
    unknown = sorted({type(f).__name__ for f in expr.atoms(AppliedUndef)})
    if unknown:
        _fail(d, key, f"unknown function(s) {', '.join(unknown)} in {text!r}; use sin, cos, tan")
    return expr


def _names(model: Model) -> str:
    return (
        f"states {', '.join(v.name for v in model.states)}; "
        f"inputs {', '.join(v.name for v in model.inputs)}; "
        f"parameters {', '.join(v.name for v in model.parameters)}"
    )


def select_outputs(d: GearboxDescription, model: Model, items: Sequence[str]) -> Model:
    """Replace the outputs (3.31) of ``model`` by ``items``.

    Each item is an output name of the model (``y_omega_1``), an expression in its states,
    inputs and parameters (``omega_1 - omega_2``; a plain state name ``omega_C`` becomes the
    output ``y_omega_C``), or ``NAME=EXPRESSION``. An output must depend on a state.
    """
    existing = dict(zip((v.name for v in model.outputs), model.output_expressions, strict=True))
    local = {v.name: v.symbol for v in (*model.states, *model.inputs, *model.parameters)}
    known = set(local.values())
    states = set(model.state_symbols)
    names: list[str] = []
    exprs: list[sp.Expr] = []
    for k, item in enumerate(items, start=1):
        if item in existing:
            name, expr = item, existing[item]
        else:
            if "=" in item:
                name, text = (part.strip() for part in item.split("=", 1))
                if not name.isidentifier():
                    _fail(d, "--outputs", f"output name {name!r} is not an identifier")
            else:
                text = item
                name = f"y_{item}" if item.isidentifier() else f"y{k}"
            expr = _parse_expression(d, "--outputs", text, local)
            stray = sorted(str(s) for s in expr.free_symbols if s not in known)
            if stray:
                _fail(
                    d,
                    "--outputs",
                    f"unknown name(s) {', '.join(stray)} in {item!r}; model outputs "
                    f"{', '.join(existing)}; {_names(model)}",
                )
        if not expr.free_symbols & states:
            _fail(
                d,
                "--outputs",
                f"{item!r} is not a function of the states "
                f"({', '.join(v.name for v in model.states)}): it carries no information on them",
            )
        if name in names:
            _fail(d, "--outputs", f"output {name!r} given twice")
        names.append(name)
        exprs.append(expr)
    if not names:
        _fail(d, "--outputs", "no outputs given")
    variables = tuple(
        next((v for v in model.outputs if v.name == n), None) or Variable(n, sp.Symbol(n))
        for n in names
    )
    return dataclasses.replace(model, outputs=variables, output_expressions=sp.Matrix(exprs))


def parse_input_models(d: GearboxDescription, model: Model, items: Sequence[str]) -> dict[str, str]:
    """``NAME=generic|constant|poly:K`` per input; ``all=...`` sets every input first."""
    inputs = [v.name for v in model.inputs]
    general: dict[str, str] = {}
    specific: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            _fail(d, "--input-model", f"expected NAME=generic|constant|poly:K, got {item!r}")
        name, spec = (part.strip() for part in item.split("=", 1))
        try:
            parsed = str(InputModel.parse(spec))
        except ValueError as exc:
            _fail(d, "--input-model", f"{item!r}: {exc}")
        if name == "all":
            general = dict.fromkeys(inputs, parsed)
        elif name in inputs:
            specific[name] = parsed
        else:
            _fail(
                d,
                "--input-model",
                f"{name!r} is not an input of the model; inputs: {', '.join(inputs)} (or all)",
            )
    return {**general, **specific}


def parse_conditions(d: GearboxDescription, model: Model, items: Sequence[str]) -> dict[str, str]:
    """``NAME=VALUE`` point restrictions (applied after differentiation, see the engine)."""
    local = {v.name: v.symbol for v in (*model.states, *model.inputs, *model.parameters)}
    inputs = {v.name for v in model.inputs}

    def known(name: str) -> bool:
        m = _DERIVATIVE.match(name)
        return name in local or (m is not None and m["input"] in inputs)

    out: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            _fail(d, "--at", f"expected NAME=VALUE, got {item!r}")
        name, value = (part.strip() for part in item.split("=", 1))
        if not known(name):
            _fail(
                d,
                "--at",
                f"{name!r} is not a variable of the model; {_names(model)}; input derivatives "
                "as <input>__d<k>",
            )
        expr = _parse_expression(d, "--at", value, local)
        stray = sorted(str(s) for s in expr.free_symbols if not known(str(s)))
        if stray:
            _fail(d, "--at", f"unknown name(s) {', '.join(stray)} in {item!r}")
        out[name] = value
    return out


def parse_parameters(d: GearboxDescription, model: Model, items: Sequence[str]) -> list[str]:
    """Names of the parameters appended as random-walk states (4.1)."""
    names = [v.name for v in model.parameters]
    stray = [p for p in items if p not in names]
    if stray:
        _fail(
            d,
            "--params",
            f"unknown parameter(s) {', '.join(stray)}; parameters of the model: {', '.join(names)}",
        )
    twice = sorted({p for p in items if items.count(p) > 1})
    if twice:
        _fail(d, "--params", f"parameter(s) given twice: {', '.join(twice)}")
    return list(items)


# ---------------------------------------------------------------------------------------------
# The analysis
# ---------------------------------------------------------------------------------------------


def analyze_shift(
    d: GearboxDescription,
    shift: str = DEFAULT_SHIFT,
    *,
    params: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    with_wheel_acceleration: bool = False,
    input_models: Sequence[str] | None = None,
    conditions: Sequence[str] | None = None,
    max_order: int | None = None,
    symbolic_known: bool = False,
    drop_search: bool = True,
    factor_minor: bool = True,
    seed: int | None = None,
    time_budget: float | None = None,
    size_budget: int | None = None,
    higher_order_seconds: float = 1.0,
) -> ObservabilityReport:
    """Observability of the augmented shift model (4.1) and where the rank of ``Q`` drops.

    ``params`` are estimated (default: ``m_veh``, the μ of the two swapping elements and
    ``zeta``, i.e. ``p = [m_veh, mu_38, mu_05, zeta]`` of (4.1) for the 2-3 shift); every
    other parameter is fixed at its default (``symbolic_known``: kept as a generic known
    value), except those named in ``conditions`` (``NAME=VALUE`` point restrictions).
    ``input_models`` are ``NAME=generic|constant|poly:K``. Without ``max_order`` the
    derivative order grows until the rank is full or an order adds nothing (at most
    ``n - 1``, (4.4)); with it, every order up to ``max_order`` is ranked. Raises
    :class:`GearsymError` for bad input and for an exceeded budget; in that case the error's
    ``partial`` attribute holds the sound partial result.
    """
    from gearsym.symbolic.drivetrain import shift_model
    from gearsym.symbolic.input_gain import INPUT_TORQUE_GAIN, with_input_torque_gain

    started = time.perf_counter()
    try:
        model = shift_model(
            d, shift, with_wheel_acceleration=with_wheel_acceleration, friction_inputs=True
        )
    except GearsymError as err:
        if err.key == "shift":
            raise GearsymError(err.file, "--shift", err.reason) from None
        raise
    if params is not None and INPUT_TORQUE_GAIN in params:
        # the input torque as the TCU is told it, times a gain to be told apart (input_gain)
        model = with_input_torque_gain(model)
    if outputs:
        model = select_outputs(d, model, outputs)
    if params is None:
        # p of (4.1) for this shift: the thesis' [m_veh, mu_38, mu_05, zeta] for 2-3
        mus = [v.name for v in model.parameters if v.name.startswith("mu_")]
        params = ["m_veh", *mus, "zeta"]
    estimate = parse_parameters(d, model, list(params))
    models = parse_input_models(d, model, input_models or ())
    conds = parse_conditions(d, model, conditions or ())
    if max_order is not None and max_order < 0:
        _fail(d, "--max-order", f"must be >= 0, got {max_order}")
    clash = sorted(set(conds) & set(estimate))
    fixed = (
        []
        if symbolic_known
        else [
            v.name
            for v in model.parameters
            if v.name not in estimate and v.default is not None and v.name not in conds
        ]
    )
    model_seconds = time.perf_counter() - started
    try:
        result = analyze_observability(
            model,
            estimate,
            substitute_defaults=fixed,
            input_models=models,
            conditions=conds,
            max_order=max_order,
            patience=1 if max_order is None else None,
            seed=seed,
            time_budget=time_budget,
            size_budget=size_budget,
        )
    except BudgetExceeded as exc:
        err = GearsymError(
            d.file,
            "--time-budget" if "time budget" in str(exc) else "--size-budget",
            f"{exc}; sound partial result: {partial_text(exc.partial)}",
        )
        err.partial = exc.partial  # type: ignore[attr-defined]
        raise err from None
    except ObservabilityError as exc:
        key = "--at" if conds else "--outputs" if outputs else "model"
        _fail(d, key, str(exc))
    except (KeyError, ValueError) as exc:
        _fail(d, "--at" if conds else "--params", str(exc).strip("'\""))
    analysis_seconds = time.perf_counter() - started - model_seconds
    drops: tuple[RankDrop, ...] = ()
    implied: tuple[str, ...] = ()
    notes: list[str] = []
    if clash:
        notes.append(f"conditions on estimated parameters {clash} restrict the point only")
    if drop_search:
        search = find_rank_drops(
            result,
            witness_minor=factor_minor,
            seed=None if seed is None else seed + 1,
            time_budget=time_budget,
            higher_order_seconds=higher_order_seconds,
        )
        drops, implied = search.candidates, search.implied
        notes.extend(search.notes)
    total = time.perf_counter() - started
    return ObservabilityReport(
        gearbox=d.name,
        file=d.file,
        shift=shift,
        model=model,
        result=result,
        output_expressions={
            v.name: str(e) for v, e in zip(model.outputs, model.output_expressions, strict=True)
        },
        drops=drops,
        implied=implied,
        notes=tuple(notes),
        drop_search=drop_search,
        timings={
            "model": model_seconds,
            "lie_derivatives": result.timings["lie_derivatives"],
            "rank": result.timings["screening"] + result.timings["exact"],
            "analysis": analysis_seconds,
            "drop_search": total - model_seconds - analysis_seconds,
            "total": total,
        },
    )


def order_label(k: int) -> str:
    """``y`` for order 0, ``y^(k)`` otherwise: the k-th time derivative of the outputs (4.4)."""
    return "y" if k == 0 else f"y^({k})"


def partial_text(partial: PartialResult) -> str:
    """One line on a budget-limited run: the sound lower bound of the rank of Q (4.13)."""
    if partial.orders_completed < 0:
        return f"no derivative order completed, rank >= 0 of {partial.n_unknowns}"
    orders = ", ".join(str(x) for x in partial.rank_by_order)
    return (
        f"rank of Q >= {partial.rank_lower_bound} of {partial.n_unknowns} with derivatives up "
        f"to {order_label(partial.orders_completed)} (rank by order {orders}; (4.13))"
    )
