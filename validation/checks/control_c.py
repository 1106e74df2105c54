"""The emitted shift controller (``gearsym_control_<a>_<b>.c``) called from Python: a strict
shared-library build and a ctypes controller with the interface of the Python one
(:class:`gearsym.validation.studies.control.controller.ShiftController`: ``step(t, speeds,
torque) -> {element: pressure}`` and ``phase``), so that it can close the loop on the plant of
:mod:`gearsym.validation.studies.control.closed_loop` and be compared with the Python
controller tick by tick.
"""

from __future__ import annotations

import ctypes
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.validation.checks.c_check import STRICT_FLAGS, CompileError

__all__ = [
    "CShiftController",
    "build_control_library",
    "emit_task_sources",
    "struct_fields",
    "structure",
]

PHASES = ("fill", "torque", "inertia", "lockup", "done")
KNOWLEDGE_FIELDS = (
    "mu_off",
    "mu_on",
    "m_veh",
    "zeta",
    "torque_gain",
    "valve_gain",
    "valve_offset",
    "fill_time",
    "fill_offset",
    "pressure_offset",
)


def emit_task_sources(d: Any, shift: str, out: Path, mu_map_dir: Path) -> Path:
    """The TCU task of ``shift`` as C into ``out``: its shift controller (both languages'
    files of :func:`~gearsym.symbolic.codegen.control.emit_control_files`), its EKF's C and
    the μ map's C copied from ``mu_map_dir`` (the same for every shift); ``generated/``
    holds the default shift's only. Returns ``out``."""
    import shutil

    from gearsym.symbolic.codegen import emit_all
    from gearsym.symbolic.codegen.control import emit_control_files
    from gearsym.symbolic.export.generate import ekf_model
    from gearsym.symbolic.shifts import shift_spec

    out.mkdir(parents=True, exist_ok=True)
    for name, text in emit_control_files(d, shift).items():
        (out / name).write_text(text, encoding="utf-8")
    ekf = ekf_model(d, shift_spec(d, shift))
    for name, text in emit_all(ekf.model, ekf.config).items():
        if not name.endswith(".py"):
            (out / name).write_text(text, encoding="utf-8")
    for name in ("gearsym_mu_map.c", "gearsym_mu_map.h"):
        shutil.copy(mu_map_dir / name, out / name)
    return out


def build_control_library(c_dir: Path, shift: str, out: Path, single: bool) -> Path:
    """Compile the controller of ``shift`` with the μ map and the shift's EKF from ``c_dir``
    into a shared library in ``out`` (the project's strict flags, ``-O2``; a warning fails)."""
    import subprocess

    name = shift.replace("-", "_")
    sources = [c_dir / f"gearsym_control_{name}.c", c_dir / "gearsym_mu_map.c"]
    sources.append(c_dir / f"gearsym_ekf_{name}.c")
    out.mkdir(parents=True, exist_ok=True)
    lib = out / f"libgearsym_control_{name}_{'single' if single else 'double'}.so"
    cmd = ["gcc", *STRICT_FLAGS, "-O2", "-fPIC", "-shared", f"-I{c_dir}"]
    cmd += ["-DGEARSYM_SINGLE_PRECISION"] if single else []
    cmd += ["-o", str(lib), *map(str, sources), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0 or proc.stderr.strip() or proc.stdout.strip():
        raise CompileError(f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}")
    return lib


def struct_fields(header: str, struct: str) -> list[tuple[str, str]]:
    """(type, name) of each field of ``typedef struct <struct> {...}`` in a header's text."""
    return [(kind, name) for kind, name, _ in _struct_fields(header, struct)]


def _struct_fields(header: str, struct: str) -> list[tuple[str, str, int]]:
    """(type, name, length: 1 for a scalar) of each field; an array's length is an integer
    macro of the header plus or minus an integer (``NAME + 1``)."""
    match = re.search(r"typedef struct " + struct + r" \{(.*?)\n\} ", header, flags=re.S)
    if match is None:
        raise ValueError(f"no struct {struct}")
    macros = {m[0]: int(m[1]) for m in re.findall(r"#define (\w+) (-?\d+)\b", header)}
    fields = []
    for line in match.group(1).splitlines():
        found = re.match(r"\s+(\w+) (\w+)(?:\[([^\]]*)\])?;", line)
        if found:
            length = 1
            if found.group(3) is not None:
                terms = re.fullmatch(r"\s*(\w+)\s*(?:([+-])\s*(\d+))?\s*", found.group(3))
                if terms is None:
                    raise ValueError(f"{struct}.{found.group(2)}: length {found.group(3)!r}")
                base = terms[1]
                length = int(base) if base.isdigit() else macros[base]
                if terms[2]:
                    length += int(terms[3]) * (1 if terms[2] == "+" else -1)
            fields.append((found.group(1), found.group(2), length))
    return fields


def _structure(header: str, struct: str, real: Any) -> type[ctypes.Structure]:
    types = {"gearsym_real": real, "int": ctypes.c_int}
    fields = [
        (name, types[kind] if length == 1 else types[kind] * length)
        for kind, name, length in _struct_fields(header, struct)
    ]
    return type(struct, (ctypes.Structure,), {"_fields_": fields})


def structure(header: str, struct: str, single: bool) -> type[ctypes.Structure]:
    """The ctypes structure of ``typedef struct <struct>`` in a header's text (gearsym_real
    float or double; arrays of a macro's length as the header defines them)."""
    return _structure(header, struct, ctypes.c_float if single else ctypes.c_double)


class CShiftController:
    """The emitted controller of one shift through ctypes, in double or float."""

    def __init__(
        self,
        lib_path: Path,
        header: Path,
        shift: str,
        off: str,
        on: str,
        knowledge: Mapping[str, float],
        single: bool = False,
    ) -> None:
        name = shift.replace("-", "_")
        self.prefix = f"gearsym_control_{name}_"
        text = header.read_text(encoding="utf-8")
        real = ctypes.c_float if single else ctypes.c_double
        self.real = real
        self.Params = _structure(text, self.prefix + "params", real)
        self.Knowledge = _structure(text, self.prefix + "knowledge", real)
        self.Inputs = _structure(text, self.prefix + "inputs", real)
        self.State = _structure(text, self.prefix + "state", real)
        self.Outputs = _structure(text, self.prefix + "outputs", real)
        self.lib = ctypes.CDLL(str(lib_path))
        self.off, self.on = off, on
        self.params = self.Params()
        self.lib[self.prefix + "params_default"](ctypes.byref(self.params))
        self.knowledge = self.Knowledge()
        self.lib[self.prefix + "knowledge_default"](ctypes.byref(self.knowledge))
        for key, value in knowledge.items():
            setattr(self.knowledge, key, value)
        self.state = self.State()
        self.lib[self.prefix + "init"](ctypes.byref(self.knowledge), ctypes.byref(self.state))
        self._step = self.lib[self.prefix + "step"]
        self._step.restype = ctypes.c_int
        self.status = 0

    @property
    def phase(self) -> str:
        return PHASES[self.state.phase]

    def step(
        self, t: float, speeds: np.ndarray, torque: float, measured: tuple[int, int] = (0, 1)
    ) -> dict[str, float]:
        """One tick: ``speeds`` every shaft's speed (the input and output shafts at
        ``measured``), ``torque`` the commanded input torque → the pressure commands (Pa)."""
        inputs = self.Inputs(t, float(speeds[measured[0]]), float(speeds[measured[1]]), torque)
        out = self.Outputs()
        self.status = self._step(
            ctypes.byref(self.params),
            ctypes.byref(self.knowledge),
            ctypes.byref(inputs),
            ctypes.byref(self.state),
            ctypes.byref(out),
        )
        return {self.off: float(out.p_off), self.on: float(out.p_on)}

    def evaluate(self, function: str, values: list[float], n_out: int) -> np.ndarray:
        """One of the model-part functions (``from_gear``, ``sliding_pos``, ...) at ``values``."""
        v = (self.real * len(values))(*values)
        out = (self.real * n_out)()
        self.lib[self.prefix + function](ctypes.byref(self.params), v, out)
        return np.array(list(out), dtype=float)
