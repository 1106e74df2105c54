"""Which shifts ``gearsym generate`` emits code for: the shift models (``--shifts``) and the
TCU shift controllers (``--controllers``), read from the command line's words against the
description's gear table; a bad selection is a one-line error naming the option."""

from __future__ import annotations

from gearsym.symbolic.defaults import DEFAULT_SHIFT
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import adjacent_shifts
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.shifts import ShiftSpec, shift_spec

__all__ = ["SHIFT_SELECTIONS", "controller_shifts", "selected_shifts"]

#: ``--shifts`` keywords: the adjacent upshifts (default) or every single- and double-swap shift.
SHIFT_SELECTIONS = ("adjacent", "all")


def selected_shifts(
    d: GearboxDescription, shifts: str = "adjacent", key: str = "--shifts"
) -> list[ShiftSpec]:
    """The shifts whose models ``generate`` emits.

    ``"adjacent"``: the upshifts between forward gears adjacent by ratio (the thesis' shifts);
    ``"all"``: every ordered pair of gears with a drive path that swaps exactly one element
    (upshifts, downshifts, skip shifts such as 5-3, and reverse engagements where they are
    single swaps), adjacent upshifts first, then every pair that swaps two elements each way
    (double swaps such as 1-5: their torque-input model only,
    :data:`~gearsym.symbolic.export.index.DOUBLE_SWAP_NOTE`);
    otherwise a comma-separated list such as ``"3-2,5-3,1-5"`` (each a single or double swap,
    else a one-line error naming it).
    """
    adjacent = adjacent_shifts(d)
    if shifts == "adjacent":
        return adjacent
    if shifts == "all":
        names = [spec.name for spec in adjacent]
        doubles = []
        driven = [g.name for g in d.gears if not g.neutral]
        for a in driven:
            for b in driven:
                if a == b or f"{a}-{b}" in names:
                    continue
                gear_a, gear_b = d.gear(a), d.gear(b)
                off = set(gear_a.closed) - set(gear_b.closed)
                on = set(gear_b.closed) - set(gear_a.closed)
                if len(off) == 1 and len(on) == 1:
                    names.append(f"{a}-{b}")
                elif len(off) == 2 and len(on) == 2:
                    doubles.append(f"{a}-{b}")
        return [shift_spec(d, name, max_swaps=2) for name in names + doubles]
    names = [part.strip() for part in shifts.split(",") if part.strip()]
    if not names:
        raise GearsymError(d.file, key, "expected adjacent, all or a list such as 3-2,5-3")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise GearsymError(d.file, key, f"shift {twice[0]} listed twice")
    try:
        return [shift_spec(d, name, max_swaps=2) for name in names]
    except GearsymError as err:  # the option the user gave, not the description's key
        raise GearsymError(d.file, key, err.reason) from None


def controller_shifts(
    d: GearboxDescription, shifts: str = "adjacent", controllers: str | None = None
) -> list[ShiftSpec]:
    """The shifts whose TCU shift controller (with its EKF) ``generate`` emits: by default the
    thesis' shift (:data:`~gearsym.symbolic.defaults.DEFAULT_SHIFT`) when its model is among
    ``shifts``; ``"none"``; or ``controllers`` as :func:`selected_shifts` reads it (upshifts,
    downshifts, skip shifts). A double swap is a one-line error: the controller hands one
    element's torque over to one other."""
    if controllers == "none":
        return []
    if controllers is None:
        return [s for s in selected_shifts(d, shifts) if s.name == DEFAULT_SHIFT][:1]
    specs = selected_shifts(d, controllers, "--controllers")
    for spec in specs:
        if not spec.single:
            raise GearsymError(
                d.file,
                "--controllers",
                f"shift {spec.name} swaps two elements each way: the controller hands one "
                "element's torque over to one other",
            )
    return specs
