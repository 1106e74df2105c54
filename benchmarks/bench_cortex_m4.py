"""Object size of the emitted C on a Cortex-M4F, against CasADi's generated C.

Every emitted source of the built-in gearbox is cross-compiled as a TCU team would
(``arm-none-eabi-gcc -mcpu=cortex-m4 -mfpu=fpv4-sp-d16 -mfloat-abi=hard -mthumb
-DGEARSYM_SINGLE_PRECISION -O2``, plus ``-ffunction-sections`` so that ``arm-none-eabi-size -A``
reports every function). Reported: the code of each model's functions and of the whole set.

Peer, same flags and the same compiler in the same run: ``casadi.CodeGenerator`` C (with
``casadi_real`` float) of the same five expression functions (rhs, outputs, jac_x, jac_u, jac_p)
of the emitted CasADi module. Compared: the code that evaluates them (gearsym: the five functions
and their helpers; CasADi: its evaluation functions, wrappers and helpers, without the API
boilerplate (name, sparsity, work-size queries) and sparsity tables it also emits; gearsym's
five are rhs, outputs and the three Jacobians, i.e. their sparse functions, which hold the
expressions, and the dense ones, which spread them, without the pattern tables). Target:
gearsym no larger for every model of the gearbox. The sensitivity systems (3.7) are reported
without a target (before the sparse Jacobians theirs compiled about 20 % larger than CasADi's;
now about 30 % smaller).
"""

from __future__ import annotations

import re
import shutil
import sys
import tempfile
from pathlib import Path

from codegen_peers import EXPR_FUNCTIONS, casadi_c, casadi_module, run, write_tree
from record import Target, begin, record, row

FLAGS = (
    "-mcpu=cortex-m4",
    "-mfpu=fpv4-sp-d16",
    "-mfloat-abi=hard",
    "-mthumb",
    "-DGEARSYM_SINGLE_PRECISION",
    "-O2",
    "-ffunction-sections",
    "-fdata-sections",
)
#: The sparse Jacobians hold the expression code; the dense ones spread their values.
SPARSE = ("jac_x_sparse", "jac_u_sparse", "jac_p_sparse")
_BOILERPLATE = re.compile(
    r"_(checkout|release|incref|decref|n_in|n_out|default_in|name_in|name_out|sparsity_in|"
    r"sparsity_out|work|work_bytes|casadi_version|casadi_int_size|casadi_real_size)$"
)


def sections(obj: Path) -> dict[str, int]:
    """Section name -> size of an object (``arm-none-eabi-size -A``)."""
    result = {}
    for line in run(["arm-none-eabi-size", "-A", str(obj)]).splitlines()[2:]:
        parts = line.split()
        if len(parts) == 3 and parts[1].isdigit():
            result[parts[0]] = int(parts[1])
    return result


def compile_m4(source: Path, include: Path) -> dict[str, int]:
    obj = source.with_suffix(".m4.o")
    run(["arm-none-eabi-gcc", *FLAGS, "-I", str(include), "-c", str(source), "-o", str(obj)])
    return sections(obj)


def code(secs: dict[str, int]) -> int:
    return sum(v for k, v in secs.items() if k.startswith(".text"))


def main() -> int:
    if shutil.which("arm-none-eabi-gcc") is None:
        print("arm-none-eabi-gcc is not installed (apt-get install gcc-arm-none-eabi)")
        return 1
    started = begin()
    rows = []
    ok = True
    print(f"Cortex-M4F object code, bytes of .text (arm-none-eabi-gcc {' '.join(FLAGS[:6])})")
    with tempfile.TemporaryDirectory(prefix="gearsym-bench-") as tmp:
        out = Path(tmp)
        models = write_tree(out)
        c_dir = out / "c"
        total = 0
        for source in sorted(c_dir.glob("*.c")):
            if source.name == "main.c":
                continue
            secs = compile_m4(source, c_dir)
            total += code(secs)
            if source.stem == "gearsym_mu_map":
                rodata = sum(v for k, v in secs.items() if k.startswith(".rodata"))
                print(f"  {'mu_map':<14} all {code(secs):6d} (+ {rodata} bytes of tables)")
                rows.append(row(f"μ map: all its code (+ {rodata} B of tables)", code(secs), "B"))
                continue
            name = source.stem.removeprefix("gearsym_")
            prefix = f".text.gearsym_{name}_"
            ours = sum(
                v
                for k, v in secs.items()
                if k.startswith(prefix)
                and k[len(prefix) :] in (*EXPR_FUNCTIONS, *SPARSE, "sign", "heaviside")
            )
            module = casadi_module(out, name)
            if not set(EXPR_FUNCTIONS) <= set(module.functions()):
                # hybrid sensitivities, linear forms, the UIO: no rhs/outputs/Jacobians of its own
                print(f"  {name:<17} all {code(secs):6d} | no {', '.join(EXPR_FUNCTIONS)}: no peer")
                rows.append(row(f"`{name}`: all its code (no peer)", code(secs), "B"))
                continue
            peer_source = casadi_c(module, EXPR_FUNCTIONS, out / "peer", f"cas_{name}", "float")
            peer = compile_m4(peer_source, peer_source.parent)
            theirs = sum(
                v for k, v in peer.items() if k.startswith(".text.") and not _BOILERPLATE.search(k)
            )
            met = ours <= theirs
            sensitivity = name.endswith("_sens")
            if not sensitivity:
                ok &= met
            verdict = "met" if met else "MISSED"
            print(
                f"  {name:<17} all {code(secs):6d} | 5 expression functions: gearsym {ours:6d}, "
                f"CasADi {theirs:6d} ({code(peer):6d} with its API): {theirs / ours:4.2f}x | "
                + (
                    f"sensitivity system, reported only: {verdict}"
                    if sensitivity
                    else f"target no larger: {verdict}"
                )
            )
            rows.append(
                row(
                    f"`{name}`: rhs, outputs and the three Jacobians (sparse and dense), "
                    f".text (the whole object: {code(secs)} B)",
                    ours,
                    "B",
                    peer=f"CasADi `CodeGenerator` C, float ({code(peer)} B with its API)",
                    peer_value=theirs,
                    target=None if sensitivity else Target("no larger", "ratio", "<=", 1.0),
                )
            )
        print(f"  all {len(models)} models and the mu map: {total} bytes of code")
        rows.append(row(f"all {len(models)} models and the μ map: all code", total, "B"))
    record(__file__, rows, started=started, title="Cortex-M4F object code against CasADi")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
