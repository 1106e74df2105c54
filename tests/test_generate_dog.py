"""Emitted code of a gearbox with dog elements (issue 30 part C): the generated models handle
an engaged dog as a locked constraint, and what cannot be supported is skipped with a printed
reason.

Box ``tests/data/dog_9speed.toml`` (B06 a dog brake, K27 a dog clutch). Expected from what
the models mean, not from the code under test:

* gear 4 closes B05 and both dogs: with them engaged as constraints the gearbox keeps one
  motion, and the measured shaft speeds the emitted outputs give stand in the gear's ratio,
  ω_1/ω_2 = 1.636 (Table 2.1, published);
* the emitted C (double and single) and CasADi agree with the SymPy model at 1000 random
  points within the models' stated tolerances (1e-12 double, 1e-5 single), for gear 4 (both
  dogs engaged) and for the hybrid mode of the 4-5 with the dog B06 engaged and K81 sliding;
* the EKF/EUIO of a shift a dog swaps refuse in one line; the hybrid sensitivities of such a
  shift are skipped with their reason, printed and in the generated README.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.drivetrain import drivetrain_model
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators.ekf import augmented_model
from gearsym.symbolic.export.generate import _bounds, generate_tree
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks import c_check

from gearsym.cli import main

BOX = Path(__file__).parent / "data" / "dog_9speed.toml"


@pytest.fixture(scope="module")
def box():  # type: ignore[no-untyped-def]
    return load_description(BOX)


def _gear_4(d):  # type: ignore[no-untyped-def]
    gear = d.gear("4")
    assert {"B06", "K27"} <= set(gear.closed)
    return drivetrain_model(d, "gear_4", locked=tuple(gear.closed), keep=(d.output_shaft,))


def _mode_4_5(d):  # type: ignore[no-untyped-def]
    hybrid = hybrid_shift(d, "4-5")
    model = hybrid.mode_of({"B06": ("locked", 0), "K81": ("sliding", 1)}).model
    return replace(model, name="mode_4_5_B06_locked_K81_slide_pos")  # a C identifier


@pytest.mark.parametrize("which", ["gear_4", "mode_4_5"])
def test_emitted_code_matches_sympy_with_a_dog_engaged(box, which, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    model = _gear_4(box) if which == "gear_4" else _mode_4_5(box)
    entry = c_check.build(model, tmp_path, _bounds(box, model))
    for precision in ("double", "single"):
        report = c_check.compare_with_sympy(model, entry[precision], n_points=1000, seed=7)
        assert report.n_points == 1000
        assert report.ok(c_check.TOLERANCE[precision]), str(report)
    report = c_check.compare_casadi_with_sympy(model, entry["casadi"], 1000, seed=8)
    assert report.ok(c_check.TOLERANCE["double"]), str(report)
    if which == "gear_4":
        names = [v.name for v in model.outputs]
        x = np.zeros(len(model.states))
        x[[v.name for v in model.states].index("omega_2")] = 100.0
        defaults = [v.default for v in model.parameters]
        y = entry["double"].evaluate("outputs", x, np.zeros(len(model.inputs)), defaults)
        ratio = y[names.index("y_omega_1")] / y[names.index("y_omega_2")]
        assert round(ratio, 3) == 1.636


def test_estimators_of_a_dog_shift_refuse_in_one_line(box) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(GearsymError) as info:
        augmented_model(box, "4-5")
    message = str(info.value)
    assert "\n" not in message and "B06 is a dog element" in message


def test_what_is_skipped_is_said(box, capsys: pytest.CaptureFixture[str], tmp_path) -> None:  # type: ignore[no-untyped-def]
    tree = generate_tree(box, hybrid_shifts="4-5")
    assert any("hybrid_4_5_sens" in s and "dog element B06" in s for s in tree.skipped)
    assert "hybrid_4_5_sens" in tree.files["README.md"]
    # the mu forms of the dog shifts are emitted: the dog open, K81's mu only
    header = tree.files["c/gearsym_shift_4_5_mu.h"]
    assert "dog element B06" in header
    assert "F_N81" in header and "F_N06" not in header
    out = tmp_path / "gen"
    assert main(["generate", str(BOX), "--out", str(out), "--hybrid-shifts", "4-5"]) == 0
    printed = capsys.readouterr()
    assert "not generated: hybrid_4_5_sens: the dog element B06 swaps" in printed.out + printed.err


def test_linear_forms_of_a_dog_shift_are_the_hybrid_modes(box) -> None:  # type: ignore[no-untyped-def]
    """A dog is locked or open: 2 × 3 − 1 (the tie-up) = 5 forms, serving the 7 hybrid modes
    as the hybrid model names them; none of them has the dog sliding."""
    from gearsym.symbolic.linear_forms import shift_linear_forms
    from gearsym.symbolic.shifts import shift_spec

    forms = shift_linear_forms(box, shift_spec(box, "4-5")).forms
    assert len(forms) == 5
    assert not any("B06_sliding" in f.name for f in forms)
    served = {m for f in forms for m in f.modes}
    assert served == set(hybrid_shift(box, "4-5").modes)
