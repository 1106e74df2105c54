"""The documentation names files that exist: every repository path in README.md and docs/*.md
(``symbolic/…``, ``validation/…``, ``templates/…``, ``gearsym/…``, ``benchmarks/…``,
``tests/…``, ``docs/…``, ``.ci/…``) is a file or folder of this checkout, so a module moved or
renamed cannot leave the documentation pointing at nothing."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROOTS = ("symbolic", "validation", "templates", "gearsym", "benchmarks", "tests", "docs", ".ci")
PATH = re.compile(
    r"(?<![\w./-])((?:" + "|".join(re.escape(r) for r in ROOTS) + r")/[\w./<>*{}-]*[\w/>*}])"
)
#: A lower-case name without a suffix (``validation/checks``, ``validation/c_check``) names a
#: folder or a module; anything else without a suffix (``gearsym/CasADi``) is prose.
MODULE_OR_FOLDER = re.compile(r"[a-z0-9_]+(/[a-z0-9_]+)*/?")


def _mentioned(text: str) -> set[str]:
    found = set()
    for match in PATH.finditer(text):
        path = match.group(1).split("::")[0].rstrip(".")
        if any(c in path for c in "<>*{}"):
            continue  # a pattern (gearsym_<model>.c, templates/fmu_*.j2), not one file
        last = path.rstrip("/").rsplit("/", 1)[-1]
        if "." not in last and not MODULE_OR_FOLDER.fullmatch(path.split("/", 1)[1]):
            continue
        found.add(path.rstrip("/"))
    return found


def _exists(path: str) -> bool:
    target = ROOT / path
    return target.exists() or target.with_name(target.name + ".py").exists()


def _missing(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    return sorted(p for p in _mentioned(text) if not _exists(p))


def test_the_pattern_finds_paths_and_skips_patterns() -> None:
    text = (
        "see `validation/sim/simulate.py::run`, `templates/fmu_*.j2`, symbolic/io/, "
        "gearsym/CasADi ratios and validation/checks/c_check.compile_shared."
    )
    assert _mentioned(text) == {
        "validation/sim/simulate.py",
        "symbolic/io",
        "validation/checks/c_check.compile_shared",
    }
    assert not _exists("validation/checks/c_check.compile_shared")
    assert _exists("validation/checks/c_check")


def test_every_path_the_docs_name_exists() -> None:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    missing = {p.relative_to(ROOT).as_posix(): m for p in pages if (m := _missing(p))}
    assert not missing, f"documentation names paths that do not exist: {missing}"
