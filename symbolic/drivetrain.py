"""Stage 3b: the elastic drivetrain and the shift models (thesis 2.42–2.58); their linear
forms (5.1)–(5.5) are :mod:`gearsym.symbolic.linear_forms`.

The rigid gearbox M ÿ = B̃ u (2.39) is closed at its output by an elastic side-shaft pair
(spring k_ss, damper d_ss, 2.47), the differential ratio i_D and an equivalent wheel that carries
the vehicle (2.45), loaded by rolling, aerodynamic and grade resistance (2.48–2.49):

    φ̇  = ω_out / i_D − ω_C                                   (2.44)
    T_ss = k_ss φ + d_ss φ̇,    T_out = 2 T_ss / i_D           (2.47), (2.52)
    I_C^eff ω̇_C = 2 T_ss − T_res,   I_C^eff = I_wheel + m_veh r_dyn²   (2.45), (2.46) corrected
    T_res = r_dyn (F_r + F_ad + F_g)                          (2.48)

A *shift model* (2.55–2.58) keeps the elements common to both gears locked — their constraints
are eliminated by projecting M and B̃ onto the remaining motions, ẏ = P z, M_r = Pᵀ M P — and
lets the off-going and the on-coming element act as input torques. The full model (2.53) locks
nothing and has every element as an input.

Corrections of printed slips (see README): (2.46) uses m_veh r_dyn² (the square is missing in
print); (2.51) reflects each inertia through the ratio it turns at: the propeller shaft turns
with the output shaft (J_cs), the differential cage at ω_out/i_D (J_D / i_D²), and the wheel-side
half of the differential belongs to I_wheel — instead of counting J_cs^eff twice.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import pairwise

import sympy as sp
from gearsym.symbolic import naming, parameters
from gearsym.symbolic.description import GearboxDescription, Quantity
from gearsym.symbolic.dynamics import GearboxDynamics, gearbox_dynamics
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.kinematics import exact
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.ratios import gear_motion, gear_ratio, idle_shafts
from gearsym.symbolic.shifts import ShiftSpec, shift_spec


def shift_keep(d: GearboxDescription, spec: ShiftSpec) -> tuple[str, ...] | None:
    """The shafts whose speeds are the gearbox states of ``spec``'s shift model: ``None`` (the
    default of :func:`drivetrain_parts`: input and output shaft, idle shafts as needed) for a
    single swap; for a double swap, whose common elements leave one more degree of freedom,
    input and output shaft, then idle shafts and then the description's generalized
    coordinates, in order, each taken while it adds a motion the others do not fix (2.55)."""
    if spec.single:
        return None
    shafts = (d.input_shaft, d.output_shaft, *idle_shafts(d), *d.coordinates)
    return _extend_keep(d, gearbox_dynamics(d), spec.locked, (), shafts)


def element_short_name(d: GearboxDescription, element: str) -> str:
    """Thesis-style short name: K38 → 38, B05 → 05 (mu_38, F_N05), when unambiguous."""
    return naming.element_short_name(element, [e.name for e in d.shift_elements])


def element_slip_in_gear(d: GearboxDescription, gear: str, element: str) -> sp.Expr:
    """Slip Δω = ω_a − ω_b of an element in a gear, per unit output speed (exact)."""
    motion = gear_motion(d, d.gear(gear))
    speeds = dict(zip(d.shaft_names, motion, strict=True))
    motion_out = speeds[d.output_shaft]
    e = d.element(element)
    slip = (speeds[e.a] if e.a is not None else 0) - speeds[e.b]
    ratio = sp.sympify(slip / motion_out)
    # a rational (numeric teeth) is exact already; nsimplify would spend ~10 ms searching for
    # another closed form of it
    return ratio if ratio.is_Rational else sp.nsimplify(ratio)


def power_on_slip_signs(d: GearboxDescription, spec: ShiftSpec) -> dict[str, int]:
    """Signs of the slip (and so of the friction torque, 2.70) of the two swapping elements
    while they slip in a power-on shift.

    The on-coming element slips as the from-gear makes it slip until it engages. The off-going
    element, in an upshift, slips the other way than the to-gear would make it (the input
    flares slightly during the torque phase, 3.1); in a downshift, the way the to-gear does.
    """
    on = sp.sign(element_slip_in_gear(d, spec.from_gear, spec.on_coming))
    off_to = sp.sign(element_slip_in_gear(d, spec.to_gear, spec.off_going))
    upshift = (
        gear_ratio(d, d.gear(spec.to_gear)).ratio < gear_ratio(d, d.gear(spec.from_gear)).ratio
    )
    return {spec.on_coming: int(on), spec.off_going: int(-off_to if upshift else off_to)}


def adjacent_shifts(d: GearboxDescription) -> list[ShiftSpec]:
    """Shifts between forward gears adjacent by ratio (largest ratio first); a double swap
    among them (the overdrive engagement 3-4 of tests/data/simpson_overdrive_idle.toml) has
    ``single`` False."""
    forward = []
    for g in d.gears:
        if g.neutral:
            continue
        ratio = gear_ratio(d, g).ratio
        if ratio is not None and ratio > 0:
            forward.append((ratio, g.name))
    forward.sort(reverse=True)
    return [shift_spec(d, f"{a}-{b}", max_swaps=2) for (_, a), (_, b) in pairwise(forward)]


def quantity(d: GearboxDescription, section: str, key: str) -> Quantity:
    """The value ``[section] key`` of the description, or a one-line error if it is missing."""
    values = getattr(d, section)
    if key not in values:
        raise GearsymError(d.file, f"{section}.{key}", "missing (needed by the drivetrain model)")
    return values[key]


#: Viscous drag of an idle shaft to the housing when the description gives no
#: ``[drivetrain] idle_drag``: 2 N·m at 1000 rad/s, the order of an open wet clutch's drag
#: (README "Idle shafts").
IDLE_DRAG_DEFAULT = Quantity(0.002, "N*m*s/rad", "default of gearsym (README 'Idle shafts')")


def idle_drag(d: GearboxDescription) -> Quantity:
    """d of the drag torque −d ω that every idle shaft (:func:`~gearsym.symbolic.ratios.
    idle_shafts`) feels against the housing in every model of the description."""
    return d.drivetrain.get("idle_drag", IDLE_DRAG_DEFAULT)


def idle_note(d: GearboxDescription) -> str:
    """The dynamics assumption for idle shafts, as text for model metadata (and so the emitted
    C headers: no word the ECU source check reads as dynamic memory); "" when no gear leaves a
    shaft idle."""
    idle = idle_shafts(d)
    if not idle:
        return ""
    drag = idle_drag(d)
    return (
        f"idle shafts {', '.join(idle)}: each has a viscous drag torque -d*omega to the "
        f"housing, d = {drag.value:g} N*m*s/rad ({drag.source}); a gear that leaves them idle "
        "keeps their speeds as states, driven by the inertia coupling and this drag"
    )


def friction_symbols(
    d: GearboxDescription, element: str, why: str = "needed for mu inputs"
) -> tuple[sp.Expr, Variable, Variable]:
    """(gain 2 N_disc r_m, normal-force input F_N, friction-coefficient parameter μ) of an
    element: its sliding torque is k_sign · gain · μ · F_N (2.69), (3.14). ``why`` completes the
    one-line error when the element lacks n_disc or r_m."""
    e = d.element(element)
    if e.n_disc is None or e.r_m is None:
        raise GearsymError(d.file, f'shift_element[name="{element}"].n_disc', f"missing ({why})")
    short = element_short_name(d, element)
    mu_default = quantity(d, "friction", "mu_nominal")
    mu = Variable(
        naming.friction_coefficient(short),
        sp.Symbol(naming.friction_coefficient(short), positive=True),
        "1",
        f"friction coefficient of {element} (2.69)",
        mu_default.value,
        mu_default.source,
    )
    normal = Variable(
        naming.normal_force(short),
        sp.Symbol(naming.normal_force(short)),
        "N",
        f"normal force on {element} (2.69)",
    )
    return 2 * e.n_disc * exact(e.r_m.value), normal, mu


def drivetrain_parameters(d: GearboxDescription) -> tuple[Variable, ...]:
    """The model parameters with defaults, units and sources from the description."""
    rolling = naming.ROLLING_KEYS[d.rolling_resistance]
    keys = list(naming.PARAMETER_KEYS) + list(rolling)
    result = []
    for key in keys:
        q = quantity(d, parameters.record(key).section, key)
        positive = key not in naming.SIGNED_PARAMETERS
        result.append(
            Variable(
                name=key,
                symbol=sp.Symbol(key, positive=positive) if positive else sp.Symbol(key, real=True),
                unit=q.unit,
                description=naming.DESCRIPTIONS[key],
                default=q.value,
                source=q.source,
            )
        )
    return tuple(result)


def slip_rows(
    d: GearboxDescription, dyn: GearboxDynamics, elements: tuple[str, ...]
) -> list[sp.Matrix]:
    """Rows of the slip Δω_e = ω_a − ω_b (2.59) of each element in ẏ: they vanish for a
    locked element."""
    transform = dyn.kinematics.transform
    index = {b: i for i, b in enumerate(d.body_names)}
    rows = []
    for name in elements:
        e = d.element(name)
        row = -transform[index[e.b], :]
        if e.a is not None:
            row += transform[index[e.a], :]
        rows.append(row)
    return rows


def locked_projection(
    d: GearboxDescription,
    dyn: GearboxDynamics,
    locked: tuple[str, ...],
    keep: tuple[str, ...],
) -> sp.Matrix:
    """P with ẏ = P·z: the motions the locked elements allow, parametrised by the speeds of
    the shafts in ``keep`` (2.55). Raises when those speeds do not parametrise them."""
    transform = dyn.kinematics.transform
    index = {b: i for i, b in enumerate(d.body_names)}
    rows = slip_rows(d, dyn, locked)
    chooser = [transform[index[s], :] for s in keep]
    system = sp.Matrix.vstack(*rows, *chooser) if rows or chooser else sp.zeros(0, 0)
    if system.shape[0] != system.shape[1] or system.det() == 0:
        raise GearsymError(
            d.file,
            "shift",
            f"with {', '.join(locked) or 'nothing'} locked, the speeds of "
            f"{', '.join(keep)} do not parametrise the remaining motion",
        )
    inverse = system.inv()
    return inverse[:, len(rows) :]


def keep_with_idle(
    d: GearboxDescription, dyn: GearboxDynamics, locked: tuple[str, ...], keep: tuple[str, ...]
) -> tuple[str, ...]:
    """``keep`` extended by idle shafts (:func:`~gearsym.symbolic.ratios.idle_shafts`, in
    order) while the locked elements and the kept speeds leave motions undetermined: a gear
    that leaves idle shafts free keeps their speeds as further states. Unchanged for a
    gearbox without idle shafts."""
    idle = [s for s in idle_shafts(d) if s not in keep]
    if not idle or len(locked) + len(keep) >= len(d.coordinates):
        return keep
    return _extend_keep(d, dyn, locked, keep, tuple(idle))


def _extend_keep(
    d: GearboxDescription,
    dyn: GearboxDynamics,
    locked: tuple[str, ...],
    keep: tuple[str, ...],
    candidates: tuple[str, ...],
) -> tuple[str, ...]:
    """``keep`` extended by the ``candidates`` (in order) whose speed adds a motion that the
    locked elements' slips and the speeds kept so far do not fix, until they fix all (2.55)."""
    f = len(d.coordinates)
    transform = dyn.kinematics.transform
    index = {b: i for i, b in enumerate(d.body_names)}
    rows = [*slip_rows(d, dyn, locked), *(transform[index[s], :] for s in keep)]
    rank = sp.Matrix.vstack(*rows).rank() if rows else 0
    extended = list(keep)
    for shaft in candidates:
        if rank >= f:
            break
        if shaft in extended:
            continue
        candidate = sp.Matrix.vstack(*rows, transform[index[shaft], :])
        if candidate.rank() > rank:
            rows.append(transform[index[shaft], :])
            rank += 1
            extended.append(shaft)
    return tuple(extended)


@dataclass(frozen=True)
class DrivetrainParts:
    """The pieces of a drivetrain model before they are assembled into a :class:`Model`."""

    keep: tuple[str, ...]
    torque_elements: tuple[str, ...]
    speeds: tuple[sp.Symbol, ...]
    gearbox_rhs: sp.Matrix  # ż of the kept shaft speeds
    phi_dot: sp.Expr  # (2.44)
    side_shaft_torque: sp.Expr  # T_ss (2.47)
    road_torque: sp.Expr  # T_res (2.48)
    rolling_and_aero_torque: sp.Expr  # r_dyn (F_r + F_ad), replaced by T_res* in (5.2)
    grade_lever: sp.Expr  # r_dyn g
    wheel_inertia: sp.Expr  # I_C^eff (2.46)
    body_speeds: dict[str, sp.Expr]  # every body's speed in terms of the kept speeds
    parameters: tuple[Variable, ...]
    torque_symbols: dict[str, sp.Symbol]
    #: With friction inputs: element -> (torque expression, normal-force input, μ parameter).
    friction: dict[str, tuple[sp.Expr, Variable, Variable]]
    #: Power d Σ ω² the idle-shaft drag dissipates (README "Idle shafts"); 0 without idle shafts.
    drag_power: sp.Expr = sp.Integer(0)


#: The parts last derived, by description object and normalised arguments: a model and its
#: linear form (5.1) share one derivation (`gearsym model` prints both; generate derives each
#: mode's model for several functions). The description is kept with its entry so its id cannot
#: be reused meanwhile; the cached parts are immutable (ImmutableMatrix, frozen dataclass).
_PARTS: dict[tuple[object, ...], tuple[GearboxDescription, DrivetrainParts]] = {}


def drivetrain_parts(
    d: GearboxDescription,
    locked: tuple[str, ...] = (),
    torque_elements: tuple[str, ...] | None = None,
    keep: tuple[str, ...] | None = None,
    slip_signs: dict[str, int] | None = None,
) -> DrivetrainParts:
    """Derive gearbox + elastic drivetrain (2.42–2.58); see :func:`drivetrain_model`.

    Remembered per description object and arguments (descriptions are immutable)."""
    locked = tuple(locked)
    if torque_elements is None:
        torque_elements = tuple(e.name for e in d.shift_elements if e.name not in locked)
    if keep is None:
        keep = d.coordinates if not locked else (d.input_shaft, d.output_shaft)
    signs = None if slip_signs is None else tuple(sorted(slip_signs.items()))
    key = (id(d), locked, tuple(torque_elements), tuple(keep), signs)
    derived = _PARTS.get(key)
    if derived is not None and derived[0] is d:
        return derived[1]
    if len(_PARTS) >= 64:
        _PARTS.clear()
    parts = _derive_parts(d, locked, tuple(torque_elements), tuple(keep), slip_signs)
    _PARTS[key] = (d, parts)
    return parts


def _derive_parts(
    d: GearboxDescription,
    locked: tuple[str, ...],
    torque_elements: tuple[str, ...],
    keep: tuple[str, ...],
    slip_signs: dict[str, int] | None,
) -> DrivetrainParts:
    dyn = gearbox_dynamics(d)
    sym = dyn.symbols
    keep = keep_with_idle(d, dyn, locked, keep)
    projection = locked_projection(d, dyn, locked, keep)

    i_d = exact(quantity(d, "drivetrain", "i_D").value)
    r_dyn = exact(quantity(d, "vehicle", "r_dyn").value)
    g = exact(quantity(d, "vehicle", "g").value)
    j_cs = exact(quantity(d, "drivetrain", "J_cs").value)
    j_d = exact(quantity(d, "drivetrain", "J_D").value)
    params = drivetrain_parameters(d)
    p = {v.name: v.symbol for v in params}

    # (2.51) corrected: propeller shaft at ω_out, differential cage at ω_out / i_D.
    index = {b: i for i, b in enumerate(d.body_names)}
    transform = dyn.kinematics.transform
    out_row = transform[index[d.output_shaft], :]
    mass = dyn.mass_matrix + (j_cs + j_d / i_d**2) * (out_row.T * out_row)
    reduced_mass = projection.T * mass * projection

    speeds = tuple(sp.Symbol(naming.speed(s)) for s in keep)
    omega_c = sp.Symbol(naming.WHEEL_SPEED)
    y_dot = projection * sp.Matrix(speeds)
    body_speeds = {b: sp.expand((transform[index[b], :] * y_dot)[0]) for b in d.body_names}
    omega_out = body_speeds[d.output_shaft]

    phi_dot = omega_out / i_d - omega_c  # (2.44)
    t_ss = p["k_ss"] * sp.Symbol(naming.TWIST) + p["d_ss"] * phi_dot  # (2.47)
    t_out = 2 * t_ss / i_d  # (2.52)
    v = r_dyn * omega_c
    zeta, m_veh = p["zeta"], p["m_veh"]
    if d.rolling_resistance == "thesis":
        f_r = v * p["f_roll"] * sp.cos(zeta) * m_veh * g  # (2.49a) as printed
    elif d.rolling_resistance == "textbook":
        f_r = p["f_R"] * sp.cos(zeta) * m_veh * g  # textbook form, forward motion
    else:  # f_Roll(v) as a polynomial in v (forward motion)
        f_roll_v = p["f_R0"] + p["f_R1"] * v + p["f_R2"] * v**2
        f_r = f_roll_v * sp.cos(zeta) * m_veh * g
    f_ad = sp.Rational(1, 2) * v**2 * p["rho_air"] * p["c_W"] * p["A_front"]  # (2.49b)
    f_g = sp.sin(zeta) * m_veh * g  # (2.49c)

    friction = {}
    torque = {e: sym.torque[e] for e in torque_elements}
    if slip_signs is not None:
        # Sliding friction torque T = k_sign 2 N_disc r_m μ F_N (2.69, 3.14) with the known
        # slip direction as k_sign; μ is a parameter, F_N a known input.
        for e in torque_elements:
            gain, normal, mu = friction_symbols(d, e, "needed for mu inputs")
            torque[e] = slip_signs[e] * gain * mu.symbol * normal.symbol
            friction[e] = (torque[e], normal, mu)
        params = params + tuple(friction[e][2] for e in torque_elements)

    column = {str(s): i for i, s in enumerate(dyn.inputs)}
    generalized = dyn.input_matrix[:, column[naming.INPUT_TORQUE]] * sym.torque[naming.INPUT]
    generalized += dyn.input_matrix[:, column[naming.OUTPUT_TORQUE]] * t_out
    for e in torque_elements:
        generalized += dyn.input_matrix[:, column[naming.torque(e)]] * torque[e]
    # Idle shafts: viscous drag −d ω to the housing on each (README "Idle shafts"); its
    # generalized force J_Rᵀ (−d ω) (2.35) and its power d Σ ω².
    drag_power = sp.Integer(0)
    idle = idle_shafts(d)
    if idle:
        drag = exact(idle_drag(d).value)
        for shaft in idle:
            row = transform[index[shaft], :]
            generalized -= drag * row.T * body_speeds[shaft]
            drag_power += drag * body_speeds[shaft] ** 2
    gearbox_rhs = sp.ImmutableMatrix(
        (reduced_mass.inv() * (projection.T * generalized)).applyfunc(sp.expand)
    )
    return DrivetrainParts(
        keep=tuple(keep),
        torque_elements=tuple(torque_elements),
        speeds=speeds,
        gearbox_rhs=gearbox_rhs,
        phi_dot=phi_dot,
        side_shaft_torque=t_ss,
        road_torque=r_dyn * (f_r + f_ad + f_g),
        rolling_and_aero_torque=r_dyn * (f_r + f_ad),
        grade_lever=r_dyn * g,
        wheel_inertia=p["I_wheel"] + m_veh * r_dyn**2,  # (2.46) with the square
        body_speeds=body_speeds,
        parameters=params,
        torque_symbols={
            naming.INPUT: sym.torque[naming.INPUT],
            **{e: sym.torque[e] for e in torque_elements},
        },
        friction=friction,
        drag_power=drag_power,
    )


def drivetrain_model(
    d: GearboxDescription,
    name: str,
    locked: tuple[str, ...] = (),
    torque_elements: tuple[str, ...] | None = None,
    keep: tuple[str, ...] | None = None,
    with_wheel_acceleration: bool = False,
    slip_signs: dict[str, int] | None = None,
    extra_parameters: tuple[Variable, ...] = (),
) -> Model:
    """Gearbox + elastic drivetrain as a :class:`Model` (2.42–2.58).

    ``locked`` elements are constraints, ``torque_elements`` are input torques (all elements
    by default, less the locked ones); every other element is open (zero torque, 2.54).
    ``keep`` names the shafts whose speeds are the gearbox states (default: the generalized
    coordinates when nothing is locked, else input and output shaft). Outputs are the measured
    shaft speeds (those a locked element makes equal to another are dropped) and the wheel
    speed (3.31), optionally the wheel acceleration (3.32). ``extra_parameters``: symbols a
    caller put into ``d``'s quantities (an inertia factor), parameters of the model after the
    description's own.
    """
    parts = drivetrain_parts(d, locked, torque_elements, keep, slip_signs)
    wheel = (2 * parts.side_shaft_torque - parts.road_torque) / parts.wheel_inertia  # (2.50)
    rhs = sp.Matrix([*parts.gearbox_rhs, parts.phi_dot, wheel])
    states = tuple(
        Variable(naming.speed(s), symbol, "rad/s", f"speed of shaft {s}")
        for s, symbol in zip(parts.keep, parts.speeds, strict=True)
    ) + (
        Variable(
            naming.TWIST,
            sp.Symbol(naming.TWIST),
            "rad",
            "side-shaft twist phi_2/i_D - phi_C (2.43)",
        ),
        Variable(naming.WHEEL_SPEED, sp.Symbol(naming.WHEEL_SPEED), "rad/s", "wheel speed"),
    )
    inputs = (
        Variable(
            naming.INPUT_TORQUE,
            parts.torque_symbols[naming.INPUT],
            "N*m",
            "input torque (engine + e-machine)",
        ),
    ) + tuple(
        parts.friction[e][1]
        if e in parts.friction
        else Variable(
            naming.torque(e),
            parts.torque_symbols[e],
            "N*m",
            f"{e} torque: +T on b, -T on a (2.36)",
        )
        for e in parts.torque_elements
    )
    outputs: list[Variable] = []
    output_exprs: list[sp.Expr] = []
    for s in d.measured_shafts:
        expr = parts.body_speeds[s]
        if any(sp.expand(expr - e) == 0 for e in output_exprs):
            continue
        y = naming.measured(naming.speed(s))
        outputs.append(Variable(y, sp.Symbol(y), "rad/s"))
        output_exprs.append(expr)
    y = naming.measured(naming.WHEEL_SPEED)
    outputs.append(Variable(y, sp.Symbol(y), "rad/s", "wheel speed"))
    output_exprs.append(sp.Symbol(naming.WHEEL_SPEED))
    if with_wheel_acceleration:
        y = naming.measured(naming.derivative(naming.WHEEL_SPEED))
        outputs.append(Variable(y, sp.Symbol(y), "rad/s^2", "wheel acceleration"))
        output_exprs.append(wheel)
    metadata = {
        "gearbox": d.name,
        "locked": " ".join(locked),
        "torque_elements": " ".join(parts.torque_elements),
        "equations": "2.42-2.58",
        "rolling_resistance": d.rolling_resistance,
    }
    validity = one_way_validity(d, locked)
    if validity:
        metadata["one_way"] = validity
    idle = idle_note(d)
    if idle:
        metadata["idle"] = idle
    return Model(
        name=name,
        states=states,
        inputs=inputs,
        parameters=(*parts.parameters, *extra_parameters),
        outputs=tuple(outputs),
        rhs=rhs,
        output_expressions=sp.Matrix(output_exprs),
        metadata=metadata,
    )


def one_way_validity(d: GearboxDescription, locked: tuple[str, ...]) -> str:
    """The condition under which a model that treats one-way clutches as locked holds, as text
    for the model's metadata (and so the emitted C header); "" when none is locked.

    A one-way clutch is a unilateral constraint: locked, it carries the reaction torque T of
    the sign it blocks (``locks``, sign convention of 2.36); when T would change sign it
    overruns, and the model with it open (absent, 2.54) holds until its slip reaches zero
    towards the blocked side again. That switch depends on the state and is the caller's.
    """
    parts = []
    for name in locked:
        e = d.element(name)
        if not e.one_way:
            continue
        sign = ">" if e.locks > 0 else "<"
        slip = f"omega_{e.a} - omega_{e.b}" if e.a is not None else f"-omega_{e.b}"
        parts.append(
            f"one-way clutch {name} treated as locked: valid only while its reaction torque "
            f"T_{name} {sign} 0 (the blocking sign); when it would change sign {name} "
            f"overruns and the model with {name} open applies until its slip {slip} "
            f"reaches 0 towards {sign} 0 again (a state-dependent switch the caller applies)"
        )
    return "; ".join(parts)


def full_model(d: GearboxDescription, with_wheel_acceleration: bool = False) -> Model:
    """ẋ_ex = f(x_ex) + B_ex,nl u (2.53): all coordinates, every element an input torque."""
    return drivetrain_model(d, naming.FULL_MODEL, with_wheel_acceleration=with_wheel_acceleration)


def shift_model(
    d: GearboxDescription,
    shift: str,
    with_wheel_acceleration: bool = False,
    friction_inputs: bool = False,
    extra_parameters: tuple[Variable, ...] = (),
) -> Model:
    """Reduced model of a shift (2.55–2.58); for 2-3: x = [ω1, ω2, φ, ω_C],
    u = [T_In, T_K38, T_B05].

    A double swap (two elements off, two on, e.g. 1-5 of the built-in box) has the torque-input
    form only: its common elements locked, the four swapping elements' torques as inputs
    (off-going first), one more shaft speed as a state (:func:`shift_keep`); for 1-5
    x = [ω1, ω2, ω3, φ, ω_C], u = [T_In, T_K38, T_B06, T_K81, T_K27].

    With ``friction_inputs`` the two element torques are sliding friction, k_sign 2 N r μ F_N
    (2.69, 3.14), with the slip directions of a power-on shift (:func:`power_on_slip_signs`),
    μ_<element> as parameters and the normal forces as inputs: u = [T_In, F_N38, F_N05]. A
    swapping one-way clutch has no μ and no F_N: while neither swapping element is locked (the
    shift model's premise) it overruns and carries no torque, so it is absent from u and p
    (the metadata says so); locked, it is a constraint of the gear or hybrid mode instead. A
    swapping dog element is open under the same premise (it cannot carry torque while it
    slips): absent from the μ form, T = 0 in the torque form (metadata ``dog``).
    """
    # the μ form needs each element's power-on slip direction: a single swap only
    spec = shift_spec(d, shift, max_swaps=1 if friction_inputs else 2)
    one_way = [e for e in spec.swapping if d.element(e).one_way] if friction_inputs else []
    dogs = [e for e in spec.swapping if d.element(e).dog]
    if friction_inputs and dogs:
        one_way += dogs  # open: no torque, no μ, no F_N (as an overrunning freewheel)
    model = drivetrain_model(
        d,
        naming.shift_model_name(spec.from_gear, spec.to_gear, friction_inputs),
        locked=spec.locked,
        torque_elements=tuple(e for e in spec.swapping if e not in one_way),
        keep=shift_keep(d, spec),
        with_wheel_acceleration=with_wheel_acceleration,
        slip_signs=power_on_slip_signs(d, spec) if friction_inputs else None,
        extra_parameters=extra_parameters,
    )
    metadata = dict(model.metadata)
    if dogs:
        metadata["dog"] = (
            f"dog element {', '.join(dogs)}: form-locking, it carries no torque while open "
            + ("(absent here: no mu, no normal force)" if friction_inputs else "(T = 0)")
            + " and never slips loaded; engaged it is a constraint (the gear, or the hybrid "
            "mode with it locked), engaging only within its engage_slip"
        )
    free = [e for e in one_way if not d.element(e).dog]
    if free:
        metadata["overrunning"] = (
            f"one-way clutch {', '.join(free)} overrunning (zero torque, no mu, no normal "
            "force): this model holds while it overruns; locked, it is a constraint (the gear, "
            "or the hybrid mode with it locked)"
        )
    if metadata == model.metadata:
        return model
    return replace(model, metadata=metadata)
