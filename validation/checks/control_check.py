"""``generate --check`` of the shift controller's model parts (``gearsym_control_<a>_<b>``):
the C double build, the C single build and the CasADi module against the SymPy expressions they
were printed from (:func:`gearsym.symbolic.codegen.control.control_expressions`), at random
points of the operating range, the vehicle's parameters at their defaults. The float build is
compared at the float-rounded arguments it sees. The phase logic is checked against the Python
controller on the closed loop (``tests/test_control_c.py``), not here. The reference is
evaluated in 30-digit arithmetic (mpmath): the sliding mode's slip acceleration subtracts nearly
equal shares (the input torque's, the road load's), which costs a double evaluation of the
expressions about 1e-12 on another gearbox.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic.codegen.control import CONTROL_ARGUMENTS, control_expressions
from gearsym.validation.checks import c_check
from gearsym.validation.checks.c_binding import load_casadi_module
from gearsym.validation.checks.control_c import CShiftController, build_control_library

__all__ = ["RANGES", "compare_control"]

#: Sampling range of each argument (SI units): speeds, torque, grade, forces, μ; the mass is
#: sampled within its prior's ±σ about the description's (:func:`_ranges`).
RANGES: dict[str, tuple[float, float]] = {
    "omega_in": (50.0, 400.0),
    "omega_out": (20.0, 150.0),
    "T_In": (20.0, 400.0),
    "zeta": (-0.1, 0.1),
    "F_last": (0.0, 1e4),
    "mu_last": (0.08, 0.16),
    "F_1": (1e3, 1e4),
    "mu_1": (0.08, 0.16),
}


def _conditioned(
    computed: dict[str, np.ndarray],
    exact: dict[str, np.ndarray],
    points: dict[str, np.ndarray],
    reference: Any,
    rng: np.random.Generator,
    n_perturbations: int = 8,
) -> dict[str, float]:
    """The float build's error allowing for each function's own conditioning, as
    :func:`gearsym.validation.checks.generated_check.conditioned_error` states it: the largest
    change of the exact reference when every argument moves by
    :data:`~gearsym.validation.checks.c_check.PERTURBATION_ULPS` float ulps (the sliding mode's
    slip acceleration subtracts the input torque's and the road load's nearly equal shares),
    and the error over max(the plain denominator, K times that spread / 1e-5)."""
    tolerance = c_check.TOLERANCE["single"]
    eps = c_check.PERTURBATION_ULPS * float(np.finfo(np.float32).eps)
    spread = {f: np.zeros_like(v) for f, v in exact.items()}
    for _ in range(n_perturbations):
        moved = {f: v * (1.0 + eps * rng.uniform(-1.0, 1.0, v.shape)) for f, v in points.items()}
        for f, v in reference(moved).items():
            spread[f] = np.fmax(spread[f], np.abs(v - exact[f]))
    out = {}
    for f, r in exact.items():
        magnitude = np.abs(r)
        denominator = np.maximum(magnitude, c_check.FLOOR["single"] * magnitude.max(axis=0))
        denominator = np.maximum(denominator, np.finfo(np.float64).tiny)
        denominator = np.maximum(denominator, c_check.CONDITIONED_FACTOR * spread[f] / tolerance)
        out[f] = float((np.abs(computed[f] - r) / denominator).max(initial=0.0))
    return out


def _ranges(d: Any) -> dict[str, tuple[float, float]]:
    """:data:`RANGES` and m_veh within the parameter record's prior σ of the description's."""
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.symbolic.parameters import record

    mass = quantity(d, "vehicle", "m_veh").value
    sigma = record("m_veh").prior_sigma
    assert sigma is not None, "m_veh's parameter record states its prior sigma"
    return {**RANGES, "m_veh": (mass * (1.0 - sigma), mass * (1.0 + sigma))}


def compare_control(
    d: Any, shift: str, root: Path, build_dir: Path, n_points: int = 1000, seed: int = 0
) -> list[c_check.ComparisonReport]:
    """C double, C single and CasADi of the controller's model parts against SymPy (module
    docstring), from the files under ``root`` (``c/`` and ``python/``)."""
    hybrid, fixed, exprs, args = control_expressions(d, shift)
    defaults = {v.symbol: float(v.default) for v in fixed if v.default is not None}
    rng = np.random.default_rng(seed)
    name = shift.replace("-", "_")
    c_dir = root / "c"
    ranges = _ranges(d)
    points = {
        f: rng.uniform(
            [ranges[a][0] for a in arguments],
            [ranges[a][1] for a in arguments],
            (n_points, len(arguments)),
        )
        for f, arguments in CONTROL_ARGUMENTS.items()
    }

    def reference(at: dict[str, np.ndarray], exact: bool = False) -> dict[str, np.ndarray]:
        """The SymPy expressions at the points: in double (numpy), or ``exact`` in 30-digit
        arithmetic (mpmath; the slip acceleration's cancellation costs double digits)."""
        import mpmath

        out = {}
        for f, arguments in CONTROL_ARGUMENTS.items():
            symbols = [args[a] for a in arguments]
            values = [sp.sympify(e).xreplace(defaults) for e in exprs[f]]
            if exact:
                function = sp.lambdify(symbols, values, "mpmath")
                with mpmath.workdps(30):
                    rows = [[float(c) for c in function(*map(mpmath.mpf, v))] for v in at[f]]
                out[f] = np.array(rows, dtype=float).reshape(n_points, len(values))
                continue
            function = sp.lambdify([symbols], values, "numpy")
            columns = function(at[f].T)
            out[f] = np.column_stack(
                [np.broadcast_to(np.asarray(c, dtype=float), (n_points,)) for c in columns]
            )
        return out

    reports = []
    spec = hybrid.spec
    header = c_dir / f"gearsym_control_{name}.h"
    for single in (False, True):
        lib = build_control_library(c_dir, shift, build_dir, single)
        c = CShiftController(lib, header, shift, spec.off_going, spec.on_coming, {}, single)
        seen = (
            {f: v.astype(np.float32).astype(float) for f, v in points.items()} if single else points
        )
        computed = {
            f: np.array([c.evaluate(f, list(v), len(exprs[f])) for v in seen[f]])
            for f in CONTROL_ARGUMENTS
        }
        floor = c_check.FLOOR["single" if single else "double"]
        exact = reference(seen, exact=True)
        report = c_check._report("C single" if single else "C double", computed, exact, floor)
        report.target = f"control_{name}: {report.target}"
        if single:
            report.conditioned = _conditioned(computed, exact, seen, reference, rng)
        reports.append(report)
    module = load_casadi_module(root / "python" / f"gearsym_control_{name}_casadi.py")
    functions = module.functions()
    p = module.parameter_defaults()
    computed = {
        f: np.array([np.asarray(functions[f](p, list(v)), dtype=float).ravel() for v in points[f]])
        for f in CONTROL_ARGUMENTS
    }
    report = c_check._report(
        "CasADi", computed, reference(points, exact=True), c_check.FLOOR["double"]
    )
    report.target = f"control_{name}: CasADi"
    reports.append(report)
    return reports
