"""Derivation time of the full 4-DOF gearbox model (kinematics, M, B̃, B).

Targets (issue 2): numeric teeth with symbolic inertias under 2 s; everything symbolic under
10 s. The peer, measured in the same run, is the textbook route: solve all Willis constraints
at once with ``sympy.linsolve``, take ``Matrix.jacobian`` and form J_Rᵀ diag(I) J_R + J_Tᵀ diag(m)
J_T by full matrix products.
"""

from __future__ import annotations

import statistics
import sys
import time

import sympy as sp
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.kinematics import gearbox_symbols, willis_constraints
from gearsym.symbolic.loader import load_description
from record import Target, begin, record, row


def ours(d, symbolic_teeth: bool):
    dyn = gearbox_dynamics(d, symbolic_teeth=symbolic_teeth, symbolic_inertias=True)
    dyn.state_input_matrix()
    return dyn.mass_matrix


def peer(d, symbolic_teeth: bool):
    sym = gearbox_symbols(d, symbolic_teeth=symbolic_teeth, symbolic_inertias=True)
    g = willis_constraints(d, sym)
    phi = [sym.angle[b] for b in d.body_names]
    unknown = [sym.angle[b] for b in d.body_names if b not in d.coordinates]
    (solution,) = sp.linsolve(list(g * sp.Matrix(phi)), unknown)
    s = sp.Matrix([dict(zip(unknown, solution, strict=True)).get(p, p) for p in phi])
    y = [sym.angle[c] for c in d.coordinates]
    j_r = s.jacobian(y)
    index = {b: i for i, b in enumerate(d.body_names)}
    r = sp.zeros(len(phi), 1)
    for ps in d.planetary_sets:
        r[index[ps.planet]] = sym.carrier_radius[ps.name] * s[index[ps.carrier]]
    j_t = r.jacobian(y)
    inertia = sp.diag(*[sym.inertia[b] for b in d.body_names])
    masses = [0] * len(phi)
    for ps in d.planetary_sets:
        masses[index[ps.planet]] = sym.planet_mass[ps.name]
    m = (j_r.T * inertia * j_r + j_t.T * sp.diag(*masses) * j_t).applyfunc(sp.simplify)
    m.LUsolve(j_r.T)
    return m


def timed(fn, *args, repeat: int = 3) -> list[float]:
    """Seconds of ``repeat`` runs, SymPy's cache cleared before each."""
    times = []
    for _ in range(repeat):
        sp.core.cache.clear_cache()  # SymPy memoises; a warm cache would flatter repeat runs
        start = time.perf_counter()
        fn(*args)
        times.append(time.perf_counter() - start)
    return times


def main() -> int:
    started = begin()
    d = load_description()
    ok = True
    rows = []
    print("derivation of the full 4-DOF model (median of 3 runs)")
    for label, symbolic_teeth, target in (
        ("numeric teeth, symbolic inertias", False, 2.0),
        ("everything symbolic", True, 10.0),
    ):
        runs_ours = timed(ours, d, symbolic_teeth)
        runs_peer = timed(peer, d, symbolic_teeth, repeat=1)
        t_ours, t_peer = statistics.median(runs_ours), statistics.median(runs_peer)
        met = t_ours < target
        ok &= met
        print(
            f"  {label:<34} gearsym {t_ours:7.3f} s   textbook route {t_peer:7.3f} s   "
            f"ratio {t_peer / t_ours:6.1f}x   target < {target:g} s: {'met' if met else 'MISSED'}"
        )
        rows.append(
            row(
                f"derive the 4-DOF model (kinematics, M, B̃, B), {label}",
                unit="s",
                samples=runs_ours,
                peer="textbook `linsolve` + `jacobian` route",
                peer_samples=runs_peer,
                target=Target(f"< {target:g} s", "value", "<", target),
            )
        )
    record(__file__, rows, started=started, title="Derivation of the full 4-DOF model")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
