"""Exact arithmetic of the rank test (4.7), (4.12): exact model numbers, random points,
evaluation of ``Q`` mod the prime ``P = 2^61 - 1`` and over the rationals, row echelon forms.

Entries of ``Q`` are SymEngine expressions (the Lie engine's output, :mod:`.lie`) built from
``+``, ``*``, integer powers, rationals, symbols and ``sin``/``cos`` of an angle symbol. They
are evaluated node by node with a cache, so subexpressions shared between entries (they share
heavily after differentiation) are evaluated once. No floating-point number takes part.

Angles: a point gives an angle ``s`` the value ``2 atan(t)`` with ``t`` sampled like any other
variable, so ``sin s = 2t/(1+t^2)`` and ``cos s = (1-t^2)/(1+t^2)`` are rational; ``1 + t^2``
never vanishes mod P because ``P = 3 (mod 4)``.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import symengine as se
import sympy as sp
from gearsym.symbolic.observability.errors import (
    SamplingError,
    UnsupportedExpressionError,
    ZeroDenominator,
)
from sympy.polys.domains import QQ

#: The prime of the screening arithmetic and the size of the sample set ``{0, ..., P-1}``.
#: ``P = 3 (mod 4)``, so ``1 + t^2`` (angle denominators) never vanishes mod P.
MODULUS = 2**61 - 1


def exact_rational(value: float | str | sp.Basic) -> sp.Rational:
    """The exact rational a model number stands for.

    Python floats and SymPy ``Float`` s of double precision become the rational value of their
    *shortest round-tripping decimal* (``repr``): ``0.405 -> 81/200``, ``0.1 -> 1/10``. That is
    the decimal the author typed; ``sympy.Rational(0.1)`` would instead give the binary value
    ``3602879701896397/36028797018963968``, and ``nsimplify`` may guess constants such as ``pi``
    — neither is wanted. Higher-precision ``Float`` s use their printed decimal digits.
    """
    if isinstance(value, bool):
        raise TypeError("a boolean is not a model number")
    if isinstance(value, int):
        return sp.Integer(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"non-finite number {value!r}")
        return sp.Rational(repr(value))
    if isinstance(value, str):
        return sp.Rational(value)
    value = sp.sympify(value)
    if isinstance(value, sp.Rational):
        return value
    if isinstance(value, sp.Float):
        if value._prec <= 53:
            return sp.Rational(repr(float(value)))
        return sp.Rational(str(value))
    raise TypeError(f"{value!r} is not a number")


def rationalize(expr: sp.Basic) -> sp.Basic:
    """Replace every ``Float`` in ``expr`` by :func:`exact_rational` of it."""
    floats = expr.atoms(sp.Float)
    if not floats:
        return expr
    return expr.xreplace({f: exact_rational(f) for f in floats})


# ---------------------------------------------------------------------------------------------
# Random points
# ---------------------------------------------------------------------------------------------


class Point:
    """A random point: each sample variable gets an integer in ``{0, ..., P-1}`` on first use.

    Variables are keyed by symbol name. For an angle ``s`` the stored integer is ``t`` with
    ``s = 2 atan(t)``.
    """

    def __init__(self, rng: random.Random, angles: Iterable[str]) -> None:
        # Values are derived from (point key, symbol name) rather than drawn in the order the
        # evaluator meets the symbols, so a seed reproduces the same point in every process.
        self.key = rng.getrandbits(64)
        self.angles = frozenset(angles)
        self.values: dict[str, int] = {}

    def value(self, name: str) -> int:
        v = self.values.get(name)
        if v is None:
            v = random.Random(f"{self.key}:{name}").randrange(MODULUS)
            self.values[name] = v
        return v

    def named(self, names: Mapping[str, str]) -> dict[str, str]:
        """The coordinates used so far, by variable name (angles as ``2*atan(t)``)."""
        out = {}
        for sym, v in self.values.items():
            out[names.get(sym, sym)] = f"2*atan({v})" if sym in self.angles else str(v)
        return dict(sorted(out.items()))


class Sampler:
    """Draws independent points; gives up when denominators keep vanishing (singular set)."""

    def __init__(self, rng: random.Random, angles: Iterable[str], limit: int = 64) -> None:
        self.rng = rng
        self.angles = frozenset(angles)
        self.limit = limit
        self.rejected = 0

    def draw(self) -> Point:
        return Point(self.rng, self.angles)

    def reject(self) -> None:
        """Count a point where a denominator vanished; give up after ``limit`` of them."""
        self.rejected += 1
        if self.rejected >= self.limit:
            raise SamplingError(
                f"a denominator of Q vanished at {self.limit} random points: the condition set "
                "lies in the singular set of the model"
            )


# ---------------------------------------------------------------------------------------------
# Evaluation at a point
# ---------------------------------------------------------------------------------------------

# zoo, oo, -oo, nan (their classes are not exported by name)
_SINGULAR = (type(se.zoo), type(se.oo), type(-se.oo), type(se.nan))


class Evaluator:
    """Evaluates SymEngine expressions at a :class:`Point`, mod P (``exact=False``) or in QQ.

    A base raised to a negative power that is zero at the point raises
    :class:`ZeroDenominator` (the caller redraws the point); an infinity left by a condition
    (``1/0`` -> ``zoo``) raises :class:`SamplingError`: every point of that set is singular.
    """

    def __init__(self, point: Point, exact: bool) -> None:
        self.point = point
        self.exact = exact
        self.cache: dict[se.Basic, Any] = {}

    def __call__(self, e: se.Basic) -> Any:
        try:
            return self.cache[e]
        except KeyError:
            pass
        v = self._exact(e) if self.exact else self._modular(e)
        self.cache[e] = v
        return v

    def row(self, row: Sequence[se.Basic]) -> list[Any]:
        return [self(e) for e in row]

    def rows(self, rows: Iterable[Sequence[se.Basic]]) -> list[list[Any]]:
        return [self.row(r) for r in rows]

    def _angle(self, e: se.Basic) -> int:
        arg = e.args[0]
        if not (isinstance(arg, se.Symbol) and arg.name in self.point.angles):
            raise UnsupportedExpressionError(
                f"{e}: only sin/cos of an angle symbol can be evaluated exactly"
            )
        return self.point.value(arg.name)

    def _symbol(self, e: se.Symbol) -> int:
        if e.name in self.point.angles:
            raise UnsupportedExpressionError(f"angle {e} outside sin/cos")
        return self.point.value(e.name)

    def _modular(self, e: se.Basic) -> int:
        if isinstance(e, se.Symbol):
            return self._symbol(e)
        if isinstance(e, se.Add):
            s = 0
            for a in e.args:
                s += self(a)
            return s % MODULUS
        if isinstance(e, se.Mul):
            m = 1
            for a in e.args:
                m = m * self(a) % MODULUS
            return m
        if isinstance(e, se.Pow):
            base, k = e.args
            if not isinstance(k, se.Integer):
                raise UnsupportedExpressionError(f"non-integer power {e}")
            b, k = self(base), int(k)
            if k < 0:
                if not b:
                    raise ZeroDenominator(str(base))
                return pow(pow(b, -1, MODULUS), -k, MODULUS)
            return pow(b, k, MODULUS)
        if isinstance(e, se.Rational):  # integers included
            return int(e.p) * pow(int(e.q), -1, MODULUS) % MODULUS
        if isinstance(e, (se.sin, se.cos)):
            t = self._angle(e)
            num = 2 * t if isinstance(e, se.sin) else 1 - t * t
            return num * pow((1 + t * t) % MODULUS, -1, MODULUS) % MODULUS
        return self._other(e)

    def _exact(self, e: se.Basic) -> Any:
        if isinstance(e, se.Symbol):
            return QQ(self._symbol(e))
        if isinstance(e, se.Add):
            s = QQ(0)
            for a in e.args:
                s += self(a)
            return s
        if isinstance(e, se.Mul):
            m = QQ(1)
            for a in e.args:
                m *= self(a)
            return m
        if isinstance(e, se.Pow):
            base, k = e.args
            if not isinstance(k, se.Integer):
                raise UnsupportedExpressionError(f"non-integer power {e}")
            b, k = self(base), int(k)
            if k < 0 and not b:
                raise ZeroDenominator(str(base))
            return b**k
        if isinstance(e, se.Rational):
            return QQ(int(e.p), int(e.q))
        if isinstance(e, (se.sin, se.cos)):
            t = self._angle(e)
            num = QQ(2 * t) if isinstance(e, se.sin) else QQ(1 - t * t)
            return num / QQ(1 + t * t)
        return self._other(e)

    @staticmethod
    def _other(e: se.Basic) -> Any:
        if isinstance(e, _SINGULAR):
            # e.g. a condition m = 0 turned 1/m into zoo: every point of the set is singular
            raise SamplingError(f"the conditions make Q singular ({e} in an entry)")
        raise UnsupportedExpressionError(f"cannot evaluate {type(e).__name__} {e} exactly")


# ---------------------------------------------------------------------------------------------
# Row echelon form
# ---------------------------------------------------------------------------------------------


class Echelon:
    """Incremental row echelon form over GF(P) (``exact=False``) or QQ.

    Each accepted row is reduced against the earlier basis rows and normalised at its pivot.
    The accepted original rows restricted to the pivot columns form a nonsingular matrix (it is
    a unit-triangular matrix times an invertible change of basis), i.e. a nonzero minor.
    """

    def __init__(self, exact: bool) -> None:
        self.exact = exact
        self.basis: list[tuple[int, list[Any]]] = []
        self.rows: list[int] = []

    @property
    def rank(self) -> int:
        return len(self.basis)

    @property
    def pivots(self) -> list[int]:
        return [pc for pc, _ in self.basis]

    def add(self, row: Sequence[Any], index: int) -> bool:
        row = list(row)
        if self.exact:
            for pc, b in self.basis:
                c = row[pc]
                if c:
                    row = [a - c * bb for a, bb in zip(row, b, strict=True)]
        else:
            for pc, b in self.basis:
                c = row[pc]
                if c:
                    row = [(a - c * bb) % MODULUS for a, bb in zip(row, b, strict=True)]
        pc = next((j for j, a in enumerate(row) if a), None)
        if pc is None:
            return False
        if self.exact:
            inv = QQ(1) / row[pc]
            row = [a * inv for a in row]
        else:
            inv = pow(row[pc], -1, MODULUS)
            row = [a * inv % MODULUS for a in row]
        self.basis.append((pc, row))
        self.rows.append(index)
        return True


def integer_vector(vec: Sequence[Any]) -> list[int]:
    """Scale a rational vector to coprime integers with a positive first nonzero entry."""
    den = 1
    for a in vec:
        den = math.lcm(den, int(a.denominator))
    ints = [int(a.numerator) * (den // int(a.denominator)) for a in vec]
    g = 0
    for a in ints:
        g = math.gcd(g, a)
    if g == 0:
        return ints
    first = next(a for a in ints if a)
    sign = 1 if first > 0 else -1
    return [sign * a // g for a in ints]
