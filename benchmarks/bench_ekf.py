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
from record import Target, begin, record, row

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
#: The table's words for each comparison of :func:`check_agreement`.
AGREEMENT_WORDS = {
    "gearsym double vs NumPy reference": "the emitted C in double against the NumPy reference",
    "gearsym_float": "the emitted C in float against it in double",
    "casadi_c_double": "CasADi's C in double against the emitted C in double",
    "casadi_c_float": "CasADi's C in float against the emitted C in double",
    "casadi_python": "CasADi called from Python against the emitted C in double",
    "filterpy": "FilterPy against the emitted C in double",
}


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


def code_size_numbers(build: Build) -> dict[str, tuple[int, int | None]]:
    """``size`` .text of each object and, for gearsym's, the bytes of the functions a step
    runs (``None`` for the peers)."""
    numbers = {}
    for name, obj in build.objects.items():
        step = None
        if name.startswith("gearsym"):
            sizes = symbol_sizes(obj)
            prefix = "f32_" if name.endswith("float") else ""
            step = sum(sizes[f"{prefix}gearsym_ekf_2_3_{fn}"] for fn in STEP_FUNCTIONS)
        numbers[name] = (text_size(obj), step)
    return numbers


def code_sizes(numbers: dict[str, tuple[int, int | None]]) -> str:
    """The printed line of :func:`code_size_numbers`."""
    parts = []
    for name, (text_bytes, step) in numbers.items():
        text = f"{name} .text {text_bytes} B"
        if step is not None:
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

    started = begin()
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
        size_numbers = {flags: code_size_numbers(build) for flags, build in builds.items()}
        sizes = {flags: code_sizes(numbers) for flags, numbers in size_numbers.items()}

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
    cas_ops = casadi_operations(cas_step)
    met = ops <= OPS_GOAL
    print(
        f"operations per step (stated in the emitted header, all 3 speeds used): predict "
        f"{sum(predict.values())} + update {sum(update.values())} = {ops} ({total['add']} add, "
        f"{total['mul']} mul, {total['div']} div, {total['calls']} calls, {total['cmp']} cmp); "
        f"CasADi's step "
        f"function: {cas_ops} arithmetic instructions"
    )
    print(f"  goal <= {OPS_GOAL}: {'met' if met else 'MISSED'}")
    for flags, text in sizes.items():
        print(f"host code size, x86-64 gcc {' '.join(flags)}: {text}")
    rows = agreement_rows(diffs)
    rows += timing_rows(c_times, python_times)
    rows.append(
        row(
            f"operations per EKF step as the emitted header states them (predict "
            f"{sum(predict.values())} + update {sum(update.values())}: {total['add']} add, "
            f"{total['mul']} mul, {total['div']} div, {total['calls']} calls, {total['cmp']} "
            "cmp; all 3 speeds used)",
            ops,
            "operations",
            peer="CasADi's step function, arithmetic instructions (counted differently)",
            peer_value=cas_ops,
            target=Target(f"≤ {OPS_GOAL}", "value", "<=", OPS_GOAL),
        )
    )
    rows += size_rows(size_numbers)
    record(__file__, rows, started=started, title="EKF step against CasADi and FilterPy")
    return 0 if met else 1


def agreement_rows(diffs: dict[str, float]) -> list[dict[str, Any]]:
    """The recorded agreement of each implementation (the benchmark stops before timing if
    one is over its limit)."""
    rows = []
    for impl, diff in diffs.items():
        limit = AGREE_FLOAT if impl.endswith("float") else AGREE_DOUBLE
        rows.append(
            row(
                f"agreement over every step (estimates against |x| + σ, σ against σ), largest "
                f"scaled difference: {AGREEMENT_WORDS[impl]}",
                diff,
                target=Target(f"< {limit:g}", "value", "<", limit),
            )
        )
    return rows


def timing_rows(
    c_times: dict[tuple[str, ...], dict[str, list[float]]],
    python_times: dict[str, list[float]],
) -> list[dict[str, Any]]:
    """ns per step of the emitted C against CasADi's C (same loop, same flags), and of the
    emitted C at -O2 against the peers called from Python; reported, no target."""
    rows = []
    for flags, times in c_times.items():
        for precision in ("double", "float"):
            rows.append(
                row(
                    f"EKF step (predict + update), emitted C in {precision} called in a C "
                    f"loop, gcc `{' '.join(flags)}`",
                    unit="ns",
                    samples=times[f"gearsym {precision}"],
                    peer=f"CasADi `CodeGenerator` C of the same step, {precision}",
                    peer_samples=times[f"CasADi C {precision}"],
                )
            )
    ours = c_times[FLAG_SETS[0]]["gearsym double"]
    for name, values in python_times.items():
        rows.append(
            row(
                f"EKF step, emitted C in double at `{' '.join(FLAG_SETS[0])}` against a peer "
                "called from Python",
                unit="ns",
                samples=ours,
                peer=name,
                peer_samples=values,
            )
        )
    return rows


def size_rows(numbers: dict[tuple[str, ...], dict[str, tuple[int, int | None]]]) -> list:
    """x86-64 .text of the emitted EKF against CasADi's C of the step; reported, no target."""
    rows = []
    for flags, sizes in numbers.items():
        for precision in ("double", "float"):
            text_bytes, step = sizes[f"gearsym {precision}"]
            rows.append(
                row(
                    f"host code of the EKF, x86-64 gcc `{' '.join(flags)}`, {precision}: "
                    f".text of the object (the step's functions {step} B)",
                    text_bytes,
                    "B",
                    peer=f"CasADi C of the step, {precision}",
                    peer_value=sizes[f"CasADi C {precision}"][0],
                )
            )
    return rows


if __name__ == "__main__":
    sys.exit(main())
