"""``gearsym observability``: Lie-derivative observability of a shift model (thesis 4.1–4.13).

The analysis is the library's (:func:`gearsym.symbolic.observability.analyze_shift`: the
augmented shift model (4.1), the generic rank of ``Q`` (4.7), (4.12) with its witness or error
bound, the sets where the rank drops, each followed to higher orders (4.13)). This module parses
the options, calls it and prints the :class:`~gearsym.symbolic.observability.ObservabilityReport`;
it does no analysis of its own. The library is imported inside the handlers: it loads SymPy and
SymEngine, which the parser must not.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, TextIO

from gearsym.commands import add_command, emit_json, load
from gearsym.options import number

#: The shift of thesis chapter 3 and 4 and its parameter vector p of (4.1).
from gearsym.symbolic.defaults import DEFAULT_SHIFT
from gearsym.symbolic.defaults import OBSERVABILITY_PARAMETERS as DEFAULT_PARAMETERS
from gearsym.symbolic.errors import GearsymError

if TYPE_CHECKING:
    from gearsym.commands import Subparsers
    from gearsym.symbolic.description import GearboxDescription
    from gearsym.symbolic.observability import ObservabilityReport, PartialResult, RankDrop

__all__ = ["cmd_observability", "print_observability_summary", "print_report", "register"]


def _items(values: Sequence[str] | None) -> list[str]:
    """Repeated options and comma-separated lists, flattened; empty items dropped."""
    out: list[str] = []
    for value in values or ():
        out.extend(part.strip() for part in value.split(",") if part.strip())
    return out


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------


def _short(text: str, limit: int = 90) -> str:
    return text if len(text) <= limit else f"{text[: limit - 1]}… ({len(text)} characters)"


def _direction_text(direction: Mapping[str, str]) -> str:
    """A kernel vector in named variables, scaled so that its largest entry is ±1."""
    from fractions import Fraction

    values = {k: Fraction(v) for k, v in direction.items()}
    big = max(abs(v) for v in values.values())
    return ", ".join(f"{k}: {float(v / big):.4g}" for k, v in values.items())


def _drop_lines(drop: RankDrop, label: str, n: int) -> list[str]:
    from gearsym.symbolic.observability import order_label

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
                f"    restored by {order_label(drop.restored_at_order)} "
                f"(rank by order {by_order}): a drop of the truncated Q only, (4.13)"
            )
        else:
            lines.append(
                f"    persists up to {order_label(len(drop.rank_by_order) - 1)} "
                f"(rank by order {by_order})"
            )
    if drop.note:
        lines.append(f"    {drop.note}")
    return lines


def print_report(report: ObservabilityReport, out: TextIO | None = None) -> None:
    """The human-readable report of ``gearsym observability``."""
    from gearsym.symbolic.observability import order_label

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
    span = "y" if r.max_order == 0 else f"y … {order_label(r.max_order)}"
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
            f"where the rank drops (Q up to {order_label(r.max_order)} as in the verdict above; "
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


def _partial_dict(partial: PartialResult) -> dict[str, Any]:
    return {"partial": partial.to_dict()}


# ---------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------


def cmd_observability(args: argparse.Namespace) -> int:
    """``gearsym observability``: verdict (4.12), per-variable observability, rank drops."""
    from gearsym.symbolic.observability import analyze_shift, partial_text

    d = load(args.config)
    if args.per_mode:
        return _per_mode(d, args)
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
                print(f"partial result (sound): {partial_text(partial)}; {partial.reason}")
            sys.stdout.flush()
        raise
    if args.json:
        emit_json(report.to_dict())
    else:
        print_report(report)
    return 0


def _per_mode(d: GearboxDescription, args: argparse.Namespace) -> int:
    """``observability --per-mode``: the verdict (4.12) of every mode of the hybrid shift
    (gearsym.symbolic.observability.modes), each with what is excluded and why."""
    from gearsym.symbolic.observability.modes import analyze_modes

    for option, given in (
        ("--outputs", args.outputs),
        ("--with-wheel-acceleration", args.with_wheel_acceleration),
        ("--max-order", args.max_order is not None),
        ("--size-budget", args.size_budget is not None),
    ):
        if given:
            raise GearsymError("observability", option, "not available with --per-mode")
    modes = analyze_modes(
        d,
        args.shift,
        params=None if args.params is None else _items([args.params]),
        input_models=_items(args.input_model),
        conditions=_items(args.at),
        symbolic_known=args.symbolic_known,
        seed=args.seed,
        time_budget=args.time_budget,
    )
    if args.json:
        emit_json(
            {
                "gearbox": d.name,
                "file": d.file,
                "shift": args.shift,
                "equations": "thesis (4.1)-(4.12) per mode of the hybrid shift model; (3.14) "
                "only where an element slides; outputs (3.31)",
                "conditions": _items(args.at),
                "input_models": _items(args.input_model),
                "modes": [m.to_dict() for m in modes],
            }
        )
        return 0
    conditions = ", ".join(_items(args.at)) or "none"
    print(
        f"Observability per mode of the hybrid {args.shift} shift (4.1)-(4.12), outputs: the "
        f"measured speeds (3.31); point conditions: {conditions}"
    )
    for m in modes:
        status = ", ".join(f"{e} {s}" for e, s in m.status.items())
        proof = (
            "proved by a nonzero minor"
            if m.result.certain
            else f"error <= {m.result.error_probability_bound:.1e}"
        )
        print(f"== {m.mode} ({status})")
        print(
            f"   x = [{', '.join(m.states)}], p = [{', '.join(m.estimated)}]: rank "
            f"{m.rank} of {m.n_unknowns} ({proof}); not observable: "
            f"{', '.join(m.unobservable) or 'none'}"
        )
        for direction in m.result.unobservable_directions:
            print(f"   unobservable direction: {_direction_text(direction)}")
        for name, reason in m.excluded.items():
            print(f"   {name} excluded: {reason}")
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
        f"elements, zeta: {','.join(DEFAULT_PARAMETERS)} for 2-3 as in (4.1); '' for none; "
        "input_torque_gain: the input torque as told times an unknown gain)",
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
    p.add_argument(
        "--per-mode",
        action="store_true",
        help="rank every mode of the hybrid shift model (locked/sliding/open per swapping "
        "element) on its own; a mu of an element that does not slide is excluded there",
    )


def print_observability_summary(
    d: GearboxDescription, shift: str = DEFAULT_SHIFT, out: TextIO | None = None
) -> None:
    """Short verdict for ``gearsym run``: generic rank of (4.12) and the structural drops."""
    from gearsym.symbolic.observability import analyze_shift, order_label

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
        f"  generic rank of Q with y … {order_label(r.max_order)}: {r.rank} of {r.n_unknowns}"
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
            fate = f"restored by {order_label(drop.restored_at_order)}"
        else:
            fate = f"persists up to {order_label(len(drop.rank_by_order) - 1)}"
        print(
            f"    {report.label(drop)}: rank {drop.rank}, not observable "
            f"{', '.join(drop.unobservable)} ({fate})",
            file=out,
        )
    print(
        f"  details, and the zero sets of the witness minor: gearsym observability --shift {shift}",
        file=out,
    )
