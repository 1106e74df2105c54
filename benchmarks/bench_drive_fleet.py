"""Wall time of a fleet of drives (``gearsym drive --fleet``) on one and on two Dask workers: the
same vehicles of the default fleet over the first 300 s of WLTC class 3b, each drive with the
EKF over its TCU log, as a user runs them (one ``gearsym`` process per fleet, a LocalCluster of
``--workers`` started and stopped inside it), the two worker counts in alternating order,
medians with min–max. The peer is the same fleet on one worker: the ratio is what a second
core buys. The drive issue asks for the fleet's wall time on 1 and 2 workers; the 100-vehicle
WLTC table in docs/drive.md has the 2-worker time of the whole cycle.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from record import Target, begin, record, row

#: Vehicles per fleet and seconds of WLTC 3b each drives.
VEHICLES = 4
DURATION = 300.0
ROUNDS = 3
SEED = 10000


def fleet_once(workers: int, out: Path) -> tuple[float, float]:
    """(the process's wall time, the fleet's own ``fleet_wall_s``) of one fleet run."""
    command = [
        sys.executable,
        "-m",
        "gearsym",
        "drive",
        "--cycle",
        "wltc3b",
        "--duration",
        f"{DURATION:g}",
        "--fleet",
        "--runs",
        str(VEHICLES),
        "--seed",
        str(SEED),
        "--scheduler",
        "local",
        "--workers",
        str(workers),
        "--out",
        str(out),
        "--json",
    ]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    data = json.loads(done.stdout)
    if data["failed"]:
        raise SystemExit(f"drives failed on {workers} worker(s): {data['failed']}")
    return wall, float(data["fleet_wall_s"])


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):6.1f} s [{min(values):.1f}–{max(values):.1f}]"


def main() -> int:
    started = begin()
    # one cache for every run: the kinematic C every vehicle shares is compiled by the first
    # (untimed) run, as in a user's second fleet
    os.environ["GEARSYM_CACHE_DIR"] = tempfile.mkdtemp(prefix="gearsym-bench-fleet-")
    scratch = Path(tempfile.mkdtemp(prefix="gearsym-bench-fleet-out-"))
    fleet_once(2, scratch / "warm")
    times: dict[int, list[float]] = {1: [], 2: []}
    inside: dict[int, list[float]] = {1: [], 2: []}
    for r in range(ROUNDS):
        for workers in (1, 2) if r % 2 == 0 else (2, 1):
            wall, fleet_wall = fleet_once(workers, scratch / f"w{workers}r{r}")
            times[workers].append(wall)
            inside[workers].append(fleet_wall)
    one, two = (statistics.median(times[w]) for w in (1, 2))
    what = f"{VEHICLES} vehicles of the default fleet, WLTC 3b's first {DURATION:.0f} s each"
    print(f"fleet of {what}, drives and filters, one gearsym process each")
    print(f"  1 worker   {spread(times[1])}   ({statistics.median(inside[1]):.1f} s in the fleet)")
    print(f"  2 workers  {spread(times[2])}   ({statistics.median(inside[2]):.1f} s in the fleet)")
    print(f"  2 workers / 1 worker {two / one:.3f} (ideal 0.5 on this machine's two cores)")
    rows = [
        row(
            f"a fleet of {what} (drives and EKF), 2 workers",
            unit="s",
            samples=times[2],
            peer="the same fleet on 1 worker",
            peer_samples=times[1],
            target=Target("reported: the drive issue asks for the wall time on 1 and 2 workers"),
        ),
        row(
            "the same, per vehicle on 2 workers (the process's wall time / vehicles)",
            unit="s",
            samples=[t / VEHICLES for t in times[2]],
            peer="per vehicle on 1 worker",
            peer_samples=[t / VEHICLES for t in times[1]],
        ),
    ]
    record(__file__, rows, started=started, title="A fleet of drives on 1 and 2 workers")
    return 0


if __name__ == "__main__":
    sys.exit(main())
