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
    # the [estimator] table: what the TCU's filter assumes
    (
        "m_veh = { mean = 1950.0, sd = 300.0",
        "m_veh = { mean = 1950.0, sd = -300.0",
        "estimator.prior.m_veh.sd",
        "must be positive",
    ),
    (
        'zeta = { mean = 0.0, sd = 0.035, unit = "rad"',
        'zeta = { mean = 0.0, sd = 0.035, unit = "deg"',
        "estimator.prior.zeta.unit",
        "expected 'rad'",
    ),
    (
        "[estimator.prior]\nm_veh",
        "[estimator.prior]\nr_dyn = { sd = 0.01, unit = 'm', source = 'x' }\nm_veh",
        "estimator.prior.r_dyn",
        "unknown prior",
    ),
    (
        "[estimator.model_error]\nomega_1",
        "[estimator.model_error]\nomega_9 = { value = 1.0, unit = '1', source = 'x' }\nomega_1",
        "estimator.model_error.omega_9",
        "not a state of a filter's model",
    ),
    (
        "[estimator]\ntuned_on",
        "[estimator]\nmu_model = 'banana'\ntuned_on",
        "estimator.mu_model",
        "expected one of random_walk, map_scale",
    ),
    (
        "[estimator.prior]\nm_veh",
        "[estimator.prior]\nvalve_offset = { sd = 6.0e3, unit = 'bar', source = 'x' }\nm_veh",
        "estimator.prior.valve_offset.unit",
        "expected 'Pa'",
    ),
    (
        "[estimator.prior]\nm_veh",
        "[estimator.prior]\nfill_time_error = { sd = 0.03, unit = 'ms', source = 'x' }\nm_veh",
        "estimator.prior.fill_time_error.unit",
        "expected 's'",
    ),
    (
        "[estimator.random_walk]\nm_veh = { value = 1.0",
        "[estimator.random_walk]\nm_veh = { value = -1.0",
        "estimator.random_walk.m_veh.value",
        "must be finite and >= 0",
    ),
    # the [control] table: the shift control's calibration
    (
        'slip_k_p = { value = 400.0, unit = "Pa*s/rad"',
        'slip_k_p = { value = 400.0, unit = "Pa/rad"',
        "control.shift.slip_k_p.unit",
        "expected 'Pa*s/rad'",
    ),
    (
        "[control.adaptation]\nfill_step",
        "[control.adaptation]\nfill_stp = { value = 0.02, unit = 's', source = 'x' }\nfill_step",
        "control.adaptation.fill_stp",
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


def _set_keys(text: str, sets: dict[str, dict[str, int]]) -> str:
    """Write integer keys into the named [[planetary_set]] blocks of a description."""
    import re

    blocks = text.split("[[planetary_set]]")
    for i, block in enumerate(blocks[1:], start=1):
        name = re.search(r'^name = "(\w+)"', block, flags=re.M).group(1)
        for key, value in sets.get(name, {}).items():
            block = re.sub(rf"^{key} = .*$", f"{key} = {value}", block, flags=re.M)
        blocks[i] = block
    return "[[planetary_set]]".join(blocks)


def _strip_teeth(text: str, zeros: bool) -> str:
    """A description as written before the teeth are known: every tooth count removed (or 0
    as a placeholder), with planet counts and pinion data left out as well."""
    import re

    keys = r"z_\w+|planet_count|planet_mass|planet_inertia|carrier_radius|teeth_source"
    keys += r"|planet_(?:short|outer)_(?:mass|inertia|radius)|centre_distance_tolerance"
    if zeros:
        return re.sub(r"^(z_\w+) = \d+.*$", r"\1 = 0", text, flags=re.M)
    return re.sub(rf"^(?:{keys}) = .*$\n", "", text, flags=re.M)


@pytest.mark.parametrize("zeros", [False, True])
def test_fit_teeth_without_teeth_in_the_file(tmp_path, zeros):
    """The Simpson 3-speed with no teeth (or 0 placeholders): the search works from the ratio
    targets alone. Hand: 2nd (C1 + B1, sun held, ring in, carrier out) is 1 + 1/k_front =
    1.4545 (4 decimals), so k_front = z_ring/z_sun = 11/5; 1st (C1 + B2) then needs
    k_rear = 2: with the rear carrier held ω_sun = −k_r ω_out, and the front set
    ω_sun + k_f ω_in = (1 + k_f) ω_out gives ω_in/ω_out = (1 + k_f + k_r)/k_f = 26/11."""
    text = _strip_teeth((DATA / "simpson_3speed.toml").read_text(), zeros)
    assert "z_sun = 30" not in text
    path = tmp_path / "no_teeth.toml"
    path.write_text(text)
    # The description is unusable without teeth everywhere else (one line, exit 2) ...
    assert gearsym("ratios", str(path)).returncode == 2
    # ... but fit-teeth searches it: 3, 4 or 5 planets where the file gives no count.
    result = gearsym("fit-teeth", str(path), "--json", "--top", "3")
    assert result.returncode == 0, result.stderr
    best = json.loads(result.stdout)[0]
    front, rear = best["sets"]["front"], best["sets"]["rear"]
    assert front["z_ring"] * 5 == front["z_sun"] * 11
    assert rear["z_ring"] == 2 * rear["z_sun"]
    for teeth in (front, rear):
        assert teeth["z_ring"] == teeth["z_sun"] + 2 * teeth["z_planet"]
        assert (teeth["z_sun"] + teeth["z_ring"]) % teeth["planet_count"] == 0
        assert teeth["planet_count"] in (3, 4, 5)
    assert round(best["ratios"]["1"], 4) == 2.3636 and round(best["ratios"]["2"], 4) == 1.4545


def test_fit_teeth_without_teeth_finds_a_ravigneaux_set(tmp_path):
    """The 6HP26 example with every tooth count removed: the Ravigneaux set's two stationary
    ratios come back as the published 85/38 and 85/31 (tests/test_examples.py shows by a
    brute force independent of gearsym that these are the only ones in a wide range), with
    teeth that are buildable without profile shift (the file re-parses with them)."""
    example = Path(__file__).parents[1] / "gearsym/data/examples/lepelletier_6speed.toml"
    original = example.read_text()
    path = tmp_path / "lep.toml"
    path.write_text(_strip_teeth(original, zeros=True).replace("centre_distance_tolerance", "#"))
    result = gearsym("fit-teeth", str(path), "--json")
    assert result.returncode == 0, result.stderr
    best = json.loads(result.stdout)[0]
    rav = best["sets"]["rav"]
    assert rav["z_ring"] * 38 == rav["z_sun"] * 85
    assert rav["z_ring"] * 31 == rav["z_sun_short"] * 85
    simple = best["sets"]["1"]
    assert simple["z_ring"] * 37 == simple["z_sun"] * 71
    # the proposed teeth pass the description's own buildability checks
    refit = _set_keys(original.replace("centre_distance_tolerance = 0.5", ""), best["sets"])
    (tmp_path / "refit.toml").write_text(refit)
    assert gearsym("ratios", str(tmp_path / "refit.toml")).returncode == 0


def test_fit_teeth_empty_search_space_is_one_line(tmp_path):
    """No buildable set in the ranges: one line naming the file and the set, exit 2."""
    path = tmp_path / "no_teeth.toml"
    path.write_text(_strip_teeth((DATA / "simpson_3speed.toml").read_text(), zeros=False))
    result = gearsym(
        "fit-teeth", str(path), "--sun", "17:17", "--planet", "13:13", "--ring-max", "40"
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert str(path) in lines[0] and 'planetary_set[name="front"]' in lines[0]
    assert "search space is empty" in lines[0]


@pytest.mark.parametrize("kind", ["double_pinion", "ravigneaux", "ravigneaux_two_rings"])
def test_fit_teeth_proposals_pass_the_description_checks(tmp_path, kind):
    """A one-set description of each compound kind (docs/set_kinds/) with its teeth zeroed:
    the best proposal, written back into the file, passes the parser's own buildability
    checks (triangles, clearances, spacing; no profile shift) and `gearsym ratios`."""
    sketch = Path(__file__).parents[1] / "docs" / "set_kinds" / f"{kind}.toml"
    original = sketch.read_text().replace("centre_distance_tolerance = 0.5", "")
    path = tmp_path / "zero.toml"
    path.write_text(_strip_teeth(original, zeros=True))
    result = gearsym("fit-teeth", str(path), "--json", "--top", "1")
    assert result.returncode == 0, result.stderr
    (best,) = json.loads(result.stdout)
    refit = tmp_path / "refit.toml"
    refit.write_text(_set_keys(original, best["sets"]))
    checked = gearsym("ratios", str(refit))
    assert checked.returncode == 0, checked.stdout + checked.stderr
