"""The numeric layer: SymPy expressions as CasADi expressions, and piecewise-linear tables.

One translator (:func:`to_casadi`) turns any expression the derivation produces (sums,
products, powers, the elementary functions, ``Abs``, ``sign``, ``Max``/``Min``, ``Piecewise``,
``ITE``, ``Heaviside``, relations and logic) into a CasADi SX/MX expression, so that CasADi's
own AD, CSE and integrators (CVODES) work on the derived models. :func:`casadi_function`
builds a named ``casadi.Function`` from symbol groups, the way every consumer needs it.
:func:`piecewise_linear` and :func:`bilinear` express table look-ups (the μ map, 2.69) in the
same graph, exactly as linear interpolation clamped to the grid, without an MX interpolant.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import sympy as sp

__all__ = ["bilinear", "casadi_function", "piecewise_linear", "to_casadi"]


def _casadi() -> Any:
    import casadi as ca  # imported on use: the derivation itself never needs CasADi

    return ca


def to_casadi(expr: sp.Basic, mapping: Mapping[sp.Symbol, Any]) -> Any:
    """A SymPy expression as a CasADi expression; every free symbol must be in ``mapping``.

    Raises ``NotImplementedError`` naming the SymPy function that has no translation (rather
    than translating it wrongly)."""
    ca = _casadi()
    unary = {
        sp.sin: ca.sin,
        sp.cos: ca.cos,
        sp.tan: ca.tan,
        sp.asin: ca.asin,
        sp.acos: ca.acos,
        sp.atan: ca.atan,
        sp.sinh: ca.sinh,
        sp.cosh: ca.cosh,
        sp.tanh: ca.tanh,
        sp.exp: ca.exp,
        sp.log: ca.log,
        sp.Abs: ca.fabs,
        sp.sign: ca.sign,
        sp.floor: ca.floor,
        sp.ceiling: ca.ceil,
    }
    relations = {
        sp.StrictLessThan: ca.lt,
        sp.LessThan: ca.le,
        sp.StrictGreaterThan: ca.gt,
        sp.GreaterThan: ca.ge,
        sp.Equality: ca.eq,
        sp.Unequality: ca.ne,
    }
    cache: dict[sp.Basic, Any] = {}

    def fold(op: Any, args: Sequence[sp.Basic]) -> Any:
        total = walk(args[0])
        for a in args[1:]:
            total = op(total, walk(a))
        return total

    def walk(e: sp.Basic) -> Any:
        if e in cache:
            return cache[e]
        result = translate(e)
        cache[e] = result
        return result

    def translate(e: sp.Basic) -> Any:
        if e.is_Symbol:
            try:
                return mapping[e]
            except KeyError:
                raise KeyError(f"no CasADi value for the symbol {e}") from None
        if e is sp.true:
            return 1.0
        if e is sp.false:
            return 0.0
        if e.is_Number or e.is_NumberSymbol:
            return float(e)
        if e.is_Add:
            return fold(lambda a, b: a + b, e.args)
        if e.is_Mul:
            return fold(lambda a, b: a * b, e.args)
        if e.is_Pow:
            base, exponent = e.args
            if exponent.is_Integer:
                return ca.constpow(walk(base), int(exponent))
            if exponent == sp.S.Half:
                return ca.sqrt(walk(base))
            return ca.power(walk(base), walk(exponent))
        if e.func in unary:
            return unary[e.func](walk(e.args[0]))
        if e.func == sp.atan2:
            return ca.atan2(walk(e.args[0]), walk(e.args[1]))
        if isinstance(e, sp.Max):
            return fold(ca.fmax, e.args)
        if isinstance(e, sp.Min):
            return fold(ca.fmin, e.args)
        if isinstance(e, sp.Heaviside):
            # d max(0, a)/da: 1 for a > 0, else 0 (the value at 0 is immaterial there)
            return ca.if_else(ca.gt(walk(e.args[0]), 0), 1.0, 0.0)
        if isinstance(e, sp.Piecewise):
            result = None
            for value, condition in reversed(e.args):
                if condition is sp.true or result is None:
                    result = walk(value)
                else:
                    result = ca.if_else(walk(condition), walk(value), result)
            return result
        if isinstance(e, sp.ITE):
            condition, yes, no = e.args
            return ca.if_else(walk(condition), walk(yes), walk(no))
        if e.func in relations:
            return relations[e.func](walk(e.args[0]), walk(e.args[1]))
        if isinstance(e, sp.And):
            return fold(ca.logic_and, e.args)
        if isinstance(e, sp.Or):
            return fold(ca.logic_or, e.args)
        if isinstance(e, sp.Not):
            return ca.logic_not(walk(e.args[0]))
        raise NotImplementedError(f"no CasADi translation for {e.func.__name__}")

    return walk(sp.sympify(expr))


def casadi_function(
    name: str,
    inputs: Sequence[tuple[str, Sequence[sp.Symbol]]],
    outputs: Sequence[tuple[str, Any]],
    extra: Mapping[sp.Symbol, Any] | None = None,
) -> Any:
    """``casadi.Function(name, [inputs], [outputs])`` (SX): each input a named vector of
    symbols, each output a named matrix (or list) of SymPy expressions. ``extra`` maps further
    symbols to CasADi expressions of the inputs (e.g. an input as a function of time)."""
    ca = _casadi()
    mapping: dict[sp.Symbol, Any] = {}
    vectors = []
    for label, symbols in inputs:
        vector = ca.SX.sym(label, len(symbols))
        vectors.append(vector)
        mapping.update({s: vector[i] for i, s in enumerate(symbols)})
    for symbol, value in (extra or {}).items():
        mapping[symbol] = value(mapping) if callable(value) else value
    results = []
    for _, exprs in outputs:
        matrix = sp.Matrix(exprs) if not isinstance(exprs, sp.MatrixBase) else exprs
        cells = [
            [to_casadi(matrix[i, j], mapping) for j in range(matrix.cols)]
            for i in range(matrix.rows)
        ]
        results.append(ca.blockcat(cells) if cells else ca.SX(0, 1))
    return ca.Function(
        name, vectors, results, [label for label, _ in inputs], [label for label, _ in outputs]
    )


def _hats(x: Any, grid: np.ndarray) -> list[Any]:
    """Piecewise-linear basis ("hat") functions of ``grid`` at x, with x clamped to the grid:
    Σ_i hat_i(x) v_i is the linear interpolation of the values v_i."""
    ca = _casadi()
    g = [float(v) for v in grid]
    if len(g) == 1:
        return [1.0]
    x = ca.fmin(ca.fmax(x, g[0]), g[-1])
    hats = []
    for i, node in enumerate(g):
        rising = (x - g[i - 1]) / (node - g[i - 1]) if i > 0 else None
        falling = (g[i + 1] - x) / (g[i + 1] - node) if i < len(g) - 1 else None
        if rising is None:
            shape = falling
        elif falling is None:
            shape = rising
        else:
            shape = ca.fmin(rising, falling)
        hats.append(ca.fmax(shape, 0.0))
    return hats


def piecewise_linear(x: Any, grid: Sequence[float], values: Sequence[float]) -> Any:
    """Linear interpolation of ``values`` over the increasing ``grid`` at x, clamped to the
    grid (constant outside), as one CasADi expression."""
    hats = _hats(x, np.asarray(grid, dtype=float))
    return sum((float(v) * h for v, h in zip(values, hats, strict=True)), 0.0)


def bilinear(
    x: Any, y: Any, x_grid: Sequence[float], y_grid: Sequence[float], table: np.ndarray
) -> Any:
    """Bilinear interpolation of ``table[i, j]`` = f(x_grid[i], y_grid[j]) at (x, y), clamped
    to the grid, as one CasADi expression (the tensor product of the two hat bases)."""
    table = np.asarray(table, dtype=float)
    hx = _hats(x, np.asarray(x_grid, dtype=float))
    hy = _hats(y, np.asarray(y_grid, dtype=float))
    total = 0.0
    for i, a in enumerate(hx):
        row = sum((float(table[i, j]) * b for j, b in enumerate(hy)), 0.0)
        total = total + a * row
    return total


def integrate_linear_inputs(
    rhs: Any,
    x0: Sequence[float],
    times: Sequence[float],
    inputs: np.ndarray,
    rtol: float = 1e-10,
    atol: float = 1e-10,
) -> np.ndarray:
    """x at ``times`` of ẋ = rhs(x, u) with u linear in time between the samples
    (``inputs[k]`` at ``times[k]``), by CVODES over every sample interval, chained in one call
    (``mapaccum``). ``rhs`` is a ``casadi.Function`` (x, u) → ẋ. Returns len(times) × nx."""
    ca = _casadi()
    times = np.asarray(times, dtype=float)
    inputs = np.asarray(inputs, dtype=float).reshape(len(times), -1)
    nx, nu = rhs.size1_in(0), rhs.size1_in(1)
    x = ca.SX.sym("x", nx)
    u0, u1 = ca.SX.sym("u0", nu), ca.SX.sym("u1", nu)
    h, tau = ca.SX.sym("h"), ca.SX.sym("tau")
    ode = h * rhs(x, u0 + tau * (u1 - u0))
    step = ca.integrator(
        "interval",
        "cvodes",
        {"x": x, "p": ca.vertcat(u0, u1, h), "t": tau, "ode": ode},
        0.0,
        1.0,
        {"abstol": atol, "reltol": rtol, "max_num_steps": 100000},
    )
    xk, pk = ca.MX.sym("xk", nx), ca.MX.sym("pk", 2 * nu + 1)
    one = ca.Function("one", [xk, pk], [step(x0=xk, p=pk)["xf"]])
    intervals = len(times) - 1
    if intervals == 0:
        return np.asarray(x0, dtype=float).reshape(1, nx)
    per_interval = np.vstack([inputs[:-1].T, inputs[1:].T, np.diff(times)[None, :]])
    states = one.mapaccum("chain", intervals)(ca.DM(np.asarray(x0, dtype=float)), per_interval)
    return np.vstack([np.asarray(x0, dtype=float), np.asarray(states.full()).T])
