"""The element modes the EKF (4.3) switches between: slip and stick of each swapping element,
as the filter detects them and as the reference simulation has them, and the two matched.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name
from gearsym.validation.sim.simulate import SimulationResult

__all__ = [
    "MODE_SOURCES",
    "ModeSwitch",
    "element_modes",
    "match_switches",
    "mode_switches",
    "reference_switches",
]


def element_modes(
    d: GearboxDescription, result: SimulationResult, t: np.ndarray
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per swapping element, (slides, sticks) as 0/1 at the sample times ``t``.

    From the reference's sliding masks (:func:`sliding_masks`: pressed and transmitting its
    capacity); an element that does not slide sticks while it is pressed and is open
    otherwise. These are the *truth's* modes (``--modes reference``); by default the filter
    decides its modes itself (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`).
    """
    from gearsym.validation.studies.driven_shift import (
        driven_shift_model,
        reference_from_result,
        sliding_masks,
    )

    data = reference_from_result(result)
    driven = driven_shift_model(d, data.shift)
    masks = sliding_masks(d, driven, data)
    index = np.clip(np.searchsorted(data.t, t - 1e-12), 0, len(data.t) - 1)
    modes = {}
    for e in driven.elements:
        force = data.signals[naming.normal_force(element_short_name(d, e))][index]
        slides = masks[e][index]
        modes[e] = (slides.astype(float), ((~slides) & (force > 0)).astype(float))
    return modes


#: Where the EKF's element modes come from: its own mode logic (the TCU's view, default) or
#: the reference's sliding masks (the truth, for comparison).
MODE_SOURCES = ("filter", "reference")


@dataclass(frozen=True)
class ModeSwitch:
    """A mode switch of one element at time ``t``: ``kind`` break-away, lock-up, opening or
    engagement (the hybrid model's guards); ``before``/``after`` are mode codes
    (:mod:`gearsym.symbolic.estimators.ekf_modes`: 0 open, ±1 slide, 2 stick)."""

    element: str
    kind: str
    t: float
    before: int
    after: int


def _status_code(slides: np.ndarray, sticks: np.ndarray) -> np.ndarray:
    """0 open, 1 slide, 2 stick per sample from 0/1 (or ±1) flags."""
    return np.where(np.abs(slides) > 0.5, 1, np.where(sticks > 0.5, 2, 0))


def mode_switches(
    t: np.ndarray, codes: Mapping[str, np.ndarray], first: Mapping[str, int] | None = None
) -> list[ModeSwitch]:
    """The switches of per-sample mode codes (0 open, ±1 slide, 2 stick; the mode held from
    sample k on), in time order: stick → slide is a break-away, slide → stick (or a slide
    reversing its direction) a lock-up, → open an opening, open → slide or stick an
    engagement. ``first``: the mode before the first sample (the from-gear), so that a switch
    at the first sample counts too (without it the first sample's mode is the start)."""
    from gearsym.symbolic.hybrid import BREAK_AWAY, ENGAGEMENT, LOCK_UP, OPENING

    out = []
    for e, code in codes.items():
        before = int(code[0]) if first is None else int(first[e])
        for k in range(len(t)):
            now = int(code[k])
            if now == before:
                continue
            if now == 0:
                kind = OPENING
            elif before == 0:
                kind = ENGAGEMENT
            elif before == 2:
                kind = BREAK_AWAY
            else:
                kind = LOCK_UP
            out.append(ModeSwitch(e, kind, float(t[k]), before, now))
            before = now
    return sorted(out, key=lambda m: (m.t, m.element))


def reference_switches(d: GearboxDescription, result: SimulationResult) -> list[ModeSwitch]:
    """The truth's mode switches on the reference simulation's own time grid (its sliding
    masks, :func:`element_modes`): the times the filter's detected events are compared with."""
    modes = element_modes(d, result, np.asarray(result.t, dtype=float))
    codes = {e: _status_code(*flags) for e, flags in modes.items()}
    return mode_switches(np.asarray(result.t, dtype=float), codes)


def match_switches(
    detected: Sequence[ModeSwitch], truth: Sequence[ModeSwitch]
) -> list[dict[str, Any]]:
    """Per truth switch (element, kind, in order) the detected one of the same element and
    kind and rank, and the error t_detected − t_truth in ms (None: not detected); detected
    switches without a truth counterpart follow with ``t_reference`` None."""
    out: list[dict[str, Any]] = []
    used: set[int] = set()
    for e, kind in dict.fromkeys((m.element, m.kind) for m in truth):
        mine = [i for i, m in enumerate(detected) if m.element == e and m.kind == kind]
        theirs = [m for m in truth if m.element == e and m.kind == kind]
        for rank, ref in enumerate(theirs):
            hit = detected[mine[rank]] if rank < len(mine) else None
            if hit is not None:
                used.add(mine[rank])
            out.append(
                {
                    "element": e,
                    "kind": kind,
                    "t_reference": ref.t,
                    "t_detected": None if hit is None else hit.t,
                    "error_ms": None if hit is None else 1e3 * (hit.t - ref.t),
                }
            )
    for i, m in enumerate(detected):
        if i not in used:
            out.append(
                {
                    "element": m.element,
                    "kind": m.kind,
                    "t_reference": None,
                    "t_detected": m.t,
                    "error_ms": None,
                }
            )
    return out
