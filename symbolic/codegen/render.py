"""The one Jinja2 entry point: a strict environment over ``templates/`` and typed views.

Every template is rendered by :func:`render` from one dataclass instance (a *view*); its fields
are the template's variables. The environment uses ``StrictUndefined``, so a field a template
names but the view lacks fails the render instead of printing nothing.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache
from typing import Any

import jinja2
from gearsym.symbolic.io.package_data import template_dir

__all__ = ["TEMPLATE_DIR", "render"]

#: ``templates/`` in the source tree, ``gearsym/templates`` when installed (package data).
TEMPLATE_DIR = template_dir()


@lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(TEMPLATE_DIR)),
        undefined=jinja2.StrictUndefined,  # a typo in a template fails loudly
        keep_trailing_newline=True,
        trim_blocks=True,
        lstrip_blocks=True,
        autoescape=False,  # C and Python, not HTML
    )


def render(template_name: str, view: Any) -> str:
    """Render ``templates/<template_name>`` with the fields of the dataclass ``view``."""
    if not dataclasses.is_dataclass(view) or isinstance(view, type):
        raise TypeError(f"render() takes a dataclass view, got {type(view).__name__}")
    context = {f.name: getattr(view, f.name) for f in dataclasses.fields(view)}
    return _environment().get_template(template_name).render(**context)
