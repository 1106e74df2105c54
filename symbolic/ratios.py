"""Gear ratios from the shaft kinematics (Table 2.1).

Adding the two Willis constraints (2.22) and (2.23) of a set eliminates its planet:

    z_S ω_S + z_H ω_H − (z_S + z_H) ω_T = 0,   i.e.   ω_S + k ω_H − (1 + k) ω_T = 0

with the stationary ratio k = z_H / z_S. Compound kinds (double pinion, Ravigneaux, stepped
planet) give one such relation per sun–ring pair, with the sign of their stationary ratio
(:mod:`gearsym.symbolic.set_kinds`). A gear closes shift elements (a clutch ties ω_a = ω_b,
a brake holds ω_b = 0); a drivable gear leaves exactly one degree of freedom and its ratio is
ω_in / ω_out along it. Ratios depend on the sets only through k, which is what
:mod:`gearsym.symbolic.teeth` searches over.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import Gear, GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.set_kinds import HOUSING
from gearsym.symbolic.set_relations import Relation, relations
from gearsym.symbolic.sympy_utils import exact_nullspace


def _symbol_name(relation: Relation, planetary_set: str) -> str:
    if relation.key == planetary_set:
        return naming.stationary_ratio(planetary_set)
    return naming.second_stationary_ratio(planetary_set)


def stationary_ratio_symbols(d: GearboxDescription) -> dict[str, sp.Symbol]:
    """k of every sun–ring pair as positive symbols: k_<set>, and k2_<set> for the second
    pair of a Ravigneaux set (keyed by :attr:`~gearsym.symbolic.set_relations.Relation.key`)."""
    return {
        rel.key: sp.Symbol(_symbol_name(rel, ps.name), positive=True)
        for ps in d.planetary_sets
        for rel in relations(ps)
    }


def stationary_ratios(d: GearboxDescription) -> dict[str, sp.Rational]:
    """Exact k of every sun–ring pair from the teeth (z_ring / z_sun for a simple set)."""
    return {
        rel.key: sp.Rational(rel.k.numerator, rel.k.denominator)
        for ps in d.planetary_sets
        for rel in relations(ps)
    }


def shaft_constraint_matrix(d: GearboxDescription, k: dict[str, sp.Expr]) -> sp.Matrix:
    """One row per sun–ring pair over the shaft speeds (file order):
    ω_S + k ω_H − (1 + k) ω_T = 0 for a negative stationary ratio (i0 = −k),
    ω_S − k ω_H − (1 − k) ω_T = 0 for a positive one (i0 = +k, double pinion)."""
    index = {name: i for i, name in enumerate(d.shaft_names)}
    pairs = [rel for ps in d.planetary_sets for rel in relations(ps)]
    rows = sp.zeros(len(pairs), len(index))
    for r, rel in enumerate(pairs):
        if rel.sign < 0:
            coefficients = ((rel.sun, 1), (rel.ring, k[rel.key]), (rel.carrier, -(1 + k[rel.key])))
        else:
            coefficients = ((rel.sun, 1), (rel.ring, -k[rel.key]), (rel.carrier, -(1 - k[rel.key])))
        for member, coefficient in coefficients:
            if member != HOUSING:  # the housing does not turn: its column is ω = 0
                rows[r, index[member]] += coefficient
    return rows


def closed_element_rows(d: GearboxDescription, closed: tuple[str, ...]) -> sp.Matrix:
    """A closed clutch ties ω_a − ω_b = 0; a closed brake holds ω_b = 0."""
    index = {name: i for i, name in enumerate(d.shaft_names)}
    rows = sp.zeros(len(closed), len(index))
    for r, name in enumerate(closed):
        element = d.element(name)
        rows[r, index[element.b]] = -1
        if element.a is not None:
            rows[r, index[element.a]] = 1
    return rows


def gear_motions(d: GearboxDescription, gear: Gear, k: dict[str, sp.Expr]) -> list[sp.Matrix]:
    """Basis of the shaft-speed vectors the gear allows (its null space)."""
    matrix = shaft_constraint_matrix(d, k).col_join(closed_element_rows(d, gear.closed))
    return exact_nullspace(matrix)


@dataclass(frozen=True)
class GearRatio:
    """The derived ratio of one gear and the ratio the description expects."""

    gear: str
    closed: tuple[str, ...]
    ratio: sp.Rational | None
    expected: float | None
    degrees_of_freedom: int
    #: Internal shafts the gear leaves free while ω_in/ω_out is fixed (speed undetermined).
    free_shafts: tuple[str, ...] = ()

    @property
    def neutral(self) -> bool:
        return self.ratio is None

    def rounded(self, decimals: int) -> float | None:
        return None if self.ratio is None else round(float(self.ratio), decimals)


def gear_ratio(d: GearboxDescription, gear: Gear, k: dict[str, sp.Expr] | None = None) -> GearRatio:
    """ω_in / ω_out of a gear (exact for numeric k), or None for a neutral gear.

    Raises :class:`GearsymError` naming the gear when its closed elements do not leave what
    the description claims: exactly one degree of freedom for a drivable gear, a free output
    for a neutral one.
    """
    k = stationary_ratios(d) if k is None else k
    key = f'gear[name="{gear.name}"].closed'
    motions = gear_motions(d, gear, k)
    dof = len(motions)
    i_in = d.shaft_names.index(d.input_shaft)
    i_out = d.shaft_names.index(d.output_shaft)
    closed = ", ".join(gear.closed) or "nothing"
    if gear.neutral:
        # Neutral: with the input held, the output must still be free to turn.
        held = [m for m in motions]
        free_output = _output_free_with_input_held(held, i_in, i_out)
        if not free_output:
            raise GearsymError(
                d.file,
                key,
                f"neutral gear {gear.name!r} (closed {closed}) does not free the output: "
                f"it leaves {dof} degree(s) of freedom and the output follows the input",
            )
        return GearRatio(gear.name, gear.closed, None, gear.ratio, dof)
    if dof == 0:
        raise GearsymError(
            d.file,
            key,
            f"gear {gear.name!r} (closed {closed}) locks the gearbox (0 degrees of freedom); "
            "a gear must leave exactly 1 (mark it neutral = true if it is a neutral)",
        )
    basis = sp.Matrix.hstack(*motions)
    free = _free_shafts(d, basis, i_in)
    if dof > 1 and _output_free_with_input_held(motions, i_in, i_out):
        raise GearsymError(
            d.file,
            key,
            f"gear {gear.name!r} (closed {closed}) leaves {dof} degrees of freedom: with the "
            f"input held, shaft(s) {', '.join(free)} can still turn, the output among them; a "
            "gear must fix the output (mark it neutral = true if it is a neutral)",
        )
    # One motion with the input turning; with idle shafts free (dof > 1) every such motion
    # has the same ω_in/ω_out, because holding the input holds the output (checked above).
    motion = next((basis * c for c in _input_moving(basis, i_in)), motions[0])
    w_in, w_out = sp.simplify(motion[i_in]), sp.simplify(motion[i_out])
    if w_out == 0 or w_in == 0:
        which = "output" if w_out == 0 else "input"
        raise GearsymError(
            d.file, key, f"gear {gear.name!r} (closed {closed}) holds the {which} shaft at rest"
        )
    return GearRatio(gear.name, gear.closed, sp.cancel(w_in / w_out), gear.ratio, dof, free)


def _input_moving(basis: sp.Matrix, i_in: int) -> list[sp.Matrix]:
    """Unit combinations of the basis whose motion turns the input."""
    return [sp.eye(basis.cols)[:, j] for j in range(basis.cols) if sp.simplify(basis[i_in, j]) != 0]


def _free_shafts(d: GearboxDescription, basis: sp.Matrix, i_in: int) -> tuple[str, ...]:
    """Shafts that can turn while the input is held (none in a gear of one degree of
    freedom); their speed is not determined by the input speed."""
    held = exact_nullspace(sp.Matrix([basis.row(i_in)]))
    return tuple(
        name
        for i, name in enumerate(d.shaft_names)
        if any(sp.simplify((basis.row(i) * c)[0]) != 0 for c in held)
    )


def gear_motion(d: GearboxDescription, gear: Gear) -> sp.Matrix:
    """The one shaft-speed motion of a drivable gear (exact), for the steady-gear uses
    (element slips, initial states, speed plans).

    A gear that leaves idle shafts free (:func:`idle_shafts`) has no unique motion by the
    kinematics; under the dynamics assumption of the models (README "Idle shafts": a viscous
    drag −d ω to the housing on every idle shaft of the description) the idle speeds settle
    where the drag does no work on the idle motion: the motion with the least Σ ω² over the
    idle shafts, which is the one returned."""
    motions = gear_motions(d, gear, stationary_ratios(d))
    if len(motions) == 1:
        return motions[0]
    i_in = d.shaft_names.index(d.input_shaft)
    basis = sp.Matrix.hstack(*motions)
    moving = next((basis * c for c in _input_moving(basis, i_in)), None)
    if moving is None or _output_free_with_input_held(
        motions, i_in, d.shaft_names.index(d.output_shaft)
    ):
        free = _free_shafts(d, basis, i_in)
        raise GearsymError(
            d.file,
            f'gear[name="{gear.name}"].closed',
            f"gear {gear.name!r} leaves shaft(s) {', '.join(free)} free and does not fix the "
            "output; its steady state cannot be derived",
        )
    idle = sp.Matrix.hstack(*(basis * c for c in exact_nullspace(sp.Matrix([basis.row(i_in)]))))
    dragged = [d.shaft_names.index(s) for s in idle_shafts(d)]
    select = sp.Matrix([[1 if j == i else 0 for j in range(len(d.shaft_names))] for i in dragged])
    a, b = select * idle, select * moving
    # least squares: (Aᵀ A) c = −Aᵀ b, A of full column rank (every idle direction moves an
    # idle shaft, by the definition of the idle shafts)
    c = (a.T * a).LUsolve(-(a.T * b))
    return (moving + idle * c).applyfunc(sp.cancel)


#: Idle shafts by description object (kept with its entry, so its id is not reused meanwhile).
_IDLE: dict[int, tuple[GearboxDescription, tuple[str, ...]]] = {}


def idle_shafts(d: GearboxDescription) -> tuple[str, ...]:
    """Shafts that some drivable gear leaves free (idle: they turn while the input, and so the
    output, is held), in the description's order; () for most gearboxes. The models give each
    a viscous drag to the housing (README "Idle shafts")."""
    cached = _IDLE.get(id(d))
    if cached is not None and cached[0] is d:
        return cached[1]
    k = stationary_ratios(d)
    i_in = d.shaft_names.index(d.input_shaft)
    found: set[str] = set()
    for g in d.gears:
        if g.neutral:
            continue
        motions = gear_motions(d, g, k)
        if len(motions) > 1:
            found.update(_free_shafts(d, sp.Matrix.hstack(*motions), i_in))
    result = tuple(s for s in d.shaft_names if s in found)
    if len(_IDLE) >= 16:
        _IDLE.clear()
    _IDLE[id(d)] = (d, result)
    return result


def _output_free_with_input_held(motions: list[sp.Matrix], i_in: int, i_out: int) -> bool:
    if not motions:
        return False
    basis = sp.Matrix.hstack(*motions)
    # Combinations c with (basis c)[in] = 0; the output is free if some such c moves it.
    held = exact_nullspace(sp.Matrix([basis.row(i_in)]))
    return any(sp.simplify((basis.row(i_out) * c)[0]) != 0 for c in held)


def ratio_table(d: GearboxDescription) -> list[GearRatio]:
    """Every gear of the description with its exact derived ratio."""
    return [gear_ratio(d, g) for g in d.gears]


def check_gear_table(d: GearboxDescription) -> None:
    """Raise on the first gear whose closed elements leave the wrong degrees of freedom."""
    for g in d.gears:
        gear_ratio(d, g)


def ratio_expressions(d: GearboxDescription) -> dict[str, sp.Expr | None]:
    """ω_in / ω_out of every gear as a rational function of the k_<set> symbols.

    Generic in k (pivots are chosen symbolically); used to search tooth counts, whose winners
    are then re-checked exactly by :func:`gear_ratio`.
    """
    k = stationary_ratio_symbols(d)
    result: dict[str, sp.Expr | None] = {}
    for g in d.gears:
        if g.neutral:
            result[g.name] = None
            continue
        motions = gear_motions(d, g, dict(k))
        if len(motions) != 1:
            raise GearsymError(
                d.file,
                f'gear[name="{g.name}"].closed',
                f"leaves {len(motions)} degrees of freedom for generic tooth counts",
            )
        m = motions[0]
        i_in = d.shaft_names.index(d.input_shaft)
        i_out = d.shaft_names.index(d.output_shaft)
        result[g.name] = sp.factor(sp.cancel(m[i_in] / m[i_out]))
    return result
