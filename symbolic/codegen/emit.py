"""The public entry points: one model and one config in, emitted files out."""

from __future__ import annotations

from gearsym.symbolic.codegen.c.emitter import emit_c_files
from gearsym.symbolic.codegen.casadi.emitter import emit_casadi_files
from gearsym.symbolic.codegen.config import Bounds, CodegenConfig
from gearsym.symbolic.codegen.cse import CseForm, cse_function
from gearsym.symbolic.codegen.table import FunctionTable, build_function_table
from gearsym.symbolic.model import Model

__all__ = ["cse_forms", "emit_all", "emit_c", "emit_casadi"]


def cse_forms(table: FunctionTable) -> dict[str, CseForm]:
    """The CSE'd form of every expression row (one CSE pass per function over all its
    outputs), computed once for all emitters."""
    return {spec.name: cse_function(spec, table.config) for spec in table if spec.kind == "expr"}


def emit_c(model: Model, config: CodegenConfig | Bounds | None = None) -> dict[str, str]:
    """The C99 header and source of ``model``: ``{"gearsym_<name>.h": ..., ".c": ...}``.

    ``config`` (or a bare bounds mapping, parameter name -> ``(min, max)``, for
    ``params_validate``) makes every language decision.
    """
    table = build_function_table(model, config)
    return emit_c_files(table, cse_forms(table))


def emit_casadi(model: Model, config: CodegenConfig | Bounds | None = None) -> dict[str, str]:
    """A Python module building ``casadi.Function`` objects and a CVODES integrator."""
    table = build_function_table(model, config)
    return emit_casadi_files(table, cse_forms(table))


def emit_all(model: Model, config: CodegenConfig | Bounds | None = None) -> dict[str, str]:
    """All emitted files of ``model`` (C header, C source, CasADi module), keyed by file name.

    Builds the table and the CSE'd forms once for both emitters.
    """
    table = build_function_table(model, config)
    forms = cse_forms(table)
    return {**emit_c_files(table, forms), **emit_casadi_files(table, forms)}
