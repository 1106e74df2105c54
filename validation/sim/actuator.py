"""Between the shift controller's pressure command and the plant's pressure: a
pressure-control valve and the clutch's piston fill (the adaptive shift control of issue 29).

The plant (:mod:`gearsym.validation.sim.hybrid_simulation`) takes per element a pressure and
presses with F_N = p · a_piston. A real clutch does not press at once: its valve answers late
and its piston must first stroke against the return spring. One :class:`ClutchActuator` is
either the TCU's nominal model (``[control.actuator]`` of the description) or one vehicle's
truth (the same with the fleet's valve gain and offset and fill-time error).

The model, p_s the return-spring pressure, p_ff the fast-fill pressure, t_fill the fill time,
τ the time constant and T_d the dead time:

- **Valve.** The command p_cmd is held from the instant it is given to the next (zero-order
  hold, one command per controller period) and reaches the valve T_d later:
  p_v(t) = max(g · p_cmd(t − T_d) + p_off, 0) where p_cmd(t − T_d) > 0, else 0 (a valve
  commanded shut stays shut: the offset does not open it; as the fleet's
  :class:`~gearsym.validation.sim.fleet.Actuators`).
- **Fill.** While the piston strokes (fill x < 1) the oil flow through the valve moves it at a
  rate proportional to the pressure above the spring, scaled so that the fast-fill pressure
  strokes it in t_fill: dx/dt = (p_v − p_s) / ((p_ff − p_s) · t_fill), x bounded to [0, 1].
  Above the spring it strokes, below it the spring pushes it back (the same law with the sign
  of p_v − p_s); the piston transmits no force while x < 1 (effective pressure 0).
- **Filled.** Once x = 1 the chamber pressure p starts from p_s (the piston just touches the
  discs) and follows the valve with a first-order lag, dp/dt = (p_v − p)/τ. The force is what
  the chamber presses above the spring: effective pressure p_eff = max(p − p_s, 0), and
  F_N = p_eff · a_piston. When p falls to p_s while p_v < p_s, the piston leaves the discs and
  retracts by the fill law.

Between the instants where the valve pressure changes, the fill completes, the pressure
crosses the spring or the piston bottoms, each law is solved exactly (x linear in t,
p − p_v exponential), so advancing in many small steps gives what one large step gives, and
the response of a step command is known in closed form (tests/test_actuator.py). The samples
:meth:`ClutchActuator.advance` returns are the plant's pressure of the element: joined over the
controller's periods they make the piecewise-linear profile
(:class:`~gearsym.validation.sim.scenario.Profile`) the plant presses with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from gearsym.symbolic.control_calibration import ControlCalibration
    from gearsym.validation.sim.fleet import Actuators, FleetDraw

__all__ = ["ActuatorState", "ClutchActuator"]


@dataclass(frozen=True)
class ActuatorState:
    """One clutch's actuator at an instant: the piston's fill (0 empty, 1 stroked onto the
    discs), the chamber pressure (Pa; the return-spring pressure while the piston strokes), the
    valve pressure now (Pa) and the commands given but still inside the dead time, as
    (instant they reach the valve, valve pressure) in time order."""

    fill: float
    pressure: float
    valve: float = 0.0
    pending: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class ClutchActuator:
    """A pressure-control valve and a clutch piston (module docstring): times in s, pressures
    in Pa; ``pressure_gain`` and ``pressure_offset`` are the valve's true p over the commanded
    one (1 and 0 for the TCU's nominal model)."""

    dead_time: float
    time_constant: float
    fill_time: float
    fast_fill_pressure: float
    return_spring: float
    pressure_gain: float = 1.0
    pressure_offset: float = 0.0

    def __post_init__(self) -> None:
        if not (self.dead_time >= 0 and self.time_constant > 0 and self.fill_time > 0):
            raise ValueError(
                f"dead_time must be >= 0 and time_constant, fill_time positive, got "
                f"{self.dead_time:g}, {self.time_constant:g}, {self.fill_time:g} s"
            )
        if not self.fast_fill_pressure > self.return_spring >= 0:
            raise ValueError(
                f"fast_fill_pressure ({self.fast_fill_pressure:g} Pa) must lie above "
                f"return_spring ({self.return_spring:g} Pa), and that at or above 0"
            )

    @classmethod
    def from_calibration(
        cls,
        control: ControlCalibration,
        actuators: Actuators | None = None,
        fill_time_error: float = 0.0,
    ) -> ClutchActuator:
        """The TCU's nominal actuator of ``control`` (a description's ``d.control``), or with a
        vehicle's valve tolerances (``actuators``, the fleet's
        :class:`~gearsym.validation.sim.fleet.Actuators`) and its fill time off by
        ``fill_time_error`` (s): that vehicle's truth."""

        def value(key: str) -> float:
            return control.si("actuator", key)

        return cls(
            dead_time=value("dead_time"),
            time_constant=value("time_constant"),
            fill_time=value("fill_time") + fill_time_error,
            fast_fill_pressure=value("fast_fill_pressure"),
            return_spring=value("return_spring"),
            pressure_gain=1.0 if actuators is None else actuators.pressure_gain,
            pressure_offset=0.0 if actuators is None else actuators.pressure_offset,
        )

    @classmethod
    def from_draw(cls, control: ControlCalibration, draw: FleetDraw) -> ClutchActuator:
        """The truth of the fleet's vehicle ``draw``: its valve gain and offset and its
        ``fill_time_error`` (0 where the fleet draws none)."""
        from gearsym.validation.sim.fleet import Actuators

        return cls.from_calibration(
            control, Actuators.from_draw(draw), draw.get("fill_time_error", 0.0)
        )

    def valve_pressure(self, command: float) -> float:
        """What the valve gives for ``command`` once the dead time has passed (Pa)."""
        if not command > 0:
            return 0.0
        return max(self.pressure_gain * command + self.pressure_offset, 0.0)

    def initial(self, filled: bool, pressure: float = 0.0) -> ActuatorState:
        """At rest: the piston stroked with the chamber at ``pressure`` (an element held
        closed, e.g. at line pressure; not below the return spring, which a stroked piston
        balances) and the valve giving that pressure, or empty with the valve shut."""
        if not filled:
            return ActuatorState(0.0, self.return_spring, 0.0)
        p = max(float(pressure), self.return_spring)
        return ActuatorState(1.0, p, p)

    def effective(self, state: ActuatorState) -> float:
        """The pressure that presses the discs (Pa): p − p_s once filled, else 0."""
        return self._effective(state.fill, state.pressure)

    def _effective(self, fill: float, pressure: float) -> float:
        return 0.0 if fill < 1.0 else max(pressure - self.return_spring, 0.0)

    def advance(
        self, state: ActuatorState, t0: float, t1: float, command: float, samples: int = 1
    ) -> tuple[ActuatorState, np.ndarray, np.ndarray]:
        """``command`` (Pa) given at ``t0`` and held to ``t1``: the state at ``t1``, the
        ``samples + 1`` instants from t0 to t1 (equally spaced) and the effective pressure
        at each (times the piston area: F_N). Calls follow each other without a gap (``t0``
        the previous call's ``t1``): the commands still inside the dead time are the state's."""
        if not t1 > t0 or samples < 1:
            raise ValueError(f"need t1 > t0 and samples >= 1, got {t0}, {t1}, {samples}")
        pending = [*state.pending, (t0 + self.dead_time, self.valve_pressure(command))]
        fill, p, valve, now = state.fill, state.pressure, state.valve, t0
        times = np.linspace(t0, t1, samples + 1)
        effective = np.empty(samples + 1)
        for k, t in enumerate(times.tolist()):
            while pending and pending[0][0] <= t:
                at, v = pending.pop(0)
                if at > now:
                    fill, p = self._evolve(fill, p, valve, at - now)
                    now = at
                valve = v
            if t > now:
                fill, p = self._evolve(fill, p, valve, t - now)
                now = t
            effective[k] = self._effective(fill, p)
        return ActuatorState(fill, p, valve, tuple(pending)), times, effective

    def stroke_time(self, command: float) -> float:
        """How long the piston takes to stroke from empty under a constant ``command`` (s),
        once the dead time has passed: t_fill (p_ff − p_s) / (p_v − p_s) by the fill law;
        infinite when the valve gives no more than the return spring."""
        above = self.valve_pressure(command) - self.return_spring
        if not above > 0:
            return math.inf
        return self.fill_time * (self.fast_fill_pressure - self.return_spring) / above

    def at_ticks(
        self,
        state: ActuatorState,
        commands: np.ndarray,
        tick: float,
        t0: float = 0.0,
        mean_over: int = 0,
    ) -> np.ndarray:
        """The effective pressure at the start of each tick (Pa) when ``commands`` are given
        one per ``tick`` from ``t0``, starting in ``state``: what a TCU believes its element
        pressed with, from its own commands and this model of the actuator. ``mean_over``
        > 0: instead the mean over each tick (the trapezoid rule on that many sub-intervals),
        the value a model that holds its input over the tick needs (a pressure rising at
        10⁶ Pa/s is 5 000 Pa above its start value in the middle of a 10 ms tick)."""
        out = np.empty(len(commands))
        for k, command in enumerate(np.asarray(commands, dtype=float).tolist()):
            start = t0 + k * tick
            if mean_over > 0:
                state, _, pressed = self.advance(state, start, start + tick, command, mean_over)
                out[k] = float(np.mean(0.5 * (pressed[1:] + pressed[:-1])))
            else:
                out[k] = self.effective(state)
                state, _, _ = self.advance(state, start, start + tick, command, 1)
        return out

    def _evolve(self, fill: float, p: float, valve: float, dt: float) -> tuple[float, float]:
        """Fill and chamber pressure after ``dt`` at the constant valve pressure ``valve``,
        exactly: piece by piece between the fill's completion, the pressure's crossing of the
        spring and the piston's bottoming."""
        spring = self.return_spring
        stroke = (self.fast_fill_pressure - spring) * self.fill_time  # Pa·s per full stroke
        while dt > 0:
            if fill < 1.0 or (p <= spring and valve < spring):
                # stroking (or just leaving the discs): x linear in t
                rate = (valve - spring) / stroke
                if rate > 0:
                    to_full = (1.0 - fill) / rate
                    if to_full >= dt:
                        return min(fill + rate * dt, 1.0), spring
                    fill, p, dt = 1.0, spring, dt - to_full
                    continue
                if rate < 0:
                    return max(fill + rate * dt, 0.0), spring
                return fill, spring
            # filled: p − p_v decays with τ
            if valve < spring:
                to_spring = self.time_constant * math.log((p - valve) / (spring - valve))
                if to_spring < dt:
                    # the piston leaves the discs at p = p_s and retracts for the rest
                    p, dt = spring, dt - to_spring
                    continue
            return fill, valve + (p - valve) * math.exp(-dt / self.time_constant)
        return fill, p
