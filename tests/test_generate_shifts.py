"""``gearsym generate --shifts``: downshifts, skip shifts and reverse engagements as code.

Checks with expected values from the gear table and from physics, not from the code:

* a downshift swaps the same two elements as its upshift with the roles exchanged, over the same
  locked set: its torque-input shift model (2.55–2.58) is the upshift's model with the two
  torque inputs renamed in place (same states, same right-hand side);
* its μ form (2.69) slides the on-coming element the way the from-gear makes it slip (2.70):
  in the power-on 3-2 the on-coming K38 slips as gear 3 makes it (sign of its slip in gear 3);
* ``all`` holds every ordered pair of gears that differ by exactly one off-going and one
  on-coming element (counted here from the gear table with set arithmetic), each once, and
  each shift's reverse too (and then the double swaps: tests/test_double_swap.py);
* the emitted C of a downshift and a skip shift compiles strictly and equals SymPy;
* a shift that is neither a single nor a double swap, or a bad list, is a one-line error
  (exit 2), nothing written.
"""

from __future__ import annotations

import subprocess
import sys
from itertools import permutations
from pathlib import Path

import pytest
import sympy as sp
from gearsym.symbolic.drivetrain import element_slip_in_gear, shift_model
from gearsym.symbolic.export.generate import gearbox_models, generate_tree, selected_shifts
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks import generated_check


@pytest.fixture(scope="module")
def d():
    return load_description()


def test_a_downshift_model_is_its_upshift_with_the_roles_exchanged(d):
    up, down = shift_spec(d, "2-3"), shift_spec(d, "3-2")
    assert (down.off_going, down.on_coming) == (up.on_coming, up.off_going)
    assert sorted(down.locked) == sorted(up.locked)
    m_up, m_down = shift_model(d, "2-3"), shift_model(d, "3-2")
    assert [v.name for v in m_up.states] == [v.name for v in m_down.states]
    assert sorted(v.name for v in m_up.inputs) == sorted(v.name for v in m_down.inputs)
    rename = {v.symbol: m_up.variable(v.name).symbol for v in (*m_down.states, *m_down.inputs)}
    difference = (m_down.rhs.xreplace(rename) - m_up.rhs).applyfunc(sp.expand)
    assert difference == sp.zeros(*difference.shape)


def test_power_on_downshift_slides_the_on_coming_element_as_the_from_gear_makes_it(d):
    spec = shift_spec(d, "3-2")
    slip_in_3 = element_slip_in_gear(d, "3", spec.on_coming)  # K38 is open in gear 3: it slips
    assert slip_in_3 != 0
    (model,) = gearbox_models(d, only="shift_3_2_mu", shifts="3-2")
    mu = sp.Symbol("mu_38", positive=True)
    force = next(v.symbol for v in model.model.inputs if v.name == "F_N38")
    torque_term = sp.diff(model.model.rhs, force).subs(mu, 1)
    assert torque_term != sp.zeros(*torque_term.shape)
    upshift = shift_model(d, "2-3", friction_inputs=True)
    up_force = next(v.symbol for v in upshift.inputs if v.name == "F_N38")
    up_term = sp.diff(upshift.rhs, up_force).subs(sp.Symbol("mu_38", positive=True), 1)
    # 2-3 power-on: K38 (off-going) slips against the way gear 3 makes it; 3-2: with it
    ratio = [sp.nsimplify(a / b) for a, b in zip(torque_term, up_term, strict=True) if b != 0]
    assert ratio and all(r == -1 for r in ratio)


def _single_swaps(d) -> set[str]:
    driven = {g.name: set(g.closed) for g in d.gears if not g.neutral}
    return {
        f"{a}-{b}"
        for a, b in permutations(driven, 2)
        if len(driven[a] - driven[b]) == 1 and len(driven[b] - driven[a]) == 1
    }


def test_all_is_every_single_swap_once_adjacent_upshifts_first(d):
    chosen = [spec.name for spec in selected_shifts(d, "all") if spec.single]
    adjacent = [spec.name for spec in selected_shifts(d, "adjacent")]
    assert chosen[: len(adjacent)] == adjacent
    assert len(chosen) == len(set(chosen))
    assert set(chosen) == _single_swaps(d)
    assert all(f"{b}-{a}" in chosen for a, b in (name.split("-") for name in chosen))
    assert {"3-2", "5-3", "2-1"} <= set(chosen)  # a downshift, a kick-down skip, into 1st


@pytest.mark.slow
def test_emitted_downshift_and_skip_shift_compile_and_equal_sympy(d, tmp_path):
    tree = generate_tree(d, shifts="3-2,5-3")
    names = sorted(m.model.name for m in tree.models if m.shift is not None)
    assert names == [
        "shift_3_2", "shift_3_2_mu", "shift_3_2_mu_sens",
        "shift_5_3", "shift_5_3_mu", "shift_5_3_mu_sens",
    ]  # fmt: skip
    assert {e.set.name for e in tree.linear_sets} == {"linear_gears", "linear_3_2", "linear_5_3"}
    root = tmp_path / "gen"
    for relative, text in tree.files.items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_text(text)
    chosen = [m for m in tree.models if m.model.name in ("shift_3_2_mu", "shift_5_3")]
    reports = generated_check.compare_models(chosen, root, tmp_path / "build", n_points=50)
    assert len(reports) == 6
    for r in reports:
        assert generated_check.comparison_ok(r), str(r)


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--shifts", "2-9", "differ by 3"),  # K81, K38, B06 -> B05, B08, K27: a triple swap
        ("--shifts", "3-2,3-2", "listed twice"),
        ("--shifts", "3-x", "unknown gear 'x'"),
        ("--shifts", ",", "expected adjacent, all or a list"),
        ("--controllers", "1-5", "swaps two elements each way"),
        ("--controllers", "3-2,3-2", "listed twice"),
        ("--controllers", "3-x", "unknown gear 'x'"),
    ],
)
def test_bad_shift_selection_is_one_line(
    tmp_path: Path, option: str, value: str, message: str
) -> None:
    """A bad selection is one line naming the option and the reason, exit 2, nothing written."""
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "gearsym", "generate", option, value, "--out", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert message in lines[-1] and lines[-1].startswith("gearsym: ")
    assert f": {option}: " in lines[-1]
    assert "Traceback" not in result.stderr
    assert not out.exists()


def test_controllers_emits_a_downshift_controller_with_its_ekf(tmp_path: Path) -> None:
    """``--controllers 3-2``: the downshift's controller and the EKF its task runs with are
    written, its README row says it is a downshift, and the default shift's controller is not
    (only what was asked for); the task compiles strictly with them (the twin tests of its
    behaviour: tests/test_control_c_downshift.py)."""
    from gearsym.validation.checks.control_c import build_control_library

    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "gearsym", "generate", "--controllers", "3-2", "--out", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    c = out / "c"
    assert (c / "gearsym_control_3_2.c").is_file() and (c / "gearsym_ekf_3_2.c").is_file()
    assert not (c / "gearsym_control_2_3.c").exists()
    readme = (out / "README.md").read_text(encoding="utf-8")
    assert "| `control_3_2` | downshift 3-2, power-on and coast: B05 off, K38 on" in readme
    assert build_control_library(c, "3-2", tmp_path / "build", single=True).is_file()
