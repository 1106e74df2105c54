"""``gearsym observability``: Lie-derivative observability of a shift model (thesis 4.1–4.13).

The shift model (2.55–2.58) with the clutch torques written as μ times the known normal force
(2.69) is augmented with the estimated parameters as random-walk states (4.1), default
``p = [m_veh, μ38, μ05, ζ]``; its outputs are the measured speeds (3.31), optionally with the
wheel acceleration (3.32). The library (:mod:`gearsym.symbolic.observability`) differentiates
the outputs along the dynamics (4.4), decides the generic rank of ``Q`` (4.7) exactly ((4.12); a
full-rank verdict carries a witness, a deficient one an error bound) and searches the sets where
the rank drops (:func:`~gearsym.symbolic.observability.find_rank_drops`), following each drop to
higher orders (4.13). This module parses the options, builds the shift model, calls the
library and prints the report; it does no analysis of its own.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NoReturn, TextIO

from gearsym.commands import add_command, emit_json, load
from gearsym.options import number
from gearsym.symbolic.errors import GearsymError

if TYPE_CHECKING:
    import sympy as sp

    from gearsym.commands import Subparsers
    from gearsym.symbolic.description import GearboxDescription
    from gearsym.symbolic.model import Model
    from gearsym.symbolic.observability import ObservabilityResult, PartialResult, RankDrop

#: The shift of thesis chapter 3 and 4 and its parameter vector p of (4.1).
from gearsym.symbolic.defaults import DEFAULT_SHIFT
from gearsym.symbolic.defaults import OBSERVABILITY_PARAMETERS as DEFAULT_PARAMETERS

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
# Input parsing (every bad value is a GearsymError naming the option)
# ---------------------------------------------------------------------------------------------


def _fail(d: GearboxDescription, key: str, reason: str) -> NoReturn:
    raise GearsymError(d.file, key, reason)


def _items(values: Sequence[str] | None) -> list[str]:
    """Repeated options and comma-separated lists, flattened; empty items dropped."""
    out: list[str] = []
    for value in values or ():
        out.extend(part.strip() for part in value.split(",") if part.strip())
    return out


def _parse_expression(
    d: GearboxDescription, key: str, text: str, local: Mapping[str, sp.Symbol]
) -> sp.Expr:
    """An expression in the model's names; unknown names become fresh symbols (checked later)."""
    import sympy as sp
    from sympy.core.function import AppliedUndef
    from sympy.parsing.sympy_parser import parse_expr, standard_transformations

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
    import sympy as sp

    from gearsym.symbolic.model import Variable

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
    from gearsym.symbolic.observability import InputModel

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


def _short(text: str, limit: int = 90) -> str:
    return text if len(text) <= limit else f"{text[: limit - 1]}… ({len(text)} characters)"


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
    from gearsym.symbolic.observability import (
        BudgetExceeded,
        ObservabilityError,
        analyze_observability,
        find_rank_drops,
    )

    started = time.perf_counter()
    try:
        model = shift_model(
            d, shift, with_wheel_acceleration=with_wheel_acceleration, friction_inputs=True
        )
    except GearsymError as err:
        if err.key == "shift":
            raise GearsymError(err.file, "--shift", err.reason) from None
        raise
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
            f"{exc}; sound partial result: {_partial_text(exc.partial)}",
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


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------


def _direction_text(direction: Mapping[str, str]) -> str:
    """A kernel vector in named variables, scaled so that its largest entry is ±1."""
    from fractions import Fraction

    values = {k: Fraction(v) for k, v in direction.items()}
    big = max(abs(v) for v in values.values())
    return ", ".join(f"{k}: {float(v / big):.4g}" for k, v in values.items())


def _order_label(k: int) -> str:
    return "y" if k == 0 else f"y^({k})"


def _drop_lines(drop: RankDrop, label: str, n: int) -> list[str]:
    flag = "" if drop.physical else "  [outside the physical range]"
    lines = [f"{_short(label, 160)}{flag}"]
    if drop.factor is not None and drop.factor not in label:
        lines.append(f"    witness-minor factor: {_short(drop.factor)}")
    lines.append(
        f"    rank {drop.rank} of {n}; not observable: {', '.join(drop.unobservable) or '—'}"
        f"; error bound {drop.error_probability_bound:.1e}"
    )
    for direction in drop.directions:
        lines.append(f"    kernel direction at the point: {_direction_text(direction)}")
    if drop.every_order:
        lines.append(f"    at every order: {drop.every_order}")
    elif drop.rank_by_order:
        by_order = ", ".join(str(r) for r in drop.rank_by_order)
        if drop.restored_at_order is not None:
            lines.append(
                f"    restored by {_order_label(drop.restored_at_order)} "
                f"(rank by order {by_order}): a drop of the truncated Q only, (4.13)"
            )
        else:
            lines.append(
                f"    persists up to {_order_label(len(drop.rank_by_order) - 1)} "
                f"(rank by order {by_order})"
            )
    if drop.note:
        lines.append(f"    {drop.note}")
    return lines


def print_report(report: ObservabilityReport, out: TextIO | None = None) -> None:
    """The human-readable report of ``gearsym observability``."""
    out = out or sys.stdout
    r = report.result
    n = r.n_unknowns

    def say(text: str = "") -> None:
        print(text, file=out)

    say(f"gearsym observability: shift {report.shift} of {report.gearbox} (model {r.model})")
    say(
        f"  unknowns ({n}): states {', '.join(r.states)}; random-walk parameters (4.1) "
        f"{', '.join(r.estimated_parameters) or '—'}"
    )
    say(f"  outputs: {', '.join(f'{k} = {v}' for k, v in report.output_expressions.items())}")
    say(f"  inputs: {', '.join(f'{k} {v}' for k, v in r.input_models.items())}")
    if r.substituted_parameters:
        fixed = ", ".join(f"{k} = {v}" for k, v in r.substituted_parameters.items())
        say(f"  known parameters at their defaults: {fixed}")
    if r.generic_parameters:
        say(f"  known parameters kept generic: {', '.join(r.generic_parameters)}")
    if r.conditions:
        say(f"  at: {', '.join(f'{k} = {v}' for k, v in r.conditions.items())}")
    say()
    orders = ", ".join(str(x) for x in r.rank_by_order)
    verdict = "full rank" if r.full_rank else "rank deficient"
    span = "y" if r.max_order == 0 else f"y … {_order_label(r.max_order)}"
    stop = "" if r.stop_reason == "full rank" else f"; {r.stop_reason}"
    say(
        f"rank of Q (4.7) with {span}: {r.rank} of {n} unknowns "
        f"({verdict}; rank by order {orders}{stop})"
    )
    if r.certain:
        assert r.witness is not None
        say(
            f"  proof: a nonzero {len(r.witness.rows)}×{len(r.witness.rows)} minor (rows "
            f"{', '.join(r.witness.rows)}) at a rational point, re-verified exactly; "
            "error probability 0"
        )
    else:
        say(
            f"  rank decided at {r.trials} random point(s) mod 2^61-1 and over the rationals; "
            f"probability that this or a per-variable verdict is wrong <= "
            f"{r.error_probability_bound:.2e}"
        )
    for name in r.unknowns:
        kind = "state" if name in r.states else "parameter"
        ok = "observable" if r.observable[name] else "NOT observable"
        say(f"  {name:<12} {kind:<10} {ok}")
    if r.unobservable_directions:
        for direction in r.unobservable_directions:
            say(f"  kernel direction at the point: {_direction_text(direction)}")
    else:
        say("  kernel: {0} — no unobservable direction")
    if report.drop_search:
        say()
        confirmed = report.confirmed_drops
        say(
            f"where the rank drops (Q up to {_order_label(r.max_order)} as in the verdict above; "
            "each drop is an exact rank at a point on the set):"
        )
        if not confirmed:
            say("  no tested set lowers the rank")
        for i, drop in enumerate(confirmed, start=1):
            lines = _drop_lines(drop, report.label(drop), n)
            say(f"  {i}. {lines[0]}")
            for line in lines[1:]:
                say(f"  {line}")
        kept = [report.label(d) for d in report.drops if d.decided and not d.confirmed]
        if kept:
            say(f"  rank stays {r.rank}: {'; '.join(_short(k, 60) for k in kept)}")
        if report.implied:
            say(f"  inside a set that already drops, not tested: {'; '.join(report.implied)}")
        for drop in report.drops:
            if not drop.decided:
                say(f"  not decided: {report.label(drop)}: {drop.note}")
        for note in report.notes:
            say(f"  note: {_short(note, 160)}")
    t = report.timings
    say()
    say(
        f"time: model {t['model']:.2f} s, Lie derivatives {t['lie_derivatives']:.2f} s, "
        f"rank {t['rank']:.3f} s, drop search {t['drop_search']:.2f} s, total {t['total']:.2f} s"
        f" (seed {r.seed})"
    )


def _partial_text(partial: PartialResult) -> str:
    if partial.orders_completed < 0:
        return f"no derivative order completed, rank >= 0 of {partial.n_unknowns}"
    orders = ", ".join(str(x) for x in partial.rank_by_order)
    return (
        f"rank of Q >= {partial.rank_lower_bound} of {partial.n_unknowns} with derivatives up "
        f"to {_order_label(partial.orders_completed)} (rank by order {orders}; (4.13))"
    )


def _partial_dict(partial: PartialResult) -> dict[str, Any]:
    return {"partial": partial.to_dict()}


# ---------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------


def cmd_observability(args: argparse.Namespace) -> int:
    """``gearsym observability``: verdict (4.12), per-variable observability, rank drops."""
    d = load(args.config)
    try:
        report = analyze_shift(
            d,
            args.shift,
            params=None if args.params is None else _items([args.params]),
            outputs=_items(args.outputs) or None,
            with_wheel_acceleration=args.with_wheel_acceleration,
            input_models=_items(args.input_model),
            conditions=_items(args.at),
            max_order=args.max_order,
            symbolic_known=args.symbolic_known,
            drop_search=not args.no_drop_search,
            factor_minor=not args.no_factor,
            seed=args.seed,
            time_budget=args.time_budget,
            size_budget=args.size_budget,
        )
    except GearsymError as err:
        partial = getattr(err, "partial", None)
        if partial is not None:
            if args.json:
                emit_json(_partial_dict(partial))
            else:
                print(f"partial result (sound): {_partial_text(partial)}; {partial.reason}")
            sys.stdout.flush()
        raise
    if args.json:
        emit_json(report.to_dict())
    else:
        print_report(report)
    return 0


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``observability``."""
    p = add_command(
        subparsers,
        "observability",
        cmd_observability,
        "Lie-derivative observability of a shift model (thesis 4.1-4.13) and where its rank drops.",
        common,
    )
    p.add_argument("--shift", default=DEFAULT_SHIFT, help="FROM-TO gears (default 2-3)")
    p.add_argument(
        "--params",
        default=None,
        help="estimated parameters, comma-separated (default m_veh, the mu of the two swapping "
        f"elements, zeta: {','.join(DEFAULT_PARAMETERS)} for 2-3 as in (4.1); '' for none)",
    )
    p.add_argument(
        "--outputs",
        action="append",
        help="outputs: model output names (y_omega_1), expressions in states/inputs/parameters, "
        "or NAME=EXPR; comma-separated or repeated (default (3.31))",
    )
    p.add_argument(
        "--with-wheel-acceleration",
        action="store_true",
        help="also measure the wheel acceleration, outputs (3.32)",
    )
    p.add_argument(
        "--input-model",
        action="append",
        metavar="NAME=generic|constant|poly:K",
        help="excitation of an input (NAME 'all' for every input); repeatable",
    )
    p.add_argument(
        "--at",
        action="append",
        metavar="NAME=VALUE",
        help="point restriction at the instant, e.g. zeta=0 or omega_C=0 (to hold an input "
        "over time, also give it --input-model NAME=constant; a known parameter named here is "
        "not fixed at its default); repeatable",
    )
    p.add_argument(
        "--max-order",
        type=number(int),  # negative: analyze_shift's one-line error (it checks API calls too)
        default=None,
        help="rank every derivative order up to N (default: grow until full rank or no gain, "
        "at most n-1)",
    )
    p.add_argument(
        "--symbolic-known",
        action="store_true",
        help="keep the known parameters as generic symbols instead of their defaults",
    )
    p.add_argument("--no-drop-search", action="store_true", help="generic verdict only")
    p.add_argument(
        "--no-factor",
        action="store_true",
        help="skip factoring the witness minor (test only inputs held at zero or constant)",
    )
    p.add_argument("--seed", type=number(int), default=None, help="seed of the random points")
    p.add_argument(
        "--time-budget",
        type=number(float, above=0),
        default=None,
        help="seconds for the verdict (exceeded: partial result, exit 2) and for each drop check "
        "(exceeded: reported as not decided)",
    )
    p.add_argument(
        "--size-budget",
        type=number(int, minimum=1),
        default=None,
        help="operations per derivative order",
    )
    p.add_argument("--json", action="store_true", help="machine-readable report")


def print_observability_summary(
    d: GearboxDescription, shift: str = DEFAULT_SHIFT, out: TextIO | None = None
) -> None:
    """Short verdict for ``gearsym run``: generic rank of (4.12) and the structural drops."""
    out = out or sys.stdout
    try:
        report = analyze_shift(d, shift, factor_minor=False, seed=0)
    except GearsymError as err:
        print(f"observability of the {shift} shift: skipped ({err.key}: {err.reason})", file=out)
        return
    r = report.result
    proof = (
        "proved by a nonzero minor" if r.certain else f"error <= {r.error_probability_bound:.1e}"
    )
    print(
        f"Observability of the {shift} shift (4.1)-(4.12), "
        f"p = [{', '.join(r.estimated_parameters)}], "
        f"outputs {', '.join(report.output_expressions)}:",
        file=out,
    )
    print(
        f"  generic rank of Q with y … {_order_label(r.max_order)}: {r.rank} of {r.n_unknowns}"
        f" ({proof}); not observable: {', '.join(r.unobservable) or 'none'}"
        f"  [{report.timings['total']:.1f} s]",
        file=out,
    )
    drops = report.confirmed_drops
    if drops:
        print(
            f"  (4.12) 'rank {r.n_unknowns} for all operating points and inputs' fails where:",
            file=out,
        )
    for drop in drops:
        if drop.every_order:
            fate = "at every order"
        elif drop.restored_at_order is not None:
            fate = f"restored by {_order_label(drop.restored_at_order)}"
        else:
            fate = f"persists up to {_order_label(len(drop.rank_by_order) - 1)}"
        print(
            f"    {report.label(drop)}: rank {drop.rank}, not observable "
            f"{', '.join(drop.unobservable)} ({fate})",
            file=out,
        )
    print(
        f"  details, and the zero sets of the witness minor: gearsym observability --shift {shift}",
        file=out,
    )
