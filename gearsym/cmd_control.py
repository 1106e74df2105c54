"""``gearsym control``: the shift controller closed around four strategies (fixed calibration,
rule-based adaptation, the estimator's values, the truth) over a fleet of vehicles shifting
the same shift again and again (:mod:`gearsym.validation.studies.control`)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from gearsym.commands import add_command, emit_json, load
from gearsym.interrupts import check
from gearsym.options import number

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_control", "register"]

#: ``--fleet`` without a file: the shipped default fleet.
DEFAULT_FLEET_ARGUMENT = "<default fleet>"


def cmd_control(args: argparse.Namespace) -> int:
    """Run the study; print the comparison (or ``--json``) and write control.json,
    control.md, runs.json, sequence.png and shift.png to ``--out``."""
    import json
    import sys

    from gearsym.cmd_dynamics import ProgressBar
    from gearsym.symbolic.errors import GearsymError
    from gearsym.symbolic.io.output_dir import OutputDir
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.studies.control.fleet_study import run_control_fleet
    from gearsym.validation.studies.control.report import (
        control_command,
        control_markdown,
        plot_control_sequence,
        plot_control_shift,
    )
    from gearsym.validation.studies.control.strategies import STRATEGIES
    from gearsym.validation.studies.control.study import OperatingPoint

    d = load(args.config)
    strategies = tuple(s.strip() for s in args.strategies.split(",") if s.strip())
    unknown = [s for s in strategies if s not in STRATEGIES]
    if unknown or not strategies:
        raise GearsymError(
            "--strategies", "", f"expected some of {', '.join(STRATEGIES)}, got {args.strategies!r}"
        )
    for option, value in (
        ("--shifts", args.shifts),
        ("--runs", args.runs),
        ("--workers", args.workers),
    ):
        if value < 1:
            raise GearsymError(option, "", f"must be at least 1, got {value}")
    if args.runs > 1 and args.fleet is None:
        raise GearsymError("--runs", "", "more than one vehicle needs --fleet")
    if args.scheduler is not None:
        from gearsym.validation.studies.dask_runner import check_scheduler

        check_scheduler(args.scheduler, ("control", "--scheduler"))
    scenario = load_scenario(d, args.scenario)
    point = OperatingPoint.from_scenario(scenario)
    fleet = _fleet(d, args.fleet)
    for item in args.fix or ():
        if args.fleet is None:
            raise GearsymError("--fix", "", "fixes an entry of a fleet: needs --fleet")
        name, sep, raw = item.partition("=")
        try:
            value = float(raw)
        except ValueError:
            value = float("nan")
        if not sep or not value == value:
            raise GearsymError("--fix", "", f"expected NAME=NUMBER, got {item!r}")
        fleet = fleet.fixed(name.strip(), value, "--fix")  # type: ignore[attr-defined]
    seeds = list(range(args.seed, args.seed + args.runs))
    command = control_command(
        args.fix or (),
        args.scenario,
        None
        if args.fleet is None
        else ("" if args.fleet == DEFAULT_FLEET_ARGUMENT else args.fleet),
        ",".join(strategies),
        args.shifts,
        args.runs,
        args.seed,
    )
    with OutputDir(args.out, "control", before_commit=check) as out:
        bar = ProgressBar("control")
        try:
            bar(0.0, f"0 of {len(seeds)} vehicles ({args.shifts} shifts x {len(strategies)})")
            result = run_control_fleet(
                d,
                scenario.shift.name,
                point,
                fleet,
                seeds,
                strategies,
                args.shifts,
                scheduler=args.scheduler,
                workers=args.workers,
                progress=lambda done, total: bar(done / total, f"{done} of {total} vehicles"),
            )
        finally:
            bar.done()
        for failed in result.failed:
            print(
                f"warning: vehicle {failed['seed']} failed and is left out: {failed['reason']}",
                file=sys.stderr,
            )
        data = {"gearbox": d.name, "command": command, **result.to_dict()}
        data["calibration"] = d.control.to_dict()
        (out.path / "control.json").write_text(json.dumps(data, indent=2) + "\n")
        # every vehicle's draw and every shift's metrics and knowledge (large: not for docs)
        (out.path / "runs.json").write_text(json.dumps(result.runs) + "\n")
        (out.path / "control.md").write_text(control_markdown(data, command))
        plot_control_sequence(data, out.path / "sequence.png")
        if result.traces:
            title = (
                f"{data['shift']}, vehicle {seeds[0]}, shift 2 of the sequence "
                "(every strategy has learned once)"
            )
            plot_control_shift(result.traces, title, out.path / "shift.png")
        paths = out.commit()
    if args.json:
        emit_json(data)
    else:
        print(control_markdown(data, command))
        print(f"  wrote {len(paths)} files to {args.out}")
    return 0


class _Calibration:
    """A fleet of one: the calibration itself as the truth (no ``--fleet``)."""

    name = "the calibration itself (no --fleet)"

    def draw(self, seed: int) -> object:
        from gearsym.validation.sim.fleet import FleetDraw

        return FleetDraw(seed, ())


def _fleet(d: object, argument: str | None) -> object:
    if argument is None:
        return _Calibration()
    from gearsym.validation.sim.fleet import load_fleet

    fleet = load_fleet(d, None if argument == DEFAULT_FLEET_ARGUMENT else argument)  # type: ignore[arg-type]
    return fleet.without_speed_sensors("control")


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``control``."""
    p = add_command(
        subparsers,
        "control",
        cmd_control,
        "Close the shift controller around fixed, rule-based, estimator-based and oracle "
        "knowledge over a fleet and a sequence of shifts.",
        common,
    )
    p.add_argument(
        "--scenario",
        help="the shift and its operating point (vehicle speed, engine and e-machine torque at "
        "t = 0; default: the built-in 2-3 power-on upshift)",
    )
    p.add_argument(
        "--fleet",
        nargs="?",
        const=DEFAULT_FLEET_ARGUMENT,
        metavar="FLEET.toml",
        help="vehicles drawn from a fleet (default file: the shipped fleet); without it the "
        "vehicle is the calibration itself",
    )
    p.add_argument(
        "--fix",
        action="append",
        metavar="NAME=VALUE",
        help="fix one fleet entry for every vehicle (e.g. fill_time_error=0 to take the fill "
        "out of the comparison, mu_scale=1.25 for cold oil); repeatable; the other entries "
        "draw as before",
    )
    p.add_argument(
        "--strategies",
        default="fixed,rule,estimator,oracle",
        help="comma-separated: fixed, rule, estimator, oracle (default all four)",
    )
    p.add_argument(
        "--shifts", type=int, default=20, help="consecutive shifts per vehicle (default 20)"
    )
    p.add_argument("--runs", type=int, default=1, help="vehicles: seeds --seed ... --seed + N - 1")
    p.add_argument(
        "--seed",
        type=number(int, minimum=0),
        default=0,
        help="the first vehicle and the sensors' noise (default 0)",
    )
    p.add_argument(
        "--scheduler",
        help="run the vehicles on Dask, local (a LocalCluster) or tcp://HOST:PORT",
    )
    p.add_argument("--workers", type=int, default=2, help="LocalCluster workers (default 2)")
    p.add_argument(
        "--out",
        default="out/control",
        help="folder for control.json, control.md, sequence.png, shift.png (replaced atomically)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
