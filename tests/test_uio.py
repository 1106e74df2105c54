"""Unknown input observer (thesis 4.4): existence per phase and the discrete design.

Expected values: the facts for the 2-3 form (5.4)/(5.5) checked by hand in the project's
digest of the thesis (rank CE = rank E = 1 with T_res* unknown and no invariant zero; with
T_K38, T_B05, T_res* unknown rank 3 and an invariant zero at s = 0); a second-order system
whose zero polynomial is derived by hand; and for the design, the defining property of a UIO
(the error obeys e_{k+1} = F e_k whatever the unknown input does) checked on a system
discretised by SciPy's own zero-order hold, an implementation independent of the design's.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators import design_uio, linear_modes, uio_existence
from gearsym.symbolic.estimators.uio import LinearMode
from gearsym.symbolic.linear_forms import LinearForm
from gearsym.symbolic.loader import load_description
from scipy.signal import cont2discrete


@pytest.fixture(scope="module")
def modes():
    return {m.phase: m for m in linear_modes(load_description(), "2-3")}


def test_the_three_phases_of_the_2_3_shift_and_their_outputs(modes):
    assert list(modes) == ["gear 2", "torque and speed phase", "gear 3"]
    during = modes["torque and speed phase"]
    assert during.form.states == ["omega_1", "omega_2", "phi", "omega_C"]
    assert during.outputs == ("y_omega_1", "y_omega_2", "y_omega_C")  # (3.31)
    # in gear 2 the input shaft turns at ratio 3.243 (Table 2.1) times the output shaft
    assert float(modes["gear 2"].C[0, 0]) == pytest.approx(3.243, abs=5e-4)
    assert float(modes["gear 3"].C[0, 0]) == pytest.approx(2.252, abs=5e-4)


def test_road_load_unknown_a_uio_exists_in_every_phase(modes):
    for mode in modes.values():
        result = uio_existence(mode, ["T_res_star"])
        assert (result.rank_CE, result.rank_E) == (1, 1)
        assert result.invariant_zeros == () and result.exists, mode.phase


def test_clutch_torques_and_road_load_unknown_leave_an_invariant_zero_at_the_origin(modes):
    result = uio_existence(modes["torque and speed phase"], ["T_K38", "T_B05", "T_res_star"])
    assert (result.rank_CE, result.rank_E) == (3, 3) and result.matching
    assert sp.simplify(result.zero_polynomial - sp.Symbol("s")) == 0
    assert not result.strongly_detectable and not result.exists
    assert "invariant zero(s) 0" in result.reason()
    with pytest.raises(GearsymError, match="torque and speed phase.*not strongly detectable"):
        design_uio(modes["torque and speed phase"], ["T_K38", "T_B05", "T_res_star"], 0.01)


def test_collinear_unknown_inputs_are_reported_and_only_their_sum_is_kept(modes):
    # (5.5): T_res* and zeta both act on the wheel only
    result = uio_existence(modes["torque and speed phase"], ["T_res_star", "zeta"])
    assert result.unknown == ("T_res_star",) and result.collinear == ("zeta",)


def test_an_input_the_phase_does_not_have_is_a_clear_error(modes):
    with pytest.raises(GearsymError, match="T_K38 is not an input of the gear 3"):
        uio_existence(modes["gear 3"], ["T_K38"])


def second_order(c: int) -> LinearMode:
    """x1' = x2 + d, x2' = -2 x1 - 3 x2 + c d + u, y = x1: by hand the Rosenbrock determinant
    is C adj(sI - A) E = s + 3 + c, so the only invariant zero is s = -(3 + c)."""
    form = LinearForm(
        mode="hand",
        A=sp.Matrix([[0, 1], [-2, -3]]),
        B=sp.Matrix([[0, 1], [1, c]]),
        states=["x1", "x2"],
        inputs=["u", "d"],
        parameters=(),
    )
    return LinearMode("hand", form, sp.Matrix([[1, 0]]), ("y",))


@pytest.mark.parametrize("c, zero, exists", [(-5, 2.0, False), (1, -4.0, True), (-3, 0.0, False)])
def test_zero_polynomial_of_a_hand_derived_system(c, zero, exists):
    result = uio_existence(second_order(c), ["d"])
    assert result.matching
    (z,) = result.invariant_zeros
    assert z == pytest.approx(zero) and result.exists is exists


def test_the_estimation_error_ignores_the_unknown_input(modes):
    mode = modes["torque and speed phase"]
    h = 0.01
    uio = design_uio(mode, ["T_res_star"], h, hold="zoh")
    assert uio.spectral_radius < 1
    values = {v.symbol: v.default for v in mode.form.parameters}
    a = np.array(mode.form.A.xreplace(values).evalf(), dtype=float)
    b = np.array(mode.form.B.xreplace(values).evalf(), dtype=float)
    c = np.array(mode.C.evalf(), dtype=float)
    ad, bd_all, *_ = cont2discrete((a, b, c, np.zeros((3, b.shape[1]))), h, method="zoh")
    inputs = mode.form.inputs
    known = [inputs.index(k) for k in uio.known]
    rng = np.random.default_rng(7)
    n_steps = 400
    u_all = np.zeros((n_steps, len(inputs)))
    u_all[:, known] = rng.normal(0, [200, 300, 300, 0.02], (n_steps, len(known)))
    # a large road load that jumps every 50 samples: the observer is never told
    road = np.repeat(rng.uniform(-3000, 3000, n_steps // 50), 50)
    u_all[:, inputs.index("T_res_star")] = road
    x = np.zeros((n_steps, 4))
    x[0] = [300.0, 90.0, 0.01, 36.0]
    for k in range(n_steps - 1):
        x[k + 1] = ad @ x[k] + bd_all @ u_all[k]
    y = x @ c.T
    x_hat, d_hat = uio.run(y, u_all[:, known], x0_guess=[250.0, 80.0, 0.0, 30.0])
    e = x - x_hat
    # e_{k+1} = F e_k exactly (up to rounding), whatever the road load does
    residual = e[1:] - e[:-1] @ uio.F.T
    assert np.max(np.abs(residual)) < 1e-9 * np.max(np.abs(x))
    assert np.max(np.abs(e[-50:])) < 1e-9 * np.max(np.abs(x))
    # the road load is recovered from the next measurement once the error has decayed
    assert np.max(np.abs(d_hat[200:, 0] - road[200:-1])) < 1e-6 * 3000
    # without the decoupling (H = 0: a Luenberger predictor with the same structure) the
    # unknown input leaves a lasting error: the check above can fail
    plain_z = uio.T @ np.zeros(4)
    worst = 0.0
    for k in range(n_steps - 1):
        plain_z = (ad - uio.K @ c) @ plain_z + bd_all[:, known] @ u_all[k, known] + uio.K @ y[k]
        worst = max(worst, abs(plain_z[3] - x[k + 1, 3])) if k > 200 else worst
    assert worst > 1e-3


def test_first_order_hold_matrices_equal_the_hold_integrals(modes):
    # B_1 = int_0^h e^{A (h - s)} s/h ds B_known and B_d = int_0^h e^{A s} ds B_known, by
    # adaptive quadrature of the matrix exponential (independent of the block exponential)
    from scipy.integrate import quad_vec
    from scipy.linalg import expm

    mode = modes["torque and speed phase"]
    h = 0.01
    uio = design_uio(mode, ["T_res_star"], h, hold="foh")
    values = {v.symbol: v.default for v in mode.form.parameters}
    a = np.array(mode.form.A.xreplace(values).evalf(), dtype=float)
    b = np.array(mode.form.B.xreplace(values).evalf(), dtype=float)
    known = [mode.form.inputs.index(k) for k in uio.known]
    b1, _ = quad_vec(lambda s: expm(a * (h - s)) * (s / h), 0.0, h, epsabs=1e-14)
    bd, _ = quad_vec(lambda s: expm(a * s), 0.0, h, epsabs=1e-14)
    np.testing.assert_allclose(uio.B1, b1 @ b[:, known], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(uio.Bd, bd @ b[:, known], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(uio.Ad, expm(a * h), rtol=1e-12)


def test_the_weighted_decoupling_holds_for_unequal_output_weights(modes):
    mode = modes["torque and speed phase"]
    uio = design_uio(mode, ["T_res_star"], 0.01, measurement_weight=[0.09, 1e-4, 1e-3])
    np.testing.assert_allclose(uio.left_inverse @ uio.C @ uio.Ed, np.eye(1), atol=1e-12)
    np.testing.assert_allclose(uio.T @ uio.Ed, 0.0, atol=1e-12 * np.max(np.abs(uio.Ed)))
    with pytest.raises(GearsymError, match="measurement_weight"):
        design_uio(mode, ["T_res_star"], 0.01, measurement_weight=[1.0, 0.0, 1.0])


def test_the_gain_solves_the_riccati_equation_as_scipy_does(modes):
    """The design's Riccati solution (mpmath, doubling) against SciPy's solve_discrete_are
    (LAPACK's QZ, an independent method) on the same T A_d and C: the gain K and F agree to
    1e-9 of their largest entry."""
    from scipy.linalg import solve_discrete_are

    mode = modes["torque and speed phase"]
    uio = design_uio(mode, ["T_res_star"], 0.01, measurement_weight=[0.09, 1e-4, 1e-3])
    a1, c = uio.T @ uio.Ad, uio.C
    r = np.diag([0.09, 1e-4, 1e-3])
    x = solve_discrete_are(a1.T, c.T, np.eye(len(a1)), r)
    k1 = a1 @ x @ c.T @ np.linalg.inv(c @ x @ c.T + r)
    f = a1 - k1 @ c
    np.testing.assert_allclose(uio.F, f, atol=1e-9 * np.max(np.abs(f)))
    np.testing.assert_allclose(uio.K, k1 + f @ uio.H, atol=1e-9 * np.max(np.abs(k1)))


def test_the_design_does_not_depend_on_the_machine_s_blas():
    """The gains are emitted as literals into generated/: the design gives the same doubles
    whichever kernels OpenBLAS picks (two processes, one forced to its generic kernels; a
    floating-point design differed at 1e-13 between two machines and made generated/ stale)."""
    import os
    import subprocess
    import sys

    script = (
        "from gearsym.symbolic.estimators import design_uio, linear_modes\n"
        "from gearsym.symbolic.loader import load_description\n"
        "m = {x.phase: x for x in linear_modes(load_description(), '2-3')}\n"
        "u = design_uio(m['torque and speed phase'], ['T_res_star'], 0.01)\n"
        "print([float(v).hex() for v in [*u.K.ravel(), *u.F.ravel(), *u.H.ravel()]])\n"
    )
    outputs = []
    for core in (None, "Prescott"):
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if core:
            env["OPENBLAS_CORETYPE"] = core
        run = subprocess.run(
            [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=600
        )
        assert run.returncode == 0, run.stderr
        outputs.append(run.stdout)
    assert outputs[0] == outputs[1]


# --------------------------------------------------------------- on the reference simulation


@pytest.fixture(scope="module")
def reference():
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description()
    return d, simulate(d, load_scenario(d, None))


def test_uio_on_the_reference_shift(reference):
    from gearsym.validation.studies.estimation.uio import run_uio

    d, result = reference
    coarse = {p.phase: p for p in run_uio(d, result, sample_time=0.01).phases}
    fine = {p.phase: p for p in run_uio(d, result, sample_time=0.001).phases}
    assert list(coarse) == [p.name for p in result.phases]
    # gear 2 is steady with K38 stuck and B05 open: the rigid gear model (2.54) is the
    # reference there up to the bristle deflection (2.66), so the road load is recovered to 1 %
    gear2 = coarse[result.phases[0].name]
    assert gear2.input_rmse["T_res_star"] < 0.01 * abs(gear2.input_mean["T_res_star"])
    for name, p in coarse.items():
        assert p.existence.exists, name
        # the measured speeds are estimated to far below a speed sensor's resolution (0.1 rad/s)
        # and the unmeasured twist to 1 % of its static value (T_ss/k_ss, about 0.02 rad)
        assert max(v for s, v in p.state_rmse.items() if s != "phi") < 0.03, name
        assert p.state_rmse["phi"] < 2e-4, name
    # in the torque and speed phases the known clutch torques move within a sample: the error
    # of the road load comes from the hold between samples and must shrink with the sample time
    for name in ("torque phase", "speed phase"):
        assert fine[name].input_rmse["T_res_star"] < 0.1 * coarse[name].input_rmse["T_res_star"]


def test_with_clutch_torques_unknown_only_the_gears_have_an_observer(reference):
    from gearsym.validation.studies.estimation.uio import run_uio

    d, result = reference
    run = run_uio(d, result, unknown=["T_K38", "T_B05", "T_res_star"])
    verdicts = {p.phase: p.existence.exists for p in run.phases}
    assert verdicts == {
        "gear 2": True,
        "torque phase": False,
        "speed phase": False,
        "gear 3": True,
    }
    assert np.all(np.isnan(run.inputs["T_K38"]))  # never estimated: no UIO where it acts
    with pytest.raises(GearsymError, match="T_K99 is not an input of any phase"):
        run_uio(d, result, unknown=["T_K99"])


def test_estimate_command(tmp_path):
    import json
    import subprocess
    import sys

    def gearsym(*args):
        return subprocess.run(
            [sys.executable, "-m", "gearsym", "estimate", *args],
            capture_output=True,
            text=True,
            timeout=300,
        )

    out = tmp_path / "est"
    run = gearsym("--json", "--out", str(out))
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert data["filter"] == "uio" and data["unknown"] == ["T_res_star"]
    assert [p["existence"]["exists"] for p in data["phases"]] == [True] * 4
    assert sorted(p.name for p in out.iterdir()) == [
        "MANIFEST",
        "uio.csv",
        "uio.json",
        "uio.md",
        "uio.png",
    ]
    header = (out / "uio.csv").read_text().splitlines()[0].split(",")
    assert header[:3] == ["t", "omega_2_hat", "omega_2"] and "T_res_star_hat" in header
    for bad, key in (
        (("--unknown", "T_K99"), "--unknown"),
        (("--noise", "-1"), "--noise"),
        (("--sample-time", "10"), "--sample-time"),
    ):
        result = gearsym(*bad, "--out", str(tmp_path / "never"))
        assert result.returncode == 2 and key in result.stderr
        assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
        assert not (tmp_path / "never").exists()
