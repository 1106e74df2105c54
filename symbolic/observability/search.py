"""The drop search of (4.12): which sets lower the rank of ``Q`` (4.7), and at which orders.

The one search of the package (the ``gearsym observability`` report calls it too); what it
proposes and how it decides is described in :mod:`.drops`.
"""

from __future__ import annotations

import itertools
import random
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace

import symengine as se
import sympy as sp
from gearsym.symbolic.observability.drops import (
    GROWTH,
    MAX_SUBSET_INPUTS,
    DropSearch,
    RankDrop,
    RankDropReport,
    is_physical,
    rank_under_conditions,
    set_label,
)
from gearsym.symbolic.observability.errors import (
    BudgetExceeded,
    SamplingError,
    UnsupportedExpressionError,
)
from gearsym.symbolic.observability.exact import exact_rational
from gearsym.symbolic.observability.lie import order_label
from gearsym.symbolic.observability.minor import minor_factors, minor_vanishes_on, preference
from gearsym.symbolic.observability.rank import ObservabilityResult

_UNDECIDED = (BudgetExceeded, SamplingError, UnsupportedExpressionError)
_Key = tuple[tuple[tuple[str, str], ...], tuple[tuple[str, str], ...]]


def _key(conditions: Mapping[str, str], models: Mapping[str, str]) -> _Key:
    return (tuple(sorted(conditions.items())), tuple(sorted(models.items())))


def minor_candidates(
    result: ObservabilityResult,
    rng: random.Random,
    *,
    factor: bool,
    lines: bool,
    symbolic_ops_limit: int,
    factor_terms_limit: int,
    notes: list[str],
) -> list[tuple[dict[str, str], str, str | None]]:
    """Sets where the witness minor of ``result`` vanishes: ``(conditions, origin, factor)``.

    If the minor is small (total ``count_ops`` of its entries at most ``symbolic_ops_limit``)
    it is factored symbolically and each factor linear in some variable gives a substitution
    (``factor``). With ``lines``, the minor is evaluated along lines parallel to each
    coordinate axis at the point ``variable = 0``; where it vanishes, that hyperplane is a
    candidate (this works however large the minor is).
    """
    session, ranked, wit = result.session, result.ranked, result.witness
    if session is None or ranked is None or wit is None:
        raise ValueError("the result carries no session or witness")
    symbols = session.symbols
    minor = [[ranked.rows[i][j] for j in wit.column_indices] for i in wit.row_indices]
    out: list[tuple[dict[str, str], str, str | None]] = []
    if not minor:
        return out
    if factor:
        cache: dict[se.Basic, sp.Expr] = {}
        symbolic = [[symbols.to_sympy(e, cache) for e in row] for row in minor]
        ops = sum(sp.count_ops(e) for row in symbolic for e in row)
        if ops <= symbolic_ops_limit:
            for fac, sol in minor_factors(symbols, symbolic, factor_terms_limit, notes):
                if sol is None:
                    notes.append(f"factor {fac}: no variable occurs linearly; not tested")
                    continue
                var, value = sol
                out.append(({symbols.variable(var): str(value)}, "witness-minor factor", str(fac)))
        else:
            notes.append(
                f"witness minor too large to factor ({ops} > {symbolic_ops_limit} operations); "
                "only coordinate hyperplanes were tested"
            )
    if lines:
        variables = sorted(
            {s for row in minor for e in row for s in e.free_symbols},
            key=lambda s: preference(symbols, s.name),
        )
        for var in variables:
            if minor_vanishes_on(minor, var, rng, symbols.angles):
                out.append(({symbols.variable(var): "0"}, "witness-minor zero", None))
    return out


class _Search:
    """Checks candidate sets against the verdict ``baseline`` and follows each confirmed drop
    to higher derivative orders (4.4), (4.13)."""

    def __init__(
        self,
        baseline: ObservabilityResult,
        rng: random.Random,
        time_budget: float | None,
        follow_orders: bool,
        higher_order_seconds: float,
    ) -> None:
        assert baseline.session is not None
        self.baseline = baseline
        self.session = baseline.session
        self.rng = rng
        self.time_budget = time_budget
        self.follow_orders = follow_orders
        self.higher_order_seconds = higher_order_seconds
        self.top_order = max(baseline.max_order, baseline.n_unknowns - 1)
        #: (drop, the full-rank result at a higher order that repairs it)
        self.restoring: list[tuple[RankDrop, ObservabilityResult]] = []

    def rank(
        self, conditions: Mapping[str, str], models: Mapping[str, str], order: int
    ) -> RankDropReport:
        return rank_under_conditions(
            self.baseline,
            conditions,
            models,
            max_order=order,
            seed=self.rng.randrange(2**63),
            time_budget=self.time_budget,
        )

    def check(
        self,
        origin: str,
        conditions: Mapping[str, str],
        models: Mapping[str, str],
        factor: str | None = None,
        label: str | None = None,
    ) -> RankDrop:
        """Exact rank on the set at the verdict's orders; a drop is then followed."""
        base = self.baseline
        drop = RankDrop(
            label=label or set_label(conditions, models, base.inputs, factor),
            origin=origin,
            conditions=dict(conditions),
            input_models=dict(models),
            factor=factor,
            confirmed=False,
            decided=False,
            rank=None,
            physical=is_physical(self.session.model, conditions),
        )
        t0 = time.perf_counter()
        try:
            report = self.rank(conditions, models, base.max_order)
        except _UNDECIDED as exc:
            return replace(drop, note=f"not decided: {exc}")
        check_seconds = time.perf_counter() - t0
        drop = replace(
            drop,
            decided=True,
            rank=report.rank,
            confirmed=report.rank < base.rank,
            unobservable=report.unobservable,
            directions=report.result.unobservable_directions,
            point=dict(report.point),
            error_probability_bound=report.error_probability_bound,
            report=report,
        )
        if not drop.confirmed:
            return drop
        proof = self.every_order(conditions, models, drop.unobservable, report.rank)
        if proof or not self.follow_orders:
            return replace(drop, rank_by_order=report.result.rank_by_order, every_order=proof)
        return self.follow(drop, report, check_seconds)

    def follow(self, drop: RankDrop, report: RankDropReport, seconds: float) -> RankDrop:
        """Add derivative orders one at a time up to ``y^(n-1)`` (4.4): does the drop survive
        (4.13)? The cost grows about fourfold per order with generic inputs, so stop when the
        next order would overrun ``higher_order_seconds`` and say how far it got."""
        base = self.baseline
        by_order = report.result.rank_by_order
        order, spent, last, note = base.max_order, 0.0, seconds, ""
        deeper = report
        while order < self.top_order and by_order[-1] < base.rank:
            if spent + GROWTH * last > self.higher_order_seconds:
                note = (
                    f"checked up to {order_label(order)}; the next order would exceed "
                    f"{self.higher_order_seconds:g} s"
                )
                break
            order += 1
            t0 = time.perf_counter()
            try:
                deeper = self.rank(drop.conditions, drop.input_models, order)
            except _UNDECIDED as exc:
                note = f"orders above {order_label(order - 1)} not checked: {exc}"
                break
            last = time.perf_counter() - t0
            spent += last
            by_order = deeper.result.rank_by_order
        restored = next((k for k, r in enumerate(by_order) if r >= base.rank), None)
        drop = replace(drop, rank_by_order=by_order, restored_at_order=restored, note=note)
        if restored is not None and restored > base.max_order:
            self.restoring.append((drop, deeper.result))
        return drop

    def every_order(
        self,
        conditions: Mapping[str, str],
        models: Mapping[str, str],
        unobservable: Sequence[str],
        rank: int,
    ) -> str:
        """Why the drop holds at *every* derivative order, or ``""`` if that is not shown.

        If every condition fixes a variable without drift (a parameter, or an input held
        constant) at a number, substituting it commutes with the Lie derivatives (4.4): they
        are those of the system with the value substituted. A variable that then no longer
        occurs in f or h has a zero column of ``Q`` at every order; if the rank equals ``n``
        minus the number of such variables it cannot grow either.
        """
        base = self.baseline
        system = self.session.system
        symbols = self.session.symbols
        parameters = set(system.parameter_names) | set(system.generic_parameter_names)
        effective = {**base.input_models, **models}
        held = {**base.conditions, **conditions}
        subs: dict[sp.Symbol, sp.Expr] = {}
        for name, value in held.items():
            try:
                number = exact_rational(value)
            except (TypeError, ValueError):
                return ""
            if name in parameters or (
                name in system.input_names and effective.get(name) == "constant"
            ):
                subs[symbols.resolve(name)] = number
            else:
                return ""
        free: set[sp.Basic] = set()
        for e in (*system.dynamics, *system.outputs):
            free |= e.xreplace(subs).free_symbols
        absent = [n for n in unobservable if symbols.resolve(n) not in free]
        if not absent or len(absent) != len(unobservable) or rank != base.n_unknowns - len(absent):
            return ""
        text = ", ".join(f"{k} = {v}" for k, v in held.items())
        verb, noun = ("does", "its column") if len(absent) == 1 else ("do", "their columns")
        return (
            f"{', '.join(absent)} {verb} not occur in f or h with {text}: {noun} of Q "
            f"{'is' if len(absent) == 1 else 'are'} zero at every order"
        )


def find_rank_drops(
    baseline: ObservabilityResult,
    *,
    inputs: bool = True,
    witness_minor: bool = True,
    lines: bool = True,
    symbolic_ops_limit: int = 3000,
    factor_terms_limit: int = 400,
    follow_orders: bool = True,
    higher_order_seconds: float = 1.0,
    nested: bool = True,
    seed: int | None = None,
    time_budget: float | None = None,
) -> DropSearch:
    """Where does the rank of ``Q`` fall below the rank of ``baseline`` (check of (4.12))?

    Candidates, tested in this order: with ``inputs``, every input held at zero (a clutch that
    is not pressed) and every set of inputs held constant (supersets of a set that already
    drops are implied — holding more inputs constant only specialises ``Q`` — and are not
    tested); with ``witness_minor``, the zero sets of the factors of the witness minor and, with
    ``lines``, the coordinate hyperplanes on which it vanishes (:func:`minor_candidates`);
    with ``nested``, inside each set of constant inputs whose drop higher orders repair, the
    hyperplanes where the repairing minor vanishes. Each is confirmed (or not) by an exact rank
    at the baseline's derivative orders. With ``follow_orders`` each confirmed drop that is not
    shown to hold at every order is re-ranked with one more derivative order at a time up to
    ``y^(n-1)`` (4.4), spending about ``higher_order_seconds`` on it. ``time_budget`` bounds
    each single rank (exceeded: the set is reported as not decided).
    """
    if baseline.session is None or baseline.ranked is None:
        raise ValueError("the baseline result carries no session (was it deserialised?)")
    rng = random.Random(random.SystemRandom().randrange(2**63) if seed is None else seed)
    search = _Search(baseline, rng, time_budget, follow_orders, higher_order_seconds)
    names = list(baseline.inputs)
    drops: list[RankDrop] = []
    implied: list[str] = []
    notes: list[str] = []
    if inputs:
        for name in names:
            drops.append(search.check("input-held-zero", {name: "0"}, {name: "constant"}))
        free = [n for n in names if baseline.input_models.get(n) != "constant"]
        if len(free) <= MAX_SUBSET_INPUTS:
            subsets = [c for k in range(1, len(free) + 1) for c in itertools.combinations(free, k)]
        else:
            subsets = [(n,) for n in free] + [tuple(free)]
        dropping: list[set[str]] = []
        for subset in subsets:
            models = dict.fromkeys(subset, "constant")
            if any(s <= set(subset) for s in dropping):
                implied.append(set_label({}, models, names))
                continue
            drop = search.check("input-constant", {}, models)
            drops.append(drop)
            if drop.confirmed:
                dropping.append(set(subset))
    if witness_minor and baseline.witness is not None:
        # a set already tested with the baseline's models (e.g. F_N05 = 0 with F_N05 already
        # constant: "held at 0" above) is not tested again
        tested = {_key(d.conditions, {**baseline.input_models, **d.input_models}) for d in drops}
        for conditions, origin, fac in minor_candidates(
            baseline,
            rng,
            factor=True,
            lines=lines,
            symbolic_ops_limit=symbolic_ops_limit,
            factor_terms_limit=factor_terms_limit,
            notes=notes,
        ):
            key = _key(conditions, baseline.input_models)
            if key not in tested:
                tested.add(key)
                drops.append(search.check(origin, conditions, {}, fac))
    if nested:
        drops.extend(_nested(search, drops, implied))
    return DropSearch(baseline.rank, tuple(drops), tuple(implied), tuple(notes))


def _nested(search: _Search, drops: list[RankDrop], implied: list[str]) -> list[RankDrop]:
    """Inside a set of constant inputs whose drop higher orders repair, the repairing minor
    may vanish on a coordinate hyperplane (e.g. a level road, zeta = 0): test those sets."""
    out: list[RankDrop] = []
    names = search.baseline.inputs
    for parent, repaired in list(search.restoring):
        if parent.origin not in ("input-held-zero", "input-constant"):
            continue
        for extra, _, _ in minor_candidates(
            repaired,
            search.rng,
            factor=False,  # coordinate hyperplanes only: cheap
            lines=True,
            symbolic_ops_limit=0,
            factor_terms_limit=0,
            notes=[],
        ):
            try:
                inside = rank_under_conditions(repaired, extra, seed=search.rng.randrange(2**63))
            except _UNDECIDED:
                continue
            if not inside.drops:
                continue
            conditions = {**parent.conditions, **extra}
            label = f"{parent.label}, {set_label(extra, {}, names)}"
            if any(
                d is not parent
                and d.confirmed
                and d.conditions.items() <= conditions.items()
                and d.input_models.items() <= parent.input_models.items()
                for d in (*drops, *out)
            ):
                implied.append(label)  # inside another set that already drops
                continue
            out.append(search.check(parent.origin, conditions, parent.input_models, label=label))
    return out


def propose_rank_drop_conditions(
    baseline: ObservabilityResult,
    *,
    symbolic_ops_limit: int = 3000,
    factor_terms_limit: int = 400,
    try_zero: bool = True,
    try_constant_inputs: bool = True,
    seed: int | None = None,
) -> DropSearch:
    """:func:`find_rank_drops` at the verdict's derivative orders only (no following of the
    drops to higher orders, no nested sets); ``try_zero`` tests coordinate hyperplanes,
    ``try_constant_inputs`` the inputs held at zero and held constant."""
    return find_rank_drops(
        baseline,
        inputs=try_constant_inputs,
        lines=try_zero,
        symbolic_ops_limit=symbolic_ops_limit,
        factor_terms_limit=factor_terms_limit,
        follow_orders=False,
        nested=False,
        seed=seed,
    )
