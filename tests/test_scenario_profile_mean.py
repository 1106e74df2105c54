"""The mean of a piecewise-linear profile over an interval (validation/sim/scenario.py:
Profile.mean), which the drive's TCU log records for a shift's commanded pressures. Expected
values are integrals worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest
from gearsym.validation.sim.scenario import Profile


def test_mean_of_a_ramp_and_a_corner() -> None:
    """A ramp 0 → 10 over [0, 1], then held: over [0.2, 0.4] the mean is the midpoint value 3;
    over [0.8, 1.4] the ramp's part (8 → 10 over 0.2: area 1.8) and the hold's (10 over 0.4:
    area 4) give 5.8 / 0.6."""
    ramp = Profile(np.array([0.0, 1.0]), np.array([0.0, 10.0]))
    assert ramp.mean(0.2, 0.4) == pytest.approx(3.0, rel=1e-14)
    assert ramp.mean(0.8, 1.4) == pytest.approx(5.8 / 0.6, rel=1e-14)
    # outside the knots the profile is held
    assert ramp.mean(-1.0, -0.5) == 0.0 and ramp.mean(2.0, 3.0) == 10.0


def test_mean_of_a_step_inside_the_interval() -> None:
    """A step from 1 to 5 at 0.013 (knots 1 ms apart): over the tick [0.01, 0.02] the mean is
    (1 · 0.0025 + 3 · 0.001 + 5 · 0.0065) / 0.01 = 3.8 (the 1 ms between the knots averages
    the two levels)."""
    step = Profile(np.array([0.0, 0.0125, 0.0135, 1.0]), np.array([1.0, 1.0, 5.0, 5.0]))
    assert step.mean(0.01, 0.02) == pytest.approx(3.8, rel=1e-12)
    with pytest.raises(ValueError):
        step.mean(0.02, 0.02)
