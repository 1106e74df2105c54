"""The hybrid shift model's sensitivities (3.7) across switches as code: one file pair per shift.

:func:`hybrid_table` binds a :class:`~gearsym.symbolic.hybrid_sensitivity.HybridSensitivity` to
the function table the models use: ``params_default`` and ``params_validate`` of
:data:`~gearsym.symbolic.codegen.table.ROWS`, and per mode ``m<i>_rhs`` (the augmented
[f; vec S]) and ``m<i>_guards`` (every guard out of the mode and its condition), per transition
``jump_<i>_<j>`` ([x⁺; vec S⁺] with the event-time term). Modes are numbered because their
names (the status of each swapping element) would make identifiers too long to stay distinct
in the 31 characters C99 guarantees; the header maps numbers to statuses, guards and targets.
:func:`emit_hybrid_files` prints ``gearsym_<set>.{h,c}`` and ``gearsym_<set>_casadi.py``
through the model emitters' function views and one strict render.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.codegen.c.emitter import (
    _BINARY_FUNCTIONS,
    CFunctionView,
    MathMacro,
    _function_views,
)
from gearsym.symbolic.codegen.casadi.emitter import CasadiFunctionView, _function_view
from gearsym.symbolic.codegen.casadi.printer import python_tuple
from gearsym.symbolic.codegen.config import CodegenConfig, as_config
from gearsym.symbolic.codegen.cse import CseForm, cse_function
from gearsym.symbolic.codegen.printing import float_repr
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
from gearsym.symbolic.hybrid_sensitivity import HybridSensitivity
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.naming import function_prefix, macro_prefix

__all__ = [
    "emit_hybrid_files",
    "hybrid_set_model",
    "hybrid_set_name",
    "hybrid_table",
]


def hybrid_set_name(hs: HybridSensitivity) -> str:
    """``hybrid_<a>_<b>_sens``: the files ``gearsym_hybrid_<a>_<b>_sens.{h,c}``."""
    spec = hs.hybrid.spec
    return f"hybrid_{spec.from_gear}_{spec.to_gear}_sens"


def hybrid_set_model(hs: HybridSensitivity) -> Model:
    """A stateless :class:`Model` with the set's name, inputs and parameters (what the parameter
    rows, the symbol names and the file names need)."""
    spec = hs.hybrid.spec
    metadata = {
        "equations": "3.7 in every mode; jumps of hybrid sensitivity analysis at switches",
        "content": f"hybrid shift {spec.name}: sensitivities across lock-up and break-away",
        "sensitivity_parameters": " ".join(v.name for v in hs.parameters),
    }
    for element, locks in hs.hybrid.one_way.items():
        metadata[f"one_way_{element}"] = (
            f"{element} is a one-way clutch (blocks slip sign {locks:+d}): locked or overrunning "
            f"(torque 0, slip sign {-locks:+d}), never open or sliding; it has no F_N, so u has "
            f"no entry for it. Its release (g = {locks:+d} * its reaction torque, falling) and "
            "lock-up (g = its slip, crossing towards the blocked sign) depend on the state: "
            "locate them inside the step like break-away and lock-up. A locked freewheel whose "
            "g is already negative at the start or after a switch releases at once (the caller "
            "switches)"
        )
    return Model(
        name=hybrid_set_name(hs),
        states=(),
        inputs=(*hs.inputs, *hs.input_rates),
        parameters=hs.hybrid.parameters,
        outputs=(),
        rhs=sp.zeros(0, 1),
        output_expressions=sp.zeros(0, 1),
        metadata=metadata,
    )


def _real(variables: tuple[Variable, ...]) -> dict[sp.Symbol, sp.Symbol]:
    return real_symbols(
        Model("symbols", variables, (), (), (), sp.zeros(len(variables), 1), sp.zeros(0, 1))
    )


def hybrid_table(hs: HybridSensitivity, config: CodegenConfig | None = None) -> FunctionTable:
    """The function table of a shift's hybrid sensitivities (module docstring)."""
    config = as_config(config)
    model = hybrid_set_model(hs)
    bounds = _normalise_bounds(model, config.bounds)
    real = real_symbols(model)
    ps = tuple(real[v.symbol] for v in model.parameters)
    p_arg = Arg("p", len(ps), True, "params", ps, tuple(v.name for v in model.parameters))
    u_arg = Arg("u", len(hs.inputs), True, "vector", tuple(real[v.symbol] for v in hs.inputs))
    rate_arg = Arg(
        "u_rate", len(hs.input_rates), True, "vector", tuple(real[v.symbol] for v in hs.input_rates)
    )
    functions = parameter_functions(model, bounds, p_arg)
    state_maps = {m.index: _real(m.states) for m in hs.modes}
    x_args = {
        m.index: Arg("x", len(m.states), True, "vector", tuple(state_maps[m.index].values()))
        for m in hs.modes
    }

    def bound(expr: sp.Matrix, index: int) -> sp.ImmutableMatrix:
        return sp.ImmutableMatrix(expr.xreplace({**real, **state_maps[index]}))

    m = len(hs.parameters)
    for mode in hs.modes:
        n_aug = len(mode.states)
        functions.append(
            FunctionSpec(
                f"m{mode.index}_rhs",
                (x_args[mode.index], u_arg, p_arg),
                (Output("xdot", (n_aug, 1)),),
                (bound(mode.rhs, mode.index),),
                f"Mode {mode.index} ({mode.label}): xdot = [f; vec(df/dx S + df/dp)] (3.7) "
                f"of x = [the {mode.nx} mode states; S column by column, {m} parameters].",
            )
        )
        ng = len(mode.guards)
        functions.append(
            FunctionSpec(
                f"m{mode.index}_guards",
                (x_args[mode.index], u_arg, p_arg),
                (Output("g", (ng, 1)), Output("c", (ng, 1))),
                (bound(mode.guard_values, mode.index), bound(mode.conditions, mode.index)),
                f"Mode {mode.index} ({mode.label}): the value g[k] of each guard out of the "
                "mode (it fires when g[k] crosses zero in its direction) and its condition "
                "c[k] at the crossing (c >= 0: the guard's target, else its alternative); "
                "the header's GUARD table names each.",
            )
        )
    for jump in hs.jumps:
        target = hs.modes[jump.target]
        term = (
            "with the event-time term (A f- - f+) dtau/dp, dtau/dp = -(g_x S + g_p) / "
            "(g_x f- + g_u u_rate)"
            if jump.event_time
            else "the guard depends on the inputs alone (a fixed switching time): S+ = A S-"
        )
        functions.append(
            FunctionSpec(
                f"jump_{jump.source}_{jump.target}",
                (x_args[jump.source], u_arg, rate_arg, p_arg),
                (Output("x_next", (len(target.states), 1)),),
                (bound(jump.expressions, jump.source),),
                f"Switch from mode {jump.source} to mode {jump.target} ({jump.guard.kind} of "
                f"{jump.guard.element}): x_next = [A x; vec S+] in the target's states, "
                f"{term}. u and u_rate at the event.",
            )
        )
    return FunctionTable(
        model=model,
        config=config,
        prefix=function_prefix(model.name),
        macro_prefix=macro_prefix(model.name),
        states=(),
        inputs=tuple(real[v.symbol] for v in model.inputs),
        parameters=ps,
        bounds=bounds,
        functions=tuple(functions),
    )


@dataclass(frozen=True)
class GuardView:
    index: int
    kind: str
    element: str
    direction: int
    target: int
    otherwise: int  # -1: none


@dataclass(frozen=True)
class ModeView:
    index: int
    label: str
    macro: str  # GEARSYM_<SET>_M<i>_
    nx: int  # mode states
    nx_aug: int  # with the sensitivities
    states: tuple[str, ...]
    guards: tuple[GuardView, ...]


@dataclass(frozen=True)
class CHybridView(ModelView):
    """What ``c_hybrid.h.j2`` and ``c_hybrid.c.j2`` print."""

    modes: tuple[ModeView, ...]
    sensitivity_parameters: tuple[str, ...]
    initial_mode: int
    final_mode: int
    functions: tuple[CFunctionView, ...]
    math_macros: tuple[MathMacro, ...]
    helpers: tuple[str, ...]
    restrict_pointers: bool


@dataclass(frozen=True)
class CasadiHybridView(ModelView):
    """What ``casadi_hybrid.py.j2`` prints."""

    functions: tuple[CasadiFunctionView, ...]
    arguments: tuple[tuple[str, str, str], ...]  # function, argument names, output names
    defaults: str
    parameter_names: str
    sensitivity_parameters: str
    model_name_repr: str
    mode_table: tuple[tuple[int, str, int, str], ...]  # index, label, nx, state names (source)


def _mode_views(hs: HybridSensitivity, macro: str) -> tuple[ModeView, ...]:
    index = {m.mode.name: m.index for m in hs.modes}
    return tuple(
        ModeView(
            m.index,
            m.label,
            f"{macro}M{m.index}_",
            m.nx,
            len(m.states),
            tuple(v.name for v in m.mode.model.states),
            tuple(
                GuardView(
                    k,
                    g.kind,
                    g.element,
                    g.direction,
                    index[g.target],
                    -1 if g.otherwise is None else index[g.otherwise],
                )
                for k, g in enumerate(m.guards)
            ),
        )
        for m in hs.modes
    )


def emit_hybrid_files(hs: HybridSensitivity, config: CodegenConfig | None = None) -> dict[str, str]:
    """``{"gearsym_<set>.h", "gearsym_<set>.c", "gearsym_<set>_casadi.py"}`` of a shift."""
    table = hybrid_table(hs, config)
    forms: dict[str, CseForm] = {
        spec.name: cse_function(spec, table.config) for spec in table if spec.kind == "expr"
    }
    functions, used_macros, used_helpers = _function_views(table, forms)
    base = model_view(table)
    names = {m.mode.name: m.index for m in hs.modes}
    modes = _mode_views(hs, table.macro_prefix)
    c_view = CHybridView(
        **vars(base),
        modes=modes,
        sensitivity_parameters=tuple(v.name for v in hs.parameters),
        initial_mode=names[hs.hybrid.from_mode],
        final_mode=names[hs.hybrid.to_mode],
        functions=tuple(functions),
        math_macros=tuple(
            MathMacro(m.upper(), m, m in _BINARY_FUNCTIONS) for m in sorted(used_macros)
        ),
        helpers=tuple(sorted(used_helpers)),
        restrict_pointers=table.config.restrict_pointers,
    )
    casadi_functions = []
    arguments = []
    for spec in table:
        if spec.kind == "expr":
            view, used = _function_view(table, spec, forms[spec.name])
            if used:
                raise ValueError(f"hybrid set {base.model_name!r} needs CasADi helpers {used}")
            casadi_functions.append(view)
            arguments.append(
                (
                    spec.name,
                    python_tuple([repr(a.name) for a in spec.args]),
                    python_tuple([repr(o.name) for o in spec.outputs]),
                )
            )
    casadi_view = CasadiHybridView(
        **vars(base),
        functions=tuple(casadi_functions),
        arguments=tuple(arguments),
        defaults=python_tuple(
            [
                'float("nan")' if v.default is None else float_repr(float(v.default))
                for v in table.model.parameters
            ]
        ),
        parameter_names=python_tuple([repr(v.name) for v in table.model.parameters]),
        sensitivity_parameters=python_tuple([repr(v.name) for v in hs.parameters]),
        model_name_repr=repr(base.model_name),
        mode_table=tuple(
            (m.index, m.label, m.nx, python_tuple([repr(s) for s in m.states])) for m in modes
        ),
    )
    return {
        base.header_name: render("c_hybrid.h.j2", c_view),
        base.source_name: render("c_hybrid.c.j2", c_view),
        base.casadi_name: render("casadi_hybrid.py.j2", casadi_view),
    }
