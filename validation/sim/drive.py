"""A whole drive: every shift of a driving cycle in one continuous simulation (``gearsym drive``).

The vehicle starts at rest in the lowest forward gear. Between shifts the engaged gear is the
hybrid shift model's gear mode (:mod:`gearsym.symbolic.hybrid`: every element of the gear
locked, 2.55–2.58, the elastic drivetrain 2.42–2.50) driven by the driver and the torque split
of :mod:`gearsym.validation.sim.drive_powertrain` in continuous time, integrated between the
cycle's points with the shift schedule's thresholds as terminal events: by default as one
compiled closed loop over the TCU's ticks (:mod:`gearsym.validation.sim.drive_fast`), with
``run(reference=True)`` by SciPy's ``solve_ivp``, the reference the fast drive is checked
against. A shift runs through the hybrid simulation of that shift
(:class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator`, every mode switch an
event) with the TCU's open-loop shift plan (:mod:`gearsym.validation.sim.drive_shift`); the
state is carried across by the shaft speeds, the twist and the wheel speed. The service brake
is a torque at the wheel (2.45): I_C^eff ω̇_C = 2 T_ss − T_res − T_brake.

At standstill (the cycle stands still and the vehicle is slower than
:data:`STANDSTILL_SPEED`) the brake holds the vehicle: the state is set to rest and the kinetic
energy left is counted as brake work.

The energy audit closes over the whole drive: W_in = ΔE_kin + ΔE_spring + W_friction +
W_damper + W_road + W_brake, every work integrated along the solution (the gear segments carry
the works as quadrature states; the shifts use
:func:`~gearsym.validation.sim.hybrid_energy.energy_audit`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drive_calibration import check_hysteresis
from gearsym.symbolic.drivetrain import (
    adjacent_shifts,
    drivetrain_parts,
    element_short_name,
    quantity,
)
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.numeric import to_casadi
from gearsym.symbolic.ratios import gear_ratio
from gearsym.validation.sim.cycles import Cycle, GradeProfile
from gearsym.validation.sim.drive_fast import (
    FastGearLoop,
    integrate_segment,
    log_segment,
    records_of,
    segment_grid,
)
from gearsym.validation.sim.drive_log import TcuLog
from gearsym.validation.sim.drive_powertrain import Powertrain, TorqueSplit
from gearsym.validation.sim.drive_result import DriveResult, Works
from gearsym.validation.sim.drive_schedule import blended_split, due_shift
from gearsym.validation.sim.drive_shift import (
    BRAKE_SPEED,
    ShiftRecord,
    ShiftRunner,
    state_from_speeds,
)
from gearsym.validation.sim.fleet import Actuators, FleetDraw, mu_scales, truth_description
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from scipy.integrate import solve_ivp

__all__ = ["DriveResult", "DriveSimulator", "DriveTruth", "simulate_drive"]

#: Below this speed (m/s) with the cycle at rest, the brake holds the vehicle.
STANDSTILL_SPEED = 0.3

#: Least time in a gear before the schedule may shift again (s): a driver's pedal moves
#: faster than a TCU lets the gear follow (assumed, production schedules: 0.5-2 s).
MIN_DWELL = 1.0

#: Spacing of the recorded samples (s).
RECORD_STEP = 0.1


@dataclass(frozen=True)
class DriveTruth:
    """The vehicle a drive drives, apart from what its TCU knows (the calibration): its
    description (mass, grade, tolerances, inertias), what its engine, machine and valves
    really give (:class:`~gearsym.validation.sim.fleet.Actuators`) and the factor on each
    element's μ map. ``None`` in :class:`DriveSimulator`: the calibration is the truth."""

    description: GearboxDescription
    actuators: Actuators = field(default_factory=Actuators)
    mu_scale: Mapping[str, float] = field(default_factory=dict)
    draw: FleetDraw | None = None

    @classmethod
    def from_draw(
        cls, d: GearboxDescription, draw: FleetDraw, constant_grade: bool = True
    ) -> DriveTruth:
        """A fleet's vehicle ``draw`` (its grade constant over the drive unless a grade
        profile is driven)."""
        return cls(
            truth_description(d, draw, constant_grade),
            Actuators.from_draw(draw),
            mu_scales(d, draw),
            draw,
        )


class DriveSimulator:
    """A drive of one vehicle along a cycle (module docstring). ``d`` is the calibration: the
    TCU's driver model, torque split, schedule and shift plans; ``truth`` the vehicle driven
    (default: the calibration's own). ``tcu_sample``: the sample time of the TCU's log.
    ``planners``: the calibration's shift models (:meth:`planner`) kept by the caller for
    the drives of other vehicles with the same calibration (a fleet's worker builds them
    once), filled here as the drive needs them."""

    def __init__(
        self,
        d: GearboxDescription,
        cycle: Cycle,
        grade: GradeProfile | None = None,
        truth: DriveTruth | None = None,
        progress: Callable[[float], None] | None = None,
        tcu_sample: float = 0.01,
        planners: dict[tuple[str, str], ShiftRunner] | None = None,
    ) -> None:
        self.d = d
        self.truth = truth if truth is not None else DriveTruth(d)
        self.tcu_sample = tcu_sample
        self.cycle = cycle
        self.grade = grade
        self.progress = progress
        specs = adjacent_shifts(d)
        double = [s.name for s in specs if not s.single]
        if double:
            raise GearsymError(
                d.file,
                "gears",
                f"a drive shifts single swaps only; {', '.join(double)} swaps two elements",
            )
        if not specs:
            raise GearsymError(d.file, "gears", "a drive needs at least two forward gears")
        for spec in specs:
            for e in (spec.off_going, spec.on_coming):
                element = d.element(e)
                if element.one_way or element.dog or element.a_piston is None:
                    what = (
                        "a one-way clutch"
                        if element.one_way
                        else "a dog element"
                        if element.dog
                        else "without a_piston"
                    )
                    raise GearsymError(
                        d.file,
                        f'shift_element[name="{e}"]',
                        f"the drive's shift plans swap friction elements with a piston; {e} "
                        f"({what}) swaps in the {spec.name} shift",
                    )
        self.gears = (specs[0].from_gear, *(s.to_gear for s in specs))
        self.ratios = tuple(float(gear_ratio(d, d.gear(g)).ratio) for g in self.gears)
        check_hysteresis(
            d.drive.file or d.file,
            d.drive.schedule,
            [
                (a, b, ra / rb)
                for a, b, ra, rb in zip(
                    self.gears[:-1], self.gears[1:], self.ratios[:-1], self.ratios[1:], strict=True
                )
            ],
        )
        # the plant is the truth's; the TCU plans its shifts on the calibration's models. Each
        # shift's models are compiled when the drive first needs them.
        plant = self.truth.description
        self._runners: dict[tuple[str, str], ShiftRunner] = {}
        self._planners = {} if planners is None else planners
        self.line = d.drive.si("shift", "line_pressure")
        first = (self.gears[0], self.gears[1])
        self.values = self._values(plant, self.runner(first), self.truth.mu_scale)
        self.calibration_values = self._values(d, self.planner(first), {})
        mass = d.estimator.prior_of("m_veh", self.calibration_values["m_veh"])[0]
        self.calibration_values["m_veh"] = mass
        self.powertrain = Powertrain(d, mass)
        self.r_dyn = quantity(plant, "vehicle", "r_dyn").value
        self.zeta0 = self.values[naming.GRADE]
        self._gear_model: dict[int, tuple[HybridSimulator, str, Any]] = {}
        self._wheel_parts = drivetrain_parts(plant)
        self._fast: dict[int, tuple[FastGearLoop, np.ndarray]] = {}

    def runner(self, pair: tuple[str, str]) -> ShiftRunner:
        """The truth's hybrid model of the shift ``pair`` (compiled on first use)."""
        if pair not in self._runners:
            self._runners[pair] = ShiftRunner(self.truth.description, "-".join(pair))
        return self._runners[pair]

    def planner(self, pair: tuple[str, str]) -> ShiftRunner:
        """The calibration's model of the shift ``pair``, which the TCU plans with."""
        if self.truth.description is self.d:
            return self.runner(pair)
        if pair not in self._planners:
            self._planners[pair] = ShiftRunner(self.d, "-".join(pair))
        return self._planners[pair]

    @staticmethod
    def _values(
        d: GearboxDescription, runner: ShiftRunner, mu_scale: Mapping[str, float]
    ) -> dict[str, float]:
        """Every parameter of every shift's hybrid model by name: the vehicle's and the
        drivetrain's (the same in every shift) and each friction element's μ (the
        description's nominal μ, 2.69) times its map factor."""
        values = runner.simulator.values()
        mu = quantity(d, "friction", "mu_nominal").value
        for e in d.shift_elements:
            if e.one_way or e.n_disc is None or e.r_m is None:
                continue
            name = naming.friction_coefficient(element_short_name(d, e.name))
            values[name] = mu * mu_scale.get(e.name, 1.0)
        return values

    def parameters_of(self, sim: HybridSimulator, values: Mapping[str, float]) -> np.ndarray:
        """``values`` in the order of ``sim``'s parameter vector."""
        return np.array([values[name] for name in sim.parameter_names], dtype=float)

    # ------------------------------------------------------------------ gear models

    def gear_model(self, k: int) -> tuple[HybridSimulator, str, Any]:
        """(simulator, mode, functions) of gear ``k`` (index into ``gears``): the from-mode of
        the upshift out of it (the to-mode of the last upshift for the top gear)."""
        if k not in self._gear_model:
            if k + 1 < len(self.gears):
                runner = self.runner((self.gears[k], self.gears[k + 1]))
                mode = runner.simulator.hybrid.from_mode
            else:
                runner = self.runner((self.gears[k - 1], self.gears[k]))
                mode = runner.simulator.hybrid.to_mode
            sim = runner.simulator
            compiled = sim.modes[mode]
            import casadi as ca

            wheel = to_casadi(self._wheel_parts.wheel_inertia, compiled.mapping)
            inertia = ca.Function("I_C", [compiled.p], [wheel])
            powers, energies = runner.energy_functions()[mode]
            p = self.parameters_of(sim, self.values)
            line = self.truth.actuators.pressure(np.array([runner.line]))[0]
            # one call per right-hand side: ẋ and the powers together (a CasADi call costs
            # more than the arithmetic of this small model); ω_in is linear in x (ẏ = P z)
            fused = ca.Function(
                "gear",
                [compiled.x, compiled.u, compiled.p],
                [ca.vertcat(compiled.rhs_sx, powers(compiled.x, compiled.u, compiled.p))],
            )
            speeds = sim.shaft_speeds(mode)
            index = [s.name for s in self.d.shafts].index(self.d.input_shaft)
            input_row = np.array(
                [float(speeds(np.eye(compiled.n)[j])[index]) for j in range(compiled.n)]
            )
            self._gear_model[k] = (
                sim,
                mode,
                {
                    "p": p,
                    "inertia": float(inertia(p)),
                    "powers": powers,
                    "energies": energies,
                    "speeds": speeds,
                    "fused": fused,
                    "input_row": input_row,
                    "line": [f * line / runner.line for f in runner.line_forces(mode)],
                    "closed": self.d.gear(self.gears[k]).closed,
                },
            )
        return self._gear_model[k]

    # ------------------------------------------------------------------ the drive

    def run(self, rtol: float = 1e-7, atol: float = 1e-8, reference: bool = False) -> DriveResult:
        """Drive the cycle from rest in the lowest gear (module docstring). The gear segments
        run as :mod:`~gearsym.validation.sim.drive_fast`'s compiled closed loop; with
        ``reference`` as the Python reference (``solve_ivp`` RK45 at ``rtol``, ``atol``, a
        Python call per right-hand side), which the fast drive is checked against."""
        started = time.perf_counter()
        cycle = self.cycle
        knots = [float(t) for t in cycle.t]
        t = 0.0
        k = 0
        sim, mode, fns = self.gear_model(0)
        x = np.zeros(sim.modes[mode].n)
        integral = 0.0
        distance = 0.0
        works = Works()
        records: list[dict[str, float]] = []
        shifts: list[ShiftRecord] = []
        last_shift = -math.inf
        failure = ""
        names = [v.name for v in sim.hybrid.modes[mode].model.states]
        wheel = names.index(naming.WHEEL_SPEED)
        e_start = self._energies(k, x)
        segments = 0
        log = TcuLog(
            self.tcu_sample,
            [sh.name for sh in self.d.shafts],
            [e.name for e in self.d.shift_elements if not e.one_way],
        )
        while t < knots[-1] - 1e-9 and not failure:
            sim, mode, fns = self.gear_model(k)
            compiled = sim.modes[mode]
            n = compiled.n
            t_next = knots[int(np.searchsorted(knots, t, side="right"))]
            v_now = x[wheel] * self.r_dyn
            if float(cycle.speed(t)) == 0.0 and float(cycle.speed(t_next)) == 0.0:
                if v_now < STANDSTILL_SPEED:
                    # the brake holds the vehicle: what kinetic and spring energy is left goes
                    # into the brake
                    energy = self._energies(k, x)
                    works.brake += float(energy.sum())
                    x = np.zeros(n)
                    integral = 0.0
                    if k != 0:
                        k = 0  # stopped: the TCU has shifted down to the lowest gear
                        first_sim, first_mode, _ = self.gear_model(0)
                        x = np.zeros(first_sim.modes[first_mode].n)
                    self._record_rest(records, t, t_next, k, distance)
                    self._log_rest(log, t, t_next, k, distance)
                    t = t_next
                    continue
            segment = _GearSegment(self, k, fns, compiled)
            events: list[Any] = []
            if t - last_shift >= MIN_DWELL:
                if k + 1 < len(self.gears):
                    events.append(segment.upshift)
                if k > 0:
                    events.append(segment.downshift)
            t_stop = t_next
            if t - last_shift < MIN_DWELL:
                t_stop = min(t_next, last_shift + MIN_DWELL)
            y0 = np.concatenate([x, [integral, distance], np.zeros(5)])
            segments += 1
            # a threshold already passed shifts now (drive_schedule); the events below see
            # crossings inside the segment only
            due = due_shift(segment, t, y0, [e.__name__ for e in events])
            if due:
                fired_name, t_end, y = due, t, y0
            elif reference:
                sol = solve_ivp(
                    segment.rhs,
                    (t, t_stop),
                    y0,
                    method="RK45",
                    rtol=rtol,
                    atol=atol,
                    events=events or None,
                    dense_output=True,
                )
                if sol.status == -1:
                    failure = f"integration failed at t = {sol.t[-1]:.3f} s in gear {self.gears[k]}"
                    break
                t_end = float(sol.t[-1])
                if sol.status == 1 and abs(t_end - t_stop) < 1e-9:
                    # a threshold that jumps at a point of the cycle (a_ref steps there, so
                    # the pedal) is crossed at that point; SciPy's root search ends within a
                    # few machine epsilons on either side of it, and the side decides which
                    # a_ref the shift's held torque reads: the point itself, after the jump
                    t_end = t_stop
                self._record_dense(records, t, t_end, sol, segment.control, n, k, wheel)
                self._log_gear(log, t, t_end, sol, segment, k)
                y = sol.y[:, -1]
                fired_name = (
                    events[next(i for i, times in enumerate(sol.t_events) if len(times))].__name__
                    if sol.status == 1
                    else ""
                )
            else:
                t_end, y, fired_name = self._fast_segment(
                    k, t, t_stop, y0, segment, [e.__name__ for e in events], records, log
                )
                if not np.all(np.isfinite(y)):
                    # fixed steps have no error control to fail: a state that is no longer
                    # finite is the fast drive's integration failure
                    failure = f"integration failed by t = {t_end:.3f} s in gear {self.gears[k]}"
                    break
            x, integral, distance = y[:n], y[n], y[n + 1]
            works.input += y[n + 2]
            works.friction += y[n + 3]
            works.damper += y[n + 4]
            works.road += y[n + 5]
            works.brake += y[n + 6]
            t = t_end
            if self.progress is not None:
                self.progress(t)
            if not fired_name:
                continue
            name = fired_name
            target = k + 1 if name == "upshift" else k - 1
            split, omega_in = segment.control(t, y)
            split = blended_split(split, name, self.powertrain.i_d * self.ratios[k])
            pair = (self.gears[k], self.gears[target])
            runner, planner = self.runner(pair), self.planner(pair)
            outcome = runner.run(
                t_start=t,
                speeds=np.asarray(fns["speeds"](x)).ravel(),
                phi=x[names.index(naming.TWIST)],
                omega_c=x[wheel],
                split=split,
                true_torque=self.true_torque(split, omega_in),
                p=self.parameters_of(runner.simulator, self.values),
                zeta=self._zeta(distance) - self.zeta0,
                planner=planner,
                calibration=self.parameters_of(planner.simulator, self.calibration_values),
                actuators=self.truth.actuators,
                kind=name,
                wheel_inertia=fns["inertia"],
                v_ref=cycle.speed,
                distance_start=distance,
                log=log,
                gear=k,
                zeta_true=self._zeta(distance),
                fast=not reference,
            )
            shifts.append(outcome.record)
            works.input += outcome.audit.input_work
            works.friction += outcome.audit.friction_dissipation
            works.damper += outcome.audit.damper_dissipation
            works.road += outcome.audit.road_work
            works.brake += outcome.brake_work
            distance += outcome.distance
            for row in outcome.samples:
                records.append(row | {"gear": float(k if row["t"] < outcome.t_end else target)})
            if outcome.failure:
                failure = outcome.failure
                break
            k = target
            sim, mode, fns = self.gear_model(k)
            x = self._state_from(k, outcome.speeds, outcome.phi, outcome.omega_c)
            t = outcome.t_end
            last_shift = t
        # the stored energies at the ends (the hand-overs between gear and shift models keep
        # the physical speeds, so they keep the energy; the audit's residual would show if not)
        e_end = self._energies(k, x)
        works.kinetic = float(e_end[0] - e_start[0])
        works.spring = float(e_end[1] - e_start[1])
        samples = _samples(records)
        return DriveResult(
            cycle=cycle,
            gears=self.gears,
            samples=samples,
            shifts=shifts,
            works=works,
            wall_s=time.perf_counter() - started,
            values=self.values,
            failure=failure,
            stats={"gear_segments": float(segments), "reference": float(reference)},
            log=log,
        )

    # ------------------------------------------------------------------ helpers

    def fast_loop(self, k: int) -> tuple[FastGearLoop, np.ndarray]:
        """Gear ``k``'s closed loop compiled for the fast drive, and its matrix x → every
        shaft's speed (linear, ẏ = P z)."""
        if k not in self._fast:
            sim, mode, fns = self.gear_model(k)
            compiled = sim.modes[mode]
            names = [v.name for v in compiled.mode.model.states]
            loop = FastGearLoop(
                fused=fns["fused"],
                n=compiled.n,
                wheel=names.index(naming.WHEEL_SPEED),
                input_row=fns["input_row"],
                p=fns["p"],
                line=fns["line"],
                wheel_inertia=fns["inertia"],
                powertrain=self.powertrain,
                ratio=self.ratios[k],
                schedule=self.d.drive.schedule,
                actuators=self.truth.actuators,
                r_dyn=self.r_dyn,
                brake_speed=BRAKE_SPEED,
                zeta0=self.zeta0,
                grade=self.grade,
            )
            speeds = np.column_stack(
                [np.asarray(fns["speeds"](column)).ravel() for column in np.eye(compiled.n)]
            )
            self._fast[k] = (loop, speeds)
        return self._fast[k]

    def _fast_segment(
        self,
        k: int,
        t0: float,
        t1: float,
        y0: np.ndarray,
        segment: _GearSegment,
        events: list[str],
        records: list[dict[str, float]],
        log: TcuLog,
    ) -> tuple[float, np.ndarray, str]:
        """The gear segment [t0, t1] by the fast loop, its records and log samples; returns
        (end time, end state, the event that ended it or "")."""
        loop, speeds = self.fast_loop(k)
        samples = np.arange(_first_sample(t0), t1, RECORD_STEP)
        grid = segment_grid(t0, t1, [log.ticks(t0, t1), samples])
        done = integrate_segment(
            loop, self.cycle, grid, y0, "upshift" in events, "downshift" in events
        )
        n = segment.n
        samples = samples[samples < done.t_end]
        records += records_of(done, samples, self.cycle, k, segment.wheel, n, self.r_dyn)
        names = [v.name for v in segment.compiled.mode.model.states]
        pressures = {e: self.line for e in segment.fns["closed"]}
        log_segment(
            log,
            done,
            log.ticks(t0, done.t_end),
            speeds,
            names.index(naming.TWIST),
            segment.wheel,
            pressures,
            k,
        )
        return done.t_end, done.y_end, done.event

    def _inputs(self, fns: dict[str, Any], torque: float, distance: float) -> np.ndarray:
        line = fns["line"]
        return np.array([torque, *line, self._zeta(distance) - self.zeta0])

    def _zeta(self, distance: float) -> float:
        return self.zeta0 if self.grade is None else self.grade.zeta(distance)

    def true_torque(self, split: TorqueSplit, omega_in: float) -> float:
        """The input torque the vehicle's engine and machine really give for the commanded
        split (the engine only while it is coupled, at idle speed or above)."""
        actuators = self.truth.actuators
        engine = actuators.engine(split.engine) if self.powertrain.coupled(omega_in) else 0.0
        return float(engine + actuators.e_machine(split.e_machine))

    def _log_gear(self, log: TcuLog, t0: float, t1: float, sol: Any, segment: Any, k: int) -> None:
        """The TCU's samples of a gear segment from the dense output."""
        fns, n = segment.fns, segment.n
        line = self.line
        pressures = {e: line for e in fns["closed"]}
        names = [v.name for v in segment.compiled.mode.model.states]
        twist, wheel = names.index(naming.TWIST), names.index(naming.WHEEL_SPEED)
        for t in log.ticks(t0, t1):
            y = sol.sol(t)
            split, _ = segment.control(float(t), y)
            speeds = np.asarray(fns["speeds"](y[:n])).ravel()
            log.add(
                t,
                speeds,
                y[twist],
                y[wheel],
                split.input_torque,
                split.brake,
                pressures,
                k,
                "",
                {},
                self._zeta(float(y[n + 1])),
                split.engine,
            )

    def _log_rest(self, log: TcuLog, t0: float, t1: float, k: int, distance: float) -> None:
        sim, mode, fns = self.gear_model(k)
        line = self.line
        for t in log.ticks(t0, t1):
            log.add(
                t,
                np.zeros(len(self.d.shafts)),
                0.0,
                0.0,
                0.0,
                0.0,
                {e: line for e in fns["closed"]},
                k,
                "",
                {},
                self._zeta(distance),
                0.0,
            )

    def _energies(self, k: int, x: np.ndarray) -> np.ndarray:
        _, _, fns = self.gear_model(k)
        return np.asarray(fns["energies"](x, fns["p"])).ravel()

    def _state_from(self, k: int, speeds: np.ndarray, phi: float, omega_c: float) -> np.ndarray:
        sim, mode, fns = self.gear_model(k)
        return state_from_speeds(sim, mode, speeds, phi, omega_c)

    def _record_rest(
        self, records: list[dict[str, float]], t0: float, t1: float, k: int, distance: float
    ) -> None:
        for t in np.arange(_first_sample(t0), t1, RECORD_STEP):
            records.append(
                {
                    "t": float(t),
                    "v_ref": float(self.cycle.speed(t)),
                    "v": 0.0,
                    "gear": float(k),
                    "T_engine": 0.0,
                    "T_e_machine": 0.0,
                    "T_brake": 0.0,
                    "pedal": 0.0,
                    "omega_in": 0.0,
                    "s": distance,
                }
            )

    def _record_dense(
        self,
        records: list[dict[str, float]],
        t0: float,
        t1: float,
        sol: Any,
        control: Callable[[float, np.ndarray], tuple[Any, float]],
        n: int,
        k: int,
        wheel: int,
    ) -> None:
        for t in np.arange(_first_sample(t0), t1, RECORD_STEP):
            y = sol.sol(t)
            split, omega_in = control(float(t), y)
            records.append(
                {
                    "t": float(t),
                    "v_ref": float(self.cycle.speed(t)),
                    "v": float(y[wheel] * self.r_dyn),
                    "gear": float(k),
                    "T_engine": split.engine,
                    "T_e_machine": split.e_machine,
                    "T_brake": split.brake,
                    "pedal": split.pedal,
                    "omega_in": omega_in,
                    "s": float(y[n + 1]),
                }
            )


class _GearSegment:
    """The closed loop in one gear: driver, torque split, brake, the gear mode's right-hand side
    with the works as quadrature states, and the shift schedule's thresholds as events."""

    def __init__(self, drive: DriveSimulator, k: int, fns: dict[str, Any], compiled: Any) -> None:
        self.drive = drive
        self.fns = fns
        self.compiled = compiled
        self.n = compiled.n
        self.ratio = drive.ratios[k]
        names = [v.name for v in compiled.mode.model.states]
        self.wheel = names.index(naming.WHEEL_SPEED)
        self.input_index = [s.name for s in drive.d.shafts].index(drive.d.input_shaft)
        self.schedule = drive.d.drive.schedule

    def control(self, t: float, y: np.ndarray) -> tuple[Any, float]:
        """(torque split, ω_in) at the state y = [x, ∫(v_ref − v), s, works]."""
        drive = self.drive
        x = y[: self.n]
        omega_in = float(self.fns["input_row"] @ x)
        v = x[self.wheel] * drive.r_dyn
        force = drive.powertrain.wheel_force(
            float(drive.cycle.speed(t)), drive.cycle.acceleration(t), v, y[self.n]
        )
        return drive.powertrain.split(force, self.ratio, omega_in), omega_in

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        drive, n = self.drive, self.n
        x = y[:n]
        split, omega_in = self.control(t, y)
        u = drive._inputs(self.fns, drive.true_torque(split, omega_in), y[n + 1])
        both = np.asarray(self.fns["fused"](x, u, self.fns["p"])).ravel()
        xdot, powers = both[:n], both[n:]
        omega_c = x[self.wheel]
        brake = split.brake * math.tanh(omega_c / BRAKE_SPEED)
        xdot[self.wheel] -= brake / self.fns["inertia"]
        v = omega_c * drive.r_dyn
        return np.concatenate(
            [xdot, [float(drive.cycle.speed(t)) - v, v], powers, [brake * omega_c]]
        )

    def upshift(self, t: float, y: np.ndarray) -> float:
        split, omega_in = self.control(t, y)
        return omega_in - self.schedule.up(split.pedal)

    def downshift(self, t: float, y: np.ndarray) -> float:
        split, omega_in = self.control(t, y)
        return omega_in - self.schedule.down(split.pedal)


# solve_ivp reads an event's ``terminal`` and ``direction`` from the function: the schedule's
# thresholds stop the gear segment when the input speed rises through the upshift speed or
# falls through the downshift speed
_GearSegment.upshift.terminal = True  # type: ignore[attr-defined]
_GearSegment.upshift.direction = 1  # type: ignore[attr-defined]
_GearSegment.downshift.terminal = True  # type: ignore[attr-defined]
_GearSegment.downshift.direction = -1  # type: ignore[attr-defined]


def _first_sample(t0: float) -> float:
    return math.ceil(t0 / RECORD_STEP - 1e-9) * RECORD_STEP


def _samples(records: list[dict[str, float]]) -> dict[str, np.ndarray]:
    records = sorted(records, key=lambda r: r["t"])
    keys = records[0].keys() if records else ()
    return {key: np.array([r[key] for r in records]) for key in keys}


def simulate_drive(
    d: GearboxDescription,
    cycle: Cycle,
    grade: GradeProfile | None = None,
    truth: DriveTruth | None = None,
    progress: Callable[[float], None] | None = None,
) -> DriveResult:
    """Drive ``cycle`` with the calibration ``d`` on the vehicle ``truth`` (default: ``d``'s
    own), module docstring."""
    return DriveSimulator(d, cycle, grade, truth, progress).run()
