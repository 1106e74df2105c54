"""Observability per mode of the hybrid shift (symbolic/observability/modes.py, issue 15 item 6).

Expected values from the thesis and from hand reasoning, not from the code under test:

* both elements sliding is the thesis' shift model: x = [ω1, ω2, φ, ω_C], p = [m_veh, μ38,
  μ05, ζ], rank 8 (4.12);
* in a gear mode neither μ acts (a locked element carries its constraint reaction, an open one
  nothing; (3.14) holds only while sliding), so both are excluded with that reason and the
  estimated set is m_veh, ζ. Generic inputs: m_veh is seen through the effective wheel inertia
  (ω̇_C responds to T_In changes with the gain 1/I_C^eff, I_C^eff = I + m_veh r²), then ζ
  through the road load r m_veh g (f_R cos ζ + sin ζ); on a level road (ζ = 0) its ζ-derivative
  is r m_veh g (cos 0 − f_R sin 0) = r m_veh g ≠ 0, so the level road is no rank drop: rank
  3 + 2 = 5 both generically and at ζ = 0;
* a sliding element's torque is 2 N r_m μ F_N: with F_N held at zero (constant input, point
  condition) μ has no influence, so exactly μ drops out;
* the two slip signs differ only by T → −T, i.e. μ → −μ, a reparametrisation: same rank, same
  unobservable set.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.observability.modes import analyze_modes


@pytest.fixture(scope="module")
def description():
    return load_description()


@pytest.fixture(scope="module")
def modes(description):
    return {m.mode: m for m in analyze_modes(description, "2-3", seed=0)}


def test_every_mode_of_the_shift_is_ranked_in_shift_order(modes):
    names = list(modes)
    assert len(names) == 15  # 4 x 4 statuses less the tie-up (symbolic/hybrid.py)
    assert names[0] == "hybrid_2_3__K38_locked__B05_open"  # gear 2 first
    path = ["hybrid_2_3__K38_slide_pos__B05_open", "hybrid_2_3__K38_slide_pos__B05_slide_pos"]
    path += ["hybrid_2_3__K38_open__B05_slide_pos", "hybrid_2_3__K38_open__B05_locked"]
    assert [n for n in names if n in path] == path


def test_both_sliding_is_the_thesis_rank_8(modes):
    for name, m in modes.items():
        if set(m.status.values()) <= {"slide_pos", "slide_neg"}:
            assert m.states == ("omega_1", "omega_2", "phi", "omega_C"), name
            assert m.estimated == ("m_veh", "mu_38", "mu_05", "zeta"), name
            assert not m.excluded
            assert (m.rank, m.n_unknowns, m.unobservable) == (8, 8, ()), name


def test_in_a_gear_both_mu_are_excluded_and_m_veh_zeta_are_observable(modes, description):
    for name in ("hybrid_2_3__K38_locked__B05_open", "hybrid_2_3__K38_open__B05_locked"):
        m = modes[name]
        assert m.estimated == ("m_veh", "zeta")
        assert set(m.excluded) == {"mu_38", "mu_05"}
        assert all("no influence" in reason for reason in m.excluded.values())
        assert "locked" in m.excluded["mu_38" if "K38_locked" in name else "mu_05"]
        assert "open" in m.excluded["mu_05" if "K38_locked" in name else "mu_38"]
        assert (m.rank, m.n_unknowns) == (5, 5), name
    level = analyze_modes(description, "2-3", conditions=["zeta=0"], seed=1)
    for m in level:
        if m.mode in ("hybrid_2_3__K38_locked__B05_open", "hybrid_2_3__K38_open__B05_locked"):
            assert (m.rank, m.n_unknowns, m.unobservable) == (5, 5, ()), m.mode


def test_a_sliding_element_without_normal_force_hides_its_mu(description):
    held = analyze_modes(
        description,
        "2-3",
        conditions=["F_N38=0"],
        input_models=["F_N38=constant"],
        seed=2,
    )
    m = next(m for m in held if m.mode == "hybrid_2_3__K38_slide_pos__B05_open")
    assert m.estimated == ("m_veh", "mu_38", "zeta")
    assert (m.rank, m.n_unknowns, m.unobservable) == (6, 7, ("mu_38",))


def test_slip_signs_give_the_same_verdict(modes):
    def flip(name):
        return name.replace("pos", "tmp").replace("neg", "pos").replace("tmp", "neg")

    for name, m in modes.items():
        other = modes[flip(name)]
        assert (m.rank, m.unobservable, m.estimated) == (
            other.rank,
            other.unobservable,
            other.estimated,
        )


def test_per_mode_command(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "gearsym", "observability", "--per-mode", "--json", "--seed", "0"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    first = data["modes"][0]
    assert first["mode"] == "hybrid_2_3__K38_locked__B05_open"
    assert first["rank"] == 5 and "mu_38" in first["excluded"]
    text = subprocess.run(
        [sys.executable, "-m", "gearsym", "observability", "--per-mode", "--seed", "0"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert "rank 8 of 8" in text.stdout and "mu_05 excluded: B05 is open" in text.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "gearsym", "observability", "--per-mode", "--at", "nonsense=1"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr.count("\n") == 1 and "--at: 'nonsense'" in bad.stderr
