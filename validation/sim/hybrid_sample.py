"""The signals of a hybrid simulation (:mod:`gearsym.validation.sim.hybrid_simulation`) at
a grid of times, read from the pieces' dense output: shaft speeds, twist, wheel speed, each
element's slip, torque, normal force and μ, and the sensitivities riding along. A simulator
running compiled reads each mode's functions through its compiled C in one loop per mode
(:meth:`~gearsym.validation.sim.compiled_c.CompiledFunction.many`), else through CasADi's
``map``: the same arithmetic."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.validation.sim.hybrid_result import Piece, states_of

__all__ = ["sample_signals", "signal_name"]


def sample_signals(
    simulator: Any, pieces: Sequence[Piece], grid: np.ndarray, p: np.ndarray, m: int = 0
) -> tuple[dict[str, np.ndarray], tuple[str, ...], dict[str, np.ndarray]]:
    """Every signal (and its sensitivities, samples × parameters) at the grid; a sample at a
    switch takes the later piece. ``simulator``: the
    :class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator` (typed loosely: that
    module imports this one)."""
    hybrid = simulator.hybrid
    shafts = [s.name for s in simulator.d.shafts]
    keys = [naming.speed(s) for s in shafts] + [naming.TWIST, naming.WHEEL_SPEED]
    signals = {k: np.zeros(len(grid)) for k in keys}
    sensitivities = {k: np.zeros((len(grid), m)) for k in keys} if m else {}
    for e in simulator.hybrid.elements:
        keys = [naming.slip_column(e), naming.torque(e)]
        if e in simulator.hybrid.normal_force:
            keys += [str(hybrid.normal_force[e]), str(hybrid.friction_coefficient[e])]
        for key in keys:
            signals[key] = np.zeros(len(grid))
    modes = [""] * len(grid)
    owner = _owners(pieces, grid)
    # the states piece by piece, the mode's functions once per mode over all its samples
    # (a CasADi map per piece cost more than the arithmetic: a closed-loop shift has
    # hundreds of pieces)
    by_mode: dict[str, list[tuple[np.ndarray, Piece]]] = {}
    order = np.argsort(owner, kind="stable")
    bounds = np.searchsorted(owner[order], np.arange(len(pieces) + 1))
    for k, piece in enumerate(pieces):
        index = order[bounds[k] : bounds[k + 1]]
        if index.size:
            by_mode.setdefault(piece.mode, []).append((index, piece))
    for mode, parts in by_mode.items():
        index = np.concatenate([i for i, _ in parts])
        y = states_of([piece for _, piece in parts], [grid[i] for i, _ in parts])
        compiled = simulator.modes[mode]
        n = compiled.n
        x = y[:, :n]
        u = simulator.inputs_many(grid[index])
        c = simulator._c()
        if c is not None:
            speeds_c = c[signal_name(mode, "speeds")]
            speeds = speeds_c.many(x)
        else:
            speeds_of = simulator.shaft_speeds(mode).map(len(x))
            speeds = np.asarray(speeds_of(x.T).full()).T
        names = [v.name for v in compiled.mode.model.states]
        for j, s in enumerate(shafts):
            signals[naming.speed(s)][index] = speeds[:, j]
        signals[naming.TWIST][index] = x[:, names.index(naming.TWIST)]
        signals[naming.WHEEL_SPEED][index] = x[:, names.index(naming.WHEEL_SPEED)]
        for col in range(m):
            # the shaft speeds are linear in x (ẏ = P z): their sensitivities are the same
            # map applied to S
            s_col = y[:, n + col * n : n + (col + 1) * n]
            if c is not None:
                d_speeds = speeds_c.many(s_col)
            else:
                d_speeds = np.asarray(speeds_of(s_col.T).full()).T
            for j, s in enumerate(shafts):
                sensitivities[naming.speed(s)][index, col] = d_speeds[:, j]
            for key in (naming.TWIST, naming.WHEEL_SPEED):
                sensitivities[key][index, col] = s_col[:, names.index(key)]
        if c is not None:
            slips, torques, mu = (
                c[signal_name(mode, signal)].many(x, u, p) for signal in ("slips", "torques", "mu")
            )
        else:
            slips = compiled.many(compiled.slips, x, u, p)
            torques = compiled.many(compiled.torques, x, u, p)
            mu = compiled.many(compiled.mu, x, u, p)
        for j, e in enumerate(simulator.hybrid.elements):
            signals[naming.slip_column(e)][index] = slips[:, j]
            signals[naming.torque(e)][index] = torques[:, j]
            if e not in simulator.hybrid.normal_force:
                continue
            signals[str(simulator.hybrid.normal_force[e])][index] = u[:, 1 + j]
            signals[str(simulator.hybrid.friction_coefficient[e])][index] = mu[:, j]
        for i in index:
            modes[i] = mode
    w_in = signals[naming.speed(simulator.d.input_shaft)]
    w_out = signals[naming.speed(simulator.d.output_shaft)]
    signals[naming.RATIO] = w_in / np.where(w_out != 0, w_out, np.nan)
    return signals, tuple(modes), sensitivities


def _owners(pieces: Sequence[Piece], grid: np.ndarray) -> np.ndarray:
    """The piece each grid time is sampled from (−1: none): the last piece whose
    [t_start, t_end] holds it, so a sample at a switch takes the later piece. Pieces follow
    each other in time: the last one starting at or before a time is found by bisection, and
    a time it does not hold (only where pieces overlap by rounding) by the search over all."""
    owner = np.full(len(grid), -1)
    if not len(grid) or not pieces:
        return owner
    starts = np.array([piece.t_start for piece in pieces])
    ends = np.array([piece.t_end for piece in pieces])
    if np.any(np.diff(starts) < 0):
        rest = np.arange(len(grid))
    else:
        last = np.searchsorted(starts, grid, side="right") - 1
        held = (last >= 0) & (grid <= ends[np.maximum(last, 0)])
        owner[held] = last[held]
        rest = np.flatnonzero(~held)
    for i in rest:
        inside = np.flatnonzero((starts <= grid[i]) & (grid[i] <= ends))
        if inside.size:
            owner[i] = inside[-1]
    return owner


def signal_name(mode: str, signal: str) -> str:
    """The name of mode ``mode``'s function ``signal`` (speeds, slips, torques, mu) among a
    simulator's compiled C."""
    return f"{mode}#{signal}"
