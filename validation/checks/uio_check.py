"""The emitted UIO (thesis 4.4) of a generated tree against the library's design, for
``gearsym generate --check`` (:func:`gearsym.validation.checks.generated_check.check_tree`).

Every function of every phase — ``_init`` (z₀ = T x₀), ``_step`` (z_{k+1} = F z + T B_d u +
T B_1 (u_{k+1} − u) + K y), ``_estimate`` (x̂ = z + H y) and ``_unknown_input``
(d̂ = L (y_{k+1} − C A_d x̂ − C B_d u − C B_1 (u_{k+1} − u))) — in C double, C single and
CasADi, at ``n_points`` random arguments, against NumPy evaluating the same equations from the
:class:`~gearsym.symbolic.estimators.uio.UioDesign` matrices (not the products the emitter
printed). The functions are linear maps, so the error is measured against the scale of their
rounding: |c − r| / Σ_j |a_ij x_j| per output, the bound of a dot product's rounding error up
to a factor n ε (a plain relative error would be unbounded where the terms cancel, e.g. the
unknown input, a small difference of speeds times a large gain). Targets 1e-12 (double, CasADi)
and 1e-5 (single), as for the models. Along the reference shift the same code is compared
with :meth:`UioDesign.run` in tests/test_uio_c.py.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.codegen.uio import phase_identifier, uio_set_name
from gearsym.validation.checks import c_check

__all__ = ["compare_uio"]

FUNCTIONS = ("init", "step", "estimate", "unknown_input")


def _terms(
    design: Any,
    z: np.ndarray,
    y: np.ndarray,
    u: np.ndarray,
    un: np.ndarray,
    x: np.ndarray,
    yn: np.ndarray,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per function: (the value, Σ|terms|) at one argument, from the design's matrices."""
    T, F, K, H = design.T, design.F, design.K, design.H
    Bd, B1, C, Ad, L = design.Bd, design.B1, design.C, design.Ad, design.left_inverse
    du = un - u
    a = np.abs
    step = F @ z + T @ (Bd @ u) + T @ (B1 @ du) + K @ y
    step_scale = a(F) @ a(z) + a(T) @ (a(Bd) @ a(u)) + a(T) @ (a(B1) @ a(du)) + a(K) @ a(y)
    predicted = C @ (Ad @ x + Bd @ u + B1 @ du)
    d = L @ (yn - predicted)
    d_scale = a(L) @ (a(yn) + a(C) @ (a(Ad) @ a(x) + a(Bd) @ a(u) + a(B1) @ a(du)))
    return {
        "init": (T @ x, a(T) @ a(x)),
        "step": (step, step_scale),
        "estimate": (z + H @ y, a(z) + a(H) @ a(y)),
        "unknown_input": (d, d_scale),
    }


def _arguments(design: Any, n_points: int, seed: int) -> list[dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    nx, ny, nu = len(design.states), len(design.outputs), len(design.known)
    lo, hi = c_check.STATE_RANGE
    return [
        {
            "z": rng.uniform(lo, hi, nx),
            "y": rng.uniform(lo, hi, ny),
            "u": rng.uniform(lo, hi, max(nu, 1))[:nu],
            "un": rng.uniform(lo, hi, max(nu, 1))[:nu],
            "x": rng.uniform(lo, hi, nx),
            "yn": rng.uniform(lo, hi, ny),
        }
        for _ in range(n_points)
    ]


def _c_call(
    lib: ctypes.CDLL,
    prefix: str,
    name: str,
    args: dict[str, np.ndarray],
    out_size: int,
    single: bool,
) -> np.ndarray:
    real = ctypes.c_float if single else ctypes.c_double
    dtype = np.float32 if single else np.float64

    keep = []  # the arrays must outlive the call

    def arg(a: np.ndarray) -> Any:
        arr = np.ascontiguousarray(a if a.size else np.zeros(1), dtype)
        keep.append(arr)
        return arr.ctypes.data_as(ctypes.POINTER(real))

    out = np.zeros(max(out_size, 1), dtype)
    fn = getattr(lib, f"{prefix}{name}")
    if name == "init":
        fn(arg(args["x"]), out.ctypes.data_as(ctypes.POINTER(real)))
    elif name == "step":
        fn(
            arg(args["z"]),
            arg(args["y"]),
            arg(args["u"]),
            arg(args["un"]),
            out.ctypes.data_as(ctypes.POINTER(real)),
        )
    elif name == "estimate":
        fn(arg(args["z"]), arg(args["y"]), out.ctypes.data_as(ctypes.POINTER(real)))
    else:
        fn(
            arg(args["x"]),
            arg(args["yn"]),
            arg(args["u"]),
            arg(args["un"]),
            out.ctypes.data_as(ctypes.POINTER(real)),
        )
    return out[:out_size].astype(np.float64)


def _casadi_call(functions: dict[str, Any], name: str, args: dict[str, np.ndarray]) -> np.ndarray:
    f = functions[name]
    if name == "init":
        value = f(args["x"])
    elif name == "step":
        value = f(args["z"], args["y"], args["u"], args["un"])
    elif name == "estimate":
        value = f(args["z"], args["y"])
    else:
        value = f(args["x"], args["yn"], args["u"], args["un"])
    return np.asarray(value, dtype=float).ravel()


def _error(got: np.ndarray, want: np.ndarray, scale: np.ndarray) -> float:
    tiny = np.finfo(np.float64).tiny
    with np.errstate(invalid="ignore"):
        err = np.abs(got - want) / np.maximum(scale, tiny)
    return float(np.nan_to_num(err, nan=np.inf).max(initial=0.0))


def compare_uio(
    shift: str,
    designs: Sequence[Any],
    root: Path,
    build_dir: Path,
    n_points: int = 1000,
    seed: int = 0,
) -> list[c_check.ComparisonReport]:
    """Reports ``uio_<a>_<b>: C double``, ``…: C single``, ``…: CasADi`` with the largest error
    per ``<phase>.<function>`` (metric in the module text) of the files under ``root``."""
    name = uio_set_name(shift)
    c_dir = root / "c"
    sources = {
        f: (c_dir / f).read_text(encoding="utf-8")
        for f in (f"gearsym_{name}.h", f"gearsym_{name}.c")
    }
    module = c_check.load_casadi_module(root / "python" / f"gearsym_{name}_casadi.py")
    casadi_functions = module.functions()
    reports = []
    for target in ("C double", "C single", "CasADi"):
        single = target == "C single"
        report = c_check.ComparisonReport(f"{name}: {target}", n_points, 0.0)
        lib = None
        if target != "CasADi":
            lib = ctypes.CDLL(str(c_check.compile_shared(sources, build_dir / name, single=single)))
        for k, design in enumerate(designs):
            ph = phase_identifier(design.phase)
            prefix = f"gearsym_{name}_{ph}_"
            errors = dict.fromkeys(FUNCTIONS, 0.0)
            for args in _arguments(design, n_points, seed + k):
                if single:  # the float build sees rounded arguments: so does its reference
                    args = {key: v.astype(np.float32).astype(np.float64) for key, v in args.items()}
                want = _terms(
                    design, args["z"], args["y"], args["u"], args["un"], args["x"], args["yn"]
                )
                for fn in FUNCTIONS:
                    value, scale = want[fn]
                    if lib is not None:
                        got = _c_call(lib, prefix, fn, args, len(value), single)
                    else:
                        got = _casadi_call(casadi_functions[ph], fn, args)
                    errors[fn] = max(errors[fn], _error(got, value, scale))
            for fn, err in errors.items():
                report.max_error[f"{ph}.{fn}"] = err
        reports.append(report)
    return reports
