"""Estimators of thesis chapter 4 (EKF 4.3, UIO 4.4, extended UIO 4.5): existence, design.

Each estimator consumes the model IR (:class:`~gearsym.symbolic.model.Model`) or a mode's linear
form (:class:`~gearsym.symbolic.linear_forms.LinearForm`, 5.1); nothing here is specific to one
gearbox.
"""

from gearsym.symbolic.estimators.ekf import (
    AugmentedModel,
    DiscreteModel,
    augmented_model,
)
from gearsym.symbolic.estimators.ekf_modes import ModeLogic, ekf_mode_update
from gearsym.symbolic.estimators.euio import EuioExistence, euio_existence
from gearsym.symbolic.estimators.uio import (
    LinearMode,
    UioDesign,
    UioExistence,
    design_uio,
    linear_modes,
    uio_existence,
)

__all__ = [
    "AugmentedModel",
    "DiscreteModel",
    "augmented_model",
    "ModeLogic",
    "ekf_mode_update",
    "EuioExistence",
    "euio_existence",
    "LinearMode",
    "UioDesign",
    "UioExistence",
    "design_uio",
    "linear_modes",
    "uio_existence",
]
