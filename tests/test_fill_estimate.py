"""The fill-time estimate from the TCU's replay of its own commands
(:mod:`gearsym.validation.studies.control.fill_estimate`). Expected values are planted: the
truth is the calibration itself with a fill-time error the test chooses, so the replay with
that error is the same physics as the record (reproduced to the integrator's tolerance) and
the estimate must find it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.sim.actuator import ClutchActuator
from gearsym.validation.sim.drive_log import TcuLog
from gearsym.validation.sim.fleet import Actuators
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import load_scenario
from gearsym.validation.studies.control import fill_estimate
from gearsym.validation.studies.control.closed_loop import TICK, ClosedLoopShift
from gearsym.validation.studies.control.controller import Knowledge
from gearsym.validation.studies.control.fill_estimate import (
    GRID_STEP,
    FillBelief,
    FillEstimate,
    FillReplay,
    _detrended_rms,
)
from gearsym.validation.studies.control.study import (
    SHIFT_DURATION,
    OperatingPoint,
    Vehicle,
    make_controller,
    run_vehicle,
)

SHIFT = "2-3"


@pytest.fixture(scope="module")
def d():  # noqa: ANN201
    return load_description(None)


@pytest.fixture(scope="module")
def point(d):  # noqa: ANN001, ANN201
    return OperatingPoint.from_scenario(load_scenario(d))


def _exact(d) -> Knowledge:  # noqa: ANN001
    """What the truth is when the truth is the calibration: nominal μ, the description's mass,
    level road."""
    mu = quantity(d, "friction", "mu_nominal").value
    hybrid = hybrid_shift(d, SHIFT)
    return Knowledge(
        mu={e: mu for e in hybrid.friction_elements},
        m_veh=quantity(d, "vehicle", "m_veh").value,
        zeta=0.0,
    )


def _record(d, point, fill_time_error: float, valve: Actuators | None = None):  # noqa: ANN001, ANN202
    """One shift of the calibration vehicle whose pistons fill ``fill_time_error`` late
    (through ``valve``'s errors, if given), commanded with exact knowledge of everything but
    the fill (and the valve): the TCU's log and its commands."""
    spec = shift_spec(d, SHIFT)
    plant = ClosedLoopShift(d, SHIFT, point.vehicle_speed)
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, SHIFT))
    nominal = ClutchActuator.from_calibration(d.control)
    true = ClutchActuator.from_calibration(d.control, valve, fill_time_error)
    log = TcuLog(TICK, [s.name for s in d.shafts], list(model.hybrid.friction_elements))
    elements = (spec.off_going, spec.on_coming)
    result = plant.run(
        make_controller(d, model, _exact(d), point.torque),
        point.torque,
        point.torque,
        {e: true for e in elements},
        {e: nominal for e in elements},
        log,
        t_end=SHIFT_DURATION,
    )
    return log.arrays(), result


def test_detrending_removes_a_straight_line_and_nothing_else() -> None:
    """Against NumPy's own least-squares polynomial fit (an independent route): a line leaves
    nothing, a parabola leaves its residual about the best line."""
    t = np.linspace(0.0, 0.4, 41)
    assert _detrended_rms(3.0 - 7.0 * t, t) == pytest.approx(0.0, abs=1e-12)
    bump = 5.0 * (t - 0.1) ** 2 + 2.0 * t
    line = np.polyval(np.polyfit(t, bump, 1), t)
    assert _detrended_rms(bump, t) == pytest.approx(np.sqrt(np.mean((bump - line) ** 2)))


@pytest.mark.parametrize("planted", [0.04, -0.03])
def test_replay_finds_a_planted_fill_error(d, point, planted: float) -> None:  # noqa: ANN001
    """Late (+40 ms: a flare) and early (−30 ms: a tie-up). With the planted error the replay
    is the record's own physics: its input speed agrees to the integrators' tolerance
    (1e-8, so far under 1e-3 rad/s); the search finds the error within 2 ms, the
    calibration's fill explains the record much worse, and the estimate counts as sure (σ
    under 1 ms: nothing is left but the sensors' resolution, and a step off the fill leaves a
    large residual)."""
    arrays, result = _record(d, point, planted)
    replay = FillReplay(d, SHIFT)
    knowledge = _exact(d)
    assert replay.residual(planted, knowledge, arrays, result.commands, result.phases) < 1e-3
    found = replay.estimate(knowledge, arrays, result.commands, result.phases)
    assert found.delta == pytest.approx(planted, abs=2e-3)
    assert found.rms_assumed > 20 * max(found.rms, 1e-3)
    assert found.rms_side > 20 * max(found.rms, 1e-3)
    assert np.sqrt(found.variance) < 1e-3
    assert found.explains


def test_a_fill_is_found_jointly_with_a_valve_offset(d, point) -> None:  # noqa: ANN001
    """A piston 35 ms late behind a valve 80 mbar low, the TCU believing the valve exact: the
    replay that searches the offset with the fill (σ 60 mbar, the prior's) reproduces the
    record at the planted pair (the same physics) and finds the fill within 3 ms and the
    offset within 15 mbar; holding the offset at zero, the fill alone must take the blame
    for the torque the low valve did not give, and lands more than 5 ms off."""
    planted, offset = 0.035, -8.0e3
    arrays, result = _record(d, point, planted, Actuators(pressure_offset=offset))
    replay = FillReplay(d, SHIFT)
    knowledge = _exact(d)
    truth = replace(knowledge, valve_offset=offset)
    assert replay.residual(planted, truth, arrays, result.commands, result.phases) < 1e-3
    joint = replay.estimate(knowledge, arrays, result.commands, result.phases, offset_sigma=6e3)
    assert joint.delta == pytest.approx(planted, abs=3e-3)
    # so late a piston has not stroked by the compared window's end: later ones replay the
    # same, and the record bounds the fill from one side (its plateau's edge is the estimate)
    assert joint.one_sided
    assert joint.offset == pytest.approx(offset, abs=1.5e3)
    alone = replay.estimate(knowledge, arrays, result.commands, result.phases)
    assert abs(alone.delta - planted) > 5e-3
    assert alone.rms > 3 * max(joint.rms, 1e-2)


def test_a_right_fill_is_kept(d, point) -> None:  # noqa: ANN001
    """The fill the shift assumed was the truth's: the record is reproduced already: nothing
    is left for a fill to explain outright, and a belief that held it (here within its
    prior's ±29 ms) ends within 1 ms of it, sure of it."""
    arrays, result = _record(d, point, 0.0)
    found = FillReplay(d, SHIFT).estimate(_exact(d), arrays, result.commands, result.phases)
    assert found.rms_assumed < 1e-3
    assert not found.explains
    after = FillBelief(0.0, 0.029**2).updated(found)
    assert abs(after.delta) < 1e-3 and after.sigma < 1e-3


def test_fill_variance_is_the_least_squares_variance(monkeypatch) -> None:  # noqa: ANN001
    """For a signature linear in δ (y = g δ + e, n independent samples) the variance from the
    residual's valley is the textbook least-squares one, σ̂² / Σ g² with σ̂² the residual's mean
    square, computed here by NumPy's least squares on the same data (an independent route)."""
    rng = np.random.default_rng(7)
    n = 40
    g = rng.normal(3.0, 1.0, n)
    y = g * 0.012 + rng.normal(0.0, 0.2, n)
    (delta,), *_ = np.linalg.lstsq(g[:, None], y, rcond=None)

    def rms(x: float) -> float:
        return float(np.sqrt(np.mean((y - g * x) ** 2)))

    side = np.sqrt((rms(delta - GRID_STEP) ** 2 + rms(delta + GRID_STEP) ** 2) / 2.0)
    monkeypatch.setattr(fill_estimate, "INDEPENDENT_SAMPLES", float(n))
    found = FillEstimate(float(delta), rms(delta), float(side), rms(0.0))
    assert found.variance == pytest.approx(rms(delta) ** 2 / np.sum(g**2), rel=1e-9)


def test_fill_belief_is_a_scalar_kalman_filter() -> None:
    """Hand-computed: prior 0 ± 20 ms, drift 0, an estimate of +30 ms with σ 20 ms: the gain is
    ½, the belief +15 ms with variance half the prior's; a record that pins nothing down
    (infinite variance) leaves the belief and, with a drift, widens it by the drift."""
    prior = FillBelief(0.0, 0.02**2)
    # the valley's side that gives σ 20 ms with 0.1 rad/s left: rms_side² = rms² (1 + h² / (σ² N))
    n = fill_estimate.INDEPENDENT_SAMPLES
    side = 0.1 * np.sqrt(1.0 + GRID_STEP**2 / (0.02**2 * n))
    found = FillEstimate(0.03, 0.1, float(side), 0.2)
    assert found.variance == pytest.approx(0.02**2, rel=1e-9)
    after = prior.updated(found)
    assert after.delta == pytest.approx(0.015, rel=1e-9)
    assert after.variance == pytest.approx(0.02**2 / 2.0, rel=1e-9)
    flat = FillEstimate(0.05, 0.3, 0.3, 0.3)
    assert flat.variance == np.inf
    drifting = FillBelief(0.01, 1e-4, drift=0.002)
    kept = drifting.updated(flat)
    assert kept.delta == 0.01 and kept.variance == pytest.approx(1e-4 + 0.002**2)


def test_estimator_strategy_commands_the_estimated_fill(d, point) -> None:  # noqa: ANN001
    """A fill 40 ms slow: the first shift flares (physics, as the controller's own test);
    the estimator strategy's second shift believes a fill time within 5 ms of the truth's and
    does not flare."""
    fill = ClutchActuator.from_calibration(d.control).fill_time
    vehicle = Vehicle(d, {}, Actuators(), 0.04)
    outcomes = run_vehicle(d, SHIFT, point, vehicle, 2, ("estimator",))["estimator"]
    assert outcomes[0].quality.flare
    assert outcomes[1].knowledge["fill_time"] == pytest.approx(fill + 0.04, abs=5e-3)
    assert not outcomes[1].quality.flare


def test_rebuilt_pressures_are_the_logged_ones(d, point) -> None:  # noqa: ANN001
    """Two routes to what the TCU believes its elements pressed with: the closed loop's log
    (its nominal actuator advanced tick by tick beside the plant) and the actuator's
    ``at_ticks`` over the recorded commands, which the estimator uses to re-tell the filter
    with a learned fill: equal."""
    arrays, result = _record(d, point, 0.02)
    spec = shift_spec(d, SHIFT)
    nominal = ClutchActuator.from_calibration(d.control)
    line = d.drive.si("shift", "line_pressure")
    for element, filled in ((spec.off_going, True), (spec.on_coming, False)):
        rebuilt = nominal.at_ticks(nominal.initial(filled, line), result.commands[element], TICK)
        np.testing.assert_allclose(rebuilt, arrays[f"p_{element}"], rtol=0, atol=1e-6)


def test_a_fill_the_model_cannot_follow_is_no_candidate(d, point, monkeypatch) -> None:  # noqa: ANN001
    """A replay whose simulation fails (in the fleet study once an element's break-away
    chattered in the TCU's model) rules that fill out instead of ending the study: here every
    early fill fails, and the planted late one is still found."""
    arrays, result = _record(d, point, 0.04)
    replay = FillReplay(d, SHIFT)
    run = ClosedLoopShift.run

    def failing(self, controller, torque, true_torque, actuators, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        if next(iter(actuators.values())).fill_time < replay.nominal.fill_time:
            raise GearsymError("<replay>", "scenario", "chattering break-away")
        return run(self, controller, torque, true_torque, actuators, *args, **kwargs)

    monkeypatch.setattr(ClosedLoopShift, "run", failing)
    assert replay.residual(-0.02, _exact(d), arrays, result.commands, result.phases) == np.inf
    found = replay.estimate(_exact(d), arrays, result.commands, result.phases)
    assert found.delta == pytest.approx(0.04, abs=2e-3) and np.sqrt(found.variance) < 1e-3


def test_fill_time_and_command_duration_through_the_valve_view(d) -> None:  # noqa: ANN001
    """The replay's fill time is its actuator view's (the stroke at the nominal fast fill);
    what the controller commands is how long the fast fill lasts through its view of the
    valve. By the fill law (stroke volume (p_ff − p_s) t_fill, rate p_valve − p_s), a view
    with gain g and offset c strokes in t_fill (p_ff − p_s) / (g p_ff + c − p_s)."""
    replay = FillReplay(d, SHIFT)
    p_ff, p_s = replay.nominal.fast_fill_pressure, replay.nominal.return_spring
    view = Knowledge(mu={}, m_veh=1.0, zeta=0.0, valve_gain=1.02, valve_offset=8.0e3)
    fill_time = 0.09
    expected = fill_time * (p_ff - p_s) / (1.02 * p_ff + 8.0e3 - p_s)
    assert replay.duration(view, fill_time) == pytest.approx(expected, rel=1e-12)
    assert replay.parameter(view, expected) == pytest.approx(fill_time, rel=1e-12)
    nominal = Knowledge(mu={}, m_veh=1.0, zeta=0.0)
    assert replay.duration(nominal, fill_time) == pytest.approx(fill_time, rel=1e-12)


@pytest.mark.parametrize("planted", [-8.0e3, 8.0e3])
def test_estimator_strategy_learns_a_planted_valve_offset(d, point, planted: float) -> None:  # noqa: ANN001
    """The calibration's own vehicle with only a valve offset planted (±80 mbar, the fleet's
    range): over four shifts the filter's offset state moves from its prior (0 ± 6 000 Pa)
    towards the planted value, its σ shrinks, and the truth stays inside 3 σ; the controller is
    told the learned value. Broken sensitivities (no ∂p/∂δ) would leave σ at the prior's, a
    wrong sign would move the estimate away from the truth."""
    vehicle = Vehicle(d, {}, Actuators(pressure_offset=planted), 0.0)
    outcomes = run_vehicle(d, SHIFT, point, vehicle, 4, ("estimator",))["estimator"]
    learned = outcomes[-1].learned["valve_offset"]
    mean, sigma = learned
    assert sigma < 0.7 * 6.0e3
    assert abs(mean - planted) < 3.0 * sigma
    assert mean * planted > 0 and abs(mean) > 0.3 * abs(planted)
    assert outcomes[-1].knowledge["valve_offset"] == outcomes[-2].learned["valve_offset"][0]


def test_the_fill_prior_comes_from_the_table(tmp_path) -> None:  # noqa: ANN001
    """``[estimator.prior] fill_time_error`` states the belief before the first shift; without
    it the stated default 0 ± 29 ms (±50 ms uniform)."""
    from gearsym.symbolic.description import default_config_text
    from gearsym.validation.studies.control.strategies import FILL_DRIFT, fill_prior

    assert fill_prior(load_description(None)) == FillBelief(0.0, 0.029**2, FILL_DRIFT)
    text = default_config_text().replace(
        "[estimator.prior]\n",
        "[estimator.prior]\n"
        "fill_time_error = { mean = 0.01, sd = 0.005, unit = 's', source = 'x' }\n",
        1,
    )
    path = tmp_path / "box.toml"
    path.write_text(text)
    belief = fill_prior(load_description(path))
    assert (belief.delta, belief.sigma) == pytest.approx((0.01, 0.005), rel=1e-12)


def test_an_estimate_that_explains_the_record_replaces_the_belief() -> None:
    """Hand-built cases of the strategy's rule (:meth:`FillBelief.after`): an estimate that
    halves the assumed fill's residual (0.2 of 2.0 rad/s) replaces the belief outright, with
    its own variance, or the predicted one when its valley is flat; one that does not (1.5 of
    2.0) is weighed in, here with the gain ½ of equal variances."""
    prior = FillBelief(0.0, 0.02**2)
    n = fill_estimate.INDEPENDENT_SAMPLES
    sharp = FillEstimate(0.04, 0.2, 0.2 * float(np.sqrt(1.0 + GRID_STEP**2 / (1e-3**2 * n))), 2.0)
    assert sharp.explains and sharp.variance == pytest.approx(1e-6, rel=1e-9)
    taken = prior.after(sharp)
    assert taken.delta == 0.04 and taken.variance == pytest.approx(1e-6, rel=1e-9)
    flat = FillEstimate(0.04, 0.2, 0.2, 2.0)
    assert flat.explains and prior.after(flat) == FillBelief(0.04, 0.02**2)
    weak = FillEstimate(0.04, 1.5, 1.5 * float(np.sqrt(1.0 + GRID_STEP**2 / (0.02**2 * n))), 2.0)
    assert not weak.explains
    weighed = prior.after(weak)
    assert weighed.delta == pytest.approx(0.02, rel=1e-9)
    assert weighed.variance == pytest.approx(0.02**2 / 2.0, rel=1e-9)


def test_the_commanded_fill_is_the_belief_shortened_by_its_doubt(monkeypatch) -> None:  # noqa: ANN001
    """δ − κσ within the adaptation's limit (κ = FILL_RISK, 0 since the trial of 0.5 was not
    adopted: the belief's own δ)."""
    from gearsym.validation.studies.control import strategies

    doubtful = FillBelief(0.02, 0.01**2)
    assert strategies.fill_to_command(doubtful, 0.1) == pytest.approx(
        0.02 - strategies.FILL_RISK * 0.01
    )
    monkeypatch.setattr(strategies, "FILL_RISK", 0.5)
    assert strategies.fill_to_command(FillBelief(0.02, 0.0), 0.1) == pytest.approx(0.02)
    assert strategies.fill_to_command(doubtful, 0.1) == pytest.approx(0.015)
    assert strategies.fill_to_command(FillBelief(-0.09, 0.03**2), 0.1) == pytest.approx(-0.1)


def test_a_plateau_of_the_residual_bounds_the_fill_from_one_side() -> None:
    """Hand-built residuals (:meth:`FillReplay._plateau_edge`): a fill so late that the
    replay's piston never strokes in the window leaves the residual flat beyond some δ (here
    falling linearly to 0.5 rad/s at δ = +37 ms, flat after): the edge nearest the fill the
    shift assumed is found to 1 ms; a sharp valley (a V) has no plateau; a plateau on the
    other side of the centre gives its own inner edge."""

    def late(x: float) -> float:
        return 0.5 + max(0.037 - x, 0.0) * 100.0

    grid = [k * GRID_STEP for k in range(-6, 7)]
    edge = FillReplay._plateau_edge(grid, [late(x) for x in grid], 6, late)
    assert edge is not None
    # the plateau starts where the slope's rise falls below the sensors' resolution
    assert edge[0] == pytest.approx(0.037 - fill_estimate.RESIDUAL_FLOOR / 100.0, abs=1e-3)
    assert edge[1] <= 0.5 + fill_estimate.RESIDUAL_FLOOR

    def valley(x: float) -> float:
        return 0.2 + abs(x - 0.013) * 100.0

    assert FillReplay._plateau_edge(grid, [valley(x) for x in grid], 6, valley) is None

    # a shallow V (0.4 rad/s per s of δ) bottoming at +15 ms, halfway between two grid points:
    # its run within the resolution (0.01 rad/s above 0.202) spans -10..+40 ms, and its edge
    # nearest the centre is where 0.2 + 0.4 |δ - 0.015| = 0.212, δ = -15 ms (by hand) ...
    def shallow(x: float) -> float:
        return 0.2 + abs(x - 0.015) * 0.4

    edge = FillReplay._plateau_edge(grid, [shallow(x) for x in grid], 6, shallow)
    assert edge is not None and edge[0] == pytest.approx(-0.015, abs=1e-3)
    # ... which does not explain the record (0.206 at the assumed fill) and, one-sided, leaves
    # the belief where it was
    found = FillEstimate(edge[0], edge[1], 0.21, shallow(0.0), one_sided=True)
    prior = FillBelief(0.0, 0.02**2)
    assert not found.explains and prior.after(found) == prior

    def early(x: float) -> float:
        return 0.5 + max(x + 0.024, 0.0) * 100.0

    edge = FillReplay._plateau_edge(grid, [early(x) for x in grid], 6, early)
    assert edge is not None and edge[0] == pytest.approx(-0.024, abs=1e-3)


def test_a_one_sided_estimate_moves_the_belief_but_not_its_doubt() -> None:
    """A one-sided estimate that explains the record replaces the belief's δ (the bound is
    what the next shift commands) and credits no variance: the belief keeps its predicted
    variance however steep the plateau's other side."""
    prior = FillBelief(0.0, 0.02**2, drift=0.002)
    bound = FillEstimate(0.045, 0.7, 2.5, 9.0, one_sided=True)
    assert bound.explains and bound.variance == np.inf
    after = prior.after(bound)
    assert after.delta == 0.045
    assert after.variance == pytest.approx(0.02**2 + 0.002**2, rel=1e-12)
    assert bound.to_dict()["sigma"] is None and bound.to_dict()["one_sided"] is True


def test_the_fill_is_replayed_again_with_what_the_shift_taught(d, point, monkeypatch) -> None:  # noqa: ANN001
    """Elements gripping 15 % less than the calibration says and a piston 30 ms early: the
    first replay, with the calibration's μ, blames part of the weaker grip on the fill (more
    than 2 ms off the planted fill); the second, with the filter's μ after the shift, finds the
    planted fill within 1 ms, and that is what the strategy believes."""
    found: list[FillEstimate] = []
    original = FillReplay.estimate

    def spy(self, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        out = original(self, *args, **kwargs)
        found.append(out)
        return out

    monkeypatch.setattr(FillReplay, "estimate", spy)
    spec = shift_spec(d, SHIFT)
    planted = -0.03
    vehicle = Vehicle(d, {spec.off_going: 0.85, spec.on_coming: 0.85}, Actuators(), planted)
    outcome = run_vehicle(d, SHIFT, point, vehicle, 1, ("estimator",))["estimator"][0]
    first, second = found
    assert abs(first.delta - planted) > 2e-3
    assert second.delta == pytest.approx(planted, abs=1e-3)
    assert outcome.fill is not None and outcome.fill["delta"] == second.delta
