"""The ``gearsym`` command line: the top-level parser, the command modules, :func:`main`.

Every command lives in a command module (``gearsym/cmd_*.py``) that registers itself through
the one protocol of :mod:`gearsym.commands` (``register(subparsers, common)``, handlers set with
``set_defaults(func=...)``). Every command takes an optional description file (the built-in
thesis gearbox when omitted). Bad input prints one line ``gearsym: <file>: <key>: <reason>`` and
exits with code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from gearsym import (
    cmd_analysis,
    cmd_control,
    cmd_draw,
    cmd_drive,
    cmd_dynamics,
    cmd_estimate,
    cmd_export,
    cmd_gearbox,
    cmd_generate,
    cmd_observability,
    cmd_run,
    cmd_sweep,
)
from gearsym.commands import common_arguments
from gearsym.interrupts import Terminated, sigterm_raises
from gearsym.interrupts import requested as terminate_requested
from gearsym.symbolic.errors import GearsymError

#: The command modules in the order ``gearsym --help`` lists their commands.
COMMAND_MODULES = (
    cmd_run,
    cmd_gearbox,
    cmd_dynamics,
    cmd_observability,
    cmd_generate,
    cmd_analysis,
    cmd_sweep,
    cmd_estimate,
    cmd_drive,
    cmd_control,
    cmd_draw,
    cmd_export,
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


def _cached_run(args: argparse.Namespace) -> int | None:
    """Replay a remembered output, or run the command and remember it; ``None`` when the
    cache does not apply (off, or the description cannot be read)."""
    from gearsym import command_cache

    root = command_cache.cache_root()
    if root is None or args.no_cache:
        return None
    skip = ("func", "cacheable", "config", "no_cache")
    options = {k: v for k, v in vars(args).items() if k not in skip}
    key = command_cache.entry_key(args.command, options, args.config)
    if key is None:
        return None
    hit = command_cache.lookup(root, key)
    if hit is None:
        from gearsym.symbolic.io.input_files import recorded_reads

        out, err = io.StringIO(), io.StringIO()
        with (
            recorded_reads() as reads,
            contextlib.redirect_stdout(out),
            contextlib.redirect_stderr(err),
        ):
            status = int(args.func(args))
        hit = (out.getvalue(), err.getvalue(), status)
        if status in (0, 1):
            # Stored under the bytes the run read, not those read for the lookup: a file saved
            # during the run must not pair its old key with its new output.
            if args.config is not None:
                read = reads.pop(str(Path(args.config).resolve()), None)
                key = (
                    None
                    if read is None
                    else command_cache.entry_key(args.command, options, args.config, digest=read)
                )
            if key is not None:
                command_cache.store(root, key, args.command, *hit, reads=reads)
    stdout, stderr, status = hit
    sys.stdout.write(stdout)
    sys.stderr.write(stderr)
    return status


def _terminated() -> int:
    """SIGTERM's one line and exit code (whatever error it surfaced as on its way out)."""
    print("gearsym: terminated; nothing was written", file=sys.stderr)
    return 143


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default: the process arguments), run the command, return its exit code:
    2 for bad input (one line on stderr), 130 when interrupted, 143 when terminated."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with sigterm_raises():
            if getattr(args, "cacheable", False):
                status = _cached_run(args)
                if status is not None:
                    return status
            return int(args.func(args))
    except GearsymError as err:
        if terminate_requested():
            # native code (CasADi's integrator) turned the Terminated into its own failure,
            # which the library reported as an error of the run: the signal came first
            return _terminated()
        print(f"gearsym: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `gearsym ... | head`: the reader left; say nothing more
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (interpreter shutdown flushes it)
        return 0
    except OSError as err:
        from gearsym.symbolic.io.output_dir import STORAGE_ERRORS

        if err.errno not in STORAGE_ERRORS:
            raise
        if terminate_requested():
            return _terminated()
        # the one output writer discarded its staging folder: nothing half-written remains
        where = err.filename or "output"
        print(
            f"gearsym: {where}: cannot write: {err.strerror}; nothing was written", file=sys.stderr
        )
        return 2
    except KeyboardInterrupt:
        print("gearsym: interrupted; nothing was written", file=sys.stderr)
        return 130
    except Terminated:
        return _terminated()
    except Exception:
        if not terminate_requested():
            raise
        # CasADi turns the Terminated its signal check raised into its own RuntimeError
        return _terminated()


if __name__ == "__main__":
    sys.exit(main())
