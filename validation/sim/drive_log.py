"""What a TCU records of a drive at its sample time (:mod:`gearsym.validation.sim.drive`): the
true shaft speeds (the estimators add their sensors' noise), what the TCU commanded (input
torque, every element's pressure, the brake), which gear or shift it was in, and the truth an
estimator is scored against (never shown to it): μ of each sliding element and the grade."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["TcuLog"]


@dataclass
class TcuLog:
    """Samples every ``sample_time`` (s). Columns: ``t``; ``omega_<shaft>`` of every shaft,
    ``phi``, ``omega_C`` (truth); ``T_In_cmd`` (N·m, what the TCU commanded), ``T_eng_cmd`` (its
    engine's part: the torque model's share, which the engine's gain error acts on), ``T_brake``
    (N·m at the wheel), ``p_<element>`` (Pa, commanded: in a shift the mean over the tick the
    sample starts); ``gear`` (index into the drive's
    gears) and ``shift`` (the shift under way, "" in a gear); ``truth_mu_<element>`` (NaN
    unless the element slides) and ``truth_zeta`` (rad)."""

    sample_time: float
    shafts: Sequence[str]
    elements: Sequence[str]
    columns: dict[str, list[float]] = field(default_factory=dict)
    shift: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        names = [
            "t",
            *(f"omega_{s}" for s in self.shafts),
            "phi",
            "omega_C",
            "T_In_cmd",
            "T_eng_cmd",
            "T_brake",
            *(f"p_{e}" for e in self.elements),
            "gear",
            *(f"truth_mu_{e}" for e in self.elements),
            "truth_zeta",
        ]
        self.columns = {name: [] for name in names}

    def ticks(self, t0: float, t1: float) -> np.ndarray:
        """The sample times in [t0, t1)."""
        h = self.sample_time
        first = math.ceil(t0 / h - 1e-9)
        last = math.ceil(t1 / h - 1e-9)
        return np.arange(first, last) * h

    def add(
        self,
        t: float,
        speeds: Sequence[float],
        phi: float,
        omega_c: float,
        torque: float,
        brake: float,
        pressures: Mapping[str, float],
        gear: int,
        shift: str,
        mu: Mapping[str, float],
        zeta: float,
        engine: float,
    ) -> None:
        """One sample; ``torque`` the commanded input torque, ``engine`` its engine part."""
        c = self.columns
        c["t"].append(float(t))
        for s, w in zip(self.shafts, speeds, strict=True):
            c[f"omega_{s}"].append(float(w))
        c["phi"].append(float(phi))
        c["omega_C"].append(float(omega_c))
        c["T_In_cmd"].append(float(torque))
        c["T_eng_cmd"].append(float(engine))
        c["T_brake"].append(float(brake))
        for e in self.elements:
            c[f"p_{e}"].append(float(pressures.get(e, 0.0)))
            c[f"truth_mu_{e}"].append(float(mu.get(e, math.nan)))
        c["gear"].append(float(gear))
        c["truth_zeta"].append(float(zeta))
        self.shift.append(shift)

    def add_many(
        self,
        t: np.ndarray,
        speeds: np.ndarray,
        phi: np.ndarray,
        omega_c: np.ndarray,
        torque: np.ndarray,
        brake: np.ndarray,
        pressures: Mapping[str, float],
        gear: int,
        zeta: np.ndarray,
        engine: np.ndarray,
    ) -> None:
        """Samples in a gear (no shift under way, no element sliding) at the times ``t``, one
        row of ``speeds`` (samples × shafts) each: :meth:`add` for a whole array at once (the
        fast drive logs a second of ticks per call)."""
        c = self.columns
        count = len(t)
        c["t"].extend(np.asarray(t, dtype=float).tolist())
        for j, s in enumerate(self.shafts):
            c[f"omega_{s}"].extend(np.asarray(speeds[:, j], dtype=float).tolist())
        c["phi"].extend(np.asarray(phi, dtype=float).tolist())
        c["omega_C"].extend(np.asarray(omega_c, dtype=float).tolist())
        c["T_In_cmd"].extend(np.asarray(torque, dtype=float).tolist())
        c["T_eng_cmd"].extend(np.asarray(engine, dtype=float).tolist())
        c["T_brake"].extend(np.asarray(brake, dtype=float).tolist())
        for e in self.elements:
            c[f"p_{e}"].extend([float(pressures.get(e, 0.0))] * count)
            c[f"truth_mu_{e}"].extend([math.nan] * count)
        c["gear"].extend([float(gear)] * count)
        c["truth_zeta"].extend(np.asarray(zeta, dtype=float).tolist())
        self.shift.extend([""] * count)

    def arrays(self) -> dict[str, np.ndarray]:
        """Every column as an array, in time order."""
        order = np.argsort(np.asarray(self.columns["t"]), kind="stable")
        out = {k: np.asarray(v, dtype=float)[order] for k, v in self.columns.items()}
        return out

    def shifts(self) -> list[str]:
        order = np.argsort(np.asarray(self.columns["t"]), kind="stable")
        return [self.shift[i] for i in order]
