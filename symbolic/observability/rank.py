"""The rank decision of (4.7), (4.12): is ``Q`` of full rank, and if not, what is its kernel?

Every entry of ``Q`` is a rational function of the *sample variables* (unknowns, inputs and
their derivatives, parameters that are neither estimated nor substituted). A point ``a`` is
drawn uniformly from ``{0, ..., P-1}^m`` with ``P = 2^61 - 1`` (:mod:`.exact`).

1. *Screening, mod P.* ``Q(a) mod P`` is row-reduced block by block (one block per derivative
   order (4.4)); the rank mod P at a point is never larger than the rank over Q at that point,
   which is never larger than the generic rank, so every screening rank is a sound lower bound
   (and by (4.13) so is the rank of the first blocks).
2. *Full rank.* If the screening rank is ``n``, the pivot rows give a nonzero ``n x n`` minor
   mod P, hence a nonzero minor over the rationals at ``a``, hence full generic rank — a proof.
   The minor is re-evaluated in exact rational arithmetic (:class:`RankWitness`).
3. *Rank deficiency.* Otherwise ``Q(a)`` is evaluated exactly over the rationals (to rule out an
   unlucky prime) at ``k`` independent points; rank, kernel and per-variable verdicts come from
   those exact matrices, with the Schwartz–Zippel bound of :mod:`.bounds`.

What is *not* covered by that bound: the stopping rule for the derivative order (stop when a
full block adds no rank at the screening point, or at ``max_order``). For autonomous systems a
block that adds no generic rank ends the growth; with input derivatives as free variables this
is the usual heuristic. The verdict is therefore always stated for ``Q`` up to the reported
``max_order``; pass ``patience=None`` to rank all orders up to ``max_order``.
"""

from __future__ import annotations

import random
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import symengine as se
import sympy as sp
from gearsym.symbolic.model import Model
from gearsym.symbolic.observability.bounds import DegreeBounds, per_trial_error, trials_needed
from gearsym.symbolic.observability.errors import (
    BudgetExceeded,
    BudgetHit,
    PartialResult,
    ZeroDenominator,
)
from gearsym.symbolic.observability.exact import (
    MODULUS,
    Echelon,
    Evaluator,
    Point,
    Sampler,
    integer_vector,
)
from gearsym.symbolic.observability.lie import Budget, LieEngine, row_label
from gearsym.symbolic.observability.session import (
    DEFAULT_MAX_ERROR,
    ObservabilitySession,
    RankedMatrix,
    RankSettings,
)
from gearsym.symbolic.observability.system import InputModel, augment, parse_input_models
from sympy.polys.domains import QQ
from sympy.polys.matrices import DomainMatrix


@dataclass(frozen=True)
class RankWitness:
    """A point and a nonzero minor of ``Q`` there: proves ``generic rank >= len(rows)``.

    ``point`` maps variable names to exact values (angles as ``2*atan(t)``); ``rows`` and
    ``columns`` name the minor; ``determinant`` is its exact rational value, ``verified`` says
    it was recomputed in exact rational arithmetic and is nonzero.
    """

    point: dict[str, str]
    rows: tuple[str, ...]
    row_indices: tuple[int, ...]
    columns: tuple[str, ...]
    column_indices: tuple[int, ...]
    determinant: str
    verified: bool

    def to_dict(self) -> dict[str, Any]:
        return {
            "point": dict(self.point),
            "rows": list(self.rows),
            "row_indices": list(self.row_indices),
            "columns": list(self.columns),
            "column_indices": list(self.column_indices),
            "determinant": self.determinant,
            "verified": self.verified,
        }


@dataclass(frozen=True)
class ObservabilityResult:
    """Verdict of the Lie-derivative rank test (4.7), (4.12) for one model and setting.

    ``rank`` is the generic rank of ``Q`` with derivatives up to ``max_order``. ``certain`` is
    true for a full-rank verdict (proved by ``witness``); otherwise ``error_probability_bound``
    bounds the chance that the rank or any per-variable verdict is wrong (:mod:`.bounds`).
    ``observable[name]`` is local (weak) observability of a state / local structural
    identifiability of an estimated parameter: the kernel of ``Q`` has no component on it.
    ``unobservable_directions`` is an exact kernel basis at the first maximal-rank point,
    each vector scaled to coprime integers, in named variables (zero entries omitted).
    ``session`` and ``ranked`` (not serialised) are what follow-up questions reuse: the
    model, its cached Lie derivatives, and the ``Q`` that was ranked.
    """

    model: str
    unknowns: tuple[str, ...]
    states: tuple[str, ...]
    estimated_parameters: tuple[str, ...]
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    input_models: dict[str, str]
    generic_parameters: tuple[str, ...]
    substituted_parameters: dict[str, str]
    conditions: dict[str, str]
    n_unknowns: int
    rank: int
    full_rank: bool
    certain: bool
    max_order: int
    rank_by_order: tuple[int, ...]
    stop_reason: str
    observable: dict[str, bool]
    unobservable_directions: tuple[dict[str, str], ...]
    witness: RankWitness | None
    kernel_point: dict[str, str]
    error_probability_bound: float
    degree_bound: int
    denominator_degree_bound: int
    sample_size: int
    trials: int
    seed: int
    timings: dict[str, float]
    session: ObservabilitySession | None = field(default=None, repr=False, compare=False)
    ranked: RankedMatrix | None = field(default=None, repr=False, compare=False)

    @property
    def unobservable(self) -> tuple[str, ...]:
        """Names of the variables that are not locally observable."""
        return tuple(n for n in self.unknowns if not self.observable[n])

    def matrix(self) -> sp.Matrix:
        """The symbolic ``Q`` (4.7) that was ranked (conditions applied), in SymPy."""
        if self.session is None or self.ranked is None:
            return sp.zeros(0, self.n_unknowns)
        cache: dict[se.Basic, sp.Expr] = {}
        to_sympy = self.session.symbols.to_sympy
        rows = [[to_sympy(e, cache) for e in row] for row in self.ranked.rows]
        return sp.Matrix(len(rows), self.n_unknowns, lambda i, j: rows[i][j])

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable dict (SymPy numbers and expressions as strings)."""
        return {
            "model": self.model,
            "unknowns": list(self.unknowns),
            "states": list(self.states),
            "estimated_parameters": list(self.estimated_parameters),
            "outputs": list(self.outputs),
            "inputs": list(self.inputs),
            "input_models": dict(self.input_models),
            "generic_parameters": list(self.generic_parameters),
            "substituted_parameters": dict(self.substituted_parameters),
            "conditions": dict(self.conditions),
            "n_unknowns": self.n_unknowns,
            "rank": self.rank,
            "full_rank": self.full_rank,
            "certain": self.certain,
            "max_order": self.max_order,
            "rank_by_order": list(self.rank_by_order),
            "stop_reason": self.stop_reason,
            "observable": dict(self.observable),
            "unobservable": list(self.unobservable),
            "unobservable_directions": [dict(v) for v in self.unobservable_directions],
            "witness": None if self.witness is None else self.witness.to_dict(),
            "kernel_point": dict(self.kernel_point),
            "error_probability_bound": self.error_probability_bound,
            "degree_bound": self.degree_bound,
            "denominator_degree_bound": self.denominator_degree_bound,
            "sample_size": self.sample_size,
            "trials": self.trials,
            "seed": self.seed,
            "timings": dict(self.timings),
        }


def analyze_observability(
    model: Model,
    estimate: Iterable[str] = (),
    *,
    substitute_defaults: bool | Iterable[str] = False,
    input_models: Mapping[str, str | InputModel] | None = None,
    default_input_model: str = "generic",
    conditions: Mapping[str, Any] | None = None,
    max_order: int | None = None,
    patience: int | None = 1,
    max_error_probability: float = DEFAULT_MAX_ERROR,
    max_trials: int = 8,
    size_budget: int | None = None,
    time_budget: float | None = None,
    seed: int | None = None,
) -> ObservabilityResult:
    """Rank test of the augmented system (4.1) with the observability matrix (4.7).

    Parameters
    ----------
    estimate:
        Parameters appended as random-walk states (4.1).
    substitute_defaults:
        See :func:`.system.augment`; other parameters stay generic (sampled) known values.
    input_models, default_input_model:
        Excitation model per input name (``generic``, ``constant``, ``poly:K``).
    conditions:
        Point restrictions ``{name: value}`` for states, parameters, inputs or input
        derivatives (``u__d1``); values may be numbers or expressions in the other variables.
        They restrict the *point* where ``Q`` is ranked (applied after differentiation). To hold
        an input at a value over time, also give it the ``constant`` model.
    max_order:
        Highest derivative order of the outputs (default ``n - 1`` as in (4.4)); a hard cap.
    patience:
        Stop after this many consecutive derivative orders that add no rank (``None``: never).
    max_error_probability, max_trials:
        Target for the probability bound of a rank-deficient verdict and the trial cap.
    size_budget, time_budget:
        Operations limit per derivative block (SymEngine's ``count_ops``) and wall-time limit
        in seconds; exceeding either raises :class:`.BudgetExceeded` with a partial result.
    seed:
        Seed of the point sampler (``None``: drawn from the OS, recorded in the result).
    """
    system = augment(model, estimate, substitute_defaults=substitute_defaults)
    session = ObservabilitySession(
        model,
        system,
        parse_input_models(system, input_models, default_input_model),
        RankSettings(max_error_probability, max_trials),
    )
    return decide_rank(
        session,
        session.input_models,
        session.parse_conditions(conditions),
        max_order=max_order,
        patience=patience,
        budget=Budget(size_budget, time_budget),
        seed=seed,
    )


@dataclass
class _Screen:
    """State of the mod-P screening: the rows so far and their echelon form at ``point``."""

    point: Point
    evaluator: Evaluator
    echelon: Echelon
    rows: list[list[se.Basic]] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    rank_by_order: list[int] = field(default_factory=list)
    stop_reason: str = ""
    seconds: float = 0.0


def _apply(rows: list[list[se.Basic]], conditions: Mapping[se.Basic, se.Basic]) -> list[list]:
    if not conditions:
        return rows
    return [[e.subs(conditions) for e in row] for row in rows]


def _screen(
    s: _Screen,
    engine: LieEngine,
    conditions: Mapping[se.Basic, se.Basic],
    sampler: Sampler,
    cap: int,
    patience: int | None,
    budget: Budget,
) -> None:
    """Rank ``Q mod P`` block by block (4.4) until full rank, ``patience`` or ``cap``.

    ``s`` is updated in place, so a budget overrun leaves the sound partial ranks in it.
    """
    system = engine.system
    n = system.n_unknowns
    stalled = 0
    k = 0
    while True:
        new_rows = _apply(engine.block(k, budget).jac, conditions)
        started = time.monotonic()
        while True:
            try:
                values = s.evaluator.rows(new_rows)
                break
            except ZeroDenominator:
                # a denominator vanished mod P: redraw and re-screen the earlier blocks
                sampler.reject()
                while True:
                    s.point = sampler.draw()
                    s.evaluator = Evaluator(s.point, exact=False)
                    s.echelon = Echelon(exact=False)
                    try:
                        for idx, vals in enumerate(s.evaluator.rows(s.rows)):
                            s.echelon.add(vals, idx)
                        break
                    except ZeroDenominator:
                        sampler.reject()
        for offset, vals in enumerate(values):
            s.echelon.add(vals, len(s.rows) + offset)
        s.seconds += time.monotonic() - started
        s.rows.extend(new_rows)
        s.labels.extend(row_label(name, k) for name in system.output_names)
        grew = s.echelon.rank > (s.rank_by_order[-1] if s.rank_by_order else 0)
        s.rank_by_order.append(s.echelon.rank)
        budget.check_time(f"ranking order {k}")
        if s.echelon.rank == n:
            s.stop_reason = "full rank"
            return
        stalled = 0 if grew else stalled + 1
        if patience is not None and stalled >= patience:
            s.stop_reason = f"rank did not grow for {stalled} derivative order(s)"
            return
        if k >= cap:
            s.stop_reason = f"maximum derivative order {cap} reached"
            return
        k += 1


def decide_rank(
    session: ObservabilitySession,
    input_models: Mapping[str, InputModel],
    conditions: Mapping[sp.Symbol, sp.Expr],
    *,
    max_order: int | None,
    patience: int | None,
    budget: Budget,
    seed: int | None,
) -> ObservabilityResult:
    """Screen mod P, then prove full rank by a witness or decide a deficiency exactly."""
    started = time.monotonic()
    engine = session.engine(input_models)
    lie_before = engine.seconds
    system = session.system
    symbols = session.symbols
    settings = session.settings
    n = system.n_unknowns
    cap = max(n - 1, 0) if max_order is None else max_order
    if seed is None:
        seed = random.SystemRandom().randrange(2**63)
    sampler = Sampler(random.Random(seed), symbols.angles)
    se_conditions = {se.Symbol(s.name): symbols.to_symengine(v) for s, v in conditions.items()}
    point = sampler.draw()
    s = _Screen(point, Evaluator(point, exact=False), Echelon(exact=False))
    try:
        _screen(s, engine, se_conditions, sampler, cap, patience, budget)
    except BudgetHit as hit:
        ranks = s.rank_by_order
        partial = PartialResult(
            model=system.model_name,
            unknowns=system.unknown_names,
            n_unknowns=n,
            rank_lower_bound=ranks[-1] if ranks else 0,
            orders_completed=len(ranks) - 1,
            rank_by_order=tuple(ranks),
            reason=str(hit),
            elapsed_seconds=time.monotonic() - started,
        )
        raise BudgetExceeded(str(hit), partial) from None
    rows, labels = s.rows, s.labels
    exact_started = time.monotonic()
    col_names = system.unknown_names
    names = symbols.names

    def finish(**verdict: Any) -> ObservabilityResult:
        now = time.monotonic()
        return ObservabilityResult(
            model=system.model_name,
            unknowns=col_names,
            states=system.state_names,
            estimated_parameters=system.parameter_names,
            outputs=system.output_names,
            inputs=system.input_names,
            input_models={name: str(m) for name, m in engine.input_models.items()},
            generic_parameters=system.generic_parameter_names,
            substituted_parameters={name: str(v) for name, v in system.substituted.items()},
            conditions={symbols.variable(k): str(v) for k, v in conditions.items()},
            n_unknowns=n,
            max_order=len(s.rank_by_order) - 1,
            rank_by_order=tuple(s.rank_by_order),
            stop_reason=s.stop_reason,
            sample_size=MODULUS,
            seed=seed,
            timings={
                "lie_derivatives": engine.seconds - lie_before,
                "screening": s.seconds,
                "exact": now - exact_started,
                "total": now - started,
            },
            session=session,
            ranked=RankedMatrix(
                rows=tuple(tuple(r) for r in rows),
                labels=tuple(labels),
                input_models=dict(engine.input_models),
                conditions=dict(conditions),
            ),
            **verdict,
        )

    def witness(pt: Point, vals: list[list[Any]], sel: list[int], cols: list[int]) -> RankWitness:
        # re-verify the minor in exact rational arithmetic (vals are exact rationals)
        sel, cols = sorted(sel), sorted(cols)
        minor = [[vals[i][j] for j in cols] for i in sel]
        det = DomainMatrix(minor, (len(sel), len(cols)), QQ).det() if sel else QQ(1)
        if not det:
            raise AssertionError("a pivot minor must be nonzero over the rationals")
        return RankWitness(
            point=pt.named(names),
            rows=tuple(labels[i] for i in sel),
            row_indices=tuple(sel),
            columns=tuple(col_names[j] for j in cols),
            column_indices=tuple(cols),
            determinant=str(det),
            verified=True,
        )

    def full_rank(pt: Point, vals: list[list[Any]], sel: list[int], trials: int) -> Any:
        return finish(
            rank=n,
            full_rank=True,
            certain=True,
            observable=dict.fromkeys(col_names, True),
            unobservable_directions=(),
            witness=witness(pt, vals, sel, list(range(n))),
            kernel_point={},
            error_probability_bound=0.0,
            degree_bound=0,
            denominator_degree_bound=0,
            trials=trials,
        )

    if s.echelon.rank == n:
        # a nonzero n x n minor mod P proves full generic rank; evaluate its rows exactly
        sel = sorted(s.echelon.rows)
        exact_ev = Evaluator(s.point, exact=True)
        vals = {i: exact_ev.row(rows[i]) for i in sel}
        return full_rank(s.point, [vals.get(i, []) for i in range(len(rows))], sel, 1)

    # -- rank deficient at the screening point: decide in exact rationals at k points ---------
    bounds = DegreeBounds()
    row_degrees = sorted((bounds.row_degree(r) for r in rows), reverse=True)
    d_den = bounds.denominator_degree
    eps = per_trial_error(row_degrees, s.echelon.rank, n, d_den)
    trials = trials_needed(eps, n, settings.max_error_probability, settings.max_trials)
    best: tuple[int, Point, list[list[Any]], Echelon, list[list[Any]]] | None = None
    unobservable: set[int] = set()
    for trial in range(trials):
        if trial == 0:
            pt = s.point
        else:
            while True:
                # the mod-P pass rejects points where a denominator vanishes mod P, which keeps
                # every trial under the same conditioning as the screening point
                pt = sampler.draw()
                try:
                    Evaluator(pt, exact=False).rows(rows)
                    break
                except ZeroDenominator:
                    sampler.reject()
        vals = Evaluator(pt, exact=True).rows(rows)
        ech_q = Echelon(exact=True)
        for idx, row in enumerate(vals):
            ech_q.add(row, idx)
            if ech_q.rank == n:
                return full_rank(pt, vals, list(ech_q.rows), trial + 1)
        kernel = DomainMatrix(vals, (len(vals), n), QQ).nullspace().to_list()
        if best is None or ech_q.rank > best[0]:
            best = (ech_q.rank, pt, vals, ech_q, kernel)
            unobservable = set()
        if ech_q.rank == best[0]:
            unobservable |= {j for vec in kernel for j in range(n) if vec[j]}
    assert best is not None
    rank, pt, vals, ech_q, kernel = best
    directions = []
    for vec in kernel:
        ints = integer_vector(vec)
        directions.append({col_names[j]: str(ints[j]) for j in range(n) if ints[j]})
    eps = per_trial_error(row_degrees, rank, n, d_den)
    return finish(
        rank=rank,
        full_rank=False,
        certain=False,
        observable={c: j not in unobservable for j, c in enumerate(col_names)},
        unobservable_directions=tuple(directions),
        witness=witness(pt, vals, list(ech_q.rows), list(ech_q.pivots)),
        kernel_point=pt.named(names),
        error_probability_bound=min(1.0, (n + 1) * eps**trials),
        degree_bound=sum(row_degrees[: min(rank + 1, n)]),
        denominator_degree_bound=d_den,
        trials=trials,
    )
