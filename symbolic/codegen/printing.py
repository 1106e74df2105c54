"""Printing rules shared by the C and the CasADi printer, and text helpers for emitted comments.

Each backend's printer (``c/printer.py``, ``casadi/printer.py``) mixes :class:`SharedPrinting`
into a SymPy printer and implements its hooks (:meth:`SharedPrinting._number` and friends).
Emitters use a printer only through :meth:`SharedPrinting.code` and its ``used_*`` sets.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import Any

import sympy as sp
from gearsym.symbolic.codegen.config import Precision
from gearsym.symbolic.codegen.expressions import (
    FUNCTION_NAMES,
    HELPER_FUNCTIONS,
    condition_operands,
    split_mul,
)
from sympy.printing.precedence import PRECEDENCE

__all__ = ["SharedPrinting", "comment_text", "float_repr", "route_functions", "wrap"]


def float_repr(value: float) -> str:
    """Shortest round-trip decimal, always with a '.' or an exponent (so ``v##f`` is valid C)."""
    text = repr(float(value))
    if not any(c in text for c in ".en"):
        text += ".0"
    return text


_ASCII_REPLACEMENTS = {
    "·": "*",
    "×": "x",
    "²": "^2",
    "³": "^3",
    "µ": "u",
    "°": "deg",
    "–": "-",
    "—": "-",
    "−": "-",
    "’": "'",
    "“": '"',
    "”": '"',
}


def comment_text(text: str) -> str:
    """Text safe inside a C block comment: ASCII only (ECU toolchains), no comment delimiters."""
    text = " ".join(str(text).split())
    if not text.isascii():
        text = "".join(
            c if ord(c) < 128 else _ASCII_REPLACEMENTS.get(c, f"<U+{ord(c):04X}>") for c in text
        )
    return text.replace("*/", "* /").replace("/*", "/ *")


def wrap(text: str, width: int = 92) -> list[str]:
    """``text`` broken into lines of at most ``width`` characters at spaces."""
    words, lines, line = text.split(), [], ""
    for word in words:
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    if line:
        lines.append(line)
    return lines


@lru_cache(maxsize=4096)
def _decimal_text(value: sp.Rational, digits: int) -> str:
    """``value`` correctly rounded to ``digits`` significant digits (both printers print the
    same large rationals, each many times: the conversion is worth remembering)."""
    return str(sp.Float(value, digits))


class SharedPrinting:
    """Printing rules common to the C and the CasADi printer (mixed into both)."""

    _symbol_map: dict[sp.Symbol, str]
    _conditions: dict[sp.Symbol, sp.Basic]  # boolean CSE temporaries -> their expressions
    _precision: Precision

    def _init_shared(
        self,
        symbol_map: Mapping[sp.Symbol, str],
        conditions: Mapping[sp.Symbol, sp.Basic] | None,
        precision: Precision | None,
    ) -> None:
        self._symbol_map = dict(symbol_map)
        self._conditions = dict(conditions or {})
        self._precision = precision or Precision()
        self.used_helpers: set[str] = set()

    def code(self, expr: sp.Basic) -> str:
        """The source text of ``expr`` (the printers' one public entry point)."""
        return self._print(expr)  # type: ignore[attr-defined]  # the SymPy printer's

    def _as_ordered_terms(self, expr: sp.Basic, order: str | None = None) -> list[sp.Basic]:
        # The terms of a sum in SymPy's own canonical order (a structural comparison, independent
        # of hashing): deterministic like as_ordered_terms(), whose monomial ordering was a
        # quarter of the printing time.
        return list(expr.args)

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        return self._symbol_map.get(expr, expr.name)

    _print_Dummy = _print_Symbol

    def _print_Mul(self, expr: sp.Mul) -> str:
        negative, coeff, numerator, denominator = split_mul(expr)
        factors = []
        if coeff != 1:
            factors.append(self._coefficient(coeff))
        factors += [self.parenthesize(f, PRECEDENCE["Mul"], strict=False) for f in numerator]
        text = "*".join(factors) if factors else self._number(1)
        if denominator:
            den = [self.parenthesize(f, PRECEDENCE["Mul"], strict=True) for f in denominator]
            text += "/" + (den[0] if len(den) == 1 else "(" + "*".join(den) + ")")
        return ("-" if negative else "") + text

    def _coefficient(self, coeff: sp.Number) -> str:
        if coeff.is_Rational and coeff.q != 1:
            return self._print_Rational(coeff)
        return self._number(float(coeff))

    def _print_Integer(self, expr: sp.Integer) -> str:
        return ("-" if expr < 0 else "") + self._number(abs(int(expr)))

    _print_Zero = _print_One = _print_NegativeOne = _print_Integer

    def _print_Rational(self, expr: sp.Rational) -> str:
        if expr.q == 1:
            return self._print_Integer(sp.Integer(expr.p))
        if max(abs(expr.p), expr.q) <= self._precision.exact_integer_limit:
            # Exact: both integers are exact literals (in float too) and the division is folded
            # at compile time into the correctly rounded quotient.
            text = "(" + self._number(abs(expr.p)) + "/" + self._number(expr.q) + ")"
        else:
            # Larger integers would be rounded (or overflow float) as literals: print the
            # quotient itself with enough digits to be correctly rounded in float and double.
            text = self._decimal(_decimal_text(abs(expr), self._precision.decimal_digits))
        return ("-" if expr < 0 else "") + text

    _print_Half = _print_Rational

    def _print_Float(self, expr: sp.Float) -> str:
        value = float(expr)
        return ("-" if value < 0 else "") + self._number(abs(value))

    def _print_NumberSymbol(self, expr: sp.NumberSymbol) -> str:
        digits = self._precision.decimal_digits  # correctly rounded in float and double
        return self._decimal(str(sp.Float(expr.evalf(digits), digits)))

    _print_Pi = _print_Exp1 = _print_GoldenRatio = _print_EulerGamma = _print_NumberSymbol
    _print_Catalan = _print_NumberSymbol

    def _print_Piecewise(self, expr: sp.Piecewise) -> str:
        pieces = list(expr.args)
        if pieces[-1].cond == sp.true:
            text = self._print(pieces.pop().expr)
        else:
            text = self._print(sp.nan)  # no piece applies: SymPy's value is undefined
        for piece in reversed(pieces):
            text = self._select(self._print(piece.cond), self._print(piece.expr), text)
        operands = condition_operands([a.cond for a in expr.args], self._conditions)
        if operands:
            text = self._nan_guard([self._print(o) for o in operands], text)
        return text

    def _print_Relational(self, expr: sp.core.relational.Relational) -> str:
        lhs = self._print(expr.lhs)
        rhs = self._print(expr.rhs)
        return f"({lhs} {expr.rel_op} {rhs})"

    _print_Equality = _print_Unequality = _print_Relational
    _print_StrictLessThan = _print_LessThan = _print_Relational
    _print_StrictGreaterThan = _print_GreaterThan = _print_Relational

    def _print_not_supported(self, expr: Any) -> str:  # never emit partially printed code
        raise NotImplementedError(f"{type(self).__name__} cannot print {type(expr).__name__}")

    _print_Mod = _print_re = _print_im = _print_DiracDelta = _print_Derivative = (
        _print_not_supported
    )
    _print_Integral = _print_Sum = _print_Product = _print_ComplexInfinity = _print_not_supported

    # Hooks the concrete printers implement.
    def _number(self, value: float) -> str:
        raise NotImplementedError

    def _decimal(self, text: str) -> str:
        raise NotImplementedError

    def _select(self, cond: str, then: str, other: str) -> str:
        raise NotImplementedError

    def _nan_guard(self, operands: Sequence[str], text: str) -> str:
        raise NotImplementedError


def route_functions(printer: type) -> None:
    """Send every supported function through ``printer._print_Function``.

    The base printers define ``_print_sin``, ``_print_Abs``, ... themselves; those must not be
    reached, or a plain ``sin`` would slip into float code.
    """
    for name in (*FUNCTION_NAMES, *HELPER_FUNCTIONS):
        setattr(printer, f"_print_{name}", printer._print_Function)
