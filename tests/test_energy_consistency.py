"""M and B̃ agree with kinetic energy and power computed independently (NumPy, no SymPy).

For random generalized speeds ẏ, every body speed is obtained by solving the Willis
constraints (2.22)–(2.23) with NumPy; the kinetic energy Σ ½ I ω² + ½ m v² must equal
½ ẏᵀ M ẏ, and the power of the applied torques Σ lᵉ·ω must equal uᵀ B̃ᵀ ẏ (virtual work, 2.15).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.loader import load_description

DATA = Path(__file__).parent / "data"


def body_speeds(d, ydot: np.ndarray) -> dict[str, float]:
    bodies = list(d.body_names)
    index = {b: i for i, b in enumerate(bodies)}
    rows, rhs = [], []
    for ps in d.planetary_sets:
        r1 = np.zeros(len(bodies))
        r1[index[ps.sun]] += ps.z_sun
        r1[index[ps.carrier]] -= ps.z_sun + ps.z_planet
        r1[index[ps.planet]] += ps.z_planet
        r2 = np.zeros(len(bodies))
        r2[index[ps.ring]] += ps.z_ring
        r2[index[ps.carrier]] -= ps.z_ring - ps.z_planet
        r2[index[ps.planet]] -= ps.z_planet
        rows += [r1, r2]
        rhs += [0.0, 0.0]
    for c, v in zip(d.coordinates, ydot, strict=True):
        r = np.zeros(len(bodies))
        r[index[c]] = 1
        rows.append(r)
        rhs.append(v)
    omega = np.linalg.solve(np.array(rows), np.array(rhs))
    return dict(zip(bodies, omega, strict=True))


@pytest.mark.parametrize("config", [None, DATA / "simpson_3speed.toml"])
def test_kinetic_energy_and_power(config):
    d = load_description(config)
    dyn = gearbox_dynamics(d)
    m = np.array(dyn.mass_matrix.evalf(), dtype=float)
    b = np.array(dyn.input_matrix.evalf(), dtype=float)
    rng = np.random.default_rng(7)
    for _ in range(20):
        ydot = rng.normal(size=len(d.coordinates)) * 100
        u = rng.normal(size=b.shape[1]) * 50
        w = body_speeds(d, ydot)
        energy = sum(0.5 * s.inertia.value * w[s.name] ** 2 for s in d.shafts)
        for ps in d.planetary_sets:
            n = ps.planet_count
            energy += 0.5 * n * ps.planet_inertia.value * w[ps.planet] ** 2
            energy += (
                0.5 * n * ps.planet_mass.value * (ps.carrier_radius.value * w[ps.carrier]) ** 2
            )
        assert 0.5 * ydot @ m @ ydot == pytest.approx(energy, rel=1e-12)
        # Power of the applied torques (2.36): T_In on the input, -T_Out on the output,
        # +T on shaft b and -T on shaft a of every element.
        power = u[0] * w[d.input_shaft] - u[1] * w[d.output_shaft]
        for col, e in enumerate(d.shift_elements, start=2):
            power += u[col] * (w[e.b] - (w[e.a] if e.a is not None else 0.0))
        assert u @ b.T @ ydot == pytest.approx(power, rel=1e-10, abs=1e-9)
