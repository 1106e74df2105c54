"""Deriving and integrating the sensitivities (3.5)–(3.7) of the default 2-3 shift.

Measured: the symbolic derivation (∂f/∂x, ∂f/∂p, augmented model, lambdify) and the integration
of [x; S] (24 states) for the thesis' five parameters along the reference shift. The peer,
measured in the same run on the same integrator and grid, is central finite differences: 2 m = 10
extra integrations of the 4-state model (plus its own lambdify). Target (issue 4: "reports the
time"): the sensitivities are at least as fast as the finite-difference peer.
"""

from __future__ import annotations

import statistics
import sys
import time

import sympy as sp
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.sensitivity import sensitivity_equations
from gearsym.validation.studies.driven_shift import (
    driven_shift_model,
    driving_inputs,
    initial_state,
    reference_data,
    sliding_masks,
)
from gearsym.validation.studies.sensitivity_integration import (
    CompiledModel,
    Interpolated,
    integrate_sensitivities,
    parameter_values,
)
from gearsym.validation.studies.sensitivity_peers import finite_difference_sensitivities
from record import Target, begin, record, row


def timed(fn, repeat: int = 3) -> tuple[list[float], object]:
    """Seconds of ``repeat`` runs (SymPy's cache cleared before each) and the last result."""
    times, result = [], None
    for _ in range(repeat):
        sp.core.cache.clear_cache()  # SymPy memoises; a warm cache would flatter repeat runs
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return times, result


def main() -> int:
    started = begin()
    d = load_description()
    print("sensitivities of the default 2-3 shift, 5 parameters (median of 3 runs)")
    start = time.perf_counter()
    data = reference_data(d)
    print(f"  {'reference simulation (not timed below)':<48}{time.perf_counter() - start:7.2f} s")
    driven = driven_shift_model(d)

    def derive():
        eqs = sensitivity_equations(driven.model)
        return eqs, CompiledModel(eqs.augmented)

    runs_derive, (eqs, compiled) = timed(derive)
    t_derive = statistics.median(runs_derive)
    values = parameter_values(driven.model)
    masks = sliding_masks(d, driven, data)
    inputs = Interpolated(data.t, driving_inputs(driven, data, masks, values))
    x0 = initial_state(driven.model, data)

    runs_integrate, _ = timed(
        lambda: integrate_sensitivities(eqs, inputs, x0, values, data.t, compiled=compiled)
    )
    t_integrate = statistics.median(runs_integrate)

    def peer():
        return finite_difference_sensitivities(
            driven.model, eqs.parameter_names, inputs, x0, values, data.t
        )

    runs_peer, _ = timed(peer, repeat=1)
    t_peer = statistics.median(runs_peer)
    ours = t_derive + t_integrate
    met = ours <= t_peer
    print(f"  {'derive ∂f/∂x, ∂f/∂p, [x; S] model, CasADi functions':<48}{t_derive:7.2f} s")
    label = f"integrate [x; S] (24 states), {len(data.t)} samples"
    print(f"  {label:<48}{t_integrate:7.2f} s")
    print(
        f"  derive + integrate {ours:6.2f} s   finite differences (10 integrations) "
        f"{t_peer:6.2f} s   ratio {t_peer / ours:5.1f}x   target ≤ peer: "
        f"{'met' if met else 'MISSED'}"
    )
    what = "sensitivities of the default 2-3 shift (5 parameters, 24 states)"
    rows = [
        row(
            f"{what}: derive + integrate (the sum of the two medians below)",
            ours,
            "s",
            runs=len(runs_derive),
            peer="central finite differences, 10 integrations",
            peer_samples=runs_peer,
            target=Target("≤ peer", "ratio", "<=", 1.0),
        ),
        row(
            f"{what}: derive ∂f/∂x, ∂f/∂p, the [x; S] model, CasADi functions",
            unit="s",
            samples=runs_derive,
        ),
        row(f"{what}: integrate [x; S], {len(data.t)} samples", unit="s", samples=runs_integrate),
    ]
    record(__file__, rows, started=started, title="Sensitivities of the default 2-3 shift")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
