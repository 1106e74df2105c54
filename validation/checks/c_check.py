"""Compile emitted C, call it through ctypes, and compare it (and the CasADi module) with SymPy.

Error metric (per function, over all sample points and output entries)::

    e = |y - y_ref| / max(|y_ref|, FLOOR * s_k)

where ``s_k`` is the largest ``|y_ref|`` of output entry ``k`` over all sample points. So ``e`` is
the relative error wherever the reference is not small compared with the entry's own scale, and
an error normalised by ``FLOOR * s_k`` where it is (near zero crossings, where any rounding in a
cancellation looks infinitely large in relative terms). ``FLOOR`` is 1e-3 in double and 1e-2
in single precision (float rounding of ~6e-8 per operation must stay below the 1e-5 target at a
cancellation). An entry that is zero at every sample point (``s_k = 0``) must be reproduced
exactly (up to the smallest normal number). Targets: 1e-12 in double, 1e-5 in single.

NaN in the same place on both sides counts as agreement (a Piecewise without a default branch is
NaN outside its pieces), NaN on one side only as an infinite error.

The single-precision comparison evaluates the reference at the float-rounded sample points, so
what is measured is the error of the emitted code, not the rounding of its inputs.

Reference: the model's own expressions through ``sympy.lambdify`` (numpy, vectorised; or mpmath
at 30 digits), with Jacobians taken by ``Matrix.jacobian`` independently of the emitter's
``smart_jacobian``.

The sparse Jacobians ``jac_*_sparse`` are checked at the same points: their values are placed by
the compressed-column pattern read from the compiled library's ``const`` arrays, every other
entry set to 0, and the resulting matrix is compared with the dense reference like any other
output, so a value in the wrong place and a nonzero left out of the pattern both fail.
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic.codegen import CodegenConfig, emit_all, file_names
from gearsym.symbolic.model import Model
from gearsym.validation.checks.c_binding import CFunctions, load_casadi_module, load_functions

STRICT_FLAGS: tuple[str, ...] = (
    "-std=c99",
    "-Wall",
    "-Wextra",
    "-Wpedantic",
    "-Wconversion",
    "-Wdouble-promotion",
    "-Wshadow",
    "-Werror",
)
FLOOR = {"double": 1e-3, "single": 1e-2}
TOLERANCE = {"double": 1e-12, "single": 1e-5}
#: The conditioned single-precision metric (``conditioned_error`` of
#: :mod:`gearsym.validation.checks.generated_check` for the models, and of
#: :mod:`gearsym.validation.checks.hybrid_code_check` for the hybrid sets): float ulps by which
#: every input is perturbed, and how many times the resulting spread of the exact function the
#: float build may deviate.
PERTURBATION_ULPS = 1.0
CONDITIONED_FACTOR = 10.0
EXPR_FUNCTIONS = ("rhs", "outputs", "jac_x", "jac_u", "jac_p")
STATE_RANGE = (-2.0, 2.0)  # default sampling range of states and inputs

Bounds = Mapping[str, tuple[float | None, float | None]]


class CompileError(RuntimeError):
    """The compiler failed or printed anything (a warning counts as a failure)."""


def _precision(single: bool) -> str:
    return "single" if single else "double"


def write_files(files: Mapping[str, str], out_dir: Path) -> list[Path]:
    """Write emitted files into ``out_dir`` (created if needed); returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in sorted(files):
        path = out_dir / name
        path.write_text(files[name], encoding="utf-8")
        paths.append(path)
    return paths


def _run_compiler(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if proc.returncode != 0 or proc.stderr.strip() or proc.stdout.strip():
        raise CompileError(f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}")


def run_with_harness(
    files: Mapping[str, str],
    out_dir: Path,
    harness: Path,
    source: str,
    single: bool = True,
    timeout: float = 600.0,
) -> subprocess.CompletedProcess[str]:
    """Write ``files`` into ``out_dir``, build the C program ``harness`` with the emitted
    ``source`` (strict flags, ``-O2``; single precision by default, the harness' own
    float/double mixing allowed) and run it; its completed process (stdout, return code)."""
    write_files(files, out_dir)
    exe = out_dir / (harness.stem + ("_float" if single else "_double"))
    cmd = ["gcc", *STRICT_FLAGS, "-O2", f"-I{out_dir}"]
    cmd += ["-DGEARSYM_SINGLE_PRECISION"] if single else []
    cmd += ["-Wno-float-conversion", "-Wno-conversion", "-Wno-double-promotion"]
    cmd += ["-o", str(exe), str(harness), str(out_dir / source), "-lm"]
    _run_compiler(cmd, out_dir)
    return subprocess.run([str(exe)], capture_output=True, text=True, timeout=timeout, check=False)


def compile_shared(
    files: Mapping[str, str],
    out_dir: Path,
    single: bool = False,
    extra_flags: Sequence[str] = (),
    compiler: str = "gcc",
) -> Path:
    """Compile every ``.c`` of ``files`` into a shared library with :data:`STRICT_FLAGS`.

    Raises :class:`CompileError` on any diagnostic. The library is named after the first source
    and the precision, so double and single builds can live in the same directory.
    """
    paths = write_files(files, out_dir)
    sources = [str(p) for p in paths if p.suffix == ".c"]
    if not sources:
        raise ValueError("no C source among the files")
    lib = out_dir / f"lib{Path(sources[0]).stem}_{_precision(single)}.so"
    cmd = [compiler, *STRICT_FLAGS, "-O2", "-fPIC", "-shared"]
    cmd += ["-DGEARSYM_SINGLE_PRECISION"] if single else []
    cmd += [*extra_flags, "-o", str(lib), *sources, "-lm"]
    _run_compiler(cmd, out_dir)
    return lib


@dataclass
class ObjectReport:
    """Static facts about one compiled source (ECU rules that the compiler can check)."""

    mutable_objects: list[str]  # symbols in .data/.bss: file-scope state that is not const
    undefined: list[str]  # external functions called (libm only, no malloc)
    call_graph: dict[str, set[str]]
    stack_bytes: dict[str, int]  # per function, from -fstack-usage
    dynamic_stack: list[str]  # functions whose stack use is unbounded (VLA, alloca)

    def recursive_functions(self) -> list[str]:
        """Functions that can reach themselves in the call graph."""
        found = []
        for start in sorted(self.call_graph):
            seen: set[str] = set()
            todo = list(self.call_graph[start])
            while todo:
                node = todo.pop()
                if node == start:
                    found.append(start)
                    break
                if node not in seen:
                    seen.add(node)
                    todo.extend(self.call_graph.get(node, ()))
        return found


def analyse_object(
    files: Mapping[str, str], out_dir: Path, single: bool = False, compiler: str = "gcc"
) -> ObjectReport:
    """Compile each source to an object (no inlining, so the call graph is the source's) and
    report mutable static data, external calls, the call graph and stack use."""
    paths = write_files(files, out_dir)
    mutable, undefined, stack, dynamic = [], [], {}, []
    graph: dict[str, set[str]] = {}
    for source in (p for p in paths if p.suffix == ".c"):
        stem = f"{source.stem}_{_precision(single)}"
        obj = out_dir / f"{stem}.o"
        cmd = [compiler, *STRICT_FLAGS, "-O2", "-fno-inline", "-c", "-fstack-usage"]
        cmd += ["-fcallgraph-info", *(["-DGEARSYM_SINGLE_PRECISION"] if single else [])]
        cmd += ["-o", str(obj), str(source)]
        _run_compiler(cmd, out_dir)
        nm = subprocess.run(["nm", str(obj)], capture_output=True, text=True, check=True).stdout
        for line in nm.splitlines():
            parts = line.split()
            kind, name = parts[-2], parts[-1]
            if kind in "DdBbCGgSs":
                mutable.append(name)
            elif kind == "U":
                undefined.append(name)
        for line in (out_dir / f"{stem}.su").read_text().splitlines():
            location, size, qualifier = line.split("\t")
            name = location.rsplit(":", 1)[-1]
            stack[name] = int(size)
            # "dynamic,bounded": a known bound, the frame changing inside the function (x86-64
            # pushes the arguments of a call with more than six); "dynamic": a VLA or alloca
            if qualifier.strip() not in ("static", "dynamic,bounded"):
                dynamic.append(name)
        for src, dst in re.findall(
            r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"',
            (out_dir / f"{stem}.ci").read_text(),
        ):
            graph.setdefault(src, set()).add(dst)
    return ObjectReport(sorted(mutable), sorted(set(undefined)), graph, stack, dynamic)


def preprocessed_own_lines(
    files: Mapping[str, str], out_dir: Path, single: bool = False, compiler: str = "gcc"
) -> str:
    """The preprocessed text of the emitted sources, without the lines of system headers
    (used to check that the single build contains no double literal)."""
    paths = write_files(files, out_dir)
    own = {p.name for p in paths}
    lines = []
    for source in (p for p in paths if p.suffix == ".c"):
        cmd = [compiler, "-std=c99", "-E", *(["-DGEARSYM_SINGLE_PRECISION"] if single else [])]
        text = subprocess.run(
            [*cmd, str(source)], capture_output=True, text=True, check=True, cwd=out_dir
        ).stdout
        current = ""
        for line in text.splitlines():
            marker = re.match(r'^# \d+ "([^"]+)"', line)
            if marker:
                current = Path(marker.group(1)).name
            elif current in own:
                lines.append(line)
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# Reference and comparison
# ---------------------------------------------------------------------------------------------


def sample_points(
    model: Model,
    n_points: int,
    seed: int = 0,
    bounds: Bounds | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Uniform random ``(X, U, P)`` of shapes ``(n, nx)``, ``(n, nu)``, ``(n, np)``.

    States and inputs lie in :data:`STATE_RANGE` unless ``ranges`` names them; parameters in
    ``ranges``, else ``[0.5, 1.5] x default`` clipped to ``bounds``, else their bounds, else
    ``[0.5, 2]``.
    """
    rng = np.random.default_rng(seed)
    ranges = dict(ranges or {})
    bounds = dict(bounds or {})

    def draw(variables: Sequence[Any], parameter: bool) -> np.ndarray:
        cols = []
        for v in variables:
            if v.name in ranges:
                lo, hi = ranges[v.name]
            elif not parameter:
                lo, hi = STATE_RANGE
            else:
                b_lo, b_hi = bounds.get(v.name, (None, None))
                if v.default is not None and v.default != 0:
                    lo, hi = sorted((0.5 * v.default, 1.5 * v.default))
                    lo = lo if b_lo is None else max(lo, b_lo)
                    hi = hi if b_hi is None else min(hi, b_hi)
                elif b_lo is not None and b_hi is not None:
                    lo, hi = b_lo, b_hi
                else:
                    lo, hi = 0.5, 2.0
            cols.append(rng.uniform(lo, hi, n_points))
        return np.array(cols).T.reshape(n_points, len(variables))

    return draw(model.states, False), draw(model.inputs, False), draw(model.parameters, True)


_MATRIX_CACHE: dict[int, tuple[Model, tuple[list[sp.Symbol], dict[str, sp.Matrix]]]] = {}


def reference_matrices(model: Model) -> tuple[list[sp.Symbol], dict[str, sp.Matrix]]:
    """The reference expressions of every expression function, over real dummies, with
    Jacobians from ``Matrix.jacobian`` and Dirac deltas dropped (derivative almost everywhere).
    Remembered per model object (the NaN rules and the pattern check both need them)."""
    cached = _MATRIX_CACHE.get(id(model))
    if cached is not None and cached[0] is model:
        return cached[1]
    if len(_MATRIX_CACHE) > 64:
        _MATRIX_CACHE.clear()
    result = _reference_matrices(model)
    _MATRIX_CACHE[id(model)] = (model, result)
    return result


def _reference_matrices(model: Model) -> tuple[list[sp.Symbol], dict[str, sp.Matrix]]:
    variables = [*model.states, *model.inputs, *model.parameters]
    # Plain real symbols with positional names (not Dummy): lambdify then needs no renaming pass,
    # which dominated the reference's cost.
    dummies = {v.symbol: sp.Symbol(f"gearsym_ref_{k}", real=True) for k, v in enumerate(variables)}
    f = model.rhs.xreplace(dummies)
    h = model.output_expressions.xreplace(dummies)

    def jac(wrt: Sequence[Any]) -> sp.Matrix:
        if not wrt:
            return sp.zeros(f.shape[0], 0)
        j = f.jacobian([dummies[v.symbol] for v in wrt])
        return j.replace(lambda e: isinstance(e, sp.DiracDelta), lambda e: sp.S.Zero)

    matrices = {
        "rhs": f,
        "outputs": h,
        "jac_x": jac(model.states),
        "jac_u": jac(model.inputs),
        "jac_p": jac(model.parameters),
    }
    return [dummies[v.symbol] for v in variables], matrices


def _heaviside(x: Any, h0: Any = 0.5) -> Any:
    return 1 if x > 0 else (0 if x < 0 else h0)


_REFERENCE_CACHE: dict[tuple[int, str], tuple[Model, dict[str, tuple[int, Any]]]] = {}


def _reference_functions(model: Model, backend: str) -> dict[str, tuple[int, Any]]:
    """Lambdified reference per expression function, cached per model object and backend
    (differentiating and lambdifying dominate the cost of a comparison)."""
    key = (id(model), backend)
    cached = _REFERENCE_CACHE.get(key)
    if cached is not None and cached[0] is model:
        return cached[1]
    if backend not in ("numpy", "mpmath"):
        raise ValueError(f"unknown backend {backend!r}")
    variables, matrices = reference_matrices(model)
    # scipy first: it vectorises erf, gamma and friends that plain numpy lacks.
    modules: Any = (
        ["scipy", "numpy"] if backend == "numpy" else [{"Heaviside": _heaviside}, "mpmath"]
    )
    functions: dict[str, tuple[int, Any]] = {}
    for name, matrix in matrices.items():
        flat = [matrix[i, j] for j in range(matrix.shape[1]) for i in range(matrix.shape[0])]
        functions[name] = (
            len(flat),
            sp.lambdify(variables, flat, modules=modules) if flat else None,
        )
    if len(_REFERENCE_CACHE) > 64:
        _REFERENCE_CACHE.clear()
    _REFERENCE_CACHE[key] = (model, functions)
    return functions


def evaluate_reference(
    model: Model, points: np.ndarray, backend: str = "numpy"
) -> dict[str, np.ndarray]:
    """Reference values ``(n, size)`` (flat column-major per point) of every expression function
    at ``points`` (rows ``[x, u, p]``), with numpy (vectorised) or mpmath (30 digits)."""
    points = np.atleast_2d(np.asarray(points, dtype=np.float64))
    n = points.shape[0]
    result = {}
    for name, (size, fn) in _reference_functions(model, backend).items():
        values = np.zeros((n, size))
        if fn is None:
            pass
        elif backend == "numpy":
            with np.errstate(all="ignore"):
                for k, column in enumerate(fn(*points.T)):
                    values[:, k] = np.broadcast_to(column, (n,))
        else:
            import mpmath

            with mpmath.workdps(30):
                for row in range(n):
                    args = [mpmath.mpf(float(v)) for v in points[row]]
                    values[row, :] = [float(v) for v in fn(*args)]
        result[name] = values
    return result


@dataclass
class ComparisonReport:
    """Largest error per function (metric in the module docstring) and where it occurred."""

    target: str  # "C double", "C single", "CasADi"
    n_points: int
    floor: float
    max_error: dict[str, float] = field(default_factory=dict)
    worst_point: dict[str, int] = field(default_factory=dict)
    extra: dict[str, float] = field(default_factory=dict)
    #: Optional second metric of some functions, allowing for their conditioning (filled by
    #: :func:`gearsym.validation.checks.generated_check.conditioned_error`); not part of
    #: :meth:`worst`.
    conditioned: dict[str, float] = field(default_factory=dict)

    def worst(self) -> float:
        return max([*self.max_error.values(), *self.extra.values()], default=0.0)

    def ok(self, tolerance: float) -> bool:
        return self.worst() <= tolerance

    def __str__(self) -> str:
        rows = [f"{self.target}: {self.n_points} points, floor {self.floor:g}"]
        for name, err in {**self.max_error, **self.extra}.items():
            more = (
                f" (conditioned {self.conditioned[name]:.3e})" if name in self.conditioned else ""
            )
            rows.append(f"  {name:<10} {err:.3e}{more}")
        return "\n".join(rows)


def mixed_error(values: np.ndarray, reference: np.ndarray, floor: float) -> np.ndarray:
    """Per-point worst error of one function, arrays ``(n, size)`` (see the module docstring)."""
    if values.shape[1] == 0:
        return np.zeros(values.shape[0])
    magnitude = np.abs(reference)
    finite = np.where(np.isfinite(magnitude), magnitude, 0.0)  # NaN/inf must not set the scale
    scale = finite.max(axis=0)
    tiny = np.finfo(np.float64).tiny
    denominator = np.maximum(magnitude, np.maximum(floor * scale, tiny))
    with np.errstate(invalid="ignore"):
        err = np.abs(values - reference) / denominator
    # NaN in exactly the same place is agreement; NaN on one side only is a failure.
    both_nan = np.isnan(values) & np.isnan(reference)
    same_inf = np.isinf(reference) & (values == reference)
    err = np.where(both_nan | same_inf, 0.0, np.where(np.isnan(err), np.inf, err))
    return err.max(axis=1)


def _report(
    target: str,
    computed: Mapping[str, np.ndarray],
    reference: Mapping[str, np.ndarray],
    floor: float,
) -> ComparisonReport:
    """Errors of every computed function; ``<jac>_sparse`` against the reference of ``<jac>``."""
    n = next(iter(reference.values())).shape[0]
    report = ComparisonReport(target, n, floor)
    for name in computed:
        per_point = mixed_error(computed[name], reference[name.removesuffix("_sparse")], floor)
        report.max_error[name] = float(per_point.max(initial=0.0))
        report.worst_point[name] = int(per_point.argmax()) if per_point.size else -1
    return report


def compare_with_sympy(
    model: Model,
    lib: CFunctions,
    n_points: int = 1000,
    seed: int = 0,
    bounds: Bounds | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    backend: str = "numpy",
    floor: float | None = None,
) -> ComparisonReport:
    """Max error of every expression function of the C library against SymPy, plus
    ``params_default`` against the model defaults (``extra``). ``floor`` overrides
    :data:`FLOOR` of the library's precision."""
    X, U, P = sample_points(model, n_points, seed, bounds, ranges)
    if lib.single:  # compare at the points the float code actually sees
        X, U, P = (a.astype(np.float32).astype(np.float64) for a in (X, U, P))
    reference = evaluate_reference(model, np.hstack([X, U, P]), backend)
    computed = {}
    for name in EXPR_FUNCTIONS:
        computed[name] = np.array(
            [lib.evaluate(name, X[k], U[k], P[k]) for k in range(n_points)]
        ).reshape(n_points, -1)
    for spec in lib.table.sparse_rows():  # the same points, spread by the compiled pattern
        jacobian = spec.name.removesuffix("_sparse")
        computed[spec.name] = np.array(
            [lib.evaluate_sparse(jacobian, X[k], U[k], P[k]) for k in range(n_points)]
        ).reshape(n_points, -1)
    precision = _precision(lib.single)
    report = _report(f"C {precision}", computed, reference, floor or FLOOR[precision])
    defaults = np.array([np.nan if v.default is None else v.default for v in model.parameters])
    if lib.single:
        defaults = defaults.astype(np.float32).astype(np.float64)
    c_defaults = lib.params_default()
    same = (c_defaults == defaults) | (np.isnan(c_defaults) & np.isnan(defaults))
    report.extra["params_default"] = 0.0 if same.all() else float("inf")
    return report


def casadi_values(module: ModuleType, X: np.ndarray, U: np.ndarray, P: np.ndarray) -> dict:
    """Flat column-major outputs ``(n, size)`` of every function of an emitted CasADi module,
    evaluated with ``Function.map`` over all points at once."""
    n = X.shape[0]
    result = {}
    for name, fn in module.functions().items():
        mapped = fn.map(n)
        out = mapped(X.T, U.T, P.T)
        full = np.array(out.full() if hasattr(out, "full") else out, dtype=np.float64)
        rows, cols = fn.size_out(0)
        # map() concatenates the n results horizontally: (rows, n*cols) -> (n, cols*rows).
        result[name] = full.reshape(rows, n, cols).transpose(1, 2, 0).reshape(n, rows * cols)
    return result


def compare_casadi_with_sympy(
    model: Model,
    module: ModuleType,
    n_points: int = 1000,
    seed: int = 0,
    bounds: Bounds | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    backend: str = "numpy",
    floor: float | None = None,
) -> ComparisonReport:
    """Max error of every function of an emitted CasADi module against SymPy."""
    X, U, P = sample_points(model, n_points, seed, bounds, ranges)
    reference = evaluate_reference(model, np.hstack([X, U, P]), backend)
    values = casadi_values(module, X, U, P)
    values = {name: values[name] for name in EXPR_FUNCTIONS}
    report = _report("CasADi", values, reference, floor or FLOOR["double"])
    defaults = np.array([np.nan if v.default is None else v.default for v in model.parameters])
    emitted = np.array(module.PARAMETER_DEFAULTS, dtype=np.float64)
    same = (emitted == defaults) | (np.isnan(emitted) & np.isnan(defaults))
    report.extra["defaults"] = 0.0 if same.all() else float("inf")
    return report


def build(
    model: Model, out_dir: Path, config: CodegenConfig | Bounds | None = None
) -> dict[str, Any]:
    """Emit with ``config`` (or a bare bounds mapping), compile (double and single, strict
    flags) and load everything for ``model``.

    Returns ``{"files": {name: text}, "double": CFunctions, "single": CFunctions,
    "casadi": module}``.
    """
    files = emit_all(model, config)
    c_files = {k: v for k, v in files.items() if k.endswith((".c", ".h"))}
    lib_double = compile_shared(c_files, out_dir, single=False)
    lib_single = compile_shared(c_files, out_dir, single=True)
    write_files(files, out_dir)
    return {
        "files": files,
        "double": load_functions(lib_double, model, single=False, config=config),
        "single": load_functions(lib_single, model, single=True, config=config),
        "casadi": load_casadi_module(out_dir / file_names(model)["casadi"]),
    }
