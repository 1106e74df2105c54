"""One shift in closed loop: the truth's hybrid shift simulation stepped from TCU tick to TCU
tick, the controller's pressure commands through each swapping element's actuator (valve and
clutch fill, :mod:`gearsym.validation.sim.actuator`) into the plant's normal forces.

Between two ticks the commands are held (zero-order hold, as the TCU's output stage holds
them); the actuator's response inside a tick is sampled at ``sub`` points and interpolated
linearly (the plant's inputs are piecewise linear). The controller sees the input and output
shaft speeds at each tick and the torque it commands; the plant gets the torque the vehicle
really gives and its own μ, mass, grade and inertias.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.hybrid import LOCK_UP, hybrid_shift
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import Profile, Scenario
from gearsym.validation.studies.control.controller import TICK, ShiftController

__all__ = ["ClosedLoopResult", "ClosedLoopShift", "TICK"]

#: Sample time of the recorded shift (s): fine enough for the jerk.
RECORD = 1e-3
#: rtol = atol of the plant's integration (DOP853).
TOLERANCE = 1e-8


@dataclass
class ClosedLoopResult:
    """The recorded shift: signals every :data:`RECORD` s (the plant's: shaft speeds, twist,
    wheel speed, each swapping element's slip, torque, F_N and μ), the mode per sample, the
    events, the commands and phases per tick, and whether it ended locked in the to-gear."""

    t: np.ndarray
    signals: dict[str, np.ndarray]
    modes: tuple[str, ...]
    events: list[Any]
    ticks: np.ndarray
    commands: dict[str, np.ndarray]
    phases: tuple[str, ...]
    completed: bool
    t_lockup: float
    spec: Any = None
    values: dict[str, float] = field(default_factory=dict)
    #: right-hand-side evaluations of the plant's integration (its cost; a bound on its steps)
    nfev: int = 0


class ClosedLoopShift:
    """The truth's side of one shift: its hybrid model, parameters and operating point."""

    def __init__(
        self,
        truth: GearboxDescription,
        shift: str,
        vehicle_speed: float,
        mu_scale: Mapping[str, float] | None = None,
    ) -> None:
        self.d = truth
        self.spec = shift_spec(truth, shift)
        self.vehicle_speed = vehicle_speed
        self.simulator = HybridSimulator(
            truth, self.scenario(1.0, {}, 0.0), hybrid_shift(truth, shift)
        )
        values = self.simulator.values()
        mu = quantity(truth, "friction", "mu_nominal").value
        for e, symbol in self.simulator.hybrid.friction_coefficient.items():
            values[str(symbol)] = mu * (mu_scale or {}).get(e, 1.0)
        self.values = values
        self.p = self.simulator.parameter_vector(values)
        self.line = truth.drive.si("shift", "line_pressure")

    def _log(
        self,
        log: Any,
        t: float,
        x: np.ndarray,
        mode: str,
        speeds: np.ndarray,
        torque: float,
        believed: Mapping[str, Any],
        beliefs: Mapping[str, Any],
        in_shift: bool,
    ) -> None:
        sim = self.simulator
        hybrid = sim.hybrid
        names = [v.name for v in sim.modes[mode].mode.model.states]
        pressures = {e: self.line for e in self.spec.locked}
        pressures |= {e: believed[e].effective(beliefs[e]) for e in beliefs}
        status = hybrid.modes[mode].status
        u = sim.inputs(t)
        mus = sim.modes[mode].value(sim.modes[mode].mu, x, u, self.p)
        mu = {
            e: float(mus[j])
            for j, e in enumerate(hybrid.elements)
            if e in hybrid.friction_coefficient and status[e][0] == "sliding"
        }
        log.add(
            t,
            speeds,
            x[names.index(naming.TWIST)],
            x[names.index(naming.WHEEL_SPEED)],
            torque,
            0.0,
            pressures,
            0 if in_shift else 1,
            self.spec.name if in_shift else "",
            mu,
            self.values[naming.GRADE],
            # the shift study commands one input torque; its filter has no engine-gain state
            math.nan,
        )

    def scenario(self, t_end: float, pressure: Mapping[str, Profile], torque: float) -> Scenario:
        """The plant's inputs up to ``t_end``: the pressures above the return springs (the
        actuators' effective pressures) and the true input torque (the grade is the truth's ζ)."""
        return Scenario(
            name=f"closed-loop shift {self.spec.name}",
            file=f"<closed-loop shift {self.spec.name}>",
            shift=self.spec,
            t_end=t_end,
            vehicle_speed=self.vehicle_speed,
            engine=Profile(np.array([0.0]), np.array([torque])),
            e_machine=Profile(np.array([0.0]), np.array([0.0])),
            pressure=dict(pressure),
            grade=None,
        )

    def run(
        self,
        controller: ShiftController,
        commanded_torque: float,
        true_torque: float,
        actuators: Mapping[str, Any],
        believed: Mapping[str, Any],
        log: Any = None,
        t_end: float = 1.5,
        sub: int = 5,
        reference: bool = False,
    ) -> ClosedLoopResult:
        """The shift from steady from-gear at the operating point: ``controller`` commands,
        ``actuators`` (one :class:`~gearsym.validation.sim.actuator.ClutchActuator` per
        swapping element, the vehicle's own) respond, the plant gets ``true_torque``.

        ``log``: a :class:`~gearsym.validation.sim.drive_log.TcuLog` that gets, every tick,
        what the TCU knows (the shaft speeds, the commanded torque, and as each swapping
        element's pressure the effective pressure its ``believed`` actuator model gives for
        the commands: the TCU's nominal model, never the vehicle's) and the truth for scoring
        (μ of a sliding element, the grade).

        The plant runs compiled (the modes as emitted C, :class:`HybridSimulator`'s
        ``compiled``) and its record is sampled once, after the last tick, from every tick's
        pieces and the whole shift's pressures; ``reference=True`` runs the reference it is
        checked against (tests/test_closed_loop_fast.py): CasADi's calls and each tick's record
        sampled in its own run. The same plant, inputs and tolerances: they differ by rounding
        and what the integrator's error control lets it grow to."""
        sim = self.simulator
        sim.compiled = not reference
        hybrid = sim.hybrid
        off, on = self.spec.off_going, self.spec.on_coming
        states = {
            off: actuators[off].initial(True, self.line),
            on: actuators[on].initial(False, 0.0),
        }
        beliefs = {
            off: believed[off].initial(True, self.line),
            on: believed[on].initial(False, 0.0),
        }
        # the steady from-gear: the off-going element at line pressure
        spring = {e: float(actuators[e].return_spring) for e in (off, on)}
        start = {
            off: Profile(np.array([0.0]), np.array([self.line - spring[off]])),
            on: Profile(np.array([0.0]), np.array([0.0])),
        }
        sim.scenario = self.scenario(TICK, start, true_torque)
        x = sim.initial_state(self.p)
        mode = hybrid.from_mode
        ticks = np.arange(0.0, t_end - 1e-12, TICK)
        commands: dict[str, list[float]] = {off: [], on: []}
        phases: list[str] = []
        chunks: list[dict[str, np.ndarray]] = []
        times: list[np.ndarray] = []
        modes: list[str] = []
        events: list[Any] = []
        pieces: list[Any] = []
        knots: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {off: [], on: []}
        no_samples = np.empty(0)
        nfev = 0
        for t0 in ticks:
            t1 = t0 + TICK
            speeds = np.asarray(sim.shaft_speeds(mode)(x)).ravel()
            command = controller.step(float(t0), speeds, commanded_torque)
            phases.append(controller.phase)
            if log is not None:
                in_shift = controller.phase != "done"
                self._log(
                    log, float(t0), x, mode, speeds, commanded_torque, believed, beliefs, in_shift
                )
            profiles = {}
            for e in (off, on):
                commands[e].append(command[e])
                beliefs[e], _, _ = believed[e].advance(
                    beliefs[e], float(t0), float(t1), command[e], 1
                )
                states[e], instants, effective = actuators[e].advance(
                    states[e], float(t0), float(t1), command[e], sub
                )
                profiles[e] = Profile(np.asarray(instants), np.asarray(effective))
                knots[e].append((np.asarray(instants), np.asarray(effective)))
            sim.scenario = self.scenario(float(t1), profiles, true_torque)
            grid = np.arange(t0, t1 - RECORD / 2, RECORD)
            result = sim.run(
                self.values,
                rtol=TOLERANCE,
                atol=TOLERANCE,
                x0=x,
                t_start=float(t0),
                mode=mode,
                t_eval=grid if reference else no_samples,
            )
            if reference:
                chunks.append(result.signals)
                modes.extend(result.modes)
            times.append(grid)
            pieces.extend(result.pieces)
            nfev += int(result.stats["nfev"])
            events.extend(result.events)
            last = result.pieces[-1]
            mode = last.mode
            n = sim.modes[mode].n
            x = last.state(np.array([last.t_end]))[0, :n]
        if reference:
            signals = {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]}
        else:
            # every tick's profile joined: a tick's last knot is the next one's first (the
            # actuator's state carries over), so each tick after the first drops its first
            whole = {
                e: Profile(
                    np.concatenate([knots[e][0][0]] + [t[1:] for t, _ in knots[e][1:]]),
                    np.concatenate([knots[e][0][1]] + [v[1:] for _, v in knots[e][1:]]),
                )
                for e in (off, on)
            }
            sim.scenario = self.scenario(float(ticks[-1] + TICK), whole, true_torque)
            signals, sampled, _ = sim._sample(pieces, np.concatenate(times), self.p)
            modes = list(sampled)
        lock = [
            e.t
            for e in events
            if e.kind == LOCK_UP and e.element == on and e.target == hybrid.to_mode
        ]
        return ClosedLoopResult(
            t=np.concatenate(times),
            signals=signals,
            modes=tuple(modes),
            events=events,
            ticks=ticks,
            commands={e: np.array(v) for e, v in commands.items()},
            phases=tuple(phases),
            completed=mode == hybrid.to_mode,
            t_lockup=lock[-1] if lock else float("nan"),
            spec=self.spec,
            values=dict(self.values),
            nfev=nfev,
        )


def output_torque(d: GearboxDescription, values: Mapping[str, float], signals: Any) -> np.ndarray:
    """The side shafts' torque k_ss φ + d_ss φ̇ (2.44) from the twist and the speeds: what the
    gearbox gives the wheels."""
    i_d = values.get("i_D", quantity(d, "drivetrain", "i_D").value)
    k = values.get("k_ss", quantity(d, "drivetrain", "k_ss").value)
    c = values.get("d_ss", quantity(d, "drivetrain", "d_ss").value)
    phi_dot = signals[naming.speed(d.output_shaft)] / i_d - signals[naming.WHEEL_SPEED]
    return k * signals[naming.TWIST] + c * phi_dot
