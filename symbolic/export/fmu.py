"""An emitted model as an FMI 2.0 Model Exchange and/or Co-Simulation **source** FMU, as a
pure function.

:func:`fmu_files` returns ``{path in the archive: bytes}`` for one model of
:func:`gearsym.symbolic.export.generate.gearbox_models`:

* ``modelDescription.xml``: every state (continuous, ``initial="exact"``), its derivative
  ``der(x)``, every input, every parameter (tunable, ``start`` = the model default, ``min``/``max``
  = the range the emitted ``params_validate`` enforces), every output; units as
  ``UnitDefinitions`` in SI base units; ``ModelStructure`` with the dependencies of the outputs
  and derivatives read from the sparsity of the Jacobians the codegen computes (∂f/∂x, ∂f/∂u,
  ∂f/∂p from the function table, ∂h/∂(x, u, p) from the same forward-mode differentiation);
* ``sources/gearsym_<model>.{h,c}``: the emitted C of ``gearsym generate``, byte for byte;
* ``sources/fmi2_gearsym.c``: the FMI wrapper (``templates/fmu_wrapper.c.j2``), which keeps
  its instance in memory from the environment's ``allocateMemory`` and calls the emitted
  ``rhs``, ``outputs``, ``params_default`` and ``params_validate``; with Co-Simulation (``kind``
  ``"cs"`` or ``"both"``) also ``fmi2DoStep``, which steps the emitted ``rk4_step`` with the
  structural parameter ``fixed_step`` (whole steps, then one partial step for the rest).

A source FMU ships no binary and no FMI headers: the importer compiles ``sources/`` with its
own ``fmi2Functions.h`` (FMPy's ``build_platform_binary``, Dymola, OpenModelica and Simulink's
FMU import do). :func:`fmu_archive` packs the files into a zip whose bytes depend on the content
only (fixed order, timestamps and attributes); the GUID is derived from the SHA-256 of the
content written with an empty GUID, so the same model gives the same FMU, and a changed model a
new GUID.
"""

from __future__ import annotations

import hashlib
import io
import re
import uuid
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from xml.sax.saxutils import escape

import sympy as sp
from gearsym.symbolic.codegen import (
    SparsityPattern,
    build_function_table,
    emit_c,
    file_names,
    jacobian_blocks,
    render,
)
from gearsym.symbolic.export.generate import sample_ranges
from gearsym.symbolic.export.tree import EmittedModel
from gearsym.symbolic.model import Variable
from gearsym.symbolic.version import __version__

__all__ = [
    "DEFAULT_FIXED_STEP",
    "KINDS",
    "WRAPPER_SOURCE",
    "FmuVariable",
    "fmu_archive",
    "fmu_files",
    "model_identifier",
    "unit_exponents",
]

#: The FMI wrapper's file name inside ``sources/``.
WRAPPER_SOURCE = "fmi2_gearsym.c"

#: What an FMU offers: Model Exchange, Co-Simulation, or both in one modelDescription (FMI 2.0
#: allows both elements side by side over the same sources; FMPy, Dymola, OpenModelica and
#: Simulink then let the user pick the interface).
KINDS = ("me", "cs", "both")
#: The Co-Simulation part's default internal RK4 step (the structural parameter ``fixed_step``).
DEFAULT_FIXED_STEP = 1e-4

#: The SI base units of FMI 2.0 ``BaseUnit`` (in its attribute order).
_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
#: Every unit symbol the descriptions use, in base-unit exponents.
_SYMBOLS: dict[str, dict[str, int]] = {
    "kg": {"kg": 1},
    "g": {"kg": 1},  # only ever as kg; kept so that a gram unit fails loudly below
    "m": {"m": 1},
    "s": {"s": 1},
    "rad": {"rad": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "K": {"K": 1},
    "1": {},
}
_TOKEN = re.compile(r"\s*(?:([A-Za-z]+|1)|(\^)\s*(-?\d+)|([*/()]))")


def unit_exponents(unit: str) -> dict[str, int]:
    """SI base-unit exponents of a unit string of the descriptions (``"N*m*s/rad"``,
    ``"kg*m^2"``, ``"(rad/s)/(kg)"``); raises ``ValueError`` for anything else."""
    tokens: list[tuple[str, str]] = []
    at = 0
    while at < len(unit):
        match = _TOKEN.match(unit, at)
        if match is None or match.end() == at:
            raise ValueError(f"cannot read unit {unit!r} at {unit[at:]!r}")
        name, _, power, op = match.groups()
        if name is not None:
            tokens.append(("name", name))
        elif power is not None:
            tokens.append(("power", power))
        else:
            tokens.append(("op", op))
        at = match.end()
    position = 0

    def peek() -> tuple[str, str] | None:
        return tokens[position] if position < len(tokens) else None

    def factor() -> dict[str, int]:
        nonlocal position
        token = peek()
        if token == ("op", "("):
            position += 1
            result = product()
            if peek() != ("op", ")"):
                raise ValueError(f"unbalanced parentheses in unit {unit!r}")
            position += 1
        elif token is not None and token[0] == "name" and token[1] in _SYMBOLS:
            if token[1] == "g":
                raise ValueError(f"unit {unit!r}: give masses in kg")
            position += 1
            result = dict(_SYMBOLS[token[1]])
        else:
            raise ValueError(f"unknown unit symbol in {unit!r}: {token}")
        token = peek()
        if token is not None and token[0] == "power":
            position += 1
            result = {k: v * int(token[1]) for k, v in result.items()}
        return result

    def product() -> dict[str, int]:
        nonlocal position
        result = factor()
        while peek() in (("op", "*"), ("op", "/")):
            sign = 1 if peek() == ("op", "*") else -1
            position += 1
            for k, v in factor().items():
                result[k] = result.get(k, 0) + sign * v
        return {k: v for k, v in result.items() if v != 0}

    result = product()
    if position != len(tokens):
        raise ValueError(f"cannot read unit {unit!r}")
    return result


def model_identifier(model_name: str) -> str:
    """The FMU's ``modelIdentifier`` (the binary's name and the C identifier prefix)."""
    return f"gearsym_{model_name}"


def _xml(text: str) -> str:
    """``text`` safe inside a double-quoted XML attribute."""
    return escape(text, {'"': "&quot;"})


def _number(value: float) -> str:
    """``xs:double`` text that reads back to exactly ``value`` (NaN for a missing default)."""
    if value != value:
        return "NaN"
    return repr(float(value))


@dataclass(frozen=True)
class FmuVariable:
    """One ``ScalarVariable`` of the model description (attributes already XML-safe)."""

    name: str
    vr: int  # value reference, the index into the wrapper's tables
    index: int  # 1-based position in ModelVariables (ModelStructure refers to it)
    description: str
    causality: str
    variability: str
    initial: str | None
    start: str | None
    unit: str | None
    min: str | None
    max: str | None
    nominal: str | None
    derivative: int | None  # for der(x): the index of x


@dataclass(frozen=True)
class Unknown:
    """An entry of ``ModelStructure``: the variable's index and the indices it depends on."""

    index: int
    dependencies: str  # space-separated, ascending


@dataclass(frozen=True)
class UnitView:
    name: str
    exponents: tuple[tuple[str, int], ...]  # nonzero base-unit exponents, FMI's order


@dataclass(frozen=True)
class ModelDescriptionView:
    """What ``fmu_model_description.xml.j2`` prints."""

    model_name: str
    identifier: str
    guid: str
    description: str
    version: str
    units: tuple[UnitView, ...]
    variables: tuple[FmuVariable, ...]
    outputs: tuple[Unknown, ...]
    derivatives: tuple[Unknown, ...]
    initial_unknowns: tuple[Unknown, ...]
    sources: tuple[str, ...]
    nx: int
    me: bool
    cs: bool


@dataclass(frozen=True)
class ParameterSlot:
    vr: int
    name: str


@dataclass(frozen=True)
class WrapperView:
    """What ``fmu_wrapper.c.j2`` prints."""

    model_name: str
    identifier: str
    guid: str
    header_name: str
    prefix: str  # gearsym_<model>_
    macro: str  # GEARSYM_<MODEL>_
    nx: int
    nu: int
    ny: int
    np: int
    vr_states: int
    vr_derivatives: int
    vr_inputs: int
    vr_outputs: int
    vr_parameters: int
    vr_end: int
    parameters: tuple[ParameterSlot, ...]
    state_starts: tuple[str, ...]
    input_starts: tuple[str, ...]
    nominals: tuple[str, ...]
    me: bool
    cs: bool
    fixed_step: str


def _variable(
    v: Variable,
    vr: int,
    *,
    causality: str,
    variability: str,
    initial: str | None,
    start: float | None,
    bounds: tuple[float | None, float | None] = (None, None),
    nominal: float | None = None,
    name: str | None = None,
    description: str | None = None,
    derivative: int | None = None,
    unit: str | None = None,
) -> FmuVariable:
    unit = v.unit if unit is None else unit
    lo, hi = bounds
    return FmuVariable(
        name=_xml(name or v.name),
        vr=vr,
        index=vr + 1,  # value references are the 0-based positions in ModelVariables
        description=_xml(description if description is not None else v.description),
        causality=causality,
        variability=variability,
        initial=initial,
        start=None if start is None else _number(start),
        unit=None if unit in ("1", "") else unit,  # unit_exponents() admits XML-safe text only
        min=None if lo is None else _number(lo),
        max=None if hi is None else _number(hi),
        nominal=None if nominal is None else _number(nominal),
        derivative=derivative,
    )


def _derivative_unit(unit: str) -> str:
    if unit in ("1", ""):
        return "1/s"
    if unit.endswith("/s") and "/" not in unit[:-2] and "(" not in unit:
        return f"{unit[:-2]}/s^2"
    return f"({unit})/s" if any(c in unit for c in "*/") else f"{unit}/s"


def _dependencies(pattern: SparsityPattern, row: int, indices: Sequence[int]) -> list[int]:
    """The ``indices`` of the columns of ``pattern`` with a structural nonzero in ``row``."""
    return [
        indices[j]
        for j in range(pattern.ncol)
        for k in range(pattern.colptr[j], pattern.colptr[j + 1])
        if pattern.rowind[k] == row
    ]


def _render(
    emitted: EmittedModel,
    gearbox: str,
    guid: str,
    c_files: Mapping[str, str],
    kind: str,
    fixed_step: float,
) -> dict:
    me, cs = kind in ("me", "both"), kind in ("cs", "both")
    model = emitted.model
    table = build_function_table(model, emitted.config)
    nx, nu, ny = len(model.states), len(model.inputs), len(model.outputs)
    np_ = len(model.parameters)
    vr_x, vr_dx, vr_u = 0, nx, 2 * nx
    vr_y, vr_p = vr_u + nu, vr_u + nu + ny
    ranges = sample_ranges(model)
    # The nominal value of a state is its typical magnitude (the sampling range validation
    # uses): an importer's solver scales its absolute tolerance with it (FMPy: rtol * nominal),
    # so a twist of 0.01 rad and a speed of 300 rad/s are both resolved.
    nominals = [
        max(abs(ranges[v.name][0]), abs(ranges[v.name][1])) if v.name in ranges else 1.0
        for v in model.states
    ]
    variables: list[FmuVariable] = []
    for i, v in enumerate(model.states):
        variables.append(
            _variable(
                v,
                vr_x + i,
                causality="local",
                variability="continuous",
                initial="exact",
                start=0.0,
                nominal=nominals[i],
            )
        )
    for i, v in enumerate(model.states):
        variables.append(
            _variable(
                v,
                vr_dx + i,
                causality="local",
                variability="continuous",
                initial="calculated",
                start=None,
                name=f"der({v.name})",
                description=f"time derivative of {v.name}",
                derivative=vr_x + i + 1,
                unit=_derivative_unit(v.unit),
            )
        )
    for i, v in enumerate(model.inputs):
        variables.append(
            _variable(
                v, vr_u + i, causality="input", variability="continuous", initial=None, start=0.0
            )
        )
    for i, v in enumerate(model.outputs):
        variables.append(
            _variable(
                v,
                vr_y + i,
                causality="output",
                variability="continuous",
                initial="calculated",
                start=None,
            )
        )
    for i, v in enumerate(model.parameters):
        variables.append(
            _variable(
                v,
                vr_p + i,
                causality="parameter",
                variability="tunable",
                initial="exact",
                # no default (shift_element's n_disc, r_m): NaN, which params_validate rejects
                # at fmi2ExitInitializationMode until the importer sets a value
                start=float("nan") if v.default is None else float(v.default),
                bounds=table.bounds[i],
            )
        )

    if cs:
        # The Co-Simulation step: structural (fixed), set before initialization ends.
        variables.append(
            FmuVariable(
                name="fixed_step",
                vr=vr_p + np_,
                index=vr_p + np_ + 1,
                description=_xml(
                    "Co-Simulation: internal RK4 step; fmi2DoStep takes whole steps of it and a "
                    "last partial one"
                ),
                causality="parameter",
                variability="fixed",
                initial="exact",
                start=_number(fixed_step),
                unit="s",
                min=_number(1e-9),
                max=_number(1.0),
                nominal=None,
                derivative=None,
            )
        )

    # Dependencies from the Jacobians' structural nonzeros: the derivatives' from the function
    # table (the patterns of jac_x, jac_u, jac_p the emitted C computes), the outputs' from the
    # same forward-mode differentiation of h.
    jac = {var: table[f"jac_{var}"].expressions[0] for var in "xup"}
    h = table["outputs"].expressions[0]
    blocks = jacobian_blocks(h, (table.states, table.inputs, table.parameters))
    jac_h = dict(zip("xup", blocks, strict=True))
    index = {
        "x": [vr_x + j + 1 for j in range(nx)],
        "u": [vr_u + j + 1 for j in range(nu)],
        "p": [vr_p + j + 1 for j in range(np_)],
    }

    def unknown(position: int, matrices: Mapping[str, sp.MatrixBase], row: int, *groups: str):
        deps = sorted(
            d for g in groups for d in _dependencies(SparsityPattern.of(matrices[g]), row, index[g])
        )
        return Unknown(position, " ".join(str(d) for d in deps))

    outputs = tuple(unknown(vr_y + i + 1, jac_h, i, "x", "u") for i in range(ny))
    derivatives = tuple(unknown(vr_dx + i + 1, jac, i, "x", "u") for i in range(nx))
    # In initialization mode the parameters (initial="exact") are knowns as well.
    initial = sorted(
        [unknown(vr_y + i + 1, jac_h, i, "x", "u", "p") for i in range(ny)]
        + [unknown(vr_dx + i + 1, jac, i, "x", "u", "p") for i in range(nx)],
        key=lambda u: u.index,
    )
    units = sorted({v.unit for v in variables if v.unit is not None})
    names = file_names(model)
    identifier = model_identifier(model.name)
    description = ModelDescriptionView(
        model_name=_xml(model.name),
        identifier=identifier,
        guid=guid,
        description=_xml(f"{emitted.summary}; gearbox {gearbox}; emitted by gearsym"),
        version=__version__,
        units=tuple(
            UnitView(
                u,
                tuple((b, e) for b in _BASE if (e := unit_exponents(u).get(b, 0)) != 0),
            )
            for u in units
        ),
        variables=tuple(variables),
        outputs=outputs,
        derivatives=derivatives,
        initial_unknowns=tuple(initial),
        sources=(names["source"], WRAPPER_SOURCE),
        nx=nx,
        me=me,
        cs=cs,
    )
    wrapper = WrapperView(
        model_name=model.name,
        identifier=identifier,
        guid=guid,
        header_name=names["header"],
        prefix=table.prefix,
        macro=table.macro_prefix,
        nx=nx,
        nu=nu,
        ny=ny,
        np=np_,
        vr_states=vr_x,
        vr_derivatives=vr_dx,
        vr_inputs=vr_u,
        vr_outputs=vr_y,
        vr_parameters=vr_p,
        vr_end=vr_p + np_,
        parameters=tuple(ParameterSlot(vr_p + i, v.name) for i, v in enumerate(model.parameters)),
        state_starts=tuple("0.0" for _ in model.states),
        input_starts=tuple("0.0" for _ in model.inputs),
        nominals=tuple(_number(n) for n in nominals),
        me=me,
        cs=cs,
        fixed_step=_number(fixed_step),
    )
    files = {
        "modelDescription.xml": render("fmu_model_description.xml.j2", description),
        f"sources/{WRAPPER_SOURCE}": render("fmu_wrapper.c.j2", wrapper),
    }
    files.update({f"sources/{name}": text for name, text in c_files.items()})
    return {path: text.encode("utf-8") for path, text in files.items()}


def fmu_files(
    emitted: EmittedModel,
    gearbox: str,
    kind: str = "both",
    fixed_step: float = DEFAULT_FIXED_STEP,
) -> dict[str, bytes]:
    """Every file of the source FMU of ``emitted``, by path inside the archive.

    ``kind`` (one of :data:`KINDS`) chooses the interfaces. The Co-Simulation part steps the
    emitted classical RK4 (``rk4_step``) with the fixed internal step ``fixed_step`` (a
    structural parameter of the FMU, this its start value): ``fmi2DoStep`` takes the whole steps
    that fit the communication interval and one last partial step for the rest.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, not {kind!r}")
    if not (1e-9 <= fixed_step <= 1.0):
        raise ValueError(f"fixed_step must lie in [1e-9, 1] s, not {fixed_step!r}")
    c_files = emit_c(emitted.model, emitted.config)
    # The GUID names this content: the hash of everything written with an empty GUID.
    draft = _render(emitted, gearbox, "", c_files, kind, fixed_step)
    digest = hashlib.sha256()
    for path in sorted(draft):
        digest.update(path.encode("utf-8") + b"\0" + draft[path] + b"\0")
    guid = "{" + str(uuid.UUID(bytes=digest.digest()[:16], version=4)) + "}"
    return _render(emitted, gearbox, guid, c_files, kind, fixed_step)


def fmu_archive(files: Mapping[str, bytes]) -> bytes:
    """A zip of ``files`` whose bytes depend on their paths and content only: sorted entries,
    the zip epoch as every timestamp, fixed attributes, deflate at level 9, no comment."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for path in sorted(files):
            info = zipfile.ZipInfo(path, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.create_system = 3  # Unix, so that external_attr holds the mode below
            info.external_attr = 0o644 << 16
            archive.writestr(info, files[path], compresslevel=9)
    return buffer.getvalue()
