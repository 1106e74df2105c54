"""The estimators' figures: the estimates against the truth with ±3σ and the phases shaded
(UIO, EKF, EUIO), and the EKF's efficiency against its bound.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.parameters import axis_label, symbol
from gearsym.validation.sim.phases import Phase
from gearsym.validation.studies.estimation.euio import EuioRun
from gearsym.validation.studies.estimation.loop import EkfRun
from gearsym.validation.studies.estimation.montecarlo import EkfMonteCarlo
from gearsym.validation.studies.estimation.uio import UioRun

__all__ = [
    "plot_efficiency",
    "plot_ekf",
    "plot_uio",
]


def plot_uio(run: UioRun, out_dir: Path) -> list[Path]:
    """The unknown input's estimate against the reference, and the unmeasured state φ, with
    the phases shaded and the UIO's existence per phase in the legend."""
    from gearsym.validation.drawing.figures import save, subplots

    fig, axes = subplots(2, 1, (8, 6), {"top": 0.9, "bottom": 0.08, "hspace": 0.15}, sharex=True)
    for k, phase in enumerate(run.phases):
        for ax in axes:
            ax.axvspan(phase.t_start, phase.t_end, color="0.93" if k % 2 else "0.85", lw=0)
        verdict = "UIO" if phase.existence and phase.existence.exists else "no UIO"
        axes[0].annotate(
            f"{phase.phase}\n({verdict})",
            ((phase.t_start + phase.t_end) / 2, 1.02),
            xycoords=("data", "axes fraction"),
            ha="center",
            fontsize=7,
        )
    for name in run.inputs:
        axes[0].plot(run.t, run.input_truth[name], color="k", lw=1.2, label=f"{name} (reference)")
        axes[0].plot(run.t, run.inputs[name], color="C1", lw=0.9, label=f"{name} (UIO)")
    truth = run.input_truth[run.unknown[0]]
    span = float(np.nanmax(np.abs(truth))) if truth.size else 1.0
    axes[0].set_ylim(-0.5 * span, 2.5 * span)  # the lock-up transient would hide the rest
    axes[0].set_ylabel("unknown input / (N·m)")
    axes[0].legend(fontsize=7, loc="upper left")
    axes[1].plot(run.t, run.truth[naming.TWIST], color="k", lw=1.2, label="φ (reference)")
    axes[1].plot(run.t, run.states[naming.TWIST], color="C0", lw=0.9, label="φ (UIO, unmeasured)")
    axes[1].set_ylabel("side-shaft twist φ / rad")
    axes[1].set_xlabel("t / s")
    axes[1].legend(fontsize=7, loc="upper left")
    fig.suptitle(
        f"Unknown input observer (4.4), shift {run.shift}, samples every "
        f"{run.sample_time * 1e3:g} ms{', noisy speeds (3.26)' if run.noise else ''}",
        fontsize=10,
    )
    return [save(fig, out_dir / "uio.png")]


def shade_phases(axes: Sequence[Any], phases: Sequence[Phase]) -> None:
    """Shade each phase on every axis and name it above the first; short phases sit side by
    side, so their names alternate between two heights and never overlap."""
    for ax in axes:
        for k, phase in enumerate(phases):
            ax.axvspan(phase.t_start, phase.t_end, color="0.93" if k % 2 else "0.85", lw=0)
    for k, phase in enumerate(phases):
        axes[0].annotate(
            phase.name,
            ((phase.t_start + phase.t_end) / 2, 1.03 + 0.1 * (k % 2)),
            xycoords=("data", "axes fraction"),
            ha="center",
            fontsize=7,
        )


def _parameter_panels(run: Any) -> tuple[Any, Any, list[str]]:
    """One panel per augmented parameter of a filter's run and one below, phases shaded."""
    from gearsym.validation.drawing.figures import subplots

    names = [p.name for p in run.parameters]
    fig, axes = subplots(
        len(names) + 1,
        1,
        (8, 2.0 * (len(names) + 1)),
        {"top": 0.93, "bottom": 0.05, "hspace": 0.12, "left": 0.1},
        sharex=True,
    )
    shade_phases(axes, run.phases)
    return fig, axes, names


def _estimate_band(ax: Any, run: Any, j: int, label: str) -> tuple[np.ndarray, np.ndarray]:
    """State j's estimate with its ±3σ band; returns it and the truth where scored."""
    est, sig = run.estimates[:, j], run.sigmas[:, j]
    ax.fill_between(run.t, est - 3 * sig, est + 3 * sig, color="C0", alpha=0.2, lw=0)
    ax.plot(run.t, est, color="C0", label=f"{label} estimate ±3σ")
    return est, np.where(run.scored[:, j], run.truth[:, j], np.nan)


def plot_ekf(run: EkfRun, path: Path) -> Path:
    """Each augmented parameter's estimate against the truth with ±3σ, the phases shaded, and
    the NEES against its per-sample 95 % χ² interval."""
    from gearsym.validation.drawing.figures import save
    from scipy.stats import chi2

    fig, axes, names = _parameter_panels(run)
    for ax, name in zip(axes, names, strict=False):
        j = run.state_names.index(name)
        est, truth = _estimate_band(ax, run, j, "EKF")
        ax.plot(run.t, truth, color="k", lw=1.2, label="reference (where defined)")
        if name.startswith("mu_"):
            ax.plot(run.t, run.truth[:, j], color="k", lw=0.6, ls=":", label="reference μ map")
        finite = truth[np.isfinite(truth)]
        centre = float(np.median(finite)) if finite.size else float(np.median(est))
        spread = max(float(np.max(np.abs(est - centre))) * 1.3, 1e-3)
        ax.set_ylim(centre - spread, centre + spread)
        ax.set_ylabel(axis_label(name))
        ax.legend(fontsize=6, loc="upper right")
    ax = axes[-1]
    lo = chi2.ppf(0.025, run.nees_dof)
    hi = chi2.ppf(0.975, run.nees_dof)
    ax.fill_between(run.t, lo, hi, color="C2", alpha=0.2, lw=0, label="95 % χ² interval")
    ax.plot(run.t, run.nees, color="C3", lw=0.8, label=f"NEES (mean {run.nees_mean:.2f})")
    ax.set_yscale("log")
    ax.set_ylabel("NEES")
    ax.set_xlabel("t / s")
    ax.legend(fontsize=6, loc="upper right")
    noise = ", ".join(f"{v:g}" for v in sorted(set(run.relative_noise)))
    fig.suptitle(
        f"EKF (4.3) on the augmented {run.shift} shift model (4.1): samples every "
        f"{run.sample_time * 1e3:g} ms, speed noise r = {noise} (3.26), seed {run.seed}",
        fontsize=10,
    )
    return save(fig, path)


def plot_efficiency_bars(
    names: Sequence[str],
    phases: Sequence[str],
    phase_stats: Mapping[str, Mapping[str, Any]],
    ylabel: str,
    title: str,
    path: Path,
    height: float = 4.4,
    top: float = 0.82,
) -> Path:
    """Every filter's efficiency figure: RMSE / bound per parameter and phase as bars (a
    phase in which the parameter is not identifiable is left empty and labelled "n.i."), ◆
    the efficiency against the bound with the filter's process noise, the line at 1 the
    bound. ``phase_stats[phase][name]`` has ``identifiable``, ``efficiency`` and
    ``efficiency_process``."""
    from gearsym.validation.drawing.figures import save, subplots

    fig, ax = subplots(1, 1, (8, height), {"top": top, "bottom": 0.1, "left": 0.08, "right": 0.98})
    width = 0.8 / len(phases)
    marked = False
    for i, phase in enumerate(phases):
        for j, name in enumerate(names):
            s = phase_stats[phase][name]
            x = j + (i - (len(phases) - 1) / 2) * width
            if s.identifiable and s.efficiency is not None:
                ax.bar(x, s.efficiency, width * 0.9, color=f"C{i}", label=phase if j == 0 else None)
                ax.plot(
                    x,
                    s.efficiency_process,
                    "kD",
                    ms=4,
                    label="against the bound with the filter's process noise"
                    if not marked
                    else None,
                )
                marked = True
                ax.annotate(
                    f"{s.efficiency:.2f}", (x, s.efficiency), ha="center", va="bottom", fontsize=6
                )
            else:
                ax.annotate("n.i.", (x, 0.05), ha="center", va="bottom", fontsize=6, rotation=90)
                if j == 0:
                    ax.bar(x, 0, width * 0.9, color=f"C{i}", label=phase)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="the bound (efficiency 1)")
    ax.set_xticks(range(len(names)), [symbol(n) for n in names])
    ax.set_xlim(-0.5, len(names) - 0.5)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=6, loc="upper left", ncol=3)
    fig.suptitle(title, fontsize=9)
    return save(fig, path)


def plot_efficiency(mc: EkfMonteCarlo, path: Path) -> Path:
    """Efficiency RMSE / posterior bound per parameter and phase (:func:`plot_efficiency_bars`)."""
    first = mc.first
    title = (
        f"EKF efficiency, {first.shift} shift, {len(mc.runs)} runs, samples every "
        f"{first.sample_time * 1e3:g} ms (n.i.: not identifiable in this phase)\n"
        "bars: RMSE / bound for constant parameters (the filter's random walks make > 1 "
        "expected)\n◆: RMSE / bound with the filter's process noise; initial estimates "
        + (
            "drawn from the prior"
            if mc.prior_draw
            else "fixed (< 1 possible while the prior rules)"
        )
    )
    phases = [p.name for p in first.phases]
    return plot_efficiency_bars(
        mc.parameter_names,
        phases,
        mc.phase_stats,
        "RMSE / posterior Cramér–Rao bound",
        title,
        path,
    )


def plot_euio(run: EuioRun, path: Path) -> Path:
    """Each parameter's estimate against the truth with ±3σ (held samples marked), the road
    load d̂ against the reference T_res, the phases shaded."""
    from gearsym.validation.drawing.figures import save

    fig, axes, names = _parameter_panels(run)
    for ax, name in zip(axes, names, strict=False):
        j = run.state_names.index(name)
        est, truth = _estimate_band(ax, run, j, "EUIO")
        held = np.where(run.held[:, j], est, np.nan)
        ax.plot(run.t, held, color="C1", lw=2.5, alpha=0.6, label="held (no UIO for it)")
        ax.plot(run.t, truth, color="k", lw=1.2, label="reference (where defined)")
        ax.set_ylabel(axis_label(name))
        ax.legend(fontsize=6, loc="upper right")
    ax = axes[-1]
    ax.plot(run.t, run.load, color="C0", lw=0.6, label="d̂ = T_res* (per sample)")
    ax.plot(run.t, run.load_truth, color="k", lw=1.2, label="reference T_res (2.48)")
    finite = run.load_truth[np.isfinite(run.load_truth)]
    spread = max(float(np.max(np.abs(finite))) * 8, 50.0)
    ax.set_ylim(-spread, spread)
    ax.set_ylabel("T_res* / N m")
    ax.set_xlabel("t / s")
    ax.legend(fontsize=6, loc="upper right")
    fig.suptitle(
        f"Extended UIO (4.5) on the {run.shift} shift model, road load unknown: samples every "
        f"{run.sample_time * 1e3:g} ms, seed {run.seed}",
        fontsize=10,
    )
    return save(fig, path)
