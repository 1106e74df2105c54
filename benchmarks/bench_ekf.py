"""ns per EKF step of the emitted C against the same filter in CasADi and in FilterPy, in one
run; operations per step against the issue's goal (≤ 600); host object code size.

The filter: the 2-3 shift EKF (thesis 4.1, 4.3; ``gearsym_ekf_2_3``), 8 states, 3 speeds,
10 ms, the default scenario's 150 steps with 1 % speed noise (seed 0); one step = predict with
the previous inputs + update with the three speeds. Implementations (:mod:`ekf_peers`):

* gearsym: the emitted ``ekf_predict`` + ``ekf_update``, double and float
  (``-DGEARSYM_SINGLE_PRECISION``), called in a C loop;
* CasADi 3.8: one ``casadi.Function`` of the whole step built from the emitted CasADi module's
  ``rhs``/``outputs`` with CasADi's AD for F and H and ``cse``; timed called from Python
  (NumPy rows in, DM carried from step to step) and as ``CodeGenerator`` C (double and float)
  in the same C loop;
* FilterPy 2.0 ``ExtendedKalmanFilter``: SymPy-lambdified NumPy f, ∂f/∂z, h, ∂h/∂z, the RK4
  step and its chain-rule Jacobian in NumPy, FilterPy's ``predict`` and batch ``update``.

Before timing, every implementation runs the sequence and its estimates and σ are compared
with the emitted C in double at every step (and that with the project's NumPy reference
filter); a disagreement stops the benchmark. C: each implementation its own translation unit,
same gcc and flags (``-O2``; ``-O3 -march=native``), one driver; each round times every
implementation over the same number of passes through the sequence, the order rotated from
round to round; reported: median ns per step over the rounds [min–max]. The Python-called
peers: one pass per round, rotated likewise. Operations: gearsym's count as stated in the
emitted header (ekf_predict + ekf_update, all three speeds used), CasADi's arithmetic
instructions of its step. Code size: ``size`` .text of each object, and ``nm -S`` of the
functions one step runs. Target: the issue's ≤ 600 operations per step.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from ekf_peers import (
    C_IMPLEMENTATIONS,
    Build,
    FilterPyPeer,
    Sequence,
    build_driver,
    c_values,
    casadi_step,
    run_casadi,
    run_cmd,
    scaled_difference,
    sequence,
    stated_operations,
    symbol_sizes,
    text_size,
)

FLAG_SETS = (("-O2",), ("-O3", "-march=native"))
ROUNDS = 11
PASSES = 40  # passes through the 150 steps per C timing (about 20 ms for the emitted C)
OPS_GOAL = 600
#: The largest scaled difference accepted against the emitted C in double, every step.
AGREE_DOUBLE = 1e-10
AGREE_FLOAT = 5e-4  # 150 steps of float rounding (measured about 5e-5)
#: The functions one emitted step runs (ekf_predict, with f and jac_x inlined, ekf_update and
#: the outputs it calls).
STEP_FUNCTIONS = ("ekf_predict", "ekf_update", "outputs")


def check_agreement(
    seq: Sequence, build: Build, cas_step: Any, peer: FilterPyPeer
) -> dict[str, float]:
    """Largest scaled difference of each implementation from the emitted C in double."""
    values = c_values(build)
    ref = values["gearsym_double"]
    diffs = {
        "gearsym double vs NumPy reference": scaled_difference(
            *ref, seq.reference[1:], seq.reference_sigma[1:]
        )
    }
    for impl in ("gearsym_float", "casadi_c_double", "casadi_c_float"):
        diffs[impl] = scaled_difference(*values[impl], *ref)
    diffs["casadi_python"] = scaled_difference(*run_casadi(cas_step, seq), *ref)
    diffs["filterpy"] = scaled_difference(*peer.run(), *ref)
    for impl, diff in diffs.items():
        limit = AGREE_FLOAT if impl.endswith("float") else AGREE_DOUBLE
        if not diff < limit:
            raise RuntimeError(f"{impl} differs from the emitted C (double): {diff:.3g}")
    return diffs


def time_c(build: Build, rounds: int) -> dict[str, list[float]]:
    times: dict[str, list[float]] = {name: [] for name in C_IMPLEMENTATIONS}
    for line in run_cmd([str(build.exe), "time", str(rounds), str(PASSES)]).splitlines():
        fields = line.split()
        if fields[0] == "T":
            times[C_IMPLEMENTATIONS[int(fields[1])]].append(float(fields[3]))
    return times


def time_python(
    seq: Sequence, cas_step: Any, peer: FilterPyPeer, rounds: int
) -> dict[str, list[float]]:
    u, y, p, h, q, r, fl = seq.u, seq.y, seq.p, seq.h, seq.q, seq.r, seq.floor

    def casadi_pass() -> float:
        x, P = seq.x1, seq.P1
        start = time.perf_counter()
        for k in range(1, len(u)):
            x, P, _ = cas_step(x, P, u[k - 1], u[k], y[k], p, h, q, r, fl)
        return time.perf_counter() - start

    def filterpy_pass() -> float:
        peer.reset()
        start = time.perf_counter()
        for k in range(1, len(u)):
            peer.step(k)
        return time.perf_counter() - start

    runners = {"CasADi from Python": casadi_pass, "FilterPy (NumPy, lambdified)": filterpy_pass}
    names = list(runners)
    times: dict[str, list[float]] = {name: [] for name in names}
    for name in names:  # warm-up
        runners[name]()
    for r in range(rounds):
        for s in range(len(names)):
            name = names[(r + s) % len(names)]
            times[name].append(1e9 * runners[name]() / seq.steps)
    return times


def code_sizes(build: Build) -> str:
    """``size`` .text of each object; for gearsym also the functions a step runs."""
    parts = []
    for name, obj in build.objects.items():
        text = f"{name} .text {text_size(obj)} B"
        if name.startswith("gearsym"):
            sizes = symbol_sizes(obj)
            prefix = "f32_" if name.endswith("float") else ""
            step = sum(sizes[f"{prefix}gearsym_ekf_2_3_{fn}"] for fn in STEP_FUNCTIONS)
            text += f" (the step's functions {step} B)"
        parts.append(text)
    return "; ".join(parts)


def _stats(values: list[float]) -> tuple[float, float, float]:
    return statistics.median(values), min(values), max(values)


def _ns(value: float) -> str:
    return f"{value:,.0f}".replace(",", " ")


def main() -> int:
    import casadi as ca
    import filterpy
    from codegen_peers import casadi_operations

    seq = sequence()
    with tempfile.TemporaryDirectory(prefix="gearsym-bench-ekf-") as tmp:
        out = Path(tmp)
        builds = {
            flags: build_driver(seq, out / "_".join(f.strip("-") for f in flags), flags)
            for flags in FLAG_SETS
        }
        first = builds[FLAG_SETS[0]]
        header = (first.exe.parent / "gearsym_ekf_2_3.h").read_text(encoding="utf-8")
        module_dir = first.exe.parent
        import importlib.util

        spec = importlib.util.spec_from_file_location(
            "gearsym_ekf_2_3_casadi", module_dir / "gearsym_ekf_2_3_casadi.py"
        )
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        cas_step = casadi_step(module, seq.aug)
        peer = FilterPyPeer(seq)
        diffs = check_agreement(seq, first, cas_step, peer)
        print(
            f"EKF 2-3 (8 states, 3 speeds, h = {seq.h * 1e3:g} ms), {seq.steps} steps of the "
            f"default shift, seed 0; CasADi {ca.__version__}, FilterPy {filterpy.__version__}"
        )
        print(
            "agreement with the emitted C (double), largest scaled difference over every step "
            "(estimates against |x| + σ, σ against σ): "
            + ", ".join(f"{k} {v:.1g}" for k, v in diffs.items())
        )
        python_times = time_python(seq, cas_step, peer, ROUNDS)
        c_times = {flags: time_c(build, ROUNDS) for flags, build in builds.items()}
        sizes = {flags: code_sizes(build) for flags, build in builds.items()}

    print(f"ns per step (predict + update), median of {ROUNDS} rotated rounds [min-max]:")
    for flags, times in c_times.items():
        stats = {name: _stats(v) for name, v in times.items()}
        ours_d, ours_f = stats["gearsym double"][0], stats["gearsym float"][0]
        print(f"  C, gcc -std=c99 {' '.join(flags)}:")
        for name, (median, lo, hi) in stats.items():
            ours = ours_d if name.endswith("double") else ours_f
            ratio = "" if name.startswith("gearsym") else f"   gearsym/peer {ours / median:4.2f}"
            print(f"    {name:<18} {median:8.1f} [{lo:.1f}-{hi:.1f}]{ratio}")
    ours_d = statistics.median(c_times[FLAG_SETS[0]]["gearsym double"])
    print("  called from Python (against the emitted C in double at -O2):")
    for name, values in python_times.items():
        median, lo, hi = _stats(values)
        print(
            f"    {name:<28} {_ns(median)} [{_ns(lo)}-{_ns(hi)}]   "
            f"gearsym/peer {ours_d / median:.4f} ({median / ours_d:,.0f}x slower)"
        )

    predict = stated_operations(header, "ekf_predict")
    update = stated_operations(header, "ekf_update")
    total = {k: predict[k] + update[k] for k in predict}
    ops = sum(total.values())
    met = ops <= OPS_GOAL
    print(
        f"operations per step (stated in the emitted header, all 3 speeds used): predict "
        f"{sum(predict.values())} + update {sum(update.values())} = {ops} ({total['add']} add, "
        f"{total['mul']} mul, {total['div']} div, {total['calls']} calls, {total['cmp']} cmp); "
        f"CasADi's step "
        f"function: {casadi_operations(cas_step)} arithmetic instructions"
    )
    print(f"  goal <= {OPS_GOAL}: {'met' if met else 'MISSED'}")
    for flags, text in sizes.items():
        print(f"host code size, x86-64 gcc {' '.join(flags)}: {text}")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
