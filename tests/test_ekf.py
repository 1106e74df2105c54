"""EKF (thesis 4.1, 4.3): the augmented discrete model and its exact Jacobian.

Expected values come from elsewhere than the code under test: the gear ratios of Table 2.1
(a sticking element must make the shift model move in that gear), central finite differences
and CasADi's algorithmic differentiation of the RK4 step (for the chain-rule Jacobian), and a
tight CVODES integration of the same right-hand side with the convergence order of RK4 (global
error ∝ h⁴) for the discretisation.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators.ekf import (
    SAMPLE_TIMES,
    DiscreteModel,
    augmented_model,
)
from gearsym.symbolic.loader import load_description

# a state of the default 2-3 shift in the torque phase (the reference at t = 0.3 s, mass and
# μ near their nominal values)
Z0 = np.array([210.9, 64.15, 0.0578, 25.99, 1800.0, 0.109, 0.13, 0.01])
INPUTS = ["T_In", "F_N38", "F_N05", "slide_K38", "stick_K38", "slide_B05", "stick_B05"]
MODES = {
    "gear 2 (K38 sticks, B05 open)": [150.0, 9750.0, 0.0, 0, 1, 0, 0],
    "torque phase (both slide)": [150.0, 1240.0, 300.0, 1, 0, 1, 0],
    "speed phase (B05 slides, K38 open)": [150.0, 0.0, 910.0, 0, 0, 1, 0],
    "gear 3 (B05 sticks, K38 open)": [150.0, 0.0, 10500.0, 0, 0, 0, 1],
}


@pytest.fixture(scope="module")
def aug():
    return augmented_model(load_description(), "2-3")


@pytest.fixture(scope="module")
def discrete(aug):
    return DiscreteModel(aug)


def test_augmented_states_inputs_and_intensities(aug):
    assert aug.state_names == [
        "omega_1",
        "omega_2",
        "phi",
        "omega_C",
        "m_veh",
        "mu_38",
        "mu_05",
        "zeta",
    ]
    assert aug.input_names == INPUTS
    assert aug.n_x == 4 and aug.model.name == "ekf_2_3"
    # random walks (4.1): the parameter rows of the right-hand side are zero
    assert all(e == 0 for e in aug.model.rhs[4:])
    assert all(aug.intensities[name] > 0 for name in aug.state_names)


@pytest.mark.parametrize(("mode", "ratio"), [(0, 3.243), (3, 2.252)])
def test_a_sticking_element_moves_the_shift_model_in_its_gear(discrete, aug, mode, ratio):
    # K38 sticking is gear 2, B05 sticking gear 3: ω̇1/ω̇2 is that gear's ratio (Table 2.1)
    u = list(MODES)[mode]
    z = Z0.copy()
    z[0] = ratio * z[1]  # on the gear's speed relation
    zdot = discrete.rhs(z, MODES[u], aug.parameter_values())
    assert zdot[0] / zdot[1] == pytest.approx(ratio, abs=5e-4)


def test_mu_acts_only_while_its_element_slides(discrete, aug):
    p = aug.parameter_values()
    for name, u in MODES.items():
        J = np.asarray(discrete.J(Z0, u, p))
        slides = {"K38": u[3] == 1, "B05": u[5] == 1}
        # a sticking element's torque depends on the other's μ (the constraint force balances
        # it), so test the μ column of a non-sliding element only
        for element, column in (("K38", 5), ("B05", 6)):
            acts = bool(np.any(J[:4, column] != 0))
            assert acts == slides[element], (name, element)


@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("h", SAMPLE_TIMES)
def test_step_jacobian_is_the_derivative_of_the_step(discrete, aug, mode, h):
    p = aug.parameter_values()
    u = MODES[mode]
    z_next, F = discrete.step(Z0, u, h, p)
    # CasADi's AD of the same step graph (independent of the stage chain rule)
    _, F_ad = discrete.step_ad(Z0, u, h, p)
    np.testing.assert_allclose(F, np.asarray(F_ad), rtol=1e-10, atol=1e-12)
    # central differences, step relative to each state's scale
    fd = np.empty_like(F)
    for j in range(len(Z0)):
        step = 1e-6 * max(abs(Z0[j]), 1e-2)
        plus, minus = Z0.copy(), Z0.copy()
        plus[j] += step
        minus[j] -= step
        fd[:, j] = (discrete.step(plus, u, h, p)[0] - discrete.step(minus, u, h, p)[0]) / (2 * step)
    # compared in the states' own scales (∂z_i/∂z_j · s_j/s_i): the entries span 10 decades
    s = np.maximum(np.abs(Z0), 1e-2)
    assert np.max(np.abs(fd - F) * s[None, :] / s[:, None]) < 1e-7
    # the random-walk rows are identity rows exactly (their estimate is frozen bit for bit)
    assert np.array_equal(F[4:], np.eye(8)[4:]) and np.array_equal(z_next[4:], Z0[4:])


def _cvodes(discrete, aug, z0, u, t_end):
    z = ca.SX.sym("z", len(z0))
    ode = discrete.f(z, ca.DM(u), ca.DM(aug.parameter_values()))
    integrator = ca.integrator(
        "ref", "cvodes", {"x": z, "ode": ode}, 0.0, t_end, {"abstol": 1e-13, "reltol": 1e-13}
    )
    return np.asarray(integrator(x0=z0)["xf"]).ravel()


@pytest.mark.parametrize("mode", list(MODES))
def test_rk4_converges_to_cvodes_with_order_four(discrete, aug, mode):
    u, p = MODES[mode], aug.parameter_values()
    t_end = 0.1  # a divisor of every sample time: 100, 20 and 10 steps
    exact = _cvodes(discrete, aug, Z0, u, t_end)
    scale = np.maximum(np.abs(Z0), 1e-3)
    errors = {}
    for h in SAMPLE_TIMES:
        z = Z0.copy()
        for _ in range(round(t_end / h)):
            z = discrete.step(z, u, h, p)[0]
        errors[h] = float(np.max(np.abs(z - exact) / scale))
    # global error of RK4 ∝ h⁴: halving h from 10 to 5 ms divides it by 16
    assert 16 / 1.6 < errors[0.01] / errors[0.005] < 16 * 1.6, errors
    # and from 5 to 1 ms by 5⁴ = 625 (the CVODES reference is 1e-13 accurate: far below)
    assert 625 / 1.6 < errors[0.005] / errors[0.001] < 625 * 1.6, errors
    # at the thesis' 10 ms the state error over 0.1 s stays below the 1 % sensor error (3.26)
    assert errors[0.01] < 1e-2, errors


def test_unknown_augmented_parameter_is_one_line(aug):
    d = load_description()
    with pytest.raises(GearsymError, match="params: T_In: choose distinct parameters"):
        augmented_model(d, "2-3", parameters=("m_veh", "T_In"))
    with pytest.raises(GearsymError, match="intensities"):
        augmented_model(d, "2-3", intensities={"omega_9": 1.0})
