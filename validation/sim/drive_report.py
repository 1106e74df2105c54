"""What ``gearsym drive`` prints and writes: the summary, the samples and shifts as CSV, and the
drive's figure (speed tracking, gear, torques, each shift's quality)."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.estimator_calibration import ENGINE_TORQUE_GAIN, STIFFNESS_FACTOR
from gearsym.validation.sim.drive import DriveResult

#: What a state the filter appends over a drive is, for the report.
APPENDED_MEANING = {
    STIFFNESS_FACTOR: "the side shafts' stiffness on the calibration's k_ss",
    ENGINE_TORQUE_GAIN: "the engine's true torque over its torque model's",
}

__all__ = [
    "drive_command",
    "drive_markdown",
    "format_drive_summary",
    "plot_drive",
    "write_drive",
]


def format_drive_summary(result: DriveResult) -> str:
    """The drive in a few lines: the cycle, tracking, shifts, energy audit, speed."""
    data = result.to_dict()
    cycle = data["cycle"]
    lines = [
        f"drive: {cycle['name']}, {cycle['duration_s']:.0f} s, {cycle['distance_km']:.2f} km, "
        f"at most {cycle['v_max_kmh']:.1f} km/h",
        f"  driven {data['distance_km']:.3f} km in {data['simulated_s']:.1f} s; speed tracking "
        f"RMS {data['tracking_rms_kmh']:.2f} km/h, worst {data['tracking_max_kmh']:.2f} km/h",
    ]
    shifts = result.shifts
    if shifts:
        ups = sum(1 for s in shifts if s.kind == "upshift")
        times = np.array([s.shift_time for s in shifts])
        jerks = np.array([s.peak_jerk for s in shifts])
        energy = np.array([s.friction_energy for s in shifts])
        lines.append(
            f"  {len(shifts)} shifts ({ups} up, {len(shifts) - ups} down), "
            f"{sum(1 for s in shifts if not s.completed)} not completed; shift time median "
            f"{np.nanmedian(times):.2f} s (max {np.nanmax(times):.2f} s), peak |jerk| median "
            f"{np.median(jerks):.1f} m/s³ (max {np.max(jerks):.1f}), friction energy median "
            f"{np.median(energy):.0f} J (max {np.max(energy):.0f} J)"
        )
    else:
        lines.append("  no shifts")
    w = result.works
    lines.append(
        f"  energy audit: input {w.input / 1e3:.1f} kJ = stored {(w.kinetic + w.spring) / 1e3:.1f}"
        f" + clutches {w.friction / 1e3:.2f} + damper {w.damper / 1e3:.2f} + road "
        f"{w.road / 1e3:.1f} + brake {w.brake / 1e3:.1f} kJ; residual {w.relative_residual:.1e}"
    )
    lines.append(
        f"  wall time {result.wall_s:.1f} s, {result.real_time_factor:.1f}x real time, one core ("
        + (
            "the Python reference simulation"
            if result.stats.get("reference")
            else "the fast drive: compiled gears and shifts"
        )
        + ")"
    )
    if result.failure:
        lines.append(f"  FAILED: {result.failure}")
    return "\n".join(lines)


def _csv(rows: list[list[object]]) -> str:
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    return buffer.getvalue()


def write_drive(result: DriveResult, folder: Path) -> list[str]:
    """drive.csv (every sample) and shifts.csv (every shift) into ``folder``."""
    s = result.samples
    keys = list(s)
    rows: list[list[object]] = [keys]
    for i in range(len(s["t"])):
        rows.append([result.gears[int(s[k][i])] if k == "gear" else f"{s[k][i]:.6g}" for k in keys])
    (folder / "drive.csv").write_text(_csv(rows))
    shift_rows: list[list[object]] = [
        [
            "shift",
            "kind",
            "t_start_s",
            "shift_time_s",
            "peak_jerk_m_s3",
            "friction_energy_J",
            "input_torque_Nm",
            "events",
            "completed",
        ]
    ]
    for r in result.shifts:
        shift_rows.append(
            [
                r.name,
                r.kind,
                f"{r.t_start:.3f}",
                f"{r.shift_time:.4f}",
                f"{r.peak_jerk:.3f}",
                f"{r.friction_energy:.1f}",
                f"{r.input_torque:.2f}",
                r.events,
                r.completed,
            ]
        )
    (folder / "shifts.csv").write_text(_csv(shift_rows))
    return ["drive.csv", "shifts.csv"]


def plot_drive(result: DriveResult, path: Path) -> Path:
    """Speed against the cycle, gear, engine/e-machine/brake torque, each shift's time, peak
    |jerk| and friction energy."""
    from gearsym.validation.drawing.figures import save, subplots

    s = result.samples
    fig, axes = subplots(
        5, 1, size=(10.0, 11.0), sharex=True, margins={"hspace": 0.25, "top": 0.95}
    )
    t = s["t"]
    axes[0].plot(t, s["v_ref"] * 3.6, color="0.6", lw=2.0, label="cycle")
    axes[0].plot(t, s["v"] * 3.6, color="C0", label="vehicle")
    axes[0].set_ylabel("v (km/h)")
    axes[0].legend(loc="upper left")
    axes[0].set_title(
        f"{result.cycle.name}: tracking RMS {result.tracking_rms_kmh:.2f} km/h, "
        f"{len(result.shifts)} shifts"
    )
    axes[1].step(t, [int(g) + 1 for g in s["gear"]], where="post", color="C1")
    axes[1].set_yticks(range(1, len(result.gears) + 1), result.gears)
    axes[1].set_ylabel("gear")
    axes[2].plot(t, s["T_engine"], label="engine")
    axes[2].plot(t, s["T_e_machine"], label="e-machine")
    axes[2].plot(t, -s["T_brake"] / 10.0, label="brake / 10 (at the wheel)")
    axes[2].set_ylabel("torque (N·m)")
    axes[2].legend(loc="upper left")
    starts = [r.t_start for r in result.shifts]
    axes[3].plot(starts, [r.peak_jerk for r in result.shifts], "o", ms=3, color="C3")
    axes[3].set_ylabel("peak |jerk| (m/s³)")
    axes[4].plot(starts, [r.friction_energy / 1e3 for r in result.shifts], "o", ms=3, color="C4")
    axes[4].set_ylabel("friction (kJ)")
    axes[4].set_xlabel("t (s)")
    return save(fig, path)


def drive_command(
    cycle: str, duration: float | None, fleet: str | None = None, seed: int = 0, runs: int = 1
) -> str:
    """The command line a drive's (or a fleet of drives') Markdown names as its writer
    (``fleet``: the argument of ``--fleet``, "" for the shipped fleet)."""
    extra = f" --duration {duration:g}" if duration is not None else ""
    if fleet is not None:
        extra += f" --fleet {fleet}".rstrip()
        extra += f" --runs {runs}" if runs > 1 else ""
        extra += f" --seed {seed}"
    return f"gearsym drive --cycle {cycle}{extra}"


def drive_markdown(data: dict[str, Any], command: str) -> str:
    """The drive's JSON as Markdown for the documentation, headed by the command that wrote it
    (the docs include this file; nobody types its numbers)."""
    cycle = data["cycle"]
    energy = data["energy"]
    shifts = data["shift_list"]
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- cycle {cycle['name']}: {cycle['duration_s']:.0f} s, {cycle['distance_km']:.3f} km, "
        f"at most {cycle['v_max_kmh']:.1f} km/h; driven {data['distance_km']:.3f} km",
        f"- speed tracking RMS {data['tracking_rms_kmh']:.2f} km/h, worst "
        f"{data['tracking_max_kmh']:.2f} km/h",
        f"- {data['shifts']} shifts, "
        f"{sum(1 for s in shifts if not s['completed'])} not completed"
        + (f"; failed: {data['failure']}" if data["failure"] else "")
        + (
            f"; record samples beyond the schedule's shift speeds with no shift made: "
            f"{data['missed_shifts']}"
            if "missed_shifts" in data
            else ""
        ),
        f"- energy audit residual {data['energy_residual']:.1e} of the losses (input "
        f"{energy['input_J'] / 1e3:.0f} kJ: road {energy['road_J'] / 1e3:.0f} kJ, clutches "
        f"{energy['friction_J'] / 1e3:.1f} kJ, damper {energy['damper_J'] / 1e3:.1f} kJ, brake "
        f"{energy['brake_J'] / 1e3:.1f} kJ, stored {energy['kinetic_change_J'] / 1e3:.1f} kJ)",
        f"- wall time {data['wall_s']:.0f} s ({data['real_time_factor']:.1f}x real time) on one "
        "core of the 2-core machine, building the shifts' models as the drive first needs them: "
        + (
            "the Python reference simulation (--reference)"
            if data.get("gear_integrator") == "reference"
            else "the fast drive (gears: compiled fixed-step RK4 per TCU tick; shifts: the "
            "hybrid simulation with its right-hand sides and guards as compiled C)"
        ),
        "",
        "Each kind of shift over the drive (open-loop shift plans from the calibration; jerk of "
        "the vehicle acceleration low-pass filtered at 10 Hz):",
        "",
        "| shift | count | shift time median (s) | peak jerk median / max (m/s³) "
        "| friction energy median / max (kJ) |",
        "|---|---|---|---|---|",
    ]
    names = sorted(
        {s["shift"] for s in shifts},
        key=lambda n: (shifts[[s["shift"] for s in shifts].index(n)]["kind"], n),
    )
    for name in names:
        group = [s for s in shifts if s["shift"] == name]
        times = np.array([s["shift_time_s"] for s in group])
        jerks = np.array([s["peak_jerk_m_s3"] for s in group])
        energies = np.array([s["friction_energy_J"] for s in group]) / 1e3
        out.append(
            f"| {name} | {len(group)} | {np.nanmedian(times):.2f} | "
            f"{np.median(jerks):.1f} / {np.max(jerks):.1f} | "
            f"{np.median(energies):.2f} / {np.max(energies):.2f} |"
        )
    if "estimates" in data:
        out += _estimates_markdown(data)
    return "\n".join(out) + "\n"


def _wheel_side_line(mass: dict[str, Any], vehicle: Any) -> list[str]:
    """For a fleet vehicle whose tyres differ from the calibration's: the final estimate
    against the wheel-side mass (:func:`~gearsym.validation.sim.fleet.wheel_side_mass`), what
    the filter can identify without a vehicle-speed source."""
    from gearsym.validation.sim.fleet import R_DYN_FACTOR, wheel_side_mass

    if not isinstance(vehicle, dict) or R_DYN_FACTOR not in vehicle:
        return []
    factor = vehicle[R_DYN_FACTOR]
    wheel = wheel_side_mass(mass["truth"], factor)
    return [
        f"- its tyres' r_dyn {factor:.4f} x the calibration's: the wheel-side mass "
        f"m_veh (r_dyn / r_dyn,cal)² is {wheel:.0f} kg, the final estimate's error against it "
        f"{100 * (mass['final'] - wheel) / wheel:+.1f} % (the filter sees wheel speeds, not the "
        "vehicle's: it identifies this product, docs/drive.md)"
    ]


def _estimates_markdown(data: dict[str, Any]) -> list[str]:
    """The EKF carried over the drive: m_veh and ζ against the truth, each μ when its element
    last slid, the filter's consistency."""
    est = data["estimates"]
    summary = data["estimator"]
    vehicle = data.get("vehicle")
    who = (
        f"fleet vehicle {vehicle['seed']}"
        if isinstance(vehicle, dict)
        else "the calibration's own vehicle"
    )
    m, z = est["m_veh"], est["zeta"]
    errors = ", ".join(
        f"{'end' if k == 'end' else k + ' s'} {100 * v:+.1f} %" for k, v in m["error_at"].items()
    )
    out = [
        "",
        f"The EKF carried over the drive ({who}; the TCU's view: commanded torque, "
        "noisy speeds, no grade sensor):",
        "",
        f"- m_veh {m['final']:.0f} ± {m['sigma']:.0f} kg, truth {m['truth']:.0f} kg; relative "
        f"error at {errors}",
        *_wheel_side_line(m, vehicle),
        f"- ζ {z['final']:+.4f} ± {z['sigma']:.4f} rad, truth {z['truth']:+.4f} rad at the end; "
        "RMS error "
        + ", ".join(
            f"{v:.4f} rad "
            + ("over the drive" if k == "all" else f"from {k.removeprefix('after_')} s on")
            for k, v in z["rms_rad"].items()
        ),
        *(
            f"- {name} {entry['final']:.4f} ± {entry['sigma']:.4f}, truth {entry['truth']:.4f} "
            "at the end" + (f" ({APPENDED_MEANING[name]})" if name in APPENDED_MEANING else "")
            for name, entry in est.items()
            if "truth" in entry and name not in ("m_veh", "zeta")
        ),
        f"- NEES/dof of (m_veh, ζ), time mean {summary['nees_per_dof_mean']:.2f} (samples "
        f"correlated: no band claimed); NIS/dof {summary['nis_per_dof']:.2f}; "
        f"{summary['held_samples']} of {summary['samples']} samples held (brake, standstill)",
        "",
        "| μ | truth when it last slid | estimate there | σ | samples sliding | slides | "
        "error / σ after its 3rd slide |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, entry in est.items():
        if "truth_last_sliding" not in entry:
            continue
        truth = entry["truth_last_sliding"]
        third = entry.get("after_third_slide")
        after = (
            "—"
            if third is None
            else f"{third['error']:+.4f} / {third['sigma']:.4f}"
            + ("" if third["inside_2_sigma"] else " (outside 2 σ)")
        )
        out.append(
            f"| {name} | {truth:.4f} | {truth + entry['error_last_sliding']:.4f} | "
            f"{entry['sigma_last_sliding']:.4f} | {entry['sliding_samples']} | "
            f"{entry.get('slides', '—')} | {after} |"
        )
    return out
