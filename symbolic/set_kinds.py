"""Planetary set kinds as data: which gears mesh, and what the pinions eliminate to.

Every kind is a list of tooth meshes between the members (sun, second sun, ring) and the
pinions (planet, second pinion), all relative to the one carrier of the set. Each mesh is one
Willis rolling condition, written in the form of the thesis' (2.22) (external mesh) and (2.23)
(internal mesh):

    external, gears a and b:  z_a ω_a + z_b ω_b − (z_a + z_b) ω_C = 0
    internal, ring a, pinion b: z_a ω_a − z_b ω_b − (z_a − z_b) ω_C = 0

(both say z_a (ω_a − ω_C) = ∓ z_b (ω_b − ω_C): teeth pass the mesh at the same rate in the
carrier frame). ω of a pinion is its absolute speed, so its kinetic energy is
½ J ω_P² + ½ m (r ω_C)² (spin and orbit, 2.34). The kinematics and the mass matrix are derived
from these meshes by the one Jacobian route (:mod:`gearsym.symbolic.kinematics`,
:mod:`gearsym.symbolic.dynamics`).

Eliminating the pinions leaves, per set, one shaft relation per sun–ring pair (Willis):

    ω_S − i0 ω_H − (1 − i0) ω_C = 0,   i0 = (ω_S − ω_C)/(ω_H − ω_C) with the carrier held,

where the stationary ratio i0 = −k for a negative-ratio pair (simple set, stepped planet, the
long-pinion pair of a Ravigneaux set) and i0 = +k for a positive-ratio pair (double pinion, the
short-pinion pair of a Ravigneaux set), k > 0 from the teeth
(:func:`gearsym.symbolic.set_relations.relations`).

The kinds (README "Planetary set kinds"):

``simple``          sun – planet – ring (thesis 2.20–2.23), k = z_H/z_S, i0 = −k.
``double_pinion``   sun – inner planet – outer planet – ring, k = z_H/z_S, i0 = +k.
``ravigneaux``      one carrier, one ring, long pinions meshing the sun and the ring, short
                    pinions meshing the long pinions and a second sun: k = z_H/z_S (i0 = −k)
                    and k2 = z_H/z_S2 (i0 = +k2).
``ravigneaux_two_rings``  one carrier, one sun, long pinions meshing the sun and a ring,
                    short pinions meshing the long pinions and a second ring (the 7G-Tronic's
                    set): k = z_H/z_S (i0 = −k) and k2 = z_H2/z_S (i0 = +k2).
``stepped_planet``  one planet body with two tooth counts, z_P on the sun, z_P2 on the ring:
                    k = z_H z_P/(z_S z_P2), i0 = −k.
"""

from __future__ import annotations

from dataclasses import dataclass

KINDS = ("simple", "double_pinion", "ravigneaux", "ravigneaux_two_rings", "stepped_planet")

#: The member that is fixed: a set member named ``housing`` never turns (no state, no brake).
HOUSING = "housing"


@dataclass(frozen=True)
class Mesh:
    """One tooth contact: roles of the two gears and the tooth-count keys that mesh there.

    Roles are attribute names of :class:`~gearsym.symbolic.description.PlanetarySet`
    (``sun``, ``sun2``, ``ring``, ``ring2``, ``planet``, ``planet2``); teeth keys likewise
    (``z_sun``, …).
    ``internal`` is the ring–pinion mesh (2.23), otherwise external (2.22).
    """

    a: str
    z_a: str
    b: str
    z_b: str
    internal: bool = False


#: Meshes per kind, in the order of the constraint rows. ``simple`` is (2.22), (2.23).
MESHES: dict[str, tuple[Mesh, ...]] = {
    "simple": (
        Mesh("sun", "z_sun", "planet", "z_planet"),
        Mesh("ring", "z_ring", "planet", "z_planet", internal=True),
    ),
    "double_pinion": (
        Mesh("sun", "z_sun", "planet", "z_planet"),
        Mesh("planet", "z_planet", "planet2", "z_planet2"),
        Mesh("ring", "z_ring", "planet2", "z_planet2", internal=True),
    ),
    "ravigneaux": (
        Mesh("sun", "z_sun", "planet", "z_planet"),
        Mesh("ring", "z_ring", "planet", "z_planet", internal=True),
        Mesh("planet2", "z_planet2", "planet", "z_planet"),
        Mesh("sun2", "z_sun2", "planet2", "z_planet2"),
    ),
    "ravigneaux_two_rings": (
        Mesh("sun", "z_sun", "planet", "z_planet"),
        Mesh("ring", "z_ring", "planet", "z_planet", internal=True),
        Mesh("planet2", "z_planet2", "planet", "z_planet"),
        Mesh("ring2", "z_ring2", "planet2", "z_planet2", internal=True),
    ),
    "stepped_planet": (
        Mesh("sun", "z_sun", "planet", "z_planet"),
        Mesh("ring", "z_ring", "planet", "z_planet2", internal=True),
    ),
}

#: Pinion bodies per kind (roles); each is its own body with its own mass and inertia.
PINIONS: dict[str, tuple[str, ...]] = {
    "simple": ("planet",),
    "double_pinion": ("planet", "planet2"),
    "ravigneaux": ("planet", "planet2"),
    "ravigneaux_two_rings": ("planet", "planet2"),
    "stepped_planet": ("planet",),
}

#: Shaft members per kind (roles), each a shaft of the description or the housing.
MEMBERS: dict[str, tuple[str, ...]] = {
    "simple": ("sun", "carrier", "ring"),
    "double_pinion": ("sun", "carrier", "ring"),
    "ravigneaux": ("sun", "sun2", "carrier", "ring"),
    "ravigneaux_two_rings": ("sun", "carrier", "ring", "ring2"),
    "stepped_planet": ("sun", "carrier", "ring"),
}

#: TOML keys of the second pinion / second sun / ring step, per kind (file key -> field).
EXTRA_KEYS: dict[str, dict[str, str]] = {
    "simple": {},
    "double_pinion": {
        "planet_outer": "planet2",
        "z_planet_outer": "z_planet2",
        "planet_outer_mass": "planet2_mass",
        "planet_outer_inertia": "planet2_inertia",
        "planet_outer_radius": "planet2_radius",
    },
    "ravigneaux": {
        "sun_short": "sun2",
        "z_sun_short": "z_sun2",
        "planet_short": "planet2",
        "z_planet_short": "z_planet2",
        "planet_short_mass": "planet2_mass",
        "planet_short_inertia": "planet2_inertia",
        "planet_short_radius": "planet2_radius",
    },
    "ravigneaux_two_rings": {
        "ring_short": "ring2",
        "z_ring_short": "z_ring2",
        "planet_short": "planet2",
        "z_planet_short": "z_planet2",
        "planet_short_mass": "planet2_mass",
        "planet_short_inertia": "planet2_inertia",
        "planet_short_radius": "planet2_radius",
    },
    "stepped_planet": {"z_planet_ring": "z_planet2"},
}


def file_key(kind: str, field: str) -> str:
    """The TOML key of a field (``planet2`` of a Ravigneaux set is ``planet_short``)."""
    for key, name in EXTRA_KEYS[kind].items():
        if name == field:
            return key
    return field
