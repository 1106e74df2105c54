"""The modes of the hybrid shift model (:mod:`gearsym.symbolic.hybrid`) against the reference
simulation, each inside the interval where the reference is in that mode.

The reference (:mod:`gearsym.validation.sim.simulate`) has no modes: its elements stick through
their elasto-plastic bristles (2.66)–(2.68). Its mode is read off the record sample by sample,
per swapping element: **open** where F_N = 0, **sliding** (with the sign of its torque, which is
the sign of the slip, 2.70) where it is pressed and transmits at least ``capacity_fraction`` of
its capacity 2 N_disc r_m μ F_N (the sliding condition of the elasto-plastic model: |z| has
reached z_ss), **locked** otherwise. Each mode model is then integrated from the recorded state
at the start of its interval with the recorded inputs (T_In, the normal forces, μ from the map
as the reference read it, ζ) and compared with the record — the hybrid model's version of
``check_reduced_models`` in :mod:`gearsym.validation.sim.model_checks`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.hybrid import (
    LOCKED,
    OPEN,
    OVERRUNNING,
    SLIDING,
    HybridShift,
    Mode,
    mode_name,
)
from gearsym.symbolic.numeric import casadi_function, integrate_linear_inputs


@dataclass(frozen=True)
class ModeInterval:
    """[t_start, t_end] where the reference is in ``mode`` (sample indices ``first``, ``last``)."""

    mode: str
    t_start: float
    t_end: float
    first: int
    last: int


@dataclass(frozen=True)
class ModeCheck:
    """A mode model integrated inside its interval against the reference."""

    mode: str
    t_start: float
    t_end: float
    max_abs_error: dict[str, float]
    #: max |error| / max |reference| of that state over the interval, worst state
    max_relative_error: float


def time_varying_symbols(hybrid: HybridShift) -> list[sp.Symbol]:
    """u of a compiled mode: T_In, the normal forces, then μ of both elements and ζ, which the
    reference reads from the μ map and the scenario at every instant (2.69), (2.49)."""
    zeta = next(v.symbol for v in hybrid.parameters if v.name == naming.GRADE)
    return [
        *(v.symbol for v in hybrid.inputs),
        *(hybrid.friction_coefficient[e] for e in hybrid.friction_elements),
        zeta,
    ]


def input_columns(hybrid: HybridShift) -> list[str]:
    """Names of the recorded signals that feed :func:`time_varying_symbols`, in that order."""
    return [str(s) for s in time_varying_symbols(hybrid)]


def compile_mode(hybrid: HybridShift, mode: Mode, expressions: sp.Matrix | None = None) -> Any:
    """``casadi.Function`` (x, u) → ``expressions`` (default: the mode's ẋ) with the other
    parameters at their defaults; u as :func:`time_varying_symbols`."""
    varying = time_varying_symbols(hybrid)
    fixed = {
        v.symbol: sp.Float(v.default)
        for v in hybrid.parameters
        if v.default is not None and v.symbol not in varying
    }
    exprs = mode.model.rhs if expressions is None else expressions
    return casadi_function(
        "mode", [("x", mode.model.state_symbols), ("u", varying)], [("out", exprs.xreplace(fixed))]
    )


def reference_statuses(
    hybrid: HybridShift,
    d: Any,
    signals: Mapping[str, np.ndarray],
    capacity_fraction: float = 0.98,
) -> dict[str, list[tuple[str, int]]]:
    """Per swapping element and sample: (status, slip sign) read off the record (module
    docstring)."""
    result = {}
    for e in hybrid.elements:
        element = d.element(e)
        if e in hybrid.one_way:
            # a freewheel carries torque only locked (its blocking sign), none overrunning
            locks = hybrid.one_way[e]
            result[e] = [
                (LOCKED, 0) if locks * t > 0 else (OVERRUNNING, -locks)
                for t in signals[naming.torque(e)]
            ]
            continue
        force = signals[str(hybrid.normal_force[e])]
        mu = signals[str(hybrid.friction_coefficient[e])]
        capacity = 2 * element.n_disc * element.r_m.value * mu * force
        torque = signals[naming.torque(e)]
        status = []
        for f, t, c in zip(force, torque, capacity, strict=True):
            if f <= 0:
                status.append((OPEN, 0))
            elif abs(t) >= capacity_fraction * c:
                status.append((SLIDING, 1 if t > 0 else -1))
            else:
                status.append((LOCKED, 0))
        result[e] = status
    return result


def reference_mode_intervals(
    hybrid: HybridShift,
    d: Any,
    t: np.ndarray,
    signals: Mapping[str, np.ndarray],
    capacity_fraction: float = 0.98,
) -> tuple[ModeInterval, ...]:
    """The record cut into intervals of constant mode (module docstring)."""
    statuses = reference_statuses(hybrid, d, signals, capacity_fraction)
    names = [
        mode_name(hybrid.spec, hybrid.elements, {e: statuses[e][k] for e in hybrid.elements})
        for k in range(len(t))
    ]
    intervals = []
    start = 0
    for k in range(1, len(t) + 1):
        if k == len(t) or names[k] != names[start]:
            intervals.append(
                ModeInterval(names[start], float(t[start]), float(t[k - 1]), start, k - 1)
            )
            start = k
    return tuple(intervals)


def recorded_state(
    mode: Mode, signals: Mapping[str, np.ndarray], index: Sequence[int] | slice
) -> np.ndarray:
    """The mode's states (kept shaft speeds, φ, ω_C) as recorded, samples × states."""
    return np.column_stack([signals[v.name][index] for v in mode.model.states])


def check_modes(
    hybrid: HybridShift,
    d: Any,
    t: np.ndarray,
    signals: Mapping[str, np.ndarray],
    intervals: Sequence[ModeInterval] | None = None,
    min_duration: float = 5e-3,
) -> tuple[ModeCheck, ...]:
    """Each mode model integrated inside each reference interval of at least ``min_duration``
    (CVODES, rtol 1e-10, the recorded inputs linear between samples) against the record."""
    if intervals is None:
        intervals = reference_mode_intervals(hybrid, d, t, signals)
    columns = input_columns(hybrid)
    checks = []
    for interval in intervals:
        if interval.t_end - interval.t_start < min_duration or interval.mode not in hybrid.modes:
            continue
        mode = hybrid.modes[interval.mode]
        inside = slice(interval.first, interval.last + 1)
        u = np.column_stack([signals[c][inside] for c in columns])
        reference = recorded_state(mode, signals, inside)
        model = integrate_linear_inputs(compile_mode(hybrid, mode), reference[0], t[inside], u)
        errors = np.max(np.abs(model - reference), axis=0)
        scales = np.maximum(np.max(np.abs(reference), axis=0), 1e-12)
        checks.append(
            ModeCheck(
                mode=mode.name,
                t_start=interval.t_start,
                t_end=interval.t_end,
                max_abs_error={
                    v.name: float(e) for v, e in zip(mode.model.states, errors, strict=True)
                },
                max_relative_error=float(np.max(errors / scales)),
            )
        )
    return tuple(checks)


def reaction_along_record(
    hybrid: HybridShift, mode: Mode, element: str, signals: Mapping[str, np.ndarray], index: slice
) -> np.ndarray:
    """T_req of a locked element (the mode's constraint reaction, sign of 2.36) evaluated on the
    recorded states and inputs."""
    function = compile_mode(hybrid, mode, sp.Matrix([mode.reaction[element]]))
    x = recorded_state(mode, signals, index)
    u = np.column_stack([signals[c][index] for c in input_columns(hybrid)])
    out = function.map(len(x))(x.T, u.T)
    return np.asarray(out.full(), dtype=float).ravel()
