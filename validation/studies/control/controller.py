"""The TCU's clutch-to-clutch shift controller (the adaptive-control issue): what runs every
TCU tick (10 ms) during a shift and turns the vehicle knowledge of a strategy into the two
swapping elements' pressure commands.

**Phases** (the numbers in the description's ``[control.shift]`` and ``[control.actuator]``):

* *fill*: the on-coming element gets the fast-fill pressure for the calibrated fill time (plus
  the strategy's learned offset), then the hold pressure (return spring plus ``fill_hold``);
  the off-going element drops to ``off_going_margin`` times what holds its torque;
* *torque phase* (``torque_phase``): the on-coming element's force ramps to what carries its
  torque in the to-gear (the to-gear's reaction at the commanded input torque, through the
  element's capacity 2 n_disc r_m μ F_N, 2.69/3.14); the off-going element's estimated torque
  falls with it and the element is vented when that estimate reaches zero;
* *inertia phase*: the on-coming slip follows a target that brings it to zero in
  ``inertia_phase`` (slip acceleration ramped in and out over a quarter of the phase each: no
  torque step at its start, a soft lock-up). The force is feed-forward from the shift model in
  the mode "off-going open, on-coming sliding" with the strategy's μ, m_veh and ζ (the slip
  acceleration is affine in F_N but for μ's pressure dependence: a secant through two
  evaluations), plus PI feedback on the slip error;
* *lock-up*: once |slip| <= ``lockup_slip`` (or the phase takes twice its target) the
  on-coming element ramps to line pressure within 0.1 s and holds; the shift is done 0.1 s
  later.

Pressure from force: p = F_N / a_piston + return spring + the strategy's pressure offset, then
through the strategy's view of the valve (gain and offset: the oracle knows the vehicle's,
the others assume the nominal valve).

**What the controller measures**: the input and output shaft speeds (the TCU's speed
sensors; here the plant's values, sensor errors not modelled) and the torque it commands. The
model state it evaluates is rebuilt from those two speeds (least squares through the mode's
projection) with the side-shaft twist at its quasi-static value (the output and the wheel
accelerating together), the twist it cannot measure.

These phases are those of a shift whose on-coming element must pull the input speed over
against the input torque: a power-on upshift, and mirrored (negative torque, every force and
slip direction taken from the model) a coast downshift. A shift the input torque drives by
itself (a power-on downshift, a coast upshift) slides the off-going element first
(:mod:`.downshift`); :func:`torque_drives_the_shift` tells which.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.control_calibration import (
    HOLD_AFTER_FILL,
    HOLD_LINE,
    RAMP_FRACTION,
    SECANT_FORCE_MIN,
    TICK,
    TIMEOUT_FACTOR,
    TO_LINE,
)
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.shifts import ShiftSpec
from gearsym.validation.sim.drive_shift import state_from_speeds
from gearsym.validation.sim.hybrid_simulation import HybridSimulator

__all__ = [
    "Knowledge",
    "PHASES",
    "ShiftController",
    "TargetSlip",
    "shift_direction",
    "torque_drives_the_shift",
]

PHASES = ("fill", "torque", "inertia", "lockup", "done")


def shift_direction(d: GearboxDescription, spec: ShiftSpec) -> str:
    """ "up" when the to-gear's ratio is the smaller (the input slows down), else "down"."""
    from gearsym.symbolic.ratios import gear_ratio

    ratio = [abs(float(gear_ratio(d, d.gear(g)).ratio)) for g in (spec.from_gear, spec.to_gear)]
    return "up" if ratio[1] < ratio[0] else "down"


def torque_drives_the_shift(d: GearboxDescription, spec: ShiftSpec, torque: float) -> bool:
    """Whether the input torque by itself moves the input speed towards the to-gear's once
    the off-going element lets go: a power-on downshift (the engine speeds the input up) or a
    coast upshift (the drag slows it down). Such a shift slides the off-going element first
    and hands over at synchronism (:class:`.downshift.DownshiftController`); the others (a
    power-on upshift, a coast downshift) need the on-coming element to pull the input over,
    torque phase first (:class:`ShiftController`). Zero torque drives neither way: refused."""
    if torque == 0.0:
        raise GearsymError(
            d.file,
            "control",
            f"shift {spec.name}: no commanded input torque: neither a power-on nor a coast "
            "shift (the controller's phase order depends on the torque's sign)",
        )
    return (shift_direction(d, spec) == "down") == (torque > 0.0)


@dataclass(frozen=True)
class Knowledge:
    """What a strategy tells the controller about its vehicle: μ of each element (the
    parameter, the map's factor), m_veh, ζ, the input torque per commanded torque, its view of
    the valve (gain, offset) and its learned fill-time and pressure offsets."""

    mu: Mapping[str, float]
    m_veh: float
    zeta: float
    torque_gain: float = 1.0
    valve_gain: float = 1.0
    valve_offset: float = 0.0
    fill_time: float | None = None  # the fill time it believes (None: the calibration's)
    fill_offset: float = 0.0
    pressure_offset: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "mu": dict(self.mu),
            "m_veh": self.m_veh,
            "zeta": self.zeta,
            "torque_gain": self.torque_gain,
            "valve_gain": self.valve_gain,
            "valve_offset": self.valve_offset,
            "fill_time": self.fill_time,
            "fill_offset": self.fill_offset,
            "pressure_offset": self.pressure_offset,
        }


@dataclass(frozen=True)
class TargetSlip:
    """The inertia phase's slip target from σ0 to 0 in ``duration``: slip acceleration
    −σ0/(T (1 − r)) w(τ), w a trapezoid rising over the first r of the phase and falling over
    the last r (τ = t/T); its integral over the phase is exactly σ0."""

    sigma0: float
    duration: float
    ramp: float = RAMP_FRACTION

    def _w_integral(self, tau: float) -> float:
        """∫₀^τ w(s) ds of the unit trapezoid."""
        r = self.ramp
        tau = min(max(tau, 0.0), 1.0)
        if tau <= r:
            return tau * tau / (2 * r)
        if tau <= 1 - r:
            return r / 2 + (tau - r)
        rest = 1.0 - tau
        return (1.0 - r) - rest * rest / (2 * r)

    def _w(self, tau: float) -> float:
        r = self.ramp
        if tau <= 0.0 or tau >= 1.0:
            return 0.0
        return min(tau / r, 1.0, (1.0 - tau) / r)

    def slip(self, t: float) -> float:
        return self.sigma0 * (1.0 - self._w_integral(t / self.duration) / (1.0 - self.ramp))

    def time_at(self, fraction: float) -> float:
        """The time at which the target slip is ``fraction`` of σ0 (0 < fraction <= 1):
        where a record's inertia phase is measured from (:func:`.quality.inertia_phase`)."""
        wanted = (1.0 - fraction) * (1.0 - self.ramp)
        low, high = 0.0, 1.0
        for _ in range(60):  # W(τ) increases monotonically: bisection
            mid = (low + high) / 2
            if self._w_integral(mid) < wanted:
                low = mid
            else:
                high = mid
        return (low + high) / 2 * self.duration

    def rate(self, t: float) -> float:
        return -self.sigma0 / (self.duration * (1.0 - self.ramp)) * self._w(t / self.duration)


@dataclass
class _Plan:
    """Forces (N) computed when the shift is commanded."""

    hold_off: float
    carry_on: float
    off_capacity: float  # torque per newton of the off-going element's F_N
    off_torque: float


@dataclass
class ShiftController:
    """The controller of one power-on upshift or coast downshift (module docstring).
    ``model`` is the calibration's hybrid model of the shift (the TCU's own, never the
    truth's); ``knowledge`` the strategy's values. :meth:`step` is the TCU task: the time
    since the shift command, the measured shaft speeds, the commanded input torque → a
    pressure command per swapping element (Pa)."""

    d: GearboxDescription
    model: HybridSimulator
    knowledge: Knowledge
    phase: str = "fill"

    def __post_init__(self) -> None:
        control = self.d.control
        self.spec: ShiftSpec = self.model.hybrid.spec
        self.off, self.on = self.spec.off_going, self.spec.on_coming
        self.line = self.d.drive.si("shift", "line_pressure")
        self.fill_time = (
            control.si("actuator", "fill_time")
            if self.knowledge.fill_time is None
            else self.knowledge.fill_time
        )
        self.fast_fill = control.si("actuator", "fast_fill_pressure")
        self.spring = control.si("actuator", "return_spring")
        self.fill_hold = control.si("shift", "fill_hold")
        self.torque_phase = control.si("shift", "torque_phase")
        self.inertia_phase = control.si("shift", "inertia_phase")
        self.k_p = control.si("shift", "slip_k_p")
        self.t_i = control.si("shift", "slip_t_i")
        self.lockup_slip = control.si("shift", "lockup_slip")
        self.margin = control.si("shift", "off_going_margin")
        # the valve's dead time and lag as the TCU's nominal actuator has them: a command
        # reaches the discs about this much later, so planned trajectories are commanded
        # that much ahead (for a ramp, a first-order lag is a pure delay of its time constant)
        self.lead = control.si("actuator", "dead_time") + control.si("actuator", "time_constant")
        self.i_d = quantity(self.d, "drivetrain", "i_D").value
        shafts = [s.name for s in self.d.shafts]
        self.measured = [shafts.index(self.d.input_shaft), shafts.index(self.d.output_shaft)]
        self.p = self._parameters()
        self._plan: _Plan | None = None
        self._t_fill_end = max(self.fill_time + self.knowledge.fill_offset, 0.0)
        self._t_torque = self._t_fill_end + HOLD_AFTER_FILL
        self._t_inertia = self._t_torque + self.torque_phase
        self._target: TargetSlip | None = None
        self._integral = 0.0
        self._last_force = 0.0
        self._t_lock = math.nan
        self._sign = 1.0
        self._t_previous = 0.0

    # ------------------------------------------------------------------ knowledge

    def _parameters(self) -> np.ndarray:
        """The model's parameter vector with the strategy's μ, m_veh and ζ."""
        values = self.model.values()
        values[naming.GRADE] = self.knowledge.zeta
        values["m_veh"] = self.knowledge.m_veh
        for e, symbol in self.model.hybrid.friction_coefficient.items():
            if e in self.knowledge.mu:
                values[str(symbol)] = self.knowledge.mu[e]
        return self.model.parameter_vector(values)

    def _capacity(self, element: str) -> float:
        """2 n_disc r_m μ (2.69): torque per newton of F_N at the strategy's μ."""
        e = self.d.element(element)
        assert e.n_disc is not None and e.r_m is not None
        symbol = self.model.hybrid.friction_coefficient[element]
        mu = self.p[self.model.parameter_names.index(str(symbol))]
        return 2 * e.n_disc * e.r_m.value * mu

    def _state(self, mode: str, speeds: np.ndarray, forces: list[float], torque: float) -> Any:
        """The model state of ``mode`` from the measured speeds, the twist quasi-static."""
        compiled = self.model.modes[mode]
        x = state_from_speeds(self.model, mode, speeds, 0.0, 0.0, shafts=self.measured)
        names = [v.name for v in compiled.mode.model.states]
        out = [s.name for s in self.d.shafts].index(self.d.output_shaft)
        x[names.index(naming.WHEEL_SPEED)] = speeds[out] / self.i_d
        u = self._inputs(forces, torque)
        x[names.index(naming.TWIST)] = self.model.quasi_static_twist(mode, x, u, self.p)
        return x, u

    def _inputs(self, forces: list[float], torque: float) -> np.ndarray:
        return np.array([self.knowledge.torque_gain * torque, *forces, 0.0])

    def _line_forces(self, mode: str) -> list[float]:
        status = self.model.hybrid.modes[mode].status
        return [
            self.line * self.model.area[e] if status[e][0] == "locked" else 0.0
            for e in self.model.hybrid.elements
        ]

    # ------------------------------------------------------------------ the plan

    #: whether this controller's phases are for a shift the input torque drives
    #: (:func:`torque_drives_the_shift`; :func:`.study.make_controller` picks)
    driven = False
    #: what the shifts it is for are called, for the refusal
    handles = "a power-on upshift or a coast downshift"

    def _make_plan(self, speeds: np.ndarray, torque: float) -> _Plan:
        if torque_drives_the_shift(self.d, self.spec, torque) != self.driven:
            raise GearsymError(
                self.d.file,
                "control",
                f"shift {self.spec.name}: this controller's phases are for {self.handles} "
                f"(commanded input torque {torque:.1f} N*m)",
            )
        hybrid = self.model.hybrid
        j_off, j_on = hybrid.elements.index(self.off), hybrid.elements.index(self.on)
        source = self.model.modes[hybrid.from_mode]
        x, u = self._state(hybrid.from_mode, speeds, self._line_forces(hybrid.from_mode), torque)
        off_torque = abs(float(source.value(source.torques, x, u, self.p)[j_off]))
        slip = float(source.value(source.slips, x, u, self.p)[j_on])
        self._sign = 1.0 if slip > 0 else -1.0
        target = self.model.modes[hybrid.to_mode]
        x_to, u_to = self._state(hybrid.to_mode, speeds, self._line_forces(hybrid.to_mode), torque)
        carry = abs(float(target.value(target.torques, x_to, u_to, self.p)[j_on]))
        return _Plan(
            hold_off=self.margin * off_torque / self._capacity(self.off),
            carry_on=carry / self._capacity(self.on),
            off_capacity=self._capacity(self.off),
            off_torque=off_torque,
        )

    # ------------------------------------------------------------------ the task

    def pressure(self, element: str, force: float, extra: float = 0.0) -> float:
        """The command for a force (N): above the return spring, through the strategy's
        view of the valve (p_valve = gain p_cmd + offset)."""
        wanted = force / self.model.area[element] + self.spring + extra
        return max((wanted - self.knowledge.valve_offset) / self.knowledge.valve_gain, 0.0)

    def step(self, t: float, speeds: np.ndarray, torque: float) -> dict[str, float]:
        """One TCU tick at ``t`` (s since the shift command): pressure commands (Pa)."""
        if self._plan is None:
            self._plan = self._make_plan(speeds, torque)
        plan = self._plan
        offset = self.knowledge.pressure_offset
        commands: dict[str, float]
        if self.phase == "fill" and t >= self._t_torque:
            self.phase = "torque"
        if self.phase == "torque" and t >= self._t_inertia:
            self.phase = "inertia"
        if self.phase == "fill":
            on = self._fill_command(t)
            commands = {self.off: self.pressure(self.off, plan.hold_off), self.on: on}
        elif self.phase == "torque":
            tau = min(max((t + self.lead - self._t_torque) / self.torque_phase, 0.0), 1.0)
            # an S-shaped hand-over (raised cosine): no corner at either end to excite the
            # side shafts' torsional mode
            share = (1.0 - math.cos(math.pi * tau)) / 2.0
            on_force = share * plan.carry_on
            # the off-going element's estimated torque falls as the on-coming one takes over
            off_torque = plan.off_torque * (1.0 - share)
            off = (
                self.pressure(self.off, self.margin * off_torque / plan.off_capacity)
                if off_torque > 0
                else 0.0
            )
            hold = self.spring + self.fill_hold
            commands = {self.off: off, self.on: max(self.pressure(self.on, on_force, offset), hold)}
            self._last_force = on_force
        elif self.phase == "inertia":
            commands = {self.off: 0.0, self.on: self._inertia(t, speeds, torque, offset)}
        else:
            commands = {self.off: 0.0, self.on: self._lockup(t)}
        self._t_previous = t
        return commands

    def _inertia(self, t: float, speeds: np.ndarray, torque: float, offset: float) -> float:
        hybrid = self.model.hybrid
        j_on = hybrid.elements.index(self.on)
        sliding = self.model.modes[
            hybrid.mode_of({self.off: ("open", 0), self.on: ("sliding", int(self._sign))}).name
        ]
        forces = [0.0, 0.0]
        forces[j_on] = self._last_force
        x, u = self._state(sliding.mode.name, speeds, forces, torque)
        slip = float(sliding.value(sliding.slips, x, u, self.p)[j_on])
        if self._target is None:
            self._target = TargetSlip(slip, self.inertia_phase)
        # the slip target starts once the off-going element's vented pressure has reached
        # its discs (the valve's delay after the torque phase); its feed-forward is commanded
        # that delay ahead
        tau = t - self._t_inertia - self.lead
        if (
            abs(slip) <= self.lockup_slip
            or slip * self._sign < 0
            or tau > (TIMEOUT_FACTOR * self.inertia_phase)
        ):
            self.phase = "lockup"
            self._t_lock = t
            return self._lockup(t)
        target = self._target
        f1 = max(self._plan.carry_on if self._plan else 0.0, SECANT_FORCE_MIN)
        r0, r1 = self._slip_rates(sliding, x, torque, j_on, j_on, f1)
        wanted = target.rate(tau + self.lead)
        feed_forward = self._last_force if r1 == r0 else (wanted - r0) / (r1 - r0) * f1
        error = self._sign * (slip - target.slip(tau))
        self._integral += error * (t - self._t_previous)
        correction = self.k_p * (error + self._integral / self.t_i)
        force = max(feed_forward, 0.0)
        self._last_force = force
        area = self.model.area[self.on]
        return self.pressure(self.on, force + correction * area, offset)

    def _fill_command(self, t: float) -> float:
        """The on-coming piston's command: the fast fill for the fill time, then the hold
        just above the return spring. When the fill ends inside a tick, that tick gets the
        same oil volume at a lower pressure (the piston strokes at a rate ∝ p − p_spring), so
        the fill completes at the tick's end instead of overfilling by up to a tick."""
        hold = self.spring + self.fill_hold
        if t + TICK <= self._t_fill_end + 1e-9:
            return self.fast_fill
        if t < self._t_fill_end:
            part = (self._t_fill_end - t) / TICK
            return max(self.spring + part * (self.fast_fill - self.spring), hold)
        return hold

    def _slip_rates(
        self, mode: Any, x: np.ndarray, torque: float, pressed: int, watched: int, force: float
    ) -> tuple[float, float]:
        """The slip acceleration of swapping element ``watched`` in ``mode`` at the state ``x``
        with element ``pressed`` at F_N = 0 and at ``force``: two points of the affine map
        the feed-forward inverts."""
        rates = []
        for value in (0.0, force):
            forces = [0.0, 0.0]
            forces[pressed] = value
            u = self._inputs(forces, torque)
            xdot = mode.rhs(x, u, self.p)
            rates.append(float(mode.value(mode.slips, xdot, u, self.p)[watched]))
        return rates[0], rates[1]

    def _lockup(self, t: float) -> float:
        if math.isnan(self._t_lock):
            self._t_lock = t
        share = min((t - self._t_lock) / TO_LINE, 1.0)
        last = self.pressure(self.on, self._last_force, self.knowledge.pressure_offset)
        if t - self._t_lock >= TO_LINE + HOLD_LINE:
            self.phase = "done"
        return last + share * (self.line - last)
