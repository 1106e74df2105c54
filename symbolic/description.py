"""Stage 1: the gearbox as data.

A TOML file describes shafts, planetary sets (with tooth counts), shift elements, the gear table,
inertias and (for later stages) drivetrain and vehicle values. This module parses and checks it
and returns an immutable :class:`GearboxDescription`; it knows nothing about any particular
gearbox. It imports nothing of the derivation: checking the gear table against the teeth
(Table 2.1) needs :mod:`gearsym.symbolic.ratios`, so the one loader that does both is
:func:`gearsym.symbolic.loader.load_description`. Every physical value is written
``{ value = ..., unit = "...", source = "..." }`` so that the file itself says where each number
comes from.
"""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

from gearsym.symbolic import set_kinds
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.input_files import parse_toml, shown, unknown_key_reason
from gearsym.symbolic.io.package_data import data_file

#: Names end up in C identifiers, always behind a prefix (``omega_<shaft>``, ``T_<element>``,
#: ``shift_<gear>_<gear>``), so they may hold letters, digits and underscores only; a leading
#: digit is allowed because of the prefix (the thesis numbers its shafts 1…8). An underscore
#: only between two letters or digits: ``__`` is reserved in C and C++ and separates generated
#: names (``S_<state>__<parameter>``, ``<input>__d1``), so ``_x``, ``x_`` and ``a__b`` could make
#: two different things one name. Matched with ``fullmatch`` (``$`` would accept "x\n").
NAME_PATTERN = re.compile(r"[A-Za-z0-9]+(?:_[A-Za-z0-9]+)*")
NAME_MAX_LENGTH = 31

#: Stated limits (README "Limits and the error contract"); each keeps a wrong number from
#: running for hours or overflowing a float instead of failing at once.
TEETH_MAX = 1000  # z_sun, z_planet, z_ring: real sets stay below ~200
PLANET_COUNT_MAX = 100
N_DISC_MAX = 100
RATIO_DECIMALS_MAX = 12  # a double carries 15-17 significant digits
ENTRIES_MAX = 100  # shafts, planetary sets, shift elements and gears, each
#: Profile shift moves a centre distance by (x1 ± x2)·module; beyond 2 modules the teeth
#: would be undercut or pointed, so a larger tolerance is a typing error, not a design.
CENTRE_DISTANCE_TOLERANCE_MAX = 2.0
#: ``planet_spacing`` of a set: "unequal" skips the equal-spacing assembly condition.
PLANET_SPACINGS = ("equal", "unequal")
#: A set given by ``k``: its planets' kinetic energy as inertias reflected to its members.
REFLECTED_KEY = "planet_inertia_reflected"
#: The keys ``planet_inertia_reflected`` replaces (their content is in the reflected values).
REFLECTED_REPLACES = ("planet_mass", "planet_inertia", "carrier_radius")

#: The unit every quantity key must carry (no conversion: a different unit is an error).
EXPECTED_UNITS: dict[str, str] = {
    "inertia": "kg*m^2",
    "planet_inertia": "kg*m^2",
    "planet_mass": "kg",
    "carrier_radius": "m",
}

#: Sections of named quantities for the elastic drivetrain (2.42–2.53), the vehicle and road
#: loads (2.48–2.49) and the shift-element friction (2.59–2.70): key -> required unit.
SECTION_UNITS: dict[str, dict[str, str]] = {
    "drivetrain": {
        "i_D": "1",
        "k_ss": "N*m/rad",
        "d_ss": "N*m*s/rad",
        "J_cs": "kg*m^2",
        "J_D": "kg*m^2",
        "I_wheel": "kg*m^2",
        # viscous drag of each idle shaft to the housing (README "Idle shafts"), optional
        "idle_drag": "N*m*s/rad",
    },
    "vehicle": {
        "m_veh": "kg",
        "r_dyn": "m",
        "g": "m/s^2",
        "rho_air": "kg/m^3",
        "c_W": "1",
        "A_front": "m^2",
        "f_roll": "s/m",
        "f_R": "1",
        "f_R0": "1",
        "f_R1": "s/m",
        "f_R2": "s^2/m^2",
        "zeta": "rad",
    },
    "friction": {
        "sigma0": "N*m/rad",
        "sigma1": "N*m*s/rad",
        "z_ba_ratio": "1",
        "T_oil": "degC",
        "mu_nominal": "1",
    },
}

#: Quantities that may be zero or negative (everything else must be positive).
#: The polynomial's coefficients may be zero (a term left out) or of either sign (a fit).
SIGNED_QUANTITIES = {"zeta", "T_oil", "z_ba_ratio", "f_R0", "f_R1", "f_R2"}

ROLLING_RESISTANCE_FORMS = ("thesis", "textbook", "polynomial")

DEFAULT_CONFIG_NAME = "thesis_9speed.toml"

#: Shift-element kinds: friction clutch (two shafts), friction brake (a shaft to the housing),
#: one-way clutch / freewheel (two shafts, or one shaft to the housing).
ONE_WAY = "one_way"
ELEMENT_KINDS = ("clutch", "brake", ONE_WAY)
#: ``locks`` of a one-way clutch: the sign of the slip ω_a − ω_b it prevents.
LOCK_DIRECTIONS = {"positive": 1, "negative": -1}


@dataclass(frozen=True)
class Quantity:
    """A physical value with its unit and where it comes from (thesis equation or "assumed")."""

    value: float
    unit: str
    source: str


@dataclass(frozen=True)
class Shaft:
    name: str
    inertia: Quantity


@dataclass(frozen=True)
class PlanetarySet:
    """One planetary set (2.20–2.23) of a kind (:mod:`gearsym.symbolic.set_kinds`).

    ``planet_mass`` and ``planet_inertia`` are per planet; the lumped planet body of the thesis
    (J_9…J_12, m_P,j) is ``planet_count`` times these. The second-pinion fields belong to the
    compound kinds: ``planet2`` is the outer pinion of a double-pinion set or the short pinion
    of a Ravigneaux set (each its own body), ``sun2`` the Ravigneaux sun meshing the short
    pinions, ``ring2`` the ring meshing the short pinions of a Ravigneaux set with two rings,
    ``z_planet2`` also the ring-side step of a stepped planet.
    ``centre_distance_tolerance`` (in modules) admits profile-shifted teeth whose
    standard-module centre distances differ by at most that much.
    """

    name: str
    sun: str
    carrier: str
    ring: str
    planet: str
    z_sun: int
    z_planet: int
    z_ring: int
    planet_count: int
    planet_mass: Quantity
    planet_inertia: Quantity
    carrier_radius: Quantity
    teeth_source: str
    kind: str = "simple"
    sun2: str | None = None
    z_sun2: int | None = None
    ring2: str | None = None
    z_ring2: int | None = None
    planet2: str | None = None
    z_planet2: int | None = None
    planet2_mass: Quantity | None = None
    planet2_inertia: Quantity | None = None
    planet2_radius: Quantity | None = None
    centre_distance_tolerance: float = 0.0
    #: The signed stationary (Willis) ratio i0 when the file gives ``k`` instead of teeth;
    #: the tooth counts are then 0 and everything that needs teeth refuses the set
    #: (:meth:`require_teeth`).
    given_k: Fraction | None = None
    #: ``"equal"`` (default): the tooth sums must allow equally spaced planets;
    #: ``"unequal"``: the file states the planets sit unequally spaced, the check is skipped.
    planet_spacing: str = "equal"
    #: A set given by ``k``: the kinetic energy of its planets (spin and orbit) as inertias
    #: reflected to its members, ``(role, inertia)`` for sun, carrier, ring (the housing left
    #: out): ½ Σ J_m ω_m² over the members equals the planets' energy for every motion the
    #: set allows (README "Stationary ratio instead of teeth"). Empty: not given.
    reflected_inertia: tuple[tuple[str, Quantity], ...] = ()
    #: False only in a description read for ``gearsym fit-teeth`` (``teeth_optional``) when
    #: the set gives no tooth counts yet: the counts are then 0, nothing is checked.
    teeth_given: bool = True

    def require_teeth(self, file: str, purpose: str, reflected_ok: bool = False) -> None:
        """Raise a one-line :class:`GearsymError` naming the set's ``k`` key when the set
        gives a stationary ratio instead of tooth counts and ``purpose`` needs teeth.
        ``reflected_ok``: the purpose (the mass matrix) is also served by
        ``planet_inertia_reflected``, which the message then names."""
        if self.given_k is None or (reflected_ok and self.reflected_inertia):
            return
        alternative = (
            f", or {REFLECTED_KEY} (the planets' inertia reflected to sun, carrier and ring)"
            if reflected_ok
            else ""
        )
        raise GearsymError(
            file,
            f'planetary_set[name="{self.name}"].k',
            f"{purpose} needs the tooth counts of set {self.name!r}, which gives only its "
            f"stationary ratio k; give z_sun, z_planet and z_ring instead{alternative}",
        )

    @property
    def members(self) -> tuple[str, ...]:
        """Shaft members (sun, second sun, carrier, ring as the kind has them)."""
        return tuple(getattr(self, role) for role in set_kinds.MEMBERS[self.kind])

    @property
    def pinions(self) -> tuple[str, ...]:
        """Pinion bodies, each with its own mass and inertia (planet first); none for a set
        given by ``k`` (its pinion speeds are unknown without teeth)."""
        if self.given_k is not None:
            return ()
        return tuple(getattr(self, role) for role in set_kinds.PINIONS[self.kind])

    @property
    def meshes(self) -> tuple[set_kinds.Mesh, ...]:
        """Tooth meshes (rows 2.22/2.23); none for a set given by ``k``."""
        return () if self.given_k is not None else set_kinds.MESHES[self.kind]

    @property
    def constraint_count(self) -> int:
        """Rows of the set in the constraint matrix: one per mesh, or the one shaft relation
        ω_S − i0 ω_H − (1 − i0) ω_C = 0 of a set given by ``k`` (its pinions eliminated)."""
        return 1 if self.given_k is not None else len(self.meshes)

    def reflected(self) -> dict[str, Quantity]:
        """Reflected planet inertia by member shaft (``planet_inertia_reflected``)."""
        return {getattr(self, role): q for role, q in self.reflected_inertia}

    def teeth(self, key: str) -> int:
        value = getattr(self, key)
        assert isinstance(value, int), (self.name, key)
        return value

    def pinion_mass(self, body: str) -> Quantity:
        """Per-pinion mass of a pinion body of this set."""
        q = self.planet_mass if body == self.planet else self.planet2_mass
        assert q is not None
        return q

    def pinion_inertia(self, body: str) -> Quantity:
        q = self.planet_inertia if body == self.planet else self.planet2_inertia
        assert q is not None
        return q

    def pinion_radius(self, body: str) -> Quantity:
        """Radius of the circle the pinion's centre runs on (2.27)."""
        q = self.carrier_radius if body == self.planet else self.planet2_radius
        assert q is not None
        return q


@dataclass(frozen=True)
class ShiftElement:
    """A clutch between shafts ``(a, b)``, a brake on shaft ``(b,)``, or a one-way clutch
    (freewheel) between ``(a, b)`` or from ``(b,)`` to the housing.

    Sign convention of (2.36): the element torque T acts with +T on ``b`` and −T on ``a`` (a is
    the housing for a brake); its slip speed is Δω = ω_a − ω_b. A one-way clutch
    (``kind = "one_way"``) prevents the slip sign ``locks`` (+1: it blocks Δω > 0, −1: it blocks
    Δω < 0) and runs free the other way; locked, it carries a torque of the sign ``locks``
    (the sign a friction element resisting that slip would have, 2.70), never the other.
    """

    name: str
    kind: str
    shafts: tuple[str, ...]
    n_disc: int | None = None  # friction surfaces pairs N_disc (2.69)
    r_m: Quantity | None = None  # mean friction radius (2.69)
    a_piston: Quantity | None = None  # piston area: F_N = p_N·A (2.69)
    locks: int = 0  # one-way clutch: the blocked slip sign, +1 or −1; 0 for the others

    @property
    def a(self) -> str | None:
        return self.shafts[0] if len(self.shafts) == 2 else None

    @property
    def one_way(self) -> bool:
        """A freewheel: a unilateral constraint, no pressure, no friction data."""
        return self.kind == ONE_WAY

    @property
    def b(self) -> str:
        return self.shafts[-1]


@dataclass(frozen=True)
class Gear:
    name: str
    closed: tuple[str, ...]
    ratio: float | None
    neutral: bool


@dataclass(frozen=True)
class GearboxDescription:
    """The parsed, checked description. Order of every tuple is the file's order."""

    name: str
    title: str
    file: str
    input_shaft: str
    output_shaft: str
    measured_shafts: tuple[str, ...]
    coordinates: tuple[str, ...]
    shafts: tuple[Shaft, ...]
    planetary_sets: tuple[PlanetarySet, ...]
    shift_elements: tuple[ShiftElement, ...]
    gears: tuple[Gear, ...]
    ratio_decimals: int
    gear_table_source: str
    drivetrain: dict[str, Quantity] = field(default_factory=dict)
    vehicle: dict[str, Quantity] = field(default_factory=dict)
    friction: dict[str, Quantity] = field(default_factory=dict)
    rolling_resistance: str = "thesis"
    mu_map: str = "built-in"

    @property
    def shaft_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.shafts)

    @property
    def planet_names(self) -> tuple[str, ...]:
        """Every pinion body, set by set (one per simple set, as 9–12 of 2.26)."""
        return tuple(p for ps in self.planetary_sets for p in ps.pinions)

    @property
    def body_names(self) -> tuple[str, ...]:
        """Shafts first, then the lumped planet bodies, as in (2.26)."""
        return self.shaft_names + self.planet_names

    @property
    def degrees_of_freedom(self) -> int:
        """f = f_free − (number of meshes) (2.24: two per simple set)."""
        return len(self.body_names) - sum(ps.constraint_count for ps in self.planetary_sets)

    def element(self, name: str) -> ShiftElement:
        return next(e for e in self.shift_elements if e.name == name)

    def gear(self, name: str) -> Gear:
        return next(g for g in self.gears if g.name == name)

    def shaft(self, name: str) -> Shaft:
        return next(s for s in self.shafts if s.name == name)


def default_config_path() -> Path:
    """Path of the built-in description (the thesis' 9-speed gearbox)."""
    return data_file(DEFAULT_CONFIG_NAME)


def default_config_text() -> str:
    return default_config_path().read_text(encoding="utf-8")


class _Reader:
    """Typed access to a TOML table that reports errors with the file and the key path."""

    def __init__(self, file: str, table: dict[str, Any], path: str) -> None:
        self.file = file
        self.data = table
        self.path = path
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, reason: str) -> GearsymError:
        return GearsymError(self.file, self.key(name), reason)

    def _get(self, name: str, required: bool) -> Any:
        self.used.add(name)
        if name not in self.data:
            if required:
                near = difflib.get_close_matches(name, [str(k) for k in self.data], n=1)
                hint = f" (is {near[0]!r} a misspelling?)" if near else ""
                raise self.fail(name, f"missing required key{hint}")
            return None
        return self.data[name]

    def string(self, name: str, required: bool = True, default: str = "") -> str:
        value = self._get(name, required)
        if value is None:
            return default
        if not isinstance(value, str):
            raise self.fail(name, f"expected a string, got {type(value).__name__}")
        return value

    def name(self, name: str = "name") -> str:
        value = self.string(name)
        if not NAME_PATTERN.fullmatch(value) or len(value) > NAME_MAX_LENGTH:
            raise self.fail(
                name,
                f"{shown(value)} is not usable in a C identifier (letters and digits, joined by "
                f"single '_'; no leading, trailing or double '_'; at most {NAME_MAX_LENGTH} "
                "characters)",
            )
        return value

    def integer(self, name: str, required: bool = True, default: int = 0) -> int:
        value = self._get(name, required)
        if value is None:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(name, f"expected an integer, got {shown(value)}")
        return value

    def positive_integer(
        self, name: str, required: bool = True, default: int = 0, maximum: int | None = None
    ) -> int:
        value = self.integer(name, required, default)
        if value <= 0:
            raise self.fail(name, f"must be a positive integer, got {_short(value)}")
        if maximum is not None and value > maximum:
            raise self.fail(name, f"must be at most {maximum}, got {_short(value)}")
        return value

    def boolean(self, name: str, default: bool = False) -> bool:
        value = self._get(name, False)
        if value is None:
            return default
        if not isinstance(value, bool):
            raise self.fail(name, f"expected true or false, got {shown(value)}")
        return value

    def number(self, name: str, required: bool = True) -> float | None:
        value = self._get(name, required)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(name, f"expected a number, got {shown(value)}")
        if not math.isfinite(value):
            raise self.fail(name, f"must be finite, got {shown(value)}")
        return float(value)

    def string_list(self, name: str, required: bool = True) -> tuple[str, ...]:
        value = self._get(name, required)
        if value is None:
            return ()
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.fail(name, "expected a list of names (strings)")
        return tuple(value)

    def quantity(self, name: str, positive: bool = True, unit: str | None = None) -> Quantity:
        value = self._get(name, True)
        if not isinstance(value, dict):
            raise self.fail(name, """expected { value = <number>, unit = "...", source = "..." }""")
        sub = _Reader(self.file, value, self.key(name))
        number = sub.number("value")
        assert number is not None
        given_unit = sub.string("unit")
        source = sub.string("source")
        sub.reject_unknown()
        expected = unit if unit is not None else EXPECTED_UNITS.get(name)
        if expected is not None and given_unit != expected:
            raise sub.fail("unit", f"expected {expected!r}, got {given_unit!r}")
        if not source.strip():
            raise sub.fail("source", "must say where the value comes from (or 'assumed')")
        if positive and number <= 0:
            raise sub.fail("value", f"must be positive, got {number}")
        return Quantity(number, given_unit, source)

    def tables(self, name: str, required: bool = True) -> list[_Reader]:
        value = self._get(name, required)
        if value is None:
            return []
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(name, f"expected an array of tables ([[{name}]])")
        if len(value) > ENTRIES_MAX:
            raise self.fail(name, f"at most {ENTRIES_MAX} [[{name}]] entries, got {len(value)}")
        return [_Reader(self.file, t, f"{self.key(name)}[{i}]") for i, t in enumerate(value)]

    def table(self, name: str, required: bool = True) -> _Reader:
        value = self._get(name, required)
        if value is None:
            return _Reader(self.file, {}, self.key(name))
        if not isinstance(value, dict):
            raise self.fail(name, f"expected a table ([{name}])")
        return _Reader(self.file, value, self.key(name))

    def reject_unknown(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.fail(unknown[0], unknown_key_reason(unknown[0], self.used))


def _short(value: int) -> str:
    """An integer for a message: 10**400 is not worth 401 digits."""
    text = str(value)
    return text if len(text) <= 20 else f"a {len(text)}-digit number"


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
        if kind == "clutch":
            pair = r.string_list("shafts")
            if len(pair) != 2:
                raise r.fail("shafts", "a clutch joins exactly two shafts [a, b]")
            if pair[0] == pair[1]:
                raise r.fail("shafts", f"a clutch must join two different shafts, got {pair}")
        elif kind == "brake":
            pair = (r.string("shaft"),)
        else:
            raise r.fail("kind", f"expected 'clutch', 'brake' or 'one_way', got {shown(kind)}")
        if "locks" in r.data:
            raise r.fail(
                "locks", f"only a one-way clutch has a locking direction; this is a {kind}"
            )
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
            f"must be 0 to {RATIO_DECIMALS_MAX} (decimals of a double), got {_short(decimals)}",
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
    if not description.coordinates:
        # Default generalized coordinates: the first f shafts (thesis 2.28 names them).
        description = _replace_coordinates(description)
    from gearsym.symbolic.naming import check_names

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


#: Sign of the stationary ratio i0 per kind that may give ``k`` (set_kinds.relations).
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
                "a one-way clutch joins exactly two shafts [a, b] "
                "(or shaft = b for one to the housing)",
            )
        if pair[0] == pair[1]:
            raise r.fail(
                "shafts", f"a one-way clutch must join two different shafts, got {list(pair)}"
            )
    else:
        pair = (r.string("shaft"),)
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


def _replace_coordinates(d: GearboxDescription) -> GearboxDescription:
    from dataclasses import replace

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


def pinion_pair_problem(
    z_sun: int, z_inner: int, z_outer: int, z_ring: int, outer_clears_sun: bool
) -> str | None:
    """Why two meshing pinions, the inner on the sun and the outer on the ring, cannot be
    built (None if they can): their centres and the axis must form a triangle, and neither
    may touch the gear it does not mesh (tip circles one module outside the pitch circles;
    the outer pinion's sun clearance only where the sun is under it, ``outer_clears_sun``)."""
    r_inner = (z_sun + z_inner) / 2
    r_outer = (z_ring - z_outer) / 2
    between = (z_inner + z_outer) / 2
    if not abs(r_outer - r_inner) < between < r_outer + r_inner:
        return (
            f"the pinions cannot mesh: centre radii {r_inner:g} and {r_outer:g} and their "
            f"distance {between:g} modules form no triangle"
        )
    if r_inner + (z_inner + 2) / 2 >= (z_ring - 2) / 2:
        return f"the sun-side pinion ({z_inner} teeth) reaches into the ring"
    if outer_clears_sun and r_outer - (z_outer + 2) / 2 <= (z_sun + 2) / 2:
        return f"the ring-side pinion ({z_outer} teeth) reaches into the sun"
    return None


def planets_fit(z_sun: int, z_planet: int, count: int) -> bool:
    """Neighbour condition: tip circles of adjacent planets (addendum = 1 module) must not touch."""
    if count < 2:
        return True
    return (z_sun + z_planet) * math.sin(math.pi / count) > z_planet + 2


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
