"""``gearsym run``: the main job, everything the description supports in one command.

The gear table, the observability verdict of the default shift, the reference simulation, the
sensitivities and the Fisher information, each printed by the module of its command and
written into one output folder; what the description does not support is skipped with the
reason.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import TYPE_CHECKING, Any

from gearsym.cmd_gearbox import print_ratio_table, ratio_json
from gearsym.commands import add_command, load
from gearsym.interrupts import check
from gearsym.symbolic.errors import GearsymError

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_run", "register"]


def _run_scenario(d: Any, path: str | None) -> tuple[Any, str | None]:
    """The scenario ``gearsym run`` simulates, or ``None`` and why not. A scenario the user
    names must load (its errors are errors); the built-in one is tried on any gearbox."""
    from gearsym.validation.sim.scenario import load_scenario

    if path is not None:
        return load_scenario(d, path), None
    try:
        return load_scenario(d, None), None
    except GearsymError as err:
        return None, (
            f"the built-in 2-3 scenario does not fit this gearbox ({err.key}: {err.reason}); "
            "give one with --scenario FILE"
        )


def cmd_run(args: argparse.Namespace) -> int:
    """The main job: derive the model, print the gear table and the observability verdict,
    simulate the shift scenario, and its sensitivities and Fisher information; everything the
    description supports, and what was skipped, with the reason."""
    from gearsym.symbolic.dynamics import gearbox_dynamics
    from gearsym.symbolic.io.output_dir import OutputDir
    from gearsym.symbolic.ratios import ratio_table

    d = load(args.config)
    scenario, skipped = _run_scenario(d, args.scenario)
    from gearsym.validation.drawing.figures import Background

    with OutputDir(args.out, "run", before_commit=check) as out, Background() as figures:
        print(f"gearsym: {d.title}")
        start = time.perf_counter()
        dyn = gearbox_dynamics(d, symbolic_inertias=True)
        m = dyn.mass_matrix
        f = len(dyn.kinematics.coordinates)
        print(
            f"  derived kinematics and dynamics in {time.perf_counter() - start:.2f} s: "
            f"{len(d.body_names)} bodies, {len(d.planetary_sets)} sets, {f} DOF, "
            f"y = [{', '.join(str(s) for s in dyn.kinematics.coordinate_symbols)}], "
            f"M {m.rows}×{m.cols} with {sum(1 for e in m if e != 0)} nonzero entries, "
            f"B̃ {dyn.input_matrix.rows}×{dyn.input_matrix.cols}"
        )
        print()
        table = ratio_table(d)  # once: printed and written
        status = print_ratio_table(d, table)
        (out.path / "ratios.json").write_text(json.dumps(ratio_json(table), indent=2) + "\n")
        from gearsym.validation.drawing.render import write_pictures

        # stick diagram, lever analogy, speed plans, drivetrain: drawn beside the analyses
        figures.submit("drawings", write_pictures, d, out.path / "drawings")
        from gearsym.cmd_observability import print_observability_summary

        print()
        print_observability_summary(d)  # verdict of (4.12) for the 2-3 shift
        steps = {"ratios": "done", "observability": "done"}
        if scenario is not None:
            from gearsym.cmd_analysis import print_fim_summary
            from gearsym.cmd_dynamics import simulate_with_progress
            from gearsym.validation.sim.report import format_summary, plot_shift, write_results

            print()
            result = simulate_with_progress(d, scenario)
            write_results(d, result, out.path, plots=False)
            # Figures 3.1-3.3 draw in a child process while the analyses run (two cores)
            figures.submit("Figures 3.1-3.3", plot_shift, d, result, out.path, args.speed_unit)
            print(format_summary(result))
            print()
            print_fim_summary(d, result, folder=out.path, scenario=scenario, background=figures)
            steps |= {"simulation": "done", "sensitivity": "done", "fim": "done"}
        else:
            print()
            for step in ("simulation", "sensitivity", "fim"):
                steps[step] = f"skipped: {skipped}"
            print(f"simulation, sensitivities and FIM skipped: {skipped}")
        (out.path / "run.json").write_text(
            json.dumps({"gearbox": d.name, "file": d.file, "steps": steps}, indent=2) + "\n"
        )
        figures.wait()  # every figure is in the staging folder before it is swapped in
        paths = out.commit()
    print(f"  wrote {len(paths)} files to {args.out}")
    return status


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``run``."""
    p = add_command(
        subparsers,
        "run",
        cmd_run,
        "Main job: derive the model, print the gear table, simulate the default shift.",
        common,
    )
    p.add_argument(
        "--scenario", help="shift scenario (default: the built-in 2-3, where the gearbox fits it)"
    )
    p.add_argument(
        "--out",
        default="out/run",
        help="folder for every result (replaced atomically, and only if gearsym wrote it)",
    )
    p.add_argument(
        "--speed-unit",
        choices=("rad/s", "rpm"),
        default="rad/s",
        help="unit of the speeds and slips in the figures (default rad/s)",
    )
