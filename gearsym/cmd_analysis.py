"""``gearsym sensitivity`` and ``gearsym fim``: sensitivities and Fisher information of a shift
(thesis 3.2–3.3), and :func:`print_fim_summary` for ``make run``."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gearsym.commands import add_command, emit_json, load, progress
from gearsym.interrupts import check
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.output_dir import OutputDir

if TYPE_CHECKING:
    from gearsym.commands import Subparsers


def _parameter_list(values: Sequence[str] | None) -> list[str] | None:
    """``--params m_veh,k_ss zeta`` → ['m_veh', 'k_ss', 'zeta'] (commas or spaces)."""
    if not values:
        return None
    return [n for v in values for n in v.split(",") if n]


def _overrides(d: Any, items: Sequence[str] | None) -> dict[str, float]:
    result = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            result[name.strip()] = float(value)
        except ValueError:
            raise GearsymError(d.file, "set", f"expected NAME=VALUE, got {item!r}") from None
        if not math.isfinite(result[name.strip()]):
            raise GearsymError(d.file, "set", f"the value must be finite, got {item!r}")
    return result


def _prepare(args: argparse.Namespace, wheel: bool) -> tuple[Any, list[str] | None, dict, Any]:
    """Load the description and check the parameter names before the (slow) simulation."""
    from gearsym.symbolic.sensitivity import select_parameters
    from gearsym.validation.studies.driven_shift import driven_shift_model, thesis_parameters
    from gearsym.validation.studies.sensitivity_integration import parameter_values

    d = load(args.config)
    names = _parameter_list(args.params)
    overrides = _overrides(d, args.set)  # before the slow derivation below
    scenario = None
    if args.scenario is not None:
        from gearsym.validation.sim.scenario import load_scenario

        scenario = _measured(args, d, load_scenario(d, args.scenario))
    elif args.measurement is not None:
        raise GearsymError("command line", "--measurement", "needs --scenario (its channel map)")
    shift = scenario.shift.name if scenario is not None else "2-3"
    driven = driven_shift_model(d, shift, wheel)
    if names is None:
        names = list(thesis_parameters(driven))
    select_parameters(driven.model, names, file=d.file)
    parameter_values(driven.model, overrides)
    return d, names, overrides, scenario


def _measured(args: argparse.Namespace, d: Any, scenario: Any) -> Any:
    """``--measurement FILE``: the scenario with the recording's inputs (its ``[measurement]``
    map; :func:`gearsym.validation.sim.scenario.with_measured_inputs`); the recorded speeds are
    not used (the Fisher information needs the noise model (3.26), not the data)."""
    if args.measurement is None:
        return scenario
    from gearsym.validation.sim.measurement import RESAMPLE_TEXT, read_measurement
    from gearsym.validation.sim.scenario import input_sources, with_measured_inputs

    if scenario.measurement is None:
        raise GearsymError(
            scenario.file, "measurement", "missing table [measurement] (the channel map)"
        )
    measurement = read_measurement(args.measurement, scenario.measurement, scenario.t_end)
    sources = input_sources(scenario, measurement)
    recorded = [name for name, where in sources.items() if where == "recording"]
    progress(
        f"inputs along the recording {measurement.file}: {', '.join(recorded) or 'none'} "
        f"({RESAMPLE_TEXT}); the others from the scenario"
    )
    return with_measured_inputs(scenario, measurement)


def _command_line() -> str:
    """The command as typed, for the header of the Markdown table ``--out`` writes (the
    documentation's result tables name the command that wrote them)."""
    return " ".join(["gearsym", *sys.argv[1:]]) if sys.argv[1:] else "gearsym fim"


def _reference(d: Any, scenario: Any) -> Any:
    from gearsym.validation.studies.driven_shift import reference_data

    start = time.perf_counter()
    progress("simulating the reference shift (gearsym.validation.sim.simulate)")
    data = reference_data(d, scenario)
    progress(f"reference simulated in {time.perf_counter() - start:.1f} s")
    return data


# ----------------------------------------------------------------------------- sensitivity


def cmd_sensitivity(args: argparse.Namespace) -> int:
    """Sensitivities along the reference shift: PNG per parameter (Figs. 3.4–3.8) and a CSV."""
    import numpy as np

    from gearsym.validation.sim.phases import phase_of
    from gearsym.validation.studies.sensitivity_output import plot_sensitivities, write_csv
    from gearsym.validation.studies.sensitivity_run import run_sensitivities

    d, names, overrides, scenario = _prepare(args, False)
    with OutputDir(args.out, "sensitivity", before_commit=check) as out:
        data = _reference(d, scenario)
        run = run_sensitivities(
            d,
            names,
            data=data,
            overrides=overrides,
            mode=_sliding(args),
            initial=args.initial,
            progress=progress,
        )
        write_csv(run, out.path / "sensitivities.csv")
        if not args.no_plots:
            progress("plotting")
            plot_sensitivities(run, out.path)
        paths = out.commit()
    tr = run.trajectory
    norm = run.normalised
    phases = [p.name for p in run.phases]
    where = np.array([phase_of(run.phases, t) for t in tr.t])
    peaks = {
        p: {
            phase: {
                x: float(np.max(np.abs(norm[where == phase, i, j]), initial=0.0))
                for i, x in enumerate(tr.state_names)
            }
            for phase in phases
        }
        for j, p in enumerate(tr.parameter_names)
    }
    if args.json:
        emit_json(
            {
                "parameters": list(tr.parameter_names),
                "nominal": dict(zip(tr.parameter_names, map(float, run.scales), strict=True)),
                "nominal_states": dict(
                    zip(tr.state_names, map(float, run.nominal_states), strict=True)
                ),
                "max_abs_normalised_sensitivity": peaks,
                "drift": run.drift(),
                "sliding": args.sliding,
                "timings_s": run.timings,
                "files": [str(p) for p in paths],
            }
        )
        return 0
    print(
        f"Sensitivities of the {data.shift} shift model driven by the reference "
        f"(3.2–3.7; sliding {_sliding(args)}, S(0) {args.initial}); "
        f"derived in {run.timings['derive_s']:.2f} s, integrated in "
        f"{run.timings['integrate_s']:.2f} s"
    )
    drift = ", ".join(f"{k} {v:.2%}" for k, v in run.drift().items())
    print(f"  open-loop drift from the reference (max |Δx|/x0): {drift}")
    print("  max |S_N| (3.3) per phase; states " + ", ".join(tr.state_names))
    width = 6 * len(tr.state_names) - 1
    print(f"    {'parameter':<10} {'p0':>9}  " + "  ".join(f"{ph:>{width}}" for ph in phases))
    for j, p in enumerate(tr.parameter_names):
        cells = [" ".join(f"{peaks[p][ph][x]:5.0e}" for x in tr.state_names) for ph in phases]
        print(f"    {p:<10} {run.scales[j]:>9.4g}  " + "  ".join(f"{c:>{width}}" for c in cells))
    print(f"  wrote {len(paths)} files to {args.out}: {', '.join(p.name for p in paths)}")
    return 0


# ----------------------------------------------------------------------------- fim


def cmd_fim(args: argparse.Namespace) -> int:
    """Fisher information per phase (3.16–3.32): on the hybrid shift model by default
    (:func:`_hybrid_fim`), the per-phase restarted open-loop study with ``--open-loop``."""
    if not args.open_loop:
        return _hybrid_fim(args)
    from gearsym.symbolic.defaults import ACCELERATION_ERROR
    from gearsym.validation.studies.fisher import fim_study, format_text, study_json

    for option, given in (
        ("--hybrid", args.hybrid),
        ("--known-initial-state", args.known_initial_state),
    ):
        if given:
            raise GearsymError("fim", option, "not available with --open-loop")
    d, names, overrides, scenario = _prepare(args, args.with_wheel_acceleration)
    with contextlib.ExitStack() as stack:
        out = (
            stack.enter_context(OutputDir(args.out, "fim", before_commit=check))
            if args.out
            else None
        )
        data = _reference(d, scenario)
        study = fim_study(
            d,
            names,
            data=data,
            with_wheel_acceleration=args.with_wheel_acceleration,
            sample_time=args.sample_time,
            speed_error=args.speed_error,
            acceleration_error=(
                ACCELERATION_ERROR if args.acceleration_error is None else args.acceleration_error
            ),
            gamma_max=args.gamma_max,
            mode=_sliding(args),
            restart=not args.carry_over,
            overrides=overrides,
            progress=progress,
        )
        paths: list[Path] = []
        if out is not None:
            write_fim(study, out.path, _command_line())
            paths = out.commit()
    if args.json:
        data_out = study_json(study)
        data_out["files"] = [str(p) for p in paths]
        emit_json(data_out)
        return 0
    print(format_text(study))
    if paths:
        print(f"\n  wrote {len(paths)} files to {args.out}")
    return 0


def _sliding(args: argparse.Namespace) -> str:
    """``--sliding`` of the open-loop paths; ``None`` (not given) is ``detected``."""
    return args.sliding or "detected"


def _hybrid_fim(args: argparse.Namespace) -> int:
    """``fim`` (default): the FIM on the hybrid shift model's sensitivities
    (gearsym.validation.studies.hybrid_fisher), per phase with φ at the phase start unknown, or with
    ``--known-initial-state`` the thesis' continuous view (3.16). The open-loop study's options
    are refused: they would silently not apply."""
    from gearsym.validation.sim.hybrid_simulation import HybridSimulator
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.studies.hybrid_fisher import (
        format_text,
        hybrid_fim,
        hybrid_fim_markdown,
        to_dict,
    )

    for option, given in (
        ("--with-wheel-acceleration", args.with_wheel_acceleration),
        ("--carry-over", args.carry_over),
        ("--sliding", args.sliding is not None),
        ("--acceleration-error", args.acceleration_error is not None),
    ):
        if given:
            raise GearsymError(
                "fim", option, "applies to --open-loop only (the default is the hybrid model)"
            )
    d = load(args.config)
    overrides = _overrides(d, args.set)
    given = _parameter_list(args.params)
    twice = sorted({n for n in given or () if given.count(n) > 1})
    if twice:  # before the slow derivation
        raise GearsymError(d.file, "params", f"parameter given twice: {', '.join(twice)}")
    if args.measurement is not None and args.scenario is None:
        raise GearsymError("command line", "--measurement", "needs --scenario (its channel map)")
    scenario = _measured(args, d, load_scenario(d, args.scenario))
    with contextlib.ExitStack() as stack:
        out = (
            stack.enter_context(OutputDir(args.out, "fim", before_commit=check))
            if args.out
            else None
        )
        progress(f"deriving the hybrid model of the {scenario.shift.name} shift")
        simulator = HybridSimulator(d, scenario)
        names = given or [
            "m_veh",
            *(str(mu) for mu in simulator.hybrid.friction_coefficient.values()),
            "zeta",
        ]
        unknown = [n for n in names if n not in simulator.parameter_names]
        if unknown:
            raise GearsymError(
                d.file, "params", f"unknown parameters {', '.join(unknown)} of the hybrid model"
            )
        simulator.values(overrides)  # unknown --set names fail before the integration
        progress("integrating the hybrid model and its sensitivities")
        study = hybrid_fim(
            d,
            names,
            view="continuous" if args.known_initial_state else "nuisance",
            sample_time=args.sample_time,
            speed_error=args.speed_error,
            gamma_max=args.gamma_max,
            overrides=overrides,
            simulator=simulator,
        )
        paths: list[Path] = []
        if out is not None:
            data = to_dict(study)
            (out.path / "fim.json").write_text(json.dumps(data, indent=2) + "\n")
            (out.path / "fim.txt").write_text(format_text(study) + "\n", encoding="utf-8")
            (out.path / "fim.md").write_text(
                hybrid_fim_markdown(data, _command_line()), encoding="utf-8"
            )
            paths = out.commit()
    if args.json:
        data_out = to_dict(study)
        data_out["files"] = [str(p) for p in paths]
        emit_json(data_out)
        return 0
    print(format_text(study))
    if paths:
        print(f"\n  wrote {len(paths)} files to {args.out}")
    return 0


def write_fim(study: Any, folder: Path, command: str = "gearsym fim --open-loop") -> list[str]:
    """``fim.json``, ``fim.txt``, ``fim.md`` (the table for the documentation, headed by
    ``command``) and the bar charts (Figs. 3.9–3.14) into ``folder``."""
    from gearsym.validation.studies.fisher import (
        fim_markdown,
        format_text,
        plot_scatter,
        study_json,
    )

    folder.mkdir(parents=True, exist_ok=True)
    data = study_json(study)
    (folder / "fim.json").write_text(json.dumps(data, indent=2) + "\n")
    (folder / "fim.txt").write_text(format_text(study) + "\n", encoding="utf-8")
    (folder / "fim.md").write_text(fim_markdown(data, command), encoding="utf-8")
    return ["fim.json", "fim.txt", "fim.md", *(p.name for p in plot_scatter(study, folder))]


def print_fim_summary(
    d: Any,
    result: Any = None,
    folder: Path | None = None,
    scenario: Any = None,
    background: Any = None,
) -> None:
    """A few lines for ``gearsym run``: per phase, the parameters that stay estimable after the
    elimination (3.3), on the hybrid shift model with φ at each phase start unknown (what
    ``gearsym fim`` prints by default; the view is printed with the verdicts).

    ``result`` is a :class:`gearsym.validation.sim.simulate.SimulationResult` of ``scenario``
    (default: the built-in 2-3); it feeds the open-loop sensitivities written with ``folder``.
    With ``folder``, also write ``fim/fim.json``, ``fim/fim.txt`` (the hybrid study) and what
    ``gearsym sensitivity`` writes (CSV, Figures 3.4–3.8) into ``folder/sensitivity``; with
    ``background`` (a :class:`gearsym.validation.drawing.figures.Background`) the figures are drawn
    in a child process while the Fisher information is computed (the caller waits for it).
    """
    from gearsym.symbolic.defaults import GAMMA_MAX, SAMPLE_TIME
    from gearsym.validation.sim.hybrid_simulation import HybridSimulator
    from gearsym.validation.studies.driven_shift import reference_data, reference_from_result
    from gearsym.validation.studies.hybrid_fisher import (
        format_text,
        hybrid_fim,
        summary_lines,
        to_dict,
    )
    from gearsym.validation.studies.sensitivity_output import plot_sensitivities, write_csv
    from gearsym.validation.studies.sensitivity_run import run_sensitivities

    figures = 0
    if folder is not None:  # first, so that its figures draw while the FIM is computed
        data = reference_from_result(result) if result is not None else reference_data(d, scenario)
        run = run_sensitivities(d, data=data)
        sens_dir = folder / "sensitivity"
        sens_dir.mkdir(parents=True, exist_ok=True)
        write_csv(run, sens_dir / "sensitivities.csv")
        figures = len(run.trajectory.parameter_names)  # one per parameter
        if background is not None:
            background.submit("Figures 3.4-3.8", plot_sensitivities, run, sens_dir)
        else:
            plot_sensitivities(run, sens_dir)
    start = time.perf_counter()
    simulator = HybridSimulator(d, scenario)
    names = [
        "m_veh",
        *(str(mu) for mu in simulator.hybrid.friction_coefficient.values()),
        "zeta",
    ]
    study = hybrid_fim(d, names, simulator=simulator)
    print(
        f"Fisher information (3.25) of {', '.join(study.parameters)} per phase of the "
        f"{simulator.scenario.shift.name} shift on the hybrid shift model, outputs "
        f"{', '.join(study.outputs)}: estimable after elimination (γ ≤ {GAMMA_MAX:g}, samples "
        f"every {SAMPLE_TIME * 1e3:g} ms; {time.perf_counter() - start:.1f} s; the open-loop "
        "study: gearsym fim --open-loop)"
    )
    for line in summary_lines(study):
        print(f"  {line}")
    if folder is None:
        return
    fim_dir = folder / "fim"
    fim_dir.mkdir(parents=True, exist_ok=True)
    (fim_dir / "fim.json").write_text(json.dumps(to_dict(study), indent=2) + "\n")
    (fim_dir / "fim.txt").write_text(format_text(study) + "\n", encoding="utf-8")
    print(
        f"  fim/: fim.json, fim.txt; sensitivity/ (open-loop shift model): sensitivities.csv "
        f"and {figures} plots"
    )


# ----------------------------------------------------------------------------- parser


def _common(p: argparse.ArgumentParser) -> None:
    from gearsym.symbolic.defaults import SENSITIVITY_PARAMETERS as DEFAULT_PARAMETERS
    from gearsym.symbolic.defaults import SLIDING_MODES

    p.add_argument(
        "--params",
        nargs="+",
        metavar="NAME",
        help=f"parameters, comma or space separated (default: {','.join(DEFAULT_PARAMETERS)})",
    )
    p.add_argument("--scenario", help="scenario TOML (default: the built-in 2-3 upshift)")
    p.add_argument(
        "--measurement",
        metavar="FILE",
        help="along a bench recording's inputs (MDF4 .mf4 or CSV, mapped by the scenario's "
        "[measurement] table; inputs it lacks stay the scenario's)",
    )
    p.add_argument(
        "--sliding",
        choices=SLIDING_MODES,
        default=None,
        help="open-loop shift model: when μ acts on an element's torque: 'detected' (default) "
        "from the record (|T| at the friction capacity), or 'phases' as the thesis assumes "
        "(torque and speed phase)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="evaluate at another parameter value (repeatable), e.g. --set zeta=0.03",
    )


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``sensitivity`` and ``fim``."""
    from gearsym.options import number
    from gearsym.symbolic.defaults import (
        ACCELERATION_ERROR,
        GAMMA_MAX,
        RECORD_SAMPLE_TIME,
        SAMPLE_TIME,
        SPEED_ERROR,
    )

    p = add_command(
        subparsers,
        "sensitivity",
        cmd_sensitivity,
        "Parameter sensitivities (3.2-3.7) of the shift model along the reference shift: "
        "sensitivities.csv and one PNG per parameter (Figures 3.4-3.8).",
        common,
    )
    _common(p)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--initial",
        choices=("stationary", "zero"),
        default="stationary",
        help="S(0): consistent with the quasi-static start (phi solves phi''=0), or zero",
    )
    p.add_argument("--no-plots", action="store_true", help="CSV only")
    p.add_argument("--json", action="store_true", help="machine-readable summary")

    p = add_command(
        subparsers,
        "fim",
        cmd_fim,
        "Fisher information per shift phase (3.16-3.32) on the hybrid shift model (elements "
        "lock, slide and open): Cramér-Rao scatter and parameter elimination per phase; "
        "--open-loop for the open-loop shift model's study.",
        common,
    )
    _common(p)
    p.add_argument(
        "--with-wheel-acceleration",
        action="store_true",
        help="with --open-loop: also measure the wheel acceleration (3.32), at "
        "--acceleration-error",
    )
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument(
        "--out",
        help="folder for fim.json, fim.txt, fim.md (the table, Markdown) and, with "
        "--open-loop, bar charts (Figs. 3.9-3.14)",
    )
    p.add_argument(
        "--sample-time",
        # finer than the simulated record (gearsym.validation.sim.scenario.SAMPLE_TIME) adds nothing
        type=number(float, minimum=RECORD_SAMPLE_TIME),
        default=SAMPLE_TIME,
        help="measurement period in s",
    )
    p.add_argument(
        "--speed-error",
        type=number(float, above=0),
        default=SPEED_ERROR,
        help="relative error r of the measured speeds (3.26)",
    )
    p.add_argument(
        "--acceleration-error",
        type=number(float, above=0),
        default=None,
        help=f"with --open-loop: relative error of the wheel acceleration (3.32) "
        f"(default {ACCELERATION_ERROR:g})",
    )
    p.add_argument(
        "--gamma-max",
        type=number(float, above=0),
        default=GAMMA_MAX,
        help="limit of the scatter γ (3.27)",
    )
    p.add_argument(
        "--carry-over",
        action="store_true",
        help="with --open-loop: carry the sensitivities over from t0 (the thesis' view) "
        "instead of restarting them at every phase: a phase then also shows what earlier "
        "phases revealed",
    )
    p.add_argument(
        "--open-loop",
        action="store_true",
        help="the per-phase study on the open-loop shift model (never locks; sensitivities "
        "restarted at every phase, or --carry-over), as before the hybrid model",
    )
    p.add_argument(
        "--hybrid",
        action="store_true",
        help="the hybrid shift model (the default; accepted for scripts that name it)",
    )
    p.add_argument(
        "--known-initial-state",
        action="store_true",
        help="hybrid model: the thesis' view (3.16), sensitivities from t0 with the initial "
        "state known; a phase then also shows what earlier phases revealed",
    )


__all__ = ["cmd_fim", "cmd_sensitivity", "print_fim_summary", "register", "write_fim"]
