"""The Lie engine: derivatives of the outputs along the dynamics (4.4)–(4.7), in SymEngine.

Block ``k`` holds ``y^(k) = h_k(x, u, u', ..., u^(k))`` (4.4) and its Jacobian rows
``dh_k/dx`` with respect to the augmented state (4.1), i.e. the rows of ``Q`` (4.7). Each block
is computed from the previous one, reusing the Jacobian rows already needed for ``Q``:

    h_{k+1} = (dh_k/dx) f + sum_i sum_j dh_k/du_i^(j) u_i^(j+1),

where ``u_i^(j+1)`` is a fresh variable ``<input>__d<j+1>`` or zero, as the input's excitation
model says (:class:`.system.InputModel`). The expressions are SymEngine's (C++; the same
Jacobians take a fraction of the time SymPy's ``diff`` needs), exact throughout: the model's
numbers are rationals, and SymEngine applies only exact canonicalisations. SymPy is used before
(model preparation, :mod:`.system`) and converted back to only where a caller wants SymPy
expressions (:func:`observability_matrix`, the symbolic witness minor of the drop search).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import symengine as se
import sympy as sp
from gearsym.symbolic.model import Model
from gearsym.symbolic.observability.errors import BudgetHit
from gearsym.symbolic.observability.system import (
    AugmentedSystem,
    InputModel,
    augment,
    parse_input_models,
)

_TO_SYMPY = (
    (se.Add, sp.Add),
    (se.Mul, sp.Mul),
    (se.Pow, sp.Pow),
    (se.sin, sp.sin),
    (se.cos, sp.cos),
)
_COMPOUND = tuple(t for t, _ in _TO_SYMPY)

#: Kinds of variables, in the order the drop search prefers to solve a factor for them.
INPUT, INPUT_DERIVATIVE, STATE, ESTIMATED, KNOWN = range(5)


class SymbolTable:
    """The variables of an augmented system by symbol name, in SymPy and SymEngine form.

    SymEngine identifies symbols by name (it has no assumptions), so two different SymPy
    symbols with one name are refused. ``names`` maps symbol names to variable names (they may
    differ in a hand-built model); input derivatives ``u^(k)`` are created on first use and
    named ``<input>__d<k>``.
    """

    def __init__(self, system: AugmentedSystem) -> None:
        self.system = system
        self.names: dict[str, str] = {}
        self.sympy: dict[str, sp.Symbol] = {}
        self.kinds: dict[str, int] = {}
        self.by_variable: dict[str, str] = {}
        #: symbol name of ``u_i^(k)`` -> ``(i, k)``; ``k = 0`` is the input itself
        self.derivative_index: dict[str, tuple[int, int]] = {}
        self._derivatives: dict[tuple[int, int], str] = {}
        n_states = len(system.state_names)
        for j, (sym, name) in enumerate(zip(system.unknowns, system.unknown_names, strict=True)):
            self._add(sym, name, STATE if j < n_states else ESTIMATED)
        for sym, name in zip(
            system.generic_parameters, system.generic_parameter_names, strict=True
        ):
            self._add(sym, name, KNOWN)
        for i, (sym, name) in enumerate(zip(system.inputs, system.input_names, strict=True)):
            self._add(sym, name, INPUT)
            self.derivative_index[sym.name] = (i, 0)
            self._derivatives[(i, 0)] = sym.name
        self.angles = frozenset(s.name for s in system.angle_symbols)

    def _add(self, sym: sp.Symbol, name: str, kind: int) -> None:
        if sym.name in self.sympy and self.sympy[sym.name] != sym:
            raise ValueError(f"two different symbols are named {sym.name!r}")
        if name in self.by_variable:
            raise ValueError(f"name {name!r} is used twice")
        self.sympy[sym.name] = sym
        self.names[sym.name] = name
        self.kinds[sym.name] = kind
        self.by_variable[name] = sym.name

    def derivative(self, i: int, k: int) -> str:
        """The symbol name of ``u_i^(k)``, ``<input>__d<k>`` (created on first use)."""
        key = (i, k)
        if key not in self._derivatives:
            name = f"{self.system.input_names[i]}__d{k}"
            if name in self.by_variable or name in self.sympy:
                raise ValueError(f"name {name!r} of an input derivative is already used")
            self._add(sp.Symbol(name, real=True), name, INPUT_DERIVATIVE)
            self.derivative_index[name] = key
            self._derivatives[key] = name
        return self._derivatives[key]

    @property
    def input_derivatives(self) -> tuple[str, ...]:
        """Names of the derivatives ``u^(k)``, ``k >= 1``, created so far."""
        return tuple(self.names[s] for s, (_, k) in self.derivative_index.items() if k > 0)

    def resolve(self, name: str) -> sp.Symbol:
        """The SymPy symbol of a state, parameter, input or input derivative (``u__d2``)."""
        if name in self.by_variable:
            return self.sympy[self.by_variable[name]]
        for i, input_name in enumerate(self.system.input_names):
            prefix = f"{input_name}__d"
            if name.startswith(prefix) and name[len(prefix) :].isdigit():
                return self.sympy[self.derivative(i, int(name[len(prefix) :]))]
        if name in self.system.substituted:
            raise KeyError(f"{name!r} was substituted by its default and is no longer a variable")
        raise KeyError(f"{name!r} is not a variable of model {self.system.model_name!r}")

    def variable(self, symbol: Any) -> str:
        """Variable name of a SymPy or SymEngine symbol."""
        return self.names.get(symbol.name, symbol.name)

    @staticmethod
    def to_symengine(expr: sp.Basic) -> se.Basic:
        return se.sympify(expr)

    def to_sympy(self, expr: se.Basic, cache: dict[se.Basic, sp.Expr] | None = None) -> sp.Expr:
        """The SymPy form of a SymEngine expression, with this table's SymPy symbols."""
        cache = {} if cache is None else cache
        hit = cache.get(expr)
        if hit is not None:
            return hit
        if isinstance(expr, se.Symbol):
            out = self.sympy.get(expr.name) or sp.Symbol(expr.name)
        elif isinstance(expr, se.Integer):
            out = sp.Integer(int(expr))
        elif isinstance(expr, se.Rational):
            out = sp.Rational(int(expr.p), int(expr.q))
        elif isinstance(expr, _COMPOUND):
            args = [self.to_sympy(a, cache) for a in expr.args]
            out = next(f for t, f in _TO_SYMPY if isinstance(expr, t))(*args)
        else:  # infinities and the like: SymPy's own conversion, symbols mapped back
            out = sp.sympify(expr).xreplace(
                {sp.Symbol(n): s for n, s in self.sympy.items() if sp.Symbol(n) != s}
            )
        cache[expr] = out
        return out


@dataclass
class Block:
    """Derivative order ``k``: ``y^(k) = h_k(x, u, ..., u^(k))`` (4.4) and its Jacobian rows."""

    order: int
    exprs: list[se.Basic]
    free: list[set[se.Basic]]
    jac: list[list[se.Basic]]
    ops: int | None


class Budget:
    """Size (operations of a derivative block) and wall-time limits."""

    def __init__(self, size: int | None, seconds: float | None) -> None:
        self.size = size
        self.seconds = seconds
        self.start = time.monotonic()

    def check_time(self, where: str) -> None:
        if self.seconds is not None and time.monotonic() - self.start > self.seconds:
            raise BudgetHit(f"time budget of {self.seconds:g} s exceeded while {where}")

    def check_size(self, ops: int, order: int) -> None:
        if self.size is not None and ops > self.size:
            raise BudgetHit(
                f"size budget of {self.size} operations exceeded by the order-{order} "
                f"derivatives ({ops} operations)"
            )


class LieEngine:
    """The blocks of (4.4) and (4.7) for one system and one set of input models, computed
    lazily and cached (a session keeps one engine per set of input models)."""

    def __init__(
        self,
        system: AugmentedSystem,
        input_models: Mapping[str, InputModel],
        symbols: SymbolTable | None = None,
    ) -> None:
        self.system = system
        self.input_models = dict(input_models)
        self.symbols = SymbolTable(system) if symbols is None else symbols
        self.unknowns = [se.Symbol(s.name) for s in system.unknowns]
        dynamics = [self.symbols.to_symengine(f) for f in system.dynamics]
        # random-walk parameters have no drift in (4.1), so they add nothing to L_f h
        self._fields = [(j, f) for j, f in enumerate(dynamics) if f != 0]
        self._outputs = [self.symbols.to_symengine(h) for h in system.outputs]
        self.blocks: list[Block] = []
        self.seconds = 0.0

    def _next(self, name: str) -> se.Basic | None:
        """``d/dt`` of the input derivative named ``name`` under its excitation model."""
        i, k = self.symbols.derivative_index[name]
        model = self.input_models[self.system.input_names[i]]
        if model.max_derivative is not None and k + 1 > model.max_derivative:
            return None
        return se.Symbol(self.symbols.derivative(i, k + 1))

    def block(self, k: int, budget: Budget) -> Block:
        while len(self.blocks) <= k:
            self._extend(budget)
        return self.blocks[k]

    def _extend(self, budget: Budget) -> None:
        started = time.monotonic()
        k = len(self.blocks)
        zero = se.Integer(0)
        if k == 0:
            exprs = list(self._outputs)
        else:
            prev = self.blocks[-1]
            index = self.symbols.derivative_index
            exprs = []
            for i, e in enumerate(prev.exprs):
                # L_f h = (dh/dx) f, reusing the Jacobian row already computed for (4.7) ...
                terms = [prev.jac[i][j] * f for j, f in self._fields if prev.jac[i][j] != 0]
                # ... plus sum_k dh/du^(k) u^(k+1), the input terms of (4.4).
                for w in prev.free[i]:
                    if w.name in index:
                        nxt = self._next(w.name)
                        if nxt is not None:
                            terms.append(e.diff(w) * nxt)
                exprs.append(se.Add(*terms) if terms else zero)
                budget.check_time(f"computing the order-{k} Lie derivatives")
        ops = None
        if budget.size is not None:
            ops = sum(int(se.count_ops(e)) for e in exprs)
            budget.check_size(ops, k)
        free = [e.free_symbols for e in exprs]
        jac = []
        for e, fr in zip(exprs, free, strict=True):
            jac.append([e.diff(v) if v in fr else zero for v in self.unknowns])
            budget.check_time(f"differentiating the order-{k} Lie derivatives")
        self.blocks.append(Block(k, exprs, free, jac, ops))
        self.seconds += time.monotonic() - started


def row_label(output: str, k: int) -> str:
    """``y``, ``y^(1)``, ``y^(2)``, ...: the block of (4.4) a row of ``Q`` comes from."""
    return output if k == 0 else f"{output}^({k})"


def order_label(k: int) -> str:
    """``y``, ``y^(1)``, ...: derivative order ``k`` of the outputs (4.4)."""
    return row_label("y", k)


@dataclass(frozen=True)
class ObservabilityMatrix:
    """Symbolic ``q`` (4.4) and ``Q = dq/dx`` (4.7) up to a derivative order (SymPy)."""

    q: sp.Matrix
    Q: sp.Matrix
    row_labels: tuple[str, ...]
    unknowns: tuple[str, ...]
    input_derivatives: tuple[str, ...]


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
    engine = LieEngine(system, parse_input_models(system, input_models, default_input_model))
    budget = Budget(None, None)
    q, rows, labels = [], [], []
    for k in range(order + 1):
        blk = engine.block(k, budget)
        q.extend(blk.exprs)
        rows.extend(blk.jac)
        labels.extend(row_label(name, k) for name in system.output_names)
    cache: dict[se.Basic, sp.Expr] = {}
    q_sp = [engine.symbols.to_sympy(e, cache) for e in q]
    rows_sp = [[engine.symbols.to_sympy(e, cache) for e in row] for row in rows]
    return ObservabilityMatrix(
        q=sp.Matrix(len(q_sp), 1, q_sp),
        Q=sp.Matrix(len(rows_sp), system.n_unknowns, lambda i, j: rows_sp[i][j]),
        row_labels=tuple(labels),
        unknowns=system.unknown_names,
        input_derivatives=engine.symbols.input_derivatives,
    )
