"""Typed access to a TOML table whose every error names the file and the key path in one
line (:class:`TableReader`): the description, the fleet and every other TOML input gearsym
reads go through it, so a wrong key reads the same wherever it is."""

from __future__ import annotations

import difflib
import math
from typing import Any

from gearsym.symbolic.description import (
    ENTRIES_MAX,
    EXPECTED_UNITS,
    NAME_MAX_LENGTH,
    NAME_PATTERN,
    Quantity,
)
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.input_files import shown, unknown_key_reason

__all__ = ["TableReader", "short_integer"]


def short_integer(value: int) -> str:
    """An integer for a message: 10**400 is not worth 401 digits."""
    text = str(value)
    return text if len(text) <= 20 else f"a {len(text)}-digit number"


class TableReader:
    """Typed access to a TOML table that reports errors with the file and the key path."""

    def __init__(self, file: str, table: dict[str, Any], path: str) -> None:
        self.file = file
        self.data = table
        self.path = path
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, reason: str) -> GearsymError:
        return GearsymError(self.file, self.key(name), reason)

    def _get(self, name: str, required: bool) -> Any:
        self.used.add(name)
        if name not in self.data:
            if required:
                near = difflib.get_close_matches(name, [str(k) for k in self.data], n=1)
                hint = f" (is {near[0]!r} a misspelling?)" if near else ""
                raise self.fail(name, f"missing required key{hint}")
            return None
        return self.data[name]

    def string(self, name: str, required: bool = True, default: str = "") -> str:
        value = self._get(name, required)
        if value is None:
            return default
        if not isinstance(value, str):
            raise self.fail(name, f"expected a string, got {type(value).__name__}")
        return value

    def name(self, name: str = "name") -> str:
        value = self.string(name)
        if not NAME_PATTERN.fullmatch(value) or len(value) > NAME_MAX_LENGTH:
            raise self.fail(
                name,
                f"{shown(value)} is not usable in a C identifier (letters and digits, joined by "
                f"single '_'; no leading, trailing or double '_'; at most {NAME_MAX_LENGTH} "
                "characters)",
            )
        return value

    def integer(self, name: str, required: bool = True, default: int = 0) -> int:
        value = self._get(name, required)
        if value is None:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(name, f"expected an integer, got {shown(value)}")
        return value

    def positive_integer(
        self, name: str, required: bool = True, default: int = 0, maximum: int | None = None
    ) -> int:
        value = self.integer(name, required, default)
        if value <= 0:
            raise self.fail(name, f"must be a positive integer, got {short_integer(value)}")
        if maximum is not None and value > maximum:
            raise self.fail(name, f"must be at most {maximum}, got {short_integer(value)}")
        return value

    def boolean(self, name: str, default: bool = False) -> bool:
        value = self._get(name, False)
        if value is None:
            return default
        if not isinstance(value, bool):
            raise self.fail(name, f"expected true or false, got {shown(value)}")
        return value

    def number(self, name: str, required: bool = True) -> float | None:
        value = self._get(name, required)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(name, f"expected a number, got {shown(value)}")
        if not math.isfinite(value):
            raise self.fail(name, f"must be finite, got {shown(value)}")
        return float(value)

    def string_list(self, name: str, required: bool = True) -> tuple[str, ...]:
        value = self._get(name, required)
        if value is None:
            return ()
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.fail(name, "expected a list of names (strings)")
        return tuple(value)

    def quantity(self, name: str, positive: bool = True, unit: str | None = None) -> Quantity:
        value = self._get(name, True)
        if not isinstance(value, dict):
            raise self.fail(name, """expected { value = <number>, unit = "...", source = "..." }""")
        sub = TableReader(self.file, value, self.key(name))
        number = sub.number("value")
        assert number is not None
        given_unit = sub.string("unit")
        source = sub.string("source")
        sub.reject_unknown()
        expected = unit if unit is not None else EXPECTED_UNITS.get(name)
        if expected is not None and given_unit != expected:
            raise sub.fail("unit", f"expected {expected!r}, got {given_unit!r}")
        if not source.strip():
            raise sub.fail("source", "must say where the value comes from (or 'assumed')")
        if positive and number <= 0:
            raise sub.fail("value", f"must be positive, got {number}")
        return Quantity(number, given_unit, source)

    def tables(self, name: str, required: bool = True) -> list[TableReader]:
        value = self._get(name, required)
        if value is None:
            return []
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(name, f"expected an array of tables ([[{name}]])")
        if len(value) > ENTRIES_MAX:
            raise self.fail(name, f"at most {ENTRIES_MAX} [[{name}]] entries, got {len(value)}")
        return [TableReader(self.file, t, f"{self.key(name)}[{i}]") for i, t in enumerate(value)]

    def table(self, name: str, required: bool = True) -> TableReader:
        value = self._get(name, required)
        if value is None:
            return TableReader(self.file, {}, self.key(name))
        if not isinstance(value, dict):
            raise self.fail(name, f"expected a table ([{name}])")
        return TableReader(self.file, value, self.key(name))

    def reject_unknown(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.fail(unknown[0], unknown_key_reason(unknown[0], self.used))
