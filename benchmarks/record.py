"""The measured rows of a benchmark as a JSON record: ``benchmarks/results/<bench>.json``.

Each ``bench_*.py`` takes :func:`begin` when it starts, builds its rows with :func:`row` and
writes them with :func:`record` when it has measured them (also when a target is missed; a
benchmark that stops with an error writes nothing, so the last record stays). The table of
``docs/results/benchmarks.md`` is rendered from these records by ``render_results.py``.

A row states what is measured, gearsym's value (a median when several runs were timed, with
its min-max spread) and unit, the peer and its value, the ratio gearsym / peer, the target
(its text and, when it has one, the number it is judged by) and the verdict, which is computed
here from the numbers: ``met`` or ``missed`` when the target has a number, ``reported`` when
there is none. The record holds the conditions of the run: date, load average at the start
and at the end (``os.getloadavg``), machine, Python, CasADi, SymPy and gcc versions.
"""

from __future__ import annotations

import json
import operator
import os
import platform
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

#: Where the records are written (committed with the rendered table).
RESULTS = Path(__file__).resolve().parent / "results"
#: The layout of a record; a change of meaning of any field changes it.
SCHEMA = 1
#: How a target's number is compared: ``quantity OP bound`` must hold for ``met``.
COMPARISONS: dict[str, Callable[[float, float], bool]] = {
    "<": operator.lt,
    "<=": operator.le,
    ">": operator.gt,
    ">=": operator.ge,
}
VERDICTS = ("met", "missed", "reported")


@dataclass(frozen=True)
class Target:
    """A target as the benchmark states it, and the number it is judged by.

    ``on`` is ``"value"`` (gearsym's value, in the row's unit) or ``"ratio"`` (gearsym / peer);
    the target is met when ``quantity op bound`` holds. A target with ``bound=None`` is text
    only (its row is ``reported``)."""

    text: str
    on: str = "value"
    op: str = "<="
    bound: float | None = None

    def __post_init__(self) -> None:
        if self.on not in ("value", "ratio"):
            raise ValueError(f"a target is judged on 'value' or 'ratio', not {self.on!r}")
        if self.op not in COMPARISONS:
            raise ValueError(f"unknown comparison {self.op!r} (one of {', '.join(COMPARISONS)})")

    def as_dict(self) -> dict[str, Any]:
        """The JSON form."""
        return {"text": self.text, "on": self.on, "op": self.op, "bound": self.bound}


def verdict(value: float | None, ratio: float | None, target: dict[str, Any] | None) -> str:
    """``met``/``missed`` from the numbers and a target's JSON form; ``reported`` if the target
    has no number (or there is no target). A quantity that was not measured misses."""
    if target is None or target.get("bound") is None:
        return "reported"
    quantity = value if target["on"] == "value" else ratio
    if quantity is None:
        return "missed"
    return "met" if COMPARISONS[target["op"]](quantity, target["bound"]) else "missed"


#: Significant digits kept of every measured number (far beyond what a timing resolves).
DIGITS = 6


def _round(x: float | None) -> float | None:
    return None if x is None else float(f"{float(x):.{DIGITS}g}")


def _median_and_spread(samples: Sequence[float]) -> tuple[float, list[float]]:
    values = [_round(v) for v in samples]
    return statistics.median(values), [min(values), max(values)]


def row(
    measured: str,
    value: float | None = None,
    unit: str = "",
    *,
    samples: Sequence[float] | None = None,
    runs: int | None = None,
    peer: str | None = None,
    peer_value: float | None = None,
    peer_samples: Sequence[float] | None = None,
    peer_runs: int | None = None,
    pair_ratios: Sequence[float] | None = None,
    target: Target | None = None,
) -> dict[str, Any]:
    """One measured row.

    Give either ``value`` (one number: a single run, a count, a size) or ``samples`` (the timed
    runs: the value is their median, with the min-max spread); likewise ``peer_value`` or
    ``peer_samples``. ``runs`` (``peer_runs``) states how many runs a ``value``
    (``peer_value``) derived from several stands on (default 1). The ratio is gearsym / peer:
    the ratio of the two values, or, when the runs were taken in alternating pairs, the median
    of ``pair_ratios`` (with their spread). The verdict is computed from the numbers and the
    target (:func:`verdict`)."""
    if value is not None and samples is not None:
        raise ValueError("give value or samples, not both")
    if peer_value is not None and peer_samples is not None:
        raise ValueError("give peer_value or peer_samples, not both")
    out: dict[str, Any] = {"measured": measured, "unit": unit}
    spread = None
    if samples is not None:
        value, spread = _median_and_spread(samples)
    value = _round(value)
    out |= {
        "value": value,
        "runs": len(samples) if samples is not None else (0 if value is None else runs or 1),
        "spread": spread,
        "samples": None if samples is None else [_round(v) for v in samples],
    }
    peer_spread = None
    if peer_samples is not None:
        peer_value, peer_spread = _median_and_spread(peer_samples)
    peer_value = _round(peer_value)
    if peer is not None:
        out["peer"] = {
            "name": peer,
            "value": peer_value,
            "runs": len(peer_samples) if peer_samples is not None else peer_runs or 1,
            "spread": peer_spread,
            "samples": None if peer_samples is None else [_round(v) for v in peer_samples],
        }
    else:
        out["peer"] = None
    ratio, ratio_of, ratio_spread, ratio_samples = None, None, None, None
    if pair_ratios is not None:
        ratio, ratio_spread = _median_and_spread(pair_ratios)
        ratio_of, ratio_samples = "pairs", [_round(v) for v in pair_ratios]
    elif value is not None and peer_value:
        ratio, ratio_of = _round(value / peer_value), "values"
    out["ratio"] = {
        "value": ratio,
        "of": ratio_of,
        "spread": ratio_spread,
        "samples": ratio_samples,
    }
    out["target"] = None if target is None else target.as_dict()
    out["verdict"] = verdict(out["value"], ratio, out["target"])
    return out


@dataclass(frozen=True)
class Start:
    """When a benchmark began and the machine's load then."""

    date: str
    load: tuple[float, float, float]
    clock: float = 0.0


def begin() -> Start:
    """Take the start of a benchmark (the first thing its ``main`` does)."""
    return Start(_now(), _load(), time.perf_counter())


def _now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _load() -> tuple[float, float, float]:
    one, five, fifteen = os.getloadavg()
    return round(one, 2), round(five, 2), round(fifteen, 2)


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def _gcc() -> str | None:
    if shutil.which("gcc") is None:
        return None
    proc = subprocess.run(["gcc", "-dumpfullversion"], capture_output=True, text=True, check=False)
    return proc.stdout.strip() or None


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def conditions(started: Start) -> dict[str, Any]:
    """The conditions of a run that began at ``started`` and ends now."""
    return {
        "date": started.date,
        "finished": _now(),
        "seconds": round(time.perf_counter() - started.clock, 1),
        "load_start": list(started.load),
        "load_end": list(_load()),
        "machine": f"{_cpu()}, {os.cpu_count()} CPUs, {platform.machine()}",
        "python": platform.python_version(),
        "casadi": _version("casadi"),
        "sympy": _version("sympy"),
        "gcc": _gcc(),
    }


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder and
    ``os.replace``: a reader sees the old file or the new one, never half of one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
        os.chmod(tmp, 0o644)  # mkstemp's 0o600 would be kept by the replace
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def record(
    name: str,
    rows: list[dict[str, Any]],
    *,
    started: Start,
    title: str,
    directory: Path = RESULTS,
) -> Path:
    """Write the record of benchmark ``name`` (``bench_x.py`` or ``bench_x``) with its ``rows``
    and the run's conditions to ``directory/bench_x.json``; returns the path. The command
    recorded carries the benchmark's options when it is the running script."""
    stem = Path(name).stem
    running = Path(sys.argv[0]).stem == stem
    arguments = sys.argv[1:] if running else []
    if not rows:
        raise ValueError(f"{stem}: a record needs at least one measured row")
    data = {
        "schema": SCHEMA,
        "benchmark": f"{stem}.py",
        "title": title,
        "command": shlex.join(["python", f"benchmarks/{stem}.py", *arguments]),
        "conditions": conditions(started),
        "rows": rows,
    }
    path = directory / f"{stem}.json"
    write_atomic(path, to_json(data))
    return path


_NUMBERS = re.compile(r"\[\s*((?:-?[\d.eE+-]+|null)(?:,\s*(?:-?[\d.eE+-]+|null))*)\s*\]")


def to_json(data: dict[str, Any]) -> str:
    """The record's text: indented, each list of numbers on one line."""
    text = json.dumps(data, indent=1, ensure_ascii=False)
    one_line = _NUMBERS.sub(
        lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text
    )
    return one_line + "\n"
