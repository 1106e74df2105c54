"""The command line: outputs, and one-line errors with exit code 2 for bad descriptions."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from gearsym.symbolic.description import default_config_text

DATA = Path(__file__).parent / "data"


def gearsym(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, timeout=120
    )


def test_ratios_json_is_gear_to_ratio_with_null_for_neutral():
    result = gearsym("ratios", "--json")
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data["N"] is None
    assert round(data["2"], 3) == 3.243 and round(data["R"], 3) == -4.798


def test_default_config_round_trips(tmp_path):
    result = gearsym("default-config")
    assert result.returncode == 0
    path = tmp_path / "copy.toml"
    path.write_text(result.stdout)
    assert gearsym("ratios", str(path)).returncode == 0


def test_show_mass_matrix_json_and_latex():
    result = gearsym("show", "--what", "mass-matrix", "--format", "json", "--symbolic-inertias")
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    m = data["items"]["M"]
    assert m["shape"] == [4, 4] and "J_1" in m["entries"][0][0]
    assert data["coordinates"] == ["phi_1", "phi_2", "phi_3", "phi_8"]
    latex = gearsym("show", "--what", "input-matrix", "--format", "latex")
    assert latex.returncode == 0 and "\\left[" in latex.stdout


def test_fit_teeth_json_on_second_gearbox():
    result = gearsym("fit-teeth", str(DATA / "simpson_3speed.toml"), "--json", "--top", "2")
    assert result.returncode == 0, result.stderr
    best = json.loads(result.stdout)[0]
    assert best["sets"]["front"]["z_ring"] * 5 == best["sets"]["front"]["z_sun"] * 11
    assert best["max_error"] <= 5e-5


BAD_CASES = [
    # (replace this, with that, expected key in the message, expected words in the reason)
    ('sun = "1"\ncarrier = "8"', 'sun = "99"\ncarrier = "8"', 'planetary_set[name="1"].sun', "99"),
    ('name = "2"\ninertia', 'name = "1"\ninertia', 'shaft[name="1"]', "used twice"),
    ("z_sun = 46", "z_sun = 46.5", 'planetary_set[name="1"].z_sun', "integer"),
    ("z_planet = 26\nz_ring = 98", "z_planet = 0\nz_ring = 98", "z_planet", "positive"),
    ("z_ring = 98", "z_ring = 97", 'planetary_set[name="1"].z_ring', "z_sun + 2 z_planet"),
    (
        "z_ring = 98\nplanet_count = 4",
        "z_ring = 98\nplanet_count = 5",
        'planetary_set[name="1"].planet_count',
        "equally spaced",
    ),
    ('name = "K81"', 'name = "K-81"', "shift_element[0].name", "C identifier"),
    (
        'closed = ["B05", "K38", "B06"]',
        'closed = ["B05", "K38"]',
        'gear[name="1"].closed',
        "leaves 2 degrees of freedom",
    ),
    (
        'closed = ["B05", "K38", "B06"]',
        'closed = ["B05", "K38", "B06", "K81"]',
        'gear[name="1"].closed',
        "locks the gearbox",
    ),
    (
        'closed = ["B05", "K38", "B06"]',
        'closed = ["B05", "K39", "B06"]',
        'gear[name="1"].closed',
        "unknown shift element 'K39'",
    ),
    ("[gearbox]\nname", "[gearbox\nname", "line", "malformed TOML"),
    (
        'inertia = { value = 0.02, unit = "kg*m^2"',
        'inertia = { value = 0.02, unit = "g*cm^2"',
        'shaft[name="1"].inertia.unit',
        "expected 'kg*m^2'",
    ),
    (
        "planet_count = 4\nteeth_source",
        "planet_cont = 4\nteeth_source",
        'planetary_set[name="1"].planet_count',
        "missing required key (is 'planet_cont' a misspelling?)",
    ),
    (
        'input_shaft = "1"',
        'input_shaft = "1"\noutput_shft = "2"',
        "gearbox.output_shft",
        "unknown key",
    ),
]


@pytest.mark.parametrize(("old", "new", "key", "reason"), BAD_CASES)
def test_bad_description_gives_one_line_error(tmp_path, old, new, key, reason):
    text = default_config_text()
    assert old in text, f"test setup: {old!r} not in the default description"
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    result = gearsym("ratios", str(path))
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    assert str(path) in lines[0] and key in lines[0] and reason in lines[0], lines[0]


def test_missing_file_gives_one_line_error(tmp_path):
    result = gearsym("ratios", str(tmp_path / "nope.toml"))
    assert result.returncode == 2
    assert result.stderr.strip() == f"gearsym: {tmp_path / 'nope.toml'}: no such file"


def test_malformed_toml_names_line_and_column(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[gearbox]\nname = \n")
    result = gearsym("ratios", str(path))
    assert result.returncode == 2
    assert "line 2, column 8" in result.stderr
