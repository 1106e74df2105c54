"""What a reference simulation returns (thesis 3.1): the time series, the phases, the energy
audit and the reduced-model checks (:func:`gearsym.validation.sim.simulate.simulate`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.validation.sim.phases import Phase
from gearsym.validation.sim.scenario import Scenario


@dataclass(frozen=True)
class EnergyAudit:
    """W_in = ΔE_kin + ΔE_spring + ΔE_bristle + W_friction + W_damper + W_road (+ residual)."""

    input_work: float
    kinetic_change: float
    spring_change: float
    bristle_change: float
    friction_dissipation: float
    damper_dissipation: float
    road_work: float

    @property
    def residual(self) -> float:
        return self.input_work - (
            self.kinetic_change
            + self.spring_change
            + self.bristle_change
            + self.friction_dissipation
            + self.damper_dissipation
            + self.road_work
        )

    @property
    def scale(self) -> float:
        """The largest term, the reference for the relative residual."""
        return max(
            abs(v)
            for v in (
                self.input_work,
                self.kinetic_change,
                self.spring_change,
                self.friction_dissipation,
                self.damper_dissipation,
                self.road_work,
            )
        )

    @property
    def relative_residual(self) -> float:
        return abs(self.residual) / self.scale

    def to_dict(self) -> dict[str, float]:
        return {
            "input_work_J": self.input_work,
            "kinetic_energy_change_J": self.kinetic_change,
            "spring_energy_change_J": self.spring_change,
            "bristle_energy_change_J": self.bristle_change,
            "friction_dissipation_J": self.friction_dissipation,
            "damper_dissipation_J": self.damper_dissipation,
            "road_work_J": self.road_work,
            "residual_J": self.residual,
            "relative_residual": self.relative_residual,
        }


@dataclass(frozen=True)
class ModelCheck:
    """A reduced model integrated inside one phase against the reference."""

    model: str
    phase: str
    t_start: float
    t_end: float
    max_abs_error: dict[str, float]
    #: max |error| / (max |reference| of that state over the phase), worst state
    max_relative_error: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "phase": self.phase,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "max_abs_error": self.max_abs_error,
            "max_relative_error": self.max_relative_error,
        }


@dataclass(frozen=True)
class SimulationResult:
    """Time series (``signals``, sampled at ``t``), phases, audit and model checks."""

    t: np.ndarray
    signals: dict[str, np.ndarray]
    phases: tuple[Phase, ...]
    audit: EnergyAudit
    checks: tuple[ModelCheck, ...]
    scenario: Scenario
    state_names: tuple[str, ...]
    stats: dict[str, float] = field(default_factory=dict)
    state_at: Callable[[float], np.ndarray] | None = None
    method: str = "cvodes"

    def phase(self, name: str) -> Phase:
        for p in self.phases:
            if p.name == name:
                return p
        raise KeyError(name)
