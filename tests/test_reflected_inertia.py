"""Sets given by ``k`` enter the mass matrix through ``planet_inertia_reflected``.

Without teeth the planets' spin is unknown, so the file gives their kinetic energy as inertias
reflected to the set's members: ½ (J_S ω_S² + J_T ω_T² + J_H ω_H²) equals the planets' energy
for every motion the set allows. Expected values are independent of the code under test:

- the reflected inertias that correspond to a set's teeth are solved here with NumPy from the
  hand-derived body speeds of tests/test_set_kinds.py (``hand_speeds``: planet spin relative
  to the carrier −(z_S/z_P)(ω_S − ω_C) for a simple set, mesh by mesh for the others), and
  for the simple set also from the closed form derived by hand (README);
- the set given by k with those values must give the mass matrix of the set given by teeth
  (2.34 through the Jacobian route, with the pinions as bodies);
- the kinetic energy ½ ẏᵀMẏ of a k set is summed shaft by shaft with NumPy from the Willis
  relation ω_H = (ω_S − (1 − i0) ω_C)/i0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.errors import GearsymError

from gearsym.cli import main
from tests.test_set_kinds import description_text, hand_speeds
from tests.test_stationary_k import GIVEN_K, k_text

N_PLANETS = 3
#: Per pinion (inertia, mass, orbit radius) as in description_text (kg m², kg, m).
PINIONS = {"P": (4e-5, 0.3, 0.05), "Po": (3e-5, 0.2, 0.06)}
SHAFTS = {"S": 0.01, "T": 0.03, "H": 0.05}


def planet_energy(kind: str, w_c: float, w_s: float) -> float:
    """n·(½ J_p ω_p² + ½ m_p (r_p ω_C)²) over the pinions, from hand-derived speeds."""
    w = hand_speeds(kind, w_c, w_s)
    return sum(
        N_PLANETS * (0.5 * j * w[p] ** 2 + 0.5 * m * (r * w_c) ** 2)
        for p, (j, m, r) in PINIONS.items()
        if p in w
    )


def reflected_by_numpy(kind: str) -> np.ndarray:
    """(J_S, J_T, J_H) with ½ Σ J ω_member² = planet energy at three independent motions."""
    motions = [(1.0, 0.0), (0.0, 1.0), (1.0, 1.7)]  # (ω_C, ω_S)
    rows, rhs = [], []
    for w_c, w_s in motions:
        w = hand_speeds(kind, w_c, w_s)
        rows.append([0.5 * w["S"] ** 2, 0.5 * w["T"] ** 2, 0.5 * w["H"] ** 2])
        rhs.append(planet_energy(kind, w_c, w_s))
    return np.linalg.solve(np.array(rows), np.array(rhs))


def reflected_line(values: np.ndarray) -> str:
    s, t, h = (repr(float(v)) for v in values)
    return (
        f"planet_inertia_reflected = {{ sun = {s}, carrier = {t}, ring = {h}, "
        'unit = "kg*m^2", source = "test: from the teeth set" }\n'
    )


def k_reflected_text(kind: str, values: np.ndarray) -> str:
    """The k set of tests/test_stationary_k.py, its planets given as reflected inertias."""
    text = k_text(kind, GIVEN_K[kind][0])
    drop = ("planet_mass", "planet_inertia", "carrier_radius", "planet_outer_")
    text = "".join(line + "\n" for line in text.splitlines() if not line.startswith(drop))
    text = text.replace('planet_outer = "Po"\n', "")
    return text.replace(
        f"k = {GIVEN_K[kind][0]}\n", f"k = {GIVEN_K[kind][0]}\n" + reflected_line(values)
    )


def mass(text: str) -> np.ndarray:
    d = parse_description(text, "set.toml")
    return np.array(gearbox_dynamics(d).mass_matrix.evalf(), dtype=float)


def test_simple_set_closed_form_matches_numpy() -> None:
    """Hand derivation for a simple set (z_S 30, z_P 18, z_H 66, n planets of J_p, m, r):
    ω_P − ω_C = −(z_S/z_P)(ω_S − ω_C); eliminating ω_H with the Willis relation and matching
    the coefficients of ω_S², ω_C², ω_S ω_C gives
    J_S = n J_p z_S² (z_H − z_P)/(z_P² (z_S + z_H)),
    J_H = n J_p (z_S + z_P) z_H²/(z_P² (z_S + z_H)),
    J_T = n m r² − n J_p (z_S + z_P)(z_H − z_P)/z_P²."""
    zs, zp, zh = 30, 18, 66
    j, m, r = PINIONS["P"]
    n = N_PLANETS
    hand = [
        n * j * zs**2 * (zh - zp) / (zp**2 * (zs + zh)),
        n * m * r**2 - n * j * (zs + zp) * (zh - zp) / zp**2,
        n * j * (zs + zp) * zh**2 / (zp**2 * (zs + zh)),
    ]
    assert reflected_by_numpy("simple") == pytest.approx(hand, rel=1e-12)


@pytest.mark.parametrize("kind", list(GIVEN_K))
def test_k_set_with_reflected_planets_has_the_teeth_mass_matrix(kind: str) -> None:
    """The teeth set (pinions as bodies) and the same set given by k plus the reflected
    inertias its teeth imply give one mass matrix (2.34)."""
    values = reflected_by_numpy(kind)
    by_teeth = mass(description_text(kind))
    by_k = mass(k_reflected_text(kind, values))
    assert by_k == pytest.approx(by_teeth, rel=1e-12, abs=1e-15)
    # the representation is exact: a fourth motion needs no further fit
    w = hand_speeds(kind, -2.3, 0.9)
    reflected = 0.5 * (values[0] * w["S"] ** 2 + values[1] * w["T"] ** 2 + values[2] * w["H"] ** 2)
    assert reflected == pytest.approx(planet_energy(kind, -2.3, 0.9), rel=1e-12)


@pytest.mark.parametrize("kind", list(GIVEN_K))
def test_k_set_kinetic_energy_by_numpy(kind: str) -> None:
    """½ ẏᵀMẏ = ½ Σ (J_shaft + J_reflected) ω² with ω_H from the Willis relation (k only)."""
    values = np.array([2.0e-4, 1.1e-3, 7.0e-4])
    d = parse_description(k_reflected_text(kind, values), "k.toml")
    assert d.body_names == ("S", "T", "H")  # no planet bodies without teeth
    m = np.array(gearbox_dynamics(d).mass_matrix.evalf(), dtype=float)
    i0 = float(d.planetary_sets[0].given_k)
    rng = np.random.default_rng(7)
    for w_c, w_s in rng.normal(size=(3, 2)) * 50:
        w = {"S": w_s, "T": w_c, "H": (w_s - (1 - i0) * w_c) / i0}
        j = {
            "S": SHAFTS["S"] + values[0],
            "T": SHAFTS["T"] + values[1],
            "H": SHAFTS["H"] + values[2],
        }
        energy = sum(0.5 * j[b] * w[b] ** 2 for b in w)
        y_dot = np.array([w_c, w_s])  # coordinates ["T", "S"]
        assert 0.5 * y_dot @ m @ y_dot == pytest.approx(energy, rel=1e-12)


def test_mass_matrix_of_a_k_set_through_the_cli(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "k.toml"
    path.write_text(k_reflected_text("simple", reflected_by_numpy("simple")), encoding="utf-8")
    assert main(["show", str(path), "--what", "mass-matrix", "--symbolic-inertias"]) == 0
    out = capsys.readouterr().out
    assert "Jr_S_x" in out and "Jr_T_x" in out and "Jr_H_x" in out


def test_k_set_without_reflected_inertia_names_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "k.toml"
    path.write_text(k_text("simple", "-2.2"), encoding="utf-8")
    assert main(["show", str(path), "--what", "mass-matrix"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1 and "Traceback" not in err
    assert f'{path}: planetary_set[name="x"].k: ' in err and "planet_inertia_reflected" in err


GOOD = reflected_line(np.array([2.0e-4, 1.1e-3, 7.0e-4]))


@pytest.mark.parametrize(
    ("edit", "key", "words"),
    [
        # with teeth the planet bodies are derived
        (
            lambda t: description_text("simple").replace("z_sun = 30\n", "z_sun = 30\n" + GOOD),
            "planet_inertia_reflected",
            "only a set given by k",
        ),
        # the planets' mass is inside the reflected values: no double counting
        (
            lambda t: t.replace(
                "k = -2.2\n", 'k = -2.2\nplanet_mass = { value = 0.3, unit = "kg", source = "t" }\n'
            ),
            "planet_mass",
            "leave out",
        ),
        (lambda t: t.replace("ring = 0.0007, ", ""), "planet_inertia_reflected.ring", "missing"),
        (
            lambda t: t.replace('"kg*m^2", source = "test:', '"kg*mm^2", source = "test:'),
            "planet_inertia_reflected.unit",
            "kg*m^2",
        ),
        (
            lambda t: t.replace("ring = 0.0007, ", "ring = 0.0007, moon = 1.0, "),
            "planet_inertia_reflected.moon",
            "",
        ),
        # J_S < 0 with the carrier held: ½ J_S ω_S² + ½ J_H (ω_S/i0)² < 0
        (
            lambda t: t.replace("sun = 0.0002", "sun = -0.01"),
            "planet_inertia_reflected.carrier",
            "negative kinetic energy",
        ),
    ],
)
def test_bad_reflected_inertia_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], edit: object, key: str, words: str
) -> None:
    text = k_reflected_text("simple", np.array([2.0e-4, 1.1e-3, 7.0e-4]))
    assert "sun = 0.0002, carrier = 0.0011, ring = 0.0007, " in text
    path = tmp_path / "bad.toml"
    path.write_text(edit(text), encoding="utf-8")  # type: ignore[operator]
    assert main(["ratios", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1 and "Traceback" not in err
    assert f'{path}: planetary_set[name="x"].{key}: ' in err and words in err, err


def test_negative_entry_with_non_negative_energy_is_accepted() -> None:
    """J_T may be negative (for thin-rim planets n m r² − n J_p (z_S+z_P)²/z_P² < 0) while
    the energy stays positive: carrier held ½(J_S + J_H/i0²) ω_S², sun held etc."""
    text = k_reflected_text("simple", np.array([2.0e-4, -1.0e-5, 7.0e-4]))
    d = parse_description(text, "k.toml")
    assert dict(d.planetary_sets[0].reflected())["T"].value == -1.0e-5


def test_housing_member_has_no_entry() -> None:
    text = k_reflected_text("simple", np.array([2.0e-4, 1.1e-3, 7.0e-4]))
    fixed = text.replace('sun = "S"', 'sun = "housing"')
    with pytest.raises(GearsymError, match="housing"):
        parse_description(fixed, "k.toml")
    d = parse_description(fixed.replace("sun = 0.0002, ", ""), "k.toml")
    assert dict(d.planetary_sets[0].reflected()).keys() == {"T", "H"}
