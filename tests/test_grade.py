"""Road grade ζ(t) as a scenario input ((2.53) and (5.3) list ζ among the inputs).

Expected values come from a hand derivation of the wheel equation (2.50) and from physics (the
energy balance), never from the code under test.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.scenario import default_scenario_path, load_scenario
from gearsym.validation.sim.simulate import simulate

STEP_AT = 0.8  # s, inside the speed phase of the built-in scenario (about 0.78-0.88 s; tested)
STEP_WIDTH = 5e-4  # s, one sample: the profile is piecewise linear, a step is a steep ramp
DELTA_ZETA = 0.05  # rad, a 5 % grade


def scenario_with(tmp_path: Path, table: str, name: str = "graded.toml") -> Path:
    path = tmp_path / name
    path.write_text(default_scenario_path().read_text(encoding="utf-8") + "\n" + table)
    return path


@pytest.fixture(scope="module")
def description():
    return load_description()


@pytest.fixture(scope="module")
def level(description):
    return simulate(description, check_models=False)


@pytest.fixture(scope="module")
def step(description, tmp_path_factory):
    table = (
        '[grade]\nunit = "rad"\n'
        f"time = [0.0, {STEP_AT}, {STEP_AT + STEP_WIDTH}]\n"
        f"value = [0.0, 0.0, {DELTA_ZETA}]\n"
    )
    path = scenario_with(tmp_path_factory.mktemp("grade"), table)
    return simulate(description, load_scenario(description, path))


def test_grade_step_decelerates_the_vehicle_by_g_sin_dzeta_times_the_mass_share(
    description, level, step
):
    """Hand derivation. The wheel equation (2.50) with (2.46) corrected and (2.49c):

        I_C^eff ω̇_C = 2 T_ss − r_dyn (F_r + F_ad + m_veh g sin ζ),  I_C^eff = I_wheel + m r².

    Right after a grade step Δζ the states are those of the level run (the step is one sample,
    0.5 ms, too short for ω_C or the twist φ, and so T_ss, to move noticeably), and F_r changes
    only through cos ζ (1 − cos 0.05 = 0.1 %). So the wheel acceleration drops by
    r_dyn m g sin Δζ / I_C^eff, and the vehicle, v = r_dyn ω_C, decelerates by

        Δa = g sin Δζ · m_veh r_dyn² / I_C^eff  (≈ g Δζ · m r²/I_C^eff for a small grade).
    """
    speed_phase = level.phase("speed phase")
    assert speed_phase.t_start < STEP_AT < STEP_AT + STEP_WIDTH < speed_phase.t_end
    vehicle = description.vehicle
    m, r, g = vehicle["m_veh"].value, vehicle["r_dyn"].value, vehicle["g"].value
    inertia = description.drivetrain["I_wheel"].value + m * r**2
    expected = g * math.sin(DELTA_ZETA) * m * r**2 / inertia
    k = int(np.argmin(np.abs(step.t - (STEP_AT + STEP_WIDTH))))
    j = int(np.argmin(np.abs(level.t - (STEP_AT + STEP_WIDTH))))
    assert step.t[k] == pytest.approx(level.t[j], abs=1e-12)
    a_level = r * level.signals["domega_C"][j]
    a_step = r * step.signals["domega_C"][k]
    assert a_level - a_step == pytest.approx(expected, rel=1e-2)
    # before the step nothing differs; afterwards the vehicle stays slower
    before = level.t < STEP_AT
    np.testing.assert_allclose(
        np.interp(level.t[before], step.t, step.signals["omega_C"]),
        level.signals["omega_C"][before],
        rtol=1e-9,
    )
    assert step.signals["v_vehicle"][-1] < level.signals["v_vehicle"][-1]
    # ζ(t) is recorded (timeseries.csv column "zeta")
    assert step.signals["zeta"][0] == 0.0
    assert step.signals["zeta"][-1] == pytest.approx(DELTA_ZETA)
    # the grade step is a breakpoint of the integration
    assert STEP_AT in step.scenario.breakpoints()


def test_energy_audit_closes_with_a_grade_profile(step):
    """Input work = Δ kinetic + Δ spring + Δ bristle + friction + damper + road work, the road
    work including the grade force's work ∫ r_dyn m g sin ζ(t) ω_C dt (T_res ω_C, 2.48)."""
    assert step.audit.relative_residual < 1e-6
    # the grade adds road work: ∫ m g sin Δζ v dt over the graded time, ≥ 0 when driving on
    assert step.audit.road_work > 0


def test_reduced_models_follow_the_reference_with_a_grade_profile(step):
    """The reduced models take ζ(t) from the record: inside their phases they stay as close
    as on the level road (README: shift 6.0e-3, gear 3 7.6e-3)."""
    assert step.checks
    for check in step.checks:
        assert check.max_relative_error < 2e-2, check


def test_constant_grade_equal_to_the_description_reproduces_the_run(description, level, tmp_path):
    zeta0 = description.vehicle["zeta"].value
    table = f'[grade]\nunit = "rad"\ntime = [0.0]\nvalue = [{zeta0}]\n'
    same = simulate(
        description, load_scenario(description, scenario_with(tmp_path, table)), check_models=False
    )
    np.testing.assert_array_equal(same.t, level.t)
    for key in ("omega_1", "omega_2", "omega_C", "phi"):
        np.testing.assert_allclose(same.signals[key], level.signals[key], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(same.signals["zeta"], np.full(len(level.t), zeta0))


@pytest.mark.parametrize(
    ("table", "key", "reason"),
    [
        ('[grade]\nunit = "deg"\ntime = [0.0]\nvalue = [0.0]\n', "grade.unit", "expected 'rad'"),
        (
            '[grade]\nunit = "rad"\ntime = [0.0, 0.0]\nvalue = [0.0, 0.1]\n',
            "grade.time",
            "increase",
        ),
        ('[grade]\nunit = "rad"\ntime = [0.0]\nvalue = [0.0, 0.1]\n', "grade.value", "1 times"),
        ('[grade]\nunit = "rad"\ntime = [0.0]\nvalue = [5.0]\n', "grade.value", "at most 0.5"),
        ('[grade]\nunit = "rad"\ntime = [0.0]\nvalue = [nan]\n', "grade.value", "finite"),
        ('[grade]\nunit = "rad"\ntime = [0.0]\nvalue = [0.0]\nvalues = [1]\n', "grade.values", ""),
    ],
)
def test_bad_grade_tables_give_one_line_errors(description, tmp_path, table, key, reason):
    with pytest.raises(GearsymError) as err:
        load_scenario(description, scenario_with(tmp_path, table))
    assert err.value.key == key
    assert reason in err.value.reason
    assert "\n" not in str(err.value)


def test_sensitivities_follow_the_recorded_grade(description, step):
    """Driven with the recorded Δζ(t), the open-loop shift model reproduces the graded
    reference as well as the level one (README: drift below 2 % of max |x_i|); with the grade
    dropped (Δζ ≡ 0) it misses the deceleration the step causes. S_ζ, the sensitivity to a
    constant offset of the whole profile, agrees with central differences of that offset."""
    from gearsym.validation.studies.driven_shift import (
        driven_shift_model,
        driving_inputs,
        initial_state,
        reference_from_result,
        sliding_masks,
    )
    from gearsym.validation.studies.sensitivity_integration import (
        CompiledModel,
        Interpolated,
        integrate,
    )
    from gearsym.validation.studies.sensitivity_peers import finite_difference_sensitivities
    from gearsym.validation.studies.sensitivity_run import run_sensitivities

    data = reference_from_result(step)
    run = run_sensitivities(description, data=data)
    drift = run.drift()
    assert max(drift.values()) < 0.02, drift

    driven = driven_shift_model(description)
    values = run.values
    masks = sliding_masks(description, driven, data)
    u = driving_inputs(driven, data, masks, values)
    column = [v.name for v in driven.model.inputs].index("zeta_dev")
    np.testing.assert_allclose(u[:, column], step.signals["zeta"] - values["zeta"])
    level_u = u.copy()
    level_u[:, column] = 0.0
    x0 = initial_state(driven.model, data)
    ignored = integrate(
        CompiledModel(driven.model), Interpolated(data.t, level_u), x0, values, data.t
    )
    wheel = [v.name for v in driven.model.states].index("omega_C")
    error_ignored = np.max(np.abs(ignored[:, wheel] - step.signals["omega_C"]))
    error_driven = np.max(np.abs(run.trajectory.x[:, wheel] - step.signals["omega_C"]))
    assert error_ignored > 3 * error_driven

    t_eval = data.t[::40]
    inputs = Interpolated(data.t, u)
    fd = finite_difference_sensitivities(
        driven.model, ["zeta"], inputs, x0, values, t_eval, relative_step=1e-4
    )
    from gearsym.symbolic.sensitivity import sensitivity_equations
    from gearsym.validation.studies.sensitivity_integration import integrate_sensitivities

    eqs = sensitivity_equations(driven.model, ["zeta"])
    s_zeta = integrate_sensitivities(eqs, inputs, x0, values, t_eval).S[:, :, 0]  # S(t0) = 0
    scale = np.max(np.abs(s_zeta), axis=0)
    assert np.max(np.abs(fd[:, :, 0] - s_zeta) / scale) < 1e-5
