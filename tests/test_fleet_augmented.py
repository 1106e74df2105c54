"""States a shift filter over a fleet may carry beside the thesis' (4.1): the side shafts'
stiffness k_ss and the input-torque gain. The stiffness
(``gearsym estimate --fleet --params m_veh,mu_38,mu_05,zeta,k_ss``): its prior and random walk
are the description's stiffness factor's times the calibration's k_ss, the twist takes the
intensity tuned for that filter, the truth is the vehicle's own stiffness (for scoring only),
and one shift moves the estimate towards a stiffer vehicle's."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import pytest
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.estimator_calibration import (
    MODEL_ERROR_AUGMENTED,
    MODEL_ERROR_MAP_SCALE,
    STIFFNESS,
)
from gearsym.symbolic.estimators.ekf import augmented_model, default_parameters
from gearsym.validation.sim.fleet import parse_fleet

THESIS_AND_STIFFNESS = ("m_veh", "mu_38", "mu_05", "zeta", STIFFNESS)


def _stated(d, table: str, name: str) -> tuple[None, float]:
    """(None, value) of an intensity, read from the description's table."""
    return None, dict(getattr(d.estimator, table))[name].value


def test_the_stiffness_state_takes_the_factors_prior_and_random_walk(default_description):
    """k_ss = 10 000 N·m/rad in the description; its prior is the stiffness factor's (1 ±
    0.058: the fleet's uniform ±10 %, 0.1/√3) times it, its random walk the factor's (about
    0.001 per root second) times k_ss², and the states' intensities the
    [estimator.model_error_augmented] table's, not the thesis filter's [estimator.model_error]."""
    d = default_description
    k_ss = quantity(d, "drivetrain", STIFFNESS).value
    mean, sd = d.estimator.stiffness_factor_prior()
    assert mean == 1.0 and sd == pytest.approx(0.1 / 3**0.5, rel=0.01)
    assert d.estimator.prior_of(STIFFNESS, k_ss) == pytest.approx((k_ss, sd * k_ss))
    aug = augmented_model(d, "2-3", THESIS_AND_STIFFNESS)
    walk = d.estimator.stiffness_factor_random_walk()
    assert walk == pytest.approx(1e-6)
    assert aug.intensities[STIFFNESS] == pytest.approx(walk * k_ss**2)
    thesis = augmented_model(d, "2-3", default_parameters(d, "2-3"))
    for name in ("phi", "omega_1", "omega_2", "omega_C"):
        _, own = _stated(d, MODEL_ERROR_AUGMENTED, name)
        _, thesis_value = _stated(d, "model_error", name)
        assert aug.intensities[name] == own != thesis_value
        # the thesis' filter keeps its own intensities
        assert thesis.intensities[name] == thesis_value
    assert STIFFNESS not in thesis.state_names


def test_one_shift_moves_the_stiffness_towards_a_stiffer_vehicle(
    default_description, default_scenario
):
    """A vehicle whose side shafts are 10 % stiffer and otherwise the calibration's: the truth
    column is its k_ss (11 000), the filter starts at the calibration's 10 000 ± 580 and ends
    the shift within 3 σ of 11 000, having closed more than half of the gap (the twist's
    oscillation after the lock-up carries the stiffness against the inertias)."""
    d = default_description
    scenario = default_scenario
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    fleet = parse_fleet(
        '[fleet]\nname = "stiffer"\nm_veh = { value = 1950.0, unit = "kg", source = "test" }\n'
        '[fleet.factor]\ndrivetrain.k_ss = { value = 1.1, unit = "1", source = "test" }\n',
        "stiffer.toml",
        d,
    )
    evaluation = run_fleet(
        d, scenario, fleet, runs=1, seed=700000, bound=False, parameters=THESIS_AND_STIFFNESS
    )
    (fr,) = evaluation.runs
    j = list(fr.run.state_names).index(STIFFNESS)
    truth = 1.1 * quantity(d, "drivetrain", STIFFNESS).value
    assert fr.run.truth[0, j] == pytest.approx(truth) and fr.run.scored[:, j].all()
    start, end, sigma = fr.run.estimates[0, j], fr.run.estimates[-1, j], fr.run.sigmas[-1, j]
    assert start == pytest.approx(10000.0)  # the calibration's, whatever the truth
    assert abs(end - truth) < 0.5 * abs(start - truth), (end, truth)
    assert abs(end - truth) < 3 * sigma, (end, sigma)
    assert evaluation.final_stats(STIFFNESS).runs == 1


def _map_scale(d):
    """The description with its filter's μ states map scales (``--mu-model map_scale``)."""
    return replace(d, estimator=replace(d.estimator, mu_model="map_scale"))


def test_a_map_scale_filter_takes_its_own_tuned_intensities(default_description):
    """With the μ states map scales and the fleet's tolerances as states, the speeds and the
    twist take [estimator.model_error_map_scale]'s values (made to differ from the random-walk
    form's [estimator.model_error_augmented]); the random-walk form and a map-scale filter of
    the thesis' parameters alone keep theirs."""
    d = default_description
    # the map-scale table's values made distinct from every other table's (the shipped
    # tables may share a value, as phi's 1.5e-5 does), so that the test sees which is taken
    d = replace(
        d,
        estimator=replace(
            d.estimator,
            model_error_map_scale=tuple(
                (name, replace(t, value=7.0 * t.value))
                for name, t in d.estimator.model_error_map_scale
            ),
        ),
    )
    scaled = _map_scale(d)
    aug = augmented_model(scaled, "2-3", THESIS_AND_STIFFNESS)
    random_walk = augmented_model(d, "2-3", THESIS_AND_STIFFNESS)
    thesis_scaled = augmented_model(scaled, "2-3", default_parameters(d, "2-3"))
    for name in ("phi", "omega_1", "omega_2", "omega_C"):
        _, own = _stated(d, MODEL_ERROR_MAP_SCALE, name)
        _, augmented_value = _stated(d, MODEL_ERROR_AUGMENTED, name)
        assert aug.intensities[name] == own != augmented_value
        assert random_walk.intensities[name] == augmented_value
        assert thesis_scaled.intensities[name] == _stated(d, "model_error", name)[1]


@pytest.mark.parametrize(
    ("mu_model", "table"),
    [("random_walk", MODEL_ERROR_AUGMENTED), ("map_scale", MODEL_ERROR_MAP_SCALE)],
)
def test_tuning_with_the_stiffness_names_its_own_table(
    default_description, default_scenario, mu_model, table
):
    """Tuned with the stiffness as a state, the result belongs in [estimator.model_error_augmented]
    (with μ as map scales: [estimator.model_error_map_scale]) and multiplies that table's
    values, so that the thesis filter's stay their own."""
    d = default_description
    d = replace(d, estimator=replace(d.estimator, mu_model=mu_model))
    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.tuning import tune_model_error

    result = tune_model_error(
        d,
        default_scenario,
        load_fleet(d),
        [500002],
        factors=(2.0,),
        twist_factors=(0.5,),
        parameters=THESIS_AND_STIFFNESS,
    )
    _, twist = _stated(d, table, "phi")
    _, speed = _stated(d, table, "omega_1")
    assert result.intensities["phi"] == pytest.approx(0.5 * twist)
    assert result.intensities["omega_1"] == pytest.approx(2.0 * speed)
    assert result.table == table
    assert f"[estimator.{table}]" in result.text()


def _gearsym(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, check=False
    )


def test_the_command_reports_the_stiffness_beside_the_thesis_parameters():
    result = _gearsym(
        "estimate",
        "--filter",
        "ekf",
        "--fleet",
        "--params",
        ",".join(THESIS_AND_STIFFNESS),
        "--runs",
        "1",
        "--seed",
        "700001",
        "--json",
    )
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["initial"][STIFFNESS] == pytest.approx({"value": 10000.0, "sigma": 580.0})
    assert data["parameters"][STIFFNESS]["final"]["runs"] == 1


@pytest.mark.parametrize(
    "params",
    [
        "m_veh,k_ss",  # a thesis parameter missing
        "m_veh,mu_38,mu_05,zeta,c_W",  # an extra the fleet's filter does not carry
    ],
)
def test_the_fleet_takes_the_thesis_parameters_with_the_stiffness_or_without_only(params):
    result = _gearsym("estimate", "--filter", "ekf", "--fleet", "--params", params)
    assert result.returncode == 2 and result.stdout == ""
    (line,) = result.stderr.strip().splitlines()
    assert "--params" in line and "optionally with k_ss" in line, line


# ------------------------------------------------------------------ the input-torque gain


def test_the_gain_state_multiplies_the_told_input_torque(default_description):
    """With input_torque_gain a state, the model's right-hand side is the thesis filter's with
    T_In replaced by g T_In: equal at g = 1, and ∂f/∂g = T_In ∂f/∂T_In (the chain rule)."""
    d = default_description
    import sympy as sp
    from gearsym.symbolic import naming
    from gearsym.symbolic.estimator_calibration import INPUT_TORQUE_GAIN

    thesis = augmented_model(d, "2-3", default_parameters(d, "2-3"))
    gained = augmented_model(d, "2-3", (*default_parameters(d, "2-3"), INPUT_TORQUE_GAIN))
    g = next(v.symbol for v in gained.model.states if v.name == INPUT_TORQUE_GAIN)
    t_in = next(v.symbol for v in gained.model.inputs if v.name == naming.INPUT_TORQUE)
    n = len(thesis.model.rhs)
    for i in range(n):
        f_gain = gained.model.rhs[i]
        assert sp.simplify(f_gain.subs(g, 1) - thesis.model.rhs[i]) == 0
        assert sp.simplify(sp.diff(f_gain, g) - t_in * sp.diff(f_gain, t_in).subs(g, 1)) == 0
    assert gained.model.rhs[n] == 0  # a random walk
    # the sticking torque the mode logic compares with the capacity sees the gain too
    for e in gained.elements:
        expr = gained.sticking_torque[e]
        assert sp.simplify(expr.subs(g, 1) - thesis.sticking_torque[e]) == 0


def test_the_gains_truth_is_the_true_over_the_told_torque(default_description, default_scenario):
    """A vehicle whose engine gives 4 % more than its torque model and the e-machine exactly
    its command: the gain's truth is (1.04 T_eng + T_em) / (T_eng + T_em) of the scenario's
    commanded profiles wherever the told torque exceeds the floor, and absent elsewhere;
    the filter starts at 1 ± 0.029 (the engine's ±5 %, uniform)."""
    d = default_description
    scenario = default_scenario
    import numpy as np
    from gearsym.symbolic.estimator_calibration import INPUT_TORQUE_GAIN
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet
    from gearsym.validation.studies.estimation.setup import GAIN_TORQUE_FLOOR

    fleet = parse_fleet(
        '[fleet]\nname = "strong"\n'
        'engine_torque_gain = { value = 1.04, unit = "1", source = "test" }\n',
        "strong.toml",
        d,
    )
    parameters = (*default_parameters(d, "2-3"), INPUT_TORQUE_GAIN)
    evaluation = run_fleet(
        d, scenario, fleet, runs=1, seed=700010, bound=False, parameters=parameters
    )
    run = evaluation.runs[0].run
    j = list(run.state_names).index(INPUT_TORQUE_GAIN)
    engine = np.array([scenario.engine(float(t)) for t in run.t])
    e_machine = np.array([scenario.e_machine(float(t)) for t in run.t])
    told = engine + e_machine
    defined = np.abs(told) > GAIN_TORQUE_FLOOR
    assert defined.any() and (run.scored[:, j] == defined).all()
    expected = (1.04 * engine + e_machine)[defined] / told[defined]
    np.testing.assert_allclose(run.truth[defined, j], expected, rtol=1e-9)
    assert run.estimates[0, j] == pytest.approx(1.0, abs=0.02)  # one update from its prior
    assert evaluation.initial[INPUT_TORQUE_GAIN] == pytest.approx((1.0, 0.029))
    assert evaluation.separability == {}  # the gain is the filter's own state


def test_an_input_gain_scales_that_input_only(default_description):
    """with_input_gain: f and h with u replaced by g u, g a new parameter (default 1), the
    model unchanged; a name that is not an input is refused."""
    d = default_description
    import sympy as sp
    from gearsym.symbolic.drivetrain import shift_model
    from gearsym.symbolic.input_gain import input_torque_gain_variable, with_input_torque_gain
    from gearsym.symbolic.model import with_input_gain

    model = shift_model(d, "2-3")
    gained = with_input_torque_gain(model)
    g = gained.variable("input_torque_gain")
    assert g.default == 1.0 and g not in model.parameters and g in gained.parameters
    t_in = model.variable("T_In").symbol
    other = next(v.symbol for v in model.inputs if v.name != "T_In")
    for f, f_gain in zip(model.rhs, gained.rhs, strict=True):
        assert sp.expand(f_gain.subs(g.symbol, 1) - f) == 0
        assert sp.expand(sp.diff(f_gain, g.symbol) - t_in * sp.diff(f, t_in)) == 0
        assert (
            sp.expand(sp.diff(f_gain, other) - sp.diff(f, other).subs(t_in, g.symbol * t_in)) == 0
        )
    with pytest.raises(KeyError, match="not an input"):
        with_input_gain(model, "m_veh", input_torque_gain_variable())


def test_observability_takes_the_gain_beside_the_parameters():
    """`gearsym observability --params m_veh,zeta,input_torque_gain --json`: the gain is one of
    the unknowns the Lie-derivative rank (4.4) judges."""
    result = _gearsym("observability", "--params", "m_veh,zeta,input_torque_gain", "--json")
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert "input_torque_gain" in data["observable"]
    assert data["n_unknowns"] == len(data["observable"])


def test_with_constant_inputs_the_gain_is_tied_to_each_sliding_elements_mu():
    """The Lie-derivative rank (4.4) per mode with T_In and F_N held constant, against a hand
    count of the gearbox's torque balance: the gearbox speeds the mode keeps give one equation
    each, and g T_In and every sliding element's μ F_N are constants in them. One speed (one
    element locked, the other sliding): two constants in one equation, so that μ and g are
    one unobservable direction. Two speeds and both sliding: three constants in two, one
    direction through both μ and g. Two speeds and one sliding (the other open): two in two,
    full rank; no element sliding: g alone, full rank."""
    result = _gearsym(
        "observability",
        "--params",
        "m_veh,mu_38,mu_05,zeta,input_torque_gain",
        "--per-mode",
        "--input-model",
        "all=constant",
        "--json",
    )
    assert result.returncode == 0, result.stderr
    modes = json.loads(result.stdout)["modes"]
    assert len(modes) == 15
    for mode in modes:
        status = mode["status"]
        sliding = sorted(
            {"K38": "mu_38", "B05": "mu_05"}[e] for e, s in status.items() if s.startswith("slide")
        )
        locked = any(s == "locked" for s in status.values())
        if sliding and (locked or len(sliding) == 2):
            assert sorted(mode["unobservable"]) == sorted([*sliding, "input_torque_gain"]), mode
            assert mode["rank"] == mode["n_unknowns"] - 1, mode
        else:
            assert mode["unobservable"] == [] and mode["full_rank"], mode


def test_the_mass_gain_correlation_by_hand_and_none_where_the_fim_is_singular():
    """fim_correlation: the Cramér-Rao correlation of two parameters from the inverse of the
    FIM. For [[2, 1], [1, 2]] the inverse is [[2, -1], [-1, 2]] / 3: correlation -1/2. A FIM
    whose two columns are one (the window cannot tell the parameters apart) has no inverse:
    None; nor has one that rounding left indefinite ([[1, 2], [2, 1]]: its inverse
    [[-1, 2], [2, -1]] / 3 has negative variances)."""
    import numpy as np
    from gearsym.validation.studies.estimation.separability import fim_correlation

    assert fim_correlation(np.array([[2.0, 1.0], [1.0, 2.0]]), 0, 1) == pytest.approx(-0.5)
    assert fim_correlation(np.array([[1.0, 1.0], [1.0, 1.0]]), 0, 1) is None
    assert fim_correlation(np.array([[1.0, 2.0], [2.0, 1.0]]), 0, 1) is None
