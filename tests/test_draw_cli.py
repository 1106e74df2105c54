"""``gearsym draw``: files written through the one writer, deterministic bytes, one-line errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.output_dir import OutputFile, sign_file, signed_by_gearsym

DATA = Path(__file__).parent / "data"


def gearsym(*args: str, seed: str = "0") -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONHASHSEED": seed}
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
    )


def test_speed_plan_svg_is_valid_signed_and_byte_identical_across_runs(tmp_path):
    first, second = tmp_path / "one" / "plan.svg", tmp_path / "two" / "plan.svg"
    a = gearsym("draw", "--what", "speeds", "--gear", "2", "--out", str(first), seed="1")
    b = gearsym("draw", "--what", "speeds", "--gear", "2", "--out", str(second), seed="4242")
    assert a.returncode == 0 and b.returncode == 0, a.stderr + b.stderr
    assert first.read_bytes() == second.read_bytes()
    root = ET.fromstring(first.read_bytes())  # the trailing signature is a legal XML comment
    assert root.tag.endswith("svg")
    assert signed_by_gearsym(first.read_bytes(), ".svg")
    assert b"<dc:date>" not in first.read_bytes()
    # the same command again refreshes its own picture
    again = gearsym("draw", "--what", "speeds", "--gear", "2", "--out", str(first))
    assert again.returncode == 0, again.stderr


@pytest.mark.parametrize("what", ["stick", "lever", "speeds", "drivetrain"])
def test_every_picture_renders_as_png(tmp_path, what):
    from PIL import Image

    out = tmp_path / f"{what}.png"
    result = gearsym("draw", str(DATA / "simpson_3speed.toml"), "--what", what, "--out", str(out))
    assert result.returncode == 0, result.stderr
    with Image.open(out) as image:
        image.load()
        assert image.width > 200 and image.height > 100
    assert signed_by_gearsym(out.read_bytes(), ".png")


def test_json_gives_the_lever_geometry_without_a_file(tmp_path):
    result = gearsym("draw", str(DATA / "simpson_3speed.toml"), "--what", "speeds", "--json")
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    # hand derivation in tests/test_drawing.py: sun 0, carrier_r 44, out 66, ring_f 96
    nodes = data["levers"][0]["nodes"]
    assert [(n["shaft"], n["position"]) for n in nodes] == [
        ("sun", 0.0),
        ("carrier_r", 44.0),
        ("out", 66.0),
        ("ring_f", 96.0),
    ]
    gears = {g["gear"]: g for g in data["gears"]}
    assert gears["1"]["ratio"] == pytest.approx(26 / 11)
    assert gears["R"]["speeds"]["out"] == -0.5


@pytest.mark.parametrize(
    ("args", "key", "words"),
    [
        (("--what", "speeds", "--gear", "10"), "--gear", "unknown gear '10'"),
        (("--what", "wiring"), "--what", "unknown picture 'wiring'"),
        (("--what", "lever", "--gear", "2"), "--gear", "only with --what speeds"),
        (("--what", "lever", "--out", "NEW/x.pdf"), "--out", "unsupported file type '.pdf'"),
        (("--what", "lever", "--out", "NEW/x"), "--out", "unsupported file type '(none)'"),
        (("--what", "lever"), "--out", "required"),
    ],
)
def test_bad_options_are_one_line_exit_2_and_write_nothing(tmp_path, args, key, words):
    args = tuple(a.replace("NEW", str(tmp_path / "new")) for a in args)
    if "--out" not in args and "--gear" in args and args[1] == "speeds":
        args += ("--out", str(tmp_path / "new" / "plan.svg"))
    result = gearsym("draw", *args)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert key in lines[0] and words in lines[0], lines[0]
    assert not (tmp_path / "new").exists()
    assert result.stdout == ""


def test_a_users_file_and_an_edited_picture_are_not_replaced(tmp_path):
    mine = tmp_path / "mine.svg"
    mine.write_text("<svg/>")
    result = gearsym("draw", "--what", "lever", "--out", str(mine))
    assert result.returncode == 2 and "not written by gearsym" in result.stderr
    assert mine.read_text() == "<svg/>"
    ours = tmp_path / "ours.png"
    assert gearsym("draw", "--what", "drivetrain", "--out", str(ours)).returncode == 0
    edited = ours.read_bytes()[:-20] + b"\0" + ours.read_bytes()[-19:]
    ours.write_bytes(edited)
    result = gearsym("draw", "--what", "drivetrain", "--out", str(ours))
    assert result.returncode == 2 and "changed since" in result.stderr
    assert ours.read_bytes() == edited
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.svg", "ours.png"]  # no leftovers


def test_signatures_detect_any_change():
    svg = b'<svg xmlns="http://www.w3.org/2000/svg"/>\n'
    signed = sign_file(svg, ".svg", "draw")
    assert signed.startswith(svg) and signed_by_gearsym(signed, ".svg")
    assert not signed_by_gearsym(signed.replace(b'"/>', b'" />'), ".svg")
    assert not signed_by_gearsym(svg, ".svg")
    assert not signed_by_gearsym(signed, ".png")


def test_output_file_refuses_a_directory_and_writes_atomically(tmp_path):
    (tmp_path / "d.svg").mkdir()
    with pytest.raises(GearsymError) as err:
        with OutputFile(tmp_path / "d.svg", "draw") as out:
            out.commit(b"<svg/>")
    assert "not a plain file" in str(err.value)
    with OutputFile(tmp_path / "x" / "p.svg", "draw") as out:
        path = out.commit(b"<svg/>\n")
    assert signed_by_gearsym(path.read_bytes(), ".svg")
    assert sorted(p.name for p in path.parent.iterdir()) == ["p.svg"]  # lock and temp gone


def test_help_does_not_import_matplotlib():
    code = (
        "import sys; from gearsym import cli; cli.build_parser(); "
        "print('matplotlib' in sys.modules, 'gearsym.validation.drawing.geometry' in sys.modules)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.stdout.split() == ["False", "False"], result.stderr


def test_the_readme_picture_is_what_the_command_draws(tmp_path):
    committed = Path(__file__).resolve().parents[1] / "docs" / "speed_plan_gear_2.svg"
    fresh = tmp_path / "plan.svg"
    result = gearsym("draw", "--what", "speeds", "--gear", "2", "--out", str(fresh))
    assert result.returncode == 0, result.stderr
    assert fresh.read_bytes() == committed.read_bytes(), (
        "regenerate: gearsym draw --what speeds --gear 2 --out docs/speed_plan_gear_2.svg"
    )
