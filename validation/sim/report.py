"""Write a simulation's results: time series (CSV), phases, energy audit, checks and plots.

Commands write through :class:`gearsym.symbolic.io.output_dir.OutputDir` (a staging folder swapped
in only when complete), so a failure leaves no half-written output.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.io.output_dir import OutputDir
from gearsym.validation.sim.simulation_result import SimulationResult


def summary(result: SimulationResult) -> dict[str, Any]:
    """The machine-readable summary: phases, audit, model checks, solver statistics."""
    return {
        "scenario": result.scenario.name,
        "scenario_file": result.scenario.file,
        "shift": result.scenario.shift.name,
        "t_end_s": float(result.t[-1]),
        "samples": int(result.t.size),
        "phases": [p.to_dict() for p in result.phases],
        "energy_audit": result.audit.to_dict(),
        "model_checks": [c.to_dict() for c in result.checks],
        "solver": {"method": result.method, **{k: float(v) for k, v in result.stats.items()}},
        "final_ratio": float(result.signals["ratio"][-1]),
        "initial_ratio": float(result.signals["ratio"][0]),
    }


def write_outputs(
    d: GearboxDescription,
    result: SimulationResult,
    out: str | Path,
    plots: bool = True,
    speed_unit: str = "rad/s",
) -> list[Path]:
    """Write ``timeseries.csv``, ``phases.csv``, ``summary.json`` and the PNG plots as the
    new content of ``out`` (through :class:`OutputDir`: atomic, never over a directory gearsym
    did not write). Returns the final paths."""
    with OutputDir(out, "simulate") as staged:
        write_results(d, result, staged.path, plots, speed_unit)
        return staged.commit()


def write_results(
    d: GearboxDescription,
    result: SimulationResult,
    folder: Path,
    plots: bool = True,
    speed_unit: str = "rad/s",
) -> list[str]:
    """Write the simulation's files into the existing ``folder``; returns their names."""
    return _write_all(d, result, folder, plots, speed_unit)


def _write_all(
    d: GearboxDescription, result: SimulationResult, folder: Path, plots: bool, speed_unit: str
) -> list[str]:
    written = []
    keys = list(result.signals)
    with open(folder / "timeseries.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["t", *keys])
        columns = [result.signals[k] for k in keys]
        for i, t in enumerate(result.t):
            writer.writerow([f"{t:.6g}", *(f"{c[i]:.10g}" for c in columns)])
    written.append("timeseries.csv")
    with open(folder / "phases.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["phase", "t_start_s", "t_end_s", "criterion"])
        for p in result.phases:
            writer.writerow([p.name, f"{p.t_start:.6g}", f"{p.t_end:.6g}", p.criterion])
    written.append("phases.csv")
    (folder / "summary.json").write_text(json.dumps(summary(result), indent=2) + "\n")
    written.append("summary.json")
    if plots:
        written += plot_shift(d, result, folder, speed_unit)
    return written


#: Units the speed plots offer: (axis label, factor from rad/s).
SPEED_UNITS: dict[str, tuple[str, float]] = {
    "rad/s": ("rad/s", 1.0),
    "rpm": ("rpm", 60.0 / (2.0 * math.pi)),
}

#: Line styles cycled over the speeds of one axis, so that a line on top of another (ω_1 on ω_8
#: while they turn together) stays visible as a dashed line over a solid one.
LINE_STYLES = ("-", "--", "-.", ":")


def plot_shift(
    d: GearboxDescription,
    result: SimulationResult,
    folder: Path,
    speed_unit: str = "rad/s",
) -> list[str]:
    """Save :func:`shift_figures` as PNG files in ``folder``; returns their names."""
    from gearsym.validation.drawing.figures import save

    names = []
    for name, fig in shift_figures(d, result, speed_unit).items():
        save(fig, folder / name)
        names.append(name)
    return names


def vehicle_motion(d: GearboxDescription, result: SimulationResult) -> tuple[Any, Any]:
    """Vehicle acceleration a = r_dyn dω_C/dt (m/s², the wheel rolling, 2.49) and jerk da/dt
    (m/s³, central differences of the sampled acceleration: the model's state has no jerk)."""
    import numpy as np

    r_dyn = float(d.vehicle["r_dyn"].value)
    acceleration = r_dyn * np.asarray(result.signals["domega_C"], dtype=float)
    return acceleration, np.gradient(acceleration, result.t)


def shift_figures(
    d: GearboxDescription, result: SimulationResult, speed_unit: str = "rad/s"
) -> dict[str, Any]:
    """Figures 3.1–3.3 of the thesis (speeds and twist; accelerations and twist rate; torques,
    slips, T_In and T_res) and the vehicle's acceleration and jerk, by file name.

    Phase boundaries are vertical lines, phase names sit above the top axes, below the title.
    Speeds (and slips) in ``speed_unit`` (:data:`SPEED_UNITS`); overlapping speeds stay visible
    through distinct line styles (:data:`LINE_STYLES`).
    """
    from gearsym.validation.drawing.figures import subplots

    if speed_unit not in SPEED_UNITS:
        raise ValueError(f"speed_unit must be one of {tuple(SPEED_UNITS)}, got {speed_unit!r}")
    unit, factor = SPEED_UNITS[speed_unit]
    s, t = result.signals, result.t
    spec = result.scenario.shift
    measured = [f"omega_{m}" for m in d.measured_shafts if f"omega_{m}" in s]

    def phases(ax: Any) -> None:
        for p in result.phases[1:]:
            ax.axvline(p.t_start, color="0.6", lw=0.8, ls="--")
        ymax = ax.get_ylim()[1]
        for p in result.phases:
            ax.text((p.t_start + p.t_end) / 2, ymax, p.name, ha="center", va="bottom", fontsize=7)

    figures = {}
    # the suptitle sits at the top of the figure, the phase names on the top axes' upper edge:
    # top 0.88 keeps a line of text between them
    two_rows = {"top": 0.88, "bottom": 0.08, "hspace": 0.12, "left": 0.1}
    fig, axes = subplots(2, 1, (8, 6.5), two_rows, sharex=True)
    for k, key in enumerate([*measured, "omega_C"]):
        label = "ω_C (wheel)" if key == "omega_C" else f"ω_{key.removeprefix('omega_')}"
        style = LINE_STYLES[k % len(LINE_STYLES)]
        axes[0].plot(t, factor * s[key], label=label, ls=style)
    axes[0].set_ylabel(f"speed / ({unit})")
    axes[0].legend(fontsize=8, ncol=2)
    phases(axes[0])
    axes[1].plot(t, s["phi"], color="C3")
    axes[1].set_ylabel("side-shaft twist φ / rad")
    axes[1].set_xlabel("t / s")
    fig.suptitle(f"{result.scenario.name}: speeds and side-shaft twist (cf. thesis Fig. 3.1)")
    figures["fig_3_1_speeds.png"] = fig

    # Fig. 3.2 shows the accelerations and the side-shaft twist rate φ̇ (2.44); φ̇ is in rad/s,
    # so it gets its own axis below.
    fig, axes = subplots(2, 1, (8, 6.5), two_rows, sharex=True)
    keys = [key for key in [f"d{m}" for m in measured] + ["domega_C"] if key in s]
    for k, key in enumerate(keys):
        style = LINE_STYLES[k % len(LINE_STYLES)]
        axes[0].plot(t, s[key], label=f"dω_{key.removeprefix('domega_')}/dt", ls=style)
    axes[0].set_ylabel("acceleration / (rad/s²)")
    axes[0].legend(fontsize=8, ncol=2)
    phases(axes[0])
    axes[1].plot(t, s["dphi"], color="C3")
    axes[1].set_ylabel("side-shaft twist rate φ̇ / (rad/s)")
    axes[1].set_xlabel("t / s")
    fig.suptitle("accelerations and side-shaft twist rate (cf. thesis Fig. 3.2)")
    figures["fig_3_2_accelerations.png"] = fig

    fig, axes = subplots(2, 1, (8, 6.5), two_rows, sharex=True)
    for k, e in enumerate((spec.off_going, spec.on_coming)):
        axes[0].plot(t, s[f"T_{e}"], label=f"T_{e}", ls=LINE_STYLES[k])
    axes[0].plot(t, s["T_In"], label="T_In", color="k")
    axes[0].plot(t, s["T_res"], label="T_res", color="0.5")
    axes[0].set_ylabel("torque / (N·m)")
    axes[0].legend(fontsize=8, ncol=2)
    phases(axes[0])
    for k, e in enumerate((spec.off_going, spec.on_coming)):
        axes[1].plot(t, factor * s[f"slip_{e}"], label=f"Δω_{e}", ls=LINE_STYLES[k])
    axes[1].set_ylabel(f"slip speed / ({unit})")
    axes[1].set_xlabel("t / s")
    axes[1].legend(fontsize=8)
    fig.suptitle("transmitted torques, slip speeds, T_In and T_res (cf. thesis Fig. 3.3)")
    figures["fig_3_3_torques.png"] = fig

    # What a shift is judged by: the vehicle's longitudinal acceleration and its jerk.
    acceleration, jerk = vehicle_motion(d, result)
    fig, axes = subplots(2, 1, (8, 6.5), two_rows, sharex=True)
    axes[0].plot(t, acceleration, color="C0")
    axes[0].set_ylabel("vehicle acceleration / (m/s²)")
    phases(axes[0])
    axes[1].plot(t, jerk, color="C1")
    axes[1].set_ylabel("jerk / (m/s³)")
    axes[1].set_xlabel("t / s")
    fig.suptitle("vehicle acceleration r_dyn dω_C/dt and jerk (central differences)")
    figures["fig_vehicle_acceleration_jerk.png"] = fig
    return figures


def format_summary(result: SimulationResult) -> str:
    """Human-readable summary of a simulation."""
    lines = [
        f"{result.scenario.name} ({result.scenario.file})",
        f"  ratio ω_in/ω_out {result.signals['ratio'][0]:.3f} → {result.signals['ratio'][-1]:.3f}",
        "  phases (detected from the simulated slips and torques):",
    ]
    for p in result.phases:
        lines.append(f"    {p.name:<13} {p.t_start:7.4f} – {p.t_end:7.4f} s   {p.criterion}")
    a = result.audit
    lines.append("  energy audit (J):")
    for label, value in (
        ("input work", a.input_work),
        ("Δ kinetic energy", a.kinetic_change),
        ("Δ side-shaft spring energy", a.spring_change),
        ("Δ bristle energy", a.bristle_change),
        ("friction dissipation", a.friction_dissipation),
        ("side-shaft damper dissipation", a.damper_dissipation),
        ("road work", a.road_work),
    ):
        lines.append(f"    {label:<30} {value:14.6f}")
    lines.append(f"    {'residual':<30} {a.residual:14.3e}  (relative {a.relative_residual:.2e})")
    if result.checks:
        lines.append("  reduced models against the reference, inside their phase:")
        for c in result.checks:
            lines.append(
                f"    {c.model:<12} {c.phase:<10} max relative state error "
                f"{c.max_relative_error:.2e}"
            )
    st = result.stats
    lines.append(
        f"  {result.method}: {int(st.get('steps', 0))} steps, {int(st.get('nfev', 0))} f; "
        f"{st.get('wall_time_s', float('nan')):.2f} s"
    )
    return "\n".join(lines)
