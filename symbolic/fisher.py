"""Fisher information, Cramér–Rao bounds and parameter elimination: the math (thesis 3.16–3.30).

Pure numerics on arrays, no model knowledge: the output sensitivities ∂y/∂p at the measurement
times come from :mod:`gearsym.validation.studies.sensitivity_run`;
:mod:`gearsym.validation.studies.fisher` runs the study along the reference shift.

* noise model (3.26): σ²_ik = r_i² · max(|y_i(t_k)|, y_i^min)², with y_i^min = 1 % of the
  largest measured |y_i| (the floor fraction is a parameter);
* Fisher information (3.25): F = Σ_k (∂y/∂p)_kᵀ C_k⁻¹ (∂y/∂p)_k with C_k = diag(σ²_ik). The
  score (3.24) is Σ (z − y)/σ² ∂y/∂p (the thesis prints the residual squared, a slip); its
  expected outer product is this F;
* Cramér–Rao (3.22)–(3.23): C_p ≥ F⁻¹, σ_j ≥ sqrt((F⁻¹)_jj); normalised scatter (3.27)
  γ_j = σ_j / p_j0;
* eigen-analysis (3.28)–(3.30) of the *normalised* FIM F_N = P F P, P = diag(p_j0), whose
  inverse has γ_j² on its diagonal: F_N = V D Vᵀ, 1/λ_j ≤ σ_j,t, and the variance of parameter
  i splits over the eigen-directions as γ_i² = Σ_j v_ij² / λ_j;
* elimination (thesis 3.3): while a scatter exceeds the limit, drop the parameter with the
  largest component in the eigen-direction of the smallest eigenvalue (the direction that
  carries the largest variance), and recompute.

A singular F is a finding, not an error: the null directions are reported as combinations of
the named parameters; parameters orthogonal to every null direction keep a finite bound (from
the pseudo-inverse), the others get an infinite scatter.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Relative rank tolerance: eigenvalues of F_N below this times the largest are treated as 0.
RANK_TOLERANCE = 1e-10


def measurement_floor(z: np.ndarray, fraction: float = 0.01) -> np.ndarray:
    """y_i^min of (3.26): ``fraction`` of the largest measured |z_i| over the record, (ny,)."""
    return fraction * np.max(np.abs(np.asarray(z, dtype=float)), axis=0)


def noise_variances(
    y: np.ndarray, relative_errors: Sequence[float], floor: np.ndarray
) -> np.ndarray:
    """σ²_ik = r_i² max(|y_ik|, y_i^min)² (3.26), shape (N, ny).

    An output whose floor is zero (never measured away from 0) and whose value is zero would
    get a zero variance; such samples are given an infinite variance (no information).
    """
    y = np.asarray(y, dtype=float)
    r = np.asarray(relative_errors, dtype=float)
    variances = (r[None, :] * np.maximum(np.abs(y), np.asarray(floor)[None, :])) ** 2
    variances[variances == 0] = np.inf
    return variances


def fisher_information(dy: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """F = Σ_k (∂y/∂p)_kᵀ C_k⁻¹ (∂y/∂p)_k (3.25); dy (N, ny, m), variances (N, ny) → (m, m)."""
    dy = np.asarray(dy, dtype=float)
    weights = 1.0 / np.asarray(variances, dtype=float)
    return np.einsum("kip,ki,kiq->pq", dy, weights, dy)


@dataclass(frozen=True)
class FimAnalysis:
    """Cramér–Rao bounds and eigen-analysis of one FIM for one parameter combination."""

    names: tuple[str, ...]
    scales: np.ndarray  # p_j0
    fim: np.ndarray  # F, absolute units
    normalised: np.ndarray  # F_N = P F P
    eigenvalues: np.ndarray  # of F_N, ascending
    eigenvectors: np.ndarray  # columns v_j of F_N
    rank: int
    sigma: np.ndarray  # Cramér–Rao σ_j, absolute units (inf where not identifiable)
    gamma: np.ndarray  # σ_j / p_j0 (3.27)
    contributions: np.ndarray  # (m, m): v_ij² / λ_j, row i parameter, column j direction
    null_directions: tuple[dict[str, float], ...]  # normalised parameter combinations
    gamma_max: float

    @property
    def singular(self) -> bool:
        return self.rank < len(self.names)

    @property
    def estimable(self) -> bool:
        """Every scatter within the limit (3.27)."""
        return bool(np.all(self.gamma <= self.gamma_max))

    @property
    def condition(self) -> float:
        if self.eigenvalues[0] <= 0:
            return float("inf")
        return float(self.eigenvalues[-1] / self.eigenvalues[0])

    def weakest(self) -> str:
        """The parameter with the largest |component| along the smallest eigenvalue (3.30)."""
        return self.names[int(np.argmax(np.abs(self.eigenvectors[:, 0])))]

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": list(self.names),
            "nominal": [float(v) for v in self.scales],
            "crb_sigma": {n: _num(s) for n, s in zip(self.names, self.sigma, strict=True)},
            "gamma": {n: _num(g) for n, g in zip(self.names, self.gamma, strict=True)},
            "gamma_max": self.gamma_max,
            "estimable": self.estimable,
            "rank": self.rank,
            "singular": self.singular,
            "condition": _num(self.condition),
            "eigenvalues": [float(v) for v in self.eigenvalues],
            "eigenvectors": [
                {n: float(self.eigenvectors[i, j]) for i, n in enumerate(self.names)}
                for j in range(len(self.names))
            ],
            "null_directions": [dict(d) for d in self.null_directions],
            "fim": self.fim.tolist(),
        }


def _num(value: float) -> float | str:
    return float(value) if np.isfinite(value) else "inf"


def analyse(
    fim: np.ndarray,
    names: Sequence[str],
    scales: Sequence[float],
    gamma_max: float = 0.1,
    rank_tolerance: float = RANK_TOLERANCE,
) -> FimAnalysis:
    """Cramér–Rao bounds (3.22)–(3.23), scatter (3.27), eigen-analysis (3.28)–(3.30)."""
    fim = np.asarray(fim, dtype=float)
    scales = np.asarray(scales, dtype=float)
    m = len(names)
    normalised = scales[:, None] * fim * scales[None, :]
    normalised = 0.5 * (normalised + normalised.T)
    eigenvalues, eigenvectors = np.linalg.eigh(normalised)
    largest = max(float(eigenvalues[-1]), 0.0) if m else 0.0
    zero = eigenvalues <= rank_tolerance * largest if largest > 0 else np.ones(m, dtype=bool)
    rank = int(m - np.count_nonzero(zero))
    null = eigenvectors[:, zero]
    null_directions = tuple(_direction(null[:, k], names) for k in range(null.shape[1]))
    # identifiable parameters: orthogonal to every null direction
    tied = np.any(np.abs(null) > 1e-6, axis=1) if null.size else np.zeros(m, dtype=bool)
    inverse_eigen = np.where(zero, 0.0, 1.0 / np.where(zero, 1.0, eigenvalues))
    gamma_sq = (eigenvectors**2) @ inverse_eigen  # diag(F_N^+)
    gamma = np.where(tied, np.inf, np.sqrt(np.maximum(gamma_sq, 0.0)))
    contributions = np.where(zero[None, :], np.inf, eigenvectors**2 * inverse_eigen[None, :])
    contributions[(eigenvectors**2 < 1e-24) & zero[None, :]] = 0.0
    return FimAnalysis(
        names=tuple(names),
        scales=scales,
        fim=fim,
        normalised=normalised,
        eigenvalues=eigenvalues,
        eigenvectors=eigenvectors,
        rank=rank,
        sigma=gamma * scales,
        gamma=gamma,
        contributions=contributions,
        null_directions=null_directions,
        gamma_max=gamma_max,
    )


def _direction(vector: np.ndarray, names: Sequence[str]) -> dict[str, float]:
    """A null direction as {parameter: component}, largest component positive, tiny dropped."""
    k = int(np.argmax(np.abs(vector)))
    v = vector * np.sign(vector[k])
    return {n: round(float(c), 6) for n, c in zip(names, v, strict=True) if abs(c) > 1e-6}


def describe_direction(direction: dict[str, float]) -> str:
    """``0.707·m_veh − 0.707·zeta`` (components of the normalised parameters)."""
    parts = []
    for name, c in direction.items():
        sign = "−" if c < 0 else "+"
        parts.append(f"{sign} {abs(c):.3g}·{name}")
    text = " ".join(parts)
    return text[2:] if text.startswith("+ ") else text


@dataclass(frozen=True)
class EliminationStep:
    """One step of the thesis' procedure: the analysis of a set and what was dropped."""

    analysis: FimAnalysis
    dropped: str | None
    reason: str


@dataclass(frozen=True)
class Elimination:
    steps: tuple[EliminationStep, ...] = field(default_factory=tuple)

    @property
    def final(self) -> tuple[str, ...]:
        """The parameters that remain estimable (may be empty)."""
        last = self.steps[-1]
        return () if last.dropped is not None else last.analysis.names

    def to_dict(self) -> dict[str, Any]:
        return {
            "final": list(self.final),
            "steps": [
                {
                    "parameters": list(s.analysis.names),
                    "gamma": {
                        n: _num(g) for n, g in zip(s.analysis.names, s.analysis.gamma, strict=True)
                    },
                    "dropped": s.dropped,
                    "reason": s.reason,
                }
                for s in self.steps
            ],
        }


def submatrix(fim: np.ndarray, names: Sequence[str], keep: Sequence[str]) -> np.ndarray:
    """The FIM of a parameter subset (the other parameters known exactly)."""
    index = [list(names).index(n) for n in keep]
    return np.asarray(fim)[np.ix_(index, index)]


def eliminate(
    fim: np.ndarray,
    names: Sequence[str],
    scales: Sequence[float],
    gamma_max: float = 0.1,
    rank_tolerance: float = RANK_TOLERANCE,
) -> Elimination:
    """The thesis' procedure (3.3): while some γ_j > γ_max, drop the parameter that dominates
    the eigen-direction of the smallest eigenvalue of F_N (3.28)–(3.30) and recompute.
    ``rank_tolerance`` as in :func:`analyse`."""
    names = list(names)
    scale_of = dict(zip(names, np.asarray(scales, dtype=float), strict=True))
    keep = list(names)
    steps = []
    while keep:
        a = analyse(
            submatrix(fim, names, keep),
            keep,
            [scale_of[n] for n in keep],
            gamma_max=gamma_max,
            rank_tolerance=rank_tolerance,
        )
        if a.estimable:
            steps.append(EliminationStep(a, None, "every scatter below the limit"))
            break
        drop = a.weakest()
        if a.singular:
            reason = "singular FIM; null direction " + describe_direction(a.null_directions[0])
        else:
            worst = a.names[int(np.argmax(a.gamma))]
            reason = (
                f"largest scatter γ({worst}) = {np.max(a.gamma):.3g} > {gamma_max:g}; "
                f"{drop} dominates the weakest direction (λ_min = {a.eigenvalues[0]:.3g})"
            )
        steps.append(EliminationStep(a, drop, reason))
        keep.remove(drop)
    return Elimination(tuple(steps))
