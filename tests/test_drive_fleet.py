"""Drives of a fleet (validation/studies/drive_fleet.py, `gearsym drive --fleet --runs N`).

The percentiles are checked against numbers computed by hand from synthetic traces; the
fleet's run is checked to drive each vehicle of its seed (the truth differs, the calibration
does not) and the command's options are checked for their one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.cycles import load_cycle
from gearsym.validation.sim.fleet import load_fleet
from gearsym.validation.studies.drive_fleet import DriveFleet, run_drive_fleet


def _run(seed: int, errors: list[float]) -> dict:
    return {
        "seed": seed,
        "drive": {"failure": ""},
        "trace_t": [0.0, 60.0, 300.0, 600.0][: len(errors)],
        "trace_mass_error": errors,
    }


def _three_runs():
    """Three vehicles' mass errors at 0, 60, 300 and 600 s (the percentiles' hand cases)."""
    return [
        _run(0, [0.10, 0.04, 0.02, 0.010]),
        _run(1, [-0.20, -0.05, 0.01, -0.005]),
        _run(2, [0.05, 0.03, -0.03, 0.020]),
    ]


def test_percentiles_by_hand():
    cycle = load_cycle("wltc3b")
    runs = _three_runs()
    stats = DriveFleet(cycle, runs, "test").percentiles()
    # |errors| at 60 s: 0.03, 0.04, 0.05 -> median 0.04; p95 by linear interpolation:
    # 0.04 + 0.9 (0.05 - 0.04) = 0.049
    assert stats["error_at"]["60"]["p50"] == pytest.approx(0.04)
    assert stats["error_at"]["60"]["p95"] == pytest.approx(0.049)
    # the end: 0.005, 0.010, 0.020 -> 0.010 and 0.010 + 0.9 (0.010) = 0.019
    assert stats["error_at"]["end"]["p50"] == pytest.approx(0.010)
    assert stats["error_at"]["end"]["p95"] == pytest.approx(0.019)
    assert stats["vehicles"] == 3


def test_the_mass_targets_judged_by_hand():
    """The drive issue's targets on the p95 of |m_veh error| (3 % after 300 s, 2 % at the end):
    the same three runs as above give p95 0.029 at 300 s (|errors| 0.01, 0.02, 0.03: 0.02 +
    0.9 x 0.01) and 0.019 at the end, both met; a fourth run with 5 % at both misses both; a
    drive that ended before 300 s has not reached that target."""
    from gearsym.validation.studies.drive_fleet import fleet_targets

    cycle = load_cycle("wltc3b")
    runs = _three_runs()
    stats = DriveFleet(cycle, runs, "test").percentiles()
    judged = {(t["what"], t["at"]): t for t in fleet_targets(stats, stats)}
    assert judged[("m_veh", "300")]["p95"] == pytest.approx(0.029)
    assert judged[("m_veh", "300")]["verdict"] == "met"
    assert judged[("m_veh", "end")]["p95"] == pytest.approx(0.019)
    assert judged[("wheel-side mass", "end")]["verdict"] == "met"
    worse = DriveFleet(cycle, [*runs, _run(3, [0.0, 0.0, 0.05, 0.05])], "test").percentiles()
    verdicts = {t["at"]: t["verdict"] for t in fleet_targets(worse, worse)}
    assert verdicts == {"300": "missed", "end": "missed"}
    short = DriveFleet(cycle, [_run(0, [0.01, 0.01])], "test").percentiles()
    judged = {t["at"]: t for t in fleet_targets(short, {})}
    assert judged["300"]["verdict"] == "not reached" and judged["300"]["p95"] is None


def test_end_normalized_errors_by_hand():
    """Each vehicle's (x̂ − x)² / σ² at the end, mean over the vehicles against χ²(N)/N: two
    vehicles with m_veh 2 σ and 0 σ off give 2.0; their band is χ²(2)/2 at 2.5 % and 97.5 %,
    by hand -ln(0.975) = 0.0253 and -ln(0.025) = 3.689 (χ²(2) is exponential with mean 2):
    inside. Against the wheel-side mass (1 σ and 3 σ off): 5.0, above. ζ 0.1 σ off in both:
    0.01, below."""
    from gearsym.validation.studies.drive_fleet import end_normalized_errors

    def run(final, truth, wheel, zeta_error):
        return {
            "estimates": {
                "m_veh": {"final": final, "sigma": 10.0, "truth": truth},
                "zeta": {"final": zeta_error, "sigma": 1.0, "truth": 0.0},
            },
            "wheel_side_mass": {"truth": wheel, "final": final},
        }

    judged = end_normalized_errors(
        [run(1020.0, 1000.0, 1010.0, 0.1), run(1000.0, 1000.0, 970.0, -0.1)]
    )
    mass = judged["m_veh"]
    assert mass["mean"] == pytest.approx(2.0)
    assert mass["band"] == pytest.approx([-np.log(0.975), -np.log(0.025)], rel=1e-6)
    assert mass["verdict"] == "inside" and mass["vehicles"] == 2
    assert judged["wheel-side mass"]["mean"] == pytest.approx(5.0)
    assert judged["wheel-side mass"]["verdict"] == "above"
    assert judged["zeta"]["mean"] == pytest.approx(0.01)
    assert judged["zeta"]["verdict"] == "below"


def test_the_error_against_the_engine_gain_by_hand():
    """Three vehicles whose wheel-side mass errors lie on error = −0.5 (g − 1) + 1 %
    exactly: slope −0.5, intercept 0.01, r −1; fewer than three vehicles, or one gain, give
    no line."""
    from gearsym.validation.studies.drive_fleet import error_against_engine_gain

    def run(gain, error):
        return {
            "vehicle": {"engine_torque_gain": gain},
            "wheel_side_mass": {"truth": 2000.0, "final": 2000.0 * (1.0 + error)},
        }

    runs = [run(g, -0.5 * (g - 1.0) + 0.01) for g in (0.96, 1.0, 1.05)]
    line = error_against_engine_gain(runs)
    assert line["slope"] == pytest.approx(-0.5)
    assert line["intercept"] == pytest.approx(0.01)
    assert line["r"] == pytest.approx(-1.0)
    assert line["vehicles"] == 3
    assert error_against_engine_gain(runs[:2]) == {}
    assert error_against_engine_gain([run(1.02, e) for e in (0.0, 0.01, 0.02)]) == {}


def test_aggregates_by_hand():
    """μ after the third slide counted per element and over all, NEES/NIS percentiles and the
    real-time factor from synthetic run summaries (numbers by hand)."""
    from gearsym.validation.studies.drive_fleet import drive_fleet_markdown, fleet_aggregates

    def run(seed, inside, nees, factor, failure=""):
        third = {"t": 1.0, "truth": 0.1, "error": 0.0, "sigma": 0.01}
        return {
            "seed": seed,
            "drive": {
                "failure": failure,
                "real_time_factor": factor,
                "wall_s": 1800 / factor,
                "missed_shifts": seed * 3,
            },
            "estimates": {
                "m_veh": {"final": 1.0},
                "zeta": {"rms_rad": {"all": 0.01}},
                "mu_38": {"after_third_slide": {**third, "inside_2_sigma": inside[0]}},
                "mu_05": {"after_third_slide": {**third, "inside_2_sigma": inside[1]}},
                "mu_08": {"after_third_slide": None},
            },
            "estimator": {"nees_per_dof_mean": nees, "nis_per_dof": nees / 2},
        }

    runs = [run(0, (True, False), 1.0, 100.0), run(1, (True, True), 3.0, 200.0)]
    out = fleet_aggregates(runs)
    assert out["mu_after_third_slide"]["per_element"] == {
        "mu_38": {"pairs": 2, "inside_2_sigma": 2},
        "mu_05": {"pairs": 2, "inside_2_sigma": 1},
    }
    assert (
        out["mu_after_third_slide"]["pairs"],
        out["mu_after_third_slide"]["inside_2_sigma"],
    ) == (
        4,
        3,
    )
    # two values: p50 the mean, p95 = 1 + 0.95 (3 - 1) = 2.9
    assert out["nees_per_dof"] == pytest.approx({"p50": 2.0, "p95": 2.9})
    assert out["nis_per_dof"] == pytest.approx({"p50": 1.0, "p95": 1.45})
    assert out["real_time_factor"] == pytest.approx({"p50": 150.0, "min": 100.0})
    assert out["drive_wall_s"] == pytest.approx(18.0 + 9.0)
    assert out["missed_shifts"] == 0 + 3
    data = DriveFleet(load_cycle("wltc3b"), runs, "test", 60.0, "in one process").to_dict()
    text = drive_fleet_markdown(data, "gearsym drive --fleet --runs 2")
    assert "3 of 4 (vehicle, element) pairs (mu_38 2 of 2, mu_05 1 of 2)" in text
    assert "1.0 min in one process" in text
    assert "beyond its schedule's shift speeds (validation/sim/drive_schedule.py): 3" in text


def test_fleet_drives_each_vehicle_of_its_seed():
    d = load_description()
    fleet = load_fleet(d)
    cycle = load_cycle("wltc3b").window(18.0)  # the launch starts at 11 s
    result = run_drive_fleet(d, cycle, None, fleet, [10000, 10001])
    masses = [run["drive"]["truth"]["m_veh"] for run in result.runs]
    assert masses == [dict(fleet.draw(s).values)["m_veh"] for s in (10000, 10001)]
    assert all(run["drive"]["failure"] == "" for run in result.runs)
    stats = result.percentiles()
    assert stats["vehicles"] == 2
    # each vehicle's filter learned its mass from the launch: σ from the prior's 300 kg (the
    # [estimator] table) to under half of it
    for run in result.runs:
        sigma = np.asarray(run["trace_mass_sigma"]) * run["drive"]["truth"]["m_veh"]
        assert sigma[0] == pytest.approx(300.0) and sigma[-1] < 300.0 / 2
        # the wheel-side mass is the draw's m_veh times its tyre factor squared, and its error
        # trace the same estimate against it
        m, factor = run["drive"]["truth"]["m_veh"], run["vehicle"]["factor.vehicle.r_dyn"]
        assert factor != 1.0
        assert run["wheel_side_mass"]["truth"] == pytest.approx(m * factor**2, rel=1e-12)
        estimate = m * (1 + np.asarray(run["trace_mass_error"]))
        wheel = run["wheel_side_mass"]["truth"] * (1 + np.asarray(run["trace_wheel_mass_error"]))
        np.testing.assert_allclose(wheel, estimate, rtol=1e-12)
    assert result.to_dict()["wheel_side_mass_error"]["vehicles"] == 2


def gearsym(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, timeout=600
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--runs", "3"], "--runs: more than one drive, or --scheduler, needs --fleet"),
        (["--runs", "0"], "--runs: must be at least 1"),
        (["--fleet", "--seed", "-1"], "--seed: must be at least 0"),
        (["--fleet", "--runs", "2", "--scheduler", "local", "--workers", "0"], "--workers: must"),
        (["--fleet", "--runs", "2", "--scheduler", "udp://x"], "drive: --scheduler: expected"),
    ],
)
def test_fleet_options_one_line(tmp_path, args, message):
    run = gearsym(*["drive", "--duration", "5", *args, "--out", str(tmp_path / "out")])
    assert run.returncode == 2
    assert message in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_cli_fleet_json(tmp_path):
    out = tmp_path / "fleet"
    args = ["drive", "--duration", "14", "--fleet", "--runs", "2", "--seed", "7", "--json"]
    run = gearsym(*[*args, "--out", str(out)])
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert [r["seed"] for r in data["runs"]] == [7, 8]
    assert set(data["mass_error"]["error_at"]) == {"end"}
    for name in ("fleet.json", "fleet.md", "fleet.png"):
        assert (out / name).exists()
    header = (out / "fleet.md").read_text(encoding="utf-8").splitlines()[0]
    assert "`gearsym drive --cycle wltc3b --duration 14 --fleet --runs 2 --seed 7`" in header
    # the grade's RMS error: p50 and p95 over the vehicles, each vehicle's its own
    own = sorted(r["estimates"]["zeta"]["rms_rad"]["all"] for r in data["runs"])
    grade = data["grade_rms_rad"]["all"]
    assert grade["p50"] == pytest.approx(sum(own) / 2) and own[0] <= grade["p95"] <= own[1]
    assert "| grade's RMS error | p50 | p95 |" in (out / "fleet.md").read_text(encoding="utf-8")


def test_a_fleet_file_is_named_in_the_command_line():
    from gearsym.validation.sim.drive_report import drive_command

    assert drive_command("udds", None, "my.toml", 3, 5) == (
        "gearsym drive --cycle udds --fleet my.toml --runs 5 --seed 3"
    )
    assert (
        drive_command("udds", 60.0, "", 3)
        == "gearsym drive --cycle udds --duration 60 --fleet --seed 3"
    )
    assert drive_command("udds", None) == "gearsym drive --cycle udds"


def test_a_fleet_vehicle_s_report_gives_its_wheel_side_mass():
    """A fleet vehicle with tyres 2 % larger than calibrated, truth 2000 kg, estimate 2100 kg:
    the wheel-side mass is 2000 x 1.02² = 2080.8 kg and the estimate's error against it
    +0.92 % (by hand); the calibration's own vehicle (no draw) gets no such line."""
    from gearsym.validation.sim.drive_report import _wheel_side_line

    mass = {"final": 2100.0, "truth": 2000.0}
    (line,) = _wheel_side_line(mass, {"seed": 1, "factor.vehicle.r_dyn": 1.02})
    assert "is 2081 kg" in line and "error against it +0.9 %" in line
    assert _wheel_side_line(mass, None) == []
