"""``gearsym generate`` and the committed ``generated/`` directory.

* ``generated/`` is exactly what ``gearsym generate --out generated`` writes now (the stale check
  CI runs), and the output is byte-identical across runs and ``PYTHONHASHSEED`` values;
* every emitted model (full model, every shift model in both input forms, the shift-element
  friction model) in C (double and single, strict flags) and in CasADi matches SymPy at 1000
  random points; the μ map matches :class:`gearsym.symbolic.friction.MuMap`;
* ``main.c`` compiles alone and runs; the ECU rules hold on the objects; cppcheck is clean; the
  code cross-compiles for a Cortex-M4F (these two skip only if the tool is not installed);
* the command's failure modes: one-line errors with exit code 2, no half-written output, no
  replacement of a foreign directory, a failed ``--check`` leaves the old content;
* end to end: a second description (changed tooth counts) is regenerated, compiled and validated
  by one command.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import pytest
from gearsym.symbolic.export.generate import (
    MANIFEST_MARKER,
    generate_tree,
    load_mu_map,
    mu_map_files,
    shift_element_model,
)
from gearsym.symbolic.export.index import example_view
from gearsym.symbolic.export.tree import C_DIR
from gearsym.symbolic.friction import DEFAULT_MU_MAP, shift_element_num
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks import c_check, generated_check

from gearsym import cli

REPO = Path(__file__).resolve().parents[1]
GENERATED = REPO / "generated"
ALT_TEETH = REPO / "tests" / "data" / "thesis_9speed_alt_teeth.toml"


@pytest.fixture(scope="module")
def tree(generated_tree: Any) -> Any:
    return generated_tree  # derived once per run (tests/conftest.py)


def _diff(expected: dict[str, str], actual: dict[str, str]) -> str:
    missing = sorted(set(expected) - set(actual))
    extra = sorted(set(actual) - set(expected))
    changed = sorted(k for k in set(expected) & set(actual) if expected[k] != actual[k])
    return f"missing {missing}, unexpected {extra}, differing {changed}"


def _gearsym(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        check=False,
    )


# ---------------------------------------------------------------------------------------------
# generated/ is fresh and deterministic
# ---------------------------------------------------------------------------------------------


def test_generated_directory_is_up_to_date(tree: Any) -> None:
    """The stale check: regenerate in memory, compare with generated/ byte for byte."""
    committed = generated_check.read_tree(GENERATED)
    assert committed == tree.files, (
        "generated/ is stale; run `gearsym generate --out generated`: "
        + _diff(tree.files, committed)
    )


@pytest.mark.slow
def test_generate_is_byte_identical_across_hash_seeds(tmp_path: Path) -> None:
    trees = []
    for seed in ("0", "4242"):
        env = {**os.environ, "PYTHONHASHSEED": seed}
        out = tmp_path / f"seed{seed}"
        result = _gearsym("generate", "--out", str(out), env=env)
        assert result.returncode == 0, result.stderr
        assert "… emitting shift_2_3_mu" in result.stderr  # progress on stderr
        assert f"to {out}" in result.stdout
        trees.append(generated_check.read_tree(out))
    assert trees[0] == trees[1], _diff(trees[0], trees[1])
    assert trees[0] == generated_check.read_tree(GENERATED), _diff(
        generated_check.read_tree(GENERATED), trees[0]
    )
    assert not list(tmp_path.glob(".*"))  # no staging directory left behind


def test_output_holds_no_paths_or_times(tree: Any) -> None:
    text = "\n".join(tree.files.values())
    assert str(REPO) not in text and "/home/" not in text and "/tmp/" not in text
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text)
    manifest = tree.files["MANIFEST"].splitlines()
    assert manifest[0] == MANIFEST_MARKER
    assert len(manifest) == 2 + len(tree.files) - 1


def test_every_model_is_emitted(tree: Any) -> None:
    from gearsym.symbolic.drivetrain import adjacent_shifts

    shifts = [s.name.replace("-", "_") for s in adjacent_shifts(load_description(None))]
    names = {m.model.name for m in tree.models}
    assert names == (
        {"full", "shift_element"}
        | {f"shift_{s}" for s in shifts}
        | {f"shift_{s}_mu" for s in shifts}
        | {f"shift_{s}_mu_sens" for s in shifts}
        | {"ekf_2_3"}  # the EKF (4.3) of the thesis' shift
        | {"euio_2_3"}  # its extended UIO (4.5)
    )
    for name in names:
        for path in (
            f"c/gearsym_{name}.h",
            f"c/gearsym_{name}.c",
            f"python/gearsym_{name}_casadi.py",
        ):
            assert path in tree.files
    for path in ("c/gearsym_mu_map.h", "c/gearsym_mu_map.c", "python/gearsym_mu_map_casadi.py"):
        assert path in tree.files


def test_large_rationals_print_as_decimals_and_small_ones_exactly() -> None:
    """Exact inertias make rationals like 6.2e49/3.2e50: as literals they would overflow float."""
    import sympy as sp
    from gearsym.symbolic.codegen import CasadiPrinter, GearsymCPrinter

    printer = GearsymCPrinter({}, "m_")
    assert printer.doprint(sp.Rational(-2, 7)) == "-(GEARSYM_LIT(2.0)/GEARSYM_LIT(7.0))"
    big = sp.Rational(10**50 + 1, 3 * 10**49)
    assert printer.doprint(big) == "GEARSYM_LIT(3.33333333333333333333)"
    assert printer.doprint(big * sp.Symbol("a")) == "GEARSYM_LIT(3.33333333333333333333)*a"
    assert CasadiPrinter({}).doprint(-big) == "-3.33333333333333333333"
    assert printer.doprint(sp.Rational(2**25 + 1, 3)) == "GEARSYM_LIT(11184811.0)"
    assert printer.doprint(sp.Rational(2**24, 3)) == "(GEARSYM_LIT(16777216.0)/GEARSYM_LIT(3.0))"


def test_expression_functions_are_restrict_in_definitions_only(tree: Any) -> None:
    header = tree.files["c/gearsym_full.h"]
    source = tree.files["c/gearsym_full.c"]
    assert "restrict" not in header  # the header stays valid C++
    assert "    const gearsym_real *restrict x,\n" in source
    assert "    gearsym_real *restrict xdot)" in source
    step = source.split("void gearsym_full_rk4_step(")[1].split("{")[0]
    assert "restrict" not in step  # x_next may alias x


# ---------------------------------------------------------------------------------------------
# The committed code, compiled and validated
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def comparisons(tree: Any, tmp_path_factory: pytest.TempPathFactory) -> list:
    return generated_check.compare_models(
        tree.models, GENERATED, tmp_path_factory.mktemp("build"), n_points=1000
    )


@pytest.mark.slow
def test_c_and_casadi_match_sympy_for_every_model(comparisons: list) -> None:
    assert len(comparisons) == 3 * 28  # 28 models (with the EKF, EUIO): C double, C single, CasADi
    for report in comparisons:
        print(report)
    failed = [str(r) for r in comparisons if not generated_check.comparison_ok(r)]
    assert not failed, "\n".join(failed)
    for report in comparisons:
        assert report.n_points == 1000
        precision = "single" if "single" in report.target else "double"
        if precision == "single" and report.target.split(":")[0].endswith("_sens"):
            errors = dict(report.max_error)
            for name in ("jac_p", "jac_p_sparse"):  # the same values, dense and sparse
                assert errors.pop(name) <= generated_check.SENSITIVITY_JAC_P_SINGLE, report
            assert max(errors.values()) <= c_check.TOLERANCE["single"], report
        elif report.conditioned:  # only the friction model's d/d z_ba_ratio, see conditioned_error
            assert report.target.startswith("shift_element: C single"), report
            assert set(report.conditioned) <= {"jac_p", "jac_p_sparse"}
        else:
            assert report.ok(c_check.TOLERANCE[precision]), report


def test_mu_map_matches_the_reference(tree: Any, tmp_path: Path) -> None:
    report = generated_check.compare_mu_map(tree.mu_map, GENERATED, tmp_path, n_points=1000)
    print(report)
    assert report.max_error["C double"] <= 1e-12
    assert report.max_error["C single"] <= 1e-5
    assert report.max_error["CasADi"] <= 1e-12
    assert report.extra["NaN propagates (C)"] == 0.0


def _config_with_mu_map(tmp_path: Path, mu_map: str) -> Path:
    from gearsym.symbolic.description import default_config_text

    text = default_config_text()
    assert 'mu_map = "built-in"' in text
    config = tmp_path / "gearbox.toml"
    # json.dumps gives a valid TOML basic string (escapes \\, \" and control characters)
    config.write_text(text.replace('mu_map = "built-in"', f"mu_map = {json.dumps(mu_map)}"))
    return config


def test_hostile_mu_map_file_name_is_printed_safely(tmp_path: Path) -> None:
    """friction.mu_map names a file whose path holds a docstring end, a comment end, a
    backslash and a newline: the output names the map by its file name with only
    [A-Za-z0-9._+-] kept and the file's SHA-256, never by its path, and every emitted file
    still compiles (C, both precisions) or imports (Python)."""
    data = DEFAULT_MU_MAP.read_bytes()
    folder, name = 'we"""ird*', 'na\\me"""\n*x.toml'  # folder + "/" + name holds "*/"
    (tmp_path / folder).mkdir()
    (tmp_path / folder / name).write_bytes(data)
    config = _config_with_mu_map(tmp_path, f"{folder}/{name}")
    tree = generate_tree(load_description(str(config)))
    origin = f"na_me_____x.toml (SHA-256 {hashlib.sha256(data).hexdigest()})"
    assert tree.mu_map.origin == origin
    for path, text in tree.files.items():
        assert str(tmp_path) not in text and "ird*" not in text and "na\\me" not in text, path
        if path.endswith(".py"):
            ast.parse(text, filename=path)  # a stray triple quote or backslash would break it
    assert f"Data: {origin}." in tree.files["c/gearsym_mu_map.h"]
    assert f"Data: {origin}." in tree.files["c/gearsym_mu_map.c"]
    assert f"μ map data: `{origin}`." in tree.files["README.md"]
    out = tmp_path / "out"
    c_check.write_files(
        {k.split("/")[1]: v for k, v in tree.files.items() if k.startswith("python/gearsym_mu")},
        out,
    )
    module = c_check.load_casadi_module(out / "gearsym_mu_map_casadi.py")
    assert module.ORIGIN == origin
    assert module.mu_map(4e5, 80.0, 10.0) == pytest.approx(float(tree.mu_map(4e5, 80.0, 10.0)))
    sources = {k.split("/")[1]: v for k, v in tree.files.items() if k.startswith("c/gearsym_mu")}
    for single in (False, True):
        c_check.compile_shared(sources, tmp_path / "c", single=single)  # no diagnostic at all


def test_absolute_mu_map_path_is_not_printed(tmp_path: Path) -> None:
    data = DEFAULT_MU_MAP.read_bytes()
    (tmp_path / "my map.toml").write_bytes(data)
    config = _config_with_mu_map(tmp_path, str(tmp_path / "my map.toml"))
    mu_map = load_mu_map(load_description(str(config)))
    assert mu_map.origin == f"my_map.toml (SHA-256 {hashlib.sha256(data).hexdigest()})"
    for text in mu_map_files(mu_map).values():
        assert str(tmp_path) not in text and "my_map.toml (SHA-256" in text


def test_shift_element_model_equals_the_friction_module() -> None:
    """The emitted friction model (written in the normalised deflection) is (2.66)-(2.70) of
    symbolic/friction.py, including the open element and the over-deflected bristle."""
    import sympy as sp

    model = shift_element_model(load_description(None))
    args = [*model.state_symbols, *model.input_symbols, *model.parameter_symbols]
    fn = sp.lambdify(args, [model.rhs[0], model.output_expressions[0]], "numpy")
    rng = np.random.default_rng(3)
    n = 4000
    z = rng.uniform(-0.02, 0.02, n)
    dw = rng.uniform(-50, 50, n)
    dw[::7] = 0.0
    f_n = rng.uniform(0, 2e4, n)
    f_n[::5] = 0.0
    mu = rng.uniform(0.08, 0.16, n)
    s0, s1, ratio, t_min = 2e5, 150.0, 0.6, 1e-3
    n_disc, r_m = 5.0, 0.08
    zdot, torque = fn(z, dw, f_n, mu, s0, s1, ratio, t_min, n_disc, r_m)
    want_zdot, want_torque = shift_element_num(z, dw, f_n, mu, s0, s1, n_disc, r_m, ratio, t_min)
    np.testing.assert_allclose(zdot, want_zdot, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(torque, want_torque, rtol=1e-12, atol=1e-9)


def test_example_main_compiles_alone_and_runs(tree: Any, tmp_path: Path) -> None:
    """``main.c`` compiles alone, runs, and prints the friction torque of the on-coming element
    of its shift by value: after 10 ms of constant slip the elasto-plastic bristle (2.66)–(2.68)
    is at its steady deflection, so the torque is the sliding torque 2 N_disc r_m μ F_N with
    F_N = p_N A_piston (2.69). N_disc, r_m and A_piston are the description's, of the element
    the shift brings on (B05 of 2-3); p_N, T_oil and the slip are the template's inputs (the
    example's view), and μ is the description's μ map there (:class:`MuMap`, which the emitted
    map matches in ``test_mu_map_matches_the_reference``), never a number read from the
    program's output.

    Teeth: a planted bug that hands the example another element's friction radius (K38's
    0.08 m instead of B05's 0.09 m, in the template or its view, then regenerated) makes the
    program print 320.46 N·m where 2 N_disc r_m μ F_N of B05 is 360.5 N·m, 11 % off and far
    outside the 1e-3 here; the former pattern ``torque 3\\d\\d\\.\\d+`` took both."""
    d = load_description()
    view = example_view(d, tree.models)
    element = d.element(shift_spec(d, view.shift).on_coming)
    assert element.n_disc and element.r_m and element.a_piston
    pressure = float(view.apply_pressure)
    mu = float(load_mu_map(d)(pressure, float(view.t_oil), float(view.slip)))
    expected = 2 * element.n_disc * element.r_m.value * mu * pressure * element.a_piston.value
    outputs = generated_check.run_example(GENERATED, tmp_path)
    for precision, text in outputs.items():
        print(precision, text)
        assert "synchronised with gear 3" in text
        printed = re.search(r"shift_element (\w+): mu (\S+), torque (\S+) N\*m", text)
        assert printed is not None and printed[1] == element.name
        assert float(printed[2]) == pytest.approx(mu, abs=1e-4)  # printed to 4 decimals
        assert float(printed[3]) == pytest.approx(expected, rel=1e-3), (precision, expected)
    line = re.search(r"omega_1 +(\S+)", outputs["double"]).group(1)
    assert float(line) == pytest.approx(
        float(re.search(r"omega_1 +(\S+)", outputs["single"])[1]), rel=1e-4
    )


@pytest.mark.slow
def test_ecu_rules_hold(tmp_path: Path) -> None:
    assert generated_check.ecu_rule_violations(GENERATED, tmp_path) == []


def test_single_build_has_no_double_literals(tmp_path: Path) -> None:
    sources = generated_check.library_sources(GENERATED / C_DIR)
    code = c_check.preprocessed_own_lines(sources, tmp_path, single=True)
    literals = re.findall(r"(?<![\w.])(?:\d+\.\d*|\.\d+|\d+[eE][-+]?\d+)(?:[eE][-+]?\d+)?\w*", code)
    assert literals and all(lit[-1] in "fF" for lit in literals)
    assert "double" not in code
    assert not re.search(r"\b(sin|cos|exp|sqrt|fabs|fmin|fmax|pow)\(", code)


@pytest.mark.slow
def test_cppcheck_is_clean() -> None:
    findings = generated_check.cppcheck(GENERATED / C_DIR)
    if findings is None:
        pytest.skip("cppcheck is not installed (CI installs it: .ci/run)")
    assert findings == []


@pytest.mark.slow
def test_cross_compiles_for_cortex_m4f(tmp_path: Path) -> None:
    sizes = generated_check.cortex_m4_sizes(GENERATED / C_DIR, tmp_path)
    if sizes is None:
        pytest.skip("arm-none-eabi-gcc is not installed (CI installs it: .ci/run)")
    print("\n".join(generated_check.describe_sizes(sizes)))
    total = sum(s.text for s in sizes.values())
    print(f"total code: {total} bytes")
    assert set(sizes) == {
        p for p in generated_check.library_sources(GENERATED / C_DIR) if p.endswith(".c")
    }
    assert all(s.data == 0 and s.bss == 0 for s in sizes.values())  # no mutable static data
    assert sizes["gearsym_shift_2_3_mu.c"].text < 16384


def test_description_without_friction_data(tmp_path: Path) -> None:
    """No [friction] section and no disc data: torque-input shift models only, no friction
    model; the example uses the torque-input 2-3 model and still compiles and runs."""
    text = ALT_TEETH.read_text()
    text = text[: text.index("[friction]")]
    text = re.sub(r"\n(n_disc|r_m|a_piston) = [^\n]*", "", text)
    config = tmp_path / "no_friction.toml"
    config.write_text(text)
    out = tmp_path / "out"
    assert cli.main(["generate", str(config), "--out", str(out)]) == 0
    files = generated_check.read_tree(out)
    assert "c/gearsym_shift_2_3.c" in files and "c/gearsym_shift_2_3_mu.c" not in files
    assert "c/gearsym_shift_element.c" not in files and "c/gearsym_mu_map.c" in files
    assert "gearsym_shift_2_3_rk4_step" in files["c/main.c"]
    outputs = generated_check.run_example(out, tmp_path / "build")
    assert all("synchronised with gear 3" in text for text in outputs.values())


# ---------------------------------------------------------------------------------------------
# The command's failure modes
# ---------------------------------------------------------------------------------------------


def test_bad_description_is_one_line_and_writes_nothing(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(ALT_TEETH.read_text().replace("z_ring = 96", "z_ring = 95"))
    out = tmp_path / "out"
    result = _gearsym("generate", str(bad), "--out", str(out))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith(f'gearsym: {bad}: planetary_set[name="1"].z_ring: ')
    assert "Traceback" not in result.stderr
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_missing_drivetrain_data_is_one_line(tmp_path: Path) -> None:
    result = _gearsym("generate", "tests/data/simpson_3speed.toml", "--out", str(tmp_path / "o"))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == (
        "gearsym: tests/data/simpson_3speed.toml: drivetrain.i_D: missing (needed by the "
        "drivetrain model)"
    )


def test_out_of_range_default_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "heavy.toml"
    text = ALT_TEETH.read_text()
    bad.write_text(text.replace("m_veh = { value = 1800.0", "m_veh = { value = 1.8e6"))
    result = _gearsym("generate", str(bad), "--out", str(tmp_path / "o"))
    assert result.returncode == 2
    assert re.fullmatch(
        rf"gearsym: {re.escape(str(bad))}: vehicle\.m_veh: value 1\.8e\+06 lies outside .*",
        result.stderr.strip().splitlines()[-1],
    )


def test_refuses_to_replace_a_foreign_directory(tmp_path: Path) -> None:
    (tmp_path / "mine.txt").write_text("keep me")
    result = _gearsym("generate", "--out", str(tmp_path))
    assert result.returncode == 2
    assert "was not written by gearsym" in result.stderr
    assert (tmp_path / "mine.txt").read_text() == "keep me"


def _fake_tree(out: Path) -> None:
    out.mkdir()
    (out / "old.txt").write_text("old")
    digest = hashlib.sha256(b"old").hexdigest()  # a tree gearsym wrote: every file listed
    (out / "MANIFEST").write_text(f"{MANIFEST_MARKER}\n# 1 files\n{digest}  old.txt\n")


@pytest.mark.slow
def test_failure_while_writing_leaves_the_old_output(tmp_path: Path, capsys: Any) -> None:
    out = tmp_path / "gen"
    _fake_tree(out)
    from gearsym import cmd_generate

    real = cmd_generate.write_files

    def half(files: dict[str, str], root: Path) -> None:
        real(dict(list(files.items())[:5]), root)
        raise OSError("disk full")

    with mock.patch.object(cmd_generate, "write_files", half), pytest.raises(OSError):
        cli.main(["generate", "--out", str(out)])
    assert sorted(p.name for p in out.iterdir()) == ["MANIFEST", "old.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["gen"]  # staging removed

    assert cli.main(["generate", "--out", str(out)]) == 0  # a gearsym directory is replaced
    assert not (out / "old.txt").exists() and (out / "c" / "main.c").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["gen"]


def test_failed_check_leaves_the_old_output(tmp_path: Path, capsys: Any) -> None:
    out = tmp_path / "gen"
    _fake_tree(out)
    failing = generated_check.TreeReport(failures=["injected failure"])
    with mock.patch.object(generated_check, "check_tree", return_value=failing):
        assert cli.main(["generate", "--out", str(out), "--check"]) == 1
    assert "FAILED: injected failure" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["MANIFEST", "old.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["gen"]


# ---------------------------------------------------------------------------------------------
# End to end: a changed description, one command
# ---------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_changed_tooth_counts_regenerate_compile_and_validate_in_one_command(
    tmp_path: Path,
) -> None:
    out = tmp_path / "alt"
    result = _gearsym("generate", str(ALT_TEETH), "--out", str(out), "--check")
    print(result.stdout)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "FAILED" not in result.stdout
    # every model and set, the UIO included (against its design, validation/checks/uio_check.py),
    # less the μ map; the shift controller's model parts among them (validation/checks/
    # control_check.py)
    emitted = len(list(out.glob("c/gearsym_*.h"))) - 1
    assert re.search(r"control_2_3: C single .*max error .* at 1000 points", result.stdout)
    assert list(out.glob("c/gearsym_uio_*.h"))  # the UIO is among them
    assert re.search(r"uio_2_3: C single .*max error .* at 1000 points", result.stdout)
    # the extended UIO's step along the default shift against the library (euio_check.py)
    for target in ("C double", "C single", "CasADi"):
        assert re.search(rf"euio_2_3 step: {target} +max error .* at 1\d\d points", result.stdout)
    assert len(re.findall(r"max error .* at 1000 points", result.stdout)) == 3 * emitted
    assert "main.c: compiled strictly and ran in double, single" in result.stdout
    assert "integration check:" in result.stdout
    assert re.search(r"0\.00100 +256 +\S+ +4\.0\d", result.stdout)  # RK4 order 4
    for tool, line in (("cppcheck", "cppcheck"), ("arm-none-eabi-gcc", "Cortex-M4F")):
        if shutil.which(tool):
            assert f"skipped: {line}" not in result.stdout
    files = generated_check.read_tree(out)
    assert "thesis_9speed_alt_teeth" in files["c/gearsym_full.h"]
    assert files["c/gearsym_full.c"] != generated_check.read_tree(GENERATED)["c/gearsym_full.c"]
    assert not list(tmp_path.glob(".*"))


def test_model_names_are_known_before_any_derivation():
    # export-fmu checks --model against these names, then derives only that model
    from gearsym.symbolic.export.generate import gearbox_model_names, gearbox_models
    from gearsym.symbolic.loader import load_description

    d = load_description()
    built = [m.model.name for m in gearbox_models(d)]
    assert gearbox_model_names(d) == built
    assert [m.model.name for m in gearbox_models(d, only="shift_2_3_mu")] == ["shift_2_3_mu"]
    assert gearbox_models(d, only="nope") == []
