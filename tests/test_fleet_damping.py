"""The side shafts' damping d_ss as a state of a shift filter over a fleet (``gearsym estimate
--fleet --params ...,d_ss``): its prior and random walk are the description's damping factor's
times the calibration's d_ss, its truth the vehicle's own damping (for scoring only), and with
it in the model a vehicle whose only difference from the calibration is its damping no longer
needs model error in the gear after the shift."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.estimator_calibration import DAMPING
from gearsym.symbolic.estimators.ekf import augmented_model
from gearsym.validation.sim.fleet import parse_fleet

THESIS = ("m_veh", "mu_38", "mu_05", "zeta")
WITH_STIFFNESS = (*THESIS, "k_ss")
WITH_DAMPING = (*WITH_STIFFNESS, DAMPING)
#: a seed no tuning uses
SEED = 700100


def test_the_damping_state_takes_the_factors_prior_and_random_walk(default_description):
    """d_ss = 40 N·m·s/rad in the description; the damping factor's prior is 1 ± 0.115 (the
    fleet's uniform ±20 %: 0.2/√3), so the state's is 40 ± 4.62; its random walk 1e-6 /s on
    the factor, 1e-6 · 40² = 1.6e-3 (N·m·s/rad)²/s on the state."""
    d = default_description
    d_ss = quantity(d, "drivetrain", DAMPING).value
    assert d_ss == pytest.approx(40.0)
    mean, sd = d.estimator.damping_factor_prior()
    assert mean == 1.0 and sd == pytest.approx(0.2 / 3**0.5, rel=0.01)
    assert d.estimator.prior_of(DAMPING, d_ss) == pytest.approx((40.0, 40.0 * sd))
    aug = augmented_model(d, "2-3", WITH_DAMPING)
    assert aug.intensities[DAMPING] == pytest.approx(1e-6 * 40.0**2)
    assert DAMPING not in augmented_model(d, "2-3", WITH_STIFFNESS).state_names


def _nearly_no_model_error(d):
    """The description with the augmented filter's model-error intensities a hundredth of
    its own: what is left of a model mismatch then shows in the NEES."""
    table = tuple(
        (name, replace(t, value=0.01 * t.value)) for name, t in d.estimator.model_error_augmented
    )
    assert table, "the description states [estimator.model_error_augmented]"
    return replace(d, estimator=replace(d.estimator, model_error_augmented=table))


def _gear_after_nees_per_dof(evaluation) -> float:
    """NEES/dof over the last phase (the gear after the shift) of the one run."""
    from gearsym.validation.studies.estimation.bounds import _phase_samples

    (fr,) = evaluation.runs
    run = fr.run
    last = len(run.phases) - 1
    inside = _phase_samples(run.t, run.phases[last], last=True)
    return float(np.sum(run.nees[inside]) / np.sum(run.nees_dof[inside]))


def _one_vehicle(d, damping_factor: float):
    """The calibration's vehicle (mass 1800 kg) with its side shafts' damping times
    ``damping_factor``."""
    return parse_fleet(
        f'[fleet]\nname = "damping x {damping_factor}"\n'
        'm_veh = { value = 1800.0, unit = "kg", source = "test" }\n'
        f'[fleet.factor]\ndrivetrain.d_ss = {{ value = {damping_factor}, unit = "1", '
        'source = "test" }\n',
        "one_vehicle.toml",
        d,
    )


def test_with_the_damping_a_state_a_less_damped_vehicle_needs_no_model_error_in_gear(
    default_description, default_scenario
):
    """One vehicle, the calibration's in everything but its side shafts' damping (0.8 times
    the calibration's: the twist rings longer after each torque step), filtered with a
    hundredth of the tuned model error. The yardstick is the same filter on the same vehicle
    with the calibration's damping (no mismatch): without d_ss in its model the filter's twist
    decays too fast and the gear after the shift's NEES/dof is more than twice the yardstick's;
    with d_ss a state at least three quarters of that excess is gone, and the damping's estimate
    closes at least a quarter of the gap from the calibration's 40 towards the vehicle's 32
    N·m·s/rad (its truth column) and ends within 3 σ of it."""
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    d = _nearly_no_model_error(default_description)

    def nees(damping_factor: float, parameters):
        evaluation = run_fleet(
            d,
            default_scenario,
            _one_vehicle(d, damping_factor),
            runs=1,
            seed=SEED,
            bound=False,
            parameters=parameters,
        )
        return _gear_after_nees_per_dof(evaluation), evaluation

    yardstick, _ = nees(1.0, WITH_STIFFNESS)
    nees_without, _ = nees(0.8, WITH_STIFFNESS)
    nees_with, with_damping = nees(0.8, WITH_DAMPING)
    assert nees_without > 2.0 * yardstick, (nees_without, yardstick)
    # the state takes away at least three quarters of what the mismatch added
    assert nees_with - yardstick < 0.25 * (nees_without - yardstick), (nees_with, yardstick)
    (fr,) = with_damping.runs
    j = list(fr.run.state_names).index(DAMPING)
    assert fr.run.truth[0, j] == pytest.approx(32.0) and fr.run.scored[:, j].all()
    assert fr.run.estimates[0, j] == pytest.approx(40.0)  # the calibration's, whatever the truth
    assert 32.0 < fr.run.estimates[-1, j] < 40.0 - 0.25 * (40.0 - 32.0)  # a quarter closed
    assert abs(fr.run.estimates[-1, j] - 32.0) < 3 * fr.run.sigmas[-1, j]
