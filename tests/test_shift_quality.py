"""Shift-quality metrics (issue 29, :mod:`gearsym.validation.studies.control.quality`): every
expected value comes from a table of the standard, a closed form evaluated here by hand, or a
synthetic record whose answer is known by construction."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from gearsym.validation.studies.control.quality import (
    FLARE_THRESHOLD,
    ShiftQuality,
    flare,
    flare_magnitude,
    friction_energy,
    inertia_phase,
    peak_jerk,
    shift_quality,
    shifts_to_converge,
    tie_up,
    vibration_dose_value,
    weighted_acceleration,
)

DT = 1e-3

#: |W_d| at one-third-octave band centres 10^(n/10) Hz: ISO 2631-1:1997 Table 3 (three
#: figures; nominal 0.5, 2, 4, 8, 31.5, 80 Hz) as reproduced in
#: github.com/laghbani/Road-Condition-Analysis-Tool-V2 iso_weighting.py, and ISO 8041-1:2017
#: Annex B (four figures; 1 Hz, 20 Hz) as transcribed in
#: github.com/jmrplens/phonometry tests/vibration/human/test_human_vibration.py.
WD_TABLE = {-3: 0.854, 0: 1.011, 3: 0.891, 6: 0.514, 9: 0.255, 13: 0.1004, 15: 0.0630, 19: 0.0213}
#: ISO 8041-1 Table 1: W_d at its reference frequency 100 rad/s (also zetlab.com's table).
WD_REFERENCE = (100.0 / (2.0 * math.pi), 0.1261)


def _wd_by_hand(f: float) -> float:
    """|W_d(j 2π f)| from ISO 2631-1 Annex A, in plain complex arithmetic."""
    p = 2j * math.pi * f
    w1, w2, w3, w4, q4 = (
        2 * math.pi * 0.4,
        2 * math.pi * 100,
        2 * math.pi * 2,
        2 * math.pi * 2,
        0.63,
    )
    high = 1 / (1 + math.sqrt(2) * w1 / p + (w1 / p) ** 2)
    low = 1 / (1 + math.sqrt(2) * p / w2 + (p / w2) ** 2)
    transition = (1 + p / w3) / (1 + p / (q4 * w4) + (p / w4) ** 2)
    return abs(high * low * transition)


def _steady_gain(f: float, seconds: float = 30.0) -> float:
    """Amplitude ratio of the weighted to the raw sinusoid over the record's last 10 periods."""
    t = np.arange(0.0, seconds, DT)
    weighted = weighted_acceleration(np.sin(2 * math.pi * f * t), DT)
    tail = weighted[-int(round(10 / f / DT)) :]
    return float(np.sqrt(2 * np.mean(tail**2)))


@pytest.mark.parametrize("n", sorted(WD_TABLE))
def test_the_weighting_meets_the_tabulated_factors(n):
    """To the table's rounding and the bilinear transform's warping at 1 kHz: 2 %."""
    assert _steady_gain(10 ** (n / 10)) == pytest.approx(WD_TABLE[n], rel=0.02)


def test_the_weighting_meets_its_reference_frequency_factor():
    f, factor = WD_REFERENCE
    assert _steady_gain(f) == pytest.approx(factor, rel=0.005)


def test_the_hand_formula_is_the_table():
    """The test's own closed form reproduces the table (so the VDV test rests on it)."""
    for n, factor in WD_TABLE.items():
        assert _wd_by_hand(10 ** (n / 10)) == pytest.approx(factor, rel=0.002)


def test_a_constant_acceleration_weighs_nothing():
    """A record that starts at a steady 1.5 m/s² has no weighted transient (zero DC gain,
    the filter started in the first sample's steady state)."""
    weighted = weighted_acceleration(np.full(5000, 1.5), DT)
    assert np.max(np.abs(weighted)) < 1e-9


@pytest.mark.parametrize(("f", "amplitude"), [(1.0, 2.0), (4.0, 0.5), (8.0, 1.0)])
def test_vdv_of_a_sinusoid(f, amplitude):
    """∫ sin⁴ over whole periods is 3T/8: VDV = (3T/8)^¼ A |W_d(f)| (the switch-on transient of
    a 60 s record stays under 1 %)."""
    seconds = 60.0
    t = np.arange(0.0, seconds, DT)
    expected = (3 * seconds / 8) ** 0.25 * amplitude * _wd_by_hand(f)
    vdv = vibration_dose_value(amplitude * np.sin(2 * math.pi * f * t), DT)
    assert vdv == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize(("f", "amplitude"), [(0.5, 1.0), (1.0, 0.5), (2.0, 0.2)])
def test_peak_jerk_of_a_slow_sinusoid(f, amplitude):
    """v = v0 + V sin(2π f t): jerk = d²v/dt², peak V (2π f)²; the 10 Hz low pass passes it."""
    t = np.arange(0.0, 10.0 + DT / 2, DT)
    v = 20.0 + amplitude * np.sin(2 * math.pi * f * t)
    assert peak_jerk(v, DT) == pytest.approx(amplitude * (2 * math.pi * f) ** 2, rel=0.005)


def _linear_slip(t, s0, t_a, t_b):
    """s0 until t_a, linearly to 0 at t_b, 0 after."""
    return s0 * np.clip((t_b - t) / (t_b - t_a), 0.0, 1.0)


@pytest.mark.parametrize("s0", [150.0, -150.0])
def test_inertia_phase_of_a_linear_slip_decay(s0):
    """Slip 150 rad/s until 0.2 s, to 0 at 0.7 s: the 2 % fall is at 0.2 + 0.02·0.5 = 0.21 s,
    |slip| ≤ 1.5 rad/s from 0.7 − 0.5·1.5/150 = 0.695 s."""
    t = np.arange(0.0, 1.0 + DT / 2, DT)
    start, end = inertia_phase(t, _linear_slip(t, s0, 0.2, 0.7), lockup_slip=1.5)
    assert start == pytest.approx(0.21, abs=1.5 * DT)
    assert end == pytest.approx(0.695, abs=1.5 * DT)


def test_inertia_phase_without_lock_up_or_without_a_fall():
    t = np.arange(0.0, 1.0 + DT / 2, DT)
    start, end = inertia_phase(t, _linear_slip(t, 100.0, 0.2, 1.5), lockup_slip=1.0)
    assert start == pytest.approx(0.2 + 0.02 * 1.3, abs=1.5 * DT) and math.isnan(end)
    assert all(math.isnan(x) for x in inertia_phase(t, np.full(len(t), 80.0), 1.0))
    assert all(math.isnan(x) for x in inertia_phase(t, np.zeros(len(t)), 1.0))


RPM = 2 * math.pi / 60


def _shift(on_sign, off_sign, on_over=0.0, off_back=0.0):
    """A synthetic shift: on-coming slip from 200 rad/s (sign ``on_sign``) to zero at 0.5 s,
    then a half-sine ``on_over`` rad/s beyond zero (0.5-0.7 s); off-going slip 0, a half-sine
    ``off_back`` rad/s against ``off_sign`` (0.1-0.3 s), then sliding to 150 rad/s with
    ``off_sign`` (0.3-0.9 s)."""
    t = np.arange(0.0, 1.0, DT)
    on = 200.0 * np.clip(1 - t / 0.5, 0.0, 1.0)
    on -= on_over * np.sin(math.pi * np.clip(t - 0.5, 0.0, 0.2) / 0.2)
    off = 150.0 * np.clip((t - 0.3) / 0.6, 0.0, 1.0)
    off -= off_back * np.sin(math.pi * np.clip(t - 0.1, 0.0, 0.2) / 0.2)
    return on_sign * on, off_sign * off


@pytest.mark.parametrize(("on_sign", "off_sign"), [(1, 1), (1, -1), (-1, 1), (-1, -1)])
def test_a_clean_shift_has_no_flare(on_sign, off_sign):
    on, off = _shift(on_sign, off_sign)
    assert not flare(on, off)
    assert flare_magnitude(on, off) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(("on_sign", "off_sign"), [(1, 1), (-1, -1), (1, -1)])
def test_the_input_overspeeding_past_the_to_gear_is_a_flare(on_sign, off_sign):
    """On-coming slip reversing by 80 rpm (> 50) is one, by 30 rpm is not."""
    on, off = _shift(on_sign, off_sign, on_over=80 * RPM)
    assert flare(on, off)
    assert flare_magnitude(on, off) == pytest.approx(80 * RPM, rel=1e-3)
    on, off = _shift(on_sign, off_sign, on_over=30 * RPM)
    assert not flare(on, off)


@pytest.mark.parametrize(("on_sign", "off_sign"), [(1, 1), (-1, 1), (1, -1)])
def test_the_off_going_slipping_the_wrong_way_is_a_flare(on_sign, off_sign):
    """Power-on upshift with both elements open: the off-going slips 70 rpm against the
    direction it ends in (or the direction the caller states for its release)."""
    on, off = _shift(on_sign, off_sign, off_back=70 * RPM)
    assert flare(on, off)
    assert flare_magnitude(on, off) == pytest.approx(70 * RPM, rel=1e-3)
    assert not flare(on, off, threshold=75 * RPM)
    assert flare(on, off, off_direction=off_sign)
    assert flare_magnitude(on, off, off_direction=-off_sign) == pytest.approx(150.0)


def test_the_default_threshold_is_50_rpm():
    assert FLARE_THRESHOLD == pytest.approx(50 * 2 * math.pi / 60)


def _torque_trace(t, from_torque, to_torque, dip):
    """From-gear torque until 0.2 s, linear to the to-gear's at 0.4 s, a triangular dip of
    ``dip`` N·m centred at 0.3 s."""
    ramp = from_torque + (to_torque - from_torque) * np.clip((t - 0.2) / 0.2, 0, 1)
    return ramp - dip * np.clip(1 - np.abs(t - 0.3) / 0.05, 0, 1)


@pytest.mark.parametrize(("from_torque", "to_torque"), [(1000.0, 700.0), (700.0, 1000.0)])
def test_tie_up_on_synthetic_torque(from_torque, to_torque):
    """Up- and downshift: the floor is the lower steady torque, 700 N·m; the ramp passes 850 at
    0.3 s, so a 300 N·m dip reaches 550 (150 under the floor, > 5 % of 700: tie-up) and a
    180 N·m dip 670 (30 under, < 35: none)."""
    t = np.arange(0.0, 0.6, DT)
    clean = _torque_trace(t, from_torque, to_torque, 0.0)
    assert tie_up(clean, from_torque, to_torque) == (False, 0.0)
    deep = _torque_trace(t, from_torque, to_torque, 300.0)
    tied, depth = tie_up(deep, from_torque, to_torque)
    assert tied and depth == pytest.approx(150.0, abs=1e-6)
    shallow = _torque_trace(t, from_torque, to_torque, 180.0)
    tied, depth = tie_up(shallow, from_torque, to_torque)
    assert not tied and depth == pytest.approx(30.0, abs=1e-6)


def test_tie_up_of_a_coast_shift_is_mirrored():
    t = np.arange(0.0, 0.6, DT)
    trace = -_torque_trace(t, 400.0, 300.0, 100.0)  # −350 + 100 = −250: 50 towards zero of −300
    tied, depth = tie_up(trace, -400.0, -300.0)
    assert tied and depth == pytest.approx(50.0, abs=1e-6)


def test_friction_energy_of_constant_torque_and_falling_slip():
    """T = 400 N·m, slip 120 → 0 rad/s over 0.5 s: T s0 T_s / 2 = 12 000 J (exact for the
    trapezoid on a linear integrand); the sign of torque and slip does not matter."""
    t = np.linspace(0.0, 0.5, 501)
    slip = 120.0 * (1 - t / 0.5)
    assert friction_energy(t, np.full_like(t, 400.0), slip) == pytest.approx(12_000.0)
    assert friction_energy(t, np.full_like(t, -400.0), slip) == pytest.approx(12_000.0)


@pytest.mark.parametrize(
    ("errors", "expected"),
    [
        ([0.5, 0.3, 0.2, 0.15, 0.12], None),
        ([0.05, -0.02, 0.09, 0.5], 1),
        ([0.4, 0.05, 0.08, 0.3, -0.05, 0.01, 0.09, 0.2], 5),  # the run at 2 breaks at 4
        ([0.4, 0.05, float("nan"), 0.05, 0.05, 0.05], 4),
        ([0.05, 0.05], None),
        ([], None),
    ],
)
def test_shifts_to_converge(errors, expected):
    assert shifts_to_converge(errors) == expected


def test_shifts_to_converge_run_and_tolerance():
    assert shifts_to_converge([0.15, 0.15, 0.3], tolerance=0.2, run=2) == 1
    assert shifts_to_converge([0.3, 0.05], run=1) == 2


def test_shift_quality_of_a_synthetic_shift():
    """Every field from the record by the single-metric definitions above."""
    t = np.arange(0.0, 1.0, DT)
    on, off = _shift(1, 1)
    v = 20.0 + 0.5 * np.sin(2 * math.pi * 1.0 * t)
    torque = _torque_trace(t, 1000.0, 700.0, 0.0)
    friction = {"K1": (np.full_like(t, 300.0), on), "B2": (np.full_like(t, 200.0), off)}
    quality = shift_quality(t, v, on, off, torque, 1000.0, 700.0, friction, 0.5, 1.0)
    assert isinstance(quality, ShiftQuality)
    start, end = inertia_phase(t, on, 1.0)
    assert quality.duration == pytest.approx(end - start)
    assert quality.duration_error == pytest.approx((end - start - 0.5) / 0.5)
    assert quality.peak_jerk == pytest.approx(peak_jerk(v, DT))
    assert quality.vdv == pytest.approx(vibration_dose_value(np.gradient(v, DT), DT))
    assert not quality.flare and not quality.tie_up
    assert quality.friction_energy["K1"] == pytest.approx(friction_energy(t, *friction["K1"]))
    assert set(quality.friction_energy) == {"K1", "B2"}
    record = quality.to_dict()
    assert json.loads(json.dumps(record)) == record
    with pytest.raises(dataclasses.FrozenInstanceError):
        quality.vdv = 0.0  # frozen


def test_shift_quality_refuses_an_uneven_time_base():
    t = np.array([0.0, 0.001, 0.003, 0.004])
    x = np.zeros(4)
    with pytest.raises(ValueError, match="constant step"):
        shift_quality(t, x, x, x, x, 1.0, 1.0, {}, 0.5, 1.0)


@pytest.mark.parametrize(("f", "within"), [(1.0, 1e-3), (10.0, 1e-3), (31.5, 4e-3), (80.0, 0.02)])
def test_the_digital_weighting_follows_the_analog_one_at_1_khz(f, within):
    """The bilinear transform's warping, as the docstring states it (the hand formula is the
    analog W_d)."""
    assert _steady_gain(f) == pytest.approx(_wd_by_hand(f), rel=within)


def test_a_sample_time_too_long_for_the_100_hz_corner_is_refused():
    with pytest.raises(ValueError, match="100 Hz"):
        weighted_acceleration(np.zeros(10), 1 / 150)


def test_shift_quality_reports_a_flare_and_a_tie_up():
    """The off-going dips 70 rpm the wrong way, the output torque 150 N·m under the floor."""
    t = np.arange(0.0, 1.0, DT)
    on, off = _shift(1, -1, off_back=70 * RPM)
    torque = _torque_trace(t, 1000.0, 700.0, 300.0)
    args = (t, np.full_like(t, 20.0), on, off, torque, 1000.0, 700.0, {}, 0.5, 1.0)
    quality = shift_quality(*args)
    assert quality.flare and quality.flare_magnitude == pytest.approx(70 * RPM, rel=1e-3)
    assert quality.tie_up and quality.tie_up_depth == pytest.approx(150.0, abs=1e-6)
    assert quality.peak_jerk == 0.0 and quality.vdv == 0.0 and quality.friction_energy == {}
    assert shift_quality(*args, off_direction=1.0).flare_magnitude == pytest.approx(150.0)


def test_torque_reversal_of_the_off_going_element():
    """A from-gear torque of −150 N·m that swings to +20 before release is held against the
    on-coming element (20 > 5 % of 150); one that falls to 0 is not."""
    from gearsym.validation.studies.control.quality import torque_reversal

    held = np.array([-150.0, -100.0, -20.0, 20.0, 0.0])
    assert torque_reversal(held) == (True, 20.0)
    clean = np.array([-150.0, -100.0, -20.0, 0.0, 0.0])
    assert torque_reversal(clean) == (False, 0.0)
    small = np.array([150.0, 50.0, -5.0, 0.0])
    assert torque_reversal(small) == (False, 5.0)
