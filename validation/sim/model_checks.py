"""The reduced models checked against the reference simulation (thesis 3.1): the from- and
to-gear with their elements locked and the shift model (2.55)–(2.58), each integrated inside
the phase where it is valid and compared at the reference's samples."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import drivetrain_model, shift_model
from gearsym.symbolic.model import Model
from gearsym.symbolic.numeric import casadi_function, integrate_linear_inputs
from gearsym.validation.sim.phases import Phase
from gearsym.validation.sim.reference_functions import CompiledReference
from gearsym.validation.sim.scenario import Scenario
from gearsym.validation.sim.simulation_result import ModelCheck


def check_reduced_models(
    d: GearboxDescription,
    scenario: Scenario,
    phases: Sequence[Phase],
    names: Sequence[str],
    grid: np.ndarray,
    states: np.ndarray,
    signals: Mapping[str, np.ndarray],
    compiled: CompiledReference,
) -> tuple[ModelCheck, ...]:
    """Integrate each reduced model inside its phase from the reference state (CVODES, rtol
    1e-10), with the reference's input torque (and, for the shift model, the swapping elements'
    transmitted torques), linear between the reference's samples, and compare the states they
    share at the reference's own samples (no interpolation of the reference states)."""
    spec = scenario.shift
    index = {name: i for i, name in enumerate(names)}
    element_index = {e: k for k, e in enumerate(compiled.elements)}
    n = compiled.n
    speeds = compiled.speeds.many(states[:, :n])

    def reader(name: str) -> np.ndarray:
        if name in ("phi", "omega_C"):
            return states[:, index[name]]
        return speeds[:, compiled.shaft_names.index(name.removeprefix("omega_"))]

    jobs: list[tuple[Model, Phase, list[str]]] = []
    # from-gear, the torque and the speed phase in the order they happened, to-gear
    gear_from, first, second, gear_to = phases
    # The rigid to-gear model is valid once the on-coming element has stuck, not merely
    # synchronised to 1 %: start its check at the first sample where the slip is below
    # 1e-4 of the initial one (about 0.02 rad/s here).
    slip_on = np.abs(compiled.slips.many(states[:, :n])[:, element_index[spec.on_coming]])
    stuck_at = np.flatnonzero((grid >= gear_to.t_start) & (slip_on < 1e-4 * slip_on[0]))
    stuck = float(grid[stuck_at[0]]) if stuck_at.size else gear_to.t_start
    locked_to = Phase(gear_to.name, stuck, gear_to.t_end, f"{spec.on_coming} stuck")
    for gear, phase in ((spec.from_gear, gear_from), (spec.to_gear, locked_to)):
        model = drivetrain_model(
            d,
            f"gear_{gear}",
            locked=tuple(d.gear(gear).closed),
            torque_elements=(),
            keep=(d.output_shaft,),
        )
        jobs.append((model, phase, ["T_In"]))
    shift = shift_model(d, spec.name)
    merged = Phase("shift", first.t_start, second.t_end, f"{first.name} + {second.name}")
    jobs.append(
        (
            shift,
            merged,
            ["T_In", f"T_{spec.off_going}", f"T_{spec.on_coming}"],
        )
    )
    checks = []
    for model, phase, input_signals in jobs:
        if phase.t_end - phase.t_start <= 0:
            continue
        params = model.parameter_defaults()
        # ζ(t) as recorded (the scenario's grade profile, or the constant): a further input
        (zeta,) = (s for s in params if s.name == naming.GRADE)
        del params[zeta]
        rhs = model.rhs.xreplace({k: sp.Float(v) for k, v in params.items()})
        f = casadi_function(
            "reduced",
            [("x", model.state_symbols), ("u", (*model.input_symbols, zeta))],
            [("xdot", rhs)],
        )
        # every sample of the phase: the recorded inputs are linear between samples (T_In
        # exactly, its breakpoints are samples; the element torques to the sampling's accuracy)
        inside = np.flatnonzero((grid >= phase.t_start) & (grid <= phase.t_end))
        times = grid[inside]
        u = np.column_stack([signals[name][inside] for name in (*input_signals, naming.GRADE)])
        reference = np.column_stack([reader(v.name)[inside] for v in model.states])
        reduced = integrate_linear_inputs(f, reference[0], times, u)
        errors = np.max(np.abs(reduced - reference), axis=0)
        scales = np.maximum(np.max(np.abs(reference), axis=0), 1e-12)
        checks.append(
            ModelCheck(
                model=model.name,
                phase=phase.name,
                t_start=phase.t_start,
                t_end=phase.t_end,
                max_abs_error={v.name: float(e) for v, e in zip(model.states, errors, strict=True)},
                max_relative_error=float(np.max(errors / scales)),
            )
        )
    return tuple(checks)
