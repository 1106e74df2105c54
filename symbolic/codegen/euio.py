"""The emitted extended UIO (thesis 4.5): the view of the CasADi ``euio_step`` and the
operation count of the C one (whose view, with the printed prediction, is
:func:`gearsym.symbolic.codegen.c.emitter.euio_step_extra`).

The rows themselves (``jac_outputs``, ``euio_load_column``, ``euio_step``) are in
:mod:`gearsym.symbolic.codegen.table`; the filter they implement operation by operation is
:func:`gearsym.symbolic.estimators.euio.euio_step_full`.
"""

from __future__ import annotations

from dataclasses import dataclass

from gearsym.symbolic.codegen.ops import OpCount
from gearsym.symbolic.codegen.table import FunctionTable

__all__ = ["CasadiEuioView", "casadi_euio_view", "euio_own_ops"]


@dataclass(frozen=True)
class CasadiEuioView:
    """What ``templates/casadi_euio.py.j2`` prints: Python source of the constants."""

    frozen: str
    phases: str


def casadi_euio_view(table: FunctionTable) -> CasadiEuioView:
    """The view of the CasADi ``euio_step`` appended to the model's CasADi module."""
    layout = table.config.euio
    assert layout is not None
    phases = ", ".join(f"{phase!r}: {tuple(held)!r}" for phase, held, _ in layout.held_phases)
    return CasadiEuioView(frozen=repr(tuple(layout.frozen)), phases="{" + phases + "}")


def euio_own_ops(nx: int, ny: int) -> OpCount:
    """Operations of ``euio_step`` beyond its calls (jac_x, outputs, jac_outputs, the load
    column) and its prediction (the code of ekf_predict, counted by :mod:`.c.ekf_code`),
    counted from the template's loops: the series E_d (3 n² + 4 n),
    C P C^T (m n² + m² n), the LDL^T of S and S^-1 (about 2 m³), P C^T S^-1 (n m²), the gain
    L (n m² + 2 n m), I - L C (n² m), the Joseph form (2 n³ + n² m), the symmetrisations."""
    n, m = nx, ny
    mul = (3 * n * n + 4 * n) + (m * n * n + m * m * n)
    mul += 2 * m**3 + 2 * n * m * m + 2 * n * m + 2 * n * n * m + 2 * n**3 + n * n
    add = (3 * n * n + 3 * n) + (m * n * n + m * m * n)
    add += 2 * m**3 + 2 * n * m * m + 2 * n * m + 2 * n * n * m + 2 * n**3 + n * n
    return OpCount(mul=mul, add=add, div=m + 1)
