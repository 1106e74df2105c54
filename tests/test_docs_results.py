"""The documentation's result tables are written by commands, not typed: each Markdown file
under ``docs/results`` that a command wrote is rendered again from the JSON the same command
wrote beside it, byte for byte, and its first line names the command."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from gearsym.validation.studies.estimation.fleet_report import fleet_markdown
from gearsym.validation.studies.estimation.markdown import monte_carlo_markdown, uio_markdown

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
HEADER = re.compile(r"^<!-- written by `(?P<command>[^`]+)`; do not edit by hand")

FLEET_TABLES = sorted(RESULTS.glob("fleet_*.md"))


@pytest.mark.parametrize("table", FLEET_TABLES, ids=lambda p: p.name)
def test_a_fleet_table_is_its_json_rendered(table):
    first = table.read_text(encoding="utf-8").splitlines()[0]
    match = HEADER.match(first)
    assert match, f"{table.name}: no 'written by' header: {first!r}"
    command = match["command"]
    assert command.startswith("gearsym estimate ") and "--fleet" in command
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    assert fleet_markdown(data, command) == table.read_text(encoding="utf-8")
    # the command that wrote it is the one make results runs
    makefile = (RESULTS.parents[1] / "Makefile").read_text(encoding="utf-8")
    assert command.removeprefix("gearsym ") in makefile


MONTE_CARLO_TABLES = sorted(RESULTS.glob("montecarlo_*.md"))


@pytest.mark.parametrize("table", MONTE_CARLO_TABLES, ids=lambda p: p.name)
def test_a_monte_carlo_table_is_its_json_rendered(table):
    first = table.read_text(encoding="utf-8").splitlines()[0]
    match = HEADER.match(first)
    assert match, f"{table.name}: no 'written by' header: {first!r}"
    command = match["command"]
    assert command.startswith("gearsym estimate ") and "--runs" in command
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    assert monte_carlo_markdown(data, command) == table.read_text(encoding="utf-8")
    makefile = (RESULTS.parents[1] / "Makefile").read_text(encoding="utf-8")
    assert command.removeprefix("gearsym ") in makefile


UIO_TABLES = sorted(RESULTS.glob("uio_*.md"))


@pytest.mark.parametrize("table", UIO_TABLES, ids=lambda p: p.name)
def test_a_uio_table_is_its_json_rendered(table):
    first = table.read_text(encoding="utf-8").splitlines()[0]
    match = HEADER.match(first)
    assert match, f"{table.name}: no 'written by' header: {first!r}"
    command = match["command"]
    assert command.startswith("gearsym estimate --filter uio")
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    assert uio_markdown(data, command) == table.read_text(encoding="utf-8")
    makefile = (RESULTS.parents[1] / "Makefile").read_text(encoding="utf-8")
    assert command.removeprefix("gearsym ") in makefile


def test_the_docs_have_monte_carlo_results():
    names = {t.name for t in MONTE_CARLO_TABLES}
    assert {"montecarlo_ekf_2_3.md", "montecarlo_euio_2_3.md"} <= names
    assert {t.name for t in UIO_TABLES} == {
        "uio_2_3_10ms.md",
        "uio_2_3_1ms.md",
        "uio_2_3_noise.md",
    }


def test_the_docs_have_fleet_results():
    assert FLEET_TABLES, "make results writes docs/results/fleet_ekf_2_3.md"


def test_a_hand_edit_is_caught(tmp_path):
    """The check has teeth: one changed digit in a rendered table no longer matches."""
    (table,) = [t for t in FLEET_TABLES if t.name == "fleet_ekf_2_3.md"]
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    command = HEADER.match(table.read_text(encoding="utf-8").splitlines()[0])["command"]
    data["parameters"]["m_veh"]["final"]["rmse"] *= 1.5
    assert fleet_markdown(data, command) != table.read_text(encoding="utf-8")
