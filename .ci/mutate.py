"""The periodic mutation run (``make mutate``): mutmut over the dynamics, the EKF and the C
printer with a targeted fast test subset; the score and the survivors into
docs/results/mutation.md.

mutmut derives a mutant's module name from its file's path below the working directory and
finds the mutated module through ``mutants/`` on ``sys.path``; this checkout's ``gearsym``
maps its subpackages to top-level folders (pyproject's package-dir: ``gearsym.symbolic`` is
``symbolic/``), so run in the repository mutmut stops ("could not figure out where the code to
mutate is"), and with ``source_paths = ["symbolic"]`` it would name the mutants
``symbolic.dynamics.…`` while the tests import ``gearsym.symbolic.dynamics`` (its own check
stops on the mismatch). The run therefore stages the installed layout in build/mutation/
(``gearsym/`` with ``symbolic/``, ``validation/`` and ``templates/`` inside, as the wheel and
the docs build have it; ``tests/`` and ``generated/`` beside it) and runs mutmut there:
``mutants/`` comes first on ``sys.path``, ahead of the editable install's finder, so the tests
import the mutated package.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAGE = ROOT / "build" / "mutation"
RESULT = ROOT / "docs" / "results" / "mutation.md"

#: The mutated modules (paths in the staged package) and why each.
TARGETS = {
    "gearsym/symbolic/dynamics.py": "the mass matrix and generalized forces (2.34-2.37)",
    "gearsym/symbolic/estimators/ekf.py": "the EKF (4.1, 4.3): its numerical core",
    "gearsym/symbolic/codegen/c/printer.py": "the C99 printer of every emitted expression",
    "gearsym/symbolic/codegen/render.py": "the one Jinja2 entry point of the emitted files",
}

#: The mutants run (mutmut's names, fnmatch patterns): every one of the dynamics, the printer
#: and the renderer; of ekf.py its numerical core (R, predict, update, the RK4 step, the
#: outputs, the frozen μ states), not the construction of the augmented model and of the
#: CasADi functions (530 of its 737 mutants, which the dynamics' and the step's tests judge
#: through what they build).
_EKF = "gearsym.symbolic.estimators.ekf."
SELECTED = [
    "gearsym.symbolic.dynamics.*",
    "gearsym.symbolic.codegen.c.printer.*",
    "gearsym.symbolic.codegen.render.*",
    _EKF + "x_measurement_variance__mutmut_*",
    _EKF + "x_ekf_predict__mutmut_*",
    _EKF + "x_ekf_update__mutmut_*",
    _EKF + "xǁDiscreteModelǁstep__mutmut_*",
    _EKF + "xǁDiscreteModelǁoutputs__mutmut_*",
    _EKF + "xǁDiscreteModelǁrhs__mutmut_*",
    _EKF + "xǁAugmentedModelǁfrozen_states__mutmut_*",
]

#: The runner: the fast tests that judge these modules by independent values.
TESTS = [
    "tests/test_numpy_dynamics.py",
    "tests/test_thesis_dynamics.py",
    "tests/test_ekf.py",
    "tests/test_ekf_ops.py",
    "tests/test_filter_consistency.py",
    "tests/test_codegen.py",
    "tests/test_printer_values.py",
]

#: Fast tier only; the EKF command's end-to-end test runs a subprocess per mutant (minutes).
PYTEST_ARGS = [
    "-m",
    "not slow",
    "-p",
    "no:cacheprovider",
    "--deselect",
    "tests/test_ekf.py::test_estimate_ekf_command",
]

#: Copied beside the package for the tests that read the checkout's files (descriptions under
#: tests/data and docs/set_kinds, validation/checks/numpy_dynamics.py read as text, generated/).
BESIDE = ("symbolic", "validation", "templates", "docs", "generated")


def _ignore(_folder: str, names: list[str]) -> set[str]:
    return {n for n in names if n in ("__pycache__", ".pytest_cache") or n.endswith(".pyc")}


def stage(targets: list[str], tests: list[str]) -> None:
    """build/mutation/: the installed layout of ``gearsym`` and what the tests read, and a
    pyproject.toml that holds mutmut's configuration and the checkout's pytest settings."""
    import tomllib

    shutil.rmtree(STAGE, ignore_errors=True)
    STAGE.mkdir(parents=True)
    shutil.copytree(ROOT / "gearsym", STAGE / "gearsym", ignore=_ignore)
    for sub in ("symbolic", "validation", "templates"):
        shutil.copytree(ROOT / sub, STAGE / "gearsym" / sub, ignore=_ignore)
    for folder in (*BESIDE, "tests"):
        shutil.copytree(ROOT / folder, STAGE / folder, ignore=_ignore)
    with open(ROOT / "pyproject.toml", "rb") as fh:
        pytest_options = tomllib.load(fh)["tool"]["pytest"]["ini_options"]

    def toml_list(values: list[str]) -> str:
        return "[" + ", ".join(json.dumps(v) for v in values) + "]"

    lines = [
        "[tool.mutmut]",
        'source_paths = ["gearsym"]',
        f"only_mutate = {toml_list(targets)}",
        f"also_copy = {toml_list(list(BESIDE))}",
        f"pytest_add_cli_args_test_selection = {toml_list(tests)}",
        f"pytest_add_cli_args = {toml_list(PYTEST_ARGS)}",
        "",
        "[tool.pytest.ini_options]",
    ]
    for key, value in pytest_options.items():
        lines.append(f"{key} = {json.dumps(value, ensure_ascii=False)}")
    (STAGE / "pyproject.toml").write_text("\n".join(lines) + "\n", encoding="utf-8")


def mutmut(*args: str, check: bool = True) -> str:
    exe = Path(sys.executable).with_name("mutmut")
    done = subprocess.run([str(exe), *args], cwd=STAGE, capture_output=True, text=True, check=False)
    if check and done.returncode != 0:
        raise SystemExit(
            f"mutmut {' '.join(args)} failed:\n{done.stdout[-2000:]}{done.stderr[-2000:]}"
        )
    return done.stdout


def _diff(name: str) -> list[str]:
    """The changed lines of one mutant (mutmut show), without the diff's headers."""
    lines = mutmut("show", name, check=False).splitlines()
    return [ln for ln in lines if ln[:1] in "+-" and not ln.startswith(("+++", "---"))]


#: Per mutated module, the test files of the runner that judge it: a survivor is run again
#: against all of them (see :func:`recheck`).
GROUPS = {
    "gearsym.symbolic.dynamics": ["tests/test_thesis_dynamics.py", "tests/test_numpy_dynamics.py"],
    "gearsym.symbolic.estimators.ekf": [
        "tests/test_ekf.py",
        "tests/test_ekf_ops.py",
        "tests/test_filter_consistency.py",
    ],
    "gearsym.symbolic.codegen.c.printer": ["tests/test_printer_values.py", "tests/test_codegen.py"],
    "gearsym.symbolic.codegen.render": ["tests/test_printer_values.py", "tests/test_codegen.py"],
}


def _module(name: str) -> str:
    return name.split(".x_")[0].split(".xǁ")[0]


def _results() -> dict[str, str]:
    import fnmatch

    results = {}
    for line in mutmut("results", "--all", "true").splitlines():
        name, _, status = line.strip().rpartition(": ")
        if name and any(fnmatch.fnmatchcase(name, pattern) for pattern in SELECTED):
            results[name] = status
    return results


def recheck(survivors: list[str], children: int) -> dict[str, str]:
    """Each survivor against every test file of its module's group (:data:`GROUPS`), not only
    the tests mutmut recorded reaching it: mutmut records a module fixture's work (and a
    cached derivation's) against the first test that needed it, so a check that reads the
    fixture later is never run against the mutant. Returns per survivor "killed" or
    "survived"; kept in build/mutation/recheck.json."""
    from concurrent.futures import ThreadPoolExecutor

    def run(name: str) -> str:
        env = {**os.environ, "MUTANT_UNDER_TEST": name}
        tests = GROUPS[_module(name)]
        done = subprocess.run(
            [sys.executable, "-m", "pytest", "-x", "-q", *PYTEST_ARGS, *tests],
            cwd=STAGE / "mutants",
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        return "survived" if done.returncode == 0 else "killed"

    with ThreadPoolExecutor(max_workers=children) as pool:
        verdicts = dict(zip(survivors, pool.map(run, survivors), strict=True))
    (STAGE / "recheck.json").write_text(json.dumps(verdicts, indent=1), encoding="utf-8")
    return verdicts


def report(
    minutes: float, tests: list[str], children: int, verdicts: dict[str, str] | None = None
) -> str:
    """docs/results/mutation.md: the score per module, before and after the recheck, and every
    survivor with its diff."""
    results = _results()
    verdicts = verdicts or {}
    modules: dict[str, dict[str, int]] = {}
    for name, status in results.items():
        counts = modules.setdefault(_module(name), {})
        counts[status] = counts.get(status, 0) + 1
        if verdicts.get(name) == "killed":
            counts["rechecked"] = counts.get("rechecked", 0) + 1
    out = [
        "<!-- written by `make mutate` (.ci/mutate.py); do not edit by hand: run the command"
        " again -->",
        "",
        f"mutmut {_version()} over {len(TARGETS)} modules (of ekf.py its numerical core: "
        "R, predict, update, the RK4 step, outputs, frozen μ states), runner: the fast tests "
        + ", ".join(f"`{t}`" for t in tests)
        + f"; {children} processes, {minutes:.0f} min.",
        "",
        "| module | mutants | killed | survived | no tests | timeout | score | killed on "
        "recheck | score after it |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    total = {"all": 0, "killed": 0, "after": 0}
    for module in sorted(modules):
        counts = modules[module]
        n = sum(v for k, v in counts.items() if k != "rechecked")
        killed = counts.get("killed", 0) + counts.get("timeout", 0) + counts.get("segfault", 0)
        after = killed + counts.get("rechecked", 0)
        total["all"] += n
        total["killed"] += killed
        total["after"] += after
        out.append(
            f"| `{module}` | {n} | {counts.get('killed', 0)} | {counts.get('survived', 0)} | "
            f"{counts.get('no tests', 0)} | {counts.get('timeout', 0)} | {killed / n:.1%} | "
            f"{counts.get('rechecked', 0)} | {after / n:.1%} |"
        )
    n = max(total["all"], 1)
    out.append(
        f"| all | {total['all']} | | | | | {total['killed'] / n:.1%} | "
        f"{total['after'] - total['killed']} | {total['after'] / n:.1%} |"
    )
    out += [
        "",
        "Score: killed (a timeout or a crash counts as killed) over all mutants. Recheck: each "
        "survivor run again against every test file of its module's group (`GROUPS` in "
        ".ci/mutate.py), not only the tests mutmut recorded reaching it.",
        "",
    ]
    survivors = [n for n, s in results.items() if s in ("survived", "no tests")]
    left = [n for n in survivors if verdicts.get(n) != "killed"]
    out += [f"### Survivors after the recheck ({len(left)})", ""]
    for name in left:
        out += _entry(name, results[name])
    rechecked = [n for n in survivors if verdicts.get(n) == "killed"]
    out += [f"### Killed on the recheck ({len(rechecked)})", ""]
    for name in rechecked:
        out += _entry(name, results[name])
    return "\n".join(out).rstrip() + "\n"


def _entry(name: str, status: str) -> list[str]:
    return [
        f"- `{name}` ({status})",
        "",
        "  ```diff",
        *(f"  {ln}" for ln in _diff(name)),
        "  ```",
        "",
    ]


def _version() -> str:
    from importlib.metadata import version

    return version("mutmut")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--children", type=int, default=2, help="parallel mutant runs")
    parser.add_argument("--out", type=Path, default=RESULT, help="the report (markdown)")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="rewrite the report from the last run and its saved recheck",
    )
    parser.add_argument(
        "--recheck-only",
        action="store_true",
        help="run the recheck of the last run's survivors, then write the report",
    )
    parser.add_argument("--no-recheck", action="store_true", help="skip the recheck")
    args = parser.parse_args(argv)
    tests = TESTS
    minutes = 0.0
    if not (args.report_only or args.recheck_only):
        stage(list(TARGETS), tests)
        start = time.monotonic()
        mutmut("run", "--max-children", str(args.children), *SELECTED)
        minutes = (time.monotonic() - start) / 60
        (STAGE / "minutes").write_text(f"{minutes}\n")
    else:
        minutes = float((STAGE / "minutes").read_text())
    saved = STAGE / "recheck.json"
    if not (args.report_only or args.no_recheck):
        survivors = [n for n, s in _results().items() if s in ("survived", "no tests")]
        verdicts = recheck(survivors, args.children)
    else:
        verdicts = json.loads(saved.read_text()) if saved.exists() else {}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(report(minutes, tests, args.children, verdicts), encoding="utf-8")
    print(f"mutation report: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
