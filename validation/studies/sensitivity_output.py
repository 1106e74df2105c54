"""What a sensitivity run (:mod:`gearsym.validation.studies.sensitivity_run`) writes: the CSV of
x, S, S_N (3.3) and Ṡ per sample, and the figures like the thesis' Figures 3.4–3.8."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from gearsym.symbolic.parameters import symbol
from gearsym.validation.sim.phases import phase_of
from gearsym.validation.studies.sensitivity_run import SensitivityRun


def write_csv(run: SensitivityRun, path: Path) -> Path:
    """One row per sample: t, phase, x, and S, S_N, Ṡ for every state and parameter."""
    tr = run.trajectory
    norm = run.normalised
    header = ["t", "phase", *tr.state_names]
    for p in tr.parameter_names:
        for x in tr.state_names:
            header += [f"S_{x}__{p}", f"SN_{x}__{p}", f"dS_{x}__{p}"]
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for k, t in enumerate(tr.t):
            row: list[Any] = [f"{t:.6g}", phase_of(run.phases, t), *(f"{v:.9g}" for v in tr.x[k])]
            for j in range(len(tr.parameter_names)):
                for i in range(len(tr.state_names)):
                    row += [f"{tr.S[k, i, j]:.9g}", f"{norm[k, i, j]:.9g}", f"{tr.dS[k, i, j]:.9g}"]
            writer.writerow(row)
    return path


# plain Unicode labels: mathtext parsing and rendering was a large share of the plotting time
STATE_LABELS = {
    "omega_1": "ω₁",
    "omega_2": "ω₂",
    "phi": "φ",
    "omega_C": "ω_C",
}


def plot_sensitivities(run: SensitivityRun, out_dir: Path) -> list[Path]:
    """One PNG per parameter like Figures 3.4–3.8: normalised sensitivities S_N (3.3) of every
    state (left) and their time derivatives (right), phases marked."""
    from gearsym.validation.drawing.figures import save, subplots

    out_dir.mkdir(parents=True, exist_ok=True)
    tr = run.trajectory
    norm, rate = run.normalised, run.normalised_rate
    paths = []
    margins = {"left": 0.09, "right": 0.98, "bottom": 0.07, "top": 0.88, "hspace": 0.15}
    for j, p in enumerate(tr.parameter_names):
        fig, axes = subplots(
            len(tr.state_names), 2, (10, 8), margins | {"wspace": 0.28}, sharex=True, squeeze=False
        )
        for i, x in enumerate(tr.state_names):
            label = STATE_LABELS.get(x, x)
            for col, (data, what) in enumerate(
                ((norm[:, i, j], "S_N"), (rate[:, i, j], "dS_N/dt in 1/s"))
            ):
                ax = axes[i, col]
                ax.plot(tr.t, data, lw=1.0)
                ax.set_ylabel(f"{what} {label}")
                for phase in run.phases[1:]:
                    ax.axvline(phase.t_start, color="0.5", lw=0.6, ls="--")
        for col in range(2):
            axes[-1, col].set_xlabel("t in s")
        for k, phase in enumerate(run.phases):
            for col in range(2):
                axes[0, col].annotate(
                    phase.name,
                    ((phase.t_start + phase.t_end) / 2, 1.03 + 0.12 * (k % 2)),
                    xycoords=("data", "axes fraction"),
                    ha="center",
                    fontsize=7,
                )
        fig.suptitle(
            f"Normalised sensitivities of the states and their derivatives with respect to "
            f"{symbol(p)} (p0 = {run.scales[j]:g})",
            fontsize=10,
        )
        paths.append(save(fig, out_dir / f"sensitivity_{p}.png", dpi=120))
    return paths
