"""``gearsym generate [CONFIG] --out DIR [--check]``: emit the C and CasADi code of a gearbox.

Everything is generated in memory first (:func:`gearsym.symbolic.export.generate.generate_tree`),
then written through :class:`gearsym.symbolic.io.output_dir.OutputDir`: into a staging directory
next to ``DIR``, swapped in only when complete, and only over a ``DIR`` that gearsym wrote (see that
module's rules).

With ``--check`` the new files are compiled and validated
(:mod:`gearsym.validation.checks.generated_check`) before they replace ``DIR``; if a check fails,
``DIR`` stays as it was and the exit code is 1. Progress goes to stderr, the summary to stdout.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from gearsym.commands import add_command, load, progress
from gearsym.interrupts import check
from gearsym.symbolic.defaults import DEFAULT_SHIFT
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.output_dir import OutputDir

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_generate", "register", "write_files"]


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``generate``."""
    p = add_command(
        subparsers,
        "generate",
        cmd_generate,
        "Emit C (TCU) and CasADi code for the full model, every shift model, the friction "
        "model and the mu map.",
        common,
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (replaced)")
    p.add_argument(
        "--check",
        action="store_true",
        help="compile and validate the code (C vs SymPy and CasADi, example, integration "
        "orders, ECU rules, cppcheck, Cortex-M4F) before it replaces DIR",
    )
    p.add_argument(
        "--shifts",
        default="adjacent",
        metavar="WHICH",
        help="shift models to emit: adjacent (default: the upshifts between adjacent forward "
        "gears), all (every single-swap shift: downshifts, skip shifts, reverse engagements; and "
        "the torque-input model of every double swap) or a list such as 3-2,5-3,1-5",
    )
    p.add_argument(
        "--hybrid-shifts",
        default=None,
        metavar="WHICH",
        help="hybrid shift models whose sensitivities across lock-up and break-away are "
        f"emitted: none, adjacent, all or a list (default: {DEFAULT_SHIFT}, the thesis' shift, "
        "if the gearbox has it)",
    )
    p.add_argument(
        "--controllers",
        default=None,
        metavar="WHICH",
        help="shifts whose TCU shift controller is emitted, each with its EKF as one 10 ms task: "
        f"none, adjacent, all or a list such as 3-2,4-3 (default: {DEFAULT_SHIFT}, the thesis' "
        "shift, when its model is emitted)",
    )
    p.add_argument(
        "--uio-unknown",
        default="T_res_star",
        metavar="NAMES",
        help="unknown inputs of the emitted UIO of the default shift (thesis 4.4), comma "
        "separated (default T_res_star; generate refuses a set for which a phase has no UIO, "
        "e.g. T_res_star,T_K38,T_B05)",
    )
    p.add_argument(
        "--points",
        type=int,
        default=1000,
        metavar="N",
        help="random points per model for --check (default 1000)",
    )


def write_files(files: dict[str, str], root: Path) -> None:
    """Write every file below ``root`` (``\\n`` line ends on every platform)."""
    for relative in sorted(files):
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(files[relative])


def cmd_generate(args: argparse.Namespace) -> int:
    """Generate, optionally check, and move the result into place."""
    from gearsym.symbolic.export.generate import (
        check_generatable,
        controller_shifts,
        generate_tree,
        hybrid_shift_names,
        selected_shifts,
    )

    shown = args.out
    if args.points < 1:
        raise GearsymError(shown, "--points", f"must be positive, got {args.points}")
    start = time.perf_counter()
    d = load(args.config)
    check_generatable(d)
    selected_shifts(d, args.shifts)  # a bad --shifts is a one-line error before any work
    hybrid_shift_names(d, args.hybrid_shifts)
    controller_shifts(d, args.shifts, args.controllers)
    with OutputDir(args.out, "generate", before_commit=check) as out:
        progress(f"generating code for {d.name}")
        unknown = tuple(name.strip() for name in args.uio_unknown.split(",") if name.strip())
        tree = generate_tree(
            d,
            progress=progress,
            shifts=args.shifts,
            hybrid_shifts=args.hybrid_shifts,
            uio_unknown=unknown,
            controllers=args.controllers,
        )
        write_files(tree.files, out.path)
        if args.check:
            from gearsym.validation.checks.generated_check import check_tree

            with tempfile.TemporaryDirectory(prefix="gearsym-check-") as build:
                report = check_tree(
                    out.path,
                    tree.models,
                    tree.mu_map,
                    Path(build),
                    args.points,
                    progress,
                    description=d,
                    linear_sets=tree.linear_sets,
                    hybrid_sets=tree.hybrid_sets,
                    uio=(tree.uio_shift, tree.uio_designs) if tree.uio_shift else None,
                )
            for line in report.summary():
                print(line)
            if not report.ok:
                print(f"gearsym: {shown}: checks failed; the previous content is unchanged")
                return 1
        out.commit()
    for line in tree.skipped:
        print(f"not generated: {line.replace('`', '')}")
    n_models = len(tree.models)
    print(
        f"wrote {len(tree.files)} files for {n_models} models of {d.name} to {shown} "
        f"in {time.perf_counter() - start:.1f} s" + (" (checked)" if args.check else "")
    )
    return 0
