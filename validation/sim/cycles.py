"""Driving cycles and grade profiles of a drive (``gearsym drive``): standard cycles as data,
a user's CSV of time and speed, and a grade over distance.

The built-in cycles live in ``gearsym/data/cycles/<name>.csv``, each with its source and its
published facts in a header of ``#`` lines: WLTC class 3b (UN GTR No. 15), UDDS (the FTP-75's
urban schedule), US06 and HWFET (US EPA). A cycle file has the columns ``t`` (s) and ``v``
(km/h); a grade file ``s`` (m, distance travelled) and ``grade`` (%, uphill positive). Lines
starting with ``#`` are comments, the first other line names the columns. Bad files raise
:class:`GearsymError` naming the file, the row and column, and the reason.

Between the samples the speed is linear in time (the regulations give 1 Hz points and a
vehicle's speed is continuous); the grade is linear in distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.input_files import read_text
from gearsym.symbolic.io.package_data import data_file

__all__ = [
    "BUILT_IN_CYCLES",
    "Cycle",
    "GradeProfile",
    "load_cycle",
    "load_grade",
]

#: The cycles shipped with gearsym (``--cycle NAME``).
BUILT_IN_CYCLES: tuple[str, ...] = ("wltc3b", "udds", "us06", "hwfet")

#: Stated limits of a user's file: a cycle of at most one day at 1 Hz, speeds of a road
#: vehicle, grades of a road (the steepest public roads are about 35 %).
ROWS_MAX = 86_400
V_MAX_KMH = 300.0
GRADE_MAX_PERCENT = 40.0


@dataclass(frozen=True)
class Cycle:
    """A speed trace: ``t`` (s, increasing from 0) and ``v`` (km/h), linear in between."""

    name: str
    t: np.ndarray
    v_kmh: np.ndarray
    source: str
    file: str

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def distance_km(self) -> float:
        """∫ v dt of the piecewise-linear trace (exact for it)."""
        return float(np.trapezoid(self.v_kmh / 3.6, self.t) / 1000.0)

    @property
    def v_max_kmh(self) -> float:
        return float(np.max(self.v_kmh))

    def speed(self, t: float | np.ndarray) -> float | np.ndarray:
        """v(t) in m/s (held at the ends)."""
        return np.interp(t, self.t, self.v_kmh) / 3.6

    def acceleration(self, t: float) -> float:
        """dv/dt in m/s² of the segment holding t (0 outside)."""
        k = int(np.searchsorted(self.t, t, side="right")) - 1
        if k < 0 or k >= len(self.t) - 1:
            return 0.0
        return float((self.v_kmh[k + 1] - self.v_kmh[k]) / 3.6 / (self.t[k + 1] - self.t[k]))

    def window(self, t_end: float) -> Cycle:
        """The first ``t_end`` seconds (a short drive for tests and previews)."""
        if not 0 < t_end:
            raise ValueError(f"t_end must be positive, got {t_end}")
        keep = self.t < t_end
        t = np.append(self.t[keep], t_end) if t_end < self.t[-1] else self.t
        v = np.interp(t, self.t, self.v_kmh)
        return Cycle(f"{self.name}[0:{t_end:g} s]", t, v, self.source, self.file)

    def to_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "duration_s": self.duration_s,
            "distance_km": self.distance_km,
            "v_max_kmh": self.v_max_kmh,
            "source": self.source,
        }


@dataclass(frozen=True)
class GradeProfile:
    """Road grade over distance: ``s`` (m, increasing) and ``grade`` (%), linear in between."""

    s: np.ndarray
    percent: np.ndarray
    file: str

    def zeta(self, s: float) -> float:
        """The grade angle ζ (rad, 2.49) at distance s: atan(grade / 100), held at the ends."""
        return math.atan(float(np.interp(s, self.s, self.percent)) / 100.0)


def load_cycle(name_or_path: str | Path) -> Cycle:
    """A built-in cycle by name (:data:`BUILT_IN_CYCLES`) or a user's CSV file."""
    name = str(name_or_path)
    if name in BUILT_IN_CYCLES:
        path = data_file(f"cycles/{name}.csv")
        shown = f"<built-in cycle {name}>"
    else:
        path = Path(name)
        shown = name
        if path.suffix.lower() != ".csv" and not path.exists():
            raise GearsymError(
                name,
                "--cycle",
                f"neither a built-in cycle ({', '.join(BUILT_IN_CYCLES)}) nor a file",
            )
    text = read_text(path, shown)
    rows, (t, v) = _read_csv(text, shown, ("t", "v"))
    _check_increasing(shown, "t", t, rows)
    if t[0] != 0.0:
        raise GearsymError(shown, f"row {rows[0]}, column t", f"must start at 0 s, got {t[0]:g}")
    for k, value in enumerate(v):
        if not 0.0 <= value <= V_MAX_KMH:
            raise GearsymError(
                shown,
                f"row {rows[k]}, column v",
                f"speed must be within 0-{V_MAX_KMH:g} km/h, got {value:g}",
            )
    source = " ".join(
        line.lstrip("#").strip() for line in text.splitlines() if line.startswith("#")
    )
    label = name if name in BUILT_IN_CYCLES else path.stem
    return Cycle(label, t, v, source or "user file", shown)


def load_grade(path: str | Path) -> GradeProfile:
    """A grade profile from a CSV file with columns ``s`` (m) and ``grade`` (%)."""
    shown = str(path)
    text = read_text(path, shown)
    rows, (s, grade) = _read_csv(text, shown, ("s", "grade"))
    _check_increasing(shown, "s", s, rows)
    if s[0] < 0:
        raise GearsymError(shown, f"row {rows[0]}, column s", f"must be >= 0 m, got {s[0]:g}")
    for k, value in enumerate(grade):
        if abs(value) > GRADE_MAX_PERCENT:
            raise GearsymError(
                shown,
                f"row {rows[k]}, column grade",
                f"must be within +-{GRADE_MAX_PERCENT:g} % (a percentage, uphill positive), "
                f"got {value:g}",
            )
    return GradeProfile(s, grade, shown)


def _read_csv(
    text: str, shown: str, names: tuple[str, str]
) -> tuple[list[int], tuple[np.ndarray, np.ndarray]]:
    """The two named columns of a comma-separated file (``#`` comments, a header line);
    returns each data row's line number and the columns. Extra columns are refused: a file with a
    column this reader ignores would be silently misread."""
    lines = text.splitlines()
    rows: list[tuple[int, list[str]]] = [
        (n, line.split(","))
        for n, line in enumerate(lines, start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not rows:
        raise GearsymError(shown, "header", f"empty file; expected columns {','.join(names)}")
    header_line, header = rows[0]
    given = tuple(h.strip() for h in header)
    if given != names:
        raise GearsymError(
            shown,
            f"row {header_line}",
            f"expected the header {','.join(names)}, got {','.join(given)}",
        )
    data = rows[1:]
    if len(data) < 2:
        raise GearsymError(shown, "rows", f"at least 2 rows of data needed, got {len(data)}")
    if len(data) > ROWS_MAX:
        raise GearsymError(shown, "rows", f"at most {ROWS_MAX} rows of data, got {len(data)}")
    columns = np.empty((2, len(data)))
    for k, (n, fields) in enumerate(data):
        if len(fields) != 2:
            raise GearsymError(shown, f"row {n}", f"expected 2 values, got {len(fields)}")
        for j, field in enumerate(fields):
            try:
                value = float(field)
            except ValueError:
                raise GearsymError(
                    shown, f"row {n}, column {names[j]}", f"not a number: {field.strip()!r}"
                ) from None
            if not math.isfinite(value):
                raise GearsymError(shown, f"row {n}, column {names[j]}", "must be finite")
            columns[j, k] = value
    return [n for n, _ in data], (columns[0], columns[1])


def _check_increasing(shown: str, column: str, values: np.ndarray, rows: list[int]) -> None:
    steps = np.diff(values)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise GearsymError(
            shown,
            f"row {rows[k]}, column {column}",
            f"must increase, got {values[k]:g} after {values[k - 1]:g}",
        )
