"""An independent reference of the gearbox dynamics, in plain NumPy (thesis 2.20–2.58).

The symbolic models (:mod:`gearsym.symbolic.kinematics`, :mod:`gearsym.symbolic.dynamics`,
:mod:`gearsym.symbolic.drivetrain`) build the kinematics from one Willis row per tooth mesh
(2.22, 2.23), propagate them set by set into the transform T of (2.29), form the mass matrix
(2.34) and project it onto the motions the locked elements allow (2.55). A test whose expected
values come from that same mass matrix cannot see a wrong mass matrix: leaving the planets'
orbit out of (2.34) kept the hybrid mode, locked-reaction and double-swap tests green. This
module derives the same right-hand sides a second way, sharing no code with the derivation:

* **Kinematics.** Per planetary set, the *published* relations of its kind in the carrier
  frame (``docs/set-kinds.md``, thesis 2.20 for a simple set), one per sun–ring pair plus one
  per pinion, each of the form ω_x − ω_C = ρ (ω_y − ω_C):

  ========================  ==============================================================
  ``simple``                ω_S − ω_C = −(z_H/z_S)(ω_H − ω_C) (Willis, 2.20);
                            ω_P − ω_C = −(z_S/z_P)(ω_S − ω_C) (planet from the sun mesh)
  ``double_pinion``         ω_S − ω_C = +(z_H/z_S)(ω_H − ω_C);
                            ω_P − ω_C = −(z_S/z_P)(ω_S − ω_C);
                            ω_Po − ω_C = +(z_H/z_Po)(ω_H − ω_C)
  ``ravigneaux``            ω_S − ω_C = −(z_H/z_S)(ω_H − ω_C) (long pair);
                            ω_S2 − ω_C = +(z_H/z_S2)(ω_H − ω_C) (short pair);
                            ω_L − ω_C = +(z_H/z_L)(ω_H − ω_C);
                            ω_Ps − ω_C = −(z_S2/z_Ps)(ω_S2 − ω_C)
  ``ravigneaux_two_rings``  ω_S − ω_C = −(z_H/z_S)(ω_H − ω_C) (long pair);
                            ω_S − ω_C = +(z_H2/z_S)(ω_H2 − ω_C) (short pair);
                            ω_L − ω_C = −(z_S/z_L)(ω_S − ω_C);
                            ω_Ps − ω_C = +(z_H2/z_Ps)(ω_H2 − ω_C)
  ``stepped_planet``        ω_S − ω_C = −(z_H z_P/(z_S z_P2))(ω_H − ω_C);
                            ω_P − ω_C = −(z_S/z_P)(ω_S − ω_C)
  set given by ``k``        ω_S − ω_C = i0 (ω_H − ω_C), no pinion bodies
  ========================  ==============================================================

  A member named ``housing`` has ω = 0. With the locked elements' zero slips ω_a − ω_b = 0
  (2.59) and the chosen shafts' speeds z, one NumPy solve gives every body's speed, shafts and
  lumped pinion bodies, as a linear map ω = J z (the Jacobian of 2.31).
* **Mass matrix from the kinetic energy** (2.34): E = ½ Σ_shafts I_s ω_s²
  + Σ_pinions n (½ J_p ω_p² + ½ m_p r_p² ω_C²) (spin of n planets and their orbit with the
  carrier), + ½ Σ J_m ω_m² of a set's ``planet_inertia_reflected``, so
  M = Σ_bodies J_bᵀ I_b J_b + Σ_pinions n m_p r_p² J_Cᵀ J_C. The propeller shaft and the
  differential cage turn with the output shaft: J_cs + J_D/i_D² on it ((2.51) as corrected in
  the README).
* **Generalized forces from virtual power** (2.35, 2.36): P = T_In ω_in − T_out ω_out
  + Σ_e T_e (ω_b − ω_a) − Σ_idle d ω_s², so Q = Σ_b J_bᵀ τ_b; then ż = M⁻¹ Q (2.40, 2.41).
  Idle shafts (a gear leaves them turning with the input held) are found here from the same
  kinematics; their drag d is ``[drivetrain] idle_drag`` or 0.002 N·m·s/rad (README "Idle
  shafts").
* **Drivetrain** (2.42–2.53), also written out here from the equations, not taken from the
  models: φ̇ = ω_out/i_D − ω_C (2.44), T_ss = k_ss φ + d_ss φ̇ (2.47), T_out = 2 T_ss/i_D
  (2.52), ω̇_C = (2 T_ss − T_res)/(I_wheel + m_veh r_dyn²) ((2.45), (2.46) with the square),
  T_res = r_dyn (F_r + F_ad + F_g) (2.48) with F_r in the description's form (2.49a as
  printed, the textbook form or the polynomial), F_ad = ½ ρ c_W A v², F_g = m g sin ζ (2.49).
  Both routes read the same printed equations and the same two corrections of printed slips,
  so a misreading shared by both would not show; the gearbox part (kinematics, mass and input
  matrix, projection) shares nothing but the description's numbers.
* **Shifts** (2.55–2.58, 3.1): the elements common to both gears stay locked, the others act
  as torques; for the friction form T = k_sign 2 N_disc r_m μ F_N (2.69, 3.14), the power-on
  slip directions are derived here from the gear speeds (the on-coming element slips as the
  from-gear makes it; the off-going one against the to-gear in an upshift, with it in a
  downshift).

Imports: NumPy and the parsed description's dataclasses only (no SymPy, no CasADi, nothing of
the derivation); ``tests/test_numpy_dynamics.py`` checks that, and compares these right-hand
sides with the symbolic models'.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from gearsym.symbolic.description import GearboxDescription, PlanetarySet, ShiftElement

__all__ = [
    "HOUSING",
    "IDLE_DRAG_DEFAULT",
    "NumpyModel",
    "Relation",
    "adjacent_shifts",
    "body_names",
    "friction_torque",
    "gear_ratio",
    "gear_speeds",
    "idle_shafts",
    "numpy_model",
    "power_on_slip_signs",
    "set_relations",
    "shift_elements",
]

#: A set member of this name is fixed to the housing: ω = 0 (README "Housing as a member").
HOUSING = "housing"
#: N·m·s/rad, drag of an idle shaft when the description gives no ``[drivetrain] idle_drag``
#: (README "Idle shafts": 2 N·m at 1000 rad/s).
IDLE_DRAG_DEFAULT = 0.002
#: Relative size below which a singular value counts as zero (the kinematics are O(1) ratios).
_RANK_TOLERANCE = 1e-10


@dataclass(frozen=True)
class Relation:
    """ω_body − ω_C = ratio · (ω_reference − ω_C): one relation of a set in its carrier frame
    (Willis, 2.20; a pinion's speed from its mesh, 2.22/2.23)."""

    body: str
    reference: str
    ratio: float
    carrier: str
    equation: str


def set_relations(ps: PlanetarySet) -> tuple[Relation, ...]:
    """The published relations of a set's kind (module docstring, ``docs/set-kinds.md``; the
    thesis' simple set 2.20–2.23): one per sun–ring pair, then one per pinion body (none for a
    set given by ``k``)."""
    c = ps.carrier
    if ps.given_k is not None:
        return (Relation(ps.sun, ps.ring, float(ps.given_k), c, "w_S - w_C = i0 (w_H - w_C)"),)
    z_s, z_p, z_h = float(ps.z_sun), float(ps.z_planet), float(ps.z_ring)
    if ps.kind == "simple":
        return (
            Relation(ps.sun, ps.ring, -z_h / z_s, c, "Willis (2.20): i0 = -z_H/z_S"),
            Relation(ps.planet, ps.sun, -z_s / z_p, c, "planet from the sun mesh (2.22)"),
        )
    assert ps.z_planet2 is not None
    z_p2 = float(ps.z_planet2)
    if ps.kind == "stepped_planet":
        return (
            Relation(ps.sun, ps.ring, -z_h * z_p / (z_s * z_p2), c, "i0 = -z_H z_P/(z_S z_P2)"),
            Relation(ps.planet, ps.sun, -z_s / z_p, c, "planet from the sun mesh"),
        )
    assert ps.planet2 is not None
    if ps.kind == "double_pinion":
        return (
            Relation(ps.sun, ps.ring, z_h / z_s, c, "i0 = +z_H/z_S"),
            Relation(ps.planet, ps.sun, -z_s / z_p, c, "inner pinion from the sun mesh"),
            Relation(ps.planet2, ps.ring, z_h / z_p2, c, "outer pinion from the ring mesh"),
        )
    if ps.kind == "ravigneaux":
        assert ps.sun2 is not None and ps.z_sun2 is not None
        z_s2 = float(ps.z_sun2)
        return (
            Relation(ps.sun, ps.ring, -z_h / z_s, c, "long pair: i0 = -z_H/z_S"),
            Relation(ps.sun2, ps.ring, z_h / z_s2, c, "short pair: i0 = +z_H/z_S2"),
            Relation(ps.planet, ps.ring, z_h / z_p, c, "long pinion from the ring mesh"),
            Relation(ps.planet2, ps.sun2, -z_s2 / z_p2, c, "short pinion from the sun2 mesh"),
        )
    if ps.kind == "ravigneaux_two_rings":
        assert ps.ring2 is not None and ps.z_ring2 is not None
        z_h2 = float(ps.z_ring2)
        return (
            Relation(ps.sun, ps.ring, -z_h / z_s, c, "long pair: i0 = -z_H/z_S"),
            Relation(ps.sun, ps.ring2, z_h2 / z_s, c, "short pair: i0 = +z_H2/z_S"),
            Relation(ps.planet, ps.sun, -z_s / z_p, c, "long pinion from the sun mesh"),
            Relation(ps.planet2, ps.ring2, z_h2 / z_p2, c, "short pinion from the ring2 mesh"),
        )
    raise ValueError(f"set {ps.name!r}: unknown kind {ps.kind!r}")


def _pinions(ps: PlanetarySet) -> tuple[str, ...]:
    """The set's pinion bodies: the planet, and the second pinion of the compound kinds."""
    if ps.given_k is not None:
        return ()
    return (ps.planet,) if ps.planet2 is None else (ps.planet, ps.planet2)


def body_names(d: GearboxDescription) -> tuple[str, ...]:
    """Shafts in file order, then every set's pinion bodies (2.26)."""
    return tuple(s.name for s in d.shafts) + tuple(
        p for ps in d.planetary_sets for p in _pinions(ps)
    )


def _slip_row(e: ShiftElement, index: Mapping[str, int]) -> np.ndarray:
    """Δω = ω_a − ω_b of an element over the body speeds (2.59)."""
    row = np.zeros(len(index))
    row[index[e.b]] -= 1.0
    if e.a is not None:
        row[index[e.a]] += 1.0
    return row


def _constraints(d: GearboxDescription, locked: Sequence[str]) -> np.ndarray:
    """Rows R with R ω = 0 over the body speeds: every set's relations, then the zero slip of
    every locked element."""
    index = {b: i for i, b in enumerate(body_names(d))}
    rows = []
    for ps in d.planetary_sets:
        for rel in set_relations(ps):
            # ω_x − ω_C − ρ (ω_y − ω_C) = 0; a housing member has ω = 0 (no column)
            row = np.zeros(len(index))
            for body, coefficient in (
                (rel.body, 1.0),
                (rel.reference, -rel.ratio),
                (rel.carrier, rel.ratio - 1.0),
            ):
                if body != HOUSING:
                    row[index[body]] += coefficient
            rows.append(row)
    elements = {e.name: e for e in d.shift_elements}
    rows += [_slip_row(elements[name], index) for name in locked]
    return np.array(rows).reshape(len(rows), len(index))


def _null_space(a: np.ndarray) -> np.ndarray:
    """Orthonormal basis (columns) of the null space of ``a``."""
    if a.shape[0] == 0:
        return np.eye(a.shape[1])
    _, s, vt = np.linalg.svd(a)
    rank = int(np.sum(s > _RANK_TOLERANCE * max(s.max(), 1.0)))
    return vt[rank:].T


def idle_shafts(d: GearboxDescription) -> tuple[str, ...]:
    """Shafts that some drivable gear leaves free to turn while the input is held (README
    "Idle shafts"), in file order: the gear's motions (the null space of the set relations
    and the closed elements' zero slips, 2.20–2.23, 2.59) that keep ω_in = 0 move them."""
    bodies = body_names(d)
    i_in = bodies.index(d.input_shaft)
    found: set[str] = set()
    for gear in d.gears:
        if gear.neutral:
            continue
        basis = _null_space(_constraints(d, gear.closed))
        if basis.shape[1] < 2:
            continue
        held = basis @ _null_space(basis[i_in : i_in + 1, :])
        scale = np.abs(basis).max()
        found |= {
            s.name for s in d.shafts if np.abs(held[bodies.index(s.name)]).max() > 1e-9 * scale
        }
    return tuple(s.name for s in d.shafts if s.name in found)


def gear_speeds(d: GearboxDescription, gear: str) -> dict[str, float]:
    """Every body's speed in a gear per unit output speed (Table 2.1). Speeds a gear leaves
    undetermined (idle shafts) are those of the least-norm motion; :func:`gear_ratio` and
    :func:`power_on_slip_signs` use only determined ones and check that they are."""
    closed = d.gear(gear).closed
    bodies = body_names(d)
    a = _constraints(d, closed)
    out = np.zeros(len(bodies))
    out[bodies.index(d.output_shaft)] = 1.0
    system = np.vstack([a, out])
    rhs = np.zeros(system.shape[0])
    rhs[-1] = 1.0
    omega, *_ = np.linalg.lstsq(system, rhs, rcond=None)
    if np.abs(system @ omega - rhs).max() > 1e-9:
        raise ValueError(f"gear {gear!r}: the output cannot turn")
    return dict(zip(bodies, omega, strict=True))


def _determined(d: GearboxDescription, gear: str, row: np.ndarray) -> bool:
    """Whether ``row`` · ω is fixed by the gear and the output speed (no idle motion moves it)."""
    bodies = body_names(d)
    out = np.zeros(len(bodies))
    out[bodies.index(d.output_shaft)] = 1.0
    free = _null_space(np.vstack([_constraints(d, d.gear(gear).closed), out]))
    return bool(np.all(np.abs(row @ free) < 1e-9 * max(np.abs(row).max(), 1.0)))


def gear_ratio(d: GearboxDescription, gear: str) -> float:
    """ω_in / ω_out of a drivable gear (Table 2.1)."""
    bodies = body_names(d)
    row = np.zeros(len(bodies))
    row[bodies.index(d.input_shaft)] = 1.0
    if not _determined(d, gear, row):
        raise ValueError(f"gear {gear!r}: the input speed is not fixed by the output's")
    return float(gear_speeds(d, gear)[d.input_shaft])


def adjacent_shifts(d: GearboxDescription) -> list[tuple[str, str]]:
    """(from, to) of the shifts between forward gears adjacent by ratio (Table 2.1), largest
    ratio first (equal ratios: the larger name first)."""
    forward = []
    for g in d.gears:
        if g.neutral:
            continue
        ratio = gear_ratio(d, g.name)
        if ratio > 0:
            forward.append((round(ratio, 12), g.name))
    forward.sort(reverse=True)
    return [(a, b) for (_, a), (_, b) in zip(forward, forward[1:], strict=False)]


def shift_elements(
    d: GearboxDescription, from_gear: str, to_gear: str
) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
    """(locked, off-going, on-coming) of a shift (3.1): the elements both gears close stay
    locked, in the from-gear's order; the others swap."""
    closed_from, closed_to = d.gear(from_gear).closed, d.gear(to_gear).closed
    return (
        tuple(e for e in closed_from if e in closed_to),
        tuple(e for e in closed_from if e not in closed_to),
        tuple(e for e in closed_to if e not in closed_from),
    )


def _slip_in_gear(d: GearboxDescription, gear: str, element: str) -> float:
    bodies = body_names(d)
    index = {b: i for i, b in enumerate(bodies)}
    row = _slip_row(d.element(element), index)
    if not _determined(d, gear, row):
        raise ValueError(f"the slip of {element!r} is not fixed in gear {gear!r}")
    speeds = gear_speeds(d, gear)
    return float(row @ np.array([speeds[b] for b in bodies]))


def power_on_slip_signs(d: GearboxDescription, from_gear: str, to_gear: str) -> dict[str, int]:
    """Slip signs of the two swapping elements of a single-swap power-on shift (3.1), so the
    sign k_sign of their friction torque (2.70): the on-coming element slips as the from-gear
    makes it slip; the off-going element against the to-gear in an upshift (the input flares
    in the torque phase), with it in a downshift."""
    _, (off,), (on,) = shift_elements(d, from_gear, to_gear)
    upshift = gear_ratio(d, to_gear) < gear_ratio(d, from_gear)
    off_to = int(np.sign(_slip_in_gear(d, to_gear, off)))
    return {on: int(np.sign(_slip_in_gear(d, from_gear, on))), off: -off_to if upshift else off_to}


def friction_torque(element: ShiftElement, mu: float, normal_force: float, sign: int) -> float:
    """Sliding torque T = k_sign 2 N_disc r_m μ F_N of a friction element (2.69, 3.14)."""
    if element.n_disc is None or element.r_m is None:
        raise ValueError(f"element {element.name!r} has no friction data (n_disc, r_m)")
    return sign * 2.0 * element.n_disc * element.r_m.value * mu * normal_force


def _value(d: GearboxDescription, key: str) -> float:
    """A number of the description's drivetrain or vehicle section."""
    for section in (d.drivetrain, d.vehicle):
        if key in section:
            return float(section[key].value)
    raise KeyError(f"{d.file}: {key} is in neither [drivetrain] nor [vehicle]")


@dataclass(frozen=True)
class NumpyModel:
    """Gearbox + elastic drivetrain with some elements locked: ẋ = f(x, T) in NumPy, with
    x = [ω of the ``keep`` shafts, φ, ω_C] (2.42–2.58)."""

    description: GearboxDescription
    locked: tuple[str, ...]
    keep: tuple[str, ...]
    bodies: tuple[str, ...]
    #: ω = J z: every body's speed per unit speed of each kept shaft (2.31).
    speed_map: np.ndarray
    #: M = Σ Jᵀ diag(I) J over the bodies (2.34), in the kept speeds.
    mass_matrix: np.ndarray
    idle: tuple[str, ...]
    orbital: bool

    def body_speeds(self, z: Sequence[float]) -> dict[str, float]:
        """Every body's speed at the kept shafts' speeds ``z``."""
        return dict(zip(self.bodies, self.speed_map @ np.asarray(z, dtype=float), strict=True))

    def kinetic_energy(self, z: Sequence[float]) -> float:
        """½ zᵀ M z of the gearbox (with J_cs, J_D on the output shaft)."""
        v = np.asarray(z, dtype=float)
        return float(0.5 * v @ self.mass_matrix @ v)

    def rhs(
        self,
        x: Sequence[float],
        input_torque: float,
        element_torques: Mapping[str, float],
        parameters: Mapping[str, float],
    ) -> np.ndarray:
        """ẋ at the state ``x``, the input torque T_In and the torques of the elements that
        act as inputs (+T on shaft b, −T on shaft a, 2.36; every other unlocked element is
        open, 2.54); ``parameters`` by name (m_veh, k_ss, d_ss, ζ, I_wheel, ρ, c_W, A, the
        rolling-resistance coefficients), the description's value for any not given."""
        d = self.description
        n = len(self.keep)
        x = np.asarray(x, dtype=float)
        z, phi, omega_c = x[:n], x[n], x[n + 1]

        def p(key: str) -> float:
            return float(parameters[key]) if key in parameters else _value(d, key)

        index = {b: i for i, b in enumerate(self.bodies)}
        omega = self.speed_map @ z
        i_d, r_dyn, g = _value(d, "i_D"), _value(d, "r_dyn"), _value(d, "g")
        phi_dot = omega[index[d.output_shaft]] / i_d - omega_c  # (2.44)
        t_ss = p("k_ss") * phi + p("d_ss") * phi_dot  # (2.47)
        torque = np.zeros(len(self.bodies))
        torque[index[d.input_shaft]] += input_torque
        torque[index[d.output_shaft]] -= 2.0 * t_ss / i_d  # T_out (2.52)
        elements = {e.name: e for e in d.shift_elements}
        for name, t in element_torques.items():
            if name in self.locked:
                raise ValueError(f"element {name!r} is locked in this model, not a torque")
            e = elements[name]
            torque[index[e.b]] += t
            if e.a is not None:
                torque[index[e.a]] -= t
        drag = d.drivetrain["idle_drag"].value if "idle_drag" in d.drivetrain else IDLE_DRAG_DEFAULT
        for shaft in self.idle:
            torque[index[shaft]] -= drag * omega[index[shaft]]  # −d ω to the housing
        generalized = self.speed_map.T @ torque  # virtual power (2.35)
        z_dot = np.linalg.solve(self.mass_matrix, generalized)  # (2.40), (2.41)
        v = r_dyn * omega_c
        m_veh, zeta = p("m_veh"), p("zeta")
        if d.rolling_resistance == "thesis":
            f_r = v * p("f_roll") * np.cos(zeta) * m_veh * g  # (2.49a) as printed
        elif d.rolling_resistance == "textbook":
            f_r = p("f_R") * np.cos(zeta) * m_veh * g
        else:
            f_r = (p("f_R0") + p("f_R1") * v + p("f_R2") * v**2) * np.cos(zeta) * m_veh * g
        f_ad = 0.5 * p("rho_air") * p("c_W") * p("A_front") * v**2  # (2.49b)
        f_g = m_veh * g * np.sin(zeta)  # (2.49c)
        t_res = r_dyn * (f_r + f_ad + f_g)  # (2.48)
        wheel = (2.0 * t_ss - t_res) / (p("I_wheel") + m_veh * r_dyn**2)  # (2.45), (2.46)
        return np.concatenate([z_dot, [phi_dot, wheel]])


def numpy_model(
    d: GearboxDescription, locked: Sequence[str], keep: Sequence[str], *, orbital: bool = True
) -> NumpyModel:
    """The model with ``locked`` elements as constraints and the speeds of the ``keep``
    shafts as its gearbox states (a gear: its closed elements and the output shaft; a shift:
    the elements both gears close (2.55); the full model (2.53): nothing, the coordinates).

    ``orbital=False`` leaves the planets' orbit ½ n m_p r_p² ω_C² out of the kinetic energy:
    a deliberately wrong mass matrix, to show that a comparison with it fails."""
    bodies = body_names(d)
    index = {b: i for i, b in enumerate(bodies)}
    locked, keep = tuple(locked), tuple(keep)
    selection = np.zeros((len(keep), len(bodies)))
    for k, shaft in enumerate(keep):
        selection[k, index[shaft]] = 1.0
    system = np.vstack([_constraints(d, locked), selection])
    if system.shape[0] != system.shape[1] or np.linalg.matrix_rank(system) < len(bodies):
        raise ValueError(
            f"with {', '.join(locked) or 'nothing'} locked, the speeds of {', '.join(keep)} "
            "do not determine every body's speed"
        )
    rhs = np.zeros((len(bodies), len(keep)))
    rhs[len(bodies) - len(keep) :, :] = np.eye(len(keep))
    jac = np.linalg.solve(system, rhs)  # ω = J z (2.31)

    def row(body: str) -> np.ndarray:
        return jac[index[body]] if body != HOUSING else np.zeros(len(keep))

    mass = np.zeros((len(keep), len(keep)))
    extra = _value(d, "J_cs") + _value(d, "J_D") / _value(d, "i_D") ** 2  # (2.51) corrected
    for s in d.shafts:
        inertia = s.inertia.value + (extra if s.name == d.output_shaft else 0.0)
        mass += inertia * np.outer(row(s.name), row(s.name))
    for ps in d.planetary_sets:
        n = ps.planet_count
        for pinion in _pinions(ps):
            first = pinion == ps.planet
            spin = ps.planet_inertia if first else ps.planet2_inertia
            mass_p = ps.planet_mass if first else ps.planet2_mass
            radius = ps.carrier_radius if first else ps.planet2_radius
            assert spin is not None and mass_p is not None and radius is not None
            mass += n * spin.value * np.outer(row(pinion), row(pinion))  # spin ½ n J_p ω_p²
            if orbital:  # orbit ½ n m_p (r_p ω_C)²: the centre moves with the carrier
                mass += (
                    n * mass_p.value * radius.value**2 * np.outer(row(ps.carrier), row(ps.carrier))
                )
        for role, q in ps.reflected_inertia:  # planet_inertia_reflected of a k set
            member = getattr(ps, role)
            mass += q.value * np.outer(row(member), row(member))
    return NumpyModel(
        description=d,
        locked=locked,
        keep=keep,
        bodies=bodies,
        speed_map=jac,
        mass_matrix=mass,
        idle=idle_shafts(d),
        orbital=orbital,
    )
