"""Hostile input: every bad name, number, file and option is one line and exit code 2.

The error contract: ``gearsym: <file>: <key>: <reason>`` on stderr, exit code 2, no traceback,
nothing on stdout and no output written. The CLI runs in-process (``gearsym.cli.main``) so
that these tests stay fast; every case fails before any model is derived.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from gearsym.symbolic import naming
from gearsym.symbolic.codegen import build_function_table
from gearsym.symbolic.description import (
    PLANET_COUNT_MAX,
    RATIO_DECIMALS_MAX,
    TEETH_MAX,
    default_config_text,
)
from gearsym.symbolic.io.input_files import MAX_INPUT_BYTES
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.model import Model, Variable
from gearsym.validation.sim.scenario import POINTS_MAX, T_END_MAX, default_scenario_path

from gearsym.cli import main

DESCRIPTION = default_config_text()
SCENARIO = default_scenario_path().read_text(encoding="utf-8")


def one_line_error(
    capsys: pytest.CaptureFixture[str], code: int | None, file: str, key: str
) -> str:
    """Assert the error contract and return the reason."""
    out, err = capsys.readouterr()
    assert code == 2, err
    assert out == ""
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1, err
    prefix = f"gearsym: {file}: {key}: " if key else f"gearsym: {file}: "
    assert lines[0].startswith(prefix), lines[0]
    return lines[0][len(prefix) :]


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> str:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return str(path)


def edited(old: str, new: str, text: str = DESCRIPTION, count: int = -1) -> str:
    assert old in text, f"test setup: {old!r} not in the text"
    return text.replace(old, new, count)


def ratios(capsys: pytest.CaptureFixture[str], path: str, key: str) -> str:
    return one_line_error(capsys, main(["ratios", path]), path, key)


# ---------------------------------------------------------------------------------------------
# 1. Names
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", ["K81\n", "K__81", "_K81", "K81_", "K-81", "K" * 32])
def test_names_are_letters_and_digits_joined_by_single_underscores(tmp_path, capsys, bad):
    # "K81\n" passed re.match with "$"; "__" separates generated names (S_<x>__<p>).
    path = write(tmp_path, edited('name = "K81"', f"name = {json.dumps(bad)}", count=1))
    reason = ratios(capsys, path, "shift_element[0].name")
    assert "not usable in a C identifier" in reason


# (rename this quoted name everywhere, to that; the two names that collide; the entry reported)
COLLISIONS = [
    ('"K81"', '"In"', "T_In", "input torque", 'shift_element[name="In"].name'),
    ('"K81"', '"Out"', "T_Out", "gearbox output torque", 'shift_element[name="Out"].name'),
    ('"K81"', '"out"', "T_out", "output torque", 'shift_element[name="out"].name'),
    ('"K81"', '"res"', "T_res", "road resistance torque column", 'shift_element[name="res"].name'),
    ('"K81"', '"ss"', "T_ss", "side-shaft torque column", 'shift_element[name="ss"].name'),
    ('"K81"', '"engine"', "T_engine", "engine torque column", 'shift_element[name="engine"].name'),
    (
        '"K81"',
        '"e_machine"',
        "T_e_machine",
        "e-machine torque column",
        'shift_element[name="e_machine"].name',
    ),
    ('"8"', '"C"', "omega_C", "wheel speed", 'shaft[name="C"].name'),
    ('planet = "9"', 'planet = "C"', "omega_C", "wheel speed", 'planetary_set[name="1"].planet'),
    # set "ss": its stationary ratio k_<set> is the side-shaft stiffness k_ss
    (
        'name = "1"\nsun',
        'name = "ss"\nsun',
        "k_ss",
        "drivetrain parameter k_ss",
        'planetary_set[name="ss"].name',
    ),
    # element "S_1": its bristle state z_<element> is the sun teeth z_S_<set> of set "1"
    ('"K81"', '"S_1"', "z_S_1", "sun teeth of set '1'", 'shift_element[name="S_1"].name'),
    # element "38" and K38 (short name 38): mu_38 and F_N38 twice, e.g. two CSV columns in one
    ('"K81"', '"38"', "mu_38", "shift element '38'", 'shift_element[name="K38"].name'),
]


@pytest.mark.parametrize(("old", "new", "name", "other", "key"), COLLISIONS)
def test_names_that_collide_with_generated_names(tmp_path, capsys, old, new, name, other, key):
    path = write(tmp_path, edited(old, new))
    reason = ratios(capsys, path, key)
    assert f"'{name}'" in reason and other in reason, reason


def test_names_differing_only_in_case_collide(tmp_path, capsys):
    # shaft "c": omega_c and the wheel speed omega_C differ only in case
    path = write(tmp_path, edited('"8"', '"c"'))
    reason = ratios(capsys, path, 'shaft[name="c"].name')
    assert "'omega_c'" in reason and "differs only in case from 'omega_C'" in reason
    # two elements k38 and K38, two gears n and N: one name, as far as case goes
    path = write(tmp_path, edited('"K81"', '"k38"'))
    assert "used twice (as 'k38'" in ratios(capsys, path, 'shift_element[name="K38"]')
    neutral = '[[gear]]\nname = "n"\nclosed = ["B05", "B06"]\nneutral = true\n'
    path = write(tmp_path, edited('[[gear]]\nname = "N"', neutral + '[[gear]]\nname = "N"'))
    assert "used twice (as 'n'" in ratios(capsys, path, 'gear[name="N"]')


def _with_gears(*gears: tuple[str, str, float]) -> str:
    """The built-in description with extra gears (name, closed list as TOML, ratio)."""
    extra = "".join(f'[[gear]]\nname = "{n}"\nclosed = {c}\nratio = {r}\n' for n, c, r in gears)
    return edited('[[gear]]\nname = "N"', extra + '[[gear]]\nname = "N"')


def test_gear_names_that_make_one_model_name_twice(tmp_path, capsys):
    # 1 (B05 K38 B06) -> 2 (K81 K38 B06) is a single swap, so is 1_2 -> mu with the same
    # elements: shift_<1>_<2> + "_mu" and shift_<1_2>_<mu> are both shift_1_2_mu.
    text = _with_gears(
        ("1_2", '["B05", "K38", "B06"]', 5.354), ("mu", '["K81", "K38", "B06"]', 3.243)
    )
    reason = ratios(capsys, write(tmp_path, text), 'gear[name="mu"].name')
    assert "'shift_1_2_mu'" in reason and "shift 1_2-mu" in reason and "shift 1-2" in reason


def test_gear_names_whose_model_names_differ_only_in_case(tmp_path, capsys):
    # 1 -> a_b and 1_A -> b (closed as gears 1 and 2): shift_1_a_b and shift_1_A_b, one file
    # on a case-insensitive file system and one include guard GEARSYM_SHIFT_1_A_B_H
    text = _with_gears(
        ("a_b", '["K81", "K38", "B06"]', 3.243),
        ("1_A", '["B05", "K38", "B06"]', 5.354),
        ("b", '["K81", "K38", "B06"]', 3.243),
    )
    reason = ratios(capsys, write(tmp_path, text), 'gear[name="b"].name')
    assert "model name 'shift_1_A_b'" in reason
    assert "differs only in case from 'shift_1_a_b'" in reason


@pytest.mark.parametrize(
    "name", ["int", "_Bool", "_Alignas", "_Static_assert", "__x", "_X", "sinf", "NAN", "lambda"]
)
def test_c_keywords_and_reserved_identifiers_are_refused(name):
    assert naming.c_identifier_problem(name) is not None
    # the emitter shares the list: a model variable of that name is refused there too
    import sympy as sp

    x = sp.Symbol("x")
    parameter = Variable(name, sp.Symbol(name))
    bad = Model("m", (Variable("x", x),), (), (parameter,), (), sp.Matrix([x]), sp.zeros(0, 1))
    with pytest.raises(ValueError, match=name):
        build_function_table(bad)


@pytest.mark.parametrize("name", ["omega_1", "T_K38", "mu_38", "z_S_1"])
def test_ordinary_identifiers_pass(name):
    assert naming.c_identifier_problem(name) is None


def test_shipped_descriptions_pass_the_name_check():
    data = Path(__file__).parent / "data"
    for path in (None, data / "simpson_3speed.toml", data / "thesis_9speed_alt_teeth.toml"):
        load_description(path)


# ---------------------------------------------------------------------------------------------
# 2. Numbers and files that used to end in a traceback
# ---------------------------------------------------------------------------------------------


def test_huge_tooth_counts(tmp_path, capsys):
    big = 10**400  # z_ring = z_sun + 2 z_planet still holds: only the limit stops it
    teeth = f"z_sun = {big}\nz_planet = 26\nz_ring = {big + 52}"
    text = edited("z_sun = 46\nz_planet = 26\nz_ring = 98", teeth)
    reason = ratios(capsys, write(tmp_path, text), 'planetary_set[name="1"].z_sun')
    assert f"at most {TEETH_MAX}" in reason and len(reason) < 200


def test_planet_count_limit(tmp_path, capsys):
    text = edited("planet_count = 4", f"planet_count = {PLANET_COUNT_MAX + 1}", count=1)
    reason = ratios(capsys, write(tmp_path, text), 'planetary_set[name="1"].planet_count')
    assert f"at most {PLANET_COUNT_MAX}" in reason


def test_deeply_nested_toml(tmp_path, capsys):
    text = DESCRIPTION + "deep = " + "[" * 5000 + "]" * 5000 + "\n"
    assert "nested too deeply" in ratios(capsys, write(tmp_path, text), "TOML")


@pytest.mark.parametrize("decimals", [-1, RATIO_DECIMALS_MAX + 1, 1000000000])
def test_ratio_decimals_limit(tmp_path, capsys, decimals):
    text = edited("ratio_decimals = 3", f"ratio_decimals = {decimals}")
    reason = ratios(capsys, write(tmp_path, text), "gear_table.ratio_decimals")
    assert f"0 to {RATIO_DECIMALS_MAX}" in reason


@pytest.mark.parametrize("value", ["inf", "-inf", "nan"])
def test_non_finite_numbers_in_a_description(tmp_path, capsys, value):
    text = edited("ratio = 3.243", f"ratio = {value}")
    assert "finite" in ratios(capsys, write(tmp_path, text), 'gear[name="2"].ratio')


def test_generate_with_one_forward_gear(tmp_path, capsys):
    from tests.test_in_gear_model_error import without_shift_tables

    start = DESCRIPTION.index('[[gear]]\nname = "2"')
    text = DESCRIPTION[:start] + DESCRIPTION[DESCRIPTION.index('[[gear]]\nname = "N"') :]
    # the estimator's per-shift entries name gears this gearbox no longer has (refused on
    # their own, tests/test_in_gear_model_error.py): gone with them
    text = without_shift_tables(text)
    path, out = write(tmp_path, text), tmp_path / "out"
    code = main(["generate", path, "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == 2 and "Traceback" not in err
    # cmd_generate prints a progress line first ("  … generating code for …")
    errors = [line for line in err.splitlines() if line.startswith("gearsym: ")]
    assert len(errors) == 1 and errors[0].startswith(f"gearsym: {path}: gear: "), err
    assert "two forward gears" in errors[0]
    assert not out.exists()


def simulate(capsys: pytest.CaptureFixture[str], tmp_path: Path, scenario: str, key: str) -> str:
    path, out = write(tmp_path, scenario, "scenario.toml"), tmp_path / "out"
    code = main(["simulate", "--scenario", path, "--out", str(out)])
    reason = one_line_error(capsys, code, path, key)
    assert not out.exists()
    return reason


@pytest.mark.parametrize("t_end", ["1e9", "300", f"{T_END_MAX + 0.001}", "inf", "nan"])
def test_scenario_duration_limit(tmp_path, capsys, t_end):
    text = edited("t_end = 1.5", f"t_end = {t_end}", SCENARIO)
    reason = simulate(capsys, tmp_path, text, "scenario.t_end")
    assert f"at most {T_END_MAX:g}" in reason or "finite" in reason


@pytest.mark.parametrize("speed", ["inf", "nan", "-inf"])
def test_scenario_speed_must_be_finite(tmp_path, capsys, speed):
    text = edited("value = 8.0", f"value = {speed}", SCENARIO)
    reason = simulate(capsys, tmp_path, text, "scenario.vehicle_speed.value")
    assert "finite" in reason


def test_scenario_profile_length_limit(tmp_path, capsys):
    times = ", ".join(str(0.001 * k) for k in range(POINTS_MAX + 1))
    values = ", ".join(["1.5e6"] * (POINTS_MAX + 1))
    profile = f"time = [{times}]\nvalue = [{values}]"
    text = edited("time = [0.0]\nvalue = [1.5e6]", profile, SCENARIO, count=1)
    reason = simulate(capsys, tmp_path, text, "pressure.K81.time")
    assert f"at most {POINTS_MAX}" in reason


@pytest.mark.parametrize(
    ("old", "new", "key", "suggestion"),
    [
        ("value = [1.5e6]\n", "value = [1.5e6]\nvlaue = [0.0]\n", "pressure.K81.vlaue", "value"),
        ('unit = "m/s",', 'unit = "m/s", sorce = "x",', "scenario.vehicle_speed.sorce", "source"),
        ("t_end = 1.5", "t_end = 1.5\nt_ned = 2.0", "scenario.t_ned", "t_end"),
        ("[input_torque]", "[input_torqe]", "input_torqe", "input_torque"),
        ('unit = "N*m"', 'unit = "N*m"\nengin = [0.0]', "input_torque.engin", "engine"),
    ],
)
def test_unknown_scenario_keys_are_refused_with_a_suggestion(
    tmp_path, capsys, old, new, key, suggestion
):
    reason = simulate(capsys, tmp_path, edited(old, new, SCENARIO, count=1), key)
    assert reason.startswith("unknown") and f"did you mean {suggestion!r}" in reason


def test_files_that_are_not_utf8(tmp_path, capsys):
    path = tmp_path / "latin1.toml"
    path.write_bytes(DESCRIPTION.encode().replace(b"assumed", b"assum\xe9d", 1))  # é in Latin-1
    at = DESCRIPTION.index("assumed") + len("assum")
    line = DESCRIPTION[:at].count("\n") + 1
    column = at - (DESCRIPTION.rfind("\n", 0, at) + 1) + 1  # in characters
    reason = ratios(capsys, str(path), f"line {line}, column {column}")
    assert "not UTF-8" in reason
    scenario = tmp_path / "scenario.toml"
    scenario.write_bytes(b"\xff\xfe[scenario]\n")
    out = tmp_path / "out"
    code = main(["simulate", "--scenario", str(scenario), "--out", str(out)])
    assert "not UTF-8" in one_line_error(capsys, code, str(scenario), "line 1, column 1")


def test_a_folder_is_no_file(tmp_path, capsys):
    assert "is a folder" in ratios(capsys, str(tmp_path), "")
    code = main(["simulate", "--scenario", str(tmp_path), "--out", str(tmp_path / "out")])
    assert "is a folder" in one_line_error(capsys, code, str(tmp_path), "")


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero")
def test_a_device_is_no_file(capsys):
    # /dev/zero used to be read forever
    assert "not a regular file" in ratios(capsys, "/dev/zero", "")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs")
def test_a_pipe_is_no_file(tmp_path, capsys):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)  # opening it for reading must not wait for a writer
    assert "not a regular file" in ratios(capsys, str(fifo), "")


def test_file_size_limit(tmp_path, capsys):
    padding = "#" * 99 + "\n"
    text = DESCRIPTION + padding * (MAX_INPUT_BYTES // len(padding) + 1)
    assert len(text.encode()) > MAX_INPUT_BYTES
    assert "larger than" in ratios(capsys, write(tmp_path, text), "")


# ---------------------------------------------------------------------------------------------
# 3. Command-line options
# ---------------------------------------------------------------------------------------------


def test_ratios_json_exits_1_on_a_mismatch_and_keeps_its_shape(tmp_path, capsys):
    path = write(tmp_path, edited("ratio = 3.243", "ratio = 3.244"))
    assert main(["ratios", path]) == 1  # text mode, as before
    capsys.readouterr()
    assert main(["ratios", "--json", path]) == 1
    out, err = capsys.readouterr()
    data = json.loads(out)
    assert data["N"] is None and round(data["2"], 3) == 3.243  # {gear: ratio or null}
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'gearsym: {path}: gear[name="2"].ratio: ')
    assert "3.244" in lines[0] and "3.243" in lines[0]


def test_ratios_json_exits_0_when_everything_matches(capsys):
    assert main(["ratios", "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["N"] is None and err == ""


BAD_OPTIONS = [
    ("fit-teeth", "--top", "0"),
    ("fit-teeth", "--top", "-3"),
    ("fit-teeth", "--top", "1.5"),
    ("fit-teeth", "--tolerance", "nan"),
    ("fit-teeth", "--tolerance", "inf"),
    ("fit-teeth", "--tolerance", "-1e-3"),
    ("fit-teeth", "--tolerance", "0"),
    ("fit-teeth", "--ring-max", "0"),
    ("fit-teeth", "--ring-max", str(TEETH_MAX + 1)),
    ("fit-teeth", "--sun", f"17:{TEETH_MAX + 1}"),
    ("fit-teeth", "--planet-count", f"3,{PLANET_COUNT_MAX + 1}"),
    ("fim", "--sample-time", "0"),
    ("fim", "--sample-time", "1e-12"),  # finer than the simulated record
    ("fim", "--sample-time", "nan"),
    ("fim", "--speed-error", "-0.01"),
    ("fim", "--speed-error", "inf"),
    ("fim", "--acceleration-error", "0"),
    ("fim", "--gamma-max", "nan"),
    ("observability", "--max-order", "1.5"),  # -1: see tests/test_cli_observability.py
    ("observability", "--time-budget", "0"),
    ("observability", "--time-budget", "inf"),
    ("observability", "--size-budget", "0"),
    ("observability", "--seed", "nan"),
    ("generate", "--points", "nan"),
]


@pytest.mark.parametrize(("command", "option", "value"), BAD_OPTIONS)
def test_numeric_options_refuse_meaningless_values(capsys, command, option, value):
    extra = ["--out", "unused"] if command == "generate" else []
    with pytest.raises(SystemExit) as exit_info:
        main([command, *extra, option, value])
    out, err = capsys.readouterr()
    assert exit_info.value.code == 2 and out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"gearsym: {command}: argument {option}"), lines[0]


def test_set_values_must_be_finite(capsys):
    code = main(["fim", "--set", "zeta=nan"])
    reason = one_line_error(capsys, code, "<built-in thesis_9speed.toml>", "set")
    assert "finite" in reason
