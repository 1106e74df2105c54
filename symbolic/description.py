"""Stage 1: the gearbox as data.

A TOML file describes shafts, planetary sets (with tooth counts), shift elements, the gear table,
inertias and (for later stages) drivetrain and vehicle values. This module holds what it becomes:
the immutable :class:`GearboxDescription` and its parts, the stated limits of every key, and the
built-in description; :mod:`gearsym.symbolic.description_parser` reads and checks a file into it.
It knows nothing about any particular gearbox and imports nothing of the derivation (no SymPy):
checking the gear table against the teeth (Table 2.1) needs :mod:`gearsym.symbolic.ratios`, so
the one loader that does both is :func:`gearsym.symbolic.loader.load_description`. Every
physical value is written ``{ value = ..., unit = "...", source = "..." }`` so that the file
itself says where each number comes from.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from fractions import Fraction
from pathlib import Path

from gearsym.symbolic import set_kinds
from gearsym.symbolic.control_calibration import ControlCalibration, default_control
from gearsym.symbolic.drive_calibration import DriveCalibration, default_drive
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import EstimatorCalibration
from gearsym.symbolic.io.package_data import data_file
from gearsym.symbolic.parameters import RECORDS, section_units

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
#: loads (2.48–2.49) and the shift-element friction (2.59–2.70): key -> required unit (the
#: records of :mod:`gearsym.symbolic.parameters`).
SECTION_UNITS: dict[str, dict[str, str]] = section_units()

#: Quantities that may be zero or negative (everything else must be positive).
#: The polynomial's coefficients may be zero (a term left out) or of either sign (a fit).
SIGNED_QUANTITIES = {r.key for r in RECORDS if r.signed and r.section != "element"}

ROLLING_RESISTANCE_FORMS = ("thesis", "textbook", "polynomial")

DEFAULT_CONFIG_NAME = "thesis_9speed.toml"

#: Shift-element kinds: friction clutch (two shafts), friction brake (a shaft to the housing),
#: one-way clutch / freewheel (two shafts, or one shaft to the housing).
ONE_WAY = "one_way"
#: Dog clutch / dog brake (form-locking, as the ZF 9HP's A and F): carries torque only when
#: engaged, engages only within ``engage_slip``, releases only below ``release_torque``.
DOG = "dog"
ELEMENT_KINDS = ("clutch", "brake", ONE_WAY, DOG)
#: Stated defaults of a dog element's keys (README "The gearbox description", dog clutches):
#: the largest |slip| at which its teeth engage (3 rad/s ≈ 29 rpm, assumed: the order the
#: synchronising control of production dog elements aims at) and the largest |reaction
#: torque| at which it can be pulled out (5 N·m, assumed: the teeth's friction under load
#: holds it engaged above that).
DOG_ENGAGE_SLIP_DEFAULT = 3.0  # rad/s
DOG_RELEASE_TORQUE_DEFAULT = 5.0  # N*m
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
    A dog element (``kind = "dog"``, clutch ``(a, b)`` or brake ``(b,)``) is form-locking:
    engaged it is a constraint of unlimited capacity, open it carries nothing; it engages only
    while |Δω| ≤ ``engage_slip`` and releases only while |T| ≤ ``release_torque``.
    """

    name: str
    kind: str
    shafts: tuple[str, ...]
    n_disc: int | None = None  # friction surfaces pairs N_disc (2.69)
    r_m: Quantity | None = None  # mean friction radius (2.69)
    a_piston: Quantity | None = None  # piston area: F_N = p_N·A (2.69)
    locks: int = 0  # one-way clutch: the blocked slip sign, +1 or −1; 0 for the others
    #: dog element: the largest |slip| at which it engages (rad/s) and the largest |reaction
    #: torque| at which it releases (N·m); None for the others
    engage_slip: Quantity | None = None
    release_torque: Quantity | None = None

    @property
    def a(self) -> str | None:
        return self.shafts[0] if len(self.shafts) == 2 else None

    @property
    def one_way(self) -> bool:
        """A freewheel: a unilateral constraint, no pressure, no friction data."""
        return self.kind == ONE_WAY

    @property
    def dog(self) -> bool:
        """A dog clutch or dog brake: a bilateral constraint when engaged, nothing when open;
        no pressure-dependent capacity, no friction data."""
        return self.kind == DOG

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
    #: What the TCU's estimators assume (``[estimator]``: prior and tuning), not the truth.
    estimator: EstimatorCalibration = field(default_factory=EstimatorCalibration)
    #: The powertrain around the gearbox and the TCU's shift schedule of a drive (``[drive]``).
    drive: DriveCalibration = field(default_factory=default_drive)
    #: The TCU's nominal valve and piston fill, its shift controller's tuning and adaptation
    #: (``[control]``; the truth of a vehicle is the fleet's, ``validation/sim/actuator.py``).
    control: ControlCalibration = field(default_factory=default_control)

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

    def with_inertias(self, scaled: Callable[[Quantity], Quantity]) -> GearboxDescription:
        """This description with every shaft's and every set's planet inertia replaced by
        ``scaled(inertia)``: the rotating parts a fleet's tolerance on the inertias covers (a
        vehicle's truth) and that a filter's inertia factor scales (one definition for both).
        Planet masses, the propeller shaft and the differential (``[drivetrain]``) keep
        theirs."""
        return replace(
            self,
            shafts=tuple(replace(s, inertia=scaled(s.inertia)) for s in self.shafts),
            planetary_sets=tuple(
                replace(ps, planet_inertia=scaled(ps.planet_inertia))
                if ps.planet_inertia is not None
                else ps
                for ps in self.planetary_sets
            ),
        )


def default_config_path() -> Path:
    """Path of the built-in description (the thesis' 9-speed gearbox)."""
    return data_file(DEFAULT_CONFIG_NAME)


def default_config_text() -> str:
    return default_config_path().read_text(encoding="utf-8")


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
