"""The CasADi printer: SymPy expressions as Python source that builds CasADi SX expressions."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import sympy as sp
from gearsym.symbolic.codegen.config import Precision
from gearsym.symbolic.codegen.expressions import FUNCTION_NAMES, HELPER_COUNT_NAMES
from gearsym.symbolic.codegen.printing import SharedPrinting, float_repr, route_functions
from sympy.printing.precedence import PRECEDENCE
from sympy.printing.pycode import PythonCodePrinter

__all__ = ["CasadiPrinter", "python_tuple"]

_CASADI_FUNCTIONS = {  # SymPy class name -> casadi function (C name where identical)
    **{k: v for k, v in FUNCTION_NAMES.items() if v not in ("tgamma", "lgamma", "cbrt", "erfc")},
    "exp2": None,
    "log2": None,
    "Cbrt": None,
}


def python_tuple(items: Sequence[str]) -> str:
    """Source text of a tuple of already-printed items."""
    return "(" + ", ".join(items) + ("," if len(items) == 1 else "") + ")"


class CasadiPrinter(SharedPrinting, PythonCodePrinter):
    """Python printer whose output builds CasADi expressions (``ca.sin``, ``ca.if_else``, ...).

    Works on the same CSE'd form as the C printer; symbols map to ``x[i]``, ``u[i]``, ``p[i]``.
    NaN behaves as in the C: ``Min``/``Max`` and a Piecewise whose condition has a NaN operand
    give NaN (CasADi's fmin/fmax drop a NaN argument, like C99's). They call helpers of the
    emitted module (``_min``, ``_max``, ``_nan_guard``); ``used_helpers`` records which.
    """

    def __init__(
        self,
        symbol_map: Mapping[sp.Symbol, str],
        conditions: Mapping[sp.Symbol, sp.Basic] | None = None,
        precision: Precision | None = None,
    ) -> None:
        super().__init__({"strict": True, "fully_qualified_modules": False})
        self._init_shared(symbol_map, conditions, precision)

    def _number(self, value: float) -> str:
        return float_repr(value)

    def _decimal(self, text: str) -> str:
        return text

    def _select(self, cond: str, then: str, other: str) -> str:
        return f"ca.if_else({cond}, {then}, {other})"

    def _nan_guard(self, operands: Sequence[str], text: str) -> str:
        self.used_helpers.add("nan_guard")
        return f"_nan_guard({python_tuple(operands)}, {text})"

    def _print_Function(self, expr: sp.Function) -> str:
        name = type(expr).__name__
        args = [self._print(a) for a in expr.args]
        if name in ("Min", "Max"):
            helper = HELPER_COUNT_NAMES[name]
            self.used_helpers.add(helper)
            text = args[-1]
            for arg in reversed(args[:-1]):
                text = f"_{helper}({arg}, {text})"
            return text
        if name == "erfc":
            return f"(1.0 - ca.erf({args[0]}))"
        if name == "sign":
            return f"ca.sign({args[0]})"
        if name == "Heaviside":
            x = args[0]
            h0 = self._print(expr.args[1] if len(expr.args) > 1 else sp.S.Half)
            # NaN stays NaN, as in the C helper (the comparisons alone would give h0)
            return self._nan_guard([x], f"ca.if_else({x} > 0, 1.0, ca.if_else({x} < 0, 0.0, {h0}))")
        if _CASADI_FUNCTIONS.get(name):
            return f"ca.{_CASADI_FUNCTIONS[name]}({', '.join(args)})"
        return self._print_not_supported(expr)

    def _print_Pow(self, expr: sp.Pow) -> str:
        base, exp = expr.base, expr.exp
        b = self.parenthesize(base, PRECEDENCE["Pow"], strict=True)
        if exp.is_Integer:
            return f"{b}**{int(exp)}" if exp > 0 else f"{b}**({int(exp)})"
        if exp == sp.S.Half:
            return f"ca.sqrt({self._print(base)})"
        if exp == -sp.S.Half:
            return f"(1.0/ca.sqrt({self._print(base)}))"
        return f"ca.power({self._print(base)}, {self._print(exp)})"

    def _print_NaN(self, expr: sp.Basic) -> str:
        return 'float("nan")'

    def _print_Infinity(self, expr: sp.Basic) -> str:
        return 'float("inf")'

    def _print_NegativeInfinity(self, expr: sp.Basic) -> str:
        return '(-float("inf"))'

    def _print_And(self, expr: sp.And) -> str:
        return self._fold_logic("ca.logic_and", expr.args)

    def _print_Or(self, expr: sp.Or) -> str:
        return self._fold_logic("ca.logic_or", expr.args)

    def _fold_logic(self, fn: str, args: Sequence[sp.Basic]) -> str:
        text = self._print(args[-1])
        for arg in reversed(args[:-1]):
            text = f"{fn}({self._print(arg)}, {text})"
        return text

    def _print_Not(self, expr: sp.Not) -> str:
        return f"ca.logic_not({self._print(expr.args[0])})"

    def _print_BooleanTrue(self, expr: sp.Basic) -> str:
        return "1"

    def _print_BooleanFalse(self, expr: sp.Basic) -> str:
        return "0"


route_functions(CasadiPrinter)
