"""What ``gearsym generate`` emits for one gearbox, as a pure function: description in, files out.

:func:`generate_tree` returns ``{relative path: text}`` for

* ``c/gearsym_<model>.{h,c}`` and ``python/gearsym_<model>_casadi.py`` for every model of
  :func:`gearbox_models`: the full model (2.53), every adjacent shift model (2.55–2.58) with the
  element torques as inputs (``shift_<a>_<b>``) and, when the description has friction data, with
  the normal forces as inputs and μ as parameters (``shift_<a>_<b>_mu``, 2.69), and the
  elasto-plastic shift-element friction model (``shift_element``, 2.66–2.70);
* ``c/gearsym_mu_map.{h,c}`` and ``python/gearsym_mu_map_casadi.py``: the μ(p_N, T_oil, |Δω|)
  map of the description, trilinear and clamped like :class:`gearsym.symbolic.friction.MuMap`;
* ``c/main.c``: an example a TCU engineer compiles alone (build line in its header comment);
* ``README.md`` (what is where, and the build line) and ``MANIFEST`` (SHA-256 of every file;
  its first line marks a directory that ``gearsym generate`` may replace).

Nothing in the output depends on the time, the machine, absolute paths or ``PYTHONHASHSEED``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.codegen import (
    CodegenConfig,
    EkfLayout,
    EuioLayout,
    emit_all,
    float_repr,
    render,
)
from gearsym.symbolic.codegen.control import control_files
from gearsym.symbolic.codegen.hybrid import emit_hybrid_files, hybrid_set_model
from gearsym.symbolic.codegen.linear import LinearSystem, LinearSystemSet, emit_linear_files
from gearsym.symbolic.codegen.mu_map import mu_map_files
from gearsym.symbolic.defaults import DEFAULT_SHIFT
from gearsym.symbolic.description import GearboxDescription, Quantity
from gearsym.symbolic.drivetrain import (
    adjacent_shifts,
    element_short_name,
    full_model,
    power_on_slip_signs,
    shift_model,
)
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.export.index import DOUBLE_SWAP_NOTE, example_view, readme
from gearsym.symbolic.export.selection import SHIFT_SELECTIONS, controller_shifts, selected_shifts
from gearsym.symbolic.export.tree import (
    C_DIR,
    PYTHON_DIR,
    EmittedHybridSet,
    EmittedLinearSet,
    EmittedModel,
    GeneratedTree,
)
from gearsym.symbolic.friction import (
    T_SS_MIN,
    load_mu_map,
    mu_map_origin,
    shift_element_sym,
)
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.hybrid_sensitivity import hybrid_sensitivity
from gearsym.symbolic.io.output_dir import MANIFEST, manifest_marker, manifest_text
from gearsym.symbolic.linear_forms import gear_linear_forms, shift_linear_forms
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.parameters import RECORDS, is_mu, record
from gearsym.symbolic.sensitivity import sensitivity_model
from gearsym.symbolic.shifts import ShiftSpec

__all__ = [
    "MANIFEST_MARKER",
    "gearbox_models",
    "linear_system_sets",
    "generate_tree",
    "load_mu_map",
    "mu_map_files",
    "mu_map_origin",
    "sample_ranges",
    "missing_friction",
    "controller_shifts",
    "selected_shifts",
    "shift_element_model",
    "skipped_models",
]

#: First line of ``MANIFEST``; ``gearsym generate`` only replaces directories that carry it.
MANIFEST_MARKER = manifest_marker("generate")


#: Plausibility ranges that the emitted ``params_validate`` enforces (ERR_RANGE outside):
#: the records' ranges (:mod:`gearsym.symbolic.parameters`). Closed intervals; ``None`` means
#: unbounded. Model defaults must lie inside.
PARAMETER_BOUNDS: dict[str, tuple[float | None, float | None]] = {
    r.key: r.bounds for r in RECORDS if r.bounds is not None and r.section != "mu"
}
MU_BOUNDS = record("mu").bounds  # every μ_<element> parameter

#: Sampling ranges of states and inputs for validation, by name prefix (first match wins).
_RANGES_BY_PREFIX: tuple[tuple[str, tuple[float, float]], ...] = (
    ("S_", (-10.0, 10.0)),  # sensitivities ∂x/∂p (3.2); compared relatively, any scale
    ("omega_C", (-150.0, 150.0)),  # wheel speed, rad/s (about ±180 km/h)
    ("omega_", (-600.0, 600.0)),  # shaft speeds, rad/s
    ("phi", (-0.05, 0.05)),  # side-shaft twist, rad
    ("T_", (-800.0, 800.0)),  # torques, N m
    ("F_N", (0.0, 20000.0)),  # normal forces, N (an open element has 0)
    ("z", (-0.02, 0.02)),  # bristle deflection of the friction model, rad
    ("dw", (-50.0, 50.0)),  # slip, rad/s
    ("mu", (0.08, 0.16)),  # friction coefficient input
)
#: Sampling ranges of parameters without a default.
_PARAMETER_RANGES = {r.key: r.sample_range for r in RECORDS if r.sample_range is not None}


# ---------------------------------------------------------------------------------------------
# Models
# ---------------------------------------------------------------------------------------------


def _bounds(d: GearboxDescription, model: Model) -> dict[str, tuple[float | None, float | None]]:
    """Bounds per parameter; a description default outside them is a one-line user error."""
    bounds = {}
    for v in model.parameters:
        if v.name.startswith("mu_"):
            lo, hi = MU_BOUNDS
        elif v.name in PARAMETER_BOUNDS:
            lo, hi = PARAMETER_BOUNDS[v.name]
        else:
            continue
        if v.default is not None:
            key = "friction.mu_nominal" if is_mu(v.name) else f"{record(v.name).section}.{v.name}"
            _check_bound(d, key, v.default, (lo, hi))
        bounds[v.name] = (lo, hi)
    return bounds


#: The ``[friction]`` values the elasto-plastic element model is emitted with (2.66-2.70).
_FRICTION_KEYS = ("sigma0", "sigma1", "z_ba_ratio", "mu_nominal")


def missing_friction(d: GearboxDescription, elements: Sequence[str] | None = None) -> str:
    """Why the μ models of ``elements`` (default: the description's) cannot be derived, "" when
    they can: no ``[friction] mu_nominal`` (the μ parameters' default), or a friction element
    without ``n_disc`` and ``r_m`` (2.69). A one-way clutch or a dog element needs neither:
    it carries no μ."""
    absent = [k for k in ("mu_nominal",) if k not in d.friction]
    if absent:
        return f"[friction] has no {', '.join(absent)}"
    names = [e.name for e in d.shift_elements] if elements is None else list(elements)
    lacking = [
        e
        for e in names
        if not (d.element(e).one_way or d.element(e).dog)
        and (d.element(e).n_disc is None or d.element(e).r_m is None)
    ]
    if lacking:
        verb = "has" if len(lacking) == 1 else "have"
        return f"{', '.join(lacking)} {verb} no n_disc and r_m (2.69)"
    return ""


def _no_slip_direction(d: GearboxDescription, spec: ShiftSpec) -> str:
    """Why the μ form of ``spec`` has no friction torque direction, "" when it has: a friction
    element that does not slip in the gear that releases it (two gears of the same ratio,
    such as a manual low and the freewheel's 1st) has no power-on slip sign (2.70)."""
    signs = power_on_slip_signs(d, spec)
    still = [
        e for e in spec.swapping if not (d.element(e).one_way or d.element(e).dog) and signs[e] == 0
    ]
    if not still:
        return ""
    it, has = ("it", "torque has") if len(still) == 1 else ("them", "torques have")
    return (
        f"{', '.join(still)} would not slip: gears {spec.from_gear} and {spec.to_gear} leave "
        f"{it} at zero slip, so the friction {has} no direction (2.70)"
    )


def _estimator_obstacle(d: GearboxDescription, spec: ShiftSpec) -> str:
    """Why the EKF and the extended UIO of ``spec`` are not emitted, "" when they are."""
    one_way = [e for e in spec.swapping if d.element(e).one_way]
    if one_way:
        return (
            f"the one-way clutch {', '.join(one_way)} swaps: the emitted filters' mode logic "
            "reads a normal force and a μ of each swapping element (the library's hybrid model "
            "runs such a shift)"
        )
    dogs = [e for e in spec.swapping if d.element(e).dog]
    if dogs:
        return (
            f"the dog element {', '.join(dogs)} swaps: the emitted filters' mode logic reads a "
            "normal force and a μ of each swapping element (the library's hybrid model runs "
            "such a shift)"
        )
    return missing_friction(d, spec.swapping)


def _quantity_default(q: Quantity) -> tuple[float, str]:
    return float(q.value), q.source


def shift_element_model(d: GearboxDescription) -> Model:
    """The elasto-plastic friction model of one shift element (2.66)–(2.70) as a :class:`Model`.

    State ``z`` (bristle deflection, rad), inputs ``dw`` (slip ω_a − ω_b), ``F_N`` (normal force),
    ``mu`` (friction coefficient, e.g. from ``gearsym_mu_map``); output ``T`` (element torque, +T
    on shaft b, −T on shaft a). Parameters ``sigma0``, ``sigma1``, ``z_ba_ratio`` from the
    description's ``[friction]``, the regularisation ``t_ss_min``, and the element geometry
    ``n_disc``, ``r_m`` (no default: set them per element; the README lists them).

    The expressions are those of :func:`gearsym.symbolic.friction.shift_element_sym` (with its
    regularisations: capacity floored at ``t_ss_min``, passive damping, elastic torque limited
    to the capacity).
    """
    z, dw, f_n, mu = (sp.Symbol(n, real=True) for n in ("z", "dw", "F_N", "mu"))
    s0, s1, ratio, t_min, n_disc, r_m = (
        sp.Symbol(n, positive=True)
        for n in ("sigma0", "sigma1", "z_ba_ratio", "t_ss_min", "n_disc", "r_m")
    )
    # The model of symbolic/friction.py itself, so the emitted code follows it.
    zdot, torque = shift_element_sym(z, dw, f_n, mu, s0, s1, n_disc, r_m, ratio, t_min)

    def friction_value(key: str, fallback: float) -> tuple[float, str]:
        if key in d.friction:
            return _quantity_default(d.friction[key])
        return fallback, "assumed"

    sigma0 = friction_value("sigma0", 2.0e5)
    sigma1 = friction_value("sigma1", 150.0)
    z_ba = friction_value("z_ba_ratio", 0.6)
    elements = ", ".join(
        f"{e.name} (n_disc {e.n_disc}, r_m {float_repr(e.r_m.value)} m)"
        for e in d.shift_elements
        if e.n_disc is not None and e.r_m is not None
    )
    return Model(
        name=naming.SHIFT_ELEMENT_MODEL,
        states=(Variable("z", z, "rad", "bristle deflection (2.66)"),),
        inputs=(
            Variable("dw", dw, "rad/s", "slip omega_a - omega_b"),
            Variable("F_N", f_n, "N", "normal force on the disc pack, p_N A_piston (2.69)"),
            Variable("mu", mu, "1", "friction coefficient, e.g. from gearsym_mu_map (2.69)"),
        ),
        parameters=(
            Variable("sigma0", s0, "N*m/rad", "bristle stiffness (2.66)", *sigma0),
            Variable("sigma1", s1, "N*m*s/rad", "bristle damping (2.67)", *sigma1),
            Variable("z_ba_ratio", ratio, "1", "break-away deflection z_ba / z_ss (2.66)", *z_ba),
            Variable(
                "t_ss_min",
                t_min,
                "N*m",
                "floor of the capacity |T_Cl,SS| (regularises an open element)",
                T_SS_MIN,
                "symbolic/friction.py T_SS_MIN",
            ),
            Variable("n_disc", n_disc, "1", "friction disc count N_disc of the element (2.69)"),
            Variable("r_m", r_m, "m", "mean friction radius of the element (2.69)"),
        ),
        outputs=(Variable("T", sp.Symbol("T"), "N*m", "element torque T_Cl (2.67)"),),
        rhs=sp.Matrix([zdot]),
        output_expressions=sp.Matrix([torque]),
        metadata={
            "gearbox": d.name,
            "equations": "2.66-2.70",
            "elements": elements or "none with friction data",
        },
    )


def sensitivity_parameters(d: GearboxDescription, spec: ShiftSpec) -> list[str]:
    """The thesis' parameter set (3.2) for a shift: m_veh, k_ss, d_ss, μ of the off-going
    element (of the on-coming one when the off-going element is a one-way clutch or a dog
    element, which have no μ), ζ."""
    off = d.element(spec.off_going)
    element = spec.on_coming if off.one_way or off.dog else spec.off_going
    mu = naming.friction_coefficient(element_short_name(d, element))
    return ["m_veh", "k_ss", "d_ss", mu, "zeta"]


def check_generatable(d: GearboxDescription) -> None:
    """Raise the description's errors that ``generate`` would meet (too few forward gears,
    missing drivetrain or vehicle data) before any work is reported: one line, exit 2."""
    if not adjacent_shifts(d):
        raise GearsymError(
            d.file,
            "gear",
            "gearsym generate needs at least two forward gears (positive ratio): it emits the "
            "models of the shifts between them and an example that drives one",
        )
    full_model(d)
    for section in ("drivetrain", "vehicle", "friction"):
        for key, q in getattr(d, section).items():
            bounds = MU_BOUNDS if key == "mu_nominal" else PARAMETER_BOUNDS.get(key)
            if bounds is not None:
                _check_bound(d, f"{section}.{key}", float(q.value), bounds)


def _check_bound(
    d: GearboxDescription, key: str, value: float, bounds: tuple[float | None, float | None]
) -> None:
    """A description value outside the range the emitted ``params_validate`` accepts is a
    one-line user error."""
    lo, hi = bounds
    if (lo is None or value >= lo) and (hi is None or value <= hi):
        return
    raise GearsymError(
        d.file,
        key,
        f"value {value:g} lies outside the range [{lo:g}, {hi:g}] that the generated "
        "params_validate accepts",
    )


def gearbox_model_names(
    d: GearboxDescription, shifts: str = "adjacent", controllers: str | None = None
) -> list[str]:
    """The names of :func:`gearbox_models`, in output order, without deriving anything."""
    return [name for name, _ in _model_plan(d, shifts, controllers)]


def gearbox_models(
    d: GearboxDescription,
    progress: Callable[[str], None] | None = None,
    only: str | None = None,
    shifts: str = "adjacent",
    controllers: str | None = None,
) -> list[EmittedModel]:
    """Every model ``gearsym generate`` emits for ``d``, in output order (with ``only``: that
    one model, deriving nothing else; an empty list for an unknown name). ``shifts`` selects
    the shift models (:func:`selected_shifts`), ``controllers`` the shifts whose EKF a
    controller runs with (:func:`controller_shifts`)."""
    say = progress or (lambda message: None)
    plan = _model_plan(d, shifts, controllers)
    return [build(say) for name, build in plan if only is None or name == only]


def _model_plan(
    d: GearboxDescription, shifts_selected: str = "adjacent", controllers: str | None = None
) -> list[tuple[str, Callable[[Callable[[str], None]], EmittedModel]]]:
    """(name, builder) of every emitted model: the names come from the naming rules, so a
    caller can pick one model before any derivation."""
    return _plan_and_skips(d, shifts_selected, controllers)[0]


def skipped_models(
    d: GearboxDescription, shifts: str = "adjacent", controllers: str | None = None
) -> tuple[str, ...]:
    """What ``generate`` leaves out for ``d`` and why, one line each (printed, and listed in the
    generated README); empty when every model is emitted."""
    return _plan_and_skips(d, shifts, controllers)[1]


def _plan_and_skips(
    d: GearboxDescription, shifts_selected: str = "adjacent", controllers: str | None = None
) -> tuple[list[tuple[str, Callable[[Callable[[str], None]], EmittedModel]]], tuple[str, ...]]:
    from gearsym.symbolic.estimators.ekf import ekf_model_name
    from gearsym.symbolic.estimators.euio import euio_model_name

    if not adjacent_shifts(d):
        check_generatable(d)  # the one-line error (missing data fails in full_model below)
    shifts = selected_shifts(d, shifts_selected)
    skipped: list[str] = []

    def full(say: Callable[[str], None]) -> EmittedModel:
        say("deriving the full model (2.53)")
        m = full_model(d)
        return EmittedModel(m, _bounds(d, m), "full", "full model (2.53)")

    def torque_shift(spec: ShiftSpec) -> Callable[[Callable[[str], None]], EmittedModel]:
        def build(say: Callable[[str], None]) -> EmittedModel:
            say(f"deriving shift model {spec.name} (2.55-2.58)")
            m = shift_model(d, spec.name)
            off, on = " and ".join(spec.off_elements), " and ".join(spec.on_elements)
            what = f"shift {spec.name}: {off} off, {on} on, torque inputs"
            return EmittedModel(m, _bounds(d, m), "shift", what, spec)

        return build

    def mu_shift(spec: ShiftSpec) -> Callable[[Callable[[str], None]], EmittedModel]:
        def build(say: Callable[[str], None]) -> EmittedModel:
            m = shift_model(d, spec.name, friction_inputs=True)
            what = f"shift {spec.name}: normal-force inputs, mu parameters (2.69)"
            return EmittedModel(m, _bounds(d, m), "shift_mu", what, spec)

        return build

    def sensitivity(spec: ShiftSpec) -> Callable[[Callable[[str], None]], EmittedModel]:
        # the sensitivity system [x; S] (3.5)-(3.7) of the mu model for the thesis' parameter
        # set, with the off-going element's μ (3.14)
        def build(say: Callable[[str], None]) -> EmittedModel:
            m = shift_model(d, spec.name, friction_inputs=True)
            parameters = sensitivity_parameters(d, spec)
            say(f"deriving the sensitivity system of shift {spec.name} (3.7)")
            s = sensitivity_model(m, parameters)
            what = f"shift {spec.name}: sensitivities to {', '.join(parameters)} (3.7)"
            # RK4 only: (3.7) is not stiff, and an implicit 24 x 24 solve does not belong on
            # an ECU's stack
            return EmittedModel(s, _bounds(d, s), "sensitivity", what, spec, integrators=("rk4",))

        return build

    def element(say: Callable[[str], None]) -> EmittedModel:
        say("building the shift-element friction model (2.66-2.70)")
        m = shift_element_model(d)
        return EmittedModel(m, _bounds(d, m), "shift_element", "shift-element friction (2.66-2.70)")

    plan: list[tuple[str, Callable[[Callable[[str], None]], EmittedModel]]] = [
        (naming.FULL_MODEL, full)
    ]
    for spec in shifts:
        plan.append((naming.shift_model_name(spec.from_gear, spec.to_gear), torque_shift(spec)))
        if not spec.single:  # a double swap: the torque-input model only (README, its note)
            continue
        mu_name = naming.shift_model_name(spec.from_gear, spec.to_gear, True)
        sens_name = naming.sensitivity_model_name(mu_name)
        why = missing_friction(d, spec.swapping) or _no_slip_direction(d, spec)
        if why:
            skipped.append(f"`{mu_name}`, `{sens_name}`: {why}")
            continue
        plan.append((mu_name, mu_shift(spec)))
        plan.append((sens_name, sensitivity(spec)))
    ekf_shift = next((spec for spec in shifts if spec.name == "2-3"), None)
    if ekf_shift is not None:
        ekf_name, euio_name = ekf_model_name(ekf_shift.name), euio_model_name(ekf_shift.name)
        why = _estimator_obstacle(d, ekf_shift)
        if why:
            skipped.append(f"`{ekf_name}`, `{euio_name}`: {why}")
        else:
            plan.append((ekf_name, lambda say: ekf_model(d, ekf_shift, say)))
            plan.append((euio_name, lambda say: euio_model(d, ekf_shift, say)))

    def ekf(spec: ShiftSpec) -> Callable[[Callable[[str], None]], EmittedModel]:
        return lambda say: ekf_model(d, spec, say)

    # the EKF each other shift's controller runs with (its obstacle is the controller's skip)
    planned = {name for name, _ in plan}
    for spec in controller_shifts(d, shifts_selected, controllers):
        if ekf_model_name(spec.name) not in planned and not _estimator_obstacle(d, spec):
            plan.append((ekf_model_name(spec.name), ekf(spec)))
    absent = [k for k in _FRICTION_KEYS if k not in d.friction]
    if absent:
        skipped.append(f"`{naming.SHIFT_ELEMENT_MODEL}`: [friction] has no {', '.join(absent)}")
    else:
        plan.append((naming.SHIFT_ELEMENT_MODEL, element))
    return plan, tuple(skipped)


def ekf_model(
    d: GearboxDescription, spec: ShiftSpec, say: Callable[[str], None] | None = None
) -> EmittedModel:
    """The EKF (4.3) of a shift: its augmented model (4.1) with the predict and update rows;
    each μ state is frozen while its element's ``slide_<E>`` input is not set."""
    from gearsym.symbolic.codegen import EkfModeElement
    from gearsym.symbolic.drivetrain import element_short_name
    from gearsym.symbolic.estimators.ekf import augmented_model, slide_input, stick_input
    from gearsym.symbolic.estimators.ekf_modes import LOCK_UP_CONFIDENCE, lock_up_map

    if say is not None:
        say(f"deriving the augmented model of shift {spec.name} for the EKF (4.1, 4.3)")
    aug = augmented_model(d, spec.name)
    states, inputs = aug.state_names, aug.input_names
    frozen = tuple(
        (states.index(mu), inputs.index(slide_input(e))) for e, mu in aug.mu_state.items()
    )
    n = aug.n_x
    modes = []
    for e in aug.elements:
        A = lock_up_map(d, aug, e)
        modes.append(
            EkfModeElement(
                e,
                inputs.index(naming.normal_force(element_short_name(d, e))),
                inputs.index(slide_input(e)),
                inputs.index(stick_input(e)),
                aug.slip_sign[e],
                states.index(aug.mu_state[e]) if e in aug.mu_state else -1,
                tuple(tuple(A[i, j] for j in range(n)) for i in range(n)),
            )
        )
    quantities = sp.ImmutableMatrix(
        [q for e in aug.elements for q in (aug.slip[e], aug.sticking_torque[e], aug.capacity[e])]
    )
    what = f"shift {spec.name}: EKF of {', '.join(aug.parameters)} (4.1, 4.3)"
    return EmittedModel(
        aug.model,
        _bounds(d, aug.model),
        "ekf",
        what,
        spec,
        integrators=("rk4",),
        ekf=EkfLayout(frozen, tuple(modes), quantities, LOCK_UP_CONFIDENCE),
    )


def euio_model(
    d: GearboxDescription, spec: ShiftSpec, say: Callable[[str], None] | None = None
) -> EmittedModel:
    """The extended UIO (4.5) of a shift: the EKF's augmented model (4.1) without ζ and
    without a road model (ζ, f_roll, c_W are 0: the road load T_res* is the unknown input),
    with the rows jac_outputs, euio_load_column and euio_step."""
    from gearsym.symbolic.estimators.euio import euio_filter_model, euio_phase_masks

    if say is not None:
        say(f"deriving the augmented model of shift {spec.name} for the extended UIO (4.5)")
    model, frozen, column = euio_filter_model(d, spec.name)
    what = f"shift {spec.name}: extended UIO of {model.metadata['augmented']} (4.5)"
    return EmittedModel(
        model,
        _bounds(d, model),
        "euio",
        what,
        spec,
        integrators=("rk4",),
        euio=EuioLayout(frozen, column, euio_phase_masks(d, spec.name)),
    )


def linear_system_sets(
    d: GearboxDescription,
    progress: Callable[[str], None] | None = None,
    shifts: str = "adjacent",
) -> list[EmittedLinearSet]:
    """The linear forms (5.1) ``generate`` emits: ``linear_gears`` (the full model and every
    gear) and ``linear_<a>_<b>`` (every mode of each emitted shift), as the emitters' sets."""
    say = progress or (lambda message: None)
    say("deriving the linear forms (5.1) of the full model and every gear")
    groups = [gear_linear_forms(d)]
    for spec in selected_shifts(d, shifts):
        if not spec.single:  # no hybrid modes for a double swap (DOUBLE_SWAP_NOTE)
            continue
        say(f"deriving the linear forms (5.1) of the modes of shift {spec.name}")
        groups.append(shift_linear_forms(d, spec))
    sets = []
    for group in groups:
        systems = tuple(
            LinearSystem(
                named.name,
                tuple(named.form.states),
                tuple(named.form.inputs),
                named.form.A,
                named.form.B,
                named.summary,
                (f"hybrid modes: {', '.join(named.modes)}",) if named.modes else (),
            )
            for named in group.forms
        )
        metadata = {"gearbox": d.name, "equations": "5.1-5.3", "content": group.summary}
        # the note where a system locks a one-way clutch (not on sets it takes no part in)
        one_way = [
            e
            for e in d.shift_elements
            if e.one_way and any(e.name in named.locked for named in group.forms)
        ]
        if one_way:
            metadata["one_way"] = (
                f"systems that lock a one-way clutch ({', '.join(e.name for e in one_way)}) "
                "hold only while it carries reaction torque of its blocking sign; when that "
                "torque would change sign the caller switches to the system with it released "
                "(a state-dependent switch, see the gearsym documentation: docs/description.md, "
                "One-way clutches)"
            )
        s = LinearSystemSet(group.name, group.parameters, systems, metadata)
        # the parameter ranges params_validate enforces are those of the models
        sets.append(EmittedLinearSet(s, CodegenConfig(bounds=_bounds(d, s.as_model()))))
    return sets


def dog_hybrid_obstacle(d: GearboxDescription, spec: ShiftSpec) -> str:
    """Why the hybrid sensitivities of ``spec`` are not emitted, "" when they are: a swapping
    dog element, whose engagement and release are command events (not an input of the
    emitted functions) and whose release guard |T_req| − release_torque has a kink the
    emitted jump would differentiate."""
    dogs = [e for e in spec.swapping if d.element(e).dog]
    if not dogs:
        return ""
    return (
        f"the dog element {', '.join(dogs)} swaps: its engagement and release are command "
        "events, not inputs of the emitted functions, and its release guard "
        "|T| - release_torque has a kink the emitted jump cannot differentiate (the library's "
        "hybrid simulation runs such a shift)"
    )


def hybrid_shift_names(d: GearboxDescription, hybrid_shifts: str | None = None) -> list[str]:
    """The shifts whose hybrid sensitivities ``generate`` emits: ``hybrid_shifts`` as
    :func:`selected_shifts` reads it, ``"none"``, or by default the thesis' shift
    (:data:`~gearsym.symbolic.defaults.DEFAULT_SHIFT`) where the gearbox has it as a single
    swap and friction data (each set is about 110 kB of object code, so not every shift by
    default). ``all`` and ``adjacent`` leave out double swaps (:data:`DOUBLE_SWAP_NOTE`); a
    list that names one is the one-line error of a double swap."""
    if hybrid_shifts == "none":
        return []
    if hybrid_shifts is None:
        specs = {spec.name: spec for spec in selected_shifts(d, "all")}
        if DEFAULT_SHIFT not in specs or not specs[DEFAULT_SHIFT].single:
            return []
        # the hybrid model needs n_disc and r_m of its friction elements (3.14)
        spec = specs[DEFAULT_SHIFT]
        blocked = missing_friction(d, spec.swapping) or dog_hybrid_obstacle(d, spec)
        return [] if blocked else [DEFAULT_SHIFT]
    specs = selected_shifts(d, hybrid_shifts, "--hybrid-shifts")
    if hybrid_shifts not in SHIFT_SELECTIONS:
        for spec in specs:
            if not spec.single:
                raise GearsymError(
                    d.file,
                    "--hybrid-shifts",
                    f"shift {spec.name} swaps two elements each way: {DOUBLE_SWAP_NOTE}",
                )
    return [spec.name for spec in specs if spec.single and not dog_hybrid_obstacle(d, spec)]


def hybrid_sensitivity_sets(
    d: GearboxDescription,
    progress: Callable[[str], None] | None = None,
    hybrid_shifts: str | None = None,
) -> list[EmittedHybridSet]:
    """The hybrid shift models' sensitivities (3.7 per mode, jumps at every switch) that
    ``generate`` emits (:func:`hybrid_shift_names`)."""
    say = progress or (lambda message: None)
    sets = []
    for name in hybrid_shift_names(d, hybrid_shifts):
        say(f"deriving the hybrid sensitivities of shift {name} (3.7 and the switch jumps)")
        hs = hybrid_sensitivity(hybrid_shift(d, name), file=d.file)
        config = CodegenConfig(bounds=_bounds(d, hybrid_set_model(hs)))
        sets.append(EmittedHybridSet(hs, config))
    return sets


def sample_ranges(model: Model) -> dict[str, tuple[float, float]]:
    """Physically meaningful sampling ranges of the states and inputs (and of parameters that
    have no default) of an emitted model, for :mod:`gearsym.validation.checks.c_check`."""
    ranges = {}
    for v in (*model.states, *model.inputs):
        for prefix, bounds in _RANGES_BY_PREFIX:
            if v.name.startswith(prefix):
                ranges[v.name] = bounds
                break
    for v in model.parameters:
        if v.default is None and v.name in _PARAMETER_RANGES:
            ranges[v.name] = _PARAMETER_RANGES[v.name]
    return ranges


def uio_files(
    d: GearboxDescription,
    progress: Callable[[str], None] | None = None,
    shifts: str = "adjacent",
    unknown: Sequence[str] = (naming.RESISTANCE_INPUT,),
) -> tuple[dict[str, str], list[str], tuple[Any, ...]]:
    """The UIO files (thesis 4.4) of the default shift, when it is emitted, their README
    rows and the designs they print. Only T_res* is unknown by default: with the clutch
    torques T_K38, T_B05 unknown too the torque and speed phase has an invariant zero at
    s = 0 and no UIO exists, and
    :func:`~gearsym.symbolic.estimators.uio.shift_uio_designs` refuses it (naming the phase
    and the condition)."""
    from gearsym.symbolic.codegen.uio import emit_uio_files, phase_identifier, uio_set_name
    from gearsym.symbolic.defaults import DEFAULT_SHIFT, SAMPLE_TIME
    from gearsym.symbolic.estimators.uio import shift_uio_designs

    if DEFAULT_SHIFT not in {spec.name for spec in selected_shifts(d, shifts)}:
        return {}, [], ()
    say = progress or (lambda message: None)
    say(f"designing the UIO of shift {DEFAULT_SHIFT} ({', '.join(unknown)} unknown)")
    designs = shift_uio_designs(d, DEFAULT_SHIFT, unknown, SAMPLE_TIME)
    metadata = {
        "gearbox": d.name,
        "equations": "4.4, 5.1-5.3",
        "unknown inputs": ", ".join(unknown),
        "sample time": f"{SAMPLE_TIME:g} s",
    }
    files = {}
    for name, text in emit_uio_files(DEFAULT_SHIFT, designs, metadata).items():
        files[f"{PYTHON_DIR if name.endswith('.py') else C_DIR}/{name}"] = text
    names = naming.model_file_names(uio_set_name(DEFAULT_SHIFT))
    rows = [
        f"| `{uio_set_name(DEFAULT_SHIFT)}` | `{phase_identifier(x.phase)}` ({x.phase}) | "
        f"{', '.join(x.unknown)} | {len(x.states)} / {len(x.outputs)} / {len(x.known)} | "
        f"{x.spectral_radius:.3g} | {C_DIR}/{names['header']}, {C_DIR}/{names['source']} | "
        f"{PYTHON_DIR}/{names['casadi']} |"
        for x in designs
    ]
    return files, rows, tuple(designs)


def generate_tree(
    d: GearboxDescription,
    progress: Callable[[str], None] | None = None,
    shifts: str = "adjacent",
    hybrid_shifts: str | None = None,
    uio_unknown: Sequence[str] = (naming.RESISTANCE_INPUT,),
    controllers: str | None = None,
) -> GeneratedTree:
    """Every file of the output directory for ``d``, by relative path (``/`` separated);
    ``shifts`` selects the shift models (:func:`selected_shifts`), ``controllers`` the shift
    controllers (:func:`controller_shifts`)."""
    say = progress or (lambda message: None)
    models = gearbox_models(d, say, shifts=shifts, controllers=controllers)
    skipped = list(skipped_models(d, shifts, controllers))
    if hybrid_shifts is None and not hybrid_shift_names(d):
        specs = {spec.name: spec for spec in selected_shifts(d, "all")}
        if DEFAULT_SHIFT in specs and specs[DEFAULT_SHIFT].single:
            why = dog_hybrid_obstacle(d, specs[DEFAULT_SHIFT]) or missing_friction(
                d, specs[DEFAULT_SHIFT].swapping
            )
            skipped.append(f"`hybrid_{DEFAULT_SHIFT.replace('-', '_')}_sens`: {why}")
    if hybrid_shifts not in (None, "none"):
        for spec in selected_shifts(d, hybrid_shifts, "--hybrid-shifts"):
            why = dog_hybrid_obstacle(d, spec) if spec.single else ""
            if why:
                skipped.append(f"`hybrid_{spec.from_gear}_{spec.to_gear}_sens`: {why}")
    files: dict[str, str] = {}
    for m in models:
        say(f"emitting {m.model.name}")
        for name, text in emit_all(m.model, m.config).items():
            folder = PYTHON_DIR if name.endswith(".py") else C_DIR
            files[f"{folder}/{name}"] = text
    linear_sets = linear_system_sets(d, say, shifts)
    for emitted in linear_sets:
        say(f"emitting {emitted.set.name}")
        for name, text in emit_linear_files(emitted.set, emitted.config).items():
            folder = PYTHON_DIR if name.endswith(".py") else C_DIR
            files[f"{folder}/{name}"] = text
    hybrid_sets = hybrid_sensitivity_sets(d, say, hybrid_shifts)
    for emitted_hybrid in hybrid_sets:
        say(f"emitting {emitted_hybrid.name}")
        for name, text in emit_hybrid_files(
            emitted_hybrid.sensitivity, emitted_hybrid.config
        ).items():
            folder = PYTHON_DIR if name.endswith(".py") else C_DIR
            files[f"{folder}/{name}"] = text
    uio, uio_rows, uio_designs = uio_files(d, say, shifts, uio_unknown)
    files.update(uio)
    control_rows: list[str] = []
    for spec in controller_shifts(d, shifts, controllers):
        why = _estimator_obstacle(d, spec)
        control, rows, control_skipped = control_files(d, spec, why, C_DIR, PYTHON_DIR, say)
        files.update(control)
        control_rows.extend(rows)
        skipped.extend(control_skipped)
    say("emitting the mu map and the example")
    mu_map = load_mu_map(d)
    files.update(mu_map_files(mu_map))
    example = example_view(d, models)
    files[f"{C_DIR}/main.c"] = render("c_example_main.c.j2", example)
    files["README.md"] = readme(
        d,
        models,
        example,
        mu_map,
        linear_sets,
        hybrid_sets=hybrid_sets,
        uio_rows=uio_rows,
        skipped=tuple(skipped),
        control_rows=control_rows,
    )
    files[MANIFEST] = manifest_text({k: v.encode("utf-8") for k, v in files.items()}, "generate")
    return GeneratedTree(
        files,
        tuple(models),
        mu_map,
        example.c_files,
        tuple(linear_sets),
        tuple(hybrid_sets),
        uio_designs=uio_designs,
        uio_shift=DEFAULT_SHIFT if uio_designs else None,
        skipped=tuple(skipped),
    )
