"""Start-up cost of the light commands (issue 12): `gearsym ratios` and `gearsym model`
against the bare `python -c "import sympy"` they cannot avoid, as whole processes.

The peer runs in the same session, alternating with each command (A B A B …, rotated), so the
ratio holds when the machine's speed drifts; medians with min–max. Target: `ratios` and
`model` ≤ 1.3× the SymPy import. `gearsym --help` is reported beside them (no SymPy at all).
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
ROUNDS = 7
TARGET = 1.3


def wall(argv: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(argv, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> int:
    peer = [PYTHON, "-c", "import sympy"]
    commands = {
        "gearsym ratios": [PYTHON, "-m", "gearsym", "ratios"],
        "gearsym model": [PYTHON, "-m", "gearsym", "model"],
        "gearsym --help": [PYTHON, "-m", "gearsym", "--help"],
    }
    ok = True
    print(f"whole-process wall time, median [min–max] of {ROUNDS} alternating runs")
    for label, argv in commands.items():
        wall(argv), wall(peer)  # warm the file cache
        ours, theirs, ratios = [], [], []
        for r in range(ROUNDS):
            pair = (argv, peer) if r % 2 == 0 else (peer, argv)
            first, second = wall(pair[0]), wall(pair[1])
            a, b = (first, second) if r % 2 == 0 else (second, first)
            ours.append(a)
            theirs.append(b)
            ratios.append(a / b)
        ratio = statistics.median(ratios)
        gated = label != "gearsym --help"
        met = ratio <= TARGET or not gated
        ok &= met
        verdict = f"target ≤ {TARGET}x: {'met' if met else 'MISSED'}" if gated else "(no target)"
        print(
            f"  {label:<16} {statistics.median(ours):5.2f} s [{min(ours):.2f}–{max(ours):.2f}]"
            f"   import sympy {statistics.median(theirs):5.2f} s"
            f"   ratio {ratio:4.2f}x [{min(ratios):.2f}–{max(ratios):.2f}]   {verdict}"
        )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
