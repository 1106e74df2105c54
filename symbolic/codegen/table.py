"""The function table: one row per emitted function, from which every signature is built.

:data:`ROWS` states each function as data (name, kind, arguments, outputs with their sizes in
model terms, return type, documentation, and the config choice that selects it), in the spirit
of AMICI's ``cxx_functions.py``. :func:`build_function_table` binds the rows to one model and
one :class:`~gearsym.symbolic.codegen.config.CodegenConfig`: sizes, symbols, the expressions
(right-hand side, outputs, Jacobians from one forward pass) and the sparsity patterns. Every
emitter and every validator reads the resulting :class:`FunctionTable` and nothing else, so the
C header, the C source, the CasADi module and the ctypes bindings cannot disagree.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.codegen.config import Bounds, CodegenConfig, as_config
from gearsym.symbolic.codegen.jacobian import SparsityPattern, jacobian_blocks
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.naming import (
    c_identifier_problem,
    function_prefix,
    macro_prefix,
    model_file_names,
)

__all__ = [
    "JACOBIANS",
    "ROWS",
    "Arg",
    "FunctionSpec",
    "FunctionTable",
    "Output",
    "Row",
    "build_function_table",
    "file_names",
    "function_names",
    "parameter_functions",
    "real_symbols",
]


@dataclass(frozen=True)
class Arg:
    """An input argument of an emitted function.

    ``kind`` is ``"vector"`` (a ``const gearsym_real *`` of ``size`` entries), ``"params"`` (a
    pointer to the parameter struct, whose fields are ``fields``) or ``"scalar"`` (by value).
    ``symbols`` are the model symbols bound to the entries, in order; printers derive their
    symbol-to-code maps from them.
    """

    name: str
    size: int
    const: bool = True
    kind: str = "vector"
    symbols: tuple[sp.Symbol, ...] = ()
    fields: tuple[str, ...] = ()


@dataclass(frozen=True)
class Output:
    """An output argument: ``shape`` entries written through a pointer of type ``ctype``
    (``"real"``, ``"int"`` or ``"params"``)."""

    name: str
    shape: tuple[int, int]
    ctype: str = "real"

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]


@dataclass(frozen=True)
class FunctionSpec:
    """One row of the function table bound to a model, i.e. one emitted function.

    ``kind``: ``"expr"`` computes ``expressions[k]`` into ``outputs[k]``; ``"spread"`` (the dense
    Jacobian of the sparse layout) calls the ``expr`` row ``source`` and spreads its values by
    ``pattern`` (``expressions`` then holds the dense matrix it equals, for reference); the
    other kinds (``"rk4"``, ``"linearly_implicit_euler"``, ``"params_default"``,
    ``"params_validate"``) have a fixed body in the template and ``expressions`` holds their
    data (defaults, bounds) or nothing. ``pattern`` is the compressed-column pattern of a sparse
    row's output (``jac_*_sparse``) or of what a spread row spreads.
    """

    name: str
    args: tuple[Arg, ...]
    outputs: tuple[Output, ...]
    expressions: tuple[sp.ImmutableMatrix, ...]
    doc: str
    kind: str = "expr"
    returns: str = "void"
    pattern: SparsityPattern | None = None
    source: str | None = None


@dataclass(frozen=True)
class FunctionTable:
    """The function table of one model plus what every emitter needs besides it."""

    model: Model
    config: CodegenConfig
    prefix: str  # C identifier prefix, ``gearsym_<model name>_``
    macro_prefix: str  # ``GEARSYM_<MODEL NAME>_``
    states: tuple[sp.Symbol, ...]  # the (real) symbols used in every expression of the table
    inputs: tuple[sp.Symbol, ...]
    parameters: tuple[sp.Symbol, ...]
    bounds: tuple[tuple[float | None, float | None], ...]  # per parameter, model order
    functions: tuple[FunctionSpec, ...]

    def __iter__(self) -> Iterator[FunctionSpec]:
        return iter(self.functions)

    def __getitem__(self, name: str) -> FunctionSpec:
        for spec in self.functions:
            if spec.name == name:
                return spec
        raise KeyError(name)

    def names(self) -> list[str]:
        return [spec.name for spec in self.functions]

    def sparse_rows(self) -> list[FunctionSpec]:
        """The ``jac_*_sparse`` rows (empty in the dense layout)."""
        return [s for s in self.functions if s.kind == "expr" and s.pattern is not None]


# ---------------------------------------------------------------------------------------------
# The rows
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Row:
    """One emitted function as data.

    ``args`` are out of ``"x"``, ``"u"``, ``"p"``, ``"h"``. Each output is ``(name, rows, cols,
    ctype)`` with sizes given as ``"nx"``, ``"nu"``, ``"np"``, ``"ny"``, ``"nnz"`` (of the row's
    pattern) or a number. ``when`` names the config choice that emits the row: ``"always"``,
    ``"sparse"`` / ``"dense"`` (Jacobian layout), ``"rk4"``, ``"implicit"``. ``doc`` is formatted
    with the model's sizes and names (see :func:`build_function_table`).
    """

    name: str
    kind: str
    args: tuple[str, ...]
    outputs: tuple[tuple[str, str, str, str], ...]
    doc: str
    returns: str = "void"
    when: str = "always"
    jacobian: str | None = None  # "x", "u" or "p": the Jacobian the row computes


#: The Jacobians: (variable group, its name in the docs).
JACOBIANS: tuple[tuple[str, str], ...] = (
    ("x", "x (states)"),
    ("u", "u (inputs)"),
    ("p", "p (parameters, in struct field order)"),
)
_XUP = ("x", "u", "p")
_SIZE = {"x": "nx", "u": "nu", "p": "np"}


def _jacobian_rows(var: str, what: str) -> tuple[Row, ...]:
    name = f"jac_{var}"
    shape = f"{{nx}} x {{n{var}}}"
    dense = (
        f"Jacobian of the state derivative with respect to {what}, d xdot / d {var} ({shape}), "
        f"dense column-major: {name}[i + j*{{nx}}] = d xdot_i / d {var}_j."
    )
    return (
        Row(
            f"{name}_sparse",
            "expr",
            _XUP,
            ((f"{name}_nz", "nnz", "1", "real"),),
            f"Structural nonzeros of d xdot / d {var} ({shape}, {{nnz_{var}}} of {{size_{var}}} "
            f"entries) in compressed-column order: {name}_nz[k] is entry (i, j) with i = "
            f"{{prefix}}{name}_rowind[k] and {{prefix}}{name}_colptr[j] <= k < "
            f"{{prefix}}{name}_colptr[j+1] ({{macro}}{name.upper()}_NNZ values).",
            when="sparse",
            jacobian=var,
        ),
        Row(
            name,
            "spread",
            _XUP,
            ((name, "nx", _SIZE[var], "real"),),
            dense,
            when="sparse",
            jacobian=var,
        ),
        Row(name, "expr", _XUP, ((name, "nx", _SIZE[var], "real"),), dense, "void", "dense", var),
    )


ROWS: tuple[Row, ...] = (
    Row(
        "rhs",
        "expr",
        _XUP,
        (("xdot", "nx", "1", "real"),),
        "State derivative xdot = f(x, u, p). States: {states}. Inputs: {inputs}.",
    ),
    Row("outputs", "expr", _XUP, (("y", "ny", "1", "real"),), "Outputs y = h(x, u, p): {outputs}."),
    *(row for var, what in JACOBIANS for row in _jacobian_rows(var, what)),
    Row(
        "rk4_step",
        "rk4",
        (*_XUP, "h"),
        (("x_next", "nx", "1", "real"),),
        "One classical explicit Runge-Kutta step (order 4) of size h, u held constant over the "
        "step. x_next may alias x (in-place stepping).",
        when="rk4",
    ),
    Row(
        "linearly_implicit_euler_step",
        "linearly_implicit_euler",
        (*_XUP, "h"),
        (("x_next", "nx", "1", "real"),),
        "One linearly implicit Euler step x_next = x + h (I - h df/dx)^-1 f(x, u, p) "
        "(Rosenbrock-Euler, order 1, L-stable on linear models: use it for stiff models). "
        "Solves the NX x NX system by Gaussian elimination with partial pivoting on the stack. "
        "Returns OK; ERR_NONFINITE if x, u, h, f, df/dx or the result holds a NaN or an "
        "infinity (a NaN parameter shows up there); ERR_SINGULAR if I - h df/dx is singular to "
        "working precision: a zero pivot, or 1/||(I - h df/dx)^-1|| (its distance to "
        "singularity) not above NX eps max_i(1 + sum_j |h df_i/dx_j|), in the inf-norm. On "
        "error x_next is untouched. x_next may alias x.",
        returns="int",
        when="implicit",
    ),
    Row(
        "jac_outputs",
        "expr",
        _XUP,
        (("dhdx", "ny", "nx", "real"),),
        "Jacobian of the outputs with respect to the states, d y / d x ({ny} x {nx}), dense "
        "column-major: dhdx[i + j*{ny}] = d y_i / d x_j (the EKF's H).",
        when="ekf",
    ),
    Row(
        "ekf_predict",
        "ekf_predict",
        ("x_io", "P_io", "u", "p", "h", "q"),
        (),
        "EKF time update (thesis 4.3) of the augmented model (4.1), in place: x = RK4 step of "
        "size h with u held, P = F P F^T + h diag(q), F the exact Jacobian of that RK4 step "
        "(chain rule through the four stages with jac_x). q: process-noise intensities per "
        "state (unit^2/s; random walks of the parameters, model error of the states); the "
        "entry of a state frozen by its input (see the header) counts as 0. P is "
        "{nx} x {nx} column-major, symmetric on entry, and exactly symmetric on return (each "
        "mirrored pair computed once).",
        when="ekf",
    ),
    Row(
        "ekf_update",
        "ekf_update",
        ("x_io", "P_io", "u", "p", "y", "r", "y_floor"),
        (("nis", "1", "1", "real"),),
        "EKF measurement update (thesis 4.3), in place, one output at a time (diagonal R), "
        "P = (I - k h) P (I - k h)^T + R k k^T (the Joseph form's value, evaluated as "
        "stated below) with R = (r_i max(|y_i|, "
        "y_floor_i))^2 (3.26). A NaN or infinite y_i is skipped (no update); the gain entry "
        "of a frozen state is 0 (its estimate and variance stay unchanged). *nis receives the "
        "sum of nu^2/s over the used outputs. Returns the number of outputs used. P is "
        "symmetric on entry and exactly symmetric on return.",
        returns="int",
        when="ekf",
    ),
    Row(
        "ekf_mode_quantities",
        "expr",
        _XUP,
        (("m", "nm", "1", "real"),),
        "Per swapping element, in the order of the mode array: its slip (2.59), the torque its "
        "sticking needs with the other element as u's flags say, and its capacity 2 N r_m mu "
        "F_N (2.60, 2.69) with mu the state where augmented: m[3 e + 0..2].",
        when="ekf_modes",
    ),
    Row(
        "ekf_mode_update",
        "ekf_mode_update",
        ("x_io", "P_io", "u", "p"),
        (("modes", "ne", "1", "int"),),
        "The filter's own mode logic (thesis 4.3 on the hybrid shift model), after "
        "ekf_update: from the posterior x, P, the known inputs u (T_In, F_N; its mode flags are "
        "ignored) and modes[e] (0 open, +1/-1 sliding with/against the power-on slip sign, 2 "
        "sticking), the modes held over the next sample, in place. F_N <= 0 opens; an open "
        "element with F_N > 0 slides in the direction of its slip; a sticking one breaks away "
        "when |sticking torque| > capacity, sliding in the torque's direction; a sliding one "
        "whose slip has reached zero locks up if |sticking torque| at A x is within the "
        "capacity with mu lowered by the stated sigma multiple (x = A x, P = A P A^T on the "
        "physical states, the parameter block untouched), else slides in the torque's "
        "direction. Returns the number of switches. u is left as it is: the caller sets its "
        "slide_/stick_ flags from the modes (slide = modes[e] if it is +-1, else 0; stick = "
        "1 if it is 2, else 0) for the next ekf_predict and ekf_update.",
        returns="int",
        when="ekf_modes",
    ),
    # The extended UIO (thesis 4.5): its own rows, beside the EKF's (symbolic/codegen/euio.py)
    Row(
        "jac_outputs",
        "expr",
        _XUP,
        (("dhdx", "ny", "nx", "real"),),
        "Jacobian of the outputs with respect to the states, d y / d x ({ny} x {nx}), dense "
        "column-major: dhdx[i + j*{ny}] = d y_i / d x_j (the EUIO's C).",
        when="euio_only",
    ),
    Row(
        "euio_load_column",
        "expr",
        _XUP,
        (("e", "nx", "1", "real"),),
        "Column E = d xdot / d d of the unknown road load d = T_res* (2.45, 2.46, 2.48): "
        "-1 / (I_wheel + m_veh r_dyn^2) in the wheel-speed row, m_veh the state (thesis 4.5).",
        when="euio",
    ),
    Row(
        "euio_step",
        "euio_step",
        ("x_io", "P_io", "u_prev", "u", "p", "h", "q", "y", "r", "y_floor", "held"),
        (("load", "3", "1", "real"),),
        "One extended-UIO step (thesis 4.5, the unbiased minimum-variance filter of Gillijns & "
        "De Moor 2007 on the linearisation of each step), in place. Predict as ekf_predict "
        "with u_prev held: x = RK4 step of size h, P = F P F^T + h diag(q) with F the exact "
        "Jacobian of that step; a held state's q counts as 0. Then, with A = jac_x and "
        "E = euio_load_column at the x before the step (u_prev), E_d = h (I + hA/2 + h^2A^2/6 + "
        "h^3A^3/24) E, C = jac_outputs and nu = y - outputs at the predicted x (u), R = "
        "diag((r_i max(|y_i|, y_floor_i))^2) (3.26), S = C P C^T + R ({ny} x {ny}, LDL^T), "
        "c = C E_d: sigma_d^2 = 1 / (c^T S^-1 c), M = sigma_d^2 c^T S^-1, d = M nu, "
        "L = P C^T S^-1 (I - c M) + E_d M with the rows of held states 0, x += L nu, "
        "P = (I - L C) P (I - L C)^T + L R L^T (Joseph), symmetrised. A state is held where "
        "held[i] > 0.5, or where it is a mu whose element does not slide under u_prev (see the "
        "header for the per-phase masks). load receives d (the road load T_res*, N m), "
        "sigma_d^2 and the NIS nu^T S^-1 nu - d^2 / sigma_d^2 (chi^2 with {ny} - 1 dof). "
        "Returns OK after the update; ERR_NONFINITE if a y_i is NaN or infinite (dropout: "
        "x and P hold the prediction, load is NaN); ERR_SINGULAR if S is not positive "
        "definite (a pivot of its LDL^T not > 0) or c^T S^-1 c is not > 0 (x and P hold the "
        "prediction, load is NaN).",
        returns="int",
        when="euio",
    ),
    Row(
        "params_default",
        "params_default",
        (),
        (("p", "np", "1", "params"),),
        "Fill p with the model's default parameter values. Parameters without a default are "
        "set to NaN, so params_validate rejects them until the caller sets them.",
    ),
    Row(
        "params_validate",
        "params_validate",
        ("p",),
        (("bad_index", "1", "1", "int"),),
        "Check every parameter in struct order. Returns OK, ERR_NONFINITE (NaN or inf) or "
        "ERR_RANGE (outside the range given at generation time) for the first offending "
        "parameter, and stores its index (or -1) in *bad_index unless bad_index is NULL.",
        returns="int",
    ),
)


def _selected(row: Row, config: CodegenConfig) -> bool:
    return {
        "always": True,
        "sparse": config.sparsity.sparse,
        "dense": not config.sparsity.sparse,
        "rk4": config.rk4_step,
        "implicit": config.implicit_step,
        "ekf": config.ekf is not None,
        "ekf_modes": config.ekf is not None and bool(config.ekf.modes),
        "euio": config.euio is not None,
        "euio_only": config.euio is not None and config.ekf is None,
    }[row.when]


# ---------------------------------------------------------------------------------------------
# Binding the rows to a model
# ---------------------------------------------------------------------------------------------


def _check_names(model: Model) -> None:
    problems = []
    if not re.match(r"^[A-Za-z][A-Za-z0-9_]*$", model.name):
        problems.append(f"model name {model.name!r} must match [A-Za-z][A-Za-z0-9_]*")
    groups = (
        ("state", model.states),
        ("input", model.inputs),
        ("parameter", model.parameters),
        ("output", model.outputs),
    )
    for what, variables in groups:
        for v in variables:
            problem = c_identifier_problem(v.name)
            if problem:
                problems.append(f"{what} {v.name!r} {problem}")
    output_names = [v.name for v in model.outputs]
    twice = sorted({n for n in output_names if output_names.count(n) > 1})
    if twice:
        problems.append(f"output names used twice: {twice}")
    if not model.states:
        problems.append("the model has no states")
    if problems:
        raise ValueError(f"model {model.name!r} cannot be emitted: " + "; ".join(problems))


def parameter_functions(
    model: Model, bounds: Sequence[tuple[float | None, float | None]], p_arg: Arg
) -> list[FunctionSpec]:
    """``params_default`` and ``params_validate`` of :data:`ROWS` for a model whose functions
    are not the model rows (the linear and hybrid sets): the defaults and the bounds as data."""
    n = len(model.parameters)
    defaults = sp.ImmutableMatrix(
        n, 1, [sp.nan if v.default is None else sp.Float(v.default) for v in model.parameters]
    )
    lower = [sp.S.NegativeInfinity if lo is None else sp.Float(lo) for lo, _ in bounds]
    upper = [sp.S.Infinity if hi is None else sp.Float(hi) for _, hi in bounds]
    data = {
        "params_default": (defaults,),
        "params_validate": (sp.ImmutableMatrix(2, n, lower + upper),),
    }
    functions = []
    for row in ROWS:
        if row.kind not in data:
            continue
        outputs = tuple(
            Output(name, (n if rows == "np" else 1, 1), ctype)
            for name, rows, _, ctype in row.outputs
        )
        functions.append(
            FunctionSpec(
                row.name,
                (p_arg,) if row.args else (),
                outputs,
                data[row.kind],
                row.doc,
                kind=row.kind,
                returns=row.returns,
            )
        )
    return functions


def _normalise_bounds(
    model: Model, bounds: Bounds
) -> tuple[tuple[float | None, float | None], ...]:
    """Bounds per parameter in model order; checks names, order and that defaults lie inside."""
    names = [v.name for v in model.parameters]
    unknown = sorted(set(bounds) - set(names))
    if unknown:
        raise ValueError(f"bounds given for unknown parameters: {unknown}")
    result = []
    for v in model.parameters:
        lo, hi = bounds.get(v.name, (None, None))
        lo = None if lo is None or lo == float("-inf") else float(lo)
        hi = None if hi is None or hi == float("inf") else float(hi)
        if lo is not None and hi is not None and not lo <= hi:
            raise ValueError(f"bounds of {v.name!r} are empty: ({lo}, {hi})")
        if v.default is not None:
            d = float(v.default)
            if (lo is not None and d < lo) or (hi is not None and d > hi):
                raise ValueError(f"default {d} of {v.name!r} lies outside its bounds ({lo}, {hi})")
        result.append((lo, hi))
    return tuple(result)


def real_symbols(model: Model) -> dict[sp.Symbol, sp.Symbol]:
    """Map every model symbol to a real symbol named after its Variable.

    Real symbols make ``d|x|/dx = sign(x)`` instead of an expression in ``re``/``im``. Variable
    names are unique in a model, so the new symbols are distinct even if two original symbols
    shared a name; existing assumptions such as ``positive`` are kept.
    """
    mapping = {}
    for v in (*model.states, *model.inputs, *model.parameters):
        assumptions = dict(v.symbol.assumptions0) if v.symbol.is_real else {"real": True}
        mapping[v.symbol] = sp.Symbol(v.name, **assumptions)
    return mapping


def _doc_variables(variables: Sequence[Variable]) -> str:
    return ", ".join(f"{v.name} [{v.unit}]" for v in variables) or "none"


def file_names(model: Model) -> dict[str, str]:
    """Names of the emitted files: keys ``"header"``, ``"source"``, ``"casadi"``."""
    return model_file_names(model.name)


def build_function_table(
    model: Model, config: CodegenConfig | Bounds | None = None
) -> FunctionTable:
    """Bind :data:`ROWS` to ``model`` under ``config`` (a bare bounds mapping is accepted as the
    default config with those bounds, see :func:`~gearsym.symbolic.codegen.config.as_config`).

    The Jacobians ∂f/∂x, ∂f/∂u, ∂f/∂p come from one forward pass over one CSE of f
    (:func:`~gearsym.symbolic.codegen.jacobian.jacobian_blocks`, cached), so building the
    table of a model again is cheap.
    """
    config = as_config(config)
    _check_names(model)
    param_bounds = _normalise_bounds(model, config.bounds)
    real = real_symbols(model)
    xs = tuple(real[v.symbol] for v in model.states)
    us = tuple(real[v.symbol] for v in model.inputs)
    ps = tuple(real[v.symbol] for v in model.parameters)
    # only the symbols that change: xreplace rebuilds every expression above a replaced symbol,
    # even one replaced by itself
    changed = {old: new for old, new in real.items() if old != new}
    f = sp.ImmutableMatrix(model.rhs.xreplace(changed) if changed else model.rhs)
    h = sp.ImmutableMatrix(
        model.output_expressions.xreplace(changed) if changed else model.output_expressions
    )
    jac = dict(zip("xup", jacobian_blocks(f, (xs, us, ps)), strict=True))
    output_jacobian = sp.ImmutableMatrix(h.jacobian(sp.Matrix(xs)))
    patterns = {var: SparsityPattern.of(matrix) for var, matrix in jac.items()}
    sizes = {
        "nx": len(xs),
        "nu": len(us),
        "np": len(ps),
        "ny": len(model.outputs),
        "ne": len(config.ekf.modes) if config.ekf is not None else 0,
        "nm": 3 * len(config.ekf.modes) if config.ekf is not None else 0,
        "1": 1,
        "3": 3,
    }

    args = {
        "x": Arg("x", len(xs), True, "vector", xs),
        "u": Arg("u", len(us), True, "vector", us),
        "p": Arg("p", len(ps), True, "params", ps, tuple(v.name for v in model.parameters)),
        "h": Arg("h", 1, True, "scalar"),
        "x_io": Arg("x", len(xs), False, "vector", xs),
        "P_io": Arg("P", len(xs) ** 2, False, "vector"),
        "q": Arg("q", len(xs), True, "vector"),
        "y": Arg("y", len(model.outputs), True, "vector"),
        "r": Arg("r", len(model.outputs), True, "vector"),
        "u_prev": Arg("u_prev", len(us), True, "vector"),
        "held": Arg("held", len(xs), True, "vector"),
        "y_floor": Arg("y_floor", len(model.outputs), True, "vector"),
    }
    defaults = sp.ImmutableMatrix(
        len(ps), 1, [sp.nan if v.default is None else sp.Float(v.default) for v in model.parameters]
    )
    lower = [sp.S.NegativeInfinity if lo is None else sp.Float(lo) for lo, _ in param_bounds]
    upper = [sp.S.Infinity if hi is None else sp.Float(hi) for _, hi in param_bounds]
    limits = sp.ImmutableMatrix(2, len(ps), lower + upper)
    prefix, macro = function_prefix(model.name), macro_prefix(model.name)
    doc_values = {
        "states": _doc_variables(model.states),
        "inputs": _doc_variables(model.inputs),
        "outputs": _doc_variables(model.outputs),
        "prefix": prefix,
        "macro": macro,
        **{k: v for k, v in sizes.items() if k != "1"},
        **{f"nnz_{var}": pattern.nnz for var, pattern in patterns.items()},
        **{f"size_{var}": pattern.size for var, pattern in patterns.items()},
    }

    functions = []
    for row in ROWS:
        if not _selected(row, config):
            continue
        pattern = patterns[row.jacobian] if row.jacobian else None
        row_sizes = {**sizes, "nnz": pattern.nnz if pattern else 0}
        outputs = tuple(
            Output(name, (row_sizes[rows], row_sizes[cols]), ctype)
            for name, rows, cols, ctype in row.outputs
        )
        expressions: tuple[sp.ImmutableMatrix, ...] = ()
        source = None
        if row.name == "rhs":
            expressions = (f,)
        elif row.name == "outputs":
            expressions = (h,)
        elif row.name == "jac_outputs":
            expressions = (output_jacobian,)
        elif row.name == "ekf_mode_quantities":
            assert config.ekf is not None
            quantities = sp.ImmutableMatrix(config.ekf.mode_quantities)
            expressions = (
                sp.ImmutableMatrix(quantities.xreplace(changed) if changed else quantities),
            )
        elif row.name == "euio_load_column":
            assert config.euio is not None
            column = sp.ImmutableMatrix(config.euio.load_column)
            expressions = (sp.ImmutableMatrix(column.xreplace(changed) if changed else column),)
        elif row.jacobian and row.name.endswith("_sparse"):
            assert pattern is not None
            expressions = (pattern.nonzeros(jac[row.jacobian]),)
        elif row.jacobian:
            expressions = (jac[row.jacobian],)
            source = f"{row.name}_sparse" if row.kind == "spread" else None
        elif row.kind == "params_default":
            expressions = (defaults,)
        elif row.kind == "params_validate":
            expressions = (limits,)
        functions.append(
            FunctionSpec(
                row.name,
                tuple(args[a] for a in row.args),
                outputs,
                expressions,
                row.doc.format(**doc_values),
                kind=row.kind,
                returns=row.returns,
                pattern=pattern if (source or row.name.endswith("_sparse")) else None,
                source=source,
            )
        )
    return FunctionTable(
        model=model,
        config=config,
        prefix=prefix,
        macro_prefix=macro,
        states=xs,
        inputs=us,
        parameters=ps,
        bounds=param_bounds,
        functions=tuple(functions),
    )


def function_names(config: CodegenConfig | None = None) -> list[str]:
    """Names of the functions every model gets under ``config`` (no model needed)."""
    config = as_config(config)
    return [row.name for row in ROWS if _selected(row, config)]
