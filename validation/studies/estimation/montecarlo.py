"""Monte-Carlo evaluation of the EKF against its matched posterior Cramér–Rao bound: many noise
draws of one set-up, the statistics per phase and parameter.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.studies.estimation.bounds import (
    BOUND_ASSUMPTION,
    NOT_IDENTIFIABLE,
    EkfBound,
    _phase_samples,
    ekf_bound,
)
from gearsym.validation.studies.estimation.loop import EkfRun, _chi2_mean_band, filter_run
from gearsym.validation.studies.estimation.setup import EkfSetup

T = TypeVar("T")

__all__ = [
    "EkfMonteCarlo",
    "PhaseParameterStats",
    "ScoredStats",
    "rms",
    "run_ekf_monte_carlo",
    "run_seeds",
    "score",
]


def run_seeds(
    run_one: Callable[[int], T], runs: int, seed: int, progress: Any = None
) -> tuple[list[T], float]:
    """Every filter's Monte-Carlo loop: ``run_one(seed + i)`` for i < ``runs`` (only the noise
    drawn anew), ``progress(fraction, message)`` after each; the runs and seconds per run."""
    import time

    if runs < 1:
        raise GearsymError("estimate", "--runs", f"must be at least 1, got {runs}")
    done = []
    start = time.perf_counter()
    for i in range(runs):
        done.append(run_one(seed + i))
        if progress is not None:
            progress((i + 1) / runs, f"run {i + 1} of {runs}")
    return done, (time.perf_counter() - start) / runs


def rms(values: np.ndarray) -> float | None:
    """Root mean square of ``values``, ``None`` for none."""
    return float(np.sqrt(np.mean(values**2))) if values.size else None


def score(
    estimates: np.ndarray,
    sigmas: np.ndarray,
    first: Any,
    inside: np.ndarray,
    j: int,
    bound_sigma: np.ndarray,
    bound_sigma_process: np.ndarray,
) -> dict[str, Any]:
    """Every filter's scoring of one parameter (state index ``j``) in one phase (its samples
    ``inside``) over the runs (``estimates``, ``sigmas``: runs × samples × states): the
    samples the first run scores, mean error and RMSE against the truth, RMS reported σ, the
    bound and the bound with the filter's process noise over the same samples, the
    efficiencies RMSE / bound, and σ and bound at the phase's last sample over those before it
    (1: no information). The truth is used for scoring only."""
    idx = inside[first.scored[inside, j]]
    err = estimates[:, idx, j] - first.truth[None, idx, j]
    rmse, crb_rms = rms(err), rms(bound_sigma[idx, j])
    process_rms = rms(bound_sigma_process[idx, j])
    before = max(int(inside[0]) - 1, 0) if inside.size else 0
    end = int(inside[-1]) if inside.size else 0
    return {
        "samples": int(idx.size),
        "mean_error": float(np.mean(err)) if idx.size else None,
        "rmse": rmse,
        "sigma": rms(sigmas[:, idx, j]),
        "crb_sigma": crb_rms,
        "efficiency": rmse / crb_rms if rmse is not None and crb_rms else None,
        "crb_sigma_process": process_rms,
        "efficiency_process": rmse / process_rms if rmse is not None and process_rms else None,
        "sigma_ratio": float(np.mean(sigmas[:, end, j]) / np.mean(sigmas[:, before, j])),
        "crb_ratio": float(bound_sigma[end, j] / bound_sigma[before, j]),
    }


@dataclass(frozen=True)
class ScoredStats:
    """What :func:`score` measures of one parameter in one phase over the runs, for every
    filter; each filter's stats add what only it knows."""

    samples: int  # scored samples per run
    mean_error: float | None
    rmse: float | None
    sigma: float | None  # reported σ, RMS over the scored samples and runs
    crb_sigma: float | None  # the bound, RMS over the same samples
    efficiency: float | None  # rmse / crb_sigma
    #: the bound with the filter's process noise (random walks, model error), and rmse over it
    crb_sigma_process: float | None
    efficiency_process: float | None
    #: filter σ and bound at the phase's last sample over those before it (1: no information)
    sigma_ratio: float
    crb_ratio: float
    identifiable: bool

    def scored_dict(self) -> dict[str, Any]:
        """The JSON keys every filter's stats share, in their printed order."""
        return {
            "samples": self.samples,
            "mean_error": self.mean_error,
            "rmse": self.rmse,
            "sigma": self.sigma,
            "crb_sigma": self.crb_sigma,
            "efficiency": self.efficiency,
            "crb_sigma_process_noise": self.crb_sigma_process,
            "efficiency_process_noise": self.efficiency_process,
        }

    def ratios_dict(self) -> dict[str, Any]:
        return {"sigma_ratio": self.sigma_ratio, "crb_ratio": self.crb_ratio}


@dataclass(frozen=True)
class PhaseParameterStats(ScoredStats):
    """One parameter in one phase over the EKF's Monte-Carlo runs."""

    gamma: float | None = None  # (3.27) on the phase's own FIM

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.scored_dict(),
            "identifiable": self.identifiable,
            "verdict": None if self.identifiable else NOT_IDENTIFIABLE,
            "gamma": self.gamma if self.gamma is None or np.isfinite(self.gamma) else "inf",
            **self.ratios_dict(),
        }


@dataclass(frozen=True)
class EkfMonteCarlo:
    """The EKF over ``len(runs)`` noise seeds of one reference shift, with the matched bound."""

    runs: tuple[EkfRun, ...]
    bound: EkfBound
    seconds_per_run: float
    #: per phase name, per parameter
    phase_stats: dict[str, dict[str, PhaseParameterStats]]
    #: initial estimates drawn from the prior around the truth (else the fixed default)
    prior_draw: bool = False

    @property
    def first(self) -> EkfRun:
        return self.runs[0]

    def _stack(self, attribute: str) -> np.ndarray:
        return np.array([getattr(r, attribute) for r in self.runs])

    def nees_run_mean(self) -> np.ndarray:
        """ε̄_k: NEES at each sample averaged over the runs."""
        return np.mean(self._stack("nees"), axis=0)

    @property
    def nees_mean(self) -> float:
        return float(np.mean(self.nees_run_mean()))

    def nees_band(self, probability: float = 0.95) -> tuple[float, float]:
        """Band of the NEES mean of a consistent filter: one sample's mean over the R runs is
        χ²(R n)/R (n its dof, the runs independent); the time average of such means, which are
        correlated in time, scatters no more than one of them. n: the mean dof."""
        from scipy.stats import chi2

        runs, dof = len(self.runs), float(np.mean(self.first.nees_dof))
        return (
            float(chi2.ppf((1 - probability) / 2, runs * dof) / runs),
            float(chi2.ppf((1 + probability) / 2, runs * dof) / runs),
        )

    def nees_inside(self, probability: float = 0.95) -> float:
        """Fraction of samples whose run-averaged NEES lies inside its χ²(R n_k)/R band."""
        from scipy.stats import chi2

        runs, dof = len(self.runs), self.first.nees_dof
        lo = chi2.ppf((1 - probability) / 2, runs * dof) / runs
        hi = chi2.ppf((1 + probability) / 2, runs * dof) / runs
        mean = self.nees_run_mean()
        return float(np.mean((mean >= lo) & (mean <= hi)))

    def parameter_summary(self, name: str) -> dict[str, Any]:
        """Over every scored sample of every run: the JSON entry of one parameter."""
        first = self.first
        j = first.state_names.index(name)
        scored = first.scored[:, j]
        errors = self._stack("estimates")[:, scored, j] - first.truth[None, scored, j]
        sigmas = self._stack("sigmas")[:, scored, j]
        crb = self.bound.sigma[scored, j]
        crb_process = self.bound.sigma_process[scored, j]
        process_rms = float(np.sqrt(np.mean(crb_process**2))) if crb_process.size else None
        final = [next(p for p in r.parameters if p.name == name) for r in self.runs]
        rmse = float(np.sqrt(np.mean(errors**2))) if errors.size else None
        crb_rms = float(np.sqrt(np.mean(crb**2))) if crb.size else None
        return {
            "truth": final[0].truth,
            "initial": float(np.mean([p.initial for p in final])),
            "estimate": float(np.mean([p.estimate for p in final])),
            "sigma": float(np.mean([p.sigma for p in final])),
            "rmse": rmse,
            "mean_error": float(np.mean(errors)) if errors.size else None,
            "sigma_rms": float(np.sqrt(np.mean(sigmas**2))) if sigmas.size else None,
            "crb_sigma": crb_rms,
            "efficiency": None if rmse is None or not crb_rms else rmse / crb_rms,
            "crb_sigma_process_noise": process_rms,
            "efficiency_process_noise": None
            if rmse is None or not process_rms
            else rmse / process_rms,
            "identifiable": [
                phase for phase, stats in self.phase_stats.items() if stats[name].identifiable
            ],
            "samples": int(np.count_nonzero(scored)),
        }

    def to_dict(self) -> dict[str, Any]:
        first = self.first
        band = self.nees_band()
        nis = self._stack("nis")
        nis_dof = first.nis_dof
        used = nis_dof > 0
        return {
            "filter": "ekf",
            "shift": first.shift,
            "runs": len(self.runs),
            "seed": first.seed,
            "seeds": [r.seed for r in self.runs],
            "sample_time": first.sample_time,
            "relative_noise": list(first.relative_noise),
            "seconds_per_run": self.seconds_per_run,
            "initial_estimate": "drawn from the prior around the truth"
            if self.prior_draw
            else "fixed",
            "parameters": {name: self.parameter_summary(name) for name in self.parameter_names},
            "bound": BOUND_ASSUMPTION,
            "nees_mean": self.nees_mean,
            "nees_band": list(band),
            "nees_dof_mean": float(np.mean(first.nees_dof)),
            "nees_inside_95": self.nees_inside(),
            "nis_mean": float(np.mean(nis[:, used])) if used.any() else None,
            "nis_band": list(_chi2_mean_band(np.tile(nis_dof[used], len(self.runs))))
            if used.any()
            else None,
            "min_covariance_eigenvalue": min(r.min_eigenvalue for r in self.runs),
            "modes": first.mode_source,
            "events": self.event_summary(),
            "phases": [
                {
                    **phase.to_dict(),
                    "parameters": {
                        name: stats.to_dict()
                        for name, stats in self.phase_stats[phase.name].items()
                    },
                }
                for phase in first.phases
            ],
        }

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.first.parameters]

    def event_summary(self) -> list[dict[str, Any]]:
        """Per truth switch: in how many runs the filter detected it and the error
        t_detected − t_truth over those runs (mean, largest magnitude, ms); then the mean
        number per run of detected switches the truth does not have."""
        per_run = [r.events() for r in self.runs]
        out: list[dict[str, Any]] = []
        for i, ev in enumerate(e for e in per_run[0] if e["t_reference"] is not None):
            errors = [
                events[i]["error_ms"] for events in per_run if events[i]["error_ms"] is not None
            ]
            out.append(
                {
                    "element": ev["element"],
                    "kind": ev["kind"],
                    "t_reference": ev["t_reference"],
                    "runs": len(self.runs),
                    "detected_runs": len(errors),
                    "error_ms_mean": float(np.mean(errors)) if errors else None,
                    "error_ms_max_abs": float(np.max(np.abs(errors))) if errors else None,
                }
            )
        extra = [sum(e["t_reference"] is None for e in events) for events in per_run]
        if any(extra):
            out.append(
                {
                    "element": "any",
                    "kind": "switches without a reference counterpart (mean per run)",
                    "t_reference": None,
                    "t_detected": None,
                    "count_mean": float(np.mean(extra)),
                }
            )
        return out


def run_ekf_monte_carlo(
    setup: EkfSetup,
    runs: int,
    seed: int = 0,
    progress: Any = None,
    bound: EkfBound | None = None,
    prior_draw: bool = False,
    dropout: tuple[float, float] | None = None,
    dropout_outputs: Sequence[str] | None = None,
) -> EkfMonteCarlo:
    """The EKF (4.3) over ``runs`` seeds ``seed``, ``seed`` + 1, …: the reference and
    everything of ``setup`` fixed, only the speed noise (3.26) drawn anew. ``progress(fraction,
    message)`` is called after each run. Per parameter and phase: mean error, RMSE and RMS
    reported σ over the scored samples of every run, the posterior bound (:func:`ekf_bound`)
    over the same samples and the efficiency RMSE / bound; the phase's own identifiability.
    ``prior_draw``: each run's initial estimate drawn from the prior around the truth
    (:func:`filter_run`), the bound's premise. ``dropout``/``dropout_outputs``: a sensor
    dropout in every run (:func:`filter_run`); the bound keeps every sample."""
    done, seconds = run_seeds(
        lambda run_seed: filter_run(
            setup,
            run_seed,
            dropout=dropout,
            prior_draw=prior_draw,
            dropout_outputs=dropout_outputs,
        ),
        runs,
        seed,
        progress,
    )
    if bound is None:
        if progress is not None:
            progress(1.0, "posterior Cramér–Rao bound")
        bound = ekf_bound(setup)
    estimates = np.array([r.estimates for r in done])
    sigmas = np.array([r.sigmas for r in done])
    first = done[0]
    stats: dict[str, dict[str, PhaseParameterStats]] = {}
    for k, phase in enumerate(first.phases):
        inside = _phase_samples(first.t, phase, last=k == len(first.phases) - 1)
        stats[phase.name] = {}
        for p in first.parameters:
            j = first.state_names.index(p.name)
            stats[phase.name][p.name] = PhaseParameterStats(
                **score(estimates, sigmas, first, inside, j, bound.sigma, bound.sigma_process),
                identifiable=p.name in bound.identifiable.get(phase.name, ()),
                gamma=bound.gamma.get(phase.name, {}).get(p.name),
            )
    return EkfMonteCarlo(
        runs=tuple(done),
        bound=bound,
        seconds_per_run=seconds,
        phase_stats=stats,
        prior_draw=prior_draw,
    )
