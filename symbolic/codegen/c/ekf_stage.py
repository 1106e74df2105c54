"""One RK4 stage of the EKF predict with the right-hand side and ∂f/∂z fused (thesis 4.3).

Over one predict step the inputs u and the parameters p are held, and so is every state whose
right-hand side is identically 0 (the random walks of the augmented model (4.1): m_veh, μ, ζ).
Only the *moving* states (those with a nonzero right-hand side) differ from stage to stage.
So each expression of f and of the structural nonzeros of J = ∂f/∂z is split, decided at
generation time from its free symbols:

- an expression polynomial in the moving states is written Σ c_m x^m with every coefficient
  c_m (free of the moving states) computed once per step; the coefficients of all expressions
  are CSE'd together;
- any other expression keeps its form, and its subexpressions free of the moving states are
  hoisted the way ``rk4_step`` hoists the u/p-only terms (:func:`..cse.hoist`).

A J entry free of the moving states is then the same in all four stages: it is computed once.
What remains per stage (the moving rows of f and the J entries that depend on the moving
states) is CSE'd together, one CSE over the stage's f and J, and printed inline: no function
call inside the step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.codegen.config import CodegenConfig
from gearsym.symbolic.codegen.cse import CseForm, cse_of, hoist
from gearsym.symbolic.codegen.ops import OpCount, count_operations

__all__ = ["FusedStage", "fused_stage"]

Entry = tuple[int, int]

#: Placeholders the predict emitter replaces per stage: the slope array, the J array.
SLOPE = "@SLOPE@"
JAC = "@JAC@"


@dataclass(frozen=True)
class FusedStage:
    """C statements of the fused stage.

    ``once``: statements computed once per step (the hoisted coefficients and the J entries
    free of the moving states, written to ``j1[k]``), with their count ``once_ops``.
    ``stage``: the statements of one stage (temporaries, then ``@SLOPE@[i] = ...`` for the
    moving rows and ``@JAC@[k] = ...`` for the moving J entries, k their position in
    ``entries``), reading the stage point through ``xs``; ``stage_ops`` counts one stage.
    ``invariant``: the J entries computed once.
    """

    once: tuple[str, ...]
    once_ops: OpCount
    stage: tuple[str, ...]
    stage_ops: OpCount
    invariant: frozenset[Entry]


def _polynomial(
    expr: sp.Basic, moving: Sequence[sp.Symbol]
) -> list[tuple[tuple[int, ...], sp.Basic]] | None:
    """(monomial exponents, coefficient) of ``expr`` as a polynomial in ``moving`` with
    coefficients free of them, or None if it is not one. Each coefficient is the Taylor
    coefficient at moving = 0, ∂^m expr / ∂x^m / m! (not an expanded form): so the
    coefficient of a state in an affine row *is* that row's Jacobian entry, and the CSE shares
    it with J."""
    if not (expr.free_symbols & set(moving)):
        return [((0,) * len(moving), expr)]
    if not expr.is_polynomial(*moving):
        return None
    try:
        monoms = sp.Poly(expr, *moving).monoms()
    except (sp.PolynomialError, sp.polys.polyerrors.CoercionFailed):
        return None
    zero = dict.fromkeys(moving, 0)
    terms = []
    for monom in monoms:
        d = expr
        scale = 1
        for symbol, k in zip(moving, monom, strict=True):
            if k:
                d = sp.diff(d, symbol, k)
                scale *= sp.factorial(k)
        terms.append((monom, d.xreplace(zero) / scale))
    return terms


def _ordered(defs: list[tuple[sp.Symbol, sp.Basic]]) -> list[tuple[sp.Symbol, sp.Basic]]:
    """``defs`` in an order where each is defined after the ones it reads (stable)."""
    names = {s for s, _ in defs}
    done: set[sp.Symbol] = set()
    pending = list(defs)
    result: list[tuple[sp.Symbol, sp.Basic]] = []
    while pending:
        ready = [d for d in pending if not ((d[1].free_symbols & names) - done)]
        assert ready, "cyclic definitions"
        for d in ready:
            result.append(d)
            done.add(d[0])
        pending = [d for d in pending if d[0] not in done]
    return result


def fused_stage(
    states: Sequence[sp.Symbol],
    rhs: Sequence[sp.Basic],
    entries: Sequence[Entry],
    jac: Callable[[Entry], sp.Basic],
    printer_for: Callable[[dict[sp.Symbol, str]], Callable[[sp.Basic], str]],
    config: CodegenConfig | None = None,
) -> FusedStage:
    """The fused stage of f (``rhs``, one expression per state) and the J ``entries``
    (``jac(e)`` their expressions). ``printer_for(mapping)`` returns a function printing an
    expression to C with the model's symbols mapped as usual and ``mapping`` on top (states
    and temporaries)."""
    n = len(states)
    moving_idx = [i for i in range(n) if rhs[i] != 0]
    moving = [states[i] for i in moving_idx]
    moving_set = set(moving)
    coeffs: dict[sp.Basic, sp.Symbol] = {}

    def coefficient(c: sp.Basic) -> sp.Basic:
        if c.is_Number:
            return c
        sign = 1
        if c.could_extract_minus_sign():
            c, sign = -c, -1
        if c not in coeffs:
            coeffs[c] = sp.Symbol(f"hc{len(coeffs)}", real=True)
        return sign * coeffs[c]

    def split(expr: sp.Basic) -> sp.Basic:
        terms = _polynomial(expr, moving)
        if terms is None:
            return expr
        parts = []
        for monom, c in terms:
            mono = sp.Mul(*(s**k for s, k in zip(moving, monom, strict=True) if k))
            parts.append(coefficient(c) * mono)
        return sp.Add(*parts)

    outputs: list[tuple[str, sp.Basic]] = [(f"{SLOPE}[{i}]", split(rhs[i])) for i in moving_idx]
    invariant: set[Entry] = set()
    once_outputs: list[tuple[str, sp.Basic]] = []
    for k, e in enumerate(entries):
        value = split(jac(e))
        if value.free_symbols & moving_set:
            outputs.append((f"{JAC}[{k}]", value))
        else:
            invariant.add(e)
            once_outputs.append((f"j1[{k}]", value))
    # the per-stage expressions: one CSE, then the subexpressions free of the moving states
    # (those of the non-polynomial expressions) hoisted into the once part
    stage_temps, stage_exprs = cse_of(tuple(e for _, e in outputs))
    renamed = {s: sp.Symbol(f"ts{k}", real=True) for k, (s, _) in enumerate(stage_temps)}
    stage_temps = tuple((renamed[s], e.xreplace(renamed)) for s, e in stage_temps)
    stage_exprs = tuple(e.xreplace(renamed) for e in stage_exprs)
    varying: set[sp.Symbol] = set(moving_set)
    hoisted: list[tuple[sp.Symbol, sp.Basic]] = []
    kept: list[tuple[sp.Symbol, sp.Basic]] = []
    for symbol, expr in stage_temps:
        if expr.free_symbols & varying:
            varying.add(symbol)
            kept.append((symbol, hoist(expr, varying, hoisted, True)))
        else:
            hoisted.append((symbol, expr))
    stage_exprs = tuple(hoist(e, varying, hoisted, True) for e in stage_exprs)
    # the once part: the coefficients, the hoisted terms and the invariant J entries, one CSE
    once_defs = [(s, c) for c, s in coeffs.items()] + hoisted
    once_exprs = [e for _, e in once_defs] + [e for _, e in once_outputs]
    once_temps, once_reduced = cse_of(tuple(once_exprs))
    names: dict[sp.Symbol, sp.Symbol] = {}
    for k, (symbol, _) in enumerate(once_temps):
        names[symbol] = sp.Symbol(f"hq{k}", real=True)
    for k, (symbol, _) in enumerate(kept):
        names[symbol] = sp.Symbol(f"t{k}", real=True)
    once_temps = tuple((names[s], e.xreplace(names)) for s, e in once_temps)
    once_reduced = tuple(e.xreplace(names) for e in once_reduced)
    defs = list(once_temps) + [
        (s, e) for (s, _), e in zip(once_defs, once_reduced[: len(once_defs)], strict=True)
    ]
    once_values = once_reduced[len(once_defs) :]
    defs = _ordered(defs)
    kept = [(names[s], e.xreplace(names)) for s, e in kept]
    stage_exprs = tuple(e.xreplace(names) for e in stage_exprs)

    mapping_once = {s: s.name for s, _ in defs}
    mapping_stage = dict(mapping_once)
    mapping_stage.update({s: f"xs[{states.index(s)}]" for s in moving})
    mapping_stage.update({s: s.name for s, _ in kept})
    print_once = printer_for(mapping_once)
    print_stage = printer_for(mapping_stage)
    once_lines = [f"const gearsym_real {s.name} = {print_once(e)};" for s, e in defs]
    once_lines += [
        f"{target} = {print_once(e)};"
        for (target, _), e in zip(once_outputs, once_values, strict=True)
    ]
    stage_lines = [f"const gearsym_real {s.name} = {print_stage(e)};" for s, e in kept]
    stage_lines += [
        f"{target} = {print_stage(e)};" for (target, _), e in zip(outputs, stage_exprs, strict=True)
    ]
    once_ops = count_operations(
        CseForm(tuple(defs), (sp.ImmutableMatrix(list(once_values) or [0]),)), config
    )
    stage_ops = count_operations(
        CseForm(tuple(kept), (sp.ImmutableMatrix(list(stage_exprs) or [0]),)), config
    )
    return FusedStage(
        tuple(once_lines), once_ops, tuple(stage_lines), stage_ops, frozenset(invariant)
    )
