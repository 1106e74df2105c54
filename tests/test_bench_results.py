"""The table of benchmark results is written by the benchmarks, not typed.

Each ``benchmarks/bench_*.py`` records its measured rows in ``benchmarks/results/<bench>.json``
(``benchmarks/record.py``) and ``benchmarks/render_results.py`` renders them into
``docs/results/benchmarks.md``, which ``docs/benchmarks.md`` includes. Checked here, from the
committed files, without running a benchmark: the committed table is the rendering of the
committed records byte for byte (so an edit by hand fails); every verdict and ratio follows
from the numbers beside it (recomputed here, not by the code that wrote them); every benchmark
``run_all.py`` runs has a record or a stated reason; and the renderer does say *missed*.
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
RESULTS = BENCH / "results"
TABLE = ROOT / "docs" / "results" / "benchmarks.md"
sys.path.insert(0, str(BENCH))

import record  # noqa: E402
import render_results  # noqa: E402


def _records() -> list[tuple[str, dict]]:
    return [
        (p.name, json.loads(p.read_text(encoding="utf-8")))
        for p in sorted(RESULTS.glob("bench_*.json"))
    ]


def _rows() -> list:
    """Every recorded row, as a pytest parameter named by its benchmark and row number."""
    return [
        pytest.param(r, id=f"{Path(name).stem}-{k}")
        for name, data in _records()
        for k, r in enumerate(data["rows"])
    ]


def test_the_committed_table_is_the_rendering_of_the_committed_records():
    rendered = render_results.render(render_results.load_records(RESULTS))
    committed = TABLE.read_bytes()
    assert rendered.encode("utf-8") == committed, (
        "docs/results/benchmarks.md is not the rendering of benchmarks/results/*.json: run "
        "`python benchmarks/render_results.py` (never edit the table by hand)"
    )
    first = committed.decode("utf-8").splitlines()[0]
    assert first.startswith("<!--") and "render_results.py" in first and "by hand" in first


#: The comparisons, written out here independently of record.COMPARISONS.
HOLDS = {
    "<": lambda q, b: q < b,
    "<=": lambda q, b: q <= b,
    ">": lambda q, b: q > b,
    ">=": lambda q, b: q >= b,
}


@pytest.mark.parametrize("row", _rows())
def test_every_verdict_follows_from_its_numbers(row):
    label = row["measured"]
    target = row["target"]
    if target is None or target["bound"] is None:
        expected = "reported"
    else:
        quantity = row["value"] if target["on"] == "value" else row["ratio"]["value"]
        if quantity is None:
            expected = "missed"
        else:
            expected = "met" if HOLDS[target["op"]](quantity, target["bound"]) else "missed"
    assert row["verdict"] == expected, label


@pytest.mark.parametrize("row", _rows())
def test_every_median_spread_and_ratio_follows_from_its_runs(row):
    label = row["measured"]
    for part in (row, row["peer"]):
        if part is None or part["samples"] is None:
            continue
        samples = part["samples"]
        assert part["runs"] == len(samples), label
        assert part["value"] == pytest.approx(statistics.median(samples), rel=1e-12), label
        assert part["spread"] == [min(samples), max(samples)], label
    ratio = row["ratio"]
    if ratio["of"] == "values":
        assert ratio["value"] == pytest.approx(row["value"] / row["peer"]["value"], rel=1e-5)
    elif ratio["of"] == "pairs":
        assert ratio["value"] == pytest.approx(statistics.median(ratio["samples"]), rel=1e-12)
        assert len(ratio["samples"]) == row["runs"] == row["peer"]["runs"], label
    else:
        assert ratio["value"] is None, label
    assert row["verdict"] in record.VERDICTS, label


def test_every_benchmark_run_all_runs_has_a_record_or_a_stated_reason():
    scripts = {p.name for p in BENCH.glob("bench_*.py")}  # what run_all.py runs
    assert scripts, "no benchmarks found"
    recorded = {data["benchmark"] for _, data in _records()}
    unexplained = sorted(scripts - recorded - set(render_results.UNRECORDED))
    assert not unexplained, f"benchmarks without a record or a stated reason: {unexplained}"
    assert all(reason.strip() for reason in render_results.UNRECORDED.values())
    assert recorded <= scripts, f"records of benchmarks that do not exist: {recorded - scripts}"
    for name in sorted(scripts - set(render_results.UNRECORDED)):
        source = (BENCH / name).read_text(encoding="utf-8")
        assert "record(__file__" in source, f"{name} does not write its record"


def test_each_record_states_its_conditions():
    for name, data in _records():
        c = data["conditions"]
        assert data["benchmark"] == name.replace(".json", ".py")
        assert len(c["load_start"]) == len(c["load_end"]) == 3, name
        assert c["date"] <= c["finished"], name
        assert c["python"] and c["casadi"], name


def _hand_made(directory: Path) -> Path:
    rows = [
        record.row(
            "a step that is too slow",
            unit="s",
            samples=[1.5, 1.2, 1.4],
            peer="a peer",
            peer_samples=[1.0, 1.1, 0.9],
            target=record.Target("≤ peer", "ratio", "<=", 1.0),
        ),
        record.row("code that fits", 900, "B", target=record.Target("< 1 KB", "value", "<", 1024)),
    ]
    return record.record(
        "bench_hand_made", rows, started=record.begin(), title="Hand-made", directory=directory
    )


def test_the_renderer_says_missed_for_a_missed_target(tmp_path):
    path = _hand_made(tmp_path)
    data = json.loads(path.read_text(encoding="utf-8"))
    assert [r["verdict"] for r in data["rows"]] == ["missed", "met"]
    text = render_results.render(render_results.load_records(tmp_path), {})
    slow = next(line for line in text.splitlines() if line.startswith("| a step that is too"))
    fits = next(line for line in text.splitlines() if line.startswith("| code that fits"))
    assert slow.endswith("| **missed** |"), slow
    assert "1.40 s [1.20–1.50], median of 3" in slow and "1.40×" in slow
    assert fits.endswith("| met |") and "missed" not in fits
    assert "| `bench_hand_made.py`: Hand-made |" in text and "| 1 | 1 | 0 |" in text


def test_a_verdict_edited_by_hand_is_refused(tmp_path):
    path = _hand_made(tmp_path)
    data = json.loads(path.read_text(encoding="utf-8"))
    data["rows"][0]["verdict"] = "met"
    path.write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(ValueError, match="its numbers 'missed'"):
        render_results.load_records(tmp_path)


def test_the_record_is_replaced_whole(tmp_path):
    target = tmp_path / "bench_x.json"
    target.write_text("old", encoding="utf-8")
    record.write_atomic(target, "new\n")
    assert target.read_text(encoding="utf-8") == "new\n"
    assert [p.name for p in tmp_path.iterdir()] == ["bench_x.json"]  # no temporary file left


def test_the_benchmarks_page_includes_the_table_and_types_none():
    page = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    assert '--8<-- "results/benchmarks.md"' in page
    typed = [line for line in page.splitlines() if line.lstrip().startswith("|")]
    assert not typed, f"docs/benchmarks.md types a table: {typed[:2]}"
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    # the README's one table is a definition (the shift element kinds), not a measurement
    lines = readme.splitlines()
    headers = [
        line
        for k, line in enumerate(lines)
        if line.lstrip().startswith("|") and not (k > 0 and lines[k - 1].lstrip().startswith("|"))
    ]
    kinds = "| `kind` | joins | carries torque | statuses (hybrid model) | data it needs "
    assert headers == [kinds + "| commanded by |"]
