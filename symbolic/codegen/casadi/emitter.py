"""The CasADi emitter: a function table and its CSE'd forms in, ``gearsym_<model>_casadi.py`` out.

Only the expression functions (rhs, outputs, the Jacobians) are emitted; step and parameter
functions are C-only (CasADi has its own integrators). Two exceptions, appended as whole
CasADi functions: the extended UIO's ``euio_step`` (``templates/casadi_euio.py.j2``) and the
EKF's own mode logic ``ekf_mode_update`` (``templates/casadi_ekf_modes.py.j2``, if_else logic
in SX with the lock-up maps as constants; the C code's ``ekf_mode_update``). A Jacobian is
a sparse SX matrix holding exactly the structural nonzeros of the C code's pattern.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.codegen.casadi.printer import CasadiPrinter, python_tuple
from gearsym.symbolic.codegen.cse import CseForm, boolean_definitions
from gearsym.symbolic.codegen.printing import float_repr
from gearsym.symbolic.codegen.render import render
from gearsym.symbolic.codegen.table import FunctionSpec, FunctionTable, file_names
from gearsym.symbolic.codegen.views import ModelView, model_view

__all__ = ["CasadiFunctionView", "CasadiModuleView", "emit_casadi_files"]


@dataclass(frozen=True)
class Entry:
    row: int
    col: int
    code: str


@dataclass(frozen=True)
class CasadiOutput:
    name: str
    shape: tuple[int, int]
    entries: tuple[Entry, ...]  # the structural nonzeros, column-major


@dataclass(frozen=True)
class Temporary:
    name: str
    code: str


@dataclass(frozen=True)
class CasadiFunctionView:
    name: str
    doc: str  # safe inside a triple-quoted docstring
    temporaries: tuple[Temporary, ...]
    outputs: tuple[CasadiOutput, ...]


@dataclass(frozen=True)
class Names:
    states: str  # source text of a tuple of names
    inputs: str
    parameters: str
    outputs: str


@dataclass(frozen=True)
class CasadiModuleView(ModelView):
    functions: tuple[CasadiFunctionView, ...]
    helpers: tuple[str, ...]
    defaults: str  # source text of the default parameter tuple
    model_name_repr: str
    names: Names


def _symbol_map(spec: FunctionSpec) -> dict[sp.Symbol, str]:
    return {s: f"{arg.name}[{i}]" for arg in spec.args for i, s in enumerate(arg.symbols)}


def _docstring(text: str) -> str:
    # Quotes and backslashes from user text could end the docstring early.
    return " ".join(text.split()).replace("\\", "/").replace('"', "'")


def _function_view(
    table: FunctionTable, spec: FunctionSpec, form: CseForm
) -> tuple[CasadiFunctionView, set[str]]:
    printer = CasadiPrinter(_symbol_map(spec), boolean_definitions(form), table.config.precision)
    temporaries = tuple(Temporary(printer.code(s), printer.code(e)) for s, e in form.temporaries)
    outputs = []
    doc = spec.doc
    if spec.kind == "spread":  # the sparse row's nonzeros, placed by its pattern
        pattern = spec.pattern
        assert pattern is not None
        (out,) = spec.outputs
        (values,) = form.outputs
        entries = tuple(
            Entry(position % pattern.nrow, position // pattern.nrow, printer.code(values[k]))
            for k, position in enumerate(pattern.positions())
        )
        outputs.append(CasadiOutput(out.name, out.shape, entries))
        doc += f" Sparse: the {pattern.nnz} structural nonzeros of the C code's pattern."
    else:
        for out, matrix in zip(spec.outputs, form.outputs, strict=True):
            entries = tuple(
                Entry(i, j, printer.code(matrix[i, j]))
                for j in range(out.shape[1])
                for i in range(out.shape[0])
                if matrix[i, j] != 0  # keep CasADi's structural sparsity
            )
            outputs.append(CasadiOutput(out.name, out.shape, entries))
    view = CasadiFunctionView(spec.name, _docstring(doc), temporaries, tuple(outputs))
    return view, printer.used_helpers


@dataclass(frozen=True)
class CasadiModeElement:
    """One element of ``templates/casadi_ekf_modes.py.j2``: Python source of its constants."""

    name: str
    normal_force: int
    slide: int
    stick: int
    slip_sign: int
    mu: int
    lock_map: tuple[str, ...]  # rows of the lock-up map's gearbox block, comma-separated


@dataclass(frozen=True)
class CasadiModeView:
    """What ``templates/casadi_ekf_modes.py.j2`` prints (the EKF's own mode logic)."""

    elements: tuple[CasadiModeElement, ...]
    n_physical: int
    confidence: str


def _python_row(row: tuple[object, ...]) -> str:
    """The entries of a tuple literal (a one-entry tuple keeps its comma)."""
    text = ", ".join(float_repr(float(sp.sympify(v))) for v in row)
    return text + "," if len(row) == 1 else text


def casadi_mode_view(table: FunctionTable) -> CasadiModeView:
    """The constants of the CasADi ``ekf_mode_update`` appended to the EKF's CasADi module: the
    same :class:`~gearsym.symbolic.codegen.config.EkfLayout` the C ``ekf_mode_update`` is
    printed from, the lock-up maps as Python floats (exact rationals rounded once)."""
    layout = table.config.ekf
    assert layout is not None and layout.modes
    elements = tuple(
        CasadiModeElement(
            repr(e.name),
            e.normal_force,
            e.slide,
            e.stick,
            e.slip_sign,
            e.mu,
            tuple(_python_row(row) for row in e.lock_map),
        )
        for e in layout.modes
    )
    return CasadiModeView(
        elements, len(layout.modes[0].lock_map), float_repr(float(layout.lock_up_confidence))
    )


def emit_casadi_files(table: FunctionTable, forms: Mapping[str, CseForm]) -> dict[str, str]:
    """``{"gearsym_<name>_casadi.py": ...}`` of one model."""
    model = table.model
    functions = []
    helpers: set[str] = set()
    for spec in table:
        if spec.kind == "expr" and spec.pattern is None:
            form = forms[spec.name]
        elif spec.kind == "spread":
            assert spec.source is not None
            form = forms[spec.source]
        else:
            continue  # sparse rows live on in their spread row; steps and parameters are C-only
        view, used = _function_view(table, spec, form)
        functions.append(view)
        helpers |= used
    defaults = [
        'float("nan")' if v.default is None else float_repr(float(v.default))
        for v in model.parameters
    ]
    view = CasadiModuleView(
        **vars(model_view(table)),
        functions=tuple(functions),
        helpers=tuple(sorted(helpers)),
        defaults=python_tuple(defaults),
        model_name_repr=repr(model.name),
        names=Names(
            states=python_tuple([repr(v.name) for v in model.states]),
            inputs=python_tuple([repr(v.name) for v in model.inputs]),
            parameters=python_tuple([repr(v.name) for v in model.parameters]),
            outputs=python_tuple([repr(v.name) for v in model.outputs]),
        ),
    )
    text = render("casadi_module.py.j2", view)
    if table.config.euio is not None:
        from gearsym.symbolic.codegen.euio import casadi_euio_view

        text += render("casadi_euio.py.j2", casadi_euio_view(table))
    if table.config.ekf is not None and table.config.ekf.modes:
        text += render("casadi_ekf_modes.py.j2", casadi_mode_view(table))
    return {file_names(model)["casadi"]: text}
