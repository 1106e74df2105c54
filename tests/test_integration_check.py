"""The emitted integrator steps and the emitted CasADi integrator against SciPy's Radau
(validation/checks/integration_check.py), on the committed generated/ code of the built-in
gearbox."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from gearsym.validation.checks.integration_check import IntegrationReport, integration_check

GENERATED = Path(__file__).resolve().parents[1] / "generated"


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> IntegrationReport:
    result = integration_check(
        root=GENERATED, build_dir=Path(tmp_path_factory.mktemp("build")), replay=True
    )
    print("\n".join(result.lines()))
    return result


def test_rk4_step_converges_with_order_four(report: IntegrationReport) -> None:
    orders = report.orders(report.rk4)
    assert len(orders) == 4
    assert all(3.9 < order < 4.1 for order in orders), orders
    assert report.rk4[-1].h == 0.001 and report.rk4[-1].error_double < 2e-6


def test_single_precision_steps_reach_the_float_floor(report: IntegrationReport) -> None:
    # Same errors as double while the truncation error dominates, then float rounding (~1e-7 of
    # the speeds, accumulated over the steps) sets a floor.
    for row in report.rk4:
        assert row.error_single is not None
        assert row.error_single < max(2.0 * row.error_double, 1e-4)


def test_sample_and_hold_costs_order_one(report: IntegrationReport) -> None:
    smooth = [row.error_vs_smooth for row in report.rk4]
    ratios = [a / b for a, b in zip(smooth[:-1], smooth[1:], strict=True)]
    assert all(1.9 < r < 2.1 for r in ratios), ratios


def test_linearly_implicit_euler_converges_with_order_one(report: IntegrationReport) -> None:
    orders = report.orders(report.lie)
    assert all(order > 0.7 for order in orders), orders
    assert orders[-1] > 0.9
    assert all(math.isfinite(row.error_double) for row in report.lie)


def test_cvodes_matches_the_reference_and_converges_in_tolerance(
    report: IntegrationReport,
) -> None:
    errors = report.cvodes
    assert errors[1e-10] < 1e-5
    assert errors[1e-8] > 10 * errors[1e-10] > 100 * errors[1e-12]


def test_replay_of_the_reference_simulation(report: IntegrationReport) -> None:
    replay = report.replay
    assert replay is not None and replay.phase == "speed phase"
    assert replay.t_end - replay.t_start > 0.05
    assert replay.max_relative_speed_error < 5e-3
