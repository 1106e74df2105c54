"""The emitted C functions of one model, callable from Python through ctypes.

:class:`CFunctions` binds every function of a model's function table (the same table the
emitter printed the signatures from) in a library built by
:func:`gearsym.validation.checks.c_check.compile_shared`, including the sparsity patterns of the
sparse Jacobians as compiled; :func:`load_casadi_module` imports an emitted CasADi module.
"""

from __future__ import annotations

import ctypes
import importlib.util
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from gearsym.symbolic.codegen import (
    Bounds,
    CodegenConfig,
    FunctionSpec,
    SparsityPattern,
    build_function_table,
)
from gearsym.symbolic.model import Model

__all__ = ["CFunctions", "load_casadi_module", "load_functions"]


class CFunctions:
    """The emitted C functions of one model, callable with numpy arrays.

    Matrices are returned in their C layout (flat, column-major); use ``reshape(shape, order="F")``
    for the matrix.
    """

    def __init__(
        self,
        lib_path: Path,
        model: Model,
        single: bool = False,
        config: CodegenConfig | Bounds | None = None,
    ) -> None:
        self.model = model
        self.single = single
        self.table = build_function_table(model, config)
        self.real = ctypes.c_float if single else ctypes.c_double
        self.dtype = np.float32 if single else np.float64
        self._lib = ctypes.CDLL(str(lib_path))
        self.prefix = self.table.prefix
        fields = [(v.name, self.real) for v in model.parameters] or [("reserved_", self.real)]
        self.Params = type("Params", (ctypes.Structure,), {"_fields_": fields})
        self._functions: dict[str, Any] = {}
        self._positions: dict[str, tuple[int, np.ndarray]] = {}
        self.specs: dict[str, FunctionSpec] = {}
        real_p = ctypes.POINTER(self.real)
        for spec in self.table:
            fn = getattr(self._lib, self.prefix + spec.name)
            argtypes: list[Any] = []
            for arg in spec.args:
                if arg.kind == "scalar":
                    argtypes.append(self.real)
                elif arg.kind == "params":
                    argtypes.append(ctypes.POINTER(self.Params))
                else:
                    argtypes.append(real_p)
            for out in spec.outputs:
                if out.ctype == "params":
                    argtypes.append(ctypes.POINTER(self.Params))
                elif out.ctype == "int":
                    argtypes.append(ctypes.POINTER(ctypes.c_int))
                else:
                    argtypes.append(real_p)
            fn.argtypes = argtypes
            fn.restype = ctypes.c_int if spec.returns == "int" else None
            self._functions[spec.name] = fn
            self.specs[spec.name] = spec

    def params(self, values: Sequence[float]) -> Any:
        """A parameter struct holding ``values`` (model order)."""
        values = list(values)
        if len(values) != len(self.model.parameters):
            raise ValueError("wrong number of parameter values")
        return self.Params(*values) if values else self.Params(0.0)

    def _buffer(self, values: Any, size: int) -> np.ndarray:
        # Never hand C a zero-length (possibly NULL) buffer.
        arr = np.zeros(max(size, 1), dtype=self.dtype)
        arr[:size] = np.asarray(values, dtype=self.dtype).reshape(-1)[:size]
        return arr

    def _ptr(self, arr: np.ndarray) -> Any:
        return arr.ctypes.data_as(ctypes.POINTER(self.real))

    def evaluate(self, name: str, x: Any, u: Any, p: Any) -> np.ndarray:
        """Flat output of an expression function (``rhs``, ``outputs``, ``jac_*``)."""
        spec = self.specs[name]
        (out,) = spec.outputs
        xb = self._buffer(x, len(self.model.states))
        ub = self._buffer(u, len(self.model.inputs))
        ob = np.zeros(max(out.size, 1), dtype=self.dtype)
        params = p if isinstance(p, self.Params) else self.params(p)
        self._functions[name](self._ptr(xb), self._ptr(ub), ctypes.byref(params), self._ptr(ob))
        return ob[: out.size].astype(np.float64)

    def step(self, name: str, x: Any, u: Any, p: Any, h: float, n_steps: int = 1) -> np.ndarray:
        """``n_steps`` of ``rk4_step`` or ``linearly_implicit_euler_step`` (in place in C).

        Raises ``RuntimeError`` if the linearly implicit step reports an error.
        """
        fn = self._functions[name]
        nx = len(self.model.states)
        xb = self._buffer(x, nx)
        ub = self._buffer(u, len(self.model.inputs))
        params = p if isinstance(p, self.Params) else self.params(p)
        xp, up, pp, hh = self._ptr(xb), self._ptr(ub), ctypes.byref(params), self.real(h)
        for _ in range(n_steps):
            status = fn(xp, up, pp, hh, xp)  # x_next aliases x: documented as allowed
            if status:
                raise RuntimeError(f"{name} returned {status}")
        return xb[:nx].astype(np.float64)

    def step_status(
        self, name: str, x: Any, u: Any, p: Any, h: float, sentinel: float = -12345.0
    ) -> tuple[int, np.ndarray]:
        """One step into a separate ``x_next`` filled with ``sentinel`` beforehand: returns the
        status (0 for ``rk4_step``, which returns nothing) and ``x_next`` (still all
        ``sentinel`` where the step did not write)."""
        nx = len(self.model.states)
        xb = self._buffer(x, nx)
        ub = self._buffer(u, len(self.model.inputs))
        out = np.full(max(nx, 1), sentinel, dtype=self.dtype)
        params = p if isinstance(p, self.Params) else self.params(p)
        status = self._functions[name](
            self._ptr(xb), self._ptr(ub), ctypes.byref(params), self.real(h), self._ptr(out)
        )
        return int(status or 0), out[:nx].astype(np.float64)

    def pattern(self, jacobian: str) -> SparsityPattern:
        """The compressed-column pattern of ``jacobian`` (``"jac_x"``, ...) as compiled: read
        from the library's ``<prefix><jacobian>_colptr`` and ``_rowind`` arrays."""
        ncol = self.table[jacobian].outputs[0].shape[1]
        colptr = (ctypes.c_int * (ncol + 1)).in_dll(self._lib, f"{self.prefix}{jacobian}_colptr")
        nnz = colptr[ncol]
        rowind = (ctypes.c_int * max(nnz, 1)).in_dll(self._lib, f"{self.prefix}{jacobian}_rowind")
        rows = self.table[jacobian].outputs[0].shape[0]
        return SparsityPattern(rows, ncol, tuple(colptr), tuple(rowind[:nnz]))

    def evaluate_sparse(self, jacobian: str, x: Any, u: Any, p: Any) -> np.ndarray:
        """``<jacobian>_sparse`` spread by the compiled pattern into the flat column-major
        matrix (zeros elsewhere), comparable with the dense reference."""
        if jacobian not in self._positions:
            pattern = self.pattern(jacobian)
            self._positions[jacobian] = (pattern.size, np.array(pattern.positions(), dtype=int))
        size, positions = self._positions[jacobian]
        dense = np.zeros(size)
        dense[positions] = self.evaluate(f"{jacobian}_sparse", x, u, p)
        return dense

    def params_default(self) -> np.ndarray:
        """Values written by ``params_default``, model order."""
        params = self.Params()
        self._functions["params_default"](ctypes.byref(params))
        names = [f[0] for f in self.Params._fields_][: len(self.model.parameters)]
        return np.array([getattr(params, n) for n in names], dtype=np.float64)

    def params_validate(self, values: Sequence[float]) -> tuple[int, int]:
        """``(status, bad_index)`` of ``params_validate``."""
        index = ctypes.c_int(-7)
        status = self._functions["params_validate"](
            ctypes.byref(self.params(values)), ctypes.byref(index)
        )
        return int(status), int(index.value)


def load_functions(
    lib_path: Path,
    model: Model,
    single: bool = False,
    config: CodegenConfig | Bounds | None = None,
) -> CFunctions:
    """Load a library built by :func:`compile_shared` for ``model``, emitted with ``config``
    (which decides the functions it holds)."""
    return CFunctions(lib_path, model, single, config)


def load_casadi_module(path: Path) -> ModuleType:
    """Import an emitted CasADi module from its file (under a name unique to the path)."""
    name = "gearsym_casadi_" + re.sub(r"\W", "_", str(path.resolve()))
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    # No __pycache__ next to the emitted file: generated/ must hold exactly what was generated.
    saved, sys.dont_write_bytecode = sys.dont_write_bytecode, True
    try:
        spec.loader.exec_module(module)
    finally:
        sys.dont_write_bytecode = saved
    return module
