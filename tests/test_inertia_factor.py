"""The gearbox's inertias as a filter state (``--params ...,inertia_factor``): a fleet's
gearboxes have every shaft and planet inertia within ±3 % of the design values (the default
fleet's ``factor.inertia``), one factor f for all of them. The filter's model with f is checked
against the same derivation on a description whose inertias are the scaled numbers (as the
fleet builds a vehicle), in every mode of the swapping elements."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from gearsym.symbolic.estimator_calibration import INERTIA_FACTOR
from gearsym.symbolic.estimators.ekf import augmented_model
from gearsym.symbolic.model import Model
from gearsym.validation.sim.fleet import parse_fleet, truth_description

THESIS = ("m_veh", "mu_38", "mu_05", "zeta")
FACTOR = 1.03


def _scaled_description(d, factor: float):
    """The calibration with every inertia times ``factor``, as the fleet builds a vehicle."""
    fleet = parse_fleet(
        f'[fleet]\nname = "heavier parts"\n[fleet.factor]\n'
        f'inertia = {{ value = {factor}, unit = "1", source = "test" }}\n',
        "parts.toml",
        d,
    )
    return truth_description(d, fleet.draw(1))


def _rhs(model: Model, values: dict[str, float]) -> np.ndarray:
    """f(x, u, p) at ``values`` (by name)."""
    symbols = {v.name: v.symbol for v in (*model.states, *model.inputs, *model.parameters)}
    return np.array(
        model.rhs.xreplace({symbols[k]: v for k, v in values.items() if k in symbols}).evalf(),
        dtype=float,
    ).ravel()


def test_the_factor_state_is_the_model_of_a_gearbox_with_scaled_inertias(default_description):
    """At a random point and in every slide/stick combination of the two swapping elements,
    the filter's right-hand side with f = 1.03 equals the one derived from the description
    with every inertia 1.03 times the design value (1e-9 relative): the gearbox's speeds slower
    by 1/f, the twist and the wheel unchanged, a sticking element's torque unchanged."""
    d = default_description
    with_f = augmented_model(d, "2-3", (*THESIS, INERTIA_FACTOR))
    scaled = augmented_model(_scaled_description(d, FACTOR), "2-3", THESIS)
    nominal = augmented_model(d, "2-3", THESIS)
    assert INERTIA_FACTOR in with_f.state_names
    rng = np.random.default_rng(5)
    point = {
        "omega_1": 180.0,
        "omega_2": 120.0,
        "phi": 0.02,
        "omega_C": 38.0,
        "m_veh": 2100.0,
        "mu_38": 0.11,
        "mu_05": 0.13,
        "zeta": 0.03,
        "T_In": 150.0,
        "F_N38": 9000.0,
        "F_N05": 12000.0,
    }
    point.update({v.name: v.default for v in with_f.model.parameters if v.default is not None})
    point = {k: v * (1 + 0.05 * rng.standard_normal()) for k, v in point.items()}
    gearbox_rows = 0
    for slide_k, stick_k, slide_b, stick_b in itertools.product((0, 1), repeat=4):
        if (slide_k and stick_k) or (slide_b and stick_b):
            continue
        modes = {
            "slide_K38": slide_k,
            "stick_K38": stick_k,
            "slide_B05": slide_b,
            "stick_B05": stick_b,
        }
        at = {**point, **modes}
        expected = _rhs(scaled.model, at)
        got = _rhs(with_f.model, {**at, INERTIA_FACTOR: FACTOR})
        n = len(expected)
        np.testing.assert_allclose(got[:n], expected, rtol=1e-9, atol=1e-9)
        assert got[n:] == pytest.approx(0.0)  # the parameters' random walks
        moved = ~np.isclose(_rhs(nominal.model, at), expected, rtol=1e-6, atol=0)
        gearbox_rows = max(gearbox_rows, int(moved.sum()))
    assert gearbox_rows == 2  # the check can fail: the scaled inertias do change ω̇1, ω̇2


def test_the_factors_prior_is_the_calibrations_and_its_truth_the_vehicles(
    default_description, default_scenario
):
    """The filter starts at f = 1 ± 0.017 (the ±3 % tolerance, 0.03/√3) whatever the vehicle;
    the scored truth is the vehicle's factor (1.03), which the filter never reads."""
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    d = default_description
    mean, sd = d.estimator.prior_of(INERTIA_FACTOR, 1.0)
    assert mean == 1.0 and sd == pytest.approx(0.03 / 3**0.5, rel=0.02)
    fleet = parse_fleet(
        '[fleet]\nname = "heavier parts"\nm_veh = { value = 1950.0, unit = "kg", source = "t" }\n'
        f'[fleet.factor]\ninertia = {{ value = {FACTOR}, unit = "1", source = "test" }}\n',
        "parts.toml",
        d,
    )
    evaluation = run_fleet(
        d,
        default_scenario,
        fleet,
        runs=1,
        seed=700000,
        bound=False,
        parameters=(*THESIS, INERTIA_FACTOR),
    )
    (fr,) = evaluation.runs
    j = list(fr.run.state_names).index(INERTIA_FACTOR)
    assert fr.run.estimates[0, j] == pytest.approx(1.0)
    assert fr.run.sigmas[0, j] == pytest.approx(sd)
    assert fr.run.truth[:, j] == pytest.approx(FACTOR)
    assert np.isfinite(fr.run.estimates[-1, j])
