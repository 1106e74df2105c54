"""Planetary sets given by their stationary ratio ``k`` instead of tooth counts.

Expected values by hand (Willis, carrier held, see tests/test_set_kinds.py): a simple set of
z_S = 30, z_H = 66 has i0 = −66/30 = −2.2; a double-pinion set of z_S = 30, z_H = 84 has
i0 = +84/30 = +2.8; a stepped planet of z_S = 30, z_P = 24, z_P2 = 18, z_H = 72 has
i0 = −72·24/(30·18) = −3.2. With the carrier braked, ω_S/ω_H = i0.
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest
import sympy as sp
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.kinematics import gearbox_symbols
from gearsym.symbolic.ratios import gear_ratio
from gearsym.validation.drawing.geometry import (
    lever_diagram,
    set_positions,
    speed_plan,
    stick_diagram,
)

from gearsym.cli import main
from tests.test_set_kinds import TEETH, description_text

#: kind -> (the file's k, the hand-derived i0 as an exact fraction)
GIVEN_K = {
    "simple": ("-2.2", sp.Rational(-11, 5)),
    "double_pinion": ("2.8", sp.Rational(14, 5)),
    "stepped_planet": ("-3.2", sp.Rational(-16, 5)),
}


def k_text(kind: str, k: str) -> str:
    """The set of :func:`description_text` with its tooth counts replaced by ``k``."""
    text = description_text(kind)
    body = "".join(line + "\n" for line in TEETH[kind].splitlines() if not line.startswith("z_"))
    return text.replace(TEETH[kind], body + f"k = {k}\n")


@pytest.mark.parametrize("kind", list(GIVEN_K))
def test_set_given_by_k_reproduces_the_teeth_ratio(kind: str) -> None:
    k, hand = GIVEN_K[kind]
    by_teeth = parse_description(description_text(kind), "teeth.toml")
    by_k = parse_description(k_text(kind, k), "k.toml")
    assert by_k.planetary_sets[0].z_sun == 0  # really no teeth
    assert gear_ratio(by_k, by_k.gear("1")).ratio == hand
    assert gear_ratio(by_teeth, by_teeth.gear("1")).ratio == hand


def test_k_ratio_through_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "k.toml"
    path.write_text(k_text("simple", "-2.2"), encoding="utf-8")
    assert main(["ratios", str(path)]) == 0
    assert "-2.2" in capsys.readouterr().out


def test_what_needs_teeth_refuses_naming_the_k_key() -> None:
    d = parse_description(k_text("simple", "-2.2"), "k.toml")
    for needs_teeth in (gearbox_symbols, stick_diagram):
        with pytest.raises(GearsymError) as err:
            needs_teeth(d)
        message = str(err.value)
        assert 'k.toml: planetary_set[name="x"].k: ' in message and "\n" not in message
        assert "tooth counts" in message
    # the lever diagram needs only k: sun 0, carrier k, ring k + 1 for i0 = −k (unit scale)
    assert set_positions(d.planetary_sets[0]) == {
        "S": Fraction(0),
        "T": Fraction(11, 5),
        "H": Fraction(16, 5),
    }
    assert lever_diagram(d).levers
    # speed plan, carrier braked: ω_H = ω_S / i0 = −5/11 per unit input
    assert speed_plan(d, "1").speeds == {"S": 1, "T": 0, "H": Fraction(-5, 11)}


@pytest.mark.parametrize(
    ("kind", "k", "extra", "words"),
    [
        ("simple", "2.2", "", "k < -1"),  # a simple set has a negative i0
        ("simple", "-0.5", "", "k < -1"),  # z_H > z_S
        ("double_pinion", "-2.8", "", "k > 1"),
        ("stepped_planet", "0.5", "", "k < 0"),
        ("simple", "-2.2", "z_sun = 30\n", "not both"),
        ("simple", '"-2.2"', "", "expected a number"),
    ],
)
def test_bad_k_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str, k: str, extra: str, words: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(k_text(kind, k).replace(f"k = {k}\n", f"k = {k}\n{extra}"), encoding="utf-8")
    assert main(["ratios", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1 and "Traceback" not in err
    assert f'{path}: planetary_set[name="x"].k: ' in err and words in err, err


def test_ravigneaux_needs_its_teeth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = description_text("ravigneaux").replace("z_sun = 38\n", "k = -2.2\n")
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["ratios", str(path)]) == 2
    assert "two stationary ratios" in capsys.readouterr().err


# ----------------------------------------------------------------------------- tolerances


def run(tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    path = tmp_path / "set.toml"
    path.write_text(text, encoding="utf-8")
    code = main(["ratios", str(path)])
    out, err = capsys.readouterr()
    return code, out, err


def test_unequal_planet_spacing_is_a_stated_choice(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 5 planets on z_S + z_H = 30 + 66 = 96 teeth: 96 / 5 is no integer, so equal spacing fails
    text = description_text("simple").replace("planet_count = 3", "planet_count = 5")
    code, out, err = run(tmp_path, text, capsys)
    assert code == 2 and 'planetary_set[name="x"].planet_count: ' in err
    assert "not divisible by 5" in err and 'planet_spacing = "unequal"' in err
    unequal = text.replace("planet_count = 5", 'planet_count = 5\nplanet_spacing = "unequal"')
    code, out, err = run(tmp_path, unequal, capsys)
    assert code == 0, err
    bad = text.replace("planet_count = 5", 'planet_count = 5\nplanet_spacing = "odd"')
    code, out, err = run(tmp_path, bad, capsys)
    assert code == 2 and 'planetary_set[name="x"].planet_spacing: ' in err and "unequal" in err


def test_coaxiality_tolerance_admits_a_profile_shifted_simple_set(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # z_H = 67 ≠ z_S + 2 z_P = 66: centre distances 48/2 and 49/2 modules differ by 0.5;
    # (30 + 67) = 97 is no multiple of 3, so one planet (no spacing condition).
    text = (
        description_text("simple")
        .replace("z_ring = 66", "z_ring = 67")
        .replace("planet_count = 3", "planet_count = 1")
        .replace(f"ratio = {float(Fraction(-66, 30))!r}", f"ratio = {-67 / 30!r}")
    )
    code, out, err = run(tmp_path, text, capsys)
    assert code == 2 and ".z_ring: " in err and "centre_distance_tolerance" in err
    shifted = text.replace("z_ring = 67", "z_ring = 67\ncentre_distance_tolerance = 0.5")
    d = parse_description(shifted, "shifted.toml")
    assert gear_ratio(d, d.gear("1")).ratio == sp.Rational(-67, 30)  # i0 = −z_H/z_S
    code, out, err = run(tmp_path, shifted, capsys)
    assert code == 0, err


@pytest.mark.parametrize("args", [["show", "--what", "mass-matrix"], ["ratios", "--json"]])
def test_k_set_through_model_commands(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    """The mass matrix needs the teeth (one line, exit 2); the JSON ratio is i0 = −2.2."""
    path = tmp_path / "k.toml"
    path.write_text(k_text("simple", "-2.2"), encoding="utf-8")
    code = main([args[0], str(path), *args[1:]])
    out, err = capsys.readouterr()
    if args[0] == "show":
        assert code == 2 and out == "" and len(err.splitlines()) == 1, err
        assert f'{path}: planetary_set[name="x"].k: building the planet bodies' in err
    else:
        assert code == 0, err
        assert json.loads(out)["1"] == pytest.approx(-2.2, abs=1e-12)
