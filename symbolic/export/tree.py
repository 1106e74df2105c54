"""The generated tree's layout and what was emitted into it
(:mod:`gearsym.symbolic.export.generate`): the two folders, one record per emitted model and
per emitted set, and the whole tree.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from gearsym.symbolic.codegen import (
    INTEGRATORS,
    CodegenConfig,
    EkfLayout,
    EuioLayout,
)
from gearsym.symbolic.codegen.hybrid import hybrid_set_name
from gearsym.symbolic.codegen.linear import LinearSystemSet
from gearsym.symbolic.friction import MuMap
from gearsym.symbolic.hybrid_sensitivity import HybridSensitivity
from gearsym.symbolic.model import Model
from gearsym.symbolic.shifts import ShiftSpec

__all__ = [
    "C_DIR",
    "PYTHON_DIR",
    "EmittedHybridSet",
    "EmittedLinearSet",
    "EmittedModel",
    "GeneratedTree",
]

C_DIR = "c"
PYTHON_DIR = "python"


@dataclass(frozen=True)
class EmittedModel:
    """One emitted model: the model, the ranges its ``params_validate`` enforces, its integrator
    steps, and what it is."""

    model: Model
    bounds: dict[str, tuple[float | None, float | None]]
    role: str  # "full", "shift", "shift_mu", "sensitivity", "ekf", "euio" or "shift_element"
    summary: str
    shift: ShiftSpec | None = None
    integrators: tuple[str, ...] = INTEGRATORS
    ekf: EkfLayout | None = None
    euio: EuioLayout | None = None

    @property
    def config(self) -> CodegenConfig:
        """The emitters' decisions for this model (bounds, integrator steps, EKF/EUIO rows)."""
        return CodegenConfig(
            bounds=self.bounds, integrators=self.integrators, ekf=self.ekf, euio=self.euio
        )


@dataclass(frozen=True)
class EmittedLinearSet:
    """One emitted file pair of linear forms (5.1) and the config it was emitted with."""

    set: LinearSystemSet
    config: CodegenConfig


@dataclass(frozen=True)
class EmittedHybridSet:
    """The sensitivities of one hybrid shift (3.7 per mode, jumps at switches) as emitted."""

    sensitivity: HybridSensitivity
    config: CodegenConfig

    @property
    def name(self) -> str:
        return hybrid_set_name(self.sensitivity)


@dataclass(frozen=True)
class GeneratedTree:
    """The output of :func:`gearsym.symbolic.export.generate.generate_tree`: files by relative
    path, and what produced them."""

    files: dict[str, str]
    models: tuple[EmittedModel, ...]
    mu_map: MuMap
    example_models: tuple[str, ...] = field(default=())
    linear_sets: tuple[EmittedLinearSet, ...] = field(default=())
    hybrid_sets: tuple[EmittedHybridSet, ...] = field(default=())
    #: The UIO designs the ``gearsym_uio_<shift>`` files print (``generate --check`` compares
    #: them) and their shift (``None``: no UIO emitted).
    uio_designs: tuple[Any, ...] = field(default=())
    uio_shift: str | None = None
    #: What was left out and why, one line each (``gearsym generate`` prints them, the README
    #: lists them).
    skipped: tuple[str, ...] = field(default=())
