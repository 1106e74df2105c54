"""The side shafts' stiffness k_ss as a state of the shift filter over a fleet
(``gearsym estimate --fleet --params m_veh,mu_38,mu_05,zeta,k_ss``): its prior and random walk
are the description's stiffness factor's times the calibration's k_ss, the twist takes the
intensity tuned for that filter, the truth is the vehicle's own stiffness (for scoring only),
and one shift moves the estimate towards a stiffer vehicle's."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.estimator_calibration import MODEL_ERROR_WITH_STIFFNESS, STIFFNESS
from gearsym.symbolic.estimators.ekf import augmented_model, default_parameters
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.fleet import parse_fleet
from gearsym.validation.sim.scenario import load_scenario

THESIS_AND_STIFFNESS = ("m_veh", "mu_38", "mu_05", "zeta", STIFFNESS)


@pytest.fixture(scope="module")
def d():
    return load_description(None)


@pytest.fixture(scope="module")
def scenario(d):
    return load_scenario(d, None)


def _stated(d, table: str, name: str) -> tuple[None, float]:
    """(None, value) of an intensity, read from the description's table."""
    return None, dict(getattr(d.estimator, table))[name].value


def test_the_stiffness_state_takes_the_factors_prior_and_random_walk(d):
    """k_ss = 10 000 N·m/rad in the description; its prior is the stiffness factor's (1 ±
    0.058: the fleet's uniform ±10 %, 0.1/√3) times it, its random walk the factor's (about
    0.001 per root second) times k_ss², and the states' intensities the
    [estimator.model_error_k_ss] table's, not the thesis filter's [estimator.model_error]."""
    k_ss = quantity(d, "drivetrain", STIFFNESS).value
    mean, sd = d.estimator.stiffness_factor_prior()
    assert mean == 1.0 and sd == pytest.approx(0.1 / 3**0.5, rel=0.01)
    assert d.estimator.prior_of(STIFFNESS, k_ss) == pytest.approx((k_ss, sd * k_ss))
    aug = augmented_model(d, "2-3", THESIS_AND_STIFFNESS)
    walk = d.estimator.stiffness_factor_random_walk()
    assert walk == pytest.approx(1e-6)
    assert aug.intensities[STIFFNESS] == pytest.approx(walk * k_ss**2)
    thesis = augmented_model(d, "2-3", default_parameters(d, "2-3"))
    for name in ("phi", "omega_1", "omega_2", "omega_C"):
        _, own = _stated(d, MODEL_ERROR_WITH_STIFFNESS, name)
        _, thesis_value = _stated(d, "model_error", name)
        assert aug.intensities[name] == own != thesis_value
        # the thesis' filter keeps its own intensities
        assert thesis.intensities[name] == thesis_value
    assert STIFFNESS not in thesis.state_names


def test_one_shift_moves_the_stiffness_towards_a_stiffer_vehicle(d, scenario):
    """A vehicle whose side shafts are 10 % stiffer and otherwise the calibration's: the truth
    column is its k_ss (11 000), the filter starts at the calibration's 10 000 ± 580 and ends
    the shift within 3 σ of 11 000, having closed more than half of the gap (the twist's
    oscillation after the lock-up carries the stiffness against the inertias)."""
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    fleet = parse_fleet(
        '[fleet]\nname = "stiffer"\nm_veh = { value = 1950.0, unit = "kg", source = "test" }\n'
        '[fleet.factor]\ndrivetrain.k_ss = { value = 1.1, unit = "1", source = "test" }\n',
        "stiffer.toml",
        d,
    )
    evaluation = run_fleet(
        d, scenario, fleet, runs=1, seed=700000, bound=False, parameters=THESIS_AND_STIFFNESS
    )
    (fr,) = evaluation.runs
    j = list(fr.run.state_names).index(STIFFNESS)
    truth = 1.1 * quantity(d, "drivetrain", STIFFNESS).value
    assert fr.run.truth[0, j] == pytest.approx(truth) and fr.run.scored[:, j].all()
    start, end, sigma = fr.run.estimates[0, j], fr.run.estimates[-1, j], fr.run.sigmas[-1, j]
    assert start == pytest.approx(10000.0)  # the calibration's, whatever the truth
    assert abs(end - truth) < 0.5 * abs(start - truth), (end, truth)
    assert abs(end - truth) < 3 * sigma, (end, sigma)
    assert evaluation.final_stats(STIFFNESS).runs == 1


def test_tuning_with_the_stiffness_names_its_own_table(d, scenario):
    """Tuned with the stiffness as a state, the result belongs in [estimator.model_error_k_ss]
    and multiplies that table's values, so that the thesis filter's stay their own."""
    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.tuning import tune_model_error

    result = tune_model_error(
        d,
        scenario,
        load_fleet(d),
        [500002],
        factors=(1.0,),
        twist_factors=(0.5,),
        parameters=THESIS_AND_STIFFNESS,
    )
    _, twist = _stated(d, MODEL_ERROR_WITH_STIFFNESS, "phi")
    assert result.intensities["phi"] == pytest.approx(0.5 * twist)
    assert result.table == MODEL_ERROR_WITH_STIFFNESS
    assert f"[estimator.{MODEL_ERROR_WITH_STIFFNESS}]" in result.text()


def _gearsym(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, check=False
    )


def test_the_command_reports_the_stiffness_beside_the_thesis_parameters():
    result = _gearsym(
        "estimate",
        "--filter",
        "ekf",
        "--fleet",
        "--params",
        ",".join(THESIS_AND_STIFFNESS),
        "--runs",
        "1",
        "--seed",
        "700001",
        "--json",
    )
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["initial"][STIFFNESS] == pytest.approx({"value": 10000.0, "sigma": 580.0})
    assert data["parameters"][STIFFNESS]["final"]["runs"] == 1


def test_the_fleet_takes_the_thesis_parameters_with_the_stiffness_or_without_only():
    result = _gearsym("estimate", "--filter", "ekf", "--fleet", "--params", "m_veh,k_ss")
    assert result.returncode == 2 and result.stdout == ""
    (line,) = result.stderr.strip().splitlines()
    assert "--params" in line and "optionally with k_ss" in line, line
