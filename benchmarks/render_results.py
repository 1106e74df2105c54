"""Render the benchmarks' JSON records (``benchmarks/results/*.json``, written by each
``bench_*.py`` through ``record.py``) into the table of ``docs/results/benchmarks.md``.

Run at the end of ``benchmarks/run_all.py`` (``make bench``) and runnable alone:
``python benchmarks/render_results.py``. The output depends on the records only, so rendering
the committed records reproduces the committed table byte for byte
(``tests/test_bench_results.py``). A benchmark that was skipped (its tools missing) keeps its
last record, and its date says when that was measured.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from record import RESULTS, SCHEMA, verdict, write_atomic

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "results" / "benchmarks.md"
COMMAND = "python benchmarks/render_results.py"
#: Benchmarks that run_all runs but that write no record, and why (none at present).
UNRECORDED: dict[str, str] = {}
#: Units whose values are counted (shown as whole numbers).
COUNTS = ("B", "instructions", "operations", "sources")
#: Units of time: a single run says so.
TIMES = ("s", "ns")


def load_records(directory: Path = RESULTS) -> list[dict[str, Any]]:
    """Every record in ``directory``, by benchmark name; a record of another schema, or whose
    stated verdicts do not follow from its numbers, is refused."""
    records = []
    for path in sorted(directory.glob("bench_*.json")):
        data = json.loads(path.read_text(encoding="utf-8"))
        if data.get("schema") != SCHEMA:
            raise ValueError(f"{path.name}: schema {data.get('schema')!r}, expected {SCHEMA}")
        if data["benchmark"] != f"{path.stem}.py":
            raise ValueError(f"{path.name}: names benchmark {data['benchmark']!r}")
        for r in data["rows"]:
            expected = verdict(r["value"], r["ratio"]["value"], r["target"])
            if r["verdict"] != expected:
                raise ValueError(
                    f"{path.name}: {r['measured']!r} says {r['verdict']!r}, its numbers "
                    f"{expected!r}"
                )
        records.append(data)
    return records


def number(x: float, unit: str = "") -> str:
    """A measured number to about three significant digits (counts whole, grouped by
    thousands with a space)."""
    if unit in COUNTS and float(x).is_integer():
        return f"{int(x):,}".replace(",", " ")
    a = abs(x)
    if a == 0:
        return "0"
    if a >= 1000:
        return f"{x:,.0f}".replace(",", " ")
    if a >= 100:
        return f"{x:.0f}"
    if a >= 10:
        return f"{x:.1f}"
    if a >= 1:
        return f"{x:.2f}"
    if a >= 0.001:
        return f"{x:.3g}"
    mantissa, exponent = f"{x:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def _quantity(value: float | None, unit: str, runs: int, spread: list[float] | None) -> str:
    if value is None:
        return "not measured"
    text = number(value, unit) + (f" {unit}" if unit else "")
    if spread is not None and runs > 1:
        text += f" [{number(spread[0], unit)}–{number(spread[1], unit)}], median of {runs}"
    elif runs > 1:
        text += f" ({runs} runs)"
    elif unit in TIMES:
        text += " (1 run)"
    return text


def ratio_text(ratio: dict[str, Any]) -> str:
    """gearsym / peer, with the spread of the pair ratios when they were taken in pairs."""
    value = ratio["value"]
    if value is None:
        return "—"
    if value >= 10:
        text = f"{value:.0f}×"
    elif value >= 0.1:
        text = f"{value:.2f}×"
    else:
        text = f"{value:.2g}×"
    if ratio["of"] == "pairs":
        low, high = ratio["spread"]
        text += f" [{low:.2f}–{high:.2f}], median of the pairs"
    return text


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def row_cells(r: dict[str, Any]) -> list[str]:
    """The table cells of one measured row."""
    peer = r["peer"]
    peer_text = "—"
    if peer is not None:
        peer_text = f"{peer['name']}: " + _quantity(
            peer["value"], r["unit"], peer["runs"], peer["spread"]
        )
    target = r["target"]["text"] if r["target"] else "—"
    shown = {"met": "met", "missed": "**missed**", "reported": "reported"}[r["verdict"]]
    cells = [
        r["measured"],
        _quantity(r["value"], r["unit"], r["runs"], r["spread"]),
        peer_text,
        ratio_text(r["ratio"]),
        target,
        shown,
    ]
    return [_cell(c) for c in cells]


def _date(stamp: str) -> str:
    return stamp.replace("T", " ")[:16] + " UTC"


def _counts(data: dict[str, Any]) -> dict[str, int]:
    counts = dict.fromkeys(("met", "missed", "reported"), 0)
    for r in data["rows"]:
        counts[r["verdict"]] += 1
    return counts


def _load(values: list[float]) -> str:
    return " / ".join(f"{v:.2f}" for v in values)


def render(records: list[dict[str, Any]], unrecorded: dict[str, str] | None = None) -> str:
    """The Markdown of ``docs/results/benchmarks.md`` from the records (and the benchmarks that
    write none, with the reason)."""
    unrecorded = UNRECORDED if unrecorded is None else unrecorded
    lines = [
        f"<!-- Written by `{COMMAND}` (the end of `make bench`) from benchmarks/results/*.json."
        " Do not edit by hand: run the benchmarks, or the renderer. -->",
        "",
        "| benchmark | measured | load average (1 min), start → end | met | missed | reported |",
        "|---|---|---|---|---|---|",
    ]
    for data in records:
        c = data["conditions"]
        counts = _counts(data)
        lines.append(
            f"| `{data['benchmark']}`: {_cell(data['title'])} | {_date(c['date'])} | "
            f"{c['load_start'][0]:.2f} → {c['load_end'][0]:.2f} | {counts['met']} | "
            f"{counts['missed']} | {counts['reported']} |"
        )
    for name, reason in sorted(unrecorded.items()):
        lines.append(f"| `{name}`: no record ({_cell(reason)}) | — | — | — | — | — |")
    lines += [
        "",
        "The ratio is gearsym's value divided by the peer's (below 1: gearsym takes less time, "
        "code or operations); where the runs alternated in pairs it is the median of the pair "
        "ratios. A verdict is computed from the numbers and the target's bound: *met*, "
        "*missed*, or *reported* where there is no target.",
    ]
    for data in records:
        c = data["conditions"]
        versions = ", ".join(
            f"{label} {c[key]}"
            for label, key in (
                ("Python", "python"),
                ("CasADi", "casadi"),
                ("SymPy", "sympy"),
                ("gcc", "gcc"),
            )
            if c.get(key)
        )
        lines += [
            "",
            f"### {data['title']} (`{data['benchmark']}`)",
            "",
            f"Measured {_date(c['date'])} by `{data['command']}` in {c['seconds']:.0f} s; load "
            f"average (1, 5, 15 min) {_load(c['load_start'])} at the start, "
            f"{_load(c['load_end'])} at the end; {c['machine']}; {versions}.",
            "",
            "| what | gearsym | peer | gearsym / peer | target | verdict |",
            "|---|---|---|---|---|---|",
        ]
        lines += ["| " + " | ".join(row_cells(r)) + " |" for r in data["rows"]]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Render the records into the Markdown table (``--check``: only compare)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS, help="folder of the records")
    parser.add_argument("--out", type=Path, default=OUT, help="the Markdown file written")
    parser.add_argument(
        "--check", action="store_true", help="fail if the file differs, write nothing"
    )
    args = parser.parse_args(argv)
    text = render(load_records(args.results))
    if args.check:
        current = args.out.read_text(encoding="utf-8") if args.out.exists() else None
        if current != text:
            print(f"{args.out} is not the rendering of {args.results}: run {COMMAND}")
            return 1
        return 0
    write_atomic(args.out, text)
    print(f"benchmark table: {args.out} (from {args.results})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
