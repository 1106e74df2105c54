"""``gearsym export-fmu`` and ``gearsym export-a2l``: the emitted code for the tools around it.

``gearsym export-fmu [CONFIG] --model NAME [--kind me|cs|both] [--fixed-step S] --out FILE.fmu``
writes an FMI 2.0 source FMU (:mod:`gearsym.symbolic.export.fmu`), Model Exchange and Co-Simulation
in one by default (the Co-Simulation part steps the emitted RK4 with the fixed internal step S,
default 1e-4 s): the model's ``modelDescription.xml``, the emitted C of ``gearsym generate`` and
an FMI wrapper in ``sources/``, for the importer to compile with its own FMI headers. ``NAME`` is
a model name of ``gearsym generate`` (``full``, ``shift_2_3``, ``shift_2_3_mu``, ...).

``gearsym export-a2l [CONFIG] [--model NAME ...] [--precision double|float] --out FILE.a2l``
writes an ASAP2 file (:mod:`gearsym.symbolic.export.a2l`) of the emitted parameter structs and the μ
map (``--model mu_map``), all of them without ``--model``, for INCA, CANape and the like.

``gearsym export-measurement [CONFIG] --scenario FILE [--noise R] [--seed K] --out FILE.mf4``
writes a bench recording (MDF4, or CSV for ``.csv``) of the scenario's reference simulation,
channels as its ``[measurement]`` table maps them, speed noise (3.26) drawn from ``K``
(:func:`gearsym.validation.sim.measurement.synthetic_recording`): the example for ``--measurement``.

``--out`` goes through :class:`gearsym.symbolic.io.output_dir.OutputFile`: written atomically,
signed (the zip's archive comment; the A2L's closing comment), and only over a file gearsym
wrote. The same input gives the same bytes. A bad model name or ``--out`` is one line on stderr,
exit 2, and nothing written.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from gearsym.commands import add_command, load, progress
from gearsym.options import number
from gearsym.symbolic.errors import GearsymError

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

#: How the printed line names each ``--kind``.
KIND_NAMES = {
    "me": "Model Exchange",
    "cs": "Co-Simulation",
    "both": "Model Exchange + Co-Simulation",
}

__all__ = ["cmd_export_a2l", "cmd_export_fmu", "cmd_export_measurement", "register"]


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``gearsym export-fmu`` and ``gearsym export-a2l``."""
    p = add_command(
        subparsers,
        "export-fmu",
        cmd_export_fmu,
        "Write one emitted model as an FMI 2.0 source FMU, Model Exchange and/or "
        "Co-Simulation (C sources, modelDescription.xml) for Simulink, Dymola, OpenModelica "
        "or FMPy.",
        common,
    )
    p.add_argument(
        "--model",
        required=True,
        metavar="NAME",
        help="a model of gearsym generate: full, shift_<a>_<b>, shift_<a>_<b>_mu, ...",
    )
    p.add_argument(
        "--kind",
        choices=("me", "cs", "both"),
        default="both",
        help="FMI interfaces: Model Exchange, Co-Simulation (the emitted RK4 at a fixed step), "
        "or both in one FMU (default)",
    )
    p.add_argument(
        "--fixed-step",
        type=number(float, minimum=1e-9, maximum=1.0),
        default=1e-4,
        metavar="S",
        help="Co-Simulation: start value of the FMU's fixed_step parameter, the internal RK4 "
        "step in s (default 1e-4)",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="FILE.fmu",
        help="the FMU; replaced only if gearsym wrote it",
    )
    m = add_command(
        subparsers,
        "export-measurement",
        cmd_export_measurement,
        "Write a bench recording (MDF4 or CSV) of the scenario's reference simulation: the "
        "channels its [measurement] table maps, speeds with noise (3.26); the example input of "
        "--measurement.",
        common,
    )
    m.add_argument("--scenario", help="scenario TOML with a [measurement] channel map")
    m.add_argument(
        "--noise",
        default="0.01",
        help="relative speed-sensor error r (3.26): one value or one per speed channel, "
        "comma-separated (default 0.01)",
    )
    m.add_argument("--seed", type=number(int, minimum=0), default=0, help="noise seed (default 0)")
    m.add_argument(
        "--out",
        required=True,
        metavar="FILE.mf4|FILE.csv",
        help="the recording; replaced only if gearsym wrote it",
    )
    a = add_command(
        subparsers,
        "export-a2l",
        cmd_export_a2l,
        "Write an ASAP2 (A2L, ASAM MCD-2 MC 1.7) file of the emitted parameter structs and the "
        "mu map for calibration tools (INCA, CANape); addresses are placeholders (0, with "
        "SYMBOL_LINK) for the linker map to fill in.",
        common,
    )
    a.add_argument(
        "--model",
        action="append",
        metavar="NAME",
        help="a model of gearsym generate (full, shift_<a>_<b>, ...) or mu_map; repeat for "
        "several; default: every model and the mu map",
    )
    a.add_argument(
        "--precision",
        choices=("double", "float"),
        default="double",
        help="gearsym_real of the ECU build: double (default) or float "
        "(-DGEARSYM_SINGLE_PRECISION)",
    )
    a.add_argument(
        "--byte-order",
        choices=("little", "big"),
        default="little",
        help="byte order of the ECU (default little: Cortex-M, TriCore)",
    )
    a.add_argument(
        "--out",
        required=True,
        metavar="FILE.a2l",
        help="the A2L file; replaced only if gearsym wrote it",
    )


def cmd_export_measurement(args: argparse.Namespace) -> int:
    """Simulate the scenario, sample its mapped channels with speed noise, write atomically."""
    from pathlib import Path

    from gearsym.symbolic.io.output_dir import OutputFile

    noise = args.noise.split(",")
    try:
        relative = [float(v) for v in noise]
    except ValueError:
        relative = [float("nan")]
    if not all(0 <= v < 1 for v in relative):  # also false for NaN
        raise GearsymError(
            "export-measurement", "--noise", f"expected r in [0, 1) per speed, got {args.noise!r}"
        )
    with OutputFile(args.out, "export-measurement", suffixes=(".mf4", ".csv")) as out:
        d = load(args.config)
        from gearsym.validation.sim.scenario import load_scenario

        scenario = load_scenario(d, args.scenario)
        cmap = scenario.measurement
        if cmap is None:
            raise GearsymError(
                scenario.file, "measurement", "missing table [measurement] (the channel map)"
            )
        speeds = [c.signal for c in cmap.channels if not c.is_input]
        if len(relative) not in (1, len(speeds)):
            raise GearsymError(
                "export-measurement",
                "--noise",
                f"give one value or one per speed channel ({', '.join(speeds)})",
            )
        if out.target.suffix.lower() == ".mf4":
            try:
                import asammdf  # noqa: F401
            except ImportError:
                raise GearsymError(
                    "export-measurement",
                    "--out",
                    "writing MDF4 needs asammdf: pip install 'gearsym[mdf]' (or write a .csv)",
                ) from None
        from gearsym.cmd_dynamics import simulate_with_progress
        from gearsym.validation.sim.measurement import recording_bytes, synthetic_recording

        result = simulate_with_progress(d, scenario)
        t, values = synthetic_recording(result, cmap, relative, args.seed)
        source = Path(args.scenario).name if args.scenario else "built-in"
        comment = (
            f"gearsym export-measurement: reference simulation of {scenario.name} ({source}), "
            f"speed noise r = {args.noise} (3.26), seed {args.seed}"
        )
        out.commit(recording_bytes(cmap, t, values, out.target.suffix, comment))
    channels = ", ".join(f"{c.signal} as {c.name!r} [{c.unit}]" for c in cmap.channels)
    print(
        f"wrote {len(t)} samples every {cmap.sample_time * 1e3:g} ms of {channels}"
        f" (speed noise r = {args.noise}, seed {args.seed}) to {args.out}"
    )
    return 0


def cmd_export_fmu(args: argparse.Namespace) -> int:
    """Check --out and --model, build the FMU in memory, write it atomically."""
    from gearsym.symbolic.io.output_dir import OutputFile

    # The target first (suffix, a foreign file, the lock): a bad --out costs no derivation.
    # Leaving the block without commit() removes any folder it created: nothing is written.
    with OutputFile(args.out, "export-fmu", suffixes=(".fmu",)) as out:
        d = load(args.config)
        from gearsym.symbolic.export.fmu import fmu_archive, fmu_files
        from gearsym.symbolic.export.generate import (
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
        files = fmu_files(emitted, d.name, kind=args.kind, fixed_step=args.fixed_step)
        out.commit(fmu_archive(files))
    m = emitted.model
    step = f", RK4 fixed_step {args.fixed_step:g} s" if args.kind != "me" else ""
    print(
        f"wrote the {KIND_NAMES[args.kind]} FMU of {m.name} ({len(m.states)} states, "
        f"{len(m.inputs)} inputs, {len(m.parameters)} parameters, {len(m.outputs)} outputs"
        f"{step}) of {d.name} to {args.out}"
    )
    return 0


def cmd_export_a2l(args: argparse.Namespace) -> int:
    """Check --out and --model, describe the chosen structs and the μ map, write atomically."""
    from gearsym.symbolic.io.output_dir import OutputFile

    # The target first (suffix, a foreign file, the lock): a bad --out costs no derivation.
    with OutputFile(args.out, "export-a2l", suffixes=(".a2l",)) as out:
        d = load(args.config)
        from gearsym.symbolic.export.a2l import a2l_text
        from gearsym.symbolic.export.generate import (
            check_generatable,
            gearbox_model_names,
            gearbox_models,
            load_mu_map,
        )

        check_generatable(d)
        names = gearbox_model_names(d)
        chosen = args.model or [*names, "mu_map"]
        for name in chosen:  # every name is checked before anything is derived
            if name not in names and name != "mu_map":
                raise GearsymError(
                    "command line",
                    "--model",
                    f"unknown model {name!r}; {d.name} has {', '.join(names)} and mu_map",
                )
        wanted = [n for n in names if n in chosen]  # output order, each once
        models = [e for name in wanted for e in gearbox_models(d, progress, only=name)]
        mu_map = load_mu_map(d) if "mu_map" in chosen else None
        structs = f"{len(models)} parameter struct{'s' * (len(models) != 1)}"
        progress(f"describing {structs}" + " and the mu map" * (mu_map is not None))
        text = a2l_text(
            models, mu_map, d.name, precision=args.precision, byte_order=args.byte_order
        )
        out.commit(text.encode("ascii"))
    fields = sum(len(e.model.parameters) for e in models)
    what = f"{structs} ({fields} fields)"
    if mu_map is not None:
        what += " and the mu map"
    print(
        f"wrote the A2L of {what} of {d.name}, gearsym_real = {args.precision}, addresses 0 "
        f"(SYMBOL_LINK) to {args.out}"
    )
    return 0
