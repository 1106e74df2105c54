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
from gearsym.validation.sim.drive_report import drive_markdown
from gearsym.validation.studies.control.report import control_markdown
from gearsym.validation.studies.drive_fleet import drive_fleet_markdown
from gearsym.validation.studies.estimation.fleet_report import fleet_markdown
from gearsym.validation.studies.estimation.markdown import monte_carlo_markdown, uio_markdown

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
HEADER = re.compile(r"^<!-- written by `(?P<command>[^`]+)`; do not edit by hand")

#: (file pattern, renderer, what the command must contain); a table takes the first pattern
#: it matches
KINDS: tuple[tuple[str, Callable[[dict[str, Any], str], str], str], ...] = (
    ("drive_*_fleet.md", drive_fleet_markdown, "--runs"),
    ("fleet_*.md", fleet_markdown, "--fleet"),
    ("montecarlo_*.md", monte_carlo_markdown, "--runs"),
    ("uio_*.md", uio_markdown, "--filter uio"),
    ("drive_*.md", drive_markdown, "drive --cycle"),
    ("control_*.md", control_markdown, "--fleet"),
)

TABLES = [
    next((table, render, marker) for pattern, render, marker in KINDS if table.match(pattern))
    for table in sorted(RESULTS.glob("*.md"))
    if any(table.match(pattern) for pattern, _, _ in KINDS)
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
    assert command.startswith(("gearsym estimate ", "gearsym drive ", "gearsym control "))
    assert marker in command
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    assert render(data, command) == table.read_text(encoding="utf-8")
    makefile = (RESULTS.parents[1] / "Makefile").read_text(encoding="utf-8")
    assert command.removeprefix("gearsym ") in makefile


#: Every estimator table and the page that includes it.
EXPECTED = {
    "fleet_ekf_2_3.md": "fleet.md",
    "fleet_ekf_2_3_map_scale.md": "fleet.md",
    "fleet_ekf_2_3_augmented.md": "fleet.md",
    "fleet_ekf_2_3_tooth_wheels.md": "fleet.md",
    "fleet_ekf_3_4_input_mean.md": "fleet.md",
    "fleet_ekf_3_4_map_scale.md": "fleet.md",
    "fleet_ekf_1_2_map_scale.md": "fleet.md",
    "montecarlo_ekf_2_3.md": "ekf.md",
    "montecarlo_ekf_2_3_1ms.md": "ekf.md",
    "montecarlo_ekf_2_3_prior_draws.md": "ekf.md",
    "montecarlo_ekf_2_3_reference_modes.md": "ekf.md",
    "montecarlo_ekf_2_3_prior_draws_reference_modes.md": "euio.md",
    "montecarlo_euio_2_3.md": "euio.md",
    "montecarlo_euio_2_3_reference_modes.md": "euio.md",
    "montecarlo_euio_2_3_prior_draws.md": "euio.md",
    "montecarlo_euio_2_3_prior_draws_reference_modes.md": "euio.md",
    "uio_2_3_10ms.md": "uio.md",
    "uio_2_3_1ms.md": "uio.md",
    "uio_2_3_noise.md": "uio.md",
    "drive_wltc3b.md": "drive.md",
    "drive_wltc3b_fleet_10000.md": "drive.md",
    "drive_wltc3b_fleet.md": "drive.md",
    "control_2_3.md": "control.md",
    "control_2_3_cold.md": "control.md",
    "control_3_4.md": "control.md",
    "control_3_2.md": "control.md",
}


def test_the_docs_have_every_estimator_table():
    assert {table.name for table, _, _ in TABLES} == set(EXPECTED)
    for name, page in EXPECTED.items():
        text = (RESULTS.parent / page).read_text(encoding="utf-8")
        assert f'--8<-- "results/{name}"' in text, (page, name)


def test_a_new_monte_carlo_table_runs_into_the_folder_it_is_named_after():
    """The tables added with the switch table (issue 25) are written into a folder of their
    own name, so ``make results`` copies each to the file it is named after."""
    for table, _, _ in TABLES:
        if table.stem.startswith("montecarlo_") and table.stem not in (
            "montecarlo_ekf_2_3",
            "montecarlo_euio_2_3",
        ):
            assert _command(table).endswith(f"--out build/results/{table.stem}"), table.name


def test_the_switch_table_is_the_json_s_events():
    """With the filter's own modes the Monte-Carlo table says, per switch of the truth, in how
    many runs the filter found it and how late, from the JSON's ``events``."""
    table = RESULTS / "montecarlo_ekf_2_3.md"
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    text = table.read_text(encoding="utf-8")
    assert data["events"]
    for ev in data["events"]:
        if ev.get("t_reference") is None:
            continue
        row = (
            f"| {ev['element']} {ev['kind']} | {ev['t_reference']:.4f} s | "
            f"{ev['detected_runs']} of {ev['runs']} runs | {ev['error_ms_mean']:+.1f} ms |"
        )
        assert row in text, row


def test_a_hand_edit_is_caught():
    """The check has teeth: one changed number in a rendered table no longer matches."""
    table = RESULTS / "fleet_ekf_2_3.md"
    data = json.loads(table.with_suffix(".json").read_text(encoding="utf-8"))
    data["parameters"]["m_veh"]["final"]["rmse"] *= 1.5
    assert fleet_markdown(data, _command(table)) != table.read_text(encoding="utf-8")


#: The tables typed into the pages on purpose: inputs and definitions (targets, limits, set
#: kinds, the thesis' printed values, published ratios, folders) and the exact findings of the
#: analyses that tests assert (existence, rank), none a measured number. Any other table of a
#: page is a result and is written by a command (``make results``) into ``docs/results``.
TYPED_TABLES = {
    # definitions: what each strategy is told and learns
    (
        "control.md",
        "| strategy | what the controller is told before a shift | what it learns after it |",
    ),
    ("verification.md", "| planted | where | fast tests that fail |"),
    ("drive.md", "| name | source | published facts |"),
    ("architecture.md", "| folder | modules | what it holds |"),
    ("architecture.md", "| stage | module | thesis |"),
    ("development.md", "| target | what it does |"),
    ("ekf.md", "| case | reproduce | tested |"),
    ("euio.md", "| parameter | gear 2 | torque phase | speed phase | gear 3 |"),
    (
        "examples.md",
        "| box | file | source of layout, ratios / teeth | ratios (reverse; forward) |",
    ),
    ("limits.md", "| what | limit | why |"),
    ("observability.md", "| set | (4.12) | reproduce |"),
    (
        "README.md",
        "| `kind` | joins | carries torque | statuses (hybrid model) | data it needs | "
        "commanded by |",
    ),
    (
        "set-kinds.md",
        "| kind | stick diagram of a one-set description | Willis relation (carrier frame) |",
    ),
    ("set-kinds.md", "| kind | extra keys | checked (module units) |"),
    ("thesis-slips.md", "| where | printed | status | test / why |"),
    ("uio.md", "| unknown inputs (2-3 shift) | gear 2 | torque and speed phase | gear 3 |"),
}


def _table_headers(text: str) -> list[str]:
    """The header row of every Markdown table outside fenced code."""
    lines, fenced, headers = text.splitlines(), False, []
    for line, following in zip(lines, [*lines[1:], ""], strict=True):
        if line.lstrip().startswith("```"):
            fenced = not fenced
        elif not fenced and line.startswith("|") and re.fullmatch(r"\|[-:| ]+\|", following):
            headers.append(line)
    return headers


def test_no_result_table_is_typed():
    """Issue 25: a table of measured results is written by the command that measures it. A
    page's typed table is one of the inputs and definitions above; a new table of results goes
    to ``make results`` and is included (``--8<-- "results/..."``)."""
    root = RESULTS.parents[1]
    pages = [*sorted((root / "docs").glob("*.md")), root / "README.md"]
    found = {
        (page.name, header)
        for page in pages
        for header in _table_headers(page.read_text(encoding="utf-8"))
    }
    assert not found - TYPED_TABLES, "typed tables: write them with a command (make results)"
    assert not TYPED_TABLES - found, "gone from the pages: remove them from TYPED_TABLES"
    assert _table_headers("| a |\n|---|\n| 1 |\n```\n| b |\n|---|\n```\n") == ["| a |"]
