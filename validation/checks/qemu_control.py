"""The emitted TCU task of the 2-3 upshift (``gearsym_control_2_3_tcu_task``: the EKF and the
shift controller in one 10 ms task) bare-metal on the emulated Cortex-M4F (QEMU
``mps2-an386``, the harness of :mod:`gearsym.validation.checks.qemu_m4`), against the host.

The case is a closed-loop shift of the Python controller (the calibration's own vehicle, the
knowledge exact): at each tick the input, output and wheel speeds and the commanded torque it
saw, and the commands it gave. The driver (``cortex_m4/control_driver.c``) calls the task once
per tick with those measurements, prints the commands, the phase and the EKF's state as float
bit patterns, and on the target times every call with SysTick (instructions under ``-icount
shift=0``, calibrated as in :mod:`~gearsym.validation.checks.qemu_m4`). The code size is the
bytes of the task's functions in the linked ELF (``arm-none-eabi-nm``: the controller, the EKF
functions it calls and the μ map) and ``arm-none-eabi-size`` of each object.
"""

from __future__ import annotations

import subprocess
from dataclasses import dataclass
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
    "COMMAND",
    "SOURCES",
    "ControlCase",
    "ControlTiming",
    "build",
    "build_host",
    "case_header",
    "code_size",
    "control_case",
    "control_lines",
    "main",
    "task_markdown",
    "task_report",
    "timing",
    "values",
]

#: The emitted sources the task links: the controller, the EKF, the μ map.
SOURCES = ("gearsym_control_2_3.c", "gearsym_ekf_2_3.c", "gearsym_mu_map.c")
#: The EKF's initial σ per state (omega_1, omega_2, phi, omega_C, m_veh, mu_38, mu_05, zeta):
#: assumed, a filter started at the shift command from the speeds it measures.
SIGMA0 = (1.0, 1.0, 1e-3, 0.5, 200.0, 0.02, 0.02, 0.02)
#: The task's budget on the TCU (issue 29): instructions per call, EKF included.
BUDGET = 20_000


@dataclass
class ControlCase:
    """The recorded closed-loop shift the driver replays (float32 where it goes to C)."""

    inputs: np.ndarray  # (ticks, 5): t, omega_in, omega_out, omega_wheel, commanded torque
    commands: np.ndarray  # (ticks, 2): the Python controller's off-going, on-coming commands
    phases: tuple[str, ...]
    x0: np.ndarray
    P0: np.ndarray
    q: np.ndarray


def control_case(d: Any, t_end: float = 1.2) -> ControlCase:
    """The Python controller's shift on the calibration's vehicle from the built-in scenario's
    operating point, sampled at its ticks."""
    from gearsym.symbolic import naming
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.symbolic.estimators.ekf import augmented_model
    from gearsym.symbolic.hybrid import hybrid_shift
    from gearsym.validation.sim.actuator import ClutchActuator
    from gearsym.validation.sim.hybrid_simulation import HybridSimulator
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.studies.control.closed_loop import RECORD, TICK, ClosedLoopShift
    from gearsym.validation.studies.control.controller import Knowledge, ShiftController
    from gearsym.validation.studies.control.study import OperatingPoint

    point = OperatingPoint.from_scenario(load_scenario(d))
    plant = ClosedLoopShift(d, "2-3", point.vehicle_speed)
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, "2-3"))
    mu = quantity(d, "friction", "mu_nominal").value
    knowledge = Knowledge(
        mu={"K38": mu, "B05": mu},
        m_veh=plant.values["m_veh"],
        zeta=plant.values[naming.GRADE],
    )
    controller = ShiftController(d, model, knowledge)
    nominal = ClutchActuator.from_calibration(d.control)
    actuators = {"K38": nominal, "B05": nominal}
    result = plant.run(controller, point.torque, point.torque, actuators, actuators, t_end=t_end)
    at_ticks = np.round(result.ticks / RECORD).astype(int)
    assert np.allclose(result.t[at_ticks], result.ticks) and TICK == 0.01
    signals = result.signals
    speeds = [signals[naming.speed(s)][at_ticks] for s in (d.input_shaft, d.output_shaft)]
    wheel = signals[naming.WHEEL_SPEED][at_ticks]
    torque = np.full(len(at_ticks), point.torque)
    aug = augmented_model(d, "2-3")
    x0 = np.array(
        [
            speeds[0][0],
            speeds[1][0],
            signals[naming.TWIST][0],
            wheel[0],
            knowledge.m_veh,
            mu,
            mu,
            knowledge.zeta,
        ]
    )
    return ControlCase(
        inputs=np.column_stack([result.ticks, *speeds, wheel, torque]),
        commands=np.column_stack([result.commands["K38"], result.commands["B05"]]),
        phases=result.phases,
        x0=x0,
        P0=np.diag(np.array(SIGMA0) ** 2),
        q=np.array([aug.intensities[n] for n in aug.state_names]),
    )


def case_header(case: ControlCase) -> str:
    """``control_case.h``: the case as exact float literals (P0 column-major)."""
    f32 = np.float32
    return "".join(
        [
            "/* Data of gearsym's TCU-task driver (gearsym.validation.checks.qemu_control). */\n",
            "#ifndef CONTROL_CASE_H\n#define CONTROL_CASE_H\n#include <math.h>\n",
            f"#define CASE_TICKS {len(case.inputs)}\n",
            f"#define CASE_CALIBRATION_TURNS {CALIBRATION_TURNS}u\n",
            _array("case_in", case.inputs.astype(f32)),
            _array("case_x0", case.x0.astype(f32)),
            _array("case_P0", case.P0.ravel(order="F").astype(f32)),
            _array("case_q", case.q.astype(f32)),
            _array("case_r", np.array(EKF_R, dtype=f32)),
            _array("case_floor", np.array(EKF_FLOOR, dtype=f32)),
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
            *(str(c_dir / s) for s in SOURCES),
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
    sources = [c_dir / s for s in SOURCES]
    driver = HARNESS_DIR / "control_driver.c"
    elf = build_target([driver, *sources], [out, c_dir], out / "control_m4.elf")
    objects = []
    for source in sources:
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


def code_size(elf: Path, objects: list[Path]) -> tuple[dict[str, int], dict[str, int]]:
    """Bytes of code of each function the task links (controller, EKF, μ map) in the ELF, and
    ``arm-none-eabi-size`` text + data + bss per object."""
    prefixes = ("gearsym_control_2_3_", "gearsym_ekf_2_3_", "gearsym_mu_map")
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


def task_report(c_dir: Path, build_dir: Path) -> dict[str, Any]:
    """The task on the emulated target along :func:`control_case` as JSON-ready data:
    instructions per call (mean, largest), the budget, the code size (the linked functions'
    bytes, each object's text + data + bss), and how far its commands are from the Python
    controller's (Pa) and whether the phases agree."""
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.studies.control.controller import PHASES

    case = control_case(load_description())
    elf, _, objects = build(c_dir, case, build_dir)
    target = qemu_m4.run_qemu(elf)
    t = timing(target)
    functions, objects_size = code_size(elf, objects)
    results = [values(ln) for ln in control_lines(target)]
    commands = np.array([v[:2] for _, _, v in results])
    return {
        "shift": "2-3",
        "board": "QEMU mps2-an386 (Cortex-M4F), -icount shift=0",
        "flags": " ".join((*COMMON_FLAGS, *TARGET_FLAGS)),
        "calls": t.calls,
        "instructions_mean": round(t.mean),
        "instructions_max": round(t.largest),
        "budget": BUDGET,
        "code_bytes": sum(functions.values()),
        "functions": dict(sorted(functions.items())),
        "objects": objects_size,
        "command_difference_pa": float(np.max(np.abs(commands - case.commands))),
        "phases_agree": tuple(PHASES[p] for _, p, _ in results) == case.phases,
    }


def task_markdown(data: dict[str, Any], command: str) -> str:
    """The report's JSON (:func:`task_report`) as the documentation's table."""
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- `gearsym_control_{data['shift'].replace('-', '_')}_tcu_task` on {data['board']}, "
        f"float build (`{data['flags']}`), {data['calls']} calls along a closed-loop "
        f"{data['shift']} upshift of the Python controller",
        f"- its commands against the Python controller's on the same measurements: at most "
        f"{data['command_difference_pa']:.3g} Pa apart, phases "
        + ("the same at every tick" if data["phases_agree"] else "**differing**"),
        "",
        "| instructions per call (mean) | at most | budget | bytes of the linked functions "
        "and tables |",
        "|---|---|---|---|",
        f"| {data['instructions_mean']} | {data['instructions_max']} | {data['budget']} | "
        f"{data['code_bytes']} |",
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
    args = parser.parse_args(argv)
    missing = qemu_m4.missing_tools()
    if missing:
        print(f"{COMMAND}: not installed: {', '.join(missing)}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="gearsym-task-") as build_dir:
        data = task_report(Path(args.c_dir).resolve(), Path(build_dir))
    command = " ".join([COMMAND, *(argv if argv is not None else sys.argv[1:])])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{out.name}.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    (out / f"{out.name}.md").write_text(task_markdown(data, command), encoding="utf-8")
    print(
        f"{data['instructions_max']} instructions at most per task call (mean "
        f"{data['instructions_mean']}, budget {BUDGET}), {data['code_bytes']} bytes of code; "
        f"wrote {out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
