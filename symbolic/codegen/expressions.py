"""What the printers and the operation counter agree on: how a SymPy expression is split into the
operations the emitted code performs.

The C printer, the CasADi printer and :func:`gearsym.symbolic.codegen.ops.count_operations` all
read products, powers, functions and piecewise conditions through these helpers, so a stated
operation count describes the printed code.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from functools import lru_cache

import sympy as sp
from sympy.logic.boolalg import BooleanAtom

__all__ = [
    "FUNCTION_NAMES",
    "HELPER_COUNT_NAMES",
    "HELPER_FUNCTIONS",
    "condition_operands",
    "is_inline_power",
    "split_mul",
]

FUNCTION_NAMES = {  # SymPy class name -> C99 double-precision function
    "sin": "sin",
    "cos": "cos",
    "tan": "tan",
    "asin": "asin",
    "acos": "acos",
    "atan": "atan",
    "atan2": "atan2",
    "sinh": "sinh",
    "cosh": "cosh",
    "tanh": "tanh",
    "asinh": "asinh",
    "acosh": "acosh",
    "atanh": "atanh",
    "exp": "exp",
    "log": "log",
    "erf": "erf",
    "erfc": "erfc",
    "gamma": "tgamma",
    "loggamma": "lgamma",
    "floor": "floor",
    "ceiling": "ceil",
    "Abs": "fabs",
    # sympy.codegen.cfunctions
    "expm1": "expm1",
    "log1p": "log1p",
    "exp2": "exp2",
    "log2": "log2",
    "log10": "log10",
    "Cbrt": "cbrt",
    "Sqrt": "sqrt",
    "hypot": "hypot",
}
#: Printed as calls of static helpers in the .c (Min/Max: C99's fmin/fmax return the other
#: argument for a NaN, which would turn a NaN input into a finite result; the helpers do not).
HELPER_FUNCTIONS = ("sign", "Heaviside", "Min", "Max")
#: Name under which a helper call is counted in :class:`~gearsym.symbolic.codegen.ops.OpCount`.
HELPER_COUNT_NAMES = {"Min": "min", "Max": "max"}


@lru_cache(maxsize=16384)
def split_mul(expr: sp.Mul) -> tuple[bool, sp.Number, tuple[sp.Basic, ...], tuple[sp.Basic, ...]]:
    """``expr = (-1 if negative) * coeff * prod(numerator) / prod(denominator)``.

    Remembered: both printers and the operation count split every product. Signs are read
    from the numbers directly (``is_negative`` would run SymPy's assumption system on each)."""
    coeff, factors = expr.as_coeff_mul()
    negative = bool(coeff.p < 0) if coeff.is_Rational else float(coeff) < 0
    if negative:
        coeff = -coeff
    numerator: list[sp.Basic] = []
    denominator: list[sp.Basic] = []
    for factor in factors:
        if factor.is_Pow and factor.exp.is_Rational and factor.exp.p < 0:
            exp = -factor.exp
            denominator.append(
                factor.base if exp == 1 else sp.Pow(factor.base, exp, evaluate=False)
            )
        else:
            numerator.append(factor)
    return negative, coeff, tuple(numerator), tuple(denominator)


def is_inline_power(expr: sp.Basic, max_inline_power: int) -> bool:
    """A power the printers expand into a product (``b**3`` as ``b*b*b``) whose base is not a
    plain symbol, i.e. one whose base the CSE must hoist so it is evaluated once."""
    return (
        expr.is_Pow
        and expr.exp.is_Integer
        and 2 <= abs(int(expr.exp)) <= max_inline_power
        and not expr.base.is_Symbol
    )


def condition_operands(
    conditions: Iterable[sp.Basic], definitions: Mapping[sp.Symbol, sp.Basic]
) -> list[sp.Basic]:
    """The non-constant operands of every comparison in ``conditions``, in order, once each.

    ``definitions`` maps boolean CSE temporaries to their expressions, which are expanded. A
    comparison with a NaN operand is false (``!=``: true) in IEEE arithmetic, so a Piecewise would
    silently pick a branch; the printers return NaN instead when any of these operands is NaN.
    """
    operands: list[sp.Basic] = []

    def visit(cond: sp.Basic) -> None:
        if isinstance(cond, BooleanAtom):
            return
        if isinstance(cond, sp.core.relational.Relational):
            for side in (cond.lhs, cond.rhs):
                if not side.is_number and side not in operands:
                    operands.append(side)
        elif isinstance(cond, (sp.And, sp.Or, sp.Not)):
            for arg in cond.args:
                visit(arg)
        elif isinstance(cond, sp.Symbol) and cond in definitions:
            visit(definitions[cond])
        else:  # never guard partially: an unknown condition must not pass silently
            raise NotImplementedError(f"cannot find the operands of condition {cond}")

    for cond in conditions:
        visit(cond)
    return operands
