"""``gearsym estimate``: estimators of thesis chapter 4 run on the reference shift.

The unknown input observer (4.4): existence per phase, and its estimates of the states and the
unknown inputs against the reference simulation; the extended Kalman filter (4.3) on the
parameter-augmented shift model (4.1): m_veh, μ of the swapping elements and ζ with σ, NEES and
NIS against the reference. This module parses the options into an
:class:`~gearsym.validation.studies.estimation.workflow.EstimateRequest` (what the filter knows
apart from the world it is judged in) and prints the report; the workflow is
:func:`gearsym.validation.studies.estimation.workflow.estimate`.
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
from gearsym.symbolic.errors import GearsymError

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_estimate", "register"]

FILTERS = ("uio", "ekf", "euio")  # the workflow's (checked there too)

#: ``--fleet`` without a file: the shipped default fleet.
DEFAULT_FLEET_ARGUMENT = "default"


class _Reporter:
    """The workflow's steps and progress on stderr (interruptible)."""

    def say(self, message: str) -> None:
        check()
        print(f"  … {message}", file=sys.stderr, flush=True)

    def bar(self, label: str) -> tuple[Callable[[float, str], None], Callable[[], None]]:
        from gearsym.cmd_dynamics import ProgressBar

        bar = ProgressBar(label)
        return bar, bar.done


def cmd_estimate(args: argparse.Namespace) -> int:
    """Parse the options into a request, run it (:func:`estimate`), print or write."""
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.studies.estimation.workflow import (
        Calibration,
        EstimateRequest,
        Truth,
        drive_truths,
        estimate,
        measured_truth,
    )

    if args.input_hold != "sample" and args.fleet is None:
        raise GearsymError(
            "estimate",
            "--input-hold",
            "mean is for the EKF over a fleet (--fleet, also with --tune) only so far",
        )
    d = load(args.config)
    calibration = Calibration(
        description=d,
        sample_time=args.sample_time,
        relative_noise=_noise(args),
        parameters=_names(args.params),
        initial=_initial_values(args.initial),
        modes=args.modes,
        mu_model=args.mu_model,
        input_hold=args.input_hold,
    )
    scenario = load_scenario(d, args.scenario)
    source = args.scenario or "built-in"
    if args.measurement is not None:
        if args.filter != "ekf":  # before the file is read
            raise GearsymError("estimate", "--measurement", "runs the EKF: add --filter ekf")
        truths: tuple[Truth, ...] = (
            measured_truth(calibration, scenario, args.measurement, source),
        )
    elif args.drive is not None:
        if args.scenario is not None:
            raise GearsymError("estimate", "--scenario", "is not available with --drive")
        if args.out is not None:
            raise GearsymError("estimate", "--out", "is not available with --drive")
        truths = drive_truths(d, args.drive)
    else:
        truths = (Truth(scenario, source),)
    if args.tune_scenario and not args.tune:
        raise GearsymError("estimate", "--tune-scenario", "is for --fleet --tune only")
    tune_scenarios = tuple(load_scenario(d, path) for path in args.tune_scenario or ())
    axes = {
        "--tune-factors": args.tune_factors,
        "--tune-twist-factors": args.tune_twist_factors,
        "--tune-in-gear": args.tune_in_gear,
    }
    for option, text in axes.items():
        if text is not None and not args.tune:
            raise GearsymError("estimate", option, "is for --fleet --tune only")
    grid = {option: _tuning_factors(text, option) for option, text in axes.items()}
    if args.tune_criterion is not None and not args.tune:
        raise GearsymError("estimate", "--tune-criterion", "is for --fleet --tune only")
    fleet = None
    if args.fleet is not None:
        from gearsym.validation.sim.fleet import load_fleet

        fleet = load_fleet(d, None if args.fleet == DEFAULT_FLEET_ARGUMENT else args.fleet)
    request = EstimateRequest(
        filter=args.filter,
        calibration=calibration,
        truths=truths,
        runs=args.runs,
        seed=args.seed,
        initial_from_prior=args.initial_from_prior,
        dropout=_dropout_window(args.dropout, truths[0].scenario.shift.name),
        dropout_outputs=_names(args.dropout_outputs),
        unknown=_names(args.unknown) or (),
        drive=args.drive is not None,
        plots=not args.no_plots,
        fleet=fleet,
        tune=args.tune,
        tune_scenarios=tune_scenarios,
        tune_factors=grid["--tune-factors"],
        tune_twist_factors=grid["--tune-twist-factors"],
        tune_in_gear=grid["--tune-in-gear"],
        tune_criterion=(args.tune_criterion or "pooled").replace("-", "_"),
        scheduler=args.scheduler,
        workers=args.workers,
        command=" ".join(["gearsym", *sys.argv[1:]]) if sys.argv[1:] else "",
    )
    paths: list[Any] = []
    if args.out is None:
        report = estimate(request, reporter=_Reporter())
    else:
        from gearsym.symbolic.io.output_dir import OutputDir

        with OutputDir(args.out, "estimate", before_commit=check) as out:
            report = estimate(request, out.path, _Reporter())
            paths = out.commit()
    if args.json:
        data = report.to_dict()
        if not request.drive:
            data = {**data, "files": [str(p) for p in paths]}
        json.dump(data, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    print(report.text)
    if paths:
        print(f"  wrote {len(paths)} files to {args.out}: {', '.join(p.name for p in paths)}")
    return 0


def _names(text: str | None) -> tuple[str, ...] | None:
    """A comma-separated list of names (``None`` when the option is absent)."""
    if text is None:
        return None
    return tuple(name.strip() for name in text.split(",") if name.strip())


def _tuning_factors(text: str | None, option: str) -> tuple[float, ...] | None:
    """A tuning axis (``--tune-factors``, ``--tune-twist-factors``, ``--tune-in-gear``):
    distinct factors > 0; ``None`` when the option is absent."""
    if text is None:
        return None
    try:
        values = tuple(float(number(float, above=0)(v)) for v in text.split(","))
    except argparse.ArgumentTypeError as err:
        raise GearsymError("estimate", option, str(err)) from None
    if len(set(values)) != len(values):
        raise GearsymError("estimate", option, "a factor given twice")
    return values


def _noise(args: argparse.Namespace) -> tuple[float, ...] | None:
    """``--noise``: one relative error r (3.26) or one per output; the UIO may run
    noise-free (0), the filters need r > 0."""
    if args.noise is None:
        return None
    parse = number(float, minimum=0) if args.filter == "uio" else number(float, above=0)
    try:
        return tuple(float(parse(v)) for v in args.noise.split(","))
    except argparse.ArgumentTypeError as err:
        raise GearsymError("estimate", "--noise", str(err)) from None


def _initial_values(items: list[str] | None) -> dict[str, float]:
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
    if text is None:
        return None
    source, target = shift.split("-")
    # option spelling -> the detected phase's name (a gear's own name may hold underscores)
    names = {
        f"gear_{source}": f"gear {source}",
        "torque_phase": "torque phase",
        "speed_phase": "speed phase",
        f"gear_{target}": f"gear {target}",
    }
    phases = list(names)
    if text.strip() in names:
        return names[text.strip()]
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
        "m_veh and mu of both swapping elements and zeta, thesis 4.1); with --fleet also "
        "k_ss, input_torque_gain, inertia_factor, and valve_offset, valve_gain (consider "
        "states: in the covariance, never corrected)",
    )
    p.add_argument(
        "--initial",
        nargs="+",
        metavar="NAME=VALUE",
        help="ekf, euio: initial estimate of a filter state (default: the description's "
        "[estimator] prior, else its own values; speeds from the first measurement)",
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
    p.add_argument(
        "--fleet",
        nargs="?",
        const=DEFAULT_FLEET_ARGUMENT,
        metavar="FLEET.toml",
        help="ekf: judge the filter over a fleet of vehicles: each of --runs N runs draws its "
        "own vehicle (mass, grade, mu map, torque and pressure errors, tolerances) from the "
        "fleet file (default: the shipped gearsym/data/fleet_default.toml), the reference "
        "simulates it, the filter knows only the calibration (the description's [estimator] "
        "prior) and is told the commanded inputs; per parameter bias, RMSE, mean sigma, "
        "coverage of the 95 %% interval, the bound and NEES/NIS against their bands",
    )
    p.add_argument(
        "--tune",
        action="store_true",
        help="ekf, with --fleet: choose the model-error intensities on the --runs vehicles "
        "(seeds --seed ...): one factor on the calibration's values, NEES/dof and NIS/dof "
        "nearest 1; prints the values for the description's [estimator.model_error] table "
        "(tune and evaluate on different seeds)",
    )
    p.add_argument(
        "--tune-scenario",
        action="append",
        default=None,
        metavar="FILE",
        help="with --tune (repeatable): tune on this shift too, every tuning vehicle running "
        "each shift and NEES and NIS summed over all: one calibration's intensities for every "
        "shift it serves (--scenario, or the built-in 2-3, is the first)",
    )
    p.add_argument(
        "--tune-factors",
        default=None,
        metavar="C1,C2,...",
        help="with --tune: the factors c on the table's intensities of the speeds tried "
        "(default 0.5,1,2)",
    )
    p.add_argument(
        "--tune-twist-factors",
        default=None,
        metavar="C1,C2,...",
        help="with --tune: the factors c_phi on the table's intensity of the twist tried "
        "(default 0.01,0.0316,0.1,0.316,1,3.16)",
    )
    p.add_argument(
        "--tune-in-gear",
        default=None,
        metavar="G1,G2,...",
        help="with --tune: an axis of factors on the model-error table's in_gear factor (its "
        "intensities of the speeds and the twist over an interval in which no element slides, "
        "1 where the table has none): the gears and the shift phases then tuned apart; the "
        "chosen in_gear is printed with the intensities",
    )
    p.add_argument(
        "--tune-criterion",
        choices=("pooled", "per-shift"),
        default=None,
        help="with --tune: 'pooled' (default), NEES/dof and NIS/dof summed over every shift "
        "near 1; 'per-shift', each shift's own near 1 (the sum of the shifts' criteria), so "
        "that no shift's inconsistency hides behind another's",
    )
    p.add_argument(
        "--input-hold",
        choices=("sample", "mean"),
        default="sample",
        help="ekf with --fleet: the known inputs (T_In, F_N) over a prediction interval: "
        "'sample' (default) held at the interval's start, as the emitted C filter; 'mean' the "
        "mean of the interval's two samples (a TCU knows the ramps it commands)",
    )
    p.add_argument(
        "--mu-model",
        choices=("random_walk", "map_scale"),
        default=None,
        help="ekf: the filter's mu (default: the description's [estimator] mu_model, else "
        "random_walk): 'random_walk', mu itself a random-walk state (thesis 4.1); 'map_scale', "
        "mu = s mu_map(p, T_oil, |slip|) with the calibration's map read at the commanded "
        "pressure and the filter's own slip estimate, the scale s per element the state",
    )
    p.add_argument(
        "--scheduler",
        metavar="local|tcp://HOST:PORT",
        help="ekf, with --fleet (also --tune): run the vehicles on Dask, one task each, instead "
        "of one after the other: 'local' starts a LocalCluster on this machine (--workers "
        "processes), tcp://HOST:PORT uses a running dask scheduler and its workers; each "
        "worker builds the filter's model once; the same seeds, draws and numbers as without",
    )
    p.add_argument(
        "--workers",
        type=number(int, minimum=1, maximum=256),
        default=None,
        help="with --scheduler local: the LocalCluster's worker processes (default 2)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG")
    p.add_argument("--json", action="store_true", help="machine-readable output")
