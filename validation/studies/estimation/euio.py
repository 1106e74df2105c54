"""The extended UIO (4.5) run on the reference simulation: the road load as unknown input
(:mod:`gearsym.symbolic.estimators.euio`), on the EKF's set-up.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import EKF_RELATIVE_NOISE
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.validation.sim.phases import Phase
from gearsym.validation.sim.phases import phase_of as sim_phase_of
from gearsym.validation.sim.simulate import SimulationResult
from gearsym.validation.studies.estimation.loop import (
    ParameterEstimate,
    noisy_outputs,
    parameter_estimates,
)
from gearsym.validation.studies.estimation.setup import EkfSetup, prepare_ekf
from gearsym.validation.studies.estimation.uio import _rms


@dataclass(frozen=True)
class EuioRun:
    """The extended UIO along one reference shift: estimates and σ per sample, the estimated
    road load d̂ = T_res* against the reference's T_res (2.48), existence per phase."""

    shift: str
    sample_time: float
    seed: int
    state_names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    estimates: np.ndarray = field(repr=False)
    sigmas: np.ndarray = field(repr=False)
    truth: np.ndarray = field(repr=False)
    scored: np.ndarray = field(repr=False)
    held: np.ndarray = field(repr=False)  # (N, n) bool: estimate held at this sample
    load: np.ndarray = field(repr=False)  # (N,) d̂ over the interval ending at sample k
    load_sigma: np.ndarray = field(repr=False)
    load_truth: np.ndarray = field(repr=False)  # T_res of the reference, mid-interval
    phases: tuple[Phase, ...]
    existence: dict[str, list[Any]]  # phase name -> per parameter EuioExistence
    parameters: tuple[ParameterEstimate, ...]
    #: where the element modes came from: "reference" (run_euio) or "filter" (the EKF's
    #: mode logic, :func:`gearsym.validation.studies.euio_evaluation.euio_filter_run`)
    mode_source: str = "reference"

    def load_rmse(self, phase: Phase | None = None) -> float:
        """RMS of d̂ − T_res over the samples (of ``phase``) where d̂ exists."""
        ok = np.isfinite(self.load)
        if phase is not None:
            ok &= (self.t > phase.t_start) & (self.t <= phase.t_end)
        return _rms(self.load[ok] - self.load_truth[ok]) if ok.any() else float("nan")

    def to_dict(self) -> dict[str, Any]:
        params = {}
        for pe in self.parameters:
            entry = pe.to_dict()
            entry["identifiable"] = {
                ph: next(e.exists for e in ex if e.parameter == pe.name)
                for ph, ex in self.existence.items()
            }
            entry["held_because"] = {
                ph: next(e.reason() for e in ex if e.parameter == pe.name)
                for ph, ex in self.existence.items()
                if not next(e.exists for e in ex if e.parameter == pe.name)
            }
            params[pe.name] = entry
        return {
            "filter": "euio",
            "shift": self.shift,
            "runs": 1,
            "modes": self.mode_source,
            "seed": self.seed,
            "sample_time": self.sample_time,
            "parameters": params,
            "unknown_inputs": {
                naming.RESISTANCE_INPUT: {
                    "rmse": self.load_rmse(),
                    "rmse_per_phase": {p.name: self.load_rmse(p) for p in self.phases},
                    "absorbs": "zeta, rolling and aero resistance (2.48)",
                }
            },
            "nees_mean": None,
            "nees_band": None,
            "nis_mean": None,
            "phases": [
                {
                    "name": p.name,
                    "t_start": p.t_start,
                    "t_end": p.t_end,
                    "existence": [e.to_dict() for e in self.existence[p.name]],
                }
                for p in self.phases
            ],
        }


def run_euio(
    d: GearboxDescription,
    result: SimulationResult,
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | float = EKF_RELATIVE_NOISE,
    seed: int = 0,
    initial: Mapping[str, float] | None = None,
    noise: bool = True,
) -> EuioRun:
    """The extended UIO (4.5) along the reference shift of ``result``: m_veh, μ_off, μ_on with
    the road load T_res* (absorbing ζ) as unknown input; measurements, noise (3.26), inputs,
    element modes and initial estimate as :func:`run_ekf` (``noise=False``: the true
    outputs, the noise level only sets R). Existence per phase on the linearisation at the
    phase's midpoint (truth states, nominal parameters); a parameter whose conditions fail in
    a phase is held there."""
    from gearsym.symbolic.estimators.ekf import default_parameters
    from gearsym.symbolic.estimators.euio import (
        ROAD_FREE,
        euio_step,
        load_column,
    )

    parameters = [name for name in default_parameters(d, result.scenario.shift.name)]
    parameters = [name for name in parameters if name != naming.GRADE]
    setup = prepare_ekf(d, result, sample_time, relative_noise, initial, parameters)
    aug, discrete = setup.aug, setup.discrete
    p = aug.parameter_values(ROAD_FREE)
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    i_wheel = float(p[[v.name for v in aug.model.parameters].index("I_wheel")])
    t, names, n = setup.t, setup.names, len(setup.names)
    h = float(t[1] - t[0])
    y = setup.y_true.copy() if not noise else noisy_outputs(setup, seed)
    z = setup.initial.copy()
    for k, name in enumerate(setup.outputs):
        if name in names:
            z[names.index(name)] = y[0, k]
    P = np.diag(setup.prior_sigma**2)
    initial_values = z.copy()
    q = np.array(setup.q, dtype=float)

    existence, held_by_phase = existence_per_phase(setup, p, r_dyn, i_wheel)

    def phase_of(time: float) -> str:
        return sim_phase_of(setup.phases, time) or setup.phases[-1].name

    estimates = np.empty((len(t), n))
    sigmas = np.empty((len(t), n))
    held = np.zeros((len(t), n), dtype=bool)
    load = np.full(len(t), np.nan)
    load_sigma = np.full(len(t), np.nan)
    estimates[0], sigmas[0] = z, np.sqrt(np.diag(P))
    for k in range(1, len(t)):
        hold = sorted(set(held_by_phase[phase_of(t[k])]) | set(aug.frozen_states(setup.u[k - 1])))
        held[k, hold] = True
        R = measurement_variances(setup, y[k])
        e = load_column(discrete, z, r_dyn, p, i_wheel)
        z, P, load[k], load_sigma[k] = euio_step(
            discrete, z, P, setup.u[k - 1], setup.u[k], y[k], R, h, p, q, e, hold
        )
        estimates[k], sigmas[k] = z, np.sqrt(np.diag(P))
    t_mid = np.r_[t[0], 0.5 * (t[1:] + t[:-1])]
    load_truth = np.interp(t_mid, result.t, result.signals[naming.ROAD_TORQUE])

    by_parameter = parameter_estimates(
        aug.parameters, names, setup.truth, setup.scored, estimates, sigmas, initial_values
    )
    return EuioRun(
        shift=setup.shift,
        sample_time=h,
        seed=seed,
        state_names=tuple(names),
        t=t,
        estimates=estimates,
        sigmas=sigmas,
        truth=setup.truth,
        scored=setup.scored,
        held=held,
        load=load,
        load_sigma=load_sigma,
        load_truth=load_truth,
        phases=setup.phases,
        existence=existence,
        parameters=tuple(by_parameter),
    )


def measurement_variances(setup: EkfSetup, y: np.ndarray) -> np.ndarray:
    """The EUIO's R per output at the measured values ``y``: r_i² max(|y_i|, y_i^min)²
    (3.26), the EKF's measurement_variance (taken at the measurement: the TCU does not know
    the true value)."""
    return (setup.relative * np.maximum(np.abs(y), setup.floor)) ** 2


def existence_per_phase(
    setup: EkfSetup, p: Sequence[float], r_dyn: float, i_wheel: float
) -> tuple[dict[str, list[Any]], dict[str, list[int]]]:
    """The EUIO's existence test (4.4) per phase, on the linearisation at the truth at the
    phase's middle (the design-time analysis, as the emitted header's masks), and per phase
    the indices of the states it holds (those whose test fails)."""
    from gearsym.symbolic.estimators.euio import euio_existence, load_column

    t, names, aug, discrete = setup.t, setup.names, setup.aug, setup.discrete
    existence: dict[str, list[Any]] = {}
    held_by_phase: dict[str, list[int]] = {}
    for phase in setup.phases:
        mid = int(np.argmin(np.abs(t - 0.5 * (phase.t_start + phase.t_end))))
        zop = setup.truth0.copy()
        zop[: aug.n_x] = setup.truth[mid, : aug.n_x]
        e = load_column(discrete, zop, r_dyn, p, i_wheel)
        existence[phase.name] = euio_existence(discrete, phase.name, zop, setup.u[mid], p, e)
        held_by_phase[phase.name] = [
            names.index(x.parameter) for x in existence[phase.name] if not x.exists
        ]
    return existence, held_by_phase
