"""Shift scenarios: input torque and element pressures over time (thesis 3.1).

A scenario is a TOML file::

    [scenario]
    name = "power-on upshift 2-3"
    shift = "2-3"
    t_end = 1.6
    vehicle_speed = { value = 8.0, unit = "m/s", source = "assumed" }

    [input_torque]              # T_In = engine + e_machine, piecewise linear in time
    unit = "N*m"
    time = [0.0, 0.8, 0.85]
    engine = [120.0, 120.0, 90.0]
    e_machine = [30.0, 30.0, -20.0]

    [pressure.K38]              # one table per element; elements not listed stay at 0 Pa
    unit = "Pa"
    time = [0.0, 0.5, 0.75]
    value = [1.0e6, 1.0e6, 0.0]

    [pressure.B06]              # a dog element (kind = "dog"): its actuation command,
    unit = "Pa"                 # engaged while > 0 (the value does not matter); it engages
    time = [0.0, 0.62, 0.63]    # only within its engage_slip, else the hybrid simulation
    value = [0.0, 0.0, 1.0]     # ends with a stated failure

    [grade]                     # optional: road grade ζ(t) (2.49), piecewise linear in time
    unit = "rad"
    time = [0.0, 0.4, 0.41]
    value = [0.0, 0.0, 0.05]

A one-way clutch takes no table (it is not pressed). A dog element's table is its command,
read by the hybrid simulation (:mod:`gearsym.validation.sim.hybrid_simulation`); the reference
simulation does not model dog elements.

An optional ``[measurement]`` table maps the signals onto the channels of a bench recording
(:mod:`gearsym.validation.sim.measurement`; ``--measurement FILE``).

Without ``[grade]`` ζ is the description's constant parameter ``vehicle.zeta``; with it ζ is an
input of the reference simulation, like T_In and the pressures ((2.53) and (5.3) list ζ among
the inputs).

Bad files raise :class:`GearsymError` naming the file, the key and the reason.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.defaults import RECORD_SAMPLE_TIME as SAMPLE_TIME
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.input_files import parse_toml, read_text, shown, unknown_key_reason
from gearsym.symbolic.io.package_data import data_file
from gearsym.symbolic.shifts import ShiftSpec, shift_spec
from gearsym.validation.sim.measurement import ChannelMap, Measurement, parse_channel_map

DEFAULT_SCENARIO = "scenario_2_3.toml"

#: Stated limits (README "Limits and the error contract"). A scenario is one shift (the
#: built-in one lasts 1.5 s); 10 s at the simulation's 0.5 ms samples is 20 000 rows of
#: timeseries.csv (about 12 MB), where 300 s wrote 356 MB and 1e9 s ran out of memory.
T_END_MAX = 10.0  # s

POINTS_MAX = 1000  # points per piecewise-linear profile

#: Largest |ζ| of a grade profile: 0.5 rad is a 55 % grade, beyond the steepest public roads
#: (about 35 %); a larger value is a unit slip (degrees or percent given as radians).
GRADE_MAX = 0.5  # rad


@dataclass(frozen=True)
class Profile:
    """A piecewise-linear signal (held constant outside its time range)."""

    time: np.ndarray
    value: np.ndarray
    # plain floats for scalar bisection: np.interp's per-call overhead dominated the inputs
    _t: list[float] = field(init=False, repr=False, compare=False)
    _v: list[float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_t", [float(v) for v in self.time])
        object.__setattr__(self, "_v", [float(v) for v in self.value])

    def __call__(self, t: float) -> float:
        ts, vs = self._t, self._v
        if t <= ts[0]:
            return vs[0]
        if t >= ts[-1]:
            return vs[-1]
        k = bisect.bisect_right(ts, t)
        return vs[k - 1] + (vs[k] - vs[k - 1]) * (t - ts[k - 1]) / (ts[k] - ts[k - 1])

    def mean(self, t0: float, t1: float) -> float:
        """The signal's mean over [t0, t1] (t1 > t0): exact, the trapezoid rule between the
        knots inside the interval and its ends."""
        if not t1 > t0:
            raise ValueError(f"need t1 > t0, got {t0}, {t1}")
        points = [t0, *(t for t in self._t if t0 < t < t1), t1]
        values = [self(t) for t in points]
        area = sum(
            (b - a) * 0.5 * (va + vb)
            for a, b, va, vb in zip(points, points[1:], values, values[1:], strict=False)
        )
        return area / (t1 - t0)

    def many(self, t: np.ndarray) -> np.ndarray:
        """The signal at every time of ``t``: the same arithmetic as a call per time, in the
        same order (so the same values), without a Python call per time."""
        t = np.asarray(t, dtype=float)
        ts, vs = self.time.astype(float), self.value.astype(float)
        if len(ts) == 1:
            return np.full(t.shape, vs[0])
        k = np.clip(np.searchsorted(ts, t, side="right"), 1, len(ts) - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            inside = vs[k - 1] + (vs[k] - vs[k - 1]) * (t - ts[k - 1]) / (ts[k] - ts[k - 1])
        return np.where(t <= ts[0], vs[0], np.where(t >= ts[-1], vs[-1], inside))


@dataclass(frozen=True)
class Scenario:
    name: str
    file: str
    shift: ShiftSpec
    t_end: float
    vehicle_speed: float
    engine: Profile
    e_machine: Profile
    pressure: dict[str, Profile]
    #: ζ(t) (2.49) from ``[grade]``, or None: ζ is then the description's constant parameter.
    grade: Profile | None = None
    #: The channel map of a bench recording (``[measurement]``, :mod:`.measurement`), or None.
    measurement: ChannelMap | None = None

    def input_torque(self, t: float) -> float:
        return self.engine(t) + self.e_machine(t)

    def breakpoints(self) -> list[float]:
        """Times where an input changes slope: the integrator restarts there."""
        times = {0.0, self.t_end}
        grade = () if self.grade is None else (self.grade,)
        for profile in (self.engine, self.e_machine, *self.pressure.values(), *grade):
            times.update(float(t) for t in profile.time if 0 < t < self.t_end)
        return sorted(times)


def default_scenario_path() -> Path:
    return data_file(DEFAULT_SCENARIO)


def load_scenario(d: GearboxDescription, path: str | Path | None = None) -> Scenario:
    """Load and check a scenario against the gearbox description."""
    file = str(path) if path is not None else f"<built-in {DEFAULT_SCENARIO}>"
    source = Path(path) if path is not None else default_scenario_path()
    data = parse_toml(read_text(source, file), file)

    def fail(key: str, reason: str) -> GearsymError:
        return GearsymError(file, key, reason)

    def only(table: dict, key: str, known: tuple[str, ...]) -> None:
        unknown = sorted(set(table) - set(known))
        if unknown:
            raise fail(f"{key}.{unknown[0]}", unknown_key_reason(unknown[0], known))

    known_tables = ("scenario", "input_torque", "pressure", "grade", "measurement")
    unknown = sorted(set(data) - set(known_tables))
    if unknown:
        known = known_tables
        raise fail(unknown[0], unknown_key_reason(unknown[0], known, "table"))
    head = data.get("scenario")
    if not isinstance(head, dict):
        raise fail("scenario", "missing table [scenario]")
    for key in ("shift", "t_end", "vehicle_speed"):
        if key not in head:
            raise fail(f"scenario.{key}", "missing required key")
    only(head, "scenario", ("name", "shift", "t_end", "vehicle_speed"))
    title = head.get("name")
    if title is not None and not isinstance(title, str):
        raise fail("scenario.name", f"expected a string, got {shown(title)}")
    try:
        spec = shift_spec(d, str(head["shift"]))
    except GearsymError as err:
        raise fail("scenario.shift", err.reason) from None
    t_end = _number(fail, "scenario.t_end", head["t_end"])
    if not 0 < t_end <= T_END_MAX:
        raise fail(
            "scenario.t_end",
            f"must be a positive number of seconds, at most {T_END_MAX:g} (one shift; the "
            f"limit bounds the run time and the {SAMPLE_TIME * 1e3:g} ms samples written), "
            f"got {t_end:g}",
        )
    speed = head["vehicle_speed"]
    if not isinstance(speed, dict) or speed.get("unit") != "m/s":
        raise fail("scenario.vehicle_speed", 'expected { value = ..., unit = "m/s", source = ... }')
    only(speed, "scenario.vehicle_speed", ("value", "unit", "source"))
    v0 = _number(fail, "scenario.vehicle_speed.value", speed.get("value"))
    if not v0 > 0:
        raise fail("scenario.vehicle_speed.value", f"must be a positive speed, got {v0:g}")

    torque = data.get("input_torque")
    if not isinstance(torque, dict):
        raise fail("input_torque", "missing table [input_torque]")
    only(torque, "input_torque", ("unit", "time", "engine", "e_machine"))
    if torque.get("unit") != "N*m":
        raise fail("input_torque.unit", f"expected 'N*m', got {shown(torque.get('unit'))}")
    times = _series(fail, "input_torque.time", torque.get("time"))
    _increasing(fail, "input_torque.time", times)
    engine = _series(fail, "input_torque.engine", torque.get("engine", [0.0] * len(times)))
    e_machine = _series(fail, "input_torque.e_machine", torque.get("e_machine", [0.0] * len(times)))
    for key, values in (("engine", engine), ("e_machine", e_machine)):
        if len(values) != len(times):
            raise fail(f"input_torque.{key}", f"has {len(values)} values for {len(times)} times")

    pressures: dict[str, Profile] = {}
    element_names = [e.name for e in d.shift_elements]
    table = data.get("pressure", {})
    if not isinstance(table, dict):
        raise fail("pressure", "expected tables [pressure.<element>]")
    for name, entry in table.items():
        key = f"pressure.{name}"
        if name not in element_names:
            raise fail(
                key, f"unknown shift element {shown(name)} (known: {', '.join(element_names)})"
            )
        if d.element(name).one_way:
            raise fail(key, f"{name} is a one-way clutch: it is not pressed, it locks by itself")
        if not isinstance(entry, dict) or entry.get("unit") != "Pa":
            raise fail(f"{key}.unit", "expected unit = 'Pa'")
        only(entry, key, ("unit", "time", "value"))
        t = _series(fail, f"{key}.time", entry.get("time"))
        _increasing(fail, f"{key}.time", t)
        values = _series(fail, f"{key}.value", entry.get("value"))
        if len(values) != len(t):
            raise fail(f"{key}.value", f"has {len(values)} values for {len(t)} times")
        if np.any(values < 0):
            raise fail(f"{key}.value", f"pressures must not be negative, got {values.min():g} Pa")
        pressures[name] = Profile(t, values)
    for name in element_names:
        pressures.setdefault(name, Profile(np.array([0.0]), np.array([0.0])))

    grade = None
    if "grade" in data:
        entry = data["grade"]
        if not isinstance(entry, dict):
            raise fail("grade", 'expected a table [grade] with unit = "rad", time, value')
        only(entry, "grade", ("unit", "time", "value"))
        if entry.get("unit") != "rad":
            raise fail("grade.unit", f"expected 'rad', got {shown(entry.get('unit'))}")
        t = _series(fail, "grade.time", entry.get("time"))
        _increasing(fail, "grade.time", t)
        values = _series(fail, "grade.value", entry.get("value"))
        if len(values) != len(t):
            raise fail("grade.value", f"has {len(values)} values for {len(t)} times")
        worst = float(np.max(np.abs(values)))
        if worst > GRADE_MAX:
            raise fail(
                "grade.value",
                f"|zeta| must be at most {GRADE_MAX:g} rad (a 55 % grade; the steepest roads "
                f"are about 35 %: degrees or percent?), got {worst:g} rad",
            )
        grade = Profile(t, values)
    channel_map = None
    if "measurement" in data:
        channel_map = parse_channel_map(d, file, data["measurement"], t_end)
    return Scenario(
        name=title if title is not None else spec.name,
        file=file,
        shift=spec,
        t_end=t_end,
        vehicle_speed=v0,
        engine=Profile(times, engine),
        e_machine=Profile(times, e_machine),
        pressure=pressures,
        grade=grade,
        measurement=channel_map,
    )


def _number(fail: Callable[[str, str], GearsymError], key: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(key, f"expected a number, got {shown(value)}")
    if not math.isfinite(value):
        raise fail(key, f"must be finite, got {shown(value)}")
    return float(value)


def _series(fail: Callable[[str, str], GearsymError], key: str, values: object) -> np.ndarray:
    if not isinstance(values, list) or not values:
        raise fail(key, "expected a non-empty list of numbers")
    if len(values) > POINTS_MAX:
        # every point can be a breakpoint, where the integrator restarts
        raise fail(key, f"at most {POINTS_MAX} points per profile, got {len(values)}")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise fail(key, "expected a list of numbers")
    array = np.array(values, dtype=float)
    if not all(math.isfinite(v) for v in array):
        raise fail(key, "values must be finite")
    return array


def _increasing(fail: Callable[[str, str], GearsymError], key: str, times: np.ndarray) -> None:
    if np.any(np.diff(times) <= 0):
        bad = int(np.argmax(np.diff(times) <= 0))
        raise fail(
            key,
            f"times must increase strictly (entry {bad + 1}: {times[bad + 1]:g} after "
            f"{times[bad]:g})",
        )


def with_measured_inputs(scenario: Scenario, measurement: Measurement) -> Scenario:
    """``scenario`` with every input the recording carries replaced by its resampled trace
    (linear between grid samples): T_In as the engine torque (e-machine 0), the pressures,
    ζ; inputs the recording lacks keep the scenario's profiles."""
    t = measurement.t
    values = measurement.values
    changes: dict[str, Any] = {}
    if "T_In" in values:
        changes["engine"] = Profile(t, values["T_In"])
        changes["e_machine"] = Profile(np.array([0.0]), np.array([0.0]))
    pressure = dict(scenario.pressure)
    for name in list(pressure):
        if f"p_{name}" in values:
            pressure[name] = Profile(t, values[f"p_{name}"])
    changes["pressure"] = pressure
    if "zeta" in values:
        changes["grade"] = Profile(t, values["zeta"])
    return replace(scenario, **changes)


def input_sources(scenario: Scenario, measurement: Measurement) -> dict[str, str]:
    """Per input of the simulation, where it comes from: the recording or the scenario."""
    names = ["T_In", *(f"p_{e}" for e in scenario.pressure), "zeta"]
    return {
        n: "recording" if n in measurement.values else "scenario"
        for n in names
        if n != "zeta" or scenario.grade is not None or n in measurement.values
    }
