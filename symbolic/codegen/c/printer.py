"""The C99 printer: SymPy expressions as ``gearsym_real`` code that builds warning-free in float
and double."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import sympy as sp
from gearsym.symbolic.codegen.config import Precision
from gearsym.symbolic.codegen.expressions import FUNCTION_NAMES, HELPER_COUNT_NAMES
from gearsym.symbolic.codegen.printing import SharedPrinting, float_repr, route_functions
from sympy.printing.c import C99CodePrinter
from sympy.printing.precedence import PRECEDENCE

__all__ = ["GearsymCPrinter"]


class GearsymCPrinter(SharedPrinting, C99CodePrinter):
    """C99 printer for ``gearsym_real`` code that builds warning-free in float and double.

    Literals are printed as ``GEARSYM_LIT(1.5)`` and math functions as ``GEARSYM_SIN(...)``; the
    emitted source maps these to ``1.5f``/``sinf`` or ``1.5``/``sin``. Integer powers up to
    ``precision.max_inline_power`` become products, rationals become exact constant quotients,
    Piecewise becomes nested ``?:`` that gives NaN when an operand of a condition is NaN;
    ``sign``/``Heaviside``/``Min``/``Max`` become static helper functions (Min/Max propagate
    NaN, unlike C99's fmin/fmax). ``conditions`` maps boolean CSE temporaries to their
    expressions (for the NaN guard). ``used_macros`` and ``used_helpers`` record what the
    printed code needs.
    """

    def __init__(
        self,
        symbol_map: Mapping[sp.Symbol, str],
        helper_prefix: str,
        conditions: Mapping[sp.Symbol, sp.Basic] | None = None,
        precision: Precision | None = None,
    ) -> None:
        super().__init__({"strict": True})
        self._init_shared(symbol_map, conditions, precision)
        self._helper_prefix = helper_prefix
        self.used_macros: set[str] = set()

    def _number(self, value: float) -> str:
        return self._decimal(float_repr(value))

    def _decimal(self, text: str) -> str:
        return f"GEARSYM_LIT({text})"

    def _select(self, cond: str, then: str, other: str) -> str:
        return f"({cond} ? {then} : {other})"

    def _nan_guard(self, operands: Sequence[str], text: str) -> str:
        test = " || ".join(f"isnan({o})" for o in operands)
        return f"(({test}) ? {self._print(sp.nan)} : {text})"

    def _call(self, c_name: str, *args: str) -> str:
        macro = "GEARSYM_" + c_name.upper()
        self.used_macros.add(c_name)
        return f"{macro}({', '.join(args)})"

    def _print_Function(self, expr: sp.Function) -> str:
        name = type(expr).__name__
        if name in ("Min", "Max"):
            helper = HELPER_COUNT_NAMES[name]
            self.used_helpers.add(helper)
            args = [self._print(a) for a in expr.args]
            text = args[-1]
            for arg in reversed(args[:-1]):
                text = f"{self._helper_prefix}{helper}({arg}, {text})"
            return text
        if name in FUNCTION_NAMES:
            return self._call(FUNCTION_NAMES[name], *(self._print(a) for a in expr.args))
        if name == "sign":
            self.used_helpers.add("sign")
            return f"{self._helper_prefix}sign({self._print(expr.args[0])})"
        if name == "Heaviside":
            self.used_helpers.add("heaviside")
            h0 = expr.args[1] if len(expr.args) > 1 else sp.S.Half
            return f"{self._helper_prefix}heaviside({self._print(expr.args[0])}, {self._print(h0)})"
        return self._print_not_supported(expr)

    def _print_Pow(self, expr: sp.Pow) -> str:
        base, exp = expr.base, expr.exp
        if exp.is_Integer and 1 <= abs(int(exp)) <= self._precision.max_inline_power:
            b = self.parenthesize(base, PRECEDENCE["Mul"], strict=True)
            product = "*".join([b] * abs(int(exp)))
            if exp < 0:
                return f"({self._number(1)}/{product if exp == -1 else '(' + product + ')'})"
            return product if exp == 1 else f"({product})"
        if exp == sp.S.Half:
            return self._call("sqrt", self._print(base))
        if exp == -sp.S.Half:
            return f"({self._number(1)}/{self._call('sqrt', self._print(base))})"
        return self._call("pow", self._print(base), self._print(exp))

    def _print_NaN(self, expr: sp.Basic) -> str:
        return "((gearsym_real)NAN)"

    def _print_Infinity(self, expr: sp.Basic) -> str:
        return "((gearsym_real)INFINITY)"

    def _print_NegativeInfinity(self, expr: sp.Basic) -> str:
        return "(-(gearsym_real)INFINITY)"

    def _print_And(self, expr: sp.And) -> str:
        return "(" + " && ".join(self._print(a) for a in expr.args) + ")"

    def _print_Or(self, expr: sp.Or) -> str:
        return "(" + " || ".join(self._print(a) for a in expr.args) + ")"

    def _print_Not(self, expr: sp.Not) -> str:
        return f"(!{self._print(expr.args[0])})"

    def _print_BooleanTrue(self, expr: sp.Basic) -> str:
        return "1"

    def _print_BooleanFalse(self, expr: sp.Basic) -> str:
        return "0"


route_functions(GearsymCPrinter)
