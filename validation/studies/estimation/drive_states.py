"""The states the drive's EKF (:mod:`~gearsym.validation.studies.estimation.drive_ekf`) may
append to its model's (4.1): tolerances the TCU cannot know per vehicle that act only through
the filter's known inputs or fixed parameters (the side shafts' stiffness, the engine's torque
gain, the adaptive-control study's valve offset and fill time), and the discrete model that
carries them."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity

__all__ = ["AppendedState", "engine_gain_state", "stiffness_state", "stiffness_truth"]


@dataclass(frozen=True)
class AppendedState:
    """A state the filter appends to its model's (4.1) that acts only through the known inputs: each
    element's pressure in the log moves by ``sensitivity[element][k]`` per unit of the state (what
    the TCU's own actuator model says, :mod:`~gearsym.validation.sim.actuator`), so the filter
    presses with p + (θ − ``logged``) ∂p/∂θ; ``sensitivity["T_In"][k]`` moves the input torque the
    same way (the engine's gain: T_In,cmd + (θ − 1) T_eng,cmd). ``logged`` is the value the log's
    inputs were built with. ``corrected`` False makes it a consider state (Schmidt): it is never
    corrected, but its variance enters the filter's covariance where the pressures depend on it (an
    uncertainty the filter must not learn from, e.g. a fill time that a separate estimate fixed
    within a stated σ).

    With ``scales`` naming one of the model's fixed parameters the state is instead that
    parameter's factor: the filter's model uses the calibration's value times θ (a tolerance
    the TCU cannot know per vehicle, e.g. the side shafts' stiffness, whose frequency would
    otherwise be read as mass); ``sensitivity`` is then empty."""

    name: str
    prior: tuple[float, float]
    random_walk: float
    sensitivity: Mapping[str, np.ndarray] = field(default_factory=dict)
    logged: float = 0.0
    corrected: bool = True
    #: the truth, for scoring only (NaN: not known)
    truth: float = math.nan
    #: the fixed parameter the state scales ("" : the state acts through the pressures)
    scales: str = ""
    #: False: corrected only in a gear and a consider state (Schmidt) through a shift, where
    #: what the filter's shift model lacks (μ's form, the valves) would be read as this state
    learns_in_shifts: bool = True


def stiffness_state(d: GearboxDescription, truth: float = math.nan) -> AppendedState:
    """The side shafts' stiffness as a filter state over a drive: the factor on the
    calibration's k_ss (2.47), prior and random walk from the ``[estimator]`` table
    (:data:`~gearsym.symbolic.estimator_calibration.STIFFNESS_FACTOR`). The twist's frequency,
    seen in every measured speed, holds the stiffness against the inertias on both sides of
    it, the vehicle's among them: with the calibration's k_ss fixed, a vehicle 9 % stiffer
    had its mass read 10 % low over a WLTC drive (by a filter that still kept its twist
    through the brake's holds). ``truth``: the vehicle's factor, for scoring only."""
    from gearsym.symbolic.estimator_calibration import STIFFNESS_FACTOR

    return AppendedState(
        STIFFNESS_FACTOR,
        d.estimator.stiffness_factor_prior(),
        d.estimator.stiffness_factor_random_walk(),
        scales="k_ss",
        truth=truth,
    )


def engine_gain_state(
    d: GearboxDescription, log: Mapping[str, np.ndarray], truth: float = math.nan
) -> AppendedState:
    """The engine's torque gain as a filter state over a drive: the true engine torque over
    the torque model's, acting on the logged input torque as T_In,cmd + (g − 1) T_eng,cmd
    (``log``: the :class:`~gearsym.validation.sim.drive_log.TcuLog` arrays with the engine's
    commanded part). Prior and random walk from the ``[estimator]`` table
    (:data:`~gearsym.symbolic.estimator_calibration.ENGINE_TORQUE_GAIN`). A gain on the
    whole input torque would scale the mass's acceleration term exactly (a 5 % torque error
    reads as 5 % less mass); over a drive the engine's share moves (electric launch below
    idle speed, the machine boosting at the engine's limit, recuperation), so the engine's
    gain and the mass are seen in different combinations. The gain learns in the gears only
    (:attr:`AppendedState.learns_in_shifts` False): corrected through the shifts too it fell
    in steps at each shift on the calibration's own vehicle (docs/drive.md). ``truth``: the
    vehicle's gain, for scoring only."""
    from gearsym.symbolic.estimator_calibration import ENGINE_TORQUE_GAIN

    engine = np.asarray(log["T_eng_cmd"], dtype=float)
    if not np.all(np.isfinite(engine)):
        raise ValueError("engine_torque_gain: the log does not record the engine's torque")
    return AppendedState(
        ENGINE_TORQUE_GAIN,
        d.estimator.engine_torque_gain_prior(),
        d.estimator.engine_torque_gain_random_walk(),
        sensitivity={naming.INPUT_TORQUE: engine},
        logged=1.0,
        truth=truth,
        learns_in_shifts=False,
    )


def stiffness_truth(d: GearboxDescription, values: Mapping[str, float]) -> float:
    """The driven vehicle's stiffness factor (``values``: the plant's parameters), for
    scoring; NaN when they do not name k_ss."""
    if "k_ss" not in values:
        return math.nan
    return float(values["k_ss"]) / quantity(d, "drivetrain", "k_ss").value


class _Appended:
    """The filter's discrete model (:class:`~gearsym.symbolic.estimators.ekf.DiscreteModel`)
    with :class:`AppendedState` s after its states: they are constant over a step and act only
    through the inputs u(θ) and the fixed parameters p(θ), so the step's Jacobian gains the
    columns ∂Φ/∂u · ∂u/∂θ + ∂Φ/∂p · ∂p/∂θ (``du_dtheta``, this sample's; ``dp_dtheta``) and
    the outputs (speeds) do not depend on them. The p the filter passes is already p(θ)."""

    def __init__(
        self, discrete: Any, du_dtheta: np.ndarray, dp_dtheta: np.ndarray | None = None
    ) -> None:
        self.discrete = discrete
        self.aug = discrete.aug
        self.du_dtheta = du_dtheta
        self.dp_dtheta = dp_dtheta
        self.m = du_dtheta.shape[1]

    def step(
        self, z: np.ndarray, u: np.ndarray, h: float, p: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        n = len(z) - self.m
        z_next, F = self.discrete.step(z[:n], u, h, p)
        jac = np.eye(len(z))
        jac[:n, :n] = F
        jac[:n, n:] = self.discrete.step_du(z[:n], u, h, p) @ self.du_dtheta
        if self.dp_dtheta is not None:
            jac[:n, n:] += self.discrete.step_dp(z[:n], u, h, p) @ self.dp_dtheta
        return np.concatenate([z_next, z[n:]]), jac

    def outputs(
        self, z: np.ndarray, u: np.ndarray, p: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        y, H = self.discrete.outputs(z[: len(z) - self.m], u, p)
        return y, np.hstack([H, np.zeros((H.shape[0], self.m))])
