"""MISRA C:2012 report of the emitted C through cppcheck's MISRA add-on, and its deviations.

cppcheck (2.x, ``--addon=misra``) checks the rules it implements without the rule texts, so it
reports rule numbers. Every rule it finds in the emitted C must be in :data:`DEVIATIONS` with
its category and the reason the emitted code departs from it (or "not yet" where the
generator could comply and does not). A rule that is not listed fails
``tests/test_misra.py``: a change to the templates that breaks a new rule is seen.

The documentation's table of findings per rule (``docs/misra.md``) is written by this module,
not typed: ``python -m gearsym.validation.checks.misra --out DIR`` checks every emitted C file
of ``generated/c`` and writes ``misra.json`` (the counts, the files, the cppcheck version and
the deviations) and ``misra.md`` (:func:`misra_markdown`, a function of that JSON alone);
``make results`` copies both into ``docs/results``.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tempfile
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "DEVIATIONS",
    "MisraUnavailable",
    "format_table",
    "main",
    "misra_markdown",
    "misra_report",
    "misra_rules",
]

#: The command that writes the documentation's table (``make results``).
COMMAND = "python -m gearsym.validation.checks.misra"

#: rule -> (category, why the emitted C departs from it). Categories as MISRA C:2012 states
#: them; no mandatory rule is deviated.
DEVIATIONS: dict[str, tuple[str, str]] = {
    "2.2": (
        "required",
        "cppcheck flags stores in the loops that spread a sparse Jacobian into its dense "
        "column-major form (gearsym_shift_element); every store is read by the caller",
    ),
    "2.5": ("advisory", "the size and index macros are the API for the integrating code"),
    "5.6": (
        "required",
        "`gearsym_real` is typedef'd in every header under one guard (GEARSYM_REAL_DEFINED) so "
        "that each header can be included alone; it is the same type each time",
    ),
    "8.7": ("advisory", "every function with external linkage is API for the integrating code"),
    "8.9": (
        "advisory",
        "the μ-map tables stay file-scope `static const` data beside their axes, though one "
        "function reads them",
    ),
    "8.14": (
        "required",
        "`restrict` on the non-overlapping argument arrays: measured 2-13 % faster at -O2 "
        "(docs/benchmarks.md, emitted C against CasADi and SymForce); the API states that "
        "arguments never alias",
    ),
    "9.3": ("required", "the example main.c initialises demo arrays partially (not TCU code)"),
    "12.1": (
        "advisory",
        "not yet: products inside sums rely on C's precedence (a*b + c); the printer could "
        "parenthesise every product",
    ),
    "15.5": (
        "advisory",
        "the validating functions return an error code at the first failed check instead of "
        "carrying a status flag to one exit",
    ),
    "18.4": ("advisory", "the μ-map look-up steps a pointer through its axis table"),
    "20.10": ("advisory", "`##` in GEARSYM_LIT(v) appends the `f` suffix in single precision"),
    "21.6": ("required", "the example main.c prints with printf (not TCU code)"),
}

_RULE = re.compile(r"misra-c2012-(\d+\.\d+)")


class MisraUnavailable(RuntimeError):
    """cppcheck, or its MISRA add-on, is not installed."""


def misra_rules(c_files: Sequence[Path], jobs: int = 2) -> Counter[str]:
    """How often each MISRA C:2012 rule is reported for ``c_files`` (C99, their headers
    beside them)."""
    cppcheck = shutil.which("cppcheck")
    if cppcheck is None:
        raise MisraUnavailable("cppcheck is not installed")
    # The add-on writes .dump files beside each source: check copies in a temporary folder, so
    # the emitted tree (generated/, checked for staleness) is never touched.
    with tempfile.TemporaryDirectory(prefix="gearsym-misra-") as tmp:
        copies = []
        for folder in sorted({Path(f).parent for f in c_files}):
            for header in sorted(folder.glob("*.h")):
                shutil.copy2(header, Path(tmp) / header.name)
        for source in c_files:
            copies.append(Path(tmp) / Path(source).name)
            shutil.copy2(source, copies[-1])
        result = subprocess.run(
            [
                cppcheck,
                "--addon=misra",
                "--std=c99",
                "-q",
                f"-j{jobs}",
                "--template={id}",
                *map(str, copies),
            ],
            capture_output=True,
            text=True,
            timeout=1800,
            check=False,
            cwd=tmp,
        )
    if "misra" in result.stderr.lower() and "failed" in result.stderr.lower():
        raise MisraUnavailable(result.stderr.strip().splitlines()[-1])
    return Counter(m.group(1) for m in _RULE.finditer(result.stderr))


def _rule_key(rule: str) -> tuple[int, int]:
    major, minor = rule.split(".")
    return int(major), int(minor)


def format_table(counts: Counter[str]) -> str:
    """A Markdown table: rule, category, findings, reason (rules in numeric order)."""
    lines = ["| rule | category | findings | why |", "|---|---|---|---|"]
    for rule in sorted(counts, key=_rule_key):
        category, why = DEVIATIONS.get(rule, ("?", "NOT JUSTIFIED"))
        lines.append(f"| {rule} | {category} | {counts[rule]} | {why} |")
    return "\n".join(lines)


def cppcheck_version() -> str:
    """``cppcheck --version`` (e.g. ``Cppcheck 2.10``)."""
    cppcheck = shutil.which("cppcheck")
    if cppcheck is None:
        raise MisraUnavailable("cppcheck is not installed")
    done = subprocess.run(
        [cppcheck, "--version"], capture_output=True, text=True, timeout=60, check=False
    )
    return done.stdout.strip() or "cppcheck (version unknown)"


def misra_report(
    c_files: Sequence[Path], jobs: int = 2, folder: str = "generated/c"
) -> dict[str, Any]:
    """The findings per rule over ``c_files`` (in ``folder``, as the table names it) as
    JSON-ready data, with what the table needs beside them: the files, the cppcheck version
    and the documented deviations."""
    counts = misra_rules(c_files, jobs)
    return {
        "tool": cppcheck_version(),
        "options": "--addon=misra --std=c99",
        "folder": folder,
        "files": sorted(Path(f).name for f in c_files),
        "counts": {rule: counts[rule] for rule in sorted(counts, key=_rule_key)},
        "deviations": {
            rule: {"category": category, "why": why} for rule, (category, why) in DEVIATIONS.items()
        },
    }


def misra_markdown(data: dict[str, Any], command: str) -> str:
    """The report's JSON (:func:`misra_report`) as the documentation's table, headed by the
    command that wrote it: every rule reported or documented, its category, how often cppcheck
    reports it and why the emitted C departs from it. A reported rule without a deviation, or a
    deviation no longer reported, says so."""
    counts = data["counts"]
    deviations = data["deviations"]
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- {data['tool']}, `{data['options']}` (MISRA add-on without the rule texts: rule "
        f"numbers), over the {len(data['files'])} C files of `{data['folder']}`; "
        f"{sum(counts.values())} findings of {len(counts)} rules",
        "",
        "| rule | category | findings | why |",
        "|---|---|---|---|",
    ]
    for rule in sorted(set(counts) | set(deviations), key=_rule_key):
        entry = deviations.get(rule)
        category = entry["category"] if entry else "?"
        why = entry["why"] if entry else "**NOT JUSTIFIED**: no documented deviation"
        found = str(counts[rule]) if rule in counts else "0 (no longer reported)"
        out.append(f"| {rule} | {category} | {found} | {why} |")
    return "\n".join(out) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m gearsym.validation.checks.misra --out DIR``: the report over every emitted C
    file of ``generated/c`` (or ``--c-dir``) into ``DIR/misra.json`` and ``DIR/misra.md``."""
    import argparse

    parser = argparse.ArgumentParser(
        prog=COMMAND, description="MISRA C:2012 findings of the emitted C (cppcheck's add-on)"
    )
    parser.add_argument("--out", required=True, help="folder for misra.json and misra.md")
    parser.add_argument(
        "--c-dir", default="generated/c", help="the emitted C files (default: generated/c)"
    )
    parser.add_argument("--jobs", type=int, default=2, help="cppcheck's -j (default 2)")
    args = parser.parse_args(argv)
    sources = sorted(Path(args.c_dir).glob("*.c"))
    if not sources:
        print(f"{COMMAND}: {args.c_dir}: no C files", file=sys.stderr)
        return 2
    try:
        data = misra_report(sources, args.jobs, args.c_dir)
    except MisraUnavailable as err:
        print(f"{COMMAND}: {err}", file=sys.stderr)
        return 2
    command = " ".join([COMMAND, *(argv if argv is not None else sys.argv[1:])])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "misra.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    (out / "misra.md").write_text(misra_markdown(data, command), encoding="utf-8")
    counts = data["counts"]
    print(
        f"{sum(counts.values())} findings of {len(counts)} rules in {len(sources)} files; "
        f"wrote {out / 'misra.json'} and {out / 'misra.md'}"
    )
    undocumented = sorted(set(counts) - set(DEVIATIONS), key=_rule_key)
    if undocumented:
        print(f"rules without a documented deviation: {', '.join(undocumented)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
