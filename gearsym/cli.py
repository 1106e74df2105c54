"""The ``gearsym`` command line.

Every command takes an optional description file (the built-in thesis gearbox when omitted).
Bad input prints one line ``gearsym: <file>: <key>: <reason>`` and exits with code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from gearsym.interrupts import Terminated, check, sigterm_raises
from gearsym.options import number
from gearsym.symbolic.description import PLANET_COUNT_MAX, TEETH_MAX
from gearsym.symbolic.errors import GearsymError


def _load(path: str | None) -> Any:
    from gearsym.symbolic.description import load_description

    return load_description(path)


def _emit_json(data: Any) -> None:
    json.dump(data, sys.stdout, indent=2, sort_keys=False)
    sys.stdout.write("\n")


def _progress(message: str) -> None:
    check()
    print(f"  … {message}", file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------- ratios


def cmd_ratios(args: argparse.Namespace) -> int:
    """Gear table; exit code 1 when a derived ratio differs from the expected one (text and
    JSON alike). The JSON stays ``{gear: ratio or null}`` (README, tests); the gears that
    differ are named on stderr."""
    from gearsym.symbolic.ratios import ratio_table

    d = _load(args.config)
    table = ratio_table(d)
    places = d.ratio_decimals
    differ = _differing_gears(d, table)
    source = f" ({d.gear_table_source})" if d.gear_table_source else ""
    if args.json:
        _emit_json({r.gear: (None if r.ratio is None else float(r.ratio)) for r in table})
        if differ:
            first = next(r for r in table if r.gear == differ[0])
            print(
                f'gearsym: {d.file}: gear[name="{first.gear}"].ratio: derived '
                f"{float(first.ratio):.{places}f} differs from the expected "
                f"{first.expected:.{places}f}{source}; gears that differ: {', '.join(differ)}",
                file=sys.stderr,
            )
            return 1
        return 0
    return print_ratio_table(d, table, differ)


def _differing_gears(d: Any, table: Sequence[Any]) -> list[str]:
    places = d.ratio_decimals
    return [
        r.gear
        for r in table
        if not r.neutral
        and r.expected is not None
        and r.rounded(places) != round(r.expected, places)
    ]


def print_ratio_table(d: Any, table: Sequence[Any], differ: Sequence[str] | None = None) -> int:
    """Print the gear table; 1 when a derived ratio differs from the expected one, else 0."""
    places = d.ratio_decimals
    differ = _differing_gears(d, table) if differ is None else differ
    source = f" ({d.gear_table_source})" if d.gear_table_source else ""
    print(f"Gear ratios ω_{d.input_shaft}/ω_{d.output_shaft} of {d.title}")
    print(f"{'gear':>5}  {'closed':<20} {'derived':>10} {'expected':>10}  ok")
    for r in table:
        closed = " ".join(r.closed)
        if r.neutral:
            print(f"{r.gear:>5}  {closed:<20} {'neutral':>10} {'—':>10}  ✓")
            continue
        ok = r.gear not in differ
        expected = "—" if r.expected is None else f"{r.expected:.{places}f}"
        value = f"{float(r.ratio):.{places}f}"
        print(f"{r.gear:>5}  {closed:<20} {value:>10} {expected:>10}  {'✓' if ok else '✗'}")
    if differ:
        print(f"{len(differ)} gear(s) differ from the expected table{source}.")
        return 1
    print(f"All ratios match the expected table{source} to {places} decimals.")
    return 0


# ----------------------------------------------------------------------------- fit-teeth


def _range(text: str) -> tuple[int, int]:
    try:
        low, high = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW:HIGH, got {text!r}") from None
    if not 0 < low <= high <= TEETH_MAX:
        raise argparse.ArgumentTypeError(f"expected 0 < LOW <= HIGH <= {TEETH_MAX}, got {text!r}")
    return low, high


def _counts(text: str) -> tuple[int, ...]:
    try:
        counts = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N[,N...], got {text!r}") from None
    if not counts or min(counts) < 1 or max(counts) > PLANET_COUNT_MAX:
        raise argparse.ArgumentTypeError(
            f"planet counts must be 1 to {PLANET_COUNT_MAX}, got {text!r}"
        )
    return counts


def cmd_fit_teeth(args: argparse.Namespace) -> int:
    from gearsym.symbolic.teeth import ToothRanges, fit_teeth

    d = _load(args.config)
    ranges = ToothRanges(
        sun=args.sun, planet=args.planet, ring_max=args.ring_max, planet_counts=args.planet_count
    )
    start = time.perf_counter()
    candidates = fit_teeth(
        d,
        ranges,
        tolerance=args.tolerance,
        top=args.top,
        progress=None if args.json else _progress,
    )
    elapsed = time.perf_counter() - start
    if args.json:
        _emit_json(
            [
                {
                    "max_error": c.max_error,
                    "sets": {
                        s: {"z_sun": t[0], "z_planet": t[1], "z_ring": t[2], "planet_count": t[3]}
                        for s, t in c.teeth.items()
                    },
                    "alternatives": {
                        s: [list(t) for t in alts] for s, alts in c.alternatives.items()
                    },
                    "ratios": c.ratios,
                    "errors": c.errors,
                }
                for c in candidates
            ]
        )
        return 0 if candidates else 1
    tol = args.tolerance if args.tolerance is not None else 0.5 * 10.0 ** (-d.ratio_decimals)
    if not candidates:
        print(f"No tooth counts in the ranges reproduce every ratio within ±{tol:g}.")
        return 1
    print(f"{len(candidates)} candidate(s) within ±{tol:g} of every ratio ({elapsed:.1f} s):")
    for rank, c in enumerate(candidates, start=1):
        print(f"\n#{rank}  largest ratio error {c.max_error:.2e}")
        for s, (zs, zp, zr, n) in c.teeth.items():
            alts = ", ".join(f"{a}/{b}/{r}" for a, b, r, _ in c.alternatives.get(s, [])[:4])
            more = f"   (same k: {alts})" if alts else ""
            print(f"   set {s:<4} sun {zs:3d}  planet {zp:3d}  ring {zr:3d}  ×{n}{more}")
        worst = max(c.errors, key=lambda g: c.errors[g])
        print(f"   worst gear {worst}: {c.ratios[worst]:.6f} (error {c.errors[worst]:.2e})")
    return 0


# ----------------------------------------------------------------------------- show

SHOW_ITEMS = (
    "constraints",
    "orientation",
    "position",
    "jacobians",
    "mass-matrix",
    "input-matrix",
    "state-input-matrix",
    "equations",
)


def _matrix_json(m: Any) -> list[list[str]]:
    return [[str(m[i, j]) for j in range(m.cols)] for i in range(m.rows)]


def cmd_show(args: argparse.Namespace) -> int:
    import sympy as sp

    from gearsym.symbolic.dynamics import gearbox_dynamics

    d = _load(args.config)
    dyn = gearbox_dynamics(
        d, symbolic_teeth=args.symbolic_teeth, symbolic_inertias=args.symbolic_inertias
    )
    kin = dyn.kinematics
    items: dict[str, tuple[str, Any, str]] = {}
    what = args.what
    if what == "constraints":
        speeds = sp.Matrix([dyn.symbols.speed[b] for b in kin.bodies])
        items["G*omega"] = (
            "Willis constraints (2.22)-(2.23), G·ω = 0",
            kin.constraints * speeds,
            "",
        )
    elif what == "orientation":
        items["s"] = ("body orientations s(y) (2.29)", kin.orientation, "")
    elif what == "position":
        items["r"] = ("body positions r(y) (2.27), (2.30)", kin.position, "")
    elif what == "jacobians":
        items["J_R"] = ("rotation Jacobian (2.32)", kin.rotation_jacobian, "")
        items["J_T"] = ("translation Jacobian (2.31)", kin.translation_jacobian, "")
    elif what == "mass-matrix":
        items["M"] = ("mass matrix (2.34)", dyn.mass_matrix, "")
    elif what == "input-matrix":
        items["B_tilde"] = ("input matrix B̃ of M·ÿ = B̃·u (2.39)", dyn.input_matrix, "")
        items["u"] = ("input vector (2.38)", dyn.inputs, "")
    elif what == "state-input-matrix":
        items["B"] = ("B = M⁻¹·B̃ of ẋ = B·u (2.41)", dyn.state_input_matrix(), "")
    elif what == "equations":
        lhs = dyn.mass_matrix * sp.Matrix([sp.Symbol(f"domega_{c}") for c in kin.coordinates])
        items["M*dx"] = ("left side M·ẋ (2.37)", lhs, "")
        items["B_tilde*u"] = ("right side B̃·u (2.37)", dyn.generalized_forces, "")
    coordinates = [str(s) for s in kin.coordinate_symbols]
    if args.format == "json":
        _emit_json(
            {
                "gearbox": d.name,
                "coordinates": coordinates,
                "bodies": list(kin.bodies),
                "items": {
                    name: {"title": title, "shape": list(m.shape), "entries": _matrix_json(m)}
                    for name, (title, m, _) in items.items()
                },
            }
        )
        return 0
    for name, (title, m, _) in items.items():
        if args.format == "latex":
            print(f"% {title}; coordinates y = {coordinates}")
            print(f"{name} = {sp.latex(m)}")
            continue
        print(f"{title}; coordinates y = {coordinates}")
        for i in range(m.rows):
            for j in range(m.cols):
                if m[i, j] != 0 or m.cols == 1:
                    index = f"[{i + 1}]" if m.cols == 1 else f"[{i + 1},{j + 1}]"
                    print(f"  {name}{index} = {m[i, j]}")
        print()
    return 0


# ----------------------------------------------------------------------------- default-config, run


def cmd_default_config(args: argparse.Namespace) -> int:
    from gearsym.symbolic.description import default_config_text

    sys.stdout.write(default_config_text())
    return 0


def _run_scenario(d: Any, path: str | None) -> tuple[Any, str | None]:
    """The scenario ``gearsym run`` simulates, or ``None`` and why not. A scenario the user
    names must load (its errors are errors); the built-in one is tried on any gearbox."""
    from gearsym.validation.scenario import load_scenario

    if path is not None:
        return load_scenario(d, path), None
    try:
        return load_scenario(d, None), None
    except GearsymError as err:
        return None, (
            f"the built-in 2-3 scenario does not fit this gearbox ({err.key}: {err.reason}); "
            "give one with --scenario FILE"
        )


def cmd_run(args: argparse.Namespace) -> int:
    """The main job: derive the model, print the gear table and the observability verdict,
    simulate the shift scenario, and its sensitivities and Fisher information; everything the
    description supports, and what was skipped, with the reason."""
    from gearsym.symbolic.dynamics import gearbox_dynamics
    from gearsym.symbolic.output_dir import OutputDir
    from gearsym.symbolic.ratios import ratio_table

    d = _load(args.config)
    scenario, skipped = _run_scenario(d, args.scenario)
    with OutputDir(args.out, "run", before_commit=check) as out:
        print(f"gearsym: {d.title}")
        start = time.perf_counter()
        dyn = gearbox_dynamics(d, symbolic_inertias=True)
        m = dyn.mass_matrix
        f = len(dyn.kinematics.coordinates)
        print(
            f"  derived kinematics and dynamics in {time.perf_counter() - start:.2f} s: "
            f"{len(d.body_names)} bodies, {len(d.planetary_sets)} sets, {f} DOF, "
            f"y = [{', '.join(str(s) for s in dyn.kinematics.coordinate_symbols)}], "
            f"M {m.rows}×{m.cols} with {sum(1 for e in m if e != 0)} nonzero entries, "
            f"B̃ {dyn.input_matrix.rows}×{dyn.input_matrix.cols}"
        )
        print()
        table = ratio_table(d)  # once: printed and written
        status = print_ratio_table(d, table)
        ratios = {r.gear: (None if r.ratio is None else float(r.ratio)) for r in table}
        (out.path / "ratios.json").write_text(json.dumps(ratios, indent=2) + "\n")
        from gearsym.cmd_observability import print_observability_summary

        print()
        print_observability_summary(d)  # verdict of (4.12) for the 2-3 shift
        steps = {"ratios": "done", "observability": "done"}
        if scenario is not None:
            from gearsym.cmd_analysis import print_fim_summary
            from gearsym.cmd_dynamics import simulate_with_progress
            from gearsym.validation.report import format_summary, write_results

            print()
            result = simulate_with_progress(d, scenario)
            write_results(d, result, out.path)
            print(format_summary(result))
            print()
            print_fim_summary(d, result, folder=out.path)
            steps |= {"simulation": "done", "sensitivity": "done", "fim": "done"}
        else:
            print()
            for step in ("simulation", "sensitivity", "fim"):
                steps[step] = f"skipped: {skipped}"
            print(f"simulation, sensitivities and FIM skipped: {skipped}")
        (out.path / "run.json").write_text(
            json.dumps({"gearbox": d.name, "file": d.file, "steps": steps}, indent=2) + "\n"
        )
        paths = out.commit()
    print(f"  wrote {len(paths)} files to {args.out}")
    return status


# ----------------------------------------------------------------------------- parser


class _Parser(argparse.ArgumentParser):
    """Usage errors (a bad option value, say) as one line, like every other error, exit 2."""

    def error(self, message: str) -> NoReturn:
        where = self.prog.removeprefix("gearsym").strip() or "command line"
        self.exit(2, f"gearsym: {where}: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="gearsym",
        description="Planetary automatic transmission → validated symbolic model → TCU code.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, handler: Callable[[argparse.Namespace], int], text: str) -> Any:
        p = sub.add_parser(name, help=text, description=text)
        p.set_defaults(handler=handler)
        return p

    def config(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "config", nargs="?", help="gearbox description (TOML); default: the built-in gearbox"
        )

    p = command(
        "run",
        cmd_run,
        "Main job: derive the model, print the gear table, simulate the default shift.",
    )
    config(p)
    p.add_argument(
        "--scenario", help="shift scenario (default: the built-in 2-3, where the gearbox fits it)"
    )
    p.add_argument(
        "--out",
        default="out/run",
        help="folder for every result (replaced atomically, and only if gearsym wrote it)",
    )

    p = command("ratios", cmd_ratios, "Derive every gear's ratio ω_in/ω_out (Table 2.1).")
    config(p)
    p.add_argument("--json", action="store_true", help="gear → ratio (null for neutral)")

    p = command(
        "fit-teeth",
        cmd_fit_teeth,
        "Search integer tooth counts that reproduce the description's gear table.",
    )
    config(p)
    p.add_argument("--sun", type=_range, default=(17, 110), help="sun teeth LOW:HIGH")
    p.add_argument("--planet", type=_range, default=(13, 60), help="planet teeth LOW:HIGH")
    p.add_argument(
        "--ring-max",
        type=number(int, minimum=1, maximum=TEETH_MAX),
        default=180,
        help="largest ring tooth count",
    )
    p.add_argument(
        "--planet-count",
        type=_counts,
        default=None,
        help="planet counts to try, e.g. 3,4,5 (default: each set's count in the file)",
    )
    p.add_argument(
        "--tolerance",
        type=number(float, above=0),
        default=None,
        help="largest ratio error (default: half a unit of the table's last printed decimal)",
    )
    p.add_argument(
        "--top", type=number(int, minimum=1), default=10, help="how many candidates to list"
    )
    p.add_argument("--json", action="store_true", help="machine-readable output")

    p = command("show", cmd_show, "Print a derived quantity (constraints, M, B̃, …).")
    config(p)
    p.add_argument("--what", choices=SHOW_ITEMS, default="mass-matrix")
    p.add_argument("--format", choices=("text", "latex", "json"), default="text")
    p.add_argument("--symbolic-teeth", action="store_true", help="keep tooth counts as symbols")
    p.add_argument("--symbolic-inertias", action="store_true", help="keep inertias as symbols")

    command("default-config", cmd_default_config, "Print the built-in gearbox description.")

    from gearsym.cmd_dynamics import add_parsers as add_dynamics_parsers

    add_dynamics_parsers(command, config)

    from gearsym.cmd_observability import add_observability_parser

    add_observability_parser(command, config)

    from gearsym.cmd_generate import add_generate_parser

    add_generate_parser(command, config)

    from gearsym.cmd_analysis import register as add_analysis_parsers

    add_analysis_parsers(command, config)

    from gearsym.cmd_draw import register as add_draw_parser

    add_draw_parser(command, config)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with sigterm_raises():
            return int(args.handler(args))
    except GearsymError as err:
        print(f"gearsym: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gearsym: interrupted; nothing was written", file=sys.stderr)
        return 130
    except Terminated:
        print("gearsym: terminated; nothing was written", file=sys.stderr)
        return 143


if __name__ == "__main__":
    sys.exit(main())
