"""CasADi functions emitted as C (CasADi's ``CodeGenerator``), compiled with the system C
compiler (``cc -O1 -shared -fPIC``) and called through ``ctypes``.

Why: calling a CasADi function from Python costs some 30-40 µs, nearly all of it converting
NumPy arrays to CasADi's matrices and back; a shift's mode right-hand side is a few hundred
floating-point operations. Called through ``ctypes`` on preallocated buffers the same
emitted code costs a few µs. The arithmetic is CasADi's own, emitted as C without fast-math,
so the values are the same operations in the same order as CasADi's virtual machine.

:meth:`CompiledFunction.many` evaluates a function at N points in one call: a loop in C
(:data:`MANY_SOURCE`, appended to the emitted file) over the function's rows, where CasADi's
``map`` costs a function object per N and its virtual machine per point, and a call per point
through ``ctypes`` costs a few µs each (a shift's samples and energy audit read thousands).

The shared library is built once per :class:`CompiledFunctions`, where the models are
compiled, at first use, and kept in the cache folder (``$GEARSYM_CACHE_DIR``, else
``$XDG_CACHE_HOME/gearsym``, else ``~/.cache/gearsym``; the command cache's folder) under
``c/<SHA-256 of the source, compiler and flags>.so``: the next process loads it instead of
compiling. ``GEARSYM_NO_CACHE=1`` compiles every time (in a temporary folder).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CompiledFunction", "CompiledFunctions", "compiler_available"]

#: The C compiler and its flags (IEEE arithmetic kept: no -ffast-math). -O1, not -O2: a
#: fleet's vehicle compiles its own shift models (their numbers differ), where -O2 took half
#: as long again (2.8 s against 1.9 s for a shift's modes) for no drive time measurable
#: beside the ctypes call's own cost.
COMPILER = "cc"
FLAGS = ("-O1", "-shared", "-fPIC")

_DOUBLE_P = ctypes.POINTER(ctypes.c_double)

#: The loop behind :meth:`CompiledFunction.many`, appended to CasADi's emitted file (whose
#: ``casadi_real`` and ``casadi_int`` it uses): ``f`` at ``count`` points, input i of point k
#: at ``in[i] + k stride[i]`` (stride 0: one value for every point), output k at
#: ``out + k n_out``; ``arg``, ``res``, ``iw``, ``w`` are ``f``'s work arrays.
MANY_SOURCE = """
typedef int (*gearsym_function)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*,
                                int);
CASADI_SYMBOL_EXPORT int gearsym_many(gearsym_function f, int n_in, const casadi_real** in,
                                      const casadi_int* stride, casadi_int n_out,
                                      casadi_real* out, casadi_int count,
                                      const casadi_real** arg, casadi_real** res,
                                      casadi_int* iw, casadi_real* w) {
  casadi_int k;
  int i;
  for (k = 0; k < count; ++k) {
    for (i = 0; i < n_in; ++i) arg[i] = in[i] + k * stride[i];
    res[0] = out + k * n_out;
    if (f(arg, res, iw, w, 0)) return 1;
  }
  return 0;
}
"""


def compiler_available() -> bool:
    """Whether :data:`COMPILER` is on the PATH (without it the callers keep CasADi's calls)."""
    return shutil.which(COMPILER) is not None


class CompiledFunction:
    """One compiled function: dense vector inputs and one dense vector output. Calling it
    copies the inputs into its buffers, runs the C function and returns a copy of the
    output (a fresh array: callers such as SciPy's integrators keep it)."""

    def __init__(self, library: Any, name: str, function: Any) -> None:
        self.name = name
        self.inputs = [np.zeros(function.size1_in(i)) for i in range(function.n_in())]
        self.output = np.zeros(function.size1_out(0))
        self._arg = (_DOUBLE_P * max(function.sz_arg(), 1))(
            *[b.ctypes.data_as(_DOUBLE_P) for b in self.inputs]
        )
        self._res = (_DOUBLE_P * max(function.sz_res(), 1))(self.output.ctypes.data_as(_DOUBLE_P))
        self._iw = (ctypes.c_longlong * max(function.sz_iw(), 1))()
        self._w = (ctypes.c_double * max(function.sz_w(), 1))()
        self._c = getattr(library, name)
        self._c.restype = ctypes.c_int
        self._c.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int]
        self._addresses = tuple(
            ctypes.addressof(a) for a in (self._arg, self._res, self._iw, self._w)
        )
        # :meth:`many`'s own argument arrays (the loop repoints them; ``__call__``'s stay)
        self._many_arg = (_DOUBLE_P * max(function.sz_arg(), 1))()
        self._many_res = (_DOUBLE_P * max(function.sz_res(), 1))()
        self._many = library.gearsym_many
        self._many.restype = ctypes.c_int
        self._function = ctypes.cast(self._c, ctypes.c_void_p)

    def __call__(self, *args: Any) -> np.ndarray:
        for buffer, value in zip(self.inputs, args, strict=True):
            buffer[:] = value
        if self._c(*self._addresses, 0):
            raise RuntimeError(f"the compiled {self.name} failed")
        return self.output.copy()

    def many(self, *args: Any) -> np.ndarray:
        """The function at N points (an input: N × size rows, or one vector for every point;
        at least one input has rows): N × outputs, the same values as N calls."""
        arrays = [np.ascontiguousarray(a, dtype=float) for a in args]
        if len(arrays) != len(self.inputs):
            raise ValueError(f"{self.name}: {len(self.inputs)} inputs, {len(arrays)} given")
        counts = {len(a) for a in arrays if a.ndim == 2}
        if len(counts) != 1:
            raise ValueError(f"{self.name}: inputs of rows {sorted(counts)} (one count needed)")
        count = counts.pop()
        strides = []
        for a, buffer in zip(arrays, self.inputs, strict=True):
            if a.shape[-1] != buffer.size:
                raise ValueError(f"{self.name}: an input of {a.shape[-1]} where {buffer.size}")
            strides.append(buffer.size if a.ndim == 2 else 0)
        out = np.empty((count, self.output.size))
        pointers = (_DOUBLE_P * len(arrays))(*[a.ctypes.data_as(_DOUBLE_P) for a in arrays])
        stride = (ctypes.c_longlong * len(arrays))(*strides)
        failed = self._many(
            self._function,
            ctypes.c_int(len(arrays)),
            pointers,
            stride,
            ctypes.c_longlong(self.output.size),
            out.ctypes.data_as(_DOUBLE_P),
            ctypes.c_longlong(count),
            self._many_arg,
            self._many_res,
            self._iw,
            self._w,
        )
        if failed:
            raise RuntimeError(f"the compiled {self.name} failed")
        return out


class CompiledFunctions:
    """``functions`` (name → CasADi function of dense vector inputs, first output used)
    emitted into one C file and compiled into one shared library; ``self[name]`` is the
    :class:`CompiledFunction`."""

    def __init__(self, functions: Mapping[str, Any]) -> None:
        import casadi as ca

        renamed = {}
        for i, (name, f) in enumerate(functions.items()):
            symbol = f"gearsym_{i}"
            inputs = f.sx_in() if f.is_a("SXFunction") else f.mx_in()
            outputs = f.call(inputs)
            renamed[name] = ca.Function(symbol, inputs, [ca.densify(outputs[0])])
        with tempfile.TemporaryDirectory(prefix="gearsym_c_") as folder:
            source = Path(folder) / "functions.c"
            generator = ca.CodeGenerator(source.name, {"with_header": False})
            for f in renamed.values():
                generator.add(f)
            generator.generate(f"{folder}/")
            with source.open("a") as emitted:
                emitted.write(MANY_SOURCE)
            command = [COMPILER, *FLAGS, "-o", "functions.so", source.name, "-lm"]
            digest = hashlib.sha256(source.read_bytes() + " ".join(command).encode()).hexdigest()
            cached = _cache_folder()
            library_path = Path(folder) / "functions.so"
            if cached is not None and (cached / f"{digest}.so").exists():
                library_path = cached / f"{digest}.so"
            else:
                subprocess.run(command, cwd=folder, check=True, capture_output=True)
                if cached is not None:
                    _store(library_path, cached / f"{digest}.so")
            library = ctypes.CDLL(str(library_path))
        self._library = library
        self.functions = {
            name: CompiledFunction(library, f.name(), f) for name, f in renamed.items()
        }

    def __getitem__(self, name: str) -> CompiledFunction:
        return self.functions[name]


def _cache_folder() -> Path | None:
    """Where compiled libraries are kept (module docstring), or None (caching off)."""
    if os.environ.get("GEARSYM_NO_CACHE", "") not in ("", "0"):
        return None
    if os.environ.get("GEARSYM_CACHE_DIR"):
        base = Path(os.environ["GEARSYM_CACHE_DIR"])
    else:
        home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        base = Path(home) / "gearsym"
    return base / "c"


def _store(library: Path, target: Path) -> None:
    """Copy ``library`` to ``target`` through a temporary name and ``os.replace``: another
    process sees the whole library or none. A cache that cannot be written is skipped."""
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = target.with_name(f".{target.name}.{os.getpid()}.tmp")
        shutil.copyfile(library, partial)
        os.replace(partial, target)
    except OSError:
        pass
