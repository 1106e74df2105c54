"""The documentation's result tables are written by commands, not typed: each Markdown file
under ``docs/results`` that an estimator command wrote is rendered again from the JSON the same
command wrote beside it, byte for byte, its first line names the command, and ``make results``
runs that command."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from gearsym.validation.studies.estimation.fleet_report import fleet_markdown
from gearsym.validation.studies.estimation.markdown import monte_carlo_markdown, uio_markdown

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
HEADER = re.compile(r"^<!-- written by `(?P<command>[^`]+)`; do not edit by hand")

#: (file pattern, renderer, what the command must contain)
KINDS: tuple[tuple[str, Callable[[dict[str, Any], str], str], str], ...] = (
    ("fleet_*.md", fleet_markdown, "--fleet"),
    ("montecarlo_*.md", monte_carlo_markdown, "--runs"),
    ("uio_*.md", uio_markdown, "--filter uio"),
)

TABLES = [
    (table, render, marker)
    for pattern, render, marker in KINDS
    for table in sorted(RESULTS.glob(pattern))
]


def _command(table: Path) -> str:
    first = table.read_text(encoding="utf-8").splitlines()[0]
    match = HEADER.match(first)
    assert match, f"{table.name}: no 'written by' header: {first!r}"
    return match["command"]


@pytest.mark.parametrize(
    ("table", "render", "marker"), TABLES, ids=lambda v: getattr(v, "name", "")
)
def test_a_result_table_is_its_json_rendered_by_the_command_make_results_runs(
    table, render, marker
):
    command = _command(table)
    assert command.startswith("gearsym estimate ") and marker in command
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    assert render(data, command) == table.read_text(encoding="utf-8")
    makefile = (RESULTS.parents[1] / "Makefile").read_text(encoding="utf-8")
    assert command.removeprefix("gearsym ") in makefile


def test_the_docs_have_every_estimator_table():
    names = {table.name for table, _, _ in TABLES}
    assert {
        "fleet_ekf_2_3.md",
        "fleet_ekf_2_3_map_scale.md",
        "montecarlo_ekf_2_3.md",
        "montecarlo_euio_2_3.md",
        "uio_2_3_10ms.md",
        "uio_2_3_1ms.md",
        "uio_2_3_noise.md",
    } <= names


def test_a_hand_edit_is_caught():
    """The check has teeth: one changed number in a rendered table no longer matches."""
    table = RESULTS / "fleet_ekf_2_3.md"
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    data["parameters"]["m_veh"]["final"]["rmse"] *= 1.5
    assert fleet_markdown(data, _command(table)) != table.read_text(encoding="utf-8")
