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
  locked.

Every form is :func:`gearsym.symbolic.drivetrain._linear_form`'s, the one derivation behind
``model --json``'s ``linear_form`` too.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import (
    LinearForm,
    ShiftSpec,
    full_linear_form,
    gear_linear_form,
    linear_form,
    shift_spec,
)
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.model import Variable

__all__ = [
    "LinearFormSet",
    "NamedLinearForm",
    "gear_linear_forms",
    "linear_form_set_name",
    "shift_linear_forms",
]

LOCKED, SLIDING, OPEN = "locked", "sliding", "open"


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
    """(5.1) of every mode of the hybrid shift ``spec``: 8 forms for a single-swap shift.

    The same locked set, torque inputs and state coordinates as the hybrid mode models
    (:func:`gearsym.symbolic.hybrid.hybrid_shift`), without deriving those models.
    """
    from gearsym.symbolic.hybrid import mode_coordinates, mode_name

    if not spec.single:  # the hybrid modes are those of one element off and one on
        shift_spec(d, spec.name)  # the one-line error of a double swap
    dyn = gearbox_dynamics(d)
    elements = (spec.off_going, spec.on_coming)
    forms = []
    for statuses in product((LOCKED, SLIDING, OPEN), repeat=2):
        status = dict(zip(elements, statuses, strict=True))
        swapped_locked = tuple(e for e in elements if status[e] == LOCKED)
        if len(swapped_locked) == 2:
            continue  # a tie-up has no motion left (hybrid.py)
        locked = (*spec.locked, *swapped_locked)
        sliding = tuple(e for e in elements if status[e] == SLIDING)
        keep = mode_coordinates(d, dyn, locked)
        name = "_".join(f"{e}_{status[e]}" for e in elements)
        choices = [
            [(SLIDING, 1), (SLIDING, -1)] if status[e] == SLIDING else [(status[e], 0)]
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
