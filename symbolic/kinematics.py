"""Stage 2: kinematics of the planetary gearbox (thesis 2.20–2.32).

From a :class:`~gearsym.symbolic.description.GearboxDescription`: the Willis constraints of every
set (2.22–2.23), the body orientations s(y) (2.26, 2.29) and positions r(y) (2.27, 2.30) for the
chosen generalized coordinates y (2.28), and the Jacobians J_R = ∂s/∂y and J_T = ∂r/∂y
(2.31–2.32). All constraints are linear and scleronomic, so s(y) = T·y with a constant matrix T
and the Jacobians are constant (the thesis' argument for k = 0 in 2.33).

Tooth counts and inertias can each be symbols (z_S_1, J_4, …) or exact numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.set_kinds import HOUSING


def exact(value: float | sp.Expr) -> sp.Expr:
    """The decimal number exactly as written in the file (0.054 → 27/500), not its binary float;
    an expression (a quantity a caller made symbolic, e.g. an inertia times a factor) as it is."""
    if isinstance(value, sp.Basic):
        return value
    return sp.Rational(repr(float(value)))


@dataclass(frozen=True)
class GearboxSymbols:
    """Every symbol the derivation uses, and the numeric value of each symbolic parameter.

    Thesis names in ASCII: phi_<body>, omega_<body>, z_S_<set>, z_P_<set>, z_H_<set>,
    r_T_<set>, m_P_<set> (lumped planet mass), J_<body> (lumped for planet bodies), T_In,
    T_Out, T_<element>.
    """

    angle: dict[str, sp.Symbol]
    speed: dict[str, sp.Symbol]
    z_sun: dict[str, sp.Expr]
    z_planet: dict[str, sp.Expr]
    z_ring: dict[str, sp.Expr]
    carrier_radius: dict[str, sp.Expr]
    planet_mass: dict[str, sp.Expr]
    inertia: dict[str, sp.Expr]
    torque: dict[str, sp.Symbol]
    values: dict[sp.Symbol, sp.Rational] = field(default_factory=dict)
    #: Per set, every tooth count by key (``z_sun``, ``z_planet``, ``z_ring``, ``z_sun2``,
    #: ``z_ring2``, ``z_planet2``): the meshes of :mod:`gearsym.symbolic.set_kinds` read them
    #: from here.
    teeth: dict[str, dict[str, sp.Expr]] = field(default_factory=dict)
    #: Lumped mass and orbit radius of every pinion body (m_P, r_T of 2.34 per pinion).
    pinion_mass: dict[str, sp.Expr] = field(default_factory=dict)
    pinion_radius: dict[str, sp.Expr] = field(default_factory=dict)
    #: Per set given by ``k``: its planets' inertia reflected to each member shaft
    #: (``planet_inertia_reflected``), added to that shaft's rotation term of (2.34).
    reflected: dict[str, dict[str, sp.Expr]] = field(default_factory=dict)


def gearbox_symbols(
    d: GearboxDescription, symbolic_teeth: bool = False, symbolic_inertias: bool = False
) -> GearboxSymbols:
    """Symbols (or exact numbers) for teeth, inertias, masses, radii, angles and torques."""
    values: dict[sp.Symbol, sp.Rational] = {}

    def quantity(name: str, value: sp.Rational, symbolic: bool) -> sp.Expr:
        symbol = sp.Symbol(name, positive=True)
        values[symbol] = value
        return symbol if symbolic else value

    z_sun, z_planet, z_ring, radius, mass = {}, {}, {}, {}, {}
    inertia: dict[str, sp.Expr] = {}
    teeth: dict[str, dict[str, sp.Expr]] = {}
    pinion_mass: dict[str, sp.Expr] = {}
    pinion_radius: dict[str, sp.Expr] = {}
    reflected: dict[str, dict[str, sp.Expr]] = {}
    for s in d.shafts:
        inertia[s.name] = quantity(
            naming.inertia(s.name), exact(s.inertia.value), symbolic_inertias
        )
    for ps in d.planetary_sets:
        ps.require_teeth(
            d.file,
            "building the planet bodies of the model (Willis meshes 2.22/2.23)",
            reflected_ok=True,
        )
        j = ps.name
        if ps.given_k is not None:
            # No teeth: the one shaft relation with |i0| (set_relations.relations), and the
            # planets only through their inertia reflected to the members.
            ratio = sp.Rational(abs(ps.given_k.numerator), ps.given_k.denominator)
            teeth[j] = {"k": quantity(naming.stationary_ratio(j), ratio, symbolic_teeth)}
            reflected[j] = {
                getattr(ps, role): quantity(
                    naming.reflected_inertia(j, role), exact(q.value), symbolic_inertias
                )
                for role, q in ps.reflected_inertia
            }
            continue
        z_sun[j] = quantity(naming.sun_teeth(j), sp.Integer(ps.z_sun), symbolic_teeth)
        z_planet[j] = quantity(naming.planet_teeth(j), sp.Integer(ps.z_planet), symbolic_teeth)
        z_ring[j] = quantity(naming.ring_teeth(j), sp.Integer(ps.z_ring), symbolic_teeth)
        n = ps.planet_count
        radius[j] = quantity(
            naming.carrier_radius(j), exact(ps.carrier_radius.value), symbolic_inertias
        )
        mass[j] = quantity(
            naming.planet_mass(j), n * exact(ps.planet_mass.value), symbolic_inertias
        )
        inertia[ps.planet] = quantity(
            naming.inertia(ps.planet), n * exact(ps.planet_inertia.value), symbolic_inertias
        )
        teeth[j] = {"z_sun": z_sun[j], "z_planet": z_planet[j], "z_ring": z_ring[j]}
        pinion_mass[ps.planet] = mass[j]
        pinion_radius[ps.planet] = radius[j]
        if ps.z_sun2 is not None:
            teeth[j]["z_sun2"] = quantity(
                naming.second_sun_teeth(j), sp.Integer(ps.z_sun2), symbolic_teeth
            )
        if ps.z_ring2 is not None:
            teeth[j]["z_ring2"] = quantity(
                naming.second_ring_teeth(j), sp.Integer(ps.z_ring2), symbolic_teeth
            )
        if ps.z_planet2 is not None:
            teeth[j]["z_planet2"] = quantity(
                naming.second_planet_teeth(j), sp.Integer(ps.z_planet2), symbolic_teeth
            )
        if ps.planet2 is not None:
            assert ps.planet2_mass and ps.planet2_inertia and ps.planet2_radius
            pinion_radius[ps.planet2] = quantity(
                naming.second_carrier_radius(j), exact(ps.planet2_radius.value), symbolic_inertias
            )
            pinion_mass[ps.planet2] = quantity(
                naming.second_planet_mass(j), n * exact(ps.planet2_mass.value), symbolic_inertias
            )
            inertia[ps.planet2] = quantity(
                naming.inertia(ps.planet2),
                n * exact(ps.planet2_inertia.value),
                symbolic_inertias,
            )
    # An element named In or Out would overwrite these keys: gearsym.symbolic.naming.check_names
    # rejects it when the description is loaded.
    torque = {
        naming.INPUT: sp.Symbol(naming.INPUT_TORQUE),
        naming.OUTPUT: sp.Symbol(naming.OUTPUT_TORQUE),
    }
    for e in d.shift_elements:
        torque[e.name] = sp.Symbol(naming.torque(e.name))
    return GearboxSymbols(
        angle={b: sp.Symbol(naming.angle(b)) for b in d.body_names},
        speed={b: sp.Symbol(naming.speed(b)) for b in d.body_names},
        z_sun=z_sun,
        z_planet=z_planet,
        z_ring=z_ring,
        carrier_radius=radius,
        planet_mass=mass,
        inertia=inertia,
        torque=torque,
        values=values,
        teeth=teeth,
        pinion_mass=pinion_mass,
        pinion_radius=pinion_radius,
        reflected=reflected,
    )


def willis_constraints(d: GearboxDescription, sym: GearboxSymbols) -> sp.Matrix:
    """G with G·ω = 0: one row per tooth mesh, set by set (2.22 external, 2.23 internal).

    For a simple set these are the thesis' two rows; compound kinds add a row per further
    mesh (:mod:`gearsym.symbolic.set_kinds`).
    """
    index = {b: i for i, b in enumerate(d.body_names)}
    rows = sp.zeros(sum(ps.constraint_count for ps in d.planetary_sets), len(index))
    r = 0
    for ps in d.planetary_sets:
        teeth = sym.teeth[ps.name]
        if ps.given_k is not None:
            # A set given by k: ω_S − i0 ω_H − (1 − i0) ω_C = 0 with i0 = ±k (set_kinds).
            assert not ps.meshes
            i0 = teeth["k"] if ps.given_k > 0 else -teeth["k"]
            for body, coefficient in ((ps.sun, 1), (ps.ring, -i0), (ps.carrier, -(1 - i0))):
                if body != HOUSING:
                    rows[r, index[body]] += coefficient
            r += 1
            continue
        for mesh in ps.meshes:
            za, zb = teeth[mesh.z_a], teeth[mesh.z_b]
            # z_a (ω_a − ω_C) = ∓ z_b (ω_b − ω_C): external meshes reverse the relative
            # rotation, internal ones keep it.
            zb_signed = -zb if mesh.internal else zb
            terms = (
                (getattr(ps, mesh.a), za),
                (ps.carrier, -(za + zb_signed)),
                (getattr(ps, mesh.b), zb_signed),
            )
            for body, coefficient in terms:
                if body != HOUSING:  # a member fixed to the housing: ω = 0, no column
                    rows[r, index[body]] += coefficient
            r += 1
    return rows


def constraint_blocks(d: GearboxDescription) -> list[tuple[int, int]]:
    """Row range [start, stop) of each set's meshes in :func:`willis_constraints`."""
    blocks, start = [], 0
    for ps in d.planetary_sets:
        blocks.append((start, start + ps.constraint_count))
        start += ps.constraint_count
    return blocks


def coordinate_transform(
    d: GearboxDescription, sym: GearboxSymbols, constraints: sp.Matrix
) -> sp.Matrix:
    """T with s = T·y (2.29): every body angle as a linear combination of the coordinates.

    Propagates set by set (a set with two known members gives the other two from its two
    constraints), which keeps the entries in the compact form of (2.29); falls back to one
    linear solve when the topology needs it. Raises when the coordinates are dependent or do
    not determine every body.
    """
    bodies = d.body_names
    f = len(d.coordinates)
    key = "gearbox.coordinates"
    rows: dict[str, sp.Matrix] = {}
    for i, c in enumerate(d.coordinates):
        rows[c] = sp.Matrix.zeros(1, f)
        rows[c][0, i] = 1
    index = {b: i for i, b in enumerate(bodies)}
    progress = True
    while progress and len(rows) < len(bodies):
        progress = False
        for ps, (start, stop) in zip(d.planetary_sets, constraint_blocks(d), strict=True):
            members = tuple(m for m in (*ps.members, *ps.pinions) if m != HOUSING)
            unknown = [m for m in members if m not in rows]
            size = stop - start
            if not unknown or len(unknown) > size:
                continue
            block = constraints[start:stop, :]
            a = sp.Matrix([[block[q, index[m]] for m in unknown] for q in range(size)])
            known = sp.zeros(size, f)
            for m in members:
                if m in rows:
                    known -= block[:, index[m]] * rows[m]
            if size == 2:
                solution = _solve_small(a, known)
            else:
                # A compound set: its members are determined once the block has full column
                # rank in the unknowns; otherwise wait for more known members.
                if a.rank(simplify=True) < len(unknown):
                    continue
                solution = _solve_block(a, known)
            if solution is None:
                raise GearsymError(
                    d.file,
                    key,
                    f"coordinates {list(d.coordinates)} are not independent "
                    f"(planetary set {ps.name!r} relates them)",
                )
            for m, row in zip(unknown, solution, strict=True):
                rows[m] = row
            progress = True
    if len(rows) < len(bodies):
        _solve_remaining(d, constraints, rows, index, f)
    transform = sp.Matrix.vstack(*(rows[b] for b in bodies))
    check = (constraints * transform).applyfunc(sp.cancel)
    if any(entry != 0 for entry in check):
        raise GearsymError(d.file, key, f"coordinates {list(d.coordinates)} are not independent")
    return transform


def _solve_small(a: sp.Matrix, rhs: sp.Matrix) -> list[sp.Matrix] | None:
    """Rows X with a·X = rhs for a 2×u system (u ≤ 2); None when inconsistent."""
    unknowns = a.shape[1]
    if unknowns == 2:
        det = sp.cancel(a.det())
        if det == 0:
            return None
        x = (a.adjugate() * rhs / det).applyfunc(sp.cancel)
        return [x[0, :], x[1, :]]
    # One unknown: take it from the equation where it appears, the other must then hold.
    q = 0 if sp.cancel(a[0, 0]) != 0 else 1
    if sp.cancel(a[q, 0]) == 0:
        return None
    x = (rhs[q, :] / a[q, 0]).applyfunc(sp.cancel)
    other = 1 - q
    if any(sp.cancel(v) != 0 for v in a[other, 0] * x - rhs[other, :]):
        return None
    return [x]


def _solve_block(a: sp.Matrix, rhs: sp.Matrix) -> list[sp.Matrix] | None:
    """Rows X with a·X = rhs for a full-column-rank block; None when inconsistent."""
    try:
        x, free = a.gauss_jordan_solve(rhs)
    except ValueError:
        return None
    assert free.shape[0] == 0
    x = x.applyfunc(sp.cancel)
    return [x[i, :] for i in range(a.shape[1])]


def _solve_remaining(
    d: GearboxDescription,
    constraints: sp.Matrix,
    rows: dict[str, sp.Matrix],
    index: dict[str, int],
    f: int,
) -> None:
    """One linear solve for bodies that set-by-set propagation could not reach."""
    unknown = [b for b in d.body_names if b not in rows]
    a = sp.Matrix.hstack(*(constraints[:, index[b]] for b in unknown))
    rhs = sp.zeros(constraints.shape[0], f)
    for b, row in rows.items():
        rhs -= constraints[:, index[b]] * row
    try:
        solution, free = a.gauss_jordan_solve(rhs)
    except ValueError:
        raise GearsymError(
            d.file, "gearbox.coordinates", f"coordinates {list(d.coordinates)} are not independent"
        ) from None
    if free.shape[0] > 0:
        raise GearsymError(
            d.file,
            "gearbox.coordinates",
            f"coordinates {list(d.coordinates)} do not determine the motion of "
            f"{', '.join(unknown)}",
        )
    for i, b in enumerate(unknown):
        rows[b] = solution[i, :].applyfunc(sp.cancel)


@dataclass(frozen=True)
class Kinematics:
    """s(y) = T·y, r(y), and the constant Jacobians J_R, J_T of every body (2.26–2.32)."""

    bodies: tuple[str, ...]
    coordinates: tuple[str, ...]
    coordinate_symbols: tuple[sp.Symbol, ...]
    constraints: sp.Matrix
    transform: sp.Matrix
    orientation: sp.Matrix
    position: sp.Matrix
    rotation_jacobian: sp.Matrix
    translation_jacobian: sp.Matrix


def kinematics(d: GearboxDescription, sym: GearboxSymbols) -> Kinematics:
    """Derive the gearbox kinematics for the description's generalized coordinates (2.28)."""
    constraints = willis_constraints(d, sym)
    transform = coordinate_transform(d, sym, constraints)
    y = sp.Matrix([sym.angle[c] for c in d.coordinates])
    orientation = transform * y
    # Shafts do not translate; a planet's centre moves on the carrier circle, so its
    # cylindrical position coordinate is r_T·φ_carrier (2.27, 2.30).
    index = {b: i for i, b in enumerate(d.body_names)}
    position = sp.zeros(len(d.body_names), 1)
    translation = sp.zeros(len(d.body_names), len(d.coordinates))
    for ps in d.planetary_sets:
        if ps.carrier == HOUSING:
            continue  # pinions on a fixed carrier spin in place: no orbit
        carrier_row = transform[index[ps.carrier], :]
        for pinion in ps.pinions:
            i = index[pinion]
            radius = sym.pinion_radius[pinion]
            position[i] = radius * orientation[index[ps.carrier]]
            translation[i, :] = radius * carrier_row
    return Kinematics(
        bodies=d.body_names,
        coordinates=d.coordinates,
        coordinate_symbols=tuple(y),
        constraints=constraints,
        transform=transform,
        orientation=orientation,
        position=position,
        rotation_jacobian=transform,
        translation_jacobian=translation,
    )
