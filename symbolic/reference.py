"""The reference model: full gearbox + elastic drivetrain + one friction state per element.

This is the model the reference simulation of a shift integrates (thesis 3.1): the 4-DOF
gearbox (2.39) with the elastic drivetrain (2.42–2.53) and every shift element acting through
the elasto-plastic friction model (2.66)–(2.70), driven by the element pressures. Locked
elements are not constraints here — they stick through their bristle stiffness σ0 — so the same
equations cover every gear and every phase of a shift.

States: the gearbox coordinates' speeds, φ, ω_C, and z_<element> for every element.
Inputs: T_In, p_<element> (apply pressure) and mu_<element> (friction coefficient, which the
simulator reads from the μ map at the current pressure, oil temperature and slip).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import drivetrain_parts, quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.friction import one_way_sym, shift_element_sym
from gearsym.symbolic.kinematics import exact
from gearsym.symbolic.model import Model, Variable


@dataclass(frozen=True)
class ReferenceModel:
    """The reference :class:`Model` and the expressions the simulator and the audit need."""

    model: Model
    slip: dict[str, sp.Expr]  # Δω = ω_a − ω_b of every element (2.59)
    element_torque: dict[str, sp.Expr]  # T_Cl (2.67)
    body_speeds: dict[str, sp.Expr]
    kinetic_energy: sp.Expr  # ½ ẏᵀ M' ẏ + ½ I_C ω_C²
    spring_energy: sp.Expr  # 2 · ½ k_ss φ²
    bristle_energy: sp.Expr  # Σ ½ σ0 z²
    input_power: sp.Expr  # T_In ω_in
    friction_power: sp.Expr  # Σ T_e Δω_e  (taken out of the shafts)
    damper_power: sp.Expr  # 2 d_ss φ̇² (+ d Σ ω² of idle shafts)
    road_power: sp.Expr  # T_res ω_C
    side_shaft_torque: sp.Expr
    road_torque: sp.Expr
    wheel_acceleration: sp.Expr


def reference_model(d: GearboxDescription, elements: Sequence[str] | None = None) -> ReferenceModel:
    """Build the reference model of the description.

    ``elements`` (default: all) get a friction state; every other element is open (zero
    torque), which keeps the model small when a scenario never presses them. A one-way clutch
    among them gets a wind-up state and the unilateral law of
    :func:`gearsym.symbolic.friction.one_way_sym` (no pressure or μ input).
    """
    names = [e.name for e in d.shift_elements]
    chosen = names if elements is None else [n for n in names if n in set(elements)]
    for e in (d.element(n) for n in chosen):
        if e.one_way:
            continue
        if e.dog:
            raise GearsymError(
                d.file,
                f'shift_element[name="{e.name}"].kind',
                "a dog element (form-locking, engaged or open by command) is not part of the "
                "reference simulation (bristle friction); simulate its shifts with the hybrid "
                "model (gearsym.validation.sim.hybrid_simulation.simulate_hybrid)",
            )
        if e.n_disc is None or e.r_m is None or e.a_piston is None:
            raise GearsymError(
                d.file,
                f'shift_element[name="{e.name}"].n_disc',
                "friction data (n_disc, r_m, a_piston) needed by the reference simulation",
            )
    friction = {k: exact(quantity(d, "friction", k).value) for k in ("sigma0", "sigma1")}
    z_ba = exact(quantity(d, "friction", "z_ba_ratio").value)
    parts = drivetrain_parts(d)
    speeds = parts.body_speeds
    slip: dict[str, sp.Expr] = {}
    torque: dict[str, sp.Expr] = {}
    rates: dict[str, sp.Expr] = {}
    z_vars, p_vars, mu_vars = [], [], []
    storage: list[sp.Expr] = []
    for e in (d.element(n) for n in chosen):
        if e.one_way:
            # a freewheel: unilateral spring-damper on its wind-up z (friction.one_way_sym),
            # with the bristle stiffness and damping of the description; no pressure, no μ
            z = sp.Symbol(naming.bristle(e.name))
            slip[e.name] = (speeds[e.a] if e.a is not None else 0) - speeds[e.b]
            dw = sp.Symbol(naming.slip_symbol(e.name), real=True)
            rate, t_ow = one_way_sym(z, dw, e.locks, friction["sigma0"], friction["sigma1"])
            with sp.evaluate(False):
                rates[e.name] = rate.xreplace({dw: slip[e.name]})
                torque[e.name] = t_ow.xreplace({dw: slip[e.name]})
            z_vars.append(Variable(z.name, z, "rad", f"wind-up of the one-way clutch {e.name}"))
            storage.append(friction["sigma0"] * sp.Max(z, 0) ** 2 / 2)
            continue
        z = sp.Symbol(naming.bristle(e.name))
        p = sp.Symbol(naming.pressure(e.name))
        mu = sp.Symbol(naming.friction_coefficient(e.name), positive=True)
        slip[e.name] = (speeds[e.a] if e.a is not None else 0) - speeds[e.b]
        assert e.r_m is not None and e.a_piston is not None and e.n_disc is not None
        # Build the friction law on a plain slip symbol, then put the slip expression in
        # without re-evaluation: SymPy's Max re-simplification on the long slip expressions
        # is slow, and a substitution changes nothing it could simplify.
        dw = sp.Symbol(naming.slip_symbol(e.name), real=True)
        rate, t_cl = shift_element_sym(
            z,
            dw,
            p * exact(e.a_piston.value),
            mu,
            friction["sigma0"],
            friction["sigma1"],
            e.n_disc,
            exact(e.r_m.value),
            z_ba,
        )
        with sp.evaluate(False):
            rates[e.name] = rate.xreplace({dw: slip[e.name]})
            torque[e.name] = t_cl.xreplace({dw: slip[e.name]})
        z_vars.append(Variable(z.name, z, "rad", f"bristle deflection of {e.name} (2.66)"))
        storage.append(friction["sigma0"] * z**2 / 2)
        p_vars.append(Variable(p.name, p, "Pa", f"apply pressure of {e.name}"))
        mu_vars.append(Variable(mu.name, mu, "1", f"friction coefficient of {e.name}"))

    substitution = {
        parts.torque_symbols[e]: torque.get(e, sp.Integer(0)) for e in parts.torque_elements
    }
    with sp.evaluate(False):
        gearbox = parts.gearbox_rhs.xreplace(substitution)
    wheel = (2 * parts.side_shaft_torque - parts.road_torque) / parts.wheel_inertia
    rhs = sp.Matrix([*gearbox, parts.phi_dot, wheel, *(rates[n] for n in chosen)])

    states = (
        *(
            Variable(naming.speed(s), sym, "rad/s", f"speed of shaft {s}")
            for s, sym in zip(parts.keep, parts.speeds, strict=True)
        ),
        Variable(naming.TWIST, sp.Symbol(naming.TWIST), "rad", "side-shaft twist (2.43)"),
        Variable(naming.WHEEL_SPEED, sp.Symbol(naming.WHEEL_SPEED), "rad/s", "wheel speed"),
        *z_vars,
    )
    inputs = (
        Variable(naming.INPUT_TORQUE, parts.torque_symbols[naming.INPUT], "N*m", "input torque"),
        *p_vars,
        *mu_vars,
    )
    measured = [naming.measured(naming.speed(s)) for s in d.measured_shafts]
    measured.append(naming.measured(naming.WHEEL_SPEED))
    outputs = tuple(Variable(y, sp.Symbol(y), "rad/s") for y in measured)
    output_exprs = sp.Matrix(
        [*(speeds[s] for s in d.measured_shafts), sp.Symbol(naming.WHEEL_SPEED)]
    )
    model = Model(
        name=naming.REFERENCE_MODEL,
        states=states,
        inputs=inputs,
        parameters=parts.parameters,
        outputs=outputs,
        rhs=rhs,
        output_expressions=output_exprs,
        metadata={"gearbox": d.name, "equations": "2.39, 2.42-2.53, 2.66-2.70"},
    )

    # Energy bookkeeping (README "energy audit"): the extra output-shaft inertia of (2.51).
    from gearsym.symbolic.dynamics import gearbox_dynamics

    dyn = gearbox_dynamics(d)
    i_d = exact(quantity(d, "drivetrain", "i_D").value)
    extra = exact(quantity(d, "drivetrain", "J_cs").value)
    extra += exact(quantity(d, "drivetrain", "J_D").value) / i_d**2
    y_dot = sp.Matrix(parts.speeds)
    index = {b: i for i, b in enumerate(d.body_names)}
    out_row = dyn.kinematics.transform[index[d.output_shaft], :]
    mass = dyn.mass_matrix + extra * (out_row.T * out_row)
    params = {v.name: v.symbol for v in parts.parameters}
    omega_c = sp.Symbol(naming.WHEEL_SPEED)
    kinetic = (y_dot.T * mass * y_dot)[0] / 2 + parts.wheel_inertia * omega_c**2 / 2
    return ReferenceModel(
        model=model,
        slip=slip,
        element_torque=torque,
        body_speeds=speeds,
        kinetic_energy=kinetic,
        spring_energy=params["k_ss"] * sp.Symbol(naming.TWIST) ** 2,
        bristle_energy=sum(storage, sp.Integer(0)),
        input_power=parts.torque_symbols[naming.INPUT] * speeds[d.input_shaft],
        friction_power=sum((torque[e] * slip[e] for e in torque), sp.Integer(0)),
        # the side-shaft dampers, and the drag of idle shafts (README "Idle shafts")
        damper_power=2 * params["d_ss"] * parts.phi_dot**2 + parts.drag_power,
        road_power=parts.road_torque * omega_c,
        side_shaft_torque=parts.side_shaft_torque,
        road_torque=parts.road_torque,
        wheel_acceleration=wheel,
    )
