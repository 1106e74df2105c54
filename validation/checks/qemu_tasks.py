"""Every adjacent shift's TCU task, up and down, on the emulated Cortex-M4F: the instructions
per 10 ms call against the issue's budget, the code size, the commands against the Python
controller's and how the task's EKF follows the shift.

``python -m gearsym.validation.checks.qemu_tasks --out DIR`` emits each shift's controller and
EKF (:func:`~gearsym.validation.checks.control_c.emit_task_sources`), runs the Python
controller's closed-loop shift on the calibration's vehicle, power-on and coast, replays its
measurements through the task on the board (:mod:`gearsym.validation.checks.qemu_control`) and
writes ``DIR/<name>.json`` and ``DIR/<name>.md`` (:func:`tasks_markdown`, a function of that
JSON alone) once every task has run.

Operating points: a shift with shipped cases (:data:`~.qemu_control.CASES`: the 2-3, 3-2 and
3-4) runs those; every other runs at the vehicle speed where the lower gear of its pair turns
the input at :data:`REFERENCE_INPUT_SPEED`, power-on at the built-in scenarios' torques and
coast at the coast cases' (:data:`POWER_ON`, :data:`COAST`; assumed, stated in the table).
"""

from __future__ import annotations

import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.validation.checks import qemu_control, qemu_m4

__all__ = [
    "COAST",
    "POWER_ON",
    "REFERENCE_INPUT_SPEED",
    "generic_point",
    "inertia_give_up",
    "main",
    "task_shifts",
    "tasks_markdown",
    "task_failures",
    "tasks_report",
]

#: The command that writes the documentation's table (``make results``).
COMMAND = "python -m gearsym.validation.checks.qemu_tasks"
#: The input speed (rad/s, about 1 860 rpm) of the lower gear of a pair at a shift without a
#: shipped case: where the built-in scenarios put the upshift's from-gear (the 2-3 at 8 m/s:
#: 194.9 rad/s in 2nd; the 3-4 at 11.5 m/s: 194.5 rad/s in 3rd).
REFERENCE_INPUT_SPEED = 195.0
#: Engine and e-machine torques (N·m) of a power-on shift without a shipped case: the built-in
#: scenarios' (120 + 30).
POWER_ON = (120.0, 30.0)
#: The same of a coast shift: the coast cases' drag (engine −20, the machine recuperating −20).
COAST = (-20.0, -20.0)


def task_shifts(d: Any) -> list[str]:
    """Every single-swap shift between adjacent forward gears, each upshift followed by its
    downshift (``["1-2", "2-1", "2-3", ...]``)."""
    from gearsym.symbolic.drivetrain import adjacent_shifts

    shifts = []
    for spec in adjacent_shifts(d):
        if spec.single:
            shifts += [spec.name, f"{spec.to_gear}-{spec.from_gear}"]
    return shifts


def generic_point(d: Any, shift: str, kind: str) -> Any:
    """The :class:`~gearsym.validation.studies.control.study.OperatingPoint` of a shift
    without a shipped case: the vehicle speed r_dyn ω_ref / (i_D i_low) with i_low the larger
    ratio of the two gears, the torques of :data:`POWER_ON` or :data:`COAST`."""
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.symbolic.ratios import gear_ratio
    from gearsym.symbolic.shifts import shift_spec
    from gearsym.validation.studies.control.study import OperatingPoint

    spec = shift_spec(d, shift)
    lower = max(float(gear_ratio(d, d.gear(g)).ratio) for g in (spec.from_gear, spec.to_gear))
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    i_d = float(quantity(d, "drivetrain", "i_D").value)
    engine, e_machine = POWER_ON if kind == "power-on" else COAST
    return OperatingPoint(REFERENCE_INPUT_SPEED * r_dyn / (i_d * lower), engine, e_machine)


def _point(d: Any, shift: str, kind: str) -> tuple[Any, str]:
    """A case's operating point and where it comes from, in words."""
    if shift in qemu_control.CASES:
        return qemu_control.operating_point(d, shift, kind), "shipped case"
    point = generic_point(d, shift, kind)
    return point, f"{point.vehicle_speed:.3g} m/s, {point.engine:g} + {point.e_machine:g} N·m"


def inertia_give_up(
    expected: tuple[str, ...], task: tuple[str, ...], limit: float, tick: float
) -> tuple[bool, bool]:
    """Whether the Python controller's inertia phase (``expected``, one phase per tick) ran
    to its ``limit`` (s: the controller's fallback, TIMEOUT_FACTOR targets) and whether the
    task's phases first part from it at the tick the controller left that phase: a time
    compared on a tick, where the float task and the double controller may round either side
    (as the lock-up's hold end, :func:`.qemu_control.lockup_end_ties`)."""
    gave_up = expected.count("inertia") * tick >= limit - tick / 2
    apart = next((i for i, (a, b) in enumerate(zip(task, expected, strict=True)) if a != b), None)
    left = next(
        (i for i in range(1, len(expected)) if expected[i - 1] == "inertia" != expected[i]),
        None,
    )
    return gave_up, gave_up and apart is not None and apart == left


def _kind_row(d: Any, c_dir: Path, shift: str, kind: str, build_dir: Path) -> dict[str, Any]:
    """One shift of one kind through the task on the board (as :func:`.qemu_control.
    task_report` does for one shift)."""
    from gearsym.symbolic.control_calibration import TIMEOUT_FACTOR
    from gearsym.validation.studies.control.closed_loop import TICK
    from gearsym.validation.studies.control.controller import PHASES

    point, where = _point(d, shift, kind)
    case = qemu_control.control_case(d, kind=kind, shift=shift, point=point)
    elf, _, objects = qemu_control.build(c_dir, case, build_dir)
    target = qemu_m4.run_qemu(elf)
    t = qemu_control.timing(target)
    results = [qemu_control.values(ln) for ln in qemu_control.control_lines(target)]
    phases = tuple(PHASES[p] for _, p, _ in results)
    commands = np.array([v[:2] for _, _, v in results])
    tracking = qemu_control.filter_tracking(case, np.array([v[2:] for _, _, v in results]))
    functions, objects_size = qemu_control.code_size(elf, objects, shift)
    limit = TIMEOUT_FACTOR * d.control.si("shift", "inertia_phase")
    gave_up, tie = inertia_give_up(case.phases, phases, limit, TICK)
    return {
        "kind": kind,
        "operating_point": where,
        "calls": t.calls,
        "failed_calls": sum(1 for status, _, _ in results if status != 0),
        "instructions_mean": round(t.mean),
        "instructions_max": round(t.largest),
        "command_difference_pa": float(np.max(np.abs(commands - case.commands))),
        "phases_agree": phases == case.phases,
        "lockup_end_ties": qemu_control.lockup_end_ties(case, phases),
        "completed": "done" in case.phases,
        "inertia_gave_up": gave_up,
        "apart_from_give_up": tie,
        "filter": asdict(tracking),
        "m_veh": float(case.x0[case.tracked[3]]),
        "code_bytes": sum(functions.values()),
        "object_bytes": sum(objects_size.values()),
    }


def tasks_report(d: Any, shifts: list[str], mu_map_dir: Path, build_dir: Path) -> dict[str, Any]:
    """Every task of ``shifts`` (power-on and coast) as JSON-ready data, a line of progress per
    shift on stderr."""
    from gearsym.validation.checks.control_c import emit_task_sources

    rows = []
    for n, shift in enumerate(shifts, 1):
        c_dir = emit_task_sources(d, shift, build_dir / shift / "c", mu_map_dir)
        kinds = [
            _kind_row(d, c_dir, shift, kind, build_dir / shift / kind)
            for kind in qemu_control.KINDS
        ]
        rows.append({"shift": shift, "kinds": kinds})
        worst = max(k["instructions_max"] for k in kinds)
        print(f"[{n}/{len(shifts)}] {shift}: {worst} instructions at most", file=sys.stderr)
    return {
        "board": "QEMU mps2-an386 (Cortex-M4F), -icount shift=0",
        "flags": " ".join((*qemu_control.COMMON_FLAGS, *qemu_control.TARGET_FLAGS)),
        "budget": qemu_control.BUDGET,
        "reference_input_speed": REFERENCE_INPUT_SPEED,
        "power_on": POWER_ON,
        "coast": COAST,
        "shifts": rows,
        "instructions_max": max(k["instructions_max"] for r in rows for k in r["kinds"]),
    }


def task_failures(kind: dict[str, Any], budget: int) -> list[str]:
    """What makes a task unfit for the TCU along a case: over budget, a failed call, phases
    apart from the Python controller's other than at a tie, or a shift not finished."""
    failures = []
    if kind["instructions_max"] >= budget:
        failures.append("over budget")
    if kind["failed_calls"]:
        failures.append(f"{kind['failed_calls']} calls failed")
    if not kind["phases_agree"] and not kind["lockup_end_ties"] and not kind["apart_from_give_up"]:
        failures.append("phases differ")
    if not kind["completed"]:
        failures.append("not locked up in 1.2 s")
    return failures


def _verdict(kind: dict[str, Any], budget: int) -> str:
    """A row's verdict: its failures (:func:`task_failures`) in bold, and where the Python
    controller's inertia phase gave up at its limit (the controller's finding, not the
    task's), and whether the float task then runs a tick behind."""
    notes = [f"**{f}**" for f in task_failures(kind, budget)]
    if kind["inertia_gave_up"]:
        notes.append("the controller's inertia phase gave up at its limit")
        if kind["apart_from_give_up"]:
            notes.append("the float task a tick later (a tie), then a tick behind")
    return ", ".join(notes) or "fits"


def tasks_markdown(data: dict[str, Any], command: str) -> str:
    """The report's JSON (:func:`tasks_report`) as the documentation's table."""
    engine, machine = data["power_on"]
    coast = data["coast"]
    lines = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- each shift's `gearsym_control_<a>_<b>_tcu_task` on {data['board']}, float build "
        f"(`{data['flags']}`), budget {data['budget']} instructions per call",
        "- along the Python controller's closed-loop shift on the calibration's vehicle: the "
        "shipped cases where there are (2-3, 3-2, 3-4), else at the speed where the lower gear "
        f"of the pair turns the input at {data['reference_input_speed']:g} rad/s, power-on at "
        f"{engine:g} + {machine:g} N·m, coast at {coast[0]:g} + {coast[1]:g} N·m (assumed)",
        "- speeds apart: the largest difference of the EKF's input, output and wheel speeds "
        "from the measured ones over the shift (the calibration's own vehicle, the knowledge "
        "exact); commands apart: from the Python controller's on the same measurements",
        "- the controller's inertia phase gives up after twice its target duration (its "
        "fallback) where it does not reach synchronism; the time is compared on a tick, and "
        "the float task may end it a tick after the double controller (a tie: its commands "
        "then run a tick behind, hence commands apart by up to the ramps' step)",
        "",
        "| shift | kind | operating point | instructions per call (mean) | at most "
        "| commands apart (Pa) | speeds apart (rad/s) | m_veh apart | code (bytes) | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in data["shifts"]:
        for k in row["kinds"]:
            f = k["filter"]
            lines.append(
                f"| {row['shift']} | {k['kind']} | {k['operating_point']} "
                f"| {k['instructions_mean']} | {k['instructions_max']} "
                f"| {k['command_difference_pa']:.3g} | {f['speed_error']:.3g} "
                f"| {100 * f['mass_error']:.2g} % | {k['code_bytes']} "
                f"| {_verdict(k, data['budget'])} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m gearsym.validation.checks.qemu_tasks --out DIR [--shifts A-B,...]``."""
    import argparse
    import json
    import tempfile

    from gearsym.symbolic.loader import load_description

    parser = argparse.ArgumentParser(
        prog=COMMAND, description="every adjacent shift's TCU task on the Cortex-M4F"
    )
    parser.add_argument("--out", required=True, help="folder for the JSON and the table")
    parser.add_argument(
        "--c-dir", default="generated/c", help="where the μ map's C is (generated/c)"
    )
    parser.add_argument(
        "--shifts", default="", help="comma-separated shifts (default: every adjacent one)"
    )
    args = parser.parse_args(argv)
    d = load_description()
    known = task_shifts(d)
    shifts = [s.strip() for s in args.shifts.split(",") if s.strip()] or known
    unknown = [s for s in shifts if s not in known]
    if unknown:
        print(
            f"{COMMAND}: --shifts: {unknown[0]!r} is not an adjacent single-swap shift "
            f"(known: {', '.join(known)})",
            file=sys.stderr,
        )
        return 2
    missing = qemu_m4.missing_tools()
    if missing:
        print(f"{COMMAND}: not installed: {', '.join(missing)}", file=sys.stderr)
        return 2
    mu_map = Path(args.c_dir).resolve()
    if not (mu_map / "gearsym_mu_map.c").is_file():
        print(f"{COMMAND}: --c-dir: {args.c_dir}: no gearsym_mu_map.c", file=sys.stderr)
        return 2
    command = " ".join([COMMAND, *(argv if argv is not None else sys.argv[1:])])
    out = Path(args.out)
    with tempfile.TemporaryDirectory(prefix="gearsym-tasks-") as build_dir:
        data = tasks_report(d, shifts, mu_map, Path(build_dir))
    # as the other reports of validation/checks (qemu_control, misra): written when all ran
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{out.name}.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    (out / f"{out.name}.md").write_text(tasks_markdown(data, command), encoding="utf-8")
    over = [
        f"{r['shift']} {k['kind']} ({', '.join(task_failures(k, data['budget']))})"
        for r in data["shifts"]
        for k in r["kinds"]
        if task_failures(k, data["budget"])
    ]
    print(
        f"{len(shifts)} tasks, {data['instructions_max']} instructions at most per call "
        f"(budget {data['budget']}); wrote {out}"
        + (f"; not fit: {'; '.join(over)}" if over else "")
    )
    return 1 if over else 0


if __name__ == "__main__":
    raise SystemExit(main())
