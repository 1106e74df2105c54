"""The derived kinematics and dynamics equal the thesis' closed forms (2.29), (2.37), symbolically.

The expected expressions below are transcribed from the thesis by hand (not produced by the
code under test). The one printed slip, the sign in (2.29j), is corrected as the digest
explains: the coefficients of any body's speed must sum to one (a rigidly locked gearbox turns
as one body), and M(1,1) of the thesis already uses the corrected form.
"""

from __future__ import annotations

import pytest
import sympy as sp
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.loader import load_description

S = sp.Symbol


def z(kind: str, j: int) -> sp.Symbol:
    return S(f"z_{kind}_{j}", positive=True)


zS1, zS2, zS3, zS4 = (z("S", j) for j in range(1, 5))
zP1, zP2, zP3, zP4 = (z("P", j) for j in range(1, 5))
zH1, zH2, zH3, zH4 = (z("H", j) for j in range(1, 5))
J = {i: S(f"J_{i}", positive=True) for i in range(1, 13)}
mP = {j: S(f"m_P_{j}", positive=True) for j in range(1, 5)}
rT = {j: S(f"r_T_{j}", positive=True) for j in range(1, 5)}
phi1, phi2, phi3, phi8 = S("phi_1"), S("phi_2"), S("phi_3"), S("phi_8")

sigma1 = zS4 / zH4 + 1
sigma2 = zS1 / zH1 + zH2 / zS2 + zH2 * zS1 / (zH1 * zS2) + 1
sigma3 = zH2 / zP2 - zS1 / zH1 + zH2 * zS1 / (zH1 * zP2) - 1
sigma4 = zH2 * zS1 / (zH1 * zS2)
sigma5 = zH2 * zS1 / (zH1 * zP2)


@pytest.fixture(scope="module")
def dynamics():
    d = load_description()
    return gearbox_dynamics(d, symbolic_teeth=True, symbolic_inertias=True)


def thesis_orientation() -> list[sp.Expr]:
    """(2.29a–l), with (2.29j) corrected: ω1 → φ1 and the sign of its first coefficient."""
    return [
        phi1,
        phi2,
        phi3,
        -zS1 / zH1 * phi1 + (zS1 / zH1 + 1) * phi8,
        (-zS1 / zH1 - zH2 * zS1 / (zH1 * zS2)) * phi1
        - zH2 / zS2 * phi3
        + (zS1 / zH1 + zH2 / zS2 + zH2 * zS1 / (zH1 * zS2) + 1) * phi8,
        (zS3 / zH3 + 1) * phi2 - zS3 / zH3 * phi3,
        (zS4 / zH4 + 1) * phi1 - zS4 / zH4 * phi3,
        phi8,
        -zS1 / zP1 * phi1 + (zS1 / zP1 + 1) * phi8,
        (zH2 * zS1 / (zH1 * zP2) - zS1 / zH1) * phi1
        + zH2 / zP2 * phi3
        + (zS1 / zH1 - zH2 / zP2 - zH2 * zS1 / (zH1 * zP2) + 1) * phi8,
        (zS3 / zP3 + 1) * phi2 - zS3 / zP3 * phi3,
        (zS4 / zP4 + 1) * phi1 - zS4 / zP4 * phi3,
    ]


def thesis_mass_matrix() -> sp.Matrix:
    """The closed-form entries printed after (2.36), with σ1…σ5."""
    a = zS1 / zH1
    m11 = (
        J[1]
        + J[7] * (zS4 / zH4 + 1) ** 2
        + J[12] * (zS4 / zP4 + 1) ** 2
        + J[10] * (a - sigma5) ** 2
        + J[5] * (a + sigma4) ** 2
        + mP[4] * rT[4] ** 2
        + J[4] * zS1**2 / zH1**2
        + J[9] * zS1**2 / zP1**2
        + mP[2] * rT[2] ** 2 * zS1**2 / zH1**2
    )
    m13 = (
        J[5] * zH2 * (a + sigma4) / zS2
        - J[12] * zS4 * (zS4 / zP4 + 1) / zP4
        - J[10] * zH2 * (a - sigma5) / zP2
        - J[7] * zS4 * (zS4 / zH4 + 1) / zH4
    )
    m14 = (
        J[10] * (a - sigma5) * sigma3
        - J[5] * (a + sigma4) * sigma2
        - J[4] * zS1 * (a + 1) / zH1
        - J[9] * zS1 * (zS1 / zP1 + 1) / zP1
        - mP[2] * rT[2] ** 2 * zS1 * (a + 1) / zH1
    )
    m22 = J[2] + J[6] * (zS3 / zH3 + 1) ** 2 + J[11] * (zS3 / zP3 + 1) ** 2 + mP[3] * rT[3] ** 2
    m23 = -J[6] * zS3 * (zS3 / zH3 + 1) / zH3 - J[11] * zS3 * (zS3 / zP3 + 1) / zP3
    m33 = (
        J[3]
        + J[10] * zH2**2 / zP2**2
        + J[5] * zH2**2 / zS2**2
        + J[6] * zS3**2 / zH3**2
        + J[7] * zS4**2 / zH4**2
        + J[11] * zS3**2 / zP3**2
        + J[12] * zS4**2 / zP4**2
    )
    m34 = -J[10] * zH2 * sigma3 / zP2 - J[5] * zH2 * sigma2 / zS2
    m44 = (
        J[8]
        + J[4] * (a + 1) ** 2
        + J[9] * (zS1 / zP1 + 1) ** 2
        + mP[1] * rT[1] ** 2
        + J[10] * sigma3**2
        + J[5] * sigma2**2
        + mP[2] * rT[2] ** 2 * (a + 1) ** 2
    )
    # Entries the thesis does not list are zero (shaft 2 couples only through set 3).
    return sp.Matrix(
        [
            [m11, 0, m13, m14],
            [0, m22, m23, 0],
            [m13, m23, m33, m34],
            [m14, 0, m34, m44],
        ]
    )


def thesis_input_matrix() -> sp.Matrix:
    """Right-hand sides of (2.37a–d) as B̃ with u = [T_In, T_Out, K81, K38, B08, B05, B06, K27]."""
    return sp.Matrix(
        [
            [1, 0, 1, 0, 0, -(zS1 / zH1 + sigma4), 0, sigma1],
            [0, -1, 0, 0, 0, 0, zS3 / zH3 + 1, -1],
            [0, 0, 0, -1, 0, -zH2 / zS2, -zS3 / zH3, -zS4 / zH4],
            [0, 0, -1, 1, 1, sigma2, 0, 0],
        ]
    )


def assert_same(derived: sp.Matrix, expected: sp.Matrix) -> None:
    assert derived.shape == expected.shape
    for i in range(derived.rows):
        for j in range(derived.cols):
            difference = sp.cancel(sp.together(derived[i, j] - expected[i, j]))
            assert difference == 0, f"entry ({i + 1},{j + 1}) differs by {difference}"


def test_orientation_equals_2_29(dynamics):
    assert_same(dynamics.kinematics.orientation, sp.Matrix(thesis_orientation()))


def test_mass_matrix_equals_closed_form(dynamics):
    assert_same(dynamics.mass_matrix, thesis_mass_matrix())


def test_input_matrix_equals_2_37(dynamics):
    assert [str(u) for u in dynamics.inputs] == [
        "T_In",
        "T_Out",
        "T_K81",
        "T_K38",
        "T_B08",
        "T_B05",
        "T_B06",
        "T_K27",
    ]
    assert_same(dynamics.input_matrix, thesis_input_matrix())


def test_printed_sign_of_2_29j_is_a_slip(dynamics):
    """The printed (2.29j) coefficient (+) would not let a locked gearbox turn as one body."""
    printed = (zH2 * zS1 / (zH1 * zP2) + zS1 / zH1) + zH2 / zP2
    printed += zS1 / zH1 - zH2 / zP2 - zH2 * zS1 / (zH1 * zP2) + 1
    assert sp.cancel(printed - 1) != 0
    row = dynamics.kinematics.transform[9, :]
    assert sp.cancel(sum(row) - 1) == 0


def test_mass_matrix_is_symmetric_positive_definite_numerically():
    dyn = gearbox_dynamics(load_description())
    m = dyn.mass_matrix
    assert m == m.T
    assert all(ev > 0 for ev in m.evalf().eigenvals(multiple=True))


def test_free_gearbox_accelerations_deliver_the_input_power():
    """ẋ = B u with B = M⁻¹ B̃ (2.41): the kinetic energy ½ ẏᵀ M ẏ then changes at the power
    of the input torques ẏᵀ B̃ u (2.35) for every speed ẏ and every u, which holds only if
    M B = B̃; checked at random speeds and torques (the inertias and teeth the built-in's)."""
    import numpy as np

    dyn = gearbox_dynamics(load_description())
    m = np.array(dyn.mass_matrix.evalf(), dtype=float)
    b_tilde = np.array(dyn.input_matrix.evalf(), dtype=float)
    b = np.array(dyn.state_input_matrix().evalf(), dtype=float)
    assert b.shape == b_tilde.shape
    rng = np.random.default_rng(31)
    for _ in range(5):
        speeds, torques = rng.normal(size=m.shape[0]) * 100, rng.normal(size=b.shape[1]) * 50
        power = speeds @ b_tilde @ torques
        assert speeds @ m @ (b @ torques) == pytest.approx(power, rel=1e-10)
