"""``gearsym ratios``, ``fit-teeth``, ``show`` and ``default-config``: the gearbox itself.

The gear table (Table 2.1), the tooth-count search, the derived kinematic and dynamic
quantities (2.20)–(2.41) and the built-in description; this module parses and prints, the
library (:mod:`gearsym.symbolic.ratios`, :mod:`~gearsym.symbolic.teeth`,
:mod:`~gearsym.symbolic.dynamics`) computes.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from gearsym.commands import add_command, emit_json, load, progress
from gearsym.options import cacheable, number
from gearsym.symbolic.description import PLANET_COUNT_MAX, TEETH_MAX

if TYPE_CHECKING:
    from gearsym.commands import Subparsers
    from gearsym.symbolic.ratios import GearRatio

__all__ = [
    "SHOW_ITEMS",
    "cmd_default_config",
    "cmd_fit_teeth",
    "cmd_ratios",
    "cmd_show",
    "print_ratio_table",
    "ratio_json",
    "register",
]


# ----------------------------------------------------------------------------- ratios


def ratio_json(table: Sequence[GearRatio]) -> dict[str, Any]:
    """``{gear: ratio or null}``, plus ``"_free_shafts": {gear: [shaft, ...]}`` when some
    gear leaves a shaft idle; the one shape ``ratios --json`` prints and ``run`` writes."""
    data: dict[str, Any] = {r.gear: (None if r.ratio is None else float(r.ratio)) for r in table}
    idle = {r.gear: list(r.free_shafts) for r in table if r.free_shafts and not r.neutral}
    if idle:
        # "_" cannot start a gear name: the key never clashes with a gear (README)
        data["_free_shafts"] = idle
    return data


def cmd_ratios(args: argparse.Namespace) -> int:
    """Gear table; exit code 1 when a derived ratio differs from the expected one (text and
    JSON alike). The JSON stays ``{gear: ratio or null}`` (README, tests); the gears that
    differ are named on stderr."""
    from gearsym.symbolic.ratios import ratio_table

    d = load(args.config)
    table = ratio_table(d)
    places = d.ratio_decimals
    differ = _differing_gears(d, table)
    source = f" ({d.gear_table_source})" if d.gear_table_source else ""
    if args.json:
        emit_json(ratio_json(table))
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
    idle = [r for r in table if r.free_shafts and not r.neutral]
    if idle:
        from gearsym.symbolic.drivetrain import idle_drag

        drag = idle_drag(d)
        assumption = f"model assumes drag {drag.value:g} N·m·s/rad to the housing per idle shaft"
    for r in idle:
        # The ratio is fixed, but these shafts are not driven by it (README "Idle shafts").
        print(f"gear {r.gear}: idle: {', '.join(r.free_shafts)} (speed undetermined; {assumption})")
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
    """Tooth counts that reproduce every ratio of the gear table (Table 2.1) within the
    tolerance; exit code 1 when no candidate in the ranges does."""
    from gearsym.symbolic.loader import load_description
    from gearsym.symbolic.teeth import ToothRanges, fit_teeth, teeth_keys

    # The file's teeth are not needed: a set may give none yet (or zeros), README "fit-teeth".
    d = load_description(args.config, teeth_optional=True)
    kinds = {ps.name: ps.kind for ps in d.planetary_sets}
    ranges = ToothRanges(
        sun=args.sun, planet=args.planet, ring_max=args.ring_max, planet_counts=args.planet_count
    )
    start = time.perf_counter()
    candidates = fit_teeth(
        d,
        ranges,
        tolerance=args.tolerance,
        top=args.top,
        progress=None if args.json else progress,
    )
    elapsed = time.perf_counter() - start
    if args.json:
        emit_json(
            [
                {
                    "max_error": c.max_error,
                    "sets": {
                        s: dict(zip(teeth_keys(kinds[s]), t, strict=True))
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
        counts = sorted({ps.planet_count for ps in d.planetary_sets if ps.planet_count})
        if args.planet_count is None and counts:
            print(
                f"  Only the planet count of each set in the file was tried "
                f"({', '.join(map(str, counts))}): equal spacing (z_sun + z_ring divisible by "
                f"it) rules out many teeth; try --planet-count 3,4,5."
            )
        return 1
    print(f"{len(candidates)} candidate(s) within ±{tol:g} of every ratio ({elapsed:.1f} s):")
    for rank, c in enumerate(candidates, start=1):
        print(f"\n#{rank}  largest ratio error {c.max_error:.2e}")
        for s, t in c.teeth.items():
            zs, zp, zr, n = t[:4]
            # the same stationary ratio with other teeth or planet counts, each once
            listed = list(dict.fromkeys(c.alternatives.get(s, [])))[:4]
            alts = ", ".join("/".join(map(str, a[:3] + a[4:])) + f"×{a[3]}" for a in listed)
            more = f"   (same k: {alts})" if alts else ""
            extra = "".join(
                f"  {key.removeprefix('z_')} {z:3d}"
                for key, z in zip(teeth_keys(kinds[s])[4:], t[4:], strict=True)
            )
            print(f"   set {s:<4} sun {zs:3d}  planet {zp:3d}  ring {zr:3d}{extra}  ×{n}{more}")
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
    """One derived quantity, (2.22)–(2.41), as text, LaTeX or JSON."""
    import sympy as sp

    from gearsym.symbolic.dynamics import gearbox_dynamics

    d = load(args.config)
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
        emit_json(
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


# ----------------------------------------------------------------------------- default-config


def cmd_default_config(args: argparse.Namespace) -> int:
    """The built-in description (the thesis' 9-speed gearbox) on stdout."""
    from gearsym.symbolic.description import default_config_text

    sys.stdout.write(default_config_text())
    return 0


# ----------------------------------------------------------------------------- parser


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``ratios``, ``fit-teeth``, ``show`` and ``default-config``."""
    p = add_command(
        subparsers,
        "ratios",
        cmd_ratios,
        "Derive every gear's ratio ω_in/ω_out (Table 2.1).",
        common,
    )
    p.add_argument("--json", action="store_true", help="gear → ratio (null for neutral)")
    cacheable(p)

    p = add_command(
        subparsers,
        "fit-teeth",
        cmd_fit_teeth,
        "Search integer tooth counts that reproduce the description's gear table.",
        common,
    )
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

    p = add_command(
        subparsers,
        "show",
        cmd_show,
        "Print a derived quantity (constraints, M, B̃, …).",
        common,
    )
    p.add_argument("--what", choices=SHOW_ITEMS, default="mass-matrix")
    p.add_argument("--format", choices=("text", "latex", "json"), default="text")
    p.add_argument("--symbolic-teeth", action="store_true", help="keep tooth counts as symbols")
    p.add_argument("--symbolic-inertias", action="store_true", help="keep inertias as symbols")

    add_command(
        subparsers,
        "default-config",
        cmd_default_config,
        "Print the built-in gearbox description.",
    )
