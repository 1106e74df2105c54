"""Stage 3d: the linear forms (5.1) that ``gearsym generate`` emits, grouped as a TCU team
uses them.

The thesis designs its unknown-input observer on ẋ = A x + B u (5.1) with the nine inputs of
(5.3). A and B depend on the parameters (vehicle mass, side-shaft stiffness and damping, wheel
inertia) but not on the state, so a TCU evaluates them once per parameter update. Emitted are

* ``linear_gears``: the full model (2.53) and every gear with a drive path (2.54);
* ``linear_<a>_<b>`` for every emitted shift: one form per mode of the hybrid shift
  (:mod:`gearsym.symbolic.hybrid`). A mode's form does not depend on its slip signs (a sliding
  element's torque is an input of (5.3), its sign is the input's), so the 15 modes of a
  single-swap shift share 8 forms: each swapping element locked, sliding or open, never both
  locked; a one-way clutch is locked or overrunning (7 modes, 5 forms).

Every form is :func:`linear_form`'s (of a gear, a shift model or a hybrid mode), the one
derivation behind ``model --json``'s ``linear_form`` too.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import drivetrain_parts, shift_keep
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.hybrid import LOCKED, OPEN, OVERRUNNING, SLIDING, hybrid_shift
from gearsym.symbolic.model import Variable
from gearsym.symbolic.shifts import ShiftSpec, shift_spec
from gearsym.symbolic.sympy_utils import smart_jacobian

__all__ = [
    "LinearFormSet",
    "NamedLinearForm",
    "gear_linear_forms",
    "linear_form_set_name",
    "shift_linear_forms",
]


def linear_shift_form(
    d: GearboxDescription, shift: str
) -> tuple[sp.Matrix, sp.Matrix, list[str], list[str]]:
    """A_ex, B_ex of the linear form (5.1)–(5.3) of a shift model in the column order of the
    printed (5.4), (5.5): inputs [T_In, T_off, T_on, T_res*, ζ], the off-going element first.

    A view of :func:`shift_linear_form` (one derivation: T_res* (5.2), sin ζ ≈ ζ as (5.5)
    prints it), whose B keeps the order of (5.3) instead. Returns (A, B, state names, input
    names).
    """
    spec = shift_spec(d, shift)
    form = shift_linear_form(d, shift)
    inputs = [
        naming.INPUT_TORQUE,
        naming.torque(spec.off_going),
        naming.torque(spec.on_coming),
        naming.RESISTANCE_INPUT,
        form.inputs[-1],  # ζ, the grade
    ]
    columns = [form.inputs.index(name) for name in inputs]
    return form.A, form.B.extract(list(range(form.B.rows)), columns), form.states, inputs


@dataclass(frozen=True)
class LinearForm:
    """ẋ = A x + B u (5.1) of one mode, with the mode's inputs in the order of (5.3)."""

    mode: str
    A: sp.Matrix
    B: sp.Matrix
    states: list[str]
    inputs: list[str]
    parameters: tuple[Variable, ...]

    def at_defaults(self) -> tuple[list[list[float]], list[list[float]]]:
        """A and B as nested lists of floats at the parameters' defaults."""
        values = {v.symbol: v.default for v in self.parameters if v.default is not None}
        a, b = self.A.xreplace(values), self.B.xreplace(values)
        return (
            [[float(a[i, j]) for j in range(a.cols)] for i in range(a.rows)],
            [[float(b[i, j]) for j in range(b.cols)] for i in range(b.rows)],
        )


def linear_form(
    d: GearboxDescription,
    mode: str,
    locked: tuple[str, ...],
    torque_elements: tuple[str, ...],
    keep: tuple[str, ...] | None,
) -> LinearForm:
    """(5.1)–(5.3) of a mode: rolling and aerodynamic resistance become the input T_res* (5.2),
    the grade term r_dyn m g sin ζ is linearised at ζ = 0 as (5.5) prints it. Everything else is
    linear already (the gearbox (2.39), the twist (2.44) and the side-shaft law (2.47)).

    Inputs in the order of (5.3), u = [T_In, T_res*, T_<element>…, ζ], where each element that
    acts as a torque in this mode keeps its place in the description (the thesis' order K81,
    K38, B08, B05, B06, K27): the full model has all of them (nine inputs for the built-in
    gearbox), a shift model the off-going and on-coming element, a gear none (its elements are
    locked constraints, the others open, 2.54).
    """
    parts = drivetrain_parts(d, locked=locked, torque_elements=torque_elements, keep=keep)
    p = {v.name: v.symbol for v in parts.parameters}
    t_res_star = sp.Symbol(naming.RESISTANCE_INPUT)
    wheel = (
        2 * parts.side_shaft_torque - t_res_star - parts.grade_lever * p["m_veh"] * p["zeta"]
    ) / parts.wheel_inertia  # (5.2), sin ζ ≈ ζ
    rhs = sp.Matrix([*parts.gearbox_rhs, parts.phi_dot, wheel])
    x = [*parts.speeds, sp.Symbol(naming.TWIST), sp.Symbol(naming.WHEEL_SPEED)]
    order = [e.name for e in d.shift_elements if e.name in parts.torque_elements]
    u = [parts.torque_symbols[naming.INPUT], t_res_star]
    u += [parts.torque_symbols[e] for e in order] + [p["zeta"]]
    return LinearForm(
        mode=mode,
        A=smart_jacobian(rhs, x, by_rules=True),
        B=smart_jacobian(rhs, u, by_rules=True),
        states=[str(s) for s in x],
        inputs=[str(s) for s in u],
        parameters=parts.parameters,
    )


def full_linear_form(d: GearboxDescription) -> LinearForm:
    """A_ex, B_ex (5.1) of the full model (2.53): nothing locked, every element an input,
    the nine inputs of (5.3) for the built-in gearbox."""
    elements = tuple(e.name for e in d.shift_elements)
    return linear_form(d, naming.FULL_MODEL, (), elements, None)


def gear_linear_form(d: GearboxDescription, gear: str) -> LinearForm:
    """(5.1) of a gear: all its elements locked (one gearbox speed left, that of the output
    shaft), the others open; inputs [T_In, T_res*, ζ]."""
    gears = {g.name: g for g in d.gears}
    if gear not in gears:
        raise GearsymError(d.file, "gear", f"unknown gear {gear!r} (known: {', '.join(gears)})")
    g = gears[gear]
    if g.neutral:
        raise GearsymError(d.file, "gear", f"gear {gear!r} is a neutral: it has no drive path")
    return linear_form(d, f"gear_{gear}", tuple(g.closed), (), (d.output_shaft,))


def shift_linear_form(d: GearboxDescription, shift: str) -> LinearForm:
    """(5.1) of a shift model (2.55–2.58): the shared elements locked; inputs [T_In, T_res*,
    the swapping elements' torques (two, or four for a double swap) in description order, ζ]
    (:func:`linear_shift_form` gives B in the column order of the printed (5.5))."""
    spec = shift_spec(d, shift, max_swaps=2)
    name = naming.shift_model_name(spec.from_gear, spec.to_gear)
    return linear_form(d, name, spec.locked, spec.swapping, shift_keep(d, spec))


def mode_linear_form(d: GearboxDescription, shift: str, mode: str) -> LinearForm:
    """(5.1) of one mode of the hybrid ``shift`` (:func:`gearsym.symbolic.hybrid.hybrid_shift`):
    the shared and the mode's locked swapping elements are constraints, a sliding element's
    torque is an input of (5.3) (its place in the description order), an open one is absent
    (2.54); the mode's own state coordinates (``Mode.keep``)."""
    hybrid = hybrid_shift(d, shift)
    if mode not in hybrid.modes:
        raise GearsymError(
            d.file,
            "mode",
            f"unknown mode {mode!r} of the {shift} shift (known: {', '.join(hybrid.modes)})",
        )
    m = hybrid.modes[mode]
    locked = (*hybrid.spec.locked, *(e for e in hybrid.elements if m.status[e][0] == LOCKED))
    sliding = tuple(e for e in hybrid.elements if m.status[e][0] == SLIDING)
    return linear_form(d, mode, locked, sliding, m.keep)


@dataclass(frozen=True)
class NamedLinearForm:
    """One emitted form: its name (a C identifier part), the form, and what it stands for."""

    name: str  # "full", "gear_2", "K38_locked_B05_sliding"
    form: LinearForm
    summary: str
    locked: tuple[str, ...]  # elements that are constraints (2.55)
    torque_elements: tuple[str, ...]  # elements whose torque is an input of (5.3)
    keep: tuple[str, ...] | None  # shafts whose speeds are the gearbox states (None: all)
    modes: tuple[str, ...] = ()  # the hybrid modes (slip-sign variants) that share it


@dataclass(frozen=True)
class LinearFormSet:
    """The forms of one emitted file pair, with the parameters any of their A or B uses."""

    name: str  # model name of the files: ``linear_gears``, ``linear_2_3``
    summary: str
    forms: tuple[NamedLinearForm, ...]

    @property
    def parameters(self) -> tuple[Variable, ...]:
        """The parameters A or B of some form depends on, in the description's order."""
        used = set()
        for named in self.forms:
            used |= named.form.A.free_symbols | named.form.B.free_symbols
        first = self.forms[0].form.parameters
        return tuple(v for v in first if v.symbol in used)


def linear_form_set_name(spec: ShiftSpec | None) -> str:
    """``linear_gears`` (spec None) or ``linear_<from>_<to>``."""
    if spec is None:
        return "linear_gears"
    return f"linear_{spec.from_gear}_{spec.to_gear}"


def gear_linear_forms(d: GearboxDescription) -> LinearFormSet:
    """(5.1) of the full model (nine inputs of (5.3) for the built-in box) and of every gear
    with a drive path (its elements locked, the others open; inputs T_In, T_res*, ζ)."""
    forms = [
        NamedLinearForm(
            "full",
            full_linear_form(d),
            "full model (2.53): nothing locked, every element a torque",
            (),
            tuple(e.name for e in d.shift_elements),
            None,
        )
    ]
    for g in d.gears:
        if g.neutral:
            continue
        closed = ", ".join(g.closed)
        forms.append(
            NamedLinearForm(
                f"gear_{g.name}",
                gear_linear_form(d, g.name),
                f"gear {g.name}: {closed} locked",
                tuple(g.closed),
                (),
                (d.output_shaft,),
            )
        )
    return LinearFormSet(
        linear_form_set_name(None),
        "linear forms (5.1) of the full model and every gear",
        tuple(forms),
    )


def shift_linear_forms(d: GearboxDescription, spec: ShiftSpec) -> LinearFormSet:
    """(5.1) of every mode of the hybrid shift ``spec``: 8 forms for a single-swap shift, 5
    when one swapping element is a one-way clutch (locked or overrunning, as in the hybrid
    model; overrunning it carries no torque, as an open element) or a dog element (locked or
    open).

    The same locked set, torque inputs and state coordinates as the hybrid mode models
    (:func:`gearsym.symbolic.hybrid.hybrid_shift`), without deriving those models.
    """
    from gearsym.symbolic.hybrid import mode_coordinates, mode_name

    if not spec.single:  # the hybrid modes are those of one element off and one on
        shift_spec(d, spec.name)  # the one-line error of a double swap
    dyn = gearbox_dynamics(d)
    elements = (spec.off_going, spec.on_coming)
    forms = []

    def statuses_of(e: str) -> tuple[str, ...]:
        # a one-way clutch is locked or overrunning (no torque), a dog element locked or open
        # (it never slides), as in the hybrid model
        if d.element(e).one_way:
            return (LOCKED, OVERRUNNING)
        return (LOCKED, OPEN) if d.element(e).dog else (LOCKED, SLIDING, OPEN)

    for statuses in product(*(statuses_of(e) for e in elements)):
        status = dict(zip(elements, statuses, strict=True))
        swapped_locked = tuple(e for e in elements if status[e] == LOCKED)
        if len(swapped_locked) == 2:
            continue  # a tie-up has no motion left (hybrid.py)
        locked = (*spec.locked, *swapped_locked)
        sliding = tuple(e for e in elements if status[e] == SLIDING)
        keep = mode_coordinates(d, dyn, locked)
        name = "_".join(f"{e}_{status[e]}" for e in elements)
        choices = [
            [(SLIDING, 1), (SLIDING, -1)]
            if status[e] == SLIDING
            else [(OVERRUNNING, -d.element(e).locks)]
            if status[e] == OVERRUNNING
            else [(status[e], 0)]
            for e in elements
        ]
        modes = tuple(
            mode_name(spec, elements, dict(zip(elements, c, strict=True)))
            for c in product(*choices)
        )
        what = ", ".join(f"{e} {status[e]}" for e in elements)
        forms.append(
            NamedLinearForm(
                name,
                linear_form(d, name, locked, sliding, keep),
                f"shift {spec.name}: {what}",
                locked,
                sliding,
                keep,
                modes,
            )
        )
    return LinearFormSet(
        linear_form_set_name(spec),
        f"linear forms (5.1) of the modes of the hybrid shift {spec.name}",
        tuple(forms),
    )
