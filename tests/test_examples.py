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
from gearsym.symbolic.description import parse_description
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
