"""The emitted linear forms (5.1) against SymPy: C (double and float) and CasADi.

Each system of a :class:`~gearsym.symbolic.codegen.linear.LinearSystemSet` is evaluated at
random parameter points (the sampling of :func:`gearsym.validation.checks.c_check.sample_points`:
0.5–1.5 × default, inside the ranges ``params_validate`` enforces) by the compiled C functions
through ctypes and by the emitted CasADi module, and compared entry by entry with A and B
evaluated from the SymPy expressions (``lambdify``), with the metric of
:func:`gearsym.validation.checks.c_check.mixed_error`. That A and B themselves are the Jacobians of
the nonlinear model is checked against finite differences in ``tests/test_linear_forms.py``.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic.codegen import CodegenConfig
from gearsym.symbolic.codegen.linear import LinearSystemSet, linear_table
from gearsym.symbolic.naming import model_file_names
from gearsym.validation.checks import c_check
from gearsym.validation.checks.c_binding import load_casadi_module

__all__ = ["LinearFunctions", "compare_linear_sets", "reference_values"]


class LinearFunctions:
    """The emitted C functions of one linear set, callable with a parameter vector."""

    def __init__(self, lib_path: Path, s: LinearSystemSet, single: bool = False) -> None:
        self.set = s
        self.real = ctypes.c_float if single else ctypes.c_double
        self.dtype = np.float32 if single else np.float64
        lib = ctypes.CDLL(str(lib_path))
        table = linear_table(s)
        fields = [(v.name, self.real) for v in s.parameters] or [("reserved_", self.real)]
        self.Params = type("Params", (ctypes.Structure,), {"_fields_": fields})
        pointer = ctypes.POINTER(self.real)
        self._functions: dict[str, Any] = {}
        for system in s.systems:
            fn = getattr(lib, table.prefix + system.name)
            fn.argtypes = [ctypes.POINTER(self.Params), pointer, pointer]
            fn.restype = None
            self._functions[system.name] = fn

    def evaluate(self, name: str, p: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """A and B (2-D arrays) of system ``name`` at the parameter vector ``p``."""
        system = next(x for x in self.set.systems if x.name == name)
        n, m = len(system.states), len(system.inputs)
        params = self.Params(*[self.real(v) for v in p])
        a = np.zeros(n * n, dtype=self.dtype)
        b = np.zeros(max(n * m, 1), dtype=self.dtype)
        real_p = ctypes.POINTER(self.real)
        self._functions[name](
            ctypes.byref(params), a.ctypes.data_as(real_p), b.ctypes.data_as(real_p)
        )
        return (
            a.astype(np.float64).reshape((n, n), order="F"),
            b[: n * m].astype(np.float64).reshape((n, m), order="F"),
        )


def reference_values(s: LinearSystemSet, points: np.ndarray) -> dict[str, np.ndarray]:
    """``[A, B]`` of every system from the SymPy expressions, flattened column-major per point:
    ``{system: (n_points, NX*NX + NX*NU)}``."""
    symbols = [v.symbol for v in s.parameters]
    result = {}
    for system in s.systems:
        flat = [*system.A.T, *system.B.T]  # column-major: the transpose's rows
        f = sp.lambdify([symbols], flat, "numpy")
        values = [np.broadcast_to(np.asarray(v, dtype=float), (len(points),)) for v in f(points.T)]
        result[system.name] = np.column_stack(values) if values else np.zeros((len(points), 0))
    return result


def _flat(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.concatenate([a.ravel(order="F"), b.ravel(order="F")])


def compare_linear_sets(
    sets: Sequence[tuple[LinearSystemSet, CodegenConfig]],
    root: Path,
    build_dir: Path,
    n_points: int = 200,
    seed: int = 0,
) -> list[c_check.ComparisonReport]:
    """C double, C single and CasADi of every set against SymPy (module docstring), from the
    files under ``root`` (``c/`` and ``python/``)."""
    reports = []
    for k, (s, config) in enumerate(sets):
        names = model_file_names(s.name)
        sources = {
            names[key]: (root / "c" / names[key]).read_text(encoding="utf-8")
            for key in ("header", "source")
        }
        model = s.as_model()
        _, _, points = c_check.sample_points(model, n_points, seed + k, config.bounds)
        reference = reference_values(s, points)
        computed: dict[str, dict[str, np.ndarray]] = {}
        for single in (False, True):
            lib_path = c_check.compile_shared(sources, build_dir / s.name, single=single)
            lib = LinearFunctions(lib_path, s, single)
            computed["C single" if single else "C double"] = {
                x.name: np.array([_flat(*lib.evaluate(x.name, p)) for p in points])
                for x in s.systems
            }
        module = load_casadi_module(root / "python" / names["casadi"])
        functions = module.functions()
        computed["CasADi"] = {
            x.name: np.array(
                [_flat(*(np.array(m, dtype=float) for m in functions[x.name](p))) for p in points]
            )
            for x in s.systems
        }
        for target, values in computed.items():
            floor = c_check.FLOOR["single" if "single" in target else "double"]
            report = c_check._report(target, values, reference, floor)
            report.target = f"{s.name}: {target}"
            reports.append(report)
    return reports
