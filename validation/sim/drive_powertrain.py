"""What a drive puts around the gearbox: the driver, the torque split between engine and
electric machine on the input shaft, and the service brake (``gearsym drive``).

All of it is calibration or driver, never the truth of the vehicle: the driver's feed-forward
and the TCU's shift plans use the description's nominal values and the estimator's prior mass
(:mod:`gearsym.symbolic.estimator_calibration`), whatever vehicle is driven.

The rules (stated, :mod:`gearsym.symbolic.drive_calibration` holds the numbers):

* **Driver**: a wheel force F = m_cal a_ref + F_road,cal(v_ref) + k_p (v_ref − v)
  + k_p/t_i ∫(v_ref − v) dt, a_ref the cycle's acceleration (a driver looks ahead),
  F_road,cal rolling and air resistance of the calibration. The demanded input torque is
  F r_dyn / (i_gear i_D).
* **Torque split**: positive demand goes to the engine first, within min(T_max, P_max/ω_in),
  while the input turns at idle speed or above (below it the engine is decoupled: electric
  launch); the electric machine adds the rest within its own limits. Negative demand is
  recuperated by the electric machine within its limits, the rest is the service brake at the
  wheel. The engine's drag is not modelled (it is decoupled in coast).
* **Pedal** (for the shift schedule): the positive demand over what engine and machine can give
  at the present input speed, within [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity


@dataclass(frozen=True)
class TorqueSplit:
    """The input torque T_In = engine + e-machine, the brake torque at the wheel (≥ 0, N·m),
    and the pedal position in [0, 1]."""

    engine: float
    e_machine: float
    brake: float
    pedal: float

    @property
    def input_torque(self) -> float:
        return self.engine + self.e_machine


class Powertrain:
    """The driver and the torque split of a description's ``[drive]`` table (module
    docstring); ``mass`` is the calibration's vehicle mass for the feed-forward."""

    def __init__(self, d: GearboxDescription, mass: float) -> None:
        drive = d.drive
        self.mass = mass
        self.r_dyn = quantity(d, "vehicle", "r_dyn").value
        self.i_d = quantity(d, "drivetrain", "i_D").value
        g = quantity(d, "vehicle", "g").value
        f_r = quantity(d, "vehicle", "f_R").value
        self.rolling = f_r * mass * g
        self.air = 0.5 * (
            quantity(d, "vehicle", "rho_air").value
            * quantity(d, "vehicle", "c_W").value
            * quantity(d, "vehicle", "A_front").value
        )
        self.k_p = drive.si("driver", "k_p")
        self.k_i = self.k_p / drive.si("driver", "t_i")
        self.engine_torque = drive.si("engine", "T_max")
        self.engine_power = drive.si("engine", "P_max")
        self.idle = drive.si("engine", "n_idle")
        self.machine_torque = drive.si("e_machine", "T_max")
        self.machine_power = drive.si("e_machine", "P_max")

    def wheel_force(self, v_ref: float, a_ref: float, v: float, integral: float) -> float:
        """The driver's demanded wheel force (N)."""
        feed_forward = self.mass * a_ref + (self.rolling + self.air * v_ref * v_ref) * (v_ref > 0)
        return feed_forward + self.k_p * (v_ref - v) + self.k_i * integral

    def coupled(self, omega_in: float) -> bool:
        """The engine is coupled at idle speed or above (below it: electric drive)."""
        return omega_in >= self.idle

    def engine_limit(self, omega_in: float) -> float:
        """Most engine torque at ω_in: 0 below idle (decoupled), else min(T_max, P_max/ω)."""
        if not self.coupled(omega_in):
            return 0.0
        return min(self.engine_torque, self.engine_power / omega_in)

    def machine_limit(self, omega_in: float) -> float:
        """Most |e-machine torque| at ω_in: min(T_max, P_max/|ω|)."""
        w = abs(omega_in)
        return (
            self.machine_torque
            if w * self.machine_torque <= self.machine_power
            else (self.machine_power / w)
        )

    def split(self, force: float, ratio: float, omega_in: float) -> TorqueSplit:
        """Engine, e-machine and brake for a wheel force in a gear of ``ratio`` (module
        docstring)."""
        overall = ratio * self.i_d
        demand = force * self.r_dyn / overall
        engine_max = self.engine_limit(omega_in)
        machine_max = self.machine_limit(omega_in)
        if demand >= 0:
            engine = min(demand, engine_max)
            machine = min(demand - engine, machine_max)
            pedal = min(1.0, demand / (engine_max + machine_max))
            return TorqueSplit(engine, machine, 0.0, pedal)
        machine = max(demand, -machine_max)
        brake = (machine - demand) * overall
        return TorqueSplit(0.0, machine, brake, 0.0)
