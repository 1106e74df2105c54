"""``gearsym sweep``: Sobol indices and Monte-Carlo robustness of a shift over parameter ranges,
evaluated in parallel on Dask (:mod:`gearsym.validation.studies.sweep`)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from gearsym.commands import add_command, emit_json, load, progress
from gearsym.interrupts import check
from gearsym.options import number
from gearsym.symbolic.defaults import SWEEP_MAX_SAMPLES
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.output_dir import OutputDir

if TYPE_CHECKING:
    from gearsym.commands import Subparsers


def _definition(args: argparse.Namespace, file: str) -> Any:
    """The sweep: the ``[sweep]`` table of ``--definition`` (if any), then every ``--param``
    (which adds or replaces ranges); ``--samples``/``--seed`` override the file's."""
    from dataclasses import replace

    from gearsym.validation.studies.sweep import (
        SweepDefinition,
        check_samples,
        load_definition,
        parse_range,
    )

    definition = (
        load_definition(args.definition)
        if args.definition
        else SweepDefinition({}, source="--param")
    )
    ranges = dict(definition.ranges)
    for item in args.param or ():
        name, bounds = parse_range(item, file)
        ranges[name] = bounds
    if not ranges:
        raise GearsymError(file, "param", "no parameter to sweep (--param NAME=LO:HI)")
    changes: dict[str, Any] = {"ranges": ranges}
    if args.samples is not None:
        check_samples(args.samples, "sweep", "samples")
        changes["samples"] = args.samples
    if args.seed is not None:
        changes["seed"] = args.seed
    return replace(definition, **changes)


def cmd_sweep(args: argparse.Namespace) -> int:
    """Sample, evaluate on Dask, write samples (CSV, Parquet), indices and one figure per
    quantity with local sensitivities."""
    from gearsym.validation.studies.sweep import (
        ShiftEvaluator,
        check_parameters,
        check_ranges,
        check_scheduler,
        connect,
    )

    d = load(args.config)
    definition = _definition(args, d.file)
    scenario = None
    if args.scenario is not None:
        from gearsym.validation.sim.scenario import load_scenario

        scenario = load_scenario(d, args.scenario)
    check_scheduler(args.scheduler)
    if args.workers is not None and args.scheduler != "local":
        raise GearsymError(
            "sweep", "workers", "is for --scheduler local; a remote scheduler brings its workers"
        )
    if args.workers is None:
        args.workers = 2
    check_ranges(definition, d.file)  # every sample passes the description's checks
    with OutputDir(args.out, "sweep", before_commit=check) as out:
        progress("building the hybrid shift model")
        evaluator = ShiftEvaluator(d, scenario, rtol=args.rtol)
        check_parameters(definition, evaluator.parameter_names(), d.file)
        # the scheduler before any simulation: an unreachable one is an error at once
        client, cluster = connect(args.scheduler, args.workers)
        try:
            summary, result, names, paths = _sweep(args, evaluator, definition, client, out)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    summary["files"] = [str(p) for p in paths]
    if args.json:
        emit_json(summary)
        return 0
    print(
        f"Sweep of {len(names)} parameters, {len(result.points)} shift runs in "
        f"{result.seconds:.1f} s on {result.workers} workers ({args.scheduler})"
    )
    for q, si in result.indices.items():
        print(f"  {q}:")
        lin = summary["local_linearised_indices"].get(q)
        for j, n in enumerate(names):
            extra = f"  local (linearised) {lin[n]:.3f}" if lin else ""
            print(
                f"    {n:<8} S1 {si['S1'][j]:7.3f} ± {si['S1_conf'][j]:.3f}   "
                f"ST {si['ST'][j]:7.3f} ± {si['ST_conf'][j]:.3f}{extra}"
            )
    for q, why in result.skipped.items():
        print(f"  {q}: no indices ({why})")
    for line in summary["implausible_indices"]:
        print(f"  ! {line}")
    print(f"  written: {args.out} (samples.csv, samples.parquet, indices.csv, sweep.json, PNGs)")
    return 0


def _sweep(
    args: argparse.Namespace,
    evaluator: Any,
    definition: Any,
    client: Any,
    out: OutputDir,
) -> tuple[dict[str, Any], Any, list[str], list[Any]]:
    """The work inside the output folder: local sensitivities, the sweep, files, figures."""
    from gearsym.validation.studies.sweep import (
        LOCAL_QUANTITIES,
        implausible_indices,
        linearised_indices,
        local_sensitivities,
        plot_indices,
        run_sweep,
        text_progress,
        write_tables,
    )

    names = list(definition.ranges)
    progress("local sensitivities at the nominal point (3.7 with event jumps)")
    local = local_sensitivities(evaluator, names)
    nominal = evaluator.simulator().values()
    runs = definition.samples * (len(names) + 2)
    progress(
        f"{runs} shift runs (N = {definition.samples}, {len(names)} parameters) on "
        f"{args.scheduler if args.scheduler != 'local' else f'{args.workers} local workers'}"
    )
    result = run_sweep(
        definition,
        evaluator,
        scheduler=args.scheduler,
        workers=args.workers,
        batch=args.batch,
        progress=text_progress,
    )
    files = write_tables(result, out.path)
    if not args.no_plots:
        for q in result.indices:
            files.append(
                plot_indices(result, q, local.get(q), nominal, out.path / f"sobol_{q}.png")
            )
    import json

    summary = {
        "parameters": {n: list(b) for n, b in definition.ranges.items()},
        "samples": definition.samples,
        "runs": int(len(result.points)),
        "seed": definition.seed,
        "evaluator": "hybrid shift model (CasADi mode functions, SciPy DOP853 with events), "
        f"rtol {args.rtol:g}",
        "scheduler": args.scheduler,
        "workers": result.workers,
        "seconds": round(result.seconds, 3),
        "indices": result.indices,
        "skipped": result.skipped,
        "statistics": result.statistics,
        "local_derivatives": local,
        "implausible_indices": implausible_indices(result.indices, names),
        "local_linearised_indices": {
            q: linearised_indices(local[q], definition.ranges)
            for q in LOCAL_QUANTITIES
            if q in local
        },
    }
    (out.path / "sweep.json").write_text(json.dumps(summary, indent=2) + "\n", "utf-8")
    paths = out.commit()
    return summary, result, names, paths


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """``gearsym sweep``."""
    p = add_command(
        subparsers,
        "sweep",
        cmd_sweep,
        "global sensitivity (Sobol S1/ST, SALib) and Monte-Carlo robustness of the hybrid shift "
        "over parameter ranges, in parallel on Dask",
        common,
    )
    p.add_argument("--scenario", help="scenario TOML (default: the built-in 2-3 shift)")
    p.add_argument(
        "--param",
        action="append",
        metavar="NAME=LO:HI",
        help="a parameter range (repeat); e.g. --param m_veh=1600:2000 --param mu_05=0.1:0.14",
    )
    p.add_argument(
        "--definition", metavar="FILE", help="TOML with a [sweep] table (samples, seed, parameters)"
    )
    p.add_argument(
        "--samples",
        type=number(int, minimum=2, maximum=SWEEP_MAX_SAMPLES),
        help="base sample count N, a power of two (runs: N (d + 2)); default 64 or the file's",
    )
    p.add_argument("--seed", type=number(int, minimum=0), help="sampling seed (default 1)")
    p.add_argument(
        "--scheduler",
        default="local",
        help="local (a LocalCluster on this machine; default) or tcp://HOST:PORT of a running "
        "dask scheduler",
    )
    p.add_argument(
        "--workers",
        type=number(int, minimum=1, maximum=256),
        default=None,
        help="LocalCluster worker processes (default 2; with a remote scheduler its workers "
        "are used, and this option is refused)",
    )
    p.add_argument(
        "--batch",
        type=number(int, minimum=1, maximum=100000),
        default=8,
        help="shift runs per Dask task (default 8)",
    )
    p.add_argument(
        "--rtol",
        type=number(float, above=0, maximum=1e-3),
        default=1e-6,
        help="integrator tolerance of each run (default 1e-6)",
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-plots", action="store_true", help="skip the figures")
    p.add_argument("--json", action="store_true", help="machine-readable summary on stdout")
