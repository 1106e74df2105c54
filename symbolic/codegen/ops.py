"""Operation counts of the emitted C, stated in every function's doc comment."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import sympy as sp
from gearsym.symbolic.codegen.config import CodegenConfig
from gearsym.symbolic.codegen.cse import CseForm, boolean_definitions
from gearsym.symbolic.codegen.expressions import (
    FUNCTION_NAMES,
    HELPER_COUNT_NAMES,
    condition_operands,
    split_mul,
)
from sympy.logic.boolalg import BooleanAtom

__all__ = [
    "OpCount",
    "count_operations",
    "count_split",
    "implicit_step_ops",
    "rk4_step_ops",
]


@dataclass
class OpCount:
    """Floating-point operations the emitted C performs, by kind.

    Counted on the CSE'd form following the printer's rules: ``b**3`` is 2 mul, ``x/3`` is 1 mul
    (the constant ``1/3`` is folded at compile time), a negation is free, ``Min``/``Max`` of n
    arguments are n-1 calls, a Piecewise of n pieces is n-1 selects (``?:``) plus its NaN guard
    (one ``isnan`` compare per operand of its conditions, the ``||`` between them, one select).
    """

    add: int = 0
    mul: int = 0
    div: int = 0
    calls: Counter[str] = field(default_factory=Counter)
    select: int = 0
    compare: int = 0
    logic: int = 0

    def __add__(self, other: OpCount) -> OpCount:
        return OpCount(
            self.add + other.add,
            self.mul + other.mul,
            self.div + other.div,
            self.calls + other.calls,
            self.select + other.select,
            self.compare + other.compare,
            self.logic + other.logic,
        )

    def scaled(self, factor: int) -> OpCount:
        """The count of ``factor`` evaluations."""
        return OpCount(
            self.add * factor,
            self.mul * factor,
            self.div * factor,
            Counter({k: v * factor for k, v in self.calls.items()}),
            self.select * factor,
            self.compare * factor,
            self.logic * factor,
        )

    @property
    def total(self) -> int:
        return (
            self.add
            + self.mul
            + self.div
            + sum(self.calls.values())
            + self.select
            + self.compare
            + self.logic
        )

    def format(self) -> str:
        """E.g. ``3 add, 5 mul, 1 div, 2 calls (sin 1, sqrt 1), 1 select, 1 cmp``."""
        n_calls = sum(self.calls.values())
        calls = "call" if n_calls == 1 else "calls"
        text = f"{self.add} add, {self.mul} mul, {self.div} div, {n_calls} {calls}"
        if n_calls:
            text += " (" + ", ".join(f"{k} {v}" for k, v in sorted(self.calls.items())) + ")"
        for n, label in ((self.select, "select"), (self.compare, "cmp"), (self.logic, "logic")):
            if n:
                text += f", {n} {label}"
        return text


def _count(
    expr: sp.Basic, acc: OpCount, definitions: Mapping[sp.Symbol, sp.Basic], max_power: int
) -> None:
    if expr.is_Atom or isinstance(expr, BooleanAtom):
        return
    if expr.is_Add:
        acc.add += len(expr.args) - 1
        children: Iterable[sp.Basic] = expr.args
    elif expr.is_Mul:
        _, coeff, numerator, denominator = split_mul(expr)
        n_num = len(numerator) + (coeff != 1)
        acc.mul += max(n_num - 1, 0) + max(len(denominator) - 1, 0)
        acc.div += 1 if denominator else 0
        children = numerator + denominator
    elif expr.is_Pow:
        exp = expr.exp
        if exp.is_Integer and 1 <= abs(int(exp)) <= max_power:
            acc.mul += abs(int(exp)) - 1
            acc.div += 1 if exp < 0 else 0
        elif exp == sp.S.Half or exp == -sp.S.Half:
            acc.calls["sqrt"] += 1
            acc.div += 1 if exp < 0 else 0
        else:
            acc.calls["pow"] += 1
        children = expr.args
    elif isinstance(expr, sp.Piecewise):
        last_default = expr.args[-1].cond == sp.true
        acc.select += len(expr.args) - (1 if last_default else 0)
        children = [a for pair in expr.args for a in pair.args]
        operands = condition_operands([pair.cond for pair in expr.args], definitions)
        if operands:  # the NaN guard: one isnan per operand, joined by ||, and one select
            acc.compare += len(operands)
            acc.logic += len(operands) - 1
            acc.select += 1
            children = children + operands
    elif isinstance(expr, sp.core.relational.Relational):
        acc.compare += 1
        children = expr.args
    elif isinstance(expr, (sp.And, sp.Or)):
        acc.logic += len(expr.args) - 1
        children = expr.args
    elif isinstance(expr, sp.Not):
        acc.logic += 1
        children = expr.args
    elif isinstance(expr, sp.Function):
        name = type(expr).__name__
        c_name = FUNCTION_NAMES.get(name, HELPER_COUNT_NAMES.get(name, name))
        acc.calls[c_name] += len(expr.args) - 1 if name in ("Min", "Max") else 1
        children = expr.args
    else:
        children = expr.args
    for child in children:
        _count(child, acc, definitions, max_power)


def count_operations(form: CseForm, config: CodegenConfig | None = None) -> OpCount:
    """Operations of the CSE'd form, as printed by the C printer."""
    return count_split(form, frozenset(), config)[1]  # nothing set apart: all in the rest


def count_split(
    form: CseForm, once: frozenset[sp.Symbol], config: CodegenConfig | None = None
) -> tuple[OpCount, OpCount]:
    """Operations of the temporaries in ``once`` and of the rest of the form (the other
    temporaries and the outputs), counted by the rules of :func:`count_operations`."""
    max_power = (config or CodegenConfig()).precision.max_inline_power
    definitions = boolean_definitions(form)
    first, rest = OpCount(), OpCount()
    for symbol, expr in form.temporaries:
        _count(expr, first if symbol in once else rest, definitions, max_power)
    for matrix in form.outputs:
        for expr in matrix:
            _count(expr, rest, definitions, max_power)
    return first, rest


def rk4_step_ops(n: int) -> OpCount:
    """Own operations of the RK4 step (without its four rhs calls): the three stage states,
    x + h/6 (k1 + 2 (k2 + k3) + k4), and the two step-size products."""
    return OpCount(add=7 * n, mul=5 * n + 2)


def implicit_step_ops(n: int, n_inputs: int) -> OpCount:
    """Own operations of the linearly implicit Euler step (without rhs and jac_x)."""
    ops = OpCount(mul=n * n)  # -h J
    ops.compare += 1 + n + n_inputs + n + n * n  # isfinite of h, x, u, f and -h J
    ops.calls["fabs"] += n * n  # scale: row sums of |h J| and their maximum
    ops.add += n * n + n  # row sums (starting at 1), then the identity
    ops.compare += n
    for k in range(n):  # factorisation: multipliers and row updates
        m = n - k - 1
        ops.div += m
        ops.mul += m * m
        ops.add += m * m
    ops.calls["fabs"] += n * (n + 1) // 2  # pivot search
    ops.compare += n * (n - 1) // 2 + 2 * n  # pivot search, zero and isfinite tests
    solves = n + 1  # the step, and the n columns of the inverse
    ops.mul += solves * n * (n - 1)  # forward and back substitution
    ops.add += solves * n * (n - 1)
    ops.div += solves * n
    ops.calls["fabs"] += n * n  # row sums of |A^-1|, their maximum
    ops.add += n * n
    ops.compare += n
    ops.mul += 3  # ||A^-1|| NX eps scale
    ops.compare += 1
    ops.mul += n  # x + h k, and its isfinite
    ops.add += n
    ops.compare += n
    return ops
