"""The shift figures an engineer judges a shift by (validation/sim/report.py::shift_figures).

Expected values from physics and definitions, not from the plotting code: rpm = rad/s · 60/2π;
the vehicle acceleration of a rolling wheel a = r_dyn ω̇_C (2.49); the jerk is its time
derivative, checked against the second derivative of the wheel speed's samples; every line on
one axis of speeds has its own line style, so one drawn over another stays visible.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.report import shift_figures
from gearsym.validation.sim.simulate import simulate


@pytest.fixture(scope="module")
def d():
    return load_description()


@pytest.fixture(scope="module")
def result(d):
    return simulate(d, check_models=False)


@pytest.fixture(autouse=True)
def close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


def _line(ax, label):
    return next(line for line in ax.get_lines() if line.get_label() == label)


def test_rpm_is_rad_per_s_times_60_over_2pi(d, result):
    rad = shift_figures(d, result, "rad/s")["fig_3_1_speeds.png"].axes[0]
    rpm = shift_figures(d, result, "rpm")["fig_3_1_speeds.png"].axes[0]
    assert rpm.get_ylabel() == "speed / (rpm)" and rad.get_ylabel() == "speed / (rad/s)"
    for line in rad.get_lines():
        label = line.get_label()
        if label.startswith("ω"):
            np.testing.assert_allclose(
                _line(rpm, label).get_ydata(), line.get_ydata() * 60 / (2 * math.pi), rtol=1e-15
            )
    np.testing.assert_allclose(
        _line(rad, "ω_C (wheel)").get_ydata(), result.signals["omega_C"], rtol=0
    )


def test_speed_lines_are_distinguishable(d, result):
    for name in ("fig_3_1_speeds.png", "fig_3_2_accelerations.png"):
        ax = shift_figures(d, result)[name].axes[0]
        lines = [line for line in ax.get_lines() if not line.get_label().startswith("_")]
        assert len(lines) >= 3
        styles = [(line.get_linestyle(), line.get_color()) for line in lines]
        assert len(set(styles)) == len(styles)
        assert len({line.get_linestyle() for line in lines}) >= min(len(lines), 4)


def test_vehicle_acceleration_and_jerk(d, result):
    fig = shift_figures(d, result)["fig_vehicle_acceleration_jerk.png"]
    top, bottom = fig.axes[:2]
    r_dyn = d.vehicle["r_dyn"].value
    acceleration = top.get_lines()[0].get_ydata()
    np.testing.assert_allclose(acceleration, r_dyn * result.signals["domega_C"], rtol=1e-15)
    # the jerk against an independent route: second differences of the wheel speed samples
    t, omega = result.t, result.signals["omega_C"]
    jerk = bottom.get_lines()[0].get_ydata()
    h = np.diff(t)  # 0.5 ms, and shorter steps at the scenario's breakpoints
    slopes = np.diff(omega) / h
    second = r_dyn * 2 * np.diff(slopes) / (h[1:] + h[:-1])
    inner = jerk[1:-1]
    scale = np.max(np.abs(inner))
    assert scale > 1.0  # a shift jerks the car: m/s³ of order one or more
    assert np.median(np.abs(inner - second)) < 0.05 * scale
    assert "jerk" in bottom.get_ylabel() and "m/s³" in bottom.get_ylabel()


def test_phase_names_stay_below_the_title(d, result):
    fig = shift_figures(d, result)["fig_3_1_speeds.png"]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    title = fig._suptitle.get_window_extent(renderer)
    names = [text for text in fig.axes[0].texts]
    assert names
    for text in names:
        box = text.get_window_extent(renderer)
        assert box.y1 < title.y0, text.get_text()


def test_unknown_speed_unit_is_refused(d, result):
    with pytest.raises(ValueError, match="speed_unit"):
        shift_figures(d, result, "km/h")
