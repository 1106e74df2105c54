"""Extended UIO (thesis 4.5): existence per phase, decoupling of the road load, CLI.

Expected values: the existence pattern from a hand argument checked with numpy's
matrix_rank on the Rosenbrock matrix built here from the SymPy Jacobian (not the CasADi one
the library uses); the road-load bias of a held wrong mass from the physics of (2.45, 2.46)
with the reference's wheel acceleration by finite differences; the grade's effect from the
scenario's truth.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.estimators.euio import ROAD_FREE
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.scenario import default_scenario_path, load_scenario
from gearsym.validation.sim.simulate import simulate
from gearsym.validation.studies.estimation.euio import run_euio
from gearsym.validation.studies.estimation.loop import run_ekf

DATA = Path(default_scenario_path()).parent


@pytest.fixture(scope="module")
def d():
    return load_description()


@pytest.fixture(scope="module")
def level(d):
    return simulate(d, load_scenario(d, None))


@pytest.fixture(scope="module")
def mass(d):
    return float(quantity(d, "vehicle", "m_veh").value)


@pytest.fixture(scope="module")
def wrong_mass_run(d, level, mass):
    return run_euio(d, level, noise=False, initial={"m_veh": 0.7 * mass})  # 30 % light


def test_existence_per_phase_matches_rank_tests_by_hand(d, level, wrong_mass_run):
    """m_veh enters ω̇_C only, through I_C^eff (2.46), the row the road load acts on: its
    column of A is a multiple of E, so P(0) = [[−A, −E], [C, 0]] drops rank (zero at s = 0)
    in every phase. μ of an element acts on ω_1, ω_2 while it slides: rank(P(0)) full there."""
    run = wrong_mass_run
    from gearsym.symbolic.estimators.ekf import augmented_model

    discrete_aug = augmented_model(d, "2-3", ("m_veh", "mu_38", "mu_05"))
    model = discrete_aug.model
    syms = [*model.state_symbols, *model.input_symbols, *model.parameter_symbols]
    jac = sp.lambdify(syms, discrete_aug.jacobian, "numpy")
    p = discrete_aug.parameter_values(ROAD_FREE)
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    names = discrete_aug.state_names
    slides = {"mu_38": "slide_K38", "mu_05": "slide_B05"}
    expected = {}
    for phase in level.phases:
        k = int(np.argmin(np.abs(run.t - 0.5 * (phase.t_start + phase.t_end))))
        z = np.array([run.truth[k, j] for j in range(4)] + [1800.0, 0.11, 0.11])
        u = {"T_In": np.interp(run.t[k], level.t, level.signals["T_In"])}
        exists = run.existence[phase.name]
        ex = {e.parameter: e.exists for e in exists}
        assert ex["m_veh"] is False
        assert any(
            abs(zz) < 1e-9
            for zz in next(e for e in exists if e.parameter == "m_veh").invariant_zeros
        )
        expected[phase.name] = {name: ex[name] for name in ("mu_38", "mu_05")}
        # independent rank test at s = 0 and at s = 1.7 with the SymPy Jacobian
        uvec = [u["T_In"], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        inputs = [v.name for v in model.inputs]
        for name in ("m_veh", "mu_38", "mu_05"):
            uu = list(uvec)
            uu[inputs.index("F_N38")] = np.interp(run.t[k], level.t, level.signals["F_N38"])
            uu[inputs.index("F_N05")] = np.interp(run.t[k], level.t, level.signals["F_N05"])
            uu[inputs.index(slides.get(name, "slide_K38"))] = 1.0
            a_full = np.array(jac(*z, *uu, *p), dtype=float)
            idx = [0, 1, 2, 3, names.index(name)]
            a = a_full[np.ix_(idx, idx)]
            e = np.zeros((5, 1))
            e[3, 0] = -1.0 / (6.4 + 1800.0 * r_dyn**2)
            c = np.zeros((3, 5))
            c[0, 0] = c[1, 1] = c[2, 3] = 1.0
            assert np.linalg.matrix_rank(c @ e) == np.linalg.matrix_rank(e) == 1  # matching

            ranks = [
                np.linalg.matrix_rank(np.block([[s * np.eye(5) - a, -e], [c, np.zeros((3, 1))]]))
                for s in (0.0, 1.7)
            ]
            dropped = ranks[0] < ranks[1]
            normal = {"mu_38": "F_N38", "mu_05": "F_N05"}
            if name == "m_veh":
                assert dropped, phase.name
            elif uu[inputs.index(normal[name])] > 0:  # pressed and sliding: decoupled
                assert not dropped, (phase.name, name)
            else:  # no normal force: μ has no effect, an unobservable integrator
                assert dropped, (phase.name, name)
    # where each μ is estimated: exactly the phases in which its element slides (2-3: K38
    # slides in the torque phase only, B05 in the torque and the speed phase, 2.55-2.58)
    assert expected == {
        "gear 2": {"mu_38": False, "mu_05": False},
        "torque phase": {"mu_38": True, "mu_05": True},
        "speed phase": {"mu_38": False, "mu_05": True},
        "gear 3": {"mu_38": False, "mu_05": False},
    }


def test_held_mass_keeps_estimate_and_sigma(wrong_mass_run, mass):
    run = wrong_mass_run
    j = run.state_names.index("m_veh")
    assert np.all(run.estimates[:, j] == 0.7 * mass)
    assert np.all(run.sigmas[:, j] == run.sigmas[0, j])
    assert run.held[1:, j].all()


def test_road_load_estimate_in_steady_gear(d, level, mass, wrong_mass_run):
    """Noise-free, gear 2 (steady, the rigid filter model fits): with the true mass the
    phase-mean d̂ is the reference T_res within 10 N m (the filter's rigid model against the
    compliant reference); with the mass held 30 % light d̂ = T_res + Δm r_dyn² ω̇_C
    ((2.45): I_C^eff ω̇_C = 2 T_ss − T_res), checked within 5 % of that bias, ω̇_C from
    finite differences of the reference."""
    right = run_euio(d, level, noise=False, initial={"m_veh": mass})
    (gear2,) = [p for p in level.phases if p.name == "gear 2"]
    ok = np.isfinite(right.load) & (right.t > gear2.t_start) & (right.t <= gear2.t_end)
    assert abs(np.mean(right.load[ok]) - np.mean(right.load_truth[ok])) < 10.0
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    t = wrong_mass_run.t
    w = np.interp(t, level.t, level.signals["omega_C"])
    acc = np.gradient(w, t)
    bias = (mass - 0.7 * mass) * r_dyn**2 * np.mean(acc[ok])
    measured = np.mean(wrong_mass_run.load[ok] - wrong_mass_run.load_truth[ok])
    assert bias > 100.0  # the shift accelerates the car: a visible bias
    assert abs(measured - bias) < 0.05 * bias


def test_decoupling_makes_mu_insensitive_to_an_unknown_grade(d, level, mass):
    """On a 4 % grade (m g r_dyn sin ζ ≈ 230 N m of road load unknown to both filters) the
    EUIO's μ errors equal the level ones within 1e-3, while the EKF told ζ = 0 explains the
    grade by a heavier car (m_veh error above 10 %)."""
    grade = simulate(d, load_scenario(d, DATA / "scenario_2_3_grade4.toml"))
    assert np.allclose(grade.signals["zeta"], math.atan(0.04), atol=1e-7)
    flat = run_euio(d, level, noise=False, initial={"m_veh": mass})
    hill = run_euio(d, grade, noise=False, initial={"m_veh": mass})
    for a, b in zip(flat.parameters[1:], hill.parameters[1:], strict=True):
        assert a.name == b.name and a.name.startswith("mu_")
        assert abs(a.rmse - b.rmse) < 1e-3, a.name
        assert b.rmse < 0.02  # and small: the reference μ map moves by about 0.02
    ekf = run_ekf(d, grade, initial={"m_veh": mass}, parameters=("m_veh", "mu_38", "mu_05"))
    (m_est,) = [p for p in ekf.parameters if p.name == "m_veh"]
    assert abs(m_est.estimate - mass) > 0.1 * mass


def test_cli_json_keys(tmp_path, capsys):
    from gearsym.cli import main

    assert main(["estimate", "--filter", "euio", "--json", "--out", str(tmp_path / "o")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["filter"] == "euio" and out["runs"] == 1 and out["sample_time"] == 0.01
    for name in ("m_veh", "mu_38", "mu_05"):
        entry = out["parameters"][name]
        for key in ("truth", "initial", "estimate", "sigma", "rmse", "crb_sigma", "identifiable"):
            assert key in entry
    assert entry["identifiable"]["speed phase"] is True
    assert "rmse" in out["unknown_inputs"]["T_res_star"]
    assert [p["name"] for p in out["phases"]] == ["gear 2", "torque phase", "speed phase", "gear 3"]
    assert {p.name for p in (tmp_path / "o").iterdir()} >= {"euio.csv", "euio.png", "euio.json"}
    assert out["modes"] == "filter"  # the filter decides the element modes by default
    assert main(["estimate", "--filter", "euio", "--modes", "reference", "--json"]) == 0
    reference = json.loads(capsys.readouterr().out)
    assert reference["modes"] == "reference"
    for run in (out, reference):  # either way μ38 is estimated: closer to the truth than
        mu = run["parameters"]["mu_38"]  # its initial value, and within 3σ of it
        assert abs(mu["estimate"] - mu["truth"]) < abs(mu["initial"] - mu["truth"])
        assert abs(mu["estimate"] - mu["truth"]) < 3.0 * mu["sigma"]


def test_cli_refuses_bad_initial_in_one_line():
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-m", "gearsym", "estimate", "--filter", "euio", "--initial", "m_veh=x"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "--initial" in lines[0] and "Traceback" not in result.stderr


def test_masks_of_a_downshift_follow_its_phase_order(d):
    """The design-time masks the emitted header states (euio_phase_masks, generic operating
    point) for the power-on 3-2 list its phases in the order they happen when the off-going
    B05 is released first (``scenario_3_2_power_on_release_first.toml``): speed phase (B05
    slides, K38 open), then torque phase (B05 slides, K38 sticks). From (3.14), a μ acts only
    while its element slides: μ38 is held in every phase, m_veh too (its column is the
    load's, above). μ05 is estimable in the speed phase only: in the torque phase K38 holds
    the gearbox rigid in gear 2, so B05's friction torque acts on it in the same direction as
    the side shaft's twist, and a constant friction torque and a constant road load reach the
    same steady state (a zero at s = 0, as for m_veh); in the speed phase the gearbox has two
    degrees of freedom and both are measured. The masks equal run_euio's existence at the
    midpoints of the reference's detected phases."""
    from gearsym.symbolic.estimators.euio import euio_phase_masks

    path = DATA / "scenario_3_2_power_on_release_first.toml"
    result = simulate(d, load_scenario(d, path), check_models=False)
    run = run_euio(d, result, noise=False)
    masks = euio_phase_masks(d, "3-2")
    assert [phase for phase, _, _ in masks] == [p.name for p in result.phases]
    stated = {phase: {run.state_names[i] for i in held} for phase, held, _ in masks}
    assert stated == {
        "gear 3": {"m_veh", "mu_38", "mu_05"},
        "speed phase": {"m_veh", "mu_38"},
        "torque phase": {"m_veh", "mu_38", "mu_05"},
        "gear 2": {"m_veh", "mu_38", "mu_05"},
    }
    found = {
        phase: {x.parameter for x in tests if not x.exists}
        for phase, tests in run.existence.items()
    }
    assert found == stated
