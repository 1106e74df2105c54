"""The emitted parameter structs and μ map as an ASAP2 (ASAM MCD-2 MC 1.7.1) file, as a pure
function: emitted models and the μ map in, A2L text out.

:func:`a2l_text` describes, for a calibration tool (INCA, CANape, a2ltool, ...):

* every ``gearsym_<model>_params`` struct of :func:`gearsym.symbolic.export.generate.gearbox_models`
  as one ``CHARACTERISTIC`` ``VALUE`` per field, in struct order, named
  ``gearsym_<model>_cal.<field>``: a field is at ``SYMBOL_LINK "gearsym_<model>_cal" <offset>``,
  the instance of the struct the integrating code defines (``gearsym_<model>_params
  gearsym_<model>_cal;``) and the field's byte offset in it (the struct holds only
  ``gearsym_real`` fields: field ``i`` is at ``i * sizeof(gearsym_real)``); its limits are the
  closed range the emitted ``params_validate`` enforces (``PARAMETER_BOUNDS``, ``MU_BOUNDS``),
  in a float build rounded to float as the emitted ``GEARSYM_LIT(v)`` (``vf``) literal is; its
  unit, meaning, default and source are in the long identifier;
* the μ map of ``gearsym_mu_map.c``: its three grids as ``AXIS_PTS`` (``gearsym_mu_map_p_N``,
  ``_T_oil``, ``_dw``, separate arrays, strictly increasing) and its table
  ``gearsym_mu_map_values`` as a ``CUBOID`` on those axes (``COM_AXIS``): X = p_N, Y = T_oil,
  Z = |dw|, stored ``ROW_DIR``, the last axis fastest, as the C array ``[i][j][k]`` at
  ``(i * N_T_OIL + j) * N_DW + k``;
* one ``COMPU_METHOD`` (``IDENTICAL``: the ECU holds physical values) per unit, the
  ``RECORD_LAYOUT`` of a value, an axis and the table in the working precision
  (``FLOAT64_IEEE`` for ``double``, ``FLOAT32_IEEE`` for ``-DGEARSYM_SINGLE_PRECISION``), one
  ``GROUP`` per model and one for the μ map.

Addresses are placeholders: every address is 0 and every object names its symbol in
``SYMBOL_LINK``; the linker map or ELF file of the ECU build fills them in (a2ltool
``--update``, INCA's or CANape's address update). The same input gives the same text.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from decimal import Decimal

import numpy as np
from gearsym.symbolic.codegen import float_repr, render
from gearsym.symbolic.codegen.printing import comment_text
from gearsym.symbolic.export.generate import MU_BOUNDS
from gearsym.symbolic.export.tree import EmittedModel
from gearsym.symbolic.friction import MuMap
from gearsym.symbolic.version import __version__

__all__ = [
    "BYTE_ORDERS",
    "PRECISIONS",
    "A2lValue",
    "a2l_text",
    "instance_name",
    "parameter_values",
]

#: ``--precision``: the C type of ``gearsym_real``, its ASAP2 data type and size in bytes.
PRECISIONS: dict[str, tuple[str, str, int]] = {
    "double": ("double", "FLOAT64_IEEE", 8),
    "float": ("float", "FLOAT32_IEEE", 4),
}
#: ``--byte-order``: ASAP2's name (MSB_LAST is little-endian: Cortex-M, TriCore, x86).
BYTE_ORDERS = {"little": "MSB_LAST", "big": "MSB_FIRST"}


def instance_name(model_name: str) -> str:
    """The symbol of the calibrated ``gearsym_<model>_params`` instance the A2L links to."""
    return f"gearsym_{model_name}_cal"


def _rounded(value: float, precision: str) -> float:
    """``value`` as the working precision holds it (float: the nearest float, as ``vf``)."""
    return float(np.float32(value)) if precision == "float" else float(value)


def _type_max(precision: str) -> float:
    return float(np.finfo(np.float32).max) if precision == "float" else float(np.finfo(float).max)


def _string(text: str) -> str:
    """Text safe inside an A2L string: one line of ASCII, no quote, no backslash."""
    return comment_text(text).replace("\\", "/").replace('"', "'")


def _ident(text: str) -> str:
    """An A2L identifier made of ``text`` (letters, digits, ``_``)."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", text)
    return ident if ident[:1].isalpha() or ident[:1] == "_" else f"_{ident}"


def _format(values: Sequence[float]) -> str:
    """``"%Length.Layout"`` that shows every finite value of ``values`` to 6 significant digits
    (ASAP2's display format has no exponent form)."""
    finite = [abs(v) for v in values if math.isfinite(v) and v != 0.0 and abs(v) < 1e15]
    exponents = [Decimal(f"{v:.6g}").as_tuple().exponent for v in finite]
    decimals = min(max([0, *(-e for e in exponents if isinstance(e, int))]), 15)
    whole = max((len(str(int(v))) for v in finite), default=1)
    return f"%{min(whole + decimals + 2, 32)}.{decimals}"


@dataclass(frozen=True)
class A2lValue:
    """One calibratable scalar: a field of a parameter struct (what a ``CHARACTERISTIC`` says)."""

    name: str  # gearsym_<model>_cal.<field>
    field: str
    index: int  # position in the struct
    offset: int  # byte offset in the struct
    unit: str
    lower: float  # the params_validate range in the working precision
    upper: float
    description: str
    compu_method: str
    format: str

    @property
    def lower_text(self) -> str:
        return float_repr(self.lower)

    @property
    def upper_text(self) -> str:
        return float_repr(self.upper)


@dataclass(frozen=True)
class StructView:
    model_name: str
    instance: str
    struct: str
    size: int
    summary: str
    values: tuple[A2lValue, ...]


@dataclass(frozen=True)
class AxisView:
    name: str  # the C array: gearsym_mu_map_<axis>
    description: str
    unit: str
    compu_method: str
    count: int
    lower: str
    upper: str
    format: str


@dataclass(frozen=True)
class MuMapA2lView:
    name: str
    description: str
    axes: tuple[AxisView, ...]  # X, Y, Z
    lower: str
    upper: str
    compu_method: str
    format: str


@dataclass(frozen=True)
class CompuMethodView:
    name: str
    unit: str
    format: str


@dataclass(frozen=True)
class A2lView:
    """What ``a2l.a2l.j2`` prints."""

    version: str
    gearbox: str
    module: str
    precision: str
    c_type: str
    datatype: str
    size: int
    byte_order: str
    byte_order_name: str
    suffix: str  # f64 / f32: the record layouts' names
    compu_methods: tuple[CompuMethodView, ...]
    structs: tuple[StructView, ...]
    mu_map: MuMapA2lView | None


class _CompuMethods:
    """One ``IDENTICAL`` COMPU_METHOD per unit, with a unique identifier."""

    def __init__(self) -> None:
        self.by_unit: dict[str, str] = {}

    def __call__(self, unit: str) -> str:
        if unit not in self.by_unit:
            base = "gearsym_cm_" + (
                _ident(unit.replace("*", "_").replace("/", "_per_").replace("^", ""))
                .strip("_")
                .replace("__", "_")
                or "1"
            )
            name, n = base, 2
            while name in self.by_unit.values():
                name, n = f"{base}_{n}", n + 1
            self.by_unit[unit] = name
        return self.by_unit[unit]

    def views(self) -> tuple[CompuMethodView, ...]:
        return tuple(
            CompuMethodView(name, _string(unit), "%12.6")
            for unit, name in sorted(self.by_unit.items(), key=lambda item: item[1])
        )


def parameter_values(
    emitted: EmittedModel, precision: str = "double", compu: _CompuMethods | None = None
) -> tuple[A2lValue, ...]:
    """The ``CHARACTERISTIC`` of every field of ``gearsym_<model>_params``, in struct order."""
    _, _, size = PRECISIONS[precision]
    compu = compu or _CompuMethods()
    instance = instance_name(emitted.model.name)
    top = _type_max(precision)
    values = []
    for i, v in enumerate(emitted.model.parameters):
        lo, hi = emitted.bounds.get(v.name, (None, None))
        lower = -top if lo is None else _rounded(lo, precision)
        upper = top if hi is None else _rounded(hi, precision)
        parts = [v.description or v.name, f"[{v.unit}]"]
        parts.append("no default" if v.default is None else f"default {float_repr(v.default)}")
        if (lo, hi) != (None, None):
            parts.append(
                f"params_validate range [{'-inf' if lo is None else float_repr(lo)}, "
                f"{'inf' if hi is None else float_repr(hi)}]"
            )
        if v.source:
            parts.append(f"source: {v.source}")
        shown = [lower, upper] + ([] if v.default is None else [float(v.default)])
        values.append(
            A2lValue(
                name=f"{instance}.{v.name}",
                field=v.name,
                index=i,
                offset=i * size,
                unit=_string(v.unit),
                lower=lower,
                upper=upper,
                description=_string("; ".join(parts)),
                compu_method=compu(v.unit),
                format=_format(shown),
            )
        )
    return tuple(values)


def _mu_map_view(mu_map: MuMap, precision: str, compu: _CompuMethods) -> MuMapA2lView:
    top = _type_max(precision)
    meaning = {
        "p_N": "apply pressure grid of the mu map",
        "T_oil": "oil temperature grid of the mu map",
        "dw": "slip grid of the mu map (read with |dw|, so >= 0)",
    }
    axes = []
    for (name, unit), grid in zip(MuMap.AXES, mu_map.grid, strict=True):
        lower = 0.0 if name == "dw" else -top  # the loader's only rule besides "increasing"
        axes.append(
            AxisView(
                name=f"gearsym_mu_map_{name}",
                description=_string(
                    f"{meaning[name]} [{unit}], strictly increasing; from {mu_map.origin}"
                ),
                unit=_string(unit),
                compu_method=compu(unit),
                count=len(grid),
                lower=float_repr(lower),
                upper=float_repr(top),
                format=_format([_rounded(g, precision) for g in grid]),
            )
        )
    lo, hi = MU_BOUNDS
    return MuMapA2lView(
        name="gearsym_mu_map_values",
        description=_string(
            "friction coefficient mu(p_N, T_oil, |dw|) of (2.69), trilinear and clamped to the "
            f"grid by gearsym_mu_map(); from {mu_map.origin}"
        ),
        axes=tuple(axes),
        lower=float_repr(lo),
        upper=float_repr(hi),
        compu_method=compu("1"),
        format=_format([float(v) for v in mu_map.table.reshape(-1)]),
    )


def a2l_text(
    models: Sequence[EmittedModel],
    mu_map: MuMap | None,
    gearbox: str,
    *,
    precision: str = "double",
    byte_order: str = "little",
) -> str:
    """The A2L file of ``models``' parameter structs and ``mu_map`` (``None``: left out)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
    if byte_order not in BYTE_ORDERS:
        raise ValueError(f"byte order must be one of {sorted(BYTE_ORDERS)}, got {byte_order!r}")
    c_type, datatype, size = PRECISIONS[precision]
    compu = _CompuMethods()
    structs = tuple(
        StructView(
            model_name=e.model.name,
            instance=instance_name(e.model.name),
            struct=f"gearsym_{e.model.name}_params",
            size=len(e.model.parameters) * size,
            summary=_string(e.summary),
            values=parameter_values(e, precision, compu),
        )
        for e in models
    )
    view = A2lView(
        version=__version__,
        gearbox=_string(gearbox),
        module=_ident(f"gearsym_{gearbox}"),
        precision=precision,
        c_type=c_type,
        datatype=datatype,
        size=size,
        byte_order=BYTE_ORDERS[byte_order],
        byte_order_name=byte_order,
        suffix=f"f{8 * size}",
        compu_methods=(),
        structs=structs,
        mu_map=None if mu_map is None else _mu_map_view(mu_map, precision, compu),
    )
    view = A2lView(**{**view.__dict__, "compu_methods": compu.views()})
    return render("a2l.a2l.j2", view)
