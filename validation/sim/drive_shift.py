"""One shift of a drive (:mod:`gearsym.validation.sim.drive`): the TCU's open-loop shift plan
and the hybrid simulation that carries it out.

**The plan** (stated, the numbers in ``[drive.shift]``), from the state at the shift's start and
the TCU's calibration (the description's values with the prior mass, never the truth):

* 0-50 ms: the off-going element's pressure falls to 1.2 times what holds its present torque
  (its reaction in the from-gear, capacity 2 n_disc r_m μ F_N, 2.69);
* torque phase (``torque_phase``): the off-going pressure ramps to 0, the on-coming one up to
  what carries its torque in the to-gear at the present input torque;
* speed phase (``speed_phase``): the on-coming pressure steps up to what brings its slip to
  zero within the phase (slip acceleration from the mode with the off-going open and the
  on-coming sliding, at the calibration's values, linear in F_N between two evaluations);
* then to line pressure within 0.1 s, held 0.15 s: a slow or early shift still ends locked.

Up- and downshifts use the same plan: a sliding on-coming element always pulls its slip
towards zero, so it brings the input up in a downshift and down in an upshift. The input torque
and the brake are held at their values at the shift's start (the driver waits the shift out;
in a downshift under recuperation the machine's torque goes to the brake,
:func:`~gearsym.validation.sim.drive_schedule.blended_split`).
The hybrid simulation decides what really happens (break-away, lock-up, flare); a shift that
does not end in the to-gear is reported as failed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.hybrid import LOCK_UP, hybrid_shift
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.sim.drive_powertrain import TorqueSplit
from gearsym.validation.sim.hybrid_energy import energy_audit
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import Profile, Scenario
from gearsym.validation.sim.simulation_result import EnergyAudit

# at import, not in the first shift: SciPy's signal package takes over half a second to load,
# which a drive's clock would count against its first shift
from scipy.signal import butter, filtfilt

__all__ = ["ShiftOutcome", "ShiftRecord", "ShiftRunner", "state_from_speeds", "vehicle_jerk"]

#: The off-going element's holding margin before the torque phase.
HOLD_MARGIN = 1.2
#: Duration of the first step (s) and of the final ramp and hold at line pressure (s).
PREPARE = 0.05
TO_LINE = 0.1
HOLD_LINE = 0.15
#: Sample time of a shift's record (s): fine enough for the jerk.
SHIFT_SAMPLE = 1e-3
#: rtol = atol of a shift's integration (DOP853) in the reference drive.
REFERENCE_TOLERANCE = 1e-8
#: rtol = atol of a shift's integration in the fast drive: the reference's. A looser 1e-6
#: held the comparison's tolerances (tests/test_drive_fast.py) on the short cycle and on the
#: first 300 s of WLTC 3b, but on the whole cycle one 3-4 shift chattered at K27's lock-up
#: (more than 200 mode switches) and the drive failed: the lock-up's stick-or-slip decision
#: is where the tolerance shows, so the fast drive keeps 1e-8.
FAST_TOLERANCE = REFERENCE_TOLERANCE
#: Speed scale of the brake's friction law T = T_brake tanh(ω_C / ω_b) (rad/s): the brake
#: opposes the motion and fades to zero at rest (0.05 rad/s is 1.6 cm/s).
BRAKE_SPEED = 0.05
#: Bandwidth of the acceleration before the jerk is taken (Hz): what a seat-rail
#: accelerometer's comfort evaluation keeps of a shift (assumed; ISO 2631-1's weighting falls
#: off above about 10 Hz for longitudinal motion).
JERK_BANDWIDTH = 10.0


@dataclass(frozen=True)
class ShiftRecord:
    """One shift's quality: when, which, how long (from the start of the torque phase to the
    on-coming element's lock-up), peak |jerk| of the vehicle (m/s³), friction energy (J)."""

    name: str
    kind: str
    t_start: float
    shift_time: float
    peak_jerk: float
    friction_energy: float
    input_torque: float
    events: int
    completed: bool

    def to_dict(self) -> dict[str, Any]:
        return {
            "shift": self.name,
            "kind": self.kind,
            "t_start": self.t_start,
            "shift_time_s": self.shift_time,
            "peak_jerk_m_s3": self.peak_jerk,
            "friction_energy_J": self.friction_energy,
            "input_torque_Nm": self.input_torque,
            "events": self.events,
            "completed": self.completed,
        }


@dataclass(frozen=True)
class ShiftOutcome:
    record: ShiftRecord
    audit: EnergyAudit
    brake_work: float
    samples: list[dict[str, float]]
    t_end: float
    speeds: np.ndarray
    phi: float
    omega_c: float
    distance: float
    failure: str


class _BrakedSimulator(HybridSimulator):
    """The hybrid simulation with a constant service-brake torque at the wheel (2.45)."""

    brake: float = 0.0
    wheel_inertia: float = 1.0

    def _right_hand_side(
        self, compiled: Any, indices: tuple[int, ...], p: np.ndarray, inputs: Any = None
    ) -> Any:
        base = super()._right_hand_side(compiled, indices, p, inputs)
        if self.brake == 0.0 or indices:
            return base
        names = [v.name for v in compiled.mode.model.states]
        wheel = names.index(naming.WHEEL_SPEED)
        brake, inertia = self.brake, self.wheel_inertia

        def rhs(time: float, y: np.ndarray) -> np.ndarray:
            out = base(time, y)
            out[wheel] -= brake / inertia * math.tanh(y[wheel] / BRAKE_SPEED)
            return out

        return rhs


class ShiftRunner:
    """The hybrid simulation of one shift of a drive and its plan (module docstring)."""

    def __init__(self, d: GearboxDescription, name: str) -> None:
        self.d = d
        self.spec = shift_spec(d, name)
        hybrid = hybrid_shift(d, name)
        placeholder = _scenario(d, self.spec, 1.0, {}, 0.0, 0.0)
        self.simulator = _BrakedSimulator(d, placeholder, hybrid)
        self.line = d.drive.si("shift", "line_pressure")
        self.torque_phase = d.drive.si("shift", "torque_phase")
        self.speed_phase = d.drive.si("shift", "speed_phase")
        self.r_dyn = quantity(d, "vehicle", "r_dyn").value
        self._energy: dict[str, tuple[Any, Any]] | None = None

    def energy_functions(self, fast: bool = False) -> dict[str, tuple[Any, Any]]:
        """The powers and stored energies of every mode (built once, for the energy audit);
        ``fast``: the powers from the simulator's compiled C (the same arithmetic, read in
        one C loop), where a C compiler is there."""
        if self._energy is None:
            from gearsym.validation.sim.hybrid_energy import energy_functions

            self._energy = energy_functions(self.simulator)
            # compiled with the modes: one library (one compiler run) per shift and vehicle
            self.simulator.also_compiled |= {f"{m}#powers": f[0] for m, f in self._energy.items()}
        if not fast:
            return self._energy
        library = self.simulator.compiled_functions()
        if library is None or any(f"{m}#powers" not in library.functions for m in self._energy):
            return self._energy  # no compiler, or compiled before the powers were added
        return {m: (library[f"{m}#powers"], f[1]) for m, f in self._energy.items()}

    def line_forces(self, mode: str) -> list[float]:
        """F_N of the swapping elements in a gear mode: line pressure on the locked ones."""
        status = self.simulator.hybrid.modes[mode].status
        return [
            self.line * self.simulator.area[e]
            if status[e][0] == "locked" and e in self.simulator.area
            else 0.0
            for e in self.simulator.hybrid.elements
        ]

    def plan(
        self, x: np.ndarray, split: TorqueSplit, p_cal: np.ndarray, zeta: float
    ) -> dict[str, tuple[list[float], list[float]]]:
        """Pressure profiles (local time, Pa) of the two swapping elements (module docstring)."""
        sim = self.simulator
        hybrid = sim.hybrid
        off, on = self.spec.off_going, self.spec.on_coming
        j_off, j_on = hybrid.elements.index(off), hybrid.elements.index(on)
        from_mode = sim.modes[hybrid.from_mode]
        u = np.array([split.input_torque, *self.line_forces(hybrid.from_mode), zeta])
        torques = from_mode.value(from_mode.torques, x, u, p_cal)
        capacity = {e: self._capacity_per_force(e, p_cal) for e in (off, on)}
        hold_off = HOLD_MARGIN * abs(torques[j_off]) / capacity[off]
        speeds = np.asarray(sim.shaft_speeds(hybrid.from_mode)(x)).ravel()
        names = [v.name for v in from_mode.mode.model.states]
        phi, omega_c = x[names.index(naming.TWIST)], x[names.index(naming.WHEEL_SPEED)]
        # the on-coming element's torque in the to-gear at the same output speed
        to_mode = sim.modes[hybrid.to_mode]
        output = [s.name for s in self.d.shafts].index(self.d.output_shaft)
        x_to = state_from_speeds(sim, hybrid.to_mode, speeds, phi, omega_c, shafts=[output])
        u_to = np.array([split.input_torque, *self.line_forces(hybrid.to_mode), zeta])
        carry = abs(to_mode.value(to_mode.torques, x_to, u_to, p_cal)[j_on]) / capacity[on]
        # the speed phase: F_N that brings the on-coming slip to zero within the phase
        slip = from_mode.value(from_mode.slips, x, u, p_cal)[j_on]
        sign = 1 if slip > 0 else -1
        status = {off: ("open", 0), on: ("sliding", sign)}
        sliding = sim.modes[hybrid.mode_of(status).name]
        x_sl = state_from_speeds(sim, sliding.mode.name, speeds, phi, omega_c)
        target = -slip / self.speed_phase

        def slip_rate(force: float) -> float:
            forces = [0.0, 0.0]
            forces[j_on] = force
            u_sl = np.array([split.input_torque, *forces, zeta])
            xdot = sliding.rhs(x_sl, u_sl, p_cal)
            return float(sliding.value(sliding.slips, xdot, u_sl, p_cal)[j_on])

        f1 = max(carry, 1e3)
        r0, r1 = slip_rate(0.0), slip_rate(f1)
        speed_force = carry if r1 == r0 else (target - r0) / (r1 - r0) * f1
        speed_force = min(max(speed_force, carry), self.line * sim.area[on])
        area_off, area_on = sim.area[off], sim.area[on]
        t1 = PREPARE
        t2 = t1 + self.torque_phase
        t3 = t2 + 0.02
        t4 = t2 + self.speed_phase
        t5 = t4 + TO_LINE
        return {
            off: ([0.0, t1, t2], [self.line, hold_off / area_off, 0.0]),
            on: (
                [0.0, t1, t2, t3, t4, t5],
                [
                    0.0,
                    0.0,
                    carry / area_on,
                    speed_force / area_on,
                    speed_force / area_on,
                    self.line,
                ],
            ),
        }

    def run(
        self,
        t_start: float,
        speeds: np.ndarray,
        phi: float,
        omega_c: float,
        split: TorqueSplit,
        true_torque: float,
        p: np.ndarray,
        zeta: float,
        planner: ShiftRunner,
        calibration: np.ndarray,
        actuators: Any,
        kind: str,
        wheel_inertia: float,
        v_ref: Any,
        distance_start: float = 0.0,
        log: Any = None,
        gear: int = 0,
        zeta_true: float = 0.0,
        fast: bool = False,
    ) -> ShiftOutcome:
        """The shift from the from-gear state given by its shaft speeds, twist and wheel speed
        (module docstring). This runner is the truth's (``p`` its parameters, ``true_torque``
        and ``actuators`` what the vehicle really gets); ``planner`` is the calibration's,
        whose plan from the commanded ``split`` and the ``calibration`` parameters is what the
        TCU commands. ``zeta``: the grade's deviation from the parameter ζ, held over the
        shift. ``log``: the TCU's log (:class:`~gearsym.validation.sim.drive_log.TcuLog`)
        gets the shift's samples. ``fast``: the modes' right-hand sides run as compiled C
        (:class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator`'s ``compiled``),
        the same arithmetic as the reference's CasADi calls, at
        :data:`FAST_TOLERANCE`."""
        sim = self.simulator
        sim.compiled = fast
        hybrid = sim.hybrid
        x0 = state_from_speeds(sim, hybrid.from_mode, speeds, phi, omega_c)
        planned = planner.simulator
        x0_plan = state_from_speeds(planned, planned.hybrid.from_mode, speeds, phi, omega_c)
        commanded = planner.plan(x0_plan, split, calibration, zeta)
        pressures = {
            e: (times, list(actuators.pressure(np.asarray(values, dtype=float))))
            for e, (times, values) in commanded.items()
        }
        t_end = PREPARE + self.torque_phase + self.speed_phase + TO_LINE + HOLD_LINE
        sim.scenario = _scenario(self.d, self.spec, t_end, pressures, true_torque, zeta)
        sim.zeta0 = 0.0  # the grade profile is the deviation itself
        sim.brake = split.brake
        sim.wheel_inertia = wheel_inertia
        values = dict(zip(sim.parameter_names, (float(v) for v in p), strict=True))
        grid = np.arange(0.0, t_end + SHIFT_SAMPLE / 2, SHIFT_SAMPLE)
        tolerance = FAST_TOLERANCE if fast else REFERENCE_TOLERANCE
        energies = self.energy_functions(fast)  # before the run: compiled with the modes
        result = sim.run(values, rtol=tolerance, atol=tolerance, x0=x0, t_eval=grid)
        audit = energy_audit(sim, result, functions=energies)
        omega = result.signals[naming.WHEEL_SPEED]
        brake_power = split.brake * np.tanh(omega / BRAKE_SPEED) * omega
        brake_work = float(np.trapezoid(brake_power, grid))
        distance = float(np.trapezoid(omega * self.r_dyn, grid))
        jerk = vehicle_jerk(omega * self.r_dyn, SHIFT_SAMPLE)
        last = result.pieces[-1]
        completed = last.mode == hybrid.to_mode
        lock = [
            e.t
            for e in result.events
            if e.kind == LOCK_UP and e.element == self.spec.on_coming and e.target == hybrid.to_mode
        ]
        shift_time = (lock[-1] - PREPARE) if lock else math.nan
        record = ShiftRecord(
            name=self.spec.name,
            kind=kind,
            t_start=t_start,
            shift_time=shift_time,
            peak_jerk=float(np.max(np.abs(jerk))),
            friction_energy=audit.friction_dissipation,
            input_torque=split.input_torque,
            events=len(result.events),
            completed=completed,
        )
        n = sim.modes[last.mode].n
        x_end = last.state(np.array([last.t_end]))[0, :n]
        names = [v.name for v in sim.modes[last.mode].mode.model.states]
        speeds_end = np.asarray(sim.shaft_speeds(last.mode)(x_end)).ravel()
        input_index = [s.name for s in self.d.shafts].index(self.d.input_shaft)
        samples = []
        step = int(round(0.1 / SHIFT_SAMPLE))
        first = int(math.ceil((t_start - 1e-9) / 0.1) * 0.1 / SHIFT_SAMPLE - t_start / SHIFT_SAMPLE)
        cumulative = np.concatenate(
            [[0.0], np.cumsum(np.diff(grid) * (omega[1:] + omega[:-1]) / 2)]
        )
        for i in range(max(first, 0), len(grid) - 1, step):
            t = t_start + grid[i]
            samples.append(
                {
                    "t": float(round(t, 9)),
                    "v_ref": float(v_ref(t)),
                    "v": float(omega[i] * self.r_dyn),
                    "T_engine": split.engine,
                    "T_e_machine": split.e_machine,
                    "T_brake": split.brake,
                    "pedal": split.pedal,
                    "omega_in": float(result.signals[naming.speed(self.d.input_shaft)][i]),
                    "s": float(distance_start + cumulative[i] * self.r_dyn),
                }
            )
        del input_index
        failure = (
            ""
            if completed
            else f"shift {self.spec.name} at t = {t_start:.2f} s ended in {last.mode}, not in "
            f"the {self.spec.to_gear} gear"
        )
        if log is not None:
            self._log(log, result, t_start, t_end, split, commanded, p, gear, zeta_true)
        return ShiftOutcome(
            record=record,
            audit=audit,
            brake_work=brake_work,
            samples=samples,
            t_end=t_start + t_end,
            speeds=speeds_end,
            phi=float(x_end[names.index(naming.TWIST)]),
            omega_c=float(x_end[names.index(naming.WHEEL_SPEED)]),
            distance=distance,
            failure=failure,
        )

    def _log(
        self,
        log: Any,
        result: Any,
        t_start: float,
        t_end: float,
        split: TorqueSplit,
        commanded: dict[str, tuple[list[float], list[float]]],
        p: np.ndarray,
        gear: int,
        zeta: float,
    ) -> None:
        """The shift's samples on the TCU's grid: the truth from the pieces' dense output,
        the commanded pressures from the plan as their mean over the tick each sample starts
        (line pressure on the elements that stay locked; a filter holds its inputs over a
        tick, and a ramp's start value is half a tick's rise below that mean), μ of each
        element while it slides."""
        sim = self.simulator
        ticks = log.ticks(t_start, t_start + t_end)
        if not len(ticks):
            return
        signals, modes, _ = sim._sample(result.pieces, ticks - t_start, p)
        profiles = {e: Profile(np.array(t), np.array(v)) for e, (t, v) in commanded.items()}
        shafts = [s.name for s in self.d.shafts]
        for i, t in enumerate(ticks):
            tau = float(t - t_start)
            pressures = {e: self.line for e in self.spec.locked}
            h = log.sample_time
            pressures |= {e: profile.mean(tau, tau + h) for e, profile in profiles.items()}
            status = sim.hybrid.modes[modes[i]].status
            mu = {
                e: float(signals[str(symbol)][i])
                for e, symbol in sim.hybrid.friction_coefficient.items()
                if status[e][0] == "sliding"
            }
            log.add(
                t,
                [signals[naming.speed(s)][i] for s in shafts],
                signals[naming.TWIST][i],
                signals[naming.WHEEL_SPEED][i],
                split.input_torque,
                split.brake,
                pressures,
                gear,
                self.spec.name,
                mu,
                zeta,
                split.engine,
            )

    def _capacity_per_force(self, element: str, p: np.ndarray) -> float:
        """2 n_disc r_m μ (2.69) with the calibration's μ: torque per newton of F_N."""
        e = self.d.element(element)
        assert e.n_disc is not None and e.r_m is not None
        symbol = self.simulator.hybrid.friction_coefficient[element]
        mu = p[self.simulator.parameter_names.index(str(symbol))]
        return 2 * e.n_disc * e.r_m.value * mu


def state_from_speeds(
    sim: HybridSimulator,
    mode: str,
    speeds: np.ndarray,
    phi: float,
    omega_c: float,
    shafts: Sequence[int] | None = None,
) -> np.ndarray:
    """The state of ``mode`` with the given shaft speeds (least squares through its
    projection, exact when the speeds satisfy the mode's constraints), twist and wheel
    speed. ``shafts``: match only these shafts' speeds (indices into the description's
    shafts), the others as the mode makes them (a gear at another gear's output speed)."""
    compiled = sim.modes[mode]
    names = [v.name for v in compiled.mode.model.states]
    n_gear = len(compiled.mode.keep)
    function = sim.shaft_speeds(mode)
    columns = []
    for j in range(n_gear):
        unit = np.zeros(compiled.n)
        unit[j] = 1.0
        columns.append(np.asarray(function(unit)).ravel())
    basis = np.column_stack(columns)
    rows = slice(None) if shafts is None else list(shafts)
    z, *_ = np.linalg.lstsq(basis[rows], np.asarray(speeds)[rows], rcond=None)
    x = np.zeros(compiled.n)
    x[:n_gear] = z
    x[names.index(naming.TWIST)] = phi
    x[names.index(naming.WHEEL_SPEED)] = omega_c
    return x


def vehicle_jerk(v: np.ndarray, dt: float) -> np.ndarray:
    """d²v/dt² of a vehicle speed sampled every ``dt``, the acceleration low-pass filtered at
    :data:`JERK_BANDWIDTH` first (2nd-order Butterworth, forward and backward: no phase lag):
    an unfiltered derivative turns every step of acceleration at a mode switch into a spike
    of Δa/dt, which depends on the sample time, not on the shift."""
    acceleration = np.gradient(v, dt)
    b, a = butter(2, JERK_BANDWIDTH * 2 * dt)
    if len(v) > 3 * max(len(a), len(b)):
        acceleration = filtfilt(b, a, acceleration)
    return np.gradient(acceleration, dt)


def _scenario(
    d: GearboxDescription,
    spec: Any,
    t_end: float,
    pressures: dict[str, tuple[list[float], list[float]]],
    torque: float,
    zeta: float,
) -> Scenario:
    zero = Profile(np.array([0.0]), np.array([0.0]))
    return Scenario(
        name=f"drive shift {spec.name}",
        file=f"<drive shift {spec.name}>",
        shift=spec,
        t_end=t_end,
        vehicle_speed=0.0,
        engine=Profile(np.array([0.0]), np.array([torque])),
        e_machine=zero,
        pressure={
            e: Profile(np.array(t, dtype=float), np.array(v, dtype=float))
            for e, (t, v) in pressures.items()
        },
        grade=Profile(np.array([0.0]), np.array([zeta])),
    )
