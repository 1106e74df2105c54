"""Shared by the code-generation benchmarks: the built-in gearbox's emitted code, and CasADi's own
C (``casadi.CodeGenerator``) for the same expressions as the peer."""

from __future__ import annotations

import collections
import importlib
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import casadi as ca
from gearsym.symbolic.codegen import build_function_table, count_operations, cse_function
from gearsym.symbolic.description import load_description
from gearsym.symbolic.generate import generate_tree

REPO = Path(__file__).resolve().parents[1]
EXPR_FUNCTIONS = ("rhs", "outputs", "jac_x", "jac_u", "jac_p")
#: Instructions of an SX function that are not arithmetic (loads, stores, constants).
_NOT_OPERATIONS = {ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_PARAMETER}


def write_tree(out: Path) -> dict:
    """Generate the built-in gearbox's code into ``out``; returns the models by name."""
    tree = generate_tree(load_description(None))
    for relative, text in tree.files.items():
        path = out / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return {m.model.name: m for m in tree.models}


def casadi_module(out: Path, model: str) -> ModuleType:
    """The emitted CasADi module of ``model`` from ``out/python``."""
    sys.path.insert(0, str(out / "python"))
    try:
        return importlib.import_module(f"gearsym_{model}_casadi")
    finally:
        sys.path.pop(0)


def casadi_c(module: ModuleType, names: tuple[str, ...], out: Path, stem: str, real: str) -> Path:
    """CasADi's generated C for the emitted functions ``names`` (renamed ``<stem>_<name>``)."""
    cg = ca.CodeGenerator(f"{stem}.c", {"with_header": True, "casadi_real": real})
    functions = module.functions()
    for name in names:
        f = functions[name]
        cg.add(ca.Function(f"{stem}_{name}", f.sx_in(), f.call(f.sx_in())))
    out.mkdir(parents=True, exist_ok=True)
    cg.generate(str(out) + "/")
    return out / f"{stem}.c"


def casadi_operations(f: ca.Function) -> int:
    """Arithmetic instructions of an SX function (CasADi's own operation count)."""
    ops = collections.Counter(f.instruction_id(k) for k in range(f.n_instructions()))
    return sum(n for op, n in ops.items() if op not in _NOT_OPERATIONS)


def gearsym_operations(model: object, name: str) -> int:
    """Operations of an emitted function as stated in its doc comment."""
    spec = build_function_table(model)[name]  # type: ignore[arg-type]
    return count_operations(cse_function(spec)).total


def run(cmd: list[str], cwd: Path | None = None) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}")
    return proc.stdout
