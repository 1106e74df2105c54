"""The initial state of a reference simulation: the from-gear at the scenario's vehicle speed,
accelerating as one rigid gear, with every slipping element in steady sliding (2.68)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import sympy as sp
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.friction import T_SS_MIN
from gearsym.symbolic.reference import ReferenceModel
from gearsym.validation.sim.reference_functions import CompiledReference, ReferenceInputs


def quasi_static_state(
    d: GearboxDescription, ref: ReferenceModel, inputs: ReferenceInputs, compiled: CompiledReference
) -> np.ndarray:
    """Initial state in the from-gear: speeds at the scenario's vehicle speed, and the bristle
    deflections and side-shaft twist that make the gearbox accelerate as one rigid gear
    (closed elements' slip accelerations zero, φ̈ = 0). The conditions are affine in (z, φ)
    while every slip is zero, so five evaluations of the right-hand side solve them."""
    scenario = inputs.scenario
    gear = d.gear(scenario.shift.from_gear)
    model = ref.model
    names = [v.name for v in model.states]
    r_dyn = quantity(d, "vehicle", "r_dyn").value
    i_d = quantity(d, "drivetrain", "i_D").value
    omega_c = scenario.vehicle_speed / r_dyn
    omega_out = i_d * omega_c
    speeds = _gear_speeds(d, gear.name, omega_out)
    x0 = np.zeros(compiled.n)
    for i, v in enumerate(model.states):
        if v.name.startswith("omega_") and v.name != "omega_C":
            x0[i] = speeds[v.name.removeprefix("omega_")]
    x0[names.index("omega_C")] = omega_c
    closed = [e for e in gear.closed if e in compiled.elements]
    unknowns = [names.index(f"z_{e}") for e in closed] + [names.index("phi")]
    _sliding_bristles(d, x0, names, inputs, closed)
    # d/dt of each closed element's slip and of φ̇ (all linear in the speeds) must vanish
    phi_dot = model.rhs[names.index("phi")]
    rows = np.array(
        [_linear_row(ref.slip[e], model.state_symbols) for e in closed]
        + [_linear_row(phi_dot, model.state_symbols)]
    )

    def residual(values: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[unknowns] = values
        return rows @ np.asarray(compiled.f(x, inputs(0.0, x)), dtype=float)[: compiled.n]

    scale = np.array([1e-3] * len(closed) + [1e-2])
    base = residual(np.zeros(len(unknowns)))
    columns = [
        (residual(scale * np.eye(len(unknowns))[k]) - base) / scale[k] for k in range(len(unknowns))
    ]
    solution = np.linalg.solve(np.column_stack(columns), -base)
    x0[unknowns] = solution
    return x0


def _sliding_bristles(
    d: GearboxDescription,
    x0: np.ndarray,
    names: Sequence[str],
    inputs: ReferenceInputs,
    closed: Sequence[str],
) -> None:
    """Put the bristles of every slipping element at their steady state z_ss sgn(Δω) (2.68):
    a slipping element starts in steady sliding, not with a relaxed bristle (which would
    add σ1 Δω, a huge damping torque, at t = 0)."""
    compiled = inputs.compiled
    sigma0 = quantity(d, "friction", "sigma0").value
    u = inputs(0.0, x0)
    ne = len(compiled.elements)
    slips = compiled.slips(x0)
    for k, e in enumerate(compiled.elements):
        if e in closed:
            continue
        element = d.element(e)
        assert element.n_disc is not None and element.r_m is not None
        assert element.a_piston is not None
        capacity = 2 * element.n_disc * element.r_m.value * u[1 + ne + k]
        capacity = max(capacity * u[1 + k] * element.a_piston.value, T_SS_MIN)
        x0[names.index(f"z_{e}")] = math.copysign(capacity / sigma0, slips[k])


def _gear_speeds(d: GearboxDescription, gear: str, omega_out: float) -> dict[str, float]:
    """Every shaft's speed in a gear at the given output speed (kinematics only; idle shafts
    at the steady speeds of the drag assumption, :func:`gearsym.symbolic.ratios.gear_motion`)."""
    from gearsym.symbolic.drivetrain import drivetrain_parts

    parts = drivetrain_parts(d, locked=tuple(d.gear(gear).closed), keep=(d.output_shaft,))
    if len(parts.speeds) > 1:  # idle shafts kept as states
        from gearsym.symbolic.ratios import gear_motion

        motion = gear_motion(d, d.gear(gear))
        scale = omega_out / float(motion[d.shaft_names.index(d.output_shaft)])
        return {s: float(w) * scale for s, w in zip(d.shaft_names, motion, strict=True)}
    out = parts.speeds[0]
    return {s.name: float(parts.body_speeds[s.name].subs(out, omega_out)) for s in d.shafts}


def _linear_row(expr: sp.Expr, x: Sequence[sp.Symbol]) -> np.ndarray:
    """Coefficients of an expression linear in the states x."""
    return np.array([float(sp.diff(expr, s)) for s in x], dtype=float)
