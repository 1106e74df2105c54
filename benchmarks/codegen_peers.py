"""Shared by the code-generation benchmarks: the built-in gearbox's emitted code, and the peers.

The peers of the speed benchmark build each model themselves from the *raw* SymPy right-hand
side that gearsym derives (never from gearsym's CSE'd or differentiated expressions): CasADi
through the one SymPy -> CasADi translator (:func:`gearsym.symbolic.numeric.to_casadi`), its
own AD (``jacobian``) and its own CSE (``Function`` option ``cse``) and ``CodeGenerator`` C;
SymForce (symengine backend) through its own ``jacobian``, its CSE and its C++ code generation.
A sensitivity system [x; S] (3.7) is assembled by each peer from the base model's raw right-hand
side with its own AD, as gearsym's ``sensitivity_model`` does with SymPy.

The Cortex-M4 benchmark still compares with ``CodeGenerator`` C of the emitted CasADi module
(:func:`casadi_c`).
"""

from __future__ import annotations

import collections
import importlib
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import casadi as ca
import sympy as sp
from gearsym.symbolic.codegen import build_function_table, count_operations, cse_function
from gearsym.symbolic.export.generate import generate_tree
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.model import Model
from gearsym.symbolic.numeric import to_casadi

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


def gearsym_operations(model: Model, name: str, config: Any = None) -> int:
    """Operations of an emitted expression function, as stated in its doc comment."""
    table = build_function_table(model, config)
    return count_operations(cse_function(table[name], table.config)).total


def run(cmd: list[str], cwd: Path | None = None) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}")
    return proc.stdout


# ---------------------------------------------------------------------------------------------
# Peers built from the raw right-hand side
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    """One timed function: what gearsym emits for it and what the peers rebuild.

    ``base`` is the model whose raw right-hand side the peers start from; ``sensitivity`` the
    parameters of the sensitivity system (3.7) they assemble from it (empty: the model itself);
    ``function`` is ``"rhs"`` or ``"jac_x"`` (of that system, with respect to its state).
    """

    label: str
    emitted: str  # the emitted model whose C function is timed
    function: str
    base: Model
    sensitivity: tuple[str, ...] = ()

    @property
    def c_function(self) -> str:
        suffix = "rhs" if self.function == "rhs" else "jac_x_sparse"
        return f"gearsym_{self.emitted}_{suffix}"


def _float_constants(expr: sp.Basic) -> sp.Basic:
    """Rationals and integers beyond 2**53 as double constants (the derivation's exact
    rationals have 36-digit numerators: as C++ integer literals they would not compile)."""
    numbers = {
        r: sp.Float(r, 17)
        for r in expr.atoms(sp.Rational)
        if r.q != 1 or abs(r.p) > 2**53  # integers below 2**53 are exact doubles
    }
    return expr.xreplace(numbers) if numbers else expr


def _state_names(problem: Problem) -> tuple[list[str], list[list[str]]]:
    base = problem.base
    names = [v.name for v in base.states]
    sens = [[f"S_{x}__{p}" for x in names] for p in problem.sensitivity]
    return names, sens


def casadi_peer(problem: Problem, name: str) -> ca.Function:
    """CasADi's function for ``problem`` from the raw SymPy right-hand side: its own AD and its
    own CSE (option ``cse``)."""
    base = problem.base
    x = ca.SX.sym("x", len(base.states))
    u = ca.SX.sym("u", len(base.inputs))
    p = ca.SX.sym("p", len(base.parameters))
    mapping: dict[sp.Symbol, Any] = {}
    for group, symbols in ((x, base.state_symbols), (u, base.input_symbols)):
        mapping.update({s: group[k] for k, s in enumerate(symbols)})
    mapping.update({s: p[k] for k, s in enumerate(base.parameter_symbols)})
    f = ca.vertcat(*(to_casadi(e, mapping) for e in base.rhs))
    state = x
    if problem.sensitivity:
        chosen = [base.variable(n).symbol for n in problem.sensitivity]
        s = ca.SX.sym("S", len(base.states), len(chosen))
        jac_p = ca.jacobian(f, ca.vertcat(*(mapping[c] for c in chosen)))
        f = ca.vertcat(f, ca.vec(ca.mtimes(ca.jacobian(f, x), s) + jac_p))
        state = ca.vertcat(x, ca.vec(s))
    out = f if problem.function == "rhs" else ca.jacobian(f, state)
    return ca.Function(name, [state, u, p], [out], ["x", "u", "p"], ["out"], {"cse": True})


def casadi_peer_c(problem: Problem, name: str, out: Path) -> tuple[Path, ca.Function]:
    """``CodeGenerator`` C (double) of :func:`casadi_peer`."""
    f = casadi_peer(problem, name)
    cg = ca.CodeGenerator(f"{name}.c", {"with_header": True, "casadi_real": "double"})
    cg.add(f)
    out.mkdir(parents=True, exist_ok=True)
    cg.generate(str(out) + "/")
    return out / f"{name}.c", f


def symforce_available() -> str | None:
    """``None`` if SymForce and Eigen can be used, else why not."""
    try:
        import symforce  # noqa: F401
    except ImportError as err:
        return f"symforce is not installed ({err}; pip install symforce==0.12.0)"
    if not Path("/usr/include/eigen3/Eigen/Core").is_file():
        return "the Eigen headers (/usr/include/eigen3) are missing (apt-get install libeigen3-dev)"
    return None


def symforce_peer(problem: Problem, name: str, out: Path) -> tuple[Path, str, int]:
    """SymForce's C++ for ``problem`` from the raw SymPy right-hand side, its own ``jacobian``
    and CSE. Returns the header, the C++ function name and SymForce's operation count."""
    import symengine as se
    import symforce

    symforce.set_epsilon_to_number()  # no epsilon symbol: the models need none
    import symforce.symbolic as sf
    from symforce.codegen import Codegen, CppConfig
    from symforce.values import Values

    base = problem.base
    names, sens = _state_names(problem)
    x = sf.Matrix([sf.Symbol(n) for n in names])
    u = sf.Matrix([sf.Symbol(v.name) for v in base.inputs])
    p = sf.Matrix([sf.Symbol(v.name) for v in base.parameters])
    rename = {v.symbol: sp.Symbol(v.name) for v in (*base.states, *base.inputs, *base.parameters)}
    f = sf.Matrix([se.sympify(_float_constants(e.xreplace(rename))) for e in base.rhs])
    state = x
    if problem.sensitivity:
        columns = [sf.Matrix([sf.Symbol(n) for n in column]) for column in sens]
        chosen = sf.Matrix([sf.Symbol(n) for n in problem.sensitivity])
        jac_x, jac_p = f.jacobian(x), f.jacobian(chosen)
        rows = f.to_flat_list()
        for j, column in enumerate(columns):
            rows += (jac_x * column + jac_p[:, j]).to_flat_list()
        f = sf.Matrix(rows)
        state = sf.Matrix(x.to_flat_list() + [e for c in columns for e in c.to_flat_list()])
    output = f if problem.function == "rhs" else f.jacobian(state)
    sparse = ["res"] if problem.function != "rhs" else None
    codegen = Codegen(
        inputs=Values(x=state, u=u, p=p),
        outputs=Values(res=output),
        config=CppConfig(),
        name=name,
        return_key=None,
        sparse_matrices=sparse,
    )
    generated = codegen.generate_function(output_dir=str(out), skip_directory_nesting=True)
    header = Path(generated.generated_files[0])
    text = header.read_text()
    ops = int(re.search(r"Total ops: (\d+)", text).group(1))
    cpp_name = re.search(r"^void (\w+)\(", text, re.MULTILINE).group(1)
    return header, cpp_name, ops
