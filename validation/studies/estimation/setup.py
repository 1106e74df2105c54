"""The EKF's (4.3) set-up on a simulated shift: the augmented model, its prior, the noise
(3.26), the measurements and inputs on the TCU's sample grid (:class:`EkfSetup`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import EKF_FLOOR_FRACTION, EKF_RELATIVE_NOISE
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name, quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import (
    CONSIDERED_STATES,
    DAMPING,
    INERTIA_FACTOR,
    INPUT_TORQUE_GAIN,
    STIFFNESS,
    VALVE_GAIN,
    VALVE_OFFSET,
)
from gearsym.validation.sim.phases import Phase
from gearsym.validation.sim.simulate import SimulationResult
from gearsym.validation.studies.estimation.modes import (
    MODE_SOURCES,
    ModeSwitch,
    element_modes,
    reference_switches,
)

__all__ = [
    "EkfSetup",
    "prepare_ekf",
]


@dataclass
class EkfSetup:
    """Everything about an EKF run that does not depend on the noise seed: the sample grid,
    the true outputs and their noise σ (3.26), the known inputs and element modes, the truth
    per augmented state, the initial estimate and the prior σ (P0 = diag(σ0²)). Built once for
    a Monte-Carlo study; only the noise draws change per run."""

    aug: Any
    discrete: Any
    shift: str
    t: np.ndarray
    y_true: np.ndarray  # (N, m)
    sigma_y: np.ndarray  # (N, m): r_i max(|y_i|, y_i^min) (3.26)
    relative: np.ndarray  # (m,)
    floor: np.ndarray  # (m,)
    u: np.ndarray  # (N, n_u), held over each sample interval
    p: list[float]
    q: list[float]
    truth: np.ndarray  # (N, n), NaN where none
    scored: np.ndarray  # (N, n) bool
    initial: np.ndarray  # (n,) initial estimate (speeds: filled in from the first measurement)
    prior_sigma: np.ndarray  # (n,)
    outputs: list[str]
    phases: tuple[Phase, ...]
    #: The outputs are a recording's (``y_true`` holds them, noise included): no noise is
    #: drawn and there is no truth.
    measured: bool = False
    #: :data:`MODE_SOURCES`: "filter" (its own mode logic, ``logic``) or "reference" (the
    #: reference's modes in ``u``); the truth's switches on the reference's own grid
    mode_source: str = "filter"
    logic: Any = None
    reference_switches: tuple[ModeSwitch, ...] = ()
    #: ``mu_model = "map_scale"``: the :class:`~gearsym.validation.studies.estimation.
    #: mu_map_form.MapScaleForm` that maps the F_N inputs at the filter's own estimate each
    #: step (its μ states hold the map scales); ``None``: the thesis' random-walk μ
    input_form: Any = None
    #: the inputs along the truth for the posterior bound (the F_N inputs mapped at the true
    #: slip under ``input_form``); ``None``: ``u``
    bound_u: np.ndarray | None = None
    #: indices of the states the filter carries as consider states (Schmidt): their prior
    #: enters the covariance, no measurement corrects them (:data:`~gearsym.symbolic.
    #: estimator_calibration.CONSIDERED_STATES`)
    considered: tuple[int, ...] = ()
    #: ``y_true`` holds a sensor model's readings (tooth wheels, a fleet's draw), not the
    #: reference's outputs: no noise is drawn on them, and the states keep their truth
    sensed: bool = False
    #: what the prediction over a sample interval takes for the known continuous inputs (T_In
    #: and each F_N): "sample", their values at the interval's start, held (as the emitted C
    #: filter); "mean", the mean of the interval's two samples (a TCU that commands ramps
    #: knows them: a steep lock-up ramp held at its start is read as μ)
    input_hold: str = "sample"

    @property
    def names(self) -> list[str]:
        return self.aug.state_names

    @property
    def truth0(self) -> np.ndarray:
        """The true z0 = [x0; p] as the filter's model sees it: the reference's initial states,
        m_veh and ζ; a μ at its mean while its element slides (the model's μ is constant),
        the initial estimate where an element never slides."""
        n, n_x = len(self.names), self.aug.n_x
        z0 = np.array(
            [
                np.mean(self.truth[self.scored[:, j], j])
                if self.scored[:, j].any()
                else self.initial[j]
                for j in range(n)
            ]
        )
        z0[:n_x] = self.truth[0, :n_x]
        return z0


#: |told T_In| (N·m) below which the input-torque gain has no truth: the ratio of two
#: torques near zero says nothing about a gain (and the filter learns nothing of it there).
GAIN_TORQUE_FLOOR = 5.0


def inertia_factor_truth(d: GearboxDescription, truth: GearboxDescription) -> float:
    """The common factor on the gearbox's inertias of the vehicle ``truth`` against the
    calibration ``d`` (the fleet scales them all alike), for scoring only."""
    shaft = max(d.shafts, key=lambda s: s.inertia.value)
    return float(truth.shaft(shaft.name).inertia.value / shaft.inertia.value)


def prepare_ekf(
    d: GearboxDescription,
    result: SimulationResult,
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | float = EKF_RELATIVE_NOISE,
    initial: Mapping[str, float] | None = None,
    parameters: Sequence[str] | None = None,
    aug: Any = None,
    discrete: Any = None,
    measured: Mapping[str, np.ndarray] | None = None,
    modes: str = "filter",
    logic: Any = None,
    told: Mapping[str, np.ndarray] | None = None,
    truth_description: GearboxDescription | None = None,
    floor: np.ndarray | None = None,
    truth_mu_scale: Mapping[str, float] | None = None,
    truth_valve: Mapping[str, float] | None = None,
) -> EkfSetup:
    """The seed-independent part of :func:`run_ekf` (its arguments of the same name).

    ``modes``: "filter" (default), the filter decides the element modes itself
    (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`; ``logic`` reuses a built
    :class:`~gearsym.symbolic.estimators.ekf_modes.ModeLogic`), or "reference", the
    reference's modes (:func:`element_modes`: the truth, which a TCU does not have).

    ``measured``: per output of the filter its recorded values on the sample grid (a bench
    recording, :mod:`gearsym.validation.sim.measurement`); they replace the reference's outputs,
    no noise is drawn on them, and no state has a truth. ``result`` is then the simulation
    driven by the recorded inputs: it gives the inputs, the element modes and the phases.

    ``d`` is the calibration (the filter's model, prior and tuning). ``told``: per known input
    of the filter its values on the sample grid as the TCU is told them
    (:func:`gearsym.validation.sim.fleet.told_inputs`); without it the inputs are read from
    ``result``, which is right only when the truth is the calibration. ``truth_description``:
    the description the reference simulated (a fleet's vehicle), for scoring only (default
    ``d``). ``floor``: the noise floor y_min of (3.26) per output (default: a fraction of the
    largest |y| of ``result``, right only when the truth is the calibration).
    ``truth_mu_scale``: the truth's factor on the μ map per element (a fleet's draw), the truth
    of the map-scale states (``[estimator] mu_model = "map_scale"``), for scoring only.
    ``truth_valve``: the vehicle's valve (a fleet's draw): ``valve_offset`` (Pa) and
    ``valve_gain``, the truths of those states, for scoring only (absent: not scored)."""
    from gearsym.symbolic.estimators.ekf import DiscreteModel, augmented_model, valve_input

    shift = result.scenario.shift.name
    if modes not in MODE_SOURCES:
        raise GearsymError(
            "estimate", "--modes", f"expected one of {', '.join(MODE_SOURCES)}, got {modes!r}"
        )
    if aug is None:
        aug = augmented_model(d, shift, parameters)
    if discrete is None:
        discrete = DiscreteModel(aug)
    span = result.t[-1] - result.t[0]
    if not (0 < sample_time <= span / 4):
        raise GearsymError(
            "estimate", "--sample-time", f"must be in (0, {span / 4:g}] s, got {sample_time!r}"
        )
    if modes == "filter" and logic is None:
        from gearsym.symbolic.estimators.ekf_modes import ModeLogic

        logic = ModeLogic(d, aug)
    t = np.arange(result.t[0], result.t[-1] + 1e-12, sample_time)
    names = aug.state_names
    n = len(names)
    outputs = [name.removeprefix("y_") for name in aug.output_names]

    def sampled(name: str) -> np.ndarray:
        return np.interp(t, result.t, result.signals[name])

    if measured is None:
        y_true = np.column_stack([sampled(name) for name in outputs])
    else:
        missing = [name for name in outputs if name not in measured]
        if missing:
            raise GearsymError(
                "estimate",
                "--measurement",
                f"the recording has no channel for the filter's output {missing[0]} (map it in "
                "[measurement.channel])",
            )
        y_true = np.column_stack([np.asarray(measured[name], dtype=float) for name in outputs])
        if y_true.shape[0] != len(t):
            raise GearsymError(
                "estimate",
                "--measurement",
                f"{y_true.shape[0]} recorded samples for {len(t)} sample times",
            )
    r = np.broadcast_to(np.asarray(relative_noise, dtype=float), (len(outputs),)).copy()
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise GearsymError("estimate", "--noise", "relative errors must be finite and > 0")
    if floor is None:
        floor = EKF_FLOOR_FRACTION * np.nanmax(np.abs(y_true), axis=0)
    sigma_y = r[None, :] * np.maximum(np.abs(y_true), floor[None, :])

    reference_modes = element_modes(d, result, t)
    columns = []
    for name in aug.input_names:
        element = name.split("_", 1)[1] if name.startswith(("slide_", "stick_")) else None
        valve = next((e for e in aug.elements if name == valve_input(e)), None)
        if valve is not None:  # commanded (as the TCU's F_N column says): the offset acts
            force = naming.normal_force(element_short_name(d, valve))
            columns.append((columns[aug.input_names.index(force)] > 0).astype(float))
        elif element is not None:
            columns.append(reference_modes[element][0 if name.startswith("slide_") else 1])
        elif told is not None and name in told:
            columns.append(np.asarray(told[name], dtype=float))
        else:
            columns.append(sampled(name))
    u = np.column_stack(columns)
    p = aug.parameter_values()
    q = [aug.intensities[name] for name in names]

    # truth per augmented state (NaN where the reference has none): for scoring only
    truth_description = truth_description or d
    truth = np.full((len(t), n), np.nan)
    scored = np.zeros((len(t), n), dtype=bool)
    nominal = {v.name: v.default for v in aug.model.states if v.default is not None}
    for j, name in enumerate(names):
        if name in result.signals:
            truth[:, j] = sampled(name)
            scored[:, j] = True
        elif name == "m_veh":
            truth[:, j] = quantity(truth_description, "vehicle", "m_veh").value
            scored[:, j] = True
        elif name in (STIFFNESS, DAMPING):  # the side shafts as states (--params ...,k_ss,d_ss)
            truth[:, j] = quantity(truth_description, "drivetrain", name).value
            scored[:, j] = True
        elif name in (VALVE_OFFSET, VALVE_GAIN):  # the vehicle's valve (a fleet draw)
            value = (truth_valve or {}).get(name, math.nan)
            truth[:, j] = value
            scored[:, j] = math.isfinite(value)
        elif name == INERTIA_FACTOR:  # the truth's inertias over the calibration's
            truth[:, j] = inertia_factor_truth(d, truth_description)
            scored[:, j] = True
        elif name == INPUT_TORQUE_GAIN:  # the true T_In over the told one, where it is told
            told_torque = u[:, aug.input_names.index(naming.INPUT_TORQUE)]
            defined = np.abs(told_torque) > GAIN_TORQUE_FLOOR
            truth[defined, j] = sampled(naming.INPUT_TORQUE)[defined] / told_torque[defined]
            scored[:, j] = defined
    scale_form = d.estimator.mu_model == "map_scale"
    for e, mu in aug.mu_state.items():
        j = names.index(mu)
        scored[:, j] = reference_modes[e][0] > 0.5  # μ is defined while the truth slides
        if scale_form:  # the state is the map's scale: the truth's factor on the same map
            truth[:, j] = float((truth_mu_scale or {}).get(e, 1.0))
    if measured is not None:  # a recording: no state has a truth
        truth[:] = np.nan
        scored[:] = False

    # initial estimate and prior (the speeds' are set from the first measurement per run)
    z = np.zeros(n)
    sig0 = np.zeros(n)
    for j, name in enumerate(names):
        if name in outputs:
            sig0[j] = sigma_y[0, outputs.index(name)]
        elif scale_form and name in aug.mu_state.values():
            z[j], sig0[j] = d.estimator.scale_prior()
            q[j] = d.estimator.scale_random_walk()
        else:  # the calibration's prior (the description's [estimator] table), not the truth
            z[j], sig0[j] = d.estimator.prior_of(name, nominal.get(name))
    input_form, bound_u = None, None
    if scale_form:
        from gearsym.validation.studies.estimation.mu_map_form import map_scale_form

        input_form = map_scale_form(d, aug)
        slips = np.column_stack([sampled(naming.slip_column(e)) for e in aug.elements])
        bound_u = input_form.along(u, slips)
    for name, value in (initial or {}).items():
        if name not in names:
            raise GearsymError(
                "estimate", "--initial", f"{name!r} is not a state ({', '.join(names)})"
            )
        z[names.index(name)] = float(value)
    return EkfSetup(
        aug=aug,
        discrete=discrete,
        shift=shift,
        t=t,
        y_true=y_true,
        sigma_y=sigma_y,
        relative=r,
        floor=floor,
        u=u,
        p=p,
        q=q,
        truth=truth,
        scored=scored,
        initial=z,
        prior_sigma=sig0,
        outputs=outputs,
        phases=tuple(result.phases),
        measured=measured is not None,
        mode_source=modes,
        logic=logic,
        reference_switches=tuple(reference_switches(d, result)),
        input_form=input_form,
        bound_u=bound_u,
        considered=tuple(j for j, name in enumerate(names) if name in CONSIDERED_STATES),
    )
