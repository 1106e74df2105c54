"""The energy audit of a hybrid simulation (:mod:`gearsym.validation.sim.hybrid_simulation`):
the reference's audit (:class:`gearsym.validation.sim.simulation_result.EnergyAudit`) without
bristles, the works integrated over each piece's dense output."""

from __future__ import annotations

from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.numeric import to_casadi
from gearsym.validation.sim.compiled_c import CompiledFunction
from gearsym.validation.sim.hybrid_result import HybridResult
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.simulation_result import EnergyAudit


def energy_functions(simulator: HybridSimulator) -> dict[str, tuple[Any, Any]]:
    """Per mode, CasADi functions (x, u, p) → [T_In ω_in, Σ T_e Δω_e, 2 d_ss φ̇², T_res ω_C] (the
    powers of :func:`energy_audit`) and (x, p) → [E_kin, E_spring]."""
    import casadi as ca
    from gearsym.symbolic.drivetrain import drivetrain_parts
    from gearsym.symbolic.hybrid import drivetrain_mass

    d = simulator.d
    mass = np.array(drivetrain_mass(d, gearbox_dynamics(d)), dtype=float)
    parts = drivetrain_parts(d)
    functions = {}
    for name, compiled in simulator.modes.items():
        mode = simulator.hybrid.modes[name]
        mapping = compiled.mapping
        n_gear = len(mode.keep)
        projection = np.array(mode.projection, dtype=float)
        reduced = projection.T @ mass @ projection
        z = compiled.x[:n_gear]
        states = [v.name for v in mode.model.states]
        phi = compiled.x[states.index(naming.TWIST)]
        omega_c = compiled.x[states.index(naming.WHEEL_SPEED)]
        wheel = to_casadi(parts.wheel_inertia, mapping)
        kinetic = 0.5 * ca.dot(z, ca.mtimes(ca.DM(reduced), z)) + 0.5 * wheel * omega_c**2
        speeds = simulator.shaft_speeds(name)(compiled.x)
        omega_in = speeds[[s.name for s in d.shafts].index(d.input_shaft)]
        friction = ca.dot(
            ca.vertcat(*[to_casadi(t, mapping) for t in compiled.torque_exprs]),
            ca.vertcat(*[to_casadi(mode.slip[e], mapping) for e in simulator.hybrid.elements]),
        )
        phi_dot = compiled.rhs_sx[states.index(naming.TWIST)]
        powers = ca.vertcat(
            compiled.u[0] * omega_in,
            friction,
            2 * _parameter(simulator, compiled, "d_ss") * phi_dot**2,
            to_casadi(parts.road_torque, mapping) * omega_c,
        )
        energies = ca.vertcat(kinetic, _parameter(simulator, compiled, "k_ss") * phi**2)
        functions[name] = (
            ca.Function("powers", [compiled.x, compiled.u, compiled.p], [powers]),
            ca.Function("energies", [compiled.x, compiled.p], [energies]),
        )
    return functions


def _parameter(simulator: HybridSimulator, compiled: Any, name: str) -> Any:
    return compiled.p[simulator.parameter_names.index(name)]


def energy_audit(
    simulator: HybridSimulator,
    result: HybridResult,
    interval: float = 1e-3,
    functions: dict[str, tuple[Any, Any]] | None = None,
) -> EnergyAudit:
    """W_in = ΔE_kin + ΔE_spring + W_friction + W_damper + W_road over the hybrid run (the
    reference's audit without bristles): E_kin = ½ zᵀ Pᵀ M P z + ½ I_C^eff ω_C² (2.34, 2.46),
    E_spring = k_ss φ² (two side shafts, 2.47), the powers T_In ω_in, Σ T_e Δω_e (sliding
    elements; a locked one has Δω = 0, an open one T = 0), 2 d_ss φ̇², T_res ω_C (2.48). The
    works are integrated over each piece's dense output by 5-point Gauss–Legendre on
    sub-intervals of at most ``interval``. The maps at lock-up and break-away conserve E_kin
    (zero slip); a residual would show an inconsistent reaction, sign or map. A dog element
    engaged at non-zero slip loses ½ Δẏᵀ M Δẏ in its map (``Event.energy_loss``): counted in
    W_friction, the impact's dissipation. ``functions``: :func:`energy_functions` of this
    simulator when the caller keeps them (building them costs more than a shift's audit); a
    mode's powers may be its :class:`~gearsym.validation.sim.compiled_c.CompiledFunction`."""
    p = simulator.parameter_vector(result.values)
    if functions is None:
        functions = energy_functions(simulator)
    nodes, weights = np.polynomial.legendre.leggauss(5)
    works = np.zeros(4)
    for piece in result.pieces:
        if piece.t_end <= piece.t_start:
            continue
        n = simulator.modes[piece.mode].n
        count = max(1, int(np.ceil((piece.t_end - piece.t_start) / interval)))
        edges = np.linspace(piece.t_start, piece.t_end, count + 1)
        half = np.diff(edges) / 2
        times = ((edges[:-1] + edges[1:]) / 2)[:, None] + half[:, None] * nodes[None, :]
        times = times.ravel()
        x = piece.state(times)[:, :n]
        u = simulator.inputs_many(times)
        powers = functions[piece.mode][0]
        if isinstance(powers, CompiledFunction):
            values = powers.many(x, u, p)
        else:
            values = np.asarray(powers.map(len(times))(x.T, u.T, p).full()).T
        w = (half[:, None] * weights[None, :]).ravel()
        works += w @ values
    first, last = result.pieces[0], result.pieces[-1]
    n0, n1 = simulator.modes[first.mode].n, simulator.modes[last.mode].n
    e0 = np.asarray(functions[first.mode][1](first.x_start[:n0], p).full()).ravel()
    end = last.state(np.array([last.t_end]))[0, :n1]
    e1 = np.asarray(functions[last.mode][1](end, p).full()).ravel()
    return EnergyAudit(
        input_work=float(works[0]),
        kinetic_change=float(e1[0] - e0[0]),
        spring_change=float(e1[1] - e0[1]),
        bristle_change=0.0,
        friction_dissipation=float(works[1]) + sum(e.energy_loss for e in result.events),
        damper_dissipation=float(works[2]),
        road_work=float(works[3]),
    )
