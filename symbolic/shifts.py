"""Shifts of a gear table: which elements stay locked, go off and come on (thesis 3.1).

Pure data over a :class:`~gearsym.symbolic.description.GearboxDescription` (no SymPy): the
names of the models a description will have (:func:`gearsym.symbolic.naming.check_names`)
and every shift model of the derivation (:mod:`gearsym.symbolic.drivetrain`) read their
shifts here.
"""

from __future__ import annotations

from dataclasses import dataclass

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError

__all__ = ["ShiftSpec", "shift_spec"]


@dataclass(frozen=True)
class ShiftSpec:
    """A shift: the common elements stay locked, the others swap (3.1).

    A single swap has one off-going and one on-coming element (``off_going``, ``on_coming``).
    A double swap (from :func:`shift_spec` with ``max_swaps=2`` only) has two of each in
    ``off_elements``, ``on_elements``; its ``off_going`` and ``on_coming`` are ``""``, and
    every analysis that needs a single swap takes its spec from :func:`shift_spec` with the
    default ``max_swaps=1``, which refuses a double swap with a one-line error.
    """

    name: str
    from_gear: str
    to_gear: str
    locked: tuple[str, ...]
    off_going: str
    on_coming: str
    #: Every off-going / on-coming element, in the gear table's order (one each for a single
    #: swap: filled from ``off_going`` / ``on_coming`` when not given).
    off_elements: tuple[str, ...] = ()
    on_elements: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.off_elements and self.off_going:
            object.__setattr__(self, "off_elements", (self.off_going,))
        if not self.on_elements and self.on_coming:
            object.__setattr__(self, "on_elements", (self.on_coming,))

    @property
    def single(self) -> bool:
        """True for a single swap (one element off, one on)."""
        return len(self.off_elements) == 1 and len(self.on_elements) == 1

    @property
    def swapping(self) -> tuple[str, ...]:
        """The elements that act as input torques in the shift model: off-going, then
        on-coming."""
        return (*self.off_elements, *self.on_elements)


def shift_spec(d: GearboxDescription, name: str, max_swaps: int = 1) -> ShiftSpec:
    """Parse ``"2-3"`` into the elements that stay locked, go off and come on.

    ``max_swaps`` is the most off-going (and on-coming) elements accepted: 1 (every analysis
    of a single-swap shift) or 2 (the torque-input shift model of a double swap,
    :func:`shift_model`)."""
    parts = name.split("-")
    if len(parts) != 2:
        raise GearsymError(d.file, "shift", f"expected FROM-TO (e.g. 2-3), got {name!r}")
    gears = {g.name: g for g in d.gears}
    for part in parts:
        if part not in gears:
            raise GearsymError(d.file, "shift", f"unknown gear {part!r} in shift {name!r}")
    g_from, g_to = gears[parts[0]], gears[parts[1]]
    if g_from.neutral or g_to.neutral:
        raise GearsymError(d.file, "shift", f"shift {name!r} involves a neutral gear")
    common = tuple(e for e in g_from.closed if e in g_to.closed)
    off = [e for e in g_from.closed if e not in g_to.closed]
    on = [e for e in g_to.closed if e not in g_from.closed]
    if len(off) == len(on) == 2 and max_swaps >= 2:
        return ShiftSpec(name, g_from.name, g_to.name, common, "", "", tuple(off), tuple(on))
    if len(off) != 1 or len(on) != 1:
        double = len(off) == len(on) == 2
        raise GearsymError(
            d.file,
            "shift",
            f"gears {g_from.name!r} and {g_to.name!r} differ by {len(off)} off-going and "
            f"{len(on)} on-coming elements; a shift model needs exactly one of each"
            + (
                " (a double swap has the torque-input model only, no mu form, hybrid modes "
                "or sensitivities: gearsym model --shift, gearsym generate --shifts)"
                if double
                else ""
            ),
        )
    return ShiftSpec(name, g_from.name, g_to.name, common, off[0], on[0])
