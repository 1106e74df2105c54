"""``gearsym observability``: the report of (4.1)–(4.13) for a shift model, and its bad inputs.

Expected verdicts come from the hand derivations in ``tests/test_observability.py`` (real 2↔3
model section): generic rank 8 with rank by order 3, 6, 8; a normal force held at zero removes
its μ at every order; both normal forces constant drop Q_123 to 7, restored by y'''; at ζ = 0
that drop persists; T_In's excitation cannot matter.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from gearsym.cli import main

BUILTIN = "<built-in thesis_9speed.toml>"


def run(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["observability", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def by_label(drops: list[dict], label: str) -> dict:
    exact = [d for d in drops if d["label"] == label]
    (match,) = exact or [d for d in drops if d["label"].startswith(label + " [")]
    return match


def test_human_report_of_the_default_2_3_shift(capsys):
    code, out, err = run(capsys, "--seed", "7")
    assert code == 0, err
    assert "shift 2-3" in out and "random-walk parameters (4.1) m_veh, mu_38, mu_05, zeta" in out
    assert "y … y^(2): 8 of 8 unknowns (full rank; rank by order 3, 6, 8" in out
    assert "re-verified exactly; error probability 0" in out
    for name in ("omega_1", "omega_2", "phi", "omega_C", "m_veh", "mu_38", "mu_05", "zeta"):
        assert any(line.split()[:1] == [name] and "NOT" not in line for line in out.splitlines())
    assert "no unobservable direction" in out
    # the sets where (4.12) fails, each with its rank and its fate at higher orders
    assert "F_N05 held at 0 [normal force on B05: element open]" in out
    assert "F_N38 held at 0 [normal force on K38: element open]" in out
    assert "not observable: mu_05;" in out and "not observable: mu_38;" in out
    assert "at every order: mu_05 does not occur in f or h with F_N05 = 0" in out
    assert "F_N38 and F_N05 constant" in out and "restored by y^(3)" in out
    assert "m_veh = 0  [outside the physical range]" in out
    assert "rank stays 8: T_In held at 0; T_In constant; F_N38 constant; F_N05 constant" in out
    assert out.rstrip().splitlines()[-1].startswith("time: model ")


def test_json_report_via_the_installed_entry_point():
    proc = subprocess.run(
        [sys.executable, "-m", "gearsym", "observability", "--json", "--seed", "8"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data["rank"] == 8 and data["n_unknowns"] == 8
    assert data["full_rank"] and data["certain"] and data["error_probability_bound"] == 0.0
    assert data["rank_by_order"] == [3, 6, 8] and data["max_order"] == 2
    assert data["observable"] == dict.fromkeys(
        ["omega_1", "omega_2", "phi", "omega_C", "m_veh", "mu_38", "mu_05", "zeta"], True
    )
    assert data["unobservable_directions"] == []
    assert data["outputs"] == {
        "y_omega_1": "omega_1",
        "y_omega_2": "omega_2",
        "y_omega_C": "omega_C",
    }
    assert data["result"]["witness"]["verified"]
    held = by_label(data["rank_drops"], "F_N05 held at 0")
    assert held["rank"] == 7 and held["unobservable"] == ["mu_05"]
    assert held["unobservable_directions"] == [{"mu_05": "1"}]
    assert held["conditions"] == {"F_N05": "0"} and held["input_models"] == {"F_N05": "constant"}
    assert held["persists"] and held["every_order"] and held["error_probability_bound"] < 1e-9
    both = by_label(data["rank_drops"], "F_N38 and F_N05 constant")
    assert both["rank"] == 7 and both["restored_at_order"] == 3 and not both["persists"]
    assert both["rank_by_order"] == [3, 6, 7, 8]
    assert {"omega_1", "omega_2", "omega_C"}.isdisjoint(both["unobservable"])
    # found inside the previous set (the repairing minor vanishes on zeta = 0): the level-road
    # case of test_observability, rank 7 at every order
    flat = by_label(data["rank_drops"], "F_N38 and F_N05 constant, zeta = 0")
    assert flat["rank"] == 7 and flat["persists"] and flat["restored_at_order"] is None
    assert set(flat["unobservable"]) == {"phi", "mu_38", "mu_05", "zeta"}
    assert flat["rank_by_order"][:4] == [3, 6, 7, 7]
    assert "F_N38 and F_N05 constant, m_veh = 0" in data["implied_not_tested"]
    mass = by_label(data["rank_drops"], "m_veh = 0")
    assert not mass["physical"] and mass["unobservable"] == ["zeta"]
    kept = {d["label"]: d["rank"] for d in data["not_dropping"]}
    assert kept["T_In constant"] == 8 and kept["F_N05 constant"] == 8
    assert "all inputs constant" in data["implied_not_tested"]
    assert set(data["timings"]) >= {"model", "lie_derivatives", "rank", "drop_search", "total"}


def test_flat_road_with_constant_normal_forces_persists(capsys):
    code, out, err = run(
        capsys,
        "--input-model",
        "F_N38=constant,F_N05=constant",
        "--input-model",
        "T_In=constant",
        "--at",
        "zeta=0",
        "--max-order",
        "4",
        "--no-drop-search",
        "--json",
        "--seed",
        "9",
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["rank"] == 7 and data["rank_by_order"] == [3, 6, 7, 7, 7]
    assert set(data["unobservable"]) == {"phi", "mu_38", "mu_05", "zeta"}
    assert data["conditions"] == {"zeta": "0"}
    assert data["input_models"] == {"T_In": "constant", "F_N38": "constant", "F_N05": "constant"}
    assert 0 < data["error_probability_bound"] < 1e-9
    assert data["drop_search"] is False and data["rank_drops"] == []


def test_outputs_params_and_known_parameter_conditions(capsys):
    # Only the wheel speed and no parameters: omega_1 enters no equation but its own, so it
    # cannot be seen (rank <= 3).
    code, out, err = run(
        capsys, "--params", "", "--outputs", "omega_C", "--no-drop-search", "--json", "--seed", "3"
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["unknowns"] == ["omega_1", "omega_2", "phi", "omega_C"]
    assert data["outputs"] == {"y_omega_C": "omega_C"} and data["unobservable"] == ["omega_1"]
    # NAME=EXPR outputs; a known parameter named in --at is not fixed at its default: with
    # k_ss = 0 the twist phi enters nothing (T_ss = d_ss phi'), so phi is unobservable.
    code, out, err = run(
        capsys,
        "--outputs",
        "y_omega_1,slip=omega_1-omega_2",
        "--outputs",
        "omega_C",
        "--at",
        "k_ss=0",
        "--no-drop-search",
        "--json",
        "--seed",
        "4",
    )
    assert code == 0, err
    data = json.loads(out)
    assert list(data["outputs"]) == ["y_omega_1", "slip", "y_omega_C"]
    assert data["outputs"]["slip"] == "omega_1 - omega_2"
    assert "k_ss" not in data["substituted_parameters"] and data["conditions"] == {"k_ss": "0"}
    assert data["unobservable"] == ["phi"] and data["unobservable_directions"] == [{"phi": "1"}]


def test_other_shift_uses_its_own_mu_parameters(capsys):
    code, out, err = run(capsys, "--shift", "3-2", "--no-drop-search", "--json", "--seed", "5")
    assert code == 0, err
    data = json.loads(out)
    assert sorted(data["result"]["estimated_parameters"]) == ["m_veh", "mu_05", "mu_38", "zeta"]
    assert data["rank"] == 8 and data["certain"]


BAD = [
    (["--params", "m_veh,nope"], "--params", "unknown parameter(s) nope"),
    (["--params", "m_veh,m_veh"], "--params", "given twice"),
    (["--outputs", "T_In"], "--outputs", "is not a function of the states"),
    (["--outputs", "k_ss*2"], "--outputs", "is not a function of the states"),
    (["--outputs", "omega_9"], "--outputs", "unknown name(s) omega_9"),
    (["--outputs", "omega_1+"], "--outputs", "cannot parse"),
    (["--outputs", "exp(omega_1)"], "--outputs", "unknown function(s) exp"),
    (["--at", "phi=1/0"], "--at", "singular"),
    (["--outputs", "y_omega_1,y_omega_1"], "--outputs", "given twice"),
    (["--input-model", "T_In"], "--input-model", "expected NAME=generic|constant|poly:K"),
    (["--input-model", "T_In=ramp"], "--input-model", "unknown input model 'ramp'"),
    (["--input-model", "T_In=poly:x"], "--input-model", "poly:x"),
    (["--input-model", "F_N99=constant"], "--input-model", "'F_N99' is not an input"),
    (["--shift", "2-4"], "--shift", "a shift model needs exactly one of each"),
    (["--shift", "2-12"], "--shift", "unknown gear '12'"),
    (["--shift", "23"], "--shift", "expected FROM-TO"),
    (["--at", "nope=1"], "--at", "'nope' is not a variable of the model"),
    (["--at", "phi=nope"], "--at", "unknown name(s) nope"),
    (["--at", "phi"], "--at", "expected NAME=VALUE"),
    (["--max-order", "-1"], "--max-order", "must be >= 0"),
]


@pytest.mark.parametrize(("args", "key", "words"), BAD)
def test_bad_input_is_one_line_with_exit_2(capsys, args, key, words):
    code, out, err = run(capsys, *args, "--no-drop-search")
    assert code == 2
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"gearsym: {BUILTIN}: {key}: ")
    assert words in lines[0]


def test_bad_input_has_no_traceback_from_the_entry_point():
    proc = subprocess.run(
        [sys.executable, "-m", "gearsym", "observability", "--outputs", "F_N38"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith(f"gearsym: {BUILTIN}: --outputs: ")


def test_budget_overrun_reports_the_sound_partial_result(capsys):
    # The order-2 block has more than 100 operations; orders 0 and 1 give rank 3 + 3 = 6
    # (hand derivation in test_observability), a sound lower bound by (4.13).
    code, out, err = run(capsys, "--size-budget", "100")
    assert code == 2
    (line,) = err.splitlines()
    assert line.startswith(f"gearsym: {BUILTIN}: --size-budget: size budget of 100 operations")
    assert "rank of Q >= 6 of 8" in line
    assert out.startswith(
        "partial result (sound): rank of Q >= 6 of 8 with derivatives up to y^(1)"
    )
    code, out, err = run(capsys, "--size-budget", "100", "--json")
    assert code == 2 and len(err.splitlines()) == 1
    partial = json.loads(out)["partial"]
    assert partial["rank_lower_bound"] == 6 and partial["rank_by_order"] == [3, 6]
    assert partial["orders_completed"] == 1 and partial["n_unknowns"] == 8


def test_run_summary_prints_the_verdict_and_skips_gearboxes_without_the_shift(capsys):
    from pathlib import Path

    from gearsym.symbolic.loader import load_description

    from gearsym.cmd_observability import print_observability_summary

    print_observability_summary(load_description(None))
    out = capsys.readouterr().out
    assert "Observability of the 2-3 shift (4.1)-(4.12), p = [m_veh, mu_38, mu_05, zeta]" in out
    assert "generic rank of Q with y … y^(2): 8 of 8 (proved by a nonzero minor)" in out
    assert "(4.12) 'rank 8 for all operating points and inputs' fails where:" in out
    assert "F_N05 held at 0 [normal force on B05: element open]: rank 7" in out
    assert "F_N38 and F_N05 constant: rank 7" in out and "(restored by y^(3))" in out
    assert "F_N38 and F_N05 constant, zeta = 0: rank 7" in out and "(persists up to" in out
    simpson = Path(__file__).parent / "data" / "simpson_3speed.toml"
    print_observability_summary(load_description(simpson))
    out = capsys.readouterr().out
    assert out.startswith("observability of the 2-3 shift: skipped (")
