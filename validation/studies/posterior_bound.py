"""The posterior (Bayesian) Cramér–Rao bound matched to the EKF (thesis 3.25, 3.26, 4.1, 4.3).

What the EKF of :mod:`gearsym.symbolic.estimators.ekf` could at best achieve under its own
assumptions: the same augmented model (4.1) with the same element modes and the inputs held over
each sample, the same measured speeds (3.31) at the same sample times with the same noise
(3.26), the initial states unknown, and the filter's prior (its initial estimate's covariance
P0) counted as information. With θ = z0 = [x0; p] (initial states and parameters) and the
parameters constant, the information after sample k is

    J_k = P0⁻¹ + Σ_{i ≤ k} S_iᵀ R_i⁻¹ S_i,        S_i = ∂y(t_i)/∂z0     (3.25 with the prior)

and every estimator of p at t_k, biased or not, has E[(p̂ − p)²] ≥ (J_k⁻¹)_pp (the Bayesian,
Van Trees bound: with a Gaussian prior, for a linear model it is the Kalman filter's P exactly).

**Independent of the filter.** The sensitivities are central differences of trajectories of
the model's right-hand side f (lambdified from SymPy to NumPy, not the filter's CasADi
functions), integrated with SciPy's adaptive DOP853 at tight tolerances (not the filter's
RK4 step, not its chain-rule Jacobian), each sample interval with its input held. The bound is
for *constant* parameters and an exact model: the filter's random walks (4.1) and model-error
intensities let it forget, so its RMS error lies above this bound even when it is as good as
it can be (efficiency RMSE / bound > 1 is expected).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

__all__ = [
    "bound_sigma",
    "process_noise_bound",
    "unknown_input_bound",
    "information_increments",
    "lambdified",
    "output_sensitivities",
    "posterior_information",
]

#: f(z, u) with z of shape (n, K) (K trajectories side by side), u of shape (n_u,): ż (n, K).
Rhs = Callable[[np.ndarray, np.ndarray], np.ndarray]


def lambdified(
    expressions: Sequence[object],
    states: Sequence[object],
    inputs: Sequence[object],
    parameters: Sequence[object],
    parameter_values: Sequence[float],
) -> Rhs:
    """SymPy ``expressions`` as g(z, u) -> array (len(expressions), K) for z of shape (n, K),
    the fixed parameters substituted; NumPy code of SymPy's own printer (not CasADi)."""
    import sympy as sp

    values = dict(zip(parameters, parameter_values, strict=True))
    exprs = [sp.sympify(e).xreplace(values) for e in expressions]
    fn = sp.lambdify([list(states), list(inputs)], exprs, "numpy")

    def g(z: np.ndarray, u: np.ndarray) -> np.ndarray:
        width = z.shape[1]
        return np.array([np.broadcast_to(v, (width,)) for v in fn(list(z), list(u))], float)

    return g


def output_sensitivities(
    f: Rhs,
    h: Rhs,
    z0: np.ndarray,
    t: np.ndarray,
    u: np.ndarray,
    steps: np.ndarray,
    rtol: float = 1e-12,
    return_flow: bool = False,
) -> Any:
    """(y, S, z): the outputs y(t_k) (N, m) of the trajectory from z0, their sensitivities
    S_k = ∂y(t_k)/∂z0 (N, m, n) by central differences with steps ``steps`` (n,), and the
    trajectory's states z(t_k) (N, n); with ``return_flow`` also Φ_k = ∂z(t_k)/∂z0 (N, n, n).

    The 2n + 1 trajectories are integrated side by side (DOP853, ``rtol``, absolute tolerance
    ``rtol`` times each state's scale), restarting at every sample with u[k] held over
    [t_k, t_{k+1}) as the filter's discrete model (4.1) assumes."""
    z0 = np.asarray(z0, dtype=float)
    n = len(z0)
    steps = np.asarray(steps, dtype=float)
    Z = np.repeat(z0[:, None], 2 * n + 1, axis=1)
    Z[np.arange(n), 1 + np.arange(n)] += steps
    Z[np.arange(n), 1 + n + np.arange(n)] -= steps
    width = Z.shape[1]
    atol = np.repeat((rtol * np.maximum(np.abs(z0), steps * 1e3))[:, None], width, axis=1).ravel()
    ys, sens, states, flows = [], [], [], []
    for k in range(len(t)):
        if k > 0:
            uk = np.asarray(u[k - 1], dtype=float)

            def rhs(_t: float, v: np.ndarray, uk: np.ndarray = uk) -> np.ndarray:
                return f(v.reshape(n, width), uk).ravel()

            sol = solve_ivp(rhs, (t[k - 1], t[k]), Z.ravel(), method="DOP853", rtol=rtol, atol=atol)
            if not sol.success:  # pragma: no cover - the smooth models integrate
                raise RuntimeError(f"sensitivity integration failed at t = {t[k]:g}: {sol.message}")
            Z = sol.y[:, -1].reshape(n, width)
        Y = h(Z, np.asarray(u[k], dtype=float))
        ys.append(Y[:, 0])
        states.append(Z[:, 0].copy())
        flows.append((Z[:, 1 : 1 + n] - Z[:, 1 + n :]) / (2.0 * steps[None, :]))
        sens.append((Y[:, 1 : 1 + n] - Y[:, 1 + n :]) / (2.0 * steps[None, :]))
    if return_flow:
        return np.array(ys), np.array(sens), np.array(states), np.array(flows)
    return np.array(ys), np.array(sens), np.array(states)


def information_increments(S: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """S_kᵀ R_k⁻¹ S_k (3.25) per sample, R_k = diag(``variances[k]``) (3.26): shape (N, n, n)."""
    return np.einsum("kmi,km,kmj->kij", S, 1.0 / variances, S)


def posterior_information(
    S: np.ndarray, variances: np.ndarray, prior_covariance: np.ndarray
) -> np.ndarray:
    """J_k = P0⁻¹ + Σ_{i ≤ k} S_iᵀ R_i⁻¹ S_i after each sample k: shape (N, n, n)."""
    prior = np.linalg.inv(np.asarray(prior_covariance, dtype=float))
    return prior[None, :, :] + np.cumsum(information_increments(S, variances), axis=0)


def bound_sigma(J: np.ndarray) -> np.ndarray:
    """sqrt(diag(J_k⁻¹)) per sample: the posterior Cramér–Rao σ of every component of z0.

    Inverted as D (D J D)⁻¹ D with D = diag(J)^(-1/2) (states and parameters differ by orders
    of magnitude in scale; the prior makes J positive definite)."""
    out = []
    for Jk in np.asarray(J, dtype=float):
        scale = 1.0 / np.sqrt(np.diag(Jk))
        inverse = np.linalg.inv(scale[:, None] * Jk * scale[None, :])
        out.append(np.diag(inverse) * scale**2)
    return np.sqrt(np.array(out))


def process_noise_bound(
    flow: np.ndarray,
    S: np.ndarray,
    variances: np.ndarray,
    prior_covariance: np.ndarray,
    process: np.ndarray,
) -> np.ndarray:
    """The posterior bound of the *current* state z_k when z also takes white process noise,
    z_{k+1} = Φ(z_k) + w_k, E[w wᵀ] = ``process[k]`` (N, n, n) over [t_k, t_{k+1}) (the
    random walks of (4.1) and the model-error intensities): the recursion of Tichavský et al.
    (1998), which for additive Gaussian noise is the Kalman covariance recursion along the
    truth, P⁻ = F P Fᵀ + Q, P = (P⁻⁻¹ + Hᵀ R⁻¹ H)⁻¹ (here in Joseph form).

    F_k = Φ_{k+1} Φ_k⁻¹ and H_k = S_k Φ_k⁻¹ come from the flow Φ_k = ∂z(t_k)/∂z0 and the
    output sensitivities of :func:`output_sensitivities` (no other model access); an output
    whose variance is infinite at a sample carries no information there (it is skipped, as
    :func:`information_increments` gives it 0). With
    ``process`` = 0 it equals :func:`posterior_information`'s bound for the parameters (whose
    z_k is z0). Returns sqrt(diag P_k) after each sample's update, shape (N, n)."""
    flow = np.asarray(flow, dtype=float)
    n = flow.shape[1]
    P = np.asarray(prior_covariance, dtype=float).copy()
    out = []
    previous = np.eye(n)
    for k in range(len(flow)):
        if k > 0:
            F = np.linalg.solve(previous.T, flow[k].T).T  # Φ_k Φ_{k-1}⁻¹
            P = F @ P @ F.T + process[k - 1]
        used = np.isfinite(variances[k])  # an infinite variance: no information (unused)
        H = np.linalg.solve(flow[k].T, S[k].T).T[used]  # S_k Φ_k⁻¹
        if not used.any():
            previous = flow[k]
            out.append(np.sqrt(np.diag(P)))
            continue
        R = np.diag(variances[k][used])
        gain = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        A = np.eye(n) - gain @ H
        P = A @ P @ A.T + gain @ R @ gain.T
        P = 0.5 * (P + P.T)
        previous = flow[k]
        out.append(np.sqrt(np.diag(P)))
    return np.array(out)


def _scaled_inverse(m: np.ndarray) -> np.ndarray:
    """m⁻¹ as D (D m D)⁻¹ D, D = diag(m)^(-1/2) (scales differ by orders of magnitude)."""
    diag = np.diag(m)
    scale = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    return scale[:, None] * np.linalg.inv(scale[:, None] * m * scale[None, :]) * scale[None, :]


def unknown_input_bound(
    F: np.ndarray,
    H: np.ndarray,
    load: np.ndarray | None,
    variances: np.ndarray,
    prior_covariance: np.ndarray,
    process: np.ndarray,
) -> np.ndarray:
    """The posterior bound of z_k when, besides white process noise, an *unknown input* d_k
    enters every sample interval along the column ``load[k]`` (n,) and nothing is assumed
    about it: z_{k+1} = F_k z_k + e_k d_k + w_k, y_k = H_k z_k + v_k (the extended UIO's
    premise, thesis 4.5: the road load is not modelled at all).

    d_k with a flat prior is d_k ~ N(0, q_d) with q_d → ∞ (Kitanidis 1987; Gillijns & De Moor
    2007: the unbiased minimum-variance filter is that limit of the Kalman filter). In
    information form the limit is exact: with Y₀ = (F P Fᵀ + Q)⁻¹ the predicted information
    is Y⁻ = Y₀ − Y₀ e (eᵀ Y₀ e)⁻¹ eᵀ Y₀ — the information along e projected out (the Schur
    complement that marginalises d_k); then Y = Y⁻ + Hᵀ R⁻¹ H, P = Y⁻¹. Only e's direction
    matters. ``F`` (N, n, n): F_k maps z_{k-1} to z_k (F[0] unused); ``process[k-1]`` and
    ``load[k]`` over the same interval; ``variances`` (N, m), ``inf`` for no measurement at
    a sample. Y must be invertible after each update (rank(C E) = rank(E), the matching
    condition). ``load`` ``None``: no unknown input (the Kalman recursion along the truth).
    Returns sqrt(diag P_k), shape (N, n)."""
    F = np.asarray(F, dtype=float)
    H = np.asarray(H, dtype=float)
    P = np.asarray(prior_covariance, dtype=float).copy()
    out = []
    for k in range(len(H)):
        if k > 0:
            predicted = F[k] @ P @ F[k].T + process[k - 1]
            Y = _scaled_inverse(0.5 * (predicted + predicted.T))
            if load is not None:
                e = np.asarray(load[k], dtype=float)
                ey = Y @ e
                Y = Y - np.outer(ey, ey) / float(e @ ey)
        else:
            Y = _scaled_inverse(P)
        Y = Y + H[k].T @ (H[k] / np.asarray(variances[k], dtype=float)[:, None])
        P = _scaled_inverse(0.5 * (Y + Y.T))
        out.append(np.sqrt(np.diag(P)))
    return np.array(out)
