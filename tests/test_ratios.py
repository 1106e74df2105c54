"""Gear ratios: Table 2.1 from the built-in gearbox, hand-derived ratios of a second gearbox."""

from __future__ import annotations

from pathlib import Path

import pytest
import sympy as sp
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import ratio_expressions, ratio_table
from gearsym.symbolic.teeth import ToothRanges, fit_teeth, with_teeth

DATA = Path(__file__).parent / "data"

# Table 2.1 of the thesis, transcribed by hand (None: neutral).
TABLE_2_1 = {
    "1": 5.354,
    "2": 3.243,
    "3": 2.252,
    "4": 1.636,
    "5": 1.211,
    "6": 1.000,
    "7": 0.865,
    "8": 0.717,
    "9": 0.601,
    "N": None,
    "R": -4.798,
}


def test_builtin_gearbox_reproduces_table_2_1_to_every_printed_decimal():
    table = {r.gear: r for r in ratio_table(load_description())}
    assert set(table) == set(TABLE_2_1)
    for gear, printed in TABLE_2_1.items():
        if printed is None:
            assert table[gear].neutral
        else:
            assert round(float(table[gear].ratio), 3) == printed, gear


def test_builtin_teeth_are_buildable():
    for ps in load_description().planetary_sets:
        assert ps.z_ring == ps.z_sun + 2 * ps.z_planet
        assert (ps.z_sun + ps.z_ring) % ps.planet_count == 0


def test_simpson_ratios_match_hand_derivation():
    d = load_description(DATA / "simpson_3speed.toml")
    k_f, k_r = sp.Rational(66, 30), sp.Rational(60, 30)
    expected = {
        "1": (1 + k_f + k_r) / k_f,  # C1 + B2: ring_f = in, rear carrier held
        "2": (1 + k_f) / k_f,  # C1 + B1: sun held
        "3": sp.Integer(1),  # C1 + C2: locked
        "R": -k_r,  # C2 + B2: sun = in, rear carrier held
    }
    table = {r.gear: r for r in ratio_table(d)}
    for gear, value in expected.items():
        assert table[gear].ratio == value, gear
    assert table["N"].neutral and table["N"].degrees_of_freedom == 2


def test_thesis_ratio_expressions_by_hand():
    """Two gears whose ratio follows by hand from one set (k = z_ring/z_sun).

    8th (B08, K38, K27): shafts 8 = 3 = 0, 7 = 2, set 4 (sun 3, carrier 1, ring 7) gives
    ω7 = (1 + 1/k4) ω1, so ω1/ω2 = k4/(1 + k4). 2nd (K81, K38, B06): 1 = 8 = 3, set 3 (sun 3,
    carrier 2, ring 6 held) gives ω1/ω2 = 1 + k3.
    """
    expressions = ratio_expressions(load_description())
    k3, k4 = sp.Symbol("k_3", positive=True), sp.Symbol("k_4", positive=True)
    assert sp.cancel(expressions["8"] - k4 / (1 + k4)) == 0
    assert sp.cancel(expressions["2"] - (1 + k3)) == 0
    assert expressions["N"] is None


def test_fit_teeth_recovers_the_builtin_stationary_ratios():
    d = load_description()
    candidates = fit_teeth(d, ToothRanges(sun=(17, 60), planet=(13, 30), ring_max=110))
    assert candidates, "no candidate found"
    best = candidates[0]
    for ps in d.planetary_sets:
        zs, _, zr, _ = best.teeth[ps.name]
        assert sp.Rational(zr, zs) == sp.Rational(ps.z_ring, ps.z_sun), ps.name
    # Every candidate reproduces the table within half a unit of the third decimal.
    assert all(c.max_error <= 5e-4 for c in candidates)
    refitted = with_teeth(d, best.teeth)
    for r in ratio_table(refitted):
        if TABLE_2_1[r.gear] is not None:
            assert round(float(r.ratio), 3) == TABLE_2_1[r.gear]


def test_fit_teeth_reports_nothing_for_an_unreachable_table():
    d = load_description(DATA / "simpson_3speed.toml")
    # A tolerance of 1e-9 cannot be met by 16/11 ≈ 1.4545454 against the printed 1.4545.
    assert fit_teeth(d, ToothRanges(sun=(20, 40), planet=(13, 20)), tolerance=1e-9) == []


@pytest.mark.parametrize("planet_counts", [(3,), (3, 4)])
def test_fit_teeth_candidates_obey_assembly_conditions(planet_counts):
    d = load_description(DATA / "simpson_3speed.toml")
    ranges = ToothRanges(sun=(20, 60), planet=(13, 30), planet_counts=planet_counts)
    candidates = fit_teeth(d, ranges, top=50)
    assert candidates
    for c in candidates:
        for zs, zp, zr, n in c.teeth.values():
            assert zr == zs + 2 * zp and (zs + zr) % n == 0 and n in planet_counts
