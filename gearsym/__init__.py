"""gearsym: planetary automatic transmission → validated symbolic model → TCU code.

The notebook API is :func:`load` (see :mod:`gearsym.api`); the command line is ``gearsym``.
"""

from gearsym.api import Gearbox, load

__all__ = ["Gearbox", "load"]
__version__ = "0.1.0"
