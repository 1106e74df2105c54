"""``gearsym export-fmu [CONFIG] --model NAME --out FILE.fmu``: one emitted model as an FMU.

Writes an FMI 2.0 Model Exchange source FMU (:mod:`gearsym.symbolic.fmu`): the model's
``modelDescription.xml``, the emitted C of ``gearsym generate`` and an FMI wrapper in
``sources/``, for the importer to compile with its own FMI headers. ``NAME`` is a model name of
``gearsym generate`` (``full``, ``shift_2_3``, ``shift_2_3_mu``, ...).

``--out`` goes through :class:`gearsym.symbolic.output_dir.OutputFile`: written atomically,
signed (the zip's archive comment), and only over an FMU gearsym wrote. The same input gives the
same bytes. A bad model name or ``--out`` is one line on stderr, exit 2, and nothing written.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from gearsym.commands import add_command, load, progress
from gearsym.symbolic.errors import GearsymError

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_export_fmu", "register"]


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``gearsym export-fmu``."""
    p = add_command(
        subparsers,
        "export-fmu",
        cmd_export_fmu,
        "Write one emitted model as an FMI 2.0 Model Exchange source FMU (C sources, "
        "modelDescription.xml) for Simulink, Dymola, OpenModelica or FMPy.",
        common,
    )
    p.add_argument(
        "--model",
        required=True,
        metavar="NAME",
        help="a model of gearsym generate: full, shift_<a>_<b>, shift_<a>_<b>_mu, ...",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="FILE.fmu",
        help="the FMU; replaced only if gearsym wrote it",
    )


def cmd_export_fmu(args: argparse.Namespace) -> int:
    """Check --out and --model, build the FMU in memory, write it atomically."""
    from gearsym.symbolic.output_dir import OutputFile

    # The target first (suffix, a foreign file, the lock): a bad --out costs no derivation.
    # Leaving the block without commit() removes any folder it created: nothing is written.
    with OutputFile(args.out, "export-fmu", suffixes=(".fmu",)) as out:
        d = load(args.config)
        from gearsym.symbolic.fmu import fmu_archive, fmu_files
        from gearsym.symbolic.generate import (
            check_generatable,
            gearbox_model_names,
            gearbox_models,
        )

        check_generatable(d)
        names = gearbox_model_names(d)  # the name is checked before anything is derived
        if args.model not in names:
            raise GearsymError(
                "command line",
                "--model",
                f"unknown model {args.model!r}; {d.name} has {', '.join(names)}",
            )
        (emitted,) = gearbox_models(d, progress, only=args.model)
        progress(f"emitting {emitted.model.name} and its FMI wrapper")
        out.commit(fmu_archive(fmu_files(emitted, d.name)))
    m = emitted.model
    print(
        f"wrote the FMU of {m.name} ({len(m.states)} states, {len(m.inputs)} inputs, "
        f"{len(m.parameters)} parameters, {len(m.outputs)} outputs) of {d.name} to {args.out}"
    )
    return 0
