"""The EKF carried over a whole drive (validation/studies/estimation/drive_ekf.py).

What is checked: the filter sees only the TCU's log (the truth changes its scores, never its
estimates); its model hand-over between shifts keeps every common state's estimate and
covariance by name and parks a μ it drops until its element comes back; on a drive whose
vehicle is the calibration's own, the mass ends inside 3σ of the description's value with most
of the prior's uncertainty removed, and the modes follow the TCU's gears.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.cycles import load_cycle
from gearsym.validation.sim.drive import DriveSimulator
from gearsym.validation.studies.estimation.drive_ekf import _hand_over, run_drive_ekf

from tests.test_drive import SHORT


@pytest.fixture(scope="module")
def description():
    return load_description()


@pytest.fixture(scope="module")
def drive(description):
    return DriveSimulator(description, load_cycle(SHORT)).run()


def _filter(description, drive, **options):
    """The EKF over the short drive's log (seed 3), with ``options`` of :func:`run_drive_ekf`."""
    log = drive.log
    return run_drive_ekf(
        description,
        log.arrays(),
        log.shifts(),
        drive.gears,
        drive.values["m_veh"],
        seed=3,
        **options,
    )


@pytest.fixture(scope="module")
def estimates(description, drive):
    return _filter(description, drive)


def test_the_truth_changes_the_scores_not_the_estimates(description, drive, estimates):
    log = drive.log
    other = run_drive_ekf(description, log.arrays(), log.shifts(), drive.gears, 2500.0, seed=3)
    for name in estimates.mean:
        np.testing.assert_array_equal(estimates.mean[name], other.mean[name])
    assert not np.allclose(estimates.nees, other.nees)


def test_the_compiled_steps_give_casadi_s_estimates(description, drive, estimates):
    """The filter's discrete steps as emitted C (the default where a compiler is there) give
    the estimates of CasADi's own calls to rounding (the same operations, CasADi's virtual
    machine against the compiler's: 5e-15 relative over the short drive, 1e-12 of each
    series' largest value allowed)."""
    from gearsym.validation.sim.compiled_c import compiler_available
    from gearsym.validation.studies.estimation.drive_ekf import FilterModels

    if not compiler_available():
        pytest.skip("no C compiler: the filter keeps CasADi's calls")
    models = FilterModels.of(description, compiled=False)
    casadi_s = _filter(description, drive, models=models)
    assert type(models.get("1-2")[1]).__name__ == "DiscreteModel"
    assert type(FilterModels.of(description).get("1-2")[1]).__name__ == "CompiledDiscrete"
    for name in estimates.mean:
        for ours, theirs in ((estimates.mean, casadi_s.mean), (estimates.sigma, casadi_s.sigma)):
            scale = np.nanmax(np.abs(theirs[name]), initial=0.0)
            np.testing.assert_allclose(ours[name], theirs[name], rtol=1e-12, atol=1e-12 * scale)


def test_mass_of_the_calibration_s_own_vehicle(description, estimates):
    """Truth 1800 kg (the description), prior 1950 ± 300 kg (the [estimator] table)."""
    m = estimates.mean["m_veh"][-1]
    sd = estimates.sigma["m_veh"][-1]
    assert abs(m - 1800.0) <= 3 * sd
    assert sd < 300.0 / 3  # most of the prior's variance is gone
    zeta = estimates.mean["zeta"][-1]
    assert abs(zeta) <= 3 * estimates.sigma["zeta"][-1]


def test_models_follow_the_shifts(drive, estimates):
    shifts = drive.log.shifts()
    for k, name in enumerate(shifts):
        if name:
            assert estimates.model[k] == name
    # between shifts the model of the last shift stays
    first = f"{drive.gears[0]}-{drive.gears[1]}"  # the filter starts in the first upshift's
    expected = [first]
    for shift in drive.shifts:
        if shift.name != expected[-1]:
            expected.append(shift.name)
    used = [m for i, m in enumerate(estimates.model) if i == 0 or m != estimates.model[i - 1]]
    assert used == expected


def _model(names):
    return SimpleNamespace(state_names=list(names))


def test_hand_over_by_name_and_the_mu_store():
    old = _model(["omega_1", "omega_2", "phi", "omega_C", "m_veh", "mu_38", "mu_05", "zeta"])
    new = _model(["omega_1", "omega_2", "phi", "omega_C", "m_veh", "mu_81", "mu_27", "zeta"])
    rng = np.random.default_rng(0)
    a = rng.normal(size=(8, 8))
    P = a @ a.T + 8 * np.eye(8)
    z = np.arange(8, dtype=float)
    store = {"mu_27": (0.11, 4e-4)}
    prior = {"mu_81": (0.12, 0.015)}
    z_new, P_new = _hand_over(old.state_names, new.state_names, z, P, store, prior)
    common = ["omega_1", "omega_2", "phi", "omega_C", "m_veh", "zeta"]
    i_old = [old.state_names.index(n) for n in common]
    i_new = [new.state_names.index(n) for n in common]
    np.testing.assert_array_equal(z_new[i_new], z[i_old])
    np.testing.assert_array_equal(P_new[np.ix_(i_new, i_new)], P[np.ix_(i_old, i_old)])
    # μ_81 never seen: the prior; μ_27 from the store, which gives it up
    j81, j27 = new.state_names.index("mu_81"), new.state_names.index("mu_27")
    assert (z_new[j81], P_new[j81, j81]) == (0.12, pytest.approx(0.015**2))
    assert (z_new[j27], P_new[j27, j27]) == (0.11, 4e-4)
    assert "mu_27" not in store
    # the μ the new model lacks wait in the store with their own variance
    assert store["mu_38"] == (z[5], P[5, 5]) and store["mu_05"] == (z[6], P[6, 6])
    # no correlation is invented for what comes from the store or the prior
    assert np.count_nonzero(P_new[j81]) == 1 and np.count_nonzero(P_new[j27]) == 1


def _with_drive_estimator(tmp_path, table: str):
    from gearsym.symbolic.io.package_data import data_file

    text = data_file("thesis_9speed.toml").read_text(encoding="utf-8")
    path = tmp_path / "box.toml"
    path.write_text(text + "\n[drive.estimator]\n" + table, encoding="utf-8")
    return path


def test_drive_estimator_table(tmp_path):
    path = _with_drive_estimator(
        tmp_path,
        'twist_model_error = { value = 2.0e-3, unit = "rad^2/s", source = "test" }\n'
        'tuned_on = "seeds 1-2"\n',
    )
    d = load_description(path)
    assert d.drive.twist_model_error() == 2.0e-3
    assert d.drive.tuned_on == "seeds 1-2"
    assert load_description().drive.twist_model_error() is None


def test_drive_estimator_table_bad_unit(tmp_path):
    from gearsym.symbolic.errors import GearsymError

    path = _with_drive_estimator(
        tmp_path, 'twist_model_error = { value = 2.0e-3, unit = "rad/s", source = "test" }\n'
    )
    with pytest.raises(GearsymError, match=r"drive.estimator.twist_model_error.unit: expected"):
        load_description(path)


def test_twist_model_error_reaches_the_filter(description, drive, estimates):
    other = _filter(
        description, drive, twist_model_error=100 * description.estimator.intensities()["phi"]
    )
    assert not np.array_equal(other.mean["m_veh"], estimates.mean["m_veh"])


def test_the_filter_s_lock_ups_follow_the_plant_s(description, drive, estimates):
    """In each shift the truth's on-coming element stops sliding at its lock-up (its μ has a
    truth only while it slides); the filter, from noisy speeds and the commanded pressures,
    decides the same lock-up within 50 ms (5 samples). A filter that never locks the element
    up would report it at the shift's end, about 0.3 s late. Shifts under the brake (the
    short cycle's downshifts braking to its stop) are not followed: the filter holds."""
    from gearsym.symbolic.estimators.ekf_modes import STICK
    from gearsym.symbolic.shifts import shift_spec

    log = drive.log.arrays()
    shifts = drive.log.shifts()
    t = log["t"]
    checked = 0
    for record in drive.shifts:
        on = shift_spec(description, record.name).on_coming
        inside = np.flatnonzero(np.array([s == record.name for s in shifts]))
        if np.all(log["T_brake"][inside] > 0.0):
            continue  # under the brake the filter holds (its model has no brake)
        sliding = np.flatnonzero(np.isfinite(log[f"truth_mu_{on}"][inside]))
        if not sliding.size:
            continue
        truth_lock = t[inside[sliding[-1]] + 1]
        filter_lock = next(t[k] for k in inside if estimates.modes[k].get(on) == STICK)
        assert abs(filter_lock - truth_lock) <= 0.05 + 1e-9, (record.name, truth_lock, filter_lock)
        checked += 1
    assert checked >= 3


def _one_parameter(name, t, mean, sigma, truth):
    """DriveEstimates of one parameter made by hand (σ constant; no NEES, NIS or held)."""
    from gearsym.validation.studies.estimation.drive_ekf import DriveEstimates

    zeros = np.zeros(len(t))
    return DriveEstimates(
        t=t,
        mean={name: mean},
        sigma={name: np.full(len(t), sigma)},
        truth={name: truth},
        nees=zeros,
        nis=zeros,
        nis_dof=zeros,
        held=0,
    )


def test_the_grade_rms_error_by_hand():
    """The grade's RMS error over the drive and from 60 s on, against a hand computation: an
    estimate 0.03 rad off for the first 60 s and 0.01 rad off after, on a 120 s record at
    1 s: RMS √((60·0.03² + 60·0.01²)/120) = √5 · 0.01 over all, 0.01 from 60 s on."""
    from gearsym.validation.studies.estimation.drive_ekf import GRADE_RMS_FROM

    t = np.arange(120.0)
    truth = np.full(len(t), 0.02)
    mean = truth + np.where(t < 60.0, 0.03, -0.01)
    est = _one_parameter("zeta", t, mean, 0.01, truth)
    assert GRADE_RMS_FROM == 60.0
    rms = est.rms_error("zeta", GRADE_RMS_FROM)
    assert rms["all"] == pytest.approx(np.sqrt(5.0) * 0.01)
    assert rms["after_60"] == pytest.approx(0.01)
    assert est.to_dict()["zeta"]["rms_rad"] == rms


def test_slides_and_the_score_after_the_third_by_hand():
    """A μ whose element slides over samples 10-19, 30-31 and 33-35 (a re-lock 0.1 s long,
    under SLIDE_GAP: one slide), 60-69 and 90-94 of a record at 0.1 s: four slides; after the
    third (its last sample 69, t = 6.9 s) the estimate is 0.01 off with σ 0.004: outside
    2 σ."""
    from gearsym.validation.studies.estimation.drive_ekf import SLIDE_GAP, THIRD

    t = 0.1 * np.arange(100)
    truth = np.full(len(t), np.nan)
    for a, b in ((10, 20), (30, 32), (33, 36), (60, 70), (90, 95)):
        truth[a:b] = 0.12
    mean = np.full(len(t), 0.13)
    est = _one_parameter("mu_05", t, mean, 0.004, truth)
    assert SLIDE_GAP == 0.5
    assert est.sliding_episodes("mu_05") == [(10, 19), (30, 35), (60, 69), (90, 94)]
    entry = est.to_dict()["mu_05"]
    assert THIRD == 3 and entry["slides"] == 4
    third = entry["after_third_slide"]
    assert third["t"] == pytest.approx(6.9) and third["error"] == pytest.approx(0.01)
    assert third["sigma"] == 0.004 and third["inside_2_sigma"] is False


def test_an_appended_state_steps_through_the_inputs(description):
    """A state appended after the model's (the valve's offset, :class:`AppendedState`) moves
    the step only through the inputs: its Jacobian column is CasADi's ∂Φ/∂u times ∂u/∂θ,
    checked against central differences of the whole step with the inputs moved (the step is
    a polynomial in u, so the difference is exact to rounding), and the outputs do not depend
    on it."""
    from gearsym.symbolic.estimators.ekf_modes import OPEN, SLIDE_POS
    from gearsym.validation.studies.estimation.drive_ekf import FilterModels
    from gearsym.validation.studies.estimation.drive_states import _Appended

    aug, discrete, logic = FilterModels(description, {}).get("2-3")
    names = aug.state_names
    nominal = {v.name: v.default for v in aug.model.states if v.default is not None}
    rng = np.random.default_rng(5)
    z = np.array([nominal.get(n, 0.0) or rng.uniform(50.0, 200.0) for n in names])
    z[names.index("m_veh")] = 1900.0
    u = np.zeros(len(aug.input_names))
    u[aug.input_names.index("T_In")] = 150.0
    off, on = logic.elements
    u = logic.inputs(u, {off: OPEN, on: SLIDE_POS})  # the inertia phase
    on_force = logic.normal_force[on]
    u[on_force] = 4.0e3
    du_dtheta = np.zeros((len(u), 1))
    du_dtheta[on_force, 0] = 7.5e-3  # an area, m²: a pressure offset's newtons per pascal
    model = _Appended(discrete, du_dtheta)
    p = aug.parameter_values()
    h = 0.01
    z_ext = np.append(z, 0.0)
    z_next, jac = model.step(z_ext, u, h, p)
    eps = 50.0
    up, _ = discrete.step(z, u + eps * du_dtheta[:, 0], h, p)
    down, _ = discrete.step(z, u - eps * du_dtheta[:, 0], h, p)
    column = (up - down) / (2 * eps)
    assert np.abs(column).max() > 0  # the offset acts
    np.testing.assert_allclose(jac[:-1, -1], column, rtol=1e-6, atol=1e-12)
    assert jac[-1, -1] == 1.0 and z_next[-1] == 0.0
    _, H = model.outputs(z_ext, u, p)
    assert np.all(H[:, -1] == 0.0)


def test_the_valve_offsets_prior_and_random_walk_come_from_the_table(tmp_path):
    """The description's ``[estimator]`` table states the offset state's prior and random
    walk; without them the stated defaults (0 ± 6 000 Pa, 2 500 Pa²/s)."""
    from gearsym.symbolic.description import default_config_text

    assert load_description().estimator.valve_offset_prior() == (0.0, 6.0e3)
    assert load_description().estimator.valve_offset_random_walk() == 2.5e3
    text = default_config_text()
    text = text.replace(
        "[estimator.prior]\n",
        "[estimator.prior]\n"
        "valve_offset = { mean = 500.0, sd = 4.0e3, unit = 'Pa', source = 'x' }\n",
        1,
    ).replace(
        "[estimator.random_walk]\n",
        "[estimator.random_walk]\n"
        "valve_offset = { value = 100.0, unit = 'Pa^2/s', source = 'x' }\n",
        1,
    )
    path = tmp_path / "box.toml"
    path.write_text(text)
    d = load_description(path)
    assert d.estimator.valve_offset_prior() == (500.0, 4.0e3)
    assert d.estimator.valve_offset_random_walk() == 100.0


def test_a_state_that_scales_a_parameter_steps_through_it(description):
    """A state that scales a fixed parameter (:attr:`AppendedState.scales`, the side shafts'
    stiffness factor): its Jacobian column is CasADi's ∂Φ/∂p times the calibration's value,
    checked against central differences of the whole step with k_ss moved."""
    from gearsym.symbolic.estimators.ekf_modes import OPEN, STICK
    from gearsym.validation.studies.estimation.drive_ekf import FilterModels
    from gearsym.validation.studies.estimation.drive_states import _Appended

    aug, discrete, logic = FilterModels(description, {}).get("2-3")
    names = aug.state_names
    z = np.zeros(len(names))
    z[names.index("m_veh")] = 1900.0
    z[names.index("phi")] = 0.02  # twisted: the stiffness acts
    for name in names:
        if name.startswith("omega"):
            z[names.index(name)] = 100.0
    u = np.zeros(len(aug.input_names))
    u[aug.input_names.index("T_In")] = 150.0
    off, on = logic.elements
    u = logic.inputs(u, {off: OPEN, on: STICK})
    parameters = [v.name for v in aug.model.parameters]
    j = parameters.index("k_ss")
    p = aug.parameter_values()
    dp = np.zeros((len(p), 1))
    dp[j, 0] = p[j]
    model = _Appended(discrete, np.zeros((len(u), 1)), dp)
    h = 0.01
    _, jac = model.step(np.append(z, 1.0), u, h, p)
    eps = 1e-3
    up, down = list(p), list(p)
    up[j] *= 1 + eps
    down[j] *= 1 - eps
    column = (discrete.step(z, u, h, up)[0] - discrete.step(z, u, h, down)[0]) / (2 * eps)
    assert abs(column[names.index("omega_C")]) > 0  # the stiffness acts on the wheel
    np.testing.assert_allclose(jac[:-1, -1], column, rtol=1e-6, atol=1e-12)


def test_a_stiffer_vehicle_is_not_read_as_a_lighter_one(description, tmp_path):
    """A vehicle whose side shafts are 9 % stiffer than the calibration's, nothing else
    changed: the filter with the stiffness factor state learns the factor (inside 3 σ) and
    keeps the mass inside 3 σ of the truth; with the calibration's k_ss fixed it reads the
    twist's higher frequency as a lighter vehicle, its mass further below the truth (on this
    short cycle 2 % low; more than 3 σ low before the filter forgot the twist over the
    brake's holds, when a stale twist added its own error)."""
    from gearsym.validation.sim.drive import DriveTruth
    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.drive_states import stiffness_state, stiffness_truth

    fleet_file = tmp_path / "stiff.toml"
    fleet_file.write_text(
        '[fleet]\nname = "stiff"\nsource = "test"\n'
        'm_veh = { value = 1800.0, unit = "kg", source = "test" }\n'
        "[fleet.factor]\n"
        'drivetrain.k_ss = { value = 1.09, unit = "1", source = "test" }\n'
    )
    truth = DriveTruth.from_draw(description, load_fleet(description, fleet_file).draw(0))
    drive = DriveSimulator(description, load_cycle(SHORT), truth=truth).run()
    log = drive.log
    factor = stiffness_truth(description, drive.values)
    assert factor == pytest.approx(1.09)
    args = (description, log.arrays(), log.shifts(), drive.gears, drive.values["m_veh"])
    with_state = run_drive_ekf(*args, seed=3, appended=(stiffness_state(description, factor),))
    without = run_drive_ekf(*args, seed=3)
    entry = with_state.to_dict()["k_ss_factor"]
    assert abs(entry["final"] - factor) <= 3 * entry["sigma"]
    assert entry["sigma"] < 0.058 / 3  # learned, not the prior
    m, sd = with_state.mean["m_veh"][-1], with_state.sigma["m_veh"][-1]
    assert abs(m - 1800.0) <= 3 * sd
    m0 = without.mean["m_veh"][-1]
    assert m0 < 1800.0 and 1800.0 - m0 > abs(m - 1800.0)


def test_a_larger_tyre_reads_as_the_wheel_side_mass(description, tmp_path):
    """Tyres 6 % larger than the calibration's r_dyn, nothing else changed: the wheel equation
    (2.49) carries m_veh r_dyn², the TCU measures the wheel's speed, so the filter (with the
    calibration's r_dyn) identifies m_veh (r_dyn / r_dyn,cal)² = 1.1236 m_veh, the wheel-side
    mass of the fleet's report: the estimate lies inside 3 σ of it and more than 3 σ above the
    vehicle's mass itself (a 12 % gap, more than three times the filter's σ on this short cycle)."""
    from gearsym.validation.sim.drive import DriveTruth
    from gearsym.validation.sim.fleet import R_DYN_FACTOR, load_fleet, wheel_side_mass

    fleet_file = tmp_path / "tyre.toml"
    fleet_file.write_text(
        '[fleet]\nname = "tyre"\nsource = "test"\n'
        'm_veh = { value = 1800.0, unit = "kg", source = "test" }\n'
        "[fleet.factor]\n"
        'vehicle.r_dyn = { value = 1.06, unit = "1", source = "test" }\n'
    )
    draw = load_fleet(description, fleet_file).draw(0)
    assert draw.get(R_DYN_FACTOR, 1.0) == pytest.approx(1.06)
    truth = DriveTruth.from_draw(description, draw)
    drive = DriveSimulator(description, load_cycle(SHORT), truth=truth).run()
    assert drive.failure == ""
    log = drive.log
    args = (description, log.arrays(), log.shifts(), drive.gears, drive.values["m_veh"])
    estimates = run_drive_ekf(*args, seed=3)
    m, sd = estimates.mean["m_veh"][-1], estimates.sigma["m_veh"][-1]
    assert abs(m - wheel_side_mass(1800.0, 1.06)) <= 3 * sd
    assert m > 1800.0 + 3 * sd


def test_the_engine_gain_state_moves_the_engine_s_part_of_the_torque(description, tmp_path):
    """A vehicle whose engine gives 8 % less torque than its torque model says. A filter told
    the true input torque by hand (T_In,cmd + (0.92 − 1) T_eng,cmd in the log) and one with
    the engine's gain as a state held at 0.92 (prior σ 1e-9, no random walk) run the same
    model: their estimates agree to the last digits. Planted: a state that scaled the whole
    input torque (sensitivity T_In,cmd) gives another mass."""
    import dataclasses

    from gearsym.validation.sim.drive import DriveTruth
    from gearsym.validation.sim.fleet import Actuators, load_fleet
    from gearsym.validation.studies.estimation.drive_states import engine_gain_state

    fleet_file = tmp_path / "weak.toml"
    fleet_file.write_text(
        '[fleet]\nname = "weak engine"\nsource = "test"\n'
        'm_veh = { value = 1800.0, unit = "kg", source = "test" }\n'
        'engine_torque_gain = { value = 0.92, unit = "1", source = "test" }\n'
    )
    draw = load_fleet(description, fleet_file).draw(0)
    gain = Actuators.from_draw(draw).engine_gain
    assert gain == pytest.approx(0.92)
    truth = DriveTruth.from_draw(description, draw)
    drive = DriveSimulator(description, load_cycle(SHORT), truth=truth).run()
    assert drive.failure == ""
    log = drive.log.arrays()
    assert np.any(log["T_eng_cmd"] > 0) and np.any(log["T_eng_cmd"] != log["T_In_cmd"])
    told = dict(log, T_In_cmd=log["T_In_cmd"] + (gain - 1.0) * log["T_eng_cmd"])
    rest = (drive.log.shifts(), drive.gears, 1800.0)
    by_hand = run_drive_ekf(description, told, *rest, seed=3)
    held = dataclasses.replace(
        engine_gain_state(description, log, gain), prior=(gain, 1e-9), random_walk=0.0
    )
    as_state = run_drive_ekf(description, log, *rest, seed=3, appended=(held,))
    np.testing.assert_allclose(as_state.mean["m_veh"], by_hand.mean["m_veh"], rtol=1e-6)
    np.testing.assert_allclose(as_state.mean["zeta"], by_hand.mean["zeta"], atol=1e-7)
    whole = dataclasses.replace(held, sensitivity={"T_In": log["T_In_cmd"]})
    planted = run_drive_ekf(description, log, *rest, seed=3, appended=(whole,))
    assert abs(planted.mean["m_veh"][-1] - by_hand.mean["m_veh"][-1]) > 1.0


def test_the_engine_gain_learns_in_the_gears_only(description, drive):
    """The engine's gain state is a consider state through every shift: over the short
    drive's shifts its mean does not move at all, in the gears it does. Planted: the same
    state corrected through the shifts moves there too."""
    import dataclasses

    from gearsym.validation.studies.estimation.drive_states import engine_gain_state

    log = drive.log.arrays()
    in_shift = np.array([bool(s) for s in drive.log.shifts()])
    assert in_shift.sum() > 100 and (~in_shift).sum() > 100

    def moves(state):
        gain = _filter(description, drive, appended=(state,)).mean["engine_torque_gain"]
        step = np.abs(np.diff(gain, prepend=gain[0]))
        return step[in_shift].sum(), step[~in_shift].sum()

    state = engine_gain_state(description, log, 1.0)
    assert not state.learns_in_shifts
    in_shifts, in_gears = moves(state)
    assert in_shifts == 0.0
    assert in_gears > 1e-3
    planted, _ = moves(dataclasses.replace(state, learns_in_shifts=True))
    assert planted > 1e-3


def test_the_log_records_the_engine_s_part_of_the_torque(description, drive):
    """The split rule (validation/sim/drive_powertrain.py): below idle speed the engine is
    decoupled (its commanded part zero, an electric launch); positive demand goes to the
    engine first, so its part never exceeds the commanded input torque, and negative demand is
    the e-machine's alone."""
    log = drive.log.arrays()
    engine, total = log["T_eng_cmd"], log["T_In_cmd"]
    idle = description.drive.si("engine", "n_idle")
    below = log[f"omega_{description.input_shaft}"] < idle - 1.0
    assert np.any(below & (total > 0))  # the launch is electric
    assert np.all(engine[below] == 0.0)
    assert np.all(engine <= np.maximum(total, 0.0) + 1e-9) and np.all(engine >= 0.0)
    assert np.any(engine > 0.0)
    assert np.all(engine[total < 0] == 0.0)


def test_a_mu_is_not_corrected_while_its_element_may_have_locked(description):
    """Fleet vehicle 10001 on the short cycle: every μ inside 2 σ of its truth when its
    element last slid. The filter holds a μ while the element's slip is within a few σ of zero
    and closing (``ambiguous_mu``); planted without that rule, μ27 ends 4 σ low (the filter
    held K27 sliding after the truth had locked it and explained the speeds by its μ)."""
    from gearsym.validation.sim.drive import DriveTruth
    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.drive_ekf import ekf_over_drive

    truth = DriveTruth.from_draw(description, load_fleet(description).draw(10001))
    drive = DriveSimulator(description, load_cycle(SHORT), truth=truth).run()
    scores = {
        name: entry["error_last_sliding"] / entry["sigma_last_sliding"]
        for name, entry in ekf_over_drive(description, drive, 10001).to_dict().items()
        if "error_last_sliding" in entry
    }
    assert len(scores) == 5, scores
    assert all(abs(z) < 2.0 for z in scores.values()), scores
