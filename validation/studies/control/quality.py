"""Shift quality of one simulated clutch-to-clutch shift, and the convergence of a shift-control
strategy over a sequence of shifts (issue 29: fixed calibration, rule-based adaptation,
estimator-based and oracle control compared by these numbers).

Every function is pure and takes NumPy arrays sampled at a constant step (the closed-loop
simulation records at :data:`~gearsym.validation.sim.drive_shift.SHIFT_SAMPLE`, 1 ms).

**Comfort** follows ISO 2631-1:1997 (*Mechanical vibration and shock: evaluation of human
exposure to whole-body vibration, Part 1*): the longitudinal acceleration of a seated occupant
is weighted with W_d (x-axis, Table 3; transfer functions of Annex A) and summarised by the
vibration dose value (6.3.2, the fourth power vibration dose method), which, unlike the
r.m.s., keeps the peaks a shift shock is made of. The weighting's parameters (Annex A,
restated from ISO 8041 in e.g. the Larson Davis HVM200 reference manual, Table 3.1):
f1 = 0.4 Hz, f2 = 100 Hz (band limiting, Q1 = Q2 = 1/√2), f3 = f4 = 2 Hz, Q4 = 0.63
(acceleration-velocity transition), no upward step, gain 1. The peak jerk (the automotive
shift-quality number) is kept beside it.

**Sign conventions** (the caller's arrays, nothing else): the on-coming element's slip has the
sign it has at the start of the record (it slides towards zero during the shift); the
off-going element's slip, by default, the sign it has at the end of the record (after the
shift it slides in the direction the ratio change drives it), or the sign the caller states
for the moment of release. Both hold for up- and downshifts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from types import MappingProxyType

import numpy as np
from gearsym.validation.sim.drive_shift import vehicle_jerk

__all__ = [
    "FLARE_THRESHOLD",
    "INERTIA_FRACTION",
    "W_D",
    "ShiftQuality",
    "flare",
    "flare_magnitude",
    "friction_energy",
    "inertia_phase",
    "peak_jerk",
    "shift_quality",
    "shifts_to_converge",
    "tie_up",
    "vibration_dose_value",
    "weighted_acceleration",
    "wd_sections",
]

#: ISO 2631-1:1997 Annex A, weighting W_d: band-limiting corners f1, f2 (Hz), the
#: acceleration-velocity transition f3, f4 (Hz) and its quality factor Q4. (No upward step.)
W_D = MappingProxyType({"f1": 0.4, "f2": 100.0, "f3": 2.0, "f4": 2.0, "q4": 0.63})
#: A slip reversal beyond 50 rpm (in rad/s) is a flare.
FLARE_THRESHOLD = 50.0 * 2.0 * math.pi / 60.0
#: The inertia phase starts when the on-coming slip has fallen by this fraction of its value at
#: the start of the record.
INERTIA_FRACTION = 0.02


def _prewarped(f: float, fs: float) -> float:
    """The analog angular frequency (rad/s) the bilinear transform at ``fs`` maps onto ``f``."""
    return 2.0 * fs * math.tan(math.pi * f / fs)


def wd_sections(dt: float) -> np.ndarray:
    """W_d as second-order sections (``scipy.signal.sosfilt`` layout) for the sample time ``dt``.

    The three factors of ISO 2631-1 Annex A, with p = jω and ω_i = 2π f_i:

    * high pass H_h = 1 / (1 + √2 ω1/p + (ω1/p)²),
    * low pass H_l = 1 / (1 + √2 p/ω2 + (p/ω2)²),
    * transition H_t = (1 + p/ω3) / (1 + p/(Q4 ω4) + (p/ω4)²),

    each discretised on its own by the bilinear transform with its corners prewarped (each
    section's digital corner is its analog corner). At 1 kHz the low pass's 100 Hz corner is
    a fifth of Nyquist: unwarped, it would sit 3 % low. What warping is left is the
    transition's 1/f slope above 2 Hz, compressed towards Nyquist: at 1 kHz the digital |W_d|
    is within 0.1 % of the analog one up to 10 Hz, 0.3 % at 31.5 Hz, 1.4 % low at 80 Hz and
    3.3 % low at 100 Hz (a shift's comfort content lies below 30 Hz). Sections, not one
    polynomial: the 0.4 Hz high pass puts two poles within 3e-3 of z = 1, where the
    coefficients of a sixth-order polynomial would lose them.
    """
    from scipy.signal import bilinear

    fs = 1.0 / dt
    if W_D["f2"] >= fs / 2.0:
        raise ValueError(f"sample time {dt} s: W_d's 100 Hz corner needs fs > 200 Hz")
    w1, w2, w3, w4 = (_prewarped(W_D[k], fs) for k in ("f1", "f2", "f3", "f4"))
    q4 = W_D["q4"]
    analog = [
        ([1.0, 0.0, 0.0], [1.0, math.sqrt(2.0) * w1, w1 * w1]),
        ([0.0, 0.0, w2 * w2], [1.0, math.sqrt(2.0) * w2, w2 * w2]),
        ([0.0, 1.0 / w3, 1.0], [1.0 / (w4 * w4), 1.0 / (q4 * w4), 1.0]),
    ]
    sections = []
    for b_s, a_s in analog:
        b_z, a_z = bilinear(b_s, a_s, fs)
        b_z, a_z = np.atleast_1d(b_z), np.atleast_1d(a_z)
        b_z = np.pad(b_z, (0, 3 - len(b_z)))
        sections.append(np.concatenate([b_z / a_z[0], a_z / a_z[0]]))
    return np.array(sections)


def weighted_acceleration(a: np.ndarray, dt: float) -> np.ndarray:
    """The longitudinal acceleration ``a`` (m/s², sampled every ``dt`` s) weighted with ISO
    2631-1 W_d (:func:`wd_sections`).

    The filter starts in the steady state of the first sample, as if the vehicle had
    accelerated at ``a[0]`` for ever before the record: a shift recorded while driving starts
    at a non-zero acceleration, and a filter starting from rest would turn that step into a
    weighted transient the shift never had (the weighting's DC gain is zero, so a constant
    ``a`` weighs zero from the first sample)."""
    from scipy.signal import sosfilt, sosfilt_zi

    a = np.asarray(a, dtype=float)
    sos = wd_sections(dt)
    weighted, _ = sosfilt(sos, a, zi=sosfilt_zi(sos) * (a[0] if len(a) else 0.0))
    return weighted


def vibration_dose_value(a: np.ndarray, dt: float) -> float:
    """VDV = (∫ a_w⁴ dt)^¼ (m/s^1.75) of the W_d-weighted acceleration a_w of ``a`` (ISO
    2631-1:1997 6.3.2; the integral as a sum of samples times ``dt``): the fourth
    power makes the shift's shock, not the record's length, set the number. ``a`` is the
    vehicle's longitudinal acceleration, taken as the seat's (no seat transmissibility)."""
    weighted = weighted_acceleration(a, dt)
    return float(np.sum(weighted**4) * dt) ** 0.25


def peak_jerk(v: np.ndarray, dt: float) -> float:
    """Largest |jerk| (m/s³) of the vehicle speed ``v`` (m/s, every ``dt`` s), from
    :func:`~gearsym.validation.sim.drive_shift.vehicle_jerk` (acceleration low-passed at
    10 Hz before it is differentiated)."""
    return float(np.max(np.abs(vehicle_jerk(np.asarray(v, dtype=float), dt))))


def inertia_phase(
    t: np.ndarray, slip_on: np.ndarray, lockup_slip: float, fraction: float = INERTIA_FRACTION
) -> tuple[float, float]:
    """Start and end (s) of the inertia (speed) phase, from the on-coming element's slip.

    * start: the first sample at which |slip_on| has fallen below (1 − ``fraction``) times
      |slip_on[0]|, its value at the start of the record (which must start before the speed
      phase: in the torque phase the slip stays near its initial value). A linear fall from
      s0 at t_a to zero at t_b starts at t_a + ``fraction`` (t_b − t_a): the 2 % keep a slip
      that wanders in the torque phase from starting the phase early;
    * end: the first sample at or after the start with |slip_on| ≤ ``lockup_slip``.

    NaN for a start that never comes (or a record that starts synchronous, slip_on[0] = 0),
    NaN for an end that never comes (the element did not lock within the record)."""
    t = np.asarray(t, dtype=float)
    slip = np.abs(np.asarray(slip_on, dtype=float))
    if not len(slip) or slip[0] == 0.0:
        return math.nan, math.nan
    fallen = np.flatnonzero(slip < (1.0 - fraction) * slip[0])
    if not len(fallen):
        return math.nan, math.nan
    i_start = int(fallen[0])
    locked = np.flatnonzero(slip[i_start:] <= lockup_slip)
    end = float(t[i_start + locked[0]]) if len(locked) else math.nan
    return float(t[i_start]), end


def _direction(x: np.ndarray, at: int) -> float:
    """The sign of ``x[at]``, or of the nearest non-zero sample towards the record's middle."""
    step = 1 if at == 0 else -1
    for value in x[at::step]:
        if value != 0.0:
            return float(np.sign(value))
    return 0.0


def flare_magnitude(
    slip_on: np.ndarray, slip_off: np.ndarray, off_direction: float | None = None
) -> float:
    """The largest slip reversal (rad/s, ≥ 0) on either element.

    * on-coming: how far its slip goes past zero against its sign at the start of the record
      (the input overspeeds past the to-gear's synchronous speed);
    * off-going: how far its slip goes against ``off_direction``, the direction it slips in
      after release in a clean shift (default: its sign at the end of the record): in a
      power-on upshift, the input speed rising above the from-gear's synchronous speed while
      both swapping elements are open.

    Zero when no slip reverses (an element that never slips has no direction)."""
    on = np.asarray(slip_on, dtype=float)
    off = np.asarray(slip_off, dtype=float)
    reversals = [0.0]
    if len(on):
        reversals.append(float(np.max(-_direction(on, 0) * on)))
    if len(off):
        sign = _direction(off, -1) if off_direction is None else float(np.sign(off_direction))
        reversals.append(float(np.max(-sign * off)) if sign else 0.0)
    return max(reversals)


def flare(
    slip_on: np.ndarray,
    slip_off: np.ndarray,
    threshold: float = FLARE_THRESHOLD,
    off_direction: float | None = None,
) -> bool:
    """Whether either element's slip reverses beyond ``threshold`` (rad/s, default 50 rpm):
    :func:`flare_magnitude` > ``threshold``, with its sign conventions."""
    return flare_magnitude(slip_on, slip_off, off_direction) > threshold


def tie_up(
    output_torque: np.ndarray,
    from_gear_torque: float,
    to_gear_torque: float,
    tolerance: float = 0.05,
) -> tuple[bool, float]:
    """Tie-up: the output torque dipping below the lower of the two gears' steady output
    torques (N·m) by more than ``tolerance`` of it, both elements carrying torque against each
    other. Returns (the flag, the depth of the dip below that floor, N·m, ≥ 0).

    Drive torque is positive; a coast shift (both steady torques negative) is mirrored: its
    floor is the one of smaller magnitude and a dip is a fall towards zero and past it."""
    torque = np.asarray(output_torque, dtype=float)
    sign = -1.0 if from_gear_torque + to_gear_torque < 0.0 else 1.0
    floor = min(sign * from_gear_torque, sign * to_gear_torque)
    depth = max(0.0, floor - float(np.min(sign * torque))) if len(torque) else 0.0
    return depth > tolerance * abs(floor), depth


def torque_reversal(off_torque: np.ndarray, tolerance: float = 0.05) -> tuple[bool, float]:
    """Tie-up seen at the off-going element: its torque reversing from its from-gear direction
    (the sign of the record's first sample) by more than ``tolerance`` of its first value,
    that is the element held against the on-coming one, both carrying torque against each
    other. Returns (the flag, the largest reversed torque, N·m, ≥ 0). Unlike the output-torque
    dip of :func:`tie_up`, it does not count the side shafts' torsional swing, which dips the
    output torque in any quick hand-over."""
    torque = np.asarray(off_torque, dtype=float)
    if not len(torque) or torque[0] == 0.0:
        return False, 0.0
    reversed_ = max(0.0, float(np.max(-np.sign(torque[0]) * torque)))
    return reversed_ > tolerance * abs(float(torque[0])), reversed_


def friction_energy(t: np.ndarray, friction_torque: np.ndarray, slip: np.ndarray) -> float:
    """Heat (J) one element's friction makes: ∫ |T_fric · slip| dt, trapezoidal."""
    power = np.abs(np.asarray(friction_torque, dtype=float) * np.asarray(slip, dtype=float))
    return float(np.trapezoid(power, np.asarray(t, dtype=float)))


def shifts_to_converge(
    errors: Sequence[float], tolerance: float = 0.10, run: int = 3
) -> int | None:
    """The 1-based index of the first shift of the first ``run`` shifts in a row with
    |error| < ``tolerance`` (a NaN error is outside), None if there is no such run."""
    count = 0
    for i, error in enumerate(errors, start=1):
        count = count + 1 if abs(error) < tolerance else 0
        if count == run:
            return i - run + 1
    return None


@dataclass(frozen=True)
class ShiftQuality:
    """One shift's quality: inertia-phase duration (s) and its error relative to the target,
    peak |jerk| (m/s³), VDV (m/s^1.75), flare and its magnitude (rad/s), tie-up and its depth
    (N·m), friction energy per element (J)."""

    duration: float
    duration_error: float
    peak_jerk: float
    vdv: float
    flare: bool
    flare_magnitude: float
    tie_up: bool
    tie_up_depth: float
    friction_energy: dict[str, float] = field(default_factory=dict)
    #: the off-going element's reversed torque (N·m) and whether it exceeds the tolerance
    #: (:func:`torque_reversal`; None and False when the caller gave no off-going torque)
    reversal: float | None = None
    reversal_tie_up: bool = False

    def to_dict(self) -> dict[str, object]:
        """Plain values (JSON-ready: bools, floats, a dict of floats)."""
        return asdict(self)


def _sample_time(t: np.ndarray) -> float:
    steps = np.diff(t)
    if not len(steps) or not np.allclose(steps, steps[0], rtol=1e-6, atol=0.0):
        raise ValueError("the record must have at least two samples at a constant step")
    return float(steps[0])


def shift_quality(
    t: np.ndarray,
    v: np.ndarray,
    slip_on: np.ndarray,
    slip_off: np.ndarray,
    output_torque: np.ndarray,
    from_gear_torque: float,
    to_gear_torque: float,
    friction: dict[str, tuple[np.ndarray, np.ndarray]],
    target_duration: float,
    lockup_slip: float,
    off_direction: float | None = None,
    off_torque: np.ndarray | None = None,
) -> ShiftQuality:
    """All metrics of one shift's record: time ``t`` (s, constant step), vehicle speed ``v``
    (m/s), the swapping elements' slips (rad/s), the output torque (N·m) and the two gears'
    steady output torques, and per element (friction torque, slip) for the heat. The duration
    is the inertia phase's (:func:`inertia_phase`); its error is (duration − target) / target,
    NaN when the element did not lock. ``off_direction``: the off-going element's slip
    direction after release (:func:`flare_magnitude`), for a record that ends before it slips
    that way (a failed shift). ``off_torque``: the off-going element's torque over the record,
    for :func:`torque_reversal`."""
    t = np.asarray(t, dtype=float)
    dt = _sample_time(t)
    v = np.asarray(v, dtype=float)
    start, end = inertia_phase(t, slip_on, lockup_slip)
    duration = end - start
    tied, depth = tie_up(output_torque, from_gear_torque, to_gear_torque)
    reversal_tie_up, reversal = (False, None) if off_torque is None else torque_reversal(off_torque)
    return ShiftQuality(
        duration=duration,
        duration_error=(duration - target_duration) / target_duration,
        peak_jerk=peak_jerk(v, dt),
        vdv=vibration_dose_value(np.gradient(v, dt), dt),
        flare=flare(slip_on, slip_off, off_direction=off_direction),
        flare_magnitude=flare_magnitude(slip_on, slip_off, off_direction),
        tie_up=tied,
        tie_up_depth=depth,
        friction_energy={
            name: friction_energy(t, torque, slip) for name, (torque, slip) in friction.items()
        },
        reversal=reversal,
        reversal_tie_up=reversal_tie_up,
    )
