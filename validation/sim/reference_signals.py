"""What is recorded of a reference simulation: every signal at every sample (speeds, torques,
pressures, μ, slips, bristles, the works) and the energy audit from the integrated works."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.validation.sim.reference_functions import CompiledReference, ReferenceInputs
from gearsym.validation.sim.scenario import Scenario
from gearsym.validation.sim.simulation_result import EnergyAudit


def reference_signals(
    d: GearboxDescription,
    grid: np.ndarray,
    states: np.ndarray,
    names: Sequence[str],
    inputs: ReferenceInputs,
    compiled: CompiledReference,
    scenario: Scenario,
) -> dict[str, np.ndarray]:
    """Every recorded signal at every sample (vectorised over the samples)."""
    n = compiled.n
    x = states[:, :n]
    u = inputs.many(grid, x)
    xdot = compiled.f.many(x, u)
    index = {name: i for i, name in enumerate(names)}
    out: dict[str, np.ndarray] = {}

    def put(key: str, value: np.ndarray) -> None:
        # two signals under one name would lose one column; check_names prevents it
        if key in out:
            raise AssertionError(f"two signals share the column name {key!r}")
        out[key] = np.asarray(value, dtype=float)

    element_names = [e.name for e in d.shift_elements]
    short = {e: naming.element_short_name(e, element_names) for e in compiled.elements}
    speeds = compiled.speeds.many(x)
    for k, s in enumerate(compiled.shaft_names):
        put(naming.speed(s), speeds[:, k])
    put(naming.TWIST, x[:, index[naming.TWIST]])
    put(naming.WHEEL_SPEED, x[:, index[naming.WHEEL_SPEED]])
    for name in names:
        if name.startswith(naming.speed("")):
            put(naming.derivative(name), xdot[:, index[name]])
    # φ̇ = ω_out/i_D − ω_C (2.44), the side-shaft twist rate Fig. 3.2 shows
    put(naming.derivative(naming.TWIST), xdot[:, index[naming.TWIST]])
    put(naming.INPUT_TORQUE, u[:, 0])
    put(naming.ENGINE_TORQUE, np.array([scenario.engine(float(t)) for t in grid]))
    put(naming.E_MACHINE_TORQUE, np.array([scenario.e_machine(float(t)) for t in grid]))
    torques = compiled.torques.many(x, u)
    ne = len(compiled.elements)
    for k, e in enumerate(compiled.elements):
        area = d.element(e).a_piston
        assert area is not None
        put(naming.pressure(e), u[:, 1 + k])
        put(naming.normal_force(short[e]), u[:, 1 + k] * area.value)
        put(naming.friction_coefficient(short[e]), u[:, 1 + ne + k])
        put(naming.bristle(e), x[:, index[naming.bristle(e)]])
    for e in compiled.one_way:
        put(naming.bristle(e), x[:, index[naming.bristle(e)]])
    slips = compiled.all_slips.many(x)
    for k, e in enumerate(compiled.all_slip_names):
        put(naming.slip_column(e.name), slips[:, k])
        carried = compiled.torque_names
        position = carried.index(e.name) if e.name in carried else None
        zero = np.zeros(len(grid))
        put(naming.torque(e.name), torques[:, position] if position is not None else zero)
    t_ss = compiled.side_shaft.many(x)[:, 0]
    put(naming.SIDE_SHAFT_TORQUE, t_ss)
    put(naming.DRIVETRAIN_OUTPUT_TORQUE, 2 * t_ss / quantity(d, "drivetrain", "i_D").value)
    put(naming.ROAD_TORQUE, compiled.road.many(x, u)[:, 0])
    put(naming.GRADE, u[:, -1])
    w_in, w_out = out[naming.speed(d.input_shaft)], out[naming.speed(d.output_shaft)]
    with np.errstate(divide="ignore", invalid="ignore"):
        put(naming.RATIO, np.where(w_out != 0, w_in / np.where(w_out != 0, w_out, 1.0), math.nan))
    r_dyn = quantity(d, "vehicle", "r_dyn").value
    put(naming.VEHICLE_SPEED, x[:, index[naming.WHEEL_SPEED]] * r_dyn)
    for k, term in enumerate(naming.ENERGY_TERMS):
        put(term, states[:, n + k])
    return out


def reference_energy_audit(
    states: np.ndarray, x0: np.ndarray, compiled: CompiledReference
) -> EnergyAudit:
    """The energy audit from the first and last state: the changes of the kinetic, spring and
    bristle energies, and the input, friction, damper and road works integrated as the states
    after the model's."""
    n = compiled.n
    end = states[-1]
    e0 = np.asarray(compiled.energies(x0), dtype=float)
    e1 = np.asarray(compiled.energies(end[:n]), dtype=float)
    w_in, w_fric, w_damp, w_road = end[n:]
    bristle = e1[2] - e0[2]
    return EnergyAudit(
        input_work=float(w_in),
        kinetic_change=float(e1[0] - e0[0]),
        spring_change=float(e1[1] - e0[1]),
        bristle_change=float(bristle),
        # Σ T_e Δω_e is what the shafts give to the elements; the bristles store part of it.
        friction_dissipation=float(w_fric - bristle),
        damper_dissipation=float(w_damp),
        road_work=float(w_road),
    )
