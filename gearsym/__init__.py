"""gearsym: planetary automatic transmission → validated symbolic model → TCU code.

The notebook API is :func:`load` (see :mod:`gearsym.api`); the command line is ``gearsym``.
"""

from gearsym.api import Gearbox, load

__all__ = ["Gearbox", "__version__", "load"]


def __getattr__(name: str) -> str:
    """``gearsym.__version__``, read from the package metadata on first use
    (:mod:`gearsym.symbolic.version`, where the emitted files take it from) so that
    ``import gearsym`` and the command line's start stay light."""
    if name == "__version__":
        from gearsym.symbolic.version import __version__

        return __version__
    raise AttributeError(f"module 'gearsym' has no attribute {name!r}")
