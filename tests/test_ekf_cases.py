"""EKF (thesis 4.3) cases of the evaluation (issue 16, item 6), one single run each.

Every time comes from the phases the reference simulation detects (never a literal time: the
default scenario's times may move). Expected values come from the scenario (the true grade,
the description's mass), from the filter's stated prior, and from a hand derivation of the
prediction of a random-walk parameter (4.1): its state equation is p' = 0, so its row of the
step Jacobian is a unit row and, with no update, its variance grows by exactly h q per sample.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.estimators.ekf import DiscreteModel, augmented_model
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.scenario import default_scenario_path, load_scenario
from gearsym.validation.sim.simulate import simulate
from gearsym.validation.studies.estimation.loop import filter_run, run_ekf
from gearsym.validation.studies.estimation.setup import prepare_ekf

DATA = Path(default_scenario_path()).parent
GRADE = math.atan(0.04)  # a 4 % grade: tan ζ = 0.04


@pytest.fixture(scope="module")
def d():
    return load_description()


@pytest.fixture(scope="module")
def aug(d):
    return augmented_model(d, "2-3")


@pytest.fixture(scope="module")
def discrete(aug):
    return DiscreteModel(aug)


@pytest.fixture(scope="module")
def level(d):
    return simulate(d, load_scenario(d, None))


def phase(result, name):
    (found,) = [p for p in result.phases if p.name == name]
    return found


def final(run, name):
    j = list(run.state_names).index(name)
    return run.estimates[-1, j], run.sigmas[-1, j], j


def test_constant_4_percent_grade_is_found_within_3_sigma(d, aug, discrete):
    result = simulate(d, load_scenario(d, DATA / "scenario_2_3_grade4.toml"))
    assert np.allclose(result.signals["zeta"], GRADE, atol=1e-7)  # the scenario's truth
    run = run_ekf(d, result, aug=aug, discrete=discrete)
    zeta, sigma, _ = final(run, "zeta")
    assert abs(zeta - GRADE) < 3 * sigma  # inside its own 3σ
    assert abs(zeta - GRADE) < 0.5 * GRADE  # and moved from 0 most of the way to 0.04
    assert sigma < 0.5 * 0.05  # the data halved the prior σ (0.05 rad)
    mass, sigma_m, _ = final(run, "m_veh")
    truth = d.vehicle["m_veh"].value
    assert abs(mass - truth) < 3 * sigma_m and abs(mass - truth) < 0.5 * 0.3 * truth


@pytest.mark.parametrize("modes", ["filter", "reference"])
def test_grade_step_during_the_shift_moves_the_grade_estimate_up(
    d, aug, discrete, level, tmp_path, modes
):
    torque = phase(level, "torque phase")
    at = 0.5 * (torque.t_start + torque.t_end)  # the middle of the torque phase
    path = tmp_path / "step.toml"
    path.write_text(
        default_scenario_path().read_text(encoding="utf-8")
        + f'\n[grade]\nunit = "rad"\ntime = [0.0, {at}, {at + 0.001}]\n'
        + f"value = [0.0, 0.0, {GRADE}]\n"
    )
    result = simulate(d, load_scenario(d, path))
    run = run_ekf(d, result, aug=aug, discrete=discrete, modes=modes)
    zeta, sigma, j = final(run, "zeta")
    before = run.estimates[run.t < at, j][-1]
    assert abs(before) < 3 * run.sigmas[run.t < at, j][-1]  # level until the step
    # after it, the estimate ends nearer the new grade than the level road it started on (the
    # last estimate before the step has σ ≈ GRADE, so a difference to it would test noise)
    assert zeta > 0.5 * GRADE
    assert abs(zeta - GRADE) < 3 * sigma


@pytest.mark.parametrize("factor", [0.7, 1.5])
def test_wrong_initial_mass_moves_towards_the_truth(d, aug, discrete, level, factor):
    truth = d.vehicle["m_veh"].value
    run = run_ekf(d, level, aug=aug, discrete=discrete, initial={"m_veh": factor * truth})
    mass, sigma, _ = final(run, "m_veh")
    assert abs(mass - truth) < 0.5 * abs(factor - 1) * truth  # at least halfway to the truth
    assert abs(mass - truth) < 3 * sigma


@pytest.fixture(scope="module")
def setup(d, level, aug, discrete):
    return prepare_ekf(d, level, aug=aug, discrete=discrete)


@pytest.mark.parametrize("outputs", [None, ["omega_C"]], ids=["all speeds", "omega_C only"])
def test_sensor_dropout_over_the_speed_phase(setup, level, aug, outputs):
    gap = phase(level, "speed phase")
    run = filter_run(setup, seed=0, dropout=(gap.t_start, gap.t_end), dropout_outputs=outputs)
    assert np.all(np.isfinite(run.estimates)) and np.all(np.isfinite(run.sigmas))
    lost = (run.t >= gap.t_start) & (run.t < gap.t_end)
    used = len(setup.outputs) - (len(outputs) if outputs else len(setup.outputs))
    assert np.all(run.nis_dof[lost] == used) and np.all(run.nis_dof[~lost][1:] == 3)
    assert run.nis_dof[0] == 0  # the first speeds are the initial estimate: not used again
    if outputs is None:
        # no update in the gap: each random-walk parameter's variance grows by exactly h q
        h = setup.t[1] - setup.t[0]
        for name in ("m_veh", "zeta"):
            j = list(run.state_names).index(name)
            k = np.flatnonzero(lost)[1:]  # a prediction from a sample of the gap itself
            growth = run.sigmas[k, j] ** 2 - run.sigmas[k - 1, j] ** 2
            np.testing.assert_allclose(growth, h * aug.intensities[name], rtol=1e-6)


def test_element_that_never_slides_keeps_its_prior(d, aug, discrete):
    result = simulate(d, load_scenario(d, DATA / "scenario_2_3_k38_never_slides.toml"))
    run = run_ekf(d, result, aug=aug, discrete=discrete)
    j = list(run.state_names).index("mu_38")
    assert not run.scored[:, j].any()  # the reference never has K38 at its capacity
    # the stated prior (the description's nominal μ 0.12; σ 0.015 from its [estimator]
    # table), to the bit, every sample
    assert np.all(run.estimates[:, j] == 0.12) and np.all(run.sigmas[:, j] == 0.015)
    # B05 does slide in the same run, and its μ moves
    assert np.ptp(run.estimates[:, list(run.state_names).index("mu_05")]) > 0


def test_estimate_command_runs_the_cases_and_states_what_it_assumes():
    import subprocess
    import sys

    def gearsym(*args):
        return subprocess.run(
            [sys.executable, "-m", "gearsym", "estimate", "--filter", "ekf", *args],
            capture_output=True,
            text=True,
            timeout=300,
        )

    run = gearsym(
        "--scenario",
        str(DATA / "scenario_2_3_grade4.toml"),
        "--initial",
        "m_veh=2700",
        "--dropout",
        "speed_phase",
        "--dropout-outputs",
        "omega_C",
    )
    assert run.returncode == 0, run.stderr
    assert "assumes scenario: power-on upshift 2-3 on a 4 % grade" in run.stdout
    assert "assumes sensor dropout: omega_C missing (NaN) in [" in run.stdout
    assert "2700" in run.stdout
    for bad, key in (
        (("--dropout", "0.5"), "--dropout"),
        (("--dropout", "0.6,0.5"), "--dropout"),
        (("--dropout", "clutch_phase"), "--dropout"),
        (("--dropout-outputs", "omega_C"), "--dropout-outputs"),
        (("--dropout", "0,1", "--dropout-outputs", "omega_9"), "--dropout-outputs"),
        (("--drive", "one.toml"), "--drive"),
        (("--drive", "upshifts", "--runs", "2"), "--runs"),
        (("--drive", "upshifts", "--initial", "mu_38=0.1"), "--initial"),
    ):
        result = gearsym(*bad)
        assert result.returncode == 2 and key in result.stderr, (bad, result.stderr)
        assert result.stderr.strip().count("\n") == 0 and "Traceback" not in result.stderr


def test_drive_of_upshifts_1_2_3_4_carries_mass_and_grade(d, level):
    from gearsym.validation.studies.estimation.loop import run_ekf_drive

    results = [
        simulate(d, load_scenario(d, DATA / "scenario_1_2.toml")),
        level,
        simulate(d, load_scenario(d, DATA / "scenario_3_4.toml")),
    ]
    assert [r.scenario.shift.name for r in results] == ["1-2", "2-3", "3-4"]
    runs = run_ekf_drive(d, results)
    truth = d.vehicle["m_veh"].value
    sigmas = []
    for k, run in enumerate(runs):
        mass, sigma, j = final(run, "m_veh")
        assert abs(mass - truth) < 3 * sigma
        if k > 0:  # each shift starts where the previous one ended (estimate and σ)
            start = {p.name: p.initial for p in run.parameters}
            assert start["m_veh"] == final(runs[k - 1], "m_veh")[0]
            assert start["zeta"] == final(runs[k - 1], "zeta")[0]
        sigmas.append(sigma)
    # information accumulates: the σ of m_veh after shift k+1 is at most the one after shift k
    assert sigmas[1] <= sigmas[0] and sigmas[2] <= sigmas[1]
    # and the last shift's σ is below a single 2-3's σ from the prior (the same noise seed)
    alone = run_ekf(d, level, seed=1)
    assert sigmas[1] < final(alone, "m_veh")[1]


def test_estimate_command_runs_the_drive():
    import json
    import subprocess
    import sys

    run = subprocess.run(
        [sys.executable, "-m", "gearsym", "estimate", "--filter", "ekf", "--drive", "upshifts"]
        + ["--json", "--initial", "m_veh=2700"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    drive = json.loads(run.stdout)["drive"]
    assert [r["shift"] for r in drive] == ["1-2", "2-3", "3-4"]
    masses = [r["parameters"]["m_veh"] for r in drive]
    assert masses[0]["initial"] == 2700.0
    assert masses[1]["initial"] == masses[0]["estimate"]  # carried
    assert masses[2]["sigma"] <= masses[1]["sigma"] <= masses[0]["sigma"]
