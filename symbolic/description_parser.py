"""Stage 1, reading: a description file's TOML parsed and checked into a
:class:`~gearsym.symbolic.description.GearboxDescription`.

Every key is typed, in its unit and inside its stated limits; the structure is checked (each
shaft, set member and element named once and referred to by name, sets that can be built,
the gear table's elements known) and so are the names the derivation will make of it
(:func:`gearsym.symbolic.naming.check_names`). Like the data it returns, it imports nothing
of the derivation (no SymPy): the gear table against the teeth (Table 2.1) is checked by the
one loader that does both, :func:`gearsym.symbolic.loader.load_description`.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace
from fractions import Fraction
from typing import Any

from gearsym.symbolic import set_kinds
from gearsym.symbolic.control_calibration import parse_control_table
from gearsym.symbolic.description import (
    CENTRE_DISTANCE_TOLERANCE_MAX,
    DOG,
    DOG_ENGAGE_SLIP_DEFAULT,
    DOG_RELEASE_TORQUE_DEFAULT,
    EXPECTED_UNITS,
    LOCK_DIRECTIONS,
    N_DISC_MAX,
    ONE_WAY,
    PLANET_COUNT_MAX,
    PLANET_SPACINGS,
    RATIO_DECIMALS_MAX,
    REFLECTED_KEY,
    REFLECTED_REPLACES,
    ROLLING_RESISTANCE_FORMS,
    SECTION_UNITS,
    SIGNED_QUANTITIES,
    TEETH_MAX,
    Gear,
    GearboxDescription,
    PlanetarySet,
    Quantity,
    Shaft,
    ShiftElement,
    pinion_pair_problem,
    planets_fit,
)
from gearsym.symbolic.drive_calibration import parse_drive_table
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import parse_estimator_table
from gearsym.symbolic.io.input_files import parse_toml, shown
from gearsym.symbolic.io.table_reader import TableReader as _Reader
from gearsym.symbolic.io.table_reader import short_integer
from gearsym.symbolic.naming import check_names

#: The keys only a dog element has.
DOG_KEYS = ("engage_slip", "release_torque")


def _label(reader: _Reader, name: str) -> None:
    """Use the entry's name in its key path, e.g. ``planetary_set[name="2"]``."""
    reader.path = re.sub(r"\[\d+\]$", f'[name="{name}"]', reader.path)


def parse_description(
    text: str, file: str = "<string>", *, teeth_optional: bool = False
) -> GearboxDescription:
    """Parse and check a description; raise :class:`GearsymError` on the first problem.

    ``teeth_optional`` (``gearsym fit-teeth`` only): a planetary set may leave out its tooth
    counts (or give 0 as a placeholder), its planet count and its pinion data; such a set
    has :attr:`PlanetarySet.teeth_given` false, tooth counts 0 and is not checked for
    buildability (the search proposes buildable teeth for it).
    """
    data = parse_toml(text, file)
    root = _Reader(file, data, "")

    gearbox = root.table("gearbox")
    name = gearbox.name()
    title = gearbox.string("title", required=False, default=name)
    input_shaft = gearbox.string("input_shaft")
    output_shaft = gearbox.string("output_shaft")
    measured = gearbox.string_list("measured_shafts", required=False)
    coordinates_given = gearbox.string_list("coordinates", required=False)
    gearbox.reject_unknown()

    shafts: list[Shaft] = []
    for r in root.tables("shaft"):
        shaft_name = r.name()
        _label(r, shaft_name)
        shafts.append(Shaft(shaft_name, r.quantity("inertia")))
        r.reject_unknown()
    if not shafts:
        raise root.fail("shaft", "a gearbox needs at least one [[shaft]]")

    sets: list[PlanetarySet] = []
    for r in root.tables("planetary_set"):
        set_name = r.name()
        _label(r, set_name)
        sets.append(_planetary_set(r, set_name, teeth_optional))

    elements: list[ShiftElement] = []
    for r in root.tables("shift_element"):
        element_name = r.name()
        _label(r, element_name)
        kind = r.string("kind")
        if kind == ONE_WAY:
            elements.append(_one_way(r, element_name))
            r.reject_unknown()
            continue
        if kind == DOG:
            elements.append(_dog(r, element_name))
            r.reject_unknown()
            continue
        if kind == "clutch":
            pair = r.string_list("shafts")
            if len(pair) != 2:
                raise r.fail("shafts", "a clutch joins exactly two shafts [a, b]")
            if pair[0] == pair[1]:
                raise r.fail("shafts", f"a clutch must join two different shafts, got {pair}")
        elif kind == "brake":
            pair = (r.string("shaft"),)
        else:
            raise r.fail(
                "kind", f"expected 'clutch', 'brake', 'one_way' or 'dog', got {shown(kind)}"
            )
        if "locks" in r.data:
            raise r.fail(
                "locks", f"only a one-way clutch has a locking direction; this is a {kind}"
            )
        for key in DOG_KEYS:
            if key in r.data:
                raise r.fail(key, f'only a dog element (kind = "dog") has {key}; this is a {kind}')
        has_friction = any(k in r.data for k in ("n_disc", "r_m", "a_piston"))
        elements.append(
            ShiftElement(
                element_name,
                kind,
                pair,
                n_disc=r.positive_integer("n_disc", maximum=N_DISC_MAX) if has_friction else None,
                r_m=r.quantity("r_m", unit="m") if has_friction else None,
                a_piston=r.quantity("a_piston", unit="m^2") if has_friction else None,
            )
        )
        r.reject_unknown()

    table = root.table("gear_table", required=False)
    decimals = table.integer("ratio_decimals", required=False, default=3)
    if not 0 <= decimals <= RATIO_DECIMALS_MAX:
        raise table.fail(
            "ratio_decimals",
            f"must be 0 to {RATIO_DECIMALS_MAX} (decimals of a double), got "
            f"{short_integer(decimals)}",
        )
    table_source = table.string("source", required=False, default="")
    table.reject_unknown()

    gears: list[Gear] = []
    for r in root.tables("gear"):
        gear_name = r.name()
        _label(r, gear_name)
        closed = r.string_list("closed")
        neutral = r.boolean("neutral")
        ratio = r.number("ratio", required=False)
        if neutral and ratio is not None:
            raise r.fail("ratio", "a neutral gear has no ratio")
        if not neutral and ratio is None:
            raise r.fail("ratio", "missing required key (or set neutral = true)")
        if ratio == 0:
            raise r.fail("ratio", "a gear ratio cannot be zero")
        gears.append(Gear(gear_name, closed, ratio, neutral))
        r.reject_unknown()

    sections: dict[str, dict[str, Quantity]] = {}
    rolling = "thesis"
    mu_map = "built-in"
    for section, units in SECTION_UNITS.items():
        r = root.table(section, required=False)
        values: dict[str, Quantity] = {}
        for key, unit in units.items():
            if key in r.data:
                values[key] = r.quantity(key, positive=key not in SIGNED_QUANTITIES, unit=unit)
        if section == "vehicle":
            rolling = r.string("rolling_resistance", required=False, default="thesis")
            if rolling not in ROLLING_RESISTANCE_FORMS:
                raise r.fail(
                    "rolling_resistance",
                    f"expected 'thesis', 'textbook' or 'polynomial', got {shown(rolling)}",
                )
        if section == "friction":
            mu_map = r.string("mu_map", required=False, default="built-in")
        r.reject_unknown()
        sections[section] = values
    estimator_table = root.table("estimator", required=False)  # read once the shafts are checked
    drive = parse_drive_table(root.table("drive", required=False))
    control = parse_control_table(root.table("control", required=False))
    root.reject_unknown()

    description = GearboxDescription(
        name=name,
        title=title,
        file=file,
        input_shaft=input_shaft,
        output_shaft=output_shaft,
        measured_shafts=measured,
        coordinates=coordinates_given,
        shafts=tuple(shafts),
        planetary_sets=tuple(sets),
        shift_elements=tuple(elements),
        gears=tuple(gears),
        ratio_decimals=decimals,
        gear_table_source=table_source,
        drivetrain=sections["drivetrain"],
        vehicle=sections["vehicle"],
        friction=sections["friction"],
        rolling_resistance=rolling,
        mu_map=mu_map,
    )
    _check_references(description)
    description = replace(
        description,
        estimator=parse_estimator_table(
            estimator_table, [s.name for s in shafts], [g.name for g in gears]
        ),
        drive=drive,
        control=control,
    )
    if not description.coordinates:
        # Default generalized coordinates: the first f shafts (thesis 2.28 names them).
        description = _replace_coordinates(description)
    check_names(description)
    return description


def _planetary_set(r: _Reader, set_name: str, teeth_optional: bool = False) -> PlanetarySet:
    """One ``[[planetary_set]]`` of any kind; the keys a kind does not have are unknown keys.

    With ``teeth_optional`` a set without tooth counts (keys absent or 0) is accepted
    unchecked, and so are absent planet count and pinion data (placeholders of value 0).
    """
    kind = r.string("kind", required=False, default="simple")
    if kind not in set_kinds.KINDS:
        raise r.fail("kind", f"expected one of {', '.join(set_kinds.KINDS)}; got {shown(kind)}")
    key_of = {name: key for key, name in set_kinds.EXTRA_KEYS[kind].items()}
    members = {role: r.string(role) for role in ("sun", "carrier", "ring")}
    planet = r.name("planet")
    given_k = _given_k(r, kind)
    teeth_keys = ("z_sun", "z_planet", "z_ring", *_teeth_keys(kind))
    # fit-teeth: a set whose teeth are all absent or 0 is searched from the ratio targets.
    teeth_given = not (
        teeth_optional and given_k is None and all(r.data.get(k, 0) == 0 for k in teeth_keys)
    )
    teeth_needed = given_k is None and teeth_given
    z_sun = r.positive_integer("z_sun", maximum=TEETH_MAX) if teeth_needed else 0
    z_planet = r.positive_integer("z_planet", maximum=TEETH_MAX) if teeth_needed else 0
    z_ring = r.positive_integer("z_ring", maximum=TEETH_MAX) if teeth_needed else 0
    lenient = not teeth_given
    if lenient:
        r.used.update(k for k in teeth_keys if k in r.data)
    count = (
        r.integer("planet_count", required=False)
        if lenient and r.data.get("planet_count", 0) == 0
        else r.positive_integer("planet_count", maximum=PLANET_COUNT_MAX)
    )

    def quantity(key: str, unit: str | None = None) -> Quantity:
        if lenient and key not in r.data:
            return Quantity(0.0, unit or EXPECTED_UNITS.get(key, ""), "not given (fit-teeth)")
        return r.quantity(key, unit=unit)

    extra: dict[str, Any] = {}
    if "sun2" in key_of:
        extra["sun2"] = r.string(key_of["sun2"])
        extra["z_sun2"] = (
            r.positive_integer(key_of["z_sun2"], maximum=TEETH_MAX) if teeth_given else 0
        )
    if "ring2" in key_of:
        extra["ring2"] = r.string(key_of["ring2"])
        extra["z_ring2"] = (
            r.positive_integer(key_of["z_ring2"], maximum=TEETH_MAX) if teeth_given else 0
        )
    reflected = _reflected_inertia(r, kind, members, given_k)
    if reflected:
        # the planets' mass, inertia and orbit radius are inside the reflected values
        replaced = REFLECTED_REPLACES + tuple(
            key_of[field]
            for field in ("planet2", "planet2_mass", "planet2_inertia", "planet2_radius")
            if field in key_of
        )
        for key in replaced:
            if key in r.data:
                raise r.fail(
                    key,
                    f"the planets of a set with {REFLECTED_KEY} enter through it "
                    "(spin and orbit); leave out " + ", ".join(replaced),
                )
    if "planet2" in key_of and not reflected:
        extra["planet2"] = r.name(key_of["planet2"])
        extra["planet2_mass"] = quantity(key_of["planet2_mass"], unit="kg")
        extra["planet2_inertia"] = quantity(key_of["planet2_inertia"], unit="kg*m^2")
        extra["planet2_radius"] = quantity(key_of["planet2_radius"], unit="m")
    if "z_planet2" in key_of and given_k is None:
        extra["z_planet2"] = (
            r.positive_integer(key_of["z_planet2"], maximum=TEETH_MAX) if teeth_given else 0
        )
    tolerance = r.number("centre_distance_tolerance", required=False)
    if tolerance is not None and not 0 <= tolerance <= CENTRE_DISTANCE_TOLERANCE_MAX:
        raise r.fail(
            "centre_distance_tolerance",
            f"must be 0 to {CENTRE_DISTANCE_TOLERANCE_MAX} modules, got {tolerance:g}",
        )
    spacing = r.string("planet_spacing", required=False, default="equal")
    if spacing not in PLANET_SPACINGS:
        raise r.fail(
            "planet_spacing", f"expected one of {', '.join(PLANET_SPACINGS)}; got {shown(spacing)}"
        )
    if reflected:
        lumped = Quantity(0.0, "", f"in {REFLECTED_KEY}")
        planet_mass = planet_inertia = carrier_radius = lumped
    else:
        planet_mass = quantity("planet_mass")
        planet_inertia = quantity("planet_inertia")
        carrier_radius = quantity("carrier_radius")
    ps = PlanetarySet(
        name=set_name,
        sun=members["sun"],
        carrier=members["carrier"],
        ring=members["ring"],
        planet=planet,
        z_sun=z_sun,
        z_planet=z_planet,
        z_ring=z_ring,
        planet_count=count,
        planet_mass=planet_mass,
        planet_inertia=planet_inertia,
        carrier_radius=carrier_radius,
        teeth_source=r.string("teeth_source", required=not lenient),
        kind=kind,
        centre_distance_tolerance=tolerance or 0.0,
        given_k=given_k,
        planet_spacing=spacing,
        reflected_inertia=reflected,
        teeth_given=teeth_given,
        **extra,
    )
    for key in r.data:
        owners = [k for k, keys in set_kinds.EXTRA_KEYS.items() if key in keys]
        if key not in r.used and owners:
            raise r.fail(key, f"belongs to kind {' or '.join(owners)}; this set is {kind!r}")
    r.reject_unknown()
    if teeth_needed:
        _check_set(r, ps)
    return ps


#: Sign of the stationary ratio i0 per kind that may give ``k`` (set_relations.relations).
K_SIGN: dict[str, int] = {"simple": -1, "double_pinion": 1, "stepped_planet": -1}


def _given_k(r: _Reader, kind: str) -> Fraction | None:
    """The optional ``k`` of a set: its signed stationary ratio i0 = (ω_S − ω_C)/(ω_H − ω_C)
    with the carrier held (Willis, thesis 2.22/2.23 with the planet eliminated), negative for
    simple and stepped-planet sets (i0 = −z_H/z_S), positive for double-pinion sets; exact as
    written in decimal (−2.1 is −21/10). Teeth keys beside it are an error."""
    value = r.number("k", required=False)
    if value is None:
        return None
    if kind not in K_SIGN:
        raise r.fail("k", f"a {kind} set has two stationary ratios; give its tooth counts")
    teeth = [key for key in ("z_sun", "z_planet", "z_ring", *_teeth_keys(kind)) if key in r.data]
    if teeth:
        raise r.fail("k", f"give either k or tooth counts, not both (also {', '.join(teeth)})")
    sign = K_SIGN[kind]
    # z_H > z_S in a simple or double-pinion set, so |k| > 1; a stepped planet may go below 1.
    least = 0 if kind == "stepped_planet" else 1
    if value * sign <= least or abs(value) > TEETH_MAX:
        bound = ("< " if sign < 0 else "> ") + str(least * sign)
        raise r.fail("k", f"a {kind} set needs k {bound} (and |k| <= {TEETH_MAX}), got {value:g}")
    return Fraction(repr(value))


def _reflected_inertia(
    r: _Reader, kind: str, members: dict[str, str], given_k: Fraction | None
) -> tuple[tuple[str, Quantity], ...]:
    """``planet_inertia_reflected = { sun = J_S, carrier = J_T, ring = J_H, unit = "kg*m^2",
    source = "..." }`` of a set given by ``k``: inertias on the members whose kinetic energy
    ½ (J_S ω_S² + J_T ω_T² + J_H ω_H²) equals that of the set's planets (spin and orbit,
    2.34) for every motion the set allows. The three are unique (holding each member in turn
    gives three independent equations); one may be negative, but the energy may not.
    A member on the housing has no entry (it does not turn)."""
    value = r._get(REFLECTED_KEY, False)
    if value is None:
        return ()
    if given_k is None:
        raise r.fail(
            REFLECTED_KEY,
            "only a set given by k needs it: with tooth counts the planet bodies are derived "
            "(planet_mass, planet_inertia, carrier_radius)",
        )
    if not isinstance(value, dict):
        raise r.fail(
            REFLECTED_KEY,
            'expected { sun = <number>, carrier = <number>, ring = <number>, unit = "kg*m^2", '
            'source = "..." }',
        )
    sub = _Reader(r.file, value, r.key(REFLECTED_KEY))
    unit = sub.string("unit")
    if unit != "kg*m^2":
        raise sub.fail("unit", f"expected 'kg*m^2', got {unit!r}")
    source = sub.string("source")
    if not source.strip():
        raise sub.fail("source", "must say where the values come from (or 'assumed')")
    entries: list[tuple[str, Quantity]] = []
    for role in ("sun", "carrier", "ring"):
        if members[role] == set_kinds.HOUSING:
            if role in sub.data:
                raise sub.fail(role, f"the {role} is the housing (it does not turn): leave it out")
            sub.used.add(role)
            continue
        number = sub.number(role)
        assert number is not None
        entries.append((role, Quantity(number, unit, source)))
    sub.reject_unknown()
    _check_reflected_energy(sub, given_k, dict(entries), members)
    return tuple(entries)


def _check_reflected_energy(
    r: _Reader, i0: Fraction, inertia: dict[str, Quantity], members: dict[str, str]
) -> None:
    """The reflected planet energy may not be negative for any motion of the set.

    Motions of a set with the Willis relation ω_S − i0 ω_H − (1 − i0) ω_C = 0, by
    (ω_S, ω_C): ω_H = (ω_S − (1 − i0) ω_C)/i0; a member on the housing is held at 0."""
    j = {role: Fraction(repr(q.value)) for role, q in inertia.items()}
    # (ω_S, ω_C, ω_H) of the two basis motions: sun alone with the carrier held; carrier alone
    basis = [(Fraction(1), Fraction(0), 1 / i0), (Fraction(0), Fraction(1), -(1 - i0) / i0)]
    fixed = [role for role in ("sun", "carrier", "ring") if members[role] == set_kinds.HOUSING]
    if fixed:
        # the motions with that member at rest: one line through the origin
        k = ("sun", "carrier", "ring").index(fixed[0])
        a, b = basis
        basis = [tuple(b[k] * x - a[k] * y for x, y in zip(a, b, strict=True))]
    roles = ("sun", "carrier", "ring")
    q = [
        [sum((j.get(m, 0) * u[n] * v[n] for n, m in enumerate(roles)), Fraction(0)) for v in basis]
        for u in basis
    ]
    diagonal_ok = all(q[i][i] >= 0 for i in range(len(q)))
    determinant_ok = len(q) == 1 or q[0][0] * q[1][1] - q[0][1] ** 2 >= 0
    if not (diagonal_ok and determinant_ok):
        raise r.fail(
            "carrier",
            "the reflected inertias give the planets a negative kinetic energy for some motion "
            "of the set (½ Σ J ω² over sun, carrier, ring must be >= 0 wherever the Willis "
            "relation holds)",
        )


def _teeth_keys(kind: str) -> tuple[str, ...]:
    return tuple(key for key, name in set_kinds.EXTRA_KEYS[kind].items() if name.startswith("z_"))


def _one_way(r: _Reader, name: str) -> ShiftElement:
    """A ``kind = "one_way"`` element: ``shafts = [a, b]`` (between two shafts) or
    ``shaft = b`` (to the housing), and ``locks = "positive" | "negative"``, the sign of the
    slip ω_a − ω_b (2.59) it prevents. A freewheel has no piston and no discs: the friction
    keys of a clutch or brake are refused."""
    pair = _clutch_or_brake_shafts(r, "a one-way clutch")
    direction = r.string("locks")
    if direction not in LOCK_DIRECTIONS:
        raise r.fail(
            "locks",
            "expected 'positive' or 'negative' (the sign of the slip ω_a − ω_b the freewheel "
            f"prevents), got {shown(direction)}",
        )
    for key in ("n_disc", "r_m", "a_piston"):
        if key in r.data:
            raise r.fail(key, "a one-way clutch has no discs or piston (it is not pressed)")
    return ShiftElement(name, ONE_WAY, pair, locks=LOCK_DIRECTIONS[direction])


def _clutch_or_brake_shafts(r: _Reader, what: str) -> tuple[str, ...]:
    """``shafts = [a, b]`` (between two shafts) or ``shaft = b`` (to the housing) of a
    one-way clutch or a dog element."""
    if "shafts" in r.data and "shaft" in r.data:
        raise r.fail(
            "shaft",
            "give shafts = [a, b] (between two shafts) or shaft = b (to the housing), not both",
        )
    if "shafts" in r.data:
        pair = r.string_list("shafts")
        if len(pair) != 2:
            raise r.fail(
                "shafts",
                f"{what} joins exactly two shafts [a, b] (or shaft = b for one to the housing)",
            )
        if pair[0] == pair[1]:
            raise r.fail("shafts", f"{what} must join two different shafts, got {list(pair)}")
        return pair
    if "shaft" not in r.data:
        raise r.fail(
            "shafts", f"{what} needs shafts = [a, b] (a clutch) or shaft = b (a brake); missing"
        )
    return (r.string("shaft"),)


def _dog(r: _Reader, name: str) -> ShiftElement:
    """A ``kind = "dog"`` element (README "Dog clutches"): ``shafts = [a, b]`` (a dog clutch)
    or ``shaft = b`` (a dog brake), optional ``engage_slip`` (rad/s) and ``release_torque``
    (N·m) with stated defaults. Form-locking: no discs, no piston, no locking direction."""
    pair = _clutch_or_brake_shafts(r, "a dog element")
    for key in ("n_disc", "r_m", "a_piston"):
        if key in r.data:
            raise r.fail(
                key,
                "a dog element is form-locking: it has no friction discs or piston (no sliding "
                "friction, no μ, no F_N); leave out n_disc, r_m and a_piston",
            )
    if "locks" in r.data:
        raise r.fail("locks", "only a one-way clutch has a locking direction; this is a dog")
    engage = (
        r.quantity("engage_slip", unit="rad/s")
        if "engage_slip" in r.data
        else Quantity(DOG_ENGAGE_SLIP_DEFAULT, "rad/s", "default (assumed)")
    )
    release = (
        r.quantity("release_torque", unit="N*m")
        if "release_torque" in r.data
        else Quantity(DOG_RELEASE_TORQUE_DEFAULT, "N*m", "default (assumed)")
    )
    return ShiftElement(name, DOG, pair, engage_slip=engage, release_torque=release)


def _replace_coordinates(d: GearboxDescription) -> GearboxDescription:

    return replace(d, coordinates=d.shaft_names[: d.degrees_of_freedom])


def _check_set(r: _Reader, ps: PlanetarySet) -> None:
    """Buildability of one set, per kind (README "Planetary set kinds"), in module units.

    simple: coaxial (z_H = z_S + 2 z_P), equal spacing ((z_S + z_H) / n ∈ ℤ), neighbours clear.
    stepped planet: coaxial (z_S + z_P = z_H − z_P2), equal spacing
    ((z_S z_P2 + z_H z_P) / (n·gcd(z_P, z_P2)) ∈ ℤ), neighbours clear.
    double pinion: the inner/outer pinion centres form a triangle with the set axis, the
    pinions clear the ring and the sun, equal spacing ((z_H − z_S) / n ∈ ℤ).
    Ravigneaux: the long pinion as a simple set, the short pinion as a double pinion
    (triangle, ring clearance), equal spacing of both pairs.
    Ravigneaux with two rings: the long pinion as a simple set with the first ring; long
    and short pinion as a double pinion between the sun and the second ring (triangle,
    clearances, (z_ring_short − z_sun) / n ∈ ℤ).
    A coaxiality error up to ``centre_distance_tolerance`` modules is accepted (profile shift).
    """
    if ps.kind in ("simple", "ravigneaux", "ravigneaux_two_rings"):
        _check_coaxial(r, ps, ps.z_sun + ps.z_planet, ps.z_ring - ps.z_planet, "z_ring")
        _check_spacing(r, ps, ps.z_sun + ps.z_ring, "(z_sun + z_ring)")
        _check_neighbours(r, ps, ps.z_sun, ps.z_planet)
    if ps.kind == "stepped_planet":
        assert ps.z_planet2 is not None
        _check_coaxial(
            r, ps, ps.z_sun + ps.z_planet, ps.z_ring - ps.z_planet2, "z_planet_ring", stepped=True
        )
        g = math.gcd(ps.z_planet, ps.z_planet2)
        assembly = ps.z_sun * ps.z_planet2 + ps.z_ring * ps.z_planet
        if ps.planet_spacing == "equal" and assembly % (ps.planet_count * g) != 0:
            raise r.fail(
                "planet_count",
                f"{ps.planet_count} stepped planets cannot be assembled equally spaced: "
                f"z_sun z_planet_ring + z_ring z_planet = "
                f"{ps.z_sun * ps.z_planet2 + ps.z_ring * ps.z_planet} is not divisible by "
                f"planet_count·gcd(z_planet, z_planet_ring) = {ps.planet_count * g}",
            )
        _check_neighbours(r, ps, ps.z_sun, ps.z_planet)
    if ps.kind == "double_pinion":
        assert ps.z_planet2 is not None
        _check_pinion_pair(r, ps, ps.z_sun, ps.z_planet, ps.z_planet2, "z_planet_outer")
        _check_spacing(r, ps, ps.z_ring - ps.z_sun, "(z_ring − z_sun)")
    if ps.kind == "ravigneaux":
        assert ps.z_planet2 is not None and ps.z_sun2 is not None
        # The short pinion meshes the second sun and the long pinion (whose centre sits at
        # (z_ring − z_planet)/2): the double-pinion triangle with the long pinion outside.
        _check_pinion_pair(r, ps, ps.z_sun2, ps.z_planet2, ps.z_planet, "z_planet_short")
        _check_spacing(r, ps, ps.z_ring - ps.z_sun2, "(z_ring − z_sun_short)")
    if ps.kind == "ravigneaux_two_rings":
        assert ps.z_planet2 is not None and ps.z_ring2 is not None
        # The long pinion (centre (z_sun + z_planet)/2) meshes the short pinion, whose centre
        # sits at (z_ring_short − z_planet_short)/2: the double-pinion triangle with the long
        # pinion inside; the short pinion must clear the sun, the long one the second ring.
        problem = pinion_pair_problem(
            ps.z_sun, ps.z_planet, ps.z_planet2, ps.z_ring2, outer_clears_sun=True
        )
        if problem:
            raise r.fail("z_planet_short", problem)
        _check_spacing(r, ps, ps.z_ring2 - ps.z_sun, "(z_ring_short − z_sun)")


def _check_coaxial(
    r: _Reader, ps: PlanetarySet, inner: int, outer: int, key: str, stepped: bool = False
) -> None:
    """Sun–planet and planet–ring centre distances (in modules: half the tooth sums) agree."""
    error = abs(inner - outer) / 2
    tolerance = ps.centre_distance_tolerance
    if error <= tolerance:
        return
    if tolerance:
        reason = (
            f"centre distances sun–planet {inner / 2:g} and planet–ring {outer / 2:g} modules "
            f"differ by {error:g}, more than centre_distance_tolerance = {tolerance:g}"
        )
    elif stepped:
        reason = (
            f"z_sun + z_planet = {inner} must equal z_ring − z_planet_ring = {outer} "
            "(same module, coaxial)"
        )
    else:
        reason = (
            f"z_ring must equal z_sun + 2 z_planet = {ps.z_sun + 2 * ps.z_planet} "
            f"(same module, coaxial), got {ps.z_ring}"
        )
    hint = "" if tolerance else "; profile-shifted teeth need centre_distance_tolerance"
    raise r.fail(key, reason + hint)


def _check_spacing(r: _Reader, ps: PlanetarySet, teeth: int, formula: str) -> None:
    if ps.planet_spacing == "equal" and teeth % ps.planet_count != 0:
        raise r.fail(
            "planet_count",
            f"{ps.planet_count} planets cannot be assembled equally spaced: "
            f"{formula} = {teeth} is not divisible by {ps.planet_count} "
            '(planet_spacing = "unequal" accepts it)',
        )


def _check_neighbours(r: _Reader, ps: PlanetarySet, z_sun: int, z_planet: int) -> None:
    if not planets_fit(z_sun, z_planet, ps.planet_count):
        raise r.fail(
            "planet_count",
            f"{ps.planet_count} planets of {z_planet} teeth collide around a sun of "
            f"{z_sun} teeth (need (z_sun + z_planet)·sin(π/n) > z_planet + 2)",
        )


def _check_pinion_pair(
    r: _Reader, ps: PlanetarySet, z_sun: int, z_inner: int, z_outer: int, key: str
) -> None:
    """A pinion meshing the sun (inner) and a pinion meshing the ring (outer), meshing each
    other: :func:`pinion_pair_problem`, raised on ``key``."""
    problem = pinion_pair_problem(
        z_sun, z_inner, z_outer, ps.z_ring, outer_clears_sun=ps.kind == "double_pinion"
    )
    if problem:
        raise r.fail(key, problem)


def _check_references(d: GearboxDescription) -> None:
    f = d.file
    shaft_names = d.shaft_names
    _no_duplicates(f, "shaft", shaft_names)
    for name in (*shaft_names, *d.planet_names):
        if name.casefold() == set_kinds.HOUSING:
            # "housing" as a set member means the fixed housing (no body, ω = 0).
            where = (
                f'shaft[name="{name}"].name'
                if name in shaft_names
                else next(
                    f'planetary_set[name="{ps.name}"]'
                    for ps in d.planetary_sets
                    if name in ps.pinions
                )
            )
            raise GearsymError(
                f, where, f"{name!r} is reserved: a set member named housing is fixed"
            )
    _no_duplicates(f, "planetary_set", [s.name for s in d.planetary_sets])
    _no_duplicates(f, "shift_element", [e.name for e in d.shift_elements])
    _no_duplicates(f, "gear", [g.name for g in d.gears])
    seen_planets: set[str] = set()
    for ps in d.planetary_sets:
        key = f'planetary_set[name="{ps.name}"]'
        roles = set_kinds.MEMBERS[ps.kind]
        for role in roles:
            shaft = getattr(ps, role)
            if shaft not in shaft_names and shaft != set_kinds.HOUSING:
                where = f"{key}.{set_kinds.file_key(ps.kind, role)}"
                raise GearsymError(f, where, f"unknown shaft {shown(shaft)}")
        if len(set(ps.members)) != len(roles):
            what = ", ".join(set_kinds.file_key(ps.kind, role) for role in roles)
            raise GearsymError(f, key, f"{what} must be {len(roles)} different shafts")
        for role in set_kinds.PINIONS[ps.kind]:
            body = getattr(ps, role)
            if body in shaft_names or body in seen_planets:
                raise GearsymError(
                    f,
                    f"{key}.{set_kinds.file_key(ps.kind, role)}",
                    f"planet body {body!r} is already a shaft or a planet",
                )
            seen_planets.add(body)
    for e in d.shift_elements:
        for shaft in e.shafts:
            if shaft == set_kinds.HOUSING:
                key = "shafts" if e.a is not None else "shaft"
                raise GearsymError(
                    f,
                    f'shift_element[name="{e.name}"].{key}',
                    "the housing is fixed: an element holding a shaft to it is a brake "
                    '(kind = "brake", shaft = "<the shaft>")'
                    + (
                        '; a freewheel to the housing has shaft = "<the shaft>"'
                        if e.one_way
                        else ""
                    ),
                )
            if shaft not in shaft_names:
                key = "shafts" if e.a is not None else "shaft"
                raise GearsymError(
                    f, f'shift_element[name="{e.name}"].{key}', f"unknown shaft {shown(shaft)}"
                )
    for key, shaft in (("input_shaft", d.input_shaft), ("output_shaft", d.output_shaft)):
        if shaft not in shaft_names:
            raise GearsymError(f, f"gearbox.{key}", f"unknown shaft {shown(shaft)}")
    if d.input_shaft == d.output_shaft:
        raise GearsymError(f, "gearbox.output_shaft", "input and output shaft must differ")
    for shaft in d.measured_shafts:
        if shaft not in shaft_names:
            raise GearsymError(f, "gearbox.measured_shafts", f"unknown shaft {shown(shaft)}")
    body_names = d.body_names
    for body in d.coordinates:
        if body not in body_names:
            raise GearsymError(f, "gearbox.coordinates", f"unknown shaft or planet {shown(body)}")
    _no_duplicates(f, "gearbox.coordinates", d.coordinates, plain=True)
    if d.degrees_of_freedom < 1:
        raise GearsymError(
            f, "planetary_set", f"the gearbox has {d.degrees_of_freedom} degrees of freedom"
        )
    if d.coordinates and len(d.coordinates) != d.degrees_of_freedom:
        raise GearsymError(
            f,
            "gearbox.coordinates",
            f"the gearbox has {d.degrees_of_freedom} degrees of freedom (2.24), "
            f"so it needs {d.degrees_of_freedom} coordinates, got {len(d.coordinates)}",
        )
    element_names = {e.name for e in d.shift_elements}
    for g in d.gears:
        key = f'gear[name="{g.name}"].closed'
        for element in g.closed:
            if element not in element_names:
                raise GearsymError(f, key, f"unknown shift element {shown(element)}")
        _no_duplicates(f, key, g.closed, plain=True)


def _no_duplicates(file: str, key: str, names: Any, plain: bool = False) -> None:
    # Ignoring case: names become parts of file names, include guards and upper-case macros.
    seen: dict[str, str] = {}
    for n in names:
        if n.casefold() in seen:
            where = key if plain else f'{key}[name="{n}"]'
            first = seen[n.casefold()]
            also = "" if first == n else f" (as {first!r}; names must differ in more than case)"
            raise GearsymError(file, where, f"name {n!r} is used twice{also}")
        seen[n.casefold()] = n
