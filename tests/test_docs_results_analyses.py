"""The analyses' result tables are written by commands, not typed (as the estimators' are,
tests/test_docs_results.py): each Markdown file under ``docs/results`` that ``gearsym fim``, the
MISRA check, the TCU task's Cortex-M4F run or the freewheel comparison wrote is rendered again
from the JSON the same command wrote beside it, byte for byte; its first line names the
command, ``make results`` runs that command into the folder the file is named after, and a
page of the documentation includes the file."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from gearsym.validation.checks.misra import DEVIATIONS, misra_markdown
from gearsym.validation.checks.qemu_control import task_markdown
from gearsym.validation.checks.qemu_tasks import tasks_markdown
from gearsym.validation.sim.one_way_comparison import one_way_markdown
from gearsym.validation.studies.fisher import fim_markdown
from gearsym.validation.studies.hybrid_fisher import hybrid_fim_markdown

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
HEADER = re.compile(r"^<!-- written by `(?P<command>[^`]+)`; do not edit by hand")

Renderer = Callable[[dict[str, Any], str], str]

#: file name pattern → (the renderer, how its command starts)
KINDS: dict[str, tuple[Renderer, str]] = {
    "fim_hybrid_*.md": (hybrid_fim_markdown, "gearsym fim "),
    "fim_open_loop_*.md": (fim_markdown, "gearsym fim --open-loop "),
    "misra.md": (misra_markdown, "python -m gearsym.validation.checks.misra "),
    "tcu_task_*.md": (task_markdown, "python -m gearsym.validation.checks.qemu_control "),
    "tcu_tasks.md": (tasks_markdown, "python -m gearsym.validation.checks.qemu_tasks "),
    "one_way_*.md": (one_way_markdown, "python -m gearsym.validation.sim.one_way_comparison "),
}
TABLES = sorted((t, *kind) for pattern, kind in KINDS.items() for t in RESULTS.glob(pattern))

#: Every table the pages include (tests/test_docs_results.py covers the estimators' own).
EXPECTED = {
    "fim_hybrid_2_3.md": "hybrid.md",
    "fim_hybrid_2_3_known_initial_state.md": "hybrid.md",
    "fim_open_loop_2_3.md": "sensitivities.md",
    "fim_open_loop_2_3_carry_over.md": "sensitivities.md",
    "misra.md": "misra.md",
    "one_way_simpson.md": "hybrid.md",
    "tcu_task_2_3.md": "control.md",
    "tcu_task_3_2.md": "control.md",
    "tcu_task_3_4.md": "control.md",
    "tcu_tasks.md": "control.md",
}


def _command(table: Path) -> str:
    first = table.read_text(encoding="utf-8").splitlines()[0]
    match = HEADER.match(first)
    assert match, f"{table.name}: no 'written by' header: {first!r}"
    return match["command"]


def _results_recipe() -> list[str]:
    """The command lines of the Makefile's ``results`` target, ``$(BIN)/`` removed."""
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = text.split("\nresults:", 1)[1].split("\n\n", 1)[0]
    return [
        line.strip().replace("$(BIN)/", "")
        for line in recipe.splitlines()[1:]
        if line.startswith("\t")
    ]


@pytest.mark.parametrize(("table", "render", "prefix"), TABLES, ids=[t[0].name for t in TABLES])
def test_an_analysis_table_is_its_json_rendered(table, render, prefix):
    command = _command(table)
    assert command.startswith(prefix), command
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    assert render(data, command) == table.read_text(encoding="utf-8")
    # make results runs exactly this command, into the folder the table is named after
    assert command in _results_recipe(), f"make results does not run {command!r}"
    out = command.split("--out ", 1)[1].split()[0]
    assert Path(out).name == table.stem, (out, table.name)


def test_the_docs_include_the_analysis_tables():
    assert {t[0].name for t in TABLES} == set(EXPECTED)
    for name, page in EXPECTED.items():
        text = (ROOT / "docs" / page).read_text(encoding="utf-8")
        assert f'--8<-- "results/{name}"' in text, (page, name)


def test_the_misra_table_has_the_documented_deviations():
    """The committed report carries the deviations of validation/checks/misra.py as they are
    now: a changed reason or a new deviation means running the check again."""
    data = json.loads((RESULTS / "misra.json").read_text(encoding="utf-8"))
    assert data["deviations"] == {
        rule: {"category": category, "why": why} for rule, (category, why) in DEVIATIONS.items()
    }
    assert not set(data["counts"]) - set(DEVIATIONS)


def test_a_hand_edit_is_caught():
    """The check has teeth: one changed digit in a table, or in the JSON it is rendered from,
    no longer matches."""
    table = RESULTS / "fim_hybrid_2_3.md"
    text = table.read_text(encoding="utf-8")
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    command = _command(table)
    assert hybrid_fim_markdown(data, command) == text
    row = next(line for line in text.splitlines() if line.startswith("| torque phase |"))
    edited = text.replace(row, re.sub(r"\d", lambda m: str((int(m[0]) + 1) % 10), row, count=1))
    assert edited != text and hybrid_fim_markdown(data, command) != edited
    torque = next(w for w in data["windows"] if w["name"] == "torque phase")
    torque["gamma"]["m_veh"] *= 1.5
    assert hybrid_fim_markdown(data, command) != text
