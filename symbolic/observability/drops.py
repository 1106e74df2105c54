"""Where the rank of ``Q`` (4.7) drops: checking claims such as (4.12) "for all operating points
and inputs".

:func:`rank_under_conditions` re-ranks ``Q`` exactly on a set given by point restrictions and
input models. :func:`find_rank_drops` is the drop search: it proposes sets — every input held
at zero (an element not pressed), every set of inputs held constant, the zero sets of the
factors of the witness minor and the coordinate hyperplanes on which that minor vanishes
(:mod:`.minor`), and, inside a set of constant inputs whose drop higher orders repair, the
hyperplanes where the repairing minor vanishes — and confirms each by an exact rank at a point
on the set, with ``Q`` up to the verdict's derivative order. A confirmed drop is then told
apart from a drop of the truncated ``Q`` only: when the set fixes drift-free variables at
numbers and the unobservable variables then leave ``f`` and ``h``, their columns of ``Q``
vanish at every order (exact); otherwise derivative orders are added up to ``y^(n-1)`` (4.4),
(4.13), one at a time. The candidates are not the complete drop locus (that is where *every*
maximal minor vanishes); the result says what was tested.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import sympy as sp
from gearsym.symbolic.model import Model
from gearsym.symbolic.observability.lie import Budget
from gearsym.symbolic.observability.rank import ObservabilityResult, decide_rank
from gearsym.symbolic.observability.session import check_unchained

#: Input-constant combinations are tested for every subset up to this many inputs; beyond, only
#: single inputs and all inputs together.
MAX_SUBSET_INPUTS = 4
#: Growth of the cost per derivative order when a drop is followed (generic inputs: ~4x).
GROWTH = 4.0


@dataclass(frozen=True)
class RankDropReport:
    """Exact rank of ``Q`` on a condition set compared with the generic rank.

    ``rank`` is computed with the same derivative orders as the baseline (unless a larger
    ``max_order`` was asked for). ``drops`` is exact *at* ``point`` (exact rational rank there);
    that the rank drops on the whole set (generically on it) holds with error probability at
    most ``error_probability_bound``. If the rank does not drop, the witness of ``result``
    proves it (``certain``).
    """

    conditions: dict[str, str]
    input_models: dict[str, str]
    baseline_rank: int
    rank: int
    max_order: int
    drops: bool
    certain: bool
    point: dict[str, str]
    error_probability_bound: float
    unobservable: tuple[str, ...]
    result: ObservabilityResult = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {
            "conditions": dict(self.conditions),
            "input_models": dict(self.input_models),
            "baseline_rank": self.baseline_rank,
            "rank": self.rank,
            "max_order": self.max_order,
            "drops": self.drops,
            "certain": self.certain,
            "point": dict(self.point),
            "error_probability_bound": self.error_probability_bound,
            "unobservable": list(self.unobservable),
            "result": self.result.to_dict(),
        }


def rank_under_conditions(
    baseline: ObservabilityResult,
    conditions: Mapping[str, Any] | None = None,
    input_models: Mapping[str, Any] | None = None,
    *,
    max_order: int | None = None,
    seed: int | None = None,
    size_budget: int | None = None,
    time_budget: float | None = None,
) -> RankDropReport:
    """Recompute the exact rank on a set given by conditions and/or input models.

    ``conditions`` are point restrictions as in :func:`.rank.analyze_observability`, added to
    (and overriding) the baseline's own conditions; ``input_models`` override the baseline's
    per input (e.g. ``{"u": "constant"}`` together with ``conditions={"u": 0}`` holds ``u`` at
    zero). The derivative orders are those of the baseline (``max_order`` may raise them, to
    see whether more derivatives restore the rank). The Lie derivatives (4.4) come from the
    baseline's session, computed once per set of input models.
    """
    session, ranked = baseline.session, baseline.ranked
    if session is None or ranked is None:
        raise ValueError("the baseline result carries no session (was it deserialised?)")
    models = session.with_overrides(ranked.input_models, input_models)
    merged = dict(ranked.conditions)
    merged.update(session.parse_conditions(conditions))
    check_unchained(merged)
    result = decide_rank(
        session,
        models,
        merged,
        max_order=baseline.max_order if max_order is None else max_order,
        patience=None,
        budget=Budget(size_budget, time_budget),
        seed=seed,
    )
    drops = result.rank < baseline.rank
    witness_point = result.witness.point if result.witness else {}
    return RankDropReport(
        conditions=dict(result.conditions),
        input_models=dict(result.input_models),
        baseline_rank=baseline.rank,
        rank=result.rank,
        max_order=result.max_order,
        drops=drops,
        certain=result.certain and baseline.certain,
        point=result.kernel_point if drops else witness_point,
        error_probability_bound=result.error_probability_bound,
        unobservable=result.unobservable,
        result=result,
    )


@dataclass(frozen=True)
class RankDrop:
    """One tested set where the rank of ``Q`` (4.7) may fall below the generic rank.

    ``origin``: ``input-held-zero``, ``input-constant``, ``witness-minor factor`` (a factor of
    the witness minor set to zero) or ``witness-minor zero`` (a coordinate hyperplane on which
    the minor vanishes). ``confirmed`` means the exact rank at a point on the set (``point``)
    is ``rank`` < the generic rank, with ``Q`` up to the verdict's derivative order; that it is
    the generic rank on the whole set holds with error probability at most
    ``error_probability_bound``. ``every_order`` states why the drop holds at every derivative
    order (exact), if that was shown. Otherwise ``rank_by_order`` is the rank on the set by
    derivative order, up to ``y^(n-1)`` (4.4) or as far as the time allowed (``note``):
    ``restored_at_order`` is the first order reaching the generic rank (a drop of the truncated
    ``Q`` only, (4.13)), ``None`` if none did. ``physical`` is false when a condition puts a
    positive quantity (mass, μ) at a value <= 0. ``report`` is the exact rank on the set at
    the verdict's orders (``None`` if not ``decided``).
    """

    label: str
    origin: str
    conditions: dict[str, str]
    input_models: dict[str, str]
    factor: str | None
    confirmed: bool
    decided: bool
    rank: int | None
    unobservable: tuple[str, ...] = ()
    directions: tuple[dict[str, str], ...] = ()
    point: dict[str, str] = field(default_factory=dict)
    error_probability_bound: float = 0.0
    physical: bool = True
    rank_by_order: tuple[int, ...] = ()
    restored_at_order: int | None = None
    every_order: str = ""
    note: str = ""
    report: RankDropReport | None = field(default=None, repr=False, compare=False)

    @property
    def persists(self) -> bool:
        """The drop survives every derivative order checked (``every_order``: all orders)."""
        if not self.confirmed:
            return False
        return bool(self.every_order) or (
            bool(self.rank_by_order) and self.restored_at_order is None
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "origin": self.origin,
            "conditions": dict(self.conditions),
            "input_models": dict(self.input_models),
            "factor": self.factor,
            "confirmed": self.confirmed,
            "decided": self.decided,
            "rank": self.rank,
            "unobservable": list(self.unobservable),
            "unobservable_directions": [dict(v) for v in self.directions],
            "point": dict(self.point),
            "error_probability_bound": self.error_probability_bound,
            "physical": self.physical,
            "rank_by_order": list(self.rank_by_order),
            "restored_at_order": self.restored_at_order,
            "persists": self.persists,
            "every_order": self.every_order,
            "note": self.note,
        }


@dataclass(frozen=True)
class DropSearch:
    """Result of :func:`find_rank_drops`: every tested set in test order, the sets inside a set
    that already drops (implied, not tested), and notes on what was not tried."""

    baseline_rank: int
    candidates: tuple[RankDrop, ...]
    implied: tuple[str, ...]
    notes: tuple[str, ...]

    @property
    def confirmed(self) -> tuple[RankDrop, ...]:
        return tuple(c for c in self.candidates if c.confirmed)

    def to_dict(self) -> dict[str, Any]:
        return {
            "baseline_rank": self.baseline_rank,
            "candidates": [c.to_dict() for c in self.candidates],
            "implied": list(self.implied),
            "notes": list(self.notes),
        }


def describe_factor(factor: str) -> str:
    """``(N terms in a, b, c)`` for a long polynomial given as text."""
    names = sorted(set(re.findall(r"[A-Za-z_][A-Za-z_0-9]*", factor)) - {"sin", "cos"})
    # names such as zeta must stay symbols (sympify would read the Riemann zeta function)
    expr = sp.sympify(factor, locals={n: sp.Symbol(n) for n in names})
    return f"({len(sp.Add.make_args(sp.expand(expr)))} terms in {', '.join(names)})"


def set_label(
    conditions: Mapping[str, str],
    input_models: Mapping[str, str],
    inputs: Sequence[str],
    factor: str | None = None,
) -> str:
    """``F_N05 held at 0``, ``F_N38 and F_N05 constant, zeta = 0``, ``all inputs constant``."""
    held = [n for n in inputs if n in conditions and input_models.get(n) == "constant"]
    parts = [f"{n} held at {conditions[n]}" for n in held]
    by_model: dict[str, list[str]] = {}
    for n in inputs:
        if n in input_models and n not in held:
            by_model.setdefault(input_models[n], []).append(n)
    for model, names in by_model.items():
        whole = len(names) == len(inputs) > 1 and model == "constant"
        parts.append("all inputs constant" if whole else f"{' and '.join(names)} {model}")
    rest = {k: v for k, v in conditions.items() if k not in held}
    text = ", ".join(f"{k} = {v}" for k, v in rest.items())
    if len(text) > 90 and factor is not None and len(rest) == 1:
        (var,) = rest
        text = f"{var} = root of the witness-minor factor {describe_factor(factor)}"
    if text:
        parts.append(text)
    return ", ".join(parts)


def is_physical(model: Model, conditions: Mapping[str, str]) -> bool:
    """False when a condition puts a quantity declared positive at a number <= 0."""
    symbols = {v.name: v.symbol for v in (*model.states, *model.inputs, *model.parameters)}
    for name, value in conditions.items():
        sym = symbols.get(name)
        if sym is None or not sym.is_positive:
            continue
        try:
            number = sp.sympify(value, locals={k: sp.Symbol(k) for k in symbols})
        except Exception:  # anything unparsable is no number, hence no range violation
            continue
        if number.is_number and bool(number <= 0):
            return False
    return True
