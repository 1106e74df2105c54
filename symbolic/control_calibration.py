"""What the TCU's shift controller assumes and how it is tuned, read from a description's
optional ``[control]`` table (the adaptive shift control of issue 29).

The plant takes a pressure per element; between the controller's command and that pressure lie
a pressure-control valve and the clutch's piston fill (``validation/sim/actuator.py``). The
table states the TCU's nominal model of them, the controller's tuning and the adaptation's
steps and limits::

    [control.actuator]      # the TCU's nominal valve and piston fill
    dead_time = { value = 0.010, unit = "s", source = "..." }
    time_constant = { value = 0.030, unit = "s", source = "..." }     # chamber pressure lag
    fill_time = { value = 0.100, unit = "s", source = "..." }         # stroke at fast fill
    fast_fill_pressure = { value = 3.0e5, unit = "Pa", source = "..." }
    return_spring = { value = 0.8e5, unit = "Pa", source = "..." }    # force only above it
    [control.shift]         # the shift controller's tuning
    torque_phase = { value = 0.15, unit = "s", source = "..." }
    inertia_phase = { value = 0.35, unit = "s", source = "..." }      # target duration
    fill_hold = { value = 0.2e5, unit = "Pa", source = "..." }        # above the spring
    slip_k_p = { value = 400.0, unit = "Pa*s/rad", source = "..." }
    slip_t_i = { value = 0.2, unit = "s", source = "..." }
    lockup_slip = { value = 5.0, unit = "rad/s", source = "..." }
    off_going_margin = { value = 1.2, unit = "1", source = "..." }
    [control.adaptation]    # rule-based adaptation: step per shift and its limit
    fill_step = { value = 0.020, unit = "s", source = "..." }
    fill_limit = { value = 0.100, unit = "s", source = "..." }
    pressure_step = { value = 500.0, unit = "Pa", source = "..." }
    pressure_limit = { value = 3.0e4, unit = "Pa", source = "..." }

Every entry is optional and positive; the defaults below are stated. The fast-fill pressure
must lie above the return spring's, or the piston never strokes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from gearsym.symbolic.drive_calibration import Entry

__all__ = [
    "HOLD_AFTER_FILL",
    "HOLD_LINE",
    "MEAN_OVER",
    "MOVING",
    "RAMP_FRACTION",
    "SECANT_FORCE_MIN",
    "TICK",
    "TIMEOUT_FACTOR",
    "TO_LINE",
    "ControlCalibration",
    "Entry",
    "default_control",
    "parse_control_table",
]

# The shift controller's fixed numbers (not calibration: the phases' structure), one place
# for the Python controller (validation/studies/control/controller.py) and the emitted C
# task (symbolic/codegen/control.py).
#: The TCU task's period (s): commands change only at its ticks.
TICK = 0.01
#: Fill hold after the fast fill (s) before the torque phase starts.
HOLD_AFTER_FILL = 0.03
#: Ramp to line pressure and hold after lock-up (s).
TO_LINE = 0.1
HOLD_LINE = 0.1
#: The inertia phase gives up on its target after this many target durations.
TIMEOUT_FACTOR = 2.0
#: Fraction of the inertia phase over which the slip acceleration ramps in and out.
RAMP_FRACTION = 0.25
#: The least F₁ of the inertia phase feed-forward's secant (N).
SECANT_FORCE_MIN = 1e3
#: The filter holds each tick's pressures over the tick: it is told their mean over it, on
#: this many sub-intervals (the trapezoid rule; the Python study's filter and the emitted task's).
MEAN_OVER = 8
#: A shift the input torque drives: the on-coming slip's fall (fraction of its start) that
#: shows the off-going element slides (the slip target's clock starts there).
MOVING = 0.01

_DEFAULT = "gearsym default (assumed; the description states none)"

#: The sections of ``[control]``, in the file's order.
SECTIONS: tuple[str, ...] = ("actuator", "shift", "adaptation")

#: (section, key): (value, unit) of every entry and its default.
_SCALARS: dict[tuple[str, str], tuple[float, str]] = {
    ("actuator", "dead_time"): (0.010, "s"),
    ("actuator", "time_constant"): (0.030, "s"),
    ("actuator", "fill_time"): (0.100, "s"),
    ("actuator", "fast_fill_pressure"): (3.0e5, "Pa"),
    ("actuator", "return_spring"): (0.8e5, "Pa"),
    ("shift", "torque_phase"): (0.15, "s"),
    ("shift", "inertia_phase"): (0.35, "s"),
    ("shift", "fill_hold"): (0.2e5, "Pa"),
    ("shift", "slip_k_p"): (400.0, "Pa*s/rad"),
    ("shift", "slip_t_i"): (0.2, "s"),
    ("shift", "lockup_slip"): (5.0, "rad/s"),
    ("shift", "off_going_margin"): (1.2, "1"),
    ("adaptation", "fill_step"): (0.020, "s"),
    ("adaptation", "fill_limit"): (0.100, "s"),
    ("adaptation", "pressure_step"): (500.0, "Pa"),
    ("adaptation", "pressure_limit"): (3.0e4, "Pa"),
}


@dataclass(frozen=True)
class ControlCalibration:
    """The ``[control]`` table (module docstring); ``values[(section, key)]`` in SI units."""

    values: tuple[tuple[tuple[str, str], Entry], ...]
    file: str = field(default="", compare=False)

    def entry(self, section: str, key: str) -> Entry:
        """The stated number with its unit and source."""
        return dict(self.values)[(section, key)]

    def si(self, section: str, key: str) -> float:
        """The entry in SI units (every unit of the table is SI already)."""
        return self.entry(section, key).value

    def to_dict(self) -> dict[str, Any]:
        """``{section: {key: {value, unit, source}}}``, for reports and JSON."""
        out: dict[str, Any] = {}
        for (section, key), q in self.values:
            entry = {"value": q.value, "unit": q.unit, "source": q.source}
            out.setdefault(section, {})[key] = entry
        return out


def default_control() -> ControlCalibration:
    """Every stated default (a description without ``[control]``)."""
    return ControlCalibration(
        tuple((k, Entry(v, unit, _DEFAULT)) for k, (v, unit) in _SCALARS.items())
    )


def parse_control_table(table: Any) -> ControlCalibration:
    """The ``[control]`` table read through a
    :class:`~gearsym.symbolic.io.table_reader.TableReader` (absent entries: the defaults);
    an unknown section or key, a wrong unit, a missing source or a value that is not positive
    raises a one-line :class:`~gearsym.symbolic.errors.GearsymError` naming file and key."""
    values = dict(default_control().values)
    actuator = None
    for section in SECTIONS:
        sub = table.table(section, required=False)
        for (s, key), (_, unit) in _SCALARS.items():
            if s == section and key in sub.data:
                q = sub.quantity(key, unit=unit)
                values[(s, key)] = Entry(q.value, q.unit, q.source)
        sub.reject_unknown()
        if section == "actuator":
            actuator = sub
    table.reject_unknown()
    fast, spring = values[("actuator", "fast_fill_pressure")], values[("actuator", "return_spring")]
    if not fast.value > spring.value:
        assert actuator is not None
        raise actuator.fail(
            "fast_fill_pressure",
            f"must lie above return_spring ({spring.value:g} Pa), got {fast.value:g} Pa: "
            "the piston would never stroke",
        )
    return ControlCalibration(tuple(values.items()), file=table.file)
