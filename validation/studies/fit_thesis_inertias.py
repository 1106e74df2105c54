"""How the default inertias of the built-in gearbox were chosen (the thesis lists none).

The printed 2↔3 matrices (5.4), (5.5) and the μ38 term (3.15) fix the reduced inverse mass
matrix of that shift model, M_r⁻¹ = [[a, b], [b, c]] over z = [ω1, ω2]: with the tooth counts
known, every printed entry of rows 1–2 is linear in (a, b, c). (3.15) is ∂f/∂μ38 per
N_disc r_m F_N38, i.e. twice the K38 column of (5.5) as printed (T = 2 N_disc r_m μ F_N, (3.14)),
but printed to one more digit: it narrows the K38 column's interval to a quarter of (5.5)'s.

Step 1 finds the (a, b, c) that lies deepest inside every printed entry's rounding interval (a
small linear programme). Step 2 moves the built-in description's inertias as little as possible
(the smallest sum of relative changes, a second linear programme, so at most three values move),
each within a plausible range, such that Pᵀ M P = [[a, b], [b, c]]⁻¹ exactly. The result is
printed as TOML values for ``gearsym/data/thesis_9speed.toml`` (six significant digits) and
checked again after that rounding.

Two columns of (5.5) — T_K38 and T_B05 — are printed with the opposite sign of the (2.36)
convention (the thesis counts those torques positive in the direction they act during the
power-on upshift); the comparison flips them. (3.15) is printed in the thesis' sign of (5.5).
Run: ``python validation/studies/fit_thesis_inertias.py``.
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from gearsym.symbolic.drivetrain import locked_projection
from gearsym.symbolic.dynamics import GearboxDynamics, gearbox_dynamics
from gearsym.symbolic.kinematics import exact
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from scipy.optimize import linprog

#: Printed rows 1–2 of (5.4) (coefficients of d_ss ω2, k_ss φ, d_ss ω_C) and (5.5)
#: (T_In, T_K38, T_B05), with the number of printed decimals.
PRINTED_A = [[(-0.799, 3), (-1.97, 2), (1.97, 2)], [(-0.248, 3), (-0.612, 3), (0.612, 3)]]
PRINTED_B = [[(10.7, 1), (-2.79, 2), (-17.0, 1)], [(2.44, 2), (0.0135, 4), (-2.41, 2)]]
#: (5.5) sign of each column relative to the (2.36) convention.
B_COLUMN_SIGN = [1, -1, -1]
#: Printed rows 1–2 of (3.15) per N_disc,38 r_m,38 F_N38: 2 × the K38 column of (5.5) as printed.
PRINTED_3_15 = [(-5.58, 2), (0.0270, 4)]

#: Plausible ranges (kg·m²) and prior guesses for each free inertia.
RANGES = {
    "J_1": (0.02, 0.30, 0.08),
    "J_2": (0.01, 0.10, 0.03),
    "J_3": (0.005, 0.10, 0.02),
    "J_4": (0.005, 0.08, 0.025),
    "J_5": (0.002, 0.06, 0.01),
    "J_6": (0.005, 0.08, 0.03),
    "J_7": (0.005, 0.15, 0.03),
    "J_8": (0.005, 0.08, 0.02),
    "J_9": (4 * 5e-5, 4 * 1e-3, 4 * 1.6e-4),
    "J_10": (4 * 5e-5, 4 * 1e-2, 4 * 2.0e-4),
    "J_11": (4 * 5e-5, 4 * 1e-3, 4 * 2.2e-4),
    "J_12": (4 * 5e-5, 4 * 1e-3, 4 * 2.2e-4),
}


def coefficient_rows(
    dyn: GearboxDynamics, projection: sp.Matrix, i_d: sp.Expr
) -> list[tuple[np.ndarray, float, float]]:
    """Printed entries of (5.4), (5.5) and (3.15) rows 1–2 as linear functions of (a, b, c).

    Returns a list of (row vector, printed value, half width of its rounding interval).
    """
    rows = []
    column = {str(s): i for i, s in enumerate(dyn.inputs)}
    pt_b = projection.T * dyn.input_matrix
    two_over = 2 / i_d
    for r in range(2):
        # A: −(M_r⁻¹ Pᵀ e_out) scaled: ω̇_r = −[b, c]_r · T_out with T_out = 2 T_ss / i_D.
        out = pt_b[:, column["T_Out"]]  # = Pᵀ(−e_out), so ω̇ = M_r⁻¹ out · T_out
        for (value, decimals), scale in zip(
            PRINTED_A[r], (two_over / i_d, two_over, -two_over), strict=True
        ):
            vec = _inverse_row(r, out) * float(scale)
            rows.append((vec, value, 0.5 * 10.0**-decimals))
        for k, name in enumerate(("T_In", "T_K38", "T_B05")):
            vec = _inverse_row(r, pt_b[:, column[name]]) * B_COLUMN_SIGN[k]
            value, decimals = PRINTED_B[r][k]
            rows.append((vec, value, 0.5 * 10.0**-decimals))
        # (3.15): ∂f_r/∂μ38 = 2 × (5.5)'s K38 entry, k_sign and N_disc r_m F_N38 divided out.
        vec = _inverse_row(r, pt_b[:, column["T_K38"]]) * (2 * B_COLUMN_SIGN[1])
        value, decimals = PRINTED_3_15[r]
        rows.append((vec, value, 0.5 * 10.0**-decimals))
    return rows


def _inverse_row(r: int, vector: sp.Matrix) -> np.ndarray:
    """Coefficients of (a, b, c) in row r of [[a, b], [b, c]]·vector."""
    v0, v1 = float(vector[0]), float(vector[1])
    return np.array([v0, v1, 0.0]) if r == 0 else np.array([0.0, v0, v1])


def main() -> None:
    d = load_description()
    dyn = gearbox_dynamics(d, symbolic_inertias=True)
    spec = shift_spec(d, "2-3")
    projection = locked_projection(d, dyn, spec.locked, (d.input_shaft, d.output_shaft))
    i_d = exact(d.drivetrain["i_D"].value)
    rows = coefficient_rows(dyn, projection, i_d)

    # Step 1: maximise the margin t: |row·abc − value| ≤ (1 − t)·half_width for every entry.
    a_ub, b_ub = [], []
    for vec, value, hw in rows:
        a_ub.append([*vec, hw])
        b_ub.append(value + hw)
        a_ub.append([*(-vec), hw])
        b_ub.append(-value + hw)
    lp = linprog([0, 0, 0, -1], A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * 3 + [(0, 1)])
    a, b, c, margin = lp.x
    print(f"M_r^-1 = [[{a:.6f}, {b:.6f}], [{b:.6f}, {c:.6f}]], margin {margin:.2f}")
    target = np.linalg.inv(np.array([[a, b], [b, c]]))

    # Step 2: inertias with Pᵀ M P = target; M_r is linear in the inertias. Smallest sum of
    # relative changes from the built-in values: Δ = δ⁺ − δ⁻, minimise Σ (δ⁺ + δ⁻)/J₀.
    index = {b_: i for i, b_ in enumerate(d.body_names)}
    out_row = dyn.kinematics.transform[index[d.output_shaft], :]
    j_extra = exact(d.drivetrain["J_cs"].value) + exact(d.drivetrain["J_D"].value) / i_d**2
    mass = dyn.mass_matrix + j_extra * (out_row.T * out_row)
    reduced = (projection.T * mass * projection).applyfunc(sp.expand)
    names = list(RANGES)
    symbols = [sp.Symbol(n, positive=True) for n in names]
    values = {str(s): v for s, v in dyn.symbols.values.items()}
    fixed = {s: v for s, v in dyn.symbols.values.items() if str(s) not in RANGES}
    entries = [reduced[0, 0], reduced[0, 1], reduced[1, 1]]
    eq_a = np.array([[float(sp.diff(e, s)) for s in symbols] for e in entries])
    eq_b = np.array(
        [
            t - float(e.subs({s: 0 for s in symbols}).subs(fixed))
            for e, t in zip(entries, (target[0, 0], target[0, 1], target[1, 1]), strict=True)
        ]
    )
    current = np.array([float(values[n]) for n in names])
    n = len(names)
    step = linprog(
        np.concatenate([1 / current, 1 / current]),
        A_eq=np.hstack([eq_a, -eq_a]),
        b_eq=eq_b - eq_a @ current,
        bounds=[(0, RANGES[m][1] - c) for m, c in zip(names, current, strict=True)]
        + [(0, c - RANGES[m][0]) for m, c in zip(names, current, strict=True)],
    )
    fitted = current + step.x[:n] - step.x[n:]
    print("residual of the three equations:", eq_a @ fitted - eq_b)
    planets = {s.planet: s.planet_count for s in d.planetary_sets}
    rounded = {}
    for name, old, new in zip(names, current, fitted, strict=True):
        body = name.removeprefix("J_")
        per = planets.get(body, 1)  # a planet body is planet_count planets
        printed = float(f"{new / per:.6g}")
        rounded[sp.Symbol(name, positive=True)] = printed * per
        what = "planet_inertia (per planet)" if body in planets else "inertia"
        change = "unchanged" if f"{old / per:.6g}" == f"{printed:.6g}" else f"was {old / per:.6g}"
        print(f"body {body}: {what} = {printed:.6g}  ({change})")
    # The printed entries again, with the TOML values as rounded above.
    inverse = np.linalg.inv(np.array(reduced.subs(fixed).subs(rounded).evalf(), dtype=float))
    abc = np.array([inverse[0, 0], inverse[0, 1], inverse[1, 1]])
    worst = max(abs(vec @ abc - value) / hw for vec, value, hw in rows)
    print(f"rounded values: every printed entry inside its rounding, worst at {worst:.2f} of it")
    if worst > 1:
        raise SystemExit("the rounded inertias leave a printed entry's rounding interval")


if __name__ == "__main__":
    main()
