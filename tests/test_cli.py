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


# ----------------------------------------------------------------------------- the command set


def _subcommands() -> dict:
    import argparse

    from gearsym.cli import build_parser

    parser = build_parser()
    (action,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {"": parser, **action.choices}


def test_every_command_module_registers_through_the_one_protocol():
    """Each ``gearsym/cmd_*.py`` is in the CLI's loop and has ``register(subparsers, common)``
    (a new command module that is not listed would silently have no commands)."""
    import inspect

    from gearsym import cli

    files = sorted(p.stem for p in (Path(cli.__file__).parent).glob("cmd_*.py"))
    assert sorted(m.__name__.rsplit(".", 1)[1] for m in cli.COMMAND_MODULES) == files
    for module in cli.COMMAND_MODULES:
        assert list(inspect.signature(module.register).parameters) == ["subparsers", "common"]


def test_every_subcommand_has_a_handler_and_is_listed_in_help():
    commands = _subcommands()
    top = commands.pop("")
    listed = top.format_help()
    assert len(commands) >= 11
    for name, sub in commands.items():
        assert callable(sub.get_default("func")), f"{name}: no handler (set_defaults(func=...))"
        assert f"    {name} " in listed or f"    {name}\n" in listed, f"{name} not in --help"
        assert sub.format_help().startswith(f"usage: gearsym {name}")


HEAVY = ("numpy", "scipy", "casadi", "matplotlib", "symengine", "jinja2")


@pytest.mark.parametrize(
    ("argv", "forbidden"),
    [
        # building the parser imports no numeric library at all, not even SymPy
        (["--help"], ("sympy", *HEAVY)),
        (["ratios", "--help"], ("sympy", *HEAVY)),
        # the gear table needs SymPy (exact ratios) and nothing else
        (["ratios"], HEAVY),
        (["default-config"], ("sympy", *HEAVY)),
    ],
)
def test_light_commands_import_no_heavy_module(argv, forbidden):
    """Start-up time: every command module is imported to build the parser, so each keeps its
    heavy imports inside its handlers (README start-up row, benchmarks/bench_cli_startup.py)."""
    code = (
        "import contextlib, io, sys\n"
        "from gearsym.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    try:\n"
        f"        main({argv!r})\n"
        "    except SystemExit:\n"
        "        pass\n"
        f"print(sorted(m for m in {forbidden!r} if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.strip() == "[]", f"gearsym {' '.join(argv)} imports {out.stdout.strip()}"


def test_fit_teeth_hints_at_planet_counts_and_lists_alternatives_once():
    # nothing in a too narrow sun range: with the file's planet counts the hint names the option
    result = gearsym("fit-teeth", "--sun", "17:18")
    assert result.returncode == 1
    assert "try --planet-count 3,4,5" in result.stdout
    result = gearsym("fit-teeth", "--sun", "17:18", "--planet-count", "3,4")
    assert result.returncode == 1 and "--planet-count" not in result.stdout
    # alternatives carry their planet count and appear once (k = 49/23 of set 1: 46/26/98 ×4)
    result = gearsym("fit-teeth", "--top", "1")
    assert result.returncode == 0, result.stderr
    line = next(x for x in result.stdout.splitlines() if x.strip().startswith("set 1"))
    alternatives = line.split("same k: ")[1].rstrip(")").split(", ")
    assert "46/26/98×4" in alternatives and len(alternatives) == len(set(alternatives))
