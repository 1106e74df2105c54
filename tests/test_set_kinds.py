"""Planetary set kinds (simple, double pinion, Ravigneaux with two suns or two rings, stepped
planet) against hand work.

Expected values are derived by hand in the comments (Willis: teeth pass every mesh at the same
rate in the carrier frame), never read off the code under test; the kinetic energy is summed
body by body with NumPy from hand-derived body speeds.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.kinematics import gearbox_symbols, willis_constraints
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import gear_ratio
from gearsym.symbolic.sympy_utils import exact_nullspace

from gearsym.cli import main


def q(value: float, unit: str) -> str:
    return f'{{ value = {value}, unit = "{unit}", source = "test" }}'


#: Per kind: the set's extra TOML lines, and (input shaft, hand-derived ω_in/ω_out with the
#: carrier held) for a gear that brakes the carrier.
TEETH = {
    "simple": "z_sun = 30\nz_planet = 18\nz_ring = 66\n",
    "double_pinion": (
        'z_sun = 30\nz_planet = 17\nz_ring = 84\nplanet_outer = "Po"\nz_planet_outer = 19\n'
        f"planet_outer_mass = {q(0.2, 'kg')}\nplanet_outer_inertia = {q(3e-5, 'kg*m^2')}\n"
        f"planet_outer_radius = {q(0.06, 'm')}\n"
    ),
    "stepped_planet": "z_sun = 30\nz_planet = 24\nz_ring = 72\nz_planet_ring = 18\n",
    "ravigneaux": (
        "z_sun = 38\nz_planet = 23\nz_ring = 85\ncentre_distance_tolerance = 0.5\n"
        'sun_short = "S2"\nz_sun_short = 31\nplanet_short = "Ps"\nz_planet_short = 20\n'
        f"planet_short_mass = {q(0.15, 'kg')}\nplanet_short_inertia = {q(2e-5, 'kg*m^2')}\n"
        f"planet_short_radius = {q(0.045, 'm')}\n"
    ),
    # the 7G-Tronic's kind: long pinion on sun and ring H, short pinion on long pinion and
    # ring H2. Buildable by hand: coaxial 30 + 2·18 = 66; long-pinion centre 24, short-pinion
    # centre (78 − 15)/2 = 31.5, distance (18 + 15)/2 = 16.5: |31.5 − 24| < 16.5 < 55.5; the
    # long pinion's tip 24 + 10 < (78 − 2)/2, the short one 31.5 − 8.5 > (30 + 2)/2;
    # (30 + 66)/3 and (78 − 30)/3 are integers.
    "ravigneaux_two_rings": (
        "z_sun = 30\nz_planet = 18\nz_ring = 66\n"
        'ring_short = "H2"\nz_ring_short = 78\nplanet_short = "Ps"\nz_planet_short = 15\n'
        f"planet_short_mass = {q(0.15, 'kg')}\nplanet_short_inertia = {q(2e-5, 'kg*m^2')}\n"
        f"planet_short_radius = {q(0.063, 'm')}\n"
    ),
}

# Hand: carrier held, z_S ω_S = −z_P ω_P (external), z_H ω_H = z_P' ω_P (internal), so
# simple  ω_S/ω_H = −z_H/z_S = −66/30;
# double  z_S ω_S = −z_P1 ω_P1 = z_P2 ω_P2 = z_H ω_H → ω_S/ω_H = +z_H/z_S = 84/30;
# stepped z_S ω_S = −z_P ω_P, z_H ω_H = z_P2 ω_P → ω_S/ω_H = −z_H z_P/(z_S z_P2) = −72·24/(30·18);
# Ravigneaux: sun–long–ring as simple, −85/38; short sun: z_S2 ω_S2 = −z_Ps ω_Ps = z_L ω_L
# = z_H ω_H → ω_S2/ω_H = +85/31.
STATIONARY = {
    "simple": Fraction(-66, 30),
    "double_pinion": Fraction(84, 30),
    "stepped_planet": Fraction(-72 * 24, 30 * 18),
    "ravigneaux": Fraction(-85, 38),
    # two rings: sun–long–ring H as simple, −66/30 (the short pair is tested below)
    "ravigneaux_two_rings": Fraction(-66, 30),
}


def description_text(kind: str, input_shaft: str = "S", ratio: Fraction | None = None) -> str:
    ratio = STATIONARY[kind] if ratio is None else ratio
    shafts = ["S", "T", "H"] + {"ravigneaux": ["S2"], "ravigneaux_two_rings": ["H2"]}.get(kind, [])
    inertias = {"S": 0.01, "T": 0.03, "H": 0.05, "S2": 0.02, "H2": 0.04}
    text = f'''
[gearbox]
name = "one_{kind}"
input_shaft = "{input_shaft}"
output_shaft = "H"
coordinates = ["T", "{input_shaft}"]
'''
    for s in shafts:
        text += f'[[shaft]]\nname = "{s}"\ninertia = {q(inertias[s], "kg*m^2")}\n'
    text += f'''
[[planetary_set]]
name = "x"
kind = "{kind}"
sun = "S"
carrier = "T"
ring = "H"
planet = "P"
planet_count = 3
teeth_source = "test"
planet_mass = {q(0.3, "kg")}
planet_inertia = {q(4e-5, "kg*m^2")}
carrier_radius = {q(0.05, "m")}
{TEETH[kind]}
[[shift_element]]
name = "BT"
kind = "brake"
shaft = "T"

[gear_table]
ratio_decimals = 9

[[gear]]
name = "1"
closed = ["BT"]
ratio = {float(ratio)!r}
'''
    return text


KINDS = list(STATIONARY)


@pytest.mark.parametrize("kind", KINDS)
def test_stationary_ratio_from_the_gear_table(kind: str) -> None:
    """The shaft relations (pinions eliminated) give the hand-derived stationary ratio."""
    d = parse_description(description_text(kind), f"{kind}.toml")
    result = gear_ratio(d, d.gear("1"))
    assert result.ratio == sp.Rational(STATIONARY[kind].numerator, STATIONARY[kind].denominator)


@pytest.mark.parametrize("kind", KINDS)
def test_stationary_ratio_from_the_mesh_constraints(kind: str) -> None:
    """The Willis rows over all bodies (pinions kept) give the same hand value: the route to
    the mass matrix agrees with the route to the gear table."""
    d = parse_description(description_text(kind), f"{kind}.toml")
    g = willis_constraints(d, gearbox_symbols(d))
    index = {b: i for i, b in enumerate(d.body_names)}
    held = sp.zeros(1, len(index))
    held[0, index["T"]] = 1
    (motion,) = exact_nullspace(g.col_join(held))
    assert motion[index["S"]] / motion[index["H"]] == sp.Rational(
        STATIONARY[kind].numerator, STATIONARY[kind].denominator
    )


def test_ravigneaux_short_sun_pair_is_a_positive_ratio() -> None:
    """Input on the short-pinion sun: ω_S2/ω_H = +z_H/z_S2 = 85/31 with the carrier held."""
    d = parse_description(description_text("ravigneaux", "S2", Fraction(85, 31)), "rav.toml")
    assert gear_ratio(d, d.gear("1")).ratio == sp.Rational(85, 31)


def test_ravigneaux_degrees_of_freedom() -> None:
    """4 shafts + 2 pinion bodies − 4 meshes = 2 (2.24 generalised)."""
    d = parse_description(description_text("ravigneaux"), "rav.toml")
    assert d.degrees_of_freedom == 2
    assert d.body_names == ("S", "T", "H", "S2", "P", "Ps")


def test_two_ring_ravigneaux_short_pair_is_a_positive_ratio() -> None:
    """Output on the ring of the short pinions, carrier held: z_S ω_S = −z_L ω_L (external),
    z_L ω_L = −z_Ps ω_Ps (external), z_Ps ω_Ps = z_H2 ω_H2 (internal), so
    ω_S/ω_H2 = +z_H2/z_S = +78/30, both from the gear table and from the mesh rows."""
    text = description_text("ravigneaux_two_rings", "S", Fraction(78, 30))
    d = parse_description(text.replace('output_shaft = "H"', 'output_shaft = "H2"'), "r2.toml")
    assert gear_ratio(d, d.gear("1")).ratio == sp.Rational(78, 30)
    g = willis_constraints(d, gearbox_symbols(d))
    index = {b: i for i, b in enumerate(d.body_names)}
    held = sp.zeros(1, len(index))
    held[0, index["T"]] = 1
    (motion,) = exact_nullspace(g.col_join(held))
    assert motion[index["S"]] / motion[index["H2"]] == sp.Rational(78, 30)
    # 4 shafts + 2 pinion bodies − 4 meshes = 2 degrees of freedom
    assert d.degrees_of_freedom == 2
    assert d.body_names == ("S", "T", "H", "H2", "P", "Ps")


def hand_speeds(kind: str, w_c: float, w_s: float) -> dict[str, float]:
    """Body speeds from carrier and sun speed, mesh by mesh (relative to the carrier)."""
    rel_s = w_s - w_c
    if kind == "simple":  # z_S rel_S = −z_P rel_P ; z_H rel_H = z_P rel_P
        rel_p = -30 / 18 * rel_s
        return {"S": w_s, "T": w_c, "P": w_c + rel_p, "H": w_c + 18 / 66 * rel_p}
    if kind == "double_pinion":  # sun–inner, inner–outer external, outer–ring internal
        rel_p = -30 / 17 * rel_s
        rel_po = -17 / 19 * rel_p
        return {
            "S": w_s,
            "T": w_c,
            "P": w_c + rel_p,
            "Po": w_c + rel_po,
            "H": w_c + 19 / 84 * rel_po,
        }
    if kind == "stepped_planet":  # sun on the 24-tooth step, ring on the 18-tooth step
        rel_p = -30 / 24 * rel_s
        return {"S": w_s, "T": w_c, "P": w_c + rel_p, "H": w_c + 18 / 72 * rel_p}
    if kind == "ravigneaux_two_rings":  # sun–long ext, ring–long int, long–short ext,
        rel_l = -30 / 18 * rel_s  # short–second ring internal
        rel_sh = -18 / 15 * rel_l
        return {
            "S": w_s,
            "T": w_c,
            "P": w_c + rel_l,
            "H": w_c + 18 / 66 * rel_l,
            "Ps": w_c + rel_sh,
            "H2": w_c + 15 / 78 * rel_sh,
        }
    # Ravigneaux: sun–long external, ring–long internal, long–short external, short–sun2
    rel_l = -38 / 23 * rel_s
    rel_sh = -23 / 20 * rel_l
    return {
        "S": w_s,
        "T": w_c,
        "P": w_c + rel_l,
        "H": w_c + 23 / 85 * rel_l,
        "Ps": w_c + rel_sh,
        "S2": w_c - 20 / 31 * rel_sh,
    }


@pytest.mark.parametrize("kind", KINDS)
def test_kinetic_energy_of_one_set(kind: str) -> None:
    """½ ẏᵀ M ẏ (2.34, Jacobian route) equals ½ Σ J ω² over the shafts plus, per pinion
    body, n·(½ J_p ω_p² + ½ m_p (r_p ω_C)²) (spin and orbit), at a random motion."""
    d = parse_description(description_text(kind), f"{kind}.toml")
    m = np.array(gearbox_dynamics(d).mass_matrix.evalf(), dtype=float)
    rng = np.random.default_rng(11)
    w_c, w_s = rng.normal(size=2) * 100
    w = hand_speeds(kind, w_c, w_s)
    shafts = {"S": 0.01, "T": 0.03, "H": 0.05, "S2": 0.02, "H2": 0.04}
    radius_short = 0.063 if kind == "ravigneaux_two_rings" else 0.045
    pinions = {"P": (4e-5, 0.3, 0.05), "Po": (3e-5, 0.2, 0.06), "Ps": (2e-5, 0.15, radius_short)}
    n = 3
    energy = sum(0.5 * shafts[b] * w[b] ** 2 for b in shafts if b in w)
    for body, (inertia, mass, radius) in pinions.items():
        if body in w:
            energy += n * (0.5 * inertia * w[body] ** 2 + 0.5 * mass * (radius * w_c) ** 2)
    y_dot = np.array([w_c, w_s])  # coordinates ["T", "S"]
    assert 0.5 * y_dot @ m @ y_dot == pytest.approx(energy, rel=1e-12)


def test_simple_kind_is_the_default() -> None:
    """No ``kind`` key: the thesis' simple set, and the built-in box keeps 4 DOF (2.24)."""
    d = load_description()
    assert {ps.kind for ps in d.planetary_sets} == {"simple"}
    assert d.degrees_of_freedom == 4


# ----------------------------------------------------------------------------- bad input


def run_ratios(tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]) -> str:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    code = main(["ratios", str(path)])
    out, err = capsys.readouterr()
    assert code == 2, err
    assert out == "" and len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith(f"gearsym: {path}: ")
    return err


@pytest.mark.parametrize(
    ("kind", "old", "new", "key", "words"),
    [
        ("simple", 'kind = "simple"', 'kind = "compound"', "kind", "ravigneaux"),
        (
            "simple",
            "z_ring = 66\n",
            "z_ring = 66\nz_planet_outer = 3\n",
            "z_planet_outer",
            "double",
        ),
        ("ravigneaux", "centre_distance_tolerance = 0.5\n", "", "z_ring", "tolerance"),
        (
            "ravigneaux",
            "centre_distance_tolerance = 0.5",
            "centre_distance_tolerance = 0.4",
            "z_ring",
            "differ by 0.5",
        ),
        (
            "ravigneaux",
            "centre_distance_tolerance = 0.5",
            "centre_distance_tolerance = 7",
            "centre_distance_tolerance",
            "0 to 2",
        ),
        ("ravigneaux", 'sun_short = "S2"\n', "", "sun_short", "missing"),
        ("ravigneaux", 'sun_short = "S2"', 'sun_short = "S"', "", "different shafts"),
        ("ravigneaux", "z_planet_short = 20", "z_planet_short = 2", "z_planet_short", "triangle"),
        ("double_pinion", "z_planet_outer = 19", "z_planet_outer = 40", "z_planet_outer", "sun"),
        # 24 + 10 ≥ (70 − 2)/2: the long pinion would touch the second ring
        (
            "ravigneaux_two_rings",
            "z_ring_short = 78",
            "z_ring_short = 70",
            "z_planet_short",
            "ring",
        ),
        # (80 − 30)/3 is no integer
        (
            "ravigneaux_two_rings",
            "z_ring_short = 78",
            "z_ring_short = 80",
            "planet_count",
            "spaced",
        ),
        ("ravigneaux_two_rings", 'ring_short = "H2"', 'ring_short = "H"', "", "different shafts"),
        ("double_pinion", "planet_count = 3", "planet_count = 4", "planet_count", "spaced"),
        ("stepped_planet", "z_planet_ring = 18", "z_planet_ring = 17", "z_planet_ring", "coaxial"),
        ("stepped_planet", "planet_count = 3", "planet_count = 5", "planet_count", "gcd"),
    ],
)
def test_bad_set_is_one_line(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    kind: str,
    old: str,
    new: str,
    key: str,
    words: str,
) -> None:
    text = description_text(kind)
    assert old in text
    err = run_ratios(tmp_path, text.replace(old, new), capsys)
    assert 'planetary_set[name="x"]' in err
    if key:
        assert f'planetary_set[name="x"].{key}: ' in err, err
    assert words in err, err


# ----------------------------------------------------------------------------- housing


def test_member_fixed_to_the_housing() -> None:
    """sun = "housing": no shaft, no brake, no state. Hand: ring in, carrier out, sun at rest:
    z_S(0 − ω_C) = −z_P(ω_P − ω_C), z_H(ω_H − ω_C) = z_P(ω_P − ω_C) → ω_H/ω_C = 1 + z_S/z_H
    = 96/66; the one coordinate is the carrier and ½ M ω_C² is the hand energy."""
    text = description_text("simple").replace('sun = "S"', 'sun = "housing"')
    text = text.replace('[[shaft]]\nname = "S"\n', '[[shaft]]\nname = "unused"\n', 1)
    text = text.replace('coordinates = ["T", "S"]', 'coordinates = ["T", "unused"]')
    text = text.replace('input_shaft = "S"', 'input_shaft = "H"')
    text = text.replace('output_shaft = "H"', 'output_shaft = "T"')
    # the brake on the carrier would now lock it: the gear closes nothing
    text = text.replace('closed = ["BT"]\nratio = -2.2', "closed = []\nratio = 1.454545454545")
    text = text.replace('kind = "brake"\nshaft = "T"', 'kind = "brake"\nshaft = "unused"')
    text = text.replace("ratio_decimals = 9", "ratio_decimals = 12")
    d = parse_description(text, "housing.toml")
    assert "housing" not in d.body_names
    # shafts unused, T, H; one planet; 2 meshes → 2 DOF: the unused shaft is its own DOF
    assert d.degrees_of_freedom == 2
    result = gear_ratio(d, d.gear("1"))
    assert result.ratio == sp.Rational(96, 66)
    assert result.free_shafts == ("unused",)


def test_housing_mass_matrix_by_hand() -> None:
    text = description_text("simple").replace('sun = "S"', 'sun = "housing"')
    d = parse_description(
        text.replace('closed = ["BT"]', 'closed = ["BT"]\nneutral = true').replace(
            "ratio = -2.2", "# ratio = -2.2"
        ),
        "housing.toml",
    )
    m = np.array(gearbox_dynamics(d).mass_matrix.evalf(), dtype=float)
    w_c, w_s = 3.0, -7.0
    # the sun shaft S is on no set now: its own coordinate; the set turns with the carrier
    rel_p = -30 / 18 * (0 - w_c)
    w_p, w_h = w_c + rel_p, w_c + 18 / 66 * rel_p
    energy = 0.5 * (0.01 * w_s**2 + 0.03 * w_c**2 + 0.05 * w_h**2)
    energy += 3 * (0.5 * 4e-5 * w_p**2 + 0.5 * 0.3 * (0.05 * w_c) ** 2)
    y_dot = np.array([w_c, w_s])
    assert 0.5 * y_dot @ m @ y_dot == pytest.approx(energy, rel=1e-12)


def test_housing_is_reserved_and_not_an_element_shaft(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = description_text("simple")
    err = run_ratios(tmp_path, text.replace('name = "H"', 'name = "housing"'), capsys)
    assert "reserved" in err
    err = run_ratios(
        tmp_path,
        text.replace('kind = "brake"\nshaft = "T"', 'kind = "brake"\nshaft = "housing"'),
        capsys,
    )
    assert 'shift_element[name="BT"].shaft: ' in err and "brake" in err


def test_a_truly_two_dof_gear_names_its_free_shafts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Simpson 3-speed with only C1 closed: input held → ring_f held, yet sun, out and
    carrier_r still turn together (two sets, three free shafts, one relation each way)."""
    text = Path("tests/data/simpson_3speed.toml").read_text(encoding="utf-8")
    text = text.replace('closed = ["C1", "B2"]', 'closed = ["C1"]')
    err = run_ratios(tmp_path, text, capsys)
    assert 'gear[name="1"].closed: ' in err
    assert "leaves 2 degrees of freedom" in err
    assert "shaft(s) sun, out, carrier_r can still turn" in err


def test_idle_shaft_is_reported_by_the_ratio_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Simpson plus a shaft reached only through an open clutch: every gear keeps its
    hand-derived ratio (26/11 in 1st, header of the file) and names the idle shaft."""
    text = Path("tests/data/simpson_3speed.toml").read_text(encoding="utf-8")
    text = text.replace(
        "[[planetary_set]]",
        '[[shaft]]\nname = "idle"\ninertia = { value = 0.01, unit = "kg*m^2", '
        'source = "test" }\n\n[[planetary_set]]',
        1,
    )
    text = text.replace(
        '[[shift_element]]\nname = "C1"',
        '[[shift_element]]\nname = "C3"\nkind = "clutch"\nshafts = ["idle", "sun"]\n\n'
        '[[shift_element]]\nname = "C1"',
    )
    path = tmp_path / "idle.toml"
    path.write_text(text, encoding="utf-8")
    d = load_description(path)
    first = gear_ratio(d, d.gear("1"))
    assert first.ratio == sp.Rational(26, 11)
    assert first.free_shafts == ("idle",)
    assert main(["ratios", str(path)]) == 0
    out = capsys.readouterr().out
    assert "gear 1: idle: idle (speed undetermined; model assumes drag" in out
