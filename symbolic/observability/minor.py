"""The witness minor of a full-rank verdict and where it vanishes (for the drop search).

A full-rank verdict (4.12) holds wherever its witness minor — a maximal minor of ``Q`` (4.7) —
is nonzero, so the rank can only drop on the minor's zero set. This module factors a small
minor symbolically (numerator of the determinant in sparse polynomial rings, factors split off
cheaply by gcds first) and tests coordinate hyperplanes ``variable = 0`` on which a large one
vanishes. Each zero set found is only a *candidate*; :mod:`.drops` decides it by an exact rank.
"""

from __future__ import annotations

import random
from typing import Any

import symengine as se
import sympy as sp
from gearsym.symbolic.observability.errors import (
    SamplingError,
    UnsupportedExpressionError,
    ZeroDenominator,
)
from gearsym.symbolic.observability.exact import Echelon, Evaluator, Point
from gearsym.symbolic.observability.lie import SymbolTable
from sympy.polys.matrices import DomainMatrix


def preference(symbols: SymbolTable, name: str) -> tuple[int, str]:
    """Order in which to solve a factor for a variable: inputs first, then their derivatives,
    states, estimated parameters, known parameters (ties by variable name)."""
    return symbols.kinds.get(name, len(symbols.kinds)), symbols.names.get(name, name)


def minor_factors(
    symbols: SymbolTable, minor: list[list[sp.Expr]], terms_limit: int, notes: list[str]
) -> list[tuple[sp.Expr, tuple[sp.Symbol, sp.Expr] | None]]:
    """Factor the numerator of a symbolic minor; solve each factor for a linear variable.

    The determinant is computed in SymPy's sparse polynomial rings (not with ``Expr``
    arithmetic, :func:`minor_numerator`), after expanding along rows and columns with a single
    constant nonzero entry (which only changes it by a nonzero constant). Multivariate
    factorisation is the expensive step, so :func:`factor_polynomial` first splits off every
    factor it can get from gcds; a remaining part with more than ``terms_limit`` terms is not
    factored further.
    """
    trig = {}
    for row in minor:
        for e in row:
            for t in e.atoms(sp.sin, sp.cos):
                trig.setdefault(t, sp.Dummy(f"{type(t).__name__}_{t.args[0]}"))
    back = {d: t for t, d in trig.items()}
    entries = drop_constant_lines([[e.xreplace(trig) for e in row] for row in minor])
    numerator = minor_numerator(entries)
    if numerator is None or numerator.is_ground:
        return []  # a constant minor has no zero set
    factors = factor_polynomial(numerator, terms_limit, notes)
    ring = numerator.ring
    out = []
    for fac, _mult in factors:
        present = {
            ring.symbols[i]: g for i, g in enumerate(ring.gens) if fac.degree(g) > 0
        }  # degrees on the sparse polynomial: no conversion to Poly per variable
        if not present:
            continue
        expr = fac.as_expr()
        sol = None
        candidates = sorted(
            (s for s in present if s not in back),
            key=lambda s: preference(symbols, s.name),
        )
        for var in candidates:
            gen = present[var]
            if fac.degree(gen) == 1:
                c1 = fac.diff(gen)  # fac = c1 * var + c0
                c0 = fac - c1 * gen
                sol = (var, sp.together(-c0.as_expr() / c1.as_expr()).xreplace(back))
                break
        if sol is None and set(present) <= set(back):
            # a pure sin/cos factor: sin(s) = 0 at s = 0, cos(s) = 0 at s = pi/2
            if expr in back and isinstance(back[expr], sp.sin):
                sol = (back[expr].args[0], sp.S.Zero)
            elif expr in back and isinstance(back[expr], sp.cos):
                sol = (back[expr].args[0], sp.pi / 2)
        out.append((expr.xreplace(back), sol))
    return out


def minor_numerator(entries: list[list[sp.Expr]]) -> Any:
    """Numerator of the determinant of a square matrix of rational functions, reduced.

    Entries are converted node by node into the fraction field ``ZZ(symbols)`` (no ``expand``
    of the expression trees); each row is multiplied by the lcm ``L_i`` of its denominators,
    the polynomial determinant ``D`` is computed fraction-free, and factors shared with
    ``prod L_i`` are divided out, so the result is the numerator of ``det = D / prod L_i`` in
    lowest terms (a sparse ``PolyElement``). ``None`` if no symbol occurs.
    """
    from sympy import ZZ

    size = len(entries)
    symbols = sorted({s for row in entries for e in row for s in e.free_symbols}, key=str)
    if size == 0 or not symbols:
        return None
    domain = ZZ.frac_field(*symbols)
    field_ = domain.field
    gens = dict(zip(symbols, field_.gens, strict=True))
    cache: dict[sp.Basic, Any] = {}

    def convert(e: sp.Basic) -> Any:
        value = cache.get(e)
        if value is not None:
            return value
        if e.is_Symbol:
            value = gens[e]
        elif e.is_Rational:
            value = field_(int(e.p)) / field_(int(e.q))
        elif e.is_Add:
            value = field_(0)
            for a in e.args:
                value = value + convert(a)
        elif e.is_Mul:
            value = field_(1)
            for a in e.args:
                value = value * convert(a)
        elif e.is_Pow and e.exp.is_Integer:
            value = convert(e.base) ** int(e.exp)
        else:
            raise UnsupportedExpressionError(f"cannot convert {type(e).__name__} {e} exactly")
        cache[e] = value
        return value

    ring = field_.ring
    rows = []
    denominators = ring(1)
    for row in entries:
        values = [convert(e) for e in row]
        lcm = ring(1)
        for v in values:
            lcm = lcm.lcm(v.denom)
        rows.append([v.numer * lcm.exquo(v.denom) for v in values])
        denominators = denominators * lcm
    numerator = DomainMatrix(rows, (size, size), domain.get_ring()).det()
    while not numerator.is_zero:
        common = numerator.gcd(denominators)
        if common.is_ground:
            break
        numerator = numerator.exquo(common)
    return numerator


def drop_constant_lines(entries: list[list[sp.Expr]]) -> list[list[sp.Expr]]:
    """Laplace expansion along rows/columns whose only nonzero entry is a number.

    The determinant of the result equals that of ``entries`` up to a nonzero constant factor,
    so both have the same zero set (e.g. the output rows ``y`` of (4.8) are unit rows).
    """
    rows = list(range(len(entries)))
    cols = list(range(len(entries)))
    changed = True
    while changed and rows:
        changed = False
        for i in rows:
            nonzero = [j for j in cols if entries[i][j] != 0]
            if len(nonzero) == 1 and entries[i][nonzero[0]].is_number:
                rows.remove(i)
                cols.remove(nonzero[0])
                changed = True
                break
        else:
            for j in cols:
                nonzero = [i for i in rows if entries[i][j] != 0]
                if len(nonzero) == 1 and entries[nonzero[0]][j].is_number:
                    rows.remove(nonzero[0])
                    cols.remove(j)
                    changed = True
                    break
    return [[entries[i][j] for j in cols] for i in rows]


def factor_polynomial(poly: Any, terms_limit: int, notes: list[str]) -> list[tuple[Any, int]]:
    """Irreducible factors of ``poly`` (a sparse ``PolyElement``), cheap parts first.

    Monomial content is split off; then, while some variable ``v`` occurs with degree 1,
    ``poly = a v + b`` splits into ``g = gcd(a, b)`` (free of ``v``, factored recursively) and
    ``poly / g``, which is primitive and of degree 1 in ``v``, hence irreducible. Only a part
    without such a variable goes to full multivariate factorisation, and only if it has at most
    ``terms_limit`` terms (otherwise it is kept whole and a note says so). Multiplicities are
    those found; factors are sparse polynomials of the same ring.
    """
    ring = poly.ring
    out: list[tuple[Any, int]] = []
    pending = [poly]
    while pending:
        p = pending.pop()
        if p.is_ground:
            continue
        low = tuple(min(column) for column in zip(*p.monoms(), strict=True))
        if any(low):
            out.extend((g, e) for g, e in zip(ring.gens, low, strict=True) if e)
            p = p.exquo(ring({low: ring.domain.one}))
            if p.is_ground:
                continue
        # among the variables of degree 1, the one with the smallest coefficient a: the gcd
        # is cheapest there (and a small a often is the whole content)
        monoms = p.monoms()
        counts = {
            i: sum(1 for m in monoms if m[i] == 1)
            for i in range(len(ring.gens))
            if max(m[i] for m in monoms) == 1
        }
        linear = ring.gens[min(counts, key=lambda i: (counts[i], i))] if counts else None
        if linear is not None:
            a = p.diff(linear)  # p = a * linear + b with a, b free of linear
            common = a.gcd(p - a * linear)
            if common.is_ground:
                out.append((p, 1))
            else:
                out.append((p.exquo(common), 1))
                pending.append(common)
            continue
        if len(p.terms()) <= terms_limit:
            _, factors = p.factor_list()
            out.extend(factors)
        else:
            notes.append(
                f"a factor of the minor numerator has {len(p.terms())} > {terms_limit} terms "
                "and no variable of degree 1: it was not factored further"
            )
            out.append((p, 1))
    return out


def minor_vanishes_on(
    minor: list[list[se.Basic]], var: se.Symbol, rng: random.Random, angles: frozenset[str]
) -> bool:
    """Does the minor vanish (mod P) where two random lines parallel to the ``var`` axis cross
    the hyperplane ``var = 0``? (For an angle ``s``, ``s = 0`` is ``t = 0``.)

    A zero here only proposes a candidate; :func:`.drops.rank_under_conditions` decides.
    """
    restricted = [[e.subs({var: 0}) for e in row] for row in minor]
    for _ in range(2):
        ev = Evaluator(Point(rng, angles), exact=False)
        try:
            vals = ev.rows(restricted)
        except (ZeroDenominator, SamplingError):
            return False  # the hyperplane lies (partly) where the model is singular
        ech = Echelon(exact=False)
        for idx, row in enumerate(vals):
            ech.add(row, idx)
        if ech.rank == len(minor):
            return False
    return True
