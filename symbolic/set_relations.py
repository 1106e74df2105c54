"""The shaft relations of a described planetary set: its pinions eliminated (Willis).

Per sun–ring pair ω_S − i0 ω_H − (1 − i0) ω_C = 0 with the stationary ratio i0 = sign·k, hand
derived per kind from the meshes of :mod:`gearsym.symbolic.set_kinds` (whose docstring derives
the signs); what the gear table (:mod:`gearsym.symbolic.ratios`), the tooth search
(:mod:`gearsym.symbolic.teeth`) and the lever diagrams use. Exact (fractions), no SymPy.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from fractions import Fraction

from gearsym.symbolic.description import PlanetarySet

__all__ = ["Relation", "relations"]


@dataclass(frozen=True)
class Relation:
    """One shaft relation ω_S − i0 ω_H − (1 − i0) ω_C = 0 with i0 = sign·k (module docstring).

    ``key`` names k in ratio tables (the set name; ``<set>:short`` for the second pair of a
    Ravigneaux set); ``k`` is exact from the teeth.
    """

    key: str
    sun: str
    ring: str
    carrier: str
    sign: int
    k: Fraction


def relations(ps: PlanetarySet) -> tuple[Relation, ...]:
    """The shaft relations of a set (its pinions eliminated), hand-derived per kind.

    simple: z_S(ω_S−ω_C) = −z_P(ω_P−ω_C) = −z_H(ω_H−ω_C)  →  i0 = −z_H/z_S.
    double pinion: z_S(ω_S−ω_C) = −z_P(ω_P−ω_C) = z_P2(ω_P2−ω_C) = z_H(ω_H−ω_C)  →  i0 = +z_H/z_S.
    stepped planet: z_S(ω_S−ω_C) = −z_P(ω_P−ω_C), z_H(ω_H−ω_C) = z_P2(ω_P−ω_C)
    →  i0 = −z_H z_P/(z_S z_P2).
    Ravigneaux: the long-pinion pair as simple, the short-pinion pair as double pinion.
    Ravigneaux with two rings: sun–long pinion–ring as simple; sun–long–short–second ring
    z_S(ω_S−ω_C) = −z_L(ω_L−ω_C) = z_Ps(ω_Ps−ω_C) = z_H2(ω_H2−ω_C) → i0 = +z_H2/z_S.
    A set that gives ``k`` (its signed i0) instead of teeth has k = |i0| with the kind's sign.
    A set without teeth yet (``teeth_given`` false, read for ``fit-teeth``) has k = 0: only
    its relation keys, members and signs are meaningful.
    """
    if not ps.teeth_given:
        z = {"z_sun": 1, "z_sun2": 1, "z_planet2": 1, "z_ring2": 0}
        ps = replace(ps, z_ring=0, **{k: v for k, v in z.items() if getattr(ps, k) is not None})
    if ps.given_k is not None:
        sign = 1 if ps.given_k > 0 else -1
        return (Relation(ps.name, ps.sun, ps.ring, ps.carrier, sign, abs(ps.given_k)),)
    if ps.kind == "simple":
        return (Relation(ps.name, ps.sun, ps.ring, ps.carrier, -1, Fraction(ps.z_ring, ps.z_sun)),)
    if ps.kind == "double_pinion":
        return (Relation(ps.name, ps.sun, ps.ring, ps.carrier, 1, Fraction(ps.z_ring, ps.z_sun)),)
    if ps.kind == "stepped_planet":
        assert ps.z_planet2 is not None
        k = Fraction(ps.z_ring * ps.z_planet, ps.z_sun * ps.z_planet2)
        return (Relation(ps.name, ps.sun, ps.ring, ps.carrier, -1, k),)
    if ps.kind == "ravigneaux_two_rings":
        assert ps.ring2 is not None and ps.z_ring2 is not None
        return (
            Relation(ps.name, ps.sun, ps.ring, ps.carrier, -1, Fraction(ps.z_ring, ps.z_sun)),
            Relation(
                f"{ps.name}:short", ps.sun, ps.ring2, ps.carrier, 1, Fraction(ps.z_ring2, ps.z_sun)
            ),
        )
    assert ps.kind == "ravigneaux" and ps.sun2 is not None and ps.z_sun2 is not None
    return (
        Relation(ps.name, ps.sun, ps.ring, ps.carrier, -1, Fraction(ps.z_ring, ps.z_sun)),
        Relation(
            f"{ps.name}:short", ps.sun2, ps.ring, ps.carrier, 1, Fraction(ps.z_ring, ps.z_sun2)
        ),
    )
