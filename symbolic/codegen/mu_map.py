"""The friction-coefficient map μ(p_N, T_oil, |Δω|) (2.69) as C99 and CasADi: ``gearsym_mu_map``.

The map is data (:class:`gearsym.symbolic.friction.MuMap`), not a model: its code is the fixed
trilinear interpolation of ``templates/c_mu_map.*.j2`` and ``casadi_mu_map.py.j2``, filled with
the grid and the table through :class:`MuMapView`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from gearsym.symbolic import naming
from gearsym.symbolic.codegen.printing import comment_text, float_repr
from gearsym.symbolic.codegen.render import render
from gearsym.symbolic.friction import MuMap

__all__ = ["MuMapView", "docstring_text", "mu_map_files"]


@dataclass(frozen=True)
class AxisView:
    name: str  # "p_N", "T_oil", "dw"
    macro: str  # "P_N", "T_OIL", "DW"
    unit: str
    values: tuple[str, ...]  # lines of GEARSYM_LIT(...) literals


@dataclass(frozen=True)
class PyAxes:
    P_N: tuple[str, ...]  # lines of Python float literals
    T_OIL: tuple[str, ...]
    DW: tuple[str, ...]


@dataclass(frozen=True)
class MuMapView:
    origin: str  # safe in a C comment
    py_origin: str  # safe in a Python docstring
    origin_repr: str
    axes: tuple[AxisView, ...]
    sizes: tuple[int, int, int]
    c_values: tuple[str, ...]
    py_axes: PyAxes
    py_values: tuple[str, ...]
    range_text: str


def docstring_text(text: str) -> str:
    """Text safe inside a triple-quoted Python docstring: one line, no backslash, no quote."""
    return " ".join(str(text).split()).replace("\\", "/").replace('"', "'")


def _c_literals(values: Sequence[float], per_line: int) -> tuple[str, ...]:
    items = [f"GEARSYM_LIT({float_repr(float(v))})" for v in values]
    return tuple(", ".join(items[i : i + per_line]) for i in range(0, len(items), per_line))


def _py_tuple(values: Sequence[float], per_line: int = 7) -> tuple[str, ...]:
    items = [float_repr(float(v)) for v in values]
    return tuple(", ".join(items[i : i + per_line]) + "," for i in range(0, len(items), per_line))


def mu_map_files(mu_map: MuMap, c_dir: str = "c", python_dir: str = "python") -> dict[str, str]:
    """``gearsym_mu_map.{h,c}`` (under ``c_dir``) and ``gearsym_mu_map_casadi.py`` (under
    ``python_dir``) for ``mu_map``."""
    p_n, t_oil, dw = mu_map.grid
    flat = mu_map.table.reshape(-1)  # C order: [i][j][k] at (i*NT + j)*ND + k
    view = MuMapView(
        origin=comment_text(mu_map.origin),
        py_origin=docstring_text(mu_map.origin),
        origin_repr=repr(mu_map.origin),
        axes=(
            AxisView("p_N", "P_N", "Pa", _c_literals(p_n, 6)),
            AxisView("T_oil", "T_OIL", "degC", _c_literals(t_oil, 6)),
            AxisView("dw", "DW", "rad/s", _c_literals(dw, 6)),
        ),
        sizes=(len(p_n), len(t_oil), len(dw)),
        c_values=_c_literals(flat, len(dw)),
        py_axes=PyAxes(_py_tuple(p_n), _py_tuple(t_oil), _py_tuple(dw)),
        py_values=_py_tuple(flat, len(dw)),
        range_text=(
            f"p_N [{float_repr(p_n[0])}, {float_repr(p_n[-1])}] Pa, "
            f"T_oil [{float_repr(t_oil[0])}, {float_repr(t_oil[-1])}] degC, "
            f"|dw| [{float_repr(dw[0])}, {float_repr(dw[-1])}] rad/s"
        ),
    )
    names = naming.model_file_names(naming.MU_MAP)
    return {
        f"{c_dir}/{names['header']}": render("c_mu_map.h.j2", view),
        f"{c_dir}/{names['source']}": render("c_mu_map.c.j2", view),
        f"{python_dir}/{names['casadi']}": render("casadi_mu_map.py.j2", view),
    }
