"""Search integer tooth counts that reproduce a target ratio table.

Gear ratios depend on a set's teeth only through its stationary ratio k = z_ring / z_sun
(:mod:`gearsym.symbolic.ratios`). The search therefore

1. lists, per set, every buildable (z_sun, z_planet, z_ring) in the given ranges — z_ring =
   z_sun + 2 z_planet, equal planet spacing ((z_sun + z_ring) divisible by the planet count) and
   no collision of neighbouring planets — grouped by the exact fraction k;
2. assigns the sets one after another (the next set is the one that completes the most gears),
   pruning every partial assignment by the gears whose ratio depends only on assigned sets;
3. re-checks every surviving combination exactly (rational arithmetic) and ranks it by its
   largest ratio error.

Nothing here is specific to one gearbox: the dependency of each gear on the sets is read off
the symbolic ratio expressions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from fractions import Fraction

import numpy as np
import sympy as sp
from gearsym.symbolic.description import GearboxDescription, planets_fit
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.ratios import gear_ratio, ratio_expressions, stationary_ratio_symbols


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

    teeth: dict[str, tuple[int, int, int, int]]  # set -> (z_sun, z_planet, z_ring, planets)
    ratios: dict[str, float]
    errors: dict[str, float]
    #: Other buildable teeth with the same k per set (same ratios, other sizes).
    alternatives: dict[str, list[tuple[int, int, int, int]]] = field(default_factory=dict)

    @property
    def max_error(self) -> float:
        return max(self.errors.values(), default=0.0)


def buildable_teeth(
    ranges: ToothRanges, planet_counts: tuple[int, ...]
) -> dict[Fraction, list[tuple[int, int, int, int]]]:
    """Every buildable (z_sun, z_planet, z_ring, planets) in range, grouped by k = z_ring/z_sun."""
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

    ``tolerance`` defaults to half a unit of the table's last printed decimal. Returns at most
    ``top`` candidates, best first (largest error, then smallest gearbox). Raises
    :class:`GearsymError` when the search would exceed ``max_partial`` partial assignments.
    """
    ranges = ranges or ToothRanges()
    for ps in d.planetary_sets:
        if ps.kind != "simple":
            # The search lists buildable simple sets (z_ring = z_sun + 2 z_planet); the
            # buildability of compound kinds (pinion triangles, two suns) is not searched.
            raise GearsymError(
                d.file,
                f'planetary_set[name="{ps.name}"].kind',
                f"fit-teeth searches simple sets only; this set is {ps.kind!r} "
                "(give its teeth, `gearsym ratios` checks them)",
            )
    tol = _tolerance(d, tolerance)
    targets = {g.name: g.ratio for g in d.gears if not g.neutral and g.ratio is not None}
    if not targets:
        raise GearsymError(d.file, "gear", "no gear has a target ratio to fit")
    expressions = ratio_expressions(d)
    k_symbols = stationary_ratio_symbols(d)
    set_names = [ps.name for ps in d.planetary_sets]
    options: dict[str, list[Fraction]] = {}
    realisations: dict[str, dict[Fraction, list[tuple[int, int, int, int]]]] = {}
    for ps in d.planetary_sets:
        counts = ranges.planet_counts or (ps.planet_count,)
        realisations[ps.name] = buildable_teeth(ranges, counts)
        options[ps.name] = sorted(realisations[ps.name])
        if not options[ps.name]:
            raise GearsymError(
                d.file, f'planetary_set[name="{ps.name}"]', "no buildable teeth in the ranges"
            )

    depends = {
        g: {s for s in set_names if k_symbols[s] in expressions[g].free_symbols}
        for g in targets
        if expressions[g] is not None
    }
    functions = {
        g: sp.lambdify([k_symbols[s] for s in set_names], expressions[g], "numpy") for g in depends
    }
    order = _assignment_order(set_names, depends, {s: len(options[s]) for s in set_names})

    # Partial assignments: one column of k values per assigned set.
    columns: dict[str, np.ndarray] = {}
    count = 1
    done: set[str] = set()
    for level, s in enumerate(order, start=1):
        values = np.array([float(k) for k in options[s]])
        total = count * len(values)
        if total > max_partial:
            raise GearsymError(
                d.file,
                "planetary_set",
                f"tooth search too large ({total} partial assignments at set {s!r}); narrow "
                "the tooth ranges or give fewer planet counts",
            )
        columns = {name: np.repeat(col, len(values)) for name, col in columns.items()}
        columns[s] = np.tile(values, count)
        done.add(s)
        keep = np.ones(total, dtype=bool)
        for g, needed in depends.items():
            if needed <= done and (needed & {s} or not needed):
                args = [columns.get(name, np.ones(total)) for name in set_names]
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = np.broadcast_to(np.asarray(functions[g](*args), dtype=float), (total,))
                keep &= np.abs(ratio - targets[g]) <= tol
        columns = {name: col[keep] for name, col in columns.items()}
        count = int(keep.sum())
        if progress:
            progress(f"set {s} ({level}/{len(order)}): {count} partial assignments kept")
        if count == 0:
            return []

    k_lookup = {s: {float(k): k for k in options[s]} for s in set_names}
    candidates: list[TeethCandidate] = []
    for row in range(count):
        ks = {s: k_lookup[s][float(columns[s][row])] for s in set_names}
        # Smallest realisation first; the others share k and so every ratio.
        options_k = {
            s: sorted(realisations[s][ks[s]], key=lambda t: (t[0] + t[2], t)) for s in set_names
        }
        candidate = _exact_candidate(d, {s: options_k[s][0] for s in set_names}, targets)
        if candidate.max_error <= tol:
            candidates.append(
                replace(candidate, alternatives={s: options_k[s][1:] for s in set_names})
            )
    candidates.sort(key=lambda c: (c.max_error, sum(t[2] for t in c.teeth.values()), str(c.teeth)))
    return candidates[:top]


def _assignment_order(
    sets: list[str], depends: dict[str, set[str]], sizes: dict[str, int]
) -> list[str]:
    """Greedy: next the set that completes the most gears; ties to the smaller candidate list."""
    order: list[str] = []
    remaining = list(sets)
    while remaining:

        def score(s: str) -> tuple[int, int, int]:
            assigned = set(order) | {s}
            completes = sum(1 for need in depends.values() if s in need and need <= assigned)
            return (-completes, sizes[s], sets.index(s))

        best = min(remaining, key=score)
        order.append(best)
        remaining.remove(best)
    return order


def _exact_candidate(
    d: GearboxDescription,
    teeth: dict[str, tuple[int, int, int, int]],
    targets: dict[str, float | None],
) -> TeethCandidate:
    k = {s: sp.Rational(t[2], t[0]) for s, t in teeth.items()}
    ratios: dict[str, float] = {}
    errors: dict[str, float] = {}
    for g in d.gears:
        if g.neutral:
            continue
        result = gear_ratio(d, g, k)
        assert result.ratio is not None
        ratios[g.name] = float(result.ratio)
        target = targets.get(g.name)
        if target is not None:
            errors[g.name] = abs(ratios[g.name] - target)
    return TeethCandidate(teeth=teeth, ratios=ratios, errors=errors)


def with_teeth(
    d: GearboxDescription, teeth: dict[str, tuple[int, int, int, int]]
) -> GearboxDescription:
    """A copy of the description with new tooth counts and planet counts."""
    sets = tuple(
        replace(ps, z_sun=t[0], z_planet=t[1], z_ring=t[2], planet_count=t[3], given_k=None)
        if (t := teeth.get(ps.name))
        else ps
        for ps in d.planetary_sets
    )
    return replace(d, planetary_sets=sets)
