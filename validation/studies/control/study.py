"""The adaptive-control study: each vehicle of a fleet shifts the same shift ``n`` times in a
row from the same operating point, once per strategy; every shift's quality is measured on the
truth's record (:mod:`.quality`).

The vehicle is the fleet's draw (:mod:`gearsym.validation.sim.fleet`): its mass, grade,
inertias, stiffness, μ factors (the "μ reset": the fleet's ``mu_scale`` ±20 %), engine and
e-machine torque errors, valve gain and offset and fill-time error
(:class:`~gearsym.validation.sim.actuator.ClutchActuator`). The TCU knows the calibration
(the description) and what it measured; the strategies learn from that, the oracle is told the
truth.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.ratios import gear_ratio
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.sim.actuator import ClutchActuator
from gearsym.validation.sim.drive_log import TcuLog
from gearsym.validation.sim.fleet import Actuators, FleetDraw, mu_scales, truth_description
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import Scenario
from gearsym.validation.studies.control.closed_loop import (
    TICK,
    ClosedLoopResult,
    ClosedLoopShift,
    output_torque,
)
from gearsym.validation.studies.control.controller import (
    Knowledge,
    ShiftController,
    TargetSlip,
    shift_direction,
    torque_drives_the_shift,
)
from gearsym.validation.studies.control.downshift import DownshiftController
from gearsym.validation.studies.control.observed import Observed, observe_shift
from gearsym.validation.studies.control.quality import (
    INERTIA_FRACTION,
    ShiftQuality,
    shift_quality,
)
from gearsym.validation.studies.control.strategies import STRATEGIES, TruthView, make_strategy

__all__ = ["OperatingPoint", "ShiftOutcome", "Vehicle", "make_controller", "run_vehicle"]

#: The slip (rad/s) at which the recorded inertia phase ends: the plant's lock-up sets it to 0.
RECORDED_LOCKUP = 0.1
#: Duration of each simulated shift (s): fill, torque phase, inertia phase, lock-up and the
#: to-gear after it.
SHIFT_DURATION = 1.2


def make_controller(
    d: GearboxDescription, model: HybridSimulator, knowledge: Knowledge, torque: float
) -> ShiftController:
    """The controller whose phases fit the shift at the commanded input ``torque`` (N·m):
    :class:`.downshift.DownshiftController` for one the torque drives (a power-on downshift,
    a coast upshift: :func:`.controller.torque_drives_the_shift`), else
    :class:`.controller.ShiftController` (a power-on upshift, a coast downshift)."""
    if torque_drives_the_shift(d, model.hybrid.spec, torque):
        return DownshiftController(d, model, knowledge)
    return ShiftController(d, model, knowledge)


@dataclass(frozen=True)
class OperatingPoint:
    """Where each shift of the sequence starts: vehicle speed (m/s) and the commanded engine
    and e-machine torques (N·m), held over the shift."""

    vehicle_speed: float
    engine: float
    e_machine: float

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> OperatingPoint:
        return cls(scenario.vehicle_speed, scenario.engine(0.0), scenario.e_machine(0.0))

    @property
    def torque(self) -> float:
        return self.engine + self.e_machine


@dataclass(frozen=True)
class Vehicle:
    """One fleet draw as the truth: its description, μ factors, engine/valve errors and fill
    time error."""

    description: GearboxDescription
    mu_scale: dict[str, float]
    actuators: Actuators
    fill_time_error: float
    draw: FleetDraw | None = None

    @classmethod
    def from_draw(cls, d: GearboxDescription, draw: FleetDraw) -> Vehicle:
        return cls(
            truth_description(d, draw),
            mu_scales(d, draw),
            Actuators.from_draw(draw),
            draw.get("fill_time_error", 0.0),
            draw,
        )


@dataclass(frozen=True)
class ShiftOutcome:
    """One shift of a sequence: its index (1-based), the strategy's knowledge before it, its
    quality and whether it ended locked in the to-gear."""

    index: int
    knowledge: dict[str, Any]
    quality: ShiftQuality
    completed: bool
    record: ClosedLoopResult | None = field(default=None, compare=False)
    #: the estimator's (mean, σ) per estimated parameter after the shift (estimator only)
    learned: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: the TCU's own verdict, what the strategy learned from (:mod:`.observed`)
    observed: Observed | None = None
    #: the fill estimate the strategy made of this shift (estimator only,
    #: :class:`.fill_estimate.FillEstimate` as a dict)
    fill: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "shift": self.index,
            "completed": self.completed,
            "knowledge": self.knowledge,
            "learned": {k: {"mean": m, "sigma": s} for k, (m, s) in self.learned.items()},
            "observed": None if self.observed is None else self.observed.to_dict(),
            "fill": self.fill,
            **self.quality.to_dict(),
        }


def run_vehicle(
    d: GearboxDescription,
    shift: str,
    point: OperatingPoint,
    vehicle: Vehicle,
    n_shifts: int,
    strategies: Sequence[str] = STRATEGIES,
    seed: int = 0,
    keep_records: bool = False,
    reuse: bool = True,
) -> dict[str, list[ShiftOutcome]]:
    """Every strategy's ``n_shifts`` consecutive shifts ``shift`` on ``vehicle`` (module
    docstring); ``seed`` draws the estimator's sensor noise. With ``reuse`` a shift whose
    knowledge a strategy already shifted with on this vehicle is not simulated again (the
    plant, the actuators and the operating point are the same every shift, so is the
    record: the fixed calibration and the oracle simulate one shift, not ``n_shifts``)."""
    spec = shift_spec(d, shift)
    off, on = spec.off_going, spec.on_coming
    truth = vehicle.description
    plant = ClosedLoopShift(truth, shift, point.vehicle_speed, vehicle.mu_scale)
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, shift))
    nominal = ClutchActuator.from_calibration(d.control)
    true = ClutchActuator.from_calibration(d.control, vehicle.actuators, vehicle.fill_time_error)
    actuators = {off: true, on: true}
    true_torque = float(
        vehicle.actuators.engine(point.engine) + vehicle.actuators.e_machine(point.e_machine)
    )
    mu_nominal = quantity(d, "friction", "mu_nominal").value
    elements = tuple(model.hybrid.friction_elements)
    view = TruthView(
        mu={e: mu_nominal * vehicle.mu_scale.get(e, 1.0) for e in elements},
        m_veh=plant.values["m_veh"],
        zeta=plant.values[naming.GRADE],
        torque_gain=true_torque / point.torque,
        valve_gain=true.pressure_gain,
        valve_offset=true.pressure_offset,
        # what the fill command must last: the vehicle's piston through its own valve (a valve
        # offset strokes it faster or slower than its fill time at the nominal fast fill)
        fill_time=true.stroke_time(nominal.fast_fill_pressure),
    )
    ratio = {g: float(gear_ratio(d, d.gear(g)).ratio) for g in (spec.from_gear, spec.to_gear)}
    gears = (spec.from_gear, spec.to_gear)
    shafts = [s.name for s in d.shafts]
    friction_elements = [e.name for e in d.shift_elements if not e.one_way]
    # the TCU's tie-up test reads the torque phase of a power-on upshift only (observed.py)
    power_on_upshift = shift_direction(d, spec) == "up" and point.torque > 0
    out: dict[str, list[ShiftOutcome]] = {}
    for name in strategies:
        strategy = make_strategy(name, d, elements, view, shift, gears, seed)
        outcomes = []
        simulated: dict[str, tuple[ClosedLoopResult, TcuLog, ShiftQuality, Observed]] = {}
        for i in range(1, n_shifts + 1):
            knowledge = strategy.knowledge
            key = json.dumps(knowledge.to_dict(), sort_keys=True)
            if reuse and key in simulated:
                result, log, quality, observed = simulated[key]
            else:
                # the TCU's view of its pistons: the calibration's, or the fill time it has
                # learned
                belief = (
                    nominal
                    if knowledge.fill_time is None
                    else replace(nominal, fill_time=knowledge.fill_time)
                )
                believed = {off: belief, on: belief}
                controller = make_controller(d, model, knowledge, point.torque)
                log = TcuLog(TICK, shafts, friction_elements)
                result = plant.run(
                    controller,
                    point.torque,
                    true_torque,
                    actuators,
                    believed,
                    log,
                    t_end=SHIFT_DURATION,
                )
                quality = evaluate(
                    d, truth, result, plant.values, ratio[spec.to_gear] / ratio[spec.from_gear]
                )
                arrays = log.arrays()
                observed = observe_shift(d, model, arrays, result.phases, power_on_upshift)
                simulated[key] = (result, log, quality, observed)
            strategy.learn(observed, log, result.commands, result.phases)
            fills = getattr(strategy, "fills", [])
            outcomes.append(
                ShiftOutcome(
                    i,
                    knowledge.to_dict(),
                    quality,
                    result.completed,
                    result if keep_records else None,
                    dict(strategy.learned),
                    observed,
                    fills[-1].to_dict() if fills and fills[-1] is not None else None,
                )
            )
        out[name] = outcomes
    return out


def measured_target(d: GearboxDescription) -> float:
    """The inertia phase's target duration as a record measures it: from the slip's first
    fall by :data:`~.quality.INERTIA_FRACTION` of its start value to lock-up, on the
    controller's target trajectory (its ramp-in makes the first 2 % take a while)."""
    target = TargetSlip(1.0, d.control.si("shift", "inertia_phase"))
    return target.duration - target.time_at(1.0 - INERTIA_FRACTION)


def evaluate(
    d: GearboxDescription,
    truth: GearboxDescription,
    result: ClosedLoopResult,
    values: dict[str, float],
    step: float,
) -> ShiftQuality:
    """The quality of one recorded shift (:func:`.quality.shift_quality`): the vehicle speed
    from the wheel, the on-coming and off-going slips, the output torque against the
    from-gear's steady value (the record's first sample) and the to-gear's (that times the
    ratio step, ``step`` = i_to / i_from), each swapping element's friction heat; the tie-up is
    looked for in the torque phase only (after it the output torque rises with the inertia
    torque of a power-on upshift)."""
    spec = result.spec
    r_dyn = quantity(truth, "vehicle", "r_dyn").value
    signals = result.signals
    v = signals[naming.WHEEL_SPEED] * r_dyn
    torque = output_torque(truth, values, signals)
    phase = np.repeat(np.array(result.phases), int(round(TICK / (result.t[1] - result.t[0]))))
    phase = phase[: len(result.t)]
    window = torque[phase == "torque"] if np.any(phase == "torque") else torque[:1]
    friction = {
        e: (signals[naming.torque(e)], signals[naming.slip_column(e)])
        for e in (spec.off_going, spec.on_coming)
    }
    return shift_quality(
        result.t,
        v,
        signals[naming.slip_column(spec.on_coming)],
        signals[naming.slip_column(spec.off_going)],
        window,
        float(torque[0]),
        float(torque[0]) * step,
        friction,
        measured_target(d),
        RECORDED_LOCKUP,
        off_torque=signals[naming.torque(spec.off_going)],
    )
