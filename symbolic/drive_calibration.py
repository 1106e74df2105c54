"""The powertrain around the gearbox and the TCU's shift schedule for a whole drive
(``gearsym drive``), read from a description's optional ``[drive]`` table.

The thesis models the gearbox from its input torque T_In = engine + e-machine (2.39) to the
wheel; a drive needs what produces T_In and when the TCU shifts. The table::

    [drive.engine]          # torque at the gearbox input: min(T_max, P_max / ω_in)
    T_max = { value = 400.0, unit = "N*m", source = "..." }
    P_max = { value = 143.0e3, unit = "W", source = "..." }
    n_idle = { value = 800.0, unit = "rpm", source = "..." }   # below it the engine is decoupled
    [drive.e_machine]       # on the input shaft: drives and recuperates within its limits
    T_max = { value = 440.0, unit = "N*m", source = "..." }
    P_max = { value = 90.0e3, unit = "W", source = "..." }
    [drive.driver]          # wheel force = feed-forward + PI on the speed error
    k_p = { value = 3000.0, unit = "N*s/m", source = "..." }
    t_i = { value = 4.0, unit = "s", source = "..." }
    [drive.shift_schedule]  # input speed over pedal (0..1), linear in between
    pedal = [0.0, 0.5, 1.0]
    upshift = { value = [1500.0, 2300.0, 3800.0], unit = "rpm", source = "..." }
    downshift = { value = [900.0, 1200.0, 2200.0], unit = "rpm", source = "..." }
    [drive.estimator]       # the EKF over a drive (optional; else the [estimator] table's)
    twist_model_error = { value = 1.5e-2, unit = "rad^2/s", source = "..." }
    tuned_on = "..."
    [drive.shift]           # the open-loop shift plan of each shift
    torque_phase = { value = 0.15, unit = "s", source = "..." }
    speed_phase = { value = 0.35, unit = "s", source = "..." }
    line_pressure = { value = 1.5e6, unit = "Pa", source = "..." }

A schedule in input speed holds for any gear set: the vehicle speeds of each shift follow from
the ratios (``gearsym drive`` prints them). Every entry is optional; the defaults below are
stated, and the built-in description states its own with sources.
"""

from __future__ import annotations

import bisect
import itertools
import math
from dataclasses import dataclass, field
from typing import Any

from gearsym.symbolic.errors import GearsymError

__all__ = ["DriveCalibration", "Entry", "ShiftSchedule", "default_drive", "parse_drive_table"]

_DEFAULT = "gearsym default (assumed; the description states none)"

#: (section, key): (value, unit) of every scalar entry and its default.
_SCALARS: dict[tuple[str, str], tuple[float, str]] = {
    ("engine", "T_max"): (400.0, "N*m"),
    ("engine", "P_max"): (143.0e3, "W"),
    ("engine", "n_idle"): (800.0, "rpm"),
    ("e_machine", "T_max"): (440.0, "N*m"),
    ("e_machine", "P_max"): (90.0e3, "W"),
    ("driver", "k_p"): (3000.0, "N*s/m"),
    ("driver", "t_i"): (4.0, "s"),
    ("shift", "torque_phase"): (0.15, "s"),
    ("shift", "speed_phase"): (0.35, "s"),
    ("shift", "line_pressure"): (1.5e6, "Pa"),
}

_DEFAULT_SCHEDULE = ((0.0, 0.5, 1.0), (1500.0, 2300.0, 3800.0), (900.0, 1200.0, 2200.0))

RPM = math.pi / 30.0  # rad/s per rpm


@dataclass(frozen=True)
class Entry:
    """One stated number of the table: value, unit and where it comes from."""

    value: float
    unit: str
    source: str


@dataclass(frozen=True)
class ShiftSchedule:
    """Upshift and downshift input speeds (rad/s) over pedal, linear in between."""

    pedal: tuple[float, ...]
    upshift: tuple[float, ...]
    downshift: tuple[float, ...]
    source: str = ""

    def up(self, pedal: float) -> float:
        return _interpolate(pedal, self.pedal, self.upshift)

    def down(self, pedal: float) -> float:
        return _interpolate(pedal, self.pedal, self.downshift)


def _interpolate(x: float, xs: tuple[float, ...], ys: tuple[float, ...]) -> float:
    """Linear in between, held at the ends (pure Python: parsing a description stays free of
    NumPy)."""
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    k = bisect.bisect_right(xs, x)
    return ys[k - 1] + (ys[k] - ys[k - 1]) * (x - xs[k - 1]) / (xs[k] - xs[k - 1])


@dataclass(frozen=True)
class DriveCalibration:
    """The ``[drive]`` table (module docstring); ``values[(section, key)]`` in SI units (rpm
    converted to rad/s)."""

    values: tuple[tuple[tuple[str, str], Entry], ...]
    schedule: ShiftSchedule
    file: str = field(default="", compare=False)
    #: what ``[drive.estimator]`` was tuned on
    tuned_on: str = ""

    def entry(self, section: str, key: str) -> Entry:
        return dict(self.values)[(section, key)]

    def twist_model_error(self) -> float | None:
        """q of the twist φ the EKF uses over a drive (``[drive.estimator] twist_model_error``,
        rad²/s), or None: the ``[estimator]`` table's (tuned on single shifts)."""
        entry = dict(self.values).get(("estimator", "twist_model_error"))
        return None if entry is None else entry.value

    def si(self, section: str, key: str) -> float:
        """The entry in SI units (rpm as rad/s)."""
        q = self.entry(section, key)
        return q.value * RPM if q.unit == "rpm" else q.value

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for (section, key), q in self.values:
            entry = {"value": q.value, "unit": q.unit, "source": q.source}
            out.setdefault(section, {})[key] = entry
        out["shift_schedule"] = {
            "pedal": list(self.schedule.pedal),
            "upshift_rpm": [w / RPM for w in self.schedule.upshift],
            "downshift_rpm": [w / RPM for w in self.schedule.downshift],
            "source": self.schedule.source,
        }
        return out


def default_drive() -> DriveCalibration:
    """Every stated default (a description without ``[drive]``)."""
    values = tuple((k, Entry(v, unit, _DEFAULT)) for k, (v, unit) in _SCALARS.items())
    pedal, up, down = _DEFAULT_SCHEDULE
    schedule = ShiftSchedule(
        pedal, tuple(w * RPM for w in up), tuple(w * RPM for w in down), _DEFAULT
    )
    return DriveCalibration(values, schedule)


def parse_drive_table(table: Any) -> DriveCalibration:
    """The ``[drive]`` table read through a
    :class:`~gearsym.symbolic.io.table_reader.TableReader` (absent entries: the defaults)."""
    base = default_drive()
    values = dict(base.values)
    for section in ("engine", "e_machine", "driver", "shift"):
        sub = table.table(section, required=False)
        for (s, key), (_, unit) in _SCALARS.items():
            if s == section and key in sub.data:
                q = sub.quantity(key, unit=unit)
                values[(s, key)] = Entry(q.value, q.unit, q.source)
        sub.reject_unknown()
    sub = table.table("estimator", required=False)
    if "twist_model_error" in sub.data:
        q = sub.quantity("twist_model_error", unit="rad^2/s")
        values[("estimator", "twist_model_error")] = Entry(q.value, q.unit, q.source)
    tuned_on = sub.string("tuned_on", required=False, default="")
    sub.reject_unknown()
    schedule = base.schedule
    sub = table.table("shift_schedule", required=False)
    if sub.data:
        schedule = _schedule(sub)
    table.reject_unknown()
    return DriveCalibration(tuple(values.items()), schedule, file=table.file, tuned_on=tuned_on)


def _schedule(sub: Any) -> ShiftSchedule:
    pedal = sub._get("pedal", True)
    if (
        not isinstance(pedal, list)
        or len(pedal) < 1
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pedal)
    ):
        raise sub.fail("pedal", "expected a list of numbers in [0, 1]")
    if pedal[0] != 0.0 or pedal[-1] != 1.0 or any(b <= a for a, b in itertools.pairwise(pedal)):
        raise sub.fail("pedal", "must increase from 0 to 1")
    lines = {}
    for key in ("upshift", "downshift"):
        entry = sub.table(key)
        raw = entry._get("value", True)
        if not isinstance(raw, list) or len(raw) != len(pedal):
            raise entry.fail("value", f"expected {len(pedal)} input speeds (one per pedal point)")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in raw):
            raise entry.fail("value", "expected positive numbers")
        if entry.string("unit") != "rpm":
            raise entry.fail("unit", "expected 'rpm'")
        source = entry.string("source")
        if not source.strip():
            raise entry.fail("source", "must say where the values come from (or 'assumed')")
        entry.reject_unknown()
        lines[key] = (tuple(float(v) * RPM for v in raw), source)
    sub.reject_unknown()
    up, source = lines["upshift"]
    down, _ = lines["downshift"]
    for k, (u, dn) in enumerate(zip(up, down, strict=True)):
        if not dn < u:
            raise sub.fail(
                "downshift.value",
                f"must lie below the upshift speed at pedal {pedal[k]:g} "
                f"({dn / RPM:g} >= {u / RPM:g} rpm): the gears would hunt",
            )
    return ShiftSchedule(tuple(float(v) for v in pedal), up, down, source)


def check_hysteresis(
    file: str, schedule: ShiftSchedule, steps: list[tuple[str, str, float]]
) -> None:
    """Refuse a schedule whose upshift lands below the next gear's downshift speed: after an
    upshift at ω_up the input turns at ω_up / step (step = i_from / i_to > 1), which must stay
    above the downshift speed, or the box shifts back at once. ``steps``: (from, to, step)."""
    for pedal, up, down in zip(schedule.pedal, schedule.upshift, schedule.downshift, strict=True):
        for a, b, step in steps:
            if up / step <= down:
                raise GearsymError(
                    file,
                    "drive.shift_schedule",
                    f"after the {a}-{b} upshift at pedal {pedal:g} the input turns at "
                    f"{up / step / RPM:.0f} rpm, not above the downshift speed "
                    f"{down / RPM:.0f} rpm: the gears would hunt",
                )
