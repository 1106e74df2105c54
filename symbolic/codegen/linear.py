"""Linear systems ẋ = A(p) x + B(p) u as code: several systems of one parameter struct per file.

A :class:`LinearSystemSet` is the emitters' view of a group of linear forms (5.1): each system
names its states and inputs and holds A and B as expressions in the set's parameters only.
:func:`linear_table` binds it to the same function table the models use: ``params_default``
and ``params_validate`` from :data:`~gearsym.symbolic.codegen.table.ROWS`, and one expression
row per system that writes A and B in one call (one CSE over both, since they share the inverse
inertias). :func:`emit_linear_files` prints ``gearsym_<set>.{h,c}`` and
``gearsym_<set>_casadi.py`` through the model emitters' function views and one strict render.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.codegen.c.emitter import CFunctionView, _function_views
from gearsym.symbolic.codegen.casadi.emitter import CasadiFunctionView, _function_view
from gearsym.symbolic.codegen.casadi.printer import python_tuple
from gearsym.symbolic.codegen.config import CodegenConfig, as_config
from gearsym.symbolic.codegen.cse import CseForm, cse_function
from gearsym.symbolic.codegen.printing import comment_text, float_repr, wrap
from gearsym.symbolic.codegen.render import render
from gearsym.symbolic.codegen.table import (
    Arg,
    FunctionSpec,
    FunctionTable,
    Output,
    _normalise_bounds,
    parameter_functions,
    real_symbols,
)
from gearsym.symbolic.codegen.views import ModelView, model_view
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.naming import c_identifier_problem, function_prefix, macro_prefix

__all__ = [
    "LinearSystem",
    "LinearSystemSet",
    "emit_linear_files",
    "linear_table",
]


@dataclass(frozen=True)
class LinearSystem:
    """ẋ = A x + B u with A, B in the set's parameters (no state or input symbol in them)."""

    name: str  # a C identifier part: the functions are gearsym_<set>_<name>
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    A: sp.Matrix
    B: sp.Matrix
    summary: str
    notes: tuple[str, ...] = ()  # further lines for the header comment


@dataclass(frozen=True)
class LinearSystemSet:
    """Linear systems emitted into one file pair, sharing one parameter struct."""

    name: str  # model name of the files: gearsym_<name>.h
    parameters: tuple[Variable, ...]
    systems: tuple[LinearSystem, ...]
    metadata: dict[str, str]

    def as_model(self) -> Model:
        """A stateless :class:`Model` carrying the set's name, parameters and provenance (what
        the parameter rows and the file names need)."""
        return Model(
            name=self.name,
            states=(),
            inputs=(),
            parameters=self.parameters,
            outputs=(),
            rhs=sp.zeros(0, 1),
            output_expressions=sp.zeros(0, 1),
            metadata=self.metadata,
        )


def _check(s: LinearSystemSet) -> None:
    """The names a set's files are made of are C identifiers, each system fits its sizes and
    uses parameters only."""
    problems = []
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", s.name):
        problems.append(f"set name {s.name!r} must match [A-Za-z][A-Za-z0-9_]*")
    for v in s.parameters:
        problem = c_identifier_problem(v.name)
        if problem:
            problems.append(f"parameter {v.name!r} {problem}")
    names = [system.name for system in s.systems]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        problems.append(f"systems named twice: {twice}")
    parameters = {v.symbol for v in s.parameters}
    for system in s.systems:
        problem = c_identifier_problem(system.name)
        if problem:
            problems.append(f"system {system.name!r} {problem}")
        n, m = len(system.states), len(system.inputs)
        if system.A.shape != (n, n) or system.B.shape != (n, m):
            problems.append(
                f"system {system.name!r}: A {system.A.shape} and B {system.B.shape} do not fit "
                f"{n} states and {m} inputs"
            )
        stray = (system.A.free_symbols | system.B.free_symbols) - parameters
        if stray:
            problems.append(f"system {system.name!r} uses non-parameters {sorted(map(str, stray))}")
    if problems:
        raise ValueError(f"linear set {s.name!r} cannot be emitted: " + "; ".join(problems))


def linear_table(s: LinearSystemSet, config: CodegenConfig | None = None) -> FunctionTable:
    """The function table of a set: the parameter rows of :data:`ROWS`, then one row per
    system, ``<system>(p, A, B)``."""
    config = as_config(config)
    model = s.as_model()
    _check(s)
    bounds = _normalise_bounds(model, config.bounds)
    real = real_symbols(model)
    ps = tuple(real[v.symbol] for v in model.parameters)
    p_arg = Arg("p", len(ps), True, "params", ps, tuple(v.name for v in model.parameters))
    prefix, macro = function_prefix(model.name), macro_prefix(model.name)
    functions = parameter_functions(model, bounds, p_arg)
    changed = {old: new for old, new in real.items() if old != new}
    for system in s.systems:
        n, m = len(system.states), len(system.inputs)
        a = sp.ImmutableMatrix(system.A.xreplace(changed))
        b = sp.ImmutableMatrix(system.B.xreplace(changed))
        doc = (
            f"{system.summary}. xdot = A x + B u with x = [{', '.join(system.states)}], "
            f"u = [{', '.join(system.inputs)}]: writes A ({n} x {n}) and B ({n} x {m}), "
            "dense column-major, A[i + j*NX] = d xdot_i / d x_j, from the parameters alone."
        )
        functions.append(
            FunctionSpec(
                system.name,
                (p_arg,),
                (Output("A", (n, n)), Output("B", (n, m))),
                (a, b),
                doc,
            )
        )
    return FunctionTable(
        model=model,
        config=config,
        prefix=prefix,
        macro_prefix=macro,
        states=(),
        inputs=(),
        parameters=ps,
        bounds=bounds,
        functions=tuple(functions),
    )


@dataclass(frozen=True)
class SystemView:
    """One system as the header prints it: sizes, index macros and the modes it serves."""

    name: str
    macro: str  # GEARSYM_<SET>_<SYSTEM>_
    nx: int
    nu: int
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    notes: tuple[str, ...]


@dataclass(frozen=True)
class CLinearView(ModelView):
    """What ``c_linear.h.j2`` and ``c_linear.c.j2`` print."""

    systems: tuple[SystemView, ...]
    functions: tuple[CFunctionView, ...]
    restrict_pointers: bool


@dataclass(frozen=True)
class CasadiLinearView(ModelView):
    """What ``casadi_linear.py.j2`` prints."""

    systems: tuple[SystemView, ...]
    functions: tuple[CasadiFunctionView, ...]
    defaults: str
    parameter_names: str
    model_name_repr: str
    sizes: tuple[tuple[str, int, int, str, str], ...]  # name, nx, nu, states, inputs (source)


def emit_linear_files(s: LinearSystemSet, config: CodegenConfig | None = None) -> dict[str, str]:
    """``{"gearsym_<set>.h", "gearsym_<set>.c", "gearsym_<set>_casadi.py"}`` of a set."""
    table = linear_table(s, config)
    forms: dict[str, CseForm] = {
        spec.name: cse_function(spec, table.config) for spec in table if spec.kind == "expr"
    }
    functions, used_macros, used_helpers = _function_views(table, forms)
    if used_helpers or used_macros:  # A and B are rational in the parameters
        raise ValueError(
            f"linear set {s.name!r} needs helpers {sorted(used_helpers | used_macros)}"
        )
    base = model_view(table)
    macro = table.macro_prefix
    systems = tuple(
        SystemView(
            system.name,
            f"{macro}{system.name.upper()}_",
            len(system.states),
            len(system.inputs),
            system.states,
            system.inputs,
            tuple(line for note in system.notes for line in wrap(comment_text(note))),
        )
        for system in s.systems
    )
    c_view = CLinearView(
        **vars(base),
        systems=systems,
        functions=tuple(functions),
        restrict_pointers=table.config.restrict_pointers,
    )
    casadi_functions = []
    for spec in table:
        if spec.kind == "expr":
            view, used = _function_view(table, spec, forms[spec.name])
            if used:
                raise ValueError(f"linear set {s.name!r} needs CasADi helpers {sorted(used)}")
            casadi_functions.append(view)
    casadi_view = CasadiLinearView(
        **vars(base),
        systems=systems,
        functions=tuple(casadi_functions),
        defaults=python_tuple(
            [
                'float("nan")' if v.default is None else float_repr(float(v.default))
                for v in s.parameters
            ]
        ),
        parameter_names=python_tuple([repr(v.name) for v in s.parameters]),
        model_name_repr=repr(s.name),
        sizes=tuple(
            (
                system.name,
                len(system.states),
                len(system.inputs),
                python_tuple([repr(n) for n in system.states]),
                python_tuple([repr(n) for n in system.inputs]),
            )
            for system in s.systems
        ),
    )
    return {
        base.header_name: render("c_linear.h.j2", c_view),
        base.source_name: render("c_linear.c.j2", c_view),
        base.casadi_name: render("casadi_linear.py.j2", casadi_view),
    }
