"""``gearsym estimate``: estimators of thesis chapter 4 run on the reference shift.

The unknown input observer (4.4): existence per phase, and its estimates of the states and the
unknown inputs against the reference simulation; the extended Kalman filter (4.3) on the
parameter-augmented shift model (4.1): m_veh, μ of the swapping elements and ζ with σ, NEES and
NIS against the reference. This module parses and prints; the
work is in :mod:`gearsym.symbolic.estimators` and :mod:`gearsym.validation.studies.estimation`.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from gearsym.commands import add_command, load
from gearsym.interrupts import check
from gearsym.options import number

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_estimate", "register"]

FILTERS = ("uio", "ekf", "euio")


def _say(message: str) -> None:
    check()
    print(f"  … {message}", file=sys.stderr, flush=True)


def cmd_estimate(args: argparse.Namespace) -> int:
    """Run the chosen estimator on the scenario's reference shift; print, or write with --out."""
    from gearsym.symbolic.errors import GearsymError
    from gearsym.validation.sim.scenario import load_scenario

    d = load(args.config)
    scenario = load_scenario(d, args.scenario)
    if args.measurement is not None:
        return _cmd_measured(args, d, scenario)
    if args.sample_time is None:
        args.sample_time = 0.01
    if args.sample_time > scenario.t_end / 4:  # before the simulation: it records [0, t_end]
        raise GearsymError(
            "estimate",
            "--sample-time",
            f"must be in (0, {scenario.t_end / 4:g}] s, got {args.sample_time!r}",
        )
    if args.modes is not None and args.filter not in ("ekf", "euio"):
        raise GearsymError("estimate", "--modes", "is for --filter ekf or euio only")
    if args.modes is None:
        args.modes = "filter"
    if args.drive is not None:
        if args.filter != "ekf":
            raise GearsymError("estimate", "--drive", "is for --filter ekf only")
        return _cmd_drive(args, d)
    if args.filter == "ekf":
        return _cmd_ekf(args, d, scenario)
    if args.filter == "euio":
        return _cmd_euio(args, d, scenario)
    if args.runs != 1:
        raise GearsymError(
            "estimate", "--runs", "Monte-Carlo runs are for --filter ekf or euio only"
        )
    if args.initial_from_prior:
        raise GearsymError("estimate", "--initial-from-prior", "is for --filter ekf or euio only")
    unknown = [u.strip() for u in args.unknown.split(",") if u.strip()]
    if not unknown:
        raise GearsymError("estimate", "--unknown", "name at least one unknown input")
    noise = None
    if args.noise is not None:
        try:
            noise = [number(float, minimum=0)(v) for v in args.noise.split(",")]
        except argparse.ArgumentTypeError as err:
            raise GearsymError("estimate", "--noise", str(err)) from None

    from gearsym.symbolic.estimators import linear_modes
    from gearsym.validation.studies.estimation.uio import check_unknown

    check_unknown(linear_modes(d, scenario.shift.name), unknown)  # before the simulation

    def work(folder: Any) -> Any:
        from gearsym.cmd_dynamics import simulate_with_progress
        from gearsym.validation.studies.estimation.plots import plot_uio
        from gearsym.validation.studies.estimation.report import write_csv
        from gearsym.validation.studies.estimation.uio import run_uio

        result = simulate_with_progress(d, scenario)
        _say("designing and running the UIO of each phase")
        run = run_uio(
            d,
            result,
            unknown=unknown,
            sample_time=args.sample_time,
            relative_noise=noise,
            seed=args.seed,
        )
        if folder is not None:
            write_csv(run, folder / "uio.csv")
            (folder / "uio.json").write_text(json.dumps(run.to_dict(), indent=2) + "\n")
            if not args.no_plots:
                plot_uio(run, folder)
        return run

    from gearsym.validation.studies.estimation.report import format_text

    return _run_and_report(args, work, format_text)


def _cmd_euio(args: argparse.Namespace, d: Any, scenario: Any) -> int:
    """``--filter euio``: the extended UIO (4.5) on the reference shift."""
    from gearsym.symbolic.errors import GearsymError

    if args.initial_from_prior and args.runs == 1:
        raise GearsymError(
            "estimate", "--initial-from-prior", "with --filter euio needs --runs N (N > 1)"
        )
    initial = _initial_values(args.initial)
    if args.initial_from_prior and initial:
        raise GearsymError(
            "estimate", "--initial-from-prior", "draws the initial estimate: drop --initial"
        )
    noise = 0.01
    if args.noise is not None:
        try:
            noise = number(float, above=0)(args.noise)
        except argparse.ArgumentTypeError as err:
            raise GearsymError("estimate", "--noise", str(err)) from None
    if args.runs > 1:
        return _cmd_euio_monte_carlo(args, d, scenario, initial, noise)

    def work(folder: Any) -> Any:
        from gearsym.cmd_dynamics import simulate_with_progress
        from gearsym.validation.studies.estimation.plots import plot_euio
        from gearsym.validation.studies.estimation.report import write_euio_csv
        from gearsym.validation.studies.euio_evaluation import euio_filter_run, prepare_euio

        result = simulate_with_progress(d, scenario)
        _say("running the extended UIO")
        setup = prepare_euio(
            d,
            result,
            sample_time=args.sample_time,
            relative_noise=noise,
            initial=initial,
            modes=args.modes,
        )
        run = euio_filter_run(setup, args.seed).run  # run_euio's loop (tested to the bit)
        if folder is not None:
            write_euio_csv(run, folder / "euio.csv")
            (folder / "euio.json").write_text(json.dumps(run.to_dict(), indent=2) + "\n")
            if not args.no_plots:
                plot_euio(run, folder / "euio.png")
        return run

    from gearsym.validation.studies.estimation.report import format_euio_text

    return _run_and_report(args, work, format_euio_text)


def _cmd_euio_monte_carlo(
    args: argparse.Namespace, d: Any, scenario: Any, initial: dict[str, float], noise: float
) -> int:
    """``--filter euio --runs N``: the extended UIO over N noise seeds with its matched bound
    (the road load unknown in every sample interval)."""

    def work(folder: Any) -> Any:
        from gearsym.cmd_dynamics import ProgressBar, simulate_with_progress
        from gearsym.validation.studies.estimation.plots import plot_euio
        from gearsym.validation.studies.estimation.report import write_euio_csv
        from gearsym.validation.studies.euio_evaluation import (
            plot_euio_efficiency,
            prepare_euio,
            run_euio_monte_carlo,
        )

        result = simulate_with_progress(d, scenario)
        setup = prepare_euio(
            d,
            result,
            sample_time=args.sample_time,
            relative_noise=noise,
            initial=initial,
            modes=args.modes,
        )
        bar = ProgressBar(f"EUIO, {args.runs} runs")
        try:
            mc = run_euio_monte_carlo(
                setup, args.runs, seed=args.seed, progress=bar, prior_draw=args.initial_from_prior
            )
        finally:
            bar.done()
        if folder is not None:
            write_euio_csv(mc.first, folder / "euio.csv")
            (folder / "euio.json").write_text(json.dumps(mc.to_dict(), indent=2) + "\n")
            if not args.no_plots:
                plot_euio(mc.first, folder / "euio.png")
                plot_euio_efficiency(mc, folder / "euio_efficiency.png")
        return mc

    from gearsym.validation.studies.euio_evaluation import format_euio_monte_carlo_text

    def text(mc: Any) -> str:
        return f"  assumes scenario: {scenario.name} ({args.scenario or 'built-in'})\n" + (
            format_euio_monte_carlo_text(mc)
        )

    return _run_and_report(args, work, text)


def _initial_values(items: list[str] | None) -> dict[str, float]:
    from gearsym.symbolic.errors import GearsymError

    values = {}
    for item in items or []:
        name, sep, text = item.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not sep or not name.strip() or value != value or abs(value) == float("inf"):
            raise GearsymError("estimate", "--initial", f"expected NAME=NUMBER, got {item!r}")
        values[name.strip()] = value
    return values


def _dropout_window(text: str | None, shift: str) -> tuple[float, float] | str | None:
    """``--dropout``: (T0, T1) in s, or the name of a phase of the shift (``speed_phase``),
    checked before the simulation; a phase is resolved to its detected window afterwards."""
    from gearsym.symbolic.errors import GearsymError

    if text is None:
        return None
    source, target = shift.split("-")
    phases = [f"gear_{source}", "torque_phase", "speed_phase", f"gear_{target}"]
    if text.strip() in phases:
        return text.strip().replace("_", " ")
    parts = text.split(",")
    try:
        t0, t1 = (float(v) for v in parts)
    except ValueError:
        t0 = t1 = float("nan")
    if not (t0 < t1):  # also false for NaN
        raise GearsymError(
            "estimate",
            "--dropout",
            f"expected T0,T1 with T0 < T1 or a phase ({', '.join(phases)}), got {text!r}",
        )
    return (t0, t1)


#: ``--drive upshifts``: the shipped scenarios of the drive 1->2->3->4.
DRIVE_UPSHIFTS = ("scenario_1_2.toml", "scenario_2_3.toml", "scenario_3_4.toml")


def _cmd_drive(args: argparse.Namespace, d: Any) -> int:
    """``--drive``: the EKF through consecutive shifts, m_veh and ζ carried across them."""
    from pathlib import Path

    from gearsym.symbolic.errors import GearsymError
    from gearsym.validation.sim.scenario import default_scenario_path, load_scenario

    for option, given in (
        ("--scenario", args.scenario is not None),
        ("--runs", args.runs != 1),
        ("--dropout", args.dropout is not None),
        ("--params", args.params is not None),
        ("--noise", args.noise is not None),
        ("--initial-from-prior", args.initial_from_prior),
        ("--out", args.out is not None),
    ):
        if given:
            raise GearsymError("estimate", option, "is not available with --drive")
    if args.drive.strip() == "upshifts":
        folder = Path(default_scenario_path()).parent
        files: list[Any] = [folder / name for name in DRIVE_UPSHIFTS]
    else:
        files = [f.strip() for f in args.drive.split(",") if f.strip()]
        if len(files) < 2:
            raise GearsymError(
                "estimate", "--drive", "give 'upshifts' or at least two scenario files"
            )
    scenarios = [load_scenario(d, f) for f in files]
    initial = _initial_values(args.initial)
    wrong = [name for name in initial if name not in ("m_veh", "zeta")]
    if wrong:
        raise GearsymError(
            "estimate", "--initial", f"with --drive only m_veh and zeta, got {', '.join(wrong)}"
        )

    from gearsym.cmd_dynamics import simulate_with_progress
    from gearsym.validation.studies.estimation.loop import run_ekf_drive
    from gearsym.validation.studies.estimation.report import format_ekf_text

    results = [simulate_with_progress(d, sc) for sc in scenarios]
    _say("running the EKF through the shifts, m_veh and zeta carried")
    runs = run_ekf_drive(
        d,
        results,
        seed=args.seed,
        sample_time=args.sample_time,
        initial=initial,
        modes=args.modes,
    )
    if args.json:
        data = {"filter": "ekf", "drive": [r.to_dict() for r in runs]}
        json.dump(data, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    print(
        "  assumes a drive of consecutive shifts "
        + " -> ".join(sc.name for sc in scenarios)
        + ": each shift simulated on its own (the reference does not chain shifts); the "
        "filter carries m_veh and zeta, estimate and covariance, from one shift's end to "
        "the next one's start; every other state starts as in a single shift"
    )
    for sc, run in zip(scenarios, runs, strict=True):
        print(f"  shift {sc.shift.name} ({sc.name}):")
        print(format_ekf_text(run))
    return 0


def _ekf_noise_and_parameters(args: argparse.Namespace) -> tuple[Any, list[str] | None]:
    """``--noise`` (one relative error or one per output, default 0.01) and ``--params``."""
    from gearsym.symbolic.errors import GearsymError

    noise: Any = 0.01
    if args.noise is not None:
        try:
            noise = [number(float, above=0)(v) for v in args.noise.split(",")]
        except argparse.ArgumentTypeError as err:
            raise GearsymError("estimate", "--noise", str(err)) from None
        if len(noise) not in (1, 3):
            raise GearsymError("estimate", "--noise", "give one value or one per output (3)")
    parameters = None
    if args.params is not None:
        parameters = [p.strip() for p in args.params.split(",") if p.strip()]
    return noise, parameters


def _cmd_ekf(args: argparse.Namespace, d: Any, scenario: Any) -> int:
    """``--filter ekf``: the EKF on the scenario's reference shift."""
    from gearsym.symbolic.errors import GearsymError
    from gearsym.symbolic.estimators.ekf import augmented_model

    noise, parameters = _ekf_noise_and_parameters(args)
    initial = _initial_values(args.initial)
    if args.initial_from_prior and initial:
        raise GearsymError(
            "estimate", "--initial-from-prior", "draws the initial estimate: drop --initial"
        )
    dropout_outputs = None
    if args.dropout_outputs is not None:
        if args.dropout is None:
            raise GearsymError("estimate", "--dropout-outputs", "needs --dropout")
        dropout_outputs = [o.strip() for o in args.dropout_outputs.split(",") if o.strip()]
    dropout = _dropout_window(args.dropout, scenario.shift.name)
    aug = augmented_model(d, scenario.shift.name, parameters)  # bad names fail before the run
    outputs = [name.removeprefix("y_") for name in aug.output_names]
    wrong = [o for o in dropout_outputs or [] if o not in outputs]
    if wrong or dropout_outputs == []:
        raise GearsymError(
            "estimate",
            "--dropout-outputs",
            f"expected outputs of the filter ({', '.join(outputs)}), got {args.dropout_outputs!r}",
        )
    wrong = [name for name in initial if name not in aug.state_names]
    if wrong:
        raise GearsymError(
            "estimate",
            "--initial",
            f"{', '.join(wrong)} is not a state of the filter ({', '.join(aug.state_names)})",
        )

    assumes: list[str] = []

    def work(folder: Any) -> Any:
        from gearsym.cmd_dynamics import ProgressBar, simulate_with_progress
        from gearsym.validation.studies.estimation.montecarlo import run_ekf_monte_carlo
        from gearsym.validation.studies.estimation.plots import plot_efficiency, plot_ekf
        from gearsym.validation.studies.estimation.report import write_ekf_csv
        from gearsym.validation.studies.estimation.setup import prepare_ekf

        result = simulate_with_progress(d, scenario)
        window: tuple[float, float] | None
        if isinstance(dropout, str):  # a phase: its window as the simulation detected it
            (phase,) = [p for p in result.phases if p.name == dropout]
            window = (float(phase.t_start), float(phase.t_end))
        else:
            window = dropout
        setup = prepare_ekf(
            d,
            result,
            sample_time=args.sample_time,
            relative_noise=noise,
            initial=initial,
            aug=aug,
            modes=args.modes,
        )
        bar = ProgressBar(f"EKF, {args.runs} run{'s' if args.runs > 1 else ''}")
        try:
            mc = run_ekf_monte_carlo(
                setup,
                args.runs,
                seed=args.seed,
                progress=bar,
                prior_draw=args.initial_from_prior,
                dropout=window,
                dropout_outputs=dropout_outputs,
            )
        finally:
            bar.done()
        assumes.append(f"scenario: {scenario.name} ({args.scenario or 'built-in'})")
        if window is not None:
            assumes.append(
                f"sensor dropout: {', '.join(dropout_outputs or outputs)} missing (NaN) in "
                f"[{window[0]:.4g}, {window[1]:.4g}) s: those updates are skipped"
            )
        if folder is not None:
            write_ekf_csv(mc.first, folder / "ekf.csv")
            (folder / "ekf.json").write_text(json.dumps(mc.to_dict(), indent=2) + "\n")
            if not args.no_plots:
                plot_ekf(mc.first, folder / "ekf.png")
                plot_efficiency(mc, folder / "ekf_efficiency.png")
        return mc

    from gearsym.validation.studies.estimation.report import (
        format_ekf_text,
        format_monte_carlo_text,
    )

    def text(mc: Any) -> str:
        body = format_monte_carlo_text(mc)
        body = body if len(mc.runs) > 1 else format_ekf_text(mc.first) + "\n" + body
        return "\n".join(f"  assumes {line}" for line in assumes) + "\n" + body

    return _run_and_report(args, work, text)


def _cmd_measured(args: argparse.Namespace, d: Any, scenario: Any) -> int:
    """``--measurement FILE``: the EKF on a bench recording mapped by the scenario's
    ``[measurement]`` table; the inputs of the simulation that gives the element modes and
    the phases are the recorded ones."""
    from gearsym.symbolic.errors import GearsymError

    if args.filter != "ekf":
        raise GearsymError("estimate", "--measurement", "runs the EKF: add --filter ekf")
    for option, given in (
        ("--drive", args.drive is not None),
        ("--runs", args.runs != 1),
        ("--initial-from-prior", args.initial_from_prior),
        ("--sample-time", args.sample_time is not None),
        ("--seed", args.seed != 0),
    ):
        if given:
            reason = {
                "--sample-time": "the recording's grid is the channel map's sample_time",
                "--seed": "a recording carries its own noise, none is drawn",
            }.get(option, "needs a truth and noise seeds; a recording has neither")
            raise GearsymError("estimate", option, f"is not available with --measurement: {reason}")
    if scenario.measurement is None:
        raise GearsymError(
            scenario.file, "measurement", "missing table [measurement] (the channel map)"
        )
    from gearsym.symbolic.estimators.ekf import augmented_model
    from gearsym.validation.sim.measurement import read_measurement

    cmap = scenario.measurement
    if cmap.sample_time > scenario.t_end / 4:
        raise GearsymError(
            scenario.file,
            "measurement.sample_time",
            f"must be at most t_end / 4 = {scenario.t_end / 4:g} s, got {cmap.sample_time:g}",
        )
    noise, parameters = _ekf_noise_and_parameters(args)
    initial = _initial_values(args.initial)
    aug = augmented_model(d, scenario.shift.name, parameters)
    outputs = [name.removeprefix("y_") for name in aug.output_names]
    missing = [o for o in outputs if cmap.channel(o) is None]
    if missing:
        raise GearsymError(
            scenario.file,
            f"measurement.channel.{missing[0]}",
            f"missing: the filter measures {', '.join(outputs)}",
        )
    measurement = read_measurement(args.measurement, cmap, scenario.t_end)
    dropout = _dropout_window(args.dropout, scenario.shift.name)
    dropout_outputs = None
    if args.dropout_outputs is not None:
        if args.dropout is None:
            raise GearsymError("estimate", "--dropout-outputs", "needs --dropout")
        dropout_outputs = [o.strip() for o in args.dropout_outputs.split(",") if o.strip()]
    assumes: list[str] = []

    def work(folder: Any) -> Any:
        from gearsym.cmd_dynamics import simulate_with_progress
        from gearsym.validation.sim.measurement import RESAMPLE_TEXT
        from gearsym.validation.sim.scenario import input_sources
        from gearsym.validation.sim.scenario import with_measured_inputs as driven
        from gearsym.validation.studies.estimation.loop import filter_run
        from gearsym.validation.studies.estimation.plots import plot_ekf
        from gearsym.validation.studies.estimation.report import measured_ekf_dict, write_ekf_csv
        from gearsym.validation.studies.estimation.setup import prepare_ekf

        measured_scenario = driven(scenario, measurement)
        result = simulate_with_progress(d, measured_scenario)
        window: tuple[float, float] | None
        if isinstance(dropout, str):
            (phase,) = [p for p in result.phases if p.name == dropout]
            window = (float(phase.t_start), float(phase.t_end))
        else:
            window = dropout
        setup = prepare_ekf(
            d,
            result,
            sample_time=cmap.sample_time,
            relative_noise=noise,
            initial=initial,
            aug=aug,
            measured={o: measurement.values[o] for o in outputs},
            modes=args.modes or "filter",
        )
        _say("running the EKF on the recording")
        run = filter_run(setup, dropout=window, dropout_outputs=dropout_outputs)
        sources = input_sources(scenario, measurement)
        assumes.extend(
            [
                f"recording: {measurement.file} ({measurement.format}, {len(measurement.t)} "
                f"samples every {cmap.sample_time * 1e3:g} ms; {RESAMPLE_TEXT})",
                "inputs: "
                + ", ".join(f"{name} from the {where}" for name, where in sources.items()),
                (
                    "element modes: decided by the filter from its estimate and F_N"
                    if (args.modes or "filter") == "filter"
                    else "element modes: from the reference simulation driven by those inputs"
                )
                + "; phases: from the reference simulation driven by those inputs (scenario "
                f"{scenario.name}, {args.scenario or 'built-in'})",
            ]
        )
        data = {
            **measured_ekf_dict(run),
            "measurement": measurement.to_dict(),
            "input_sources": sources,
        }
        if folder is not None:
            write_ekf_csv(run, folder / "ekf.csv")
            (folder / "ekf.json").write_text(json.dumps(data, indent=2) + "\n")
            if not args.no_plots:
                plot_ekf(run, folder / "ekf.png")
        return _Report(data, run)

    from gearsym.validation.studies.estimation.report import format_measured_ekf_text

    def text(report: Any) -> str:
        body = format_measured_ekf_text(report.run)
        return "\n".join(f"  assumes {line}" for line in assumes) + "\n" + body

    return _run_and_report(args, work, text)


class _Report:
    """A run with its JSON (``to_dict``), as :func:`_run_and_report` expects."""

    def __init__(self, data: dict[str, Any], run: Any) -> None:
        self.data, self.run = data, run

    def to_dict(self) -> dict[str, Any]:
        return self.data


def _run_and_report(
    args: argparse.Namespace, work: Callable[[Any], Any], text: Callable[[Any], str]
) -> int:
    """Run ``work`` (given the staging folder with ``--out``, else ``None``), write through
    the one output writer, print the run as JSON or as ``text`` with the files written."""
    paths: list[Any] = []
    if args.out is None:
        run = work(None)
    else:
        from gearsym.symbolic.io.output_dir import OutputDir

        with OutputDir(args.out, "estimate", before_commit=check) as out:
            run = work(out.path)
            paths = out.commit()
    if args.json:
        json.dump({**run.to_dict(), "files": [str(p) for p in paths]}, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    print(text(run))
    if paths:
        print(f"  wrote {len(paths)} files to {args.out}: {', '.join(p.name for p in paths)}")
    return 0


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``estimate``."""
    p = add_command(
        subparsers,
        "estimate",
        cmd_estimate,
        "Run an estimator of thesis chapter 4 on the reference shift: the unknown input "
        "observer (4.4, existence per phase, errors against the reference) or the extended "
        "Kalman filter (4.3) of m_veh, mu and the grade with its sigma, NEES and NIS.",
        common,
    )
    p.add_argument("--scenario", help="scenario TOML (default: the built-in 2-3 power-on upshift)")
    p.add_argument(
        "--measurement",
        metavar="FILE",
        help="ekf: run on a bench recording (MDF4 .mf4 or CSV) mapped by the scenario's "
        "[measurement] table: measured speeds and inputs instead of the synthetic ones",
    )
    p.add_argument("--filter", choices=FILTERS, default="uio", help="the estimator (default uio)")
    p.add_argument(
        "--params",
        help="ekf: parameters appended as random-walk states, comma-separated (default "
        "m_veh and mu of both swapping elements and zeta, thesis 4.1)",
    )
    p.add_argument(
        "--initial",
        nargs="+",
        metavar="NAME=VALUE",
        help="ekf, euio: initial estimate of a filter state (default: m_veh 30 %% below the "
        "description's value, mu nominal, zeta 0, phi 0, speeds from the first measurement)",
    )
    p.add_argument(
        "--initial-from-prior",
        action="store_true",
        help="ekf, euio (with --runs): draw each run's initial estimate of phi and the "
        "parameters from the "
        "filter's prior around the truth (the premise of the posterior Cramer-Rao bound) "
        "instead of the fixed default",
    )
    p.add_argument(
        "--unknown",
        default="T_res_star",
        help="unknown inputs of the linear form (5.3), comma-separated (default T_res_star; "
        "e.g. T_K38,T_B05,T_res_star)",
    )
    p.add_argument(
        "--sample-time",
        type=number(float, above=0),
        default=None,
        help="TCU sample time in s (default 0.01, as the thesis; with --measurement the "
        "channel map's sample_time)",
    )
    p.add_argument(
        "--noise",
        help="relative speed-sensor error r (3.26): one value for every output or one per "
        "output, comma-separated (default: uio no noise, ekf 0.01)",
    )
    p.add_argument(
        "--seed",
        type=number(int, minimum=0),
        default=0,
        help="noise seed (with --runs N: the seeds K, K+1, ..., K+N-1)",
    )
    p.add_argument(
        "--runs",
        type=number(int, minimum=1),
        default=1,
        help="ekf, euio: Monte-Carlo runs over noise seeds, the reference simulated once "
        "(default 1); per parameter and phase: mean error, RMSE, sigma, the posterior "
        "Cramer-Rao bound (euio: with the road load unknown) and the efficiency RMSE / bound, "
        "NEES mean against its chi2 band",
    )
    p.add_argument(
        "--out",
        help="folder for uio.csv/.json/.png or ekf.csv/.json/.png and ekf_efficiency.png "
        "(written atomically)",
    )
    p.add_argument(
        "--dropout",
        metavar="T0,T1|PHASE",
        help="ekf: sensor dropout, the measurements in [T0, T1) s (or in a detected phase: "
        "gear_2, torque_phase, speed_phase, gear_3) are NaN and their updates skipped",
    )
    p.add_argument(
        "--dropout-outputs",
        metavar="NAMES",
        help="ekf: only these speeds drop out, comma-separated (default: all of them)",
    )
    p.add_argument(
        "--drive",
        metavar="upshifts|FILE,FILE,...",
        help="ekf: run the filter through consecutive shifts (each its own scenario), "
        "carrying m_veh and zeta with their covariance; 'upshifts' is the shipped 1-2, 2-3, "
        "3-4",
    )
    p.add_argument(
        "--modes",
        choices=("filter", "reference"),
        default=None,
        help="ekf, euio: where the element modes (stick, slide, open) come from: 'filter' "
        "(default) "
        "decides them itself from its estimate and F_N, as a TCU must (lock-up when the "
        "estimated slip reaches zero and the sticking torque is within 2 N r_m mu_hat F_N, "
        "break-away when it exceeds it, open while F_N = 0); 'reference' takes the reference "
        "simulation's (the truth), for comparison; the output reports the detected switch "
        "times against the reference's",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG")
    p.add_argument("--json", action="store_true", help="machine-readable output")
