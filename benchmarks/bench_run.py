"""`gearsym run` on the built-in gearbox against the version issue 12 measured (commit
243e332, before the renovation), as whole processes in the same session.

The baseline is unpacked from this repository's history (`git archive`) into a temporary
folder and run from there with the same interpreter and libraries; the two alternate
(A B B A …) and the ratio is taken pair by pair. Target: ≤ 0.5× the baseline. The current run
does more than the baseline did (per-phase restarted sensitivities, ratios.json, run.json, a
MANIFEST): the ratio is the user's cost, not a like-for-like kernel time.
"""

from __future__ import annotations

import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from record import Target, begin, record, row

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "243e332"
ROUNDS = 3
TARGET = 0.5


def wall(argv: list[str], cwd: Path, out: Path) -> float:
    shutil.rmtree(out, ignore_errors=True)
    start = time.perf_counter()
    subprocess.run(argv, cwd=cwd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> int:
    started = begin()
    with tempfile.TemporaryDirectory(prefix="gearsym-bench-run-") as tmp:
        base = Path(tmp) / "baseline"
        base.mkdir()
        archive = subprocess.run(
            ["git", "archive", BASELINE], cwd=ROOT, capture_output=True, check=False
        )
        if archive.returncode != 0:
            print(f"skipped: commit {BASELINE} is not in this clone (shallow?)")
            return 0
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive.stdout, check=True)
        ours_cmd = [sys.executable, "-m", "gearsym", "run", "--out", str(Path(tmp) / "new")]
        base_cmd = [sys.executable, "-m", "gearsym", "run", "--out", str(Path(tmp) / "old")]
        ours, theirs, ratios = [], [], []
        for r in range(ROUNDS):
            if r % 2 == 0:
                a = wall(ours_cmd, ROOT, Path(tmp) / "new")
                b = wall(base_cmd, base, Path(tmp) / "old")
            else:
                b = wall(base_cmd, base, Path(tmp) / "old")
                a = wall(ours_cmd, ROOT, Path(tmp) / "new")
            ours.append(a)
            theirs.append(b)
            ratios.append(a / b)
    ratio = statistics.median(ratios)
    met = ratio <= TARGET
    print(f"gearsym run, built-in gearbox, median [min–max] of {ROUNDS} alternating runs")
    print(f"  now              {statistics.median(ours):6.2f} s [{min(ours):.2f}–{max(ours):.2f}]")
    print(
        f"  baseline {BASELINE} {statistics.median(theirs):6.2f} s "
        f"[{min(theirs):.2f}–{max(theirs):.2f}]"
    )
    print(
        f"  ratio {ratio:4.2f}x [{min(ratios):.2f}–{max(ratios):.2f}]   target ≤ {TARGET}x: "
        f"{'met' if met else 'MISSED'}"
    )
    rows = [
        row(
            "`gearsym run` on the built-in gearbox, whole process",
            unit="s",
            samples=ours,
            peer=f"the same command at {BASELINE} (before the renovation), alternating",
            peer_samples=theirs,
            pair_ratios=ratios,
            target=Target(f"≤ {TARGET}×", "ratio", "<=", TARGET),
        )
    ]
    record(__file__, rows, started=started, title="`gearsym run` against its baseline")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
