"""The shift the input torque drives (a power-on downshift; mirrored, a coast upshift): the
same controller (:mod:`.controller`), its phases in the other order. The input must speed up
to the lower gear (slow down to the higher one, in coast), which the input torque does by
itself once the off-going element lets it slide; so the inertia phase comes first and the
torque phase after it, at synchronism:

* *fill*: as in an upshift (the on-coming piston to its kiss point, the off-going element to
  its holding margin);
* *inertia phase* (from the end of the fast fill): the off-going element slides; its force
  is feed-forward from the shift model in the mode "off-going sliding, on-coming open" (the
  on-coming slip's acceleration is affine in the off-going F_N) so that the on-coming slip
  follows the target to zero in ``inertia_phase``, plus PI feedback on the slip error (while the
  element is released and the slip still behind, the target waits and the integral holds:
  the input torque moves the slip no faster); the
  target's acceleration ends at zero, so at synchronism the off-going element carries the
  input torque with the speeds steady;
* *torque phase* (once |slip| <= ``lockup_slip``): the on-coming force rises along the same
  S-curve to what carries its torque in the to-gear, the off-going force falls to zero with it;
* *lock-up*: the on-coming element to line pressure.

Only the off-going element's sliding direction differs from the upshift's logic: it slides the
way its reaction torque in the from-gear pushes (the sliding torque ± capacity continues the
reaction at break-away).
"""

from __future__ import annotations

import math

import numpy as np
from gearsym.symbolic.control_calibration import MOVING, SECANT_FORCE_MIN, TICK
from gearsym.validation.studies.control.controller import (
    TIMEOUT_FACTOR,
    ShiftController,
    TargetSlip,
)

__all__ = ["DownshiftController"]


class DownshiftController(ShiftController):
    """The controller of one power-on downshift or coast upshift (module docstring)."""

    driven = True
    handles = "a power-on downshift or a coast upshift"

    def __post_init__(self) -> None:
        super().__post_init__()
        self._t_slide = self._t_fill_end  # the inertia phase starts after the fast fill
        self._off_sign = 0
        self._off_force = 0.0
        self._t_sync = math.nan
        self._t_moving = math.nan
        self._released = False

    def step(self, t: float, speeds: np.ndarray, torque: float) -> dict[str, float]:
        """One TCU tick at ``t`` (s since the shift command): pressure commands (Pa)."""
        if self._plan is None:
            self._plan = self._make_plan(speeds, torque)
            self._off_force = self._plan.hold_off
        plan = self._plan
        offset = self.knowledge.pressure_offset
        hold = self.spring + self.fill_hold
        on = self._fill_command(t)
        if self.phase == "fill" and t >= self._t_slide:
            self.phase = "inertia"
        if self.phase == "fill":
            commands = {self.off: self.pressure(self.off, plan.hold_off), self.on: on}
        elif self.phase == "inertia":
            off = self.pressure(self.off, self._inertia_down(t, speeds, torque))
            commands = {self.off: off, self.on: on}
            if self.phase == "torque":  # synchronism reached this tick
                self._t_sync = t
        if self.phase == "torque":
            tau = min(max((t + self.lead - self._t_sync) / self.torque_phase, 0.0), 1.0)
            share = (1.0 - math.cos(math.pi * tau)) / 2.0
            on_force = share * plan.carry_on * self.margin
            # the off-going element keeps the input at synchronism while it hands over
            off_force = (1.0 - share) * self._inertia_down(t, speeds, torque, hold_sync=True)
            commands = {
                self.off: self.pressure(self.off, off_force) if off_force > 0 else 0.0,
                self.on: max(self.pressure(self.on, on_force, offset), hold),
            }
            self._last_force = on_force
            # over at the tick nearest the ramp's end: the end falls on a tick when the phase
            # lengths are whole ticks, and a rounding either way must not decide the tick
            if t + self.lead - self._t_sync >= self.torque_phase - TICK / 2:
                self.phase = "lockup"
                self._t_lock = t
        if self.phase in ("lockup", "done"):
            commands = {self.off: 0.0, self.on: self._lockup(t)}
        self._t_previous = t
        return commands

    def _inertia_down(
        self, t: float, speeds: np.ndarray, torque: float, hold_sync: bool = False
    ) -> float:
        """The off-going element's force (N) while it slides (module docstring); with
        ``hold_sync`` (the torque phase) its target is the end of the slip trajectory:
        synchronism held while the on-coming element takes over."""
        hybrid = self.model.hybrid
        j_off, j_on = hybrid.elements.index(self.off), hybrid.elements.index(self.on)
        if not self._off_sign:
            source = self.model.modes[hybrid.from_mode]
            x0, u0 = self._state(
                hybrid.from_mode, speeds, self._line_forces(hybrid.from_mode), torque
            )
            reaction = float(source.value(source.torques, x0, u0, self.p)[j_off])
            self._off_sign = 1 if reaction > 0 else -1
        status = {self.off: ("sliding", self._off_sign), self.on: ("open", 0)}
        sliding = self.model.modes[hybrid.mode_of(status).name]
        forces = [0.0, 0.0]
        forces[j_off] = self._off_force
        x, u = self._state(sliding.mode.name, speeds, forces, torque)
        slip = float(sliding.value(sliding.slips, x, u, self.p)[j_on])
        if self._target is None:
            self._target = TargetSlip(slip, self.inertia_phase)
            self._sign = 1.0 if slip > 0 else -1.0
        target = self._target
        # the target's clock starts when the measured slip starts to fall (the off-going
        # element has broken away): until then the valve's lag, not the controller, holds
        # the input, and an integrator running on that delay would overshoot later
        if math.isnan(self._t_moving) and abs(slip) < (1.0 - MOVING) * abs(target.sigma0):
            self._t_moving = t
        elif self._released and not hold_sync:
            # the target waits while the element is released and the slip still behind it:
            # the input torque moves the slip no faster, and a target run on past its end
            # would ask the element to hold the input where it is (the shift stalls)
            self._t_moving += t - self._t_previous
        tau = 0.0 if math.isnan(self._t_moving) else t - self._t_moving
        if hold_sync:
            tau = 2.0 * target.duration
        elif (
            abs(slip) <= self.lockup_slip
            or slip * self._sign < 0
            or t - self._t_slide > TIMEOUT_FACTOR * self.inertia_phase
        ):
            self.phase = "torque"
        f1 = max(self._plan.hold_off if self._plan else 0.0, SECANT_FORCE_MIN)
        r0, r1 = self._slip_rates(sliding, x, torque, j_off, j_on, f1)
        wanted = target.rate(tau + self.lead)
        feed_forward = self._off_force if r1 == r0 else (wanted - r0) / (r1 - r0) * f1
        error = self._sign * (slip - target.slip(tau))
        if not math.isnan(self._t_moving) and not self._released:
            self._integral += error * (t - self._t_previous)
        # more off-going force holds the input back: it slows the on-coming slip's fall when
        # the slip's rate per newton has the slip's own sign
        direction = 1.0 if (r1 - r0) * self._sign > 0 else -1.0
        correction = -direction * self.k_p * (error + self._integral / self.t_i)
        self._off_force = max(feed_forward, 0.0)
        area = self.model.area[self.off]
        force = self._off_force + correction * area
        if not hold_sync:
            self._released = force <= 0.0 and error > 0.0
        return max(force, 0.0)
