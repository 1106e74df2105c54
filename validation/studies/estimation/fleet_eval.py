"""The EKF judged over a fleet of vehicles as a TCU meets them (the estimation issue's world).

Each run draws one vehicle from the fleet (:mod:`gearsym.validation.sim.fleet`), simulates it
with the reference (its own truth trajectory), and runs the filter of the calibration on its
noisy speeds with the inputs the TCU is told. The filter's model, prior, tuning, noise floor
and mode logic come from the calibration alone and are the same in every run; the draw is
used to simulate and to score, never handed to the filter.

Per parameter, over every run: the filter's own value at the end of the shift (its decision
time: what an adaptation would read) against that run's truth (bias, RMSE, mean σ, coverage of
the 95 % interval), and per detected phase the same over the samples where the parameter has
a truth, with the posterior bound of each run's truth under the filter's own assumptions
(:func:`~gearsym.validation.studies.estimation.bounds.ekf_bound`) and the efficiency RMSE /
bound. NEES and NIS against their χ² bands over the runs.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import VALVE_GAIN, VALVE_OFFSET
from gearsym.validation.sim.fleet import (
    Fleet,
    FleetDraw,
    speed_sensor,
    told_inputs,
    truth_world,
)
from gearsym.validation.sim.scenario import Scenario
from gearsym.validation.sim.tooth_wheel import tooth_wheel_speeds

__all__ = [
    "COVERAGE_Z",
    "FilterModel",
    "FleetContext",
    "FleetEvaluation",
    "FleetRun",
    "FleetStats",
    "each_vehicle",
    "filter_model",
    "fleet_vehicle",
    "run_fleet",
    "vehicle_setup",
]

#: The 95 % interval of a Gaussian estimate: ±1.96 σ.
COVERAGE_Z = 1.959963984540054

#: Bootstrap draws of the fleet's vehicles for :meth:`FleetEvaluation.nees_over_vehicles`.
NEES_RESAMPLES = 2000

Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class FleetRun:
    """One vehicle: its draw, the filter's run on it, and the bound along its truth."""

    draw: FleetDraw
    run: Any  # EkfRun
    bound: Any = None  # EkfBound or None
    seconds: float = 0.0
    #: what the filter was handed: initial estimate, prior σ, intensities q, parameters p,
    #: noise floor, and the known inputs (told T_In, F_N) per sample; the same in every run of
    #: a calibration, whatever the truth (tests compare them across fleets)
    handed: dict[str, np.ndarray] = field(default_factory=dict, repr=False)


@dataclass(frozen=True)
class FleetStats:
    """One parameter (in one phase, or at the end of the shift) over the fleet's runs."""

    runs: int  # runs that score it here
    samples: int  # scored samples over those runs
    bias: float | None
    rmse: float | None
    mean_sigma: float | None  # RMS of the reported σ over the same samples
    coverage_95: float | None  # fraction with |error| <= 1.96 σ
    bound: float | None = None  # RMS of the posterior bound over the same samples
    efficiency: float | None = None  # rmse / bound
    identifiable: float | None = None  # fraction of runs whose phase identifies it
    #: ``coverage_95`` over the samples of those runs only (``None``: no such run): a run
    #: that cannot identify the parameter keeps it near its prior, whose interval covers a
    #: fleet drawn within the prior's range whatever the filter does
    coverage_identifiable: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "runs": self.runs,
            "samples": self.samples,
            "bias": self.bias,
            "rmse": self.rmse,
            "mean_sigma": self.mean_sigma,
            "coverage_95": self.coverage_95,
            "bound": self.bound,
            "efficiency": self.efficiency,
            "identifiable": self.identifiable,
            **(
                {}
                if self.identifiable is None
                else {"coverage_95_identifiable": self.coverage_identifiable}
            ),
        }


def _stats(
    errors: Sequence[np.ndarray],
    sigmas: Sequence[np.ndarray],
    bounds: Sequence[np.ndarray] | None = None,
    identifiable: Sequence[bool] | None = None,
) -> FleetStats:
    kept = [k for k, e in enumerate(errors) if e.size]
    if not kept:
        return FleetStats(0, 0, None, None, None, None)
    err = np.concatenate([errors[k] for k in kept])
    sig = np.concatenate([sigmas[k] for k in kept])
    rmse = float(np.sqrt(np.mean(err**2)))
    covered = [np.abs(errors[k]) <= COVERAGE_Z * sigmas[k] for k in kept]
    where = (
        [] if identifiable is None else [covered[i] for i, k in enumerate(kept) if identifiable[k]]
    )
    bound = None
    if bounds is not None and all(bounds[k] is not None for k in kept):
        b = np.concatenate([bounds[k] for k in kept])
        bound = float(np.sqrt(np.mean(b**2)))
    return FleetStats(
        runs=len(kept),
        samples=int(err.size),
        bias=float(np.mean(err)),
        rmse=rmse,
        mean_sigma=float(np.sqrt(np.mean(sig**2))),
        coverage_95=float(np.mean(np.abs(err) <= COVERAGE_Z * sig)),
        bound=bound,
        efficiency=rmse / bound if bound else None,
        identifiable=None
        if identifiable is None
        else float(np.mean([identifiable[k] for k in kept])),
        coverage_identifiable=float(np.mean(np.concatenate(where))) if where else None,
    )


@dataclass
class FleetEvaluation:
    """The EKF over a fleet: the runs, the runs that could not be simulated, and the scores."""

    fleet: Fleet
    calibration: GearboxDescription
    scenario: Scenario
    seeds: tuple[int, ...]
    runs: list[FleetRun]
    failed: list[tuple[int, str]] = field(default_factory=list)
    seconds_per_run: float = 0.0
    initial: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: the filter's μ states by element (the augmented model's)
    mu_elements: dict[str, str] = field(default_factory=dict)
    #: the calibration's ``[estimator] mu_model``: "map_scale" makes the μ states map scales
    mu_model: str = "random_walk"
    #: what one shift cannot separate (:mod:`.separability`), on the calibration's vehicle
    separability: dict[str, Any] = field(default_factory=dict)
    #: the states the filter carries as consider states (never corrected)
    considered: tuple[str, ...] = ()
    #: :attr:`~gearsym.validation.studies.estimation.setup.EkfSetup.input_hold`
    input_hold: str = "sample"

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.runs[0].run.parameters] if self.runs else []

    def final_rows(self, fr: FleetRun) -> dict[str, tuple[float, float, float | None]]:
        """Per parameter of one run: the filter's last estimate, its σ, and the truth it is
        scored against (``None``: none; module text)."""
        run = fr.run
        out = {}
        for name in self.parameter_names:
            j = list(run.state_names).index(name)
            # a map scale has one truth (the draw's factor); a random-walk μ follows the slip
            element = None if self.mu_model == "map_scale" else self.mu_elements.get(name)
            truth = _final_truth(run, j, element)
            out[name] = (float(run.estimates[-1, j]), float(run.sigmas[-1, j]), truth)
        return out

    def final_stats(self, name: str) -> FleetStats:
        """The filter's own value at the end of each run (what an adaptation reads) against
        that run's truth at the end; μ against the mean true μ over the samples the filter
        itself judged its element sliding (its own decision, not the truth's)."""
        errors, sigmas = [], []
        for fr in self.runs:
            estimate, sigma, truth = self.final_rows(fr)[name]
            known = truth is not None
            errors.append(np.array([estimate - truth]) if known else np.zeros(0))
            sigmas.append(np.array([sigma]) if known else np.zeros(0))
        return _stats(errors, sigmas)

    def phase_names(self) -> list[str]:
        names: list[str] = []
        for fr in self.runs:
            for p in fr.run.phases:
                if p.name not in names:
                    names.append(p.name)
        return names

    def phase_stats(self, phase: str, name: str) -> FleetStats:
        """Over the samples of ``phase`` (as each run's reference detected it) where ``name``
        has a truth."""
        from gearsym.validation.studies.estimation.bounds import _phase_samples

        errors, sigmas, bounds, ident = [], [], [], []
        for fr in self.runs:
            run = fr.run
            found = [k for k, p in enumerate(run.phases) if p.name == phase]
            j = list(run.state_names).index(name)
            if not found:
                errors.append(np.zeros(0))
                sigmas.append(np.zeros(0))
                bounds.append(None)
                ident.append(False)
                continue
            k = found[0]
            inside = _phase_samples(run.t, run.phases[k], last=k == len(run.phases) - 1)
            idx = inside[run.scored[inside, j]]
            errors.append(run.estimates[idx, j] - run.truth[idx, j])
            sigmas.append(run.sigmas[idx, j])
            bounds.append(None if fr.bound is None else fr.bound.sigma[idx, j])
            ident.append(fr.bound is not None and name in fr.bound.identifiable.get(phase, ()))
        with_bound = all(fr.bound is not None for fr in self.runs)
        return _stats(errors, sigmas, bounds if with_bound else None, ident if with_bound else None)

    def nees(self) -> tuple[float, tuple[float, float]]:
        """Mean NEES over samples of the run-averaged NEES, and its 95 % band: one sample's
        sum over the runs is χ² with the summed dof; the time average of such correlated
        means scatters no more than one of them (the mean dof taken)."""
        from scipy.stats import chi2

        runs = len(self.runs)
        nees = np.array([fr.run.nees for fr in self.runs])
        dof = np.array([fr.run.nees_dof for fr in self.runs])
        total = float(np.mean(np.sum(dof, axis=0)))
        return float(np.mean(np.mean(nees, axis=0))), (
            float(chi2.ppf(0.025, total) / runs),
            float(chi2.ppf(0.975, total) / runs),
        )

    def nees_over_vehicles(
        self, resamples: int = NEES_RESAMPLES, seed: int = 0
    ) -> dict[str, Any] | None:
        """How far the NEES mean moves with the fleet's vehicles: the 95 % interval of
        :meth:`nees`'s mean when the vehicles are drawn again with replacement (``resamples``
        bootstrap draws from ``seed``), beside the value a consistent filter expects (the mean
        dof). The χ² band of :meth:`nees` assumes every vehicle the same filter with an exact
        model; vehicles that differ in what no state carries scatter more than that, which this
        interval shows (``None`` with fewer than two vehicles)."""
        if len(self.runs) < 2:
            return None
        nees = np.array([fr.run.nees for fr in self.runs])
        dof = np.array([fr.run.nees_dof for fr in self.runs])
        rng = np.random.default_rng(seed)
        picks = rng.integers(0, len(self.runs), size=(resamples, len(self.runs)))
        means = np.array([float(np.mean(np.mean(nees[k], axis=0))) for k in picks])
        low, high = np.percentile(means, [2.5, 97.5])
        return {
            "interval": [float(low), float(high)],
            "expected": float(np.mean(dof)),
            "resamples": resamples,
        }

    def nis(self) -> tuple[float | None, tuple[float, float] | None]:
        """Mean NIS over every used update of every run and its band (innovations are white:
        the summed NIS is χ² with the summed dof)."""
        from scipy.stats import chi2

        nis = np.concatenate([fr.run.nis[fr.run.nis_dof > 0] for fr in self.runs])
        dof = np.concatenate([fr.run.nis_dof[fr.run.nis_dof > 0] for fr in self.runs])
        if not dof.size:
            return None, None
        total = float(np.sum(dof))
        return float(np.mean(nis)), (
            float(chi2.ppf(0.025, total) / dof.size),
            float(chi2.ppf(0.975, total) / dof.size),
        )

    def consistency_per_phase(self) -> dict[str, dict[str, Any]]:
        """Per phase (as each run's reference detected it): NEES and NIS over the phase's
        samples of every run, each summed and divided by its summed dof, and the NIS's 95 %
        band (innovations are white: the summed NIS is χ² with the summed dof; the NEES's
        samples are correlated in time, so it gets no band). Where a filter is consistent
        overall but not in a phase, its model error is in the wrong place."""
        from gearsym.validation.studies.estimation.bounds import _phase_samples
        from scipy.stats import chi2

        sums: dict[str, np.ndarray] = {name: np.zeros(5) for name in self.phase_names()}
        for fr in self.runs:
            run = fr.run
            for k, phase in enumerate(run.phases):
                inside = _phase_samples(run.t, phase, last=k == len(run.phases) - 1)
                used = inside[run.nis_dof[inside] > 0]
                sums[phase.name] += (
                    float(np.sum(run.nees[inside])),
                    float(np.sum(run.nees_dof[inside])),
                    float(np.sum(run.nis[used])),
                    float(np.sum(run.nis_dof[used])),
                    float(inside.size),
                )
        out: dict[str, dict[str, Any]] = {}
        for name, (nees, nees_dof, nis, nis_dof, samples) in sums.items():
            out[name] = {
                "nees_per_dof": nees / nees_dof if nees_dof else None,
                "nis_per_dof": nis / nis_dof if nis_dof else None,
                "nis_band_per_dof": [
                    float(chi2.ppf(0.025, nis_dof) / nis_dof),
                    float(chi2.ppf(0.975, nis_dof) / nis_dof),
                ]
                if nis_dof
                else None,
                "nees_dof": int(nees_dof),
                "nis_dof": int(nis_dof),
                "samples": int(samples),
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        nees, nees_band = self.nees()
        nis, nis_band = self.nis()
        cal = self.calibration.estimator
        return {
            "filter": "ekf",
            "mu_model": self.mu_model,
            "shift": self.scenario.shift.name,
            "scenario": self.scenario.name,
            "runs": len(self.runs),
            "seeds": list(self.seeds),
            "failed": [{"seed": s, "reason": r} for s, r in self.failed],
            "seconds_per_run": self.seconds_per_run,
            "fleet": self.fleet.to_dict(),
            "tuning": {
                "tuned_on": cal.tuned_on or "the code's defaults (no [estimator] table)",
                "evaluated_on": f"fleet {self.fleet.name} ({self.fleet.file}), seeds "
                f"{self.seeds[0]}-{self.seeds[-1]}"
                if self.seeds
                else "",
                "calibration": cal.to_dict(),
            },
            "initial": {name: {"value": v, "sigma": s} for name, (v, s) in self.initial.items()},
            "considered": list(self.considered),
            "input_hold": self.input_hold,
            "parameters": {
                name: {
                    "final": self.final_stats(name).to_dict(),
                    "phases": {
                        phase: self.phase_stats(phase, name).to_dict()
                        for phase in self.phase_names()
                    },
                }
                for name in self.parameter_names
            },
            "nees_mean": nees,
            "nees_band": list(nees_band),
            "nees_over_vehicles": self.nees_over_vehicles(),
            "nis_mean": nis,
            "nis_band": None if nis_band is None else list(nis_band),
            "consistency_per_phase": self.consistency_per_phase(),
            "separability": self.separability,
            "draws": [fr.draw.to_dict() for fr in self.runs],
        }


def _final_truth(run: Any, j: int, element: str | None) -> float | None:
    if element is not None:  # a μ: over the samples the filter judged its element sliding
        sliding = np.abs(run.modes[element]) == 1
        use = sliding & run.scored[:, j]
        return float(np.mean(run.truth[use, j])) if use.any() else None
    column = run.truth[:, j]
    return float(column[-1]) if np.isfinite(column[-1]) else None


#: The command and option a Dask error of a fleet study names.
WHERE = ("estimate", "--scheduler")


@dataclass(frozen=True)
class FilterModel:
    """The filter's model of a calibration: the augmented model (4.1), its discretisation and
    the mode logic (``None`` with the reference's modes). The expensive part of a fleet study
    and the same for every vehicle: built once per process."""

    aug: Any
    discrete: Any
    logic: Any = None


def filter_model(
    d: GearboxDescription,
    shift: str,
    modes: str = "filter",
    parameters: Sequence[str] | None = None,
) -> FilterModel:
    """Build the EKF's model of the calibration ``d`` for ``shift``: the thesis' (4.1), or
    with ``parameters`` its states appended (e.g. the side shafts' stiffness k_ss beside
    them, :data:`~gearsym.symbolic.estimator_calibration.STIFFNESS`)."""
    from gearsym.symbolic.estimators.ekf import DiscreteModel, augmented_model
    from gearsym.symbolic.estimators.ekf_modes import ModeLogic

    aug = augmented_model(d, shift, parameters)
    return FilterModel(aug, DiscreteModel(aug), ModeLogic(d, aug) if modes == "filter" else None)


@dataclass(frozen=True, eq=False)
class FleetContext:
    """What every vehicle of one fleet study shares: small and picklable, it travels with
    each Dask task; the filter's model does not (:meth:`model` builds it once per worker
    process). ``floor``: the noise floor (3.26) of the calibration's own vehicle; ``grid``:
    its sample times, on which the TCU is told the commanded inputs; ``filter_noise``: the
    filter's own sensor-noise model when it differs from the sensors' (:func:`run_fleet`)."""

    d: GearboxDescription
    scenario: Scenario
    fleet: Fleet
    sample_time: float
    relative_noise: Any
    modes: str
    floor: np.ndarray = field(repr=False)
    grid: np.ndarray = field(repr=False)
    bound: bool = True
    filter_noise: Any = None
    #: the filter's augmented parameters (``None``: the thesis' 4.1)
    parameters: tuple[str, ...] | None = None
    #: :attr:`~gearsym.validation.studies.estimation.setup.EkfSetup.input_hold`
    input_hold: str = "sample"

    @property
    def key(self) -> str:
        """What the filter's model is built from, as a key of the workers' cache."""
        from gearsym.validation.studies.dask_runner import content_key

        return content_key(
            "fleet filter model", self.d, self.scenario.shift.name, self.modes, self.parameters
        )

    def model(self) -> FilterModel:
        """The filter's model, built once per process and calibration."""
        from gearsym.validation.studies.dask_runner import worker_cached

        return worker_cached(
            self.key,
            lambda: filter_model(self.d, self.scenario.shift.name, self.modes, self.parameters),
        )


def calibration_setup(
    d: GearboxDescription,
    scenario: Scenario,
    model: FilterModel,
    sample_time: float,
    relative_noise: Any,
    modes: str = "filter",
) -> Any:
    """The filter's set-up on the calibration's own vehicle (the TCU engineer's simulation of
    the commanded shift): what every vehicle's filter shares, the noise floor (3.26) and the
    prior, never a run's truth."""
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    return prepare_ekf(
        d,
        simulate(d, scenario),
        sample_time,
        relative_noise,
        aug=model.aug,
        discrete=model.discrete,
        modes=modes,
        logic=model.logic,
    )


def vehicle_setup(
    context: FleetContext, model: FilterModel, seed: int
) -> tuple[FleetDraw, Any, tuple[str, ...]] | str:
    """Vehicle ``seed`` of the fleet simulated by the reference and the filter's set-up on
    it: (draw, :class:`~gearsym.validation.studies.estimation.setup.EkfSetup`, the inputs the
    TCU is told), or why its simulation failed."""
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    d, scenario = context.d, context.scenario
    draw = context.fleet.draw(seed)
    world = truth_world(d, scenario, draw)
    try:
        result = simulate(world.description, world.scenario, mu_scale=world.mu_scale)
    except GearsymError as err:
        return str(err)
    told = told_inputs(d, scenario, context.grid, model.aug.input_names)
    setup = prepare_ekf(
        d,
        result,
        context.sample_time,
        context.relative_noise,
        aug=model.aug,
        discrete=model.discrete,
        modes=context.modes,
        logic=model.logic,
        told=told,
        truth_description=world.description,
        floor=context.floor,
        truth_mu_scale=world.mu_scale,
        truth_valve={
            VALVE_OFFSET: float(dict(draw.values).get("pressure_offset", 0.0)),
            VALVE_GAIN: float(dict(draw.values).get("pressure_gain", 1.0)),
        },
    )
    setup = replace(setup, input_hold=context.input_hold)
    # the speeds as the TCU reads them from its tooth wheels (a fleet draws a wheel for every
    # measured speed or for none: parse_fleet)
    sensors = [speed_sensor(draw, name) for name in setup.outputs]
    if all(sensor is not None for sensor in sensors):
        readings = [
            tooth_wheel_speeds(result.t, result.signals[name], setup.t, sensor)
            for name, sensor in zip(setup.outputs, sensors, strict=True)
            if sensor is not None
        ]
        setup = replace(setup, y_true=np.column_stack(readings), sensed=True)
    return draw, setup, tuple(told)


def fleet_vehicle(
    context: FleetContext, model: FilterModel, seed: int
) -> FleetRun | tuple[int, str]:
    """One run of the fleet evaluation: vehicle ``seed`` simulated, the filter run on it
    (noise from ``seed``) and, with ``context.bound``, the posterior bound along its truth;
    (seed, reason) when its simulation failed."""
    from gearsym.validation.studies.estimation.bounds import ekf_bound
    from gearsym.validation.studies.estimation.loop import filter_run

    t0 = time.perf_counter()
    found = vehicle_setup(context, model, seed)
    if isinstance(found, str):
        return (seed, found)
    draw, setup, told = found
    if context.filter_noise is not None:  # the filter told another noise than the sensors have
        setup.relative = np.broadcast_to(
            np.asarray(context.filter_noise, dtype=float), setup.relative.shape
        ).copy()
    run = filter_run(setup, seed)
    run_bound = ekf_bound(setup) if context.bound else None
    known = [k for k, name in enumerate(model.aug.input_names) if name in told]
    handed = {
        "initial": setup.initial.copy(),
        "prior_sigma": setup.prior_sigma.copy(),
        "q": np.asarray(setup.q, dtype=float),
        "p": np.asarray(setup.p, dtype=float),
        "floor": np.asarray(setup.floor, dtype=float),
        "told_inputs": np.asarray(setup.u, dtype=float)[:, known],
    }
    return FleetRun(draw, run, run_bound, time.perf_counter() - t0, handed)


def _fleet_task(context: FleetContext, seed: int) -> FleetRun | tuple[int, str]:
    """:func:`fleet_vehicle` on a Dask worker, with the worker's own filter model."""
    return fleet_vehicle(context, context.model(), seed)


def each_vehicle(
    seeds: Sequence[int],
    here: Callable[[int], Any],
    task: Callable[..., Any],
    context: FleetContext,
    client: Any = None,
    progress: Callable[[int, int, Any], None] | None = None,
    args: Sequence[Any] = (),
) -> list[Any]:
    """The outcome of every seed, in the seeds' order: ``here(seed)`` one after the other
    without ``client``, else ``task(context, seed, *args)`` on its Dask workers (a worker that
    died or a scheduler lost is a one-line error). ``progress(done, total, outcome)`` after
    each (on Dask: as they complete)."""
    from gearsym.validation.studies.dask_runner import completed, submit_each

    total = len(seeds)
    outcomes: list[Any] = [None] * total
    if client is None:
        for i, seed in enumerate(seeds):
            outcomes[i] = here(seed)
            if progress is not None:
                progress(i + 1, total, outcomes[i])
        return outcomes
    futures = submit_each(client, task, context, list(seeds), *args)
    for done, (i, outcome) in enumerate(completed(futures, WHERE), 1):
        outcomes[i] = outcome
        if progress is not None:
            progress(done, total, outcome)
    return outcomes


def run_fleet(
    d: GearboxDescription,
    scenario: Scenario,
    fleet: Fleet,
    runs: int,
    seed: int = 0,
    sample_time: float = 0.01,
    relative_noise: Any = 0.01,
    modes: str = "filter",
    bound: bool = True,
    progress: Progress | None = None,
    filter_noise: Any = None,
    client: Any = None,
    parameters: Sequence[str] | None = None,
    input_hold: str = "sample",
) -> FleetEvaluation:
    """The EKF of the calibration ``d`` over ``runs`` vehicles of ``fleet`` (run i: seed
    ``seed`` + i draws the vehicle and, in its own stream, the speed noise) on ``scenario``
    (the commanded inputs). ``bound``: the posterior bound of each run's truth (about 1.5 s a
    run). A vehicle whose simulation fails is reported in ``failed`` with the reason.
    ``filter_noise``: the filter's own sensor-noise model r (3.26) when it differs from the
    sensors' ``relative_noise`` (a mistuned filter, to show that the consistency checks see
    it); ``None``: the same.

    ``client``: a ``dask.distributed`` client (:func:`~gearsym.validation.studies.
    dask_runner.connect`); the vehicles then run on its workers, one task each, every worker
    building the filter's model once; the same seeds, draws and numbers as without."""
    from gearsym.symbolic.estimator_calibration import INPUT_TORQUE_GAIN
    from gearsym.validation.studies.estimation.separability import torque_gain_separability

    if runs < 1:
        raise GearsymError("estimate", "--runs", f"must be at least 1, got {runs}")
    report = progress or (lambda fraction, message: None)
    model = filter_model(d, scenario.shift.name, modes, parameters)
    # The noise floor of (3.26) is calibration: from the TCU engineer's own simulation of the
    # calibration's vehicle on the same commanded shift, never from a run's truth.
    report(0.0, "simulating the calibration's own vehicle (the noise floor)")
    nominal = calibration_setup(d, scenario, model, sample_time, relative_noise, modes)
    separability = {}
    if INPUT_TORQUE_GAIN not in model.aug.parameters:  # else the gain is the filter's own state
        report(0.0, "what one shift cannot separate (Fisher information with a torque gain)")
        separability = {INPUT_TORQUE_GAIN: torque_gain_separability(nominal).to_dict()}
    initial = {
        name: (float(nominal.initial[j]), float(nominal.prior_sigma[j]))
        for j, name in enumerate(nominal.names)
        if name not in nominal.outputs
    }
    context = FleetContext(
        d,
        scenario,
        fleet,
        sample_time,
        relative_noise,
        modes,
        nominal.floor,
        nominal.t,
        bound,
        filter_noise,
        None if parameters is None else tuple(parameters),
        input_hold,
    )
    seeds = tuple(range(seed, seed + runs))

    def told(done: int, total: int, outcome: Any) -> None:
        failed = "" if isinstance(outcome, FleetRun) else ": simulation failed"
        report(done / total, f"run {done} of {total}{failed}")

    start = time.perf_counter()
    outcomes = each_vehicle(
        seeds, lambda s: fleet_vehicle(context, model, s), _fleet_task, context, client, told
    )
    done = [o for o in outcomes if isinstance(o, FleetRun)]
    failed = [o for o in outcomes if not isinstance(o, FleetRun)]
    if not done:
        raise GearsymError(
            "estimate", "--fleet", f"every run's simulation failed (first: {failed[0][1]})"
        )
    return FleetEvaluation(
        fleet=fleet,
        calibration=d,
        scenario=scenario,
        seeds=seeds,
        runs=done,
        failed=failed,
        seconds_per_run=(time.perf_counter() - start) / runs,
        initial=initial,
        mu_elements={mu: e for e, mu in model.aug.mu_state.items()},
        mu_model=d.estimator.mu_model,
        separability=separability,
        considered=tuple(nominal.names[j] for j in nominal.considered),
        input_hold=input_hold,
    )
