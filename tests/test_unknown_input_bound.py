"""The bound with an unknown input projected out (the extended UIO's premise, thesis 4.5)
against hand cases and against the Kalman recursion with a very large input variance.

Expected values are derived here, not taken from the code under test:

* **collinear** (a parameter acting exactly like the unknown input): a_{k+1} = a_k + h p + h d_k,
  y = a. With d_k arbitrary, a_{k+1} says nothing about p: its bound stays at the prior σ.
* **decoupled**: a_{k+1} = a_k + h d_k, b_{k+1} = b_k + h p, y = [a, b]. The unknown input
  touches only a, so (b_0, p) keep the information of the ramp y_b = b_0 + p k h:
  J = diag(1/σ_b², 1/σ_p²) + Σ_k [1, k h]ᵀ[1, k h] / r², inverted by hand as a 2 × 2.
* **the limit**: for any linear system the projection is the Kalman recursion with the input
  as white noise of variance q_d → ∞ along e (Kitanidis 1987); the existing
  :func:`process_noise_bound` with q_d = 1e7 must agree to about 1/q_d.
* without an unknown input the recursion is :func:`process_noise_bound` itself.
"""

from __future__ import annotations

import numpy as np
from gearsym.validation.studies.posterior_bound import process_noise_bound, unknown_input_bound


def _flows(F: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Φ_k = F_k … F_1 and S_k = H_k Φ_k (what process_noise_bound takes)."""
    n = F.shape[1]
    flow, phi = [], np.eye(n)
    for k in range(len(F)):
        if k > 0:
            phi = F[k] @ phi
        flow.append(phi.copy())
    flow_arr = np.array(flow)
    return flow_arr, np.einsum("kmi,kij->kmj", H, flow_arr)


def test_a_parameter_collinear_with_the_unknown_input_keeps_its_prior():
    h, N, r, sp = 0.01, 60, 0.1, 2.0
    F = np.tile(np.array([[1.0, h], [0.0, 1.0]]), (N, 1, 1))
    H = np.tile(np.array([[1.0, 0.0]]), (N, 1, 1))
    e = np.tile(np.array([h, 0.0]), (N, 1))
    var = np.full((N, 1), r**2)
    prior = np.diag([1.0, sp**2])
    sigma = unknown_input_bound(F, H, e, var, prior, np.zeros((N, 2, 2)))
    np.testing.assert_allclose(sigma[:, 1], sp, rtol=1e-12)
    # and with the input known, the same data would identify p
    known = unknown_input_bound(F, H, None, var, prior, np.zeros((N, 2, 2)))
    assert known[-1, 1] < 0.1 * sp


def test_a_parameter_decoupled_from_the_unknown_input_keeps_the_ramp_bound():
    h, N, r = 0.01, 80, 0.05
    sa, sb, sp = 3.0, 0.5, 4.0
    F = np.tile(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, h], [0.0, 0.0, 1.0]]), (N, 1, 1))
    H = np.tile(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), (N, 1, 1))
    e = np.tile(np.array([h, 0.0, 0.0]), (N, 1))
    var = np.full((N, 2), r**2)
    sigma = unknown_input_bound(F, H, e, var, np.diag([sa**2, sb**2, sp**2]), np.zeros((N, 3, 3)))
    for k in (0, 1, 10, N - 1):
        # by hand: information on (b_0, p) from y_b,i = b_0 + p i h, i = 0..k
        i = np.arange(k + 1) * h
        j11 = 1 / sb**2 + (k + 1) / r**2
        j12 = np.sum(i) / r**2
        j22 = 1 / sp**2 + np.sum(i**2) / r**2
        det = j11 * j22 - j12**2
        np.testing.assert_allclose(sigma[k, 2], np.sqrt(j11 / det), rtol=1e-10)
    # a is re-measured every sample and forgotten through d: σ_a = r after the first sample
    np.testing.assert_allclose(sigma[1:, 0], r, rtol=1e-10)


def test_the_projection_is_the_limit_of_a_large_input_variance():
    rng = np.random.default_rng(5)
    n, m, N = 4, 2, 40
    F = np.array([np.eye(n) + 0.05 * rng.normal(size=(n, n)) for _ in range(N)])
    H = np.array([rng.normal(size=(m, n)) for _ in range(N)])
    e = rng.normal(size=(N, n))
    var = rng.uniform(0.01, 0.1, size=(N, m))
    prior = np.diag(rng.uniform(0.5, 2.0, n) ** 2)
    q = np.array([np.diag(rng.uniform(0.0, 1e-3, n)) for _ in range(N)])
    got = unknown_input_bound(F, H, e, var, prior, q)
    flow, S = _flows(F, H)
    big = 1e7
    process = q.copy()
    process[:-1] += big * np.einsum("ki,kj->kij", e[1:], e[1:])  # over [t_k, t_{k+1})
    limit = process_noise_bound(flow, S, var, prior, process)
    np.testing.assert_allclose(got, limit, rtol=1e-4)
    # without the unknown input it is the Kalman recursion itself
    none = unknown_input_bound(F, H, None, var, prior, q)
    np.testing.assert_allclose(none, process_noise_bound(flow, S, var, prior, q), rtol=1e-9)
    # information only gets lost by not knowing the input
    assert np.all(got >= none * (1 - 1e-12))
