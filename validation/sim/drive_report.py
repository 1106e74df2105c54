"""What ``gearsym drive`` prints and writes: the summary, the samples and shifts as CSV, and the
drive's figure (speed tracking, gear, torques, each shift's quality)."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from gearsym.validation.sim.drive import DriveResult

__all__ = ["format_drive_summary", "plot_drive", "write_drive"]


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
        f"  wall time {result.wall_s:.1f} s, {result.real_time_factor:.1f}x real time "
        "(Python reference simulation, one core)"
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
