"""Observability per mode of the hybrid shift model (issue 15 item 6).

The thesis ranks ``Q`` (4.7) of one shift model in which both swapping elements slide, and
states rank 8 for ``x = [ω1, ω2, φ, ω_C]``, ``p = [m_veh, μ38, μ05, ζ]`` (4.12). The hybrid
model (:mod:`gearsym.symbolic.hybrid`) says when that model holds: only while both elements
slide. This module ranks every mode of the shift on its own model, so "rank 8 in the torque
phase" and "what is left in gear 3" are separate statements.

The estimated set of a mode is the requested one without the μ of each element that does not
slide there: a locked element carries its constraint reaction and an open one no torque, so
its μ does not enter the mode's equations (3.14 holds "nur im Gleitbereich") and has no
influence at all on the outputs of that mode. Appending it as a random-walk state (4.1) would
only add a zero column to ``Q``: it is reported as excluded, with the reason, instead of as
"unobservable".

The two slip signs of a sliding element give two modes whose models differ only in the sign of
T = ±2 N r_m μ F_N (2.70); μ → −μ is a reparametrisation, so both have the same rank and the
same unobservable set (tested, not assumed).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.observability.rank import ObservabilityResult, analyze_observability
from gearsym.symbolic.observability.report import (
    parse_conditions,
    parse_input_models,
    partial_text,
)

__all__ = ["ModeObservability", "analyze_modes", "mode_order"]


@dataclass(frozen=True)
class ModeObservability:
    """The generic verdict (4.12) of one mode's augmented model (4.1).

    ``status`` is ``element → "locked" | "slide_pos" | "slide_neg" | "open"``; ``estimated``
    the parameters appended as random-walk states; ``excluded`` each requested parameter left
    out, with the reason (a μ of an element that does not slide in this mode).
    """

    mode: str
    status: dict[str, str]
    states: tuple[str, ...]
    estimated: tuple[str, ...]
    excluded: dict[str, str]
    result: ObservabilityResult
    seconds: float

    @property
    def rank(self) -> int:
        return self.result.rank

    @property
    def n_unknowns(self) -> int:
        return self.result.n_unknowns

    @property
    def unobservable(self) -> tuple[str, ...]:
        return tuple(self.result.unobservable)

    def to_dict(self) -> dict[str, Any]:
        r = self.result
        return {
            "mode": self.mode,
            "status": dict(self.status),
            "states": list(self.states),
            "estimated": list(self.estimated),
            "excluded": dict(self.excluded),
            "rank": r.rank,
            "n_unknowns": r.n_unknowns,
            "full_rank": r.full_rank,
            "certain": r.certain,
            "max_order": r.max_order,
            "rank_by_order": list(r.rank_by_order),
            "unobservable": list(r.unobservable),
            "unobservable_directions": [dict(v) for v in r.unobservable_directions],
            "seconds": self.seconds,
        }


def mode_order(hybrid: Any) -> list[str]:
    """The modes in the order a single-swap shift meets them: the from-gear, the off-going
    element sliding alone, both sliding, the on-coming sliding alone, the to-gear; then the
    remaining combinations (e.g. the on-coming element sliding while the off-going one is still
    locked, or both open); slip sign + before −."""
    off, on = hybrid.elements
    path = [
        ("locked", "open"),
        ("sliding", "open"),
        ("sliding", "sliding"),
        ("open", "sliding"),
        ("open", "locked"),
    ]

    def key(name: str) -> tuple[int, tuple[str, str], int, int]:
        status = hybrid.modes[name].status
        pair = (status[off][0], status[on][0])
        position = path.index(pair) if pair in path else len(path)
        return (position, pair, -status[off][1], -status[on][1])

    return sorted(hybrid.modes, key=key)


def analyze_modes(
    d: GearboxDescription,
    shift: str,
    *,
    params: Sequence[str] | None = None,
    input_models: Sequence[str] | None = None,
    conditions: Sequence[str] | None = None,
    symbolic_known: bool = False,
    seed: int | None = None,
    time_budget: float | None = None,
) -> list[ModeObservability]:
    """The generic rank of ``Q`` (4.7), (4.12) of every mode of the hybrid ``shift``
    (:func:`gearsym.symbolic.hybrid.hybrid_shift`), in :func:`mode_order`.

    ``params`` (default ``m_veh``, the μ of both swapping elements, ``zeta``: p of (4.1)) are
    estimated where they act; a μ of an element that is locked or open in a mode is excluded
    there (module docstring). Every other parameter is fixed at its default unless
    ``symbolic_known``. Outputs are the mode model's measured speeds (3.31). ``conditions``
    (``NAME=VALUE``) and ``input_models`` (``NAME=generic|constant|poly:K``) apply to every
    mode that has the variable; a name that no mode has is an error keyed ``--at`` /
    ``--input-model``. Raises :class:`GearsymError` for bad input.
    """
    from gearsym.symbolic.hybrid import hybrid_shift, status_label
    from gearsym.symbolic.input_gain import INPUT_TORQUE_GAIN, with_input_torque_gain
    from gearsym.symbolic.observability.errors import BudgetExceeded, ObservabilityError

    try:
        hybrid = hybrid_shift(d, shift)
    except GearsymError as err:
        if err.key == "shift":
            raise GearsymError(err.file, "--shift", err.reason) from None
        raise
    mus = {str(mu): e for e, mu in hybrid.friction_coefficient.items()}
    known = {v.name for v in hybrid.parameters} | {INPUT_TORQUE_GAIN}
    requested = list(params) if params is not None else ["m_veh", *mus, "zeta"]
    gained = INPUT_TORQUE_GAIN in requested  # T_In told, times a gain (input_gain)
    stray = [p for p in requested if p not in known]
    if stray:
        raise GearsymError(
            d.file,
            "--params",
            f"unknown parameter(s) {', '.join(stray)}; parameters of the hybrid model: "
            f"{', '.join(sorted(known))}",
        )
    twice = sorted({p for p in requested if requested.count(p) > 1})
    if twice:
        raise GearsymError(d.file, "--params", f"parameter(s) given twice: {', '.join(twice)}")
    _check_names(d, hybrid, "--at", conditions or ())
    _check_names(d, hybrid, "--input-model", input_models or (), allow_all=True)

    results = []
    for name in mode_order(hybrid):
        mode = hybrid.modes[name]
        model = with_input_torque_gain(mode.model) if gained else mode.model
        present = {v.name for v in model.parameters}
        variables = {v.name for v in (*model.states, *model.inputs, *model.parameters)}
        excluded = {}
        for p in requested:
            element = mus.get(p)
            if element is not None and mode.status[element][0] != "sliding":
                excluded[p] = (
                    f"{element} is {mode.status[element][0]} in this mode: its torque is "
                    + (
                        "the constraint reaction"
                        if mode.status[element][0] == "locked"
                        else "zero (F_N = 0)"
                    )
                    + ", not (3.14), so μ has no influence here"
                )
            elif p not in present:
                excluded[p] = "not in this mode's equations: no influence here"
        estimate = [p for p in requested if p not in excluded]
        conds = parse_conditions(d, model, _restrict(conditions or (), variables))
        models = parse_input_models(d, model, _restrict(input_models or (), variables | {"all"}))
        fixed = (
            []
            if symbolic_known
            else [
                v.name
                for v in model.parameters
                if v.name not in estimate and v.default is not None and v.name not in conds
            ]
        )
        started = time.perf_counter()
        try:
            result = analyze_observability(
                model,
                estimate,
                substitute_defaults=fixed,
                input_models=models,
                conditions=conds,
                patience=1,
                seed=seed,
                time_budget=time_budget,
            )
        except BudgetExceeded as exc:
            raise GearsymError(
                d.file, "--time-budget", f"{name}: {exc}; {partial_text(exc.partial)}"
            ) from None
        except ObservabilityError as exc:
            raise GearsymError(d.file, "--at" if conds else "model", f"{name}: {exc}") from None
        results.append(
            ModeObservability(
                mode=name,
                status={e: status_label(*mode.status[e]) for e in hybrid.elements},
                states=tuple(v.name for v in model.states),
                estimated=tuple(estimate),
                excluded=excluded,
                result=result,
                seconds=time.perf_counter() - started,
            )
        )
    return results


def _restrict(items: Sequence[str], names: set[str]) -> list[str]:
    """The ``NAME=...`` items whose NAME (or ``NAME__dK``) the mode has."""
    kept = []
    for item in items:
        name = item.split("=", 1)[0].strip()
        if name in names or name.split("__d", 1)[0] in names:
            kept.append(item)
    return kept


def _check_names(
    d: GearboxDescription, hybrid: Any, key: str, items: Sequence[str], allow_all: bool = False
) -> None:
    """A ``NAME=...`` item must name a variable of at least one mode (else it would silently
    apply nowhere)."""
    names = {"all"} if allow_all else set()
    for mode in hybrid.modes.values():
        m = mode.model
        names |= {v.name for v in (*m.states, *m.inputs, *m.parameters)}
    for item in items:
        if "=" not in item:
            raise GearsymError(d.file, key, f"expected NAME=VALUE, got {item!r}")
        name = item.split("=", 1)[0].strip()
        if name not in names and name.split("__d", 1)[0] not in names:
            raise GearsymError(
                d.file, key, f"{name!r} is a variable of no mode of the {hybrid.spec.name} shift"
            )
