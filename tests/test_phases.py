"""Shift phases detected from what happens, in either order (validation/sim/phases.py, thesis
3.1): power-on and coast, up- and downshifts.

Expected values from physics and from an independent source, the hybrid model's events (its
guards, not the phase detection, decide when an element breaks away or locks up):

* which phase comes first is the shift's physics: before synchronism the on-coming element's
  friction torque has the sign of the load it will carry only in a power-on upshift and a
  coast downshift (it can take the load first: torque phase first); in a power-on downshift and
  a coast upshift it would act against the load, so the off-going element is released first
  and the load moves at synchronism (speed phase first);
* the ratio holds in the torque phase (at the from-gear's before the speed phase, at the
  to-gear's after it) and moves in the speed phase; the phase boundaries fall at the hybrid
  model's break-away and lock-up events;
* on the release-first power-on 3-2 (``scenario_3_2_power_on_release_first.toml``), the
  to-gear starts when B05's friction torque, falling with its pressure ramp to zero at 1.1 s,
  drops below 5 % of what B05 held in gear 3 (a hand value from the scenario's ramp).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import gear_ratio
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.phases import detect_phases
from gearsym.validation.sim.scenario import load_scenario
from gearsym.validation.sim.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "gearsym" / "data"
TESTS = Path(__file__).parent / "data"
RELEASE_FIRST = DATA / "scenario_3_2_power_on_release_first.toml"
TORQUE_FIRST = ["torque phase", "speed phase"]
SPEED_FIRST = ["speed phase", "torque phase"]

#: (description, scenario, order of the two shift phases, what the shift is)
CASES = {
    "power-on upshift 2-3": (None, DATA / "scenario_2_3.toml", TORQUE_FIRST),
    "coast upshift 2-3": (None, DATA / "scenario_2_3_coast.toml", SPEED_FIRST),
    "power-on downshift 3-2, B05 released first": (None, RELEASE_FIRST, SPEED_FIRST),
    "coast downshift 3-2": (None, TESTS / "scenario_3_2_coast.toml", TORQUE_FIRST),
    "power-on downshift 2-1 onto the freewheel F1": (
        TESTS / "simpson_3speed_one_way.toml",
        TESTS / "simpson_one_way_2_1.toml",
        SPEED_FIRST,
    ),
}


@pytest.fixture(scope="module")
def hybrid_runs():
    runs = {}
    for key, (config, path, _) in CASES.items():
        d = load_description(config)
        scenario = load_scenario(d, path)
        result = HybridSimulator(d, scenario).run(rtol=1e-10, atol=1e-10)
        runs[key] = (d, scenario, result, detect_phases(d, scenario, result.t, result.signals))
    return runs


@pytest.mark.parametrize("key", list(CASES))
def test_phase_order_and_boundaries_follow_the_hybrid_models_events(hybrid_runs, key):
    """The order is the shift's physics (module text); the ratio holds where the detection
    says torque phase and moves where it says speed phase; the speed phase ends within 3 ms
    before the on-coming element's lock-up (its slip falls below 1 % first); a torque phase
    first starts once the on-coming element has engaged or the off-going one broken away, and
    no later than that break-away (within a sample and the 5 % threshold's ramp time)."""
    d, scenario, result, phases = hybrid_runs[key]
    spec = scenario.shift
    expected = CASES[key][2]
    assert [p.name for p in phases] == [
        f"gear {spec.from_gear}",
        *expected,
        f"gear {spec.to_gear}",
    ]
    for a, b in zip(phases[:-1], phases[1:], strict=True):
        assert a.t_end == b.t_start
    by_name = {p.name: p for p in phases}
    assert all(p.t_end > p.t_start for p in phases if p.name != "torque phase"), phases
    torque_phase = by_name["torque phase"]
    if torque_phase.t_end == torque_phase.t_start:
        # no load left to move at synchronism: the off-going element opened before the
        # on-coming one locked up (the coast 2-3: K38 empty at 0.35 s, B05 locks at 0.46 s)
        opened = [e.t for e in result.events if e.kind == "opening" and e.element == spec.off_going]
        assert expected == SPEED_FIRST and opened and opened[0] < torque_phase.t_start
    else:
        assert torque_phase.t_end > torque_phase.t_start
    r_from = float(gear_ratio(d, d.gear(spec.from_gear)).ratio)
    r_to = float(gear_ratio(d, d.gear(spec.to_gear)).ratio)
    progress = (r_from - result.signals["ratio"]) / (r_from - r_to)
    t = result.t

    def inside(name: str) -> np.ndarray:
        p = by_name[name]
        return (t > p.t_start + 1e-9) & (t < p.t_end - 1e-9)

    torque, speed = inside("torque phase"), inside("speed phase")
    if expected == TORQUE_FIRST:
        assert np.all(progress[torque] < 0.02)  # still at the from-gear's ratio
    else:
        assert np.all(np.abs(progress[torque] - 1) < 0.01)  # already at the to-gear's ratio
    assert progress[speed][0] < 0.1 and progress[speed][-1] > 0.9
    lock = [e.t for e in result.events if e.kind == "lock-up" and e.element == spec.on_coming]
    assert lock, result.events
    end_of_speed = by_name["speed phase"].t_end
    assert lock[-1] - 3e-3 <= end_of_speed <= lock[-1] + 1e-9
    if expected == TORQUE_FIRST:
        engages = [
            e.t for e in result.events if e.kind == "engagement" and e.element == spec.on_coming
        ]
        slides = [
            e.t for e in result.events if e.kind == "break-away" and e.element == spec.off_going
        ]
        assert min(engages + slides) - 1e-3 <= torque_phase.t_start <= min(slides) + 1e-3


def test_release_first_downshift_on_the_reference(hybrid_runs):
    """The reference simulation (bristles, CVODES) of the release-first power-on 3-2: speed
    phase first, from B05's break-away in the hybrid model (within a sample, 0.5 ms): K38
    carries no load there in its gear-2 direction; the torque phase ends when B05's torque,
    falling linearly with its pressure from 1.0 s to zero at 1.1 s from its sliding value
    T_s, drops below 5 % of its gear-3 torque T_3: at 1.1 s − 0.1 s · 0.05 T_3 / T_s
    (within 1 ms: μ follows the map, not exactly constant)."""
    d = load_description()
    result = simulate(d, load_scenario(d, RELEASE_FIRST), check_models=False)
    names = [p.name for p in result.phases]
    assert names == ["gear 3", "speed phase", "torque phase", "gear 2"]
    gear3, speed, torque, gear2 = result.phases
    _, _, hybrid, _ = hybrid_runs["power-on downshift 3-2, B05 released first"]
    (break_away,) = (e.t for e in hybrid.events if e.kind == "break-away" and e.element == "B05")
    assert abs(speed.t_start - break_away) <= 5e-4
    s, t = result.signals, result.t
    during = (t >= speed.t_start) & (t < speed.t_end)
    final = s["T_K38"][-1]
    assert np.all(np.sign(final) * s["T_K38"][during] < 0.05 * abs(final))
    t_3 = abs(s["T_B05"][0])
    t_s = abs(np.interp(1.0, t, s["T_B05"]))
    assert t_s < t_3  # B05 slides in the speed phase: it holds less than in gear 3
    assert gear2.t_start == pytest.approx(1.1 - 0.1 * 0.05 * t_3 / t_s, abs=1e-3)


def test_an_empty_torque_phase_is_no_window_of_the_open_loop_study():
    """The coast 2-3 empties K38 before B05 locks up: its torque phase is empty (t_start =
    t_end, above), so the open-loop Fisher study (restarted per phase) has no window there
    and no sample is lost: the windows are gear 2, speed phase, gear 3 and the whole shift,
    and the phase windows' samples add up to the whole shift's."""
    import json
    import subprocess
    import sys

    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "gearsym",
            "fim",
            "--open-loop",
            "--scenario",
            str(DATA / "scenario_2_3_coast.toml"),
            "--params",
            "m_veh,mu_38",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    windows = json.loads(run.stdout)["windows"]
    assert [w["name"] for w in windows] == ["gear 2", "speed phase", "gear 3", "whole shift"]
    samples = [w["output_sets"][0]["samples"] for w in windows]
    assert sum(samples[:-1]) == samples[-1]
