"""Measured shifts: a bench recording (MDF4 or CSV) mapped onto gearsym's signals.

A scenario file may carry a channel map, the table ``[measurement]``::

    [measurement]
    sample_time = 0.01        # s: the analysis grid t_k = k T_s, 0 <= t_k <= t_end
    resample = "linear"       # linear interpolation between the recorded samples (the only one)
    time_channel = "time"     # CSV: the header of the time column (MDF4: each channel's master)
    time_unit = "s"           # "s" or "ms"
    time_offset = 0.0         # s: the recording's time at the scenario's t = 0

    [measurement.channel]     # gearsym signal = { name, unit [, gain, offset] }
    omega_1 = { name = "n_turbine", unit = "rpm" }
    T_In = { name = "Tq_in", unit = "Nm" }
    p_K38 = { name = "p_K38", unit = "bar", gain = 1.0, offset = 0.0 }

Signals: the measured speeds ``omega_<shaft>`` and the wheel speed ``omega_C`` (outputs, thesis
(3.31)); the inputs ``T_In`` (engine + e-machine), ``p_<element>`` and ``zeta`` (2.49). A value
in SI units is ``to_si(gain * raw + offset, unit)`` with the explicit table :data:`UNITS`
(rpm -> rad/s by 2π/60, bar -> Pa by 1e5, % grade -> rad by atan(g/100), ...).

Resampling: every channel is interpolated linearly onto the analysis grid (``np.interp``
between the recorded samples around each grid time); the simulation holds an input linear
between grid samples, as the scenario's own profiles. A NaN in a speed channel makes the grid
samples next to it NaN: the filter skips those updates (a sensor dropout); an input must not be
NaN. Refused, one line naming the file, the key and the reason: a missing channel, an unknown
unit or one that contradicts the recording's, a time base that does not cover the scenario's
window, time that does not increase strictly, NaN in an input, a sample beyond its quantity's
plausible bound (:data:`PLAUSIBLE_MAX`), a file beyond the limits on bytes, samples and
channels (:data:`RECORDING_BYTES_MAX`, :data:`RECORDING_SAMPLES_MAX`,
:data:`RECORDING_CHANNELS_MAX`; docs/limits.md), a damaged MDF4 file (read in a child process,
:mod:`.mdf_read`: a crash of asammdf is one line, not the end of gearsym).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from gearsym.symbolic.defaults import EKF_FLOOR_FRACTION, RECORD_SAMPLE_TIME
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.input_files import shown, unknown_key_reason

if TYPE_CHECKING:
    from gearsym.symbolic.description import GearboxDescription

__all__ = [
    "PLAUSIBLE_MAX",
    "RECORDING_BYTES_MAX",
    "RECORDING_CHANNELS_MAX",
    "RECORDING_SAMPLES_MAX",
    "UNITS",
    "Channel",
    "ChannelMap",
    "Measurement",
    "from_si",
    "parse_channel_map",
    "read_measurement",
    "recording_bytes",
    "to_si",
]

#: Most samples of the analysis grid: each is a breakpoint of the recorded inputs where the
#: integrator restarts (1501 samples, 1 ms over the 1.5 s example, simulated in 15 s).
GRID_SAMPLES_MAX = 5000

#: Largest recording read (bytes): a one-shift bench file at 1 kHz with 50 channels is ~10 MB.
RECORDING_BYTES_MAX = 256 << 20

#: Most samples of one recorded channel (MDF4: the cycle count of its channel group, checked in
#: the header before any data are read; CSV: data rows): 1000 s at 1 kHz. A channel read is
#: 8 bytes a sample for its time and 8 for its values (16 MB at the limit).
RECORDING_SAMPLES_MAX = 1_000_000

#: Most channels in an MDF4 file (all channel groups) or columns in a CSV header.
RECORDING_CHANNELS_MAX = 10_000

#: Longest CSV line (characters): a header of 10 000 channel names fits.
CSV_LINE_CHARS_MAX = 1 << 20

#: Largest plausible |value| per quantity (SI, after gain, offset and unit) of a recorded
#: sample the analysis uses: 5000 rad/s is 47 700 rpm (e-machines turn up to ~20 000 rpm),
#: 100 bar (clutch pressures stay below ~30 bar), 10 000 N*m (a truck engine gives ~3500 N*m);
#: 0.5 rad of grade, the scenarios' GRADE_MAX (a test holds them equal). A sample of 1e300 is
#: a broken sensor or file.
PLAUSIBLE_MAX = {"speed": 5000.0, "pressure": 1e7, "torque": 1e4, "grade": 0.5}

#: The start time written into a synthetic MDF4 (the same input gives the same bytes).
RECORDING_START_TEXT = "2018-01-01T00:00:00+00:00"

RESAMPLE = "linear"
RESAMPLE_TEXT = (
    "linear interpolation of each channel onto the analysis grid t_k = k T_s; the simulation "
    "holds the inputs linear between grid samples"
)


def _percent_to_rad(v: np.ndarray) -> np.ndarray:
    return np.arctan(v / 100.0)


def _rad_to_percent(v: np.ndarray) -> np.ndarray:
    return 100.0 * np.tan(v)


def _scale(k: float) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], Any]]:
    return (lambda v: v * k), (lambda v: v / k)


#: Per quantity, per unit: (to SI, from SI). SI: rad/s, Pa, N*m, rad.
UNITS: dict[str, dict[str, tuple[Callable[[np.ndarray], Any], Callable[[np.ndarray], Any]]]] = {
    "speed": {
        "rad/s": _scale(1.0),
        "rpm": _scale(2 * math.pi / 60),
        "1/min": _scale(2 * math.pi / 60),
    },
    "pressure": {
        "Pa": _scale(1.0),
        "kPa": _scale(1e3),
        "bar": _scale(1e5),
        "mbar": _scale(1e2),
        "MPa": _scale(1e6),
    },
    "torque": {"N*m": _scale(1.0), "Nm": _scale(1.0)},
    "grade": {
        "rad": _scale(1.0),
        "deg": _scale(math.pi / 180),
        "%": (_percent_to_rad, _rad_to_percent),
    },
}
SI_UNIT = {"speed": "rad/s", "pressure": "Pa", "torque": "N*m", "grade": "rad"}


def to_si(values: np.ndarray, unit: str, quantity: str) -> np.ndarray:
    """``values`` in ``unit`` converted to the SI unit of ``quantity`` (:data:`UNITS`)."""
    return np.asarray(UNITS[quantity][unit][0](np.asarray(values, dtype=float)), dtype=float)


def from_si(values: np.ndarray, unit: str, quantity: str) -> np.ndarray:
    """The inverse of :func:`to_si`."""
    return np.asarray(UNITS[quantity][unit][1](np.asarray(values, dtype=float)), dtype=float)


@dataclass(frozen=True)
class Channel:
    """One gearsym signal's channel in the recording: SI = to_si(gain * raw + offset, unit)."""

    signal: str
    name: str
    unit: str
    quantity: str
    gain: float = 1.0
    offset: float = 0.0

    @property
    def is_input(self) -> bool:
        return self.quantity != "speed"

    def to_si(self, raw: np.ndarray) -> np.ndarray:
        return to_si(
            self.gain * np.asarray(raw, dtype=float) + self.offset, self.unit, self.quantity
        )

    def from_si(self, values: np.ndarray) -> np.ndarray:
        return (from_si(values, self.unit, self.quantity) - self.offset) / self.gain


@dataclass(frozen=True)
class ChannelMap:
    """The scenario's ``[measurement]`` table, checked."""

    file: str  # the scenario file (for messages)
    sample_time: float
    channels: tuple[Channel, ...]
    time_channel: str = "time"
    time_unit: str = "s"
    time_offset: float = 0.0
    resample: str = RESAMPLE

    def channel(self, signal: str) -> Channel | None:
        return next((c for c in self.channels if c.signal == signal), None)

    def to_dict(self) -> dict[str, Any]:
        return {
            "sample_time": self.sample_time,
            "resample": self.resample,
            "resample_text": RESAMPLE_TEXT,
            "time_channel": self.time_channel,
            "time_unit": self.time_unit,
            "time_offset": self.time_offset,
            "channels": {
                c.signal: {"name": c.name, "unit": c.unit, "gain": c.gain, "offset": c.offset}
                for c in self.channels
            },
        }


def _quantity(d: GearboxDescription, signal: str) -> str | None:
    if signal == "omega_C" or signal in {f"omega_{s.name}" for s in d.shafts}:
        return "speed"
    if signal == "T_In":
        return "torque"
    if signal == "zeta":
        return "grade"
    pressed = {f"p_{e.name}" for e in d.shift_elements if not e.one_way}
    return "pressure" if signal in pressed else None


def parse_channel_map(d: GearboxDescription, file: str, table: object, t_end: float) -> ChannelMap:
    """Check the scenario's ``[measurement]`` table (module docstring) against ``d`` and the
    scenario's ``t_end``."""

    def fail(key: str, reason: str) -> GearsymError:
        return GearsymError(file, key, reason)

    if not isinstance(table, dict):
        raise fail("measurement", "expected a table [measurement]")
    known = ("sample_time", "resample", "time_channel", "time_unit", "time_offset", "channel")
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise fail(f"measurement.{unknown[0]}", unknown_key_reason(unknown[0], known))
    if "sample_time" not in table:
        raise fail("measurement.sample_time", "missing required key (the analysis grid, s)")
    sample_time = _number(fail, "measurement.sample_time", table["sample_time"])
    if sample_time < RECORD_SAMPLE_TIME:
        raise fail(
            "measurement.sample_time",
            f"must be at least {RECORD_SAMPLE_TIME:g} s (the simulated record's spacing), "
            f"got {sample_time:g}",
        )
    if t_end / sample_time + 1 > GRID_SAMPLES_MAX:
        raise fail(
            "measurement.sample_time",
            f"{t_end:g} s at {sample_time:g} s is more than {GRID_SAMPLES_MAX} grid samples (each "
            "one a breakpoint of the recorded inputs, where the integrator restarts)",
        )
    resample = table.get("resample", RESAMPLE)
    if resample != RESAMPLE:
        raise fail(
            "measurement.resample", f"only {RESAMPLE!r} ({RESAMPLE_TEXT}), got {shown(resample)}"
        )
    time_channel = table.get("time_channel", "time")
    if not isinstance(time_channel, str) or not time_channel:
        raise fail("measurement.time_channel", f"expected a column name, got {shown(time_channel)}")
    time_unit = table.get("time_unit", "s")
    if not isinstance(time_unit, str) or time_unit not in ("s", "ms"):
        raise fail("measurement.time_unit", f"expected 's' or 'ms', got {shown(time_unit)}")
    time_offset = _number(fail, "measurement.time_offset", table.get("time_offset", 0.0))
    entries = table.get("channel")
    if not isinstance(entries, dict) or not entries:
        raise fail(
            "measurement.channel",
            'expected a table [measurement.channel] of SIGNAL = { name = "...", unit = "..." }',
        )
    channels = []
    for signal, entry in entries.items():
        key = f"measurement.channel.{signal}"
        quantity = _quantity(d, signal)
        if quantity is None:
            raise fail(
                key,
                f"unknown signal {shown(signal)}: expected omega_<shaft>, omega_C, T_In, "
                "p_<element> (a pressed element) or zeta",
            )
        if not isinstance(entry, dict):
            raise fail(key, 'expected { name = "...", unit = "..." [, gain, offset] }')
        bad = sorted(set(entry) - {"name", "unit", "gain", "offset"})
        if bad:
            raise fail(
                f"{key}.{bad[0]}", unknown_key_reason(bad[0], ("name", "unit", "gain", "offset"))
            )
        name = entry.get("name")
        if not isinstance(name, str) or not name:
            raise fail(f"{key}.name", f"expected the channel's name, got {shown(name)}")
        unit = entry.get("unit")
        if not isinstance(unit, str) or unit not in UNITS[quantity]:
            raise fail(
                f"{key}.unit",
                f"unknown unit {shown(unit)} for a {quantity} (known: "
                f"{', '.join(UNITS[quantity])})",
            )
        gain = _number(fail, f"{key}.gain", entry.get("gain", 1.0))
        if gain == 0:
            raise fail(f"{key}.gain", "must not be 0")
        offset = _number(fail, f"{key}.offset", entry.get("offset", 0.0))
        channels.append(Channel(signal, name, str(unit), quantity, gain, offset))
    return ChannelMap(
        file=file,
        sample_time=sample_time,
        channels=tuple(channels),
        time_channel=time_channel,
        time_unit=str(time_unit),
        time_offset=time_offset,
    )


def _number(fail: Callable[[str, str], GearsymError], key: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(key, f"expected a number, got {shown(value)}")
    if not math.isfinite(value):
        raise fail(key, f"must be finite, got {shown(value)}")
    return float(value)


@dataclass(frozen=True)
class Measurement:
    """A recording resampled onto the analysis grid, in SI units."""

    file: str
    format: str  # "mdf4" or "csv"
    channel_map: ChannelMap
    t: np.ndarray = field(repr=False)  # the grid, scenario time (s)
    values: dict[str, np.ndarray] = field(repr=False)  # per gearsym signal, SI, on ``t``

    @property
    def inputs(self) -> list[str]:
        return [c.signal for c in self.channel_map.channels if c.is_input]

    @property
    def outputs(self) -> list[str]:
        return [c.signal for c in self.channel_map.channels if not c.is_input]

    def to_dict(self) -> dict[str, Any]:
        return {
            "file": self.file,
            "format": self.format,
            "samples": len(self.t),
            "inputs": self.inputs,
            "outputs": self.outputs,
            "missing_samples": {s: int(np.sum(~np.isfinite(v))) for s, v in self.values.items()},
            **self.channel_map.to_dict(),
        }


def analysis_grid(t_end: float, sample_time: float) -> np.ndarray:
    """t_k = k T_s on [0, t_end], as the estimator samples a simulated shift."""
    return np.arange(0.0, t_end + 1e-12, sample_time)


def read_measurement(
    path: str | Path, channel_map: ChannelMap, t_end: float, require: Sequence[str] = ()
) -> Measurement:
    """Read the recording ``path`` (``.mf4``/``.mdf`` through asammdf in a child process,
    :mod:`.mdf_read`; else CSV with a header row, streamed), take every mapped channel, convert
    it to SI and resample it onto the grid of ``channel_map.sample_time`` over [0, ``t_end``]
    (module docstring). Every signal in ``require`` (the outputs a filter needs) must have a
    finite sample on the grid: a filter that receives no measurement estimates nothing."""
    file = str(path)
    source = Path(path)
    try:
        if not source.is_file():
            raise GearsymError(file, "", "no such file" if not source.exists() else "not a file")
        if source.stat().st_size > RECORDING_BYTES_MAX:
            raise GearsymError(
                file, "", f"larger than RECORDING_BYTES_MAX = {RECORDING_BYTES_MAX >> 20} MiB"
            )
    except OSError as err:
        raise GearsymError(file, "", f"cannot be read ({err.strerror})") from None
    grid = analysis_grid(t_end, channel_map.sample_time)
    if source.suffix.lower() in (".mf4", ".mdf"):
        from gearsym.validation.sim.mdf_read import read_mdf_on_grid

        values = read_mdf_on_grid(source, file, channel_map, t_end)
        kind = "mdf4"
    else:
        raw = _read_csv(source, file, channel_map)
        values = {
            c.signal: on_grid(file, channel_map, c, *raw.pop(c.signal), grid, t_end)
            for c in channel_map.channels
        }
        kind = "csv"
    for signal in require:
        channel = channel_map.channel(signal)
        if channel is not None and not np.any(np.isfinite(values[signal])):
            raise GearsymError(
                file,
                f"measurement.channel.{signal}",
                f"channel {channel.name!r} has no finite sample in the analysis window "
                f"0..{t_end:g} s: the filter would receive no measurement of {signal}",
            )
    return Measurement(file=file, format=kind, channel_map=channel_map, t=grid, values=values)


def on_grid(
    file: str,
    channel_map: ChannelMap,
    channel: Channel,
    t: np.ndarray,
    v: np.ndarray,
    grid: np.ndarray,
    t_end: float,
) -> np.ndarray:
    """One recorded channel (recording time ``t``, raw values ``v``) checked, in SI units and
    resampled onto ``grid`` (module docstring)."""
    key = f"measurement.channel.{channel.signal}"
    if channel_map.time_unit == "ms":
        t = t / 1e3
    t = t - channel_map.time_offset
    if not np.all(np.isfinite(t)):
        raise GearsymError(file, key, f"time of channel {channel.name!r} is not finite")
    if len(t) < 2 or np.any(np.diff(t) <= 0):
        bad = int(np.argmax(np.diff(t) <= 0)) + 1 if len(t) >= 2 else 0
        raise GearsymError(
            file,
            key,
            f"time of channel {channel.name!r} must increase strictly (sample {bad})",
        )
    slack = 1e-9 * max(1.0, t_end)
    if t[0] > slack or t[-1] < t_end - slack:
        raise GearsymError(
            file,
            key,
            f"channel {channel.name!r} covers {t[0]:g}..{t[-1]:g} s of scenario time, not "
            f"the scenario's window 0..{t_end:g} s (time_offset "
            f"{channel_map.time_offset:g} s)",
        )
    with np.errstate(over="ignore", invalid="ignore"):
        si = channel.to_si(v)
    if np.any(np.isinf(si)):
        first = int(np.argmax(np.isinf(si)))
        raise GearsymError(
            file,
            key,
            f"channel {channel.name!r} is infinite at t = {t[first]:g} s (after its gain, "
            "offset and unit)",
        )
    if channel.is_input and not np.all(np.isfinite(si)):
        first = int(np.argmax(~np.isfinite(si)))
        raise GearsymError(
            file,
            key,
            f"input channel {channel.name!r} is NaN or infinite at t = {t[first]:g} s "
            "(an input must be known at every sample)",
        )
    bound = plausible_max(channel.quantity)
    # the samples the grid uses: those in the window and one on either side
    lo = max(int(np.searchsorted(t, 0.0, side="right")) - 1, 0)
    hi = int(np.searchsorted(t, t_end, side="left")) + 1
    used = si[lo:hi]
    with np.errstate(invalid="ignore"):
        beyond = np.abs(used) > bound
    if np.any(beyond):
        first = int(np.argmax(beyond))
        raise GearsymError(
            file,
            key,
            f"channel {channel.name!r} is {used[first]:g} {SI_UNIT[channel.quantity]} at t = "
            f"{t[lo + first]:g} s, beyond the plausible |{channel.quantity}| <= {bound:g} "
            f"{SI_UNIT[channel.quantity]} (PLAUSIBLE_MAX; after its gain, offset and unit)",
        )
    resampled = np.interp(grid, t, si)
    if channel.quantity == "pressure" and np.any(resampled < 0):
        raise GearsymError(
            file,
            key,
            f"pressure {channel.name!r} is negative ({resampled.min():g} Pa); set its "
            "offset to the sensor's zero",
        )
    return resampled


def plausible_max(quantity: str) -> float:
    """The largest plausible |value| of ``quantity`` in SI units (:data:`PLAUSIBLE_MAX`)."""
    return PLAUSIBLE_MAX[quantity]


def _few(names: Sequence[str]) -> str:
    shown_names = ", ".join(names[:12])
    return f"channels: {shown_names}{', ...' if len(names) > 12 else ''}"


def _bounded_lines(handle: io.TextIOBase, file: str) -> Iterator[str]:
    """The lines of ``handle``, each read with a length limit: a file without line breaks is
    refused at :data:`CSV_LINE_CHARS_MAX` characters instead of being read whole."""
    while True:
        line = handle.readline(CSV_LINE_CHARS_MAX + 1)
        if not line:
            return
        if len(line) > CSV_LINE_CHARS_MAX:
            raise GearsymError(
                file, "", f"a line longer than CSV_LINE_CHARS_MAX = {CSV_LINE_CHARS_MAX} characters"
            )
        yield line


def _read_csv(
    source: Path, file: str, channel_map: ChannelMap
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The mapped columns, streamed row by row into float arrays (8 bytes a value): at most
    :data:`RECORDING_SAMPLES_MAX` data rows and :data:`RECORDING_CHANNELS_MAX` columns."""
    from array import array

    wanted = [("measurement.time_channel", channel_map.time_channel)] + [
        (f"measurement.channel.{c.signal}.name", c.name) for c in channel_map.channels
    ]
    names = list(dict.fromkeys(name for _, name in wanted))
    columns = {name: array("d") for name in names}
    try:
        with source.open(encoding="utf-8", newline="") as handle:
            rows = (
                r
                for r in csv.reader(_bounded_lines(handle, file))
                if r and not r[0].lstrip().startswith("#")
            )
            header_row = next(rows, None)
            if header_row is None:
                raise GearsymError(file, "", "empty: expected a header row and samples")
            header = [h.strip() for h in header_row]
            if len(header) > RECORDING_CHANNELS_MAX:
                raise GearsymError(
                    file,
                    "",
                    f"{len(header)} columns, more than RECORDING_CHANNELS_MAX = "
                    f"{RECORDING_CHANNELS_MAX}",
                )
            for key, name in wanted:
                if name not in header:
                    raise GearsymError(
                        file, key, f"no column {name!r} in the header ({_few(header)})"
                    )
            place = [(name, header.index(name)) for name in names]
            keys = {name: key for key, name in reversed(wanted)}
            for line, row in enumerate(rows, start=1):
                if line > RECORDING_SAMPLES_MAX:
                    raise GearsymError(
                        file,
                        "",
                        f"more than RECORDING_SAMPLES_MAX = {RECORDING_SAMPLES_MAX} data rows",
                    )
                for name, j in place:
                    cell = row[j].strip() if j < len(row) else ""
                    try:
                        columns[name].append(float(cell) if cell else math.nan)
                    except ValueError:
                        raise GearsymError(
                            file,
                            keys[name],
                            f"column {name!r}, data row {line}: not a number: {_clip(cell)!r}",
                        ) from None
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise GearsymError(file, "", f"cannot be read as UTF-8 CSV text ({err})") from None
    t = np.frombuffer(columns[channel_map.time_channel], dtype=float)
    return {
        c.signal: (t, np.frombuffer(columns[c.name], dtype=float)) for c in channel_map.channels
    }


def _clip(text: str, n: int = 40) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def recording_bytes(
    channel_map: ChannelMap,
    t: np.ndarray,
    values: Mapping[str, np.ndarray],
    suffix: str,
    comment: str = "",
) -> bytes:
    """A recording of ``values`` (SI, per gearsym signal, at ``t`` scenario time) as the
    channel map describes it: each channel under its name, in its unit, with gain and offset
    undone; MDF4 (float32 samples, one channel group) or CSV (``%.9g``)."""
    raw_t = t + channel_map.time_offset
    if channel_map.time_unit == "ms":
        raw_t = raw_t * 1e3
    if suffix.lower() == ".mf4":
        from asammdf import MDF, Signal

        mdf = MDF(version="4.10")
        signals = [
            Signal(
                np.asarray(c.from_si(values[c.signal]), dtype=np.float32),
                raw_t,
                name=c.name,
                unit=c.unit,
                comment=f"gearsym signal {c.signal}",
            )
            for c in channel_map.channels
        ]
        mdf.append(signals, comment=comment)
        # The same input gives the same bytes: a fixed start time and one history block
        # of a fixed time instead of the clock's.
        from datetime import UTC, datetime

        from asammdf.blocks.v4_blocks import FileHistory

        start = datetime.fromisoformat(RECORDING_START_TEXT).astimezone(UTC)
        mdf.header.start_time = start
        history = FileHistory()
        history.abs_time = int(start.timestamp()) * 10**9
        history.comment = (
            "<FHcomment><TX>created</TX><tool_id>gearsym export-measurement</tool_id>"
            "<tool_vendor>gearsym</tool_vendor><tool_version>0.1.0</tool_version></FHcomment>"
        )
        mdf.file_history.append(history)
        buffer = io.BytesIO()
        mdf.save(buffer, overwrite=True, compression=0, add_history_block=False)
        mdf.close()
        return buffer.getvalue()
    lines = [f"# {comment}"] if comment else []
    lines.append(",".join([channel_map.time_channel, *(c.name for c in channel_map.channels)]))
    columns = [np.asarray(c.from_si(values[c.signal]), dtype=float) for c in channel_map.channels]
    for k, tk in enumerate(raw_t):
        lines.append(",".join([f"{tk:.9g}", *(f"{col[k]:.9g}" for col in columns)]))
    return ("\n".join(lines) + "\n").encode("utf-8")


def synthetic_recording(
    result: Any, channel_map: ChannelMap, relative_noise: float | Sequence[float], seed: int
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A bench recording made from a reference simulation ``result``: every mapped signal
    sampled (linear interpolation) on the grid of the channel map; on the speeds Gaussian noise
    of σ_i = r_i max(|y_i|, y_i^min) (3.26), y_i^min 1 % of the largest |y_i|, drawn from
    ``seed`` as one (samples × speeds) array in the map's order; the inputs exact.

    The draw is the EKF's synthetic one
    (:func:`gearsym.validation.studies.estimation.loop.noisy_outputs`) when the map lists the
    filter's outputs in the filter's order: the same seed, the same noise. Returns the grid
    (scenario time) and the SI values per signal."""

    t_end = float(result.scenario.t_end)
    grid = analysis_grid(t_end, channel_map.sample_time)
    values = {}
    for c in channel_map.channels:
        if c.signal not in result.signals:
            raise GearsymError(
                channel_map.file,
                f"measurement.channel.{c.signal}",
                "the reference simulation has no such signal",
            )
        values[c.signal] = np.interp(grid, result.t, result.signals[c.signal])
    speeds = [c.signal for c in channel_map.channels if not c.is_input]
    if speeds:
        y = np.column_stack([values[s] for s in speeds])
        r = np.broadcast_to(np.asarray(relative_noise, dtype=float), (len(speeds),))
        floor = EKF_FLOOR_FRACTION * np.max(np.abs(y), axis=0)
        sigma = r[None, :] * np.maximum(np.abs(y), floor[None, :])
        y = y + np.random.default_rng(seed).normal(0.0, 1.0, y.shape) * sigma
        for k, s in enumerate(speeds):
            values[s] = y[:, k]
    return grid, values


def compare_outputs(result: Any, measurement: Measurement) -> dict[str, dict[str, Any]]:
    """Per recorded speed: the simulation (driven by the recorded inputs) at the grid times
    against the recording: RMS and largest residual (simulated − measured) over the samples
    that are not NaN, in rad/s and relative to the RMS of the recorded speed."""
    out = {}
    for name in measurement.outputs:
        simulated = np.interp(measurement.t, result.t, result.signals[name])
        measured = measurement.values[name]
        ok = np.isfinite(measured)
        residual = simulated[ok] - measured[ok]
        rms = float(np.sqrt(np.mean(residual**2))) if ok.any() else None
        scale = float(np.sqrt(np.mean(measured[ok] ** 2))) if ok.any() else 0.0
        out[name] = {
            "channel": measurement.channel_map.channel(name).name,  # type: ignore[union-attr]
            "samples": int(ok.sum()),
            "rms_residual": rms,
            "max_abs_residual": float(np.max(np.abs(residual))) if ok.any() else None,
            "relative_rms_residual": rms / scale if rms is not None and scale > 0 else None,
            "unit": "rad/s",
        }
    return out


def write_comparison_csv(result: Any, measurement: Measurement, path: Path) -> Path:
    """At the grid times: per recorded speed the measured and the simulated value (rad/s)."""
    header = ["t"]
    columns = []
    for name in measurement.outputs:
        header += [f"{name}_measured", f"{name}_simulated"]
        columns += [
            measurement.values[name],
            np.interp(measurement.t, result.t, result.signals[name]),
        ]
    lines = [",".join(header)]
    for k, t in enumerate(measurement.t):
        cells = [f"{t:.6g}", *(f"{c[k]:.9g}" if np.isfinite(c[k]) else "" for c in columns)]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def plot_comparison(result: Any, measurement: Measurement, path: Path) -> Path:
    """The recorded speeds (dots) against the simulation driven by the recorded inputs."""
    from gearsym.validation.drawing.figures import save, subplots

    names = measurement.outputs
    fig, axes = subplots(len(names), 1, size=(8.0, 2.2 * len(names) + 0.8), sharex=True)
    axes = np.atleast_1d(axes)
    stats = compare_outputs(result, measurement)
    for ax, name in zip(axes, names, strict=True):
        ax.plot(result.t, result.signals[name], lw=1.2, label="simulated (recorded inputs)")
        ax.plot(measurement.t, measurement.values[name], ".", ms=2.5, label="recorded")
        rms = stats[name]["rms_residual"]
        ax.set_ylabel(f"{name} (rad/s)")
        ax.set_title(
            f"{name} ({stats[name]['channel']}): RMS residual "
            + ("n/a" if rms is None else f"{rms:.3g} rad/s"),
            fontsize=9,
        )
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("t (s)")
    fig.suptitle(f"{measurement.file}: recording against the reference simulation", fontsize=10)
    return save(fig, path)
