"""The generated tree's example and index: the view of ``c/main.c`` (one shift model driven
through a shift, built alone) and ``README.md`` (what is where, the build line, every model and
set with its files), both rendered from the records of :mod:`gearsym.symbolic.export.tree`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.codegen import (
    file_names,
    float_repr,
    function_names,
    render,
)
from gearsym.symbolic.codegen.linear import LinearSystemSet
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name, element_slip_in_gear
from gearsym.symbolic.export.tree import (
    C_DIR,
    PYTHON_DIR,
    EmittedHybridSet,
    EmittedLinearSet,
    EmittedModel,
)
from gearsym.symbolic.friction import MuMap

__all__ = ["DOUBLE_SWAP_NOTE", "ExampleView", "example_view", "readme"]

#: What a double swap gets instead of the models and sets of a single swap, and why (the
#: generated README lists each double swap with it).
DOUBLE_SWAP_NOTE = (
    "torque-input model only (2.55-2.58, the four swapping elements' torques as inputs); no mu "
    "form, sensitivities, linear forms of hybrid modes or hybrid model: each needs the slip "
    "direction or lock state of every swapping element, which the gear table fixes for one "
    "element off and one on but not for two sliding at once"
)


def _example_shift(models: Sequence[EmittedModel]) -> EmittedModel:
    """The shift model main.c drives: 2-3 (the thesis' example) if there is one, with friction
    inputs if available."""
    shifts = [m for m in models if m.role in ("shift", "shift_mu")]
    if not shifts:
        raise ValueError("no shift model to show in the example")
    preferred = (
        [m for m in shifts if m.shift is not None and m.shift.name == "2-3"]
        or [m for m in shifts if m.shift is not None and m.shift.single]
        or shifts
    )
    with_mu = [m for m in preferred if m.role == "shift_mu"]
    return (with_mu or preferred)[0]


@dataclass(frozen=True)
class ExampleInput:
    name: str  # input variable
    code: str  # C expression of its value
    what: str


@dataclass(frozen=True)
class ExampleElement:
    """The shift element whose friction model main.c runs."""

    name: str
    n_disc: str
    r_m: str
    area: str


@dataclass(frozen=True)
class ExampleView:
    """What ``c_example_main.c.j2`` prints (and the README's build line)."""

    gearbox: str
    shift: str
    from_gear: str
    to_gear: str
    ratio_to: str
    omega_in: str
    omega_out: str
    shift_model: str
    shift_macro: str
    shift_header: str
    shift_states: tuple[str, ...]
    x0: tuple[str, ...]
    inputs: tuple[ExampleInput, ...]
    mu_settings: tuple[tuple[str, str], ...]  # (mu parameter, which element)
    t_oil: str
    apply_pressure: str
    slip: str
    speed: str
    full_model: str
    full_macro: str
    full_header: str
    element: ExampleElement | None
    element_header: str | None
    c_files: tuple[str, ...]


def example_view(d: GearboxDescription, models: Sequence[EmittedModel]) -> ExampleView:
    from gearsym.symbolic.ratios import gear_ratio

    shift = _example_shift(models)
    spec = shift.shift
    assert spec is not None
    full = next(m for m in models if m.role == "full")
    element = next((m for m in models if m.role == "shift_element"), None)
    sm = shift.model
    ratio = float(gear_ratio(d, d.gear(spec.from_gear)).ratio)
    ratio_to = float(gear_ratio(d, d.gear(spec.to_gear)).ratio)
    i_d = float(d.drivetrain["i_D"].value)
    r_dyn = float(d.vehicle["r_dyn"].value)
    speed = 15.0  # m/s
    omega_c = speed / r_dyn
    omega_out = omega_c * i_d
    initial = {
        naming.speed(d.input_shaft): ratio * omega_out,
        naming.speed(d.output_shaft): omega_out,
        naming.WHEEL_SPEED: omega_c,
    }
    apply_pressure = 5.0e5  # Pa
    slip = 20.0  # rad/s
    t_oil = float(d.friction["T_oil"].value) if "T_oil" in d.friction else 80.0
    inputs = []
    mu_settings = []
    for v in sm.inputs:
        if v.name == naming.INPUT_TORQUE:
            inputs.append(ExampleInput(v.name, "GEARSYM_LIT(150.0)", "engine torque"))
    if shift.role == "shift_mu":
        for elem_name, role in ((spec.off_going, "off-going"), (spec.on_coming, "on-coming")):
            e = d.element(elem_name)
            short = element_short_name(d, elem_name)
            force = naming.normal_force(short)
            if role == "off-going":
                inputs.append(ExampleInput(force, "GEARSYM_LIT(0.0)", f"{role} {e.name} released"))
            else:
                assert e.a_piston is not None
                area = f"GEARSYM_LIT({float_repr(e.a_piston.value)})"
                inputs.append(ExampleInput(force, f"P_APPLY * {area}", f"{role} {e.name}: p_N A"))
            mu_settings.append((naming.friction_coefficient(short), f"{role} {e.name}"))
    else:
        # Sliding torque of each on-coming element with the sign of its slip in the from-gear
        # (2.70; power_on_slip_signs for a single swap).
        for name in spec.off_elements:
            inputs.append(
                ExampleInput(naming.torque(name), "GEARSYM_LIT(0.0)", "off-going element open")
            )
        for name in spec.on_elements:
            sign = int(sp.sign(element_slip_in_gear(d, spec.from_gear, name)))
            inputs.append(
                ExampleInput(
                    naming.torque(name),
                    f"GEARSYM_LIT({300.0 * sign})",
                    "on-coming element sliding",
                )
            )
    element_view = None
    if element is not None:
        e = d.element(spec.on_elements[0])
        element_view = ExampleElement(
            name=e.name,
            n_disc=float_repr(float(e.n_disc or 0)),
            r_m=float_repr(e.r_m.value if e.r_m else 0.0),
            area=float_repr(e.a_piston.value if e.a_piston else 0.0),
        )
    c_files = [file_names(sm)["source"], "gearsym_mu_map.c", file_names(full.model)["source"]]
    if element is not None:
        c_files.insert(2, file_names(element.model)["source"])
    return ExampleView(
        gearbox=d.name,
        shift=spec.name,
        from_gear=spec.from_gear,
        to_gear=spec.to_gear,
        ratio_to=float_repr(round(ratio_to, 12)),
        omega_in=naming.speed(d.input_shaft),
        omega_out=naming.speed(d.output_shaft),
        shift_model=sm.name,
        shift_macro=naming.macro_prefix(sm.name),
        shift_header=file_names(sm)["header"],
        shift_states=tuple(v.name for v in sm.states),
        x0=tuple(float_repr(round(initial.get(v.name, 0.0), 6)) for v in sm.states),
        inputs=tuple(inputs),
        mu_settings=tuple(mu_settings),
        t_oil=float_repr(t_oil),
        apply_pressure=float_repr(apply_pressure),
        slip=float_repr(slip),
        speed=float_repr(speed),
        full_model=full.model.name,
        full_macro=naming.macro_prefix(full.model.name),
        full_header=file_names(full.model)["header"],
        element=element_view,
        element_header=file_names(element.model)["header"] if element else None,
        c_files=tuple(c_files),
    )


@dataclass(frozen=True)
class ReadmeRow:
    name: str
    summary: str
    sizes: str  # "NX / NU / NP / NY"
    states: str
    inputs: str
    c: str  # the C files
    python: str  # the CasADi module


@dataclass(frozen=True)
class ReadmeView:
    gearbox: str
    title: str
    models: tuple[ReadmeRow, ...]
    functions: tuple[str, ...]
    explicit_only: tuple[str, ...]  # models without the implicit step
    example: ExampleView
    mu_map_origin: str  # mu_map_origin() leaves only [A-Za-z0-9._+-] and spaces: Markdown-safe
    linear_sets: tuple[LinearSetRow, ...]
    hybrid_sets: tuple[LinearSetRow, ...] = ()
    uio_rows: tuple[str, ...] = ()  # Markdown table rows of the emitted UIOs
    control_rows: tuple[str, ...] = ()  # Markdown table rows of the emitted controllers
    double_swaps: tuple[str, ...] = ()  # "`shift_1_5`: K38 and B06 off, K81 and K27 on"
    double_swap_note: str = DOUBLE_SWAP_NOTE
    skipped: tuple[str, ...] = ()  # "`shift_1_2_mu`, `shift_1_2_mu_sens`: B1 has no ..."


@dataclass(frozen=True)
class LinearSetRow:
    name: str
    summary: str
    systems: str  # "full (6 x 9), gear_1 (3 x 3), ..."
    parameters: str
    c: str
    python: str


def readme(
    d: GearboxDescription,
    models: Sequence[EmittedModel],
    example: ExampleView,
    mu_map: MuMap,
    linear_sets: Sequence[EmittedLinearSet] = (),
    hybrid_sets: Sequence[EmittedHybridSet] = (),
    uio_rows: Sequence[str] = (),
    skipped: Sequence[str] = (),
    control_rows: Sequence[str] = (),
) -> str:
    rows = []
    for m in models:
        names = file_names(m.model)
        rows.append(
            ReadmeRow(
                name=m.model.name,
                summary=m.summary,
                sizes=f"{len(m.model.states)} / {len(m.model.inputs)} / "
                f"{len(m.model.parameters)} / {len(m.model.outputs)}",
                states=", ".join(v.name for v in m.model.states),
                inputs=", ".join(v.name for v in m.model.inputs),
                c=f"{C_DIR}/{names['header']}, {C_DIR}/{names['source']}",
                python=f"{PYTHON_DIR}/{names['casadi']}",
            )
        )
    view = ReadmeView(
        gearbox=d.name,
        title=d.title,
        models=tuple(rows),
        functions=tuple(function_names(models[0].config)),
        explicit_only=tuple(m.model.name for m in models if not m.config.implicit_step),
        example=example,
        mu_map_origin=mu_map.origin,
        linear_sets=tuple(_linear_set_row(emitted.set) for emitted in linear_sets),
        hybrid_sets=tuple(_hybrid_set_row(emitted) for emitted in hybrid_sets),
        uio_rows=tuple(uio_rows),
        control_rows=tuple(control_rows),
        double_swaps=tuple(
            f"`{m.model.name}`: {' and '.join(m.shift.off_elements)} off, "
            f"{' and '.join(m.shift.on_elements)} on"
            for m in models
            if m.role == "shift" and m.shift is not None and not m.shift.single
        ),
        skipped=tuple(skipped),
    )
    return render("generated_readme.md.j2", view)


def _linear_set_row(s: LinearSystemSet) -> LinearSetRow:
    names = naming.model_file_names(s.name)
    return LinearSetRow(
        name=s.name,
        summary=s.metadata["content"],
        systems=", ".join(f"`{x.name}` ({len(x.states)} x {len(x.inputs)})" for x in s.systems),
        parameters=", ".join(v.name for v in s.parameters),
        c=f"{C_DIR}/{names['header']}, {C_DIR}/{names['source']}",
        python=f"{PYTHON_DIR}/{names['casadi']}",
    )


def _hybrid_set_row(emitted: EmittedHybridSet) -> LinearSetRow:
    hs = emitted.sensitivity
    names = naming.model_file_names(emitted.name)
    return LinearSetRow(
        name=emitted.name,
        summary=f"shift {hs.hybrid.spec.name}: {len(hs.jumps)} switches",
        systems=f"{len(hs.modes)} (NX_AUG {min(len(m.states) for m in hs.modes)}"
        f"-{max(len(m.states) for m in hs.modes)})",
        parameters=", ".join(v.name for v in hs.parameters),
        c=f"{C_DIR}/{names['header']}, {C_DIR}/{names['source']}",
        python=f"{PYTHON_DIR}/{names['casadi']}",
    )
