"""The EKF (thesis 4.1, 4.3) carried over a whole drive (:mod:`gearsym.validation.sim.drive`),
from the TCU's log only: the measured speeds with the sensors' noise (3.26), the commanded
input torque and pressures, the brake; the truth is for scoring.

**One filter, its model following the gearbox.** The filter runs the augmented model of one
single-swap shift (:func:`~gearsym.symbolic.estimators.ekf.augmented_model`: the two swapping
elements' torques by their modes, the others locked): between shifts the model of the last
shift in its to-gear (the on-coming element sticking), at the start the first upshift's in its
from-gear. When the TCU starts a shift whose model is another one, the filter hands over by
state name: the speeds, the twist, m_veh and ζ with their covariance block; each element's μ
from the model that had it, or from the store where the μ of elements outside the present
model wait (mean and variance; their covariances with the rest are dropped there: a μ is only
observable while its element slides, which decouples it between its shifts); a μ never seen
starts at the prior. The modes start as the TCU knows them (the from-gear) and follow the
filter's own mode logic (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`)
during the shift, with a synchronisation window (:data:`SYNC_BAND`). In a gear the TCU holds
line pressure on the gear's elements, so the filter's modes are the gear's (its own decision,
no mode logic): a lock-up the logic had not decided by the shift's end is mapped there (the
hybrid model's lock-up map).
A μ's random walk runs only while its element slides (a locked or open element's μ does not
move what the filter sees; :meth:`~gearsym.symbolic.estimators.ekf.AugmentedModel.frozen_states`).

**What the filter cannot model.** Its model has no service brake and no standstill: while the
TCU sees the brake applied or the vehicle standing (measured wheel speed below
:data:`STANDSTILL_SPEED`, no torque), it holds the parameters and their covariance and sets
the measured speeds from the measurement (their variance from R); the side shafts' twist it
cannot measure goes back to its prior's σ (what the brake did to it is unknown to the model).
Stated, not hidden: the samples held are counted.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import EKF_FLOOR_FRACTION, EKF_RELATIVE_NOISE
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name, quantity
from gearsym.validation.studies.estimation.compiled_discrete import compiled_or_casadi
from gearsym.validation.studies.estimation.drive_states import (
    AppendedState,
    _Appended,
    engine_gain_state,
    stiffness_state,
    stiffness_truth,
)

__all__ = ["DriveEstimates", "EkfCarry", "FilterModels", "ekf_over_drive", "run_drive_ekf"]

#: Below this measured vehicle speed (m/s), with no torque commanded, the vehicle stands.
STANDSTILL_SPEED = 0.3

#: The TCU's synchronisation window (rad/s): a sliding element's estimated slip this close to
#: zero counts as locking up (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`).
#: Assumed: about the slip one 10 ms sample covers at the end of a 0.35 s speed phase.
SYNC_BAND = 2.0

#: The grade's RMS error is also reported from this time on (s): the first minute is the
#: prior's (the grade is learned only once the vehicle drives).
GRADE_RMS_FROM = 60.0

#: Slides of an element closer than this (s) count as one (a shift's break-away and re-lock).
SLIDE_GAP = 0.5
#: Each μ is also scored at the end of its element's third slide (the drive issue's "after
#: its third shift").
THIRD = 3

#: The vehicle's parameters every model has, carried with their covariance block.
CARRIED = ("m_veh", naming.GRADE)


@dataclass(frozen=True)
class EkfCarry:
    """What the filter keeps from the end of one log to the start of the next (a TCU keeps it
    over ignition cycles, the adaptive-control study from shift to shift): the states
    ``names`` with their joint mean and covariance (m_veh and ζ, the valve's offset when the
    filter has it, the μ of the model it ended in), and the μ of the elements outside that
    model as mean and variance (their covariances with the rest dropped, as in the store
    between shifts)."""

    names: tuple[str, ...]
    mean: tuple[float, ...]
    covariance: tuple[tuple[float, ...], ...]
    mu: tuple[tuple[str, float, float], ...]

    def of(self, name: str) -> tuple[float, float]:
        """(mean, σ) of a carried state."""
        if name in self.names:
            j = self.names.index(name)
            return self.mean[j], math.sqrt(max(self.covariance[j][j], 0.0))
        for other, mean, var in self.mu:
            if other == name:
                return mean, math.sqrt(max(var, 0.0))
        raise KeyError(name)


def ekf_over_drive(
    d: GearboxDescription,
    drive: Any,
    seed: int,
    engine_gain: bool = False,
    engine_gain_truth: float = math.nan,
    models: FilterModels | None = None,
) -> DriveEstimates:
    """The EKF over a finished drive's TCU log (:class:`~gearsym.validation.sim.drive.DriveResult`
    with a log), as ``gearsym drive`` and the fleet's drives run it: the side shafts'
    stiffness factor as a state (:func:`stiffness_state`), with ``engine_gain`` the engine's
    torque gain too (:func:`engine_gain_state`; tried and not adopted, docs/drive.md); the
    drive's truth for scoring only (its mass and stiffness factor; ``engine_gain_truth`` the
    vehicle's engine gain), the sensors' noise from ``seed``; ``models``: the filter's
    models kept by a caller that runs many drives (:class:`FilterModels`)."""
    arrays = drive.log.arrays()
    appended = [stiffness_state(d, stiffness_truth(d, drive.values))]
    if engine_gain:
        appended.append(engine_gain_state(d, arrays, engine_gain_truth))
    return run_drive_ekf(
        d,
        arrays,
        drive.log.shifts(),
        drive.gears,
        drive.values["m_veh"],
        seed,
        appended=tuple(appended),
        models=models,
    )


@dataclass
class DriveEstimates:
    """Per TCU sample: each estimated parameter's mean and σ (``m_veh``, ``zeta``,
    ``mu_<short>``; a μ keeps its last value while its element is outside the model), its
    truth (NaN where none: μ while its element does not slide), the NEES of (m_veh, ζ) and
    the NIS of the update with its dof; and how many samples were held (brake, standstill)."""

    t: np.ndarray
    mean: dict[str, np.ndarray]
    sigma: dict[str, np.ndarray]
    truth: dict[str, np.ndarray]
    nees: np.ndarray
    nis: np.ndarray
    nis_dof: np.ndarray
    held: int
    model: list[str] = field(default_factory=list)
    #: the filter's mode per swapping element of its model after each sample
    #: (:mod:`~gearsym.symbolic.estimators.ekf_modes` codes: 0 open, ±1 sliding, 2 sticking)
    modes: list[dict[str, int]] = field(default_factory=list)
    elements: dict[str, str] = field(default_factory=dict)
    #: the filter's state at the end, to start the next log from
    carry: EkfCarry | None = None
    #: the corrected :class:`AppendedState` s (scored at the end against their truth)
    appended: tuple[str, ...] = ()

    def error_at(self, name: str, times: Sequence[float]) -> dict[str, float]:
        """Relative error of ``name`` at the given times (s) and at the end."""
        out = {}
        truth = self.truth[name]
        for time_ in times:
            k = int(np.searchsorted(self.t, time_))
            if k < len(self.t):
                out[f"{time_:g}"] = float((self.mean[name][k] - truth[k]) / truth[k])
        out["end"] = float((self.mean[name][-1] - truth[-1]) / truth[-1])
        return out

    def summary(self) -> dict[str, Any]:
        """The filter's consistency over the drive: NEES of (m_veh, ζ) per dof (time mean;
        the samples are strongly correlated, so no χ² band is claimed for it), NIS per dof over
        every update, and the samples held (brake, standstill)."""
        used = self.nis_dof > 0
        return {
            "nees_per_dof_mean": float(np.nanmean(self.nees) / len(CARRIED)),
            "nis_per_dof": float(self.nis[used].sum() / self.nis_dof[used].sum()),
            "held_samples": self.held,
            "samples": len(self.t),
            "note": "the sensors' noise (3.26) drawn from --seed; the filter sees the TCU's "
            "log only (commanded torque and pressures, noisy speeds)",
        }

    def lines(self) -> list[str]:
        """The estimates in a few lines of text."""
        out = []
        m = self.to_dict()["m_veh"]
        errors = ", ".join(
            f"{k if k == 'end' else k + ' s'} {100 * v:+.1f} %" for k, v in m["error_at"].items()
        )
        out.append(
            f"  m_veh: {m['final']:.0f} ± {m['sigma']:.0f} kg (truth {m['truth']:.0f}); "
            f"error at {errors}"
        )
        z = self.to_dict()[naming.GRADE]
        rms = z["rms_rad"]
        out.append(
            f"  ζ: {z['final']:+.4f} ± {z['sigma']:.4f} rad (truth {z['truth']:+.4f}) at the "
            f"end; RMS error {rms['all']:.4f} rad over the drive, "
            f"{rms[f'after_{GRADE_RMS_FROM:g}']:.4f} rad from {GRADE_RMS_FROM:g} s on"
        )
        for name, entry in self.to_dict().items():
            if name in self.appended:
                out.append(
                    f"  {name}: {entry['final']:.4g} ± {entry['sigma']:.2g} at the end "
                    f"(truth {entry['truth']:.4g})"
                )
            if "truth_last_sliding" in entry:
                out.append(
                    f"  {name}: {entry['truth_last_sliding']:.4f} true when it last slid, "
                    f"estimate {entry['truth_last_sliding'] + entry['error_last_sliding']:.4f} "
                    f"± {entry['sigma_last_sliding']:.4f} ({entry['sliding_samples']} samples "
                    "sliding)"
                )
        summary = self.summary()
        out.append(
            f"  NEES/dof (m_veh, ζ) time mean {summary['nees_per_dof_mean']:.2f}, NIS/dof "
            f"{summary['nis_per_dof']:.2f}; {self.held} of {len(self.t)} samples held "
            "(brake, standstill)"
        )
        return out

    def sliding_episodes(self, name: str) -> list[tuple[int, int]]:
        """(first, last) sample of each slide of the element of μ ``name``: runs of samples
        where the truth's element slides (its μ has a truth), runs closer than
        :data:`SLIDE_GAP` merged (a shift's break-away and re-lock are one slide)."""
        inside = np.flatnonzero(np.isfinite(self.truth[name]))
        if inside.size == 0:
            return []
        gap = max(int(round(SLIDE_GAP / float(self.t[1] - self.t[0]))), 1)
        breaks = np.flatnonzero(np.diff(inside) > gap)
        starts = np.r_[inside[0], inside[breaks + 1]]
        ends = np.r_[inside[breaks], inside[-1]]
        return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]

    def rms_error(self, name: str, after: float) -> dict[str, float]:
        """The RMS of the estimate's error against the truth over the whole drive and over
        the samples from ``after`` s on (the start's prior excluded), in the state's unit."""
        error = self.mean[name] - self.truth[name]
        late = self.t >= after
        return {
            "all": float(np.sqrt(np.nanmean(error**2))),
            f"after_{after:g}": float(np.sqrt(np.nanmean(error[late] ** 2)))
            if late.any()
            else float("nan"),
        }

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name in self.mean:
            truth = self.truth[name]
            finite = np.flatnonzero(np.isfinite(truth))
            entry: dict[str, Any] = {
                "final": float(self.mean[name][-1]),
                "sigma": float(self.sigma[name][-1]),
            }
            if name in self.appended:
                entry["truth"] = float(truth[-1])
            elif name in CARRIED:
                entry["truth"] = float(truth[-1])
                if name == "m_veh":
                    entry["error_at"] = self.error_at(name, (60.0, 300.0))
                else:
                    entry["error_at_rad"] = {
                        "end": float(self.mean[name][-1] - truth[-1]),
                    }
                    entry["rms_rad"] = self.rms_error(name, GRADE_RMS_FROM)
            elif finite.size:
                k = int(finite[-1])  # the truth while the element last slid
                entry["truth_last_sliding"] = float(truth[k])
                entry["error_last_sliding"] = float(self.mean[name][k] - truth[k])
                entry["sigma_last_sliding"] = float(self.sigma[name][k])
                entry["sliding_samples"] = int(finite.size)
                episodes = self.sliding_episodes(name)
                entry["slides"] = len(episodes)
                if len(episodes) >= THIRD:
                    k = episodes[THIRD - 1][1]  # the last sample of its third slide
                    error = float(self.mean[name][k] - truth[k])
                    sigma = float(self.sigma[name][k])
                    entry["after_third_slide"] = {
                        "t": float(self.t[k]),
                        "truth": float(truth[k]),
                        "error": error,
                        "sigma": sigma,
                        "inside_2_sigma": bool(abs(error) <= 2.0 * sigma),
                    }
            out[name] = entry
        return out


class FilterModels:
    """The augmented model, its discrete step and mode logic of each shift, built on first
    use (the calibration's: the filter's model is what the TCU knows). A caller that runs the
    filter over many logs of the same description hands one to :func:`run_drive_ekf` so they
    are built once (the lock-up maps alone take about half a second). The discrete steps run
    as emitted C (``compiled``, default) where a C compiler is there."""

    def __init__(
        self, d: GearboxDescription, overrides: Mapping[str, float], compiled: bool = True
    ) -> None:
        self.d = d
        self.overrides = dict(overrides)
        #: the discrete steps as emitted C where a compiler is there (the same values to rounding,
        #: :mod:`~gearsym.validation.studies.estimation.compiled_discrete`); False: CasADi's
        self.compiled = compiled
        self._cache: dict[str, tuple[Any, Any, Any]] = {}

    @classmethod
    def of(
        cls, d: GearboxDescription, twist_model_error: float | None = None, compiled: bool = True
    ) -> FilterModels:
        """The models of ``d`` with the twist's model error (rad²/s; default the
        ``[drive.estimator]`` table's, else the description's intensities)."""
        if twist_model_error is None:
            twist_model_error = d.drive.twist_model_error()
        overrides = {} if twist_model_error is None else {naming.TWIST: twist_model_error}
        return cls(d, overrides, compiled)

    def get(self, shift: str) -> tuple[Any, Any, Any]:
        if shift not in self._cache:
            from gearsym.symbolic.estimators.ekf import DiscreteModel, augmented_model
            from gearsym.symbolic.estimators.ekf_modes import ModeLogic

            intensities = self.d.estimator.intensities() | self.overrides
            aug = augmented_model(self.d, shift, intensities=intensities)
            discrete = DiscreteModel(aug)
            if self.compiled:
                discrete = compiled_or_casadi(discrete)
            self._cache[shift] = (aug, discrete, ModeLogic(self.d, aug))
        return self._cache[shift]


def run_drive_ekf(
    d: GearboxDescription,
    log: Mapping[str, np.ndarray],
    shifts: Sequence[str],
    gears: Sequence[str],
    truth_mass: float,
    seed: int = 0,
    relative_noise: float = EKF_RELATIVE_NOISE,
    twist_model_error: float | None = None,
    start: EkfCarry | None = None,
    mu_model: str | None = None,
    truth_mu_scale: Mapping[str, float] | None = None,
    appended: Sequence[AppendedState] = (),
    models: FilterModels | None = None,
) -> DriveEstimates:
    """The EKF over a drive's TCU log (module docstring). ``d`` is the calibration (model,
    prior, tuning, piston areas); ``log`` the :class:`~gearsym.validation.sim.drive_log.TcuLog`
    arrays and ``shifts`` its shift column; ``truth_mass`` scores m_veh (never shown to the
    filter). The sensors' noise (3.26) is drawn from ``seed``. ``twist_model_error``: q of
    the twist φ (rad²/s) over the drive (default: the ``[drive.estimator]`` table's, else the
    ``[estimator]`` one's). ``start``: m_veh, ζ and the μ where an earlier log left them
    (:attr:`DriveEstimates.carry`) instead of the calibration's prior. ``mu_model``: the
    filter's μ (default the ``[estimator]`` table's): "random_walk" (4.1) or "map_scale" (each
    μ state the scale on the calibration's μ map,
    :mod:`~gearsym.validation.studies.estimation.mu_map_form`; then ``truth_mu_scale``, the
    truth's factor per element, scores it). ``appended``: states outside the model that act
    through the pressures (:class:`AppendedState`; the adaptive-control study's valve offset,
    estimated, and fill time, considered); a corrected one is carried in :attr:`carry`.
    ``models``: the filter's models from earlier calls on ``d`` with the same twist model
    error (:class:`FilterModels`), built here when None."""
    from gearsym.symbolic.estimators.ekf import ekf_predict, ekf_update
    from gearsym.symbolic.estimators.ekf_modes import STICK, ambiguous_mu, ekf_mode_update

    if twist_model_error is None:
        twist_model_error = d.drive.twist_model_error()
    scale_form = (mu_model or d.estimator.mu_model) == "map_scale"
    if models is None:
        models = FilterModels.of(d, twist_model_error)
    elif (models.d is not d and models.d != d) or models.overrides != FilterModels.of(
        d, twist_model_error
    ).overrides:
        raise ValueError("models: built for another description or twist model error")
    t = log["t"]
    h = float(t[1] - t[0])
    r_dyn = quantity(d, "vehicle", "r_dyn").value
    element_names = [e.name for e in d.shift_elements]
    short = {e: element_short_name(d, e) for e in element_names if not d.element(e).one_way}
    mu_name = {e: naming.friction_coefficient(s) for e, s in short.items()}

    # the sensors (every measured shaft and the wheel) with noise (3.26), the floor from the
    # log's range; each model reads the ones it has as outputs
    sensors = [naming.speed(s) for s in d.measured_shafts] + [naming.WHEEL_SPEED]
    y_true = np.column_stack([log[name] for name in sensors])
    floor_all = EKF_FLOOR_FRACTION * np.nanmax(np.abs(y_true), axis=0)
    sigma_all = relative_noise * np.maximum(np.abs(y_true), floor_all[None, :])
    y_all = y_true + np.random.default_rng(seed).normal(0.0, 1.0, y_true.shape) * sigma_all
    first_shift = f"{gears[0]}-{gears[1]}"
    aug, discrete, logic = models.get(first_shift)

    def sensor_columns(aug: Any) -> list[int]:
        return [sensors.index(name.removeprefix("y_")) for name in aug.output_names]

    columns = sensor_columns(aug)
    outputs = [sensors[c] for c in columns]

    extra = {a.name: a for a in appended}
    scaling = [(i, a) for i, a in enumerate(appended) if a.scales]
    for _, a in scaling:
        if a.scales not in [v.name for v in aug.model.parameters]:
            raise ValueError(f"{a.name}: scales {a.scales!r}, not a parameter of the model")
    considered = [a.name for a in appended if not a.corrected]

    def state_names(aug: Any) -> list[str]:
        return [*aug.state_names, *(a.name for a in appended)]

    # the filter's start: the first upshift's model in the from-gear, the calibration's prior
    current = first_shift
    names = state_names(aug)
    nominal = {v.name: v.default for v in aug.model.states if v.default is not None}
    z = np.zeros(len(names))
    sig0 = np.zeros(len(names))
    for j, name in enumerate(names):
        if name in outputs:
            c = sensors.index(name)
            z[j], sig0[j] = y_all[0, c], sigma_all[0, c]
        elif scale_form and name.startswith("mu_"):
            z[j], sig0[j] = d.estimator.scale_prior()
        elif name in extra:
            z[j], sig0[j] = extra[name].prior
        else:
            z[j], sig0[j] = d.estimator.prior_of(name, nominal.get(name))
    P = np.diag(sig0**2)
    twist_sigma = d.estimator.prior_of(naming.TWIST, 0.0)[1]
    modes = logic.initial_modes()
    store: dict[str, tuple[float, float]] = {}  # μ of elements outside the model
    if start is not None:
        carried_mean = np.asarray(start.mean, dtype=float)
        carried_cov = np.asarray(start.covariance, dtype=float)
        present = [i for i, name in enumerate(start.names) if name in names]
        idx = [names.index(start.names[i]) for i in present]
        z[idx] = carried_mean[present]
        P[np.ix_(idx, idx)] = carried_cov[np.ix_(present, present)]
        for i, name in enumerate(start.names):
            if name not in names:
                store[name] = (float(carried_mean[i]), float(carried_cov[i, i]))
        for name, mean_, var in start.mu:
            if name in names:
                j = names.index(name)
                z[j], P[j, j] = mean_, var
            else:
                store[name] = (mean_, var)

    tracked = [
        "m_veh",
        naming.GRADE,
        *mu_name.values(),
        *(a.name for a in appended if a.corrected),
    ]
    mean = {name: np.full(len(t), np.nan) for name in tracked}
    sigma = {name: np.full(len(t), np.nan) for name in tracked}
    nees = np.full(len(t), np.nan)
    nis = np.zeros(len(t))
    nis_dof = np.zeros(len(t))
    held_count = 0
    model_at: list[str] = []
    modes_at: list[dict[str, int]] = []
    areas = {e: d.element(e).a_piston.value for e in short if d.element(e).a_piston is not None}
    zeta_truth = log["truth_zeta"]

    def known_inputs(k: int, aug: Any, theta: Sequence[float] = ()) -> np.ndarray:
        u = np.zeros(len(aug.input_names))
        for i, name in enumerate(aug.input_names):
            if name == naming.INPUT_TORQUE:
                u[i] = log["T_In_cmd"][k] + sum(
                    (value - a.logged) * a.sensitivity[name][k]
                    for a, value in zip(appended, theta, strict=True)
                    if name in a.sensitivity
                )
            elif name.startswith("F_N"):
                e = next(e for e, s in short.items() if naming.normal_force(s) == name)
                pressure = log[f"p_{e}"][k]
                if len(appended):
                    moved = sum(
                        (value - a.logged) * a.sensitivity[e][k]
                        for a, value in zip(appended, theta, strict=True)
                        if e in a.sensitivity
                    )
                    pressure = max(pressure + moved, 0.0)
                u[i] = pressure * areas[e]
        return u

    forms: dict[str, Any] = {}

    def mapped(z: np.ndarray, u: np.ndarray, aug: Any) -> np.ndarray:
        """The F_N inputs times the μ map at the filter's own slip (map-scale form)."""
        if not scale_form:
            return u
        if aug.shift not in forms:
            from gearsym.validation.studies.estimation.mu_map_form import map_scale_form

            forms[aug.shift] = map_scale_form(d, aug)
        return forms[aug.shift](z, u)

    n_model = len(aug.state_names)

    def filter_inputs(
        z: np.ndarray, k: int, aug: Any, logic: Any, modes: Mapping[str, int]
    ) -> tuple[np.ndarray, np.ndarray, Any]:
        """The known inputs at sample ``k`` (mapped, for the mode logic), the model's inputs
        with ``modes``, and the model the filter steps (with the appended states: ∂u/∂θ by a
        forward difference of 1 % of each one's prior σ, exact but for the clip at zero
        pressure and the μ map's pressure slope)."""
        zm = z[:n_model]
        theta = np.asarray(z[n_model:], dtype=float)
        known = mapped(zm, known_inputs(k, aug, theta), aug)
        u = logic.inputs(known, modes)
        if not appended:
            return known, u, discrete_of[aug.shift]
        columns_ = []
        for i, a in enumerate(appended):
            if a.scales:
                columns_.append(np.zeros(len(u)))
                continue
            step = 0.01 * a.prior[1]
            moved = theta.copy()
            moved[i] += step
            u_plus = logic.inputs(mapped(zm, known_inputs(k, aug, moved), aug), modes)
            columns_.append((u_plus - u) / step)
        dp = None
        if any(a.scales for a in appended):
            nominal = aug.parameter_values()
            parameters = [v.name for v in aug.model.parameters]
            dp = np.zeros((len(nominal), len(appended)))
            for i, a in enumerate(appended):
                if a.scales:
                    j = parameters.index(a.scales)
                    dp[j, i] = nominal[j]
        return known, u, _Appended(discrete_of[aug.shift], np.column_stack(columns_), dp)

    def parameters_at(z: np.ndarray, aug: Any) -> list[float]:
        """The fixed parameters the filter's model uses: the calibration's, each one a scaling
        state names times that state (:attr:`AppendedState.scales`)."""
        p = aug.parameter_values()
        if scaling:
            parameters = [v.name for v in aug.model.parameters]
            n = len(aug.state_names)
            for i, a in scaling:
                p[parameters.index(a.scales)] *= float(z[n + i])
        return p

    discrete_of = {aug.shift: discrete}

    for k in range(len(t)):
        wanted = shifts[k] or current
        if wanted != current:
            new_aug, new_discrete, new_logic = models.get(wanted)
            priors = _prior_of(d, new_aug)
            if scale_form:
                priors |= {n: d.estimator.scale_prior() for n in new_aug.mu_state.values()}
            new_names = state_names(new_aug)
            z, P = _hand_over(names, new_names, z, P, store, sig0_of=priors)
            aug, discrete, logic, current = new_aug, new_discrete, new_logic, wanted
            discrete_of[aug.shift] = discrete
            names = new_names
            n_model = len(aug.state_names)
            columns = sensor_columns(aug)
            outputs = [sensors[c] for c in columns]
            modes = logic.initial_modes()
        model_at.append(current)
        in_gear = not shifts[k]
        if in_gear:
            # in a gear the TCU holds line pressure on the gear's elements: no element slides,
            # the filter's modes are the gear's (a lock-up its own logic had not decided by
            # the shift's end is mapped now)
            target = _gear_modes(logic, current, gears[int(log["gear"][k])])
            for e, code in target.items():
                if code == STICK and modes[e] != STICK:
                    z, P = logic.map_state(e, z, P)
            modes = target
        standing = (
            log["omega_C"][k] * r_dyn < STANDSTILL_SPEED and log["T_In_cmd"][k] == 0.0
        ) or log["T_brake"][k] > 0.0
        if standing:
            # the filter's model has no brake or standstill: hold the parameters, take the
            # speeds from the measurement
            held_count += 1
            for c, name in zip(columns, outputs, strict=True):
                if name not in names:
                    continue
                j = names.index(name)
                P[j, :] = 0.0
                P[:, j] = 0.0
                z[j] = y_all[k, c]
                P[j, j] = sigma_all[k, c] ** 2
            if naming.TWIST in names:
                # what the brake did to the side shafts' twist the filter cannot know: it
                # starts again from its prior's doubt (its mean kept), not from a stale
                # certainty that the next samples would read as stiffness or mass
                j = names.index(naming.TWIST)
                P[j, :] = 0.0
                P[:, j] = 0.0
                P[j, j] = twist_sigma**2
            modes = _gear_modes(logic, current, gears[int(log["gear"][k])])
        else:
            if k > 0:
                p = parameters_at(z, aug)
                _, u_prev, model = filter_inputs(z, k - 1, aug, logic, modes)
                q = [
                    d.estimator.scale_random_walk()
                    if scale_form and name.startswith("mu_")
                    else extra[name].random_walk
                    if name in extra
                    else aug.intensities[name]
                    for name in names
                ]
                z, P = ekf_predict(model, z, P, u_prev, h, p, q)
            p = parameters_at(z, aug)
            u_known, u_now, model = filter_inputs(z, k, aug, logic, modes)
            relative = np.full(len(columns), relative_noise)
            consider = [names.index(name) for name in considered]
            if not in_gear:
                # a μ whose element may already have locked up is not corrected (its slip
                # within MU_AMBIGUITY_SIGMA σ of zero and closing): the speeds of a locked
                # element say nothing of its friction, and a μ corrected there runs away
                consider += ambiguous_mu(logic, z, P, u_known, p, modes)
                # a state that learns in the gears only is held through the shift
                consider += [
                    names.index(a.name) for a in appended if a.corrected and not a.learns_in_shifts
                ]
            z, P, nis[k], nis_dof[k] = ekf_update(
                model,
                z,
                P,
                u_now,
                y_all[k, columns],
                p,
                relative,
                floor_all[columns],
                consider=consider,
            )
            if not in_gear:
                p = parameters_at(z, aug)
                z, P, modes, _ = ekf_mode_update(
                    logic, z, P, u_known, p, modes, sync_band=SYNC_BAND
                )
        # record
        for name in tracked:
            if name in names:
                j = names.index(name)
                mean[name][k] = z[j]
                sigma[name][k] = math.sqrt(max(P[j, j], 0.0))
            elif name in store:
                mean[name][k], var = store[name]
                sigma[name][k] = math.sqrt(var)
        modes_at.append(dict(modes))
        idx = [names.index(n) for n in CARRIED]
        error = z[idx] - np.array([truth_mass, zeta_truth[k]])
        nees[k] = float(error @ np.linalg.solve(P[np.ix_(idx, idx)], error))
    joint = [
        *CARRIED,
        *(a.name for a in appended if a.corrected),
        *(name for name in names if name.startswith("mu_")),
    ]
    idx = [names.index(n) for n in joint]
    carry = EkfCarry(
        tuple(joint),
        tuple(float(v) for v in z[idx]),
        tuple(tuple(float(v) for v in row) for row in P[np.ix_(idx, idx)]),
        tuple((name, m_, v_) for name, (m_, v_) in sorted(store.items())),
    )
    truth = {
        "m_veh": np.full(len(t), truth_mass),
        naming.GRADE: np.asarray(zeta_truth, dtype=float),
        **{mu_name[e]: np.asarray(log[f"truth_mu_{e}"], dtype=float) for e in mu_name},
        **{a.name: np.full(len(t), a.truth) for a in appended if a.corrected},
    }
    if scale_form:  # the state is the map's scale: the truth's factor where the element slides
        for e, name in mu_name.items():
            sliding = np.isfinite(truth[name])
            truth[name] = np.where(sliding, (truth_mu_scale or {}).get(e, np.nan), np.nan)
    return DriveEstimates(
        t=np.asarray(t, dtype=float),
        mean=mean,
        sigma=sigma,
        truth=truth,
        nees=nees,
        nis=nis,
        nis_dof=nis_dof,
        held=held_count,
        model=model_at,
        modes=modes_at,
        elements={mu_name[e]: e for e in mu_name},
        carry=carry,
        appended=tuple(a.name for a in appended if a.corrected),
    )


def _gear_modes(logic: Any, shift: str, gear: str) -> dict[str, int]:
    """The modes of ``shift``'s model in ``gear``: its from-gear (the off-going element
    sticks, the on-coming one is open) or its to-gear (the other way round)."""
    from gearsym.symbolic.estimators.ekf_modes import OPEN, STICK

    off, on = logic.elements
    if gear == shift.split("-")[0]:
        return {off: STICK, on: OPEN}
    return {off: OPEN, on: STICK}


def _prior_of(d: GearboxDescription, aug: Any) -> dict[str, tuple[float, float]]:
    """The calibration's prior (mean, σ) of every unmeasured state of ``aug``."""
    nominal = {v.name: v.default for v in aug.model.states if v.default is not None}
    out = {}
    for name in aug.state_names:
        try:
            out[name] = d.estimator.prior_of(name, nominal.get(name))
        except Exception:  # a state without a prior (the speeds): set from the old model
            continue
    return out


def _hand_over(
    old_names: Sequence[str],
    new_names: Sequence[str],
    z: np.ndarray,
    P: np.ndarray,
    store: dict[str, tuple[float, float]],
    sig0_of: Mapping[str, tuple[float, float]],
) -> tuple[np.ndarray, np.ndarray]:
    """z and P of the filter with the states ``new_names`` from the one with ``old_names``,
    by state name (module docstring); the μ of the old model that the new one lacks go to
    ``store`` (mean, variance)."""
    for j, name in enumerate(old_names):
        if name.startswith("mu_") and name not in new_names:
            store[name] = (float(z[j]), float(P[j, j]))
    n = len(new_names)
    z_new = np.zeros(n)
    P_new = np.zeros((n, n))
    common = [name for name in new_names if name in old_names]
    i_new = [new_names.index(name) for name in common]
    i_old = [old_names.index(name) for name in common]
    z_new[i_new] = z[i_old]
    P_new[np.ix_(i_new, i_new)] = P[np.ix_(i_old, i_old)]
    for j, name in enumerate(new_names):
        if name in common:
            continue
        if name in store:
            mean, var = store.pop(name)
        elif name in sig0_of:
            mean, sd = sig0_of[name]
            var = sd * sd
        else:
            raise ValueError(f"{name}: neither in the previous model nor with a prior")
        z_new[j] = mean
        P_new[j, j] = var
    return z_new, P_new
