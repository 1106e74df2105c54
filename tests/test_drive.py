"""A whole drive (validation/sim/drive.py, `gearsym drive`): every shift of a short cycle in one
continuous simulation.

Expected values come from physics and hand derivations, never from the code under test: the
energy balance over the whole drive (input work = stored energy + clutch, damper, road and
brake losses), the steady state at constant speed (input power = road-load power), the torque
split's rules computed by hand, the cycle's own distance, the schedule's hysteresis condition.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.cycles import load_cycle
from gearsym.validation.sim.drive import DriveSimulator
from gearsym.validation.sim.drive_powertrain import Powertrain
from gearsym.validation.sim.drive_shift import state_from_speeds

#: A short cycle with a launch, upshifts, a cruise, a braked stop and a standstill.
SHORT = Path(__file__).parent / "data" / "cycle_short.csv"


@pytest.fixture(scope="module")
def description():
    return load_description()


@pytest.fixture(scope="module")
def short_drive(description):
    cycle = load_cycle(SHORT)
    simulator = DriveSimulator(description, cycle)
    return simulator, simulator.run()


def test_short_drive_shifts_up_and_down_without_a_miss(short_drive):
    _, result = short_drive
    assert result.failure == ""
    kinds = [s.kind for s in result.shifts]
    assert "upshift" in kinds and "downshift" in kinds
    assert all(s.completed for s in result.shifts)
    # every shift ends with the on-coming element locked, within the plan's length
    for s in result.shifts:
        assert 0.0 < s.shift_time < 0.85
    # each shift goes to an adjacent gear of the one before
    gears = result.gears
    current = gears[0]
    for s in result.shifts:
        a, b = s.name.split("-")
        assert a == current
        assert abs(gears.index(b) - gears.index(a)) == 1
        current = b


def test_the_schedule_is_a_level_not_only_a_crossing(description, short_drive):
    """The short cycle's braked stop: the input falls through the 4-3's downshift speed
    while the gear waits out its dwell after the 5-4. A schedule read as crossings only
    never shifts again (the speed keeps falling; planted, this drive sat 3.7 s in gear 3
    below the 3-2's speed and came to rest in it); read as a level it shifts when the dwell
    ends, down to the lowest gear before the stop."""
    from gearsym.validation.sim.drive import MIN_DWELL
    from gearsym.validation.sim.drive_schedule import missed_shifts

    _, result = short_drive
    assert missed_shifts(result, description.drive.schedule, MIN_DWELL) == []
    assert [s.name for s in result.shifts][-2:] == ["3-2", "2-1"]


def test_a_downshift_braking_to_a_stop_does_not_reverse_the_input(description, short_drive):
    """The short cycle's 2-1 at about 10 km/h while the machine recuperates: with the
    recuperation held through the shift, the input shaft (free between the two sliding
    elements) was driven backwards to −23 rad/s; handed to the brake it never turns back."""
    _, result = short_drive
    assert "2-1" in [s.name for s in result.shifts]
    log = result.log.arrays()
    in_2_1 = np.array([shift == "2-1" for shift in result.log.shifts()])
    assert np.min(log[f"omega_{description.input_shaft}"][in_2_1]) > 0.0


def test_blended_split_moves_recuperation_to_the_brake_by_hand():
    """A downshift under recuperation: −50 N·m of machine torque through an overall ratio of
    10 is 500 N·m at the wheel, added to the brake's 100; the wheel's torque is unchanged
    (−50 · 10 − 100 = −600 = −(0 + 600)). An upshift, or a downshift under drive, keeps its
    split."""
    from gearsym.validation.sim.drive_powertrain import TorqueSplit
    from gearsym.validation.sim.drive_schedule import blended_split

    recuperating = TorqueSplit(0.0, -50.0, 100.0, 0.0)
    assert blended_split(recuperating, "downshift", 10.0) == TorqueSplit(0.0, 0.0, 600.0, 0.0)
    assert blended_split(recuperating, "upshift", 10.0) == recuperating
    driving = TorqueSplit(80.0, 20.0, 0.0, 0.4)
    assert blended_split(driving, "downshift", 10.0) == driving


def _record(gears, samples, shifts=()):
    from types import SimpleNamespace

    columns = ("t", "gear", "omega_in", "pedal")
    data = {
        name: np.array([row[i] for row in samples], dtype=float) for i, name in enumerate(columns)
    }
    return SimpleNamespace(
        gears=gears,
        samples=data,
        shifts=[SimpleNamespace(t_start=t) for t in shifts],
    )


def test_missed_shifts_reads_the_schedule_by_hand():
    """A schedule of constant speeds (up 100, down 50 rad/s at any pedal), dwell 1 s, three
    gears: a sample above 100 in the middle gear after its dwell is a missed upshift, one
    below 50 a missed downshift; inside the dwell, with a shift started, or at the top and
    bottom gear's open side nothing is missed."""
    from types import SimpleNamespace

    from gearsym.validation.sim.drive_schedule import missed_shifts

    schedule = SimpleNamespace(up=lambda pedal: 100.0, down=lambda pedal: 50.0)
    gears = ("1", "2", "3")
    rows = [
        (0.0, 1, 80.0, 0.5),
        (0.5, 1, 120.0, 0.5),  # inside the dwell after entering gear 2 at t = 0
        (1.5, 1, 120.0, 0.5),  # missed upshift
        (2.0, 1, 40.0, 0.5),  # missed downshift
        (3.0, 1, 120.0, 0.5),  # a shift started at 2.5 s is under way
        (4.0, 2, 300.0, 0.5),
        (5.5, 2, 300.0, 0.5),  # the top gear cannot shift up
        (6.0, 0, 10.0, 0.5),
        (7.5, 0, 10.0, 0.5),  # the lowest gear cannot shift down
    ]
    assert missed_shifts(_record(gears, rows, shifts=[2.5, 3.5]), schedule, 1.0) == [1.5, 2.0]


def test_energy_balance_closes_over_the_drive(short_drive):
    """W_in = ΔE_stored + W_clutches + W_damper + W_road + W_brake, every term integrated
    separately along the solution (gear segments, shifts, standstill)."""
    _, result = short_drive
    w = result.works
    assert w.brake > 0, "the stop is braked"
    assert w.friction > 0, "the shifts slide"
    assert abs(w.residual) <= 1e-6 * (w.friction + w.damper + abs(w.road) + w.brake)


def test_drive_follows_the_cycle(short_drive):
    simulator, result = short_drive
    s = result.samples
    assert result.tracking_rms_kmh < 1.5
    # the distance driven is the cycle's (trapezoid of the trace: 0.3972 km) within tracking
    distance = np.trapezoid(simulator.cycle.v_kmh / 3.6, simulator.cycle.t)
    assert s["s"][-1] == pytest.approx(distance, rel=0.01)
    # at rest in the lowest gear at the end
    assert s["v"][-1] == 0.0 and result.gears[int(s["gear"][-1])] == result.gears[0]


def test_cruise_input_power_is_the_road_load(short_drive, description):
    """At constant speed in a locked gear nothing is stored: T_In ω_in = T_res ω_C + 2 d_ss φ̇²
    with φ̇ = 0, T_res ω_C = v (F_r + F_ad), thesis (2.48)-(2.49) with the description's
    values: F_r = f_roll v m g (2.49a as printed), F_ad = ½ ρ c_W A v²."""
    _, result = short_drive
    s = result.samples
    cruise = (s["t"] > 27.0) & (s["t"] < 31.5)
    v = s["v"][cruise]
    assert np.ptp(v) < 0.05
    vehicle = {k: q.value for k, q in description.vehicle.items()}
    m, g = vehicle["m_veh"], vehicle["g"]
    road = v * (
        vehicle["f_roll"] * v * m * g
        + 0.5 * vehicle["rho_air"] * vehicle["c_W"] * vehicle["A_front"] * v**2
    )
    torque = s["T_engine"][cruise] + s["T_e_machine"][cruise]
    power = torque * s["omega_in"][cruise]
    # small acceleration is left in the samples: m v dv/dt bounds the difference
    dv = np.gradient(v, s["t"][cruise])
    assert np.all(np.abs(power - road) <= np.abs(m * v * dv) + 0.01 * road)


def test_torque_split_by_hand(description):
    """The stated rules (validation/sim/drive_powertrain.py) with the description's [drive]
    numbers: engine 400 N·m / 143 kW above 800 rpm, e-machine 440 N·m / 90 kW."""
    p = Powertrain(description, 1950.0)
    r_dyn = description.vehicle["r_dyn"].value
    i_d = description.drivetrain["i_D"].value
    ratio = 3.243
    overall = ratio * i_d
    rpm = math.pi / 30
    # below idle: electric only
    split = p.split(100.0 * overall / r_dyn, ratio, 500 * rpm)
    assert (split.engine, split.e_machine, split.brake) == pytest.approx((0.0, 100.0, 0.0))
    # above idle: engine first, machine adds the rest
    split = p.split(500.0 * overall / r_dyn, ratio, 2000 * rpm)
    assert split.engine == pytest.approx(400.0)
    assert split.e_machine == pytest.approx(100.0)
    # at 2000 rpm (209.4 rad/s) the machine's power binds: 90 kW / 209.4 rad/s = 429.7 N·m
    assert split.pedal == pytest.approx(500.0 / (400.0 + 90e3 / (2000 * rpm)))
    # at 4000 rpm the power limits bind: 143 kW / 418.9 rad/s, 90 kW / 418.9 rad/s
    w = 4000 * rpm
    split = p.split(1000.0 * overall / r_dyn, ratio, w)
    assert split.engine == pytest.approx(143e3 / w)
    assert split.e_machine == pytest.approx(90e3 / w)
    assert split.pedal == 1.0
    # braking beyond the machine (at 1000 rpm its 440 N·m binds, 46 kW): the rest is the
    # brake, at the wheel
    split = p.split(-600.0 * overall / r_dyn, ratio, 1000 * rpm)
    assert split.e_machine == pytest.approx(-440.0)
    assert split.brake == pytest.approx(160.0 * overall)


def test_gear_state_hand_over_keeps_the_shaft_speeds(short_drive):
    simulator, _ = short_drive
    for k in range(len(simulator.gears)):
        sim, mode, fns = simulator.gear_model(k)
        x = np.zeros(sim.modes[mode].n)
        x[0] = 100.0
        speeds = np.asarray(fns["speeds"](x)).ravel()
        back = state_from_speeds(sim, mode, speeds, 0.01, 40.0)
        assert np.asarray(fns["speeds"](back)).ravel() == pytest.approx(speeds, rel=1e-12)


def test_hunting_schedule_is_refused(description, tmp_path):
    """After a 1-2 upshift (step 5.354/3.243 = 1.651) at 1500 rpm the input turns at 909 rpm:
    a downshift speed of 950 rpm would shift straight back."""
    text = (
        Path(description.file).read_text(encoding="utf-8")
        if Path(description.file).exists()
        else None
    )
    if text is None:
        from gearsym.symbolic.io.package_data import data_file

        text = data_file("thesis_9speed.toml").read_text(encoding="utf-8")
    text = text.replace("[850.0, 1200.0, 2200.0]", "[950.0, 1200.0, 2200.0]")
    path = tmp_path / "hunting.toml"
    path.write_text(text, encoding="utf-8")
    d = load_description(path)
    with pytest.raises(GearsymError, match=r"drive.shift_schedule: after the 1-2 upshift"):
        DriveSimulator(d, load_cycle("udds").window(5.0))


def gearsym(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, timeout=600
    )


def test_cli_drive_json_and_files(tmp_path):
    out = tmp_path / "drive"
    run = gearsym(*["drive", "--cycle", "udds", "--duration", "25", "--out", str(out), "--json"])
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert data["cycle"]["name"] == "udds[0:25 s]"
    for key in ("shifts", "wall_s", "real_time_factor", "energy_residual", "tracking_rms_kmh"):
        assert key in data
    assert data["energy_residual"] < 1e-6
    assert data["missed_shifts"] == 0
    assert data["gear_integrator"] == "fast"
    for name in ("drive.json", "drive.csv", "shifts.csv", "drive.png"):
        assert (out / name).exists()


def test_cli_drive_engine_gain_state_reports_the_gain(tmp_path):
    """With --engine-gain-state the EKF's estimates name the engine's gain, scored against
    the vehicle's (the calibration's own here: exactly 1). What the state does to the filter's
    input is tests/test_drive_ekf.py's."""
    out = tmp_path / "drive"
    args = ["drive", "--cycle", "udds", "--duration", "25", "--engine-gain-state", "--json"]
    run = gearsym(*args, "--out", str(out))
    assert run.returncode == 0, run.stderr
    entry = json.loads(run.stdout)["estimates"]["engine_torque_gain"]
    assert entry["truth"] == 1.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--cycle", "nope"], "nope: --cycle: neither a built-in cycle"),
        (["--cycle", "{bad}"], "row 2, column v: not a number"),
        (["--duration", "-3"], "--duration: must be positive"),
        (["--fleet", "--runs", "2", "--reference"], "--reference: drives one vehicle"),
        (["--fleet", "--runs", "2", "--engine-gain-state"], "--engine-gain-state: one drive"),
        (["--estimate", "none", "--engine-gain-state"], "--engine-gain-state: one drive"),
    ],
)
def test_cli_drive_bad_input_is_one_line(tmp_path, args, message):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,v\n0,x\n1,0\n", encoding="utf-8")
    args = [str(bad) if a == "{bad}" else a for a in args]
    run = gearsym("drive", *args, "--out", str(tmp_path / "out"))
    assert run.returncode == 2
    assert message in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def fleet_drive(description):
    """A fleet vehicle (heavier, other tolerances) on the short cycle: the TCU's calibration
    apart from the truth."""
    from gearsym.validation.sim.drive import DriveTruth
    from gearsym.validation.sim.fleet import load_fleet

    draw = load_fleet(description).draw(10000)
    truth = DriveTruth.from_draw(description, draw)
    simulator = DriveSimulator(description, load_cycle(SHORT), truth=truth)
    return simulator, simulator.run()


def test_fleet_vehicle_drive_keeps_calibration_and_truth_apart(fleet_drive, description):
    simulator, result = fleet_drive
    truth = simulator.truth
    assert result.failure == ""
    # the plant is the drawn vehicle, the TCU plans with the calibration's prior mass
    assert result.values["m_veh"] == dict(truth.draw.values)["m_veh"]
    assert simulator.calibration_values["m_veh"] == description.estimator.prior_of("m_veh", 0)[0]
    w = result.works
    assert abs(w.residual) <= 1e-6 * (w.friction + w.damper + abs(w.road) + w.brake)
    # the μ of the truth is the map's times the draw's factor: the parameter values say so
    scale = truth.mu_scale["K38"]
    assert result.values["mu_38"] == pytest.approx(0.12 * scale)


def test_tcu_log_is_what_the_tcu_commanded_on_its_grid(fleet_drive, description):
    simulator, result = fleet_drive
    log = result.log.arrays()
    shifts = result.log.shifts()
    t = log["t"]
    assert np.allclose(np.diff(t), simulator.tcu_sample)
    assert t[0] == 0.0 and t[-1] >= simulator.cycle.t[-1] - 0.011
    line = description.drive.si("shift", "line_pressure")
    gears = result.gears
    in_gear = np.array([s == "" for s in shifts])
    for i in np.flatnonzero(in_gear)[::50]:
        closed = description.gear(gears[int(log["gear"][i])]).closed
        for e in (e.name for e in description.shift_elements):
            assert log[f"p_{e}"][i] == (line if e in closed else 0.0)
    # μ has a truth only while an element slides: inside shifts, never in a gear
    mu = np.column_stack([log[f"truth_mu_{e.name}"] for e in description.shift_elements])
    assert not np.isfinite(mu[in_gear]).any()
    assert np.isfinite(mu[~in_gear]).any()


@pytest.mark.parametrize(
    ("box", "element", "what"),
    [
        ("tests/data/dog_9speed.toml", "K27", "a dog element"),
        ("tests/data/simpson_3speed_one_way.toml", "F1", "a one-way clutch"),
    ],
)
def test_cli_drive_refuses_a_box_its_shift_plans_cannot_serve(tmp_path, box, element, what):
    root = Path(__file__).resolve().parents[1]
    run = gearsym(*["drive", str(root / box), "--duration", "5", "--out", str(tmp_path / "o")])
    assert run.returncode == 2
    assert f'shift_element[name="{element}"]' in run.stderr and what in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
