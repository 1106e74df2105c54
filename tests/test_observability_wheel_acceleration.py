"""Observability with the wheel acceleration measured (3.32).

Hand argument: ω̇_C is the first Lie derivative of the measured ω_C, so measuring it adds to
the rows of Q at order k only rows that Q without it has at order k + 1. Hence, for every k,
rank_without(k) ≤ rank_with(k) ≤ rank_without(k + 1): it can speed up the verdict by one order,
never change the final one. The default 2-3 shift stays at the full rank 8 of (4.12); on a level
road with constant inputs the rank stays 7 with the same kernel directions (φ, μ38, μ05, ζ), as
the README states.
"""

from __future__ import annotations

import pytest
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.observability import analyze_shift


@pytest.fixture(scope="module")
def d():
    return load_description()


def test_the_default_shift_stays_fully_observable(d):
    report = analyze_shift(d, with_wheel_acceleration=True, drop_search=False)
    assert report.result.rank == 8 and report.result.certain
    assert report.result.outputs == ("y_omega_1", "y_omega_2", "y_omega_C", "y_domega_C")


def test_level_road_rank_chain_and_the_same_kernel(d):
    common = dict(
        drop_search=False, input_models=["all=constant"], conditions=["zeta=0"], max_order=5
    )
    without = analyze_shift(d, **common).result
    with_acc = analyze_shift(d, with_wheel_acceleration=True, **common).result
    r0, r1 = without.rank_by_order, with_acc.rank_by_order
    for k in range(len(r1) - 1):
        assert r0[k] <= r1[k] <= r0[k + 1], k
    assert r1[0] > r0[0]  # ω̇_C is a new row at order 0: the chain can fail both ways
    assert without.rank == with_acc.rank == 7
    (kernel0,) = without.unobservable_directions
    (kernel1,) = with_acc.unobservable_directions
    assert set(kernel0) == set(kernel1) == {"phi", "mu_38", "mu_05", "zeta"}
