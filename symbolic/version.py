"""The installed gearsym's version (its package metadata, from pyproject.toml), the one the
emitted FMU and A2L files record; :mod:`gearsym` re-exports it as ``gearsym.__version__``."""

from importlib.metadata import version

__version__ = version("gearsym")
