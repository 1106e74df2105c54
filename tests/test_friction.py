"""Properties of the friction models in symbolic/friction.py (thesis eqs. 2.59-2.70).

Expected values come from closed-form hand derivations (noted at each test), never from the
code under test. Shift-element data of the tests: N_disc = 4, r_m = 0.08 m, mu = 0.12,
F_N = p_N A_disc = 5e5 Pa * 0.01 m^2 = 5000 N, so |T_Cl,SS| = 2 * 4 * 0.08 * 0.12 * 5000 = 384 N m;
sigma0 = 1e5 N m/rad gives z_ss = 3.84e-3 rad.
"""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic import friction as fr
from scipy.integrate import solve_ivp

N_DISC, R_M, MU, F_N = 4, 0.08, 0.12, 5000.0
SIGMA0, SIGMA1, RATIO = 1e5, 100.0, 0.7
T_SS = 384.0  # 2 N_disc r_m mu F_N, by hand
Z_SS = T_SS / SIGMA0
ELEMENT = {"sigma0": SIGMA0, "sigma1": SIGMA1, "n_disc": N_DISC, "r_m": R_M, "z_ba_ratio": RATIO}


def element(z, dw, f_n=F_N, mu=MU):
    return fr.shift_element_num(z, dw, f_n, mu, **ELEMENT)


# ------------------------------------------------------------------------------------------
# Shift element (2.67)-(2.70)
# ------------------------------------------------------------------------------------------


def test_normal_force_and_capacity_by_hand():
    assert fr.normal_force(5e5, 0.01) == pytest.approx(F_N)
    # (2.69)/(2.70): sign from z if z != 0, else from dw.
    assert fr.t_cl_ss_num(-3.0, 1e-4, F_N, MU, N_DISC, R_M) == pytest.approx(T_SS)
    assert fr.t_cl_ss_num(-3.0, 0.0, F_N, MU, N_DISC, R_M) == pytest.approx(-T_SS)


@pytest.mark.parametrize("dw", [5.0, -20.0, 0.3])
def test_steady_sliding_converges_to_closed_form(dw):
    sol = solve_ivp(
        lambda t, y: [element(y[0], dw)[0]],
        (0.0, 0.2),
        [0.0],
        method="Radau",
        rtol=1e-10,
        atol=1e-14,
    )
    z_end = sol.y[0, -1]
    _, torque = element(z_end, dw)
    # Sliding element: +T_SS sign(dw), the power T dw is dissipated.
    assert torque == pytest.approx(math.copysign(T_SS, dw), rel=1e-6)
    assert z_end == pytest.approx(math.copysign(Z_SS, dw), rel=1e-6)


def _mass_on_surface(model, cycles=4):
    """Shaft b braked against the housing (dw = 0 - w), J dw_b/dt = T_ext + T, with the
    periodic load T_ext = F0 + A sin(Omega t) peaking at 0.5 T_SS (Dupont et al. 2002)."""
    inertia, f0, amp, omega = 0.1, 0.3 * T_SS, 0.2 * T_SS, 2 * math.pi

    def rhs(t, y):
        _, w, z = y
        zdot, torque = model(z, -w)
        return [w, (f0 + amp * math.sin(omega * t) + torque) / inertia, zdot]

    t_ends = np.arange(cycles + 1) * 2 * math.pi / omega
    # Start in the quasi-static equilibrium sigma0 z = -F0 so no transient is excited.
    sol = solve_ivp(
        rhs,
        (0.0, t_ends[-1]),
        [0.0, 0.0, -f0 / SIGMA0],
        method="LSODA",
        rtol=1e-9,
        atol=[1e-12, 1e-9, 1e-12],
        t_eval=t_ends,
        dense_output=True,
    )
    assert sol.success
    return sol


def test_periodic_load_below_breakaway_lugre_drifts_elastoplastic_does_not():
    lugre = _mass_on_surface(lambda z, dw: fr.lugre_num(z, dw, T_SS, SIGMA0, SIGMA1))
    ep = _mass_on_surface(element)
    # Quasi-static LuGre (sigma0 y = T_ext, y = -z, dy = dphi (1 -/+ sigma0 y / T_SS) on
    # loading/unloading) creeps per cycle by
    #   (T_SS / sigma0) ln((1 - u_min^2) / (1 - u_max^2)),  u = T_ext / T_SS in [0.1, 0.5].
    drift = Z_SS * math.log((1 - 0.1**2) / (1 - 0.5**2))
    per_cycle = np.diff(lugre.y[0])
    assert np.all(per_cycle > 0)
    np.testing.assert_allclose(per_cycle[1:], drift, rtol=0.03)
    assert lugre.y[0, -1] > 3.5 * drift
    # Elasto-plastic: |z| <= 0.5 z_ss < z_ba = 0.7 z_ss, purely elastic, phi = -(z - z0), so phi
    # is periodic. (The first cycle end differs from t = 0 by the damper's phase lag
    # -sigma1 A Omega / sigma0^2 ~ 5e-6 rad, because the start is not on the periodic orbit.)
    assert np.all(np.abs(ep.y[0, 1:] - ep.y[0, 1]) < 1e-3 * drift)
    phi = ep.sol(np.linspace(0.0, ep.t[-1], 400))[0]
    assert np.max(np.abs(phi)) <= 1.05 * 0.2 * T_SS / SIGMA0  # elastic amplitude A / sigma0


def _power_balance(z, dw, f_n, mu):
    zdot, torque = element(z, dw, f_n, mu)
    return torque * dw - SIGMA0 * z * zdot  # T dw - dV/dt


def test_dissipation_nonnegative_pointwise():
    rng = np.random.default_rng(1)
    n = 20000
    z = rng.uniform(-3, 3, n) * Z_SS  # includes over-deflected bristles |z| > z_ss
    dw = rng.uniform(-100, 100, n) * rng.choice([1e-3, 1.0], n)
    f_n = rng.uniform(0, 1, n) ** 3 * F_N * rng.choice([0.0, 1.0], n, p=[0.1, 0.9])
    mu = rng.uniform(0.10, 0.14, n)
    d = _power_balance(z, dw, f_n, mu)
    assert np.all(d >= -1e-9 * (1 + np.abs(SIGMA0 * z * dw)))


def test_overdeflected_bristle_relaxes_without_driving_the_shafts():
    # Hand derivation at z = 2 z_ss, dw > 0: alpha = 1, r = 2, so dz/dt = dw (1 - 2) = -dw, the
    # clipped damping vanishes and the elastic term is limited to the capacity: T = T_SS.
    dw = 10.0
    zdot, torque = element(2 * Z_SS, dw)
    assert zdot == pytest.approx(-dw)
    assert torque == pytest.approx(T_SS)
    # sticking (dw = 0) with the capacity dropped to half the bristle force: T_SS, not 2 T_SS
    assert element(2 * Z_SS, 0.0)[1] == pytest.approx(T_SS)
    # The literal (2.67), T = sigma0 z + sigma1 dz/dt, would generate energy here:
    # T dw - sigma0 z dz/dt = 4 T_SS dw - sigma1 dw^2 < 0 for dw > 4 T_SS / sigma1 = 15.4 rad/s.
    dw = 20.0
    zdot, torque = element(2 * Z_SS, dw)
    literal = (SIGMA0 * 2 * Z_SS + SIGMA1 * zdot) * dw - SIGMA0 * 2 * Z_SS * zdot
    assert literal == pytest.approx(4 * T_SS * dw - SIGMA1 * dw**2)
    assert literal < 0
    assert torque * dw - SIGMA0 * 2 * Z_SS * zdot >= 0  # the element as implemented


def _random_slip(rng):
    amp = rng.uniform(0.05, 2.0, 4)
    freq = rng.uniform(1.0, 15.0, 4) * 2 * math.pi
    phase = rng.uniform(0, 2 * math.pi, 4)
    return lambda t: float(np.sum(amp * np.sin(freq * t + phase)))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("drop", [False, True])
def test_no_energy_generated_along_trajectories(seed, drop):
    rng = np.random.default_rng(seed)
    slip = _random_slip(rng)
    t_drop = rng.uniform(0.2, 0.4)

    def f_n(t):  # optional fast ramp of the normal force down to zero over 5 ms
        return F_N * min(1.0, max(0.0, (t_drop + 5e-3 - t) / 5e-3)) if drop else F_N

    def rhs(t, y):
        dw = slip(t)
        zdot, torque = element(y[0], dw, f_n(t))
        return [zdot, torque * dw]

    t_eval = np.linspace(0.0, 0.6, 301)
    sol = solve_ivp(
        rhs, (0.0, 0.6), [0.0, 0.0], method="LSODA", rtol=1e-8, atol=[1e-13, 1e-9], t_eval=t_eval
    )
    assert sol.success
    z, work = sol.y
    stored = 0.5 * SIGMA0 * z**2
    assert np.all(work - stored >= -1e-6 * (1 + np.abs(work)))
    # The trajectory must actually exercise sliding (|z| reaching z_ss), else it proves little.
    assert np.max(np.abs(z)) > 0.99 * Z_SS
    if drop:  # open element: the bristle has relaxed to the floor capacity, torque ~ 0
        assert abs(z[-1]) <= 1.01 * fr.T_SS_MIN / SIGMA0 + 1e-12


def test_open_element_at_rest_is_finite():
    # F_N = 0, z = 0, dw = 0: the printed (2.68) with k_sign = 0 would evaluate 0 / 0.
    zdot, torque = element(0.0, 0.0, 0.0)
    assert (zdot, torque) == (0.0, 0.0)


# ------------------------------------------------------------------------------------------
# alpha (2.66), static models, Dahl
# ------------------------------------------------------------------------------------------


def test_alpha_continuous_bounded_and_sign_rule():
    z_ss, z_ba = 2.0, 0.8
    eps = 1e-7
    for edge in (z_ba, z_ss):
        for sign in (1.0, -1.0):
            lo = fr.ep_alpha_num(sign * (edge - eps), sign, z_ss, z_ba)
            hi = fr.ep_alpha_num(sign * (edge + eps), sign, z_ss, z_ba)
            assert abs(hi - lo) < 1e-9  # the sine ramp has zero slope at both ends
    assert fr.ep_alpha_num(z_ba, 1.0, z_ss, z_ba) == 0.0
    assert fr.ep_alpha_num(z_ss, 1.0, z_ss, z_ba) == 1.0
    # Middle of the ramp: sin(0) = 0, so alpha = 1/2.
    assert fr.ep_alpha_num(-(z_ss + z_ba) / 2, -3.0, z_ss, z_ba) == pytest.approx(0.5)
    rng = np.random.default_rng(2)
    z = rng.uniform(-3, 3, 5000)
    dw = rng.uniform(-1, 1, 5000)
    a = fr.ep_alpha_num(z, dw, z_ss, z_ba)
    assert np.all((a >= 0) & (a <= 1))
    assert np.all(a[z * dw < 0] == 0)
    np.testing.assert_array_equal(a, fr.ep_alpha_num(-z, -dw, z_ss, z_ba))
    assert np.all(np.diff(fr.ep_alpha_num(np.linspace(0, 3, 301), 1.0, z_ss, z_ba)) >= 0)


def test_stribeck_limits_and_kinetic_model():
    f_n, mu_c, mu_s, w_s = 1000.0, 0.1, 0.15, 0.5
    assert fr.stribeck_num(0.0, f_n, mu_c, mu_s, w_s, 2.0) == pytest.approx(mu_s * f_n)
    # At |dw| = 20 w_s the Stribeck term is exp(-400): Coulomb remains.
    fast = fr.stribeck_num(-20 * w_s, f_n, mu_c, mu_s, w_s, 2.0)
    assert fast == pytest.approx(abs(fr.coulomb_num(-20 * w_s, f_n, mu_c)), rel=1e-12)
    assert fr.coulomb_num(-2.0, f_n, mu_c) == pytest.approx(-100.0)
    assert fr.coulomb_num(0.0, f_n, mu_c) == 0.0
    curve = fr.stribeck_num(np.linspace(0, 5, 50), f_n, mu_c, mu_s, w_s, 2.0)
    assert np.all(np.diff(curve) <= 0)
    assert fr.viscous_num(-4.0, 3.0, 0.5) == pytest.approx(-6.0)  # 3 * 4^0.5 * (-1)
    args = (f_n, mu_c, mu_s, w_s, 2.0, 3.0, 1.0)
    assert fr.kinetic_num(0.0, 80.0, *args) == pytest.approx(80.0)  # held: F = F_A
    assert fr.kinetic_num(0.0, -500.0, *args) == pytest.approx(-150.0)  # break-away mu_S F_N
    # dw = -w_s: -(100 + 50 e^-1) - 3 * 0.5
    assert fr.kinetic_num(-w_s, 0.0, *args) == pytest.approx(-(100 + 50 / math.e) - 1.5)


def test_dahl_matches_closed_form():
    # beta = 1, constant dw = v > 0, F(0) = 0: dF/dt = sigma0 v (1 - F/F_C), so
    # F(t) = F_C (1 - exp(-sigma0 v t / F_C)).
    f_c, sigma0, v = 50.0, 1e4, 0.2
    t = np.array([0.0, 0.01, 0.02, 0.05])
    sol = solve_ivp(
        lambda _, y: [fr.dahl_num(y[0], v, f_c, sigma0, 1.0)],
        (0, t[-1]),
        [0.0],
        t_eval=t,
        rtol=1e-10,
        atol=1e-10,
    )
    np.testing.assert_allclose(sol.y[0], f_c * (1 - np.exp(-sigma0 * v * t / f_c)), rtol=1e-7)


# ------------------------------------------------------------------------------------------
# Symbolic versions: agree with the numeric ones and print as C
# ------------------------------------------------------------------------------------------

S = sp.symbols(
    "z dw f_n mu sigma0 sigma1 n_disc r_m ratio f_a mu_c mu_s w_s d_s nu d_v beta", real=True
)
z, dw, f_n, mu, s0, s1, n_disc, r_m, ratio, f_a, mu_c, mu_s, w_s, d_s, nu, d_v, beta = S
C_FUNCS = {"sign", "Abs", "exp", "sin", "Max", "Min", "Piecewise", "mu_map"}

CASES = {
    "coulomb": (fr.coulomb_sym, fr.coulomb_num, (dw, f_n, mu_c)),
    "stiction": (fr.stiction_sym, fr.stiction_num, (f_a, f_n, mu_s)),
    "viscous": (fr.viscous_sym, fr.viscous_num, (dw, nu, d_v)),
    "stribeck": (fr.stribeck_sym, fr.stribeck_num, (dw, f_n, mu_c, mu_s, w_s, d_s)),
    "kinetic": (fr.kinetic_sym, fr.kinetic_num, (dw, f_a, f_n, mu_c, mu_s, w_s, d_s, nu, d_v)),
    "dahl": (fr.dahl_sym, fr.dahl_num, (f_a, dw, mu_c, s0, beta)),
    "lugre": (fr.lugre_sym, fr.lugre_num, (z, dw, mu_c, s0, s1)),
    "alpha": (fr.ep_alpha_sym, fr.ep_alpha_num, (z, dw, mu_c, mu_s)),
    "k_sign": (fr.k_sign_sym, fr.k_sign_num, (dw, z)),
    "t_cl_ss": (fr.t_cl_ss_sym, fr.t_cl_ss_num, (dw, z, f_n, mu, n_disc, r_m)),
    "shift_element": (
        fr.shift_element_sym,
        fr.shift_element_num,
        (z, dw, f_n, mu, s0, s1, n_disc, r_m, ratio),
    ),
}


def _sample(rng, sym):
    name = sym.name
    if name in ("z", "dw", "f_a"):  # signed, with exact zeros the models treat specially
        return rng.choice([0.0, *rng.uniform(-2, 2, 6)]) * (Z_SS if name == "z" else 10.0)
    if name == "f_n":
        return rng.choice([0.0, rng.uniform(0, 2 * F_N)])
    if name == "mu_s":  # used as z_ba in the alpha case: keep z_ba < z_ss (= mu_c there)
        return rng.uniform(0.0, 0.9) * 1e-3
    if name == "mu_c":
        return rng.uniform(1.0, 1.5) * 1e-3 if rng.random() < 0.5 else rng.uniform(100, 500)
    if name == "ratio":
        return rng.uniform(0.3, 0.9)
    return {
        "mu": 0.12,
        "sigma0": SIGMA0,
        "sigma1": SIGMA1,
        "n_disc": 4,
        "r_m": 0.08,
        "w_s": 0.7,
        "d_s": 2.0,
        "nu": 1.5,
        "d_v": 0.8,
        "beta": 1.3,
    }[name] * rng.uniform(0.5, 1.5)


@pytest.mark.parametrize("name", sorted(CASES))
def test_symbolic_matches_numeric_and_prints_as_c(name):
    sym_fn, num_fn, args = CASES[name]
    expr = sym_fn(*args)
    exprs = expr if isinstance(expr, tuple) else (expr,)
    for e in exprs:
        assert {f.func.__name__ for f in e.atoms(sp.Function)} <= C_FUNCS
        sp.ccode(e)  # strict printer: raises on anything C cannot evaluate
    compiled = sp.lambdify(args, exprs, modules="numpy")
    rng = np.random.default_rng(sum(map(ord, name)))
    for _ in range(300):
        vals = [_sample(rng, a) for a in args]
        if name == "alpha" and vals[3] >= vals[2]:
            vals[3] = 0.5 * vals[2]
        want = num_fn(*vals)
        want = want if isinstance(want, tuple) else (want,)
        np.testing.assert_allclose(compiled(*vals), want, rtol=1e-11, atol=1e-12, err_msg=name)


def test_shift_element_with_map_placeholder_matches_numeric():
    mu_map = fr.MuMap.from_toml()
    p_n, t_oil = sp.symbols("p_N T_oil", real=True)
    a_disc = 0.01
    zdot, torque = fr.shift_element_sym(
        z, dw, fr.normal_force(p_n, a_disc), mu_map.symbolic(p_n, t_oil, dw), s0, s1, 4, 0.08, 0.7
    )
    compiled = sp.lambdify(
        (z, dw, p_n, t_oil, s0, s1), (zdot, torque), modules=[{"mu_map": mu_map}, "numpy"]
    )
    rng = np.random.default_rng(3)
    for _ in range(100):
        zz, ww = rng.uniform(-2, 2) * Z_SS, rng.uniform(-150, 150)
        pp, tt = rng.uniform(0, 2e6), rng.uniform(0, 130)
        want = element(zz, ww, pp * a_disc, mu_map(pp, tt, ww))
        np.testing.assert_allclose(compiled(zz, ww, pp, tt, SIGMA0, SIGMA1), want, rtol=1e-11)


# ------------------------------------------------------------------------------------------
# Friction-coefficient map
# ------------------------------------------------------------------------------------------


def test_default_map_data_properties():
    with open(fr.DEFAULT_MU_MAP, "rb") as fh:
        doc = tomllib.load(fh)
    tables = [doc["axes"]["p_N"], doc["axes"]["T_oil"], doc["axes"]["dw"], doc["mu"]]
    assert all(t["unit"] and t["source"] for t in tables)
    mu_table = np.array(doc["mu"]["values"])
    assert mu_table.min() >= 0.10 and mu_table.max() <= 0.14
    assert np.all(np.diff(mu_table, axis=2) >= 0)  # non-negative mu-slip slope


def test_map_reproduces_grid_points_is_linear_between_and_clamps():
    with open(fr.DEFAULT_MU_MAP, "rb") as fh:
        doc = tomllib.load(fh)
    p, t, w = (np.array(doc["axes"][k]["values"]) for k in ("p_N", "T_oil", "dw"))
    table = np.array(doc["mu"]["values"])
    mu_map = fr.MuMap.from_toml()
    grid = np.meshgrid(p, t, w, indexing="ij")
    np.testing.assert_allclose(mu_map(*grid), table, rtol=0, atol=1e-15)
    # A point inside one cell: trilinear combination of its 8 corners, weights by hand.
    i, j, k, (a, b, c) = 1, 2, 3, (0.25, 0.6, 0.9)
    point = (
        p[i] + a * (p[i + 1] - p[i]),
        t[j] + b * (t[j + 1] - t[j]),
        w[k] + c * (w[k + 1] - w[k]),
    )
    want = sum(
        (a if di else 1 - a)
        * (b if dj else 1 - b)
        * (c if dk else 1 - c)
        * table[i + di, j + dj, k + dk]
        for di in (0, 1)
        for dj in (0, 1)
        for dk in (0, 1)
    )
    assert mu_map(*point) == pytest.approx(want, rel=1e-12)
    assert mu_map(point[0], point[1], -point[2]) == pytest.approx(want, rel=1e-12)  # |dw|
    # Clamped at the edges: below/above the grid the edge value holds (no extrapolation).
    assert mu_map(0.0, -40.0, 0.0) == table[0, 0, 0]
    assert mu_map(1e8, 500.0, -1e4) == table[-1, -1, -1]
    assert mu_map(p[1], t[2], 1e4) == table[1, 2, -1]


GOOD = {
    "axes.p_N": {"unit": "Pa", "source": "test", "values": [1e5, 2e5]},
    "axes.T_oil": {"unit": "degC", "source": "test", "values": [20.0, 80.0]},
    "axes.dw": {"unit": "rad/s", "source": "test", "values": [0.0, 10.0, 50.0]},
    "mu": {"unit": "1", "source": "test", "values": [[[0.1, 0.11, 0.12]] * 2] * 2},
}


def _write(path, tables):
    lines = []
    for name, entries in tables.items():
        lines.append(f"[{name}]")
        lines += [f"{key} = {json.dumps(value)}" for key, value in entries.items()]
    path.write_text("\n".join(lines) + "\n")


def _mutated(table, key, value):
    tables = json.loads(json.dumps(GOOD))
    if value is None:
        del tables[table][key]
    else:
        tables[table][key] = value
    return tables


@pytest.mark.parametrize(
    ("tables", "key", "reason"),
    [
        (_mutated("axes.T_oil", "values", [20.0, 20.0]), "axes.T_oil.values", "increasing"),
        (_mutated("axes.dw", "values", [0.0, 50.0, 10.0]), "axes.dw.values", "increasing"),
        (_mutated("mu", "values", [[[0.1, 0.11]] * 2] * 2), "mu.values", "shape"),
        (_mutated("mu", "values", [[[0.1, 0.11, 0.12], [0.1]]] * 2), "mu.values", "shape"),
        (_mutated("mu", "values", [[[0.1, -0.01, 0.12]] * 2] * 2), "mu.values", "negative"),
        (_mutated("axes.p_N", "unit", None), "axes.p_N.unit", "missing unit"),
        (_mutated("mu", "unit", None), "mu.unit", "missing unit"),
        (_mutated("axes.p_N", "unit", "bar"), "axes.p_N.unit", "not supported"),
        (_mutated("mu", "source", None), "mu.source", "missing source"),
    ],
)
def test_bad_map_files_give_one_line_errors(tmp_path, tables, key, reason):
    path = tmp_path / "bad_map.toml"
    _write(path, tables)
    with pytest.raises(ValueError) as info:
        fr.MuMap.from_toml(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key}: ")
    assert reason in message and "\n" not in message


def test_good_small_map_loads(tmp_path):
    path = tmp_path / "good.toml"
    _write(path, GOOD)
    # Halfway between dw = 10 and 50 rad/s: (0.11 + 0.12) / 2.
    assert fr.MuMap.from_toml(path)(1.5e5, 50.0, -30.0) == pytest.approx(0.115)
