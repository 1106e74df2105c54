"""The EKF benchmark compares one filter (benchmarks/bench_ekf.py): the FilterPy peer and the
CasADi step give the emitted C's estimates.

Expected values: the emitted C in double (itself checked against the project's NumPy reference
filter here and step by step in tests/test_ekf_c.py); the peers are independent routes to the
same filter (FilterPy's own predict/update with SymPy-lambdified NumPy functions; CasADi's AD
of the RK4 step). Equal in exact arithmetic (module text of benchmarks/ekf_peers.py: batch =
sequential update for linear outputs and diagonal R; a consider state = the optimal update with
its estimate and covariance block restored, H not seeing it), so the limit is rounding: 1e-10
of each quantity's scale over the 150 steps. And the comparison can tell: FilterPy's plain
update, which corrects the frozen μ, differs by far more.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import ekf_peers  # noqa: E402

LIMIT = 1e-10


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    seq = ekf_peers.sequence()
    build = ekf_peers.build_driver(seq, tmp_path_factory.mktemp("ekf_bench"))
    return seq, ekf_peers.c_values(build)


def test_the_emitted_c_follows_the_reference_filter(setup):
    seq, values = setup
    x, sigma = values["gearsym_double"]
    assert x.shape == (seq.steps, 8)
    diff = ekf_peers.scaled_difference(x, sigma, seq.reference[1:], seq.reference_sigma[1:])
    assert diff < LIMIT, diff


def test_filterpy_gives_the_emitted_estimates(setup):
    seq, values = setup
    ref = values["gearsym_double"]
    x, sigma = ekf_peers.FilterPyPeer(seq).run()
    assert ekf_peers.scaled_difference(x, sigma, *ref) < LIMIT
    # the mass moves over the shift (started 30 % light): the agreement is not of a still filter
    assert x[-1, 4] - seq.x1[4] > 200.0  # from 1260 kg (ekf_peers.sequence)


def test_the_comparison_tells_a_different_filter(setup):
    seq, values = setup
    x, sigma = ekf_peers.FilterPyPeer(seq, consider=False).run()
    assert ekf_peers.scaled_difference(x, sigma, *values["gearsym_double"]) > 1e-3


def test_casadi_step_gives_the_emitted_estimates(setup):
    seq, values = setup
    ref = values["gearsym_double"]
    assert ekf_peers.scaled_difference(*values["casadi_c_double"], *ref) < LIMIT
    assert ekf_peers.scaled_difference(*values["gearsym_float"], *ref) < 5e-4
