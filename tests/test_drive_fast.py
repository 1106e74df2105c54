"""The fast drive (validation/sim/drive_fast.py: the gear segments' closed loop compiled,
RK4 over the TCU's ticks) against the Python reference (``run(reference=True)``: SciPy's RK45
at rtol 1e-7, a Python call per right-hand side) on the same drive: the short test cycle
(a launch, upshifts, a cruise, a braked stop and a standstill).

The tolerances come from what the drive's outputs are for, never from this comparison's
numbers:

* **speeds** (the records' vehicle and input speed, every shaft speed in the TCU's log):
  within a tenth of the speed sensors' noise, σ = r max(|y|, y_min) with r = 1 % and y_min =
  1 % of the largest value (3.26, :data:`gearsym.symbolic.defaults.SPEED_ERROR`): what an
  estimator reading the log cannot tell from the noise it is built for. Inside a shift, plus
  what the difference of the two shifts' starts (bounded below) moves a slipping shaft by.
* **shifts**: the same shifts in the same order, each starting within 1 ms, a tenth of the
  TCU's 10 ms tick (the TCU cannot tell a shift 1 ms earlier from one at the same tick);
  shift time and friction energy within 1 % (what the shift-quality table prints to: three
  digits).
* **energy**: the fast drive's audit closes as the reference's must (1e-6 of the energy
  scale, tests/test_drive.py), and every work differs by less than ten times that closure,
  the audit's own resolution.
* **distance**: within 1e-5 of the distance, a fortieth of the precision the cycles'
  published distances are stated to (WLTC 3b: 23.27 km, 4e-4).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.defaults import FLOOR_FRACTION, SPEED_ERROR
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.cycles import load_cycle
from gearsym.validation.sim.drive import DriveSimulator
from gearsym.validation.sim.drive_fast import piecewise_linear

SHORT = Path(__file__).parent / "data" / "cycle_short.csv"
#: The fraction of the sensors' noise σ (3.26) the two drives' speeds may differ by.
NOISE_FRACTION = 0.1
SHIFT_START_S = 1e-3
SHIFT_QUALITY_REL = 0.01
ENERGY_CLOSURE = 1e-6
DISTANCE_REL = 1e-5


@pytest.fixture(scope="module")
def drives():
    d = load_description()
    cycle = load_cycle(SHORT)
    fast = DriveSimulator(d, cycle).run()
    reference = DriveSimulator(d, cycle).run(reference=True)
    return fast, reference


def _sigma(y: np.ndarray) -> np.ndarray:
    """The speed sensor's σ (3.26) at each sample of ``y``."""
    floor = FLOOR_FRACTION * np.max(np.abs(y))
    return SPEED_ERROR * np.maximum(np.abs(y), floor)


def _distinct(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sample times without repeats (a time within 1 µs of the one before, in time
    order) and their indices."""
    order = np.argsort(t, kind="stable")
    keep = np.concatenate([[True], np.diff(t[order]) > 1e-6])
    return t[order][keep], order[keep]


def _timing_allowance(y: np.ndarray, t: np.ndarray, dt: float) -> np.ndarray:
    """What a time offset ``dt`` moves ``y`` by at each sample: its rate times dt, the rate
    the larger of the two adjacent intervals' |Δy|/Δt, doubled (a shaft's rate that rises
    from nought across an interval, as a slip decelerating into lock-up, peaks at twice its
    mean)."""
    slope = np.abs(np.diff(y)) / np.diff(t)
    left = np.concatenate([[0.0], slope])
    right = np.concatenate([slope, [0.0]])
    return 2.0 * np.maximum(left, right) * dt


def _shift_offset(fast, reference) -> float:
    """The largest difference of the two drives' shift starts (s)."""
    pairs = zip(fast.shifts, reference.shifts, strict=True)
    return max(abs(a.t_start - b.t_start) for a, b in pairs)


def test_both_drives_complete_and_say_how_they_integrated(drives):
    fast, reference = drives
    assert fast.failure == "" and reference.failure == ""
    assert fast.to_dict()["gear_integrator"] == "fast"
    assert reference.to_dict()["gear_integrator"] == "reference"


def test_same_shifts_at_the_same_times(drives):
    fast, reference = drives
    assert [(s.name, s.kind) for s in fast.shifts] == [(s.name, s.kind) for s in reference.shifts]
    assert len(fast.shifts) >= 4  # the short cycle shifts up and down
    for a, b in zip(fast.shifts, reference.shifts, strict=True):
        assert a.completed and b.completed
        assert abs(a.t_start - b.t_start) <= SHIFT_START_S, a.name
        assert a.shift_time == pytest.approx(b.shift_time, rel=SHIFT_QUALITY_REL)
        assert a.friction_energy == pytest.approx(b.friction_energy, rel=SHIFT_QUALITY_REL)


def test_recorded_speeds_agree_within_the_sensor_noise(drives):
    """Vehicle and input speed at the reference's record times (the fast drive's records
    interpolated there: inside a shift the samples move with the shift's start; as in the
    log, a slipping shaft's rate times that Δt is the shift's start, not the speed)."""
    fast, reference = drives
    dt = _shift_offset(fast, reference)
    t_ref, first = _distinct(reference.samples["t"])
    t_fast, first_fast = _distinct(fast.samples["t"])
    # the same samples: a shift's move with its start (a drive records the instant that ends
    # a segment twice at times, from both sides: merged)
    assert len(t_fast) == len(t_ref)
    assert np.max(np.abs(t_fast - t_ref)) <= dt + 1e-9
    for key in ("v", "omega_in"):
        ref = reference.samples[key][first]
        got = np.interp(t_ref, t_fast, fast.samples[key][first_fast])
        bound = NOISE_FRACTION * _sigma(ref) + _timing_allowance(ref, t_ref, dt)
        assert np.all(np.abs(got - ref) <= bound), key
    gear_ref = reference.samples["gear"][first]
    gear = fast.samples["gear"][first_fast]
    # the gear changes at the same samples, but for one at a shift's end (1 ms above)
    assert np.count_nonzero(gear != gear_ref) <= len(fast.shifts)


def test_tcu_log_agrees_within_the_sensor_noise(drives):
    """Every shaft's speed and the wheel speed the TCU logged, tick by tick (the ticks are
    the same: the TCU's clock, not the integrator's). Inside a shift the two shifts run
    Δt apart (the largest difference of their starts), so a slipping shaft differs by its
    own rate times Δt besides (:func:`_timing_allowance`): that is the shift's start,
    checked above, not the speed. In a gear the bound is the noise's alone."""
    fast, reference = drives
    a, b = fast.log.arrays(), reference.log.arrays()
    assert np.array_equal(a["t"], b["t"])
    dt = _shift_offset(fast, reference)
    shifting = np.array([s != "" for s in reference.log.shifts()])
    speeds = [k for k in a if k.startswith("omega_")]
    assert "omega_C" in speeds
    for key in speeds:
        timing = np.where(shifting, _timing_allowance(b[key], b["t"], dt), 0.0)
        bound = NOISE_FRACTION * _sigma(b[key]) + timing
        assert np.all(np.abs(a[key] - b[key]) <= bound), key


def test_energy_audit_closes_and_agrees(drives):
    fast, reference = drives
    w, r = fast.works, reference.works
    scale = max(abs(r.input), r.friction + r.damper + abs(r.road) + r.brake)
    assert w.relative_residual <= ENERGY_CLOSURE
    for name, value in w.to_dict().items():
        if name == "relative_residual":
            continue
        assert abs(value - r.to_dict()[name]) <= 10 * ENERGY_CLOSURE * scale, name


def test_distance_agrees(drives):
    fast, reference = drives
    s_fast, s_ref = fast.samples["s"][-1], reference.samples["s"][-1]
    assert s_fast == pytest.approx(s_ref, rel=DISTANCE_REL)


def test_piecewise_linear_is_numpys_interp_held_at_the_ends():
    """The schedule's and the grade's interpolation in CasADi: NumPy's ``interp``."""
    import casadi as ca

    xs, ys = (0.0, 0.5, 1.0), (157.0, 240.9, 397.9)
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [piecewise_linear(x, xs, ys)])
    for value in (-0.5, 0.0, 0.2, 0.5, 0.75, 1.0, 3.0):
        assert float(f(value)) == pytest.approx(float(np.interp(value, xs, ys)), rel=1e-15)


def test_compiled_c_is_casadis_arithmetic():
    """A shift mode's right-hand side emitted as C and called through ctypes gives CasADi's
    values (the same operations, no fast-math)."""
    from gearsym.validation.sim.compiled_c import CompiledFunctions, compiler_available

    if not compiler_available():
        pytest.skip("no C compiler: the fast drive keeps CasADi's calls")
    d = load_description()
    simulator = DriveSimulator(d, load_cycle(SHORT))
    runner = simulator.runner((simulator.gears[0], simulator.gears[1]))
    modes = runner.simulator.modes
    compiled = CompiledFunctions({name: m.f for name, m in modes.items()})
    p = simulator.parameters_of(runner.simulator, simulator.values)
    rng = np.random.default_rng(0)
    for name, mode in modes.items():
        x = rng.normal(scale=50.0, size=mode.n)
        u = np.array([80.0, 2e4, 1e4, 0.01])
        assert np.allclose(compiled[name](x, u, p), mode.rhs(x, u, p), rtol=1e-14, atol=0)


def test_compiled_many_is_one_call_per_point():
    """``many`` (one C loop over the rows) gives, row by row, the values of one call per
    point and of CasADi's ``map``; an input given once holds for every row; inputs of
    different row counts are refused."""
    from gearsym.validation.sim.compiled_c import CompiledFunctions, compiler_available

    if not compiler_available():
        pytest.skip("no C compiler")
    d = load_description()
    simulator = DriveSimulator(d, load_cycle(SHORT))
    runner = simulator.runner((simulator.gears[0], simulator.gears[1]))
    name, mode = next(iter(runner.simulator.modes.items()))
    compiled = CompiledFunctions({"torques": mode.torques})["torques"]
    p = simulator.parameters_of(runner.simulator, simulator.values)
    rng = np.random.default_rng(1)
    x = rng.normal(scale=50.0, size=(7, mode.n))
    u = np.column_stack([rng.normal(80.0, 5.0, 7), np.full(7, 2e4), np.full(7, 1e4), np.zeros(7)])
    rows = compiled.many(x, u, p)
    one_by_one = np.array([compiled(xi, ui, p) for xi, ui in zip(x, u, strict=True)])
    assert np.array_equal(rows, one_by_one)
    mapped = np.asarray(mode.torques.map(7)(x.T, u.T, p).full()).T
    assert np.allclose(rows, mapped, rtol=1e-14, atol=0), name
    assert np.array_equal(compiled.many(x, u[0], p), compiled.many(x, np.tile(u[0], (7, 1)), p))
    with pytest.raises(ValueError, match="one count needed"):
        compiled.many(x, u[:3], p)


def test_compiled_c_is_kept_in_the_cache(tmp_path, monkeypatch):
    """The second build of the same functions loads the cached library, no compiler run;
    GEARSYM_NO_CACHE=1 compiles again."""
    import casadi as ca
    from gearsym.validation.sim import compiled_c

    if not compiled_c.compiler_available():
        pytest.skip("no C compiler")
    monkeypatch.setenv("GEARSYM_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("GEARSYM_NO_CACHE", raising=False)
    x = ca.SX.sym("x", 2)
    functions = {"f": ca.Function("f", [x], [ca.vertcat(x[0] * x[1], ca.sin(x[0]))])}
    first = compiled_c.CompiledFunctions(functions)
    assert len(list((tmp_path / "c").glob("*.so"))) == 1

    def refuse(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(compiled_c.subprocess, "run", refuse)
    again = compiled_c.CompiledFunctions(functions)
    assert np.array_equal(again["f"]([0.5, 2.0]), first["f"]([0.5, 2.0]))
    monkeypatch.setenv("GEARSYM_NO_CACHE", "1")
    with pytest.raises(AssertionError, match="compiled again"):
        compiled_c.CompiledFunctions(functions)


def test_accelerations_are_the_cycles():
    from gearsym.validation.sim.drive_fast import accelerations

    cycle = load_cycle(SHORT)
    times = np.array([-1.0, 0.0, 1.0, 2.0, 2.5, 8.0, 19.99, 44.0, 46.9, 47.0, 50.0])
    expected = [cycle.acceleration(float(t)) for t in times]
    assert accelerations(cycle, times).tolist() == expected


def test_cli_drive_reference(tmp_path):
    """``gearsym drive --reference`` drives with the reference and says so."""
    import json
    import subprocess
    import sys

    out = tmp_path / "drive"
    args = ["drive", "--cycle", "udds", "--duration", "10", "--estimate", "none", "--json"]
    run = subprocess.run(
        [sys.executable, "-m", "gearsym", *args, "--reference", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["gear_integrator"] == "reference"
    assert "--reference" in (out / "drive.md").read_text(encoding="utf-8")


#: The checks above, each taking the pair (fast, reference).
CHECKS = (
    test_both_drives_complete_and_say_how_they_integrated,
    test_same_shifts_at_the_same_times,
    test_recorded_speeds_agree_within_the_sensor_noise,
    test_tcu_log_agrees_within_the_sensor_noise,
    test_energy_audit_closes_and_agrees,
    test_distance_agrees,
)


@pytest.mark.slow
def test_the_whole_wltc_3b_agrees():
    """The same checks over the whole WLTC 3b (114 shifts; the reference takes over a minute):
    the short cycle does not cross every gear, nor the coasting downshifts."""
    d = load_description()
    simulator = DriveSimulator(d, load_cycle("wltc3b"))
    pair = (simulator.run(), simulator.run(reference=True))
    for check in CHECKS:
        check(pair)
