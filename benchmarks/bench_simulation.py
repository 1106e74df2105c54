"""Wall time of the reference simulation of the default 2→3 shift and of deriving every shift
model of the built-in gearbox (issue 3).

Targets: the reference simulation (derivation of the reference model, compilation, Radau
integration, sampling, phase detection and energy audit; without the reduced-model checks)
under 5 s. The peer, measured in the same run, is the same integration with SciPy's
finite-difference Jacobian instead of the analytic one from SymPy. Deriving all adjacent shift
models (2.55-2.58) is reported beside deriving the full model once.
"""

from __future__ import annotations

import statistics
import sys
import time

import sympy as sp

from symbolic.description import load_description
from symbolic.drivetrain import adjacent_shifts, full_model, shift_model
from validation.simulate import simulate


def timed(fn, repeat: int = 3) -> tuple[float, object]:
    times, value = [], None
    for _ in range(repeat):
        sp.core.cache.clear_cache()  # a warm SymPy cache would flatter repeated runs
        start = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


def main() -> int:
    d = load_description()
    ok = True
    t_ours, result = timed(lambda: simulate(d, check_models=False))
    t_peer, peer = timed(lambda: simulate(d, check_models=False, analytic_jacobian=False), repeat=1)
    met = t_ours < 5.0
    ok &= met
    print("reference simulation of the default 2-3 shift (median of 3 runs)")
    print(
        f"  analytic Jacobian {t_ours:6.2f} s ({int(result.stats['nfev'])} f-calls)   "
        f"finite-difference Jacobian {t_peer:6.2f} s ({int(peer.stats['nfev'])} f-calls)   "
        f"ratio {t_peer / t_ours:5.2f}x   target < 5 s: {'met' if met else 'MISSED'}"
    )
    shifts = adjacent_shifts(d)
    t_shifts, _ = timed(lambda: [shift_model(d, s.name) for s in shifts])
    t_full, _ = timed(lambda: full_model(d))
    print(
        f"  deriving all {len(shifts)} adjacent shift models {t_shifts:6.2f} s; the full model "
        f"{t_full:6.2f} s; ratio {t_shifts / t_full:5.2f}x"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
