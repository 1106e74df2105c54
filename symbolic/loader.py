"""The one loader of a gearbox description: read, parse, check the structure, check the gear table.

:mod:`gearsym.symbolic.description_parser` parses and checks the file as data
(:mod:`gearsym.symbolic.description`); :mod:`gearsym.symbolic.ratios` derives what the gears do
with it. A description is usable only when both agree (every gear leaves the one degree of
freedom it claims, Table 2.1), so the composition lives here, above both, and the CLI, the
notebook API and the validation all load through :func:`load_description`. Keeping it out of
the parser keeps the data layer free of any import of the derivation (no ``description`` ↔
``ratios`` circle).
"""

from __future__ import annotations

from pathlib import Path

from gearsym.symbolic.description import (
    DEFAULT_CONFIG_NAME,
    GearboxDescription,
    default_config_text,
)
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.io.input_files import read_text
from gearsym.symbolic.ratios import check_gear_table

__all__ = ["load_description"]


def load_description(
    path: str | Path | None = None, *, teeth_optional: bool = False
) -> GearboxDescription:
    """Load a description file, or the built-in default when ``path`` is None.

    Checks the structure (:func:`~gearsym.symbolic.description_parser.parse_description`) and that
    every gear leaves the degrees of freedom it claims
    (:func:`~gearsym.symbolic.ratios.check_gear_table`, Table 2.1). Bad input raises
    :class:`~gearsym.symbolic.errors.GearsymError` (file, key, reason).

    ``teeth_optional`` (``gearsym fit-teeth``): sets may leave out their teeth; the gear
    table of such a description is checked by the search, for generic stationary ratios.
    """
    if path is None:
        text = default_config_text()
        file = f"<built-in {DEFAULT_CONFIG_NAME}>"
    else:
        file = str(path)
        text = read_text(path, file)
    description = parse_description(text, file, teeth_optional=teeth_optional)
    if all(ps.teeth_given for ps in description.planetary_sets):
        check_gear_table(description)
    return description
