"""The emitted extended UIO (thesis 4.5): what ``euio_step`` of ``templates/c_euio.c.j2`` needs
from the function table, and its stated operation count.

The rows themselves (``jac_outputs``, ``euio_load_column``, ``euio_step``) are in
:mod:`gearsym.symbolic.codegen.table`; the filter they implement operation by operation is
:func:`gearsym.symbolic.estimators.euio.euio_step_full`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from gearsym.symbolic.codegen.ops import OpCount
from gearsym.symbolic.codegen.table import FunctionTable

__all__ = ["CasadiEuioView", "casadi_euio_view", "euio_own_ops", "euio_step_extra"]


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


def euio_step_extra(
    table: FunctionTable, counts: Mapping[str, OpCount]
) -> tuple[dict[str, Any], str, set[str], set[str]]:
    """(the view fields of ``euio_step``, its operation text for the doc comment, the math
    macros and helpers its printed prediction uses)."""
    layout = table.config.euio
    assert layout is not None
    nx, ny = len(table.states), len(table.model.outputs)
    names = [v.name for v in table.model.states]
    frozen = ", ".join(
        f"{names[i]} while |{table.model.inputs[j].name}| <= 0.5" for i, j in layout.frozen
    )
    from gearsym.symbolic.codegen.c.emitter import predict_body

    jac_ops = counts.get("jac_x_sparse", counts.get("jac_x"))
    assert jac_ops is not None
    code, fused, macros, helpers = predict_body(table, inputs="u_prev")
    predict = fused.once_ops + fused.stage_ops.scaled(4) + code.ops
    own = euio_own_ops(nx, ny)
    total = (
        predict
        + jac_ops
        + counts["outputs"]
        + counts["jac_outputs"]
        + counts["euio_load_column"]
        + own
    )
    phases = "; ".join(
        f"{phase}: {', '.join(names[i] for i in held) or 'none'}"
        for phase, held, _ in layout.held_phases
    )
    reasons = list(
        dict.fromkeys(
            r for _, _, why in layout.held_phases for r in why.replace("μ", "mu").split("; ") if r
        )
    )
    # series, rate, E, E_d; J, dstage, FP; C, CP, K/L; S, S^-1; 7 of size NY; the prediction's
    stack = 5 * nx + 3 * nx * nx + 3 * nx * ny + 2 * ny * ny + 7 * ny + code.stack
    text = (
        f"Held by the element modes: {frozen or 'none'}. "
        + (
            f"Pass held[] per phase as the library's existence result (4.4, "
            f"euio_phase_masks) says: {phases}; because {'; '.join(reasons)}. "
            if phases
            else ""
        )
        + f"Operations (about): {total.format()} (the prediction as ekf_predict: "
        f"{predict.format()}; jac_x + outputs + jac_outputs + the load column + "
        f"{own.format()}); stack: {stack} reals."
    )
    extra = {
        "frozen": layout.frozen,
        "declarations": code.declarations,
        "statements": code.statements,
    }
    return extra, text, macros, helpers
