"""The C printer's rarer paths by value (found by the mutation run, docs/verification.md): Max and
Min of three arguments, Heaviside with its value at zero, ±∞, a negated condition, and the
forms the printer's docstring promises for x⁻¹, the boolean constants and an unsupported
function. Emitted, compiled in double and single precision and called; expected values from
the functions' definitions (max, min, H(0) = H0, IEEE ±∞), not from SymPy's evaluation.

Each test builds its own model: the mutation run attributes a module fixture's work to the
first test that used it, so checks on a shared build would not be run against a mutant.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic import codegen
from gearsym.symbolic.model import Model, Variable
from gearsym.validation.checks import c_check

X, Y, Z = sp.symbols("x y z", real=True)


def _build(tmp_path: Path, rows: list[sp.Expr]) -> dict:
    model = Model(
        "edges",
        (Variable("x", X), Variable("y", Y), Variable("z", Z)),
        (),
        (Variable("k", sp.Symbol("k"), default=1.0),),
        (Variable("a", sp.Symbol("a")),),
        sp.Matrix(rows),
        sp.Matrix([X]),
    )
    return c_check.build(model, tmp_path)


@pytest.mark.parametrize("precision", ["double", "single"])
def test_max_and_min_of_three_pick_the_extreme_wherever_it_stands(tmp_path, precision) -> None:
    lib = _build(tmp_path, [sp.Max(X, Y, Z), sp.Min(X, Y, Z), X])[precision]
    for point in ([1.0, 2.0, 3.0], [3.0, 1.0, 2.0], [2.0, 3.0, 1.0], [-1.0, -3.0, -2.0]):
        value = lib.evaluate("rhs", point, [], [1.0])
        assert value[0] == max(point) and value[1] == min(point), (point, value)


@pytest.mark.parametrize("precision", ["double", "single"])
def test_heaviside_takes_its_stated_value_at_zero(tmp_path, precision) -> None:
    # H(t) = 0 below zero, 1 above, H0 at zero: 1/2 by default, 1 when given
    lib = _build(tmp_path, [sp.Heaviside(X - Y), sp.Heaviside(X - Y, 1), sp.Heaviside(X - Y, 0)])
    assert list(lib[precision].evaluate("rhs", [2.0, 2.0, 0.0], [], [1.0])) == [0.5, 1.0, 0.0]
    assert list(lib[precision].evaluate("rhs", [3.0, 2.0, 0.0], [], [1.0])) == [1.0, 1.0, 1.0]
    assert list(lib[precision].evaluate("rhs", [1.0, 2.0, 0.0], [], [1.0])) == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("precision", ["double", "single"])
def test_infinities_and_a_negated_condition(tmp_path, precision) -> None:
    saturated = sp.Piecewise((sp.oo, X > 10), (-sp.oo, X < -10), (X, True))
    outside = sp.Piecewise((1, sp.Not(sp.And(X > 0, Y > 0))), (0, True))
    lib = _build(tmp_path, [saturated, outside, Z])[precision]
    assert list(lib.evaluate("rhs", [20.0, 1.0, 0.0], [], [1.0])[:2]) == [math.inf, 0.0]
    assert list(lib.evaluate("rhs", [-20.0, 1.0, 0.0], [], [1.0])[:2]) == [-math.inf, 1.0]
    assert list(lib.evaluate("rhs", [0.5, -1.0, 0.0], [], [1.0])[:2]) == [0.5, 1.0]
    assert np.isnan(lib.evaluate("rhs", [math.nan, 1.0, 0.0], [], [1.0])[0])


@pytest.mark.parametrize("precision", ["double", "single"])
def test_negative_and_half_powers(tmp_path, precision) -> None:
    # 4^(-1/2) = 1/2, 2^(-3) = 1/8, 2^(-1) = 1/2: exact in binary floating point
    lib = _build(tmp_path, [X ** sp.Rational(-1, 2), Y**-3, Z**-1])[precision]
    assert list(lib.evaluate("rhs", [4.0, 2.0, 2.0], [], [1.0])) == [0.5, 0.125, 0.5]


def test_printed_forms_of_the_documented_rules() -> None:
    printer = codegen.GearsymCPrinter({X: "x[0]"}, "gearsym_t_")
    # integer powers up to max_inline_power are products: x**-1 is one division, x**8 the
    # last product (the default limit), x**9 a pow call; x**(-1/2) one division by a sqrt
    limit = codegen.Precision().max_inline_power
    assert limit == 8
    assert printer.doprint(X**-1) == "(GEARSYM_LIT(1.0)/x[0])"
    assert printer.doprint(X**-2) == "(GEARSYM_LIT(1.0)/(x[0]*x[0]))"
    assert printer.doprint(X**limit) == "(" + "*".join(["x[0]"] * limit) + ")"
    assert printer.doprint(X ** (limit + 1)) == "GEARSYM_POW(x[0], GEARSYM_LIT(9.0))"
    assert printer.doprint(X ** sp.Rational(-1, 2)) == "(GEARSYM_LIT(1.0)/GEARSYM_SQRT(x[0]))"
    assert "sqrt" in printer.used_macros
    # a caller's precision is the one used: with products up to the square, x**3 is a pow
    short = codegen.GearsymCPrinter(
        {X: "x[0]"}, "gearsym_t_", precision=codegen.Precision(max_inline_power=2)
    )
    assert short.doprint(X**2) == "(x[0]*x[0])"
    assert short.doprint(X**3) == "GEARSYM_POW(x[0], GEARSYM_LIT(3.0))"
    # C's truth values
    assert printer.doprint(sp.true) == "1" and printer.doprint(sp.false) == "0"
    # an unsupported function is refused by name
    with pytest.raises(NotImplementedError, match="unknown"):
        printer.doprint(sp.Function("unknown")(X))
    # the renderer names what it was given instead of a view
    with pytest.raises(TypeError, match="got dict"):
        codegen.render("c_header.h.j2", {"model_name": "m"})
