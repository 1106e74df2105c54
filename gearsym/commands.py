"""The registration protocol of the command modules, and what they share.

Every command module (``gearsym/cmd_*.py``) has one entry point::

    def register(subparsers: Subparsers, common: argparse.ArgumentParser) -> None

which adds its subcommands with :func:`add_command`. Each subcommand names its handler with
``set_defaults(func=...)``; a handler takes the parsed arguments and returns the exit code, and
imports what it computes with (SymPy, NumPy, SciPy, CasADi, Matplotlib) inside its body, so
building the parser (``gearsym --help``, every command's start-up) stays free of them.
``common`` is the parent parser holding the positional description file most commands take.
:mod:`gearsym.cli` owns the top-level parser, calls ``register`` of each module in turn and
runs the chosen handler.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from gearsym.interrupts import check

if TYPE_CHECKING:
    from gearsym.symbolic.description import GearboxDescription

    #: What ``ArgumentParser.add_subparsers`` returns (argparse names the class privately).
    Subparsers = argparse._SubParsersAction[argparse.ArgumentParser]

__all__ = [
    "Handler",
    "add_command",
    "common_arguments",
    "emit_json",
    "load",
    "progress",
]

#: A subcommand's handler: parsed arguments in, exit code out.
Handler = Callable[[argparse.Namespace], int]


def common_arguments() -> argparse.ArgumentParser:
    """The parent parser of every command that reads a description: the optional ``config``."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "config", nargs="?", help="gearbox description (TOML); default: the built-in gearbox"
    )
    return common


def add_command(
    subparsers: Subparsers,
    name: str,
    func: Handler,
    text: str,
    common: argparse.ArgumentParser | None = None,
) -> argparse.ArgumentParser:
    """Add subcommand ``name`` (help and description ``text``) run by ``func``; with ``common``
    it takes the description file as its first positional argument."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        name, help=text, description=text, parents=[] if common is None else [common]
    )
    parser.set_defaults(func=func)
    return parser


def load(path: str | None) -> GearboxDescription:
    """The description a command names (the built-in gearbox for ``None``), through the one
    loader; imported on first use, since the loader pulls in SymPy."""
    from gearsym.symbolic.loader import load_description

    return load_description(path)


def emit_json(data: Any) -> None:
    """``data`` as indented JSON on stdout, one trailing newline."""
    json.dump(data, sys.stdout, indent=2, sort_keys=False)
    sys.stdout.write("\n")


def progress(message: str) -> None:
    """One progress line on stderr; also where a pending SIGTERM ends the command."""
    check()
    print(f"  … {message}", file=sys.stderr, flush=True)
