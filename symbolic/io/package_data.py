"""Files shipped inside the package, found through :mod:`importlib.resources`.

Paths computed from the repository layout (``Path(__file__).parents[...]``) hold only in a
checkout; an installed (non-editable) gearsym keeps its data under ``gearsym/data`` and its
templates under ``gearsym/templates`` (pyproject's package-dir mapping). Both are found here, in
one place, by package name.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["data_file", "template_dir"]


def data_file(name: str) -> Path:
    """Path of ``name`` in the package's shipped data (``gearsym/data``)."""
    return Path(str(resources.files("gearsym") / "data" / name))


def template_dir() -> Path:
    """Folder of the Jinja2 templates (``templates/`` in a checkout, ``gearsym/templates``
    installed)."""
    return Path(str(resources.files("gearsym.templates")))
