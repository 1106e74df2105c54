"""Stage 3: rigid gearbox dynamics by Newton–Euler / d'Alembert (thesis 2.33–2.41).

The constraints are linear and scleronomic, so the Jacobians are constant, the local
accelerations and gyroscopic terms vanish (k = 0 in 2.19), and the equations of motion reduce
to M ÿ = q with

    M  = J_Tᵀ diag(m) J_T + J_Rᵀ diag(I) J_R        (2.34)
    q  = J_Rᵀ lᵉ = J_Rᵀ E u = B̃ u                   (2.35, 2.36, 2.39)
    ẋ  = M⁻¹ B̃ u = B u,   x = ẏ                      (2.40, 2.41)

where lᵉ = E u distributes the input vector u = [T_In, T_Out, T_<element>…] (2.38) over the
bodies: T_In on the input shaft, −T_Out on the output shaft, and for an element +T on shaft b,
−T on shaft a (2.36).
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.kinematics import GearboxSymbols, Kinematics, gearbox_symbols, kinematics


def mass_matrix(d: GearboxDescription, sym: GearboxSymbols, kin: Kinematics) -> sp.Matrix:
    """M = J_Tᵀ diag(m) J_T + J_Rᵀ diag(I) J_R (2.34), summed body by body."""
    f = len(kin.coordinates)
    m = sp.zeros(f, f)
    for i, body in enumerate(kin.bodies):
        row = kin.rotation_jacobian[i, :]
        if any(entry != 0 for entry in row):
            m += sym.inertia[body] * (row.T * row)
    # Every pinion body also orbits with its carrier: m r² ω_C² (2.27, 2.30).
    for i, body in enumerate(kin.bodies):
        if body in sym.pinion_mass:
            row = kin.translation_jacobian[i, :]
            m += sym.pinion_mass[body] * (row.T * row)
    # A set given by k: its planets as inertias reflected to its members, the same rotation
    # term J ω_member² on the member's row of J_R (planet_inertia_reflected).
    index = {b: i for i, b in enumerate(kin.bodies)}
    for members in sym.reflected.values():
        for shaft, inertia in members.items():
            row = kin.rotation_jacobian[index[shaft], :]
            m += inertia * (row.T * row)
    return m


def torque_inputs(d: GearboxDescription, sym: GearboxSymbols) -> sp.Matrix:
    """u = [T_In, T_Out, T_<element> in file order] (2.38)."""
    return sp.Matrix(
        [sym.torque["In"], sym.torque["Out"]] + [sym.torque[e.name] for e in d.shift_elements]
    )


def torque_distribution(d: GearboxDescription) -> sp.Matrix:
    """E with lᵉ = E·u (2.36): which body each input torque acts on, and with which sign."""
    index = {b: i for i, b in enumerate(d.body_names)}
    e = sp.zeros(len(index), 2 + len(d.shift_elements))
    e[index[d.input_shaft], 0] = 1
    e[index[d.output_shaft], 1] = -1
    for col, element in enumerate(d.shift_elements, start=2):
        e[index[element.b], col] += 1
        if element.a is not None:
            e[index[element.a], col] -= 1
    return e


@dataclass(frozen=True)
class GearboxDynamics:
    """M ÿ = B̃ u for the free gearbox (all shift elements as torques)."""

    description: GearboxDescription
    symbols: GearboxSymbols
    kinematics: Kinematics
    mass_matrix: sp.Matrix
    torque_distribution: sp.Matrix
    inputs: sp.Matrix
    input_matrix: sp.Matrix

    @property
    def generalized_forces(self) -> sp.Matrix:
        """q = J_Rᵀ lᵉ = B̃ u (2.35)."""
        return self.input_matrix * self.inputs

    @property
    def speeds(self) -> sp.Matrix:
        """x = ẏ (2.40)."""
        return sp.Matrix([self.symbols.speed[c] for c in self.kinematics.coordinates])

    def state_input_matrix(self) -> sp.Matrix:
        """B = M⁻¹ B̃ of ẋ = B u (2.41). Expensive when the inertias are symbols."""
        return self.mass_matrix.LUsolve(self.input_matrix)


#: The dynamics last derived, by description object and options: `gearsym generate` derives 19
#: drivetrain models of one gearbox, each from the same free gearbox (0.3 s of repeats). The
#: description object is kept with its entry, so its id cannot be reused meanwhile.
_DERIVED: dict[tuple[int, bool, bool], tuple[GearboxDescription, GearboxDynamics]] = {}


def gearbox_dynamics(
    d: GearboxDescription, symbolic_teeth: bool = False, symbolic_inertias: bool = False
) -> GearboxDynamics:
    """Derive kinematics, mass matrix and input matrix of the free gearbox (2.26–2.39).

    Remembered per description object (descriptions are immutable; callers build new matrices
    from the result and never assign into it)."""
    key = (id(d), symbolic_teeth, symbolic_inertias)
    derived = _DERIVED.get(key)
    if derived is not None and derived[0] is d:
        return derived[1]
    if len(_DERIVED) >= 8:
        _DERIVED.clear()
    result = _derive(d, symbolic_teeth, symbolic_inertias)
    _DERIVED[key] = (d, result)
    return result


def _derive(
    d: GearboxDescription, symbolic_teeth: bool, symbolic_inertias: bool
) -> GearboxDynamics:
    sym = gearbox_symbols(d, symbolic_teeth=symbolic_teeth, symbolic_inertias=symbolic_inertias)
    kin = kinematics(d, sym)
    m = mass_matrix(d, sym, kin)
    e = torque_distribution(d)
    b_tilde = kin.rotation_jacobian.T * e
    return GearboxDynamics(
        description=d,
        symbols=sym,
        kinematics=kin,
        mass_matrix=m,
        torque_distribution=e,
        inputs=torque_inputs(d, sym),
        input_matrix=b_tilde,
    )
