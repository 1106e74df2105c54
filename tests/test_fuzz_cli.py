"""Property-based hostile-input suite (issues 9, 26): mutate valid gearbox descriptions,
scenarios and the options of the newer commands (estimate, sweep, draw, export-measurement) and
hold every command to the error contract.

For every mutated input and every command: exit 0 with a correct result, or exit 2 with one line
on stderr and no traceback (``ratios`` may also exit 1, after saying which gears differ from the
expected table), the process's peak memory under :data:`MEMORY_MAX_BYTES`; no file outside the
chosen ``--out`` changes; code that ``generate`` emits compiles under the strict flags. A result
is "correct" when an independent computation agrees: the gear ratios are re-derived here with
NumPy from the mutated TOML (Willis equations by hand), not with gearsym's SymPy code.

The budget is fixed and the seed too (``derandomize``), so ``make test`` is reproducible. The
nightly run raises the budget: ``GEARSYM_FUZZ_EXAMPLES=2000 make fuzz`` (see the Makefile).
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import shutil
import signal
import subprocess
import tempfile
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from gearsym import cli

ROOT = Path(__file__).resolve().parents[1]
BUILT_IN = ROOT / "gearsym" / "data" / "thesis_9speed.toml"
SIMPSON = ROOT / "tests" / "data" / "simpson_3speed.toml"
SCENARIO = ROOT / "gearsym" / "data" / "scenario_2_3.toml"
BASES = {
    "thesis": tomllib.loads(BUILT_IN.read_text(encoding="utf-8")),
    "simpson": tomllib.loads(SIMPSON.read_text(encoding="utf-8")),
}
SCENARIO_BASE = tomllib.loads(SCENARIO.read_text(encoding="utf-8"))

EXAMPLES = int(os.environ.get("GEARSYM_FUZZ_EXAMPLES", "60"))
SLOW_EXAMPLES = max(2, EXAMPLES // 15)  # generate and simulate take seconds per example
COMMAND_SECONDS = 120  # one command on one mutated file; a hang is a failure

FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,  # a fixed seed: the same examples in every run of make test
    database=None,
    suppress_health_check=list(HealthCheck),
)
SLOW = settings(FUZZ, max_examples=SLOW_EXAMPLES)
#: estimate's valid option sets simulate and filter (seconds each), its refusals are instant
FUZZ_OPTIONS = settings(FUZZ, max_examples=max(4, EXAMPLES // 4))

# ----------------------------------------------------------------------------- mutations

HOSTILE_NAMES = [
    "",
    "a\n",
    "x y",
    "int",
    "for",
    "_Bool",
    "_X",
    "__x",
    "res",
    "In",
    "ss",
    "out",
    "engine",
    "e_machine",
    "C",
    "mu",
    "1_2",
    "38",
    "k38",
    "K38",
    "B05",
    "NAN",
    "sinf",
    "ö",
    "x" * 40,
    'q"""q',
    "a*/b",
]

SPECIAL_INTS = [0, -1, 1, 2, 3, 10**400, -(10**400), 2**63, 10**9]
SPECIAL_FLOATS = [0.0, -0.0, 1e-300, 1e300, -1.0, math.nan, math.inf, -math.inf]

scalar_values = st.one_of(
    st.sampled_from(SPECIAL_INTS),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.sampled_from(SPECIAL_FLOATS),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(HOSTILE_NAMES),
    st.text(max_size=12),
    st.booleans(),
)
values = st.one_of(
    scalar_values,
    st.lists(scalar_values, max_size=4),
    st.just({}),
    st.builds(
        lambda v, u: {"value": v, "unit": u, "source": "fuzz"},
        scalar_values,
        st.sampled_from(["kg*m^2", "kg", "m", "1", "Pa", "N*m", "s", "furlong"]),
    ),
)


def _paths(tree: Any, prefix: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """Every key path of a TOML tree (dict keys and list indices)."""
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield (*prefix, key)
            yield from _paths(value, (*prefix, key))
    elif isinstance(tree, list):
        for index, value in enumerate(tree):
            yield (*prefix, index)
            yield from _paths(value, (*prefix, index))


def _get(tree: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        tree = tree[key]
    return tree


def _mutate(tree: dict[str, Any], data: st.DataObject) -> dict[str, Any]:
    tree = copy.deepcopy(tree)
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        paths = list(_paths(tree))
        path = data.draw(st.sampled_from(paths), label="path")
        parent, key = _get(tree, path[:-1]), path[-1]
        kind = data.draw(
            st.sampled_from(["replace", "delete", "rename", "add-key", "duplicate"]),
            label="kind",
        )
        if kind == "replace":
            parent[key] = data.draw(values, label="value")
        elif kind == "delete":
            del parent[key]
        elif kind == "rename":
            names = [p for p in paths if p[-1] in ("name", "sun", "ring", "carrier", "shaft")]
            if not names:
                continue
            target = data.draw(st.sampled_from(names), label="name path")
            _get(tree, target[:-1])[target[-1]] = data.draw(
                st.sampled_from(HOSTILE_NAMES), label="name"
            )
        elif kind == "add-key" and isinstance(parent, dict):
            parent[data.draw(st.sampled_from(["extra", "nmae", "Name"]))] = 1
        elif kind == "duplicate" and isinstance(parent, list) and parent:
            parent.append(copy.deepcopy(parent[key]))
    return tree


def _rename_everywhere(tree: Any, old: str, new: str) -> Any:
    """Every string equal to ``old`` becomes ``new`` (a consistent rename of a shaft, set,
    element or gear, wherever the description refers to it)."""
    if isinstance(tree, dict):
        return {k: _rename_everywhere(v, old, new) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_rename_everywhere(v, old, new) for v in tree]
    return new if tree == old else tree


def _plausible_change(tree: dict[str, Any], data: st.DataObject) -> dict[str, Any]:
    """A change a user makes on purpose: rename something consistently (to a plain or a
    hostile name), scale a physical value, or scale a set's teeth (same ratios)."""
    tree = copy.deepcopy(tree)
    kind = data.draw(st.sampled_from(["rename", "scale-value", "scale-teeth"]), label="change")
    if kind == "rename":
        section = data.draw(st.sampled_from(["shaft", "shift_element", "gear"]), label="what")
        old = data.draw(st.sampled_from([e["name"] for e in tree[section]]), label="old")
        new = data.draw(
            st.one_of(
                st.sampled_from(HOSTILE_NAMES),
                st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,6}", fullmatch=True),
            ),
            label="new",
        )
        return _rename_everywhere(tree, old, new)
    if kind == "scale-value":
        # a scalar quantity (a schedule's "value" is a list: scaling it is another change)
        quantities = [
            p
            for p in _paths(tree)
            if p[-1] == "value"
            and isinstance(_get(tree, p), int | float)
            and not isinstance(_get(tree, p), bool)
        ]
        path = data.draw(st.sampled_from(quantities), label="quantity")
        factor = data.draw(st.sampled_from([0.5, 0.9, 1.1, 2.0, -1.0, 0.0]), label="factor")
        _get(tree, path[:-1])["value"] = _get(tree, path) * factor
        return tree
    ps = data.draw(st.sampled_from(tree["planetary_set"]), label="set")
    factor = data.draw(st.sampled_from([2, 3]), label="teeth factor")
    for key in ("z_sun", "z_planet", "z_ring"):
        ps[key] *= factor
    return tree


def _dump(tree: dict[str, Any]) -> str | None:
    """TOML text of a mutated tree, or None when TOML cannot express it (e.g. mixed arrays
    that tomli_w refuses): those examples test nothing and are skipped by the caller."""
    try:
        return tomli_w.dumps(tree)
    except (TypeError, ValueError):
        return None


RAW_ATTACKS = [
    lambda text: text[: len(text) // 2],  # truncated
    lambda text: text.replace("=", "==", 1),
    lambda text: "\ufeff" + text,  # BOM
    lambda text: "x = " + "[" * 5000 + "]" * 5000 + "\n" + text,  # deep nesting
    lambda text: text + "\n[gearbox]\nname = 'again'\n",  # a table twice
]

# ----------------------------------------------------------------------------- running


class _Timeout(BaseException):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise _Timeout


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``gearsym ARGV`` in-process: (exit code, stdout, stderr). Any exception other than
    argparse's SystemExit propagates: that is a traceback the user would see."""
    out, err = io.StringIO(), io.StringIO()
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(COMMAND_SECONDS)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = cli.main(argv)
            except SystemExit as exc:  # argparse usage errors
                status = int(exc.code or 0)
    except _Timeout:
        pytest.fail(f"gearsym {' '.join(argv)} ran longer than {COMMAND_SECONDS} s")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    return status, out.getvalue(), err.getvalue()


def _snapshot(root: Path, skip: Path | None = None) -> dict[str, bytes]:
    files = {}
    for path in sorted(root.rglob("*")):
        if skip is not None and (path == skip or skip in path.parents):
            continue
        if path.is_file() or path.is_symlink():
            files[path.relative_to(root).as_posix()] = path.read_bytes()
    return files


@contextlib.contextmanager
def workdir() -> Iterator[Path]:
    """A fresh temporary working directory (hypothesis forbids function-scoped fixtures)."""
    previous = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="gearsym-fuzz-") as folder:
        os.chdir(folder)
        try:
            yield Path(folder)
        finally:
            os.chdir(previous)


#: Peak resident memory the suite's process (and any child, e.g. the MDF reader) may reach
#: over every mutated input: the whole test process, so it bounds each command too.
MEMORY_MAX_BYTES = 3 << 30


def peak_memory() -> int:
    """Largest resident set of this process or of any child it waited for, in bytes."""
    import resource

    kib = max(
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
        resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss,
    )
    return kib * 1024  # Linux reports KiB


def assert_contract(status: int, stdout: str, stderr: str, allow: tuple[int, ...] = (0, 2)) -> None:
    event(f"exit {status}")  # --hypothesis-show-statistics shows how often each outcome ran
    assert status in allow, (status, stdout[-2000:], stderr[-2000:])
    assert "Traceback" not in stderr
    assert peak_memory() < MEMORY_MAX_BYTES, f"peak memory {peak_memory() >> 20} MiB"
    if status == 2:
        lines = stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gearsym: "), stderr[-2000:]


# ----------------------------------------------------------------------------- ratios, by hand


def independent_ratios(tree: dict[str, Any]) -> dict[str, float | None]:
    """ω_in/ω_out per gear from the TOML alone (NumPy): Willis z_s ω_s + z_r ω_r =
    (z_s + z_r) ω_c per set, ω_a = ω_b per closed clutch, ω_b = 0 per closed brake, ω_in = 1.
    None where the output speed is not determined (a neutral)."""
    box = tree["gearbox"]
    shafts = [s["name"] for s in tree["shaft"]]
    index = {name: k for k, name in enumerate(shafts)}
    rows = []
    for ps in tree["planetary_set"]:
        row = np.zeros(len(shafts))
        row[index[ps["sun"]]] += ps["z_sun"]
        row[index[ps["ring"]]] += ps["z_ring"]
        row[index[ps["carrier"]]] -= ps["z_sun"] + ps["z_ring"]
        rows.append(row)
    elements = {e["name"]: e for e in tree["shift_element"]}
    result: dict[str, float | None] = {}
    for gear in tree["gear"]:
        a = list(rows)
        for name in gear.get("closed", []):
            e = elements[name]
            row = np.zeros(len(shafts))
            if e["kind"] == "clutch":
                row[index[e["shafts"][0]]] += 1.0
                row[index[e["shafts"][1]]] -= 1.0
            else:
                row[index[e["shaft"]]] = 1.0
            a.append(row)
        drive = np.zeros(len(shafts))
        drive[index[box["input_shaft"]]] = 1.0
        matrix = np.vstack([*a, drive])
        rhs = np.zeros(len(matrix))
        rhs[-1] = 1.0
        omega, *_ = np.linalg.lstsq(matrix, rhs, rcond=None)
        _, sv, vt = np.linalg.svd(matrix)
        null = vt[np.sum(sv > 1e-9 * sv[0]) :]
        out = index[box["output_shaft"]]
        determined = np.allclose(matrix @ omega, rhs, atol=1e-9) and np.all(
            np.abs(null[:, out]) < 1e-9
        )
        result[gear["name"]] = 1.0 / omega[out] if determined and omega[out] != 0 else None
    return result


def test_the_independent_ratios_reproduce_table_2_1() -> None:
    """The hand solver itself, against the thesis' printed Table 2.1."""
    table = {"1": 5.354, "2": 3.243, "3": 2.252, "4": 1.636, "5": 1.211, "6": 1.0}
    got = independent_ratios(BASES["thesis"])
    for gear, ratio in table.items():
        assert round(got[gear], 3) == ratio


# ----------------------------------------------------------------------------- properties


@FUZZ
@given(data=st.data(), base=st.sampled_from(sorted(BASES)))
def test_mutated_descriptions_keep_the_error_contract(data: st.DataObject, base: str) -> None:
    if data.draw(st.booleans(), label="plausible"):
        tree = _plausible_change(BASES[base], data)
    else:
        tree = _mutate(BASES[base], data)
    text = _dump(tree)
    if text is None:
        return
    with workdir() as root:
        config = root / "box.toml"
        config.write_text(text, encoding="utf-8")
        before = _snapshot(root)
        status, stdout, stderr = run_cli(["ratios", "--json", str(config)])
        assert_contract(status, stdout, stderr, allow=(0, 1, 2))
        if status in (0, 1):
            import json

            got = json.loads(stdout)
            ratios = got.get("ratios", got) if isinstance(got, dict) else got
            expected = independent_ratios(tomllib.loads(text))
            for gear, value in expected.items():
                if value is None:
                    assert ratios[gear] is None, gear
                else:
                    assert ratios[gear] == pytest.approx(value, rel=1e-9), gear
        status, stdout, stderr = run_cli(["ratios", str(config)])
        assert_contract(status, stdout, stderr, allow=(0, 1, 2))
        status, stdout, stderr = run_cli(["show", str(config), "--what", "mass-matrix"])
        assert_contract(status, stdout, stderr)
        status, stdout, stderr = run_cli(["model", str(config), "--shift", "2-3"])
        assert_contract(status, stdout, stderr)
        assert _snapshot(root) == before  # nothing written without --out


@FUZZ
@given(attack=st.sampled_from(range(len(RAW_ATTACKS))), encoding=st.sampled_from(["utf-8", "x"]))
def test_broken_files_are_one_line_errors(attack: int, encoding: str) -> None:
    text = RAW_ATTACKS[attack](BUILT_IN.read_text(encoding="utf-8"))
    with workdir() as root:
        config = root / "box.toml"
        if encoding == "utf-8":
            config.write_text(text, encoding="utf-8")
        else:
            config.write_bytes(b"\xff\xfe" + text.encode("utf-16-le"))  # not UTF-8
        status, stdout, stderr = run_cli(["ratios", str(config)])
        assert_contract(status, stdout, stderr, allow=(0, 1, 2))


@contextlib.contextmanager
def writing_command(
    text: str, file_name: str, argv: list[str], out_name: str
) -> Iterator[tuple[int, Path, Path]]:
    """Write ``text`` to ``file_name`` in a fresh folder and run ``gearsym ARGV`` (``{file}``
    and ``{out}`` filled in): the error contract holds, nothing outside ``--out`` changed, no
    staging folder or lock is left, and ``--out`` exists exactly when the command succeeded.
    Yields (exit code, ``--out``, the folder) for further checks."""
    with workdir() as root:
        path = root / file_name
        path.write_text(text, encoding="utf-8")
        before = _snapshot(root)
        out = root / out_name
        status, stdout, stderr = run_cli([a.format(file=path, out=out) for a in argv])
        assert_contract(status, stdout, stderr)
        assert _snapshot(root, skip=out) == before
        assert [p.name for p in root.iterdir() if p.name.startswith(".")] == []
        assert out.exists() == (status == 0)
        yield status, out, root


@SLOW
@given(data=st.data())
def test_mutated_scenarios_keep_the_error_contract(data: st.DataObject) -> None:
    text = _dump(_mutate(SCENARIO_BASE, data))
    if text is None:
        return
    argv = ["simulate", "--scenario", "{file}", "--out", "{out}", "--no-plots"]
    with writing_command(text, "scenario.toml", argv, "sim"):
        pass


def _strict_compile(c_dir: Path, build: Path) -> None:
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        pytest.skip("no C compiler")
    flags = ["-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Werror"]
    for source in sorted(c_dir.glob("*.c")):
        result = subprocess.run(
            [compiler, *flags, "-c", str(source), "-o", str(build / (source.stem + ".o"))],
            capture_output=True,
            text=True,
        )
        assert result.returncode == 0, f"{source.name}: {result.stderr[-3000:]}"


@pytest.mark.slow
@SLOW
@given(data=st.data())
def test_changed_descriptions_generate_compilable_code_or_one_line(data: st.DataObject) -> None:
    text = _dump(_plausible_change(BASES["thesis"], data))
    if text is None:
        return
    argv = ["generate", "{file}", "--out", "{out}"]
    with writing_command(text, "box.toml", argv, "gen") as (status, out, root):
        if status == 0:
            build = root / "build"
            build.mkdir()
            _strict_compile(out / "c", build)


# ----------------------------------------------------------------------------- options

#: Hostile and plain values per option of the newer commands: NaN, infinities, signs, sizes,
#: wrong types, names that do not exist, underscores, empty lists.
ESTIMATE_OPTIONS: dict[str, list[str]] = {
    "--sample-time": ["nan", "inf", "-1", "0", "1e-9", "1e9", "0.01", "abc", "0.0005"],
    "--noise": ["nan", "-0.1", "0", "1e300", "0.01", "0.01,0.02", "a,b", "0.01,0.01,0.01"],
    "--runs": ["0", "-1", "1", "2", "1e9", "x"],
    "--seed": ["-1", "1.5", "0", "7"],
    "--initial": ["m_veh=nan", "x=1", "m_veh=1500", "=", "m_veh", "zeta=1e308"],
    "--dropout": ["0.5,0.1", "nan,1", "speed_phase", "gear_9", "0.2,0.4", "gear_2_a", ""],
    "--dropout-outputs": ["omega_1", "x", ",", "omega_1,omega_2"],
    "--params": ["m_veh", "x", ",", "m_veh,zeta"],
    "--modes": ["filter", "reference", "truth"],
    "--unknown": ["T_res_star", "x", ","],
}


@FUZZ_OPTIONS
@given(
    flt=st.sampled_from(["uio", "ekf", "euio", "kalman"]),
    chosen=st.dictionaries(
        st.sampled_from(sorted(ESTIMATE_OPTIONS)),
        st.integers(min_value=0, max_value=8),
        max_size=3,
    ),
)
def test_mutated_estimate_options_keep_the_error_contract(flt: str, chosen: dict[str, int]) -> None:
    """Every combination of hostile options: a run (exit 0) or one line (exit 2), never a
    traceback, and nothing written outside ``--out``."""
    argv = ["estimate", "--filter", flt, "--no-plots"]
    for option, k in sorted(chosen.items()):
        values = ESTIMATE_OPTIONS[option]
        argv += [option, values[k % len(values)]]
    with workdir() as folder:
        status, stdout, stderr = run_cli([*argv, "--out", "out"])
        assert_contract(status, stdout, stderr)
        written = {p.name for p in folder.iterdir()}
        assert written <= {"out"} and (status == 0) == ("out" in written), (argv, written)


SWEEP_RANGES = ["1600:2000", "-2000:-1000", "0:1", "nan:1", "2:1", "1e308:1e309", "0.1:0.12"]


@FUZZ
@given(
    mass=st.sampled_from(SWEEP_RANGES),
    mu=st.sampled_from(SWEEP_RANGES),
    samples=st.sampled_from(["3", "0", "1048576", "x", "-4", "4"]),
    scheduler=st.sampled_from(["tls://h:1", "udp://h", "tcp://", "local"]),
)
def test_mutated_sweeps_are_refused_in_one_line_before_any_work(
    mass: str, mu: str, samples: str, scheduler: str
) -> None:
    """Ranges outside a parameter's plausible values, bad sample counts and schedulers are
    refused in one line before a model is built; nothing is written. A valid sweep is not run
    here (it takes minutes): only its refusals are the property."""
    valid = mass == "1600:2000" and mu == "0.1:0.12" and samples == "4" and scheduler == "local"
    if valid:
        return
    argv = ["sweep", "--param", f"m_veh={mass}", "--param", f"mu_05={mu}"]
    argv += ["--samples", samples, "--scheduler", scheduler, "--out", "out"]
    with workdir() as folder:
        status, stdout, stderr = run_cli(argv)
        if status == 0:
            pytest.fail(f"a sweep with a bad value ran: {argv}")
        assert_contract(status, stdout, stderr, allow=(2,))
        assert list(folder.iterdir()) == []


@FUZZ_OPTIONS
@given(
    what=st.sampled_from(["stick", "lever", "speeds", "drivetrain", "x"]),
    gear=st.sampled_from([None, "2", "9", "x", "_", ""]),
    suffix=st.sampled_from([".svg", ".png", ".pdf", ""]),
)
def test_mutated_draw_options_keep_the_error_contract(
    what: str, gear: str | None, suffix: str
) -> None:
    argv = ["draw", "--what", what, "--out", f"picture{suffix}"]
    if gear is not None:
        argv += ["--gear", gear]
    with workdir() as folder:
        status, stdout, stderr = run_cli(argv)
        assert_contract(status, stdout, stderr)
        written = sorted(p.name for p in folder.iterdir())
        assert written == ([f"picture{suffix}"] if status == 0 else []), (argv, written)


@FUZZ_OPTIONS
@given(
    noise=st.sampled_from([None, "nan", "-1", "0", "1e300", "0.01", "x"]),
    seed=st.sampled_from([None, "-1", "3", "1.5"]),
    suffix=st.sampled_from([".mf4", ".csv", ".txt", ""]),
    scenario=st.sampled_from([None, "scenario_2_3_measured.toml", "missing.toml"]),
)
def test_mutated_export_measurement_options_keep_the_error_contract(
    noise: str | None, seed: str | None, suffix: str, scenario: str | None
) -> None:
    argv = ["export-measurement", "--out", f"rec{suffix}"]
    if scenario is not None:
        path = ROOT / "gearsym" / "data" / scenario
        argv += ["--scenario", str(path) if path.exists() else scenario]
    for option, value in (("--noise", noise), ("--seed", seed)):
        if value is not None:
            argv += [option, value]
    with workdir() as folder:
        status, stdout, stderr = run_cli(argv)
        assert_contract(status, stdout, stderr)
        written = sorted(p.name for p in folder.iterdir())
        assert written == ([f"rec{suffix}"] if status == 0 else []), (argv, written)
