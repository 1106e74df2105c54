"""Reading the user's TOML files (descriptions, scenarios, μ maps) without surprises.

Every failure is a one-line :class:`GearsymError`: only regular files are read (a device such
as ``/dev/zero`` or a pipe would never end, a folder is no file), at most
:data:`MAX_INPUT_BYTES` of them, as UTF-8, and the TOML parser's own failures (syntax, nesting
deeper than its recursion allows) are reported with their place, never as a traceback.
"""

from __future__ import annotations

import contextlib
import difflib
import hashlib
import os
import re
import reprlib
import stat
import tomllib
from collections.abc import Iterable, Iterator
from contextvars import ContextVar
from pathlib import Path
from typing import Any

from gearsym.symbolic.errors import GearsymError

__all__ = [
    "MAX_INPUT_BYTES",
    "parse_toml",
    "read_text",
    "recorded_reads",
    "shown",
    "unknown_key_reason",
]

#: Largest input file read. The built-in description is about 12 kB; a megabyte leaves room
#: for any real gearbox or scenario and bounds the memory and parse time of a wrong file.
MAX_INPUT_BYTES = 1 << 20

#: While :func:`recorded_reads` is active: resolved path -> SHA-256 of the bytes read.
_READS: ContextVar[dict[str, str] | None] = ContextVar("gearsym_reads", default=None)


@contextlib.contextmanager
def recorded_reads() -> Iterator[dict[str, str]]:
    """Record every file :func:`read_text` reads inside the block: resolved path -> SHA-256 of
    the very bytes the caller received (the output cache keys a result by what it was computed
    from, not by what the file holds before or after)."""
    reads: dict[str, str] = {}
    token = _READS.set(reads)
    try:
        yield reads
    finally:
        _READS.reset(token)


def read_text(path: str | Path, shown: str | None = None) -> str:
    """The UTF-8 text of the regular file ``path`` (``shown`` names it in errors)."""
    shown = str(path) if shown is None else shown
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer; the mode check below then
        # rejects it. The check is on the opened descriptor, so the file cannot be swapped.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise GearsymError(shown, "", "no such file") from None
    except IsADirectoryError:
        raise GearsymError(shown, "", "is a folder; expected a TOML file") from None
    except OSError as err:
        raise GearsymError(shown, "", f"cannot read: {err.strerror or err}") from None
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise GearsymError(shown, "", "is a folder; expected a TOML file")
        if not stat.S_ISREG(mode):
            raise GearsymError(
                shown, "", "is not a regular file (a device, pipe or socket); expected a TOML file"
            )
        chunks = []
        size = 0
        while size <= MAX_INPUT_BYTES:  # bounded even if the file grows meanwhile
            chunk = os.read(fd, MAX_INPUT_BYTES + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        data = b"".join(chunks)
    except OSError as err:
        raise GearsymError(shown, "", f"cannot read: {err.strerror or err}") from None
    finally:
        os.close(fd)
    if len(data) > MAX_INPUT_BYTES:
        raise GearsymError(
            shown, "", f"larger than {MAX_INPUT_BYTES} bytes (1 MiB), the limit for input files"
        )
    reads = _READS.get()
    if reads is not None:
        reads[str(Path(path).resolve())] = hashlib.sha256(data).hexdigest()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        line_start = data.rfind(b"\n", 0, err.start) + 1
        column = len(data[line_start : err.start].decode("utf-8", "replace")) + 1
        raise GearsymError(
            shown,
            f"line {line}, column {column}",
            f"not UTF-8 text (byte 0x{data[err.start]:02x}); save the file as UTF-8",
        ) from None


def parse_toml(text: str, shown: str) -> dict[str, Any]:
    """Parse TOML; syntax errors name the line and column as the key."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        match = re.search(r"\(at line (\d+), column (\d+)\)", str(err))
        where = f"line {match.group(1)}, column {match.group(2)}" if match else "TOML"
        reason = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(err))
        raise GearsymError(shown, where, f"malformed TOML: {reason}") from None
    except RecursionError:
        # tomllib recurses once per nested array or inline table.
        raise GearsymError(
            shown, "TOML", "malformed TOML: arrays or tables nested too deeply"
        ) from None


def unknown_key_reason(key: str, known: Iterable[str], what: str = "key") -> str:
    """``unknown key (did you mean 'value'?)``: the reason for a key nobody reads."""
    near = difflib.get_close_matches(key, sorted(known), n=1)
    hint = f"did you mean {near[0]!r}?" if near else f"known: {', '.join(sorted(known))}"
    return f"unknown {what} (misspelt? {hint})"


_REPR = reprlib.Repr()  # keyword arguments only from Python 3.12
_REPR.maxlevel, _REPR.maxstring, _REPR.maxother, _REPR.maxlist, _REPR.maxdict = 2, 40, 40, 4, 4


def shown(value: object) -> str:
    """``repr`` of a value from a file, short: a message quotes it in one line, and a 1 MB
    string or a list nested 900 deep would make that line useless (or the repr fail)."""
    return _REPR.repr(value)
