"""The emitted EKF's unrolled predict and constant-H update (gearsym_ekf_2_3.c, thesis 4.3).

Expected values: the structure derived by hand from the 2-3 model (states omega_1, omega_2,
phi, omega_C, m_veh, mu_38, mu_05, zeta; the rows of ∂f/∂z of the four parameters are zero, the
outputs are omega_1, omega_2, omega_C), the operators counted in the emitted C text (an
independent count of what the header states), and the NumPy reference filter for the dense
Jacobian layout (the sparse layout is tests/test_ekf_c.py).
"""

from __future__ import annotations

import ctypes
import re

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.codegen import emit_all
from gearsym.symbolic.codegen.c.ekf_code import output_selection
from gearsym.symbolic.export.generate import ekf_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec

PREFIX = "gearsym_ekf_2_3_"


@pytest.fixture(scope="module")
def emitted():
    d = load_description()
    m = ekf_model(d, shift_spec(d, "2-3"))
    return d, m, emit_all(m.model, m.config)


def _body(source: str, function: str) -> str:
    start = source.index(f"{PREFIX}{function}(\n")
    start = source.index("{\n", start)
    return source[start : source.index("\n}\n", start)]


def _doc(header: str, function: str) -> str:
    at = header.index(f"{PREFIX}{function}(")
    comment = header[header.rindex("/**", 0, at) : at]
    return " ".join(comment.replace("*", " ").split())


def test_predict_structure_follows_the_zero_parameter_rows(emitted):
    _, _, files = emitted
    body = _body(files["gearsym_ekf_2_3.c"], "ekf_predict")
    # ∂f/∂z: 17 nonzeros in rows 0..3 (columns 1..3 among the states, m_veh, mu, zeta); by hand
    # J K1 fills rows 0..3 x columns 1..7, so F - I has 28 entries and A = F[R, :] P 4 rows
    assert "gearsym_real F[28];" in body
    assert "gearsym_real A[32];" in body
    assert "R = {0, 1, 2, 3}" in body
    # f and J inlined: no call inside the step
    code = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    assert not re.search(r"\b\w+\((x|stage), u, p\b", code)
    assert "_rhs(" not in body and "_jac_x" not in body
    # no dense loop over k: the products are unrolled
    assert "for (k = 0" not in body
    # the parameter block P[4..7, 4..7] is untouched but for the rate on its diagonal and the
    # copy of its upper triangle to the lower one (exact symmetry)
    for j1 in range(4, 8):
        for j2 in range(4, 8):
            writes = re.findall(rf"\bP\[{j1 + 8 * j2}\] (\+?= [^;]*);", body)
            if j1 == j2:
                expected = [f"+= h * rate[{j1}]"]
            elif j1 > j2:
                expected = [f"= P[{j2 + 8 * j1}]"]
            else:
                expected = []
            assert writes == expected, (j1, j2, writes)


def test_predict_computes_the_entries_free_of_the_moving_states_once(emitted):
    """By hand from the 2-3 model: only omega_1, omega_2, phi, omega_C move within a step (the
    four parameters' right-hand sides are 0), and of ∂f/∂z only the wheel row's entries in
    omega_C (drag), m_veh (1/(I_wheel + c m_veh) times the moving numerator) and zeta
    (cos zeta omega_C) depend on them: those three are evaluated in each stage, the other 14
    once per step."""
    _, m, files = emitted
    body = _body(files["gearsym_ekf_2_3.c"], "ekf_predict")
    jac = m.model.rhs.jacobian(m.model.state_symbols)
    entries = [(i, j) for j in range(8) for i in range(8) if jac[i, j] != 0]
    assert len(entries) == 17
    moving_entries = {entries.index(e) for e in ((3, 3), (3, 4), (3, 7))}
    once = {int(k) for k in re.findall(r"^    j1\[(\d+)\] = ", body, flags=re.M)}
    staged = [int(k) for k in re.findall(r"^        j(?:1|s)\[(\d+)\] = ", body, flags=re.M)]
    assert once == set(range(17)) - moving_entries
    assert sorted(staged) == sorted(list(moving_entries) * 4)
    # the four stages: one block each, the moving rows of f written in each
    assert body.count("const gearsym_real *const xs = ") == 4
    for s in range(4):
        assert sorted(re.findall(rf"slopes\[{s}\]\[(\d)\] = ", body)) == ["0", "1", "2", "3"]
    # sin and cos of zeta (not moving) once per step, not per stage
    assert body.count("GEARSYM_SIN(") == 1 and body.count("GEARSYM_COS(") == 1


def _own_and_fused(body: str) -> tuple[str, str]:
    """The predict's own statements and the printer's (the fused f and J: the temporaries
    computed once, the J entries stored once, the four stage blocks)."""
    text = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    own, fused, depth = [], [], 0
    for line in text.splitlines()[1:]:  # after the function's opening brace
        stripped = line.strip()
        if stripped == "{":
            depth += 1
        elif stripped == "}" and depth:
            depth -= 1
        elif depth or re.match(r"(const gearsym_real h[cpq]\d+|j1\[\d+\]) = ", stripped):
            fused.append(stripped)
        else:
            own.append(stripped)
    return "\n".join(own), "\n".join(fused)


def test_predict_states_the_operations_its_code_performs(emitted):
    _, _, files = emitted
    body = _body(files["gearsym_ekf_2_3.c"], "ekf_predict")
    own, fused = _own_and_fused(body)
    # the predict's own statements: binary operators written with spaces
    adds = len(re.findall(r" \+ |\+= ", own))
    muls = len(re.findall(r" \* ", own))
    compares = len(re.findall(r" > GEARSYM_LIT\(0\.5\)| < GEARSYM_LIT\(-0\.5\)", own))
    doc = _doc(files["gearsym_ekf_2_3.h"], "ekf_predict")
    stated = re.search(r"\); (\d+) add, (\d+) mul, 0 div, 0 calls, (\d+) cmp for the stage", doc)
    assert stated is not None, doc
    assert (adds, muls, compares) == tuple(int(v) for v in stated.groups())
    # the printed f and J (operators without spaces, constant quotients folded): the stated
    # once + 4 x per stage
    folded = re.sub(r"GEARSYM_LIT\([^)]*\)/GEARSYM_LIT\([^)]*\)", "c", fused)
    folded = folded.replace("*const xs", "")
    counted = (
        len(re.findall(r" [+-] ", folded)),
        folded.count("*"),
        folded.count("/"),
        len(re.findall(r"GEARSYM_(?:SIN|COS)\(", folded)),
    )
    once = re.search(r"once \((\d+) add, (\d+) mul, (\d+) div, (\d+) calls", doc)
    stage = re.search(r"4 stages \((\d+) add, (\d+) mul, (\d+) div, (\d+) calls", doc)
    assert once is not None and stage is not None, doc
    expected = tuple(
        int(a) + 4 * int(b) for a, b in zip(once.groups(), stage.groups(), strict=True)
    )
    assert counted == expected
    total = re.search(r"Operations: (\d+) add, (\d+) mul, (\d+) div", doc)
    assert total is not None
    assert int(total.group(1)) == adds + expected[0]
    assert int(total.group(2)) == muls + expected[1]


def test_update_uses_the_outputs_as_a_selection(emitted):
    _, m, files = emitted
    # outputs omega_1, omega_2, omega_C: states 0, 1, 3
    assert "measured[GEARSYM_EKF_2_3_NY] = { 0, 1, 3 }" in files["gearsym_ekf_2_3.c"]
    body = _body(files["gearsym_ekf_2_3.c"], "ekf_update")
    assert "jac_outputs" not in body
    x, y = sp.symbols("x y", real=True)
    assert output_selection(sp.Matrix([[0, 1], [1, 0]])) == (1, 0)
    assert output_selection(sp.Matrix([[0, 2]])) is None
    assert output_selection(sp.Matrix([[1, 1]])) is None
    assert output_selection(sp.Matrix([[x, 0]])) is None
    # per output, by hand: R 2 mul; s 1 add; 1/s 1 div; w = v/s 8 mul; innovation 1 add;
    # x 8 mul + 8 add; 36 upper-triangle entries P - v w^T 1 mul + 1 add; NIS 2 mul + 1 add;
    # compares: isfinite(y), y < 0, level < floor, s > 0, isfinite(s); once per call the 2
    # frozen flags (two compares each: a slide flag of +1 or -1 slides)
    doc = _doc(files["gearsym_ekf_2_3.h"], "ekf_update")
    per = {"add": 1 + 1 + 8 + 36 + 1, "mul": 2 + 8 + 8 + 36 + 2, "div": 1, "cmp": 5}
    expected = f"{3 * per['add']} add, {3 * per['mul']} mul, {3 * per['div']} div, 0 calls, "
    assert f"Operations: {expected}{3 * per['cmp'] + 4} cmp" in doc
    # the frozen condition is written once, one flag per frozen state
    assert body.count("frozen[5] = ") == 1 and body.count("frozen[6] = ") == 1
    assert body.count("GEARSYM_LIT(0.5)") == 2


def test_dense_layout_predict_equals_the_reference(emitted, tmp_path):
    """The predict unrolled over the dense jac_x (Sparsity("dense")) against the NumPy
    reference (CasADi's chain rule, dense F P F^T) at random symmetric P."""
    import dataclasses

    from gearsym.symbolic.codegen import config as cfg

    d, m, _ = emitted
    config = dataclasses.replace(m.config, sparsity=cfg.Sparsity("dense"))
    files = {k: v for k, v in emit_all(m.model, config).items() if not k.endswith(".py")}
    assert "_jac_x(" not in _body(files["gearsym_ekf_2_3.c"], "ekf_predict")

    def cases(n, _inputs):
        rng = np.random.default_rng(11)
        z0 = np.array([194.89, 60.09, 0.0578, 24.34, 1500.0, 0.12, 0.1, 0.01])
        sigma = np.array([1.95, 0.6, 0.05, 0.25, 300.0, 0.03, 0.03, 0.05])
        for u in (
            [80.0, 3000.0, 2000.0, 1.0, 0.0, 1.0, 0.0],
            [50.0, 0.0, 5000.0, 0.0, 0.0, 1.0, 0.0],
        ):
            for _ in range(5):
                z = z0 * (1 + 0.05 * rng.normal(size=n))
                C = np.corrcoef(rng.normal(size=(n, 3 * n)))
                yield z, C * np.outer(sigma, sigma), u

    _predict_matches_the_reference(files, d, "2-3", cases, tmp_path)


def test_joseph_update_form_equals_the_reference(emitted, tmp_path):
    """``update_form="joseph"`` (the expanded Joseph form, selectable) against the NumPy
    reference's Joseph update at random symmetric P, with frozen μ states; and an unknown form
    is refused."""
    import dataclasses

    from gearsym.symbolic.codegen.config import EkfLayout

    with pytest.raises(ValueError, match="update_form"):
        EkfLayout(update_form="ud")
    d, m, _ = emitted
    config = dataclasses.replace(
        m.config, ekf=dataclasses.replace(m.config.ekf, update_form="joseph")
    )
    files = {k: v for k, v in emit_all(m.model, config).items() if not k.endswith(".py")}
    assert "Joseph form expanded" in files["gearsym_ekf_2_3.c"]
    _update_matches_the_reference(
        files,
        d,
        "2-3",
        tmp_path,
        z0=np.array([194.89, 60.09, 0.0578, 24.34, 1500.0, 0.12, 0.1, 0.01]),
        floor=np.array([2.0, 0.7, 0.27]),
        sigma=np.array([1.95, 0.6, 0.05, 0.25, 300.0, 0.03, 0.03, 0.05]),
        seed=12,
        inputs=(
            [80.0, 3000.0, 2000.0, 1.0, 0.0, 1.0, 0.0],
            [50.0, 0.0, 5000.0, 0.0, 0.0, 1.0, 0.0],
        ),
    )


def test_constant_output_map_update_equals_the_reference(tmp_path):
    """The 3-4's filter measures shaft 8, whose speed the model eliminates: its row of H is a
    constant combination of omega_1 and omega_2 (not a selection). Its update takes v = P h^T
    over the nonzeros of H (no jac_outputs, no dense product): against the NumPy reference's
    Joseph update at random symmetric P with the μ states frozen or not, to 1e-12, P exactly
    symmetric; its stated operations are those counted by hand."""
    from gearsym.symbolic.codegen.c.ekf_code import output_rows, output_selection

    d = load_description()
    m = ekf_model(d, shift_spec(d, "3-4"))
    files = {k: v for k, v in emit_all(m.model, m.config).items() if not k.endswith(".py")}
    prefix = "gearsym_ekf_3_4_"
    source, header = files["gearsym_ekf_3_4.c"], files["gearsym_ekf_3_4.h"]
    start = source.index(f"{prefix}ekf_update(\n")
    body = source[start : source.index("\n}\n", start)]
    assert "jac_outputs" not in body and "h_coef" in body
    # outputs omega_1, omega_2, omega_8 = a omega_1 + b omega_2, omega_C: 1 + 1 + 2 + 1 nonzeros
    assert "h_start[GEARSYM_EKF_3_4_NY + 1] = { 0, 1, 2, 4, 5 }" in body
    assert "h_state[5] = { 0, 1, 0, 1, 3 }" in body
    x, y = sp.symbols("x y", real=True)
    rows = output_rows(sp.Matrix([[1, 0, 0], [sp.Rational(1, 3), 2, 0]]))
    assert rows == (((0, 1),), ((0, sp.Rational(1, 3)), (1, 2)))
    assert output_rows(sp.Matrix([[x, 1]])) is None
    assert output_rows(sp.Matrix([[0, 0], [1, 0]])) == ((), ((0, 1),))
    assert output_rows(sp.Matrix([[0, 0]])) is None
    assert output_selection(sp.Matrix([[sp.Rational(1, 3), 2]])) is None
    # by hand, per output as the selection update (add 1+1+8+36+1, mul 2+8+8+36+2, 1 div, 5
    # cmp) plus, per row of k nonzeros, v = P h^T (8 k mul, 8 (k - 1) add) and s (k mul, k add,
    # where the selection's s = v[m] + R has the 1 add counted above, so k - 1 more)
    per_add, per_mul = 1 + 1 + 8 + 36 + 1, 2 + 8 + 8 + 36 + 2
    sizes = (1, 1, 2, 1)
    # and the outputs at every output: omega_8's combination, 1 add and 2 mul
    add = 4 * (per_add + 1) + sum(8 * (k - 1) + k - 1 for k in sizes)
    mul = 4 * (per_mul + 2) + sum(8 * k + k for k in sizes)
    start = header.index(f"{prefix}ekf_update(")
    doc = " ".join(header[header.rindex("/**", 0, start) : start].replace("*", " ").split())
    assert f"Operations: {add} add, {mul} mul, 4 div, 0 calls, {4 * 5 + 4} cmp" in doc

    _update_matches_the_reference(
        files,
        d,
        "3-4",
        tmp_path,
        z0=np.array([150.0, 80.0, 0.05, 30.0, 1700.0, 0.12, 0.11, 0.01]),
        floor=np.array([2.0, 0.7, 0.7, 0.27]),
    )


def test_an_output_no_state_moves_leaves_the_filter_alone(tmp_path):
    """The 8-9's filter measures shaft 8, which both gears hold still: its row of H is zero.
    The constant-H update skips its products (v = 0: x and P stay) and still counts its NIS
    term, as the NumPy reference's Joseph update does; the stated operations by hand."""
    from gearsym.symbolic.estimators.ekf import augmented_model

    d = load_description()
    assert "omega_8" in augmented_model(d, "8-9").output_names[2]
    m = ekf_model(d, shift_spec(d, "8-9"))
    files = {k: v for k, v in emit_all(m.model, m.config).items() if not k.endswith(".py")}
    source, header = files["gearsym_ekf_8_9.c"], files["gearsym_ekf_8_9.h"]
    assert "h_start[GEARSYM_EKF_8_9_NY + 1] = { 0, 1, 2, 2, 3 }" in source
    assert "h_i = 0 (a shaft this shift holds still)" in source
    # three unit rows as the selection update (add 47, mul 56 each) plus v = P h^T (8 mul) and
    # s (1 mul) each; the zero row: R 2 mul, innovation 1 add, nu^2/R 1 mul + 1 div + 1 add,
    # 5 compares; the frozen flags 4 compares
    start = header.index("gearsym_ekf_8_9_ekf_update(")
    doc = " ".join(header[header.rindex("/**", 0, start) : start].replace("*", " ").split())
    assert "Operations: 143 add, 198 mul, 4 div, 0 calls, 24 cmp" in doc
    _update_matches_the_reference(
        files,
        d,
        "8-9",
        tmp_path,
        z0=np.array([190.0, 270.0, 0.05, 110.0, 1700.0, 0.12, 0.11, 0.01]),
        floor=np.array([2.0, 2.7, 0.5, 1.1]),
    )


def _update_matches_the_reference(
    files,
    d,
    shift: str,
    tmp_path,
    z0,
    floor,
    sigma=None,
    seed: int = 34,
    inputs=([80.0, 3000.0, 2000.0, 1.0, 0.0, 1.0, 0.0], [50.0, 0.0, 5000.0, 0.0, 1.0, 0.0, 0.0]),
) -> None:
    """The emitted ``ekf_update`` of ``shift`` (double) against the NumPy reference's Joseph
    update at random states near ``z0`` (spread ``sigma``) and random symmetric P, under each
    of ``inputs`` (the μ states frozen or not): x and P to 1e-12, the same outputs used, P
    exactly symmetric."""
    from gearsym.symbolic.estimators.ekf import ekf_update

    prefix = f"gearsym_ekf_{shift.replace('-', '_')}_"
    lib, discrete, p, params = _compiled_filter(files, d, shift, tmp_path)
    n = len(discrete.aug.state_names)
    ptr = ctypes.POINTER(ctypes.c_double)
    fn = lib[f"{prefix}ekf_update"]
    fn.restype = ctypes.c_int
    rng = np.random.default_rng(seed)
    if sigma is None:
        sigma = np.array([1.5, 0.8, 0.05, 0.3, 300.0, 0.03, 0.03, 0.05])
    r = np.array([0.01] * len(floor))
    for u in inputs:
        for _ in range(5):
            z = z0 * (1 + 0.05 * rng.normal(size=n))
            C = np.corrcoef(rng.normal(size=(n, 3 * n)))
            P = 0.5 * (C + C.T) * np.outer(sigma, sigma)  # corrcoef is symmetric to rounding
            y_true = discrete.outputs(z, u, p)[0]
            y_meas = y_true * (1 + 0.01 * rng.normal(size=len(floor)))
            z_ref, P_ref, _, used = ekf_update(discrete, z, P, u, y_meas, p, r, floor)
            x_c, P_c, nis = z.copy(), P.ravel(order="F").copy(), ctypes.c_double(0.0)
            count = fn(
                x_c.ctypes.data_as(ptr),
                P_c.ctypes.data_as(ptr),
                np.array(u).ctypes.data_as(ptr),
                ctypes.byref(params),
                y_meas.ctypes.data_as(ptr),
                r.ctypes.data_as(ptr),
                floor.ctypes.data_as(ptr),
                ctypes.byref(nis),
            )
            assert count == used == len(floor)
            P_c = P_c.reshape(n, n, order="F")
            s = np.sqrt(np.diag(P_ref))
            assert np.max(np.abs(x_c - z_ref) / (np.abs(z_ref) + s)) < 1e-12
            assert np.max(np.abs(P_c - P_ref) / np.outer(s, s)) < 1e-12
            assert np.array_equal(P_c, P_c.T)


@pytest.mark.parametrize("shift", ["1-2", "8-9"])
def test_fused_predict_of_other_shifts_equals_the_reference(shift, tmp_path):
    """The fused predict is decided from the expressions' free symbols, not from the 2-3: the
    EKF of other shifts against the NumPy reference's predict (CasADi's chain rule, dense
    F P F^T) at random states, inputs and symmetric P, to 1e-12."""
    d = load_description()
    m = ekf_model(d, shift_spec(d, shift))
    files = {k: v for k, v in emit_all(m.model, m.config).items() if not k.endswith(".py")}

    def cases(n, inputs):
        rng = np.random.default_rng(1)
        z0 = np.array([100.0, 50.0, 0.05, 20.0, 1500.0, 0.12, 0.1, 0.01])[:n]
        for _ in range(5):
            z = z0 * (1 + 0.05 * rng.normal(size=n))
            sigma = np.abs(z) * 0.05 + 0.01
            P = np.corrcoef(rng.normal(size=(n, 3 * n))) * np.outer(sigma, sigma)
            u = np.abs(rng.normal(size=len(inputs))) * 100.0
            for k, name in enumerate(inputs):
                if name.startswith(("slide_", "stick_")):
                    u[k] = float(rng.integers(0, 2))
            yield z, P, u

    _predict_matches_the_reference(files, d, shift, cases, tmp_path)


def _predict_matches_the_reference(files: dict[str, str], d, shift: str, cases, tmp_path) -> None:
    """Compile ``files`` (double), run the emitted ``ekf_predict`` of ``shift`` on each
    ``(z, P, u)`` of ``cases(n, input_names)`` and compare with the NumPy reference's predict
    (CasADi's chain rule, dense F P F^T) to 1e-12; P must come out exactly symmetric."""
    from gearsym.symbolic.estimators.ekf import ekf_predict

    lib, discrete, p, params = _compiled_filter(files, d, shift, tmp_path)
    aug = discrete.aug
    q = np.array([aug.intensities[n] for n in aug.state_names])
    n = len(aug.state_names)
    ptr = ctypes.POINTER(ctypes.c_double)
    predict = lib[f"gearsym_ekf_{shift.replace('-', '_')}_ekf_predict"]
    checked = 0
    for z, P, u in cases(n, aug.input_names):
        u = np.asarray(u, dtype=float)
        z_ref, P_ref = ekf_predict(discrete, z, P, u, 0.01, p, q)
        x_c, P_c = z.copy(), P.ravel(order="F").copy()
        predict(
            x_c.ctypes.data_as(ptr),
            P_c.ctypes.data_as(ptr),
            u.ctypes.data_as(ptr),
            ctypes.byref(params),
            ctypes.c_double(0.01),
            q.ctypes.data_as(ptr),
        )
        P_c = P_c.reshape(n, n, order="F")
        s = np.sqrt(np.diag(P_ref))
        assert np.max(np.abs(x_c - z_ref) / (np.abs(z_ref) + s)) < 1e-12
        assert np.max(np.abs(P_c - P_ref) / np.outer(s, s)) < 1e-12
        assert np.array_equal(P_c, P_c.T)
        checked += 1
    assert checked > 0


def _compiled_filter(files: dict[str, str], d, shift: str, tmp_path):
    """The emitted filter compiled in double, the library's discrete model of ``shift``, its
    parameter values and them as the emitted parameter struct."""
    from gearsym.symbolic.estimators.ekf import DiscreteModel, augmented_model
    from gearsym.validation.checks.c_check import compile_shared

    lib = ctypes.CDLL(str(compile_shared(files, tmp_path, single=False)))
    discrete = DiscreteModel(augmented_model(d, shift))
    p = discrete.aug.parameter_values()
    Params = type(
        "Params",
        (ctypes.Structure,),
        {"_fields_": [(f"p{i}", ctypes.c_double) for i in range(len(p))]},
    )
    return lib, discrete, p, Params(*p)
