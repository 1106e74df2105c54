"""Small SymPy helpers, one purpose each."""

from __future__ import annotations

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


def smart_jacobian(expressions: sp.Matrix, variables: list[sp.Symbol]) -> sp.Matrix:
    """∂expressions/∂variables, differentiating only entries in which the variable occurs."""
    result = sp.zeros(expressions.rows, len(variables))
    for i in range(expressions.rows):
        entry = expressions[i]
        present = entry.free_symbols
        for j, v in enumerate(variables):
            if v in present:
                result[i, j] = sp.diff(entry, v)
    return result
