"""Time per right-hand-side call of the emitted C against CasADi's own generated C and SymPy.

For the full model and the 2-3 shift model (normal-force inputs) of the built-in gearbox:

* the emitted ``gearsym_<model>_rhs`` against ``casadi.CodeGenerator`` C of the emitted CasADi
  module's ``rhs`` (the same CSE'd expressions), both compiled by the same gcc with the same
  flags (``-O2 -std=c99``, separate translation units, so neither call can be inlined into the
  timing loop), timed in the same C program, alternating, best of 7 rounds. Target: no slower
  (within 5 % timing noise) with no more operations (gearsym's stated count against CasADi's
  arithmetic instructions);
* against ``sympy.lambdify`` of the model's right-hand side (``modules="math"``, ``cse=True``,
  scalar calls from Python): reported, no target.
"""

from __future__ import annotations

import sys
import tempfile
import timeit
from pathlib import Path

import sympy as sp
from codegen_peers import (
    casadi_c,
    casadi_module,
    casadi_operations,
    gearsym_operations,
    run,
    write_tree,
)

MODELS = ("full", "shift_2_3_mu")
FLAGS = ("-O2", "-std=c99")
CALLS = 2_000_000
ROUNDS = 7
NOISE = 1.05  # "no slower" allows 5 % timing noise on a shared machine

HARNESS = """\
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "gearsym_{model}.h"
#include "cas_{model}.h"

static double now(void)
{{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}}

int main(int argc, char **argv)
{{
    long n = argc > 1 ? atol(argv[1]) : 1000000L;
    double x[{nx}] = {{ {x} }};
    double u[{nu}] = {{ {u} }};
    double pv[{np}] = {{ {p} }};
    double out[{nx}];
    double w[{sz_w} + 1];
    casadi_int iw[{sz_iw} + 1];
    const double *arg[3];
    double *res[1];
    gearsym_{model}_params p;
    double best_ours = 1e30, best_casadi = 1e30, sink = 0.0;
    long i;
    int round;

    arg[0] = x; arg[1] = u; arg[2] = pv; res[0] = out;
    gearsym_{model}_params_default(&p);
    for (round = 0; round < {rounds}; ++round) {{
        double t0 = now();
        for (i = 0; i < n; ++i) {{
            x[0] += 1e-12;
            gearsym_{model}_rhs(x, u, &p, out);
            sink += out[0];
        }}
        double t1 = now();
        for (i = 0; i < n; ++i) {{
            x[0] += 1e-12;
            cas_{model}_rhs(arg, res, iw, w, 0);
            sink += out[0];
        }}
        double t2 = now();
        if (t1 - t0 < best_ours) best_ours = t1 - t0;
        if (t2 - t1 < best_casadi) best_casadi = t2 - t1;
    }}
    printf("%.6e %.6e %g\\n", best_ours / (double)n, best_casadi / (double)n, sink);
    return 0;
}}
"""


def c_timings(out: Path, model_name: str, emitted: object) -> tuple[float, float, int, int]:
    """(ns per call emitted, ns per call CasADi, ops emitted, ops CasADi)."""
    module = casadi_module(out, model_name)
    build = out / "bench" / model_name
    casadi_source = casadi_c(module, ("rhs",), build, f"cas_{model_name}", "double")
    rhs = module.functions()["rhs"]
    model = emitted.model  # type: ignore[attr-defined]
    defaults = [float(v.default) for v in model.parameters]
    x = [100.0 + 10.0 * k for k in range(len(model.states))]
    u = [50.0 * (k + 1) for k in range(len(model.inputs))]
    harness = build / "harness.c"
    harness.write_text(
        HARNESS.format(
            model=model_name,
            nx=len(model.states),
            nu=len(model.inputs),
            np=len(model.parameters),
            x=", ".join(map(repr, x)),
            u=", ".join(map(repr, u)),
            p=", ".join(map(repr, defaults)),
            sz_w=rhs.sz_w(),
            sz_iw=rhs.sz_iw(),
            rounds=ROUNDS,
        )
    )
    sources = [harness, out / "c" / f"gearsym_{model_name}.c", casadi_source]
    objects = []
    for source in sources:
        obj = build / (source.stem + ".o")
        run(
            [
                "gcc",
                *FLAGS,
                "-I",
                str(out / "c"),
                "-I",
                str(build),
                "-c",
                str(source),
                "-o",
                str(obj),
            ]
        )
        objects.append(str(obj))
    exe = build / "harness"
    run(["gcc", *objects, "-o", str(exe), "-lm"])
    ours, theirs, _ = run([str(exe), str(CALLS)]).split()
    return (
        float(ours) * 1e9,
        float(theirs) * 1e9,
        gearsym_operations(model, "rhs"),
        casadi_operations(rhs),
    )


def lambdify_time(emitted: object) -> float:
    """ns per scalar call of sympy.lambdify(..., modules="math", cse=True)."""
    model = emitted.model  # type: ignore[attr-defined]
    args = [*model.state_symbols, *model.input_symbols, *model.parameter_symbols]
    f = sp.lambdify(args, list(model.rhs), modules="math", cse=True)
    values = [100.0 + 10.0 * k for k in range(len(model.states))]
    values += [50.0 * (k + 1) for k in range(len(model.inputs))]
    values += [float(v.default) for v in model.parameters]
    n = 20_000
    times = timeit.repeat(lambda: f(*values), number=n, repeat=5)
    return min(times) / n * 1e9


def main() -> int:
    ok = True
    print(f"time per rhs call (best of {ROUNDS} rounds of {CALLS} calls; gcc {' '.join(FLAGS)})")
    with tempfile.TemporaryDirectory(prefix="gearsym-bench-") as tmp:
        out = Path(tmp)
        models = write_tree(out)
        for name in MODELS:
            ours, theirs, ops_ours, ops_theirs = c_timings(out, name, models[name])
            lam = lambdify_time(models[name])
            fast = ours <= NOISE * theirs
            lean = ops_ours <= ops_theirs
            ok &= fast and lean
            print(
                f"  {name:<13} emitted C {ours:6.1f} ns, {ops_ours} ops | CasADi C "
                f"{theirs:6.1f} ns, {ops_theirs} ops: {theirs / ours:4.2f}x | lambdify "
                f"{lam / 1000:6.2f} us: "
                f"{lam / ours:6.0f}x | target no slower, ops <=: "
                f"{'met' if fast and lean else 'MISSED'}"
            )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
