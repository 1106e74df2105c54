"""Stage 3c: the hybrid shift model — modes, guards and state maps of a single-swap shift.

The thesis' shift model (2.55)–(2.58) keeps the elements common to both gears locked and lets
the off-going and the on-coming element act as torques; its friction form (3.14),
T = k_sign 2 N_disc r_m μ F_N, holds only while an element slides ("nur im Gleitbereich").
A shift is therefore a hybrid system. Each of the two swapping elements is, at any time,

* **locked**: a constraint (its slip is zero); the torque it carries is the constraint
  reaction, bounded by its static capacity 2 N_disc r_m μ F_N (2.60) with (2.69);
* **sliding** with slip sign s = ±1: a torque T = s 2 N_disc r_m μ F_N (2.69), (3.14), k_sign
  from the slip sign (2.70);
* **open**: no torque (F_N = 0, 2.54).

The elements shared by both gears stay locked. Every combination except "both locked" (a
tie-up: no degree of freedom left, the gearbox stands still) is a *mode*, and each mode's model
comes from :func:`gearsym.symbolic.drivetrain.drivetrain_model` like today's gear and shift
models: locked elements are eliminated by the projection ẏ = P z (2.55), sliding elements act
through (3.14) with μ a parameter and F_N an input, open elements are absent.

Transitions are *guards*, symbolic expressions in the source mode's states, inputs and
parameters that cross zero at the event:

* **break-away** of a locked element: |T_req| exceeds its capacity, T_req the torque the mode's
  constraint must carry (the Lagrange multiplier of the locked element, from the model with that
  element released: the torque that keeps its slip acceleration at zero). The element slides
  in the direction of T_req: with less torque than needed the slip grows with the sign of
  T_req − T (:func:`slip_acceleration_gain` is negative), and (2.70) then gives k_sign = that sign.
* **lock-up** of a sliding element: its slip crosses zero. It sticks if the torque the locked
  mode needs is inside the capacity (the guard's *condition*), else it slides on the other way.
* **opening**: the normal force vanishes; **engagement**: it becomes positive again (the slip
  sign picks the direction).

The state map at a switch (:class:`StateMap`) is the projection onto the new constraint set in
the metric of the mass matrix M (2.34), z⁺ = (P⁺ᵀ M P⁺)⁻¹ P⁺ᵀ M P⁻ z⁻, the twist φ and the wheel
speed ω_C unchanged. It conserves the generalized momentum of the motions the new mode allows,
which is what a perfectly plastic (impulsive) engagement does. Two cases:

* at lock-up the slip is zero, so P⁻ z⁻ already lies in the range of P⁺ and the map is only a
  change of coordinates: no speed jumps, no energy is lost;
* at break-away, opening and engagement the new mode has the larger motion space, P⁺ z⁺ = P⁻ z⁻
  exactly (an embedding).

An engagement at non-zero slip (closing a clutch on a slipping pair with infinite capacity, or a
dog clutch) would need that impulse and lose the energy ½ Δẏᵀ M Δẏ; the same formula gives it,
but friction elements of finite capacity never do it: they slide until the slip is zero.

**One-way clutches** (``kind = "one_way"``, ``locks`` = the slip sign they block) may be a
swapping element: the classic 1-2 upshift of a Simpson box where only the on-coming brake is
pressed and the freewheel releases by itself, or the 2-1 downshift where it locks again. A
freewheel is a unilateral constraint, so it has two statuses only (no "open", no sliding with
friction):

* **locked**: a constraint like a locked friction element; it can carry a reaction torque of
  the sign ``locks`` only (sign convention of 2.36), with no capacity limit;
* **overrunning** with slip sign −``locks``: no torque (like an open element, 2.54).

Its guards: **release** (locked → overrunning) when ``locks`` · T_req falls through zero, T_req
the reaction as for a break-away; **lock-up** (overrunning → locked) when its slip crosses zero
heading into the blocked sign, with the condition ``locks`` · T_req ≥ 0 of the locked mode at the
mapped state. At a transversal crossing the condition holds by itself: the released slip
acceleration has the blocked sign there, and the reaction has the sign of that acceleration
(T_req = −a₀/g with the gain g < 0 of :func:`slip_acceleration_gain`); a grazing crossing that
fails it keeps the freewheel overrunning. The state maps are the friction elements' M-metric
projections: at a release P⁺ z⁺ = P⁻ z⁻ (an embedding), at a lock-up the slip is zero (a change
of coordinates). A freewheel has no normal force and no μ: the shift's inputs and parameters
carry those of its friction element only.

**Dog elements** (``kind = "dog"``: form-locking, as the ZF 9HP's A and F) may be a swapping
element too. A dog has two statuses, **locked** (a constraint of unlimited capacity: no
break-away) and **open** (no torque); no sliding friction, no μ, no F_N. It is commanded, not
pressed: the scenario's ``[pressure.<dog>]`` profile is its actuation command (engaged while
> 0, the value itself does not matter; :mod:`gearsym.validation.sim.hybrid_simulation`). Its
guards:

* **engagement** (open → locked) fires when the command rises, *not* at a zero crossing; its
  condition is ``engage_slip`` − |Δω| ≥ 0 and it has no ``otherwise``: a commanded engagement
  away from synchronism is a failure the simulation states (the teeth would clash), never a
  silent slip. The state map is the M-metric projection above, an impulsive engagement that
  loses ½ Δẏᵀ M Δẏ (zero at zero slip), which the simulation reports per event;
* **disengagement** (locked → open) when the command is off and |T_req| falls through
  ``release_torque`` (a loaded dog cannot be pulled out: it stays locked until the friction
  partner has taken its load); a dog already unloaded when the command falls opens at once.
  An embedding, like a release.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from itertools import product

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import (
    drivetrain_model,
    drivetrain_parameters,
    drivetrain_parts,
    friction_symbols,
    locked_projection,
    quantity,
    slip_rows,
)
from gearsym.symbolic.dynamics import GearboxDynamics, gearbox_dynamics
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.kinematics import exact
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.shifts import ShiftSpec, shift_spec

LOCKED = "locked"
SLIDING = "sliding"
OPEN = "open"
OVERRUNNING = "overrunning"

#: Status of a swapping element in a mode: locked, sliding with slip sign +1 / −1, open.
STATUSES: tuple[tuple[str, int], ...] = ((LOCKED, 0), (SLIDING, 1), (SLIDING, -1), (OPEN, 0))

BREAK_AWAY = "break-away"
LOCK_UP = "lock-up"
OPENING = "opening"
ENGAGEMENT = "engagement"
RELEASE = "release"
DISENGAGEMENT = "disengagement"

#: The guards that depend on the state (located by a root search, with the event-time term of
#: the sensitivity jump); opening and engagement depend on F_N alone. A dog's disengagement is
#: a state guard that is armed only while its command is off.
STATE_GUARDS = (BREAK_AWAY, LOCK_UP, RELEASE, DISENGAGEMENT)

#: Statuses of a dog element: locked or open (module docstring).
DOG_STATUSES: tuple[tuple[str, int], ...] = ((LOCKED, 0), (OPEN, 0))


def status_label(status: str, sign: int) -> str:
    """``locked``, ``slide_pos``, ``slide_neg``, ``open`` or ``overrun`` (parts of a mode
    name)."""
    if status == SLIDING:
        return "slide_pos" if sign > 0 else "slide_neg"
    if status == OVERRUNNING:
        return "overrun"
    return status


def element_statuses(d: GearboxDescription, element: str) -> tuple[tuple[str, int], ...]:
    """The statuses a swapping element can take: :data:`STATUSES` for a friction element;
    locked or overrunning (slip sign −``locks``) for a one-way clutch (module docstring)."""
    e = d.element(element)
    if e.one_way:
        return ((LOCKED, 0), (OVERRUNNING, -e.locks))
    if e.dog:
        return DOG_STATUSES
    return STATUSES


def released_status(d: GearboxDescription, element: str) -> tuple[str, int]:
    """The status of a swapping element in the gear that does not close it: open, or
    overrunning for a one-way clutch."""
    e = d.element(element)
    return (OVERRUNNING, -e.locks) if e.one_way else (OPEN, 0)


@dataclass(frozen=True)
class Mode:
    """One mode of the hybrid shift: a :class:`Model` (2.55)–(2.58) with (3.14) for the sliding
    elements, and what the guards need.

    ``status[e]`` is (``"locked"`` | ``"sliding"`` | ``"open"``, slip sign) of each swapping
    element; ``projection`` is P with ẏ = P z (2.55), z the mode's gearbox speeds (``keep``);
    ``slip[e]`` is Δω_e = ω_a − ω_b of each swapping element in the mode's states (2.59);
    ``reaction[e]`` the torque a locked element must carry (sign of 2.36); ``capacity[e]`` the
    magnitude 2 N_disc r_m μ_e F_N,e (2.69) of each swapping friction element (a one-way
    clutch has none).
    """

    name: str
    status: dict[str, tuple[str, int]]
    model: Model
    keep: tuple[str, ...]
    projection: sp.Matrix
    slip: dict[str, sp.Expr]
    reaction: dict[str, sp.Expr]
    capacity: dict[str, sp.Expr]

    @property
    def locked(self) -> tuple[str, ...]:
        return tuple(e for e, (s, _) in self.status.items() if s == LOCKED)

    @property
    def sliding(self) -> dict[str, int]:
        return {e: k for e, (s, k) in self.status.items() if s == SLIDING}


@dataclass(frozen=True)
class Guard:
    """A transition out of mode ``source``: when ``expression`` (source mode's x, u, p) crosses
    zero in ``direction`` (+1 rising, −1 falling), the shift goes to ``target`` if
    ``condition`` (source mode's x, u, p, evaluated after the crossing) is ≥ 0 or absent, else
    to ``otherwise``."""

    source: str
    element: str
    kind: str
    expression: sp.Expr
    direction: int
    target: str
    condition: sp.Expr | None = None
    otherwise: str | None = None


@dataclass(frozen=True)
class StateMap:
    """x⁺ = ``matrix`` · x⁻ at a switch from ``source`` to ``target``: the M-metric projection
    of the gearbox speeds onto the target's constraint set (module docstring), φ and ω_C
    unchanged. ``kind``: "change of coordinates" (fewer motions: lock-up at zero slip),
    "embedding" (more motions) or "same" (same constraint set)."""

    source: str
    target: str
    matrix: sp.Matrix
    kind: str


@dataclass(frozen=True)
class HybridShift:
    """Modes, guards and state maps of a single-swap shift (module docstring).

    ``inputs`` (T_In, F_N of the off-going and the on-coming element) and ``parameters`` (the
    drivetrain's and both μ) are the union over the modes; a mode's model uses a subset. A
    one-way clutch among the elements has no F_N and no μ: ``normal_force`` and
    ``friction_coefficient`` name the friction elements only, and ``one_way`` maps a one-way
    swapping element to its ``locks``. ``from_mode`` is the from-gear (off-going locked,
    on-coming open or overrunning), ``to_mode`` the to-gear. ``dog`` maps a dog swapping
    element to its (``engage_slip`` in rad/s, ``release_torque`` in N·m).
    """

    spec: ShiftSpec
    elements: tuple[str, str]
    modes: dict[str, Mode]
    guards: tuple[Guard, ...]
    maps: dict[tuple[str, str], StateMap]
    inputs: tuple[Variable, ...]
    parameters: tuple[Variable, ...]
    normal_force: dict[str, sp.Symbol]
    friction_coefficient: dict[str, sp.Symbol]
    from_mode: str
    to_mode: str
    one_way: dict[str, int] = field(default_factory=dict)
    dog: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def friction_elements(self) -> tuple[str, ...]:
        """The swapping elements with a normal force and a μ (not one-way clutches, not dog
        elements)."""
        return tuple(e for e in self.elements if e not in self.one_way and e not in self.dog)

    def guards_from(self, mode: str) -> tuple[Guard, ...]:
        """Every guard whose source is ``mode``."""
        return tuple(g for g in self.guards if g.source == mode)

    def mode_of(self, status: Mapping[str, tuple[str, int]]) -> Mode:
        """The mode with the given status per swapping element."""
        return self.modes[mode_name(self.spec, self.elements, status)]


def mode_name(
    spec: ShiftSpec, elements: tuple[str, str], status: Mapping[str, tuple[str, int]]
) -> str:
    """``hybrid_2_3__K38_locked__B05_open``: shift and status of each swapping element."""
    parts = [f"{e}_{status_label(*status[e])}" for e in elements]
    return "__".join([f"hybrid_{spec.from_gear}_{spec.to_gear}", *parts])


def _constraint_rows(
    d: GearboxDescription, dyn: GearboxDynamics, locked: tuple[str, ...]
) -> list[sp.Matrix]:
    """Rows of the slip Δω_e = ω_a − ω_b of each locked element in ẏ (2.59), which vanish."""
    return slip_rows(d, dyn, locked)


def mode_coordinates(
    d: GearboxDescription, dyn: GearboxDynamics, locked: tuple[str, ...]
) -> tuple[str, ...]:
    """The shafts whose speeds are a mode's gearbox states: the output shaft alone when one
    motion is left (as the gear models), else the input and output shaft first (as the shift
    model (2.55)), completed by the measured shafts and the coordinates if more are needed."""
    transform = dyn.kinematics.transform
    index = {b: i for i, b in enumerate(d.body_names)}
    rows = _constraint_rows(d, dyn, locked)
    rank = sp.Matrix.vstack(*rows).rank() if rows else 0
    free = transform.cols - rank
    order = [d.output_shaft, d.input_shaft, *d.measured_shafts, *d.coordinates, *d.shaft_names]
    chosen: list[str] = []
    for shaft in dict.fromkeys(order):
        if len(chosen) == free:
            break
        trial = sp.Matrix.vstack(*rows, *(transform[index[s], :] for s in [*chosen, shaft]))
        if trial.rank() == rank + len(chosen) + 1:
            chosen.append(shaft)
    preferred = [d.input_shaft, d.output_shaft]
    return tuple(sorted(chosen, key=lambda s: preferred.index(s) if s in preferred else 2))


def _friction_symbols(d: GearboxDescription, element: str) -> tuple[sp.Expr, Variable, Variable]:
    """(gain 2 N_disc r_m, F_N input, μ parameter) of an element, named as drivetrain_parts
    names them (2.69), (3.14)."""
    return friction_symbols(
        d, element, "the hybrid shift model needs n_disc and r_m of the swapping elements"
    )


def _slip(d: GearboxDescription, body_speeds: Mapping[str, sp.Expr], element: str) -> sp.Expr:
    e = d.element(element)
    return sp.expand((body_speeds[e.a] if e.a is not None else 0) - body_speeds[e.b])


def _released(
    d: GearboxDescription,
    dyn: GearboxDynamics,
    locked: tuple[str, ...],
    sliding: Mapping[str, int],
    element: str,
    friction: Mapping[str, tuple[sp.Expr, Variable, Variable]],
) -> tuple[sp.Expr, sp.Expr, tuple[str, ...], dict[str, sp.Expr]]:
    """The mode with ``element`` released to a torque input T_e: (d Δω_e/dt at T_e = 0,
    ∂(d Δω_e/dt)/∂T_e, the released model's kept shafts, its body speeds)."""
    others = tuple(e for e in locked if e != element)
    keep = mode_coordinates(d, dyn, others)
    parts = drivetrain_parts(d, others, (*sliding, element), keep)
    torque = {
        parts.torque_symbols[e]: sign
        * friction[e][0]
        * friction[e][2].symbol
        * friction[e][1].symbol
        for e, sign in sliding.items()
    }
    slip = _slip(d, parts.body_speeds, element)
    row = sp.Matrix([[slip.diff(s) for s in parts.speeds]])
    acceleration = sp.expand((row * parts.gearbox_rhs.xreplace(torque))[0])
    t_e = parts.torque_symbols[element]
    gain = acceleration.diff(t_e)
    return sp.expand(acceleration.xreplace({t_e: 0})), gain, keep, parts.body_speeds


def slip_acceleration_gain(
    d: GearboxDescription, shift: str, element: str, locked_too: tuple[str, ...] = ()
) -> sp.Expr:
    """∂(d Δω_e/dt)/∂T_e of a swapping element released from the shift's locked set (plus
    ``locked_too``): minus the inverse of the effective inertia the element sees, so negative
    whenever M (2.34) is positive definite. It fixes the slip direction after a break-away."""
    spec = shift_spec(d, shift)
    dyn = gearbox_dynamics(d)
    friction = {
        e: _friction_symbols(d, e)
        for e in (spec.off_going, spec.on_coming)
        if not d.element(e).one_way and not d.element(e).dog
    }
    locked = (*spec.locked, *locked_too, element)
    return _released(d, dyn, locked, {}, element, friction)[1]


def hybrid_shift(d: GearboxDescription, shift: str) -> HybridShift:
    """Derive the hybrid model of a single-swap shift (module docstring): every mode's model
    (2.55)–(2.58) with (3.14), the guards (break-away, lock-up, opening, engagement) and the
    state maps. Nothing here is specific to a gearbox: the shift's elements come from the
    gear table (:func:`gearsym.symbolic.shifts.shift_spec`)."""
    spec = shift_spec(d, shift)
    dyn = gearbox_dynamics(d)
    elements = (spec.off_going, spec.on_coming)
    one_way = {e: d.element(e).locks for e in elements if d.element(e).one_way}
    if len(one_way) == 2:
        raise GearsymError(
            d.file,
            "shift",
            f"shift {shift!r} swaps two one-way clutches ({', '.join(elements)}); the hybrid "
            "model needs a friction element that is pressed",
        )
    dog = {
        e: (d.element(e).engage_slip.value, d.element(e).release_torque.value)  # type: ignore[union-attr]
        for e in elements
        if d.element(e).dog
    }
    if len(dog) + len(one_way) == 2:
        raise GearsymError(
            d.file,
            "shift",
            f"shift {shift!r} swaps {', '.join(elements)}, neither a friction element: a dog "
            "element or a freewheel is synchronised by a friction element of the shift, which "
            "the hybrid model needs",
        )
    friction = {e: _friction_symbols(d, e) for e in elements if e not in one_way and e not in dog}
    modes: dict[str, Mode] = {}
    for statuses in product(*(element_statuses(d, e) for e in elements)):
        status = dict(zip(elements, statuses, strict=True))
        swapped_locked = tuple(e for e in elements if status[e][0] == LOCKED)
        if len(swapped_locked) == 2:
            continue  # tie-up: no motion left (module docstring)
        locked = (*spec.locked, *swapped_locked)
        sliding = {e: k for e, (s, k) in status.items() if s == SLIDING}
        keep = mode_coordinates(d, dyn, locked)
        name = mode_name(spec, elements, status)
        model = drivetrain_model(
            d, name, locked=locked, torque_elements=tuple(sliding), keep=keep, slip_signs=sliding
        )
        parts_speeds = drivetrain_parts(d, locked, (), keep).body_speeds
        slip = {e: _slip(d, parts_speeds, e) for e in elements}
        reaction = {}
        for e in swapped_locked:
            free, gain, released_keep, _ = _released(d, dyn, locked, sliding, e, friction)
            # the released model's speeds in this mode's coordinates (slip_e = 0 there)
            to_mode = {sp.Symbol(naming.speed(s)): parts_speeds[s] for s in released_keep}
            reaction[e] = sp.expand((-free / gain).xreplace(to_mode))
        capacity = {e: f[0] * f[2].symbol * f[1].symbol for e, f in friction.items()}
        projection = locked_projection(d, dyn, locked, keep)
        modes[name] = Mode(name, status, model, keep, projection, slip, reaction, capacity)

    mass = drivetrain_mass(d, dyn)
    maps: dict[tuple[str, str], StateMap] = {}
    guards: list[Guard] = []

    def to(mode: Mode, element: str, status: tuple[str, int]) -> str | None:
        new = {**mode.status, element: status}
        name = mode_name(spec, elements, new)
        if name not in modes:
            return None
        if (mode.name, name) not in maps:
            maps[(mode.name, name)] = _state_map(mode, modes[name], mass)
        return name

    def mapped(source: Mode, target: str) -> dict[sp.Symbol, sp.Expr]:
        """The target mode's states as the state map gives them from the source's."""
        matrix = maps[(source.name, target)].matrix
        return dict(
            zip(
                modes[target].model.state_symbols,
                matrix * sp.Matrix(source.model.state_symbols),
                strict=True,
            )
        )

    for mode in modes.values():
        for e in elements:
            state, sign = mode.status[e]
            if e in one_way:
                guards.extend(_one_way_guards(mode, e, one_way[e], modes, to, mapped))
                continue
            if e in dog:
                guards.extend(_dog_guards(mode, e, dog[e], to))
                continue
            normal = friction[e][1].symbol
            if state == LOCKED:
                for k in (1, -1):
                    target = to(mode, e, (SLIDING, k))
                    assert target is not None
                    guards.append(
                        Guard(
                            mode.name,
                            e,
                            BREAK_AWAY,
                            k * mode.reaction[e] - mode.capacity[e],
                            1,
                            target,
                        )
                    )
                target = to(mode, e, (OPEN, 0))
                assert target is not None
                guards.append(Guard(mode.name, e, OPENING, normal, -1, target))
            elif state == SLIDING:
                reverse = to(mode, e, (SLIDING, -sign))
                stick = to(mode, e, (LOCKED, 0))
                if stick is None:  # the other element is locked: lock-up would be a tie-up
                    guards.append(Guard(mode.name, e, LOCK_UP, mode.slip[e], -sign, str(reverse)))
                else:
                    x_next = mapped(mode, stick)
                    target_mode = modes[stick]
                    inside = mode.capacity[e] - sp.Abs(target_mode.reaction[e].xreplace(x_next))
                    guards.append(
                        Guard(mode.name, e, LOCK_UP, mode.slip[e], -sign, stick, inside, reverse)
                    )
                target = to(mode, e, (OPEN, 0))
                assert target is not None
                guards.append(Guard(mode.name, e, OPENING, normal, -1, target))
            else:
                forward, backward = to(mode, e, (SLIDING, 1)), to(mode, e, (SLIDING, -1))
                assert forward is not None and backward is not None
                guards.append(
                    Guard(mode.name, e, ENGAGEMENT, normal, 1, forward, mode.slip[e], backward)
                )

    friction_elements = tuple(e for e in elements if e in friction)
    parameters = drivetrain_parameters(d) + tuple(friction[e][2] for e in friction_elements)
    from_status = {spec.off_going: (LOCKED, 0), spec.on_coming: released_status(d, spec.on_coming)}
    to_status = {spec.off_going: released_status(d, spec.off_going), spec.on_coming: (LOCKED, 0)}
    u_in = modes[mode_name(spec, elements, from_status)]
    inputs = (
        u_in.model.variable(naming.INPUT_TORQUE),
        *(friction[e][1] for e in friction_elements),
    )
    return HybridShift(
        spec=spec,
        elements=elements,
        modes=modes,
        guards=tuple(guards),
        maps=maps,
        inputs=inputs,
        parameters=parameters,
        normal_force={e: friction[e][1].symbol for e in friction_elements},
        friction_coefficient={e: friction[e][2].symbol for e in friction_elements},
        from_mode=u_in.name,
        to_mode=mode_name(spec, elements, to_status),
        one_way=one_way,
        dog=dog,
    )


def _dog_guards(
    mode: Mode,
    element: str,
    limits: tuple[float, float],
    to: Callable[[Mode, str, tuple[str, int]], str | None],
) -> list[Guard]:
    """The guards of a dog swapping element (module docstring): disengagement of a locked dog
    when |T_req| falls through ``release_torque`` (armed while its command is off); engagement
    of an open dog when its command rises, with the condition ``engage_slip`` − |Δω| ≥ 0 and
    no ``otherwise`` (a failure). With the other element locked an engagement would be a
    tie-up: no guard (the simulation states that failure too)."""
    engage_slip, release_torque = (exact(v) for v in limits)
    state, _ = mode.status[element]
    if state == LOCKED:
        target = to(mode, element, (OPEN, 0))
        assert target is not None
        expression = sp.Abs(mode.reaction[element]) - release_torque
        return [Guard(mode.name, element, DISENGAGEMENT, expression, -1, target)]
    target = to(mode, element, (LOCKED, 0))
    if target is None:
        return []
    inside = engage_slip - sp.Abs(mode.slip[element])
    return [Guard(mode.name, element, ENGAGEMENT, mode.slip[element], 0, target, inside, None)]


def _one_way_guards(
    mode: Mode,
    element: str,
    locks: int,
    modes: Mapping[str, Mode],
    to: Callable[[Mode, str, tuple[str, int]], str | None],
    mapped: Callable[[Mode, str], dict[sp.Symbol, sp.Expr]],
) -> list[Guard]:
    """The guards of a one-way swapping element (module docstring): release when ``locks`` ·
    T_req falls through zero; lock-up when the slip crosses zero towards the blocked sign, with
    the condition ``locks`` · T_req ≥ 0 of the locked mode (else it stays overrunning). With
    the other element locked a lock-up would be a tie-up: the slip of an overrunning freewheel
    is then a fixed multiple of the output speed and reaches zero only with the vehicle at
    rest, which a shift model does not cover, so there is no guard."""
    state, _ = mode.status[element]
    if state == LOCKED:
        target = to(mode, element, (OVERRUNNING, -locks))
        assert target is not None
        return [Guard(mode.name, element, RELEASE, locks * mode.reaction[element], -1, target)]
    stick = to(mode, element, (LOCKED, 0))
    if stick is None:
        return []
    stay = to(mode, element, mode.status[element])
    condition = locks * modes[stick].reaction[element].xreplace(mapped(mode, stick))
    return [Guard(mode.name, element, LOCK_UP, mode.slip[element], locks, stick, condition, stay)]


def drivetrain_mass(d: GearboxDescription, dyn: GearboxDynamics) -> sp.Matrix:
    """M of (2.34) with the output-side inertias of (2.51) (as drivetrain_parts adds them)."""
    i_d = exact(quantity(d, "drivetrain", "i_D").value)
    extra = exact(quantity(d, "drivetrain", "J_cs").value)
    extra += exact(quantity(d, "drivetrain", "J_D").value) / i_d**2
    index = {b: i for i, b in enumerate(d.body_names)}
    out_row = dyn.kinematics.transform[index[d.output_shaft], :]
    return dyn.mass_matrix + extra * (out_row.T * out_row)


def _state_map(source: Mode, target: Mode, mass: sp.Matrix) -> StateMap:
    """z⁺ = (P⁺ᵀ M P⁺)⁻¹ P⁺ᵀ M P⁻ z⁻, φ and ω_C unchanged (module docstring)."""
    p_new, p_old = target.projection, source.projection
    gearbox = (p_new.T * mass * p_new).inv() * (p_new.T * mass * p_old)
    n_old, n_new = p_old.cols, p_new.cols
    matrix = sp.zeros(n_new + 2, n_old + 2)
    matrix[:n_new, :n_old] = gearbox
    matrix[n_new, n_old] = 1  # φ
    matrix[n_new + 1, n_old + 1] = 1  # ω_C
    if n_new < n_old:
        kind = "change of coordinates"
    elif n_new > n_old:
        kind = "embedding"
    else:
        kind = "same"
    return StateMap(source.name, target.name, matrix, kind)
