"""Reference simulation of a shift (thesis 3.1), its phases, energy audit and model checks.

The reference model (:mod:`gearsym.symbolic.reference`) is the full gearbox (2.39) with the elastic
drivetrain (2.42–2.53) and one elasto-plastic friction state per pressed element (2.66)–(2.70).
It is integrated with SciPy's Radau (stiff, implicit, order 5) and the analytic Jacobian from
SymPy, restarting at every breakpoint of the scenario's piecewise-linear inputs. μ comes from the
friction map at each element's pressure, the oil temperature and the current slip.

What is derived from the result, never from the scenario's times:

* the phases (:func:`gearsym.validation.sim.phases.detect_phases`): from-gear, torque phase
  (the on-coming element takes over the load) and speed phase (the input speed moves to the
  new ratio) in the order they happen, to-gear;
* the energy audit (:class:`~gearsym.validation.sim.simulation_result.EnergyAudit`): input
  work = Δ kinetic + Δ spring + Δ bristle energy + friction dissipation + damper dissipation +
  road work, with the works integrated as extra ODE states at the solver's accuracy;
* the model checks (:class:`~gearsym.validation.sim.simulation_result.ModelCheck`): each
  reduced model (the from- and to-gear with their elements locked, the shift model
  (2.55)–(2.58) with the two swapping elements' torques taken from the reference) integrated
  inside the phase where it is valid and compared.

This module holds :func:`simulate`, the one entry; the parts it joins live beside it: the
result records (:mod:`~gearsym.validation.sim.simulation_result`: :class:`SimulationResult`,
:class:`~gearsym.validation.sim.simulation_result.EnergyAudit`,
:class:`~gearsym.validation.sim.simulation_result.ModelCheck`), the compiled model and its
inputs (:mod:`~gearsym.validation.sim.reference_functions`), the quasi-static start
(:mod:`~gearsym.validation.sim.quasi_static`), the integration loops
(:mod:`~gearsym.validation.sim.reference_integrators`), the recorded signals and the audit
(:mod:`~gearsym.validation.sim.reference_signals`) and the reduced-model checks
(:mod:`~gearsym.validation.sim.model_checks`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.friction import load_mu_map
from gearsym.symbolic.reference import reference_model
from gearsym.validation.sim.model_checks import check_reduced_models
from gearsym.validation.sim.phases import detect_phases
from gearsym.validation.sim.quasi_static import quasi_static_state
from gearsym.validation.sim.reference_functions import CompiledReference, ReferenceInputs
from gearsym.validation.sim.reference_integrators import (
    Progress,
    absolute_tolerances,
    integrate_cvodes,
    integrate_scipy,
)
from gearsym.validation.sim.reference_signals import reference_energy_audit, reference_signals
from gearsym.validation.sim.scenario import SAMPLE_TIME, Scenario, load_scenario
from gearsym.validation.sim.simulation_result import ModelCheck, SimulationResult
from scipy.interpolate import CubicHermiteSpline

ENERGY_TERMS = naming.ENERGY_TERMS

#: Most samples one simulation returns (and writes to timeseries.csv): 100 000 rows are about
#: 75 MB of CSV. The scenario's t_end limit keeps the default sampling at 20 000.
SAMPLES_MAX = 100_000

METHODS = ("cvodes", "Radau", "BDF")


def simulate(
    d: GearboxDescription,
    scenario: Scenario | None = None,
    progress: Progress | None = None,
    rtol: float = 1e-8,
    sample_time: float = SAMPLE_TIME,
    check_models: bool = True,
    method: str = "cvodes",
    analytic_jacobian: bool = True,
    phases: bool = True,
    mu_scale: Mapping[str, float] | None = None,
) -> SimulationResult:
    """Integrate the reference model through the scenario (thesis 3.1).

    ``mu_scale``: a factor on the μ map per element name (a fleet's truth: oil temperature,
    wear); elements not named keep the map.

    ``method``: "cvodes" (default; SUNDIALS CVODES through CasADi, BDF with CasADi's exact
    Jacobian, in C) or a stiff SciPy integrator, "Radau" or "BDF" (the cross-checks; the tests
    compare them). Every method restarts at each breakpoint of the scenario's inputs.
    ``sample_time`` is the spacing of the returned time series; between samples the state is a
    cubic Hermite interpolant (values and derivatives at the samples). ``analytic_jacobian``
    False lets SciPy difference the right-hand side instead (SciPy methods only).
    ``phases`` False skips the phase detection and the model checks (a scenario that holds its
    from-gear, e.g. a one-way clutch in drive or coast).

    Every one-way clutch of the description is in the model (it needs no pressure): the
    unilateral spring-damper of :func:`gearsym.symbolic.friction.one_way_sym`, starting
    unwound (z = 0); its wind-up energy is part of the bristle energy of the audit.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    start = time.perf_counter()
    scenario = scenario if scenario is not None else load_scenario(d)
    if not scenario.t_end / sample_time <= SAMPLES_MAX:
        raise GearsymError(
            scenario.file,
            "scenario.t_end",
            f"{scenario.t_end:g} s at {sample_time:g} s per sample is more than {SAMPLES_MAX} "
            "samples, the limit of a simulation",
        )
    report = progress or (lambda fraction, message: None)
    elements = tuple(
        e.name
        for e in d.shift_elements
        if not e.one_way and float(np.max(scenario.pressure[e.name].value)) > 0
    )
    one_way = tuple(e.name for e in d.shift_elements if e.one_way)
    report(0.0, "deriving the reference model")
    ref = reference_model(d, elements + one_way)
    compiled = CompiledReference(ref, d, elements, one_way)
    t_oil = quantity(d, "friction", "T_oil").value
    unknown = sorted(set(mu_scale or {}) - {e.name for e in d.shift_elements})
    if unknown:
        raise GearsymError(d.file, "mu_scale", f"{unknown[0]!r} is not a shift element")
    inputs = ReferenceInputs(scenario, elements, load_mu_map(d), t_oil, compiled, mu_scale)
    x0 = quasi_static_state(d, ref, inputs, compiled)
    n = compiled.n
    names = tuple(v.name for v in ref.model.states)
    atol = absolute_tolerances(names, rtol, x0)
    y0 = np.concatenate([x0, np.zeros(len(ENERGY_TERMS))])
    breakpoints = scenario.breakpoints()
    grid = np.unique(np.concatenate([np.arange(0.0, scenario.t_end, sample_time), breakpoints]))
    report(0.0, f"integrating {len(breakpoints) - 1} segments with {method} (rtol {rtol:g})")
    if method == "cvodes":
        states, stats = integrate_cvodes(
            compiled, inputs, y0, grid, breakpoints, rtol, atol, report
        )
    else:
        states, stats = integrate_scipy(
            compiled, inputs, y0, grid, breakpoints, rtol, atol, method, analytic_jacobian, report
        )
    rates = compiled.f.many(states[:, :n], inputs.many(grid, states[:, :n]))
    dense = CubicHermiteSpline(grid, states, rates, axis=0)

    def state_at(t: float) -> np.ndarray:
        return np.asarray(dense(min(max(t, grid[0]), grid[-1])), dtype=float)

    signals = reference_signals(d, grid, states, names, inputs, compiled, scenario)
    audit = reference_energy_audit(states, x0, compiled)
    found = detect_phases(d, scenario, grid, signals) if phases else ()
    checks: tuple[ModelCheck, ...] = ()
    if check_models and phases:
        report(1.0, "checking the reduced models phase by phase")
        checks = check_reduced_models(d, scenario, found, names, grid, states, signals, compiled)
    stats["wall_time_s"] = time.perf_counter() - start
    return SimulationResult(
        t=grid,
        signals=signals,
        phases=found,
        audit=audit,
        checks=checks,
        scenario=scenario,
        state_names=names,
        stats=stats,
        state_at=state_at,
        method=method,
    )
