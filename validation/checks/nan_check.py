"""Emitted C under AddressSanitizer and UndefinedBehaviorSanitizer, and the NaN contract.

:func:`run` compiles the emitted sources of some models (and the μ map) with a generated driver,
``-fsanitize=address,undefined -fno-sanitize-recover=all``, in double and single precision, and
runs it. The driver calls every function of every model (rhs, outputs, jac_x, jac_u, jac_p,
jac_*_sparse, rk4_step, linearly_implicit_euler_step, as emitted, params_default,
params_validate) at three
base points (a nominal one; every state, input and parameter at the low end of its range or
bound and h = 1e-6; all at the high end and h = 0.1). From each base point it sets every
argument entry (x, u, p, h) in turn, and then all of them at once, to each of NaN, +-inf, +-0,
+-huge (the largest finite value) and +-tiny (the smallest subnormal). Every output buffer is
allocated with its exact size, so ASan sees any write past it. A sanitizer report or a non-zero
exit fails the run.

What the driver prints is judged against rules derived from IEEE 754 and the model's own
expressions (:func:`gearsym.validation.checks.c_check.reference_matrices`), never from the
emitted code:

* NaN contract, expression functions: with one NaN argument entry (nominal base point), every
  output entry whose expression is NaN-strict in that entry (:func:`nan_strict_symbols`) is NaN;
  entry k of a sparse Jacobian ``jac_*_sparse`` is judged by the reference entry its
  compressed-column pattern places it at, and the pattern must hold every reference entry that
  is not identically 0 (:func:`pattern_problems`);
* ``rk4_step``: every x_next entry that a NaN reaches through the four stages
  (:func:`rk4_nan_entries`) is NaN; all of them for a NaN h;
* ``linearly_implicit_euler_step``: NaN or +-inf in x, u or h, or NaN in a parameter that f or
  df/dx is strict in, gives ERR_NONFINITE; for any argument the status is OK with a finite
  x_next, or an error with x_next untouched;
* ``params_validate``: the status and index of the first non-finite or out-of-range parameter;
* at the nominal point every output is finite and the implicit step returns OK;
* ``gearsym_mu_map``: NaN in any argument gives NaN; otherwise (+-inf, huge, tiny, 0 included)
  a value between the smallest and the largest table entry (clamped trilinear interpolation is a
  convex combination of table entries).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np
import sympy as sp
from gearsym.symbolic.codegen import (
    INTEGRATORS,
    CodegenConfig,
    SparsityPattern,
    build_function_table,
    file_names,
    float_repr,
)
from gearsym.symbolic.friction import MuMap
from gearsym.symbolic.model import Model
from gearsym.validation.checks import c_check

SANITIZE_FLAGS: tuple[str, ...] = (
    "-fsanitize=address,undefined",
    "-fno-sanitize-recover=all",
    "-fno-omit-frame-pointer",
    "-g",
    "-O0",  # the sanitizers need no optimisation; -O0 halves the build time of the 27 sources
)
#: Special values in the order of the driver's codes 0..8.
SPECIAL_NAMES: tuple[str, ...] = (
    "nan",
    "+inf",
    "-inf",
    "+0",
    "-0",
    "+huge",
    "-huge",
    "+tiny",
    "-tiny",
)
NAN, POS_INF, NEG_INF = 0, 1, 2
SENTINEL = -1.25e30  # x_next before the implicit step; exact in float and double
BASE_STEPS = (1e-3, 1e-6, 0.1)  # h at the nominal, low and high base points
STATUS = {"OK": 0, "ERR_NONFINITE": 1, "ERR_RANGE": 2, "ERR_SINGULAR": 3}
EXPRESSION_FUNCTIONS = ("rhs", "outputs", "jac_x", "jac_u", "jac_p")

Bounds = Mapping[str, tuple[float | None, float | None]]


@dataclass(frozen=True)
class CheckedModel:
    """A model, the parameter bounds its params_validate enforces, its sampling ranges and the
    integrator steps it was emitted with."""

    model: Model
    bounds: Bounds
    ranges: Mapping[str, tuple[float, float]]
    integrators: tuple[str, ...] = INTEGRATORS

    @property
    def config(self) -> CodegenConfig:
        return CodegenConfig(bounds=self.bounds, integrators=self.integrators)

    def sparse_patterns(self) -> dict[str, SparsityPattern]:
        """The pattern of every ``jac_*_sparse`` function emitted for the model."""
        table = build_function_table(self.model, self.config)
        return {spec.name: spec.pattern for spec in table.sparse_rows() if spec.pattern}


@dataclass
class NanReport:
    """Outcome of :func:`run`: what was exercised, and every violation found."""

    calls: dict[str, int] = field(default_factory=dict)  # per precision
    failures: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failures


# ---------------------------------------------------------------------------------------------
# Rules
# ---------------------------------------------------------------------------------------------


def nan_strict_symbols(expr: sp.Basic, memo: dict[sp.Basic, frozenset] | None = None) -> frozenset:
    """The symbols a NaN in which makes ``expr`` NaN (all other symbols finite).

    IEEE 754: every arithmetic operation and elementary function with a NaN operand is NaN
    (``pow(1, NaN)`` and ``pow(NaN, 0)`` aside, which need an exact 1 or 0 at run time). min/max
    and a comparison deciding a piecewise term are NaN-strict by the emitted code's contract. A
    piecewise term is strict in its conditions' symbols and in those strict in *every* branch; a
    symbol occurring only in some branches is no dependency where another branch is taken.
    """
    memo = {} if memo is None else memo
    found = memo.get(expr)
    if found is not None:
        return found
    if isinstance(expr, sp.Symbol):
        found = frozenset((expr,))
    elif not expr.args or expr.is_number:
        found = frozenset()
    elif isinstance(expr, sp.Piecewise):
        conditions = frozenset().union(*(pair.cond.free_symbols for pair in expr.args))
        branches = [nan_strict_symbols(pair.expr, memo) for pair in expr.args]
        found = conditions | frozenset.intersection(*branches)
    else:
        found = frozenset().union(*(nan_strict_symbols(a, memo) for a in expr.args))
    memo[expr] = found
    return found


def strict_entries(
    model: Model, patterns: Mapping[str, SparsityPattern] | None = None
) -> dict[str, list[frozenset[int]]]:
    """Per expression function, per output entry (column-major): the argument indices (x, u, p
    in order) its reference expression is NaN-strict in. ``patterns`` adds the sparse Jacobians
    (``jac_x_sparse``: ...), entry k taken from where the pattern places it."""
    variables, matrices = c_check.reference_matrices(model)
    index = {s: k for k, s in enumerate(variables)}
    memo: dict[sp.Basic, frozenset] = {}
    result = {}
    for name, matrix in matrices.items():
        rows, cols = matrix.shape
        result[name] = [
            frozenset(index[s] for s in nan_strict_symbols(matrix[i, j], memo) if s in index)
            for j in range(cols)
            for i in range(rows)
        ]
    for name, pattern in (patterns or {}).items():
        dense = result[name.removesuffix("_sparse")]
        result[name] = [dense[k] for k in pattern.positions()]
    return result


def pattern_problems(model: Model, patterns: Mapping[str, SparsityPattern]) -> list[str]:
    """Reference entries that are not identically 0 but lie outside their sparse pattern (the
    emitted dense Jacobian would hold a 0 there)."""
    _, matrices = c_check.reference_matrices(model)
    problems = []
    for name, pattern in patterns.items():
        matrix = matrices[name.removesuffix("_sparse")]
        if matrix.shape != (pattern.nrow, pattern.ncol):
            problems.append(f"{model.name} {name}: pattern shape differs from {matrix.shape}")
            continue
        inside = set(pattern.positions())
        missing = [
            (i, j)
            for j in range(pattern.ncol)
            for i in range(pattern.nrow)
            if i + j * pattern.nrow not in inside and matrix[i, j] != 0
        ]
        if missing:
            problems.append(f"{model.name} {name}: nonzero entries {missing} outside the pattern")
    return problems


def rk4_nan_entries(rhs_strict: Sequence[frozenset[int]], nx: int, target: int) -> set[int]:
    """x_next entries of one classical RK4 step that are NaN when argument ``target`` (an index
    into x, u, p, or ``-1`` for h) is NaN, given the NaN-strictness of each entry of f.

    k1 = f(x), k2 = f(x + h/2 k1), k3 = f(x + h/2 k2), k4 = f(x + h k3), x_next = x + h/6 (k1 +
    2 k2 + 2 k3 + k4): a stage argument entry is NaN where x or the previous k is; u and p enter
    every stage.
    """
    if target == -1:
        return set(range(nx))
    nan_args = {target}  # NaN entries among (stage state, u, p): x_j or u/p, at every stage
    ks: set[int] = set()
    for _ in range(4):
        k = {i for i in range(nx) if rhs_strict[i] & nan_args}
        ks |= k
        nan_args = {target} | k  # the next stage's state is x + c h k
    return ks | ({target} & set(range(nx)))


def expected_validate(
    values: Sequence[float], bounds: Sequence[tuple[float | None, float | None]], dtype: type
) -> tuple[int, int]:
    """(status, index) of params_validate for parameter values in ``dtype`` (float32/64)."""
    for k, (value, (lo, hi)) in enumerate(zip(values, bounds, strict=True)):
        v = dtype(value)
        if not np.isfinite(v):
            return STATUS["ERR_NONFINITE"], k
        if (lo is not None and v < dtype(lo)) or (hi is not None and v > dtype(hi)):
            return STATUS["ERR_RANGE"], k
    return STATUS["OK"], -1


def special_values(dtype: type) -> list[float]:
    """The values of the driver's codes 0..8 in ``dtype`` (as Python floats)."""
    info = np.finfo(dtype)
    huge, tiny = float(info.max), float(info.smallest_subnormal)
    return [float("nan"), float("inf"), float("-inf"), 0.0, -0.0, huge, -huge, tiny, -tiny]


# ---------------------------------------------------------------------------------------------
# Base points
# ---------------------------------------------------------------------------------------------


def base_points(m: CheckedModel, seed: int = 0) -> np.ndarray:
    """(3, nx + nu + np + 1) rows [x, u, p, h]: nominal, low end, high end (see the module)."""
    model = m.model
    x, u, p = c_check.sample_points(model, 1, seed, m.bounds, m.ranges)
    nominal = np.concatenate([x[0], u[0], p[0], [BASE_STEPS[0]]])
    rows = [nominal]
    for side, h in ((0, BASE_STEPS[1]), (1, BASE_STEPS[2])):
        values = []
        for v in (*model.states, *model.inputs):
            values.append(m.ranges.get(v.name, c_check.STATE_RANGE)[side])
        for k, v in enumerate(model.parameters):
            bound = m.bounds.get(v.name, (None, None))[side]
            values.append(
                nominal[len(model.states) + len(model.inputs) + k] if bound is None else bound
            )
        rows.append(np.array([*values, h], dtype=np.float64))
    return np.array(rows)


# ---------------------------------------------------------------------------------------------
# The driver
# ---------------------------------------------------------------------------------------------

_DRIVER_HEAD = r"""/* Sanitizer and NaN-contract driver (gearsym.validation.checks.nan_check). */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

{includes}

#ifdef GEARSYM_SINGLE_PRECISION
#define DRIVER_HUGE FLT_MAX
#define DRIVER_TINY (FLT_MIN * FLT_EPSILON)
#else
#define DRIVER_HUGE DBL_MAX
#define DRIVER_TINY (DBL_MIN * DBL_EPSILON)
#endif
#define N_SPECIAL 9

static long calls = 0;

static gearsym_real special(int code)
{{
    switch (code) {{
    case 0: return (gearsym_real)NAN;
    case 1: return (gearsym_real)INFINITY;
    case 2: return -(gearsym_real)INFINITY;
    case 3: return GEARSYM_LIT(0.0);
    case 4: return -GEARSYM_LIT(0.0);
    case 5: return DRIVER_HUGE;
    case 6: return -DRIVER_HUGE;
    case 7: return DRIVER_TINY;
    default: return -DRIVER_TINY;
    }}
}}

/* Exactly n entries on the heap, so that ASan reports any access past them. */
static gearsym_real *buffer(int n)
{{
    gearsym_real *b = (gearsym_real *)malloc(sizeof(gearsym_real) * (size_t)(n > 0 ? n : 1));
    if (b == NULL) {{
        exit(3);
    }}
    return b;
}}

/* One character per entry: n NaN, i infinite, f finite. */
static void classes(const gearsym_real *v, int n)
{{
    int i;
    putchar(' ');
    for (i = 0; i < n; ++i) {{
        putchar(isnan(v[i]) ? 'n' : (isinf(v[i]) ? 'i' : 'f'));
    }}
    if (n == 0) {{
        putchar('-');
    }}
}}

static void set_args(gearsym_real *v, const gearsym_real *base, int n, int target, int code)
{{
    int i;
    for (i = 0; i < n; ++i) {{
        v[i] = (target == -2) ? special(code) : base[i];
    }}
    if (target >= 0) {{
        v[target] = special(code);
    }}
}}
"""

_MODEL_TEMPLATE = r"""
/* ---- {name} ---- */
static const gearsym_real base_{name}[3][{n}] = {{
{rows}
}};

static void run_{name}(int b, int target, int code)
{{
    const int nx = {nx};
    const int nu = {nu};
    gearsym_real v[{n}];
    gearsym_real *x = buffer({nx});
    gearsym_real *u = buffer({nu});
    gearsym_real *out = NULL;
    {prefix}params *p = ({prefix}params *)malloc(sizeof({prefix}params));
    {prefix}params *defaults = ({prefix}params *)malloc(sizeof({prefix}params));
    gearsym_real h;
    int i;
    int status;
    int bad = -7;
    const int full = (b == 0) && (target == -1 || code == 0) && target != -2;

    if (p == NULL || defaults == NULL) {{
        exit(3);
    }}
    memset(p, 0, sizeof(*p));
    set_args(v, base_{name}[b], {n}, target, code);
    for (i = 0; i < nx; ++i) {{
        x[i] = v[i];
    }}
    for (i = 0; i < nu; ++i) {{
        u[i] = v[nx + i];
    }}
{param_loads}
    h = v[{n} - 1];
{expression_calls}{rk4_call}{implicit_call}
    {prefix}params_default(defaults);
    status = {prefix}params_validate(p, &bad);
    calls += 2;
    if (target == -1 || target == -2 || (target >= nx + nu && target < {n} - 1)) {{
        printf("V {name} %d %d %d %d %d\n", b, target, code, status, bad);
    }}
    free(defaults);
    free(p);
    free(u);
    free(x);
}}
"""

_EXPRESSION_CALL = r"""    out = buffer({size});
    {prefix}{fn}(x, u, p, out);
    calls++;
    if (full) {{
        printf("E {name} %d %d %d {fn}", b, target, code);
        classes(out, {size});
        putchar('\n');
    }}
    free(out);
"""

_RK4_CALL = r"""    out = buffer({nx});
    {prefix}rk4_step(x, u, p, h, out);
    calls++;
    if (full) {{
        printf("E {name} %d %d %d rk4_step", b, target, code);
        classes(out, {nx});
        putchar('\n');
    }}
    free(out);
"""

_IMPLICIT_CALL = r"""    out = buffer({nx});
    for (i = 0; i < {nx}; ++i) {{
        out[i] = GEARSYM_LIT({sentinel});
    }}
    status = {prefix}linearly_implicit_euler_step(x, u, p, h, out);
    calls++;
    {{
        int untouched = 1;
        for (i = 0; i < {nx}; ++i) {{
            untouched = untouched && out[i] == GEARSYM_LIT({sentinel});
        }}
        printf("L {name} %d %d %d %d", b, target, code, status);
        classes(out, {nx});
        printf(" %d\n", untouched);
    }}
    free(out);
"""

_MU_MAP_PART = r"""
static void run_mu_map(void)
{
    static const gearsym_real base[3] = {BASE};
    gearsym_real v[3];
    int target;
    int code;

    for (target = -2; target < 3; ++target) {
        for (code = 0; code < N_SPECIAL; ++code) {
            gearsym_real mu;
            set_args(v, base, 3, target, code);
            mu = gearsym_mu_map(v[0], v[1], v[2]);
            calls++;
            printf("M %d %d", target, code);
            classes(&mu, 1);
            printf(" %a\n", (double)mu);
        }
    }
}
"""


def _literal(value: float) -> str:
    return f"GEARSYM_LIT({float_repr(float(value))})"


def driver_source(models: Sequence[CheckedModel], mu_map_base: Sequence[float] | None) -> str:
    """C source of the driver for ``models`` (and the μ map, given a nominal (p_N, T_oil, dw))."""
    includes = [f'#include "{file_names(m.model)["header"]}"' for m in models]
    if mu_map_base is not None:
        includes.append('#include "gearsym_mu_map.h"')
    parts = [_DRIVER_HEAD.format(includes="\n".join(includes))]
    for m in models:
        model = m.model
        name = model.name
        prefix = f"gearsym_{name}_"
        nx, nu = len(model.states), len(model.inputs)
        n = nx + nu + len(model.parameters) + 1
        rows = ",\n".join(
            "    {" + ", ".join(_literal(v) for v in row) + "}" for row in base_points(m)
        )
        loads = "\n".join(
            f"    p->{v.name} = v[{nx + nu + k}];" for k, v in enumerate(model.parameters)
        )
        sizes = {
            "rhs": nx,
            "outputs": len(model.outputs),
            "jac_x": nx * nx,
            "jac_u": nx * nu,
            "jac_p": nx * len(model.parameters),
            **{name: pattern.nnz for name, pattern in m.sparse_patterns().items()},
        }
        expression_calls = "".join(
            _EXPRESSION_CALL.format(prefix=prefix, fn=fn, size=size, name=name)
            for fn, size in sizes.items()
        )
        rk4 = ""
        if m.config.rk4_step:
            rk4 = _RK4_CALL.format(prefix=prefix, nx=nx, name=name)
        implicit = ""
        if m.config.implicit_step:
            implicit = _IMPLICIT_CALL.format(
                prefix=prefix, nx=nx, name=name, sentinel=float_repr(SENTINEL)
            )
        parts.append(
            _MODEL_TEMPLATE.format(
                name=name,
                n=n,
                rows=rows,
                nx=nx,
                nu=nu,
                prefix=prefix,
                param_loads=loads,
                expression_calls=expression_calls,
                rk4_call=rk4,
                implicit_call=implicit,
            )
        )
    if mu_map_base is not None:
        base = "{" + ", ".join(_literal(v) for v in mu_map_base) + "}"
        parts.append(_MU_MAP_PART.replace("{BASE}", base))
    main = ["", "int main(void)", "{", "    int b;", "    int target;", "    int code;", ""]
    for m in models:
        n = len(m.model.states) + len(m.model.inputs) + len(m.model.parameters) + 1
        name = m.model.name
        main += [
            "    for (b = 0; b < 3; ++b) {",
            f"        run_{name}(b, -1, -1);",
            f"        for (target = -2; target < {n}; ++target) {{",
            "            for (code = 0; code < N_SPECIAL; ++code) {",
            f"                run_{name}(b, target, code);",
            "            }",
            "        }",
            "    }",
        ]
    if mu_map_base is not None:
        main.append("    run_mu_map();")
    main += ['    printf("calls %ld\\n", calls);', "    return 0;", "}", ""]
    parts.append("\n".join(main))
    return "".join(parts)


# ---------------------------------------------------------------------------------------------
# Build, run, judge
# ---------------------------------------------------------------------------------------------


def sanitizer_support(compiler: str = "gcc", build_dir: Path | None = None) -> str | None:
    """``None`` if ``compiler`` builds and links with :data:`SANITIZE_FLAGS`, else the reason."""
    if shutil.which(compiler) is None:
        return f"{compiler} is not installed"
    folder = build_dir or Path(os.environ.get("TMPDIR", "/tmp"))
    folder.mkdir(parents=True, exist_ok=True)
    source = folder / "gearsym_sanitizer_probe.c"
    source.write_text("int main(void) { return 0; }\n")
    cmd = [compiler, *SANITIZE_FLAGS, "-o", str(folder / "gearsym_sanitizer_probe"), str(source)]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode:
        first = (proc.stderr.strip().splitlines() or ["(no message)"])[0]
        return f"{compiler} cannot build with {' '.join(SANITIZE_FLAGS[:2])}: {first}"
    return None


def _compile(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if proc.returncode or proc.stdout.strip() or proc.stderr.strip():
        raise c_check.CompileError(f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}")


def build_driver(
    sources: Mapping[str, str], driver: str, build_dir: Path, single: bool, compiler: str = "gcc"
) -> Path:
    """Compile the sources and the driver (strict flags and sanitizers) and link them."""
    tag = "single" if single else "double"
    folder = build_dir / tag
    c_check.write_files({**sources, "gearsym_nan_driver.c": driver}, folder)
    flags = [*c_check.STRICT_FLAGS, *SANITIZE_FLAGS]
    flags += ["-DGEARSYM_SINGLE_PRECISION"] if single else []
    names = sorted(n for n in [*sources, "gearsym_nan_driver.c"] if n.endswith(".c"))
    commands = [[compiler, *flags, "-c", "-o", f"{Path(n).stem}.o", n] for n in names]
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        list(pool.map(lambda cmd: _compile(cmd, folder), commands))
    exe = folder / "gearsym_nan_driver"
    objects = [f"{Path(n).stem}.o" for n in names]
    _compile([compiler, *SANITIZE_FLAGS, "-o", str(exe), *objects, "-lm"], folder)
    return exe


def run(
    models: Sequence[CheckedModel],
    sources: Mapping[str, str],
    build_dir: Path,
    mu_map: MuMap | None = None,
    compiler: str = "gcc",
) -> NanReport:
    """Build and run the driver in both precisions and judge its output (module docstring).

    ``sources``: the emitted headers and sources by file name, those of ``models`` and, with
    ``mu_map`` (what the μ map files were emitted from), ``gearsym_mu_map.{h,c}``.
    """
    report = NanReport()
    mu_map_table = None if mu_map is None else mu_map.table
    mu_map_base = None if mu_map is None else [float(np.mean(a[[0, -1]])) for a in mu_map.grid]
    driver = driver_source(models, mu_map_base)
    patterns = {m.model.name: m.sparse_patterns() for m in models}
    strict = {m.model.name: strict_entries(m.model, patterns[m.model.name]) for m in models}
    for m in models:
        report.failures += pattern_problems(m.model, patterns[m.model.name])
    for single in (False, True):
        tag = "single" if single else "double"
        exe = build_driver(sources, driver, build_dir, single, compiler)
        env = {
            **os.environ,
            "ASAN_OPTIONS": "detect_leaks=1:abort_on_error=0:exitcode=86",
            "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1",
        }
        proc = subprocess.run(
            [str(exe)], capture_output=True, text=True, check=False, env=env, timeout=300
        )
        if proc.returncode or proc.stderr.strip():
            report.failures.append(
                f"{tag}: driver exited {proc.returncode}; sanitizer output:\n{proc.stderr[-4000:]}"
            )
            continue
        lines = proc.stdout.splitlines()
        report.calls[tag] = (
            int(lines[-1].split()[1]) if lines and lines[-1].startswith("calls") else 0
        )
        dtype = np.float32 if single else np.float64
        report.failures += [
            f"{tag}: {f}" for f in judge(lines, models, strict, dtype, mu_map_table)
        ]
    return report


def judge(
    lines: Sequence[str],
    models: Sequence[CheckedModel],
    strict: Mapping[str, Mapping[str, list[frozenset[int]]]],
    dtype: type,
    mu_map_table: np.ndarray | None = None,
) -> list[str]:
    """Every violation of the rules (module docstring) in the driver's output ``lines``."""
    failures: list[str] = []
    by_name = {m.model.name: m for m in models}
    bases = {m.model.name: base_points(m) for m in models}
    seen = {"E": 0, "L": 0, "V": 0, "M": 0}
    specials = special_values(dtype)
    for line in lines:
        kind, *fields = line.split()
        if kind == "calls":
            continue
        seen[kind] += 1
        if kind == "M":
            failures += _judge_mu_map(fields, mu_map_table)
            continue
        name, b, target, code = fields[0], int(fields[1]), int(fields[2]), int(fields[3])
        m = by_name[name]
        model = m.model
        nx, nu, npar = len(model.states), len(model.inputs), len(model.parameters)
        h_index = nx + nu + npar
        what = f"{name} base {b}, " + (
            "unmodified"
            if target == -1
            else f"{'all arguments' if target == -2 else _argument(model, target)} = "
            f"{SPECIAL_NAMES[code]}"
        )
        if kind == "E":
            fn, got = fields[4], fields[5]
            if target == -1:
                if set(got) - {"f", "-"}:
                    failures.append(f"{what}: {fn} not finite at the nominal point: {got}")
                continue
            if fn == "rk4_step":
                must = rk4_nan_entries(strict[name]["rhs"], nx, -1 if target == h_index else target)
            elif target == h_index:
                must = set()
            else:
                must = {k for k, deps in enumerate(strict[name][fn]) if target in deps}
            hidden = sorted(k for k in must if got[k] != "n")
            if hidden:
                failures.append(f"{what}: {fn} entries {hidden} not NaN: {got}")
        elif kind == "L":
            status, got, untouched = int(fields[4]), fields[5], fields[6] == "1"
            if status == STATUS["OK"]:
                if set(got) != {"f"} or untouched:
                    failures.append(f"{what}: implicit step OK with x_next {got}")
            elif status in (STATUS["ERR_NONFINITE"], STATUS["ERR_SINGULAR"]):
                if not untouched:
                    failures.append(f"{what}: implicit step error {status} wrote x_next")
            else:
                failures.append(f"{what}: implicit step returned {status}")
            nonfinite = code in (NAN, POS_INF, NEG_INF)
            must_fail = False
            if target == -1:
                must_ok = b == 0
                if must_ok and status != STATUS["OK"]:
                    failures.append(f"{what}: implicit step returned {status} at the nominal point")
            elif nonfinite and (target == -2 or target < nx + nu or target == h_index):
                must_fail = True
            elif code == NAN:
                deps = set().union(*strict[name]["rhs"], *strict[name]["jac_x"])
                must_fail = target in deps
            if must_fail and status != STATUS["ERR_NONFINITE"]:
                failures.append(f"{what}: implicit step returned {status}, not ERR_NONFINITE")
        elif kind == "V":
            status, bad = int(fields[4]), int(fields[5])
            values = bases[name][b][nx + nu : nx + nu + npar].copy()
            if target == -2:
                values[:] = specials[code]
            elif target >= 0:
                values[target - nx - nu] = specials[code]
            bounds = [m.bounds.get(v.name, (None, None)) for v in model.parameters]
            want = expected_validate(values, bounds, dtype)
            if npar == 0:
                want = (STATUS["OK"], -1)
            if (status, bad) != want:
                failures.append(f"{what}: params_validate gave {(status, bad)}, expected {want}")
    for kind, count in seen.items():
        if kind == "M" and mu_map_table is None:
            continue
        if count == 0:
            failures.append(f"the driver printed no {kind} line")
    return failures


def _argument(model: Model, index: int) -> str:
    names = [
        *(f"x[{v.name}]" for v in model.states),
        *(f"u[{v.name}]" for v in model.inputs),
        *(f"p->{v.name}" for v in model.parameters),
        "h",
    ]
    return names[index]


def _judge_mu_map(fields: Sequence[str], table: np.ndarray | None) -> list[str]:
    target, code, got, value = int(fields[0]), int(fields[1]), fields[2], float.fromhex(fields[3])
    if target == -1:
        what = "mu_map at the nominal point"
    else:
        what = f"mu_map({'all' if target == -2 else ('p_N', 'T_oil', 'dw')[target]} = "
        what += f"{SPECIAL_NAMES[code]})"
    if code == NAN and target != -1:
        return [] if got == "n" else [f"{what} = {value}, not NaN"]
    assert table is not None
    lo, hi = float(table.min()), float(table.max())
    if not (got == "f" and lo * (1 - 1e-6) <= value <= hi * (1 + 1e-6)):
        return [f"{what} = {value}, outside the table's range [{lo}, {hi}]"]
    return []


# ---------------------------------------------------------------------------------------------
# CasADi
# ---------------------------------------------------------------------------------------------


def casadi_failures(
    module: ModuleType, m: CheckedModel, strict: Mapping[str, list[frozenset[int]]] | None = None
) -> list[str]:
    """The NaN contract for an emitted CasADi module: finite at the nominal base point, and with
    one NaN argument entry at a time NaN in every entry strict in it (as for the C)."""
    model = m.model
    strict = strict if strict is not None else strict_entries(model)
    nx, nu = len(model.states), len(model.inputs)
    n = nx + nu + len(model.parameters)
    points = np.tile(base_points(m)[0][:n], (n + 1, 1))
    for target in range(n):
        points[target + 1, target] = np.nan
    values = c_check.casadi_values(
        module, points[:, :nx], points[:, nx : nx + nu], points[:, nx + nu :]
    )
    failures = []
    for fn in EXPRESSION_FUNCTIONS:
        nominal = values[fn][0]
        if not np.all(np.isfinite(nominal)):
            failures.append(f"{model.name} CasADi {fn}: not finite at the nominal point")
        for target in range(n):
            got = values[fn][target + 1]
            must = [k for k, deps in enumerate(strict[fn]) if target in deps]
            hidden = [k for k in must if not np.isnan(got[k])]
            if hidden:
                failures.append(
                    f"{model.name} CasADi {fn}, {_argument(model, target)} = nan: entries "
                    f"{hidden} not NaN"
                )
    return failures


def casadi_mu_map_failures(module: ModuleType, mu_map: MuMap) -> list[str]:
    """The emitted CasADi μ map: NaN in any argument gives NaN, ±inf and extreme values give a
    value within the table's range (as for the C)."""
    nominal = [float(np.mean(a[[0, -1]])) for a in mu_map.grid]
    lo, hi = float(mu_map.table.min()), float(mu_map.table.max())
    specials = special_values(np.float64)
    fn = module.function()
    failures = []
    for target in range(3):
        for code, value in enumerate(specials):
            args = list(nominal)
            args[target] = value
            mu = float(fn(*args))
            what = f"CasADi mu_map({('p_N', 'T_oil', 'dw')[target]} = {SPECIAL_NAMES[code]})"
            if code == NAN:
                if not np.isnan(mu):
                    failures.append(f"{what} = {mu}, not NaN")
            elif not lo * (1 - 1e-12) <= mu <= hi * (1 + 1e-12):
                failures.append(f"{what} = {mu}, outside [{lo}, {hi}]")
            if code == NAN and not np.isnan(module.mu_map(*args)):
                failures.append(f"{what}: numbers in, not NaN out")
    return failures
