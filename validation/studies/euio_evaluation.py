"""Monte-Carlo evaluation of the extended UIO (thesis 4.5) against its matched bound.

The EUIO (:mod:`gearsym.symbolic.estimators.euio`) estimates m_veh, μ_off, μ_on as random
walks (4.1) with the road load T_res* (absorbing ζ, (5.5)) as an unknown input about which it
assumes nothing. Its runs here are :func:`~gearsym.validation.studies.estimation.euio.run_euio`'s
(the same loop, checked equal to the bit by the tests), split like the EKF's Monte-Carlo study: the
reference simulated once (:func:`prepare_euio`), the speed noise (3.26) drawn anew per run
(:func:`euio_filter_run`).

**The matched bound** (:func:`euio_bound`). Under the EUIO's own assumptions — its model
(4.1) with ζ, f_roll, c_W = 0, its element modes and held inputs, its sample times, speed noise
(3.26) and prior P0, the initial states unknown — and *the road load unknown in every sample
interval*: the Kalman recursion along the truth (Tichavský et al. 1998) with the road load's
direction projected out of the predicted information at every step
(:func:`~gearsym.validation.studies.posterior_bound.unknown_input_bound`: the limit of a load with
infinite variance, of which the unbiased minimum-variance filter is the Kalman filter). As for
the EKF, twice: with the parameters constant and the model exact (``crb_sigma``), and with the
filter's own process noise (random walks and model-error intensities, zero for a held state;
``crb_sigma_process_noise``), the best a filter with exactly these assumptions could do. F_k,
H_k and the load's discrete column e_k are central differences of DOP853 trajectories of the
filter's right-hand side lambdified to NumPy (not its RK4 step, its CasADi Jacobians or its
RK4 series for E_d): e_k is the flow's column of an extra state d with ḋ = 0 entering
I_C^eff ω̇_C = 2 T_ss − d (2.45, 2.46); the trajectory is driven by the reference's T_res, so
it follows the truth. Beside them the process-noise bound with the road load *known* (no
projection: what modelling the load would be worth).

**Identifiable per phase**: the EUIO's own existence test (rank(CE) = rank(E) and no
invariant zero with Re s ≥ 0, per parameter and phase); elsewhere the parameter is held and
the report says "not identifiable in this phase" with how much its σ and the bound moved there.
m_veh is not identifiable with the road load unknown in any phase (an invariant zero at s = 0:
a mass error is a road load); its bound shows it: it barely shrinks below the prior.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import EKF_RELATIVE_NOISE
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.validation.sim.phases import phase_of as sim_phase_of
from gearsym.validation.sim.simulation_result import SimulationResult
from gearsym.validation.studies.estimation.bounds import NOT_IDENTIFIABLE, _phase_samples
from gearsym.validation.studies.estimation.euio import EuioRun, existence_per_phase
from gearsym.validation.studies.estimation.loop import (
    ParameterEstimate,
    _chi2_mean_band,
    noisy_outputs,
)
from gearsym.validation.studies.estimation.montecarlo import ScoredStats, rms, run_seeds, score
from gearsym.validation.studies.estimation.setup import EkfSetup, prepare_ekf

__all__ = [
    "EUIO_BOUND_ASSUMPTION",
    "EuioBound",
    "EuioMonteCarlo",
    "EuioSetup",
    "EuioTrial",
    "euio_bound",
    "euio_filter_run",
    "format_euio_monte_carlo_text",
    "plot_euio_efficiency",
    "prepare_euio",
    "run_euio_monte_carlo",
]

EUIO_BOUND_ASSUMPTION = (
    "posterior Cramér–Rao bound under the EUIO's own assumptions: its model (4.1, road-free: "
    "zeta, f_roll, c_W = 0), element modes, held inputs, sample times, speed noise (3.26), "
    "prior P0, initial states unknown, and the road load T_res* an unknown input in every "
    "sample interval (its direction projected out of the information at each step: the limit "
    "of infinite load variance); parameters constant and the model exact (the second bound adds "
    "the filter's process noise); Kalman recursion along the truth from DOP853 differences"
)


@dataclass
class EuioSetup:
    """The seed-independent part of an EUIO run: the EKF's setup without ζ (sample grid,
    true outputs, noise σ, inputs, modes, truths, initial estimate, prior), the road-free
    fixed parameters, the load column's constants, existence and held states per phase, and
    the reference's road load at mid-interval."""

    ekf: EkfSetup
    p: list[float]
    r_dyn: float
    i_wheel: float
    existence: dict[str, list[Any]]
    held_by_phase: dict[str, list[int]]
    phase_at: list[str]  # per sample: the phase its step is held by
    load_truth: np.ndarray  # (N,) T_res at mid-interval (sample 0: at t0)
    #: filter modes: existence per combination of element modes (the mode flags of u), at
    #: the generic point (:func:`~gearsym.symbolic.estimators.euio.euio_mode_existence`)
    mode_existence: dict[tuple[float, ...], list[Any]] = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        return self.ekf.names

    @property
    def mode_source(self) -> str:
        """ "filter" (the EKF's mode logic decides the element modes) or "reference"."""
        return self.ekf.mode_source

    def held_for_modes(self, u_before: Sequence[float]) -> list[int]:
        """State indices held over a step whose element modes are those of ``u_before``
        (the filter's own): the parameters without a UIO for that mode combination
        (existence 4.4 at the generic point, as the emitted header's masks) and the μ of a
        non-sliding element."""
        from gearsym.symbolic.estimators.euio import euio_mode_existence

        s = self.ekf
        flags = [
            j for j, name in enumerate(s.aug.input_names) if name.startswith(("slide_", "stick_"))
        ]
        key = tuple(float(u_before[j]) for j in flags)
        if key not in self.mode_existence:
            self.mode_existence[key] = euio_mode_existence(
                s.discrete, u_before, self.p, self.r_dyn, self.i_wheel, s.logic.normal_force
            )
        failing = [self.names.index(x.parameter) for x in self.mode_existence[key] if not x.exists]
        return sorted(set(failing) | set(s.aug.frozen_states(u_before)))

    def held(self, k: int) -> list[int]:
        """State indices held over the step into sample k (k ≥ 1): the phase's parameters
        without a UIO and the μ of a non-sliding element."""
        s = self.ekf
        return sorted(
            set(self.held_by_phase[self.phase_at[k]]) | set(s.aug.frozen_states(s.u[k - 1]))
        )


def prepare_euio(
    d: GearboxDescription,
    result: SimulationResult,
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | float = EKF_RELATIVE_NOISE,
    initial: Mapping[str, float] | None = None,
    modes: str = "filter",
) -> EuioSetup:
    """As :func:`~gearsym.validation.studies.estimation.euio.run_euio` before its loop: the EKF's
    setup for m_veh and the μ of the swapping elements, existence per phase on the linearisation at
    the phase's midpoint (truth states, the truth's parameters). ``modes``: "filter" (default),
    the EKF's mode logic (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`)
    decides the element modes in each run, or "reference", the reference's (the truth)."""
    from gearsym.symbolic.estimators.ekf import default_parameters
    from gearsym.symbolic.estimators.euio import ROAD_FREE

    shift = result.scenario.shift.name
    parameters = [name for name in default_parameters(d, shift) if name != naming.GRADE]
    setup = prepare_ekf(d, result, sample_time, relative_noise, initial, parameters, modes=modes)
    aug = setup.aug
    p = aug.parameter_values(ROAD_FREE)
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    i_wheel = float(p[[v.name for v in aug.model.parameters].index("I_wheel")])
    t = setup.t
    existence, held_by_phase = existence_per_phase(setup, p, r_dyn, i_wheel)

    def phase_of(time: float) -> str:
        return sim_phase_of(setup.phases, time) or setup.phases[-1].name

    t_mid = np.r_[t[0], 0.5 * (t[1:] + t[:-1])]
    return EuioSetup(
        ekf=setup,
        p=p,
        r_dyn=r_dyn,
        i_wheel=i_wheel,
        existence=existence,
        held_by_phase=held_by_phase,
        phase_at=[phase_of(float(v)) for v in t],
        load_truth=np.interp(t_mid, result.t, result.signals[naming.ROAD_TORQUE]),
    )


@dataclass(frozen=True)
class EuioTrial:
    """One EUIO run with its consistency statistics: NEES over the scored states (speeds,
    φ, m_veh, μ while its element slides) and the NIS of the load-free innovation
    (:class:`~gearsym.symbolic.estimators.euio.EuioStep`, χ²(m − 1))."""

    run: EuioRun
    nees: np.ndarray = field(repr=False)
    nees_dof: np.ndarray = field(repr=False)
    nis: np.ndarray = field(repr=False)  # NaN at sample 0 (no update: the initial estimate)
    nis_dof: np.ndarray = field(repr=False)
    min_eigenvalue: float
    switches: int = 0  # mode switches the filter decided (its own modes only)


def euio_filter_run(
    setup: EuioSetup, seed: int = 0, noise: bool = True, prior_draw: bool = False
) -> EuioTrial:
    """One EUIO run on ``setup`` with the speed noise (3.26) drawn from ``seed`` (``noise``
    False: the true outputs). ``prior_draw``: φ and the parameters start at the truth
    (:attr:`EkfSetup.truth0`) plus a draw from the prior (a second stream of ``seed``), the
    bound's premise, instead of the fixed initial estimate.

    Element modes (``setup.mode_source``): "reference" takes them from the reference (``u``)
    and the held masks from the reference's phases (:meth:`EuioSetup.held`); "filter" starts
    in the from-gear and lets the EKF's mode logic
    (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`, from the posterior and
    F_N; a lock-up maps z and P through the hybrid model's state map) decide after each
    sample the modes held over the next interval, with the held mask of that mode combination
    (:meth:`EuioSetup.held_for_modes`), as
    :func:`~gearsym.validation.studies.estimation.loop.filter_run` does for the EKF, including
    its rule for a mode in doubt (:func:`~gearsym.symbolic.estimators.ekf_modes.ambiguous_mu`,
    judged on the posterior before each step). The estimate
    and NEES recorded at a sample are the update's."""
    from gearsym.symbolic.estimators.ekf_modes import ambiguous_mu, ekf_mode_update
    from gearsym.symbolic.estimators.euio import euio_step_full, load_column

    s = setup.ekf
    discrete = s.discrete
    t, names, n = s.t, s.names, len(s.names)
    h = float(t[1] - t[0])
    y = noisy_outputs(s, seed) if noise else s.y_true.copy()
    z = s.initial.copy()
    if prior_draw:
        unmeasured = np.array([name not in s.outputs for name in names])
        draw = np.random.default_rng([seed, 1]).normal(0.0, 1.0, n) * s.prior_sigma
        z[unmeasured] = s.truth0[unmeasured] + draw[unmeasured]
    for k, name in enumerate(s.outputs):
        if name in names:
            z[names.index(name)] = y[0, k]
    P = np.diag(s.prior_sigma**2)
    initial_values = z.copy()
    q = np.array(s.q, dtype=float)
    scale = np.maximum(s.prior_sigma, 1e-12)

    estimates = np.empty((len(t), n))
    sigmas = np.empty((len(t), n))
    held = np.zeros((len(t), n), dtype=bool)
    load = np.full(len(t), np.nan)
    load_sigma = np.full(len(t), np.nan)
    nis = np.full(len(t), np.nan)
    nis_dof = np.zeros(len(t))
    nees = np.zeros(len(t))
    min_eig = float(np.linalg.eigvalsh(P / np.outer(scale, scale))[0])
    estimates[0], sigmas[0] = z, np.sqrt(np.diag(P))
    logic = s.logic if s.mode_source == "filter" else None
    if logic is not None:
        modes = logic.initial_modes()
        u_held = logic.inputs(s.u[0], modes)
        switches = 0
    for k in range(len(t)):
        if k > 0:
            if logic is None:
                u_before, u_now, hold = s.u[k - 1], s.u[k], setup.held(k)
            else:  # the modes held since the previous sample, the known inputs of this one
                u_before, u_now = u_held, logic.inputs(s.u[k], modes)
                hold = setup.held_for_modes(u_before)
            held[k, hold] = True
            R = (s.relative * np.maximum(np.abs(y[k]), s.floor)) ** 2
            e = load_column(discrete, z, setup.r_dyn, setup.p, setup.i_wheel)
            # a μ whose element may already have locked up is not corrected (judged on the
            # posterior before the step, which predicts inside)
            consider = [] if logic is None else ambiguous_mu(logic, z, P, s.u[k], setup.p, modes)
            step = euio_step_full(
                discrete, z, P, u_before, u_now, y[k], R, h, setup.p, q, e, hold, consider
            )
            z, P = step.z, step.P
            load[k], load_sigma[k] = step.d_hat, step.sigma_d
            nis[k], nis_dof[k] = step.nis, step.nis_dof
            estimates[k], sigmas[k] = z, np.sqrt(np.diag(P))
            min_eig = min(min_eig, float(np.linalg.eigvalsh(P / np.outer(scale, scale))[0]))
        idx = np.flatnonzero(s.scored[k])
        error = z[idx] - s.truth[k, idx]
        nees[k] = float(error @ np.linalg.solve(P[np.ix_(idx, idx)], error))
        if logic is not None:  # as the EKF (filter_run): decided after the update at k
            z, P, modes, events = ekf_mode_update(logic, z, P, s.u[k], setup.p, modes)
            switches += len(events)
            u_held = logic.inputs(s.u[k], modes)

    by_parameter = []
    for name in s.aug.parameters:
        j = names.index(name)
        inside = np.flatnonzero(s.scored[:, j])
        last = inside[-1] if inside.size else len(t) - 1
        err = estimates[inside, j] - s.truth[inside, j]
        by_parameter.append(
            ParameterEstimate(
                name=name,
                truth=float(s.truth[last, j]),
                initial=float(initial_values[j]),
                estimate=float(estimates[last, j]),
                sigma=float(sigmas[last, j]),
                rmse=float(np.sqrt(np.mean(err**2))) if inside.size else float("nan"),
                scored=int(inside.size),
            )
        )
    run = EuioRun(
        shift=s.shift,
        sample_time=h,
        seed=seed,
        state_names=tuple(names),
        t=t,
        estimates=estimates,
        sigmas=sigmas,
        truth=s.truth,
        scored=s.scored,
        held=held,
        load=load,
        load_sigma=load_sigma,
        load_truth=setup.load_truth,
        phases=s.phases,
        existence=setup.existence,
        parameters=tuple(by_parameter),
        mode_source=s.mode_source,
    )
    return EuioTrial(
        run=run,
        nees=nees,
        nees_dof=s.scored.sum(axis=1).astype(float),
        nis=nis,
        nis_dof=nis_dof,
        min_eigenvalue=min_eig,
        switches=switches if logic is not None else 0,
    )


@dataclass(frozen=True)
class EuioBound:
    """The bound of :func:`euio_bound` per sample, and the one with the road load known."""

    names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    #: (N, n): road load unknown (projected out), parameters constant, model exact (the
    #: EKF's first bound, with the load's direction removed)
    sigma: np.ndarray = field(repr=False)
    #: (N, n): the same with the filter's process noise (random walks 4.1, model error): the
    #: best a filter with exactly the EUIO's assumptions could do
    sigma_process: np.ndarray = field(repr=False)
    #: (N, n): with the process noise, the road load known (what modelling it would be worth)
    sigma_load_known: np.ndarray = field(repr=False)
    linearised_at: np.ndarray = field(repr=False)


def euio_bound(setup: EuioSetup, relative_step: float = 1e-5) -> EuioBound:
    """The matched bound of the EUIO (module text): F_k, H_k and the road load's discrete
    column e_k from the flow of the filter's right-hand side, extended by a constant load
    state d, integrated by DOP853 from the truth with the reference's T_res as input; then
    :func:`~gearsym.validation.studies.posterior_bound.unknown_input_bound` with the filter's prior
    and process noise (zero for the states held over the interval)."""
    import sympy as sp
    from gearsym.validation.studies.posterior_bound import (
        lambdified,
        output_sensitivities,
        unknown_input_bound,
    )

    s = setup.ekf
    model = s.aug.model
    names = s.names
    n = len(names)
    d_state = sp.Symbol("d_load_state", real=True)
    d_input = sp.Symbol("d_load_input", real=True)
    mass = model.state_symbols[names.index("m_veh")]
    i_wheel = model.parameter_symbols[[v.name for v in model.parameters].index("I_wheel")]
    rhs = list(model.rhs)
    j_c = names.index(naming.WHEEL_SPEED)  # I_C^eff ω̇_C = 2 T_ss − d (2.45, 2.46)
    rhs[j_c] = rhs[j_c] - (d_state + d_input) / (i_wheel + mass * setup.r_dyn**2)
    states = [*model.state_symbols, d_state]
    inputs = [*model.input_symbols, d_input]
    args = (states, inputs, model.parameter_symbols, setup.p)
    f = lambdified([*rhs, 0], *args)
    h = lambdified(list(model.output_expressions), *args)
    z0 = np.r_[s.truth0, 0.0]
    u = np.column_stack([s.u, setup.load_truth])
    # the load over [t_k, t_{k+1}) is the mid-interval value stored at sample k + 1
    u[:-1, -1] = setup.load_truth[1:]
    steps = relative_step * np.maximum(np.abs(z0), np.r_[s.prior_sigma, 100.0])
    _, S, _, flow = output_sensitivities(f, h, z0, s.t, u, steps, return_flow=True)
    N = len(s.t)
    F = np.zeros((N, n, n))
    E = np.zeros((N, n))
    H = np.zeros((N, S.shape[1], n))
    for k in range(N):
        H[k] = np.linalg.solve(flow[k].T, S[k].T).T[:, :n]
        if k > 0:
            step = np.linalg.solve(flow[k - 1].T, flow[k].T).T  # Φ_k Φ_{k-1}⁻¹
            F[k], E[k] = step[:n, :n], step[:n, n]
    variances = s.sigma_y**2
    variances[0] = np.inf  # sample 0 is the initial estimate (speeds from it: the prior)
    hstep = float(s.t[1] - s.t[0])
    process = np.zeros((N, n, n))
    for k in range(1, N):
        rates = np.array(s.q, dtype=float)
        rates[setup.held(k)] = 0.0
        process[k - 1] = np.diag(hstep * rates)
    prior = np.diag(s.prior_sigma**2)
    return EuioBound(
        names=tuple(names),
        t=s.t,
        sigma=unknown_input_bound(F, H, E, variances, prior, np.zeros_like(process)),
        sigma_process=unknown_input_bound(F, H, E, variances, prior, process),
        sigma_load_known=unknown_input_bound(F, H, None, variances, prior, process),
        linearised_at=z0[:n],
    )


@dataclass(frozen=True)
class EuioPhaseStats(ScoredStats):
    """One parameter in one phase over the runs (keys as the EKF's)."""

    crb_sigma_load_known: float | None = None
    reason: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.scored_dict(),
            "crb_sigma_load_known": self.crb_sigma_load_known,
            "identifiable": self.identifiable,
            "verdict": None if self.identifiable else NOT_IDENTIFIABLE,
            "reason": self.reason,
            **self.ratios_dict(),
        }


@dataclass(frozen=True)
class EuioMonteCarlo:
    """The EUIO over ``len(trials)`` noise seeds of one reference shift, with its bound."""

    trials: tuple[EuioTrial, ...]
    bound: EuioBound
    seconds_per_run: float
    phase_stats: dict[str, dict[str, EuioPhaseStats]]
    relative_noise: tuple[float, ...]
    prior_draw: bool = False
    mode_source: str = "reference"

    @property
    def first(self) -> EuioRun:
        return self.trials[0].run

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.first.parameters]

    def _stack(self, attribute: str) -> np.ndarray:
        return np.array([getattr(tr, attribute) for tr in self.trials])

    def _run_stack(self, attribute: str) -> np.ndarray:
        return np.array([getattr(tr.run, attribute) for tr in self.trials])

    def nees_run_mean(self) -> np.ndarray:
        return np.mean(self._stack("nees"), axis=0)

    @property
    def nees_mean(self) -> float:
        return float(np.mean(self.nees_run_mean()))

    def nees_band(self, probability: float = 0.95) -> tuple[float, float]:
        """χ²(R n)/R quantiles of one sample's mean over R runs (as the EKF's)."""
        from scipy.stats import chi2

        runs, dof = len(self.trials), float(np.mean(self.trials[0].nees_dof))
        return (
            float(chi2.ppf((1 - probability) / 2, runs * dof) / runs),
            float(chi2.ppf((1 + probability) / 2, runs * dof) / runs),
        )

    def nees_inside(self, probability: float = 0.95) -> float:
        from scipy.stats import chi2

        runs, dof = len(self.trials), self.trials[0].nees_dof
        lo = chi2.ppf((1 - probability) / 2, runs * dof) / runs
        hi = chi2.ppf((1 + probability) / 2, runs * dof) / runs
        mean = self.nees_run_mean()
        return float(np.mean((mean >= lo) & (mean <= hi)))

    def nis(self) -> tuple[float | None, tuple[float, float] | None]:
        """Mean NIS over every update of every run and the band of that mean (innovations
        white: Σ NIS ~ χ²(Σ dof), divided by the number of updates)."""
        nis, dof = self._stack("nis"), self._stack("nis_dof")
        used = dof > 0
        if not used.any():
            return None, None
        return float(np.mean(nis[used])), _chi2_mean_band(dof[used])

    def load_summary(self) -> dict[str, Any]:
        load, truth = self._run_stack("load"), self.first.load_truth
        sig = self._run_stack("load_sigma")
        ok = np.isfinite(load[0])
        per_phase = {}
        for k, phase in enumerate(self.first.phases):
            inside = _phase_samples(self.first.t, phase, last=k == len(self.first.phases) - 1)
            idx = inside[ok[inside]]
            per_phase[phase.name] = rms(load[:, idx] - truth[None, idx])
        return {
            "rmse": rms(load[:, ok] - truth[None, ok]),
            "sigma_rms": rms(sig[:, ok]),
            "rmse_per_phase": per_phase,
            "absorbs": "zeta, rolling and aero resistance (2.48)",
        }

    def parameter_summary(self, name: str) -> dict[str, Any]:
        first = self.first
        j = first.state_names.index(name)
        scored = first.scored[:, j]
        errors = self._run_stack("estimates")[:, scored, j] - first.truth[None, scored, j]
        sigmas = self._run_stack("sigmas")[:, scored, j]
        crb = self.bound.sigma[scored, j]
        crb_process = rms(self.bound.sigma_process[scored, j])
        final = [next(p for p in tr.run.parameters if p.name == name) for tr in self.trials]
        rmse, crb_rms = rms(errors), rms(crb)
        identifiable = [ph for ph, st in self.phase_stats.items() if st[name].identifiable]
        return {
            "truth": final[0].truth,
            "initial": float(np.mean([p.initial for p in final])),
            "estimate": float(np.mean([p.estimate for p in final])),
            "sigma": float(np.mean([p.sigma for p in final])),
            "rmse": rmse,
            "mean_error": float(np.mean(errors)) if errors.size else None,
            "sigma_rms": rms(sigmas),
            "crb_sigma": crb_rms if identifiable else None,
            "efficiency": rmse / crb_rms if identifiable and rmse and crb_rms else None,
            "crb_sigma_process_noise": crb_process if identifiable else None,
            "efficiency_process_noise": rmse / crb_process
            if identifiable and rmse and crb_process
            else None,
            "crb_sigma_load_known": rms(self.bound.sigma_load_known[scored, j]),
            "identifiable": identifiable,
            "samples": int(np.count_nonzero(scored)),
        }

    def to_dict(self) -> dict[str, Any]:
        first = self.first
        nis_mean, nis_band = self.nis()
        return {
            "filter": "euio",
            "shift": first.shift,
            "runs": len(self.trials),
            "seed": first.seed,
            "seeds": [tr.run.seed for tr in self.trials],
            "sample_time": first.sample_time,
            "relative_noise": list(self.relative_noise),
            "seconds_per_run": self.seconds_per_run,
            "initial_estimate": "drawn from the prior around the truth"
            if self.prior_draw
            else "fixed",
            "modes": self.mode_source,
            "mode_switches_mean": float(np.mean([tr.switches for tr in self.trials])),
            "parameters": {name: self.parameter_summary(name) for name in self.parameter_names},
            "unknown_inputs": {naming.RESISTANCE_INPUT: self.load_summary()},
            "bound": EUIO_BOUND_ASSUMPTION,
            "nees_mean": self.nees_mean,
            "nees_band": list(self.nees_band()),
            "nees_dof_mean": float(np.mean(self.trials[0].nees_dof)),
            "nees_inside_95": self.nees_inside(),
            "nis_mean": nis_mean,
            "nis_band": list(nis_band) if nis_band is not None else None,
            "nis_note": "innovation with the road load's estimate removed, chi2(m - 1)",
            "min_covariance_eigenvalue": min(tr.min_eigenvalue for tr in self.trials),
            "phases": [
                {
                    "name": phase.name,
                    "t_start": phase.t_start,
                    "t_end": phase.t_end,
                    "existence": [e.to_dict() for e in first.existence[phase.name]],
                    "parameters": {
                        name: st.to_dict() for name, st in self.phase_stats[phase.name].items()
                    },
                }
                for phase in first.phases
            ],
        }


def run_euio_monte_carlo(
    setup: EuioSetup,
    runs: int,
    seed: int = 0,
    progress: Callable[[float, str], None] | None = None,
    bound: EuioBound | None = None,
    prior_draw: bool = False,
) -> EuioMonteCarlo:
    """The EUIO (4.5) over ``runs`` seeds ``seed``, ``seed`` + 1, …, only the speed noise
    (3.26) drawn anew; ``progress(fraction, message)`` after each run. Per parameter and
    phase: mean error, RMSE and RMS σ over the scored samples of every run, the matched bound
    (:func:`euio_bound`) over the same samples and the efficiency RMSE / bound where the
    phase's existence test passes; elsewhere "not identifiable in this phase"."""
    trials, seconds = run_seeds(
        lambda run_seed: euio_filter_run(setup, run_seed, prior_draw=prior_draw),
        runs,
        seed,
        progress,
    )
    if bound is None:
        if progress is not None:
            progress(1.0, "matched bound (road load unknown)")
        bound = euio_bound(setup)
    first = trials[0].run
    estimates = np.array([tr.run.estimates for tr in trials])
    sigmas = np.array([tr.run.sigmas for tr in trials])
    stats: dict[str, dict[str, EuioPhaseStats]] = {}
    for k, phase in enumerate(first.phases):
        inside = _phase_samples(first.t, phase, last=k == len(first.phases) - 1)
        stats[phase.name] = {}
        for p in first.parameters:
            j = first.state_names.index(p.name)
            (ex,) = [x for x in setup.existence[phase.name] if x.parameter == p.name]
            idx = inside[first.scored[inside, j]]
            stats[phase.name][p.name] = EuioPhaseStats(
                **score(estimates, sigmas, first, inside, j, bound.sigma, bound.sigma_process),
                crb_sigma_load_known=rms(bound.sigma_load_known[idx, j]),
                identifiable=ex.exists,
                reason=ex.reason(),
            )
    return EuioMonteCarlo(
        trials=tuple(trials),
        bound=bound,
        seconds_per_run=seconds,
        phase_stats=stats,
        relative_noise=tuple(float(v) for v in setup.ekf.relative),
        prior_draw=prior_draw,
        mode_source=setup.mode_source,
    )


def format_euio_monte_carlo_text(mc: EuioMonteCarlo) -> str:
    """Per phase and parameter: mean error, RMSE, σ, bound, efficiency, or "not identifiable
    in this phase" with the reason and the σ / bound ratios; the road load; NEES and NIS."""
    first = mc.first
    runs = len(mc.trials)
    lines = [
        f"extended UIO (4.5) of the {first.shift} shift, Monte-Carlo over {runs} noise seeds "
        f"({first.seed}..{first.seed + runs - 1}; the reference simulated once), samples every "
        f"{first.sample_time * 1e3:g} ms, speed noise (3.26) r = "
        f"{', '.join(f'{v:g}' for v in sorted(set(mc.relative_noise)))}; "
        f"{mc.seconds_per_run * 1e3:.0f} ms per run; initial estimates "
        f"{'drawn from the prior around the truth' if mc.prior_draw else 'fixed'}",
        "  element modes: "
        + (
            "decided by the filter (the EKF's mode logic: estimated slip, sticking torque "
            f"against capacity, F_N; {np.mean([tr.switches for tr in mc.trials]):.1f} "
            "switches per run); the bound keeps the reference's"
            if mc.mode_source == "filter"
            else "from the reference's sliding masks (the truth, not a TCU's)"
        ),
        f"  bound: {EUIO_BOUND_ASSUMPTION}",
        "  the second bound adds the filter's own process noise (random walks 4.1, model error);"
        " the third is that one with the road load known",
        "  phase          parameter   mean error       RMSE    σ (RMS)      bound  efficiency"
        "  | bound w/ noise  efficiency | load known",
    ]
    for phase in first.phases:
        for name, s in mc.phase_stats[phase.name].items():
            head = f"  {phase.name:<14} {name:<8}"
            if not s.identifiable:
                lines.append(
                    f"{head} {NOT_IDENTIFIABLE} (σ × {s.sigma_ratio:.3f}, bound × "
                    f"{s.crb_ratio:.3f}): {s.reason}"
                )
                continue
            if s.rmse is None or s.crb_sigma is None or s.mean_error is None:
                lines.append(f"{head} no scored sample")
                continue
            lines.append(
                f"{head} {s.mean_error:>11.3g} {s.rmse:>10.3g} {s.sigma:>10.3g} "
                f"{s.crb_sigma:>10.3g} {s.efficiency:>10.2f}  | {s.crb_sigma_process:>14.3g} "
                f"{s.efficiency_process:>11.2f} | {s.crb_sigma_load_known:>10.3g}"
            )
    load = mc.load_summary()
    lines.append(
        f"  T_res* (unknown input, per-sample estimate): RMSE {load['rmse']:.4g} N m, σ (RMS) "
        f"{load['sigma_rms']:.4g} N m; per phase "
        + ", ".join(f"{k} {v:.4g}" for k, v in load["rmse_per_phase"].items() if v is not None)
    )
    lo, hi = mc.nees_band()
    lines.append(
        f"  NEES mean {mc.nees_mean:.2f} over {runs} runs (dof "
        f"{float(np.mean(mc.trials[0].nees_dof)):.2f}; 95 % band {lo:.2f}..{hi:.2f}): "
        f"{'inside' if lo <= mc.nees_mean <= hi else 'OUTSIDE'}; "
        f"{100 * mc.nees_inside():.0f} % of samples' run means inside their band"
    )
    nis_mean, nis_band = mc.nis()
    if nis_mean is not None and nis_band is not None:
        lines.append(
            f"  NIS mean {nis_mean:.2f} (road load removed, dof m - 1; 95 % band "
            f"{nis_band[0]:.2f}..{nis_band[1]:.2f}): "
            f"{'inside' if nis_band[0] <= nis_mean <= nis_band[1] else 'OUTSIDE'}"
        )
    return "\n".join(lines)


def plot_euio_efficiency(mc: EuioMonteCarlo, path: Path) -> Path:
    """RMSE / matched bound per parameter and phase (n.i.: not identifiable in this phase), in
    the EKF's figure (:func:`~gearsym.validation.studies.estimation.plots.plot_efficiency_bars`)."""
    from gearsym.validation.studies.estimation.plots import plot_efficiency_bars

    first = mc.first
    title = (
        f"Extended UIO efficiency, {first.shift} shift, {len(mc.trials)} runs, samples every "
        f"{first.sample_time * 1e3:g} ms (n.i.: not identifiable in this phase)\nbars: RMSE / "
        "bound with the road load unknown in every interval, constant parameters; initial "
        f"estimates {'drawn from the prior' if mc.prior_draw else 'fixed'}"
    )
    phases = [p.name for p in first.phases]
    return plot_efficiency_bars(
        mc.parameter_names,
        phases,
        mc.phase_stats,
        "RMSE / matched bound",
        title,
        path,
        height=4.2,
        top=0.84,
    )
