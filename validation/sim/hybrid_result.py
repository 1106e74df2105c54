"""What a hybrid simulation returns
(:class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator`): the switches, the
integration pieces in each mode, and the samples with their sensitivities."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic.hybrid import HybridShift
from gearsym.validation.sim.scenario import Scenario


@dataclass(frozen=True)
class Event:
    """A switch: guard ``kind`` of ``element`` fired at ``t``, from ``source`` to ``target``."""

    t: float
    kind: str
    element: str
    source: str
    target: str
    #: ½ Δẏᵀ M Δẏ the state map took out of the gearbox (J): nonzero only for a dog element
    #: engaged at non-zero slip (the impulsive engagement of :mod:`gearsym.symbolic.hybrid`)
    energy_loss: float = 0.0


@dataclass(frozen=True)
class Piece:
    """One integration piece in one mode: [t_start, t_end] with SciPy's dense output."""

    mode: str
    t_start: float
    t_end: float
    solution: Any  # scipy OdeSolution, or None for a piece of zero length
    x_start: np.ndarray

    def state(self, t: np.ndarray) -> np.ndarray:
        """The state (and the sensitivities riding along) at the times ``t``: len(t) × size."""
        if self.solution is None:
            return np.repeat(self.x_start[None, :], len(t), axis=0)
        if len(self.solution.interpolants) == 1:
            # one step (most of a closed loop's pieces): its interpolant, which the
            # OdeSolution would call after a search of its segments
            return np.asarray(self.solution.interpolants[0](t)).T
        return np.asarray(self.solution(t)).T


def states_of(pieces: Sequence[Piece], times: Sequence[np.ndarray]) -> np.ndarray:
    """``pieces[k].state(times[k])`` for every k, stacked (rows in that order; the pieces of
    one mode: states of one size). Pieces of one DOP853 step (most of a closed-loop shift's
    hundreds) are evaluated together by the interpolant's own arithmetic (SciPy's
    ``Dop853DenseOutput``: the same operations in the same order, so the same values), one
    NumPy expression instead of a call per piece, which cost some 25 µs each; any other
    piece by :meth:`Piece.state`."""
    dense = []
    for piece in pieces:
        solution = piece.solution
        one = solution is not None and len(solution.interpolants) == 1
        interpolant = solution.interpolants[0] if one else None
        if type(interpolant).__name__ != "Dop853DenseOutput" or not hasattr(interpolant, "F"):
            return np.concatenate([piece.state(t) for piece, t in zip(pieces, times, strict=True)])
        dense.append(interpolant)
    if not dense:
        return np.zeros((0, 0))
    which = np.repeat(np.arange(len(dense)), [len(t) for t in times])
    t = np.concatenate(times)
    t_old = np.array([d.t_old for d in dense])[which]
    h = np.array([d.h for d in dense])[which]
    f = np.stack([d.F for d in dense])[which]
    y_old = np.stack([d.y_old for d in dense])[which]
    x = ((t - t_old) / h)[:, None]
    y = np.zeros_like(y_old)
    for i in range(f.shape[1]):
        y += f[:, f.shape[1] - 1 - i, :]
        if i % 2 == 0:
            y *= x
        else:
            y *= 1 - x
    y += y_old
    return y


@dataclass(frozen=True)
class HybridResult:
    """Samples of the hybrid simulation: ``signals`` (every shaft speed ``omega_<s>``, φ, ω_C,
    the swapping elements' slips ``slip_<e>`` and torques ``T_<e>``), the mode at each sample,
    the events and the pieces."""

    t: np.ndarray
    signals: dict[str, np.ndarray]
    modes: tuple[str, ...]
    events: tuple[Event, ...]
    pieces: tuple[Piece, ...]
    hybrid: HybridShift
    scenario: Scenario
    values: dict[str, float]
    stats: dict[str, float] = field(default_factory=dict)
    #: ∂(signal)/∂p of the states and shaft speeds, signals × samples × parameters
    parameters: tuple[str, ...] = ()
    sensitivities: dict[str, np.ndarray] = field(default_factory=dict)
    #: ∂τ/∂p of every event (zero for the switches at breakpoints), events × parameters
    event_time_sensitivities: np.ndarray | None = None
