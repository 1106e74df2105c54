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


def smart_jacobian(
    exprs: Sequence[sp.Expr],
    variables: Sequence[sp.Symbol],
    free_symbols: Sequence[set[sp.Basic]] | None = None,
) -> sp.Matrix:
    """Jacobian ``d exprs / d variables`` that differentiates only where a variable occurs.

    Entries whose expression does not contain the variable are zero without calling ``diff``
    (which would still walk the whole expression). ``free_symbols`` may pass the precomputed
    free-symbol sets of ``exprs``. (:func:`gearsym.symbolic.codegen.smart_jacobian` is the
    forward-mode variant over a CSE graph that the emitters use.)
    """
    rows = []
    for i, e in enumerate(exprs):
        e = sp.sympify(e)
        free = e.free_symbols if free_symbols is None else free_symbols[i]
        rows.append([e.diff(v) if v in free else sp.S.Zero for v in variables])
    return sp.Matrix(len(rows), len(variables), lambda i, j: rows[i][j])
