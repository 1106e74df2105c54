"""Tests of the code-generation core: symbolic/codegen.py, templates/, validation/checks/c_check.py.

Three hand-written models exercise it: a damped pendulum (sin, cos), a LuGre-type friction model
(Piecewise, sign, Abs, exp, Min/Max, Heaviside, a compound cube) and a 4-state stiff linear
chain with a matrix-exponential solution. Each is emitted, compiled in double and single
precision with the strict flags and loaded once per module (fixture ``built``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any
from unittest import mock

import jinja2
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
import sympy as sp
from gearsym.symbolic import codegen
from gearsym.symbolic.model import Model, Variable
from gearsym.validation.checks import c_check

REPO = Path(__file__).resolve().parents[1]
V = Variable

# ---------------------------------------------------------------------------------------------
# Models
# ---------------------------------------------------------------------------------------------


def pendulum_model() -> Model:
    """Damped pendulum driven by a torque: sin/cos, divisions, integer powers."""
    th, om, tau, g, l, m, d = sp.symbols("theta omega tau g l m d")
    rhs = sp.Matrix([om, -(g / l) * sp.sin(th) - d / (m * l**2) * om + tau / (m * l**2)])
    energy = m * l**2 * om**2 / 2 + m * g * l * (1 - sp.cos(th))
    return Model(
        "pendulum",
        (V("theta", th, "rad"), V("omega", om, "rad/s")),
        (V("tau", tau, "N·m", "drive torque"),),
        (
            V("g", g, "m/s²", default=9.81, source="assumed"),
            V("l", l, "m", default=0.7, source="assumed"),
            V("m", m, "kg", default=1.3, source="assumed"),
            V("d", d, "N·m·s/rad", default=0.05, source="assumed"),
        ),
        (V("angle", sp.Symbol("y_angle"), "rad"), V("energy", sp.Symbol("y_energy"), "J")),
        rhs,
        sp.Matrix([th, energy]),
        {"purpose": "codegen test */ comment-closer must be escaped"},
    )


PENDULUM_BOUNDS = {"g": (0.0, 20.0), "l": (0.01, None), "m": (1e-3, 100.0), "d": (0.0, None)}


def friction_model() -> Model:
    """Slider with LuGre bristle friction, a stick/slip clutch torque and a saturated drive."""
    v, z, th, u, pn = sp.symbols("v z theta u p_N")
    m, s0, s1, s2, fc, fs, vs, veps, mus, muk, tmax, cw = sp.symbols(
        "m sigma0 sigma1 sigma2 F_c F_s v_s v_eps mu_s mu_k T_max c_w"
    )
    g = fc + (fs - fc) * sp.exp(-((v / vs) ** 2))
    zdot = v - s0 * sp.Abs(v) * z / g
    force = s0 * z + s1 * zdot + s2 * v
    clutch = sp.Piecewise((mus * pn * v / veps, sp.Abs(v) < veps), (muk * pn * sp.sign(v), True))
    drive = sp.Min(sp.Max(u, 0), tmax)
    drag = cw * (v + sp.Rational(1, 3) * th) ** 3 / (1 + z**2) ** 2
    rhs = sp.Matrix([(drive - force - clutch - drag) / m, zdot, v])
    outputs = sp.Matrix([force, clutch, sp.sqrt(1 + v**2) * sp.Heaviside(th)])
    params = (
        V("m", m, "kg", default=2.0),
        V("sigma0", s0, "N/m", default=50.0),
        V("sigma1", s1, "N·s/m", default=1.5),
        V("sigma2", s2, "N·s/m", default=0.4),
        V("F_c", fc, "N", default=1.0),
        V("F_s", fs, "N", default=1.5),
        V("v_s", vs, "m/s", default=0.1),
        V("v_eps", veps, "m/s", default=0.05),
        V("mu_s", mus, default=0.14),
        V("mu_k", muk, default=0.12),
        V("T_max", tmax, "N", default=1.2),
        V("c_w", cw, default=0.3),
    )
    return Model(
        "friction",
        (V("v", v, "m/s"), V("z", z, "m"), V("theta", th, "m")),
        (V("u", u, "N"), V("p_N", pn, "bar")),
        params,
        (V("F", sp.Symbol("F")), V("T_c", sp.Symbol("T_c")), V("w", sp.Symbol("w"))),
        rhs,
        outputs,
    )


FRICTION_BOUNDS = {"m": (0.1, 10.0), "sigma0": (1.0, 1e6), "mu_k": (0.0, 0.3)}


def stiff_model() -> Model:
    """Four first-order lags coupled in a chain: dx/dt = A(k, c) x + b u, eigenvalues ~ -k_i."""
    xs = sp.symbols("x1:5")
    ks = sp.symbols("k1:5")
    c, b, u = sp.symbols("c b u")
    a = sp.zeros(4, 4)
    for i in range(4):
        a[i, i] = -ks[i] - c * (2 if 0 < i < 3 else 1)
        if i > 0:
            a[i, i - 1] = c
        if i < 3:
            a[i, i + 1] = c
    params = tuple(
        V(f"k{i + 1}", k, "1/s", default=d)
        for i, (k, d) in enumerate(zip(ks, STIFF_K, strict=True))
    ) + (V("c", c, "1/s", default=0.5), V("b", b, default=1.0))
    return Model(
        "stiff",
        tuple(V(f"x{i + 1}", s) for i, s in enumerate(xs)),
        (V("u", u),),
        params,
        (V("y_sum", sp.Symbol("y_sum")),),
        a * sp.Matrix(xs) + sp.Matrix([0, 0, 0, b * u]),
        sp.Matrix([sum(xs)]),
    )


def coverage_model() -> Model:
    """Every remaining printer path: And/Or conditions shared between outputs (boolean
    temporaries), a Piecewise without default (NaN), atan2, tanh, log, erf, asinh, x**12,
    x**(3/2), 1/sqrt, pi and E, Max of three, Heaviside of a difference; no inputs."""
    x, y, k = sp.symbols("x y k")
    cond = sp.And(x > k, y < 1)
    first = sp.Piecewise((x**12 / 100, cond), (sp.atan2(x, y + 3), sp.Or(x < -1, y > 1)))
    second = (
        sp.tanh(y) * sp.log(1 + x**2)
        + sp.exp(-k * y) * sp.erf(x)
        - sp.pi * sp.sign(x - y)
        + sp.E * sp.Abs(y)
    )
    outputs = sp.Matrix(
        [
            sp.Piecewise((1, cond), (0, True)) + sp.Heaviside(y - k),
            sp.asinh(x) * sp.sqrt(k) / sp.sqrt(1 + y**2) + (1 + x**2) ** sp.Rational(3, 2),
        ]
    )
    return Model(
        "coverage",
        (V("x", x), V("y", y)),
        (),
        (V("k", k, default=0.5),),
        (V("a", sp.Symbol("a")), V("b", sp.Symbol("b"))),
        sp.Matrix([first + sp.Max(x, y, k), second]),
        outputs,
    )


STIFF_K = (1.0, 10.0, 100.0, 2000.0)
STIFF_BOUNDS = {"k1": (0.0, None), "k2": (0.0, None), "k3": (0.0, None), "k4": (0.0, None)}

MODELS: dict[str, tuple[Callable[[], Model], dict[str, tuple[float | None, float | None]]]] = {
    "pendulum": (pendulum_model, PENDULUM_BOUNDS),
    "friction": (friction_model, FRICTION_BOUNDS),
    "stiff": (stiff_model, STIFF_BOUNDS),
    "coverage": (coverage_model, {"k": (0.0, 1.0)}),
}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Any]]:
    """Every model emitted, compiled (double, single) and loaded once."""
    result = {}
    for name, (factory, bounds) in MODELS.items():
        model = factory()
        entry = c_check.build(model, tmp_path_factory.mktemp(name), bounds)
        entry.update(model=model, bounds=bounds, dir=tmp_path_factory.mktemp(f"{name}_analysis"))
        result[name] = entry
    return result


def _defaults(model: Model) -> np.ndarray:
    return np.array([v.default for v in model.parameters], dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# Function table, Jacobians, CSE, printer
# ---------------------------------------------------------------------------------------------


def test_function_table_rows_and_shapes() -> None:
    table = codegen.build_function_table(friction_model(), FRICTION_BOUNDS)
    assert [f.name for f in table] == [
        "rhs",
        "outputs",
        "jac_x_sparse",
        "jac_x",
        "jac_u_sparse",
        "jac_u",
        "jac_p_sparse",
        "jac_p",
        "rk4_step",
        "linearly_implicit_euler_step",
        "params_default",
        "params_validate",
    ]
    assert table["jac_p"].outputs[0].shape == (3, 12)
    assert table["jac_u"].expressions[0].shape == (3, 2)
    pattern = table["jac_p"].pattern
    assert table["jac_p_sparse"].outputs[0].shape == (pattern.nnz, 1)
    assert table["jac_p"].kind == "spread" and table["jac_p"].source == "jac_p_sparse"
    # the config decides the rows: dense layout, explicit step only
    config = codegen.CodegenConfig(
        FRICTION_BOUNDS, integrators=("rk4",), sparsity=codegen.Sparsity("dense")
    )
    names = [f.name for f in codegen.build_function_table(friction_model(), config)]
    assert names == ["rhs", "outputs", "jac_x", "jac_u", "jac_p", "rk4_step", *names[-2:]]
    assert names == codegen.function_names(config)
    assert [a.name for a in table["rk4_step"].args] == ["x", "u", "p", "h"]
    assert table["linearly_implicit_euler_step"].returns == "int"
    assert table.prefix == "gearsym_friction_"


def test_smart_jacobian_differentiates_only_where_the_variable_occurs() -> None:
    table = codegen.build_function_table(friction_model())
    f = table["rhs"].expressions[0]
    wrt = [*table.states, *table.inputs, *table.parameters]
    calls: list[tuple[sp.Basic, sp.Symbol]] = []
    original = codegen.jacobian._partial

    def recording_partial(expr: sp.Basic, symbol: sp.Symbol) -> sp.Basic:
        calls.append((expr, symbol))
        return original(expr, symbol)

    codegen.clear_jacobian_cache()  # the table above computed (and cached) this Jacobian
    with mock.patch.object(codegen.jacobian, "_partial", recording_partial):
        jac = codegen.smart_jacobian(f, wrt)
    assert calls and all(symbol in expr.free_symbols for expr, symbol in calls)
    assert len(calls) < f.shape[0] * len(wrt)  # a dense Jacobian would need one per entry
    for i, expr in enumerate(f):
        for j, var in enumerate(wrt):
            if var not in expr.free_symbols:
                assert jac[i, j] is sp.S.Zero
    reference = f.jacobian(wrt).replace(lambda e: isinstance(e, sp.DiracDelta), lambda e: 0)
    rng = np.random.default_rng(5)
    for _ in range(20):
        point = {s: sp.Float(rng.uniform(0.2, 1.5)) for s in wrt}
        got = np.array(jac.xreplace(point).evalf(), dtype=float)
        want = np.array(reference.xreplace(point).evalf(), dtype=float)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_cse_is_one_pass_with_sequential_temporaries() -> None:
    form = codegen.cse_function(codegen.build_function_table(friction_model())["jac_x_sparse"])
    names = [s.name for s, _ in form.temporaries]
    assert names == [f"t{k}" for k in range(len(names))]
    # The compound cube base (v + theta/3) is computed once and multiplied out.
    assert _cube_base() in [e for _, e in form.temporaries]


def test_shared_products_save_multiplications_and_keep_values() -> None:
    """A constant-symbol pair that three products share is computed once (SymPy's cse never
    shares a constant); every output keeps its value and sign, and the count drops by 2."""
    a, b, c, d, x = sp.symbols("a b c d x", real=True)
    outputs = [3 * a * c + b, -3 * a * d - b, 3 * a * x, sp.sin(x) * b]
    temps, shared = codegen.cse.share_products([], list(outputs))
    assert [e for _, e in temps] == [3 * a]
    definitions = dict(temps)
    assert [o.xreplace(definitions) for o in shared] == outputs
    before = codegen.count_operations(codegen.CseForm((), (sp.ImmutableMatrix(outputs),)))
    after = codegen.count_operations(codegen.CseForm(tuple(temps), (sp.ImmutableMatrix(shared),)))
    assert (before.mul, after.mul) == (7, 5) and before.add == after.add


def test_calls_are_computed_first_unless_conditional() -> None:
    """sin(x), used unconditionally, becomes the first temporary; exp(x) inside a piecewise
    branch stays there (evaluated only when its branch is taken)."""
    a, b, x = sp.symbols("a b x", real=True)
    t0 = sp.Symbol("_t0")
    branch = sp.Piecewise((sp.exp(x), x > 0), (0, True))
    temps, outputs = codegen.cse.schedule_calls([(t0, a + b)], [t0 * sp.sin(x) + branch], 8)
    assert [e for _, e in temps] == [sp.sin(x), a + b]
    assert outputs[0].xreplace(dict(temps)) == (a + b) * sp.sin(x) + branch
    assert outputs[0].has(sp.exp(x)) and not outputs[0].has(sp.sin(x))


def _cube_base() -> sp.Expr:
    v, th = sp.Symbol("v", real=True), sp.Symbol("theta", real=True)
    return v + th / 3


def _c_print(expr: sp.Expr, symbols: dict[sp.Symbol, str]) -> tuple[str, Any]:
    printer = codegen.GearsymCPrinter(symbols, "gearsym_t_")
    return printer.doprint(expr), printer


def test_c_printer_rules() -> None:
    x, y = sp.symbols("x y", real=True)
    names = {x: "x[0]", y: "p->y"}
    assert _c_print(x**3, names)[0] == "(x[0]*x[0]*x[0])"
    assert _c_print(y / x**2, names)[0] == "p->y/(x[0]*x[0])"
    assert "GEARSYM_POW" in _c_print(x**12, names)[0]
    assert _c_print(x / 3, names)[0] == "(GEARSYM_LIT(1.0)/GEARSYM_LIT(3.0))*x[0]"
    assert _c_print(sp.Rational(-2, 7), names)[0] == "-(GEARSYM_LIT(2.0)/GEARSYM_LIT(7.0))"
    assert _c_print(sp.sqrt(x), names)[0] == "GEARSYM_SQRT(x[0])"
    assert _c_print(sp.pi, names)[0] == "GEARSYM_LIT(3.14159265358979323846)"
    assert _c_print(sp.Float(0.1) * x, names)[0] == "GEARSYM_LIT(0.1)*x[0]"
    text, printer = _c_print(sp.Piecewise((x, x > y), (-x, True)) + sp.sign(y), names)
    # a comparison with NaN is false: the guard keeps a NaN operand from picking a branch
    guarded = (
        "((isnan(x[0]) || isnan(p->y)) ? ((gearsym_real)NAN) : ((x[0] > p->y) ? x[0] : -x[0]))"
    )
    assert guarded in text and "gearsym_t_sign(p->y)" in text
    assert printer.used_helpers == {"sign"}
    text, printer = _c_print(sp.Max(x, y, 0) + sp.Min(x, 1), names)
    assert text.count("gearsym_t_max(") == 2 and text.count("gearsym_t_min(") == 1
    assert "FMAX" not in text and printer.used_helpers == {"max", "min"}
    assert _c_print(sp.Abs(x), names)[0] == "GEARSYM_FABS(x[0])"
    with pytest.raises(NotImplementedError):
        _c_print(sp.Mod(x, y), names)
    with pytest.raises(NotImplementedError):
        _c_print(sp.Function("unknown")(x), names)


def test_op_count_follows_the_printer() -> None:
    x, y = sp.symbols("x y", real=True)
    form = codegen.CseForm((), (sp.ImmutableMatrix([x**3 + x / 3 - sp.sin(y) / (x * y)]),))
    ops = codegen.count_operations(form)
    assert (ops.add, ops.mul, ops.div, dict(ops.calls)) == (2, 4, 1, {"sin": 1})
    assert ops.format() == "2 add, 4 mul, 1 div, 1 call (sin 1)"


def test_names_and_bounds_are_checked() -> None:
    model = pendulum_model()
    bad_param = Model(
        "bad",
        model.states,
        model.inputs,
        (V("int", sp.Symbol("g")), *model.parameters[1:]),
        model.outputs,
        model.rhs,
        model.output_expressions,
    )
    with pytest.raises(ValueError, match="'int'"):
        codegen.emit_c(bad_param)
    bad_name = Model("my-model", *[getattr(model, a) for a in _FIELDS])
    with pytest.raises(ValueError, match="model name"):
        codegen.emit_c(bad_name)
    with pytest.raises(ValueError, match="unknown parameters"):
        codegen.emit_c(model, {"nope": (0.0, 1.0)})
    with pytest.raises(ValueError, match="outside its bounds"):
        codegen.emit_c(model, {"g": (0.0, 1.0)})


_FIELDS = ("states", "inputs", "parameters", "outputs", "rhs", "output_expressions")


def test_render_takes_a_typed_view_and_uses_strict_undefined() -> None:
    @dataclasses.dataclass(frozen=True)
    class Incomplete:
        model_name: str

    with pytest.raises(jinja2.UndefinedError):  # the header needs far more than a name
        codegen.render("c_header.h.j2", Incomplete("m"))
    with pytest.raises(TypeError, match="dataclass view"):
        codegen.render("c_header.h.j2", {"model_name": "m"})


# ---------------------------------------------------------------------------------------------
# Emitted C: strict build, ECU rules, agreement with SymPy
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("precision", ["double", "single"])
def test_c_matches_sympy(built: dict[str, Any], name: str, precision: str) -> None:
    entry = built[name]
    report = c_check.compare_with_sympy(entry["model"], entry[precision], n_points=1000, seed=7)
    print(report)
    assert report.n_points == 1000
    assert report.ok(c_check.TOLERANCE[precision]), str(report)


@pytest.mark.parametrize("name", list(MODELS))
def test_casadi_matches_sympy(built: dict[str, Any], name: str) -> None:
    entry = built[name]
    report = c_check.compare_casadi_with_sympy(entry["model"], entry["casadi"], 1000, seed=8)
    print(report)
    assert report.ok(c_check.TOLERANCE["double"]), str(report)


@pytest.mark.parametrize("name", list(MODELS))
def test_emitted_c_is_ecu_grade(built: dict[str, Any], name: str) -> None:
    entry = built[name]
    c_files = {k: v for k, v in entry["files"].items() if k.endswith((".c", ".h"))}
    text = "\n".join(c_files.values())
    assert not re.search(r"\b(malloc|calloc|realloc|free|alloca)\b", text)
    # File scope holds functions only; any static object would have to be const.
    assert not re.search(r"^static (?!const\b)[^(]*[;=]", text, re.MULTILINE)
    for single in (False, True):
        report = c_check.analyse_object(c_files, entry["dir"], single=single)
        assert report.mutable_objects == []
        assert report.dynamic_stack == []
        assert report.recursive_functions() == []
        assert max(report.stack_bytes.values()) < 1024
        libm = set(report.undefined) - {"memcpy", "memset", "memmove"}
        assert not libm & {"malloc", "calloc", "realloc", "free"}
        if single:  # float build calls only the f-suffixed functions
            assert all(fn.endswith("f") for fn in libm), libm


@pytest.mark.parametrize("name", list(MODELS))
def test_single_build_has_no_double_literals(built: dict[str, Any], name: str) -> None:
    entry = built[name]
    c_files = {k: v for k, v in entry["files"].items() if k.endswith((".c", ".h"))}
    code = c_check.preprocessed_own_lines(c_files, entry["dir"], single=True)
    literals = re.findall(r"(?<![\w.])(?:\d+\.\d*|\.\d+|\d+[eE][-+]?\d+)(?:[eE][-+]?\d+)?\w*", code)
    assert literals and all(lit[-1] in "fF" for lit in literals), literals
    assert "double" not in code
    assert not re.search(r"\b(sin|cos|exp|sqrt|fabs|fmin|fmax|pow)\(", code)


def test_sanitizers_and_nan_contract_on_the_test_models(
    built: dict[str, Any], tmp_path: Path
) -> None:
    """The four test models (Piecewise with and without default, shared And/Or conditions, Min,
    Max of three, sign, Heaviside, no inputs) under ASan/UBSan with NaN, ±inf, ±0, ±huge, ±tiny
    and boundary arguments: see validation/checks/nan_check.py."""
    from gearsym.validation.checks import nan_check

    reason = nan_check.sanitizer_support(build_dir=tmp_path / "probe")
    if reason is not None:
        pytest.skip(reason)
    models, sources = [], {}
    for entry in built.values():
        models.append(nan_check.CheckedModel(entry["model"], entry["bounds"], {}))
        sources.update({k: v for k, v in entry["files"].items() if k.endswith((".c", ".h"))})
    report = nan_check.run(models, sources, tmp_path / "build")
    assert report.ok, "\n".join(report.failures[:50])
    assert report.calls["double"] == report.calls["single"] > 10_000
    for entry in built.values():
        strict = nan_check.strict_entries(entry["model"])
        checked = nan_check.CheckedModel(entry["model"], entry["bounds"], {})
        assert nan_check.casadi_failures(entry["casadi"], checked, strict) == []


def test_conditions_shared_by_cse_become_bool_temporaries(built: dict[str, Any]) -> None:
    """A shared condition is an essentially Boolean temporary (MISRA C:2012 rule 10.3)."""
    source = built["coverage"]["files"]["gearsym_coverage.c"]
    assert re.search(r"const _Bool t\d+ = \(\(p->k < x\[0\]\) && \(x\[1\] < GEARSYM_LIT", source)
    assert "((gearsym_real)NAN)" in source and "GEARSYM_POW(x[0], GEARSYM_LIT(12.0))" in source


def test_header_api_and_op_counts(built: dict[str, Any]) -> None:
    header = built["pendulum"]["files"]["gearsym_pendulum.h"]
    for macro in ("NX 2", "NU 1", "NP 4", "NY 2", "X_omega 1", "ERR_RANGE 2"):
        assert f"#define GEARSYM_PENDULUM_{macro}" in header
    assert "typedef double gearsym_real;" in header and "v##f" in header
    assert "comment-closer must be escaped" in header and "*/ comment" not in header
    prototypes = re.findall(r"^(?:void|int) gearsym_pendulum_(\w+)\(", header, re.MULTILINE)
    assert len(prototypes) == 12 and "jac_x_sparse" in prototypes
    docs = re.findall(r"/\*\*(.*?)\*/", header, re.DOTALL)
    assert len(docs) == 12 and all("Operations" in d for d in docs)
    assert re.search(r"Operations: \d+ add, \d+ mul, \d+ div, 1 call \(sin 1\)", header)


@pytest.mark.parametrize("name", list(MODELS))
def test_sparse_jacobians_hold_the_structural_nonzeros(built: dict[str, Any], name: str) -> None:
    """The compiled pattern of every jac_*_sparse is the set of entries of SymPy's own
    Matrix.jacobian that are not identically 0 (Dirac deltas dropped), the values spread by it
    equal the dense jac_* bit for bit and SymPy at random points, and the header's NNZ macro
    matches. The four models cover every way the dense function is filled: spread (most),
    every entry nonzero (coverage: d/dk), no nonzero (coverage has no inputs)."""
    entry = built[name]
    model = entry["model"]
    _, reference = c_check.reference_matrices(model)
    header = entry["files"][f"gearsym_{name}.h"]
    source = entry["files"][f"gearsym_{name}.c"]
    X, U, P = c_check.sample_points(model, 50, seed=11, bounds=entry["bounds"])
    # exact in float too, so the single build's error is that of its code, not of its inputs
    X, U, P = (a.astype(np.float32).astype(np.float64) for a in (X, U, P))
    values = c_check.evaluate_reference(model, np.hstack([X, U, P]))
    for jacobian in ("jac_x", "jac_u", "jac_p"):
        matrix = reference[jacobian]
        expected = [
            i + j * matrix.rows
            for j in range(matrix.cols)
            for i in range(matrix.rows)
            if matrix[i, j] != 0
        ]
        for precision in ("double", "single"):
            lib = entry[precision]
            pattern = lib.pattern(jacobian)
            assert pattern.positions() == expected, (name, jacobian)
            macro = f"#define GEARSYM_{name.upper()}_{jacobian.upper()}_NNZ {len(expected)} "
            assert macro in header
            computed = []
            for k in range(len(X)):
                spread = lib.evaluate_sparse(jacobian, X[k], U[k], P[k])
                np.testing.assert_array_equal(spread, lib.evaluate(jacobian, X[k], U[k], P[k]))
                computed.append(spread)
            error = c_check.mixed_error(
                np.array(computed).reshape(len(X), -1), values[jacobian], c_check.FLOOR[precision]
            )
            assert error.max(initial=0.0) <= c_check.TOLERANCE[precision], (name, jacobian)
    if name == "coverage":
        assert "the compressed-column order is the dense one" in source  # d/dk: 2 of 2 nonzero
        assert "#define GEARSYM_COVERAGE_JAC_U_NNZ 0 " in header  # no inputs
        assert "gearsym_coverage_jac_u_rowind[1] = {\n    0,\n};" in source


def test_edge_models_compile_strictly(tmp_path: Path) -> None:
    x, k = sp.symbols("x k")
    bare = Model("bare", (V("x", x),), (), (), (), sp.Matrix([-x]), sp.zeros(0, 1))
    unset = Model("unset", (V("x", x),), (), (V("k", k),), (), sp.Matrix([-k * x]), sp.zeros(0, 1))
    for model in (bare, unset):
        files = codegen.emit_c(model)
        for single in (False, True):
            lib = c_check.load_functions(
                c_check.compile_shared(files, tmp_path / model.name, single), model, single
            )
            assert lib.step("rk4_step", [1.0], [], [2.0] if model.parameters else [], 0.1)[0] > 0
    assert np.isnan(lib.params_default()[0])  # no default: NaN, which validation rejects
    assert lib.params_validate([float("nan")]) == (1, 0)


def test_params_validate(built: dict[str, Any]) -> None:
    model = built["pendulum"]["model"]
    for precision in ("double", "single"):
        lib = built["pendulum"][precision]
        p = _defaults(model)
        assert lib.params_validate(p) == (0, -1)
        for bad, status in ((np.nan, 1), (np.inf, 1), (-np.inf, 1), (-1.0, 2), (25.0, 2)):
            q = p.copy()
            q[0] = bad  # g in (0, 20)
            assert lib.params_validate(q) == (status, 0)
        q = p.copy()
        q[1], q[3] = 0.0, np.nan  # l below 0.01 and d NaN: the first one is reported
        assert lib.params_validate(q) == (2, 1)
        q[1] = 1e30  # l has no upper bound
        assert lib.params_validate(q) == (1, 3)


# ---------------------------------------------------------------------------------------------
# Integrators
# ---------------------------------------------------------------------------------------------


def _linear_solution(model: Model, x0: np.ndarray, u: np.ndarray, p: np.ndarray, t: float) -> Any:
    """Closed form of a linear model through the matrix exponential of [[A, B u], [0, 0]]."""
    ref = c_check.evaluate_reference(model, np.concatenate([np.zeros_like(x0), u, p]))
    nx = len(x0)
    a = ref["jac_x"][0].reshape(nx, nx, order="F")
    bu = ref["rhs"][0]  # f(0, u, p) = B u
    m = np.zeros((nx + 1, nx + 1))
    m[:nx, :nx], m[:nx, nx] = a, bu
    return (scipy.linalg.expm(m * t) @ np.append(x0, 1.0))[:nx]


def _order(hs: list[float], errors: list[float]) -> float:
    return float(np.polyfit(np.log(hs), np.log(errors), 1)[0])


def test_rk4_converges_with_order_four(built: dict[str, Any]) -> None:
    hs = [0.1, 0.05, 0.025, 0.0125]
    # Pendulum against a tight DOP853 solution of the SymPy right-hand side.
    model, lib = built["pendulum"]["model"], built["pendulum"]["double"]
    x0, u, p, t_end = np.array([1.0, 0.0]), np.array([0.2]), _defaults(model), 2.0

    def f(_t: float, x: np.ndarray) -> np.ndarray:
        return c_check.evaluate_reference(model, np.concatenate([x, u, p]))["rhs"][0]

    exact = scipy.integrate.solve_ivp(f, (0, t_end), x0, "DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    errors = [np.abs(lib.step("rk4_step", x0, u, p, h, round(t_end / h)) - exact).max() for h in hs]
    assert 3.8 < _order(hs, errors) < 4.2, errors
    # Linear chain (non-stiff parameter set) against its matrix exponential.
    model, lib = built["stiff"]["model"], built["stiff"]["double"]
    x0, u, p = np.array([1.0, -0.5, 0.25, 2.0]), np.array([0.3]), np.array([1, 2, 3, 4, 0.5, 1.0])
    exact = _linear_solution(model, x0, u, p, 1.0)
    errors = [np.abs(lib.step("rk4_step", x0, u, p, h, round(1.0 / h)) - exact).max() for h in hs]
    assert 3.8 < _order(hs, errors) < 4.2, errors


def test_linearly_implicit_euler_is_stable_where_rk4_blows_up(built: dict[str, Any]) -> None:
    model, lib = built["stiff"]["model"], built["stiff"]["double"]
    x0, u, p = np.array([1.0, -0.5, 0.25, 2.0]), np.array([0.3]), _defaults(model)
    h, t_end = 0.01, 0.5  # h * |lambda_max| ~ 20, far outside RK4's stability region (~2.8)
    exact = _linear_solution(model, x0, u, p, t_end)
    with np.errstate(all="ignore"):
        rk4 = lib.step("rk4_step", x0, u, p, h, round(t_end / h))
    assert not np.all(np.isfinite(rk4)) or np.abs(rk4).max() > 1e6
    lie = lib.step("linearly_implicit_euler_step", x0, u, p, h, round(t_end / h))
    assert np.abs(lie - exact).max() < 0.02 * np.abs(x0).max()
    # First order: halving h halves the error.
    hs = [0.02, 0.01, 0.005, 0.0025]
    errors = [
        np.abs(
            lib.step("linearly_implicit_euler_step", x0, u, p, hh, round(t_end / hh)) - exact
        ).max()
        for hh in hs
    ]
    assert 0.9 < _order(hs, errors) < 1.1, errors


def test_linearly_implicit_euler_step_formula_with_pivoting(built: dict[str, Any]) -> None:
    """One step equals x + h (I - h J)^-1 f at random points; the large h makes |h J_21| > 1,
    so partial pivoting must swap rows."""
    model, lib = built["pendulum"]["model"], built["pendulum"]["double"]
    x_all, u_all, p_all = c_check.sample_points(model, 50, seed=3)
    ref = c_check.evaluate_reference(model, np.hstack([x_all, u_all, p_all]))
    h = 2.0
    for k in range(50):
        jac = ref["jac_x"][k].reshape(2, 2, order="F")
        expected = x_all[k] + h * np.linalg.solve(np.eye(2) - h * jac, ref["rhs"][k])
        got = lib.step("linearly_implicit_euler_step", x_all[k], u_all[k], p_all[k], h)
        np.testing.assert_allclose(got, expected, rtol=1e-11, atol=1e-12)


def test_linearly_implicit_euler_refuses_non_finite_arguments(built: dict[str, Any]) -> None:
    """NaN or ±inf in x, u, h or a parameter that f or J depend on: ERR_NONFINITE (1), and
    x_next is not written. The stiff chain's f and J depend on every parameter."""
    model = built["stiff"]["model"]
    x0, u, p, h = np.array([1.0, -0.5, 0.25, 2.0]), np.array([0.3]), _defaults(model), 0.01
    for precision in ("double", "single"):
        lib = built["stiff"][precision]
        status, x_next = lib.step_status("linearly_implicit_euler_step", x0, u, p, h)
        assert status == 0 and np.all(np.isfinite(x_next))
        for bad in (np.nan, np.inf, -np.inf):
            cases = [(x0.copy(), u.copy(), p.copy(), h) for _ in range(4 + 1 + len(p))]
            for k in range(4):
                cases[k][0][k] = bad
            cases[4][1][0] = bad
            for k in range(len(p)):
                cases[5 + k][2][k] = bad
            cases.append((x0, u, p, bad))
            for xc, uc, pc, hc in cases:
                status, x_next = lib.step_status("linearly_implicit_euler_step", xc, uc, pc, hc)
                assert status == 1, (precision, bad, xc, uc, pc, hc)
                assert np.all(x_next == -12345.0)  # untouched


def test_linearly_implicit_euler_reports_a_singular_matrix(built: dict[str, Any]) -> None:
    """The stiff chain is linear, f = A x + b u with A symmetric: with h = 1/lambda for an
    eigenvalue lambda of A, I - h A is singular, and the step must say so (ERR_SINGULAR, 3)
    instead of returning the huge result of a rounding-level pivot. With h moved by 1e-6
    relative, the matrix is regular (condition about 1e9) and the step matches NumPy."""
    model = built["stiff"]["model"]
    x0, u, p = np.array([1.0, -0.5, 0.25, 2.0]), np.array([0.3]), _defaults(model)
    ref = c_check.evaluate_reference(model, np.concatenate([x0, u, p]))
    a = ref["jac_x"][0].reshape(4, 4, order="F")
    f = ref["rhs"][0]
    eigenvalues = np.linalg.eigvalsh(a)  # A is symmetric: real eigenvalues, all negative
    for precision in ("double", "single"):
        lib = built["stiff"][precision]
        for lam in eigenvalues:
            status, x_next = lib.step_status("linearly_implicit_euler_step", x0, u, p, 1 / lam)
            assert status == 3 and np.all(x_next == -12345.0), (precision, lam, x_next)
    lib = built["stiff"]["double"]
    lam = eigenvalues[-1]  # the slowest mode, about -1.5
    h = (1 + 1e-6) / lam
    status, x_next = lib.step_status("linearly_implicit_euler_step", x0, u, p, h)
    expected = x0 + h * np.linalg.solve(np.eye(4) - h * a, f)
    assert status == 0
    np.testing.assert_allclose(x_next, expected, rtol=1e-6)


def test_casadi_integrator_matches_closed_form(built: dict[str, Any]) -> None:
    model, module = built["stiff"]["model"], built["stiff"]["casadi"]
    x0, u, p = np.array([1.0, -0.5, 0.25, 2.0]), np.array([0.3]), _defaults(model)
    result = module.integrator(0.5)(x0=x0, u=u, p=p)
    xf = result["xf"].full().ravel()
    np.testing.assert_allclose(xf, _linear_solution(model, x0, u, p, 0.5), atol=1e-8)
    assert np.allclose(module.parameter_defaults().full().ravel(), p)


# ---------------------------------------------------------------------------------------------
# Determinism
# ---------------------------------------------------------------------------------------------

_DIGEST_SCRIPT = """
import hashlib, importlib.util, sys
spec = importlib.util.spec_from_file_location("gearsym_codegen_models", sys.argv[1])
models = importlib.util.module_from_spec(spec)
spec.loader.exec_module(models)
print(models.emitted_digest())
"""


def emitted_digest() -> str:
    """SHA-256 over the bytes of every emitted file of every test model."""
    digest = hashlib.sha256()
    for name in sorted(MODELS):
        factory, bounds = MODELS[name]
        for file_name, text in sorted(codegen.emit_all(factory(), bounds).items()):
            digest.update(file_name.encode() + b"\0" + text.encode("utf-8") + b"\0")
    return digest.hexdigest()


def test_output_is_byte_identical_across_hash_seeds() -> None:
    procs = []
    for seed in ("0", "4242"):
        env = {**os.environ, "PYTHONHASHSEED": seed, "PYTHONPATH": str(REPO)}
        procs.append(
            subprocess.Popen(
                [sys.executable, "-c", _DIGEST_SCRIPT, __file__],
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    outputs = [proc.communicate(timeout=120) for proc in procs]
    for proc, (_, err) in zip(procs, outputs, strict=True):
        assert proc.returncode == 0, err
    digests = {out.strip() for out, _ in outputs}
    assert digests == {emitted_digest()}
