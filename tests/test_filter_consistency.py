"""NEES and NIS of the EKF (4.3) and of the extended UIO (4.5) against their χ² bands, with the
filter mistuned by a factor 2 in R or in Q run alongside and shown to fail the band.

Why a synthetic truth: the reference simulation is deterministic, so along it the process noise
Q of the filter is a model-error allowance, not a distribution the truth was drawn from, and a
doubled Q (or R) still passed every fast test of the filters (issue 31). The textbook check
(Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001,
5.4) simulates the filter's own stated model with its stated noises: then a consistent filter's
NIS over all samples is χ² with the summed dof (its innovations are white) and its NEES at one
time over independent runs is χ² with n·runs dof; the band below is that distribution's 99 %
interval, divided by the dof.

Expected values: the truth's noises are read here from the description file itself (its
``[estimator.model_error]`` and ``[estimator.random_walk]`` intensities, parsed with tomllib)
and from the thesis' measurement model (3.26), 1 % of the measured speed; the filter's are
what the estimation runs use (``prepare_ekf``'s q, relative error and floor; the EUIO's
``measurement_variances``). The filter under test is the library's own steps
(``ekf_predict``/``ekf_update``, ``euio_step_full``).

The state: the default 2-3 shift's torque phase (both elements slide, so every μ is estimated;
as tests/test_ekf.py), inputs held, 40 samples of 10 ms per run. The truth's parameters start
at the calibration's nominal values and the filter's estimate at a draw from its prior, whose σ
for the parameters is 0.3 × the description's: at the full prior (m_veh ± 300 kg, 17 %) the
EKF's linearisation alone raises the NEES/dof to 1.05–1.07 (measured over 300 runs), a
separate effect from the tuning this test is about.

Measured (seed 31, 200 runs of each filter): EKF NIS/dof 1.00, NEES/dof 1.05 (bands 0.977–1.024
and 0.911–1.093); R × 2: NIS/dof 0.55; Q × 2: NEES/dof 0.77 (NIS/dof 0.95). EUIO NIS/dof 1.01,
NEES/dof 0.97 (bands 0.971–1.029 and 0.905–1.100); R × 2: NIS/dof 0.55; Q × 2: NEES/dof 0.78
(NIS/dof 0.94).

Below them: the EKF and the extended UIO with their own mode logic through a break-away, an
opening and a lock-up (the same bands, and each μ's own), and the EKF's accuracy against the
posterior Cramér–Rao bound. About 2 min on one core.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.loader import load_description
from scipy.stats import chi2

# a state of the default 2-3 shift in the torque phase and its inputs (tests/test_ekf.py)
Z0 = {
    "omega_1": 210.9,
    "omega_2": 64.15,
    "phi": 0.0578,
    "omega_C": 25.99,
    "m_veh": 1800.0,
    "mu_38": 0.109,
    "mu_05": 0.13,
    "zeta": 0.01,
}
TORQUE_PHASE = [150.0, 1240.0, 300.0, 1, 0, 1, 0]  # T_In, F_N38, F_N05, slide/stick K38, B05
H = 0.01  # s, the thesis' sample time
STEPS = 40
RELATIVE = 0.01  # (3.26): 1 % of the measured value
PRIOR_SCALE = 0.3  # the parameters' prior σ relative to the description's (module text)
PROBABILITY = 0.99
BUILT_IN = Path(__file__).resolve().parents[1] / "gearsym" / "data" / "thesis_9speed.toml"
MISTUNED = {"consistent": (1.0, 1.0), "R doubled": (2.0, 1.0), "Q doubled": (1.0, 2.0)}


def band(dof: float) -> tuple[float, float]:
    """The 99 % interval of χ²(dof)/dof: where a consistent filter's summed statistic lies."""
    lo, hi = chi2.ppf([(1 - PROBABILITY) / 2, (1 + PROBABILITY) / 2], dof)
    return float(lo / dof), float(hi / dof)


@pytest.fixture(scope="module")
def stated():
    """Per state name, (process-noise intensity, prior σ) as the description file states them:
    the model error of the speeds and the twist, the random walks of the parameters (one
    ``mu`` entry for every μ)."""
    with open(BUILT_IN, "rb") as fh:
        est = tomllib.load(fh)["estimator"]
    rates = {name: entry["value"] for name, entry in est["model_error"].items()}
    rates.update({name: entry["value"] for name, entry in est["random_walk"].items()})
    prior = {name: entry["sd"] for name, entry in est["prior"].items()}
    for mu in ("mu_38", "mu_05"):
        rates[mu], prior[mu] = rates["mu"], prior["mu"]
    return rates, prior


@pytest.fixture(scope="module")
def reference():
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description()
    return d, simulate(d, load_scenario(d, None))


def _truth_noise(names, rates, prior, y0, outputs):
    """(√(h q) per state, the prior σ per state): the speeds' prior is their first
    measurement's σ (3.26), the twist's and the parameters' the description's."""
    root_q = np.array([np.sqrt(H * rates[name]) for name in names])
    sigma0 = np.empty(len(names))
    for j, name in enumerate(names):
        if name in outputs:
            sigma0[j] = RELATIVE * abs(y0[outputs.index(name)])
        elif name == "phi":
            sigma0[j] = prior[name]
        else:
            sigma0[j] = PRIOR_SCALE * prior[name]
    return root_q, sigma0


def _statistics(nis, nis_dof, nees_end, n):
    nis_mean = float(np.sum(nis) / np.sum(nis_dof))
    nees_mean = float(np.sum(nees_end) / (n * len(nees_end)))
    return nis_mean, band(float(np.sum(nis_dof))), nees_mean, band(float(n * len(nees_end)))


def _judge(case, nis, nis_band, nees, nees_band):
    print(f"{case}: NIS/dof {nis:.3f} in {nis_band}, NEES/dof {nees:.3f} in {nees_band}")
    if case == "consistent":
        assert nis_band[0] < nis < nis_band[1], (nis, nis_band)
        assert nees_band[0] < nees < nees_band[1], (nees, nees_band)
    elif case == "R doubled":  # the innovations look too small for the filter's R
        assert nis < nis_band[0], (nis, nis_band)
    else:  # Q doubled: the filter thinks its errors are larger than they are
        assert nees < nees_band[0], (nees, nees_band)


#: Plants for the accuracy check (:func:`test_ekf_accuracy_against_the_posterior_bound`): a
#: filter that drops its input speed sensor (ω_1) states its own, larger P, so NEES and NIS stay
#: consistent; only a bound computed from every sensor shows what it gave away.
DROPPED_OUTPUT = {"consistent": None, "input speed unused": 0}


@pytest.fixture(scope="module")
def ekf_runs(reference, stated):
    """The EKF's Monte-Carlo on its own stated model, per (R factor, Q factor, dropped
    output), computed once: (NIS per sample, its dof, NEES at the end, the error z − ẑ at the
    end per run, the setup, the truth's √(h q), σ0)."""
    from gearsym.symbolic.estimators.ekf import ekf_predict, ekf_update
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    d, result = reference
    setup = prepare_ekf(d, result, modes="reference")
    cache: dict[tuple, tuple] = {}

    def run(r_factor: float, q_factor: float, dropped: int | None = None) -> tuple:
        key = (r_factor, q_factor, dropped)
        if key in cache:
            return cache[key]
        disc, names, outputs = setup.discrete, setup.names, setup.outputs
        p = setup.p
        z0 = np.array([Z0[name] for name in names])
        y0 = disc.outputs(z0, TORQUE_PHASE, p)[0]
        root_q, sigma0 = _truth_noise(names, *stated, y0, outputs)
        # the filter's tuning: what the estimation runs use, mistuned by the case's factors
        q = [q_factor * v for v in setup.q]
        relative = np.sqrt(r_factor) * np.asarray(setup.relative)
        rng = np.random.default_rng(31)
        runs, n = 200, len(names)
        nis, nis_dof, nees_end, errors = [], [], [], []
        for _ in range(runs):
            z = z0.copy()
            z_hat = z0 + rng.standard_normal(n) * sigma0
            P = np.diag(sigma0**2)
            for _ in range(STEPS):
                z = disc.step(z, TORQUE_PHASE, H, p)[0] + rng.standard_normal(n) * root_q
                y = disc.outputs(z, TORQUE_PHASE, p)[0]
                y = y + rng.standard_normal(len(y)) * RELATIVE * np.abs(y)
                if dropped is not None:
                    y[dropped] = np.nan  # the plant: this sensor never reaches the update
                z_hat, P = ekf_predict(disc, z_hat, P, TORQUE_PHASE, H, p, q)
                z_hat, P, s, dof = ekf_update(
                    disc, z_hat, P, TORQUE_PHASE, y, p, relative, setup.floor
                )
                nis.append(s)
                nis_dof.append(dof)
            error = z_hat - z
            nees_end.append(float(error @ np.linalg.solve(P, error)))
            errors.append(error)
        cache[key] = (nis, nis_dof, nees_end, np.array(errors), setup, root_q, sigma0)
        return cache[key]

    return run


@pytest.mark.parametrize("case", list(MISTUNED))
def test_ekf_nees_and_nis_inside_their_chi2_bands_and_mistuned_outside(case, ekf_runs):
    nis, nis_dof, nees_end, errors, *_ = ekf_runs(*MISTUNED[case])
    _judge(case, *_statistics(nis, nis_dof, nees_end, errors.shape[1]))


#: The efficiency RMSE / bound the issue of the fleet evaluation (27) asks of m_veh.
EFFICIENCY_LIMIT = 1.3


@pytest.mark.parametrize("case", list(DROPPED_OUTPUT))
def test_ekf_accuracy_against_the_posterior_bound(case, ekf_runs):
    """Accuracy judged against the posterior Cramér–Rao bound, not "closer than the start":
    each parameter's RMS error at the end over the 200 runs against the bound of the same
    problem (:func:`~gearsym.validation.studies.posterior_bound.process_noise_bound`: the
    truth's model, process noise, prior σ0 and 1 % speed noise, every sensor; the flow and the
    output sensitivities by central differences of DOP853 trajectories of the lambdified
    right-hand side, independent of the filter's CasADi step). The bound is taken along the
    noise-free trajectory (the expectation over the truth's noisy trajectories, which it
    approximates, differs by the process noise's second-order effect). An efficient filter's
    RMSE / bound lies above the 99 % sampling floor √(χ²(200)/200) ≈ 0.87 (below it, the truth
    leaks into the filter or the bound is wrong) and at most 1.3 (issue 27's target). The
    plant drops the input speed sensor (ω_1): consistent by NEES and NIS, it must fail here.
    Measured (seed 31): consistent m_veh 1.01, μ_38 1.12, μ_05 1.12, ζ 0.98; input speed
    unused μ_38 1.56, μ_05 1.41 (m_veh 1.02, ζ 0.99; without ω_C or ω_2 the loss stays below
    15 %, too little to judge by 200 runs)."""
    from gearsym.validation.studies.posterior_bound import (
        lambdified,
        output_sensitivities,
        process_noise_bound,
    )

    nis, nis_dof, nees_end, errors, setup, root_q, sigma0 = ekf_runs(1.0, 1.0, DROPPED_OUTPUT[case])
    model = setup.aug.model
    args = (model.state_symbols, model.input_symbols, model.parameter_symbols, setup.p)
    f = lambdified(list(model.rhs), *args)
    h = lambdified(list(model.output_expressions), *args)
    names = setup.names
    z0 = np.array([Z0[name] for name in names])
    t = H * np.arange(STEPS + 1)
    u = np.tile(np.asarray(TORQUE_PHASE, dtype=float), (len(t), 1))
    steps = 1e-5 * np.maximum(np.abs(z0), sigma0)
    y, S, _, flow = output_sensitivities(f, h, z0, t, u, steps, return_flow=True)
    variances = (RELATIVE * np.abs(y)) ** 2
    variances[0] = np.inf  # the prior is at t = 0; the first measurement follows one step
    process = np.tile(np.diag(root_q**2), (len(t), 1, 1))
    bound = process_noise_bound(flow, S, variances, np.diag(sigma0**2), process)[-1]
    rmse = np.sqrt(np.mean(errors**2, axis=0))
    floor = float(np.sqrt(band(len(errors))[0]))
    efficiency = {
        name: float(rmse[j] / bound[j]) for j, name in enumerate(names) if j >= setup.aug.n_x
    }
    print(case, {k: round(v, 3) for k, v in efficiency.items()})
    if case == "consistent":
        for name, value in efficiency.items():
            assert floor < value < EFFICIENCY_LIMIT, (name, value)
        _judge(case, *_statistics(nis, nis_dof, nees_end, len(names)))
    else:  # consistent by its own P, inefficient against what every sensor allows
        _judge("consistent", *_statistics(nis, nis_dof, nees_end, len(names)))
        assert max(efficiency.values()) > EFFICIENCY_LIMIT, efficiency


@pytest.fixture(scope="module")
def euio_runs(reference, stated):
    """The extended UIO's Monte-Carlo on its filter model with the truth's road load, per (R
    factor, Q factor), computed once: (NIS, dof, NEES at the end, errors at the end, and what
    the bound needs: the setup, p of the truth, r_dyn, I_wheel, √(h q) of the truth, σ0)."""
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.symbolic.estimators.euio import ROAD_FREE, euio_step_full, load_column
    from gearsym.validation.studies.estimation.euio import measurement_variances
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    d, result = reference
    setup = prepare_ekf(d, result, parameters=("m_veh", "mu_38", "mu_05"), modes="reference")
    aug, disc, names, outputs = setup.aug, setup.discrete, setup.names, setup.outputs
    p = aug.parameter_values(ROAD_FREE)
    p_truth = aug.parameter_values({"zeta": 0.03})
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    i_wheel = float(p[[v.name for v in aug.model.parameters].index("I_wheel")])
    held = [names.index("m_veh")]
    cache: dict[tuple, tuple] = {}

    def run(r_factor: float, q_factor: float) -> tuple:
        if (r_factor, q_factor) in cache:
            return cache[(r_factor, q_factor)]
        z0 = np.array([Z0[name] for name in names])
        y0 = disc.outputs(z0, TORQUE_PHASE, p)[0]
        root_q, sigma0 = _truth_noise(names, *stated, y0, outputs)
        root_q[held] = 0.0
        q = q_factor * np.asarray(setup.q, dtype=float)
        rng = np.random.default_rng(31)
        runs, n = 200, len(names)
        nis, nis_dof, nees_end, errors = [], [], [], []
        for _ in range(runs):
            z = z0.copy()
            z_hat = z0 + rng.standard_normal(n) * sigma0
            P = np.diag(sigma0**2)
            for _ in range(STEPS):
                z = disc.step(z, TORQUE_PHASE, H, p_truth)[0] + rng.standard_normal(n) * root_q
                y = disc.outputs(z, TORQUE_PHASE, p)[0]
                y = y + rng.standard_normal(len(y)) * RELATIVE * np.abs(y)
                R = r_factor * measurement_variances(setup, y)
                e = load_column(disc, z_hat, r_dyn, p, i_wheel)
                step = euio_step_full(
                    disc, z_hat, P, TORQUE_PHASE, TORQUE_PHASE, y, R, H, p, q, e, held
                )
                z_hat, P = step.z, step.P
                nis.append(step.nis)
                nis_dof.append(step.nis_dof)
            error = z_hat - z
            nees_end.append(float(error @ np.linalg.solve(P, error)))
            errors.append(error)
        context = (setup, p, p_truth, r_dyn, i_wheel, root_q, sigma0)
        cache[(r_factor, q_factor)] = (nis, nis_dof, nees_end, np.array(errors), context)
        return cache[(r_factor, q_factor)]

    return run


@pytest.mark.parametrize("case", list(MISTUNED))
def test_euio_nees_and_nis_inside_their_chi2_bands_and_mistuned_outside(case, euio_runs):
    """The extended UIO on its filter model (ζ, f_roll, c_W zero) while the truth has a road
    load (the built-in rolling and aero resistance and a 3 % grade, ζ = 0.03): the load is the
    unknown input it decouples, so its NIS (with d̂ removed) is χ²(m − 1) whatever the load.
    m_veh is held (never decoupled from the load, symbolic/estimators/euio.py): its truth has
    no random walk, as the filter assumes."""
    nis, nis_dof, nees_end, errors, _ = euio_runs(*MISTUNED[case])
    _judge(case, *_statistics(nis, nis_dof, nees_end, errors.shape[1]))


def test_euio_accuracy_against_the_unknown_input_bound(euio_runs):
    """The extended UIO's μ against the posterior bound of its own premise, an unknown input
    about which nothing is assumed
    (:func:`~gearsym.validation.studies.posterior_bound.unknown_input_bound`: the information
    along the load's column projected out at every step), along the truth's noise-free
    trajectory (its road load included) with the truth's process noise and prior; F and H from
    the flow and the output sensitivities of DOP853 trajectories of the lambdified right-hand
    side; the load's column is the model's (``load_column`` at the truth's state, only its
    direction counts). Each μ's RMSE / bound must lie between the sampling floor and 1.3 (as
    the EKF's). m_veh is not judged: the filter holds it by design (its error is the prior
    draw), where the bound would let the gears' data inform it. Measured (seed 31): μ_38
    1.05, μ_05 0.98."""
    from gearsym.symbolic.estimators.euio import load_column
    from gearsym.validation.studies.posterior_bound import (
        lambdified,
        output_sensitivities,
        unknown_input_bound,
    )

    _, _, _, errors, context = euio_runs(1.0, 1.0)
    setup, p, p_truth, r_dyn, i_wheel, root_q, sigma0 = context
    model = setup.aug.model
    symbols = (model.state_symbols, model.input_symbols, model.parameter_symbols)
    f = lambdified(list(model.rhs), *symbols, p_truth)
    h = lambdified(list(model.output_expressions), *symbols, p)
    names = setup.names
    z0 = np.array([Z0[name] for name in names])
    t = H * np.arange(STEPS + 1)
    u = np.tile(np.asarray(TORQUE_PHASE, dtype=float), (len(t), 1))
    steps = 1e-5 * np.maximum(np.abs(z0), sigma0)
    y, S, states, flow = output_sensitivities(f, h, z0, t, u, steps, return_flow=True)
    n = len(names)
    F = np.empty((len(t), n, n))
    F[0] = np.eye(n)
    F[1:] = [np.linalg.solve(flow[k - 1].T, flow[k].T).T for k in range(1, len(t))]
    Hk = np.array([np.linalg.solve(flow[k].T, S[k].T).T for k in range(len(t))])
    load = np.array(
        [
            load_column(setup.discrete, states[max(k - 1, 0)], r_dyn, p, i_wheel)
            for k in range(len(t))
        ]
    )
    variances = (RELATIVE * np.abs(y)) ** 2
    variances[0] = np.inf  # the prior is at t = 0; the first measurement follows one step
    process = np.tile(np.diag(root_q**2), (len(t), 1, 1))
    bound = unknown_input_bound(F, Hk, load, variances, np.diag(sigma0**2), process)[-1]
    rmse = np.sqrt(np.mean(errors**2, axis=0))
    floor = float(np.sqrt(band(len(errors))[0]))
    efficiency = {
        mu: float(rmse[names.index(mu)] / bound[names.index(mu)]) for mu in ("mu_38", "mu_05")
    }
    print({k: round(v, 3) for k, v in efficiency.items()})
    for name, value in efficiency.items():
        assert floor < value < EFFICIENCY_LIMIT, (name, value)


# The filter's own mode logic (symbolic/estimators/ekf_modes.py) on the same stated model: a
# torque phase (both elements slide), the off-going K38's force lowered below what it must
# hold (it breaks away), then released (it opens) while the on-coming B05 closes its slip
# and locks up, about 30 samples later. The truth switches by the hybrid model's guards on
# its own state (2.60, 2.69, 2.70: ekf_mode_update with P = 0, so no confidence margin, and
# its lock-up map), the filter by the same logic on its estimate.
MODE_STEPS = 60
OWN_MODES = {**MISTUNED, "no ambiguity rule": (1.0, 1.0)}


def _mode_inputs(k: int) -> list[float]:
    u = list(TORQUE_PHASE)
    if 6 <= k < 12:
        u[1], u[2] = 250.0, 600.0  # K38 below its sticking torque: a break-away
    elif k >= 12:
        u[1], u[2] = 0.0, 600.0  # K38 open, B05 closing its slip
    return u


@pytest.mark.parametrize("case", list(OWN_MODES))
def test_ekf_with_its_own_mode_logic_inside_the_chi2_bands_and_mistuned_outside(
    case, reference, stated
):
    """NIS over all samples and NEES at the end against their 99 % bands, and each μ's
    normalised squared error e²/σ² at the end (χ²(runs)/runs if consistent) against its own
    band. Without the ambiguity rule (:func:`ambiguous_mu`) a lock-up the filter decides a
    sample after the truth leaves μ_05 biased low (its normalised squared error
    1.27-1.89 over seeds 1-7 and 31, the NEES/dof 1.02-1.17): that case must fail μ_05's
    band. Measured with the rule, seeds 1, 3, 6, 7 and 31: NIS/dof 0.993-1.017, NEES/dof
    0.968-1.026, μ_38 0.93-1.10, μ_05 0.90-1.18; at seed 31 without it μ_05 1.59 (R × 2:
    NIS/dof 0.55; Q × 2: NEES/dof 0.72). About 45 s for the four cases."""
    from gearsym.symbolic.estimators.ekf import ekf_predict, ekf_update
    from gearsym.symbolic.estimators.ekf_modes import ambiguous_mu, ekf_mode_update
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    d, result = reference
    setup = prepare_ekf(d, result, modes="filter")
    logic, disc, names, outputs, p = (
        setup.logic,
        setup.discrete,
        setup.names,
        setup.outputs,
        setup.p,
    )
    r_factor, q_factor = OWN_MODES[case]
    rule_off = case == "no ambiguity rule"
    z0 = np.array([Z0[name] for name in names])
    y0 = disc.outputs(z0, TORQUE_PHASE, p)[0]
    root_q, sigma0 = _truth_noise(names, *stated, y0, outputs)
    q = [q_factor * v for v in setup.q]
    relative = np.sqrt(r_factor) * np.asarray(setup.relative)
    rng = np.random.default_rng(31)
    runs, n = 200, len(names)
    no_p = np.zeros((n, n))
    nis, nis_dof, nees_end, normalised = [], [], [], []
    for _ in range(runs):
        z = z0.copy()
        z_hat = z0 + rng.standard_normal(n) * sigma0
        P = np.diag(sigma0**2)
        truth_modes, modes = logic.initial_modes(), logic.initial_modes()
        for k in range(MODE_STEPS):
            u = _mode_inputs(k)
            if k > 0:
                held = logic.inputs(_mode_inputs(k - 1), truth_modes)
                noise = rng.standard_normal(n) * root_q
                noise[disc.aug.frozen_states(held)] = 0.0  # a μ walks only while it slides
                z = disc.step(z, held, H, p)[0] + noise
                z_hat, P = ekf_predict(
                    disc, z_hat, P, logic.inputs(_mode_inputs(k - 1), modes), H, p, q
                )
            y = disc.outputs(z, logic.inputs(u, truth_modes), p)[0]
            y = y + rng.standard_normal(len(y)) * RELATIVE * np.abs(y)
            consider = [] if rule_off else ambiguous_mu(logic, z_hat, P, u, p, modes)
            z_hat, P, s, dof = ekf_update(
                disc, z_hat, P, logic.inputs(u, modes), y, p, relative, setup.floor, consider
            )
            nis.append(s)
            nis_dof.append(dof)
            if k == MODE_STEPS - 1:
                break  # scored after the last update, as the estimation runs record it
            z, _, truth_modes, _ = ekf_mode_update(logic, z, no_p, u, p, truth_modes)
            z_hat, P, modes, _ = ekf_mode_update(logic, z_hat, P, u, p, modes)
        error = z_hat - z
        nees_end.append(float(error @ np.linalg.solve(P, error)))
        normalised.append(error**2 / np.diag(P))
    nis_mean, nis_band, nees_mean, nees_band = _statistics(nis, nis_dof, nees_end, n)
    per_state = dict(zip(names, np.mean(normalised, axis=0), strict=True))
    one = band(runs)
    print(case, {k: round(float(v), 2) for k, v in per_state.items()}, one)
    if case == "no ambiguity rule":
        assert per_state["mu_05"] > one[1], (per_state["mu_05"], one)
        return
    _judge(case, nis_mean, nis_band, nees_mean, nees_band)
    if case == "consistent":
        for mu in ("mu_38", "mu_05"):
            assert one[0] < per_state[mu] < one[1], (mu, per_state[mu], one)


@pytest.mark.parametrize("case", list(MISTUNED))
def test_euio_with_its_own_mode_logic_inside_the_chi2_bands_and_mistuned_outside(
    case, reference, stated
):
    """The extended UIO with the EKF's mode logic (its evaluation loop's: ``ekf_mode_update``
    and ``ambiguous_mu`` judged on the posterior before each step, the held mask per mode
    combination) through the same break-away, opening and lock-up, on its filter model with
    the truth's road load (as the fixed-mode test above; m_veh held). NEES at the end and each
    μ's normalised squared error against their bands; the NIS over the samples where the
    filter's modes are the truth's (the truth used for scoring only) against its band: on the
    samples after a switch the filter decided a sample off the truth's (about 2 %) the
    innovations are larger (NIS/dof 1.3-1.6), which lifts the NIS over all samples to
    1.017-1.024, the upper edge of its band (seeds 1, 6, 31). Measured at seed 31: NIS/dof
    1.017 where the modes agree, NEES/dof 0.968, μ_38 0.90, μ_05 0.97."""
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.symbolic.estimators.ekf_modes import ambiguous_mu, ekf_mode_update
    from gearsym.symbolic.estimators.euio import euio_step_full, load_column
    from gearsym.validation.studies.estimation.euio import measurement_variances
    from gearsym.validation.studies.euio_evaluation import prepare_euio

    d, result = reference
    setup = prepare_euio(d, result, modes="filter")
    s = setup.ekf
    logic, disc, names, outputs, p = s.logic, s.discrete, s.names, s.outputs, setup.p
    p_truth = s.aug.parameter_values({"zeta": 0.03})
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    r_factor, q_factor = MISTUNED[case]
    held_mass = [names.index("m_veh")]
    z0 = np.array([Z0[name] for name in names])
    y0 = disc.outputs(z0, TORQUE_PHASE, p)[0]
    root_q, sigma0 = _truth_noise(names, *stated, y0, outputs)
    root_q[held_mass] = 0.0
    q = q_factor * np.asarray(s.q, dtype=float)
    rng = np.random.default_rng(31)
    runs, n = 200, len(names)
    no_p = np.zeros((n, n))
    nis, nis_dof, agree, nees_end, normalised = [], [], [], [], []
    for _ in range(runs):
        z = z0.copy()
        z_hat = z0 + rng.standard_normal(n) * sigma0
        P = np.diag(sigma0**2)
        truth_modes, modes = logic.initial_modes(), logic.initial_modes()
        # sample 0: the prior as it is (the evaluation loop updates from the first step on)
        z, _, truth_modes, _ = ekf_mode_update(
            logic, z, no_p, _mode_inputs(0), p_truth, truth_modes
        )
        z_hat, P, modes, _ = ekf_mode_update(logic, z_hat, P, _mode_inputs(0), p, modes)
        for k in range(1, MODE_STEPS):
            before, u = _mode_inputs(k - 1), _mode_inputs(k)
            held_truth = logic.inputs(before, truth_modes)
            noise = rng.standard_normal(n) * root_q
            noise[disc.aug.frozen_states(held_truth)] = 0.0
            z = disc.step(z, held_truth, H, p_truth)[0] + noise
            y = disc.outputs(z, logic.inputs(u, truth_modes), p)[0]
            y = y + rng.standard_normal(len(y)) * RELATIVE * np.abs(y)
            u_before, u_now = logic.inputs(before, modes), logic.inputs(u, modes)
            hold = sorted({*setup.held_for_modes(u_before), *held_mass})
            consider = ambiguous_mu(logic, z_hat, P, u, p, modes)
            R = r_factor * measurement_variances(s, y)
            e = load_column(disc, z_hat, r_dyn, p, setup.i_wheel)
            step = euio_step_full(disc, z_hat, P, u_before, u_now, y, R, H, p, q, e, hold, consider)
            z_hat, P = step.z, step.P
            nis.append(step.nis)
            nis_dof.append(step.nis_dof)
            agree.append(modes == truth_modes)
            if k == MODE_STEPS - 1:
                break
            z, _, truth_modes, _ = ekf_mode_update(logic, z, no_p, u, p_truth, truth_modes)
            z_hat, P, modes, _ = ekf_mode_update(logic, z_hat, P, u, p, modes)
        error = z_hat - z
        nees_end.append(float(error @ np.linalg.solve(P, error)))
        normalised.append(error**2 / np.diag(P))
    agree = np.array(agree)
    nis_agree = [v for v, a in zip(nis, agree, strict=True) if a]
    dof_agree = [v for v, a in zip(nis_dof, agree, strict=True) if a]
    nis_mean, nis_band, nees_mean, nees_band = _statistics(nis_agree, dof_agree, nees_end, n)
    per_state = dict(zip(names, np.mean(normalised, axis=0), strict=True))
    one = band(runs)
    print(case, {k: round(float(v), 2) for k, v in per_state.items()}, f"agree {agree.mean():.3f}")
    _judge(case, nis_mean, nis_band, nees_mean, nees_band)
    if case == "consistent":
        for mu in ("mu_38", "mu_05"):
            assert one[0] < per_state[mu] < one[1], (mu, per_state[mu], one)
