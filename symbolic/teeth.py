"""Search integer tooth counts that reproduce a target ratio table.

Gear ratios depend on a set's teeth only through its stationary ratios: k = z_ring / z_sun of
a simple or double-pinion set, k, k2 = z_ring / z_sun_short of a Ravigneaux set and k,
k2 = z_ring_short / z_sun of a Ravigneaux set with two rings
(:mod:`gearsym.symbolic.ratios`, :mod:`gearsym.symbolic.set_kinds`). The search therefore

1. lists, per set, every buildable realisation in the given ranges, grouped by the exact
   tuple of its stationary ratios. Buildable is what the description checks
   (:func:`gearsym.symbolic.description_parser.parse_description`, README "Planetary set kinds"),
   with exact coaxiality (no profile shift):

   - simple: z_ring = z_sun + 2 z_planet, (z_sun + z_ring) divisible by the planet count,
     neighbouring planets clear;
   - double pinion: the inner/outer pinion centres and the axis form a triangle, the inner
     pinion clears the ring and the outer one the sun
     (:func:`~gearsym.symbolic.description.pinion_pair_problem`), (z_ring − z_sun) divisible
     by the planet count;
   - Ravigneaux: the long pinion as a simple set, the short pinion with the second sun and
     the long pinion as a pinion pair, (z_ring − z_sun_short) divisible by the planet count;
   - Ravigneaux with two rings: the long pinion as a simple set, long and short pinion as a
     pinion pair between the sun and the second ring, (z_ring_short − z_sun) divisible by
     the planet count;

2. assigns the stationary ratios one after another (the next is the one that completes the
   most gears), pruning every partial assignment by the gears whose ratio depends only on
   assigned ratios; the two ratios of a Ravigneaux set are searched separately and joined
   at the end (only pairs one tooth set realises survive);
3. re-checks every surviving combination exactly (rational arithmetic) and ranks it by its
   largest ratio error.

The file's tooth counts are not needed: a description read with ``teeth_optional`` (a set
given only its kind and members, or zeros) is searched from the ratio targets alone. Nothing
here is specific to one gearbox: the dependency of each gear on the ratios is read off the
symbolic ratio expressions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from fractions import Fraction

import numpy as np
import sympy as sp
from gearsym.symbolic.description import GearboxDescription, planets_fit
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.ratios import (
    gear_ratio,
    ratio_expressions,
    stationary_ratio_symbols,
    stationary_ratios,
)
from gearsym.symbolic.set_relations import relations

#: Kinds the search knows how to build, with the tooth keys (file names) after
#: (z_sun, z_planet, z_ring, planet_count) in a realisation tuple.
EXTRA_TEETH: dict[str, tuple[str, ...]] = {
    "simple": (),
    "double_pinion": ("z_planet_outer",),
    "ravigneaux": ("z_sun_short", "z_planet_short"),
    "ravigneaux_two_rings": ("z_ring_short", "z_planet_short"),
}
#: Planet counts tried for a set that gives none (and no --planet-count).
DEFAULT_PLANET_COUNTS = (3, 4, 5)

#: One realisation: (z_sun, z_planet, z_ring, planet_count, *EXTRA_TEETH[kind]).
Realisation = tuple[int, ...]


def teeth_keys(kind: str) -> tuple[str, ...]:
    """The file keys of a realisation tuple of ``kind``, in order."""
    return ("z_sun", "z_planet", "z_ring", "planet_count", *EXTRA_TEETH[kind])


@dataclass(frozen=True)
class ToothRanges:
    """Inclusive tooth-count bounds and the planet counts to consider."""

    sun: tuple[int, int] = (17, 110)
    planet: tuple[int, int] = (13, 60)
    ring_max: int = 180
    planet_counts: tuple[int, ...] | None = None  # None: each set's count from the description


@dataclass(frozen=True)
class TeethCandidate:
    """One buildable tooth-count realisation per set and its ratio errors."""

    #: set -> (z_sun, z_planet, z_ring, planets, *extra teeth of its kind, see teeth_keys)
    teeth: dict[str, Realisation]
    ratios: dict[str, float]
    errors: dict[str, float]
    #: Other buildable teeth with the same stationary ratios per set (same ratios, other sizes).
    alternatives: dict[str, list[Realisation]] = field(default_factory=dict)

    @property
    def max_error(self) -> float:
        return max(self.errors.values(), default=0.0)


def buildable_teeth(
    ranges: ToothRanges, planet_counts: tuple[int, ...]
) -> dict[Fraction, list[tuple[int, int, int, int]]]:
    """Every buildable simple set (z_sun, z_planet, z_ring, planets) in range, grouped by
    k = z_ring/z_sun."""
    by_ratio: dict[Fraction, list[tuple[int, int, int, int]]] = {}
    for z_sun in range(ranges.sun[0], ranges.sun[1] + 1):
        for z_planet in range(ranges.planet[0], ranges.planet[1] + 1):
            z_ring = z_sun + 2 * z_planet
            if z_ring > ranges.ring_max:
                break
            for n in planet_counts:
                if (z_sun + z_ring) % n == 0 and planets_fit(z_sun, z_planet, n):
                    by_ratio.setdefault(Fraction(z_ring, z_sun), []).append(
                        (z_sun, z_planet, z_ring, n)
                    )
    return by_ratio


def _pair_fits(
    z_sun: np.ndarray, z_inner: np.ndarray, z_outer: np.ndarray, z_ring: int, clears_sun: bool
) -> np.ndarray:
    """Vectorised :func:`~gearsym.symbolic.description.pinion_pair_problem` is None, in
    half-module units (every quantity doubled, so the comparisons are exact integers)."""
    r_inner = z_sun + z_inner
    r_outer = z_ring - z_outer
    between = z_inner + z_outer
    ok = (np.abs(r_outer - r_inner) < between) & (between < r_outer + r_inner)
    ok &= r_inner + z_inner + 2 < z_ring - 2
    if clears_sun:
        ok &= r_outer - z_outer - 2 > z_sun + 2
    return ok


def buildable_realisations(
    kind: str, ranges: ToothRanges, planet_counts: tuple[int, ...]
) -> dict[tuple[Fraction, ...], list[Realisation]]:
    """Every buildable realisation of a set of ``kind`` in range, grouped by the tuple of its
    stationary ratios (in the order of :func:`gearsym.symbolic.set_relations.relations`); one
    pinion choice (the smallest) per set of sun/ring teeth."""
    planets = np.arange(ranges.planet[0], ranges.planet[1] + 1)
    suns = np.arange(ranges.sun[0], ranges.sun[1] + 1)
    found: dict[tuple[Fraction, ...], list[Realisation]] = {}
    if kind == "simple":
        for k, teeth in buildable_teeth(ranges, planet_counts).items():
            found[(k,)] = list(teeth)
        return found
    if kind == "double_pinion":
        inner, outer = np.meshgrid(planets, planets, indexing="ij")
        order = np.argsort((inner + outer).ravel(), kind="stable")
        for z_sun in suns.tolist():
            for z_ring in range(z_sun + 1, ranges.ring_max + 1):
                counts = [n for n in planet_counts if (z_ring - z_sun) % n == 0]
                if not counts:
                    continue
                ok = _pair_fits(np.full(inner.shape, z_sun), inner, outer, z_ring, True).ravel()
                hits = order[ok[order]]
                if hits.size == 0:
                    continue
                z_p, z_p2 = int(inner.ravel()[hits[0]]), int(outer.ravel()[hits[0]])
                key = (Fraction(z_ring, z_sun),)
                for n in counts:
                    found.setdefault(key, []).append((z_sun, z_p, z_ring, n, z_p2))
        return found
    if kind == "ravigneaux":
        sun2, short = np.meshgrid(suns, planets, indexing="ij")
        for z_sun, z_long, z_ring, n in (
            t for teeth in buildable_teeth(ranges, planet_counts).values() for t in teeth
        ):
            # the short pinion: inner on the second sun, outer the long pinion
            ok = _pair_fits(sun2, short, np.full(short.shape, z_long), z_ring, False)
            ok &= (z_ring - sun2) % n == 0
            for i in np.flatnonzero(ok.any(axis=1)).tolist():
                z_s2 = int(suns[i])
                z_p2 = int(planets[np.flatnonzero(ok[i])[0]])
                key = (Fraction(z_ring, z_sun), Fraction(z_ring, z_s2))
                found.setdefault(key, []).append((z_sun, z_long, z_ring, n, z_s2, z_p2))
        return found
    if kind == "ravigneaux_two_rings":
        rings = np.arange(1, ranges.ring_max + 1)
        ring2, short = np.meshgrid(rings, planets, indexing="ij")
        for z_sun, z_long, z_ring, n in (
            t for teeth in buildable_teeth(ranges, planet_counts).values() for t in teeth
        ):
            # the short pinion: outer, on the second ring; inner the long pinion on the sun
            ok = _pair_fits(
                np.full(short.shape, z_sun), np.full(short.shape, z_long), short, ring2, True
            )
            ok &= (ring2 - z_sun) % n == 0
            for i in np.flatnonzero(ok.any(axis=1)).tolist():
                z_r2 = int(rings[i])
                z_p2 = int(planets[np.flatnonzero(ok[i])[0]])
                key = (Fraction(z_ring, z_sun), Fraction(z_r2, z_sun))
                found.setdefault(key, []).append((z_sun, z_long, z_ring, n, z_r2, z_p2))
        return found
    raise ValueError(f"fit-teeth cannot build kind {kind!r}")


def _tolerance(d: GearboxDescription, tolerance: float | None) -> float:
    # "Reproduce to every printed decimal": within half a unit of the last printed place.
    return 0.5 * 10.0 ** (-d.ratio_decimals) if tolerance is None else tolerance


def fit_teeth(
    d: GearboxDescription,
    ranges: ToothRanges | None = None,
    tolerance: float | None = None,
    top: int = 10,
    max_partial: int = 2_000_000,
    progress: Callable[[str], None] | None = None,
) -> list[TeethCandidate]:
    """Tooth counts whose ratios all lie within ``tolerance`` of the description's gear table.

    ``tolerance`` defaults to half a unit of the table's last printed decimal. The file's
    teeth are not used (a set may have none, ``teeth_optional``). Returns at most ``top``
    candidates, best first (largest error, then smallest gearbox). Raises
    :class:`GearsymError` when a set has no buildable teeth in the ranges or the search would
    exceed ``max_partial`` partial assignments.
    """
    ranges = ranges or ToothRanges()
    for ps in d.planetary_sets:
        if ps.kind not in EXTRA_TEETH:
            raise GearsymError(
                d.file,
                f'planetary_set[name="{ps.name}"].kind',
                f"fit-teeth searches {', '.join(EXTRA_TEETH)} sets; this set is {ps.kind!r} "
                "(give its teeth, `gearsym ratios` checks them)",
            )
    tol = _tolerance(d, tolerance)
    targets = {g.name: g.ratio for g in d.gears if not g.neutral and g.ratio is not None}
    if not targets:
        raise GearsymError(d.file, "gear", "no gear has a target ratio to fit")
    expressions = ratio_expressions(d)
    k_symbols = stationary_ratio_symbols(d)
    variables = list(k_symbols)  # one per sun–ring pair (relation key)
    set_keys = {ps.name: [rel.key for rel in relations(ps)] for ps in d.planetary_sets}
    realisations: dict[str, dict[tuple[Fraction, ...], list[Realisation]]] = {}
    options: dict[str, list[Fraction]] = {}
    for ps in d.planetary_sets:
        counts = ranges.planet_counts or (
            (ps.planet_count,) if ps.planet_count else DEFAULT_PLANET_COUNTS
        )
        realisations[ps.name] = buildable_realisations(ps.kind, ranges, counts)
        if not realisations[ps.name]:
            raise GearsymError(
                d.file,
                f'planetary_set[name="{ps.name}"]',
                f"no buildable {ps.kind} teeth in the ranges (sun {ranges.sun[0]}:"
                f"{ranges.sun[1]}, planet {ranges.planet[0]}:{ranges.planet[1]}, ring ≤ "
                f"{ranges.ring_max}, planet counts {', '.join(map(str, counts))}): the search "
                "space is empty",
            )
        for i, key in enumerate(set_keys[ps.name]):
            options[key] = sorted({ks[i] for ks in realisations[ps.name]})

    depends = {
        g: {v for v in variables if k_symbols[v] in expressions[g].free_symbols}
        for g in targets
        if expressions[g] is not None
    }
    functions = {
        g: sp.lambdify([k_symbols[v] for v in variables], expressions[g], "numpy") for g in depends
    }
    order = _assignment_order(variables, depends, {v: len(options[v]) for v in variables})

    # Partial assignments: one column of k values per assigned stationary ratio.
    columns: dict[str, np.ndarray] = {}
    count = 1
    done: set[str] = set()
    for level, v in enumerate(order, start=1):
        values = np.array([float(k) for k in options[v]])
        total = count * len(values)
        if total > max_partial:
            raise GearsymError(
                d.file,
                "planetary_set",
                f"tooth search too large ({total} partial assignments at {v!r}); narrow "
                "the tooth ranges or give fewer planet counts",
            )
        columns = {name: np.repeat(col, len(values)) for name, col in columns.items()}
        columns[v] = np.tile(values, count)
        done.add(v)
        keep = np.ones(total, dtype=bool)
        for g, needed in depends.items():
            if needed <= done and (needed & {v} or not needed):
                args = [columns.get(name, np.ones(total)) for name in variables]
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = np.broadcast_to(np.asarray(functions[g](*args), dtype=float), (total,))
                keep &= np.abs(ratio - targets[g]) <= tol
        columns = {name: col[keep] for name, col in columns.items()}
        count = int(keep.sum())
        if progress:
            progress(f"{v} ({level}/{len(order)}): {count} partial assignments kept")
        if count == 0:
            return []

    lookup = {v: {float(k): k for k in options[v]} for v in variables}
    candidates: list[TeethCandidate] = []
    for row in range(count):
        ks = {v: lookup[v][float(columns[v][row])] for v in variables}
        chosen: dict[str, list[Realisation]] = {}
        for s, keys in set_keys.items():
            found = realisations[s].get(tuple(ks[key] for key in keys))
            if not found:  # the two ratios of a Ravigneaux set: no one tooth set has both
                break
            # Smallest realisation first; the others share k and so every ratio.
            chosen[s] = sorted(found, key=lambda t: (t[0] + t[2], t))
        else:
            candidate = _exact_candidate(d, {s: ts[0] for s, ts in chosen.items()}, targets)
            if candidate.max_error <= tol:
                candidates.append(
                    replace(candidate, alternatives={s: ts[1:] for s, ts in chosen.items()})
                )
    candidates.sort(key=lambda c: (c.max_error, sum(t[2] for t in c.teeth.values()), str(c.teeth)))
    return candidates[:top]


def _assignment_order(
    variables: list[str], depends: dict[str, set[str]], sizes: dict[str, int]
) -> list[str]:
    """Greedy: next the ratio that completes the most gears; ties to the smaller list."""
    order: list[str] = []
    remaining = list(variables)
    while remaining:

        def score(v: str) -> tuple[int, int, int]:
            assigned = set(order) | {v}
            completes = sum(1 for need in depends.values() if v in need and need <= assigned)
            return (-completes, sizes[v], variables.index(v))

        best = min(remaining, key=score)
        order.append(best)
        remaining.remove(best)
    return order


def _exact_candidate(
    d: GearboxDescription,
    teeth: dict[str, Realisation],
    targets: dict[str, float | None],
) -> TeethCandidate:
    fitted = with_teeth(d, teeth)
    k = stationary_ratios(fitted)
    ratios: dict[str, float] = {}
    errors: dict[str, float] = {}
    for g in fitted.gears:
        if g.neutral:
            continue
        result = gear_ratio(fitted, g, k)
        assert result.ratio is not None
        ratios[g.name] = float(result.ratio)
        target = targets.get(g.name)
        if target is not None:
            errors[g.name] = abs(ratios[g.name] - target)
    return TeethCandidate(teeth=teeth, ratios=ratios, errors=errors)


def with_teeth(d: GearboxDescription, teeth: dict[str, Realisation]) -> GearboxDescription:
    """A copy of the description with new tooth counts and planet counts (realisation tuples
    as :func:`teeth_keys` orders them)."""
    sets = []
    for ps in d.planetary_sets:
        t = teeth.get(ps.name)
        if t is None:
            sets.append(ps)
            continue
        extra: dict[str, int] = {}
        if ps.kind == "double_pinion":
            extra = {"z_planet2": t[4]}
        elif ps.kind == "ravigneaux":
            extra = {"z_sun2": t[4], "z_planet2": t[5]}
        elif ps.kind == "ravigneaux_two_rings":
            extra = {"z_ring2": t[4], "z_planet2": t[5]}
        sets.append(
            replace(
                ps,
                z_sun=t[0],
                z_planet=t[1],
                z_ring=t[2],
                planet_count=t[3],
                given_k=None,
                teeth_given=True,
                **extra,
            )
        )
    return replace(d, planetary_sets=tuple(sets))
