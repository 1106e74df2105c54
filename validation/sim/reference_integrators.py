"""The integration loops of the reference simulation: CVODES (default) or SciPy's Radau / BDF,
restarting at every breakpoint of the scenario's piecewise-linear inputs, with the per-state
absolute tolerances."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.numeric import bilinear
from gearsym.validation.sim.reference_functions import CompiledReference, ReferenceInputs
from scipy.integrate import solve_ivp

#: Progress callback: (fraction done in [0, 1], message).
Progress = Callable[[float, str], None]


def integrate_scipy(
    compiled: CompiledReference,
    inputs: ReferenceInputs,
    y0: np.ndarray,
    grid: np.ndarray,
    breakpoints: Sequence[float],
    rtol: float,
    atol: np.ndarray,
    method: str,
    analytic_jacobian: bool,
    report: Progress,
) -> tuple[np.ndarray, dict[str, float]]:
    """SciPy's Radau or BDF, segment by segment; the states at ``grid`` from its dense output."""
    n = compiled.n
    t_end = breakpoints[-1]

    def fun(t: float, y: np.ndarray) -> np.ndarray:
        return compiled.f(y[:n], inputs(t, y[:n]))

    def jac(t: float, y: np.ndarray) -> np.ndarray:
        out = np.zeros((len(y), len(y)))
        out[:, :n] = compiled.jac(y[:n], inputs(t, y[:n]))
        return out

    y = y0
    states = np.zeros((len(grid), len(y0)))
    states[0] = y0
    stats = {"nfev": 0.0, "njev": 0.0, "nlu": 0.0, "steps": 0.0}
    for t0, t1 in zip(breakpoints[:-1], breakpoints[1:], strict=True):
        sol = solve_ivp(
            fun,
            (t0, t1),
            y,
            method=method,
            jac=jac if analytic_jacobian else None,
            rtol=rtol,
            atol=atol,
            dense_output=True,
        )
        if not sol.success:
            raise GearsymError(
                inputs.scenario.file,
                "scenario",
                f"integration failed at t = {sol.t[-1]:.6g} s: {sol.message}",
            )
        inside = (grid > t0) & (grid <= t1)
        states[inside] = np.asarray(sol.sol(grid[inside])).T
        stats["nfev"] += sol.nfev
        stats["njev"] += sol.njev
        stats["nlu"] += sol.nlu
        stats["steps"] += len(sol.t) - 1
        y = sol.y[:, -1]
        report(t1 / t_end, f"t = {t1:.3f} s of {t_end:g} s")
    return states, stats


def integrate_cvodes(
    compiled: CompiledReference,
    inputs: ReferenceInputs,
    y0: np.ndarray,
    grid: np.ndarray,
    breakpoints: Sequence[float],
    rtol: float,
    atol: np.ndarray,
    report: Progress,
) -> tuple[np.ndarray, dict[str, float]]:
    """CVODES (BDF, CasADi's exact Jacobian) segment by segment. Inside a segment every
    scenario input is linear in time, so T_In, the pressures and ζ enter as a + b (t − t0) with
    (a, b) per segment, and μ as the μ map's bilinear interpolation at the pressure and the
    current |slip| (as :class:`~gearsym.validation.sim.reference_functions.ReferenceInputs`).
    The states are scaled by atol/rtol so that one scalar tolerance means the per-state
    ``atol``."""
    import casadi as ca

    n, ne = compiled.n, len(compiled.elements)
    size = len(y0)
    scale = atol / rtol
    xi = ca.SX.sym("xi", size)
    t = ca.SX.sym("t")
    nd = 2 + ne  # T_In, the pressures, ζ
    coefficients = ca.SX.sym("c", 2 * nd + 1)  # a (nd), b (nd), t0
    a, b, t0 = coefficients[:nd], coefficients[nd : 2 * nd], coefficients[-1]
    driven = a + b * (t - t0)  # T_In, the pressures and ζ
    x = xi[:n] * scale[:n]
    slip = ca.substitute(compiled.slips_sx, compiled.x, x)
    p_grid, dw_grid = inputs.map_grid
    mu = [
        bilinear(driven[1 + k], ca.fabs(slip[k]), p_grid, dw_grid, inputs.map_plane)
        * float(inputs.mu_scale[k])
        for k in range(ne)
    ]
    u = ca.vertcat(driven[: 1 + ne], *mu, driven[1 + ne])
    rhs = ca.substitute(compiled.rhs_sx, ca.vertcat(compiled.x, compiled.u), ca.vertcat(x, u))
    dae = {"x": xi, "t": t, "p": coefficients, "ode": rhs / scale}
    options = {"abstol": rtol, "reltol": rtol, "max_num_steps": 200000}
    states = np.zeros((len(grid), size))
    states[0] = y0
    y = y0 / scale
    stats = {"nfev": 0.0, "steps": 0.0}
    t_end = breakpoints[-1]
    scenario = inputs.scenario
    for ta, tb in zip(breakpoints[:-1], breakpoints[1:], strict=True):
        inside = np.flatnonzero((grid > ta) & (grid <= tb))
        tout = [float(v) for v in grid[inside]]
        if not tout or tout[-1] < tb:
            tout.append(float(tb))
        ua = np.array([scenario.input_torque(ta), *inputs.pressures(ta), inputs.grade(ta)])
        ub = np.array([scenario.input_torque(tb), *inputs.pressures(tb), inputs.grade(tb)])
        c = np.concatenate([ua, (ub - ua) / (tb - ta), [ta]])
        step = ca.integrator("segment", "cvodes", dae, float(ta), tout, options)
        try:
            out = np.asarray(step(x0=y, p=c)["xf"].full())
        except RuntimeError as err:
            raise GearsymError(
                scenario.file, "scenario", f"integration failed in [{ta:.6g}, {tb:.6g}] s: {err}"
            ) from None
        states[inside] = (out[:, : len(inside)] * scale[:, None]).T
        y = out[:, -1]
        solver_stats = step.stats()
        stats["nfev"] += float(solver_stats.get("nfevals", 0))
        stats["steps"] += float(solver_stats.get("nsteps", 0))
        report(tb / t_end, f"t = {tb:.3f} s of {t_end:g} s")
    return states, stats


def absolute_tolerances(names: Sequence[str], rtol: float, x0: np.ndarray) -> np.ndarray:
    """Per-state absolute tolerances of the states ``names`` and the works that follow them:
    ``rtol`` times each state's scale."""
    # Per-state scales: speeds ~ 100 rad/s, twist ~ 1e-2 rad, bristles ~ 1e-4 rad, works ~ 1e3 J.
    scale = []
    for name in names:
        if name.startswith("z_"):
            scale.append(1e-6)
        elif name == "phi":
            scale.append(1e-3)
        else:
            scale.append(1.0)
    scale += [1.0] * len(naming.ENERGY_TERMS)
    return rtol * np.array(scale)
