"""``estimate(request) -> report``: the workflow of every estimator of thesis chapter 4, from a
request to a report (JSON, text, files), usable from a notebook as from ``gearsym estimate``.

A request keeps apart what the filter knows and the world it is judged in:

* :class:`Calibration`: what the TCU knows: the description (nominal vehicle, elements), the
  filter's sample time, its sensor-noise model, its augmented parameters, its initial estimate
  and where its element modes come from;
* :class:`Truth`: the world: a scenario simulated by the reference (with the description's own
  values: today the truth equals the calibration's vehicle) or a bench recording.

The filters (:mod:`gearsym.symbolic.estimators`) and their evaluation
(:mod:`gearsym.validation.studies.estimation`, :mod:`gearsym.validation.studies.euio_evaluation`)
do the work; this module decides which of them a request runs, refuses what a request asks that
the chosen filter would not use, and assembles the report.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import MU_MODELS
from gearsym.validation.sim.scenario import Scenario

__all__ = [
    "DRIVE_UPSHIFTS",
    "FILTERS",
    "Calibration",
    "EstimateReport",
    "EstimateRequest",
    "Reporter",
    "Truth",
    "check_request",
    "drive_truths",
    "estimate",
    "measured_truth",
]

FILTERS = ("uio", "ekf", "euio")

#: ``--drive upshifts``: the shipped scenarios of the drive 1->2->3->4.
DRIVE_UPSHIFTS = ("scenario_1_2.toml", "scenario_2_3.toml", "scenario_3_4.toml")

#: The filters' sensor-noise model when the calibration states none: the relative speed error
#: r (3.26) of the EKF and the EUIO; the UIO is run noise-free.
DEFAULT_RELATIVE_NOISE = 0.01

#: Largest relative speed-sensor error r (3.26) a request may state: σ equal to the speed
#: itself; beyond it the filter's covariances overflow (r = 1e300 ended in a LinAlgError).
MAX_RELATIVE_NOISE = 1.0

#: LocalCluster worker processes of ``--scheduler local`` when ``--workers`` is not given.
DEFAULT_WORKERS = 2

#: Default TCU sample time (s), the thesis'.
DEFAULT_SAMPLE_TIME = 0.01
#: The smallest sample time: the simulated record's spacing (0.5 ms); a smaller one would
#: only repeat samples, and 1e-9 s took the machine's memory.
MIN_SAMPLE_TIME = 0.0005


@dataclass(frozen=True)
class Calibration:
    """What the TCU knows; nothing here is read from the truth.

    ``relative_noise``: the filter's sensor-noise model, one relative error r (3.26) for every
    output or one per output (``None``: :data:`DEFAULT_RELATIVE_NOISE`; the UIO: no noise).
    ``parameters``: the EKF's augmented parameters (``None``: the thesis' (4.1)). ``initial``:
    initial estimates by state name. ``modes``: "filter" (the filter decides the element modes,
    as a TCU must) or "reference" (the reference simulation's, for comparison); ``None``:
    "filter". ``sample_time``: the TCU's (``None``: :data:`DEFAULT_SAMPLE_TIME`, or a
    recording's channel-map grid)."""

    description: GearboxDescription
    sample_time: float | None = None
    relative_noise: tuple[float, ...] | None = None
    parameters: tuple[str, ...] | None = None
    initial: Mapping[str, float] = field(default_factory=dict)
    modes: str | None = None
    #: overrides the description's ``[estimator] mu_model`` (``None``: the description's)
    mu_model: str | None = None

    @property
    def mode_source(self) -> str:
        return self.modes or "filter"

    @property
    def filter_sample_time(self) -> float:
        return DEFAULT_SAMPLE_TIME if self.sample_time is None else self.sample_time


@dataclass(frozen=True)
class Truth:
    """The world one evaluation runs in: ``scenario`` simulated by the reference, or its inputs
    and outputs taken from ``measurement`` (a bench recording, mapped by the scenario's
    ``[measurement]`` table). ``source`` names where the scenario came from, for the report."""

    scenario: Scenario
    source: str = "built-in"
    measurement: Any = None


@dataclass(frozen=True)
class EstimateRequest:
    """One ``gearsym estimate``: the filter, what it knows, the world(s), and the evaluation.

    ``truths``: one truth, or several consecutive shifts with ``drive`` (the EKF carries m_veh
    and ζ from one to the next). ``runs``/``seed``: Monte-Carlo over noise seeds seed, seed+1, …
    ``initial_from_prior``: each run's initial estimate drawn from the prior around the truth
    (the posterior bound's premise). ``dropout``: a sensor dropout (T0, T1) in s or the name of
    a detected phase ("speed phase"); ``dropout_outputs``: the outputs that drop out (default:
    all). ``unknown``: the UIO's unknown inputs (5.3). ``plots``: write the PNGs with files."""

    filter: str
    calibration: Calibration
    truths: tuple[Truth, ...]
    runs: int = 1
    seed: int = 0
    initial_from_prior: bool = False
    dropout: tuple[float, float] | str | None = None
    dropout_outputs: tuple[str, ...] | None = None
    unknown: tuple[str, ...] = ("T_res_star",)
    drive: bool = False
    plots: bool = True
    #: a :class:`~gearsym.validation.sim.fleet.Fleet`: each run draws its own vehicle (the
    #: truth) and the reference simulates it; ``None``: one truth equal to the calibration
    fleet: Any = None
    #: the command that made the request, for the Markdown table a fleet evaluation writes
    command: str = ""
    #: with ``fleet``: tune the model-error intensities on these runs' vehicles instead of
    #: evaluating (:func:`~gearsym.validation.studies.estimation.tuning.tune_model_error`)
    tune: bool = False
    #: with ``fleet``: run the vehicles on Dask, ``"local"`` (a LocalCluster of ``workers``
    #: processes, default :data:`DEFAULT_WORKERS`) or ``"tcp://HOST:PORT"`` (a running
    #: scheduler and its workers); ``None``: one after the other in this process
    scheduler: str | None = None
    workers: int | None = None

    @property
    def truth(self) -> Truth:
        return self.truths[0]


class Reporter(Protocol):
    """Where the workflow tells how far it is: ``say`` a step, ``bar`` a progress display
    (``bar(label)`` returns ``(update, done)``; ``update(fraction, message)``)."""

    def say(self, message: str) -> None: ...

    def bar(self, label: str) -> tuple[Callable[[float, str], None], Callable[[], None]]: ...


class _Silent:
    def say(self, message: str) -> None:
        pass

    def bar(self, label: str) -> tuple[Callable[[float, str], None], Callable[[], None]]:
        return (lambda fraction, message: None), (lambda: None)


@dataclass
class EstimateReport:
    """What :func:`estimate` found: ``data`` (the JSON of ``gearsym estimate --json``),
    ``text`` (what it prints), ``result`` (the run or Monte-Carlo object, for a notebook)."""

    data: dict[str, Any]
    text: str
    result: Any = None

    def to_dict(self) -> dict[str, Any]:
        return self.data


# ---------------------------------------------------------------------------------------------
# What a request may ask: every option is used by the chosen filter or refused
# ---------------------------------------------------------------------------------------------


_EKF_OR_EUIO = "is for --filter ekf or euio only"


def _refuse(option: str, given: bool, reason: str) -> None:
    if given:
        raise GearsymError("estimate", option, reason)


def check_request(request: EstimateRequest) -> None:
    """Refuse, before any simulation, what the chosen filter would not use or cannot do; a
    one-line :class:`GearsymError` naming the option."""
    cal = request.calibration
    if request.filter not in FILTERS:
        raise GearsymError(
            "estimate", "--filter", f"expected one of {', '.join(FILTERS)}, got {request.filter!r}"
        )
    if cal.mu_model is not None and cal.mu_model not in MU_MODELS:
        raise GearsymError(
            "estimate",
            "--mu-model",
            f"expected one of {', '.join(MU_MODELS)}, got {cal.mu_model!r}",
        )
    mu_model = cal.mu_model or cal.description.estimator.mu_model
    _refuse(
        "--mu-model" if cal.mu_model else "estimator.mu_model",
        mu_model == "map_scale" and request.filter != "ekf",
        "map_scale is for --filter ekf (the extended UIO keeps the thesis' random-walk mu)",
    )
    noise = cal.relative_noise or ()
    if any(not 0 <= r <= MAX_RELATIVE_NOISE for r in noise):
        raise GearsymError(
            "estimate",
            "--noise",
            f"a relative speed error must be in [0, {MAX_RELATIVE_NOISE:g}], got "
            f"{', '.join(f'{r:g}' for r in noise)}",
        )
    _check_scheduler(request)
    if request.truth.measurement is not None:
        _refuse("--fleet", request.fleet is not None, "needs a simulated truth, not a recording")
        _check_measured(request)
        return
    _refuse("--tune", request.tune and request.fleet is None, "needs --fleet (it tunes on one)")
    if request.fleet is not None:
        _check_fleet(request)
    t_end = request.truth.scenario.t_end
    sample_time = cal.filter_sample_time
    if not MIN_SAMPLE_TIME <= sample_time <= t_end / 4:  # the simulation records [0, t_end]
        raise GearsymError(
            "estimate",
            "--sample-time",
            f"must be in [{MIN_SAMPLE_TIME:g}, {t_end / 4:g}] s, got {sample_time!r}",
        )
    _refuse("--modes", cal.modes is not None and request.filter == "uio", _EKF_OR_EUIO)
    if request.drive:
        _refuse("--drive", request.filter != "ekf", "is for --filter ekf only")
        for option, given in (
            ("--runs", request.runs != 1),
            ("--dropout", request.dropout is not None),
            ("--params", cal.parameters is not None),
            ("--noise", cal.relative_noise is not None),
            ("--initial-from-prior", request.initial_from_prior),
        ):
            _refuse(option, given, "is not available with --drive")
        for before, after in zip(request.truths, request.truths[1:], strict=False):
            a, b = before.scenario.shift, after.scenario.shift
            if a.to_gear != b.from_gear:
                raise GearsymError(
                    "estimate",
                    "--drive",
                    f"the shifts do not chain: {a.name} ends in gear {a.to_gear}, the next "
                    f"one ({b.name}, {after.source}) starts in gear {b.from_gear}",
                )
        return
    if request.filter == "uio":
        _refuse("--runs", request.runs != 1, "Monte-Carlo runs are for --filter ekf or euio only")
        for option, given in (
            ("--initial-from-prior", request.initial_from_prior),
            ("--params", cal.parameters is not None),
            ("--initial", bool(cal.initial)),
            ("--dropout", request.dropout is not None),
            ("--dropout-outputs", request.dropout_outputs is not None),
        ):
            _refuse(
                option,
                given,
                "is for --filter ekf only"
                if "drop" in option or option == "--params"
                else _EKF_OR_EUIO,
            )
        if not request.unknown:
            raise GearsymError("estimate", "--unknown", "name at least one unknown input")
        return
    _refuse(
        "--unknown",
        tuple(request.unknown) != ("T_res_star",),
        "is for --filter uio only (the EUIO's unknown input is the road load)",
    )
    if request.initial_from_prior and cal.initial:
        raise GearsymError(
            "estimate", "--initial-from-prior", "draws the initial estimate: drop --initial"
        )
    if request.filter == "euio":
        for option, given in (
            ("--params", cal.parameters is not None),
            ("--dropout", request.dropout is not None),
            ("--dropout-outputs", request.dropout_outputs is not None),
        ):
            _refuse(option, given, "is for --filter ekf only")
        if request.initial_from_prior and request.runs == 1:
            raise GearsymError(
                "estimate", "--initial-from-prior", "with --filter euio needs --runs N (N > 1)"
            )
        if cal.relative_noise is not None and len(cal.relative_noise) != 1:
            raise GearsymError("estimate", "--noise", "the extended UIO takes one value")
        return
    if cal.relative_noise is not None and len(cal.relative_noise) not in (1, 3):
        raise GearsymError("estimate", "--noise", "give one value or one per output (3)")
    if request.dropout_outputs is not None and request.dropout is None:
        raise GearsymError("estimate", "--dropout-outputs", "needs --dropout")


def _check_scheduler(request: EstimateRequest) -> None:
    """``--scheduler`` spreads the runs over a fleet on Dask, nothing else; ``--workers`` is
    the size of a LocalCluster (a remote scheduler brings its own workers)."""
    from gearsym.validation.studies.dask_runner import check_scheduler
    from gearsym.validation.studies.estimation.fleet_eval import WHERE

    if request.scheduler is not None:
        _refuse(
            "--scheduler",
            request.fleet is None,
            "needs --fleet (only the runs over a fleet go to Dask)",
        )
        check_scheduler(request.scheduler, WHERE)
    if request.workers is not None:
        _refuse(
            "--workers",
            request.scheduler != "local",
            "is for --scheduler local; a remote scheduler brings its workers"
            if request.scheduler is not None
            else "is for --scheduler local (the LocalCluster's worker processes)",
        )
        _refuse("--workers", request.workers < 1, f"must be at least 1, got {request.workers}")


def _check_fleet(request: EstimateRequest) -> None:
    """What a fleet evaluation does not take: the filter's start is the calibration's prior
    (no --initial, --initial-from-prior), its parameters the thesis' (4.1)."""
    cal = request.calibration
    _refuse(
        "--fleet",
        request.filter != "ekf",
        "is for --filter ekf (the UIO and the extended UIO over a fleet are not built yet)",
    )
    for option, given, reason in (
        ("--drive", request.drive, "a drive over a fleet is not built yet"),
        ("--initial", bool(cal.initial), "the filter starts from the calibration's prior"),
        (
            "--initial-from-prior",
            request.initial_from_prior,
            "each vehicle is drawn from the fleet; the filter starts from the calibration's prior",
        ),
        ("--params", cal.parameters is not None, "the fleet evaluation runs the thesis' (4.1)"),
        ("--dropout", request.dropout is not None, "not available over a fleet yet"),
        ("--dropout-outputs", request.dropout_outputs is not None, "needs --dropout"),
    ):
        _refuse(option, given, f"is not available with --fleet: {reason}")


def _check_measured(request: EstimateRequest) -> None:
    _refuse("--measurement", request.filter != "ekf", "runs the EKF: add --filter ekf")
    cal = request.calibration
    for option, given in (
        ("--drive", request.drive),
        ("--runs", request.runs != 1),
        ("--initial-from-prior", request.initial_from_prior),
        ("--sample-time", cal.sample_time is not None),
        ("--seed", request.seed != 0),
    ):
        reason = {
            "--sample-time": "the recording's grid is the channel map's sample_time",
            "--seed": "a recording carries its own noise, none is drawn",
        }.get(option, "needs a truth and noise seeds; a recording has neither")
        _refuse(option, given, f"is not available with --measurement: {reason}")
    scenario = request.truth.scenario
    if scenario.measurement is None:
        raise GearsymError(
            scenario.file, "measurement", "missing table [measurement] (the channel map)"
        )
    if scenario.measurement.sample_time > scenario.t_end / 4:
        raise GearsymError(
            scenario.file,
            "measurement.sample_time",
            f"must be at most t_end / 4 = {scenario.t_end / 4:g} s, "
            f"got {scenario.measurement.sample_time:g}",
        )
    if cal.relative_noise is not None and len(cal.relative_noise) not in (1, 3):
        raise GearsymError("estimate", "--noise", "give one value or one per output (3)")
    if request.dropout_outputs is not None and request.dropout is None:
        raise GearsymError("estimate", "--dropout-outputs", "needs --dropout")


# ---------------------------------------------------------------------------------------------
# Truths
# ---------------------------------------------------------------------------------------------


def filter_model(calibration: Calibration, shift: str) -> tuple[Any, list[str]]:
    """The EKF's augmented model (4.1) of ``shift`` with the calibration's parameters (a bad
    name is a one-line error before any run) and the outputs it measures."""
    from gearsym.symbolic.estimators.ekf import augmented_model

    parameters = None if calibration.parameters is None else list(calibration.parameters)
    aug = augmented_model(calibration.description, shift, parameters)
    return aug, [name.removeprefix("y_") for name in aug.output_names]


def measured_truth(
    calibration: Calibration, scenario: Scenario, recording: str | Path, source: str
) -> Truth:
    """A bench recording as the truth: the scenario's ``[measurement]`` table must map every
    output the filter measures (checked before the file is read), then the file is read."""
    from gearsym.validation.sim.measurement import read_measurement

    cmap = scenario.measurement
    if cmap is None:
        raise GearsymError(
            scenario.file, "measurement", "missing table [measurement] (the channel map)"
        )
    _, outputs = filter_model(calibration, scenario.shift.name)
    missing = [o for o in outputs if cmap.channel(o) is None]
    if missing:
        raise GearsymError(
            scenario.file,
            f"measurement.channel.{missing[0]}",
            f"missing: the filter measures {', '.join(outputs)}",
        )
    measurement = read_measurement(recording, cmap, scenario.t_end, require=outputs)
    return Truth(scenario, source, measurement)


def drive_truths(d: GearboxDescription, spec: str) -> tuple[Truth, ...]:
    """``upshifts`` (the shipped 1-2, 2-3, 3-4) or comma-separated scenario files, at least
    two, each the truth of one shift of the drive."""
    from gearsym.validation.sim.scenario import default_scenario_path, load_scenario

    if spec.strip() == "upshifts":
        folder = Path(default_scenario_path()).parent
        files = [(str(folder / name), f"built-in {name}") for name in DRIVE_UPSHIFTS]
    else:
        files = [(f.strip(), f.strip()) for f in spec.split(",") if f.strip()]
        if len(files) < 2:
            raise GearsymError(
                "estimate", "--drive", "give 'upshifts' or at least two scenario files"
            )
    return tuple(Truth(load_scenario(d, path), source) for path, source in files)


# ---------------------------------------------------------------------------------------------
# The workflow
# ---------------------------------------------------------------------------------------------


def estimate(
    request: EstimateRequest, folder: Path | None = None, reporter: Reporter | None = None
) -> EstimateReport:
    """Run ``request``: check it (:func:`check_request`), simulate each truth with the
    reference, run the filter (once or over the Monte-Carlo seeds) and report; with ``folder``
    (a staging folder of the one output writer), also write the CSV, JSON and plots there."""
    check_request(request)
    reporter = reporter or _Silent()
    cal = request.calibration
    if cal.mu_model is not None:  # the filter's μ form, over the description's table
        d = cal.description
        d = replace(d, estimator=replace(d.estimator, mu_model=cal.mu_model))
        request = replace(request, calibration=replace(cal, description=d))
    if request.truth.measurement is not None:
        return _measured(request, folder, reporter)
    if request.fleet is not None:
        return _fleet(request, folder, reporter)
    if request.drive:
        return _drive(request, reporter)
    if request.filter == "uio":
        return _uio(request, folder, reporter)
    if request.filter == "euio":
        return _euio(request, folder, reporter)
    return _ekf(request, folder, reporter)


def _simulate(d: GearboxDescription, scenario: Scenario, reporter: Reporter) -> Any:
    from gearsym.validation.sim.simulate import simulate

    update, done = reporter.bar("simulate")
    try:
        return simulate(d, scenario, progress=update)
    finally:
        done()


def _noise(cal: Calibration) -> Any:
    """The EKF's and the EUIO's noise model: one value for every output, or one per output."""
    if cal.relative_noise is None:
        return DEFAULT_RELATIVE_NOISE
    return list(cal.relative_noise)


def _window(dropout: tuple[float, float] | str | None, result: Any) -> tuple[float, float] | None:
    """A dropout phase resolved to its window as the simulation detected it."""
    if isinstance(dropout, str):
        (phase,) = [p for p in result.phases if p.name == dropout]
        return (float(phase.t_start), float(phase.t_end))
    return dropout


def _write_json(path: Path, data: Mapping[str, Any]) -> None:
    import json

    path.write_text(json.dumps(data, indent=2) + "\n")


def _write_markdown(
    path: Path, data: Mapping[str, Any], request: EstimateRequest, kind: str = "monte_carlo"
) -> None:
    """A result table for the documentation (written by the command, never typed)."""
    from gearsym.validation.studies.estimation.markdown import monte_carlo_markdown, uio_markdown

    command = request.command or f"gearsym estimate --filter {request.filter}"
    render = uio_markdown if kind == "uio" else monte_carlo_markdown
    path.write_text(render(dict(data), command), encoding="utf-8")


def _assumes(lines: Sequence[str]) -> str:
    return "\n".join(f"  assumes {line}" for line in lines)


def _uio(request: EstimateRequest, folder: Path | None, reporter: Reporter) -> EstimateReport:
    from gearsym.symbolic.estimators import linear_modes
    from gearsym.validation.studies.estimation.plots import plot_uio
    from gearsym.validation.studies.estimation.report import format_text, write_csv
    from gearsym.validation.studies.estimation.uio import check_unknown, run_uio

    cal, truth = request.calibration, request.truth
    d = cal.description
    check_unknown(linear_modes(d, truth.scenario.shift.name), list(request.unknown))
    result = _simulate(d, truth.scenario, reporter)
    reporter.say("designing and running the UIO of each phase")
    run = run_uio(
        d,
        result,
        unknown=list(request.unknown),
        sample_time=cal.filter_sample_time,
        relative_noise=None if cal.relative_noise is None else list(cal.relative_noise),
        seed=request.seed,
    )
    if folder is not None:
        write_csv(run, folder / "uio.csv")
        _write_json(folder / "uio.json", run.to_dict())
        _write_markdown(folder / "uio.md", run.to_dict(), request, "uio")
        if request.plots:
            plot_uio(run, folder)
    return EstimateReport(run.to_dict(), format_text(run), run)


def _check_ekf_names(request: EstimateRequest, aug: Any) -> list[str]:
    """The filter's outputs; the dropout outputs and initial values named exist."""
    outputs = [name.removeprefix("y_") for name in aug.output_names]
    chosen = request.dropout_outputs
    wrong = [o for o in chosen or () if o not in outputs]
    if wrong or chosen == ():
        raise GearsymError(
            "estimate",
            "--dropout-outputs",
            f"expected outputs of the filter ({', '.join(outputs)}), got "
            f"{','.join(chosen or ())!r}",
        )
    wrong = [name for name in request.calibration.initial if name not in aug.state_names]
    if wrong:
        raise GearsymError(
            "estimate",
            "--initial",
            f"{', '.join(wrong)} is not a state of the filter ({', '.join(aug.state_names)})",
        )
    return outputs


def _ekf(request: EstimateRequest, folder: Path | None, reporter: Reporter) -> EstimateReport:
    from gearsym.validation.studies.estimation.montecarlo import run_ekf_monte_carlo
    from gearsym.validation.studies.estimation.plots import plot_efficiency, plot_ekf
    from gearsym.validation.studies.estimation.report import (
        format_ekf_text,
        format_monte_carlo_text,
        write_ekf_csv,
    )
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    cal, truth = request.calibration, request.truth
    d = cal.description
    aug, _ = filter_model(cal, truth.scenario.shift.name)  # bad names: before the run
    outputs = _check_ekf_names(request, aug)
    result = _simulate(d, truth.scenario, reporter)
    window = _window(request.dropout, result)
    setup = prepare_ekf(
        d,
        result,
        sample_time=cal.filter_sample_time,
        relative_noise=_noise(cal),
        initial=dict(cal.initial),
        aug=aug,
        modes=cal.mode_source,
    )
    update, done = reporter.bar(f"EKF, {request.runs} run{'s' if request.runs > 1 else ''}")
    try:
        mc = run_ekf_monte_carlo(
            setup,
            request.runs,
            seed=request.seed,
            progress=update,
            prior_draw=request.initial_from_prior,
            dropout=window,
            dropout_outputs=None
            if request.dropout_outputs is None
            else list(request.dropout_outputs),
        )
    finally:
        done()
    assumes = [f"scenario: {truth.scenario.name} ({truth.source})"]
    if window is not None:
        dropped = ", ".join(request.dropout_outputs or outputs)
        assumes.append(
            f"sensor dropout: {dropped} missing (NaN) in [{window[0]:.4g}, {window[1]:.4g}) s: "
            "those updates are skipped"
        )
    if folder is not None:
        write_ekf_csv(mc.first, folder / "ekf.csv")
        _write_json(folder / "ekf.json", mc.to_dict())
        if len(mc.runs) > 1:
            _write_markdown(folder / "monte_carlo.md", mc.to_dict(), request)
        if request.plots:
            plot_ekf(mc.first, folder / "ekf.png")
            plot_efficiency(mc, folder / "ekf_efficiency.png")
    body = format_monte_carlo_text(mc)
    body = body if len(mc.runs) > 1 else format_ekf_text(mc.first) + "\n" + body
    return EstimateReport(mc.to_dict(), _assumes(assumes) + "\n" + body, mc)


def _euio(request: EstimateRequest, folder: Path | None, reporter: Reporter) -> EstimateReport:
    from gearsym.validation.studies.estimation.plots import plot_euio
    from gearsym.validation.studies.estimation.report import format_euio_text, write_euio_csv
    from gearsym.validation.studies.euio_evaluation import (
        euio_filter_run,
        format_euio_monte_carlo_text,
        plot_euio_efficiency,
        prepare_euio,
        run_euio_monte_carlo,
    )

    cal, truth = request.calibration, request.truth
    d = cal.description
    noise = DEFAULT_RELATIVE_NOISE if cal.relative_noise is None else cal.relative_noise[0]
    result = _simulate(d, truth.scenario, reporter)
    if request.runs == 1:
        reporter.say("running the extended UIO")
    setup = prepare_euio(
        d,
        result,
        sample_time=cal.filter_sample_time,
        relative_noise=noise,
        initial=dict(cal.initial),
        modes=cal.mode_source,
    )
    if request.runs == 1:
        run = euio_filter_run(setup, request.seed).run  # run_euio's loop (tested to the bit)
        if folder is not None:
            write_euio_csv(run, folder / "euio.csv")
            _write_json(folder / "euio.json", run.to_dict())
            if request.plots:
                plot_euio(run, folder / "euio.png")
        return EstimateReport(run.to_dict(), format_euio_text(run), run)
    update, done = reporter.bar(f"EUIO, {request.runs} runs")
    try:
        mc = run_euio_monte_carlo(
            setup,
            request.runs,
            seed=request.seed,
            progress=update,
            prior_draw=request.initial_from_prior,
        )
    finally:
        done()
    if folder is not None:
        write_euio_csv(mc.first, folder / "euio.csv")
        _write_json(folder / "euio.json", mc.to_dict())
        _write_markdown(folder / "monte_carlo.md", mc.to_dict(), request)
        if request.plots:
            plot_euio(mc.first, folder / "euio.png")
            plot_euio_efficiency(mc, folder / "euio_efficiency.png")
    text = f"  assumes scenario: {truth.scenario.name} ({truth.source})\n"
    return EstimateReport(mc.to_dict(), text + format_euio_monte_carlo_text(mc), mc)


def _drive(request: EstimateRequest, reporter: Reporter) -> EstimateReport:
    from gearsym.validation.studies.estimation.loop import DRIVE_CARRIED, run_ekf_drive
    from gearsym.validation.studies.estimation.report import format_ekf_text

    cal = request.calibration
    d = cal.description
    wrong = [name for name in cal.initial if name not in DRIVE_CARRIED]
    if wrong:
        raise GearsymError(
            "estimate",
            "--initial",
            f"with --drive only {' and '.join(DRIVE_CARRIED)}, got {', '.join(wrong)}",
        )
    scenarios = [t.scenario for t in request.truths]
    results = [_simulate(d, sc, reporter) for sc in scenarios]
    reporter.say("running the EKF through the shifts, m_veh and zeta carried")
    runs = run_ekf_drive(
        d,
        results,
        seed=request.seed,
        sample_time=cal.filter_sample_time,
        initial=dict(cal.initial),
        modes=cal.mode_source,
    )
    lines = [
        "  assumes a drive of consecutive shifts "
        + " -> ".join(sc.name for sc in scenarios)
        + ": each shift simulated on its own (the reference does not chain shifts); the "
        "filter carries m_veh and zeta, estimate and covariance, from one shift's end to "
        "the next one's start; every other state starts as in a single shift"
    ]
    for sc, run in zip(scenarios, runs, strict=True):
        lines.append(f"  shift {sc.shift.name} ({sc.name}):")
        lines.append(format_ekf_text(run))
    data = {"filter": "ekf", "drive": [r.to_dict() for r in runs]}
    return EstimateReport(data, "\n".join(lines), runs)


def _measured(request: EstimateRequest, folder: Path | None, reporter: Reporter) -> EstimateReport:
    """The EKF on a bench recording mapped by the scenario's ``[measurement]`` table; the
    inputs of the simulation that gives the element modes and the phases are the recorded
    ones."""
    from gearsym.validation.sim.measurement import RESAMPLE_TEXT
    from gearsym.validation.sim.scenario import input_sources
    from gearsym.validation.sim.scenario import with_measured_inputs as driven
    from gearsym.validation.studies.estimation.loop import filter_run
    from gearsym.validation.studies.estimation.plots import plot_ekf
    from gearsym.validation.studies.estimation.report import (
        format_measured_ekf_text,
        measured_ekf_dict,
        write_ekf_csv,
    )
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    cal, truth = request.calibration, request.truth
    d, scenario, measurement = cal.description, truth.scenario, truth.measurement
    cmap = scenario.measurement
    aug, outputs = filter_model(cal, scenario.shift.name)
    result = _simulate(d, driven(scenario, measurement), reporter)
    window = _window(request.dropout, result)
    setup = prepare_ekf(
        d,
        result,
        sample_time=cmap.sample_time,
        relative_noise=_noise(cal),
        initial=dict(cal.initial),
        aug=aug,
        measured={o: measurement.values[o] for o in outputs},
        modes=cal.mode_source,
    )
    reporter.say("running the EKF on the recording")
    run = filter_run(
        setup,
        dropout=window,
        dropout_outputs=None if request.dropout_outputs is None else list(request.dropout_outputs),
    )
    sources = input_sources(scenario, measurement)
    assumes = [
        f"recording: {measurement.file} ({measurement.format}, {len(measurement.t)} "
        f"samples every {cmap.sample_time * 1e3:g} ms; {RESAMPLE_TEXT})",
        "inputs: " + ", ".join(f"{name} from the {where}" for name, where in sources.items()),
        (
            "element modes: decided by the filter from its estimate and F_N"
            if cal.mode_source == "filter"
            else "element modes: from the reference simulation driven by those inputs"
        )
        + "; phases: from the reference simulation driven by those inputs (scenario "
        f"{scenario.name}, {truth.source})",
    ]
    data = {
        **measured_ekf_dict(run),
        "measurement": measurement.to_dict(),
        "input_sources": sources,
    }
    if folder is not None:
        write_ekf_csv(run, folder / "ekf.csv")
        _write_json(folder / "ekf.json", data)
        if request.plots:
            plot_ekf(run, folder / "ekf.png")
    return EstimateReport(data, _assumes(assumes) + "\n" + format_measured_ekf_text(run), run)


def _fleet(request: EstimateRequest, folder: Path | None, reporter: Reporter) -> EstimateReport:
    """The EKF over a fleet (:func:`~gearsym.validation.studies.estimation.fleet_eval.
    run_fleet`): each run its own vehicle, simulated, the filter told the commands."""
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet
    from gearsym.validation.studies.estimation.fleet_report import (
        fleet_markdown,
        format_fleet_text,
        plot_fleet,
        write_fleet_csv,
    )

    cal, truth = request.calibration, request.truth
    if request.tune:
        return _tune(request, folder, reporter)
    with _dask(request, reporter) as client:
        update, done = reporter.bar(f"EKF over the fleet, {request.runs} vehicles")
        try:
            evaluation = run_fleet(
                cal.description,
                truth.scenario,
                request.fleet,
                request.runs,
                seed=request.seed,
                sample_time=cal.filter_sample_time,
                relative_noise=_noise(cal),
                modes=cal.mode_source,
                progress=update,
                client=client,
            )
        finally:
            done()
    data = evaluation.to_dict()
    if folder is not None:
        write_fleet_csv(evaluation, folder / "fleet.csv")
        _write_json(folder / "fleet.json", data)
        (folder / "fleet.md").write_text(
            fleet_markdown(data, request.command or "gearsym estimate --fleet"),
            encoding="utf-8",
        )
        if request.plots:
            plot_fleet(evaluation, folder / "fleet.png")
    return EstimateReport(data, format_fleet_text(data), evaluation)


@contextmanager
def _dask(request: EstimateRequest, reporter: Reporter) -> Iterator[Any]:
    """The Dask client of ``request.scheduler`` for the block (``None`` without one), closed
    after it with the LocalCluster it started; reached before any simulation, so an
    unreachable scheduler is a one-line error at once."""
    from gearsym.validation.studies.dask_runner import connect
    from gearsym.validation.studies.estimation.fleet_eval import WHERE

    if request.scheduler is None:
        yield None
        return
    workers = DEFAULT_WORKERS if request.workers is None else request.workers
    if request.scheduler == "local":
        reporter.say(f"starting a local Dask cluster of {workers} worker processes")
    else:
        reporter.say(f"connecting to the Dask scheduler {request.scheduler}")
    client, cluster = connect(request.scheduler, workers, where=WHERE)
    try:
        reporter.say(
            f"{len(client.scheduler_info().get('workers', {}))} Dask workers; each builds the "
            "filter's model once"
        )
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _tune(request: EstimateRequest, folder: Path | None, reporter: Reporter) -> EstimateReport:
    """``--fleet --tune``: the model-error intensities chosen on the runs' vehicles (tuning
    seeds, which an evaluation must not reuse)."""
    from gearsym.validation.studies.estimation.tuning import tune_model_error

    cal, truth = request.calibration, request.truth
    seeds = list(range(request.seed, request.seed + request.runs))
    with _dask(request, reporter) as client:
        update, done = reporter.bar(f"tuning over the fleet, {request.runs} vehicles")
        try:
            result = tune_model_error(
                cal.description,
                truth.scenario,
                request.fleet,
                seeds,
                sample_time=cal.filter_sample_time,
                relative_noise=_noise(cal),
                progress=update,
                client=client,
            )
        finally:
            done()
    data = {"filter": "ekf", "tuning": result.to_dict()}
    if folder is not None:
        _write_json(folder / "tuning.json", data)
    return EstimateReport(data, result.text(), result)
