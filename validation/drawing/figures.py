"""One style for every figure gearsym writes, and one fast way to save them.

Figures are laid out with fixed margins (each caller states them) instead of
``tight_layout``, which measured every tick label of every axis and took most of the plotting
time; PNGs are written with light zlib compression (lossless, a little larger, much faster).
"""

from __future__ import annotations

import io
import os
import signal
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any

__all__ = ["STYLE", "Background", "pyplot", "save", "subplots", "to_bytes"]

#: Shared rcParams: fonts, grid and line widths of every figure.
STYLE: dict[str, Any] = {
    "font.size": 8,
    "axes.titlesize": 9,
    "axes.labelsize": 8,
    "legend.fontsize": 7,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "axes.grid": True,
    "grid.linewidth": 0.3,
    "lines.linewidth": 1.0,
    "figure.dpi": 100,
    # A fixed title height: with the default (None) matplotlib measures every tick label of
    # every axis at each draw to lift titles clear of top ticks, which none of ours have.
    "axes.titley": 1.0,
}


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed) with :data:`STYLE`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(STYLE)
    return plt


def subplots(
    rows: int = 1,
    cols: int = 1,
    size: tuple[float, float] = (8.0, 4.5),
    margins: dict[str, float] | None = None,
    **options: Any,
) -> tuple[Any, Any]:
    """A figure with fixed margins (fractions of the figure: left, right, bottom, top, hspace,
    wspace), no layout engine."""
    plt = pyplot()
    fig, axes = plt.subplots(rows, cols, figsize=size, **options)
    fig.subplots_adjust(
        **{"left": 0.08, "right": 0.98, "bottom": 0.1, "top": 0.9, **(margins or {})}
    )
    return fig, axes


def save(fig: Any, path: Path, dpi: int = 110) -> Path:
    """Write ``fig`` as PNG and close it."""
    fig.savefig(path, dpi=dpi, pil_kwargs={"compress_level": 1})
    pyplot().close(fig)
    return path


def to_bytes(fig: Any, fmt: str, dpi: int = 110) -> bytes:
    """``fig`` as SVG or PNG bytes, and close it. The same figure gives the same bytes: the SVG
    ids come from a fixed hash salt instead of a random UUID, and no date is written."""
    plt = pyplot()
    buffer = io.BytesIO()
    if fmt == "svg":
        with plt.rc_context({"svg.hashsalt": "gearsym", "svg.fonttype": "path"}):
            fig.savefig(buffer, format="svg", metadata={"Date": None})
    else:
        fig.savefig(buffer, format="png", dpi=dpi, pil_kwargs={"compress_level": 1})
    plt.close(fig)
    return buffer.getvalue()


class Background:
    """Draw figures in forked child processes while the caller goes on computing.

    Drawing is pure Python inside matplotlib (one core); ``gearsym run`` spends about as long
    drawing as computing the Fisher information, so on a machine with two cores the two
    overlap. Each :meth:`submit` forks once: the child inherits the data (nothing is pickled),
    writes its files, and leaves with ``os._exit`` (no buffers of the parent flushed twice).
    :meth:`wait` reaps every child and raises if one failed; leaving the ``with`` block on an
    error (or a signal) kills and reaps the children, so no figure outlives the command. Where
    ``os.fork`` is missing the work runs inline.
    """

    def __init__(self) -> None:
        self._children: list[tuple[int, str]] = []

    def submit(self, what: str, function: Callable[..., object], *args: object) -> None:
        """Run ``function(*args)`` in a child process (``what`` names it in an error)."""
        if not hasattr(os, "fork"):
            function(*args)
            return
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the child: draw, then leave without running the parent's cleanup
            status = 0
            try:
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                function(*args)
            except BaseException:  # reported by the parent as a failed figure job
                traceback.print_exc()
                status = 1
            finally:
                sys.stderr.flush()
                os._exit(status)
        self._children.append((pid, what))

    def wait(self) -> None:
        """Reap every child; raise :class:`RuntimeError` naming the jobs that failed."""
        failed = []
        while self._children:
            pid, what = self._children.pop(0)
            _, status = os.waitpid(pid, 0)
            if os.waitstatus_to_exitcode(status) != 0:
                failed.append(what)
        if failed:
            raise RuntimeError(f"drawing failed: {', '.join(failed)}")

    def kill(self) -> None:
        """Stop and reap every child still drawing."""
        for pid, _ in self._children:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        for pid, _ in self._children:
            try:
                os.waitpid(pid, 0)
            except ChildProcessError:
                pass
        self._children.clear()

    def __enter__(self) -> Background:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if kind is None:
            self.wait()
        else:
            self.kill()
