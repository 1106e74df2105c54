"""The Schwartz–Zippel bound of a rank-deficient verdict of (4.12).

If the computed rank ``r`` of ``Q`` (4.7) is below the generic rank, some ``(r+1)``-minor ``M``
is a nonzero rational function that vanishes at every trial point. :class:`DegreeBounds` bounds,
without expanding anything, each entry of ``Q`` as ``N/D`` where ``D`` is a product of known
"denominator keys" (bases raised to negative powers, and ``1 + t^2`` for angles). Clearing the
row-wise least common multiple of those keys turns row ``i`` into polynomials of degree at most
``d_i``; a minor on rows ``R`` is then ``det / prod(L_i)`` with ``deg det <= sum_{i in R} d_i``.
So ``D_num`` = sum of the ``r+1`` largest ``d_i`` bounds the degree of the numerator of every
relevant minor. Points at which a denominator vanishes mod P are redrawn; the denominators have
total degree at most ``D_den`` (sum of the numerator-degree bounds of all inverted bases), so by
Schwartz–Zippel one trial misses a nonzero minor with probability at most
``eps = D_num / (P - D_den)``. The per-variable verdicts are rank statements about ``Q`` with
one column removed (minors of size ``r``, same degree bound), so with ``k`` independent trials
and a union bound over the rank and the ``n`` variable verdicts the reported bound is
``(n + 1) * eps^k``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import symengine as se
from gearsym.symbolic.observability.errors import UnsupportedExpressionError
from gearsym.symbolic.observability.exact import MODULUS

# A rational-function degree bound: (numerator degree, {denominator key: (degree, exponent)}).
_Deg = tuple[int, dict[Any, tuple[int, int]]]


def _den_degree(den: Mapping[Any, tuple[int, int]]) -> int:
    return sum(d * x for d, x in den.values())


def _lcm(parts: Sequence[_Deg]) -> tuple[int, dict[Any, tuple[int, int]]]:
    """Degree bound of a sum: lcm of the denominators (max exponent per key)."""
    lcm: dict[Any, tuple[int, int]] = {}
    for _, den in parts:
        for key, (d, x) in den.items():
            if key not in lcm or lcm[key][1] < x:
                lcm[key] = (d, x)
    dl = _den_degree(lcm)
    return max(n + dl - _den_degree(den) for n, den in parts), lcm


class DegreeBounds:
    """Bounds ``entry = N/D`` with ``deg N`` and ``D`` a product of keyed polynomials.

    Keys are ``("inv", b)`` for a base ``b`` raised to a negative power (degree = numerator
    bound of ``b``) and ``("circle", s)`` for ``1 + t^2`` of an angle. Rules: a sample variable
    is ``(1, {})``; ``sin/cos(s)`` is ``(2, {circle: 1})``; a sum takes the least common
    multiple of the denominators (max exponent per key) and ``max(n_i + deg L - deg D_i)``; a
    product adds; ``b^k`` multiplies; ``b^-k = D_b^k / N_b^k``. Nothing is expanded.
    ``inverted`` collects every inverted base with its numerator bound, for ``D_den``.
    """

    def __init__(self) -> None:
        self.cache: dict[se.Basic, _Deg] = {}
        self.inverted: dict[se.Basic, int] = {}

    def __call__(self, e: se.Basic) -> _Deg:
        try:
            return self.cache[e]
        except KeyError:
            pass
        v = self._compute(e)
        self.cache[e] = v
        return v

    def _compute(self, e: se.Basic) -> _Deg:
        if isinstance(e, se.Symbol):
            return 1, {}
        if isinstance(e, se.Number):
            return 0, {}
        if isinstance(e, se.Add):
            return _lcm([self(a) for a in e.args])
        if isinstance(e, se.Mul):
            num, prod = 0, {}
            for n, den in (self(a) for a in e.args):
                num += n
                for key, (d, x) in den.items():
                    prod[key] = (d, prod[key][1] + x) if key in prod else (d, x)
            return num, prod
        if isinstance(e, se.Pow):
            base, exp = e.args
            n, den = self(base)
            k = int(exp)
            if k >= 0:
                return k * n, {key: (d, x * k) for key, (d, x) in den.items()}
            self.inverted[base] = n
            return -k * _den_degree(den), {("inv", base): (n, -k)}
        if isinstance(e, (se.sin, se.cos)):
            return 2, {("circle", e.args[0]): (2, 1)}
        raise UnsupportedExpressionError(f"no degree bound for {type(e).__name__} {e}")

    def row_degree(self, row: Sequence[se.Basic]) -> int:
        """Degree bound of the row's entries after multiplying by their common denominator."""
        parts = [self(e) for e in row if e != 0]
        return _lcm(parts)[0] if parts else 0

    @property
    def denominator_degree(self) -> int:
        """``D_den``: total degree bound of every denominator met so far."""
        return sum(self.inverted.values())


def per_trial_error(row_degrees: Sequence[int], rank: int, n: int, d_den: int) -> float:
    """``eps = D_num / (P - D_den)`` for a computed rank ``rank`` of an ``n``-column ``Q``.

    ``row_degrees`` are the row bounds ``d_i`` sorted from largest to smallest.
    """
    d_num = sum(row_degrees[: min(rank + 1, n)])
    return min(1.0, d_num / (MODULUS - d_den)) if d_den < MODULUS else 1.0


def trials_needed(eps: float, n: int, max_error: float, max_trials: int) -> int:
    """Smallest ``k <= max_trials`` with ``(n + 1) eps^k <= max_error``."""
    trials = 1
    while eps > 0 and trials < max_trials and (n + 1) * eps**trials > max_error:
        trials += 1
    return trials
