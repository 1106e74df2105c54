"""The drive's estimates as a picture (``gearsym drive --out``): m_veh and ζ with ±3σ against
the truth over the drive, and each element's μ estimate against its truth while it slides."""

from __future__ import annotations

from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.validation.studies.estimation.drive_ekf import DriveEstimates

__all__ = ["plot_drive_estimates"]


def plot_drive_estimates(estimates: DriveEstimates, path: Any) -> Any:
    """m_veh and ζ with ±3σ against the truth over the drive, and each element's μ estimate
    against its truth while it slides."""
    from gearsym.validation.drawing.figures import save, subplots

    t = estimates.t
    mus = [name for name in estimates.mean if name.startswith("mu_")]
    fig, axes = subplots(3, 1, size=(10.0, 8.5), sharex=True, margins={"hspace": 0.3})
    for ax, name, label in (
        (axes[0], "m_veh", "m_veh (kg)"),
        (axes[1], naming.GRADE, "ζ (rad)"),
    ):
        mean, sd = estimates.mean[name], estimates.sigma[name]
        ax.fill_between(t, mean - 3 * sd, mean + 3 * sd, color="C0", alpha=0.2, lw=0, label="±3σ")
        ax.plot(t, mean, color="C0", label="estimate")
        ax.plot(t, estimates.truth[name], color="k", lw=1.5, ls="--", label="truth")
        ax.set_ylabel(label)
        ax.legend(loc="upper right")
    axes[0].set_title("EKF carried over the drive (the TCU's view: commanded torque, noisy speeds)")
    for i, name in enumerate(mus):
        truth = estimates.truth[name]
        sliding = np.isfinite(truth)
        if not sliding.any():
            continue
        color = f"C{i % 10}"
        axes[2].plot(t[sliding], truth[sliding], ".", ms=2, color=color, alpha=0.4)
        axes[2].plot(t, estimates.mean[name], color=color, lw=0.8, label=f"{name} (dots: truth)")
    axes[2].set_ylabel("μ")
    axes[2].set_xlabel("t (s)")
    axes[2].legend(loc="upper right", fontsize=7, ncol=3)
    return save(fig, path)
