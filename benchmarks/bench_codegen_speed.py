"""Time per call of the emitted C against CasADi's and SymForce's generated code.

Functions (the built-in gearbox): ``rhs`` and ``jac_x`` of the full model (2.53) and of the 2-3
shift model with normal-force inputs, and ``rhs`` and ``jac_x`` of that shift's 24-state
sensitivity system (3.7). gearsym: the emitted ``gearsym_<model>_rhs`` and
``gearsym_<model>_jac_x_sparse`` (the structural nonzeros; CasADi and SymForce write theirs
too). Peers (:mod:`codegen_peers`), built in the same run from the raw SymPy right-hand side
with their own AD and CSE, never from gearsym's expressions: ``casadi.CodeGenerator`` C of an SX
``Function`` with ``cse`` on; SymForce 0.12 C++ (symengine backend, Eigen types, sparse output
for the Jacobians), skipped with a printed reason if SymForce or Eigen is missing.

Method: each implementation is compiled as its own translation unit (no inlining into the
timing loop) by the same gcc/g++ with the same flags, ``-O2`` and ``-O3 -march=native`` (the
latter twice: with ``-ffp-contract=off`` and ``=fast`` for every unit, since g++ would
otherwise contract into FMAs where gcc -std=c99 does not) and ``-DNDEBUG`` (Eigen's index
checks off, as in a release build); one C++ program times all of them. Inputs: 256 random
points (states, inputs and parameters uniform in the physical ranges of
``gearsym.symbolic.export.generate.sample_ranges`` and the parameter bounds, so the road grade is
not 0 and sin/cos leave their fast paths), cycled through call by call. Each round
times every implementation over the same number of calls (about 4 ms), in an order rotated
from round to round; reported: the median over the rounds and the min-max spread. Before
timing, the three results at one point are compared (the Jacobians spread by their own
patterns). Operation counts: gearsym's stated count, CasADi's arithmetic instructions,
SymForce's "Total ops" (three different ways of counting: shown, not compared). Target:
gearsym's median at most 1.0x each peer's, for every function and every flag set.
"""

from __future__ import annotations

import re
import statistics
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from codegen_peers import (
    Problem,
    casadi_operations,
    casadi_peer_c,
    gearsym_operations,
    run,
    symforce_available,
    symforce_peer,
    write_tree,
)
from gearsym.symbolic.codegen import build_function_table
from gearsym.symbolic.export.generate import sample_ranges, sensitivity_parameters
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks.c_check import sample_points
from record import Target, begin, record, row

#: ``-ffp-contract``: g++ (the SymForce peer) contracts a*b + c into FMA instructions by
#: default, gcc in ISO C mode (gearsym's and CasADi's -std=c99) does not; with -march=native
#: (FMA available) every translation unit gets the same policy, once off, once fast.
FLAG_SETS = (
    ("-O2",),
    ("-O3", "-march=native", "-ffp-contract=off"),
    ("-O3", "-march=native", "-ffp-contract=fast"),
)
ROUNDS = 11
POINTS = 256  # a power of two: the loop picks point i & (POINTS - 1)
SECONDS_PER_TIMING = 0.004
EIGEN = "/usr/include/eigen3"
IMPLEMENTATIONS = ("gearsym", "CasADi", "SymForce")
#: The table's words for each emitted model, and how each peer counts its operations.
MODEL_WORDS = {
    "full": "full model",
    "shift_2_3_mu": "2-3 shift",
    "shift_2_3_mu_sens": "2-3 sensitivity system (24 states)",
}
FUNCTION_WORDS = {"rhs": "`rhs`", "jac_x": "`jac_x` (its structural nonzeros)"}
PEER_WORDS = {
    "CasADi": "CasADi `CodeGenerator` C ({ops} arithmetic instructions)",
    "SymForce": "SymForce C++ ({ops} ops, its count)",
}


@dataclass
class Case:
    """One problem with everything the harness needs."""

    problem: Problem
    nx: int  # state of the timed system
    nu: int
    np: int
    n_out: dict[str, int]  # output entries per implementation
    points: tuple[np.ndarray, np.ndarray, np.ndarray]
    casadi: Any  # the casadi.Function
    casadi_ops: int
    ours_ops: int
    patterns: dict[str, tuple[list[int], list[int]]]  # implementation -> (colptr, rowind)
    parameter_fields: list[str]  # of gearsym's parameter struct, in order
    symforce_name: str | None = None
    symforce_ops: int | None = None


def problems() -> tuple[list[Problem], dict]:
    d = load_description(None)
    from gearsym.symbolic.export.generate import gearbox_models

    models = {m.model.name: m for m in gearbox_models(d)}
    full, shift = models["full"], models["shift_2_3_mu"]
    chosen = tuple(sensitivity_parameters(d, shift.shift))
    result = [
        Problem("full_rhs", "full", "rhs", full.model),
        Problem("full_jac_x", "full", "jac_x", full.model),
        Problem("shift_rhs", "shift_2_3_mu", "rhs", shift.model),
        Problem("shift_jac_x", "shift_2_3_mu", "jac_x", shift.model),
        Problem("sens_rhs", "shift_2_3_mu_sens", "rhs", shift.model, chosen),
        Problem("sens_jac_x", "shift_2_3_mu_sens", "jac_x", shift.model, chosen),
    ]
    return result, models


def _ccs_from_header(text: str) -> tuple[list[int], list[int]]:
    colptr = re.search(r"kColPtrs_res\[\] = \{([^}]*)\}", text).group(1)
    rowind = re.search(r"kRowIndices_res\[\] = \{([^}]*)\}", text).group(1)
    return [int(v) for v in colptr.split(",")], [int(v) for v in rowind.split(",")]


def prepare(problem: Problem, models: dict, build: Path, symforce: bool) -> Case:
    emitted = models[problem.emitted]
    model = emitted.model
    nx, nu, npar = len(model.states), len(model.inputs), len(model.parameters)
    X, U, P = sample_points(model, POINTS, 1, emitted.bounds, sample_ranges(model))
    name = "rhs" if problem.function == "rhs" else "jac_x_sparse"
    table = build_function_table(model, emitted.config)
    n_out = {"gearsym": table[name].outputs[0].size}
    patterns = {}
    if problem.function != "rhs":
        pattern = table["jac_x"].pattern
        patterns["gearsym"] = (list(pattern.colptr), list(pattern.rowind))
    source, f = casadi_peer_c(problem, f"cas_{problem.label}", build)
    n_out["CasADi"] = f.sparsity_out(0).nnz()
    colind, rows = f.sparsity_out(0).get_ccs()
    patterns["CasADi"] = (list(colind), list(rows))
    case = Case(
        problem,
        nx,
        nu,
        npar,
        n_out,
        (X, U, P),
        f,
        casadi_operations(f),
        gearsym_operations(model, name, emitted.config),
        patterns,
        [v.name for v in model.parameters],
    )
    if symforce:
        header, cpp_name, ops = symforce_peer(problem, f"sf_{problem.label}", build)
        case.symforce_name, case.symforce_ops = cpp_name, ops
        if problem.function == "rhs":
            n_out["SymForce"] = nx
            patterns["SymForce"] = ([0, nx], list(range(nx)))
        else:
            patterns["SymForce"] = _ccs_from_header(header.read_text())
            n_out["SymForce"] = patterns["SymForce"][0][-1]
    if problem.function == "rhs":
        for impl in n_out:
            patterns.setdefault(impl, ([0, nx], list(range(nx))))
    return case


def _array(values: np.ndarray) -> str:
    rows = ["{" + ", ".join(repr(float(v)) for v in row) + "}" for row in values]
    return "{\n    " + ",\n    ".join(rows) + "\n}"


def harness_source(cases: list[Case], symforce: bool) -> str:
    """The C++ timing program (and the SymForce wrappers it calls, one translation unit each)."""
    parts = [
        "#include <chrono>",
        "#include <cstdio>",
        "#include <cstdlib>",
    ]
    if symforce:  # Eigen is SymForce's, needed (and present) only when SymForce runs
        parts += ["#include <Eigen/Core>", "#include <Eigen/SparseCore>"]
    for case in cases:
        parts.append(f'#include "gearsym_{case.problem.emitted}.h"')
        parts.append(f'#include "cas_{case.problem.label}.h"')
    parts += [
        "static double sink = 0.0;",
        "static void show(int k, const char *impl, const double *v, int n) {",
        '    printf("V %d %s", k, impl);',
        '    for (int e = 0; e < n; ++e) printf(" %.17g", v[e]);',
        '    printf("\\n");',
        "}",
        "static double now() {",
        "    return std::chrono::duration<double>(",
        "        std::chrono::steady_clock::now().time_since_epoch()).count();",
        "}",
    ]
    main = ["int main(int argc, char **argv) {", "    const int rounds = atoi(argv[1]);"]
    for k, case in enumerate(cases):
        p = case.problem
        label = p.label
        X, U, P = case.points
        fn = p.c_function
        params = f"gearsym_{p.emitted}_params"
        nx, nu, npar = case.nx, case.nu, case.np
        n_sf = case.n_out.get("SymForce", 0)
        sparse_out = "Eigen::SparseMatrix<double>"
        sf_out = f"Eigen::Matrix<double, {n_sf}, 1>" if p.function == "rhs" else sparse_out
        sf_first = f"out_sf_{k}(0)" if p.function == "rhs" else f"out_sf_{k}.valuePtr()[0]"
        cas = case.casadi
        parts += [
            f"static const double X_{k}[{POINTS}][{nx}] = {_array(X)};",
            f"static const double U_{k}[{POINTS}][{nu}] = {_array(U)};",
            f"static const double P_{k}[{POINTS}][{npar}] = {_array(P)};",
            f"static {params} PS_{k}[{POINTS}];",
            f"static double out_ours_{k}[{case.n_out['gearsym']}];",
            f"static double out_cas_{k}[{case.n_out['CasADi']}];",
            f"static double w_{k}[{cas.sz_w() + 1}];",
            f"static casadi_int iw_{k}[{cas.sz_iw() + 1}];",
            f"static double time_ours_{k}(long n) {{",
            "    double t0 = now();",
            "    for (long i = 0; i < n; ++i) {",
            f"        const long j = i & {POINTS - 1};",
            f"        {fn}(X_{k}[j], U_{k}[j], &PS_{k}[j], out_ours_{k});",
            f"        sink += out_ours_{k}[0];",
            "    }",
            "    return (now() - t0) / (double)n;",
            "}",
            f"static double time_cas_{k}(long n) {{",
            f"    const double *arg[{cas.sz_arg() + 1}];",
            f"    double *res[{cas.sz_res() + 1}];",
            "    double t0 = now();",
            f"    res[0] = out_cas_{k};",
            "    for (long i = 0; i < n; ++i) {",
            f"        const long j = i & {POINTS - 1};",
            f"        arg[0] = X_{k}[j]; arg[1] = U_{k}[j]; arg[2] = P_{k}[j];",
            f"        cas_{label}(arg, res, iw_{k}, w_{k}, 0);",
            f"        sink += out_cas_{k}[0];",
            "    }",
            "    return (now() - t0) / (double)n;",
            "}",
        ]
        if symforce:
            parts += [
                f"void sfw_{label}(const Eigen::Matrix<double, {nx}, 1> &x, "
                f"const Eigen::Matrix<double, {nu}, 1> &u, "
                f"const Eigen::Matrix<double, {npar}, 1> &p, {sf_out} *res);",
                f"static Eigen::Matrix<double, {nx}, 1> XS_{k}[{POINTS}];",
                f"static Eigen::Matrix<double, {nu}, 1> US_{k}[{POINTS}];",
                f"static Eigen::Matrix<double, {npar}, 1> PV_{k}[{POINTS}];",
                f"static {sf_out} out_sf_{k};",
                f"static double time_sf_{k}(long n) {{",
                "    double t0 = now();",
                "    for (long i = 0; i < n; ++i) {",
                f"        const long j = i & {POINTS - 1};",
                f"        sfw_{label}(XS_{k}[j], US_{k}[j], PV_{k}[j], &out_sf_{k});",
                f"        sink += {sf_first};",
                "    }",
                "    return (now() - t0) / (double)n;",
                "}",
            ]
        sf_values = f"out_sf_{k}.data()" if p.function == "rhs" else f"out_sf_{k}.valuePtr()"
        main += [
            "    {",
            "        int j, e, r, s;",
            f"        for (j = 0; j < {POINTS}; ++j) {{",
            *[
                f"            PS_{k}[j].{v} = P_{k}[j][{e}];"
                for e, v in enumerate(case.parameter_fields)
            ],
            *(
                [
                    f"            for (e = 0; e < {nx}; ++e) XS_{k}[j](e) = X_{k}[j][e];",
                    f"            for (e = 0; e < {nu}; ++e) US_{k}[j](e) = U_{k}[j][e];",
                    f"            for (e = 0; e < {npar}; ++e) PV_{k}[j](e) = P_{k}[j][e];",
                ]
                if symforce
                else []
            ),
            "        }",
            "        /* the results at point 0, for the comparison, and a warm-up */",
            f"        time_ours_{k}(1); time_cas_{k}(1);",
            *([f"        time_sf_{k}(1);"] if symforce else []),
            f'        show({k}, "gearsym", out_ours_{k}, {case.n_out["gearsym"]});',
            f'        show({k}, "CasADi", out_cas_{k}, {case.n_out["CasADi"]});',
            *(
                [f'        show({k}, "SymForce", {sf_values}, {case.n_out.get("SymForce", 0)});']
                if symforce
                else []
            ),
            "        double t = time_ours_" + str(k) + "(2000);",
            f"        long n = (long)({SECONDS_PER_TIMING} / (t > 1e-10 ? t : 1e-10));",
            "        if (n < 2000) n = 2000;",
            f"        const int impls = {3 if symforce else 2};",
            "        for (r = 0; r < rounds; ++r) {",
            "            for (s = 0; s < impls; ++s) {",
            "                const int which = (r + s) % impls;",
            f"                double ns = 1e9 * (which == 0 ? time_ours_{k}(n) : "
            + (
                f"which == 1 ? time_cas_{k}(n) : time_sf_{k}(n));"
                if symforce
                else f"time_cas_{k}(n));"
            ),
            f'                printf("T {k} %d %d %.4f\\n", which, r, ns);',
            "            }",
            "        }",
            "    }",
        ]
    main += ['    printf("sink %g\\n", sink);', "    return 0;", "}"]
    return "\n".join(parts + main) + "\n"


def symforce_wrapper(case: Case) -> str:
    p = case.problem
    out = (
        f"Eigen::Matrix<double, {case.nx}, 1>"
        if p.function == "rhs"
        else "Eigen::SparseMatrix<double>"
    )
    return "\n".join(
        [
            f'#include "sf_{p.label}.h"',
            f"void sfw_{p.label}(const Eigen::Matrix<double, {case.nx}, 1> &x, "
            f"const Eigen::Matrix<double, {case.nu}, 1> &u, "
            f"const Eigen::Matrix<double, {case.np}, 1> &p, {out} *res) {{",
            f"    sym::{case.symforce_name}<double>(x, u, p, res);",
            "}",
            "",
        ]
    )


def _dense(values: list[float], pattern: tuple[list[int], list[int]], rows: int) -> np.ndarray:
    colptr, rowind = pattern
    dense = np.zeros((rows, len(colptr) - 1))
    for j in range(len(colptr) - 1):
        for k in range(colptr[j], colptr[j + 1]):
            dense[rowind[k], j] = values[k]
    return dense


def build_and_run(
    cases: list[Case], build: Path, c_dir: Path, flags: tuple[str, ...], symforce: bool
) -> dict[int, dict[int, list[float]]]:
    tag = "_".join(f.strip("-").replace("=", "") for f in flags)
    folder = build / tag
    folder.mkdir(parents=True, exist_ok=True)
    common = [*flags, "-DNDEBUG", "-I", str(c_dir), "-I", str(build)]
    if symforce:
        common += ["-I", EIGEN]
    objects = []
    emitted = sorted({c.problem.emitted for c in cases})
    sources = [(c_dir / f"gearsym_{e}.c", "c") for e in emitted]
    sources += [(build / f"cas_{c.problem.label}.c", "c") for c in cases]
    if symforce:
        for c in cases:
            wrapper = build / f"sfw_{c.problem.label}.cc"
            wrapper.write_text(symforce_wrapper(c))
            sources.append((wrapper, "c++"))
    harness = build / "harness.cc"
    harness.write_text(harness_source(cases, symforce))
    sources.append((harness, "c++"))
    for source, language in sources:
        obj = folder / (source.stem + ".o")
        compiler = ["gcc", "-std=c99"] if language == "c" else ["g++", "-std=c++17"]
        run([*compiler, *common, "-c", str(source), "-o", str(obj)])
        objects.append(str(obj))
    exe = folder / "harness"
    run(["g++", *objects, "-o", str(exe), "-lm"])
    output = run([str(exe), str(ROUNDS)])
    times: dict[int, dict[int, list[float]]] = {}
    values: dict[int, dict[str, list[float]]] = {}
    for line in output.splitlines():
        fields = line.split()
        if fields[0] == "T":
            k, which, _, ns = int(fields[1]), int(fields[2]), int(fields[3]), float(fields[4])
            times.setdefault(k, {}).setdefault(which, []).append(ns)
        elif fields[0] == "V":
            values.setdefault(int(fields[1]), {})[fields[2]] = [float(v) for v in fields[3:]]
    for k, case in enumerate(cases):  # the implementations compute the same thing
        ref = _dense(values[k]["gearsym"], case.patterns["gearsym"], case.nx)
        for impl, got in values[k].items():
            dense = _dense(got, case.patterns[impl], case.nx)
            scale = max(float(np.abs(ref).max()), 1e-300)
            if not np.allclose(dense, ref, rtol=1e-9, atol=1e-12 * scale):
                raise RuntimeError(f"{case.problem.label}: {impl} differs from gearsym")
    return times


def main() -> int:
    started = begin()
    rows = []
    reason = symforce_available()
    symforce = reason is None
    if not symforce:
        print(f"SymForce skipped: {reason}")
    ok = True
    with tempfile.TemporaryDirectory(prefix="gearsym-bench-") as tmp:
        out = Path(tmp)
        write_tree(out)
        items, models = problems()
        build = out / "bench"
        build.mkdir()
        cases = [prepare(p, models, build, symforce) for p in items]
        print(
            f"time per call: median of {ROUNDS} rotated rounds [min-max], {POINTS} random points "
            f"in physical ranges; gcc/g++ {sys.platform}"
        )
        for flags in FLAG_SETS:
            times = build_and_run(cases, build, out / "c", flags, symforce)
            print(f"{' '.join(flags)}:")
            for k, case in enumerate(cases):
                p = case.problem
                stats = {
                    IMPLEMENTATIONS[w]: (statistics.median(v), min(v), max(v))
                    for w, v in times[k].items()
                }
                ours = stats["gearsym"][0]
                text = (
                    f"  {p.function:<5} {p.emitted:<17} gearsym {ours:7.1f} ns "
                    f"[{stats['gearsym'][1]:.1f}-{stats['gearsym'][2]:.1f}], {case.ours_ops} ops"
                )
                met = True
                peers = [("CasADi", case.casadi_ops)]
                if symforce:
                    peers.append(("SymForce", case.symforce_ops))
                for impl, ops in peers:
                    median, lo, hi = stats[impl]
                    ratio = ours / median
                    met &= ratio <= 1.0
                    rows.append(
                        row(
                            f"{FUNCTION_WORDS[p.function]} of the {MODEL_WORDS[p.emitted]}, gcc "
                            f"`{' '.join(flags)}` ({case.ours_ops} operations stated)",
                            unit="ns",
                            samples=times[k][0],
                            peer=PEER_WORDS[impl].format(ops=ops),
                            peer_samples=times[k][IMPLEMENTATIONS.index(impl)],
                            target=Target("≤ 1.0× each peer", "ratio", "<=", 1.0),
                        )
                    )
                    text += (
                        f" | {impl} {median:7.1f} ns [{lo:.1f}-{hi:.1f}], {ops} ops: "
                        f"ours/{impl} {ratio:4.2f}"
                    )
                ok &= met
                print(text + f" | target <= 1.0: {'met' if met else 'MISSED'}")
    title = "Emitted C against CasADi" + (" and SymForce" if symforce else "")
    record(__file__, rows, started=started, title=f"{title}: time per call")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
