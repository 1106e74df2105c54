"""What a drive (:mod:`gearsym.validation.sim.drive`) returns: the works over the drive and
the recorded drive (samples, shifts, energy audit, wall time, the TCU's log)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.validation.sim.cycles import Cycle
from gearsym.validation.sim.drive_log import TcuLog
from gearsym.validation.sim.drive_shift import ShiftRecord

__all__ = ["DriveResult", "Works"]


@dataclass
class Works:
    """Works (J) over the drive: input, friction, damper, road, brake, and the change of the
    stored energies (kinetic, spring)."""

    input: float = 0.0
    friction: float = 0.0
    damper: float = 0.0
    road: float = 0.0
    brake: float = 0.0
    kinetic: float = 0.0
    spring: float = 0.0

    @property
    def residual(self) -> float:
        return self.input - (
            self.kinetic + self.spring + self.friction + self.damper + self.road + self.brake
        )

    @property
    def relative_residual(self) -> float:
        scale = max(abs(self.input), self.friction + self.damper + abs(self.road) + self.brake)
        return abs(self.residual) / scale if scale > 0 else 0.0

    def to_dict(self) -> dict[str, float]:
        return {
            "input_J": self.input,
            "kinetic_change_J": self.kinetic,
            "spring_change_J": self.spring,
            "friction_J": self.friction,
            "damper_J": self.damper,
            "road_J": self.road,
            "brake_J": self.brake,
            "residual_J": self.residual,
            "relative_residual": self.relative_residual,
        }


@dataclass
class DriveResult:
    """The recorded drive: samples every :data:`RECORD_STEP` (``t``, ``v_ref``, ``v`` in m/s,
    ``gear`` index into ``gears``, engine, e-machine and brake torque, input speed, pedal,
    distance), the shifts, the energy audit and the wall time."""

    cycle: Cycle
    gears: tuple[str, ...]
    samples: dict[str, np.ndarray]
    shifts: list[ShiftRecord]
    works: Works
    wall_s: float
    values: dict[str, float]
    failure: str = ""
    stats: dict[str, float] = field(default_factory=dict)
    #: the TCU's record of the drive at its sample time (:mod:`.drive_log`)
    log: TcuLog | None = None

    @property
    def tracking_rms_kmh(self) -> float:
        e = (self.samples["v"] - self.samples["v_ref"]) * 3.6
        return float(np.sqrt(np.mean(e * e)))

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return float(self.samples["t"][-1]) / self.wall_s if self.wall_s > 0 else math.inf

    def to_dict(self) -> dict[str, Any]:
        t = self.samples["t"]
        return {
            "cycle": self.cycle.to_dict(),
            "simulated_s": float(t[-1]),
            "shifts": len(self.shifts),
            "shift_list": [s.to_dict() for s in self.shifts],
            "wall_s": self.wall_s,
            "real_time_factor": self.real_time_factor,
            "gear_integrator": "reference" if self.stats.get("reference") else "fast",
            "energy_residual": self.works.relative_residual,
            "energy": self.works.to_dict(),
            "tracking_rms_kmh": self.tracking_rms_kmh,
            "tracking_max_kmh": float(
                np.max(np.abs(self.samples["v"] - self.samples["v_ref"])) * 3.6
            ),
            "distance_km": float(self.samples["s"][-1] / 1000.0),
            "failure": self.failure,
            "truth": self.values,
        }
