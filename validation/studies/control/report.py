"""What ``gearsym control`` writes: the comparison as Markdown (headed by its command), the
metrics over the shift sequence per strategy, and one shift's commands, speeds, torque and
jerk per strategy."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["control_command", "control_markdown", "plot_control_sequence", "plot_control_shift"]


def control_command(
    fixes: Sequence[str],
    shift_or_scenario: str | None,
    fleet: str | None,
    strategies: str,
    shifts: int,
    runs: int,
    seed: int,
) -> str:
    """The command line that reproduces a study (named in what it writes)."""
    parts = ["gearsym control"]
    if shift_or_scenario:
        parts.append(f"--scenario {shift_or_scenario}")
    if fleet is not None:
        parts.append("--fleet" if not fleet else f"--fleet {fleet}")
    parts += [f"--fix {item}" for item in fixes]
    parts += [
        f"--strategies {strategies}",
        f"--shifts {shifts}",
        f"--runs {runs}",
        f"--seed {seed}",
    ]
    return " ".join(parts)


def _f(value: Any, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}g}"


def _failed_lines(data: dict[str, Any]) -> list[str]:
    """A line per vehicle the simulation could not carry through (left out of every
    statistic below)."""
    failed = data.get("vehicles_failed") or []
    if not failed:
        return []
    return [
        f"- **{len(failed)} more vehicle(s) failed** and are left out of every number below:",
        *(f"  - seed {f['seed']}: {f['reason']}" for f in failed),
    ]


def control_markdown(data: dict[str, Any], command: str) -> str:
    """The study's comparison table for the documentation."""
    point = data["operating_point"]
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- {data['vehicles']} vehicles of the {data['fleet']} fleet (seeds "
        f"{data['seeds'][0]}-{data['seeds'][-1]}), each shifting {data['shift']} "
        f"{data['shifts_per_vehicle']} times in a row per strategy from "
        f"{point['vehicle_speed_m_s']:.1f} m/s with {point['engine_Nm']:.0f} + "
        f"{point['e_machine_Nm']:.0f} N·m commanded",
        *_failed_lines(data),
        "- the truth per vehicle: the fleet's mass, grade, inertias, stiffness, μ factor (the "
        "μ reset), engine and e-machine torque errors, valve gain and offset, fill-time error; "
        "the TCU knows the calibration and what it measures; only the oracle is told the truth",
        "- p95 over the vehicles at each shift; |jerk| peak per shift (10 Hz filtered, m/s³); "
        "VDV of the ISO 2631-1 W_d-weighted acceleration (m/s^1.75); friction energy of both "
        "swapping elements (J); duration error of the inertia phase against its target "
        "(relative); tie-up: the off-going element held against the on-coming one (its torque "
        "reversed by more than 5 %); dips: output torque more than 5 % below the to-gear's "
        "steady torque, the side shafts' torsional swing included",
        "",
        "| strategy | shift | p95 peak jerk | mean peak jerk | p95 VDV | p95 friction energy | "
        "p95 duration error | flares | tie-ups | dips | failed |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, entry in data["strategies"].items():
        rows = entry["per_shift"]
        shown = sorted({0, 1, len(rows) // 2, len(rows) - 1} & set(range(len(rows))))
        for i in shown:
            r = rows[i]
            out.append(
                f"| {name} | {r['shift']} | {_f(r['jerk_p95'])} | {_f(r['jerk_mean'])} | "
                f"{_f(r['vdv_p95'])} | {_f(r['friction_energy_p95'], 4)} | "
                f"{_f(r['duration_error_p95'], 2)} | {r['flares']} | {r['tie_ups']} | "
                f"{r['output_dips']} | {r['failed']} |"
            )
    out += [
        "",
        "| strategy | shifts to a duration error under 10 % three in a row: median | p95 | never "
        "| within 10 % of the oracle (p95 jerk and energy) from shift |",
        "|---|---|---|---|---|",
    ]
    for name, entry in data["strategies"].items():
        c = entry["shifts_to_converge"]
        near = entry["near_oracle_from_shift"]
        out.append(
            f"| {name} | {_f(c['median'])} | {_f(c['p95'])} | {c['never']} | "
            f"{'—' if near is None else near} |"
        )
    return "\n".join(out) + "\n"


_STYLE = {"fixed": "tab:gray", "rule": "tab:orange", "estimator": "tab:blue", "oracle": "k"}


def plot_control_sequence(data: dict[str, Any], path: Any) -> Any:
    """p95 |jerk|, p95 friction energy, p95 |duration error| and flares + tie-ups over the
    shift sequence, one line per strategy."""
    from gearsym.validation.drawing.figures import save, subplots

    fig, axes = subplots(2, 2, size=(10.0, 6.5))
    panels = (
        ("jerk_p95", "p95 |jerk| (m/s³)"),
        ("friction_energy_p95", "p95 friction energy (J)"),
        ("duration_error_p95", "p95 |duration error|"),
        ("flares+tie_ups", "flares + tie-ups (vehicles)"),
    )
    for ax, (key, label) in zip(np.ravel(axes), panels, strict=True):
        for name, entry in data["strategies"].items():
            rows = entry["per_shift"]
            x = [r["shift"] for r in rows]
            if key == "flares+tie_ups":
                y = [r["flares"] + r["tie_ups"] for r in rows]
            else:
                y = [np.nan if r[key] is None else min(r[key], 1e9) for r in rows]
            ax.plot(x, y, marker="o", ms=3, label=name, color=_STYLE.get(name))
        ax.set_xlabel("shift of the sequence")
        ax.set_ylabel(label)
    np.ravel(axes)[0].legend(loc="upper right")
    fig.suptitle(
        f"{data['shift']}: {data['vehicles']} vehicles x {data['shifts_per_vehicle']} shifts"
    )
    return save(fig, path)


def plot_control_shift(traces: dict[str, Any], title: str, path: Any) -> Any:
    """One shift per strategy: the on-coming and off-going pressure commands, the input
    speed, the output torque and the jerk."""
    from gearsym.validation.drawing.figures import save, subplots

    fig, axes = subplots(4, 1, size=(9.0, 9.0))
    for name, trace in traces.items():
        color = _STYLE.get(name)
        axes[0].step(
            trace["ticks"],
            np.asarray(trace["p_on"]) / 1e5,
            where="post",
            color=color,
            label=f"{name} on-coming",
        )
        axes[0].step(
            trace["ticks"], np.asarray(trace["p_off"]) / 1e5, where="post", color=color, ls=":"
        )
        axes[1].plot(trace["t"], trace["omega_in"], color=color, label=name)
        axes[2].plot(trace["t"], trace["output_torque"], color=color)
        axes[3].plot(trace["t"], trace["jerk"], color=color)
    axes[0].set_ylabel("command (bar)")
    axes[0].set_ylim(0, 6)
    axes[1].set_ylabel("ω_in (rad/s)")
    axes[2].set_ylabel("output torque (N·m)")
    axes[3].set_ylabel("jerk (m/s³)")
    axes[3].set_xlabel("t (s), from the shift command")
    axes[0].legend(loc="upper right", fontsize=7)
    axes[0].set_title(title)
    return save(fig, path)
