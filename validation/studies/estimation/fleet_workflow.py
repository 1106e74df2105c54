"""``gearsym estimate --fleet``'s part of the workflow (:mod:`.workflow` dispatches here): what
a fleet request may not take, the evaluation over the fleet (serial or on Dask) and the tuning
on a fleet's tuning seeds."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from gearsym.validation.studies.estimation.request import (
    DEFAULT_WORKERS,
    EstimateReport,
    EstimateRequest,
    Reporter,
    filter_noise,
    refuse,
    write_json,
)

__all__ = ["check_fleet_request", "check_scheduler_request", "run_fleet_request"]


def check_scheduler_request(request: EstimateRequest) -> None:
    """``--scheduler`` spreads the runs over a fleet on Dask, nothing else; ``--workers`` is
    the size of a LocalCluster (a remote scheduler brings its own workers)."""
    from gearsym.validation.studies.dask_runner import check_scheduler
    from gearsym.validation.studies.estimation.fleet_eval import WHERE

    if request.scheduler is not None:
        refuse(
            "--scheduler",
            request.fleet is None,
            "needs --fleet (only the runs over a fleet go to Dask)",
        )
        check_scheduler(request.scheduler, WHERE)
    if request.workers is not None:
        refuse(
            "--workers",
            request.scheduler != "local",
            "is for --scheduler local; a remote scheduler brings its workers"
            if request.scheduler is not None
            else "is for --scheduler local (the LocalCluster's worker processes)",
        )
        refuse("--workers", request.workers < 1, f"must be at least 1, got {request.workers}")


def check_fleet_request(request: EstimateRequest) -> None:
    """What a fleet evaluation does not take: the filter's start is the calibration's prior
    (no --initial, --initial-from-prior), its parameters the thesis' (4.1)."""
    cal = request.calibration
    refuse(
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
        ("--dropout", request.dropout is not None, "not available over a fleet yet"),
        ("--dropout-outputs", request.dropout_outputs is not None, "needs --dropout"),
    ):
        refuse(option, given, f"is not available with --fleet: {reason}")
    if cal.parameters is not None:
        from gearsym.symbolic.estimator_calibration import (
            AUGMENTED_STATES,
            DAMPING,
            STIFFNESS,
        )
        from gearsym.symbolic.estimators.ekf import default_parameters

        thesis = default_parameters(cal.description, request.truth.scenario.shift.name)
        extra = set(cal.parameters) - set(thesis)
        refuse(
            "--params",
            not set(thesis) <= set(cal.parameters)
            or not extra <= set(AUGMENTED_STATES)
            or len(set(cal.parameters)) != len(cal.parameters),
            f"with --fleet: the thesis' (4.1) {','.join(thesis)}, optionally with "
            f"{', '.join(AUGMENTED_STATES)} ({STIFFNESS}, {DAMPING}: the side shafts' stiffness "
            f"and damping), got "
            f"{','.join(cal.parameters)}",
        )


def run_fleet_request(
    request: EstimateRequest, folder: Path | None, reporter: Reporter
) -> EstimateReport:
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
                relative_noise=filter_noise(cal),
                modes=cal.mode_source,
                progress=update,
                client=client,
                parameters=cal.parameters,
                input_hold=cal.input_hold,
            )
        finally:
            done()
    data = evaluation.to_dict()
    if folder is not None:
        write_fleet_csv(evaluation, folder / "fleet.csv")
        write_json(folder / "fleet.json", data)
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
    from gearsym.validation.studies.estimation.tuning import (
        FACTORS,
        IN_GEAR_FACTORS,
        TWIST_FACTORS,
        tune_model_error,
    )

    cal, truth = request.calibration, request.truth
    seeds = list(range(request.seed, request.seed + request.runs))
    with _dask(request, reporter) as client:
        shifts = 1 + len(request.tune_scenarios)
        each = f" x {shifts} shifts" if shifts > 1 else ""
        update, done = reporter.bar(f"tuning over the fleet, {request.runs} vehicles{each}")
        try:
            result = tune_model_error(
                cal.description,
                (truth.scenario, *request.tune_scenarios),
                request.fleet,
                seeds,
                sample_time=cal.filter_sample_time,
                relative_noise=filter_noise(cal),
                progress=update,
                client=client,
                parameters=cal.parameters,
                input_hold=cal.input_hold,
                factors=request.tune_factors or FACTORS,
                twist_factors=request.tune_twist_factors or TWIST_FACTORS,
                in_gear_factors=request.tune_in_gear or IN_GEAR_FACTORS,
                criterion=request.tune_criterion,
            )
        finally:
            done()
    data = {"filter": "ekf", "tuning": result.to_dict()}
    if folder is not None:
        write_json(folder / "tuning.json", data)
    return EstimateReport(data, result.text(), result)
