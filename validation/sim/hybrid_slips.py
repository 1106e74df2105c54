"""The slips of a hybrid simulation's sliding elements at its switches
(:mod:`gearsym.validation.sim.hybrid_simulation`): where a sliding element starts after a
switch that leaves it at zero slip, and the check that no sliding element's slip has turned
against its mode's sign (a lock-up the event search missed). ``simulator`` is the
:class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator` (untyped here: this module
sits below it, the simulator imports it)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.hybrid import SLIDING

__all__ = ["SLIP_START", "SLIP_WRONG_SIGN", "check_slip_signs", "onto_sliding_side"]

#: Slip (rad/s) a sliding element starts with after a switch that leaves it at zero slip
#: (break-away, engagement at zero slip, a lock-up that slides on the other way): on its
#: mode's side of the lock-up guard. Starting *on* the guard, a rounding residue of the wrong
#: sign (1e-14) hides the next crossing when the slip dips and returns within one step (a
#: 3-2 downshift of the fleet's drive slid on with K38's slip of the wrong sign for 0.5 s and
#: negative friction work). 1e-9 rad/s is far below any slip the model resolves.
SLIP_START = 1e-9
#: A sliding element whose slip has the wrong sign by more than this (rad/s) at the end of an
#: integration piece ends the simulation with a stated failure (a missed lock-up), never with
#: a result that dissipates negative friction work.
SLIP_WRONG_SIGN = 1e-6


def onto_sliding_side(
    simulator: Any, mode: str, element: str, x: np.ndarray, t: float, p: np.ndarray
) -> np.ndarray:
    """``x`` with the slip of ``element``, if it slides in ``mode`` and sits within
    :data:`SLIP_START` of zero, moved to ``SLIP_START`` on its sliding side (along the
    slip's gradient, the smallest change of x): the lock-up guard then starts strictly on
    its armed side. Any other ``x`` is returned unchanged."""
    state, sign = simulator.hybrid.modes[mode].status[element]
    if state != SLIDING:
        return x
    compiled = simulator.modes[mode]
    k = simulator.hybrid.elements.index(element)
    u = simulator.inputs(t)
    slip = compiled.value(compiled.slips, x, u, p)[k]
    if abs(slip) > SLIP_START or sign * slip == SLIP_START:
        return x
    # the slips are linear in the mode's speeds: the gradient from unit steps
    base = compiled.value(compiled.slips, np.zeros_like(x), u, p)[k]
    gradient = np.array(
        [compiled.value(compiled.slips, row, u, p)[k] - base for row in np.eye(len(x))]
    )
    return x + (sign * SLIP_START - slip) * gradient / float(gradient @ gradient)


def check_slip_signs(simulator: Any, mode: str, x: np.ndarray, t: float, p: np.ndarray) -> None:
    """A stated failure if a sliding element of ``mode`` ends a piece at ``x`` with its
    slip of the wrong sign (beyond :data:`SLIP_WRONG_SIGN`): a lock-up the event search
    missed, whose continuation would dissipate negative friction work."""
    status = simulator.hybrid.modes[mode].status
    compiled = simulator.modes[mode]
    slips = compiled.value(compiled.slips, x, simulator.inputs(t), p)
    for k, e in enumerate(simulator.hybrid.elements):
        state, sign = status[e]
        if state == SLIDING and sign * slips[k] < -SLIP_WRONG_SIGN:
            raise GearsymError(
                simulator.scenario.file,
                "scenario",
                f"the slip of {e} is {slips[k]:.3g} rad/s at t = {t:.6g} s, against its "
                f"sliding direction in {mode} (a lock-up the event search missed)",
            )
