"""The shift schedule as a TCU applies it over a drive (:mod:`gearsym.validation.sim.drive`): a
level, not only a crossing. A gear segment ends where the input speed crosses a threshold (the
solvers' events), and a threshold already passed when a segment starts (the dwell after a shift
ends with the input above the upshift speed, or the pedal steps at a point of the cycle) shifts
at once (:func:`due_shift`). In a downshift under recuperation the machine's torque is handed to
the service brake for the shift (:func:`blended_split`). :func:`missed_shifts` checks a finished
drive against the schedule from its records: where the input stayed beyond a threshold with no
shift under way or waiting out its dwell."""

from __future__ import annotations

from typing import Any

import numpy as np
from gearsym.validation.sim.drive_powertrain import TorqueSplit

__all__ = ["blended_split", "due_shift", "missed_shifts"]


def due_shift(segment: Any, t: float, y: np.ndarray, armed: list[str]) -> str:
    """The shift the schedule asks for at the state ``y`` already ("upshift": the input above
    the upshift speed of the present pedal; "downshift": below the downshift speed), among
    the ``armed`` ones; "" for none. ``segment``: the gear segment's event functions."""
    if "upshift" in armed and segment.upshift(t, y) > 0:
        return "upshift"
    if "downshift" in armed and segment.downshift(t, y) < 0:
        return "downshift"
    return ""


def blended_split(split: TorqueSplit, kind: str, overall: float) -> TorqueSplit:
    """The torque split a shift of ``kind`` holds (the driver waits the shift out): in a
    downshift while the machine recuperates, its torque goes to the service brake at the
    wheel (the same wheel torque through the from-gear's ``overall`` ratio, i_gear i_D), as
    hybrids blend recuperation out while the gear changes; the input shaft, free between the
    two sliding elements, would otherwise be driven backwards through zero (a 2-1 braking to a
    stop did: the input at −23 rad/s). Any other shift holds ``split``."""
    if kind != "downshift" or split.e_machine >= 0.0:
        return split
    return TorqueSplit(split.engine, 0.0, split.brake - split.e_machine * overall, split.pedal)


def missed_shifts(
    result: Any, schedule: Any, min_dwell: float, tolerance: float = 1e-6
) -> list[float]:
    """The recorded times (s) at which ``result`` (a
    :class:`~gearsym.validation.sim.drive.DriveResult`) sat in a gear with its input speed
    above the upshift speed of the recorded pedal (in any gear but the top) or below the
    downshift speed (in any gear but the lowest), at least ``min_dwell`` after the gear was
    entered and with no shift started since: shifts the schedule asked for and the drive did
    not make. ``tolerance``: relative, for a threshold met within the integrator's
    accuracy."""
    s = result.samples
    t, gear = np.asarray(s["t"]), np.asarray(s["gear"]).astype(int)
    omega, pedal = np.asarray(s["omega_in"]), np.asarray(s["pedal"])
    top = len(result.gears) - 1
    starts = np.array(sorted(shift.t_start for shift in result.shifts))
    entered = np.empty(len(t))
    since = t[0]
    for i in range(len(t)):
        if i and gear[i] != gear[i - 1]:
            since = t[i]
        entered[i] = since
    missed = []
    for i in range(len(t)):
        if t[i] - entered[i] < min_dwell + 1e-9:
            continue
        # a shift started at or before this sample and not yet ended (its gear not entered)
        if np.any((starts <= t[i] + 1e-9) & (starts > entered[i])):
            continue
        up, down = schedule.up(float(pedal[i])), schedule.down(float(pedal[i]))
        if gear[i] < top and omega[i] > up * (1 + tolerance):
            missed.append(float(t[i]))
        elif gear[i] > 0 and omega[i] < down * (1 - tolerance):
            missed.append(float(t[i]))
    return missed
