"""Common-subexpression elimination: one pass over all outputs of one emitted function."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import sympy as sp
from gearsym.symbolic.codegen.config import CodegenConfig
from gearsym.symbolic.codegen.expressions import is_inline_power
from sympy.logic.boolalg import Boolean

if TYPE_CHECKING:
    from gearsym.symbolic.codegen.table import FunctionSpec

__all__ = ["CseForm", "boolean_definitions", "cse_function", "cse_of", "flatten_column_major"]


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


def boolean_definitions(form: CseForm) -> dict[sp.Symbol, sp.Basic]:
    """The boolean temporaries of ``form`` (shared conditions), by symbol."""
    return {s: e for s, e in form.temporaries if isinstance(e, Boolean)}


def cse_function(spec: FunctionSpec, config: CodegenConfig | None = None) -> CseForm:
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

    def hoist(expr: sp.Basic) -> sp.Basic:
        if expr.is_Atom or not expr.args:
            return expr
        new_args = tuple(hoist(a) for a in expr.args)
        if new_args != expr.args:
            expr = expr.func(*new_args)
        if is_inline_power(expr, max_power):
            base = expr.base
            if base not in memo:
                memo[base] = next(generator)
                hoisted.append((memo[base], base))
            return sp.Pow(memo[base], expr.exp, evaluate=False)
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

    rename = {old: sp.Symbol(f"t{k}") for k, (old, _) in enumerate(temporaries)}
    temporaries = [(rename[s], e.xreplace(rename)) for s, e in temporaries]
    new_reduced = [e.xreplace(rename) for e in new_reduced]

    outputs = []
    offset = 0
    for out in spec.outputs:
        outputs.append(_unflatten_column_major(new_reduced[offset : offset + out.size], out.shape))
        offset += out.size
    return CseForm(tuple(temporaries), tuple(outputs))
