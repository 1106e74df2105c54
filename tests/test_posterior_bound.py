"""The posterior Cramér–Rao bound route (3.25 with the prior) against closed forms by hand.

Expected values are derived here, not taken from the code under test:

* a ramp ẋ = θ u with u held over each sample: x(t_k) = x0 + θ h Σ_{i<k} u_i, so
  S_k = [1, h Σ_{i<k} u_i] and J = P0⁻¹ + Σ S_kᵀ S_k / R, inverted by hand as a 2 × 2;
* exponential decay ẋ = −a x: y = x0 e^{−a t}, ∂y/∂x0 = e^{−a t}, ∂y/∂a = −t x0 e^{−a t};
* a scalar linear Kalman filter without process noise has P_k = J_k⁻¹ exactly (the bound is
  attained), P_k⁻¹ = 1/σ0² + (k+1)/R for a constant observed directly.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from gearsym.validation.studies.posterior_bound import (
    bound_sigma,
    lambdified,
    output_sensitivities,
    posterior_information,
)

x, theta, a, u = sp.symbols("x theta a u", real=True)


def _ramp():
    f = lambdified([theta * u, 0], [x, theta], [u], [], [])
    h = lambdified([x], [x, theta], [u], [], [])
    return f, h


def test_ramp_with_held_inputs_matches_the_hand_bound():
    f, h = _ramp()
    step, n = 0.01, 40
    t = np.arange(n) * step
    u_values = 1.0 + 0.5 * np.sin(np.arange(n))  # held over each sample interval
    z0 = np.array([3.0, 2.0])
    y, S, z = output_sensitivities(f, h, z0, t, u_values[:, None], np.array([1e-3, 1e-3]))
    # by hand: x_k = x0 + θ h Σ_{i<k} u_i
    cumulative = np.concatenate([[0.0], np.cumsum(u_values[:-1])]) * step
    assert y[:, 0] == pytest.approx(3.0 + 2.0 * cumulative, rel=1e-11)
    assert S[:, 0, 0] == pytest.approx(np.ones(n), abs=1e-8)
    assert S[:, 0, 1] == pytest.approx(cumulative, abs=1e-8)
    assert z[:, 1] == pytest.approx(np.full(n, 2.0))

    R, s_x, s_t = 0.04, 0.5, 3.0
    J = posterior_information(S, np.full((n, 1), R), np.diag([s_x**2, s_t**2]))
    # hand: J = [[1/s_x² + k/R, Σc/R], [Σc/R, 1/s_t² + Σc²/R]], σ_θ² = J_xx / det J
    for k in (0, 9, n - 1):
        c = cumulative[: k + 1]
        jxx = 1 / s_x**2 + (k + 1) / R
        jxt = c.sum() / R
        jtt = 1 / s_t**2 + (c**2).sum() / R
        det = jxx * jtt - jxt**2
        sigma = bound_sigma(J[k : k + 1])[0]
        assert sigma[1] == pytest.approx(np.sqrt(jxx / det), rel=1e-8)
        assert sigma[0] == pytest.approx(np.sqrt(jtt / det), rel=1e-8)
    # with no data the bound is the prior; information only shrinks it
    sig = bound_sigma(J)
    assert np.all(np.diff(sig[:, 1]) <= 1e-12)
    assert sig[-1, 1] < 0.1 * s_t
    # the first sample has c = 0: it says nothing about θ, whose bound is still its prior
    assert sig[0, 1] == pytest.approx(s_t, rel=1e-12)


def test_exponential_decay_sensitivities_match_the_closed_form():
    f = lambdified([-a * x, 0], [x, a], [u], [], [])
    h = lambdified([x], [x, a], [u], [], [])
    t = np.linspace(0.0, 2.0, 21)
    x0, a0 = 2.0, 1.3
    _, S, _ = output_sensitivities(
        f, h, np.array([x0, a0]), t, np.zeros((len(t), 1)), np.array([1e-4, 1e-4])
    )
    decay = np.exp(-a0 * t)
    assert S[:, 0, 0] == pytest.approx(decay, rel=1e-7)
    assert S[:, 0, 1] == pytest.approx(-t * x0 * decay, rel=1e-7, abs=1e-12)


def test_fixed_parameters_are_substituted():
    c = sp.Symbol("c")
    f = lambdified([c * u], [x], [u], [c], [4.0])
    assert f(np.array([[1.0, 2.0]]), np.array([0.5])) == pytest.approx(np.array([[2.0, 2.0]]))


def test_the_scalar_kalman_filter_attains_the_posterior_bound():
    # constant x observed directly: KF with P0 = σ0², no process noise
    sigma0, R, n = 2.0, 0.25, 15
    S = np.ones((n, 1, 1))
    J = posterior_information(S, np.full((n, 1), R), np.array([[sigma0**2]]))
    P = sigma0**2
    for k in range(n):
        P = P - P * P / (P + R)  # scalar Kalman update
        assert bound_sigma(J[k : k + 1])[0, 0] ** 2 == pytest.approx(P, rel=1e-12)
        assert P == pytest.approx(1 / (1 / sigma0**2 + (k + 1) / R), rel=1e-12)


def test_process_noise_bound_of_a_random_walk_follows_the_hand_recursion():
    # x_{k+1} = x_k + w_k (variance q), y_k = x_k + v_k (variance R): P⁻ = P + q,
    # P = P⁻ R / (P⁻ + R), from P0 before the first update
    from gearsym.validation.studies.posterior_bound import process_noise_bound

    n, q, R, P0 = 30, 0.3, 0.5, 4.0
    flow, S = np.ones((n, 1, 1)), np.ones((n, 1, 1))
    sigma = process_noise_bound(
        flow, S, np.full((n, 1), R), np.array([[P0]]), np.full((n, 1, 1), q)
    )
    P = P0
    for k in range(n):
        if k > 0:
            P = P + q
        P = P * R / (P + R)
        assert sigma[k, 0] ** 2 == pytest.approx(P, rel=1e-12)
    predicted = (q + np.sqrt(q * q + 4 * q * R)) / 2  # P⁻ at steady state: P⁻² − q P⁻ − q R = 0
    assert sigma[-1, 0] ** 2 == pytest.approx(predicted * R / (predicted + R), rel=1e-9)


def test_process_noise_bound_without_noise_is_the_constant_parameter_bound():
    from gearsym.validation.studies.posterior_bound import process_noise_bound

    f, h = _ramp()
    t = np.arange(25) * 0.02
    u_values = 1.0 + 0.3 * np.cos(np.arange(25))
    _, S, _, flow = output_sensitivities(
        f, h, np.array([1.0, -2.0]), t, u_values[:, None], np.array([1e-3, 1e-3]), return_flow=True
    )
    # the flow of ẋ = θ u by hand: ∂x_k/∂θ = h Σ_{i<k} u_i
    cumulative = np.concatenate([[0.0], np.cumsum(u_values[:-1])]) * 0.02
    assert flow[:, 0, 1] == pytest.approx(cumulative, abs=1e-8)
    variances = np.full((25, 1), 0.01)
    prior = np.diag([0.5**2, 2.0**2])
    constant = bound_sigma(posterior_information(S, variances, prior))
    noisy = process_noise_bound(flow, S, variances, prior, np.zeros((25, 2, 2)))
    assert noisy[:, 1] == pytest.approx(constant[:, 1], rel=1e-7)  # θ: z_k's θ is z0's
    # with a random walk on θ the bound can only be larger
    walk = np.zeros((25, 2, 2))
    walk[:, 1, 1] = 0.05
    assert np.all(process_noise_bound(flow, S, variances, prior, walk)[1:, 1] > noisy[1:, 1])
