"""``gearsym generate [CONFIG] --out DIR [--check]``: emit the C and CasADi code of a gearbox.

Everything is generated in memory first (:func:`symbolic.generate.generate_tree`), then written
into a fresh temporary directory next to ``DIR`` and renamed into place only when complete, so
an error or an interrupt leaves ``DIR`` as it was. An existing ``DIR`` is replaced only if it is
empty or was written by this command (its ``MANIFEST`` starts with the marker line).

With ``--check`` the new files are compiled and validated (:mod:`validation.generated_check`)
before they replace ``DIR``; if a check fails, ``DIR`` stays as it was and the exit code is 1.
Progress goes to stderr, the summary to stdout.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from symbolic.errors import GearsymError

__all__ = ["add_generate_parser", "cmd_generate", "write_atomically"]


def add_generate_parser(command: Callable[..., Any], config: Callable[..., None]) -> None:
    """Register ``gearsym generate`` (``command`` and ``config`` are the CLI's helpers)."""
    p = command(
        "generate",
        cmd_generate,
        "Emit C (TCU) and CasADi code for the full model, every shift model, the friction "
        "model and the mu map.",
    )
    config(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (replaced)")
    p.add_argument(
        "--check",
        action="store_true",
        help="compile and validate the code (C vs SymPy and CasADi, example, integration "
        "orders, ECU rules, cppcheck, Cortex-M4F) before it replaces DIR",
    )
    p.add_argument(
        "--points",
        type=int,
        default=1000,
        metavar="N",
        help="random points per model for --check (default 1000)",
    )


def _progress(message: str) -> None:
    print(f"  … {message}", file=sys.stderr, flush=True)


def _is_replaceable(out: Path) -> bool:
    from symbolic.generate import MANIFEST_MARKER

    if not out.exists():
        return True
    if not out.is_dir() or out.is_symlink():
        return False
    if not any(out.iterdir()):
        return True
    manifest = out / "MANIFEST"
    try:
        first = manifest.read_text(encoding="utf-8").splitlines()[:1]
    except (OSError, UnicodeDecodeError):
        return False
    return first == [MANIFEST_MARKER]


def write_atomically(files: dict[str, str], out: Path, staging: Path | None = None) -> None:
    """Write ``files`` (relative path → text) as the complete content of ``out``.

    The files go into ``staging`` (a fresh directory next to ``out``, created if ``None``), which
    is then renamed to ``out``; a previous ``out`` is moved aside first and deleted last. On any
    error the staging directory is removed and ``out`` is left untouched.
    """
    parent = out.parent
    own_staging = staging is None
    if staging is None:
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=parent))
    old = None
    try:
        if own_staging:
            write_files(files, staging)
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=parent))
            os.rmdir(old)
            os.replace(out, old)
        try:
            os.replace(staging, out)
        except OSError:
            if old is not None:
                os.replace(old, out)  # put the previous content back
                old = None
            raise
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_files(files: dict[str, str], root: Path) -> None:
    """Write every file below ``root`` (``\\n`` line ends on every platform)."""
    for relative in sorted(files):
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(files[relative])


def cmd_generate(args: argparse.Namespace) -> int:
    """Generate, optionally check, and move the result into place."""
    from symbolic.description import load_description
    from symbolic.generate import generate_tree

    shown = args.out
    out = Path(args.out)
    if out.is_symlink() or not out.resolve().name:
        raise GearsymError(shown, "--out", "must name a directory (not a symlink or /)")
    out = out.resolve()
    if not _is_replaceable(out):
        raise GearsymError(
            shown, "--out", "exists and was not written by gearsym generate; not replacing it"
        )
    if args.points < 1:
        raise GearsymError(shown, "--points", f"must be positive, got {args.points}")
    start = time.perf_counter()
    d = load_description(args.config)
    _progress(f"generating code for {d.name}")
    tree = generate_tree(d, progress=_progress)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    except OSError as err:
        raise GearsymError(shown, "--out", f"cannot create the output: {err}") from None
    try:
        write_files(tree.files, staging)
        if args.check:
            from validation.generated_check import check_tree

            with tempfile.TemporaryDirectory(prefix="gearsym-check-") as build:
                report = check_tree(
                    staging,
                    tree.models,
                    tree.mu_map,
                    Path(build),
                    args.points,
                    _progress,
                    description=d,
                )
            for line in report.summary():
                print(line)
            if not report.ok:
                shutil.rmtree(staging, ignore_errors=True)
                print(f"gearsym: {shown}: checks failed; the previous content is unchanged")
                return 1
        write_atomically(tree.files, out, staging)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    n_models = len(tree.models)
    print(
        f"wrote {len(tree.files)} files for {n_models} models of {d.name} to {shown} "
        f"in {time.perf_counter() - start:.1f} s" + (" (checked)" if args.check else "")
    )
    return 0
