"""Reference simulation of the 2→3 power-on upshift (thesis 3.1): ratios, phases, energy audit,
a second integrator, the reduced models inside their phases, and the command line.

Expected values come from Table 2.1 (the gear ratios), from physics (energy balance, locked
elements do not slip), and from independent methods (BDF against Radau; a trapezoid quadrature
of the sampled input power against the integrated input work).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.description import default_config_text
from gearsym.symbolic.drivetrain import power_on_slip_signs, shift_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.sim.scenario import default_scenario_path, load_scenario
from gearsym.validation.sim.simulate import simulate

TABLE_2_1 = {"2": 3.243, "3": 2.252}
SIMPSON = Path(__file__).parent / "data" / "simpson_3speed.toml"


@pytest.fixture(scope="module")
def description():
    return load_description()


@pytest.fixture(scope="module")
def result(description):
    return simulate(description)


def test_shift_goes_from_the_2nd_to_the_3rd_gear_ratio(result):
    ratio = result.signals["ratio"]
    assert round(ratio[0], 3) == TABLE_2_1["2"]
    assert round(ratio[-1], 3) == TABLE_2_1["3"]


def test_phases_are_detected_in_order_and_cover_the_run(result):
    names = [p.name for p in result.phases]
    assert names == ["gear 2", "torque phase", "speed phase", "gear 3"]
    for a, b in zip(result.phases[:-1], result.phases[1:], strict=True):
        assert a.t_end == b.t_start
        assert a.t_end > a.t_start
    assert result.phases[0].t_start == 0.0
    assert result.phases[-1].t_end == pytest.approx(result.scenario.t_end)


def test_phase_signatures(description, result):
    """What defines each phase physically: the ratio holds through the torque phase, the input
    speed falls in the speed phase, B05 then sticks and K38 slips at the gear-3 kinematics."""
    s, t = result.signals, result.t
    torque, speed, gear3 = result.phases[1], result.phases[2], result.phases[3]
    inside = (t >= torque.t_start) & (t < torque.t_end)
    # the ratio does not move towards gear 3 (the input may flare: K38 was brought to slip)
    assert np.all(s["ratio"][inside] > TABLE_2_1["2"] - 0.02 * (3.243 - 2.252))
    # K38 slides in the flare direction (power_on_slip_signs) at its capacity 2 N r μ F_N (2.69)
    sign = power_on_slip_signs(description, shift_spec(description, "2-3"))["K38"]
    sliding = inside & (np.abs(s["slip_K38"]) > 1.0) & (np.abs(s["T_K38"]) > 5.0)
    assert np.count_nonzero(sliding) > 0.5 * np.count_nonzero(inside)
    assert np.all(np.sign(s["slip_K38"][sliding]) == sign)
    k38 = description.element("K38")
    capacity = 2 * k38.n_disc * k38.r_m.value * s["mu_38"] * s["F_N38"]
    assert np.allclose(np.abs(s["T_K38"][sliding]), capacity[sliding], rtol=1e-3, atol=0.1)
    inside = (t >= speed.t_start) & (t <= speed.t_end)
    assert s["omega_1"][inside][-1] < s["omega_1"][inside][0] - 20
    after = t >= gear3.t_start + 0.05
    assert np.max(np.abs(s["slip_B05"][after])) < 1e-2
    assert np.min(np.abs(s["slip_K38"][after])) > 10


def test_locked_elements_never_slide(description, result):
    """K81 and B06 are closed throughout: their torque stays below the sliding capacity
    2 N_disc r_m μ F_N (2.69), so they only twist elastically (the bristle) and their net slip
    angle stays below the steady-state bristle deflection capacity/σ0."""
    s, t = result.signals, result.t
    sigma0 = description.friction["sigma0"].value
    for element, short in (("K81", "81"), ("B06", "06")):
        e = description.element(element)
        capacity = 2 * e.n_disc * e.r_m.value * s[f"mu_{short}"] * s[f"F_N{short}"]
        assert np.all(np.abs(s[f"T_{element}"]) < capacity)
        slip = s[f"slip_{element}"]
        angle = np.concatenate([[0.0], np.cumsum((slip[1:] + slip[:-1]) / 2 * np.diff(t))])
        assert np.max(np.abs(angle)) < np.min(capacity) / sigma0


def test_initial_state_is_quasi_static(result):
    """At t = 0 the gearbox accelerates as one rigid gear: the closed elements' slips do not
    change and the side shaft does not wind up (φ̇ = 0 and all speeds in the gear's ratios)."""
    s = result.signals
    for element in ("K81", "K38", "B06"):
        slip = s[f"slip_{element}"]  # K38 is closed at t = 0 too
        assert abs(slip[1] - slip[0]) < 1e-6
    assert abs(s["phi"][1] - s["phi"][0]) < 1e-8


def test_energy_audit_closes(result):
    audit = result.audit
    assert audit.relative_residual < 1e-6
    # every dissipation is non-negative (passivity of friction, damper) and the car gains speed
    assert audit.friction_dissipation > 0
    assert audit.damper_dissipation > 0
    assert audit.road_work > 0
    assert audit.kinetic_change > 0


def test_input_work_matches_a_quadrature_of_the_sampled_power(result):
    s = result.signals
    power = s["T_In"] * s["omega_1"]
    trapezoid = float(np.sum((power[1:] + power[:-1]) / 2 * np.diff(result.t)))
    assert trapezoid == pytest.approx(result.audit.input_work, rel=1e-5)


def test_second_integrator_agrees(description, result):
    """BDF (variable order, a different method) against Radau on the same scenario."""
    other = simulate(description, check_models=False, method="BDF", rtol=1e-10)
    for key in ("omega_1", "omega_2", "omega_8", "omega_C"):
        scale = np.max(np.abs(result.signals[key]))
        assert np.max(np.abs(other.signals[key] - result.signals[key])) < 1e-5 * scale, key
    assert [p.name for p in other.phases] == [p.name for p in result.phases]
    for a, b in zip(other.phases, result.phases, strict=True):
        assert abs(a.t_start - b.t_start) <= 1e-3


def test_reduced_models_follow_the_reference_inside_their_phase(result):
    """The rigid gear models and the shift model (2.55–2.58), driven by the reference's input
    and element torques, against the reference whose closed elements are elastic bristles
    (stiffness σ0): they agree to the compliance the bristles add."""
    checks = {c.model: c for c in result.checks}
    assert set(checks) == {"gear_2", "gear_3", "shift_2_3"}
    assert checks["gear_2"].max_relative_error < 1e-3
    assert checks["shift_2_3"].max_relative_error < 2e-2
    assert checks["gear_3"].max_relative_error < 1.5e-2


def test_reduced_model_differences_are_the_bristle_compliance(tmp_path, result):
    """Ten times the bristle stiffness σ0 (σ1 by √10, the same damping ratio): the reduced
    models' differences from the reference shrink about tenfold, so they are the compliance of
    the closed elements, not an error of the reduction."""
    text = default_config_text()
    for old, new in (
        ("sigma0 = { value = 2.0e5,", "sigma0 = { value = 2.0e6,"),
        ("sigma1 = { value = 150.0,", "sigma1 = { value = 474.3,"),
    ):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / "stiff.toml"
    path.write_text(text)
    stiff = simulate(load_description(path))
    soft = {c.model: c.max_relative_error for c in result.checks}
    for c in stiff.checks:
        if c.model != "gear_2":  # gear 2 is already at the integration tolerance
            assert c.max_relative_error < soft[c.model] / 5, (c.model, soft[c.model])


# ----------------------------------------------------------------------------- command line


def gearsym(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, timeout=300
    )


def test_model_json_rhs_parses_back_and_a_matches_5_4(description):
    result = gearsym("model", "--shift", "2-3", "--json")
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert [v["name"] for v in data["states"]] == ["omega_1", "omega_2", "phi", "omega_C"]
    assert [v["name"] for v in data["inputs"]] == ["T_In", "T_K38", "T_B05"]
    names = [v["name"] for g in ("states", "inputs", "parameters") for v in data[g]]
    symbols = {n: sp.Symbol(n) for n in names}
    model = shift_model(description, "2-3")
    rename = {v.symbol: sp.Symbol(v.name) for v in (*model.states, *model.inputs)}
    rename |= {v.symbol: sp.Symbol(v.name) for v in model.parameters}
    for v, expr in zip(model.states, model.rhs, strict=True):
        parsed = sp.parse_expr(data["rhs"][v.name], local_dict=symbols)
        assert sp.simplify(parsed - expr.xreplace(rename)) == 0
    a = np.array(data["linear_form"]["A"])
    # (5.4) printed at the defaults d_ss = 40, k_ss = 1e4: row 3 and the printed coefficients
    assert a[2, 1] == pytest.approx(0.405, abs=5e-4) and a[2, 3] == -1
    assert a[0, 2] == pytest.approx(-1.97 * 1e4, rel=3e-3)
    assert a[1, 1] == pytest.approx(-0.248 * 40, rel=3e-3)


def test_simulate_cli_writes_everything(tmp_path):
    out = tmp_path / "run"
    result = gearsym("simulate", "--out", str(out), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert [p["name"] for p in summary["phases"]][1:3] == ["torque phase", "speed phase"]
    assert summary["energy_audit"]["relative_residual"] < 1e-6
    files = sorted(p.name for p in out.iterdir())
    assert files == sorted(
        [
            "timeseries.csv",
            "phases.csv",
            "summary.json",
            "fig_3_1_speeds.png",
            "fig_3_2_accelerations.png",
            "fig_3_3_torques.png",
            "fig_vehicle_acceleration_jerk.png",
            "MANIFEST",
        ]
    )
    assert all((out / f).stat().st_size > 0 for f in files)
    header = (out / "timeseries.csv").read_text().splitlines()[0].split(",")
    for column in ("t", "omega_1", "T_K38", "T_B05", "slip_B05", "T_In", "T_res", "phi"):
        assert column in header
    assert "simulate [" in result.stderr  # progress display
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # no staging folders left


DEFAULT = default_scenario_path().read_text()
# A missing ']' is reported at the end of the table header's line, like a description's.
_HEADER_LINE = DEFAULT.splitlines().index("[scenario]") + 1

BAD_SCENARIOS = [
    ("[pressure.K38]", "[pressure.K39]", "pressure.K39", "unknown shift element 'K39'"),
    (
        "value = [1.5e6, 1.5e6, 2.3e5, 0.0]",
        "value = [1.5e6, 1.5e6, -2.3e5, 0.0]",
        "pressure.K38.value",
        "pressures must not be negative",
    ),
    (
        "time = [0.0, 0.5, 0.57, 0.75]",
        "time = [0.0, 0.6, 0.57, 0.75]",
        "pressure.K38.time",
        "times must increase strictly",
    ),
    ('shift = "2-3"', 'shift = "2-4"', "scenario.shift", "needs exactly one of each"),
    ("t_end = 1.5", "t_end = -1.5", "scenario.t_end", "must be a positive number"),
    (
        "[scenario]\nname",
        "[scenario\nname",
        f"line {_HEADER_LINE}, column {len('[scenario') + 1}",
        "malformed TOML",
    ),
]


@pytest.mark.parametrize(("old", "new", "key", "reason"), BAD_SCENARIOS)
def test_bad_scenarios_give_one_line_errors(tmp_path, old, new, key, reason):
    assert old in DEFAULT, f"test setup: {old!r} not in the default scenario"
    path = tmp_path / "bad.toml"
    path.write_text(DEFAULT.replace(old, new, 1))
    out = tmp_path / "out"
    result = gearsym("simulate", "--scenario", str(path), "--out", str(out))
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"gearsym: {path}: {key}: ")
    assert reason in lines[0]
    assert not out.exists()


def test_scenario_loader_reads_the_default(description):
    scenario = load_scenario(description)
    assert scenario.shift.off_going == "K38" and scenario.shift.on_coming == "B05"
    assert scenario.input_torque(0.0) == 150.0


def test_run_is_the_main_job_end_to_end(tmp_path):
    """`gearsym run` (what `make run` calls): gear table, observability verdict, simulation,
    FIM summary, and the files of `simulate`, `sensitivity` and `fim` in one folder."""
    out = tmp_path / "run"
    result = gearsym("run", "--out", str(out))
    assert result.returncode == 0, result.stderr
    for text in ("All ratios match", "generic rank of Q", "energy audit", "Fisher information"):
        assert text in result.stdout
    for name in ("timeseries.csv", "summary.json", "fim/fim.json", "sensitivity/sensitivities.csv"):
        assert (out / name).stat().st_size > 0, name
    assert len(list((out / "sensitivity").glob("sensitivity_*.png"))) == 5
    for name in ("stick", "lever", "speeds", "drivetrain"):  # drawn in a child process
        assert (out / "drawings" / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    steps = json.loads((out / "run.json").read_text())["steps"]
    assert set(steps.values()) == {"done"}
    assert json.loads((out / "ratios.json").read_text())["2"] == pytest.approx(3.243, abs=5e-4)
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # no staging folder, no lock left


def test_run_on_another_gearbox_says_what_it_skipped_and_why(tmp_path):
    """A gearbox the built-in 2-3 scenario does not fit: gear table and observability run,
    the simulation is skipped with its reason (stdout and run.json), --out is honoured."""
    out = tmp_path / "simpson"
    result = gearsym("run", str(SIMPSON), "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "All ratios match" in result.stdout
    assert "simulation, sensitivities and FIM skipped: the built-in 2-3 scenario" in result.stdout
    steps = json.loads((out / "run.json").read_text())["steps"]
    assert steps["ratios"] == "done"
    assert steps["simulation"].startswith("skipped: the built-in 2-3 scenario does not fit")
    assert sorted(json.loads((out / "ratios.json").read_text())) == ["1", "2", "3", "N", "R"]


def test_profile_matches_numpy_interp():
    """The scenario's scalar interpolation against np.interp (held constant outside)."""
    from gearsym.validation.sim.scenario import Profile

    rng = np.random.default_rng(3)
    times = np.cumsum(rng.uniform(0.01, 0.2, 12))
    values = rng.uniform(-5.0, 5.0, 12)
    profile = Profile(times, values)
    for t in rng.uniform(times[0] - 0.5, times[-1] + 0.5, 500):
        assert profile(float(t)) == pytest.approx(float(np.interp(t, times, values)), abs=1e-12)


def test_twist_rate_is_recorded_as_2_44(description, result):
    """Fig. 3.2 shows φ̇: the recorded dphi is (2.44), φ̇ = ω_out/i_D − ω_C, at every sample."""
    s = result.signals
    i_d = description.drivetrain["i_D"].value
    expected = s["omega_2"] / i_d - s["omega_C"]
    scale = float(np.max(np.abs(expected)))
    assert scale > 0
    assert float(np.max(np.abs(s["dphi"] - expected))) <= 1e-9 * max(scale, 1.0)
