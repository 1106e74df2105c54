"""The input torque as the TCU is told it, times a gain: T_In,true = g T_In,told.

A TCU knows the input torque from the engine's torque model and the e-machine's command, a few
percent off the true one (the fleet's ``engine_torque_gain``). An estimator that takes that
gain as a state (the fleet's EKF, ``--params ...,input_torque_gain``) and an observability
analysis that asks whether it can be told apart from the mass and the grade both need the
shift model with g T_In in place of T_In: :func:`with_input_torque_gain` builds it from any
model with the input T_In (:func:`~gearsym.symbolic.model.with_input_gain`)."""

from __future__ import annotations

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.estimator_calibration import INPUT_TORQUE_GAIN
from gearsym.symbolic.model import Model, Variable, with_input_gain

__all__ = ["INPUT_TORQUE_GAIN", "input_torque_gain_variable", "with_input_torque_gain"]


def input_torque_gain_variable() -> Variable:
    """g of T_In,true = g T_In,told: dimensionless, nominal 1 (a calibrated torque model)."""
    return Variable(
        INPUT_TORQUE_GAIN,
        sp.Symbol(INPUT_TORQUE_GAIN, real=True),
        "1",
        "the true input torque over the one the TCU is told",
        1.0,
        "assumed: the TCU's torque model is right on average",
    )


def with_input_torque_gain(model: Model) -> Model:
    """``model`` with T_In acting as g T_In and g a parameter (nominal 1)."""
    return with_input_gain(model, naming.INPUT_TORQUE, input_torque_gain_variable())
