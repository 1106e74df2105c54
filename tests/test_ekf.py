"""EKF (thesis 4.1, 4.3): the augmented discrete model and its exact Jacobian.

Expected values come from elsewhere than the code under test: the gear ratios of Table 2.1
(a sticking element must make the shift model move in that gear), central finite differences
and CasADi's algorithmic differentiation of the RK4 step (for the chain-rule Jacobian), and a
tight CVODES integration of the same right-hand side with the convergence order of RK4 (global
error ∝ h⁴) for the discretisation.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators.ekf import (
    SAMPLE_TIMES,
    DiscreteModel,
    augmented_model,
)
from gearsym.symbolic.loader import load_description

# a state of the default 2-3 shift in the torque phase (the reference 0.03 s into it, mass and
# μ near their nominal values)
Z0 = np.array([210.9, 64.15, 0.0578, 25.99, 1800.0, 0.109, 0.13, 0.01])
INPUTS = ["T_In", "F_N38", "F_N05", "slide_K38", "stick_K38", "slide_B05", "stick_B05"]
MODES = {
    "gear 2 (K38 sticks, B05 open)": [150.0, 9750.0, 0.0, 0, 1, 0, 0],
    "torque phase (both slide)": [150.0, 1240.0, 300.0, 1, 0, 1, 0],
    "speed phase (B05 slides, K38 open)": [150.0, 0.0, 910.0, 0, 0, 1, 0],
    "gear 3 (B05 sticks, K38 open)": [150.0, 0.0, 10500.0, 0, 0, 0, 1],
}


@pytest.fixture(scope="module")
def aug():
    return augmented_model(load_description(), "2-3")


@pytest.fixture(scope="module")
def discrete(aug):
    return DiscreteModel(aug)


def test_augmented_states_inputs_and_intensities(aug):
    assert aug.state_names == [
        "omega_1",
        "omega_2",
        "phi",
        "omega_C",
        "m_veh",
        "mu_38",
        "mu_05",
        "zeta",
    ]
    assert aug.input_names == INPUTS
    assert aug.n_x == 4 and aug.model.name == "ekf_2_3"
    # random walks (4.1): the parameter rows of the right-hand side are zero
    assert all(e == 0 for e in aug.model.rhs[4:])
    assert all(aug.intensities[name] > 0 for name in aug.state_names)


@pytest.mark.parametrize(("mode", "ratio"), [(0, 3.243), (3, 2.252)])
def test_a_sticking_element_moves_the_shift_model_in_its_gear(discrete, aug, mode, ratio):
    # K38 sticking is gear 2, B05 sticking gear 3: ω̇1/ω̇2 is that gear's ratio (Table 2.1)
    u = list(MODES)[mode]
    z = Z0.copy()
    z[0] = ratio * z[1]  # on the gear's speed relation
    zdot = discrete.rhs(z, MODES[u], aug.parameter_values())
    assert zdot[0] / zdot[1] == pytest.approx(ratio, abs=5e-4)


def test_mu_acts_only_while_its_element_slides(discrete, aug):
    p = aug.parameter_values()
    for name, u in MODES.items():
        J = np.asarray(discrete.J(Z0, u, p))
        slides = {"K38": u[3] == 1, "B05": u[5] == 1}
        # a sticking element's torque depends on the other's μ (the constraint force balances
        # it), so test the μ column of a non-sliding element only
        for element, column in (("K38", 5), ("B05", 6)):
            acts = bool(np.any(J[:4, column] != 0))
            assert acts == slides[element], (name, element)


@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("h", SAMPLE_TIMES)
def test_step_jacobian_is_the_derivative_of_the_step(discrete, aug, mode, h):
    p = aug.parameter_values()
    u = MODES[mode]
    z_next, F = discrete.step(Z0, u, h, p)
    # CasADi's AD of the same step graph (independent of the stage chain rule)
    _, F_ad = discrete.step_ad(Z0, u, h, p)
    np.testing.assert_allclose(F, np.asarray(F_ad), rtol=1e-10, atol=1e-12)
    # central differences, step relative to each state's scale
    fd = np.empty_like(F)
    for j in range(len(Z0)):
        step = 1e-6 * max(abs(Z0[j]), 1e-2)
        plus, minus = Z0.copy(), Z0.copy()
        plus[j] += step
        minus[j] -= step
        fd[:, j] = (discrete.step(plus, u, h, p)[0] - discrete.step(minus, u, h, p)[0]) / (2 * step)
    # compared in the states' own scales (∂z_i/∂z_j · s_j/s_i): the entries span 10 decades
    s = np.maximum(np.abs(Z0), 1e-2)
    assert np.max(np.abs(fd - F) * s[None, :] / s[:, None]) < 1e-7
    # the random-walk rows are identity rows exactly (their estimate is frozen bit for bit)
    assert np.array_equal(F[4:], np.eye(8)[4:]) and np.array_equal(z_next[4:], Z0[4:])


def _cvodes(discrete, aug, z0, u, t_end):
    z = ca.SX.sym("z", len(z0))
    ode = discrete.f(z, ca.DM(u), ca.DM(aug.parameter_values()))
    integrator = ca.integrator(
        "ref", "cvodes", {"x": z, "ode": ode}, 0.0, t_end, {"abstol": 1e-13, "reltol": 1e-13}
    )
    return np.asarray(integrator(x0=z0)["xf"]).ravel()


@pytest.mark.parametrize("mode", list(MODES))
def test_rk4_converges_to_cvodes_with_order_four(discrete, aug, mode):
    u, p = MODES[mode], aug.parameter_values()
    t_end = 0.1  # a divisor of every sample time: 100, 20 and 10 steps
    exact = _cvodes(discrete, aug, Z0, u, t_end)
    scale = np.maximum(np.abs(Z0), 1e-3)
    errors = {}
    for h in SAMPLE_TIMES:
        z = Z0.copy()
        for _ in range(round(t_end / h)):
            z = discrete.step(z, u, h, p)[0]
        errors[h] = float(np.max(np.abs(z - exact) / scale))
    # global error of RK4 ∝ h⁴: halving h from 10 to 5 ms divides it by 16
    assert 16 / 1.6 < errors[0.01] / errors[0.005] < 16 * 1.6, errors
    # and from 5 to 1 ms by 5⁴ = 625 (the CVODES reference is 1e-13 accurate: far below)
    assert 625 / 1.6 < errors[0.005] / errors[0.001] < 625 * 1.6, errors
    # at the thesis' 10 ms the state error over 0.1 s stays below the 1 % sensor error (3.26)
    assert errors[0.01] < 1e-2, errors


def test_unknown_augmented_parameter_is_one_line(aug):
    d = load_description()
    with pytest.raises(GearsymError, match="params: T_In: choose distinct parameters"):
        augmented_model(d, "2-3", parameters=("m_veh", "T_In"))
    with pytest.raises(GearsymError, match="intensities"):
        augmented_model(d, "2-3", intensities={"omega_9": 1.0})


# ------------------------------------------------------- the filter on the reference (4.3)


@pytest.fixture(scope="module")
def reference():
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description()
    return d, simulate(d, load_scenario(d, None))


@pytest.fixture(scope="module")
def ekf_run(reference, aug, discrete):
    from gearsym.validation.studies.estimation.loop import run_ekf

    d, result = reference
    return run_ekf(d, result, sample_time=0.01, seed=0, aug=aug, discrete=discrete)


def test_nees_of_one_run_is_consistent_with_its_chi2_distribution(ekf_run):
    """One run (seed 0): finite NEES, NIS near its χ²(3) mean, the covariance positive definite
    (Joseph form). Its NEES alone says little: over seeds 0–9 the time-averaged NEES/dof of one
    run ranges from 0.5 to 3 (the mass error of a run is one draw), so consistency is judged
    over the ten seeds (next test)."""
    assert np.all(np.isfinite(ekf_run.nees))
    # NIS: three speeds per sample, χ²(3) has mean 3
    assert 1.5 < float(np.mean(ekf_run.nis)) < 6.0
    # Joseph form: the covariance stays symmetric positive definite
    assert ekf_run.min_eigenvalue > 0


def test_nees_over_ten_seeds_is_not_overconfident(reference, aug, discrete):
    """A consistent filter has NEES_k ~ χ²(dof_k). On the calibration's own vehicle, from the
    fixed start, the filter tuned for the fleet (its twist's model error covers the fleet's
    stiffness and torque errors, which this vehicle does not have) is conservative, so only
    the upper side binds here: the seed- and time-averaged NEES/dof below 2 (one run's errors
    are correlated in time, the filter's memory is ~0.1 s, so a factor 2 is what "reasonable"
    means) and at least 95 % of the pooled samples below their per-sample 97.5 % quantile;
    the NIS (three speeds per sample, white innovations) within a factor 2 either side of 1.
    Consistency over the fleet: tests/test_fleet.py."""
    from gearsym.validation.studies.estimation.loop import run_ekf
    from scipy.stats import chi2

    d, result = reference
    runs = [
        run_ekf(d, result, sample_time=0.01, seed=seed, aug=aug, discrete=discrete)
        for seed in range(10)
    ]
    nees = sum(float(np.sum(r.nees)) for r in runs) / sum(float(np.sum(r.nees_dof)) for r in runs)
    used = [r.nis_dof > 0 for r in runs]
    nis = sum(float(np.sum(r.nis[u])) for r, u in zip(runs, used, strict=True)) / sum(
        float(np.sum(r.nis_dof[u])) for r, u in zip(runs, used, strict=True)
    )
    assert nees < 2.0, nees
    assert 0.5 < nis < 2.0, nis
    below = np.mean([np.mean(r.nees <= chi2.ppf(0.975, r.nees_dof)) for r in runs])
    assert below > 0.95, below
    assert all(r.min_eigenvalue > 0 for r in runs)


def test_mass_starts_at_the_calibrations_prior_and_ends_within_its_sigma(ekf_run):
    """The filter starts at the description's [estimator] prior (1950 ± 300 kg, stated for a
    fleet), not at a value made from the truth (1800 kg); one shift shrinks the σ by at least
    40 % and the truth lies inside the filter's own 3σ."""
    (mass,) = [p for p in ekf_run.parameters if p.name == "m_veh"]
    assert mass.initial == 1950.0 and mass.truth == 1800.0
    j = list(ekf_run.state_names).index("m_veh")
    assert ekf_run.sigmas[0, j] == 300.0
    assert abs(mass.estimate - mass.truth) < 3 * mass.sigma
    assert mass.sigma < 0.6 * 300.0


def test_mass_converges_towards_the_truth_from_30_percent_light(reference, aug, discrete):
    """Started 30 % light (--initial m_veh=1260), the shift moves the mass well towards the
    truth and the truth lies inside the filter's own 3σ."""
    from gearsym.validation.studies.estimation.loop import run_ekf

    d, result = reference
    run = run_ekf(d, result, seed=0, aug=aug, discrete=discrete, initial={"m_veh": 1260.0})
    (mass,) = [p for p in run.parameters if p.name == "m_veh"]
    assert mass.initial == 1260.0 == pytest.approx(0.7 * mass.truth)
    error = abs(mass.estimate - mass.truth)
    assert error < 0.5 * abs(mass.initial - mass.truth)
    assert error < 3 * mass.sigma


def _sliding_windows(result) -> dict[str, tuple[float, float]]:
    """When each swapping element of the reference slides, from the scenario and the detected
    phases: K38 from the torque phase's start until its pressure reaches zero (it opens), B05
    from the moment its fill pressure rises until the speed phase ends (it locks up)."""
    scenario = result.scenario
    k38, b05 = scenario.pressure["K38"], scenario.pressure["B05"]
    k38_open = float(k38.time[np.flatnonzero(k38.value == 0.0)[0]])
    b05_fill = float(b05.time[np.flatnonzero(b05.value > 0.0)[0] - 1])
    return {
        "mu_38": (result.phase("torque phase").t_start, k38_open),
        "mu_05": (b05_fill, result.phase("speed phase").t_end),
    }


@pytest.fixture(scope="module")
def reference_modes_run(reference, aug, discrete):
    """The run with the reference's element modes (``modes="reference"``): their sliding
    windows are the scenario's; the filter's own modes are tested in tests/test_ekf_modes.py."""
    from gearsym.validation.studies.estimation.loop import run_ekf

    d, result = reference
    return run_ekf(
        d, result, sample_time=0.01, seed=0, aug=aug, discrete=discrete, modes="reference"
    )


def test_mu_is_frozen_while_its_element_does_not_slide(reference_modes_run, reference):
    ekf_run = reference_modes_run
    names = list(ekf_run.state_names)
    for mu, slides in _sliding_windows(reference[1]).items():
        j = names.index(mu)
        sliding = ekf_run.scored[:, j]
        t_slide = ekf_run.t[sliding]
        # the reference's sliding windows (K38 from the torque phase until it opens, B05 from
        # its fill until it locks), to a sample
        assert t_slide[0] == pytest.approx(slides[0], abs=0.011)
        assert t_slide[-1] == pytest.approx(slides[1], abs=0.011)
        before = ekf_run.t < t_slide[0]
        # before the element first slides: the prior, to the bit (0.12 nominal; σ 0.015 from
        # the description's [estimator] table)
        assert np.all(ekf_run.estimates[before, j] == 0.12)
        assert np.all(ekf_run.sigmas[before, j] == 0.015)
        # after it stops sliding: the last estimate, and the σ at the end of the last sample
        # interval in which it slid (the inputs are held, so it slid until then), to the bit
        after = np.flatnonzero(ekf_run.t > t_slide[-1])
        assert np.all(ekf_run.estimates[after, j] == ekf_run.estimates[after[0] - 1, j])
        assert np.all(ekf_run.sigmas[after, j] == ekf_run.sigmas[after[0], j])
        # while sliding, the measurements move it
        assert np.ptp(ekf_run.estimates[sliding, j]) > 0


def test_dropout_skips_updates_and_no_nan_enters_the_state(reference, aug, discrete, ekf_run):
    from gearsym.validation.studies.estimation.loop import run_ekf

    d, result = reference
    # 0.2 s without measurements early in gear 3, then 0.1 s to recover
    gear_3 = result.phase("gear 3").t_start
    start, end, back_at = gear_3 + 0.02, gear_3 + 0.22, gear_3 + 0.32
    run = run_ekf(d, result, sample_time=0.01, aug=aug, discrete=discrete, dropout=(start, end))
    lost = (run.t >= start) & (run.t < end)
    assert np.all(np.isfinite(run.estimates)) and np.all(np.isfinite(run.sigmas))
    assert np.all(run.nis_dof[lost] == 0) and np.all(run.nis_dof[~lost][1:] == 3)
    assert run.nis_dof[0] == 0  # the first speeds are the initial estimate: not used again
    # without measurements the speeds' σ is the prediction's (it swings with the drivetrain
    # mode, 2.44-2.47, so not monotonic) and above the σ with measurements; before the
    # dropout the two runs are the same run
    j = list(run.state_names).index("omega_2")
    inside = np.flatnonzero(lost)
    assert np.all(run.sigmas[inside, j] > ekf_run.sigmas[inside, j])
    before = run.t < start
    np.testing.assert_array_equal(run.estimates[before], ekf_run.estimates[before])
    # after it the filter recovers: the state's error is back inside 3σ
    back = np.flatnonzero(run.t >= back_at)
    error = np.abs(run.estimates[back, j] - run.truth[back, j])
    assert np.all(error < 3 * run.sigmas[back, j])


def test_estimate_ekf_command(tmp_path):
    import json
    import subprocess
    import sys

    def gearsym(*args):
        return subprocess.run(
            [sys.executable, "-m", "gearsym", "estimate", "--filter", "ekf", *args],
            capture_output=True,
            text=True,
            timeout=300,
        )

    out = tmp_path / "est"
    run = gearsym("--json", "--out", str(out), "--initial", "m_veh=1500")
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert data["filter"] == "ekf" and data["shift"] == "2-3" and data["runs"] == 1
    assert set(data["parameters"]) == {"m_veh", "mu_38", "mu_05", "zeta"}
    for key in ("truth", "initial", "estimate", "sigma", "rmse", "crb_sigma", "efficiency"):
        assert key in data["parameters"]["m_veh"]
    assert data["parameters"]["m_veh"]["initial"] == 1500.0
    # the filter decided its element modes itself (default) and says how close it came
    assert data["modes"] == "filter"
    assert {(e["element"], e["kind"]) for e in data["events"]} >= {
        ("K38", "break-away"),
        ("B05", "lock-up"),
    }
    for event in data["events"]:
        if event["t_reference"] is not None:
            assert event["detected_runs"] == 1 and abs(event["error_ms_mean"]) <= 20.0
    assert "run 1 of 1" in run.stderr  # the Monte-Carlo progress bar (one run by default)
    for key in ("nees_mean", "nees_band", "nis_mean", "phases", "sample_time"):
        assert key in data
    mass = data["parameters"]["m_veh"]
    # one run: rmse is that run's error; the matched bound and the efficiency are filled in
    assert mass["crb_sigma"] > 0 and mass["efficiency"] == pytest.approx(
        mass["rmse"] / mass["crb_sigma"]
    )
    assert "m_veh" in data["parameters"] and isinstance(mass["identifiable"], list)
    assert sorted(p.name for p in out.iterdir()) == [
        "MANIFEST",
        "ekf.csv",
        "ekf.json",
        "ekf.png",
        "ekf_efficiency.png",
    ]
    header = (out / "ekf.csv").read_text().splitlines()[0].split(",")
    assert header[:5] == ["t", "phase", "omega_1_hat", "omega_1_sigma", "omega_1"]
    assert header[-2:] == ["mode_K38", "mode_B05"]
    for bad, key in (
        (("--initial", "m_veh"), "--initial"),
        (("--initial", "m_car=3"), "--initial"),
        (("--params", "m_veh,T_In"), "params"),
        (("--noise", "0"), "--noise"),
        (("--runs", "0"), "--runs"),
        (("--runs", "2", "--filter", "uio"), "--runs"),
        (("--modes", "filter", "--filter", "uio"), "--modes"),
    ):
        result = gearsym(*bad, "--out", str(tmp_path / "never"))
        assert result.returncode == 2 and key in result.stderr, (bad, result.stderr)
        assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
        assert not (tmp_path / "never").exists()


def test_a_missing_first_speed_leaves_the_others_updating(aug, discrete):
    """One sensor out (ω_1 NaN): the update must use the other two speeds as the batch Kalman
    update with those rows does, K = P Hᵀ (H P Hᵀ + R)⁻¹, z⁺ = z + K ν, P⁺ = (I − K H) P
    (the outputs are the states ω_2, ω_C, so H selects them; R from (3.26) at the measured
    values), with its NIS νᵀ (H P Hᵀ + R)⁻¹ ν on 2 dof. In the torque phase both μ slide, so
    no state is held out of the update."""
    from gearsym.symbolic.estimators.ekf import ekf_update

    u, p = MODES["torque phase (both slide)"], aug.parameter_values()
    sigma = np.array([2.0, 0.6, 0.05, 0.3, 200.0, 0.01, 0.01, 0.02])
    rng = np.random.default_rng(3)
    a = rng.normal(size=(8, 8)) * 0.2
    P = np.diag(sigma) @ (np.eye(8) + a @ a.T) @ np.diag(sigma)  # correlated, SPD
    y = np.array([np.nan, 64.9, 25.7])  # ω_2 and ω_C measured, ω_1 lost
    relative, floor = [0.01, 0.01, 0.01], [1.0, 1.0, 1.0]
    z_new, P_new, nis, used = ekf_update(discrete, Z0, P, u, y, p, relative, floor)
    H = np.zeros((2, 8))
    H[0, 1] = H[1, 3] = 1.0  # ω_2, ω_C
    R = np.diag((0.01 * y[1:]) ** 2)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    nu = y[1:] - H @ Z0
    assert used == 2
    np.testing.assert_allclose(z_new, Z0 + K @ nu, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P_new, (np.eye(8) - K @ H) @ P, rtol=1e-9, atol=1e-12)
    assert nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-10)
