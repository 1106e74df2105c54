"""Tooth-wheel speed readings against closed forms: a constant speed (the period is the pitch
over the speed, rounded to the timer) and a constant acceleration (edges where
a t + b t²/2 reaches k·pitch, solved by hand), with latency and a shaft turning backwards."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gearsym.validation.sim.tooth_wheel import ToothWheel, tooth_wheel_speeds


def test_a_constant_speed_reads_the_pitch_over_the_rounded_period():
    """100 rad/s, 60 teeth: period 2π/60/100 = 1.0472 ms, with a 1 µs timer 1 047 ticks, so
    the reading is 0.1047198 / 0.001047 = 100.0189 rad/s at every sample (a 0.019 % step);
    with a 10 µs timer 105 ticks, 99.733 rad/s."""
    t = np.linspace(0.0, 0.1, 201)
    omega = np.full_like(t, 100.0)
    samples = np.arange(0.0, 0.1, 0.01)
    pitch = 2 * math.pi / 60
    for timer, ticks in ((1e-6, 1047), (1e-5, 105)):
        got = tooth_wheel_speeds(t, omega, samples, ToothWheel(60, timer))
        assert got == pytest.approx(np.full(len(samples), pitch / (ticks * timer)), rel=1e-12)
    assert pitch / (1047 * 1e-6) == pytest.approx(100.0189, abs=1e-4)


def test_a_constant_acceleration_reads_the_mean_speed_of_the_last_period():
    """ω = 50 + 400 t: the angle is 50 t + 200 t², the k-th edge at the root of
    200 t² + 50 t = k·pitch; the reading at t_s is pitch over the last period ending before
    t_s − latency (timer 1 ns, so rounding is below 1e-6), which lags the true speed by about
    half a period plus the latency."""
    teeth, latency = 36, 0.002
    pitch = 2 * math.pi / teeth
    t = np.linspace(0.0, 0.5, 1001)
    omega = 50.0 + 400.0 * t
    samples = np.arange(0.05, 0.5, 0.01)
    got = tooth_wheel_speeds(t, omega, samples, ToothWheel(teeth, 1e-9, latency))
    k = np.arange(1, 2000)
    edges = (-50.0 + np.sqrt(50.0**2 + 4 * 200.0 * k * pitch)) / (2 * 200.0)
    expected = []
    for ts in samples:
        last = np.searchsorted(edges, ts - latency, side="right") - 1
        expected.append(pitch / (edges[last] - edges[last - 1]))
    np.testing.assert_allclose(got, expected, rtol=2e-6)
    lag = (50.0 + 400.0 * samples) - got
    assert np.all(lag > 400.0 * latency) and np.all(lag < 400.0 * (latency + 0.02))


def test_a_shaft_turning_backwards_reads_negative_and_the_first_sample_has_a_period():
    """−80 rad/s, 48 teeth, 1 µs: −pitch/(round(pitch/80 µs)·1 µs) from the first sample on
    (the shaft turned at its initial speed before the window)."""
    t = np.linspace(0.0, 0.05, 101)
    omega = np.full_like(t, -80.0)
    pitch = 2 * math.pi / 48
    got = tooth_wheel_speeds(t, omega, np.array([0.0, 0.02, 0.04]), ToothWheel(48, 1e-6))
    ticks = round(pitch / 80.0 / 1e-6)
    assert got == pytest.approx(np.full(3, -pitch / (ticks * 1e-6)), rel=1e-12)


@pytest.mark.parametrize(
    "kwargs, word",
    [({"teeth": 0, "timer": 1e-6}, "teeth"), ({"teeth": 4, "timer": 0.0}, "timer")],
)
def test_a_sensor_without_teeth_or_timer_is_refused(kwargs, word):
    with pytest.raises(ValueError, match=word):
        ToothWheel(**kwargs)


def one_vehicle(d, scenario, fleet, seed: int):
    """(draw, the filter's set-up) of vehicle ``seed`` of ``fleet`` as the fleet evaluation
    builds it (10 ms, 1 % speed noise in the filter's model, modes decided by the filter)."""
    from gearsym.validation.studies.estimation.fleet_eval import (
        FleetContext,
        calibration_setup,
        filter_model,
        vehicle_setup,
    )

    model = filter_model(d, scenario.shift.name, "filter", None)
    nominal = calibration_setup(d, scenario, model, 0.01, 0.01)
    context = FleetContext(
        d, scenario, fleet, 0.01, 0.01, "filter", nominal.floor, nominal.t, bound=False
    )
    draw, setup, _ = vehicle_setup(context, model, seed)
    return draw, setup


def test_a_fleet_with_tooth_wheels_hands_the_filter_the_readings_without_noise(
    default_description, default_scenario
):
    """A vehicle with 48-tooth wheels, a 1 µs timer and 1 ms latency: the filter's
    measurements are the tooth-wheel readings of the reference's speeds (the same for any noise
    seed: no Gaussian noise on them), off the true speed by at most the latency and one and a
    half periods times its largest acceleration plus one timer tick, and the states keep their
    truth for scoring."""
    from gearsym.validation.sim.fleet import parse_fleet, truth_world
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.loop import filter_run

    d, scenario = default_description, default_scenario
    fleet = parse_fleet(
        '[fleet]\nname = "wheels"\nm_veh = { value = 2100.0, unit = "kg", source = "t" }\n'
        'speed_sensor_teeth = { value = 48.0, unit = "1", source = "t" }\n'
        'speed_sensor_timer = { value = 1.0e-6, unit = "s", source = "t" }\n'
        'speed_sensor_latency = { value = 1.0e-3, unit = "s", source = "t" }\n',
        "wheels.toml",
        d,
    )
    draw, setup = one_vehicle(d, scenario, fleet, 5)
    assert setup.sensed

    world = truth_world(d, scenario, draw)
    result = simulate(world.description, world.scenario, mu_scale=world.mu_scale)
    for k, name in enumerate(setup.outputs):
        true = np.interp(setup.t, result.t, result.signals[name])
        t_unique, first = np.unique(result.t, return_index=True)  # events repeat a time
        rate = np.max(np.abs(np.gradient(result.signals[name][first], t_unique)))
        period = 2 * math.pi / 48 / np.abs(true)
        quantum = np.abs(true) * 1e-6 / period  # one timer tick in the period
        lag = rate * (1e-3 + 1.5 * period)  # the last edge up to a period old, its mean T/2 more
        bad = np.flatnonzero(np.abs(setup.y_true[:, k] - true) > lag + quantum)
        assert bad.size == 0, (name, bad, setup.y_true[bad, k], true[bad], lag[bad], rate)
        assert np.any(setup.y_true[:, k] != true)
    one, two = filter_run(setup, 1), filter_run(setup, 2)
    np.testing.assert_array_equal(one.estimates, two.estimates)
    j = list(one.state_names).index("m_veh")
    assert one.truth[:, j] == pytest.approx(2100.0)


@pytest.mark.parametrize("command", ["drive", "control"])
def test_commands_that_do_not_read_tooth_wheels_refuse_a_fleet_with_them(command):
    """gearsym drive and control read speeds without the sensor model: a fleet with tooth
    wheels is refused in one line naming the file and the entry (exit 2), not ignored."""
    from pathlib import Path

    import gearsym
    from tests.test_cli import gearsym as run_gearsym

    wheels = Path(gearsym.__file__).parent / "data" / "fleet_tooth_wheels.toml"
    result = run_gearsym(command, "--fleet", str(wheels))
    assert result.returncode == 2 and result.stdout == ""
    (line,) = result.stderr.strip().splitlines()
    assert "fleet_tooth_wheels.toml" in line and "fleet.speed_sensor_" in line, line
    assert f"gearsym {command} would ignore them" in line


def test_a_sensor_of_its_own_overrides_the_common_wheel(default_description):
    """speed_sensor_teeth_omega_C gives the wheel speed its own 100-tooth wheel beside the
    common 48: the wheel's sensor has 100 teeth, a shaft's 48; without any teeth entry there
    is no sensor (Gaussian noise)."""
    from gearsym.validation.sim.fleet import measured_speeds, parse_fleet, speed_sensor

    d = default_description
    fleet = parse_fleet(
        '[fleet]\nname = "w"\n'
        'speed_sensor_teeth = { value = 48.0, unit = "1", source = "t" }\n'
        'speed_sensor_teeth_omega_C = { value = 100.0, unit = "1", source = "t" }\n'
        'speed_sensor_timer = { value = 1.0e-6, unit = "s", source = "t" }\n',
        "w.toml",
        d,
    )
    draw = fleet.draw(3)
    assert measured_speeds(d) == ("omega_1", "omega_2", "omega_8", "omega_C")
    assert speed_sensor(draw, "omega_C") == ToothWheel(100, 1e-6, 0.0)
    assert speed_sensor(draw, "omega_1") == ToothWheel(48, 1e-6, 0.0)
    plain = parse_fleet(
        '[fleet]\nname = "p"\nm_veh = { value = 1800.0, unit = "kg", source = "t" }\n',
        "p.toml",
        d,
    )
    assert speed_sensor(plain.draw(3), "omega_C") is None
