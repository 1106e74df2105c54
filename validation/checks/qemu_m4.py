"""The emitted C bare-metal on an emulated Cortex-M4F (QEMU ``mps2-an386``), against the host.

The harness in ``validation/checks/cortex_m4/`` (start-up with vector table and FPU enable, linker
script of the board's memory map, semihosting output, a driver) runs the emitted float EKF of
the 2-3 shift (predict + update, thesis 4.3, on the augmented model 4.1) along the reference
shift with noisy measurements, the emitted float extended UIO's ``euio_step`` (4.5) along the
run of :func:`gearsym.validation.checks.euio_check.reference_steps` (on its own state), and RK4
steps of the emitted 2-3 shift model (2.42-2.58) on the
reference simulation's torques. The same driver compiled for the host prints the same lines;
every float is printed as its bit pattern, so the two outputs are compared exactly.

Bitwise equality is a fair expectation because both builds evaluate the same C in IEEE single
precision (FLT_EVAL_METHOD 0 on x86-64 SSE and on the FPv4-SP; +, -, *, / and sqrt correctly
rounded on both), with ``-ffp-contract=off`` on both sides: in GNU C modes GCC would fuse a*b+c
into the M4F's vfma (one rounding instead of two); measured with ``-std=gnu99`` and no
``-ffp-contract=off``, 3088 of the 3151 result lines differ. (``-std=c99`` alone already
implies ``-ffp-contract=off``; the flag is stated so that a change of standard cannot undo it.)
The one part not equal by construction is ``sinf``/``cosf``: glibc's and newlib's (the fdlibm
float code, ``__kernel_sinf``) are different implementations and may differ in the last bit.
Their only argument here is the road grade ζ (0 in the shift model, the filter's estimate in
the EKF run): at most of its values they agree, but not at all (on one version of the filter
one estimate of ζ hit a value where they differ, and 114 of 9 153 lines then differed in P's
last bits from step 37 on). So the bitwise comparison builds both sides with the harness' own sine
and cosine (``build(..., same_trig=True)``, ``cortex_m4/harness_trig.c``, the way a team that
needs equality links one math library on both sides: ``-DGEARSYM_SIN=...``,
``-DGEARSYM_COS=...``), and the build with each side's own library (the benchmark's) is
compared within a float tolerance.

Timing: under ``qemu-system-arm -icount shift=0`` each instruction advances the virtual clock
by 1 ns; the driver reads SysTick (processor clock) around each step and calibrates the
instructions per tick with a loop of exactly two instructions per turn.
"""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

HARNESS_DIR = Path(__file__).parent / "cortex_m4"
TOOLS = ("arm-none-eabi-gcc", "arm-none-eabi-size", "arm-none-eabi-nm", "qemu-system-arm", "gcc")
COMMON_FLAGS: tuple[str, ...] = (
    "-std=c99",
    "-Wall",
    "-Wextra",
    "-Werror",
    "-O2",
    "-ffp-contract=off",
    "-DGEARSYM_SINGLE_PRECISION",
)
TARGET_FLAGS: tuple[str, ...] = (
    "-mcpu=cortex-m4",
    "-mfpu=fpv4-sp-d16",
    "-mfloat-abi=hard",
    "-mthumb",
    "-ffunction-sections",
    "-fdata-sections",
    "-DGEARSYM_M4_TARGET",
)
#: The emitted sources the driver links.
SOURCES = (
    "gearsym_ekf_2_3.c",
    "gearsym_euio_2_3.c",
    "gearsym_shift_2_3.c",
    "gearsym_shift_2_3_mu.c",
    "gearsym_full.c",
)
#: Tags of the RK4 result lines: the 2-3 shift model, its μ form, the full model.
RK4_TAGS = ("rk4", "rk4mu", "rk4full")
FULL_STATES = ("omega_1", "omega_2", "omega_3", "omega_8", "phi", "omega_C")
FULL_INPUTS = ("T_In", "T_K81", "T_K38", "T_B08", "T_B05", "T_B06", "T_K27")
CALIBRATION_TURNS = 100_000
EKF_SAMPLE_TIME = 0.01
EKF_R = (0.01, 0.01, 0.01)
EKF_FLOOR = (2.0, 0.7, 0.27)


class HarnessError(RuntimeError):
    """A build or the emulator failed."""


def missing_tools() -> list[str]:
    """The tools of :data:`TOOLS` that are not on PATH."""
    return [t for t in TOOLS if shutil.which(t) is None]


@dataclass
class Case:
    """The data the driver runs on, all in float32."""

    x0: np.ndarray
    P0: np.ndarray
    q: np.ndarray
    u: np.ndarray  # (steps, nu) inputs of the augmented model at each sample
    y: np.ndarray  # (steps, 3) measurements (NaN: a dropout)
    shift_x0: np.ndarray
    shift_u: np.ndarray  # (steps, 3) T_In, T_K38, T_B05
    shift_h: float
    mu_u: np.ndarray  # (steps, 3) T_In, F_N38, F_N05
    full_x0: np.ndarray
    full_u: np.ndarray  # (steps, 7) T_In and the six element torques
    full_truth: np.ndarray  # (steps + 1, 6)
    truth: np.ndarray  # (samples, 8) the augmented state along the shift, at the EKF samples
    shift_truth: np.ndarray  # (steps + 1, 4) the reference simulation's 2-3 model states
    # the extended UIO (4.5) of the 2-3 shift: validation/checks/euio_check.py's run (float32)
    euio_x0: np.ndarray  # (7,)
    euio_P0: np.ndarray  # (7, 7)
    euio_q: np.ndarray
    euio_r: np.ndarray
    euio_floor: np.ndarray
    euio_u: np.ndarray  # (samples, 7) inputs with the reference's element modes
    euio_y: np.ndarray  # (samples, 3) measurements (NaN: a dropout)
    euio_held: np.ndarray  # (samples, 7) 1.0 where a state is held over the step into k
    euio_library: np.ndarray  # (samples - 1, 7) the library's double estimate after each step
    euio_library_sigma: np.ndarray  # (samples - 1, 7) its σ
    euio_truth: np.ndarray  # (samples - 1, 7) the truth after each step (NaN where none)


def reference_case(description: Any, seed: int = 11, noise: float = 0.01) -> Case:
    """The reference shift (built-in scenario) sampled for the EKF at 10 ms with relative
    measurement noise ``noise`` (and a dropout of the second speed sensor every 17th sample),
    started from the reference filter's first estimate; and the reference simulation's torques
    and normal forces for the 2-3 shift model (torque and μ form) and the full model at the
    simulation's own step."""
    from gearsym.symbolic.estimators.ekf import augmented_model
    from gearsym.validation.checks.euio_check import reference_steps
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.loop import run_ekf
    from gearsym.validation.studies.estimation.modes import element_modes

    result = simulate(description, load_scenario(description, None))
    aug = augmented_model(description, "2-3")
    run = run_ekf(description, result, sample_time=EKF_SAMPLE_TIME, seed=3, aug=aug)
    modes = element_modes(description, result, run.t)
    columns = []
    for name in aug.input_names:
        if name.startswith(("slide_", "stick_")):
            element = name.split("_", 1)[1]
            columns.append(modes[element][0 if name.startswith("slide_") else 1])
        else:
            columns.append(np.interp(run.t, result.t, result.signals[name]))
    rng = np.random.default_rng(seed)
    y = run.truth[:, [0, 1, 3]] * (1 + noise * rng.normal(size=(len(run.t), 3)))
    y[::17, 1] = np.nan
    f32 = np.float32
    shift_states = ("omega_1", "omega_2", "phi", "omega_C")
    shift_truth = np.column_stack([result.signals[n] for n in shift_states])
    full_truth = np.column_stack([result.signals[n] for n in FULL_STATES])
    euio = reference_steps(description, result=result)
    s = euio.setup.ekf
    euio_held = np.zeros((len(s.t), len(s.names)))
    euio_y = np.full((len(s.t), len(s.outputs)), np.nan)
    for k, st in enumerate(euio.steps, start=1):
        euio_held[k], euio_y[k] = st.held, st.y
    scored = s.scored[1:]
    return Case(
        x0=np.asarray(run.estimates[0], dtype=f32),
        P0=np.diag(np.asarray(run.sigmas[0]) ** 2).astype(f32),
        q=np.array([aug.intensities[n] for n in aug.state_names], dtype=f32),
        u=np.column_stack(columns).astype(f32),
        y=y.astype(f32),
        shift_x0=shift_truth[0].astype(f32),
        shift_u=np.column_stack([result.signals[n] for n in ("T_In", "T_K38", "T_B05")])[
            :-1
        ].astype(f32),
        shift_h=float(result.t[1] - result.t[0]),
        mu_u=np.column_stack([result.signals[n] for n in ("T_In", "F_N38", "F_N05")])[:-1].astype(
            f32
        ),
        full_x0=full_truth[0].astype(f32),
        full_u=np.column_stack([result.signals[n] for n in FULL_INPUTS])[:-1].astype(f32),
        full_truth=full_truth,
        truth=run.truth,
        shift_truth=shift_truth,
        euio_x0=np.asarray(euio.steps[0].z, dtype=f32),
        euio_P0=np.asarray(euio.steps[0].P, dtype=f32),
        euio_q=euio.q.astype(f32),
        euio_r=euio.r.astype(f32),
        euio_floor=euio.floor.astype(f32),
        euio_u=np.asarray(s.u, dtype=f32),
        euio_y=euio_y.astype(f32),
        euio_held=euio_held.astype(f32),
        euio_library=np.array([st.result.z for st in euio.steps]),
        euio_library_sigma=np.array([np.sqrt(np.diag(st.result.P)) for st in euio.steps]),
        euio_truth=np.where(scored, s.truth[1:], np.nan),
    )


def _literal(v: float) -> str:
    """Exact C literal of a float32 (hex float; NaN as 0.0f/0.0f is not constant: use NAN)."""
    v = float(np.float32(v))
    if np.isnan(v):
        return "NAN"
    return f"{v.hex()}f"


def _array(name: str, a: np.ndarray) -> str:
    a = np.asarray(a)
    if a.ndim == 1:
        return f"static const float {name}[{len(a)}] = {{{', '.join(map(_literal, a))}}};\n"
    rows = ",\n    ".join("{" + ", ".join(map(_literal, r)) + "}" for r in a)
    return f"static const float {name}[{a.shape[0]}][{a.shape[1]}] = {{\n    {rows}}};\n"


def case_header(case: Case) -> str:
    """``case_data.h``: the case as exact float literals (P column-major)."""
    parts = [
        "/* Data of gearsym's Cortex-M4F driver (gearsym.validation.checks.qemu_m4). */\n",
        "#ifndef CASE_DATA_H\n#define CASE_DATA_H\n#include <math.h>\n",
        f"#define CASE_EKF_STEPS {len(case.u)}\n",
        f"#define CASE_SHIFT_STEPS {len(case.shift_u)}\n",
        f"#define CASE_CALIBRATION_TURNS {CALIBRATION_TURNS}u\n",
        f"#define CASE_H {_literal(EKF_SAMPLE_TIME)}\n",
        f"#define CASE_SHIFT_H {_literal(case.shift_h)}\n",
        _array("case_x0", case.x0),
        _array("case_P0", case.P0.ravel(order="F")),
        _array("case_q", case.q),
        _array("case_r", np.array(EKF_R)),
        _array("case_floor", np.array(EKF_FLOOR)),
        _array("case_u", case.u),
        _array("case_y", case.y),
        _array("case_shift_x0", case.shift_x0),
        _array("case_shift_u", case.shift_u),
        _array("case_mu_u", case.mu_u),
        _array("case_full_x0", case.full_x0),
        _array("case_full_u", case.full_u),
        f"#define CASE_EUIO_STEPS {len(case.euio_u)}\n",
        _array("case_euio_x0", case.euio_x0),
        _array("case_euio_P0", case.euio_P0.ravel(order="F")),
        _array("case_euio_q", case.euio_q),
        _array("case_euio_r", case.euio_r),
        _array("case_euio_floor", case.euio_floor),
        _array("case_euio_u", case.euio_u),
        _array("case_euio_y", case.euio_y),
        _array("case_euio_held", case.euio_held),
        "#endif\n",
    ]
    return "".join(parts)


def _run(cmd: list[str], cwd: Path) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if proc.returncode or proc.stderr.strip():
        raise HarnessError(f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}")
    return proc.stdout


def build_target(
    sources: list[Path], includes: list[Path], elf: Path, extra: tuple[str, ...] = ()
) -> Path:
    """Link ``sources`` with the harness' start-up into ``elf`` for the mps2-an386 board
    (no start files of newlib; its libm and libc only for sinf, cosf, memcpy)."""
    harness = HARNESS_DIR
    _run(
        [
            "arm-none-eabi-gcc",
            *COMMON_FLAGS,
            *TARGET_FLAGS,
            *extra,
            *(f"-I{d}" for d in (*includes, harness)),
            "-nostartfiles",
            "-T",
            str(harness / "mps2_an386.ld"),
            "-Wl,--gc-sections",
            "-o",
            str(elf),
            str(harness / "startup.c"),
            *map(str, sources),
            "-lm",
            "-lc",
            "-lgcc",
        ],
        elf.parent,
    )
    return elf


#: Both builds take the harness' own sine and cosine (``cortex_m4/harness_trig.c``: +, -, *
#: only) instead of their C libraries' sinf/cosf: what the bitwise comparison needs.
SAME_TRIG_FLAGS: tuple[str, ...] = (
    "-include",
    str(HARNESS_DIR / "harness_trig.h"),
    "-DGEARSYM_SIN(a)=gearsym_m4_sinf(a)",
    "-DGEARSYM_COS(a)=gearsym_m4_cosf(a)",
)


def build(c_dir: Path, case: Case, out: Path, same_trig: bool = False) -> tuple[Path, Path]:
    """Write the case into ``out`` and build the driver with the emitted sources of ``c_dir``
    twice: the ELF for the mps2-an386 board and the host executable. Returns both paths.

    ``same_trig``: both builds use the harness' sine and cosine (:data:`SAME_TRIG_FLAGS`), so
    every result is equal by construction; otherwise each links its own C library's
    sinf/cosf (newlib on the target, glibc on the host), as a TCU build would."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "case_data.h").write_text(case_header(case), encoding="utf-8")
    sources = [c_dir / s for s in SOURCES]
    trig = SAME_TRIG_FLAGS if same_trig else ()
    if same_trig:
        sources.append(HARNESS_DIR / "harness_trig.c")
    elf = build_target(
        [HARNESS_DIR / "driver.c", *sources], [out, c_dir], out / "gearsym_m4.elf", trig
    )
    host = out / "gearsym_host"
    _run(
        [
            "gcc",
            *COMMON_FLAGS,
            *trig,
            *(f"-I{d}" for d in (out, c_dir, HARNESS_DIR)),
            "-o",
            str(host),
            str(HARNESS_DIR / "host.c"),
            str(HARNESS_DIR / "driver.c"),
            *map(str, sources),
            "-lm",
        ],
        out,
    )
    return elf, host


def run_qemu(elf: Path, timeout: float = 120.0) -> str:
    """Run ``elf`` on QEMU's mps2-an386 with semihosting and ``-icount shift=0``; its output."""
    cmd = [
        "qemu-system-arm",
        "-M",
        "mps2-an386",
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
        "-icount",
        "shift=0",
        "-kernel",
        str(elf),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    # QEMU writes the semihosting console (SYS_WRITE0) to its stderr
    if proc.returncode != 0 or not proc.stderr.rstrip().endswith("done"):
        raise HarnessError(f"{' '.join(cmd)}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return proc.stderr


def run_host(exe: Path) -> str:
    """Run the host build of the driver; its output."""
    return _run([str(exe)], exe.parent)


def result_lines(text: str) -> list[str]:
    """The lines holding results (EKF and RK4 steps), in order."""
    tags = ("ekf ", "euio ", *(t + " " for t in RK4_TAGS))
    return [ln for ln in text.splitlines() if ln.startswith(tags)]


def floats(line: str) -> np.ndarray:
    """The float32 values of a result line (after its tag and step counters)."""
    words = line.split()
    skip = 3 if words[0] in ("ekf", "euio") else 2
    bits = np.array([int(w, 16) for w in words[skip:]], dtype=np.uint32)
    return bits.view(np.float32).astype(float)


@dataclass
class Timing:
    """Instructions measured on the emulated target (SysTick under ``-icount shift=0``)."""

    instructions_per_tick: float
    ekf_predict: float  # instructions per call
    ekf_update: float
    rk4: float
    rk4mu: float
    rk4full: float
    ekf_steps: int
    rk4_steps: int
    euio: float  # instructions per EUIO step (euio_step: predict, decoupling, update)
    euio_steps: int

    @property
    def ekf_step(self) -> float:
        return self.ekf_predict + self.ekf_update


def reports(text: str) -> dict[str, int]:
    """The target's report lines (``name hex``) by name."""
    found = {}
    for ln in text.splitlines():
        words = ln.split()
        if len(words) == 2 and words[0] not in ("ekf", "euio", *RK4_TAGS):
            found[words[0]] = int(words[1], 16)
    return found


def instructions(text: str, name: str, calls: int) -> float:
    """Instructions per call of the region reported as ``name`` (SysTick ticks over ``calls``
    calls, by the calibrated instructions per tick, less one read of SysTick)."""
    v = reports(text)
    per_tick = 2 * CALIBRATION_TURNS / v["calibration"]
    return v[name] * per_tick / calls - v["empty64"] * per_tick / 64 / calls


def timing(text: str) -> Timing:
    """Instructions per step from the target's report lines: SysTick ticks times the
    calibrated instructions per tick, less the cost of reading SysTick (``empty64``); the
    EKF steps are timed one by one (one read each), the RK4 steps as one loop."""
    v = reports(text)
    per_tick = 2 * CALIBRATION_TURNS / v["calibration"]
    read = v["empty64"] * per_tick / 64
    n_ekf, n_rk4 = v["ekf_steps"], v["rk4_steps"]
    return Timing(
        instructions_per_tick=per_tick,
        ekf_predict=v["ekf_predict"] * per_tick / n_ekf - read,
        ekf_update=v["ekf_update"] * per_tick / n_ekf - read,
        rk4=instructions(text, "rk4_total", n_rk4),
        rk4mu=instructions(text, "rk4mu_total", n_rk4),
        rk4full=instructions(text, "rk4full_total", n_rk4),
        ekf_steps=n_ekf,
        rk4_steps=n_rk4,
        euio=v["euio_step"] * per_tick / v["euio_steps"] - read,
        euio_steps=v["euio_steps"],
    )


def function_sizes(elf: Path, prefixes: tuple[str, ...]) -> dict[str, int]:
    """Bytes of code of each function of the linked ELF whose name starts with one of
    ``prefixes`` (``arm-none-eabi-nm --size-sort``)."""
    out = _run(["arm-none-eabi-nm", "-S", "--size-sort", str(elf)], elf.parent)
    sizes = {}
    for ln in out.splitlines():
        parts = ln.split()
        if len(parts) == 4 and parts[2] in "tT" and parts[3].startswith(prefixes):
            sizes[parts[3]] = int(parts[1], 16)
    return sizes
