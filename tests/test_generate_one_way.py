"""``gearsym generate`` on a gearbox with a one-way clutch (issue 30): nothing removed in
silence.

The Simpson 3-speed with the low freewheel F1 (``tests/data/simpson_3speed_one_way.toml``)
against the same box with a brake in F1's place (a friction brake on the same shaft, named F1
as well). Expected from what the models mean, not from the code under test:

* a shift the freewheel takes no part in (2-3: B1 off, C2 on) has the same equations whatever
  F1 is, so every file of its models and sets is the same text in both trees, and both trees
  hold the same files;
* in the μ form of a shift whose swapping element is the freewheel, the freewheel overruns
  (the shift model's premise: neither swapping element locked), so it carries no torque and
  has no μ and no normal force; the friction element's torque is k_sign 2 N_disc r_m μ F_N
  (2.69) with the hand slip sign (B1 on the sun, which turns backwards in a Simpson 1st:
  slip 0 − ω_sun > 0);
* a freewheel is locked or overrunning, so the linear forms of its shifts are 2 × 3 − 1 = 5,
  named and serving the modes as the hybrid model names them;
* what is not generated is printed and listed in the README with its reason.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import sympy as sp
from gearsym.symbolic.drivetrain import shift_model
from gearsym.symbolic.export.generate import (
    gearbox_model_names,
    generate_tree,
    skipped_models,
)
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.linear_forms import shift_linear_forms
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec

ONE_WAY = Path(__file__).parent / "data" / "simpson_3speed_one_way.toml"
FREEWHEEL = """[[shift_element]]
name = "F1"
kind = "one_way"
shaft = "carrier_r"
locks = "positive"
"""
BRAKE = """[[shift_element]]
name = "F1"
kind = "brake"
shaft = "carrier_r"
n_disc = 5
r_m = { value = 0.09, unit = "m", source = "assumed" }
a_piston = { value = 0.007, unit = "m^2", source = "assumed" }
"""


def _variant(tmp_path: Path, old: str, new: str, name: str) -> Path:
    text = ONE_WAY.read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def boxes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("boxes")
    brake = _variant(folder, FREEWHEEL, BRAKE, "simpson_3speed_brake.toml")
    return load_description(ONE_WAY), load_description(brake)


@pytest.fixture(scope="module")
def trees(boxes):
    return tuple(generate_tree(d) for d in boxes)


def test_the_other_shifts_are_generated_as_with_a_brake(boxes, trees):
    """Both trees hold the same files; every file of the 2-3 (models, EKF, extended UIO,
    hybrid sensitivities, linear forms, UIO) and the μ map is the same text. Before, the
    freewheel removed every μ form, sensitivity, estimator and hybrid model of the box."""
    one_way, brake = trees
    assert sorted(one_way.files) == sorted(brake.files)
    other = [path for path in one_way.files if "_2_3" in path or "mu_map" in path]
    assert len(other) >= 24  # shift_2_3, _mu, _mu_sens, ekf, euio, hybrid, linear, uio: C + py
    for path in other:
        assert one_way.files[path] == brake.files[path], path
    names = {m.model.name for m in one_way.models}
    for expected in (
        "shift_2_3_mu",
        "shift_2_3_mu_sens",
        "ekf_2_3",
        "euio_2_3",
        "shift_element",
        "shift_1_2_mu",
        "shift_1_2_mu_sens",
    ):
        assert expected in names, expected
    assert [s.name for s in one_way.hybrid_sets] == [s.name for s in brake.hybrid_sets]
    assert one_way.hybrid_sets  # the default hybrid 2-3
    assert names == {m.model.name for m in brake.models}


def test_mu_form_of_a_freewheel_shift(boxes):
    """shift_1_2_mu: u = [T_In, F_N1], μ of B1 only, F1 overrunning (zero torque); the
    right-hand side is the torque-input model's with T_F1 = 0 and T_B1 = +2·5·0.09 μ F_N."""
    d, _ = boxes
    mu_form = shift_model(d, "1-2", friction_inputs=True)
    assert [v.name for v in mu_form.inputs] == ["T_In", "F_N1"]
    assert [v.name for v in mu_form.parameters if v.name.startswith("mu_")] == ["mu_1"]
    assert "F1 overrunning" in mu_form.metadata["overrunning"]
    torque_form = shift_model(d, "1-2")
    mu, force = mu_form.variable("mu_1").symbol, mu_form.variable("F_N1").symbol
    hand = torque_form.rhs.xreplace(
        {
            torque_form.variable("T_F1").symbol: 0,
            torque_form.variable("T_B1").symbol: 2 * 5 * sp.Rational(9, 100) * mu * force,
        }
    )
    assert (mu_form.rhs - hand).applyfunc(sp.simplify) == sp.zeros(*hand.shape)


@pytest.mark.parametrize("shift", ["1-2", "2-1", "1M-1"])
def test_freewheel_modes_in_the_linear_forms_are_the_hybrid_models(boxes, shift):
    """5 forms (locked or overrunning × locked, sliding or open, less the tie-up), named
    locked/overrunning, never sliding or open, and serving exactly the hybrid model's 7
    modes."""
    d, _ = boxes
    forms = shift_linear_forms(d, shift_spec(d, shift)).forms
    assert len(forms) == 5
    assert all("F1_locked" in f.name or "F1_overrunning" in f.name for f in forms)
    assert not any("F1_sliding" in f.name or "F1_open" in f.name for f in forms)
    served = [mode for f in forms for mode in f.modes]
    assert sorted(served) == sorted(hybrid_shift(d, shift).modes)
    assert len(served) == 7


def test_what_is_left_out_is_said_with_its_reason(tmp_path):
    """Two gears of the same ratio (1M, 1: F1 holds the shaft B2 brakes, so B2 does not slip
    between them) have no power-on slip direction, so no μ form; a description without
    ``[friction] z_ba_ratio`` has no elasto-plastic element model; everything else is
    generated. The command prints each line and the README lists it."""
    path = _variant(
        tmp_path,
        'z_ba_ratio = { value = 0.6, unit = "1", source = "assumed (public data: z_ba = '
        '0.3-0.9 z_ss)" }\n',
        "",
        "simpson_one_way_without_z_ba.toml",
    )
    d = load_description(path)
    skipped = skipped_models(d)
    assert skipped == (
        "`shift_1M_1_mu`, `shift_1M_1_mu_sens`: B2 would not slip: gears 1M and 1 leave it "
        "at zero slip, so the friction torque has no direction (2.70)",
        "`shift_element`: [friction] has no z_ba_ratio",
    )
    names = gearbox_model_names(d)
    assert {"shift_1_2_mu", "shift_2_3_mu_sens", "ekf_2_3", "euio_2_3"} <= set(names)
    assert "shift_element" not in names and "shift_1M_1_mu" not in names
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "gearsym", "generate", str(path), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    printed = [line for line in done.stdout.splitlines() if line.startswith("not generated: ")]
    listed = (out / "README.md").read_text(encoding="utf-8")
    assert len(printed) == len(skipped)
    for line in skipped:
        assert f"not generated: {line.replace('`', '')}" in printed
        assert f"- {line}" in listed
    files = {p.name for p in (out / "c").iterdir()}
    assert "gearsym_shift_element.c" not in files and "gearsym_shift_1_2_mu.c" in files


def test_estimators_of_a_freewheel_shift_refuse_in_one_line(boxes):
    """The EKF's and the extended UIO's augmented model (4.1) of a shift the freewheel swaps
    in is refused with the reason (no normal force, no μ to decide its mode or estimate),
    naming the freewheel; the 2-3 of the same box has one."""
    from gearsym.symbolic.errors import GearsymError
    from gearsym.symbolic.estimators.ekf import augmented_model

    d, _ = boxes
    for shift in ("1-2", "2-1"):
        with pytest.raises(GearsymError, match="F1 is a one-way clutch") as err:
            augmented_model(d, shift)
        assert "\n" not in str(err.value)
    assert augmented_model(d, "2-3").parameters == ("m_veh", "mu_1", "mu_C2", "zeta")
