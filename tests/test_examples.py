"""Example descriptions of published transmissions (gearsym/data/examples/).

The ZF 6HP26 Lepelletier 6-speed: its published ratios (4.171, 2.340, 1.521, 1.143, 0.867,
0.691, R −3.403) from `gearsym ratios`; exact ratios from the hand derivation in the file's
header; the tooth counts confirmed by an independent brute-force search (plain fractions, not
the code under test); the housing member against the old workaround (a dummy shaft held by a
brake closed in every gear).
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.drivetrain import full_model
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import ratio_table

from gearsym.cli import main

LEPELLETIER = Path(__file__).resolve().parents[1] / "gearsym/data/examples/lepelletier_6speed.toml"
PUBLISHED = {"1": 4.171, "2": 2.340, "3": 1.521, "4": 1.143, "5": 0.867, "6": 0.691, "R": -3.403}


def hand_ratios(zs1: int, zr1: int, zs2: int, zs3: int, zr: int) -> dict[str, Fraction]:
    """Lepelletier ratios by hand (file header): c1 = zr1/(zs1 + zr1) ω_in; Ravigneaux
    long-pinion pair i0 = −k1 = −zr/zs3, short-pinion pair i0 = +k2 = zr/zs2."""
    p = Fraction(zs1 + zr1, zr1)
    k1, k2 = Fraction(zr, zs3), Fraction(zr, zs2)
    c2 = k1 / (1 + k1)  # 2nd: s3 held, per unit output speed
    return {
        "1": p * k2,
        "2": p * (c2 + k2 * (1 - c2)),
        "3": p,
        "4": 1 / (1 + (1 / p - 1) / k2),
        "5": 1 / (1 - (1 / p - 1) / k1),
        "6": 1 / (1 + 1 / k1),
        "R": -p * k1,
    }


def test_ratios_reproduce_the_published_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ratios", str(LEPELLETIER), "--json"]) == 0
    derived = json.loads(capsys.readouterr().out)
    for gear, published in PUBLISHED.items():
        assert round(derived[gear], 3) == published, gear
    assert derived["N"] is None


def test_exact_ratios_equal_the_hand_derivation() -> None:
    d = load_description(LEPELLETIER)
    hand = hand_ratios(37, 71, 31, 38, 85)
    for r in ratio_table(d):
        if not r.neutral:
            assert r.ratio == sp.Rational(hand[r.gear].numerator, hand[r.gear].denominator)
            assert r.free_shafts == ()


def test_tooth_counts_are_the_only_ones_in_a_wide_range() -> None:
    """Independent of gearsym: every (z_S1, z_H1, z_S2, z_S3, z_H) with planets of 13–40
    teeth in the simple set, suns of 20+ teeth and rings of 60–120 teeth; only the file's
    counts reproduce all seven published ratios to three decimals."""
    found = []
    for zs1 in range(20, 60):
        for zr1 in range(zs1 + 26, zs1 + 81, 2):
            p = (zs1 + zr1) / zr1
            if abs(p - 1.521) > 0.0005:
                continue
            for zr in range(60, 121):
                for zs3 in range(20, zr - 20):
                    if abs(p * zr / zs3 - 3.403) > 0.0005:
                        continue
                    for zs2 in range(20, zr - 20):
                        ratios = hand_ratios(zs1, zr1, zs2, zs3, zr)
                        if all(round(float(ratios[g]), 3) == v for g, v in PUBLISHED.items()):
                            found.append((zs1, zr1, zs2, zs3, zr))
    assert found == [(37, 71, 31, 38, 85)]


def test_housing_adds_no_state_and_no_input() -> None:
    model = full_model(load_description(LEPELLETIER))
    assert [v.name for v in model.states] == [
        "omega_in",
        "omega_s3",
        "omega_out",
        "phi",
        "omega_C",
    ]
    assert [v.name for v in model.inputs] == ["T_In", "T_A", "T_B", "T_C", "T_D", "T_E"]


def test_housing_mass_matrix_equals_the_dummy_brake_workaround() -> None:
    """The old workaround: the fixed sun as a shaft s1 with a brake closed in every gear. With
    s1 a coordinate held at zero, its mass matrix restricted to the other coordinates is the
    housing version's mass matrix (the same bodies turn at the same speeds)."""
    text = LEPELLETIER.read_text(encoding="utf-8")
    dummy = text.replace('sun = "housing"', 'sun = "s1"')
    dummy = dummy.replace(
        '[[shaft]]\nname = "in"',
        '[[shaft]]\nname = "s1"\ninertia = { value = 0.02, unit = "kg*m^2", source = "t" }\n'
        '[[shaft]]\nname = "in"',
    )
    dummy = dummy.replace(
        'coordinates = ["in", "s3", "out"]', 'coordinates = ["in", "s3", "out", "s1"]'
    )
    dummy = dummy.replace(
        '[[shift_element]]\nname = "A"',
        '[[shift_element]]\nname = "F"\nkind = "brake"\nshaft = "s1"\n\n'
        '[[shift_element]]\nname = "A"',
    )
    for gear_closed in (
        '["A", "D"]',
        '["A", "C"]',
        '["A", "B"]',
        '["A", "E"]',
        '["B", "E"]',
        '["C", "E"]',
        '["B", "D"]',
        "[]",
    ):
        dummy = dummy.replace(
            f"closed = {gear_closed}",
            f'closed = {gear_closed[:-1]}{", " if gear_closed != "[]" else ""}"F"]',
        )
    d_dummy = parse_description(dummy, "dummy.toml")
    d_housing = load_description(LEPELLETIER)
    m_dummy = np.array(gearbox_dynamics(d_dummy).mass_matrix.evalf(), dtype=float)
    m_housing = np.array(gearbox_dynamics(d_housing).mass_matrix.evalf(), dtype=float)
    assert m_dummy.shape == (4, 4) and m_housing.shape == (3, 3)
    np.testing.assert_allclose(m_dummy[:3, :3], m_housing, rtol=1e-14)
    assert [r.ratio for r in ratio_table(d_dummy)] == [r.ratio for r in ratio_table(d_housing)]


def test_generate_runs_end_to_end(tmp_path: Path) -> None:
    """`gearsym generate` on the example writes the full model, every adjacent shift and the
    friction model (the compiled validation, --check, is run by hand: see README)."""
    out = tmp_path / "lep"
    assert main(["generate", str(LEPELLETIER), "--out", str(out)]) == 0
    c_files = {p.name for p in (out / "c").iterdir()}
    for model in ("full", "shift_1_2", "shift_5_6", "shift_element"):
        assert f"gearsym_{model}.c" in c_files


# ----------------------------------------------------------------------------- 7G-Tronic

SEVEN_G = Path(__file__).resolve().parents[1] / "gearsym/data/examples/mercedes_7g_tronic.toml"
SEVEN_G_PUBLISHED = {
    "1": 4.377,
    "2": 2.859,
    "3": 1.921,
    "4": 1.368,
    "5": 1.000,
    "6": 0.820,
    "7": 0.728,
    "R1": -3.416,
    "R2": -2.231,
}


def seven_g_hand(a: Fraction, b: Fraction, r: Fraction, f: Fraction) -> dict[str, Fraction]:
    """7G-Tronic ratios by hand (file header), ω_in = 1 on the small ring 5.

    Ravigneaux set with two rings, carrier 6: ring 8 held (B3) → a/(a + b), sun 7 held (B1)
    → a/(1 + a), locked (K1) → 1, with a = z_ring/z_sun (long pair, i0 = −a) and
    b = z_ring_short/z_sun (short pair, i0 = +b). Then the two simple sets (r, f = ring/sun):
    suns 11 and 14 held (K3 + B2): ω_out = ω6 r/(1 + r) f/(1 + f); carrier 10 driven (K2)
    with K3: ω_out = (1 + r − r ω6 + f)/(1 + f); carrier 10 held (BR) with K3:
    ω_out = −r ω6/(1 + f).
    """
    w6 = {"B3": a / (a + b), "B1": a / (1 + a), "K1": Fraction(1)}

    def held(w: Fraction) -> Fraction:
        return 1 / (w * r / (1 + r) * f / (1 + f))

    def driven(w: Fraction) -> Fraction:
        return (1 + f) / (1 + r - r * w + f)

    def reverse(w: Fraction) -> Fraction:
        return -(1 + f) / (r * w)

    return {
        "1": held(w6["B3"]),
        "2": held(w6["B1"]),
        "3": held(w6["K1"]),
        "4": (1 + f) / f,
        "5": Fraction(1),
        "6": driven(w6["B1"]),
        "7": driven(w6["B3"]),
        "R1": reverse(w6["B3"]),
        "R2": reverse(w6["B1"]),
    }


def test_7g_ratios_reproduce_the_published_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ratios", str(SEVEN_G), "--json"]) == 0
    derived = json.loads(capsys.readouterr().out)
    for gear, published in SEVEN_G_PUBLISHED.items():
        assert round(derived[gear], 3) == published, gear
    assert derived["N"] is None


def test_7g_exact_ratios_equal_the_hand_derivation() -> None:
    d = load_description(SEVEN_G)
    assert [ps.kind for ps in d.planetary_sets] == ["ravigneaux_two_rings", "simple", "simple"]
    rav, rear, front = d.planetary_sets
    assert rav.ring2 == "r8" and rav.sun == "s7" and rav.ring == d.input_shaft
    hand = seven_g_hand(
        Fraction(rav.z_ring, rav.z_sun),
        Fraction(rav.z_ring2, rav.z_sun),
        Fraction(rear.z_ring, rear.z_sun),
        Fraction(front.z_ring, front.z_sun),
    )
    for r in ratio_table(d):
        if not r.neutral:
            assert r.ratio == sp.Rational(hand[r.gear].numerator, hand[r.gear].denominator)
            assert r.degrees_of_freedom == 1 and r.free_shafts == ()


def test_7g_stationary_ratios_are_the_only_ones_in_the_fit_ranges() -> None:
    """Independent of gearsym: every stationary ratio z_ring/z_sun with suns of 17–110 and
    rings up to 180 teeth (fit-teeth's default ranges, buildability aside); only
    a = 43/21, b = 55/21 (one sun for both), r = 57/23, f = 19/7 reproduce all nine
    published ratios to three decimals. Gear 4 fixes f, gear 3 then r, gear 2 a, gear 1 b
    (each to an interval that the rounding allows; every survivor is checked exactly)."""
    near = 5e-4 + 1e-9

    def between(low: float, high: float) -> list[Fraction]:
        """Every z_ring/z_sun in [low, high] (low > 0)."""
        return [
            Fraction(zr, zs)
            for zs in range(17, 111)
            for zr in range(max(1, int(zs * low)), min(180, int(zs * high) + 1) + 1)
            if low <= zr / zs <= high
        ]

    found = set()
    # gear 4: (1 + f)/f = 1.368 ± near  →  f = 1/(i − 1)
    for f in between(1 / (1.368 + near - 1), 1 / (1.368 - near - 1)):
        p = float((1 + f) / f)
        # gear 3: (1 + r)/r · p = 1.921 ± near
        for r in between(1 / ((1.921 + near) / p - 1), 1 / ((1.921 - near) / p - 1)):
            q = float((1 + r) / r) * p
            # gear 2: (1 + a)/a · q = 2.859 ± near, then gear 1: (a + b)/a · q = 4.377 ± near
            for a in between(1 / ((2.859 + near) / q - 1), 1 / ((2.859 - near) / q - 1)):
                low, high = ((4.377 - near) / q - 1) * a, ((4.377 + near) / q - 1) * a
                # a and b share the sun: every sun that realises a (a multiple of its
                # denominator) with every second ring in the interval
                for zs in range(a.denominator, 111, a.denominator):
                    for zb in range(int(low * zs), min(180, int(high * zs) + 1) + 1):
                        b = Fraction(zb, zs)
                        ratios = seven_g_hand(a, b, r, f)
                        if all(
                            round(float(ratios[g]), 3) == v for g, v in SEVEN_G_PUBLISHED.items()
                        ):
                            found.add((a, b, r, f))
    assert found == {(Fraction(43, 21), Fraction(55, 21), Fraction(57, 23), Fraction(19, 7))}


def test_7g_fit_teeth_from_zero_teeth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The header's claim: fit-teeth on the file with every tooth count 0 finds exactly one
    set of stationary ratios, the file's."""
    import re

    text = re.sub(r"^(z_\w+) = \d+", r"\1 = 0", SEVEN_G.read_text(encoding="utf-8"), flags=re.M)
    path = tmp_path / "zero.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["fit-teeth", str(path), "--planet-count", "3,4,5", "--json"]) == 0
    candidates = json.loads(capsys.readouterr().out)
    assert len(candidates) == 1
    sets = candidates[0]["sets"]
    rav = sets["rav"]
    assert Fraction(rav["z_ring"], rav["z_sun"]) == Fraction(43, 21)
    assert Fraction(rav["z_ring_short"], rav["z_sun"]) == Fraction(55, 21)
    assert Fraction(sets["rear"]["z_ring"], sets["rear"]["z_sun"]) == Fraction(57, 23)
    assert Fraction(sets["front"]["z_ring"], sets["front"]["z_sun"]) == Fraction(19, 7)
