"""``gearsym model`` and ``gearsym simulate``: the dynamics models and the reference shift."""

from __future__ import annotations

import argparse
import sys
import time
from typing import TYPE_CHECKING, Any

from gearsym.commands import add_command, emit_json, load
from gearsym.interrupts import check
from gearsym.options import cacheable

if TYPE_CHECKING:
    from gearsym.commands import Subparsers


def _variables(variables: Any) -> list[dict[str, Any]]:
    return [
        {
            "name": v.name,
            "unit": v.unit,
            "description": v.description,
            **({"default": v.default} if v.default is not None else {}),
            **({"source": v.source} if v.source else {}),
        }
        for v in variables
    ]


def model_dict(
    d: Any,
    shift: str | None,
    friction_inputs: bool,
    wheel: bool,
    gear: str | None = None,
    mode: str | None = None,
) -> dict[str, Any]:
    """The model as data: variables, right-hand side (SymPy-parsable strings) and the numeric
    linear form A_ex, B_ex (5.1)–(5.5) at the defaults, with the inputs of (5.3) the mode has
    (full model, a shift, a gear with all its elements locked, or a mode of the hybrid shift:
    ``mode`` with ``shift``)."""
    from gearsym.symbolic.drivetrain import drivetrain_model, full_model, shift_model
    from gearsym.symbolic.linear_forms import (
        full_linear_form,
        gear_linear_form,
        mode_linear_form,
        shift_linear_form,
    )

    if mode is not None:
        from gearsym.symbolic.hybrid import hybrid_shift

        form = mode_linear_form(d, shift or "2-3", mode)  # checks the mode name first
        model = hybrid_shift(d, shift or "2-3").modes[mode].model
    elif gear is not None:
        form = gear_linear_form(d, gear)  # checks the gear name first
        model = drivetrain_model(
            d,
            form.mode,
            locked=tuple(d.gear(gear).closed),
            torque_elements=(),
            keep=(d.output_shaft,),
            with_wheel_acceleration=wheel,
        )
    elif shift is None:
        form = full_linear_form(d)
        model = full_model(d, with_wheel_acceleration=wheel)
    else:
        form = shift_linear_form(d, shift)
        model = shift_model(
            d, shift, with_wheel_acceleration=wheel, friction_inputs=friction_inputs
        )
    data: dict[str, Any] = {
        "name": model.name,
        "gearbox": d.name,
        "equations": model.metadata.get("equations", ""),
        "states": _variables(model.states),
        "inputs": _variables(model.inputs),
        "parameters": _variables(model.parameters),
        "outputs": _variables(model.outputs),
        # parse with sympy.parse_expr(text, local_dict={name: Symbol(name) for every variable})
        # (a bare sympify would read zeta as the Riemann zeta function)
        "rhs": {v.name: str(e) for v, e in zip(model.states, model.rhs, strict=True)},
        "output_expressions": {
            v.name: str(e) for v, e in zip(model.outputs, model.output_expressions, strict=True)
        },
    }
    if "idle" in model.metadata:
        data["idle"] = model.metadata["idle"]  # the dynamics assumption (README "Idle shafts")
    a, b = form.at_defaults()
    data["linear_form"] = {
        "equations": "5.1-5.5",
        "mode": form.mode,
        "states": form.states,
        "inputs": form.inputs,
        "A": a,
        "B": b,
    }
    return data


def cmd_model(args: argparse.Namespace) -> int:
    """Print a shift model (or the full model): variables, rhs, and A, B at the defaults."""
    import sympy as sp

    d = load(args.config)
    gear = getattr(args, "gear", None)
    if gear is not None and args.shift is not None:
        from gearsym.symbolic.errors import GearsymError

        raise GearsymError("model", "--gear", "give --shift or --gear, not both")
    mode = getattr(args, "mode", None)
    if mode is not None:
        from gearsym.symbolic.errors import GearsymError

        for option, given in (
            ("--gear", gear is not None),
            ("--friction-inputs", args.friction_inputs),
            ("--with-wheel-acceleration", args.with_wheel_acceleration),
        ):
            if given:
                raise GearsymError("model", option, "not available with --mode")
    data = model_dict(d, args.shift, args.friction_inputs, args.with_wheel_acceleration, gear, mode)
    if args.json:
        emit_json(data)
        return 0
    print(f"model {data['name']} of {d.title}  (thesis {data['equations']})")
    for group in ("states", "inputs", "parameters", "outputs"):
        print(f"  {group}:")
        for v in data[group]:
            default = f" = {v['default']:g}" if "default" in v else ""
            print(f"    {v['name']:<14} [{v['unit']}]{default}  {v['description']}")
    if "idle" in data:
        print(f"  assumption: {data['idle']}")
    print("  right-hand side (6 digits shown; --json gives the exact expressions):")
    names = [v["name"] for group in ("states", "inputs", "parameters") for v in data[group]]
    symbols = {n: sp.Symbol(n) for n in names}
    for name, expr in data["rhs"].items():
        print(f"    d{name}/dt = {sp.parse_expr(expr, local_dict=symbols).evalf(6)}")
    if "linear_form" in data:
        lf = data["linear_form"]
        x, u = ", ".join(lf["states"]), ", ".join(lf["inputs"])
        print(f"  linear form (5.1): x = [{x}], u = [{u}]")
        for label in ("A", "B"):
            print(f"  {label} =")
            for row in lf[label]:
                print("    [" + "  ".join(f"{v:11.4g}" for v in row) + "]")
    return 0


class ProgressBar:
    """A one-line progress display on stderr (plain lines when stderr is not a terminal)."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.start = time.perf_counter()
        self.tty = sys.stderr.isatty()
        self.last = ""

    def __call__(self, fraction: float, message: str) -> None:
        check()
        width = 24
        filled = int(round(width * max(0.0, min(1.0, fraction))))
        bar = "#" * filled + "." * (width - filled)
        elapsed = time.perf_counter() - self.start
        line = f"{self.label} [{bar}] {fraction:4.0%} {elapsed:5.1f} s  {message}"
        if self.tty:
            sys.stderr.write("\r" + line.ljust(len(self.last)))
        elif message != self.last:
            sys.stderr.write(line + "\n")
        sys.stderr.flush()
        self.last = line if self.tty else message

    def done(self) -> None:
        if self.tty:
            sys.stderr.write("\n")
            sys.stderr.flush()


def simulate_with_progress(d: Any, scenario: Any) -> Any:
    """Simulate a loaded scenario with a progress display on stderr."""
    from gearsym.validation.sim.simulate import simulate

    bar = ProgressBar("simulate")
    try:
        return simulate(d, scenario, progress=bar)
    finally:
        bar.done()


def cmd_simulate(args: argparse.Namespace) -> int:
    """Simulate the scenario's shift with the reference model and write the results."""
    from gearsym.symbolic.io.output_dir import OutputDir
    from gearsym.validation.sim.report import format_summary, summary, write_results
    from gearsym.validation.sim.scenario import load_scenario

    d = load(args.config)
    scenario = load_scenario(d, args.scenario)
    measurement = None
    if args.measurement is not None:
        from gearsym.validation.sim.measurement import read_measurement

        if scenario.measurement is None:
            from gearsym.symbolic.errors import GearsymError

            raise GearsymError(
                scenario.file, "measurement", "missing table [measurement] (the channel map)"
            )
        measurement = read_measurement(args.measurement, scenario.measurement, scenario.t_end)
    with OutputDir(args.out, "simulate", before_commit=check) as out:
        comparison: dict[str, Any] = {}
        if measurement is not None:
            from gearsym.validation.sim.measurement import (
                RESAMPLE_TEXT,
                compare_outputs,
                plot_comparison,
                write_comparison_csv,
            )
            from gearsym.validation.sim.scenario import input_sources, with_measured_inputs

            result = simulate_with_progress(d, with_measured_inputs(scenario, measurement))
            comparison = {
                "measurement": measurement.to_dict(),
                "input_sources": input_sources(scenario, measurement),
                "resample": RESAMPLE_TEXT,
                "residuals": compare_outputs(result, measurement),
            }
        else:
            result = simulate_with_progress(d, scenario)
        write_results(d, result, out.path, plots=not args.no_plots, speed_unit=args.speed_unit)
        if measurement is not None:
            import json

            write_comparison_csv(result, measurement, out.path / "measured.csv")
            (out.path / "measured.json").write_text(json.dumps(comparison, indent=2) + "\n")
            if not args.no_plots:
                plot_comparison(result, measurement, out.path / "measured.png")
        paths = out.commit()
    if args.json:
        emit_json({**summary(result), **comparison, "files": [str(p) for p in paths]})
    else:
        print(format_summary(result))
        if comparison:
            print(_comparison_text(comparison))
        print(f"  wrote {len(paths)} files to {args.out}: {', '.join(p.name for p in paths)}")
    return 0


def _comparison_text(comparison: dict[str, Any]) -> str:
    m = comparison["measurement"]
    lines = [
        f"  recording {m['file']} ({m['format']}, {m['samples']} samples every "
        f"{m['sample_time'] * 1e3:g} ms; {comparison['resample']})",
        "  inputs: "
        + ", ".join(f"{k} from the {v}" for k, v in comparison["input_sources"].items()),
        "  simulated - recorded speed (recorded inputs), over the samples that are not NaN:",
    ]
    for name, r in comparison["residuals"].items():
        if r["rms_residual"] is None:
            lines.append(f"    {name:<10} ({r['channel']}): no finite sample")
            continue
        lines.append(
            f"    {name:<10} ({r['channel']}): RMS {r['rms_residual']:.4g} rad/s "
            f"({100 * r['relative_rms_residual']:.3g} % of its RMS), max "
            f"{r['max_abs_residual']:.4g} rad/s, {r['samples']} samples"
        )
    return "\n".join(lines)


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``model`` and ``simulate``."""
    p = add_command(
        subparsers,
        "model",
        cmd_model,
        "Print the drivetrain model of a shift (2.55-2.58), a gear or the full model (2.53): "
        "states, "
        "inputs, parameters with defaults, right-hand side, and A, B of (5.1) at the defaults.",
        common,
    )
    p.add_argument(
        "--shift",
        help="e.g. 2-3, or a double swap such as 1-5 (torque inputs only) (default: the full "
        "model, every element a torque)",
    )
    p.add_argument(
        "--gear",
        help="e.g. 3: the gear with all its elements locked, inputs T_In, T_res*, zeta (5.3)",
    )
    p.add_argument(
        "--mode",
        help="a mode of the hybrid shift (--shift, default 2-3), e.g. "
        "hybrid_2_3__K38_slide_pos__B05_open: its model and linear form (5.1), sliding "
        "elements' torques as inputs",
    )
    p.add_argument(
        "--friction-inputs",
        action="store_true",
        help="element torques as mu times the normal-force inputs F_N (3.14)",
    )
    p.add_argument("--with-wheel-acceleration", action="store_true", help="add the output (3.32)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    cacheable(p)

    p = add_command(
        subparsers,
        "simulate",
        cmd_simulate,
        "Reference simulation of a shift (thesis 3.1): writes timeseries.csv, phases.csv, "
        "summary.json (phases, energy audit, model checks), Figures 3.1-3.3 and the vehicle's "
        "acceleration and jerk as PNG.",
        common,
    )
    p.add_argument("--scenario", help="scenario TOML (default: the built-in 2-3 power-on upshift)")
    p.add_argument(
        "--out",
        required=True,
        help="output folder (replaced atomically, and only if gearsym wrote it)",
    )
    p.add_argument(
        "--measurement",
        metavar="FILE",
        help="a bench recording (MDF4 .mf4 or CSV) mapped by the scenario's [measurement] "
        "table: its inputs drive the simulation, its speeds are compared with the simulated "
        "ones (measured.csv/.json/.png, RMS residual printed)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    p.add_argument(
        "--speed-unit",
        choices=("rad/s", "rpm"),
        default="rad/s",
        help="unit of the speeds and slips in the figures (default rad/s; the CSV stays in rad/s)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")


__all__ = ["cmd_model", "cmd_simulate", "model_dict", "register", "simulate_with_progress"]
