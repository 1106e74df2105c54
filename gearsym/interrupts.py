"""SIGTERM handling for the command line: raised like Ctrl-C, so every ``with`` block (the
output writer's above all) cleans up on the way out.

Native code can swallow the exception a signal handler raises (CasADi calls Python's signal
check inside its integrators and may clear the error), so the handler also sets a flag that
every progress report checks: a swallowed SIGTERM still stops the command at its next report.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["Terminated", "check", "requested", "sigterm_raises"]

_requested = threading.Event()


class Terminated(BaseException):
    """SIGTERM arrived (a BaseException, like KeyboardInterrupt, so no ``except Exception``
    swallows it)."""


def _handler(signum: int, frame: Any) -> None:
    _requested.set()
    raise Terminated


def check() -> None:
    """Raise :class:`Terminated` if SIGTERM arrived (and was swallowed on its way)."""
    if _requested.is_set():
        raise Terminated


def requested() -> bool:
    """SIGTERM arrived within :func:`sigterm_raises` (native code may have turned the
    :class:`Terminated` it raised into its own error on the way out)."""
    return _requested.is_set()


@contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _requested.clear()
    previous: Callable[..., Any] | int | None = signal.signal(signal.SIGTERM, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
