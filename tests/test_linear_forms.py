"""Linear forms (5.1) of every mode: the full model, each gear, each adjacent shift.

Independent check: A and B equal finite-difference Jacobians of the nonlinear drivetrain model
(:func:`drivetrain_model`, 2.42–2.58) at the linearisation point (ζ = 0, the defaults). There
the road load r_dyn (F_r + F_ad) is the input T_res* (5.2), so the nonlinear model is taken with
f_roll = c_W = 0 (no rolling or aerodynamic part left in it) and T_res* enters the wheel like
the grade torque r_dyn m g sin ζ: ∂f/∂T_res* = (∂f/∂ζ at ζ = 0) / (r_dyn m_veh g).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.drivetrain import adjacent_shifts, drivetrain_model
from gearsym.symbolic.linear_forms import full_linear_form, gear_linear_form, shift_linear_form
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec


@pytest.fixture(scope="module")
def d():
    return load_description()


def nonlinear(d, locked, torque_elements, keep):
    """f(x, u_elements, ζ) of the nonlinear model at the defaults, rolling and aero removed."""
    model = drivetrain_model(d, "check", locked, torque_elements, keep)
    values = {v.symbol: v.default for v in model.parameters if v.name not in ("zeta",)}
    for v in model.parameters:
        if v.name in ("f_roll", "f_R", "c_W"):
            values[v.symbol] = 0.0
    (zeta,) = (v.symbol for v in model.parameters if v.name == "zeta")
    rhs = model.rhs.xreplace(values)
    f = sp.lambdify([model.state_symbols, model.input_symbols, zeta], list(rhs), "numpy")
    return model, lambda x, u, z: np.array(f(x, u, z), dtype=float)


def fd_jacobians(d, form, locked, torque_elements, keep):
    model, f = nonlinear(d, locked, torque_elements, keep)
    rng = np.random.default_rng(3)
    x0 = rng.uniform(-50, 50, len(model.states))
    u0 = rng.uniform(-100, 100, len(model.inputs))
    h = 1e-4
    a = np.column_stack(
        [(f(x0 + h * e, u0, 0.0) - f(x0 - h * e, u0, 0.0)) / (2 * h) for e in np.eye(len(x0))]
    )
    columns = {
        v.name: (f(x0, u0 + h * e, 0.0) - f(x0, u0 - h * e, 0.0)) / (2 * h)
        for v, e in zip(model.inputs, np.eye(len(u0)), strict=True)
    }
    columns["zeta"] = (f(x0, u0, h) - f(x0, u0, -h)) / (2 * h)
    m, r, g = (d.vehicle[k].value for k in ("m_veh", "r_dyn", "g"))
    columns["T_res_star"] = columns["zeta"] / (r * m * g)
    assert [v.name for v in model.states] == form.states
    return a, np.column_stack([columns[name] for name in form.inputs])


def check(d, form, locked, torque_elements, keep):
    a, b = (np.array(m) for m in form.at_defaults())
    a_fd, b_fd = fd_jacobians(d, form, locked, torque_elements, keep)
    np.testing.assert_allclose(a, a_fd, rtol=1e-6, atol=1e-6 * np.abs(a_fd).max())
    np.testing.assert_allclose(b, b_fd, rtol=1e-6, atol=1e-6 * np.abs(b_fd).max())


def test_full_form_has_the_nine_inputs_of_5_3_and_matches_the_jacobians(d):
    form = full_linear_form(d)
    assert form.inputs == [
        "T_In", "T_res_star", "T_K81", "T_K38", "T_B08", "T_B05", "T_B06", "T_K27", "zeta"
    ]  # fmt: skip
    assert form.states == ["omega_1", "omega_2", "omega_3", "omega_8", "phi", "omega_C"]
    elements = tuple(e.name for e in d.shift_elements)
    check(d, form, (), elements, None)


def test_every_adjacent_shift_form_matches_the_jacobians(d):
    for spec in adjacent_shifts(d):
        form = shift_linear_form(d, spec.name)
        elements = sorted(
            (spec.off_going, spec.on_coming), key=[e.name for e in d.shift_elements].index
        )
        assert form.inputs == ["T_In", "T_res_star", *(f"T_{e}" for e in elements), "zeta"]
        check(d, form, spec.locked, (spec.off_going, spec.on_coming), None)


def test_every_gear_form_is_locked_and_matches_the_jacobians(d):
    for gear in (g for g in d.gears if not g.neutral):
        form = gear_linear_form(d, gear.name)
        # locked: one gearbox speed (the output shaft's), the twist and the wheel; no element
        # torque is an input
        assert form.states == ["omega_2", "phi", "omega_C"]
        assert form.inputs == ["T_In", "T_res_star", "zeta"]
        a = np.array(form.at_defaults()[0])
        assert a.shape == (3, 3)
        check(d, form, tuple(gear.closed), (), (d.output_shaft,))


def test_2_3_shift_form_is_the_5_4_5_5_form_with_columns_in_5_3_order(d):
    from gearsym.symbolic.linear_forms import linear_shift_form

    a_old, b_old, x, u = linear_shift_form(d, "2-3")
    form = shift_linear_form(d, "2-3")
    assert form.states == x
    assert sp.simplify(form.A - a_old) == sp.zeros(*a_old.shape)
    for name in u:
        assert sp.simplify(form.B[:, form.inputs.index(name)] - b_old[:, u.index(name)]) == (
            sp.zeros(4, 1)
        )
    assert shift_spec(d, "2-3").locked == ("K81", "B06")


@pytest.mark.parametrize(
    ("args", "inputs"),
    [
        ([], 9),
        (["--shift", "2-3"], 5),
        (["--gear", "3"], 3),
    ],
)
def test_model_json_prints_the_linear_form(args, inputs):
    out = subprocess.run(
        [sys.executable, "-m", "gearsym", "model", *args, "--json"],
        capture_output=True,
        text=True,
        check=True,
    )
    lf = json.loads(out.stdout)["linear_form"]
    assert len(lf["inputs"]) == inputs
    assert np.array(lf["B"]).shape == (len(lf["states"]), inputs)
    assert np.array(lf["A"]).shape == (len(lf["states"]),) * 2


def test_model_gear_errors_are_one_line():
    out = subprocess.run(
        [sys.executable, "-m", "gearsym", "model", "--gear", "12"], capture_output=True, text=True
    )
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and "gear: unknown gear '12'" in out.stderr


def test_every_mode_of_the_hybrid_2_3_has_its_linear_form(d):
    """(5.1) per mode of the hybrid shift: the mode's coordinates (as the hybrid model's
    states), a sliding element's torque an input, locked and open ones absent; A and B equal
    finite-difference Jacobians of the nonlinear model with the same constraint set. The slip
    sign only picks the sign of T (2.70), and T is the input here, so the two sign variants of a
    mode have the same form."""
    from gearsym.symbolic.hybrid import hybrid_shift
    from gearsym.symbolic.linear_forms import mode_linear_form

    hybrid = hybrid_shift(d, "2-3")
    spec = hybrid.spec
    forms = {}
    for name, mode in hybrid.modes.items():
        form = mode_linear_form(d, "2-3", name)
        locked = (*spec.locked, *(e for e in hybrid.elements if mode.status[e][0] == "locked"))
        sliding = tuple(e for e in hybrid.elements if mode.status[e][0] == "sliding")
        assert form.states == [v.name for v in mode.model.states], name
        order = [e.name for e in d.shift_elements]  # (5.3): description order K81, K38, ...
        torques = [f"T_{e}" for e in sorted(sliding, key=order.index)]
        assert form.inputs == ["T_In", "T_res_star", *torques, "zeta"], name
        check(d, form, locked, sliding, mode.keep)
        forms[name] = form
    for name, form in forms.items():
        twin = forms[name.replace("slide_neg", "slide_pos")]
        assert form.A == twin.A and form.B == twin.B, name


def test_model_json_of_a_mode_and_an_unknown_mode():
    name = "hybrid_2_3__K38_slide_pos__B05_open"
    out = subprocess.run(
        [sys.executable, "-m", "gearsym", "model", "--shift", "2-3", "--mode", name, "--json"],
        capture_output=True,
        text=True,
        check=True,
    )
    data = json.loads(out.stdout)
    lf = data["linear_form"]
    assert data["name"] == lf["mode"] == name
    assert lf["inputs"] == ["T_In", "T_res_star", "T_K38", "zeta"]
    assert np.array(lf["B"]).shape == (4, 4)
    bad = subprocess.run(
        [sys.executable, "-m", "gearsym", "model", "--mode", "nonsense", "--json"],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and bad.stdout == "" and bad.stderr.count("\n") == 1
    assert "mode: unknown mode 'nonsense' of the 2-3 shift" in bad.stderr
