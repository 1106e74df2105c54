"""``gearsym draw [CONFIG] --what stick|lever|speeds|drivetrain [--gear G] --out FILE [--json]``.

The pictures a gearbox engineer checks a description with: the stick diagram (thesis
Fig. 2.1 style), the lever analogy (Benford & Leising, SAE 810102), the speed plan of one gear
or of every gear, and the drivetrain (Fig. 2.2). Geometry comes from
:mod:`gearsym.validation.drawing.geometry`, pixels from :mod:`gearsym.validation.drawing.render`;
both, and matplotlib, are imported inside the handler so that ``gearsym --help`` stays light.

``--out FILE`` names one file, ``.svg`` or ``.png`` (the format follows the suffix). It is
written through :class:`gearsym.symbolic.io.output_dir.OutputFile`: atomically, parent folders
created, and only over a file gearsym wrote (its embedded signature matches its content), so
re-running the command refreshes the picture but never replaces a user's file or a picture
edited since. The same input gives the same bytes. ``--json`` prints the geometry and values
the picture shows to stdout (``--out`` is then optional).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from gearsym.commands import add_command, load
from gearsym.symbolic.errors import GearsymError

if TYPE_CHECKING:
    from gearsym.commands import Subparsers

__all__ = ["cmd_draw", "register"]

#: Kept here as well as in the drawing module so that building the parser imports nothing.
KINDS = ("stick", "lever", "speeds", "drivetrain")
_NAMES = {
    "stick": "stick diagram",
    "lever": "lever diagram",
    "speeds": "speed plan",
    "drivetrain": "drivetrain",
}


def _kind(text: str) -> str:
    if text not in KINDS:
        raise argparse.ArgumentTypeError(
            f"unknown picture {text!r}; expected {', '.join(KINDS[:-1])} or {KINDS[-1]}"
        )
    return text


def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None:
    """Register ``gearsym draw``."""
    p = add_command(
        subparsers,
        "draw",
        cmd_draw,
        "Draw the gearbox: stick diagram, lever analogy, speed plan per gear, drivetrain "
        "(SVG or PNG; --json for the values shown).",
        common,
    )
    p.add_argument(
        "--what",
        type=_kind,
        required=True,
        metavar="|".join(KINDS),
        help="which picture",
    )
    p.add_argument(
        "--gear",
        default=None,
        help="with --what speeds: one gear's plan (default: every gear in one figure)",
    )
    p.add_argument(
        "--out",
        default=None,
        metavar="FILE.svg|FILE.png",
        help="the picture; replaced only if gearsym wrote it (format from the suffix)",
    )
    p.add_argument("--json", action="store_true", help="print the geometry and values as JSON")


def cmd_draw(args: argparse.Namespace) -> int:
    """Check every option, compute the geometry, render, write atomically."""
    from gearsym.symbolic.io.output_dir import OutputFile

    if args.gear is not None and args.what != "speeds":
        raise GearsymError("command line", "--gear", f"only with --what speeds, not {args.what}")
    if args.out is None and not args.json:
        raise GearsymError("command line", "--out", "required (FILE.svg or FILE.png), or --json")
    # Open the target first: a bad suffix or a foreign file costs no rendering.
    out = OutputFile(args.out, "draw") if args.out is not None else None
    d = load(args.config)
    from gearsym.validation.drawing import geometry as drawing

    plans = None
    if args.what == "speeds":
        gears = [args.gear] if args.gear is not None else [g.name for g in d.gears]
        plans = [drawing.speed_plan(d, g) for g in gears]  # an unknown gear raises here
    if args.what == "stick":
        geometry = drawing.stick_diagram(d)
    elif args.what == "drivetrain":
        geometry = drawing.drivetrain_diagram(d)
    else:
        geometry = drawing.lever_diagram(d)
    if args.json:
        json.dump(drawing.to_json(args.what, d, geometry, plans), sys.stdout, indent=2)
        sys.stdout.write("\n")
    if out is None:
        return 0
    with out:
        from gearsym.validation.drawing import render
        from gearsym.validation.drawing.figures import to_bytes

        if args.what == "stick":
            fig = render.stick_figure(d, geometry)
        elif args.what == "drivetrain":
            fig = render.drivetrain_figure(d, geometry)
        elif args.what == "lever":
            fig = render.lever_figure(d)
        else:
            assert plans is not None
            fig = render.speeds_figure(d, plans)
        data = to_bytes(fig, out.target.suffix.lower().lstrip("."))
        out.commit(data)
    which = _NAMES[args.what] + (f" of gear {args.gear}" if args.gear is not None else "")
    print(f"wrote the {which} of {d.name} to {args.out}", file=sys.stderr if args.json else None)
    return 0
