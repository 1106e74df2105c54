"""The C99 emitter: a function table and its CSE'd forms in, ``gearsym_<model>.{h,c}`` out."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import sympy as sp
from gearsym.symbolic.codegen.c.ekf_code import (
    EkfPredictCode,
    linear_update_ops,
    output_rows,
    output_selection,
    predict_code,
    selection_update_ops,
)
from gearsym.symbolic.codegen.c.ekf_stage import FusedStage, fused_stage
from gearsym.symbolic.codegen.c.printer import GearsymCPrinter
from gearsym.symbolic.codegen.cse import (
    CseForm,
    boolean_definitions,
    flatten_column_major,
    hoist,
    is_condition,
)
from gearsym.symbolic.codegen.euio import euio_own_ops
from gearsym.symbolic.codegen.jacobian import SparsityPattern
from gearsym.symbolic.codegen.ops import (
    OpCount,
    count_operations,
    count_split,
    implicit_step_ops,
    rk4_step_ops,
)
from gearsym.symbolic.codegen.printing import comment_text, wrap
from gearsym.symbolic.codegen.render import render
from gearsym.symbolic.codegen.table import Arg, FunctionSpec, FunctionTable, Output, file_names
from gearsym.symbolic.codegen.views import ModelView, model_view

__all__ = [
    "CFunctionView",
    "CModuleView",
    "PatternView",
    "emit_c_files",
]

#: C99 math functions of two arguments (their override macros take two parameters).
_BINARY_FUNCTIONS = ("atan2", "pow", "fmin", "fmax", "hypot")


@dataclass(frozen=True)
class Temporary:
    ctype: str  # "gearsym_real", or "_Bool" for a shared condition (MISRA C:2012 10.3)
    name: str
    code: str


@dataclass(frozen=True)
class Assignment:
    target: str
    code: str


@dataclass(frozen=True)
class ParamDefault:
    field: str
    code: str


@dataclass(frozen=True)
class ParamCheck:
    index: int
    field: str
    lower: str | None  # printed bound, None if unbounded
    upper: str | None


@dataclass(frozen=True)
class Spread:
    """How a dense Jacobian is filled from its sparse function."""

    source: str  # the sparse function (without prefix)
    target: str  # the output array
    rows: str  # size macro suffixes: "NX", and "NX", "NU" or "NP"
    cols: str
    nnz_macro: str  # e.g. "JAC_X_NNZ"
    pattern: str  # e.g. "jac_x": the arrays <prefix>jac_x_colptr, _rowind
    mode: str  # "zero" (no nonzero), "copy" (every entry a nonzero) or "spread"


@dataclass(frozen=True)
class MathMacro:
    macro: str  # GEARSYM_<macro>
    fn: str  # the C99 double function (the float build appends f)
    binary: bool


@dataclass(frozen=True)
class PatternView:
    """The compressed-column pattern of one Jacobian, as the header and source print it."""

    name: str  # "jac_x"
    macro: str  # "JAC_X"
    rows: str  # size macro suffix of the rows, "NX"
    cols: str  # of the columns
    nnz: int
    size: int
    colptr: tuple[str, ...]  # lines of comma-separated integers
    rowind: tuple[str, ...]  # ("0",) when there is no nonzero (C has no empty arrays)


@dataclass(frozen=True)
class ModeElementView:
    """One element of the emitted EKF mode logic (see ``EkfModeElement``)."""

    index: int  # in the modes array
    other: int
    name: str
    normal_force: int
    slide: int
    stick: int
    slip_sign: int
    mu: int  # state index of its μ, -1 if not augmented
    lock_map: tuple[str, ...]  # lines of the row-major gearbox block of A, printed


@dataclass(frozen=True)
class CFunctionView:
    """One function as the C templates print it (fields beyond ``doc`` belong to one kind)."""

    name: str
    kind: str
    returns: str
    args: tuple[Arg, ...]
    outputs: tuple[Output, ...]
    doc: tuple[str, ...]
    temporaries: tuple[Temporary, ...] = ()
    assignments: tuple[Assignment, ...] = ()
    unused: tuple[str, ...] = ()
    defaults: tuple[ParamDefault, ...] = ()
    checks: tuple[ParamCheck, ...] = ()
    spread: Spread | None = None
    frozen: tuple[tuple[int, int], ...] = ()  # EKF: (state, input) pairs, see EkfLayout
    mode_elements: tuple[ModeElementView, ...] = ()  # EKF mode logic
    n_physical: int = 0  # states the lock-up map acts on
    confidence: str = ""  # σ multiples of μ̂ off the capacity at lock-up, printed
    declarations: tuple[str, ...] = ()  # EKF predict: unrolled from the sparsity (ekf_code)
    statements: tuple[str, ...] = ()
    selection: tuple[int, ...] = ()  # EKF update: the state each output is (H a selection)
    # EKF update with H constant but not a selection: per output, (state, coefficient printed)
    linear_rows: tuple[tuple[tuple[int, str], ...], ...] = ()
    update_form: str = ""  # EKF update with H constant: "symmetric" or "joseph"
    stage_temporaries: tuple[Temporary, ...] = ()  # RK4: the rhs terms that depend on x


@dataclass(frozen=True)
class CModuleView(ModelView):
    """Everything ``c_header.h.j2`` and ``c_source.c.j2`` print for one model."""

    functions: tuple[CFunctionView, ...]
    math_macros: tuple[MathMacro, ...]
    helpers: tuple[str, ...]
    implicit_step: bool
    patterns: tuple[PatternView, ...]
    restrict_pointers: bool  # expression functions' pointers restrict in their definitions


def _symbol_map(spec: FunctionSpec) -> dict[sp.Symbol, str]:
    mapping = {}
    for arg in spec.args:
        for i, symbol in enumerate(arg.symbols):
            if arg.kind == "params":
                mapping[symbol] = f"{arg.name}->{arg.fields[i]}"
            else:
                mapping[symbol] = f"{arg.name}[{i}]"
    return mapping


def _used_args(spec: FunctionSpec, form: CseForm) -> set[str]:
    free: set[sp.Basic] = set()
    for _, expr in form.temporaries:
        free |= expr.free_symbols
    for matrix in form.outputs:
        free |= matrix.free_symbols
    return {arg.name for arg in spec.args if any(s in free for s in arg.symbols)}


_SIZE_MACROS = {"x": "NX", "u": "NU", "p": "NP"}


def _lines(values: tuple[int, ...], per_line: int = 16) -> tuple[str, ...]:
    items = [str(v) for v in values] or ["0"]
    return tuple(", ".join(items[i : i + per_line]) for i in range(0, len(items), per_line))


def _pattern_view(spec: FunctionSpec) -> PatternView:
    pattern = spec.pattern
    assert pattern is not None and spec.source is not None
    return PatternView(
        name=spec.name,
        macro=spec.name.upper(),
        rows="NX",
        cols=_SIZE_MACROS[spec.name[-1]],
        nnz=pattern.nnz,
        size=pattern.size,
        colptr=_lines(pattern.colptr),
        rowind=_lines(pattern.rowind),
    )


def _spread(spec: FunctionSpec, pattern: SparsityPattern) -> Spread:
    assert spec.source is not None
    mode = "zero" if pattern.nnz == 0 else ("copy" if pattern.dense else "spread")
    return Spread(
        source=spec.source,
        target=spec.outputs[0].name,
        rows="NX",
        cols=_SIZE_MACROS[spec.name[-1]],
        nnz_macro=f"{spec.name.upper()}_NNZ",
        pattern=spec.name,
        mode=mode,
    )


def _rk4_hoisted(table: FunctionTable, form: CseForm) -> tuple[OpCount, OpCount, dict] | None:
    """The RK4 step with the right-hand side inlined and its terms that depend on u and p only
    (held over the step) computed once, not in each of the four stages (CasADi's CSE of the
    whole step shares them the same way): the CSE temporaries free of x, and within the
    others and the outputs the invariant terms of sums and factors of products. None if nothing
    is invariant or nothing depends on x."""
    states = set(table.states)
    varying: set[sp.Symbol] = set(states)
    new: list[tuple[sp.Symbol, sp.Basic]] = []
    stage_temps: list[tuple[sp.Symbol, sp.Basic]] = []
    once_temps: list[tuple[sp.Symbol, sp.Basic]] = []
    for symbol, expr in form.temporaries:
        if expr.free_symbols & varying:
            varying.add(symbol)
            stage_temps.append((symbol, hoist(expr, varying, new)))
        else:
            once_temps.append((symbol, expr))
    outputs = tuple(
        sp.ImmutableMatrix(m.rows, m.cols, [hoist(e, varying, new) for e in m])
        for m in form.outputs
    )
    uses_x = any(e.free_symbols & varying for m in outputs for e in m)
    once = frozenset(s for s, _ in once_temps + new)
    if not once or not uses_x:
        return None
    form = CseForm(tuple(once_temps + new + stage_temps), outputs)
    spec = table["rhs"]
    mapping = _symbol_map(spec)
    for i, symbol in enumerate(table.states):
        mapping[symbol] = f"xs[{i}]"
    printer = GearsymCPrinter(
        mapping, table.prefix, boolean_definitions(form), table.config.precision
    )

    def temporary(symbol: sp.Symbol, expr: sp.Basic) -> Temporary:
        ctype = "_Bool" if is_condition(expr) else "gearsym_real"
        return Temporary(ctype, printer.code(symbol), printer.code(expr))

    used = _used_args(spec, form)
    extra = {
        "temporaries": tuple(temporary(s, e) for s, e in once_temps + new),
        "stage_temporaries": tuple(temporary(s, e) for s, e in stage_temps),
        "assignments": tuple(
            Assignment(str(k), printer.code(expr))
            for k, expr in enumerate(flatten_column_major(form.outputs[0]))
        ),
        "unused": tuple(a for a in ("u", "p") if a not in used),
    }
    first, rest = count_split(form, once, table.config)
    return first, rest, extra


def predict_body(
    table: FunctionTable, inputs: str = "u"
) -> tuple[EkfPredictCode, FusedStage, set[str], set[str]]:
    """The unrolled predict body of the table's model (see :mod:`.ekf_code`), its fused
    stage (:mod:`.ekf_stage`), and the math macros and helpers the printed code uses; the
    inputs read from the C array ``inputs``. One emitter for ``ekf_predict`` and the
    prediction of ``euio_step``."""
    n = len(table.states)
    dense = table["jac_x"].expressions[0]
    entries = [(i, j) for j in range(n) for i in range(n) if dense[i, j] != 0]
    rhs = table["rhs"].expressions[0]
    base = _symbol_map(table["rhs"])
    base.update({s: f"{inputs}[{i}]" for i, s in enumerate(table.inputs)})
    printers: list[GearsymCPrinter] = []

    def printer_for(extra: dict[sp.Symbol, str]):  # noqa: ANN202 - a printing function
        printer = GearsymCPrinter({**base, **extra}, table.prefix, {}, table.config.precision)
        printers.append(printer)
        return printer.code

    fused = fused_stage(
        list(table.states),
        [rhs[i] for i in range(n)],
        entries,
        # the pattern is jac_x's; the entries are differentiated again from rhs because the
        # table's simplified jac_x form costs 3 more operations here once fused (measured)
        lambda e: sp.diff(rhs[e[0]], table.states[e[1]]),
        printer_for,
        table.config,
    )
    code = predict_code(n, entries, [i for i in range(n) if rhs[i] == 0], fused)
    macros = set().union(*(p.used_macros for p in printers))
    helpers = set().union(*(p.used_helpers for p in printers))
    return code, fused, macros, helpers


def euio_step_extra(
    table: FunctionTable, counts: Mapping[str, OpCount]
) -> tuple[dict[str, Any], str, set[str], set[str]]:
    """What ``euio_step`` of ``templates/c_euio.c.j2`` needs from the function table: (the view
    fields, its operation text for the doc comment, the math macros and helpers its printed
    prediction uses)."""
    layout = table.config.euio
    assert layout is not None
    nx, ny = len(table.states), len(table.model.outputs)
    names = [v.name for v in table.model.states]
    frozen = ", ".join(
        f"{names[i]} while |{table.model.inputs[j].name}| <= 0.5" for i, j in layout.frozen
    )
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


def _function_views(
    table: FunctionTable, forms: Mapping[str, CseForm]
) -> tuple[list[CFunctionView], set[str], set[str]]:
    """The views of every function, and the math macros and helpers their code uses."""
    used_macros: set[str] = set()
    used_helpers: set[str] = set()
    views = []
    counts: dict[str, OpCount] = {}
    precision = table.config.precision
    nx = len(table.states)
    for spec in table:
        conditions = boolean_definitions(forms[spec.name]) if spec.name in forms else {}
        printer = GearsymCPrinter(_symbol_map(spec), table.prefix, conditions, precision)
        extra: dict = {}
        if spec.kind == "expr":
            form = forms[spec.name]
            ops = count_operations(form, table.config)
            counts[spec.name] = ops
            extra["temporaries"] = tuple(
                Temporary(
                    "_Bool" if is_condition(expr) else "gearsym_real",
                    printer.code(symbol),
                    printer.code(expr),
                )
                for symbol, expr in form.temporaries
            )
            extra["assignments"] = tuple(
                Assignment(f"{out.name}[{k}]", printer.code(expr))
                for out, matrix in zip(spec.outputs, form.outputs, strict=True)
                for k, expr in enumerate(flatten_column_major(matrix))
            )
            used = _used_args(spec, form)
            extra["unused"] = tuple(
                [a.name for a in spec.args if a.name not in used]
                + [o.name for o in spec.outputs if o.size == 0]
            )
            op_text = f"Operations: {ops.format()}; {len(form.temporaries)} temporaries."
        elif spec.kind == "spread":
            assert spec.source is not None and spec.pattern is not None
            extra["spread"] = _spread(spec, spec.pattern)
            op_text = (
                f"Computes {spec.source} into the first NNZ entries and spreads them in place; "
                f"every other entry is 0. Operations: those of {spec.source} "
                f"({counts[spec.source].format()}); the spreading moves values only."
            )
        elif spec.kind == "rk4":
            own = rk4_step_ops(nx)
            hoisted = _rk4_hoisted(table, forms["rhs"])
            if hoisted is None:
                total = counts["rhs"].scaled(4) + own
                op_text = f"Operations: {total.format()} (4 rhs calls + {own.format()})."
            else:
                once, per_stage, rk4_extra = hoisted
                extra.update(rk4_extra)
                total = once + per_stage.scaled(4) + own
                op_text = (
                    f"The right-hand side is inlined: its terms in u and p only are computed "
                    f"once ({once.format()}), the rest in each of the 4 stages "
                    f"({per_stage.format()}). Operations: {total.format()} (with "
                    f"{own.format()} of the step itself)."
                )
        elif spec.kind == "linearly_implicit_euler":
            used_macros.add("fabs")
            own = implicit_step_ops(nx, len(table.inputs))
            jac_ops = counts.get("jac_x_sparse", counts.get("jac_x"))
            assert jac_ops is not None
            total = counts["rhs"] + jac_ops + own
            op_text = (
                f"Operations (at most): {total.format()} (rhs + jac_x + {own.format()} for "
                "the checks, forming I - h J, its LU factors, the solve and ||(I - h J)^-1||)."
            )
        elif spec.kind in ("ekf_predict", "ekf_update"):
            assert table.config.ekf is not None
            extra["frozen"] = table.config.ekf.frozen
            frozen = ", ".join(
                f"{table.model.states[i].name} while |{table.model.inputs[j].name}| <= 0.5"
                for i, j in table.config.ekf.frozen
            )
            if spec.kind == "ekf_predict":
                code, fused, macros, helpers = predict_body(table)
                used_macros |= macros
                used_helpers |= helpers
                extra["declarations"] = code.declarations
                extra["statements"] = code.statements
                own = code.ops + OpCount(compare=2 * len(table.config.ekf.frozen))
                total = fused.once_ops + fused.stage_ops.scaled(4) + own
                what = (
                    f"f and jac_x fused and inlined: their terms without the moving states "
                    f"once ({fused.once_ops.format()}), the rest in each of the 4 stages "
                    f"({fused.stage_ops.format()}); {own.format()} for the stage tangents over "
                    "the structural nonzeros of jac_x, x and F P F^T blockwise"
                )
                stack = code.stack + nx
            else:
                ny = len(table.model.outputs)
                selection = output_selection(table["jac_outputs"].expressions[0])
                if selection is not None:
                    form = table.config.ekf.update_form
                    extra["selection"] = selection
                    extra["update_form"] = form
                    own = selection_update_ops(nx, ny, len(table.config.ekf.frozen), form)
                    total = counts["outputs"].scaled(ny) + own
                    update = (
                        "the Joseph form expanded"
                        if form == "joseph"
                        else "the Schmidt update P - v w^T, equal to the Joseph form of the "
                        "Schmidt gain"
                    )
                    what = (
                        f"{ny} x (outputs + {update}, with H a selection of states: "
                        "no product with H, upper triangle), the frozen flags once"
                    )
                    stack = ny + 3 * nx
                elif (h_rows := output_rows(table["jac_outputs"].expressions[0])) is not None:
                    form = table.config.ekf.update_form
                    extra["linear_rows"] = tuple(
                        tuple((j, printer.code(v)) for j, v in row) for row in h_rows
                    )
                    extra["update_form"] = form
                    sizes = [len(row) for row in h_rows]
                    own = linear_update_ops(nx, sizes, len(table.config.ekf.frozen), form)
                    total = counts["outputs"].scaled(ny) + own
                    what = (
                        f"{ny} x outputs; per output with a nonzero row of H v = P h^T over "
                        f"its nonzeros ({sum(sizes)} in all, H constant) and the Schmidt update "
                        "P - v w^T (upper triangle); the frozen flags once"
                    )
                    stack = ny + 3 * nx
                else:
                    own = OpCount(
                        mul=ny * (4 * nx * nx + 4 * nx + 4), add=ny * (4 * nx * nx + 3 * nx)
                    )
                    total = (counts["outputs"] + counts["jac_outputs"]).scaled(ny) + own
                    what = f"{ny} x (outputs + jac_outputs + the Joseph update)"
                    stack = 6 * nx * nx + 6 * nx
            op_text = (
                f"Frozen: {frozen or 'none'}. Operations: {total.format()} ({what}); "
                f"stack: {stack} reals."
            )
        elif spec.kind == "ekf_mode_update":
            layout = table.config.ekf
            assert layout is not None
            used_macros |= {"fabs", "sqrt"}
            elements = []
            for k, element in enumerate(layout.modes):
                rows = tuple(
                    ", ".join(printer.code(sp.sympify(v)) for v in row) for row in element.lock_map
                )
                elements.append(
                    ModeElementView(
                        k,
                        1 - k,
                        element.name,
                        element.normal_force,
                        element.slide,
                        element.stick,
                        element.slip_sign,
                        element.mu,
                        rows,
                    )
                )
            extra["mode_elements"] = tuple(elements)
            extra["n_physical"] = len(layout.modes[0].lock_map)
            extra["confidence"] = printer.code(sp.Float(layout.lock_up_confidence))
            n = len(layout.modes[0].lock_map)
            quantities = counts["ekf_mode_quantities"]
            own = OpCount(mul=2 * n * n * n + n * n + n * nx, add=2 * n * n * n + n * nx)
            total = quantities.scaled(2 * len(layout.modes)) + own
            op_text = (
                f"Operations (at most): {total.format()} (ekf_mode_quantities at most twice per "
                f"element, the lock-up map of x and P: {own.format()}); stack: "
                f"{nx * nx + 2 * nx + 6 * len(layout.modes) + len(table.inputs)} reals."
            )
        elif spec.kind == "euio_step":
            euio_extra, op_text, macros, helpers = euio_step_extra(table, counts)
            extra.update(euio_extra)
            used_macros |= macros
            used_helpers |= helpers
        elif spec.kind == "params_default":
            (defaults,) = spec.expressions
            extra["defaults"] = tuple(
                ParamDefault(v.name, printer.code(d))
                for v, d in zip(table.model.parameters, defaults, strict=True)
            )
            op_text = "Operations: none (stores only)."
        elif spec.kind == "params_validate":
            (limits,) = spec.expressions
            checks = []
            for j, v in enumerate(table.model.parameters):
                lo, hi = limits[0, j], limits[1, j]
                checks.append(
                    ParamCheck(
                        j,
                        v.name,
                        None if lo == sp.S.NegativeInfinity else printer.code(lo),
                        None if hi == sp.S.Infinity else printer.code(hi),
                    )
                )
            extra["checks"] = tuple(checks)
            n_cmp = sum((c.lower is not None) + (c.upper is not None) for c in checks)
            op_text = f"Operations: {len(checks)} isfinite, {n_cmp} cmp."
        else:  # pragma: no cover - the table only has the kinds above
            raise ValueError(f"unknown function kind {spec.kind!r}")
        used_macros |= printer.used_macros
        used_helpers |= printer.used_helpers
        doc = tuple(wrap(comment_text(spec.doc)) + wrap(comment_text(op_text)))
        views.append(
            CFunctionView(spec.name, spec.kind, spec.returns, spec.args, spec.outputs, doc, **extra)
        )
    return views, used_macros, used_helpers


def emit_c_files(table: FunctionTable, forms: Mapping[str, CseForm]) -> dict[str, str]:
    """``{"gearsym_<name>.h": ..., "gearsym_<name>.c": ...}`` of one model."""
    functions, used_macros, used_helpers = _function_views(table, forms)
    view = CModuleView(
        **vars(model_view(table)),
        functions=tuple(functions),
        math_macros=tuple(
            MathMacro(m.upper(), m, m in _BINARY_FUNCTIONS) for m in sorted(used_macros)
        ),
        helpers=tuple(sorted(used_helpers)),
        implicit_step=any(f.kind == "linearly_implicit_euler" for f in functions),
        patterns=tuple(_pattern_view(s) for s in table if s.kind == "spread"),
        restrict_pointers=table.config.restrict_pointers,
    )
    names = file_names(table.model)
    return {
        names["header"]: render("c_header.h.j2", view),
        names["source"]: render("c_source.c.j2", view),
    }
