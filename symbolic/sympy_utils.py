"""Small SymPy helpers, one purpose each."""

from __future__ import annotations

from collections.abc import Sequence

import sympy as sp
from sympy.polys.matrices import DomainMatrix


def exact_nullspace(matrix: sp.Matrix) -> list[sp.Matrix]:
    """Basis of the null space, computed over the exact field of the entries.

    Uses SymPy's DomainMatrix (fraction-field arithmetic, no expression simplification), which
    is orders of magnitude faster than ``Matrix.nullspace`` for entries with symbols.
    """
    if matrix.rows == 0:
        return [sp.eye(matrix.cols)[:, i] for i in range(matrix.cols)]
    basis = DomainMatrix.from_Matrix(matrix).to_field().nullspace().to_Matrix()
    return [basis[i, :].T for i in range(basis.rows)]


#: Functions of one argument whose derivative is ``fdiff(1)`` times that of the argument.
_CHAIN_RULE_FUNCTIONS = frozenset(
    (sp.sin, sp.cos, sp.tan, sp.exp, sp.log, sp.sinh, sp.cosh, sp.tanh, sp.asin, sp.acos, sp.atan)
)


def derivative(expr: sp.Basic, symbol: sp.Symbol) -> sp.Basic:
    """``d expr / d symbol``, the same expression as ``expr.diff(symbol)``, faster.

    Applies the sum, product, constant-power and chain rules itself to the node types the
    derivation produces, building the same canonical expressions as SymPy's ``diff`` (which
    applies the same rules through ``_eval_derivative``) without its per-node ``Derivative``
    dispatch: that dispatch was most of the time ``gearsym generate`` spent differentiating.
    Every other node (Abs, sign, Piecewise, Min, Max, ...) goes to ``diff`` itself.
    """
    return _derivative(sp.sympify(expr), symbol, {}) or sp.S.Zero


def _derivative(
    expr: sp.Basic, symbol: sp.Symbol, memo: dict[sp.Basic, sp.Basic | None]
) -> sp.Basic | None:
    """:func:`derivative`, ``None`` where it is zero; ``memo`` holds the visited nodes."""
    if expr in memo:
        return memo[expr]
    result: sp.Basic | None
    if expr == symbol:
        result = sp.S.One
    elif expr.is_Atom:
        result = None
    elif expr.is_Add:
        parts = [_derivative(a, symbol, memo) for a in expr.args]
        nonzero = [d for d in parts if d is not None]
        result = sp.Add(*nonzero) if nonzero else None
    elif expr.is_Mul:
        args = list(expr.args)
        terms = []
        for i, arg in enumerate(args):
            d = _derivative(arg, symbol, memo)
            if d is not None:
                terms.append(sp.Mul(*args[:i], d, *args[i + 1 :]))
        result = sp.Add(*terms) if terms else None
    elif expr.is_Pow and not expr.exp.has(symbol):
        d = _derivative(expr.base, symbol, memo)
        result = None if d is None else expr * expr.exp * d / expr.base
    elif expr.func in _CHAIN_RULE_FUNCTIONS:
        d = _derivative(expr.args[0], symbol, memo)
        result = None if d is None else expr.fdiff(1) * d
    else:
        result = expr.diff(symbol) if expr.has(symbol) else None
    if result is not None and result == 0:
        result = None
    memo[expr] = result
    return result


def smart_jacobian(
    exprs: Sequence[sp.Expr],
    variables: Sequence[sp.Symbol],
    free_symbols: Sequence[set[sp.Basic]] | None = None,
    by_rules: bool = False,
) -> sp.Matrix:
    """Jacobian ``d exprs / d variables`` that differentiates only where a variable occurs.

    Entries whose expression does not contain the variable are zero without calling ``diff``
    (which would still walk the whole expression). ``free_symbols`` may pass the precomputed
    free-symbol sets of ``exprs``. ``by_rules`` differentiates with :func:`derivative` (the
    same expressions, several times faster) instead of ``diff``.
    (:func:`gearsym.symbolic.codegen.smart_jacobian` is the forward-mode variant over a CSE
    graph that the emitters use.)
    """
    rows = []
    for i, e in enumerate(exprs):
        e = sp.sympify(e)
        free = e.free_symbols if free_symbols is None else free_symbols[i]
        diff = derivative if by_rules else sp.Expr.diff
        rows.append([diff(e, v) if v in free else sp.S.Zero for v in variables])
    return sp.Matrix(len(rows), len(variables), lambda i, j: rows[i][j])
