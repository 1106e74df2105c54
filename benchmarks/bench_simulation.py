"""Wall time of the reference simulation of the default 2→3 shift and of deriving every shift
model of the built-in gearbox.

The simulation (derivation of the reference model, translation to CasADi, integration,
sampling, phase detection and energy audit; without the reduced-model checks) with CVODES
(the default: BDF in C with CasADi's exact Jacobian) against the peers a numerics engineer
would try first, measured in the same run, in rotated order, medians with min–max: SciPy's
Radau with the same exact Jacobian, and Radau with SciPy's finite-difference Jacobian. Target
for the default: under 5 s (and the README states the ratio to Radau).
"""

from __future__ import annotations

import statistics
import sys
import time

import sympy as sp
from gearsym.symbolic.drivetrain import adjacent_shifts, full_model, shift_model
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.simulate import simulate
from record import Target, begin, record, row


def rotated(runs: dict, rounds: int = 3) -> dict[str, list[float]]:
    """Each candidate once per round, the order rotated every round (no warm-cache bias)."""
    names = list(runs)
    times: dict[str, list[float]] = {n: [] for n in names}
    for r in range(rounds):
        for name in names[r % len(names) :] + names[: r % len(names)]:
            sp.core.cache.clear_cache()  # a warm SymPy cache would flatter repeated runs
            start = time.perf_counter()
            runs[name]()
            times[name].append(time.perf_counter() - start)
    return times


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):6.2f} s [{min(values):.2f}–{max(values):.2f}]"


def main() -> int:
    started = begin()
    d = load_description()
    runs = {
        "CVODES (default)": lambda: simulate(d, check_models=False),
        "Radau, exact Jacobian": lambda: simulate(d, check_models=False, method="Radau"),
        "Radau, finite differences": lambda: simulate(
            d, check_models=False, method="Radau", analytic_jacobian=False
        ),
    }
    times = rotated(runs)
    ours = statistics.median(times["CVODES (default)"])
    met = ours < 5.0
    print("reference simulation of the default 2-3 shift (median [min–max] of 3 rotated runs)")
    for name, values in times.items():
        ratio = statistics.median(values) / ours
        print(f"  {name:<26} {spread(values)}   {ratio:5.2f}x the default")
    print(f"  target < 5 s: {'met' if met else 'MISSED'}")
    shifts = adjacent_shifts(d)
    t_shifts = rotated({"shifts": lambda: [shift_model(d, s.name) for s in shifts]}, 1)["shifts"]
    t_full = rotated({"full": lambda: full_model(d)}, 1)["full"]
    print(
        f"  deriving all {len(shifts)} adjacent shift models {t_shifts[0]:6.2f} s; the full "
        f"model {t_full[0]:6.2f} s"
    )
    what = "reference simulation of the default 2→3 shift (derive, translate, integrate, sample)"
    rows = [
        row(
            f"{what}, CVODES (the default)",
            unit="s",
            samples=times["CVODES (default)"],
            peer="SciPy Radau with the same exact Jacobian",
            peer_samples=times["Radau, exact Jacobian"],
            target=Target("< 5 s", "value", "<", 5.0),
        ),
        row(
            "the same, against Radau with finite differences",
            unit="s",
            samples=times["CVODES (default)"],
            peer="SciPy Radau, finite-difference Jacobian",
            peer_samples=times["Radau, finite differences"],
        ),
        row(
            f"derive all {len(shifts)} adjacent shift models",
            unit="s",
            samples=t_shifts,
            peer="the full model once",
            peer_samples=t_full,
        ),
    ]
    record(__file__, rows, started=started, title="Reference simulation and shift models")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
