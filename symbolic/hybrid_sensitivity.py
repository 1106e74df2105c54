"""Stage 4b: sensitivities across the switches of the hybrid shift model, as expressions.

Inside each mode of :class:`~gearsym.symbolic.hybrid.HybridShift` the sensitivities S = ∂x/∂p
obey (3.7), Ṡ = ∂f/∂x S + ∂f/∂p, with the mode's own f. At a switch from mode ⁻ to mode ⁺ the
state is mapped, x⁺ = A x⁻ (:class:`~gearsym.symbolic.hybrid.StateMap`), and the sensitivities
jump as hybrid sensitivity analysis prescribes (Hiskens & Pai 2000; Galán, Feehery & Barton
1999):

    S⁺ = A S⁻ + (A f⁻ − f⁺) ∂τ/∂p,   ∂τ/∂p = −(∂g/∂x S⁻ + ∂g/∂p) / (∂g/∂x f⁻ + ∂g/∂u u̇),

τ the event time, g the guard that fired, f∓ the right-hand sides before and after the switch
at the event, u̇ the input rate (the guards depend on time through T_In and F_N). A guard that
depends on the inputs alone (opening and engagement: F_N crosses zero at a time the scenario
fixes) has ∂τ/∂p = 0 and S⁺ = A S⁻.

For the friction elements of a shift the term (A f⁻ − f⁺) ∂τ/∂p vanishes at the true events
although ∂τ/∂p does not: at break-away the reaction equals the capacity, at lock-up the slip is
zero, and in both cases the friction torque acts along the slip, which the M-metric projection
onto the new constraint set annihilates, so A f⁻ = f⁺ (checked at every event of the default
shift in ``tests/test_hybrid_sensitivity_code.py``). It is emitted all the same: it is the
correct jump for any guard, and away from an exact event (a located crossing) it corrects to
first order.

:func:`hybrid_sensitivity` derives, for every mode, the augmented right-hand side [f; vec S]
and the values of all its guards and their conditions, and, for every transition (source,
target) the guards allow, the post-switch state [x⁺; vec S⁺]. These expressions are what
:mod:`gearsym.symbolic.codegen.hybrid` emits as C and CasADi, so a TCU can carry the
sensitivities of the Fisher information (3.25) through lock-up and break-away.

Unlike :func:`~gearsym.symbolic.sensitivity.sensitivity_equations`, a parameter that a mode
does not depend on is kept (μ of an element that is locked or open): its ∂f/∂p is zero there,
but its sensitivity is carried, since it was built up while the element slid.

The grade enters as in :class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator`: the
parameter ζ plus the input ζ_dev(t) (2.53), so a grade profile moves the guards too.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import SENSITIVITY_PARAMETERS
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.hybrid import Guard, HybridShift, Mode, status_label
from gearsym.symbolic.model import Variable
from gearsym.symbolic.sensitivity import sensitivity_name
from gearsym.symbolic.sympy_utils import smart_jacobian

__all__ = [
    "HybridSensitivity",
    "Jump",
    "ModeSensitivity",
    "default_hybrid_parameters",
    "hybrid_sensitivity",
    "input_rate_name",
]


def input_rate_name(name: str) -> str:
    """Name of the rate of an input, ``<input>_rate`` (the u̇ of ∂τ/∂p)."""
    return f"{name}_rate"


@dataclass(frozen=True)
class ModeSensitivity:
    """One mode's part: the augmented states [x; S_1; …; S_m] (column by column, as (3.7) stacks
    them), their right-hand side, and every guard out of the mode with its value and condition
    (1 where a guard has no condition)."""

    index: int
    mode: Mode
    label: str  # K38_locked__B05_open: the status of each swapping element
    states: tuple[Variable, ...]
    rhs: sp.Matrix
    guards: tuple[Guard, ...]
    guard_values: sp.Matrix
    conditions: sp.Matrix

    @property
    def nx(self) -> int:
        """States of the mode itself (without the sensitivities)."""
        return len(self.mode.model.states)


@dataclass(frozen=True)
class Jump:
    """The switch from mode ``source`` to mode ``target`` (indices) through ``guard``:
    ``expressions`` = [x⁺; vec S⁺] in the source's augmented states, the inputs, their rates
    and the parameters. ``event_time``: the guard depends on the state or the parameters, so
    the jump carries the event-time term (module docstring)."""

    source: int
    target: int
    guard: Guard
    expressions: sp.Matrix
    event_time: bool
    #: g_x f⁻ + g_u u̇, the rate at which the guard crosses zero (near 0: a grazing crossing,
    #: where ∂τ/∂p is ill-conditioned)
    rate: sp.Expr = sp.Integer(0)


@dataclass(frozen=True)
class HybridSensitivity:
    """Everything :mod:`gearsym.symbolic.codegen.hybrid` emits for one shift."""

    hybrid: HybridShift
    parameters: tuple[Variable, ...]  # the sensitivity parameters p_j
    inputs: tuple[Variable, ...]  # T_In, F_N of each swapping element, ζ_dev
    input_rates: tuple[Variable, ...]  # their time derivatives
    modes: tuple[ModeSensitivity, ...]
    jumps: tuple[Jump, ...]

    def mode(self, name: str) -> ModeSensitivity:
        """The mode of the hybrid model named ``name``."""
        return next(m for m in self.modes if m.mode.name == name)

    def jump(self, source: str, target: str) -> Jump:
        """The jump between two modes named as in the hybrid model."""
        i, j = self.mode(source).index, self.mode(target).index
        return next(k for k in self.jumps if (k.source, k.target) == (i, j))


def default_hybrid_parameters(hybrid: HybridShift) -> tuple[str, ...]:
    """The thesis' sensitivity parameters (3.2) the shift has, then μ of both swapping
    elements (3.15) if not already among them."""
    names = [v.name for v in hybrid.parameters]
    chosen = [n for n in SENSITIVITY_PARAMETERS if n in names]
    for e in hybrid.friction_elements:
        mu = str(hybrid.friction_coefficient[e])
        if mu not in chosen:
            chosen.append(mu)
    return tuple(chosen)


def _label(hybrid: HybridShift, mode: Mode) -> str:
    return "__".join(f"{e}_{status_label(*mode.status[e])}" for e in hybrid.elements)


def hybrid_sensitivity(
    hybrid: HybridShift, parameters: Sequence[str] | None = None, file: str = ""
) -> HybridSensitivity:
    """Derive the per-mode sensitivity systems (3.7) and the jump of every transition (module
    docstring) for ``parameters`` (default :func:`default_hybrid_parameters`). Raises
    :class:`GearsymError` (``file``, key ``params``) for an unknown or repeated name."""
    names = list(default_hybrid_parameters(hybrid) if parameters is None else parameters)
    known = {v.name: v for v in hybrid.parameters}
    unknown = [n for n in names if n not in known]
    if unknown or not names or len(set(names)) != len(names):
        reason = (
            f"unknown parameters {unknown} of shift {hybrid.spec.name} (known: {', '.join(known)})"
            if unknown
            else "the parameters must be given, each once"
        )
        raise GearsymError(file, "params", reason)
    chosen = tuple(known[n] for n in names)
    p = [v.symbol for v in chosen]
    grade = known[naming.GRADE]
    deviation = Variable(
        naming.GRADE_DEVIATION,
        sp.Symbol(naming.GRADE_DEVIATION, real=True),
        grade.unit,
        "grade deviation input zeta(t) - zeta (2.53)",
    )
    inputs = (*hybrid.inputs, deviation)
    rates = tuple(
        Variable(
            input_rate_name(v.name),
            sp.Symbol(input_rate_name(v.name), real=True),
            f"({v.unit})/s",
            f"time derivative of {v.name} at the event (the guard's input term)",
        )
        for v in inputs
    )
    u = [v.symbol for v in inputs]
    u_dot = sp.Matrix([v.symbol for v in rates])
    shifted = {grade.symbol: grade.symbol + deviation.symbol}

    modes: list[ModeSensitivity] = []
    parts: dict[str, tuple[sp.Matrix, sp.Matrix, list[sp.Symbol]]] = {}
    for index, mode in enumerate(hybrid.modes.values()):
        model = mode.model
        x = model.state_symbols
        f = model.rhs.xreplace(shifted)
        states = list(model.states)
        s_columns = []
        for v in chosen:
            column = []
            for xv in model.states:
                name = sensitivity_name(xv.name, v.name)
                s = Variable(name, sp.Symbol(name, real=True), "", f"d{xv.name}/d{v.name} (3.2)")
                states.append(s)
                column.append(s.symbol)
            s_columns.append(column)
        sens = sp.Matrix(s_columns).T  # n x m, column j = S_j
        f_x = smart_jacobian(f, x, by_rules=True)
        f_p = smart_jacobian(f, p, by_rules=True)
        rhs_s = f_x * sens + f_p  # (3.7)
        rhs = sp.Matrix([*f, *[rhs_s[i, j] for j in range(len(p)) for i in range(len(x))]])
        guards = hybrid.guards_from(mode.name)
        values = sp.Matrix([g.expression.xreplace(shifted) for g in guards])
        conditions = sp.Matrix(
            [
                sp.Integer(1) if g.condition is None else g.condition.xreplace(shifted)
                for g in guards
            ]
        )
        modes.append(
            ModeSensitivity(
                index, mode, _label(hybrid, mode), tuple(states), rhs, guards, values, conditions
            )
        )
        parts[mode.name] = (f, sens, x)

    index_of = {m.mode.name: m.index for m in modes}
    jumps: list[Jump] = []
    for source in modes:
        f_minus, sens, x = parts[source.mode.name]
        for guard in source.guards:
            g = guard.expression.xreplace(shifted)
            g_x = smart_jacobian([g], x)
            g_p = smart_jacobian([g], p)
            event_time = any(e != 0 for e in (*g_x, *g_p))
            g_u = smart_jacobian([g], u)
            terms = [
                *(g_x[k] * f_minus[k] for k in range(len(x))),
                *(g_u[k] * u_dot[k] for k in range(len(u))),
            ]
            rate = sp.Add(*terms)
            for target_name in (guard.target, guard.otherwise):
                if target_name is None:
                    continue
                matrix = hybrid.maps[(source.mode.name, target_name)].matrix
                x_plus = matrix * sp.Matrix(x)
                s_plus = matrix * sens
                if event_time:
                    f_plus, _, x_target = parts[target_name]
                    f_plus = f_plus.xreplace(dict(zip(x_target, x_plus, strict=True)))
                    tau_p = -(g_x * sens + g_p) / rate
                    s_plus = s_plus + (matrix * f_minus - f_plus) * tau_p
                expressions = sp.Matrix(
                    [*x_plus, *[s_plus[i, j] for j in range(len(p)) for i in range(len(x_plus))]]
                )
                jumps.append(
                    Jump(
                        source.index,
                        index_of[target_name],
                        guard,
                        expressions,
                        event_time,
                        rate if event_time else sp.Integer(0),
                    )
                )
    pairs = [(j.source, j.target) for j in jumps]
    assert len(set(pairs)) == len(pairs), "one guard per transition"
    return HybridSensitivity(hybrid, chosen, inputs, rates, tuple(modes), tuple(jumps))
