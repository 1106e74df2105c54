"""(2.51) as corrected: each drivetrain inertia is reflected through the ratio it turns at.

The thesis prints J_2^eff = J_2 + J_cs^eff + J_cs^eff / i_D^2, counting the propeller shaft twice
(SPEC, known slips). Physics: the propeller shaft J_cs turns with the output shaft (ω_out), the
differential cage J_D at ω_out / i_D, so their kinetic energy ½ (J_cs + J_D / i_D²) ω_out² adds
J_cs + J_D / i_D² to the inertia seen at the output shaft. Hand check: in a gear (one gearbox
DOF, the output speed), with the side shaft relaxed (φ = 0, speeds 0), a unit input torque
accelerates the output at ω̇_out = i / J_red (i the gear's ratio, the torque reaching the output
shaft), so J_red = i / ω̇_out. Changing J_cs by a and J_D by b (0.25 and 2 kg·m² here) must
change J_red by exactly a + b / i_D², whatever the gear.
"""

from __future__ import annotations

import sympy as sp
from gearsym.symbolic.description import default_config_text
from gearsym.symbolic.drivetrain import drivetrain_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import ratio_table


def reduced_inertia(path, gear: str) -> sp.Rational:
    d = load_description(str(path))
    model = drivetrain_model(
        d, "g", locked=tuple(d.gear(gear).closed), torque_elements=(), keep=(d.output_shaft,)
    )
    (ratio,) = (r.ratio for r in ratio_table(d) if r.gear == gear)
    at_rest = {v.symbol: 0 for v in (*model.states, *model.inputs)}
    at_rest[model.inputs[0].symbol] = 1  # T_In = 1 N·m
    params = {v.symbol: v.default for v in model.parameters}
    acceleration = model.rhs[0].xreplace(at_rest).xreplace(params)
    return sp.nsimplify(ratio) / sp.nsimplify(acceleration, rational=True)


def test_propeller_shaft_and_differential_are_reflected_once(tmp_path):
    text = default_config_text()
    assert "J_cs = { value = 0.010," in text and "J_D = { value = 0.040," in text
    base = tmp_path / "base.toml"
    base.write_text(
        text.replace("J_cs = { value = 0.010,", "J_cs = { value = 0.25,").replace(
            "J_D = { value = 0.040,", "J_D = { value = 1.0,"
        )
    )
    heavy = tmp_path / "heavy.toml"
    heavy.write_text(
        text.replace("J_cs = { value = 0.010,", "J_cs = { value = 0.5,").replace(
            "J_D = { value = 0.040,", "J_D = { value = 3.0,"
        )
    )
    i_d = sp.Rational("2.469")
    expected = sp.Rational("0.25") + sp.Rational(2) / i_d**2  # ΔJ_cs = 0.25, ΔJ_D = 2
    for gear in ("1", "3", "7", "R"):
        change = reduced_inertia(heavy, gear) - reduced_inertia(base, gear)
        assert abs(float(change - expected)) < 1e-9 * float(expected), gear
        # the thesis' printed (2.51) would give J_cs (1 + 1/i_D^2), ignoring J_D: not this
        assert abs(float(change - sp.Rational("0.25") * (1 + 1 / i_d**2))) > 0.1
