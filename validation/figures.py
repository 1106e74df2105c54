"""One style for every figure gearsym writes, and one fast way to save them.

Figures are laid out with fixed margins (each caller states them) instead of
``tight_layout``, which measured every tick label of every axis and took most of the plotting
time; PNGs are written with light zlib compression (lossless, a little larger, much faster).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

__all__ = ["STYLE", "pyplot", "save", "subplots", "to_bytes"]

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
