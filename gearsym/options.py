"""Command-line options shared by several commands: numbers checked in one place, the cache flag.

Every numeric option of every command is parsed by :func:`number`, so ``nan``, ``inf``, a
negative count or a zero tolerance is a usage error (exit code 2, one line) before any work
starts, not a silently wrong result ("no solution exists" for ``--top 0``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["cacheable", "number"]


def number(
    kind: type[int] | type[float] = float,
    *,
    above: float | None = None,
    minimum: float | None = None,
    maximum: float | None = None,
) -> Callable[[str], int | float]:
    """An argparse ``type=``: a finite ``kind`` (int or float) with ``value > above``,
    ``value >= minimum`` and ``value <= maximum`` where given."""

    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            expected = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
        if above is not None and not value > above:
            raise argparse.ArgumentTypeError(f"must be greater than {above:g}, got {text}")
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum:g}, got {text}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum:g}, got {text}")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in some messages
    return parse


def cacheable(p: argparse.ArgumentParser) -> None:
    """Mark an inspection command whose output may be remembered (:mod:`gearsym.command_cache`)
    and give it ``--no-cache``."""
    p.set_defaults(cacheable=True)
    p.add_argument(
        "--no-cache",
        action="store_true",
        help="derive afresh; do not read or write the output cache (also GEARSYM_NO_CACHE=1)",
    )
