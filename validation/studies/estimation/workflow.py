"""``estimate(request) -> report``: the workflow of every estimator of thesis chapter 4, from a
request to a report (JSON, text, files), usable from a notebook as from ``gearsym estimate``.

A request (:mod:`.request`) keeps apart what the filter knows and the world it is judged in:

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

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import MU_MODELS
from gearsym.validation.sim.scenario import Scenario
from gearsym.validation.studies.estimation.fleet_workflow import (
    check_fleet_request,
    check_scheduler_request,
    run_fleet_request,
)
from gearsym.validation.studies.estimation.request import (
    DEFAULT_RELATIVE_NOISE,
    DRIVE_UPSHIFTS,
    FILTERS,
    MAX_RELATIVE_NOISE,
    MIN_SAMPLE_TIME,
    Calibration,
    EstimateReport,
    EstimateRequest,
    Reporter,
    Silent,
    Truth,
    filter_noise,
    refuse,
    write_json,
)

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

# ---------------------------------------------------------------------------------------------
# What a request may ask: every option is used by the chosen filter or refused
# ---------------------------------------------------------------------------------------------


_EKF_OR_EUIO = "is for --filter ekf or euio only"


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
    refuse(
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
    check_scheduler_request(request)
    if request.truth.measurement is not None:
        refuse("--fleet", request.fleet is not None, "needs a simulated truth, not a recording")
        _check_measured(request)
        return
    refuse("--tune", request.tune and request.fleet is None, "needs --fleet (it tunes on one)")
    if request.fleet is not None:
        check_fleet_request(request)
    t_end = request.truth.scenario.t_end
    sample_time = cal.filter_sample_time
    if not MIN_SAMPLE_TIME <= sample_time <= t_end / 4:  # the simulation records [0, t_end]
        raise GearsymError(
            "estimate",
            "--sample-time",
            f"must be in [{MIN_SAMPLE_TIME:g}, {t_end / 4:g}] s, got {sample_time!r}",
        )
    refuse("--modes", cal.modes is not None and request.filter == "uio", _EKF_OR_EUIO)
    if request.drive:
        refuse("--drive", request.filter != "ekf", "is for --filter ekf only")
        for option, given in (
            ("--runs", request.runs != 1),
            ("--dropout", request.dropout is not None),
            ("--params", cal.parameters is not None),
            ("--noise", cal.relative_noise is not None),
            ("--initial-from-prior", request.initial_from_prior),
        ):
            refuse(option, given, "is not available with --drive")
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
        refuse("--runs", request.runs != 1, "Monte-Carlo runs are for --filter ekf or euio only")
        for option, given in (
            ("--initial-from-prior", request.initial_from_prior),
            ("--params", cal.parameters is not None),
            ("--initial", bool(cal.initial)),
            ("--dropout", request.dropout is not None),
            ("--dropout-outputs", request.dropout_outputs is not None),
        ):
            refuse(
                option,
                given,
                "is for --filter ekf only"
                if "drop" in option or option == "--params"
                else _EKF_OR_EUIO,
            )
        if not request.unknown:
            raise GearsymError("estimate", "--unknown", "name at least one unknown input")
        return
    refuse(
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
            refuse(option, given, "is for --filter ekf only")
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


def _check_measured(request: EstimateRequest) -> None:
    refuse("--measurement", request.filter != "ekf", "runs the EKF: add --filter ekf")
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
        refuse(option, given, f"is not available with --measurement: {reason}")
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
    reporter = reporter or Silent()
    cal = request.calibration
    if cal.mu_model is not None:  # the filter's μ form, over the description's table
        d = cal.description
        d = replace(d, estimator=replace(d.estimator, mu_model=cal.mu_model))
        request = replace(request, calibration=replace(cal, description=d))
    if request.truth.measurement is not None:
        return _measured(request, folder, reporter)
    if request.fleet is not None:
        return run_fleet_request(request, folder, reporter)
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


def _window(dropout: tuple[float, float] | str | None, result: Any) -> tuple[float, float] | None:
    """A dropout phase resolved to its window as the simulation detected it."""
    if isinstance(dropout, str):
        (phase,) = [p for p in result.phases if p.name == dropout]
        return (float(phase.t_start), float(phase.t_end))
    return dropout


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
        write_json(folder / "uio.json", run.to_dict())
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
        relative_noise=filter_noise(cal),
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
        write_json(folder / "ekf.json", mc.to_dict())
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
            write_json(folder / "euio.json", run.to_dict())
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
        write_json(folder / "euio.json", mc.to_dict())
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
        relative_noise=filter_noise(cal),
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
        write_json(folder / "ekf.json", data)
        if request.plots:
            plot_ekf(run, folder / "ekf.png")
    return EstimateReport(data, _assumes(assumes) + "\n" + format_measured_ekf_text(run), run)
