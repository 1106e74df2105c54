"""``gearsym drive``: a whole driving cycle through every shift in one continuous simulation
(:mod:`gearsym.validation.sim.drive`)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from gearsym.commands import add_command, emit_json, load
from gearsym.interrupts import check
from gearsym.options import number

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_drive", "register"]

#: ``--fleet`` without a file: the shipped default fleet.
DEFAULT_FLEET_ARGUMENT = "<default fleet>"


def cmd_drive(args: argparse.Namespace) -> int:
    """Drive the cycle with the description's vehicle; print the summary (or ``--json``) and
    write drive.json, drive.md, drive.csv, shifts.csv and drive.png to ``--out``."""
    import json
    import sys

    from gearsym.cmd_dynamics import ProgressBar
    from gearsym.symbolic.errors import GearsymError
    from gearsym.symbolic.io.output_dir import OutputDir
    from gearsym.validation.sim.cycles import load_cycle, load_grade
    from gearsym.validation.sim.drive import MIN_DWELL, DriveSimulator, DriveTruth
    from gearsym.validation.sim.drive_schedule import missed_shifts

    d = load(args.config)
    cycle = load_cycle(args.cycle)
    if args.duration is not None:
        if not 0 < args.duration:
            raise GearsymError("--duration", "", f"must be positive, got {args.duration:g}")
        if args.duration < cycle.duration_s:
            cycle = cycle.window(args.duration)
    grade = load_grade(args.grade) if args.grade is not None else None
    truth = None
    for option, value in (("--runs", args.runs), ("--workers", args.workers)):
        if value < 1:
            raise GearsymError(option, "", f"must be at least 1, got {value}")
    if (args.runs > 1 or args.scheduler is not None) and args.fleet is None:
        raise GearsymError("--runs", "", "more than one drive, or --scheduler, needs --fleet")
    if args.engine_gain_state and (args.runs > 1 or args.estimate != "ekf"):
        raise GearsymError("--engine-gain-state", "", "one drive with --estimate ekf only")
    if args.reference and args.runs > 1:
        raise GearsymError("--reference", "", "drives one vehicle; a fleet runs the fast drive")
    if args.scheduler is not None:
        from gearsym.validation.studies.dask_runner import check_scheduler

        check_scheduler(args.scheduler, ("drive", "--scheduler"))
    if args.fleet is not None:
        from gearsym.validation.sim.fleet import load_fleet

        fleet = load_fleet(d, None if args.fleet == DEFAULT_FLEET_ARGUMENT else args.fleet)
        fleet = fleet.without_speed_sensors("drive")
        if args.runs > 1:
            return _drive_fleet(args, d, cycle, grade, fleet)
        truth = DriveTruth.from_draw(d, fleet.draw(args.seed), constant_grade=grade is None)
    # built before any output: a description the drive cannot serve is refused in one line
    simulator = DriveSimulator(d, cycle, grade, truth=truth)
    with OutputDir(args.out, "drive", before_commit=check) as out:
        bar = ProgressBar("drive")
        shown = {"step": -1}
        total = cycle.duration_s

        def progress(t: float) -> None:
            # one line per 5 % of the cycle when stderr is not a terminal
            step = int(20 * t / total)
            if step != shown["step"]:
                shown["step"] = step
                bar(t / total, f"t = {t:.0f} of {total:.0f} s")

        try:
            simulator.progress = progress
            bar(0.0, "driving (each shift's models compiled when first needed)")
            result = simulator.run(reference=args.reference)
        finally:
            bar.done()
        estimates = None
        if args.estimate == "ekf" and not result.failure:
            from gearsym.validation.studies.estimation.drive_ekf import ekf_over_drive

            print("  … the EKF over the drive's TCU log", file=sys.stderr, flush=True)
            assert result.log is not None
            gain = truth.actuators.engine_gain if truth is not None else 1.0
            estimates = ekf_over_drive(
                d,
                result,
                seed=args.seed,
                engine_gain=args.engine_gain_state,
                engine_gain_truth=gain,
            )
        from gearsym.validation.sim.drive_report import (
            drive_markdown,
            format_drive_summary,
            plot_drive,
            write_drive,
        )

        data = {"gearbox": d.name, **result.to_dict()}
        data["missed_shifts"] = len(missed_shifts(result, d.drive.schedule, MIN_DWELL))
        data["calibration"] = d.drive.to_dict()
        data["vehicle"] = (
            {"fleet": args.fleet, "seed": args.seed, **truth.draw.to_dict()}
            if truth is not None and truth.draw is not None
            else "the calibration's own (no --fleet)"
        )
        if estimates is not None:
            from gearsym.validation.studies.estimation.drive_ekf_plot import plot_drive_estimates

            data["estimates"] = estimates.to_dict()
            data["estimator"] = estimates.summary()
            plot_drive_estimates(estimates, out.path / "estimates.png")
        (out.path / "drive.json").write_text(json.dumps(data, indent=2) + "\n")
        write_drive(result, out.path)
        command = _command(args)
        (out.path / "drive.md").write_text(drive_markdown(data, command))
        plot_drive(result, out.path / "drive.png")
        paths = out.commit()
    if args.json:
        emit_json(data)
    else:
        print(format_drive_summary(result))
        if estimates is not None:
            print("EKF carried over the drive (the TCU's view):")
            print("\n".join(estimates.lines()))
        print(f"  wrote {len(paths)} files to {args.out}")
    if result.failure:
        print(f"gearsym: drive failed: {result.failure}", file=sys.stderr)
        return 1
    return 0


def _command(args: argparse.Namespace) -> str:
    """The command line the written Markdown names (the shipped fleet as a bare --fleet)."""
    from gearsym.validation.sim.drive_report import drive_command

    fleet = None
    if args.fleet is not None:
        fleet = "" if args.fleet == DEFAULT_FLEET_ARGUMENT else args.fleet
    command = drive_command(args.cycle, args.duration, fleet, args.seed, args.runs)
    command += " --engine-gain-state" if args.engine_gain_state else ""
    return command + (" --reference" if args.reference else "")


def _drive_fleet(args: argparse.Namespace, d: Any, cycle: Any, grade: Any, fleet: Any) -> int:
    """``--runs N`` vehicles of the fleet (seeds --seed ... --seed + N - 1): fleet.json,
    fleet.md and fleet.png (the mass error over time, percentiles over the fleet)."""
    import json

    from gearsym.cmd_dynamics import ProgressBar
    from gearsym.symbolic.io.output_dir import OutputDir
    from gearsym.validation.studies.drive_fleet import (
        drive_fleet_markdown,
        plot_drive_fleet,
        run_drive_fleet,
    )

    seeds = list(range(args.seed, args.seed + args.runs))
    with OutputDir(args.out, "drive", before_commit=check) as out:
        bar = ProgressBar("drive fleet")
        try:
            bar(0.0, f"0 of {len(seeds)} vehicles")
            result = run_drive_fleet(
                d,
                cycle,
                grade,
                fleet,
                seeds,
                scheduler=args.scheduler,
                workers=args.workers,
                progress=lambda done, total: bar(done / total, f"{done} of {total} vehicles"),
            )
        finally:
            bar.done()
        data = {"gearbox": d.name, **result.to_dict()}
        command = _command(args)
        (out.path / "fleet.json").write_text(json.dumps(data, indent=2) + "\n")
        (out.path / "fleet.md").write_text(drive_fleet_markdown(data, command))
        plot_drive_fleet(result, out.path / "fleet.png")
        paths = out.commit()
    if args.json:
        emit_json(data)
    else:
        print(drive_fleet_markdown(data, command))
        print(f"  wrote {len(paths)} files to {args.out}")
    return 1 if data["failed"] else 0


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``drive``."""
    p = add_command(
        subparsers,
        "drive",
        cmd_drive,
        "Drive a standard cycle (or a CSV of t, v) through every shift in one simulation.",
        common,
    )
    p.add_argument(
        "--cycle",
        default="wltc3b",
        help="wltc3b (default), udds, us06, hwfet, or a CSV file with columns t (s), v (km/h)",
    )
    p.add_argument("--grade", help="CSV file with columns s (m), grade (%%, uphill positive)")
    p.add_argument("--duration", type=float, help="drive only the cycle's first DURATION seconds")
    p.add_argument(
        "--out",
        default="out/drive",
        help="folder for drive.json, drive.csv, shifts.csv, drive.png (replaced atomically)",
    )
    p.add_argument(
        "--fleet",
        nargs="?",
        const=DEFAULT_FLEET_ARGUMENT,
        metavar="FLEET.toml",
        help="drive a vehicle of a fleet (default file: the shipped fleet) drawn by --seed; "
        "the TCU keeps the description's calibration",
    )
    p.add_argument(
        "--seed",
        type=number(int, minimum=0),
        default=0,
        help="the fleet vehicle and the sensors' noise (default 0)",
    )
    p.add_argument(
        "--runs",
        type=int,
        default=1,
        help="with --fleet: drive N vehicles (seeds --seed ... --seed + N - 1) and report the "
        "mass error's percentiles over the fleet",
    )
    p.add_argument(
        "--scheduler",
        help="with --runs: run the vehicles on Dask, local (a LocalCluster) or tcp://HOST:PORT",
    )
    p.add_argument("--workers", type=int, default=2, help="LocalCluster workers (default 2)")
    p.add_argument(
        "--estimate",
        choices=("ekf", "none"),
        default="ekf",
        help="carry the EKF over the drive from the TCU's log (default ekf)",
    )
    p.add_argument(
        "--engine-gain-state",
        action="store_true",
        help="one drive: the EKF estimates the engine's torque gain too (tried and not "
        "adopted: docs/drive.md)",
    )
    p.add_argument(
        "--reference",
        action="store_true",
        help="integrate the gears by the Python reference (SciPy RK45, a Python call per "
        "right-hand side), which the compiled closed loop is checked against; one vehicle",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
