"""The ``gearsym`` command line: the top-level parser, the command modules, :func:`main`.

Every command lives in a command module (``gearsym/cmd_*.py``) that registers itself through
the one protocol of :mod:`gearsym.commands` (``register(subparsers, common)``, handlers set with
``set_defaults(func=...)``). Every command takes an optional description file (the built-in
thesis gearbox when omitted). Bad input prints one line ``gearsym: <file>: <key>: <reason>`` and
exits with code 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from gearsym import (
    cmd_analysis,
    cmd_dynamics,
    cmd_gearbox,
    cmd_generate,
    cmd_observability,
    cmd_run,
)
from gearsym.commands import common_arguments
from gearsym.interrupts import Terminated, sigterm_raises
from gearsym.symbolic.errors import GearsymError

#: The command modules in the order ``gearsym --help`` lists their commands.
COMMAND_MODULES = (
    cmd_run,
    cmd_gearbox,
    cmd_dynamics,
    cmd_observability,
    cmd_generate,
    cmd_analysis,
)


class _Parser(argparse.ArgumentParser):
    """Usage errors (a bad option value, say) as one line, like every other error, exit 2."""

    def error(self, message: str) -> NoReturn:
        where = self.prog.removeprefix("gearsym").strip() or "command line"
        self.exit(2, f"gearsym: {where}: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every command module's subcommands (the subparsers are
    ``_Parser`` too: argparse gives them the class of their parent)."""
    parser = _Parser(
        prog="gearsym",
        description="Planetary automatic transmission → validated symbolic model → TCU code.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    common = common_arguments()
    for module in COMMAND_MODULES:
        module.register(subparsers, common)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default: the process arguments), run the command, return its exit code:
    2 for bad input (one line on stderr), 130 when interrupted, 143 when terminated."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with sigterm_raises():
            return int(args.func(args))
    except GearsymError as err:
        print(f"gearsym: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gearsym: interrupted; nothing was written", file=sys.stderr)
        return 130
    except Terminated:
        print("gearsym: terminated; nothing was written", file=sys.stderr)
        return 143


if __name__ == "__main__":
    sys.exit(main())
