"""Common-subexpression elimination: one pass over all outputs of one emitted function."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import sympy as sp
from gearsym.symbolic.codegen.config import CodegenConfig
from gearsym.symbolic.codegen.expressions import is_inline_power
from sympy.logic.boolalg import Boolean

__all__ = [
    "CseForm",
    "boolean_definitions",
    "cse_function",
    "cse_of",
    "flatten_column_major",
    "hoist",
    "is_condition",
    "share_products",
]


class FunctionExpressions(Protocol):
    """What a CSE pass reads of an emitted function: its output matrices, in order (a row of
    the function table, :class:`gearsym.symbolic.codegen.table.FunctionSpec`, which is built
    on the Jacobians and so on this module)."""

    @property
    def expressions(self) -> tuple[sp.ImmutableMatrix, ...]: ...


@lru_cache(maxsize=256)
def cse_of(
    exprs: tuple[sp.Basic, ...], optimizations: str | None = None
) -> tuple[tuple[tuple[sp.Symbol, sp.Basic], ...], tuple[sp.Basic, ...]]:
    """:func:`sympy.cse` of ``exprs`` with temporaries ``_cse0, _cse1, ...``, remembered.

    The right-hand side of a model is CSE'd twice otherwise: for its own function and as the
    graph its Jacobians are differentiated over (:mod:`gearsym.symbolic.codegen.jacobian`).
    Temporaries carry no assumptions while every model symbol is real, so a temporary can never
    be equal to a model symbol, whatever the names.
    """
    generator = sp.numbered_symbols("_cse", cls=sp.Symbol)
    replacements, reduced = sp.cse(list(exprs), symbols=generator, optimizations=optimizations)
    return tuple(replacements), tuple(reduced)


@dataclass(frozen=True)
class CseForm:
    """Result of :func:`cse_function`: ordered temporaries, then one matrix per output."""

    temporaries: tuple[tuple[sp.Symbol, sp.Basic], ...]
    outputs: tuple[sp.ImmutableMatrix, ...]


def flatten_column_major(matrix: sp.MatrixBase) -> list[sp.Basic]:
    """Entries in the emitted layout: ``(i, j)`` at ``i + j*rows``."""
    rows, cols = matrix.shape
    return [matrix[i, j] for j in range(cols) for i in range(rows)]


def _unflatten_column_major(values: Sequence[sp.Basic], shape: tuple[int, int]) -> sp.Matrix:
    rows, cols = shape
    return sp.ImmutableMatrix(rows, cols, lambda i, j: values[i + j * rows])


@dataclass
class _Product:
    """A distinct product during :func:`share_products`: sign, the factors it may share (its
    symbols and the magnitude of its constant) and the rest (powers, sums, calls)."""

    sign: int
    factors: list[sp.Basic]
    others: list[sp.Basic]


def _product(mul: sp.Mul) -> _Product:
    coeff, rest = mul.as_coeff_mul()
    factors: list[sp.Basic] = [abs(coeff)] if abs(coeff) != 1 else []
    factors += [f for f in rest if f.is_Symbol]
    return _Product(-1 if coeff < 0 else 1, factors, [f for f in rest if not f.is_Symbol])


def share_products(
    temporaries: list[tuple[sp.Symbol, sp.Basic]], outputs: list[sp.Basic]
) -> tuple[list[tuple[sp.Symbol, sp.Basic]], list[sp.Basic]]:
    """Factor out the pairs of factors (two symbols, or a constant and a symbol) that several
    distinct products share, most shared pair first, as new temporaries.

    :func:`sympy.cse` never shares a constant with a symbol, and its product matching misses
    pairs: the sensitivity rows ``-c_1 S_a d_ss - c_2 S_b k_ss + c_1 S_c d_ss`` of (3.7) repeat
    the same ``c d_ss`` and ``c k_ss`` in every sensitivity column. A pair used by n products
    costs one multiplication instead of n; the products keep their sign. A new temporary is
    defined as soon as both its factors are, so before every use.
    """
    exprs = [e for _, e in temporaries] + list(outputs)
    seen: dict[sp.Basic, None] = {}  # every distinct product, in first-occurrence order
    for expr in exprs:
        for node in sp.preorder_traversal(expr):
            if node.is_Mul and node not in seen:
                seen[node] = None
    muls = list(seen)
    products = [_product(m) for m in muls]
    keys: dict[sp.Basic, tuple] = {}

    def key(factor: sp.Basic) -> tuple:
        if factor not in keys:
            keys[factor] = sp.default_sort_key(factor)
        return keys[factor]

    def pairs(factors: list[sp.Basic]) -> list[tuple[sp.Basic, sp.Basic]]:
        ordered = sorted(factors, key=key)
        return [(a, b) for i, a in enumerate(ordered) for b in ordered[i + 1 :]]

    users: dict[tuple[sp.Basic, sp.Basic], set[int]] = {}
    for i, product in enumerate(products):
        for pair in pairs(product.factors):
            users.setdefault(pair, set()).add(i)
    generator = sp.numbered_symbols("_shared", cls=sp.Symbol)  # renamed by the caller
    new: list[tuple[sp.Symbol, sp.Basic, sp.Basic]] = []
    changed: set[int] = set()
    while True:
        shared = [(pair, len(u)) for pair, u in users.items() if len(u) >= 2]
        if not shared:
            break
        (a, b), _ = min(shared, key=lambda item: (-item[1], key(item[0][0]), key(item[0][1])))
        symbol = next(generator)
        new.append((symbol, a, b))
        for i in sorted(users[(a, b)]):
            product = products[i]
            for pair in pairs(product.factors):
                users[pair].discard(i)
            product.factors = [f for f in product.factors if f not in (a, b)] + [symbol]
            for pair in pairs(product.factors):
                users.setdefault(pair, set()).add(i)
            changed.add(i)
        users = {pair: u for pair, u in users.items() if u}
    if not new:
        return temporaries, outputs

    rewritten = {muls[i]: products[i] for i in changed}
    memo: dict[sp.Basic, sp.Basic] = {}

    def rebuild(node: sp.Basic) -> sp.Basic:
        if node in memo:
            return memo[node]
        if node in rewritten:
            product = rewritten[node]
            result = sp.Mul(product.sign, *(rebuild(o) for o in product.others), *product.factors)
        elif node.is_Atom or not node.args:
            result = node
        else:
            args = tuple(rebuild(a) for a in node.args)
            result = node.func(*args) if args != node.args else node
        memo[node] = result
        return result

    defined: set[sp.Basic] = set()
    pending = list(new)
    result: list[tuple[sp.Symbol, sp.Basic]] = []

    def emit_ready() -> None:
        progress = True
        while progress:
            progress = False
            for item in list(pending):
                symbol, a, b = item
                if all(f.is_Number or f not in temp_symbols or f in defined for f in (a, b)):
                    result.append((symbol, sp.Mul(a, b)))
                    defined.add(symbol)
                    pending.remove(item)
                    progress = True

    temp_symbols = {s for s, _ in temporaries} | {s for s, _, _ in new}
    # A temporary that was only such a pair (2*t0 when 2*t0 is shared) became an alias of the
    # new temporary: it is dropped and its uses refer to that temporary.
    alias: dict[sp.Basic, sp.Basic] = {}
    emit_ready()
    for symbol, expr in temporaries:
        expr = rebuild(expr).xreplace(alias) if alias else rebuild(expr)
        if expr.is_Symbol or expr.is_Number:
            alias[symbol] = expr
        else:
            result.append((symbol, expr))
        defined.add(symbol)
        emit_ready()
    outputs = [rebuild(e) for e in outputs]
    return result, [e.xreplace(alias) for e in outputs] if alias else outputs


def is_condition(expr: sp.Basic) -> bool:
    """Whether a temporary holds a condition (``int`` in C) rather than a number; a plain symbol
    is a SymPy ``Boolean`` too, but every symbol here is a number."""
    return isinstance(expr, Boolean) and not expr.is_Symbol


#: Functions the compilers turn into instructions, not calls.
_INLINE_FUNCTIONS = frozenset(("Abs", "floor", "ceiling", "Min", "Max", "sign", "Heaviside"))


def _is_call(expr: sp.Basic, max_power: int) -> bool:
    """A call of the math library as printed (``sin``, ``exp``, ``pow``, ...)."""
    if isinstance(expr, sp.Function):
        return type(expr).__name__ not in _INLINE_FUNCTIONS
    if expr.is_Pow:
        exp = expr.exp
        inline = exp.is_Integer and 1 <= abs(int(exp)) <= max_power
        return not (inline or exp == sp.S.Half or exp == -sp.S.Half)
    return False


def schedule_calls(
    temporaries: list[tuple[sp.Symbol, sp.Basic]], outputs: list[sp.Basic], max_power: int
) -> tuple[list[tuple[sp.Symbol, sp.Basic]], list[sp.Basic]]:
    """Compute every unconditional math-library call first, each as soon as its argument is.

    A call clobbers every floating-point register on the usual ABIs (x86-64 System V, AAPCS),
    so each value live across it is spilled to the stack and reloaded; with the calls first,
    little is live yet (the 24-state sensitivity right-hand side: 10 % faster at -O2). Calls
    inside a piecewise term stay where they are: they are evaluated only on their branch.
    """
    generator = sp.numbered_symbols("_call", cls=sp.Symbol)  # renamed by the caller
    extracted: dict[sp.Basic, sp.Symbol] = {}
    definitions: list[tuple[sp.Symbol, sp.Basic]] = []

    def collect(expr: sp.Basic) -> None:
        if expr.is_Atom or isinstance(expr, sp.Piecewise) or expr in extracted:
            return
        for arg in expr.args:
            collect(arg)
        if _is_call(expr, max_power):
            definitions.append((next(generator), expr.xreplace(extracted) if extracted else expr))
            extracted[expr] = definitions[-1][0]

    calls: list[tuple[sp.Symbol, sp.Basic]] = []
    others: list[tuple[sp.Symbol, sp.Basic]] = []
    for symbol, expr in temporaries:
        if _is_call(expr, max_power):  # already a call of its own: only moved
            for arg in expr.args:
                collect(arg)
            calls += definitions
            definitions.clear()
            calls.append((symbol, expr.xreplace(extracted) if extracted else expr))
        else:
            collect(expr)
            calls += definitions
            definitions.clear()
            others.append((symbol, expr.xreplace(extracted) if extracted else expr))
    for expr in outputs:
        collect(expr)
    calls += definitions
    outputs = [e.xreplace(extracted) for e in outputs] if extracted else list(outputs)
    if not calls:
        return temporaries, outputs

    names = {s for s, _ in temporaries} | {s for s, _ in calls}
    placed: set[sp.Basic] = set()
    result: list[tuple[sp.Symbol, sp.Basic]] = []

    def place_ready_calls() -> None:
        progress = True
        while progress:
            progress = False
            for item in list(calls):
                if (item[1].free_symbols & names) <= placed:
                    result.append(item)
                    placed.add(item[0])
                    calls.remove(item)
                    progress = True

    place_ready_calls()
    for item in others:
        result.append(item)
        placed.add(item[0])
        place_ready_calls()
    return result, outputs


def hoist(
    expr: sp.Basic,
    varying: set[sp.Symbol],
    new: list[tuple[sp.Symbol, sp.Basic]],
    keep_negations: bool = False,
) -> sp.Basic:
    """``expr`` with its subexpressions free of ``varying`` symbols moved into ``new``
    temporaries (``hp0, hp1, ...``): whole invariant subtrees, and the invariant terms of a sum
    and factors of a product grouped into one. Piecewise and boolean nodes stay as they are.
    ``keep_negations``: a negated symbol is left in place (a negation costs nothing where it
    is used), not made a temporary."""

    def invariant(e: sp.Basic) -> bool:
        return not (e.free_symbols & varying)

    def temporary(e: sp.Basic) -> sp.Basic:
        if e.is_Atom or (keep_negations and (-e).is_Atom):
            return e
        symbol = sp.Symbol(f"hp{len(new)}", real=True)
        new.append((symbol, e))
        return symbol

    if expr.is_Atom or isinstance(expr, (sp.Piecewise, Boolean)):
        return expr
    if invariant(expr):
        return temporary(expr)
    if expr.is_Add or expr.is_Mul:
        fixed = [a for a in expr.args if invariant(a)]
        moving = [hoist(a, varying, new, keep_negations) for a in expr.args if not invariant(a)]
        grouped = expr.func(*fixed) if fixed else None
        if (
            grouped is not None
            and not grouped.is_Atom
            and not (keep_negations and (-grouped).is_Atom)
        ):
            symbol = sp.Symbol(f"hp{len(new)}", real=True)
            new.append((symbol, grouped))
            grouped = symbol
        return expr.func(*([grouped] if grouped is not None else []), *moving, evaluate=False)
    if expr.is_Pow or isinstance(expr, sp.Function):
        args = (hoist(a, varying, new, keep_negations) for a in expr.args)
        return expr.func(*args, evaluate=False)
    return expr


def boolean_definitions(form: CseForm) -> dict[sp.Symbol, sp.Basic]:
    """The boolean temporaries of ``form`` (shared conditions), by symbol."""
    return {s: e for s, e in form.temporaries if is_condition(e)}


def cse_function(spec: FunctionExpressions, config: CodegenConfig | None = None) -> CseForm:
    """One CSE pass over all outputs of ``spec``, with deterministic temporaries ``t0, t1, ...``.

    After :func:`sympy.cse`, bases of small integer powers that are not plain symbols are hoisted
    into temporaries too, because the printer expands ``b**3`` to ``b*b*b`` and must not evaluate
    a compound ``b`` three times. Temporaries are finally renumbered in definition order.
    """
    config = config or CodegenConfig()
    max_power = config.precision.max_inline_power
    flat = tuple(e for m in spec.expressions for e in flatten_column_major(m))
    replacements, reduced = cse_of(flat, config.cse_optimizations)
    generator = sp.numbered_symbols("_hoisted", cls=sp.Symbol)  # renamed below, like the rest

    hoisted: list[tuple[sp.Symbol, sp.Basic]] = []
    memo: dict[sp.Basic, sp.Symbol] = {}

    done: dict[sp.Basic, sp.Basic] = {}  # shared subtrees are rewritten once

    def hoist(expr: sp.Basic) -> sp.Basic:
        if expr.is_Atom or not expr.args:
            return expr
        if expr in done:
            return done[expr]
        original = expr
        new_args = tuple(hoist(a) for a in expr.args)
        if new_args != expr.args:
            expr = expr.func(*new_args)
        if is_inline_power(expr, max_power):
            base = expr.base
            if base not in memo:
                memo[base] = next(generator)
                hoisted.append((memo[base], base))
            expr = sp.Pow(memo[base], expr.exp, evaluate=False)
        done[original] = expr
        return expr

    temporaries: list[tuple[sp.Symbol, sp.Basic]] = []
    for symbol, expr in replacements:
        new_expr = hoist(expr)
        temporaries.extend(hoisted)
        hoisted.clear()
        temporaries.append((symbol, new_expr))
    new_reduced = []
    for expr in reduced:
        new_expr = hoist(expr)
        temporaries.extend(hoisted)
        hoisted.clear()
        new_reduced.append(new_expr)

    temporaries, new_reduced = share_products(temporaries, new_reduced)
    temporaries, new_reduced = schedule_calls(temporaries, new_reduced, max_power)
    rename = {old: sp.Symbol(f"t{k}") for k, (old, _) in enumerate(temporaries)}
    temporaries = [(rename[s], e.xreplace(rename)) for s, e in temporaries]
    new_reduced = [e.xreplace(rename) for e in new_reduced]

    outputs = []
    offset = 0
    for out in spec.outputs:
        outputs.append(_unflatten_column_major(new_reduced[offset : offset + out.size], out.shape))
        offset += out.size
    return CseForm(tuple(temporaries), tuple(outputs))
