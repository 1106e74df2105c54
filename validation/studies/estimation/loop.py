"""The EKF (4.3) run: the filter loop over the measurements of an :class:`~.setup.EkfSetup`
(predict, per-output update, element-mode switches) and its result (:class:`EkfRun`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic.defaults import EKF_RELATIVE_NOISE
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.sim.phases import Phase
from gearsym.validation.sim.simulate import SimulationResult
from gearsym.validation.studies.estimation.modes import (
    ModeSwitch,
    _status_code,
    match_switches,
    mode_switches,
)
from gearsym.validation.studies.estimation.setup import EkfSetup, prepare_ekf

__all__ = [
    "EkfRun",
    "ParameterEstimate",
    "filter_run",
    "noisy_outputs",
    "run_ekf",
    "start_from_first_measurement",
]


@dataclass(frozen=True)
class ParameterEstimate:
    """One augmented parameter over one EKF run."""

    name: str
    truth: float  # at the end of the scored samples (μ: the last sliding sample)
    initial: float
    estimate: float  # at the same sample
    sigma: float
    rmse: float  # over the scored samples (μ: while its element slides)
    scored: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "truth": self.truth,
            "initial": self.initial,
            "estimate": self.estimate,
            "sigma": self.sigma,
            "rmse": self.rmse,
            "samples": self.scored,
            "crb_sigma": None,
            "efficiency": None,
        }


@dataclass(frozen=True)
class EkfRun:
    """The EKF along one reference shift: estimates, σ, truths, NEES and NIS per sample."""

    shift: str
    sample_time: float
    relative_noise: tuple[float, ...]
    seed: int
    state_names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    estimates: np.ndarray = field(repr=False)  # (N, n) after each update
    sigmas: np.ndarray = field(repr=False)  # (N, n)
    truth: np.ndarray = field(repr=False)  # (N, n), NaN where there is none
    scored: np.ndarray = field(repr=False)  # (N, n) bool: truth defined and compared
    nees: np.ndarray = field(repr=False)  # (N,)
    nees_dof: np.ndarray = field(repr=False)  # (N,)
    nis: np.ndarray = field(repr=False)  # (N,)
    nis_dof: np.ndarray = field(repr=False)  # (N,)
    phases: tuple[Phase, ...]
    parameters: tuple[ParameterEstimate, ...]
    min_eigenvalue: float  # smallest eigenvalue of P over the run (scaled), > 0: SPD
    covariance: np.ndarray | None = field(default=None, repr=False)  # P after the last sample
    #: where the element modes came from (:data:`MODE_SOURCES`), the mode codes held from each
    #: sample on (0 open, ±1 slide, 2 stick), the switches, and the truth's switches
    mode_source: str = "reference"
    modes: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    switches: tuple[ModeSwitch, ...] = ()
    reference_switches: tuple[ModeSwitch, ...] = ()

    def events(self) -> list[dict[str, Any]]:
        """The detected switches against the truth's (:func:`match_switches`)."""
        return match_switches(self.switches, self.reference_switches)

    @property
    def nees_mean(self) -> float:
        return float(np.mean(self.nees))

    def nees_band(self, probability: float = 0.95) -> tuple[float, float]:
        """Band of the time-averaged NEES if the filter were consistent: Σ NEES ~ χ²(Σ dof)
        (samples treated as independent, so the band is a narrow one), divided by N."""
        return _chi2_mean_band(self.nees_dof, probability)

    def nees_inside(self, probability: float = 0.95) -> float:
        """Fraction of samples whose NEES lies inside its χ²(dof) interval (expected:
        ``probability``)."""
        from scipy.stats import chi2

        lo = chi2.ppf((1 - probability) / 2, self.nees_dof)
        hi = chi2.ppf((1 + probability) / 2, self.nees_dof)
        return float(np.mean((self.nees >= lo) & (self.nees <= hi)))

    def to_dict(self) -> dict[str, Any]:
        band = self.nees_band()
        used = self.nis_dof > 0
        return {
            "filter": "ekf",
            "shift": self.shift,
            "runs": 1,
            "seed": self.seed,
            "sample_time": self.sample_time,
            "relative_noise": list(self.relative_noise),
            "parameters": {p.name: p.to_dict() for p in self.parameters},
            "nees_mean": self.nees_mean,
            "nees_band": list(band),
            "nees_inside_95": self.nees_inside(),
            "nees_dof_mean": float(np.mean(self.nees_dof)),
            "nis_mean": float(np.mean(self.nis[used])) if used.any() else None,
            "nis_band": list(_chi2_mean_band(self.nis_dof[used])) if used.any() else None,
            "min_covariance_eigenvalue": self.min_eigenvalue,
            "modes": self.mode_source,
            "events": self.events(),
            "phases": [p.to_dict() for p in self.phases],
        }


def parameter_estimates(
    parameters: Sequence[str],
    names: Sequence[str],
    truth: np.ndarray,
    scored: np.ndarray,
    estimates: np.ndarray,
    sigmas: np.ndarray,
    initial: np.ndarray,
) -> list[ParameterEstimate]:
    """Per parameter of one run (the EKF's or the EUIO's): the estimate and σ at its last
    scored sample (μ: the last sliding one), the truth there, the initial value, the RMSE
    over the scored samples."""
    out = []
    for name in parameters:
        j = list(names).index(name)
        inside = np.flatnonzero(scored[:, j])
        last = inside[-1] if inside.size else len(estimates) - 1
        err = estimates[inside, j] - truth[inside, j]
        out.append(
            ParameterEstimate(
                name=name,
                truth=float(truth[last, j]),
                initial=float(initial[j]),
                estimate=float(estimates[last, j]),
                sigma=float(sigmas[last, j]),
                rmse=float(np.sqrt(np.mean(err**2))) if inside.size else float("nan"),
                scored=int(inside.size),
            )
        )
    return out


def _chi2_mean_band(dof: np.ndarray, probability: float = 0.95) -> tuple[float, float]:
    from scipy.stats import chi2

    total, n = float(np.sum(dof)), len(dof)
    return (
        float(chi2.ppf((1 - probability) / 2, total) / n),
        float(chi2.ppf((1 + probability) / 2, total) / n),
    )


def run_ekf(
    d: GearboxDescription,
    result: SimulationResult,
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | float = EKF_RELATIVE_NOISE,
    seed: int = 0,
    initial: Mapping[str, float] | None = None,
    parameters: Sequence[str] | None = None,
    dropout: tuple[float, float] | None = None,
    aug: Any = None,
    discrete: Any = None,
    setup: EkfSetup | None = None,
    modes: str = "filter",
) -> EkfRun:
    """The EKF (4.3) on the augmented model (4.1) along the reference shift of ``result``.

    Measurements: the reference's speeds (3.31) every ``sample_time`` s plus Gaussian noise of
    σ_i = r_i max(|y_i|, y_i^min) (3.26), drawn with ``seed``; ``dropout`` = (t0, t1) replaces
    every measurement in [t0, t1) by NaN (a sensor dropout: the updates are skipped). Known
    inputs T_In, F_N at the samples, held; element modes decided by the filter (``modes``
    "filter", default) or the reference's (:func:`element_modes`, ``modes`` "reference").
    ``initial`` overrides the default initial estimate (m_veh 30 % light, μ nominal, ζ 0, φ 0,
    the speeds from the first measurement). ``aug``/``discrete`` reuse a built model;
    ``setup`` (from :func:`prepare_ekf`) reuses everything but the noise draws.
    """
    if setup is None:
        setup = prepare_ekf(
            d, result, sample_time, relative_noise, initial, parameters, aug, discrete, modes=modes
        )
    return filter_run(setup, seed, dropout)


def interval_mean(setup: EkfSetup, u_before: np.ndarray, k: int) -> np.ndarray:
    """``u_before`` (the inputs held from sample k - 1) with each known continuous input (T_In,
    each F_N) at the mean of its samples k - 1 and k: the interval's mean of a linear ramp. The
    element modes and valve flags the filter decided stay held."""
    from gearsym.symbolic.estimators.ekf import slide_input, stick_input, valve_input

    flags = {f(e) for e in setup.aug.elements for f in (slide_input, stick_input, valve_input)}
    out = np.array(u_before, dtype=float)
    for i, name in enumerate(setup.aug.input_names):
        if name not in flags:
            out[i] = 0.5 * (float(setup.u[k - 1][i]) + float(setup.u[k][i]))
    return out


def noisy_outputs(setup: EkfSetup, seed: int) -> np.ndarray:
    """The synthetic measurements: the reference's outputs plus Gaussian noise of
    σ_i = r_i max(|y_i|, y_i^min) (3.26), drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    return setup.y_true + rng.normal(0.0, 1.0, setup.y_true.shape) * setup.sigma_y


def start_from_first_measurement(
    s: EkfSetup, y0: np.ndarray, z: np.ndarray, sig0: np.ndarray
) -> np.ndarray:
    """Set the measured states of ``z`` to the first measurement ``y0`` (in place; a missing
    one: 0 with σ 1e3 in ``sig0``) and return what the first update may still use.

    The first measurement of a speed *is* its initial estimate (variance R, the prior of
    sig0): it is used once, so the update at the first sample skips it (NaN). Updating with it
    again would count one noise draw twice (the speed's σ halved for an error of one σ) and
    add innovations that are 0 by construction to the NIS (3 of its dof per run)."""
    first = np.array(y0, dtype=float)
    for k, name in enumerate(s.outputs):
        if name in s.names:
            j = s.names.index(name)
            if np.isfinite(y0[k]):
                z[j] = y0[k]
                first[k] = np.nan
            else:
                z[j], sig0[j] = 0.0, 1e3
    return first


def filter_run(
    setup: EkfSetup,
    seed: int = 0,
    dropout: tuple[float, float] | None = None,
    prior_draw: bool = False,
    dropout_outputs: Sequence[str] | None = None,
    carried: tuple[Sequence[str], np.ndarray, np.ndarray] | None = None,
    lock_up_before_update: bool = True,
) -> EkfRun:
    """One EKF run (4.3) on ``setup``'s samples with the noise (3.26) drawn from ``seed``.

    ``carried`` = (names, mean, covariance): the initial estimate and the covariance block of
    these states are taken over from a previous run (a drive of consecutive shifts: what the
    filter knows about m_veh and ζ at the end of one shift is its prior for the next).

    ``dropout`` = (t0, t1): the measurements in [t0, t1) are NaN (a sensor dropout), of every
    output or only of ``dropout_outputs`` (names of :attr:`EkfSetup.outputs`); the update
    skips each NaN speed on its own, as the emitted C does.

    ``prior_draw``: the initial estimate of every unmeasured state (φ and the parameters) is
    the truth (:attr:`EkfSetup.truth0`) plus a draw from the prior N(0, σ0²) (a second stream
    of ``seed``), the premise of the posterior bound, instead of the fixed initial estimate.

    Element modes (``setup.mode_source``): "reference" takes them from ``setup.u`` (the
    truth's); "filter" starts in the from-gear and, after each update, lets
    :func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update` decide the modes held over
    the next interval from the posterior, the measured speeds' estimate and F_N (a lock-up
    maps z and P through the hybrid model's state map); a μ whose element it holds sliding
    but whose estimated slip is within two σ of zero is not corrected in that update
    (:func:`~gearsym.symbolic.estimators.ekf_modes.ambiguous_mu`). The estimate, σ and NEES
    recorded at a sample are the update's; a switch decided there acts from the next
    prediction on.

    ``lock_up_before_update`` (default): the lock-ups are also decided on the *predicted*
    state, before the sample's measurement update (``ekf_mode_update(..., lock_ups_only=True)``),
    and the interval is predicted again through the lock-up: sliding up to the slip's zero,
    the lock-up map there, sticking after (:func:`_predict_through_lock_up`, the hybrid model's
    event located inside the interval). Decided after the update only, the filter weighs the
    first locked sample's speeds with a slip the truth no longer has; on the 3-4 with the
    μ-map scales that one update moved the torque gain by 4 % and left the fleet's NEES/NIS
    far outside their bands (docs/fleet.md)."""
    from gearsym.symbolic.estimators.ekf import ekf_predict, ekf_update
    from gearsym.symbolic.estimators.ekf_modes import ambiguous_mu, ekf_mode_update

    s = setup
    t, names, n = s.t, s.names, len(s.names)
    sample_time = float(t[1] - t[0])
    y = s.y_true.copy() if s.measured or s.sensed else noisy_outputs(s, seed)
    if dropout is not None:
        lost = (t >= dropout[0]) & (t < dropout[1])
        for name in dropout_outputs if dropout_outputs is not None else s.outputs:
            if name not in s.outputs:
                raise GearsymError(
                    "estimate", "--dropout", f"{name!r} is not an output ({', '.join(s.outputs)})"
                )
            y[lost, s.outputs.index(name)] = np.nan
    z = s.initial.copy()
    sig0 = s.prior_sigma.copy()
    if prior_draw:
        unmeasured = np.array([name not in s.outputs for name in names])
        draw = np.random.default_rng([seed, 1]).normal(0.0, 1.0, len(z)) * sig0
        z[unmeasured] = s.truth0[unmeasured] + draw[unmeasured]
    first = start_from_first_measurement(s, y[0], z, sig0)
    P = np.diag(sig0**2)
    if carried is not None:
        idx = [names.index(name) for name in carried[0]]
        z[idx] = carried[1]
        P[np.ix_(idx, idx)] = carried[2]
        sig0[idx] = np.sqrt(np.diag(carried[2]))
    initial_values = z.copy()
    truth, scored = s.truth, s.scored

    estimates = np.empty((len(t), n))
    sigmas = np.empty((len(t), n))
    nis = np.zeros(len(t))
    nis_dof = np.zeros(len(t))
    nees = np.zeros(len(t))
    min_eig = np.inf
    scale = np.maximum(sig0, 1e-12)
    logic = s.logic if s.mode_source == "filter" else None
    form = s.input_form
    if logic is not None:
        modes = logic.initial_modes()
        codes = {e: np.zeros(len(t), dtype=int) for e in logic.elements}
        switches: list[ModeSwitch] = []
        held = logic.inputs(s.u[0], modes)
    last_switch = -np.inf  # the time of the filter's last mode switch (in-gear settling)
    for k in range(len(t)):
        if logic is None:
            u_before, u_now = s.u[k - 1], s.u[k]
        else:  # the modes held since the previous sample, the known inputs of this one
            u_before, u_now = held, logic.inputs(s.u[k], modes)
        if k > 0 and s.input_hold == "mean":  # the commanded ramp's mean over the interval
            u_before = interval_mean(s, u_before, k)  # (before the map: it reads the F_N)
        if form is not None:  # the μ map read at the filter's own estimate (mu_map_form)
            u_before = form(z, u_before)
        if k > 0:
            z_before, P_before = z, P
            since = float(t[k - 1] - last_switch)
            z, P = ekf_predict(s.discrete, z, P, u_before, sample_time, s.p, s.q, since)
        if logic is not None and k > 0 and lock_up_before_update:
            known = s.u[k] if form is None else form(z, s.u[k])
            _, _, after, decided = ekf_mode_update(
                logic, z, P, known, s.p, modes, lock_ups_only=True, passed_sigmas=LOCK_UP_SURE
            )
            if decided:  # locked up inside the interval: predict to there, map, predict on
                (locked,) = decided  # one element sticks at a time
                z, P = _predict_through_lock_up(
                    s, logic, z_before, P_before, z, u_before, locked.element, after, sample_time
                )
                modes = after
                last_switch = float(t[k])
                switches.append(
                    ModeSwitch(
                        locked.element, locked.kind, float(t[k]), locked.before, locked.after
                    )
                )
                u_now = logic.inputs(s.u[k], modes)
        if form is not None:
            u_now = form(z, u_now)
        # a μ whose element may already stick is not corrected (ambiguous_mu)
        consider = [] if logic is None else ambiguous_mu(logic, z, P, u_now, s.p, modes)
        consider = [*s.considered, *consider]  # and the states no shift corrects
        z, P, nis[k], nis_dof[k] = ekf_update(
            s.discrete, z, P, u_now, first if k == 0 else y[k], s.p, s.relative, s.floor, consider
        )
        estimates[k] = z
        sigmas[k] = np.sqrt(np.diag(P))
        idx = np.flatnonzero(scored[k])
        error = z[idx] - truth[k, idx]
        min_eig = min(min_eig, float(np.linalg.eigvalsh(P / np.outer(scale, scale))[0]))
        nees[k] = float(error @ np.linalg.solve(P[np.ix_(idx, idx)], error))
        if logic is not None:
            known = s.u[k] if form is None else form(z, s.u[k])
            z, P, modes, decided = ekf_mode_update(logic, z, P, known, s.p, modes)
            switches += [
                ModeSwitch(ev.element, ev.kind, float(t[k]), ev.before, ev.after) for ev in decided
            ]
            if decided:
                last_switch = float(t[k])
            for e, code in modes.items():
                codes[e][k] = code
            held = logic.inputs(s.u[k], modes)
    if logic is None:
        aug, inputs = s.aug, s.aug.input_names
        codes = {
            e: _status_code(s.u[:, inputs.index(f"slide_{e}")], s.u[:, inputs.index(f"stick_{e}")])
            for e in aug.elements
        }
        switches = mode_switches(t, codes)

    estimates_by_parameter = parameter_estimates(
        s.aug.parameters, names, truth, scored, estimates, sigmas, initial_values
    )
    return EkfRun(
        shift=s.shift,
        sample_time=sample_time,
        relative_noise=tuple(float(v) for v in s.relative),
        seed=seed,
        state_names=tuple(names),
        t=t,
        estimates=estimates,
        sigmas=sigmas,
        truth=truth,
        scored=scored,
        nees=nees,
        nees_dof=scored.sum(axis=1).astype(float),
        nis=nis,
        nis_dof=nis_dof,
        phases=s.phases,
        parameters=tuple(estimates_by_parameter),
        min_eigenvalue=min_eig,
        covariance=P,
        mode_source=s.mode_source,
        modes=codes,
        switches=tuple(switches),
        reference_switches=s.reference_switches,
    )


#: How many σ of its predicted slip an element's slip must have passed zero by for the filter
#: to lock it up before the sample's update (:func:`filter_run`). Closer to zero the truth may
#: still slide at the sample while the mapped filter holds the slip at zero with the small
#: model error of part of an interval (one such sample gave a NEES of 741 on the default 2-3,
#: seed 8, at 0); such a lock-up is left to the decision after the update, whose overshoot is
#: then within those σ.
LOCK_UP_SURE = 2.0


def _predict_through_lock_up(
    s: EkfSetup,
    logic: Any,
    z_before: np.ndarray,
    P_before: np.ndarray,
    z_predicted: np.ndarray,
    u_before: np.ndarray,
    element: str,
    modes_after: Mapping[str, int],
    sample_time: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The prediction over an interval in which ``element`` locks up (the hybrid model's
    event inside a sample interval): the slip is linear in the speeds, so its zero lies at the
    fraction τ = s₀ / (s₀ − s₁) of the interval (s₀ the slip at the previous posterior, s₁ at
    the sliding prediction); predict to τ h with the element sliding, map z and P there
    (:meth:`~gearsym.symbolic.estimators.ekf_modes.ModeLogic.map_state`), predict the rest with
    it sticking (``modes_after``). The model error of that rest keeps P regular at the update."""
    from gearsym.symbolic.estimators.ekf import ekf_predict

    i = list(logic.elements).index(element)
    s0 = float(logic._evaluate(z_before, u_before, s.p)[0][i])
    s1 = float(logic._evaluate(z_predicted, u_before, s.p)[0][i])
    # s0 has the sliding direction's sign and s1 has passed zero; τ = 0 if s0 had already
    tau = min(max(s0 / (s0 - s1), 0.0), 1.0) if s0 != s1 else 0.0
    z, P = z_before, P_before
    if tau > 0.0:
        z, P = ekf_predict(s.discrete, z, P, u_before, tau * sample_time, s.p, s.q)
    z, P = logic.map_state(element, z, P)
    rest = (1.0 - tau) * sample_time
    if rest > 0.0:
        u_rest = logic.inputs(u_before, modes_after)
        z, P = ekf_predict(s.discrete, z, P, u_rest, rest, s.p, s.q, since_switch=0.0)
    return z, P


#: The parameters a drive of consecutive shifts carries from one shift to the next: they
#: belong to the vehicle and the road, not to a shift's elements.
DRIVE_CARRIED = ("m_veh", "zeta")


def run_ekf_drive(
    d: GearboxDescription,
    results: Sequence[SimulationResult],
    seed: int = 0,
    sample_time: float = 0.01,
    initial: Mapping[str, float] | None = None,
    modes: str = "filter",
) -> list[EkfRun]:
    """The EKF (4.3) through consecutive shifts, carrying m_veh and ζ (:data:`DRIVE_CARRIED`).

    Each result is one shift's reference simulation (its own scenario, simulated on its own:
    the reference does not chain shifts, so the vehicle speed at one shift's start is its
    scenario's, not the previous shift's end). The filter of shift k+1 (its own augmented
    model (4.1): the μ of its swapping elements) starts from the estimate and the covariance
    block of m_veh and ζ at the end of shift k; its other states start as in a single shift
    (μ at the prior: another element or another operating point). ``initial`` is the first
    shift's initial estimate; shift k uses noise seed ``seed`` + k. ``modes``: as
    :func:`prepare_ekf` (each shift's filter starts in its from-gear)."""
    runs: list[EkfRun] = []
    carried = None
    for k, result in enumerate(results):
        setup = prepare_ekf(
            d, result, sample_time, initial=initial if k == 0 else None, modes=modes
        )
        run = filter_run(setup, seed + k, carried=carried)
        idx = [list(run.state_names).index(name) for name in DRIVE_CARRIED]
        assert run.covariance is not None
        carried = (
            DRIVE_CARRIED,
            run.estimates[-1, idx].copy(),
            run.covariance[np.ix_(idx, idx)].copy(),
        )
        runs.append(run)
    return runs
