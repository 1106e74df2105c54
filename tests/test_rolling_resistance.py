"""f_Roll(v) speed dependent (2.49a): rolling_resistance = "polynomial", F_r = (f_R0 + f_R1 v +
f_R2 v²) cos ζ m g. Expected values: the polynomial contains the thesis' printed form (only
f_R1 = f_roll) and the textbook form (only f_R0 = f_R) exactly, and the term of f_R2 in the
sensitivities (3.7) is the hand derivative of the wheel equation (2.50).
"""

from __future__ import annotations

import subprocess
import sys

import pytest
import sympy as sp
from gearsym.symbolic.description import default_config_text
from gearsym.symbolic.drivetrain import shift_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.sensitivity import sensitivity_equations

THESIS = 'rolling_resistance = "thesis"'


def polynomial(tmp_path, f0: str, f1: str, f2: str, unit2: str = "s^2/m^2"):
    text = default_config_text()
    assert THESIS in text
    lines = (
        f'f_R0 = {{ value = {f0}, unit = "1", source = "test" }}\n'
        f'f_R1 = {{ value = {f1}, unit = "s/m", source = "test" }}\n'
        f'f_R2 = {{ value = {f2}, unit = "{unit2}", source = "test" }}\n'
        'rolling_resistance = "polynomial"'
    )
    path = tmp_path / f"poly_{f0}_{f1}_{f2}_{unit2.replace('/', '_')}.toml"
    path.write_text(text.replace(THESIS, lines))
    return path


def wheel_rhs(path, form: str | None = None):
    text = path.read_text() if form is None else default_config_text().replace(THESIS, form)
    tmp = path.with_name(path.stem + "_form.toml")
    tmp.write_text(text)
    model = shift_model(load_description(str(tmp)), "2-3")
    values = {v.symbol: v.default for v in model.parameters}
    return sp.expand(model.rhs[-1].xreplace(values))


def test_the_polynomial_contains_the_thesis_and_the_textbook_forms(tmp_path):
    thesis = wheel_rhs(tmp_path / "a.toml", THESIS)
    textbook = wheel_rhs(tmp_path / "b.toml", 'rolling_resistance = "textbook"')
    # defaults of the built-in file: f_roll = 0.001 s/m, f_R = 0.009
    as_thesis = wheel_rhs(polynomial(tmp_path, "0.0", "0.001", "0.0"))
    as_textbook = wheel_rhs(polynomial(tmp_path, "0.009", "0.0", "0.0"))
    assert sp.simplify(as_thesis - thesis) == 0
    assert sp.simplify(as_textbook - textbook) == 0
    assert sp.simplify(thesis - textbook) != 0  # the two forms differ: the check can fail


def test_the_f_R2_term_of_the_sensitivities_is_the_hand_derivative(tmp_path):
    d = load_description(str(polynomial(tmp_path, "0.008", "0.0002", "0.00001")))
    model = shift_model(d, "2-3")
    eqs = sensitivity_equations(model, ["f_R2", "f_R1", "f_R0"])
    s = {v.name: v.symbol for v in (*model.parameters, *model.states)}
    r_dyn, g = sp.Rational("0.3287"), sp.Rational("9.81")
    v = r_dyn * s["omega_C"]
    i_eff = s["I_wheel"] + s["m_veh"] * r_dyn**2  # (2.46) with the square
    # (2.50): ω̇_C = (2 T_ss − r_dyn (F_r + F_ad + F_g)) / I_C^eff, F_r = f_Roll(v) cos ζ m g
    for name, power in (("f_R2", 2), ("f_R1", 1), ("f_R0", 0)):
        expected = -r_dyn * v**power * sp.cos(s["zeta"]) * s["m_veh"] * g / i_eff
        got = eqs.inhomogeneous_term(name)[-1]
        assert sp.simplify(got - expected) == 0, name
        assert all(e == 0 for e in eqs.inhomogeneous_term(name)[:-1])  # wheel row only


def test_model_lists_the_coefficients_with_units(tmp_path):
    import json

    path = polynomial(tmp_path, "0.008", "0.0002", "0.00001")
    result = subprocess.run(
        [sys.executable, "-m", "gearsym", "model", str(path), "--json"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    units = {p["name"]: p["unit"] for p in json.loads(result.stdout)["parameters"]}
    assert (units["f_R0"], units["f_R1"], units["f_R2"]) == ("1", "s/m", "s^2/m^2")
    assert "f_roll" not in units and "f_R" not in units


@pytest.mark.parametrize(
    "edit, key",
    [
        (
            lambda p: p.write_text(p.read_text().replace('unit = "s^2/m^2"', 'unit = "s/m"')),
            "vehicle.f_R2.unit",
        ),
        (
            lambda p: p.write_text(p.read_text().replace('"polynomial"', '"cubic"')),
            "vehicle.rolling_resistance",
        ),
    ],
)
def test_bad_polynomial_input_is_one_line(tmp_path, edit, key):
    path = polynomial(tmp_path, "0.008", "0.0002", "0.00001")
    edit(path)
    result = subprocess.run(
        [sys.executable, "-m", "gearsym", "ratios", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and key in result.stderr
    assert result.stderr.count("\n") == 1
