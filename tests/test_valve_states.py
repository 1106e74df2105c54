"""The valves as the fleet's filter may carry them (``--params ...,valve_offset,valve_gain``):
the TCU is told F_N = A p_cmd, the piston sees A (g p_cmd + offset) while p_cmd > 0 (the
fleet's actuator, :class:`~gearsym.validation.sim.fleet.Actuators`). Both are consider states
(Schmidt): their tolerance enters the covariance, no measurement corrects them."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.drivetrain import element_short_name
from gearsym.symbolic.estimator_calibration import (
    CONSIDERED_STATES,
    INERTIA_FACTOR,
    VALVE_GAIN,
    VALVE_OFFSET,
)
from gearsym.symbolic.estimators.ekf import augmented_model, default_parameters, valve_input
from gearsym.validation.sim.fleet import parse_fleet

GAIN, OFFSET = 1.02, 7000.0  # a valve 2 % strong and 70 mbar high


def _values(model, at):
    symbols = {v.name: v.symbol for v in (*model.states, *model.inputs, *model.parameters)}
    return {symbols[k]: v for k, v in at.items() if k in symbols}


@pytest.mark.parametrize("commanded", [1.0, 0.0])
def test_the_valve_states_act_as_the_fleets_actuator_on_each_piston(default_description, commanded):
    """At a point with both elements sliding: the filter's right-hand side with g = 1.02 and
    offset 7 000 Pa equals the thesis filter's with each F_N replaced by g F_N + A offset
    (commanded) or g F_N (not commanded: the valve gives no offset), A each element's piston
    area from the description."""
    d = default_description
    thesis_params = default_parameters(d, "2-3")
    thesis = augmented_model(d, "2-3", thesis_params)
    valved = augmented_model(d, "2-3", (*thesis_params, VALVE_OFFSET, VALVE_GAIN))
    point = {
        "omega_1": 190.0,
        "omega_2": 110.0,
        "phi": 0.015,
        "omega_C": 36.0,
        "m_veh": 2000.0,
        "mu_38": 0.115,
        "mu_05": 0.125,
        "zeta": 0.02,
        "T_In": 140.0,
        "slide_K38": 1.0,
        "stick_K38": 0.0,
        "slide_B05": 1.0,
        "stick_B05": 0.0,
    }
    point.update({v.name: v.default for v in thesis.model.parameters if v.default is not None})
    told = {"K38": 8000.0, "B05": 11000.0}
    at_valved = dict(point, **{VALVE_GAIN: GAIN, VALVE_OFFSET: OFFSET})
    at_thesis = dict(point)
    for e, force in told.items():
        name = naming.normal_force(element_short_name(d, e))
        at_valved[name] = force
        at_valved[valve_input(e)] = commanded
        area = d.element(e).a_piston.value
        at_thesis[name] = GAIN * force + commanded * area * OFFSET
    n = len(thesis.model.rhs)
    got = [float(valved.model.rhs[i].xreplace(_values(valved.model, at_valved))) for i in range(n)]
    expected = [
        float(thesis.model.rhs[i].xreplace(_values(thesis.model, at_thesis))) for i in range(n)
    ]
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    told_only = _values(thesis.model, dict(point, F_N38=8000.0, F_N05=11000.0))
    unvalved = [float(thesis.model.rhs[i].xreplace(told_only)) for i in range(n)]
    assert got[0] != pytest.approx(unvalved[0], rel=1e-4)  # the check can fail
    # the capacity the mode logic compares with sees the valve too
    for e in valved.elements:
        cap = valved.capacity[e].xreplace(_values(valved.model, at_valved))
        cap_thesis = thesis.capacity[e].xreplace(_values(thesis.model, at_thesis))
        assert float(cap) == pytest.approx(float(cap_thesis), rel=1e-12)
    assert set(CONSIDERED_STATES) == {VALVE_OFFSET, VALVE_GAIN}
    assert sp.Symbol(VALVE_OFFSET, real=True) in valved.model.rhs.free_symbols


def test_considered_valve_states_are_never_corrected_but_widen_mu(
    default_description, default_scenario
):
    """One vehicle whose valves are 2 % strong and 70 mbar high: the filter's offset and gain
    stay at the calibration's 0 ± 6 000 Pa and 1 ± 0.017 at every sample (never corrected; the
    offset's σ grows by its random walk only);
    its on-coming μ's σ while the element slides is wider than the filter's without them (their
    tolerance enters the covariance: μ F_N is what the speeds show); the truths scored are the
    vehicle's valve."""
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    d = default_description
    fleet = parse_fleet(
        '[fleet]\nname = "valve"\nm_veh = { value = 1950.0, unit = "kg", source = "t" }\n'
        f'pressure_gain = {{ value = {GAIN}, unit = "1", source = "t" }}\n'
        f'pressure_offset = {{ value = {OFFSET}, unit = "Pa", source = "t" }}\n',
        "valve.toml",
        d,
    )
    thesis_params = default_parameters(d, "2-3")
    runs = {}
    for key, params in (
        # both with a state beyond the thesis', so both take the same tuned intensities
        ("with", (*thesis_params, INERTIA_FACTOR, VALVE_OFFSET, VALVE_GAIN)),
        ("without", (*thesis_params, INERTIA_FACTOR)),
    ):
        ev = run_fleet(
            d, default_scenario, fleet, runs=1, seed=700001, bound=False, parameters=params
        )
        runs[key] = ev
    (fr,) = runs["with"].runs
    names = list(fr.run.state_names)
    for name, (mean, sd), truth in (
        (VALVE_OFFSET, (0.0, 6000.0), OFFSET),
        (VALVE_GAIN, (1.0, 0.017), GAIN),
    ):
        j = names.index(name)
        assert np.all(fr.run.estimates[:, j] == mean)
        # the prior's variance and the random walk's (the valve drifts with oil temperature)
        q = d.estimator.valve_offset_random_walk() if name == VALVE_OFFSET else 0.0
        elapsed = fr.run.t - fr.run.t[0]
        assert fr.run.sigmas[:, j] == pytest.approx(np.sqrt(sd**2 + q * elapsed), rel=1e-9)
        assert fr.run.truth[:, j] == pytest.approx(truth)
    assert runs["with"].considered == (VALVE_OFFSET, VALVE_GAIN)
    mu = "mu_05"
    (plain,) = runs["without"].runs

    def sliding_sigma(run) -> float:  # mean σ of μ over the samples its element slides
        j = list(run.state_names).index(mu)
        return float(np.mean(run.sigmas[run.scored[:, j], j]))

    wide, narrow = sliding_sigma(fr.run), sliding_sigma(plain.run)
    assert wide > 1.05 * narrow, (wide, narrow)


def test_under_the_map_scale_the_offsets_force_goes_through_the_same_map_value(
    default_description,
):
    """With μ = s μ_map (``mu_model = "map_scale"``) the filter's F_N input carries the map
    value, F_N μ_map; the valve's force A θ must carry it too, or θ acts as if μ were s (about
    eight times μ): the form multiplies each element's valve input by the same map value as its
    F_N, read at the commanded pressure and the filter's slip, along a state and along a known
    slip history (the bound's)."""
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.symbolic.friction import load_mu_map
    from gearsym.validation.studies.estimation.mu_map_form import map_scale_form

    d = default_description
    aug = augmented_model(d, "2-3", (*default_parameters(d, "2-3"), VALVE_OFFSET, VALVE_GAIN))
    form = map_scale_form(d, aug)
    names = list(aug.input_names)
    z = np.zeros(len(aug.state_names))
    z[aug.state_names.index("omega_1")] = 190.0
    z[aug.state_names.index("omega_2")] = 120.0
    u = np.zeros(len(names))
    pressures = {"K38": 3.0e5, "B05": 5.0e5}
    for e, p in pressures.items():
        u[names.index(naming.normal_force(element_short_name(d, e)))] = p * (
            d.element(e).a_piston.value
        )
        u[names.index(valve_input(e))] = 1.0
    mapped = form(z, u)
    along = form.along(u[None, :], np.array([[abs(r @ z) for r in form.slip_rows]]))[0]
    mu_map, t_oil = load_mu_map(d), quantity(d, "friction", "T_oil").value
    for k, (e, p) in enumerate(pressures.items()):
        slip = abs(form.slip_rows[k] @ z)
        value = float(mu_map(np.array([p]), t_oil, np.array([slip]))[0])
        assert 0.05 < value < 0.3  # a μ, not 1
        for out in (mapped, along):
            assert out[names.index(valve_input(e))] == pytest.approx(value, rel=1e-12)
            force = out[names.index(naming.normal_force(element_short_name(d, e)))]
            assert force == pytest.approx(p * d.element(e).a_piston.value * value, rel=1e-12)
