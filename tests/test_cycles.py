"""Driving cycles as data (validation/sim/cycles.py): the built-in cycles against the facts their
regulations publish, and a user's cycle or grade file against the one-line error contract.

Expected values are the published facts (UN GTR No. 15 for WLTC class 3b; US EPA for UDDS, US06
and HWFET), never numbers taken from the files under test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.sim.cycles import BUILT_IN_CYCLES, load_cycle, load_grade

MILE_KM = 1.609344

#: name: (duration s, distance km and its published rounding, maximum km/h and its rounding).
PUBLISHED = {
    # UN GTR No. 15, Annex 1, Table A1/12 summary: 1 800 s, 23 266 m, 131.3 km/h
    "wltc3b": (1800.0, 23.266, 0.0005, 131.3, 0.05),
    # EPA: UDDS 1 369 s, 7.45 mi, 56.7 mph
    "udds": (1369.0, 7.45 * MILE_KM, 0.005 * MILE_KM, 56.7 * MILE_KM, 0.05 * MILE_KM),
    # EPA: US06 596 s of schedule (the file keeps 4 s of standstill after it), 8.01 mi, 80.3 mph
    "us06": (600.0, 8.01 * MILE_KM, 0.005 * MILE_KM, 80.3 * MILE_KM, 0.05 * MILE_KM),
    # EPA: HWFET 765 s, 10.26 mi, 59.9 mph
    "hwfet": (765.0, 10.26 * MILE_KM, 0.005 * MILE_KM, 59.9 * MILE_KM, 0.05 * MILE_KM),
}


@pytest.mark.parametrize("name", BUILT_IN_CYCLES)
def test_built_in_cycle_matches_its_published_facts(name):
    duration, distance, distance_tol, v_max, v_tol = PUBLISHED[name]
    cycle = load_cycle(name)
    assert cycle.duration_s == duration
    assert abs(cycle.distance_km - distance) <= distance_tol
    assert abs(cycle.v_max_kmh - v_max) <= v_tol
    assert cycle.v_kmh[0] == 0.0 and cycle.v_kmh[-1] == 0.0
    assert np.all(np.diff(cycle.t) == 1.0), "1 Hz as published"
    assert "Published facts" in cycle.source


def test_wltc3b_phases_match_the_regulation():
    """UN GTR No. 15, Annex 1, 3.3: low 0-589 s 3 095 m, medium 589-1022 s 4 756 m, high
    1022-1477 s 7 162 m, extra high 1477-1800 s 8 254 m (to the metre)."""
    cycle = load_cycle("wltc3b")
    for (a, b), metres in zip(
        [(0, 589), (589, 1022), (1022, 1477), (1477, 1800)], [3095, 4756, 7162, 8254], strict=True
    ):
        inside = (cycle.t >= a) & (cycle.t <= b)
        assert abs(np.trapezoid(cycle.v_kmh[inside] / 3.6, cycle.t[inside]) - metres) < 0.5


def test_us06_ends_with_its_standstill():
    cycle = load_cycle("us06")
    assert np.all(cycle.v_kmh[cycle.t >= 596] == 0.0)


def test_window_is_the_cycle_s_start():
    cycle = load_cycle("wltc3b").window(30.5)
    assert cycle.duration_s == 30.5
    full = load_cycle("wltc3b")
    assert cycle.speed(17.25) == pytest.approx(full.speed(17.25))


def write(tmp_path: Path, text: str, name: str = "cycle.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_user_cycle_with_comments(tmp_path):
    path = write(tmp_path, "# my test track\nt,v\n0,0\n# a comment inside\n10,36\n20,0\n")
    cycle = load_cycle(path)
    assert cycle.name == "cycle"
    assert cycle.distance_km == pytest.approx(0.1)  # a triangle: 20 s x 10 m/s / 2
    assert cycle.speed(5.0) == pytest.approx(5.0)
    assert cycle.acceleration(5.0) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("text", "key", "reason"),
    [
        ("t,speed\n0,0\n1,1\n", "row 1", "expected the header t,v"),
        ("t,v\n0,0\n1,abc\n", "row 3, column v", "not a number"),
        ("t,v\n0,0\n2,1\n1,2\n", "row 4, column t", "must increase"),
        ("t,v\n0,0\n# c\n1,-3\n", "row 4, column v", "within 0-300 km/h"),
        ("t,v\n1,0\n2,0\n", "row 2, column t", "must start at 0 s"),
        ("t,v\n0,0\n1,2,3\n", "row 3", "expected 2 values"),
        ("t,v\n0,0\n", "rows", "at least 2 rows"),
        ("t,v\n0,0\n1,nan\n", "row 3, column v", "must be finite"),
    ],
)
def test_bad_cycle_file_gives_one_line(tmp_path, text, key, reason):
    path = write(tmp_path, text)
    with pytest.raises(GearsymError) as err:
        load_cycle(path)
    assert err.value.file == str(path)
    assert err.value.key == key
    assert reason in err.value.reason
    assert "\n" not in str(err.value)


def test_unknown_cycle_name():
    with pytest.raises(GearsymError, match="neither a built-in cycle"):
        load_cycle("wltc9")


def test_grade_file(tmp_path):
    path = write(tmp_path, "s,grade\n0,0\n1000,6\n", "grade.csv")
    grade = load_grade(path)
    assert grade.zeta(500.0) == pytest.approx(np.arctan(0.03))
    assert grade.zeta(5000.0) == pytest.approx(np.arctan(0.06))
    bad = write(tmp_path, "s,grade\n0,0\n10,45\n", "steep.csv")
    with pytest.raises(GearsymError, match=r"row 3, column grade: must be within \+-40 %"):
        load_grade(bad)
