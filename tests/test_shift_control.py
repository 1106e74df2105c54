"""The shift controller's phases in closed loop with the hybrid shift model and the actuator
(the adaptive-control issue). Expected values come from the calibration's own numbers (the
phases' timing), from physics (a piston that is not filled when the off-going element lets go
gives no torque: the input flares; one filled early presses against the off-going element:
tie-up) and from the target trajectory's closed form."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from gearsym.symbolic import naming
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.io.package_data import data_file
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import gear_ratio
from gearsym.validation.sim.fleet import Actuators
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import load_scenario
from gearsym.validation.studies.control.controller import (
    HOLD_AFTER_FILL,
    TIMEOUT_FACTOR,
    TO_LINE,
    Knowledge,
    ShiftController,
    TargetSlip,
)
from gearsym.validation.studies.control.downshift import DownshiftController
from gearsym.validation.studies.control.study import (
    OperatingPoint,
    Vehicle,
    make_controller,
    measured_target,
    run_vehicle,
)


@pytest.fixture(scope="module")
def d():  # noqa: ANN201
    return load_description(None)


@pytest.fixture(scope="module")
def point(d):  # noqa: ANN001, ANN201
    return OperatingPoint.from_scenario(load_scenario(d))


def _vehicle(d, fill_time_error: float = 0.0, m_veh: float | None = None) -> Vehicle:  # noqa: ANN001
    """The calibration as the truth, but for the stated differences."""
    truth = d
    if m_veh is not None:
        vehicle = dict(d.vehicle)
        vehicle["m_veh"] = replace(vehicle["m_veh"], value=m_veh)
        truth = replace(d, vehicle=vehicle)
    return Vehicle(truth, {}, Actuators(), fill_time_error)


# ------------------------------------------------------------------ the target trajectory


def test_target_slip_closed_form() -> None:
    """The trapezoidal slip acceleration integrates to σ0 over the phase; by symmetry half the
    slip is gone at half the phase; the peak rate is σ0 / (T (1 − r))."""
    target = TargetSlip(-200.0, 0.4, ramp=0.25)
    assert target.slip(0.0) == pytest.approx(-200.0)
    assert target.slip(0.4) == pytest.approx(0.0, abs=1e-12)
    assert target.slip(0.2) == pytest.approx(-100.0)
    assert target.rate(0.2) == pytest.approx(200.0 / (0.4 * 0.75))
    assert target.rate(0.0) == 0.0 and target.rate(0.4) == 0.0
    # by the ramp's closed form: at τ = r the slip has fallen by (r/2)/(1 − r) of σ0
    assert target.slip(0.1) == pytest.approx(-200.0 * (1 - 0.125 / 0.75))
    assert target.time_at(0.5) == pytest.approx(0.2, abs=1e-9)


# ------------------------------------------------------------------ pressure from force


def test_pressure_from_force_through_the_valve_view(d) -> None:  # noqa: ANN001
    """p_cmd = (F / a_piston + p_spring + offset − valve offset) / valve gain, by hand."""
    model = HybridSimulator(d, load_scenario(d), hybrid_shift(d, "2-3"))
    knowledge = Knowledge(mu={}, m_veh=2000.0, zeta=0.0, valve_gain=0.95, valve_offset=5e3)
    controller = ShiftController(d, model, knowledge)
    area = d.element("B05").a_piston.value
    spring = d.control.si("actuator", "return_spring")
    expected = (1000.0 / area + spring + 2e3 - 5e3) / 0.95
    assert controller.pressure("B05", 1000.0, 2e3) == pytest.approx(expected)


# ------------------------------------------------------------------ the phases in closed loop


@pytest.fixture(scope="module")
def nominal(d, point):  # noqa: ANN001, ANN201
    """The oracle on a vehicle that is the calibration (its knowledge exact)."""
    return run_vehicle(d, "2-3", point, _vehicle(d), 1, ("oracle",), keep_records=True)["oracle"][0]


def test_fill_phase_timing(d, nominal) -> None:  # noqa: ANN001
    """Fast fill for the calibrated fill time, then the hold pressure until the torque phase
    starts HOLD_AFTER_FILL later."""
    record = nominal.record
    fill = d.control.si("actuator", "fill_time")
    fast = d.control.si("actuator", "fast_fill_pressure")
    hold = d.control.si("actuator", "return_spring") + d.control.si("shift", "fill_hold")
    on = record.commands["B05"]
    ticks = record.ticks
    assert np.all(on[ticks < fill - 1e-9] == fast)
    between = (ticks >= fill - 1e-9) & (ticks < fill + HOLD_AFTER_FILL - 1e-9)
    assert between.any() and np.all(on[between] == pytest.approx(hold))
    first_torque = ticks[list(record.phases).index("torque")]
    assert first_torque == pytest.approx(fill + HOLD_AFTER_FILL, abs=0.0101)


def test_off_going_holds_until_the_torque_phase(nominal) -> None:  # noqa: ANN001
    """At its holding margin the off-going element stays locked through the fill, and it is
    commanded shut by the end of the torque phase (its estimated torque reached zero)."""
    record = nominal.record
    phases = np.array(record.phases)
    first_torque = record.ticks[np.argmax(phases == "torque")]
    releases = [e.t for e in record.events if e.element == "K38"]
    assert releases and min(releases) > first_torque
    last_torque = np.flatnonzero(phases == "torque")[-1]
    assert record.commands["K38"][last_torque + 1] == 0.0


def test_inertia_phase_meets_its_target_with_exact_knowledge(d, nominal) -> None:  # noqa: ANN001
    """Knowledge exact and the actuator nominal: the inertia phase lasts its target within
    10 %, no flare, the off-going element never held against the on-coming one (no tie-up),
    the shift ends locked in the to-gear."""
    quality = nominal.quality
    assert nominal.completed
    assert quality.duration == pytest.approx(measured_target(d), rel=0.10)
    assert not quality.flare and not quality.reversal_tie_up


def test_lockup_ramps_to_line_pressure(d, nominal) -> None:  # noqa: ANN001
    """After the lock-up decision the on-coming command reaches line pressure within TO_LINE
    and stays there."""
    record = nominal.record
    phases = np.array(record.phases)
    first = record.ticks[np.argmax(phases == "lockup")]
    line = d.drive.si("shift", "line_pressure")
    late = record.ticks >= first + TO_LINE + 1e-9
    assert late.any() and np.all(record.commands["B05"][late] == pytest.approx(line))
    assert "done" in record.phases


def test_underfill_flares_and_overfill_ties_up(d, point) -> None:  # noqa: ANN001
    """A piston 50 ms slower to fill than the TCU believes has not reached the discs when the
    off-going element lets go: the input flares. One 50 ms faster is pressed by the fast-fill
    pressure against the still-closed off-going element: tie-up."""
    slow = run_vehicle(d, "2-3", point, _vehicle(d, 0.05), 1, ("fixed",))["fixed"][0]
    fast = run_vehicle(d, "2-3", point, _vehicle(d, -0.05), 1, ("fixed",))["fixed"][0]
    assert slow.quality.flare and not slow.quality.reversal_tie_up
    assert fast.quality.reversal_tie_up and not fast.quality.flare


def test_rule_learns_the_fill_time(d, point) -> None:  # noqa: ANN001
    """The rule adds a fill step after each flare until the flare is gone: a fill 50 ms slow
    takes at most ceil(50 / 20) = 3 steps."""
    outcomes = run_vehicle(d, "2-3", point, _vehicle(d, 0.05), 5, ("rule",))["rule"]
    step = d.control.si("adaptation", "fill_step")
    flares = [o.quality.flare for o in outcomes]
    assert flares[0]
    first_clean = flares.index(False)
    assert first_clean <= math.ceil(0.05 / step)
    assert outcomes[first_clean].knowledge["fill_offset"] == pytest.approx(first_clean * step)


def test_the_torque_sign_picks_the_phase_order(d) -> None:  # noqa: ANN001
    """A 2-3 upshift under drive torque needs the on-coming element to pull the input down
    (torque phase first); under drag (a coast upshift) the drag slows the input by itself
    once the off-going element slides (inertia phase first, the downshift's order). A
    controller stepped with the other sign refuses in one line, and so does zero torque."""
    model = HybridSimulator(d, load_scenario(d), hybrid_shift(d, "2-3"))
    mu = quantity(d, "friction", "mu_nominal").value
    knowledge = Knowledge(mu={"K38": mu, "B05": mu}, m_veh=2000.0, zeta=0.0)
    assert type(make_controller(d, model, knowledge, 150.0)) is ShiftController
    assert type(make_controller(d, model, knowledge, -40.0)) is DownshiftController
    controller = make_controller(d, model, knowledge, 150.0)
    speeds = np.ones(len(d.shafts)) * 100.0
    with pytest.raises(GearsymError) as info:
        controller.step(0.0, speeds, -40.0)
    assert "phases are for a power-on upshift or a coast downshift" in str(info.value)
    assert "\n" not in str(info.value)
    with pytest.raises(GearsymError, match="no commanded input torque"):
        make_controller(d, model, knowledge, 0.0)


@pytest.fixture(scope="module")
def downshift(d):  # noqa: ANN001, ANN201
    """The oracle's power-on 3-2 downshift on the calibration's own vehicle."""
    scenario = load_scenario(d, data_file("scenario_3_2_power_on.toml"))
    point = OperatingPoint.from_scenario(scenario)
    return run_vehicle(d, "3-2", point, _vehicle(d), 1, ("oracle",), keep_records=True)["oracle"][0]


def test_downshift_slides_the_off_going_first_then_hands_over(d, downshift) -> None:  # noqa: ANN001
    """Power-on 3-2: the off-going element slides first (the inertia phase before the torque
    phase), the input rises to the lower gear's speed, the on-coming element locks at
    synchronism, the inertia phase lasts its target within 15 %, no flare and no tie-up."""
    record = downshift.record
    phases = list(record.phases)
    assert phases.index("inertia") < phases.index("torque") < phases.index("lockup")
    kinds = [(e.kind, e.element) for e in record.events]
    assert kinds.index(("break-away", "B05")) < kinds.index(("lock-up", "K38"))
    assert downshift.completed
    quality = downshift.quality
    assert quality.duration == pytest.approx(measured_target(d), rel=0.15)
    assert not quality.flare and not quality.reversal_tie_up


def _coast_scenario(d, tmp_path_factory):  # noqa: ANN001, ANN202
    """The shipped power-on 3-2 scenario with drag instead of drive torque (engine −20 N·m,
    the electric machine recuperating −20 N·m): a coast downshift."""
    text = data_file("scenario_3_2_power_on.toml").read_text()
    text = text.replace("engine =    [120.0]", "engine =    [-20.0]")
    text = text.replace("e_machine = [30.0]", "e_machine = [-20.0]")
    assert "[-20.0]" in text
    path = tmp_path_factory.mktemp("coast") / "scenario_3_2_coast.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def coast(d, tmp_path_factory):  # noqa: ANN001, ANN201
    """The oracle's coast 2-3 upshift (the shipped scenario) and coast 3-2 downshift on the
    calibration's own vehicle."""
    out = {}
    for shift, path in (
        ("2-3", data_file("scenario_2_3_coast.toml")),
        ("3-2", _coast_scenario(d, tmp_path_factory)),
    ):
        point = OperatingPoint.from_scenario(load_scenario(d, path))
        assert point.torque < 0
        outcome = run_vehicle(d, shift, point, _vehicle(d), 1, ("oracle",), keep_records=True)
        out[shift] = outcome["oracle"][0]
    return out


@pytest.mark.parametrize(
    ("shift", "order"),
    [("2-3", ("inertia", "torque", "lockup")), ("3-2", ("torque", "inertia", "lockup"))],
)
def test_coast_shifts_take_the_mirrored_phase_order(d, coast, shift: str, order) -> None:  # noqa: ANN001
    """Under drag the phase order flips: a coast upshift lets the drag slow the input while
    the off-going element slides (inertia phase first, handed over at synchronism); a coast
    downshift needs the on-coming element to pull the input up against the drag (torque
    phase first). Either way the shift completes with the input at the to-gear's speed
    (ω_in = i_to ω_out, 1 %), ends its inertia phase by synchronism rather than the
    timeout, and neither flares nor ties up (the off-going element's torque never reverses:
    the study's tie-up count; the output torque's dip below the to-gear's, which also counts
    the side shafts' swing after a hand-over, is not asserted)."""
    outcome = coast[shift]
    record = outcome.record
    phases = list(record.phases)
    assert [phases.index(p) for p in order] == sorted(phases.index(p) for p in order)
    assert outcome.completed
    spec = record.spec
    ratio = float(gear_ratio(d, d.gear(spec.to_gear)).ratio)
    w_in = record.signals[naming.speed(d.input_shaft)][-1]
    w_out = record.signals[naming.speed(d.output_shaft)][-1]
    assert w_in == pytest.approx(ratio * w_out, rel=0.01)
    timeout = TIMEOUT_FACTOR * d.control.si("shift", "inertia_phase")
    assert outcome.quality.duration < timeout
    assert not outcome.quality.flare
    assert not outcome.quality.reversal_tie_up


def test_the_estimator_does_not_learn_from_a_coast_shift(d) -> None:  # noqa: ANN001
    """Two coast 2-3 upshifts of a vehicle 20 ms late and heavier than the calibration: the
    estimator strategy goes into the second with the knowledge it had before the first (no
    fill estimate, no filter run), as the fixed calibration does."""
    point = OperatingPoint.from_scenario(load_scenario(d, data_file("scenario_2_3_coast.toml")))
    vehicle = _vehicle(d, fill_time_error=0.02, m_veh=2100.0)
    outcomes = run_vehicle(d, "2-3", point, vehicle, 2, ("fixed", "estimator"))
    estimator, fixed = outcomes["estimator"], outcomes["fixed"]
    assert estimator[1].knowledge == estimator[0].knowledge == fixed[1].knowledge
    assert estimator[0].fill is None and estimator[1].learned == {}


# ------------------------------------------------------------------ the command


def gearsym(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, timeout=600
    )


def test_cli_control_json_and_files(tmp_path) -> None:  # noqa: ANN001
    """Two shifts of the calibration's own vehicle: the JSON the issue names, every file."""
    out = tmp_path / "control"
    run = gearsym(
        *["control", "--strategies", "fixed,oracle", "--shifts", "2", "--out", str(out), "--json"]
    )
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    for name in ("fixed", "oracle"):
        entry = data["strategies"][name]
        assert len(entry["per_shift"]) == 2
        for key in (
            "shift",
            "jerk_mean",
            "jerk_p95",
            "vdv_p95",
            "duration_error_p95",
            "friction_energy_p95",
            "flares",
            "tie_ups",
        ):
            assert key in entry["per_shift"][0]
        assert set(entry["shifts_to_converge"]) >= {"median", "p95"}
    for name in ("control.json", "control.md", "runs.json", "sequence.png", "shift.png"):
        assert (out / name).exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--strategies", "fixed,psychic"], "--strategies: expected some of"),
        (["--shifts", "0"], "--shifts: must be at least 1"),
        (["--fleet", "--seed", "-1"], "--seed: must be at least 0"),
        (["--fleet", "--runs", "2", "--scheduler", "local", "--workers", "0"], "--workers: must"),
        (["--runs", "3"], "--runs: more than one vehicle needs --fleet"),
        (["--fix", "mu_scale=1.2"], "--fix: fixes an entry of a fleet: needs --fleet"),
        (["--fleet", "--fix", "mu_scale"], "--fix: expected NAME=NUMBER"),
        (["--fleet", "--fix", "mass=3"], "no fleet entry 'mass'"),
        (["--scenario", "{missing}"], "missing.toml"),
    ],
)
def test_cli_control_bad_input_is_one_line(tmp_path, args, message) -> None:  # noqa: ANN001
    args = [str(tmp_path / "missing.toml") if a == "{missing}" else a for a in args]
    run = gearsym("control", *args, "--out", str(tmp_path / "out"))
    assert run.returncode == 2, run.stderr
    assert message in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_rule_shortens_an_overfill(d, point) -> None:  # noqa: ANN001
    """A piston 50 ms faster than the TCU believes ties the shift up; the rule takes a fill
    step off after each tie-up until it is gone (at most ceil(50 / 20) = 3 steps), however the
    shock flares the input afterwards."""
    outcomes = run_vehicle(d, "2-3", point, _vehicle(d, -0.05), 5, ("rule",))["rule"]
    step = d.control.si("adaptation", "fill_step")
    tied = [o.quality.reversal_tie_up for o in outcomes]
    assert tied[0]
    first_clean = tied.index(False)
    assert first_clean <= math.ceil(0.05 / step)
    assert outcomes[first_clean].knowledge["fill_offset"] == pytest.approx(-first_clean * step)


def test_fixing_a_fleet_entry_leaves_the_other_draws(d) -> None:  # noqa: ANN001
    """--fix takes one entry out of the comparison: that entry is fixed, every other entry of
    every vehicle draws as before (each entry has its own random stream)."""
    from gearsym.validation.sim.fleet import load_fleet

    fleet = load_fleet(d)
    fixed = fleet.fixed("fill_time_error", 0.0, "--fix")
    for seed in (3, 10000):
        before, after = dict(fleet.draw(seed).values), dict(fixed.draw(seed).values)
        assert after.pop("fill_time_error") == 0.0
        before.pop("fill_time_error")
        assert after == before
    with pytest.raises(GearsymError, match="no fleet entry 'nope'"):
        fleet.fixed("nope", 1.0, "--fix")


def test_the_tcu_sees_what_the_truth_scores(d, point) -> None:  # noqa: ANN001
    """The strategies learn from the TCU's own verdict (input and output speeds only); on an
    underfill, an overfill and an exact shift it agrees with the truth's record on the flare,
    the tie-up and the rule's reading of the duration (too slow, within the band, too fast)."""
    from gearsym.validation.studies.control.strategies import RULE_BAND

    def reading(error: float) -> int:
        return 0 if abs(error) <= RULE_BAND else (1 if error > 0 else -1)

    for error in (0.05, -0.05, 0.0):
        (outcome,) = run_vehicle(d, "2-3", point, _vehicle(d, error), 1, ("fixed",))["fixed"]
        seen, truth = outcome.observed, outcome.quality
        assert seen.flare == truth.flare, error
        assert seen.tie_up == truth.reversal_tie_up, error
        assert reading(seen.duration_error) == reading(truth.duration_error), error


def test_fill_ending_inside_a_tick_gets_the_same_oil_volume(d) -> None:  # noqa: ANN001
    """A fill that ends 5 ms into a 10 ms tick: that tick is commanded p_s + ½ (p_ff − p_s),
    the oil volume ∝ (p − p_s) t of the remaining 5 ms at the fast-fill pressure (the piston's
    stroke law), spread over the tick; the next tick holds."""
    model = HybridSimulator(d, load_scenario(d), hybrid_shift(d, "2-3"))
    mu = quantity(d, "friction", "mu_nominal").value
    fill = d.control.si("actuator", "fill_time")
    knowledge = Knowledge(mu={"K38": mu, "B05": mu}, m_veh=2000.0, zeta=0.0, fill_offset=0.005)
    controller = make_controller(d, model, knowledge, 150.0)
    speeds = np.asarray(
        model.shaft_speeds(model.hybrid.from_mode)(
            model.initial_state(model.parameter_vector(model.values()))
        )
    ).ravel()
    commands = {
        round(t, 3): controller.step(t, speeds, 150.0)["B05"]
        for t in np.arange(0.0, fill + 0.025, 0.01)
    }
    fast = d.control.si("actuator", "fast_fill_pressure")
    spring = d.control.si("actuator", "return_spring")
    assert commands[round(fill - 0.01, 3)] == fast
    assert commands[round(fill, 3)] == pytest.approx(spring + 0.5 * (fast - spring))
    assert commands[round(fill + 0.01, 3)] == pytest.approx(
        spring + d.control.si("shift", "fill_hold")
    )


def test_a_repeated_knowledge_reuses_a_record_equal_to_a_fresh_one(d, point) -> None:  # noqa: ANN001
    """The fixed calibration shifts with the same knowledge every time and the rule's pressure
    offset settles: the reused records must be what simulating again gives."""
    vehicle = _vehicle(d, 0.05)
    kinds = ("fixed", "rule")
    reused = run_vehicle(d, "2-3", point, vehicle, 4, kinds)
    fresh = run_vehicle(d, "2-3", point, vehicle, 4, kinds, reuse=False)
    for kind in kinds:
        for a, b in zip(reused[kind], fresh[kind], strict=True):
            assert a.knowledge == b.knowledge
            assert a.quality.to_dict() == b.quality.to_dict()
            assert a.observed == b.observed
