"""The emitted TCU task of a shift (``gearsym_control_2_3_tcu_task`` of the default 2-3
upshift, with ``--shift 3-2`` the downshift's: the EKF and the shift controller in one 10 ms
task) bare-metal on the emulated Cortex-M4F (QEMU ``mps2-an386``, the harness of
:mod:`gearsym.validation.checks.qemu_m4`), against the host.

A case is a closed-loop shift of the Python controller (the calibration's own vehicle, the
knowledge exact), power-on or coast (:data:`CASES`: the 2-3 from the built-in scenario and
``scenario_2_3_coast.toml``, the 3-2 from ``scenario_3_2_power_on.toml`` and at its speed with
drag; whichever the input torque drives runs inertia phase first): at each tick the input,
output and wheel speeds and the commanded torque it saw, and the commands it gave. The driver
(``cortex_m4/control_driver.c``, one for every shift: the case's header names the shift's
functions) calls the task once per tick with those measurements, prints the commands, the
phase and the EKF's state as float bit patterns, and on the target times every call with
SysTick (instructions under ``-icount shift=0``, calibrated as in
:mod:`~gearsym.validation.checks.qemu_m4`). The code size is the bytes of the task's functions
in the linked ELF (``arm-none-eabi-nm``: the controller, the EKF functions it calls and the μ
map) and ``arm-none-eabi-size`` of each object.
"""

from __future__ import annotations

import math
import subprocess
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.validation.checks import qemu_m4
from gearsym.validation.checks.qemu_m4 import (
    CALIBRATION_TURNS,
    COMMON_FLAGS,
    EKF_FLOOR,
    EKF_R,
    HARNESS_DIR,
    TARGET_FLAGS,
    _array,
    _run,
    build_target,
)

__all__ = [
    "BUDGET",
    "CASES",
    "COMMAND",
    "SOURCES",
    "ControlCase",
    "ControlTiming",
    "FilterTracking",
    "build",
    "build_host",
    "case_header",
    "code_size",
    "control_case",
    "control_lines",
    "filter_tracking",
    "lockup_end_ties",
    "main",
    "operating_point",
    "sources",
    "task_markdown",
    "task_report",
    "timing",
    "values",
]

#: The EKF's initial σ of the physical states: the measured speeds, the side shafts' twist and
#: the wheel speed (assumed: a filter started at the shift command from the speeds it
#: measures); the parameters' is the description's prior (``[estimator]``, prior_of).
SIGMA0 = {"speed": 1.0, "twist": 1e-3, "wheel": 0.5}
#: The task's budget on the TCU (issue 29): instructions per call, EKF included.
BUDGET = 20_000
#: The shifts the task is run along, per shift: the kind → its operating point, a shipped
#: scenario (None: the built-in one) and, where none is shipped, the engine and e-machine
#: torques (N·m) that replace the scenario's: the coast 3-2 at the power-on 3-2's speed with
#: the coast 2-3's drag (engine −20, the machine recuperating −20; assumed).
CASES: dict[str, dict[str, tuple[str | None, tuple[float, float] | None]]] = {
    "2-3": {"power-on": (None, None), "coast": ("scenario_2_3_coast.toml", None)},
    "3-4": {
        "power-on": ("scenario_3_4.toml", None),
        "coast": ("scenario_3_4.toml", (-20.0, -20.0)),
    },
    "3-2": {
        "power-on": ("scenario_3_2_power_on.toml", None),
        "coast": ("scenario_3_2_power_on.toml", (-20.0, -20.0)),
    },
}
#: The kinds of :data:`CASES` (each shift has both).
KINDS = ("power-on", "coast")


def sources(shift: str) -> tuple[str, ...]:
    """The emitted sources the task of ``shift`` links: the controller, the EKF, the μ map."""
    tag = shift.replace("-", "_")
    return (f"gearsym_control_{tag}.c", f"gearsym_ekf_{tag}.c", "gearsym_mu_map.c")


#: The default shift's sources (generated/c holds them).
SOURCES = sources("2-3")


def operating_point(d: Any, shift: str, kind: str) -> Any:
    """The :class:`~gearsym.validation.studies.control.study.OperatingPoint` of a case
    (:data:`CASES`)."""
    from dataclasses import replace

    from gearsym.symbolic.io.package_data import data_file
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.studies.control.study import OperatingPoint

    scenario, torques = CASES[shift][kind]
    point = OperatingPoint.from_scenario(
        load_scenario(d, None if scenario is None else data_file(scenario))
    )
    if torques is not None:
        point = replace(point, engine=torques[0], e_machine=torques[1])
    return point


@dataclass
class ControlCase:
    """The recorded closed-loop shift the driver replays (float32 where it goes to C)."""

    inputs: np.ndarray  # (ticks, 5): t, omega_in, omega_out, omega_wheel, commanded torque
    commands: np.ndarray  # (ticks, 2): the Python controller's off-going, on-coming commands
    phases: tuple[str, ...]
    x0: np.ndarray
    P0: np.ndarray
    q: np.ndarray
    shift: str = "2-3"
    #: where the on-coming element's μ sits in the filter's state
    mu_on_index: int = 6
    #: the EKF's relative measurement noise and its floor per output (3.26)
    r: np.ndarray = field(default_factory=lambda: np.array(EKF_R))
    floor: np.ndarray = field(default_factory=lambda: np.array(EKF_FLOOR))
    #: where the input, output and wheel speeds and m_veh sit in the filter's state
    tracked: tuple[int, int, int, int] = (0, 1, 3, 4)
    #: the task's input fields of the shaft speeds only its EKF measures (inputs' columns 5...)
    extra: tuple[str, ...] = ()


def control_case(
    d: Any, t_end: float = 1.2, kind: str = "power-on", shift: str = "2-3", point: Any = None
) -> ControlCase:
    """The Python controller's ``shift`` of ``kind`` (:data:`CASES`) on the calibration's
    vehicle from its operating point (``point``, an
    :class:`~gearsym.validation.studies.control.study.OperatingPoint`, where given), sampled at
    its ticks."""
    from gearsym.symbolic import naming
    from gearsym.symbolic.codegen.control import extra_speeds, task_measurements
    from gearsym.symbolic.defaults import EKF_FLOOR_FRACTION, EKF_RELATIVE_NOISE
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.symbolic.estimators.ekf import augmented_model
    from gearsym.symbolic.hybrid import hybrid_shift
    from gearsym.validation.sim.actuator import ClutchActuator
    from gearsym.validation.sim.hybrid_simulation import HybridSimulator
    from gearsym.validation.studies.control.closed_loop import RECORD, TICK, ClosedLoopShift
    from gearsym.validation.studies.control.controller import Knowledge
    from gearsym.validation.studies.control.study import make_controller

    if point is None:
        point = operating_point(d, shift, kind)
    plant = ClosedLoopShift(d, shift, point.vehicle_speed)
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, shift))
    mu = quantity(d, "friction", "mu_nominal").value
    elements = tuple(model.hybrid.friction_coefficient)
    knowledge = Knowledge(
        mu=dict.fromkeys(elements, mu),
        m_veh=plant.values["m_veh"],
        zeta=plant.values[naming.GRADE],
    )
    controller = make_controller(d, model, knowledge, point.torque)
    nominal = ClutchActuator.from_calibration(d.control)
    spec = plant.spec
    actuators = {e: nominal for e in (spec.off_going, spec.on_coming)}
    result = plant.run(controller, point.torque, point.torque, actuators, actuators, t_end=t_end)
    at_ticks = np.round(result.ticks / RECORD).astype(int)
    assert np.allclose(result.t[at_ticks], result.ticks) and TICK == 0.01
    signals = result.signals
    speeds = [signals[naming.speed(s)][at_ticks] for s in (d.input_shaft, d.output_shaft)]
    wheel = signals[naming.WHEEL_SPEED][at_ticks]
    torque = np.full(len(at_ticks), point.torque)
    aug = augmented_model(d, shift)
    # the shaft speeds only the task's EKF measures (its inputs' extra fields, in order)
    measurements = task_measurements(d, model.hybrid)
    extra = extra_speeds(measurements)
    # the EKF's measurement noise (3.26) as the estimation studies set it: relative, with a
    # floor of a fraction of each output's largest value over the record
    measured = {
        "in->control.omega_in": speeds[0],
        "in->control.omega_out": speeds[1],
        "in->omega_wheel": wheel,
        **{f"in->{f}": signals[f][at_ticks] for f in extra},
    }
    y = np.column_stack([measured[c] for _, c in measurements])
    # the filter's start: the shafts' speeds and the record's twist and wheel, the calibration
    start = {
        naming.speed(s.name): (float(signals[naming.speed(s.name)][0]), SIGMA0["speed"])
        for s in d.shafts
    }
    start[naming.TWIST] = (signals[naming.TWIST][0], SIGMA0["twist"])
    start[naming.WHEEL_SPEED] = (wheel[0], SIGMA0["wheel"])
    calibration = {"m_veh": knowledge.m_veh, naming.GRADE: knowledge.zeta}
    calibration |= {str(s): mu for s in model.hybrid.friction_coefficient.values()}
    for name, value in calibration.items():
        start[name] = (value, d.estimator.prior_of(name, value)[1])
    x0 = np.array([start[name][0] for name in aug.state_names])
    sigma0 = np.array([start[name][1] for name in aug.state_names])
    return ControlCase(
        inputs=np.column_stack(
            [result.ticks, *speeds, wheel, torque, *(signals[f][at_ticks] for f in extra)]
        ),
        commands=np.column_stack(
            [result.commands[spec.off_going], result.commands[spec.on_coming]]
        ),
        phases=result.phases,
        x0=x0,
        P0=np.diag(sigma0**2),
        q=np.array([aug.intensities[n] for n in aug.state_names]),
        shift=shift,
        mu_on_index=aug.state_names.index(str(model.hybrid.friction_coefficient[spec.on_coming])),
        r=np.full(y.shape[1], EKF_RELATIVE_NOISE),
        floor=EKF_FLOOR_FRACTION * np.max(np.abs(y), axis=0),
        tracked=tuple(
            aug.state_names.index(n)
            for n in (
                naming.speed(d.input_shaft),
                naming.speed(d.output_shaft),
                naming.WHEEL_SPEED,
                "m_veh",
            )
        ),
        extra=extra,
    )


@dataclass(frozen=True)
class FilterTracking:
    """How the task's EKF followed a case (its state after every task call against the
    recorded shift on the calibration's own vehicle): the largest difference of its input,
    output and wheel speeds from the measured ones over the whole shift and after it (rad/s),
    its largest relative mass error, its mass at the end (kg), and how far the on-coming
    element's μ moved from where it started (the element slides in every case)."""

    speed_error: float
    speed_error_done: float
    mass_error: float
    m_veh_end: float
    mu_on_moved: float


def filter_tracking(case: ControlCase, states: np.ndarray) -> FilterTracking:
    """:class:`FilterTracking` of the filter's ``states`` (one row per task call)."""
    speeds = list(case.tracked[:3])
    error = np.abs(states[:, speeds] - case.inputs[:, [1, 2, 3]])
    done = np.array(case.phases) == "done"
    index = case.tracked[3]
    m_veh = case.x0[index]
    mu = states[:, case.mu_on_index]
    return FilterTracking(
        speed_error=float(error.max()),
        speed_error_done=float(error[done].max()) if done.any() else math.nan,
        mass_error=float(np.max(np.abs(states[:, index] - m_veh)) / m_veh),
        m_veh_end=float(states[-1, index]),
        mu_on_moved=float(abs(mu[-1] - case.x0[case.mu_on_index])),
    )


def case_header(case: ControlCase) -> str:
    """``control_case.h``: the case as exact float literals (P0 column-major)."""
    f32 = np.float32
    tag = case.shift.replace("-", "_")
    return "".join(
        [
            "/* Data of gearsym's TCU-task driver (gearsym.validation.checks.qemu_control). */\n",
            "#ifndef CONTROL_CASE_H\n#define CONTROL_CASE_H\n#include <math.h>\n",
            # the driver names the shift's task through these (one driver for every shift)
            f'#include "gearsym_control_{tag}.h"\n',
            f"#define CTL(name) gearsym_control_{tag}_##name\n",
            f"#define EKF(name) gearsym_ekf_{tag}_##name\n",
            f"#define EKF_NX GEARSYM_EKF_{tag}_NX\n",
            # the shaft speeds only the EKF measures: columns 5... of case_in
            "#define CASE_SET_EXTRA(in, row) do { "
            + "".join(f"(in).{f} = (row)[{5 + i}]; " for i, f in enumerate(case.extra))
            + "} while (0)\n",
            f"#define CASE_TICKS {len(case.inputs)}\n",
            f"#define CASE_CALIBRATION_TURNS {CALIBRATION_TURNS}u\n",
            _array("case_in", case.inputs.astype(f32)),
            _array("case_x0", case.x0.astype(f32)),
            _array("case_P0", case.P0.ravel(order="F").astype(f32)),
            _array("case_q", case.q.astype(f32)),
            _array("case_r", case.r.astype(f32)),
            _array("case_floor", case.floor.astype(f32)),
            "#endif\n",
        ]
    )


def build_host(c_dir: Path, case: ControlCase, out: Path) -> Path:
    """The driver with the task's sources for the host (float, ``-ffp-contract=off``, glibc's
    sinf/cosf): what :func:`build` builds beside the target, without the cross tools."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "control_case.h").write_text(case_header(case), encoding="utf-8")
    host = out / "control_host"
    _run(
        [
            "gcc",
            *COMMON_FLAGS,
            *(f"-I{d}" for d in (out, c_dir, HARNESS_DIR)),
            "-o",
            str(host),
            str(HARNESS_DIR / "host.c"),
            str(HARNESS_DIR / "control_driver.c"),
            *(str(c_dir / s) for s in sources(case.shift)),
            "-lm",
        ],
        out,
    )
    return host


def build(c_dir: Path, case: ControlCase, out: Path) -> tuple[Path, Path, list[Path]]:
    """The driver with the task's sources for the mps2-an386 board and for the host (both
    float, ``-ffp-contract=off``), each with its own C library's sinf/cosf (the harness'
    stand-ins of ``qemu_m4.SAME_TRIG_FLAGS`` hold for |a| <= 0.8 only, and the torque phase's
    raised cosine takes cos(pi tau) up to pi); and the target objects of the task's sources
    alone (for their sizes)."""
    host = build_host(c_dir, case, out)
    linked = [c_dir / s for s in sources(case.shift)]
    driver = HARNESS_DIR / "control_driver.c"
    elf = build_target([driver, *linked], [out, c_dir], out / "control_m4.elf")
    objects = []
    for source in linked:
        obj = out / (source.stem + ".o")
        _run(
            [
                "arm-none-eabi-gcc",
                *COMMON_FLAGS,
                *TARGET_FLAGS,
                f"-I{c_dir}",
                "-c",
                "-o",
                str(obj),
                str(source),
            ],
            out,
        )
        objects.append(obj)
    return elf, host, objects


def control_lines(text: str) -> list[str]:
    """The task's result lines, in order."""
    return [ln for ln in text.splitlines() if ln.startswith("ctl ")]


def values(line: str) -> tuple[int, int, np.ndarray]:
    """(status, phase, floats: p_off, p_on, the EKF's x) of a result line."""
    words = line.split()
    bits = np.array([int(w, 16) for w in words[4:]], dtype=np.uint32)
    return int(words[2], 16), int(words[3], 16), bits.view(np.float32).astype(float)


@dataclass
class ControlTiming:
    """Instructions per task call on the emulated target."""

    instructions_per_tick: float
    mean: float
    largest: float
    calls: int


def timing(text: str) -> ControlTiming:
    """Mean and largest instructions per call of the task (SysTick ticks times the calibrated
    instructions per tick, less one read of SysTick)."""
    v = qemu_m4.reports(text)
    per_tick = 2 * CALIBRATION_TURNS / v["calibration"]
    read = v["empty64"] * per_tick / 64
    calls = v["ctl_ticks"]
    return ControlTiming(
        per_tick, v["ctl_total"] * per_tick / calls - read, v["ctl_max"] * per_tick - read, calls
    )


def code_size(
    elf: Path, objects: list[Path], shift: str = "2-3"
) -> tuple[dict[str, int], dict[str, int]]:
    """Bytes of code of each function the task of ``shift`` links (controller, EKF, μ map) in
    the ELF, and ``arm-none-eabi-size`` text + data + bss per object."""
    tag = shift.replace("-", "_")
    prefixes = (f"gearsym_control_{tag}_", f"gearsym_ekf_{tag}_", "gearsym_mu_map")
    functions = qemu_m4.function_sizes(elf, prefixes)
    sizes = {}
    for obj in objects:
        out = (
            subprocess.run(
                ["arm-none-eabi-size", str(obj)], capture_output=True, text=True, check=True
            )
            .stdout.splitlines()[1]
            .split()
        )
        sizes[obj.stem] = int(out[0]) + int(out[1]) + int(out[2])
    return functions, sizes


#: The command that writes the documentation's table (``make results``).
COMMAND = "python -m gearsym.validation.checks.qemu_control"


def task_report(c_dir: Path, build_dir: Path, shift: str = "2-3") -> dict[str, Any]:
    """The task of ``shift`` on the emulated target along each :func:`control_case`
    (:data:`CASES`) as JSON-ready data: per kind the calls, instructions per call (mean,
    largest) and how far its commands are from the Python controller's (Pa) and whether the
    phases agree; the budget and the code size (the linked functions' bytes, each object's
    text + data + bss: the same build for every kind, only the driver's data differ)."""
    from gearsym.symbolic.loader import load_description
    from gearsym.symbolic.shifts import shift_spec
    from gearsym.validation.studies.control.controller import PHASES, shift_direction

    d = load_description()
    kinds = []
    for kind in KINDS:
        case = control_case(d, kind=kind, shift=shift)
        elf, _, objects = build(c_dir, case, build_dir / kind)
        target = qemu_m4.run_qemu(elf)
        t = timing(target)
        functions, objects_size = code_size(elf, objects, shift)
        results = [values(ln) for ln in control_lines(target)]
        commands = np.array([v[:2] for _, _, v in results])
        tracking = filter_tracking(case, np.array([v[2:] for _, _, v in results]))
        kinds.append(
            {
                "kind": kind,
                "calls": t.calls,
                "instructions_mean": round(t.mean),
                "instructions_max": round(t.largest),
                "command_difference_pa": float(np.max(np.abs(commands - case.commands))),
                "phases_agree": tuple(PHASES[p] for _, p, _ in results) == case.phases,
                "lockup_end_ties": lockup_end_ties(case, tuple(PHASES[p] for _, p, _ in results)),
                "operating_point": _point_text(shift, kind),
                "filter": asdict(tracking),
                "m_veh": float(case.x0[case.tracked[3]]),
            }
        )
    return {
        "shift": shift,
        "direction": shift_direction(d, shift_spec(d, shift)),
        "board": "QEMU mps2-an386 (Cortex-M4F), -icount shift=0",
        "flags": " ".join((*COMMON_FLAGS, *TARGET_FLAGS)),
        "kinds": kinds,
        "instructions_max": max(k["instructions_max"] for k in kinds),
        "budget": BUDGET,
        "code_bytes": sum(functions.values()),
        "functions": dict(sorted(functions.items())),
        "objects": objects_size,
    }


def _point_text(shift: str, kind: str) -> str:
    """Where a case's operating point comes from, in words (:data:`CASES`)."""
    scenario, torques = CASES[shift][kind]
    name = "the built-in scenario" if scenario is None else f"`{scenario}`"
    if torques is None:
        return name
    return (
        f"{name} at engine {torques[0]:g} N·m and e-machine {torques[1]:g} N·m (assumed: "
        "no coast scenario of this shift is shipped)"
    )


def lockup_end_ties(case: ControlCase, phases: tuple[str, ...]) -> int | None:
    """How many ticks the task's phases differ from the Python controller's only where the
    lock-up's hold ends on a tick (``TO_LINE + HOLD_LINE`` after lock-up to rounding: the float
    task and the double controller may round either side of it, commanding line pressure
    either way); None when they differ anywhere else."""
    from gearsym.symbolic.control_calibration import HOLD_LINE, TO_LINE

    t = case.inputs[:, 0]
    lock = next((t[i] for i, p in enumerate(case.phases) if p == "lockup"), None)
    ties = 0
    for i, (ours, theirs) in enumerate(zip(phases, case.phases, strict=True)):
        if ours == theirs:
            continue
        at_end = lock is not None and abs(t[i] - lock - (TO_LINE + HOLD_LINE)) < 1e-4
        if not (at_end and {ours, theirs} == {"lockup", "done"}):
            return None
        ties += 1
    return ties


def _phases(kind: dict[str, Any]) -> str:
    if kind["phases_agree"]:
        return "the same"
    ties = kind.get("lockup_end_ties")
    if ties:
        return f"the same but at {ties} tick where the lock-up's hold ends (a float tie)"
    return "**differing**"


def task_markdown(data: dict[str, Any], command: str) -> str:
    """The report's JSON (:func:`task_report`) as the documentation's table."""
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- `gearsym_control_{data['shift'].replace('-', '_')}_tcu_task` on {data['board']}, "
        f"float build (`{data['flags']}`), along closed-loop {data['shift']} "
        f"{data.get('direction', 'up')}shifts of the Python controller ("
        + "; ".join(f"{k['kind']}: {k.get('operating_point', '')}" for k in data["kinds"])
        + ")",
        "- its commands against the Python controller's on the same measurements, and the "
        "phases at every tick",
        "",
        "| shift | calls | instructions per call (mean) | at most | budget | commands apart (Pa) "
        "| phases |",
        "|---|---|---|---|---|---|---|",
        *(
            f"| {k['kind']} | {k['calls']} | {k['instructions_mean']} | {k['instructions_max']} "
            f"| {data['budget']} | {k['command_difference_pa']:.3g} | {_phases(k)} |"
            for k in data["kinds"]
        ),
        "",
        "The task's EKF along the same shifts (the calibration's own vehicle, the knowledge "
        "exact):",
        "",
        "| shift | speeds apart, whole shift (rad/s) | after it (rad/s) | m_veh apart, most "
        "| m_veh at the end (kg) | on-coming μ moved by |",
        "|---|---|---|---|---|---|",
        *(
            f"| {k['kind']} | {k['filter']['speed_error']:.3g} "
            f"| {k['filter']['speed_error_done']:.2g} | {100 * k['filter']['mass_error']:.2g} % "
            f"| {k['filter']['m_veh_end']:.0f} of {k['m_veh']:.0f} "
            f"| {k['filter']['mu_on_moved']:.3g} |"
            for k in data["kinds"]
            if "filter" in k
        ),
        "",
        "Its speeds are the largest difference of its input, output and wheel speeds from the "
        "measured ones; it is told the forces its commands give through the TCU's actuator "
        "model (the valve's dead time and lag, the piston's fill: `actuator_tick`).",
        "",
        f"Bytes of the linked functions and tables: {data['code_bytes']}.",
        "",
        "| object | text + data + bss (bytes) |",
        "|---|---|",
        *(f"| {name}.o | {size} |" for name, size in data["objects"].items()),
    ]
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m gearsym.validation.checks.qemu_control --out DIR``: the task's report into
    ``DIR/<name>.json`` and ``DIR/<name>.md``, ``<name>`` the folder's name."""
    import argparse
    import json
    import sys
    import tempfile

    parser = argparse.ArgumentParser(prog=COMMAND, description="the TCU task on the Cortex-M4F")
    parser.add_argument("--out", required=True, help="folder for the JSON and the table")
    parser.add_argument("--c-dir", default="generated/c", help="the emitted C (generated/c)")
    parser.add_argument(
        "--shift",
        default="2-3",
        help="the shift whose task runs (default 2-3); one whose C is not in --c-dir is "
        "emitted into the build folder first",
    )
    args = parser.parse_args(argv)
    missing = qemu_m4.missing_tools()
    if missing:
        print(f"{COMMAND}: not installed: {', '.join(missing)}", file=sys.stderr)
        return 2
    if args.shift not in CASES:
        print(
            f"{COMMAND}: --shift: no cases for {args.shift!r} (known: {', '.join(CASES)})",
            file=sys.stderr,
        )
        return 2
    c_dir = Path(args.c_dir).resolve()
    with tempfile.TemporaryDirectory(prefix="gearsym-task-") as build_dir:
        if not all((c_dir / s).is_file() for s in sources(args.shift)):
            from gearsym.symbolic.loader import load_description
            from gearsym.validation.checks.control_c import emit_task_sources

            c_dir = emit_task_sources(load_description(), args.shift, Path(build_dir) / "c", c_dir)
        data = task_report(c_dir, Path(build_dir), args.shift)
    command = " ".join([COMMAND, *(argv if argv is not None else sys.argv[1:])])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{out.name}.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    (out / f"{out.name}.md").write_text(task_markdown(data, command), encoding="utf-8")
    means = ", ".join(f"{k['kind']} {k['instructions_mean']}" for k in data["kinds"])
    print(
        f"{data['instructions_max']} instructions at most per task call (mean {means}; budget "
        f"{BUDGET}), {data['code_bytes']} bytes of code; wrote {out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
