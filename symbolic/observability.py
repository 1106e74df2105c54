"""Lie-derivative observability and structural identifiability of any :class:`Model`.

This is the generic engine behind thesis section 4.1 (equations 4.1–4.13):

* **Augmented system (4.1).** Parameters to be estimated are appended to the state vector as
  random walks; in the Lie derivatives their drift is zero (``dp/dt = 0``), exactly as the
  thesis does for ``p = [m_veh, mu38, mu05, zeta]``.
* **Observability map and matrix (4.4)–(4.7), (4.8)–(4.11).** The outputs are differentiated
  along the dynamics; the time derivatives of the inputs ``u, u', u'', ...`` enter as further
  variables (the ``h_k(x, u, u', ..., u^(k))`` of (4.4)). ``Q`` is the Jacobian of the stacked
  derivatives with respect to the (augmented) states (4.7).
* **Rank (4.12), (4.13).** The generic rank of ``Q`` is decided with exact arithmetic at random
  points instead of floating-point rank guesses. A full-rank verdict is a proof: it carries a
  point and a nonzero maximal minor, re-verified in exact rational arithmetic. A rank-deficient
  verdict is probabilistic, with a Schwartz–Zippel bound on the chance that it is wrong.
  (4.13) is why a lower bound computed from the first blocks is sound: adding rows never
  lowers the rank.

How the rank is computed
------------------------
Every entry of ``Q`` is a rational function of the *sample variables* (unknowns, inputs and
their derivatives, parameters that are neither estimated nor substituted), after the model's
float coefficients were made exact (:func:`exact_rational`). A point ``a`` is drawn uniformly
from ``{0, ..., P-1}^m`` with ``P = 2^61 - 1`` (a Mersenne prime).

1. *Screening, mod P.* ``Q(a) mod P`` is row-reduced block by block (one block per derivative
   order); the rank mod P at a point is never larger than the rank over Q at that point, which
   is never larger than the generic rank, so every screening rank is a sound lower bound.
2. *Full rank.* If the screening rank is ``n``, the pivot rows give a nonzero ``n x n`` minor
   mod P, hence a nonzero minor over the rationals at ``a``, hence full generic rank — a proof.
   The minor is re-evaluated in exact rational arithmetic (:class:`RankWitness`).
3. *Rank deficiency.* Otherwise ``Q(a)`` is evaluated exactly over the rationals (to rule out an
   unlucky prime) at ``k`` independent points; rank, kernel and per-variable verdicts come from
   those exact matrices.

The probability bound
---------------------
If the computed rank ``r`` is below the generic rank, some ``(r+1)``-minor ``M`` is a nonzero
rational function that vanishes at every trial point. :class:`_DegreeBounds` bounds, without
expanding anything, each entry of ``Q`` as ``N/D`` where ``D`` is a product of known
"denominator keys" (bases raised to negative powers, and ``1 + t^2`` for angles, see below).
Clearing the row-wise least common multiple of those keys turns row ``i`` into polynomials of
degree at most ``d_i``; a minor on rows ``R`` is then ``det / prod(L_i)`` with ``deg det <=
sum_{i in R} d_i``. So ``D_num`` = sum of the ``r+1`` largest ``d_i`` bounds the degree of the
numerator of every relevant minor. Points at which a denominator vanishes mod P are redrawn;
the denominators have total degree at most ``D_den`` (sum of the numerator-degree bounds of all
inverted bases), so by Schwartz–Zippel one trial misses a nonzero minor with probability at
most ``eps = D_num / (P - D_den)``. The per-variable verdicts are rank statements about ``Q``
with one column removed (minors of size ``r``, same degree bound), so with ``k`` independent
trials and a union bound over the rank and the ``n`` variable verdicts the reported bound is
``(n + 1) * eps^k``. ``k`` is chosen as the smallest number of trials reaching
``max_error_probability`` (default ``1e-9``), at most ``max_trials``.

What is *not* covered by that bound: the stopping rule for the derivative order (stop when a
full block adds no rank at the screening point, or at ``max_order``). For autonomous systems a
block that adds no generic rank ends the growth; with input derivatives as free variables this
is the usual heuristic. The verdict is therefore always stated for ``Q`` up to the reported
``max_order``; pass ``patience=None`` to rank all orders up to ``max_order``.

Non-rational functions
----------------------
``sin(s)``/``cos(s)`` of a single symbol ``s`` (road grade ``zeta`` in (2.49)) are supported:
the point is drawn on the rational parametrisation ``s = 2 atan(t)``, i.e. ``sin s = 2t/(1+t^2)``,
``cos s = (1-t^2)/(1+t^2)`` with ``t`` sampled like any other variable. This is an exact point
of the real domain (``1 + t^2`` never vanishes mod P because ``P = 3 mod 4``), and generic
rank in ``t`` equals generic rank in ``s`` because ``t -> 2 atan t`` is a local diffeomorphism.
Such ``s`` must not appear outside ``sin``/``cos``. ``tan`` is rewritten as ``sin/cos``;
``sin(2s)``, ``sin(s + w)`` are expanded. Anything else (``exp``, ``sqrt``, ``Abs``, ``sign``,
``tanh``, ``Piecewise``, ``pi``) raises :class:`UnsupportedExpressionError`: replace it by its
value on the operating region (e.g. ``sign(slip) = 1`` during a shift phase) first.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import sympy as sp
from gearsym.symbolic.model import Model
from gearsym.symbolic.sympy_utils import smart_jacobian
from sympy.polys.domains import QQ
from sympy.polys.matrices import DomainMatrix

__all__ = [
    "MODULUS",
    "AugmentedSystem",
    "BudgetExceeded",
    "CandidateCondition",
    "DropSearch",
    "InputModel",
    "ObservabilityError",
    "ObservabilityMatrix",
    "ObservabilityResult",
    "PartialResult",
    "RankDropReport",
    "RankWitness",
    "SamplingError",
    "UnsupportedExpressionError",
    "analyze_observability",
    "augment",
    "exact_rational",
    "observability_matrix",
    "propose_rank_drop_conditions",
    "rank_under_conditions",
    "rationalize",
    "smart_jacobian",
]

#: The prime of the screening arithmetic and the size of the sample set ``{0, ..., P-1}``.
#: ``P = 3 (mod 4)``, so ``1 + t^2`` (angle denominators) never vanishes mod P.
MODULUS = 2**61 - 1

_DEFAULT_MAX_ERROR = 1e-9

# ---------------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------------


class ObservabilityError(Exception):
    """Base class of the errors of this module."""


class UnsupportedExpressionError(ObservabilityError, ValueError):
    """The model uses a function that cannot be evaluated exactly at a rational point."""


class SamplingError(ObservabilityError):
    """No point with nonzero denominators was found (the condition set is singular)."""


class BudgetExceeded(ObservabilityError):
    """The size or time budget was exceeded; :attr:`partial` holds the sound lower bound."""

    def __init__(self, message: str, partial: PartialResult) -> None:
        super().__init__(message)
        self.partial = partial


class _BudgetHit(Exception):
    """Internal: raised inside the Lie-derivative engine, turned into :class:`BudgetExceeded`."""


class _ZeroDenominator(Exception):
    """Internal: a denominator vanished at the sampled point; the point must be redrawn."""


# ---------------------------------------------------------------------------------------------
# Exact numbers
# ---------------------------------------------------------------------------------------------


def exact_rational(value: float | str | sp.Basic) -> sp.Rational:
    """The exact rational a model number stands for.

    Python floats and SymPy ``Float`` s of double precision become the rational value of their
    *shortest round-tripping decimal* (``repr``): ``0.405 -> 81/200``, ``0.1 -> 1/10``. That is
    the decimal the author typed; ``sympy.Rational(0.1)`` would instead give the binary value
    ``3602879701896397/36028797018963968``, and ``nsimplify`` may guess constants such as ``pi``
    — neither is wanted. Higher-precision ``Float`` s use their printed decimal digits.
    """
    if isinstance(value, bool):
        raise TypeError("a boolean is not a model number")
    if isinstance(value, int):
        return sp.Integer(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"non-finite number {value!r}")
        return sp.Rational(repr(value))
    if isinstance(value, str):
        return sp.Rational(value)
    value = sp.sympify(value)
    if isinstance(value, sp.Rational):
        return value
    if isinstance(value, sp.Float):
        if value._prec <= 53:
            return sp.Rational(repr(float(value)))
        return sp.Rational(str(value))
    raise TypeError(f"{value!r} is not a number")


def rationalize(expr: sp.Basic) -> sp.Basic:
    """Replace every ``Float`` in ``expr`` by :func:`exact_rational` of it."""
    floats = expr.atoms(sp.Float)
    if not floats:
        return expr
    return expr.xreplace({f: exact_rational(f) for f in floats})


# ---------------------------------------------------------------------------------------------
# Input excitation models
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# Augmented system (4.1)
# ---------------------------------------------------------------------------------------------

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


def _normalize_trig(expr: sp.Expr) -> sp.Expr:
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
        return _normalize_trig(expr)

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


# ---------------------------------------------------------------------------------------------
# Lie derivatives and the observability matrix (4.4)–(4.11)
# ---------------------------------------------------------------------------------------------


@dataclass
class _Block:
    """Derivative order ``k``: ``y^(k) = h_k(x, u, ..., u^(k))`` (4.4) and its Jacobian rows."""

    order: int
    exprs: list[sp.Expr]
    free: list[set[sp.Basic]]
    jac: list[list[sp.Expr]]
    ops: int | None


class _Budget:
    """Size (count_ops of a derivative block) and wall-time limits."""

    def __init__(self, size: int | None, seconds: float | None) -> None:
        self.size = size
        self.seconds = seconds
        self.start = time.monotonic()

    def check_time(self, where: str) -> None:
        if self.seconds is not None and time.monotonic() - self.start > self.seconds:
            raise _BudgetHit(f"time budget of {self.seconds:g} s exceeded while {where}")

    def check_size(self, ops: int, order: int) -> None:
        if self.size is not None and ops > self.size:
            raise _BudgetHit(
                f"size budget of {self.size} operations exceeded by the order-{order} "
                f"derivatives ({ops} operations)"
            )


class _LieEngine:
    """Computes the blocks of (4.4) and (4.7) lazily and caches them for reuse."""

    def __init__(self, system: AugmentedSystem, input_models: Mapping[str, InputModel]) -> None:
        self.system = system
        self.input_models = dict(input_models)
        # random-walk parameters have no drift in (4.1), so they add nothing to L_f h
        self._fields = [(j, f) for j, f in enumerate(system.dynamics) if f != 0]
        self._derivatives: dict[tuple[int, int], sp.Symbol] = {}
        self._index: dict[sp.Symbol, tuple[int, int]] = {}
        self.names: dict[sp.Basic, str] = {}
        for sym, name in zip(system.unknowns, system.unknown_names, strict=True):
            self.names[sym] = name
        for sym, name in zip(
            system.generic_parameters, system.generic_parameter_names, strict=True
        ):
            self.names[sym] = name
        for i, (sym, name) in enumerate(zip(system.inputs, system.input_names, strict=True)):
            self._derivatives[(i, 0)] = sym
            self._index[sym] = (i, 0)
            self.names[sym] = name
        self._taken = set(self.names.values())
        self.blocks: list[_Block] = []
        self.seconds = 0.0

    def derivative_symbol(self, i: int, k: int) -> sp.Symbol:
        """The symbol of ``u_i^(k)``, named ``<input>__d<k>``."""
        key = (i, k)
        if key not in self._derivatives:
            name = f"{self.system.input_names[i]}__d{k}"
            if name in self._taken:
                raise ValueError(f"name {name!r} of an input derivative is already used")
            sym = sp.Symbol(name, real=True)
            self._derivatives[key] = sym
            self._index[sym] = key
            self.names[sym] = name
            self._taken.add(name)
        return self._derivatives[key]

    def symbol_for(self, name: str) -> sp.Symbol:
        """Resolve a state, parameter, input or input-derivative name (``u__d2``)."""
        for sym, n in self.names.items():
            if n == name:
                return sym
        for i, input_name in enumerate(self.system.input_names):
            prefix = f"{input_name}__d"
            if name.startswith(prefix) and name[len(prefix) :].isdigit():
                return self.derivative_symbol(i, int(name[len(prefix) :]))
        if name in self.system.substituted:
            raise KeyError(f"{name!r} was substituted by its default and is no longer a variable")
        raise KeyError(f"{name!r} is not a variable of model {self.system.model_name!r}")

    def _next(self, sym: sp.Symbol) -> sp.Expr:
        """``d/dt`` of an input derivative symbol under its excitation model."""
        i, k = self._index[sym]
        model = self.input_models[self.system.input_names[i]]
        if model.max_derivative is not None and k + 1 > model.max_derivative:
            return sp.S.Zero
        return self.derivative_symbol(i, k + 1)

    def block(self, k: int, budget: _Budget) -> _Block:
        while len(self.blocks) <= k:
            self._extend(budget)
        return self.blocks[k]

    def _extend(self, budget: _Budget) -> None:
        started = time.monotonic()
        k = len(self.blocks)
        unknowns = self.system.unknowns
        if k == 0:
            exprs = list(self.system.outputs)
        else:
            prev = self.blocks[-1]
            exprs = []
            for i, e in enumerate(prev.exprs):
                # L_f h = (dh/dx) f, reusing the Jacobian row already computed for (4.7) ...
                terms = [prev.jac[i][j] * f for j, f in self._fields if prev.jac[i][j] != 0]
                # ... plus sum_k dh/du^(k) u^(k+1), the input terms of (4.4).
                for w in prev.free[i]:
                    if w in self._index:
                        nxt = self._next(w)
                        if nxt != 0:
                            terms.append(e.diff(w) * nxt)
                exprs.append(sp.Add(*terms))
                budget.check_time(f"computing the order-{k} Lie derivatives")
        ops = None
        if budget.size is not None:
            ops = sum(sp.count_ops(e) for e in exprs)
            budget.check_size(ops, k)
        free = [e.free_symbols for e in exprs]
        jac = []
        for e, fr in zip(exprs, free, strict=True):
            jac.append(list(smart_jacobian([e], unknowns, [fr])))
            budget.check_time(f"differentiating the order-{k} Lie derivatives")
        self.blocks.append(_Block(k, exprs, free, jac, ops))
        self.seconds += time.monotonic() - started


@dataclass(frozen=True)
class ObservabilityMatrix:
    """Symbolic ``q`` (4.4) and ``Q = dq/dx`` (4.7) up to a derivative order."""

    q: sp.Matrix
    Q: sp.Matrix
    row_labels: tuple[str, ...]
    unknowns: tuple[str, ...]
    input_derivatives: tuple[str, ...]


def _parse_input_models(
    system: AugmentedSystem, input_models: Mapping[str, str | InputModel] | None, default: str
) -> dict[str, InputModel]:
    given = dict(input_models or {})
    stray = sorted(set(given) - set(system.input_names))
    if stray:
        raise KeyError(f"input models for unknown inputs: {stray}")
    return {name: InputModel.parse(given.get(name, default)) for name in system.input_names}


def observability_matrix(
    model: Model,
    estimate: Iterable[str] = (),
    order: int = 2,
    *,
    substitute_defaults: bool | Iterable[str] = False,
    input_models: Mapping[str, str | InputModel] | None = None,
    default_input_model: str = "generic",
) -> ObservabilityMatrix:
    """``q`` and ``Q`` of (4.4)/(4.7) with derivatives ``y, y', ..., y^(order)``.

    ``order=2`` gives the thesis' ``q_123`` and ``Q_123`` of (4.11)/(4.12).
    """
    system = augment(model, estimate, substitute_defaults=substitute_defaults)
    engine = _LieEngine(system, _parse_input_models(system, input_models, default_input_model))
    budget = _Budget(None, None)
    q, rows, labels = [], [], []
    for k in range(order + 1):
        blk = engine.block(k, budget)
        q.extend(blk.exprs)
        rows.extend(blk.jac)
        labels.extend(_row_label(name, k) for name in system.output_names)
    derivs = tuple(engine.names[s] for s, (_, kk) in engine._index.items() if kk > 0)
    n = system.n_unknowns
    return ObservabilityMatrix(
        q=sp.Matrix(len(q), 1, q),
        Q=sp.Matrix(len(rows), n, lambda i, j: rows[i][j]),
        row_labels=tuple(labels),
        unknowns=system.unknown_names,
        input_derivatives=derivs,
    )


def _row_label(output: str, k: int) -> str:
    """``y``, ``y^(1)``, ``y^(2)``, ...: the block of (4.4) a row of ``Q`` comes from."""
    return output if k == 0 else f"{output}^({k})"


# ---------------------------------------------------------------------------------------------
# Exact evaluation at a point (mod P and over the rationals)
# ---------------------------------------------------------------------------------------------


class _Sampler:
    """Draws independent points; gives up when denominators keep vanishing (singular set)."""

    def __init__(self, rng: random.Random, angles: frozenset[sp.Symbol], limit: int = 64) -> None:
        self.rng = rng
        self.angles = angles
        self.limit = limit
        self.rejected = 0

    def draw(self) -> _Point:
        return _Point(self.rng, self.angles)

    def reject(self) -> None:
        """Count a point where a denominator vanished; give up after ``limit`` of them."""
        self.rejected += 1
        if self.rejected >= self.limit:
            raise SamplingError(
                f"a denominator of Q vanished at {self.limit} random points: the condition set "
                "lies in the singular set of the model"
            )


class _Point:
    """A random point: each sample variable gets an integer in ``{0, ..., P-1}`` on first use.

    For an angle symbol ``s`` the stored integer is ``t`` with ``s = 2 atan(t)``.
    """

    def __init__(self, rng: random.Random, angles: frozenset[sp.Symbol]) -> None:
        # Values are derived from (point key, symbol name) rather than drawn in the order the
        # evaluator meets the symbols, so a seed reproduces the same point in every process.
        self.key = rng.getrandbits(64)
        self.angles = angles
        self.values: dict[sp.Symbol, int] = {}

    def value(self, sym: sp.Symbol) -> int:
        v = self.values.get(sym)
        if v is None:
            v = random.Random(f"{self.key}:{sym.name}").randrange(MODULUS)
            self.values[sym] = v
        return v


class _Evaluator:
    """Evaluates expression trees at a :class:`_Point`, mod P (``exact=False``) or in QQ.

    Values are cached per node, so subexpressions shared between entries of ``Q`` (SymPy
    trees share them heavily after differentiation) are evaluated once.
    """

    def __init__(self, point: _Point, exact: bool) -> None:
        self.point = point
        self.exact = exact
        self.cache: dict[sp.Basic, Any] = {}

    def __call__(self, e: sp.Basic) -> Any:
        try:
            return self.cache[e]
        except KeyError:
            pass
        v = self._compute(e)
        self.cache[e] = v
        return v

    def _compute(self, e: sp.Basic) -> Any:
        exact = self.exact
        if e.is_Symbol:
            if e in self.point.angles:
                raise UnsupportedExpressionError(f"angle {e} outside sin/cos")
            v = self.point.value(e)
            return QQ(v) if exact else v
        if e.is_Rational:
            if exact:
                return QQ(int(e.p), int(e.q))
            return e.p * pow(e.q, -1, MODULUS) % MODULUS
        if e.is_Add:
            if exact:
                s = QQ(0)
                for a in e.args:
                    s += self(a)
                return s
            s = 0
            for a in e.args:
                s += self(a)
            return s % MODULUS
        if e.is_Mul:
            if exact:
                m = QQ(1)
                for a in e.args:
                    m *= self(a)
                return m
            m = 1
            for a in e.args:
                m = m * self(a) % MODULUS
            return m
        if e.is_Pow:
            if not e.exp.is_Integer:
                raise UnsupportedExpressionError(f"non-integer power {e}")
            b = self(e.base)
            k = int(e.exp)
            if k < 0:
                if not b:
                    raise _ZeroDenominator(str(e.base))
                if exact:
                    return b**k
                return pow(pow(b, -1, MODULUS), -k, MODULUS)
            return b**k if exact else pow(b, k, MODULUS)
        if isinstance(e, _TRIG_ALLOWED):
            arg = e.args[0]
            if not (arg.is_Symbol and arg in self.point.angles):
                raise UnsupportedExpressionError(
                    f"{e}: only sin/cos of an angle symbol can be evaluated exactly"
                )
            t = self.point.value(arg)
            if exact:
                num = QQ(2 * t) if isinstance(e, sp.sin) else QQ(1 - t * t)
                return num / QQ(1 + t * t)
            num = 2 * t if isinstance(e, sp.sin) else 1 - t * t
            return num * pow((1 + t * t) % MODULUS, -1, MODULUS) % MODULUS
        if e.is_infinite or e is sp.nan:
            # e.g. a condition m = 0 turned 1/m into zoo: every point of the set is singular
            raise SamplingError(f"the conditions make Q singular ({e} in an entry)")
        raise UnsupportedExpressionError(f"cannot evaluate {type(e).__name__} {e} exactly")


class _Echelon:
    """Incremental row echelon form over GF(P) (``exact=False``) or QQ.

    Each accepted row is reduced against the earlier basis rows and normalised at its pivot.
    The accepted original rows restricted to the pivot columns form a nonsingular matrix (it is
    a unit-triangular matrix times an invertible change of basis), i.e. a nonzero minor.
    """

    def __init__(self, exact: bool) -> None:
        self.exact = exact
        self.basis: list[tuple[int, list[Any]]] = []
        self.rows: list[int] = []

    @property
    def rank(self) -> int:
        return len(self.basis)

    @property
    def pivots(self) -> list[int]:
        return [pc for pc, _ in self.basis]

    def add(self, row: Sequence[Any], index: int) -> bool:
        row = list(row)
        if self.exact:
            for pc, b in self.basis:
                c = row[pc]
                if c:
                    row = [a - c * bb for a, bb in zip(row, b, strict=True)]
        else:
            for pc, b in self.basis:
                c = row[pc]
                if c:
                    row = [(a - c * bb) % MODULUS for a, bb in zip(row, b, strict=True)]
        pc = next((j for j, a in enumerate(row) if a), None)
        if pc is None:
            return False
        if self.exact:
            inv = QQ(1) / row[pc]
            row = [a * inv for a in row]
        else:
            inv = pow(row[pc], -1, MODULUS)
            row = [a * inv % MODULUS for a in row]
        self.basis.append((pc, row))
        self.rows.append(index)
        return True


# ---------------------------------------------------------------------------------------------
# Degree bounds for Schwartz–Zippel
# ---------------------------------------------------------------------------------------------

# A rational-function degree bound: (numerator degree, {denominator key: (degree, exponent)}).
_Deg = tuple[int, dict[Any, tuple[int, int]]]


def _den_degree(den: Mapping[Any, tuple[int, int]]) -> int:
    return sum(d * x for d, x in den.values())


class _DegreeBounds:
    """Bounds ``entry = N/D`` with ``deg N`` and ``D`` a product of keyed polynomials.

    Keys are ``("inv", b)`` for a base ``b`` raised to a negative power (degree = numerator
    bound of ``b``) and ``("circle", s)`` for ``1 + t^2`` of an angle. Rules: a sample variable
    is ``(1, {})``; ``sin/cos(s)`` is ``(2, {circle: 1})``; a sum takes the least common
    multiple of the denominators (max exponent per key) and ``max(n_i + deg L - deg D_i)``; a
    product adds; ``b^k`` multiplies; ``b^-k = D_b^k / N_b^k``. Nothing is expanded.
    ``inverted`` collects every inverted base with its numerator bound, for ``D_den``.
    """

    def __init__(self) -> None:
        self.cache: dict[sp.Basic, _Deg] = {}
        self.inverted: dict[sp.Basic, int] = {}

    def __call__(self, e: sp.Basic) -> _Deg:
        try:
            return self.cache[e]
        except KeyError:
            pass
        v = self._compute(e)
        self.cache[e] = v
        return v

    def _compute(self, e: sp.Basic) -> _Deg:
        if e.is_Symbol:
            return 1, {}
        if e.is_Number:
            return 0, {}
        if e.is_Add:
            parts = [self(a) for a in e.args]
            lcm: dict[Any, tuple[int, int]] = {}
            for _, den in parts:
                for key, (d, x) in den.items():
                    if key not in lcm or lcm[key][1] < x:
                        lcm[key] = (d, x)
            dl = _den_degree(lcm)
            return max(n + dl - _den_degree(den) for n, den in parts), lcm
        if e.is_Mul:
            num, prod = 0, {}
            for n, den in (self(a) for a in e.args):
                num += n
                for key, (d, x) in den.items():
                    prod[key] = (d, prod[key][1] + x) if key in prod else (d, x)
            return num, prod
        if e.is_Pow:
            n, den = self(e.base)
            k = int(e.exp)
            if k >= 0:
                return k * n, {key: (d, x * k) for key, (d, x) in den.items()}
            self.inverted[e.base] = n
            return -k * _den_degree(den), {("inv", e.base): (n, -k)}
        if isinstance(e, _TRIG_ALLOWED):
            return 2, {("circle", e.args[0]): (2, 1)}
        raise UnsupportedExpressionError(f"no degree bound for {type(e).__name__} {e}")

    def row_degree(self, row: Sequence[sp.Expr]) -> int:
        """Degree bound of the row's entries after multiplying by their common denominator."""
        parts = [self(e) for e in row if e != 0]
        if not parts:
            return 0
        lcm: dict[Any, tuple[int, int]] = {}
        for _, den in parts:
            for key, (d, x) in den.items():
                if key not in lcm or lcm[key][1] < x:
                    lcm[key] = (d, x)
        dl = _den_degree(lcm)
        return max(n + dl - _den_degree(den) for n, den in parts)


# ---------------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------------


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
class PartialResult:
    """What was established before a budget ran out.

    ``rank_lower_bound`` is the rank of ``Q`` restricted to the derivative orders
    ``0..orders_completed`` at a point mod P: a sound lower bound on the generic rank (4.13).
    """

    model: str
    unknowns: tuple[str, ...]
    n_unknowns: int
    rank_lower_bound: int
    orders_completed: int
    rank_by_order: tuple[int, ...]
    reason: str
    elapsed_seconds: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "unknowns": list(self.unknowns),
            "n_unknowns": self.n_unknowns,
            "rank_lower_bound": self.rank_lower_bound,
            "orders_completed": self.orders_completed,
            "rank_by_order": list(self.rank_by_order),
            "reason": self.reason,
            "elapsed_seconds": self.elapsed_seconds,
        }


@dataclass(frozen=True)
class ObservabilityResult:
    """Verdict of the Lie-derivative rank test (4.7), (4.12) for one model and setting.

    ``rank`` is the generic rank of ``Q`` with derivatives up to ``max_order``. ``certain`` is
    true for a full-rank verdict (proved by ``witness``); otherwise ``error_probability_bound``
    bounds the chance that the rank or any per-variable verdict is wrong (module docstring).
    ``observable[name]`` is local (weak) observability of a state / local structural
    identifiability of an estimated parameter: the kernel of ``Q`` has no component on it.
    ``unobservable_directions`` is an exact kernel basis at the first maximal-rank point,
    each vector scaled to coprime integers, in named variables (zero entries omitted).
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
    _engine: _LieEngine | None = field(default=None, repr=False, compare=False)
    _rows: list[list[sp.Expr]] | None = field(default=None, repr=False, compare=False)
    _conditions: dict[sp.Symbol, sp.Expr] | None = field(default=None, repr=False, compare=False)
    _settings: dict[str, Any] | None = field(default=None, repr=False, compare=False)

    @property
    def unobservable(self) -> tuple[str, ...]:
        """Names of the variables that are not locally observable."""
        return tuple(n for n in self.unknowns if not self.observable[n])

    def matrix(self) -> sp.Matrix:
        """The symbolic ``Q`` (4.7) that was ranked (conditions applied)."""
        rows = self._rows or []
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


# ---------------------------------------------------------------------------------------------
# The analysis
# ---------------------------------------------------------------------------------------------


def _point_to_names(point: _Point, names: Mapping[sp.Basic, str]) -> dict[str, str]:
    out = {}
    for sym, v in point.values.items():
        name = names.get(sym, str(sym))
        out[name] = f"2*atan({v})" if sym in point.angles else str(v)
    return dict(sorted(out.items()))


def _integer_vector(vec: Sequence[Any]) -> list[int]:
    """Scale a rational vector to coprime integers with a positive first nonzero entry."""
    den = 1
    for a in vec:
        den = math.lcm(den, int(a.denominator))
    ints = [int(a.numerator) * (den // int(a.denominator)) for a in vec]
    g = 0
    for a in ints:
        g = math.gcd(g, a)
    if g == 0:
        return ints
    first = next(a for a in ints if a)
    sign = 1 if first > 0 else -1
    return [sign * a // g for a in ints]


def _evaluate_rows(rows: Sequence[Sequence[sp.Expr]], ev: _Evaluator) -> list[list[Any]]:
    return [[ev(e) for e in row] for row in rows]


def _apply_conditions(expr: sp.Expr, conditions: Mapping[sp.Symbol, sp.Expr]) -> sp.Expr:
    if not conditions:
        return expr
    return expr.xreplace(conditions) if expr.free_symbols & conditions.keys() else expr


def _parse_conditions(
    engine: _LieEngine, conditions: Mapping[str, Any] | None
) -> dict[sp.Symbol, sp.Expr]:
    """Names -> symbols; values (numbers, strings, expressions) -> exact expressions."""
    if not conditions:
        return {}
    local = {name: sym for sym, name in engine.names.items()}
    parsed: dict[sp.Symbol, sp.Expr] = {}
    for name, value in conditions.items():
        sym = engine.symbol_for(name)
        local[name] = sym
        if isinstance(value, str):
            expr = sp.sympify(value, locals=local)
        elif isinstance(value, (int, float)):
            expr = exact_rational(value)
        else:
            expr = sp.sympify(value)
        expr = _normalize_trig(rationalize(expr))
        parsed[sym] = expr
    chained = {s for e in parsed.values() for s in e.free_symbols} & parsed.keys()
    if chained:
        raise ValueError(
            f"condition values must not use conditioned variables: {sorted(map(str, chained))}"
        )
    return parsed


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
    max_error_probability: float = _DEFAULT_MAX_ERROR,
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
        See :func:`augment`; other parameters stay generic (sampled) known values.
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
        ``count_ops`` limit per derivative block and wall-time limit in seconds; exceeding
        either raises :class:`BudgetExceeded` with a :class:`PartialResult`.
    seed:
        Seed of the point sampler (``None``: drawn from the OS, recorded in the result).
    """
    system = augment(model, estimate, substitute_defaults=substitute_defaults)
    engine = _LieEngine(system, _parse_input_models(system, input_models, default_input_model))
    return _analyze(
        engine,
        conditions=_parse_conditions(engine, conditions),
        max_order=max_order,
        patience=patience,
        max_error_probability=max_error_probability,
        max_trials=max_trials,
        budget=_Budget(size_budget, time_budget),
        seed=seed,
    )


def _analyze(
    engine: _LieEngine,
    *,
    conditions: dict[sp.Symbol, sp.Expr],
    max_order: int | None,
    patience: int | None,
    max_error_probability: float,
    max_trials: int,
    budget: _Budget,
    seed: int | None,
) -> ObservabilityResult:
    started = time.monotonic()
    lie_before = engine.seconds
    system = engine.system
    n = system.n_unknowns
    cap = max(n - 1, 0) if max_order is None else max_order
    if seed is None:
        seed = random.SystemRandom().randrange(2**63)
    rng = random.Random(seed)
    names = engine.names
    sampler = _Sampler(rng, system.angle_symbols)

    # -- screening mod P, one derivative block at a time (4.4), (4.7) -------------------------
    rows: list[list[sp.Expr]] = []
    labels: list[str] = []
    rank_by_order: list[int] = []
    point = sampler.draw()
    ev = _Evaluator(point, exact=False)
    ech = _Echelon(exact=False)
    eval_seconds = 0.0
    stop_reason = ""
    stalled = 0
    k = 0
    try:
        while True:
            blk = engine.block(k, budget)
            new_rows = [[_apply_conditions(e, conditions) for e in row] for row in blk.jac]
            t_eval = time.monotonic()
            while True:
                try:
                    vals_new = _evaluate_rows(new_rows, ev)
                    break
                except _ZeroDenominator:
                    # a denominator vanished mod P: redraw and re-screen the earlier blocks
                    sampler.reject()
                    while True:
                        point = sampler.draw()
                        ev = _Evaluator(point, exact=False)
                        ech = _Echelon(exact=False)
                        try:
                            for idx, vals in enumerate(_evaluate_rows(rows, ev)):
                                ech.add(vals, idx)
                            break
                        except _ZeroDenominator:
                            sampler.reject()
            for offset, vals in enumerate(vals_new):
                ech.add(vals, len(rows) + offset)
            eval_seconds += time.monotonic() - t_eval
            rows.extend(new_rows)
            labels.extend(_row_label(name, k) for name in system.output_names)
            grew = ech.rank > (rank_by_order[-1] if rank_by_order else 0)
            rank_by_order.append(ech.rank)
            budget.check_time(f"ranking order {k}")
            if ech.rank == n:
                stop_reason = "full rank"
                break
            stalled = 0 if grew else stalled + 1
            if patience is not None and stalled >= patience:
                stop_reason = f"rank did not grow for {stalled} derivative order(s)"
                break
            if k >= cap:
                stop_reason = f"maximum derivative order {cap} reached"
                break
            k += 1
    except _BudgetHit as hit:
        partial = PartialResult(
            model=system.model_name,
            unknowns=system.unknown_names,
            n_unknowns=n,
            rank_lower_bound=rank_by_order[-1] if rank_by_order else 0,
            orders_completed=len(rank_by_order) - 1,
            rank_by_order=tuple(rank_by_order),
            reason=str(hit),
            elapsed_seconds=time.monotonic() - started,
        )
        raise BudgetExceeded(str(hit), partial) from None

    exact_started = time.monotonic()
    col_names = system.unknown_names

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
            conditions={names.get(s, str(s)): str(v) for s, v in conditions.items()},
            n_unknowns=n,
            max_order=len(rank_by_order) - 1,
            rank_by_order=tuple(rank_by_order),
            stop_reason=stop_reason,
            sample_size=MODULUS,
            seed=seed,
            timings={
                "lie_derivatives": engine.seconds - lie_before,
                "screening": eval_seconds,
                "exact": now - exact_started,
                "total": now - started,
            },
            _engine=engine,
            _rows=rows,
            _conditions=conditions,
            _settings={
                "max_order": cap,
                "max_error_probability": max_error_probability,
                "max_trials": max_trials,
            },
            **verdict,
        )

    def witness(pt: _Point, vals: list[list[Any]], sel: list[int], cols: list[int]) -> RankWitness:
        # re-verify the minor in exact rational arithmetic (vals are exact rationals)
        sel, cols = sorted(sel), sorted(cols)
        minor = [[vals[i][j] for j in cols] for i in sel]
        det = DomainMatrix(minor, (len(sel), len(cols)), QQ).det() if sel else QQ(1)
        if not det:
            raise AssertionError("a pivot minor must be nonzero over the rationals")
        return RankWitness(
            point=_point_to_names(pt, names),
            rows=tuple(labels[i] for i in sel),
            row_indices=tuple(sel),
            columns=tuple(col_names[j] for j in cols),
            column_indices=tuple(cols),
            determinant=str(det),
            verified=True,
        )

    def full_rank(
        pt: _Point, vals: list[list[Any]], sel: list[int], trials: int
    ) -> ObservabilityResult:
        return finish(
            rank=n,
            full_rank=True,
            certain=True,
            observable={c: True for c in col_names},
            unobservable_directions=(),
            witness=witness(pt, vals, sel, list(range(n))),
            kernel_point={},
            error_probability_bound=0.0,
            degree_bound=0,
            denominator_degree_bound=0,
            trials=trials,
        )

    if ech.rank == n:
        # a nonzero n x n minor mod P proves full generic rank; evaluate its rows exactly
        sel = sorted(ech.rows)
        exact_ev = _Evaluator(point, exact=True)
        vals = {i: [exact_ev(e) for e in rows[i]] for i in sel}
        return full_rank(point, [vals.get(i, []) for i in range(len(rows))], sel, 1)

    # -- rank deficient at the screening point: decide in exact rationals at k points ---------
    bounds = _DegreeBounds()
    row_degrees = sorted((bounds.row_degree(r) for r in rows), reverse=True)
    d_den = sum(bounds.inverted.values())

    def per_trial_error(rank: int) -> float:
        d_num = sum(row_degrees[: min(rank + 1, n)])
        return min(1.0, d_num / (MODULUS - d_den)) if d_den < MODULUS else 1.0

    eps = per_trial_error(ech.rank)
    trials = 1
    while eps > 0 and trials < max_trials and (n + 1) * eps**trials > max_error_probability:
        trials += 1
    best: tuple[int, _Point, list[list[Any]], _Echelon, list[list[Any]]] | None = None
    unobservable: set[int] = set()
    for trial in range(trials):
        if trial == 0:
            pt = point
        else:
            while True:
                # the mod-P pass rejects points where a denominator vanishes mod P, which keeps
                # every trial under the same conditioning as the screening point
                pt = sampler.draw()
                try:
                    _evaluate_rows(rows, _Evaluator(pt, exact=False))
                    break
                except _ZeroDenominator:
                    sampler.reject()
        vals = _evaluate_rows(rows, _Evaluator(pt, exact=True))
        ech_q = _Echelon(exact=True)
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
        ints = _integer_vector(vec)
        directions.append({col_names[j]: str(ints[j]) for j in range(n) if ints[j]})
    eps = per_trial_error(rank)
    return finish(
        rank=rank,
        full_rank=False,
        certain=False,
        observable={c: j not in unobservable for j, c in enumerate(col_names)},
        unobservable_directions=tuple(directions),
        witness=witness(pt, vals, list(ech_q.rows), list(ech_q.pivots)),
        kernel_point=_point_to_names(pt, names),
        error_probability_bound=min(1.0, (n + 1) * eps**trials),
        degree_bound=sum(row_degrees[: min(rank + 1, n)]),
        denominator_degree_bound=d_den,
        trials=trials,
    )


# ---------------------------------------------------------------------------------------------
# Where the rank drops (checking claims such as (4.12) "for all operating points and inputs")
# ---------------------------------------------------------------------------------------------


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
    input_models: Mapping[str, str | InputModel] | None = None,
    *,
    max_order: int | None = None,
    seed: int | None = None,
    size_budget: int | None = None,
    time_budget: float | None = None,
) -> RankDropReport:
    """Recompute the exact rank on a set given by conditions and/or input models.

    ``conditions`` are point restrictions as in :func:`analyze_observability`, added to (and
    overriding) the baseline's own conditions; ``input_models`` override the baseline's per
    input (e.g. ``{"u": "constant"}`` together with ``conditions={"u": 0}`` holds ``u`` at
    zero). The derivative orders are those of the baseline (``max_order`` may raise them, to
    see whether more derivatives restore the rank).
    """
    engine = baseline._engine
    if engine is None:
        raise ValueError("the baseline result carries no engine (was it deserialised?)")
    models = dict(engine.input_models)
    for name, spec in (input_models or {}).items():
        if name not in models:
            raise KeyError(f"{name!r} is not an input")
        models[name] = InputModel.parse(spec)
    if models != engine.input_models:
        engine = _LieEngine(engine.system, models)
    settings = baseline._settings or {}
    order = baseline.max_order if max_order is None else max_order
    merged = dict(baseline._conditions or {})
    merged.update(_parse_conditions(engine, conditions))
    chained = {s for e in merged.values() for s in e.free_symbols} & merged.keys()
    if chained:
        raise ValueError(
            f"condition values must not use conditioned variables: {sorted(map(str, chained))}"
        )
    result = _analyze(
        engine,
        conditions=merged,
        max_order=order,
        patience=None,
        max_error_probability=settings.get("max_error_probability", _DEFAULT_MAX_ERROR),
        max_trials=settings.get("max_trials", 8),
        budget=_Budget(size_budget, time_budget),
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
class CandidateCondition:
    """A proposed set where the rank may drop, and whether an exact rank confirmed it.

    ``origin`` is ``"minor-factor"`` (a factor of the witness minor set to zero),
    ``"line"`` (the minor vanishes on the coordinate hyperplane ``variable = 0``, found by
    evaluating along lines) or ``"input-model"`` (an input held constant, or held at zero).
    """

    conditions: dict[str, str]
    input_models: dict[str, str]
    origin: str
    factor: str | None
    confirmed: bool
    report: RankDropReport | None
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "conditions": dict(self.conditions),
            "input_models": dict(self.input_models),
            "origin": self.origin,
            "factor": self.factor,
            "confirmed": self.confirmed,
            "report": None if self.report is None else self.report.to_dict(),
            "note": self.note,
        }


def _variable_preference(engine: _LieEngine, sym: sp.Symbol) -> int:
    """Order in which to solve a factor for a variable: inputs first, then states, ..."""
    system = engine.system
    if sym in engine._index:
        return 0 if engine._index[sym][1] == 0 else 1
    if sym in system.unknowns[: len(system.state_names)]:
        return 2
    if sym in system.unknowns:
        return 3
    return 4


@dataclass(frozen=True)
class DropSearch:
    """Result of :func:`propose_rank_drop_conditions`: candidates and what was skipped."""

    baseline_rank: int
    candidates: tuple[CandidateCondition, ...]
    notes: tuple[str, ...]

    @property
    def confirmed(self) -> tuple[CandidateCondition, ...]:
        return tuple(c for c in self.candidates if c.confirmed)

    def to_dict(self) -> dict[str, Any]:
        return {
            "baseline_rank": self.baseline_rank,
            "candidates": [c.to_dict() for c in self.candidates],
            "notes": list(self.notes),
        }


def propose_rank_drop_conditions(
    baseline: ObservabilityResult,
    *,
    symbolic_ops_limit: int = 3000,
    factor_terms_limit: int = 400,
    try_zero: bool = True,
    try_constant_inputs: bool = True,
    seed: int | None = None,
) -> DropSearch:
    """Propose sets where the rank of ``Q`` drops, each checked by an exact rank.

    The rank can only drop where the baseline's witness minor vanishes. If that minor is small
    (total ``count_ops`` of its entries at most ``symbolic_ops_limit``) it is computed and
    factored symbolically (fully if its numerator has at most ``factor_terms_limit`` terms);
    each factor that is linear in some variable gives a substitution.
    Independently (and always when the minor is too large), the minor is evaluated along lines
    parallel to each coordinate axis at the point ``variable = 0``; where it vanishes, that
    hyperplane is a candidate. With ``try_constant_inputs`` every input is also held constant
    and held at zero.
    Every candidate is then confirmed (or not) by :func:`rank_under_conditions` at the
    baseline's derivative orders.
    """
    engine = baseline._engine
    if engine is None or baseline.witness is None or baseline._rows is None:
        raise ValueError("the baseline result carries no engine or witness")
    rng = random.Random(seed)
    system = engine.system
    wit = baseline.witness
    minor = [[baseline._rows[i][j] for j in wit.column_indices] for i in wit.row_indices]
    proposals: list[tuple[dict[str, str], dict[str, str], str, str | None]] = []
    seen: set[tuple[tuple[tuple[str, str], ...], tuple[tuple[str, str], ...]]] = set()
    notes: list[str] = []

    def propose(
        conds: dict[str, str], models: dict[str, str], origin: str, fac: str | None
    ) -> None:
        key = (tuple(sorted(conds.items())), tuple(sorted(models.items())))
        if key not in seen:
            seen.add(key)
            proposals.append((conds, models, origin, fac))

    if minor:
        ops = sum(sp.count_ops(e) for row in minor for e in row)
        if ops <= symbolic_ops_limit:
            for fac, sol in _minor_factors(engine, minor, factor_terms_limit, notes):
                if sol is None:
                    notes.append(f"factor {fac}: no variable occurs linearly; not tested")
                    continue
                var, value = sol
                propose({engine.names[var]: str(value)}, {}, "minor-factor", str(fac))
        else:
            notes.append(
                f"witness minor too large to factor ({ops} > {symbolic_ops_limit} operations); "
                "only coordinate hyperplanes were tested"
            )
        if try_zero:
            variables = sorted(
                {s for row in minor for e in row for s in e.free_symbols},
                key=lambda s: (_variable_preference(engine, s), engine.names.get(s, str(s))),
            )
            for var in variables:
                if _minor_vanishes_on(minor, var, rng, system.angle_symbols):
                    propose({engine.names[var]: "0"}, {}, "line", None)
    if try_constant_inputs:
        for name in system.input_names:
            # held at an arbitrary constant, and held at zero (a disengaged clutch)
            if str(engine.input_models[name]) != "constant":
                propose({}, {name: "constant"}, "input-model", None)
            propose({name: "0"}, {name: "constant"}, "input-model", None)

    out = []
    for conds, models, origin, fac in proposals:
        try:
            report = rank_under_conditions(baseline, conds, models, seed=rng.randrange(2**63))
        except (SamplingError, UnsupportedExpressionError) as exc:
            out.append(CandidateCondition(conds, models, origin, fac, False, None, str(exc)))
            continue
        out.append(CandidateCondition(conds, models, origin, fac, report.drops, report))
    return DropSearch(baseline.rank, tuple(out), tuple(notes))


def _minor_factors(
    engine: _LieEngine, minor: list[list[sp.Expr]], terms_limit: int, notes: list[str]
) -> list[tuple[sp.Expr, tuple[sp.Symbol, sp.Expr] | None]]:
    """Factor the numerator of a symbolic minor; solve each factor for a linear variable.

    The determinant is computed in SymPy's sparse polynomial rings (not with ``Expr``
    arithmetic, :func:`_minor_numerator`), after expanding along rows and columns with a single
    constant nonzero entry (which only changes it by a nonzero constant). Multivariate
    factorisation is the expensive step, so :func:`_factor_polynomial` first splits off every
    factor it can get from gcds; a remaining part with more than ``terms_limit`` terms is not
    factored further.
    """
    trig = {}
    for row in minor:
        for e in row:
            for t in e.atoms(sp.sin, sp.cos):
                trig.setdefault(t, sp.Dummy(f"{type(t).__name__}_{t.args[0]}"))
    back = {d: t for t, d in trig.items()}
    entries = _drop_constant_lines([[e.xreplace(trig) for e in row] for row in minor])
    numerator = _minor_numerator(entries)
    if numerator is None or numerator.is_ground:
        return []  # a constant minor has no zero set
    factors = _factor_polynomial(numerator, terms_limit, notes)
    ring = numerator.ring
    out = []
    for fac, _mult in factors:
        present = {
            ring.symbols[i]: g for i, g in enumerate(ring.gens) if fac.degree(g) > 0
        }  # degrees on the sparse polynomial: no conversion to Poly per variable
        if not present:
            continue
        expr = fac.as_expr()
        sol = None
        candidates = sorted(
            (s for s in present if s not in back),
            key=lambda s: (_variable_preference(engine, s), engine.names.get(s, str(s))),
        )
        for var in candidates:
            gen = present[var]
            if fac.degree(gen) == 1:
                c1 = fac.diff(gen)  # fac = c1 * var + c0
                c0 = fac - c1 * gen
                sol = (var, sp.together(-c0.as_expr() / c1.as_expr()).xreplace(back))
                break
        if sol is None and set(present) <= set(back):
            # a pure sin/cos factor: sin(s) = 0 at s = 0, cos(s) = 0 at s = pi/2
            if expr in back and isinstance(back[expr], sp.sin):
                sol = (back[expr].args[0], sp.S.Zero)
            elif expr in back and isinstance(back[expr], sp.cos):
                sol = (back[expr].args[0], sp.pi / 2)
        out.append((expr.xreplace(back), sol))
    return out


def _minor_numerator(entries: list[list[sp.Expr]]) -> Any:
    """Numerator of the determinant of a square matrix of rational functions, reduced.

    Entries are converted node by node into the fraction field ``ZZ(symbols)`` (no ``expand``
    of the expression trees); each row is multiplied by the lcm ``L_i`` of its denominators,
    the polynomial determinant ``D`` is computed fraction-free, and factors shared with
    ``prod L_i`` are divided out, so the result is the numerator of ``det = D / prod L_i`` in
    lowest terms (a sparse ``PolyElement``). ``None`` if no symbol occurs.
    """
    from sympy import ZZ

    size = len(entries)
    symbols = sorted({s for row in entries for e in row for s in e.free_symbols}, key=str)
    if size == 0 or not symbols:
        return None
    domain = ZZ.frac_field(*symbols)
    field_ = domain.field
    gens = dict(zip(symbols, field_.gens, strict=True))
    cache: dict[sp.Basic, Any] = {}

    def convert(e: sp.Basic) -> Any:
        value = cache.get(e)
        if value is not None:
            return value
        if e.is_Symbol:
            value = gens[e]
        elif e.is_Rational:
            value = field_(int(e.p)) / field_(int(e.q))
        elif e.is_Add:
            value = field_(0)
            for a in e.args:
                value = value + convert(a)
        elif e.is_Mul:
            value = field_(1)
            for a in e.args:
                value = value * convert(a)
        elif e.is_Pow and e.exp.is_Integer:
            value = convert(e.base) ** int(e.exp)
        else:
            raise UnsupportedExpressionError(f"cannot convert {type(e).__name__} {e} exactly")
        cache[e] = value
        return value

    ring = field_.ring
    rows = []
    denominators = ring(1)
    for row in entries:
        values = [convert(e) for e in row]
        lcm = ring(1)
        for v in values:
            lcm = lcm.lcm(v.denom)
        rows.append([v.numer * lcm.exquo(v.denom) for v in values])
        denominators = denominators * lcm
    numerator = DomainMatrix(rows, (size, size), domain.get_ring()).det()
    while not numerator.is_zero:
        common = numerator.gcd(denominators)
        if common.is_ground:
            break
        numerator = numerator.exquo(common)
    return numerator


def _drop_constant_lines(entries: list[list[sp.Expr]]) -> list[list[sp.Expr]]:
    """Laplace expansion along rows/columns whose only nonzero entry is a number.

    The determinant of the result equals that of ``entries`` up to a nonzero constant factor,
    so both have the same zero set (e.g. the output rows ``y`` of (4.8) are unit rows).
    """
    rows = list(range(len(entries)))
    cols = list(range(len(entries)))
    changed = True
    while changed and rows:
        changed = False
        for i in rows:
            nonzero = [j for j in cols if entries[i][j] != 0]
            if len(nonzero) == 1 and entries[i][nonzero[0]].is_number:
                rows.remove(i)
                cols.remove(nonzero[0])
                changed = True
                break
        else:
            for j in cols:
                nonzero = [i for i in rows if entries[i][j] != 0]
                if len(nonzero) == 1 and entries[nonzero[0]][j].is_number:
                    rows.remove(nonzero[0])
                    cols.remove(j)
                    changed = True
                    break
    return [[entries[i][j] for j in cols] for i in rows]


def _factor_polynomial(poly: Any, terms_limit: int, notes: list[str]) -> list[tuple[Any, int]]:
    """Irreducible factors of ``poly`` (a sparse ``PolyElement``), cheap parts first.

    Monomial content is split off; then, while some variable ``v`` occurs with degree 1,
    ``poly = a v + b`` splits into ``g = gcd(a, b)`` (free of ``v``, factored recursively) and
    ``poly / g``, which is primitive and of degree 1 in ``v``, hence irreducible. Only a part
    without such a variable goes to full multivariate factorisation, and only if it has at most
    ``terms_limit`` terms (otherwise it is kept whole and a note says so). Multiplicities are
    those found; factors are sparse polynomials of the same ring.
    """
    ring = poly.ring
    out: list[tuple[Any, int]] = []
    pending = [poly]
    while pending:
        p = pending.pop()
        if p.is_ground:
            continue
        low = tuple(min(column) for column in zip(*p.monoms(), strict=True))
        if any(low):
            out.extend((g, e) for g, e in zip(ring.gens, low, strict=True) if e)
            p = p.exquo(ring({low: ring.domain.one}))
            if p.is_ground:
                continue
        # among the variables of degree 1, the one with the smallest coefficient a: the gcd
        # is cheapest there (and a small a often is the whole content)
        monoms = p.monoms()
        counts = {
            i: sum(1 for m in monoms if m[i] == 1)
            for i in range(len(ring.gens))
            if max(m[i] for m in monoms) == 1
        }
        linear = ring.gens[min(counts, key=lambda i: (counts[i], i))] if counts else None
        if linear is not None:
            a = p.diff(linear)  # p = a * linear + b with a, b free of linear
            common = a.gcd(p - a * linear)
            if common.is_ground:
                out.append((p, 1))
            else:
                out.append((p.exquo(common), 1))
                pending.append(common)
            continue
        if len(p.terms()) <= terms_limit:
            _, factors = p.factor_list()
            out.extend(factors)
        else:
            notes.append(
                f"a factor of the minor numerator has {len(p.terms())} > {terms_limit} terms "
                "and no variable of degree 1: it was not factored further"
            )
            out.append((p, 1))
    return out


def _minor_vanishes_on(
    minor: list[list[sp.Expr]], var: sp.Symbol, rng: random.Random, angles: frozenset
) -> bool:
    """Does the minor vanish (mod P) where two random lines parallel to the ``var`` axis cross
    the hyperplane ``var = 0``? (For an angle ``s``, ``s = 0`` is ``t = 0``.)

    A zero here only proposes a candidate; :func:`rank_under_conditions` decides.
    """
    restricted = [[e.xreplace({var: 0}) for e in row] for row in minor]
    for _ in range(2):
        ev = _Evaluator(_Point(rng, angles), exact=False)
        try:
            vals = _evaluate_rows(restricted, ev)
        except (_ZeroDenominator, SamplingError):
            return False  # the hyperplane lies (partly) where the model is singular
        ech = _Echelon(exact=False)
        for idx, row in enumerate(vals):
            ech.add(row, idx)
        if ech.rank == len(minor):
            return False
    return True
