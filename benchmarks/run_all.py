"""Run every benchmark in this folder and report which targets were missed.

A benchmark whose tools are missing (a compiler, the Arm toolchain, QEMU) is skipped with the
reason; one that fails for another reason is reported in one line, its full output kept in a
log file whose path is printed, never a traceback on the terminal.

Each benchmark writes its measured rows to ``benchmarks/results/<bench>.json`` (``record.py``);
at the end ``render_results.py`` renders every record into ``docs/results/benchmarks.md``. A
skipped or failed benchmark keeps its last record, whose date the table shows.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import render_results

#: The programs each benchmark runs, beyond Python (and the Debian package that brings them).
NEEDS: dict[str, tuple[tuple[str, str], ...]] = {
    "bench_closed_loop.py": (("cc", "gcc"),),
    "bench_codegen_speed.py": (("gcc", "gcc"), ("g++", "g++")),
    "bench_cortex_m4.py": (("arm-none-eabi-gcc", "gcc-arm-none-eabi"),),
    "bench_cortex_m4_qemu.py": (
        ("arm-none-eabi-gcc", "gcc-arm-none-eabi"),
        ("qemu-system-arm", "qemu-system-arm"),
        ("gcc", "gcc"),
    ),
    "bench_ekf.py": (("gcc", "gcc"),),
    "bench_ekf_forms.py": (("gcc", "gcc"),),
    "bench_regeneration.py": (("gcc", "gcc"),),
    "bench_sensitivity.py": (("gcc", "gcc"),),
}


def missing_tools(script: str) -> str | None:
    """Why ``script`` cannot run here, or ``None``."""
    absent = [
        f"{tool} (apt-get install {package})"
        for tool, package in NEEDS.get(script, ())
        if shutil.which(tool) is None
    ]
    return f"missing {', '.join(absent)}" if absent else None


def main() -> int:
    here = Path(__file__).parent
    failed, crashed, skipped = [], [], []
    logs = Path(tempfile.mkdtemp(prefix="gearsym-bench-logs-"))
    for script in sorted(here.glob("bench_*.py")):
        print(f"== {script.name}", flush=True)
        reason = missing_tools(script.name)
        if reason:
            print(f"skipped: {reason}")
            skipped.append(script.name)
            continue
        proc = subprocess.run(
            [sys.executable, str(script)], stderr=subprocess.PIPE, text=True, check=False
        )
        if proc.returncode == 0:
            continue
        if "Traceback (most recent call last)" in proc.stderr:
            log = logs / f"{script.stem}.log"
            log.write_text(proc.stderr, encoding="utf-8")
            last = proc.stderr.strip().splitlines()[-1]
            print(f"error: {script.name} stopped: {last} (full output: {log})")
            crashed.append(script.name)
        else:
            sys.stderr.write(proc.stderr)
            failed.append(script.name)
    print("== render_results.py", flush=True)
    try:
        render_results.main([])
    except (ValueError, KeyError, OSError) as err:
        print(f"error: the records could not be rendered: {err}")
        crashed.append("render_results.py")
    if skipped:
        print(f"skipped (tools missing): {', '.join(skipped)}")
    if crashed:
        print(f"errors (not a measurement): {', '.join(crashed)}")
    if failed:
        print(f"targets missed in: {', '.join(failed)}")
    if failed or crashed:
        return 1
    print("all benchmark targets met" + (" (of those that ran)" if skipped else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
