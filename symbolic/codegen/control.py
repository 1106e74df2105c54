"""The TCU's shift controller as C: the model parts of a shift's controller (power-on and
coast, upshift or downshift) derived here, its phase logic in
``templates/c_shift_control.{h,c}.j2``, emitted as ``gearsym_control_<a>_<b>.{h,c}``.

The controller is the one of ``validation/studies/control/controller.py`` (``ShiftController``:
fill, torque phase, inertia phase with feed-forward and PI on the on-coming slip, lock-up;
for a shift the input torque drives, a coast upshift or a power-on downshift,
``DownshiftController``'s order: the inertia phase first with the off-going element
sliding), stated for code: every model evaluation it makes becomes a closed-form expression
of the two measured shaft speeds (input, output), the commanded input torque and the
strategy's knowledge, derived from the hybrid shift model
(:func:`gearsym.symbolic.hybrid.hybrid_shift`):

* *state rebuild*: the gear states z of a mode from the two measured speeds by least squares
  through the mode's projection (exact rationals: ``(BᵀB)⁻¹Bᵀ`` of the 2 x n_gear map of z to the
  input and output speeds, 2.29), the wheel speed ω_C = ω_out / i_D;
* *quasi-static twist* φ: d(φ̇)/dt = ω̇_out / i_D − ω̇_C = 0 (2.44), affine in φ, solved in closed
  form;
* in the from-gear: the off-going element's reaction torque and the on-coming slip (2.59);
  in the to-gear: the on-coming element's reaction torque;
* in the mode "off-going open, on-coming sliding" (both slip directions): the on-coming slip
  and its acceleration at F_N = 0 and at F_N = F₁ (the feed-forward's secant; the capacity is
  2 N_disc r_m μ F_N, 2.69/3.14), μ an argument: the C code reads it from ``gearsym_mu_map``
  at the element's pressure and slip, scaled by the strategy's μ over μ_nominal, as the
  Python controller's model does;
* for a shift the input torque drives, in the mode "off-going sliding, on-coming open" (both
  directions): the on-coming slip and its acceleration at the off-going F_N = 0 and F_N = F₁,
  and the off-going slip (where its μ map is read).

The parameters of the expressions are the vehicle's fixed ones (side shafts, wheel inertia,
road load); the strategy's m_veh and ζ are arguments, as μ. The phase constants (fill time,
pressures, phase durations, PI gains, valve lead) are the description's ``[control]`` values,
printed as literals.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.codegen.c.emitter import CFunctionView, MathMacro, _function_views
from gearsym.symbolic.codegen.casadi.emitter import CasadiFunctionView, _function_view
from gearsym.symbolic.codegen.casadi.printer import python_tuple
from gearsym.symbolic.codegen.config import CodegenConfig, as_config
from gearsym.symbolic.codegen.cse import CseForm, cse_function
from gearsym.symbolic.codegen.printing import float_repr
from gearsym.symbolic.codegen.render import render
from gearsym.symbolic.codegen.table import (
    Arg,
    FunctionSpec,
    FunctionTable,
    Output,
    _normalise_bounds,
    parameter_functions,
    real_symbols,
)
from gearsym.symbolic.codegen.views import ModelView, model_view
from gearsym.symbolic.control_calibration import (
    HOLD_AFTER_FILL,
    HOLD_LINE,
    MEAN_OVER,
    MOVING,
    RAMP_FRACTION,
    SECANT_FORCE_MIN,
    TICK,
    TIMEOUT_FACTOR,
    TO_LINE,
)
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name, quantity
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators.ekf import default_parameters
from gearsym.symbolic.hybrid import HybridShift, Mode, hybrid_shift
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.naming import function_prefix, macro_prefix
from gearsym.symbolic.parameters import RECORDS
from gearsym.symbolic.ratios import gear_ratio
from gearsym.symbolic.shifts import ShiftSpec

__all__ = [
    "CONTROL_ARGUMENTS",
    "control_files",
    "ekf_mismatch",
    "extra_speeds",
    "task_measurements",
    "ControlConstant",
    "control_model_name",
    "control_table",
    "emit_control_files",
]


#: The strategy's values the expressions take as arguments (the rest of the parameters are
#: the vehicle's fixed ones, in the params struct).
KNOWLEDGE_PARAMETERS = ("m_veh", naming.GRADE)

#: Arguments of each emitted expression function, by function (entries of its vector ``v``).
CONTROL_ARGUMENTS: dict[str, tuple[str, ...]] = {
    "from_gear": ("omega_in", "omega_out", "T_In", "m_veh", "zeta"),
    "to_gear": ("omega_in", "omega_out", "T_In", "m_veh", "zeta"),
    "sliding_slip": ("omega_in", "omega_out"),
    "sliding_pos": (
        "omega_in",
        "omega_out",
        "T_In",
        "m_veh",
        "zeta",
        "F_last",
        "mu_last",
        "F_1",
        "mu_1",
    ),
}
CONTROL_ARGUMENTS["sliding_neg"] = CONTROL_ARGUMENTS["sliding_pos"]
# the shift the input torque drives (a coast upshift, a power-on downshift): the off-going
# element slides, the on-coming one is open; F and mu are the off-going element's
CONTROL_ARGUMENTS["driven_slip"] = CONTROL_ARGUMENTS["sliding_slip"]
CONTROL_ARGUMENTS["driven_pos"] = CONTROL_ARGUMENTS["sliding_pos"]
CONTROL_ARGUMENTS["driven_neg"] = CONTROL_ARGUMENTS["sliding_pos"]


def control_model_name(shift: str) -> str:
    """``control_2_3`` for ``2-3``: the files ``gearsym_control_2_3.{h,c}``."""
    return "control_" + shift.replace("-", "_")


@dataclass(frozen=True)
class ControlConstant:
    """A number the controller's template prints as a macro: name, value, unit, meaning."""

    name: str
    code: str  # GEARSYM_LIT(...) literal
    unit: str
    meaning: str


def _lit(value: float) -> str:
    return f"GEARSYM_LIT({float_repr(float(value))})"


def _rational(value: float) -> sp.Rational:
    return sp.Rational(repr(float(value)))


def _speed_rows(d: GearboxDescription, hybrid: HybridShift, mode: Mode) -> sp.Matrix:
    """The map of a mode's gear states z to the input and output shaft speeds (2 x n_gear),
    ẏ = P z then the shaft speeds s(ẏ) (2.29)."""
    dyn = gearbox_dynamics(d)
    index = {b: i for i, b in enumerate(d.body_names)}
    z = sp.Matrix(mode.model.state_symbols[: len(mode.keep)])
    y_dot = mode.projection * z
    rows = []
    for shaft in (d.input_shaft, d.output_shaft):
        speed = sp.expand((dyn.kinematics.transform[index[shaft], :] * y_dot)[0])
        rows.append([sp.nsimplify(speed.coeff(s)) for s in z])
    return sp.Matrix(rows)


def _rebuilt(
    d: GearboxDescription,
    hybrid: HybridShift,
    mode: Mode,
    omega: tuple[sp.Symbol, sp.Symbol],
    u: dict[sp.Symbol, sp.Expr],
) -> dict[sp.Symbol, sp.Expr]:
    """The mode's states from the two measured speeds (least squares through the projection),
    ω_C = ω_out / i_D and the twist at its quasi-static value (2.44) for the inputs ``u``."""
    states = list(mode.model.state_symbols)
    names = [v.name for v in mode.model.states]
    basis = _speed_rows(d, hybrid, mode)
    projection = (basis.T * basis).inv() * basis.T
    z = projection * sp.Matrix(omega)
    i_d = _rational(quantity(d, "drivetrain", "i_D").value)
    values: dict[sp.Symbol, sp.Expr] = {s: z[k] for k, s in enumerate(states[: len(mode.keep)])}
    values[states[names.index(naming.WHEEL_SPEED)]] = omega[1] / i_d
    phi = states[names.index(naming.TWIST)]
    rhs = mode.model.rhs.xreplace(u)
    rates = dict(zip(states, rhs, strict=True))
    z_dot = sp.Matrix([rates[s] for s in states[: len(mode.keep)]])
    condition = (basis[1, :] * z_dot)[0] / i_d - rates[states[names.index(naming.WHEEL_SPEED)]]
    condition = condition.xreplace(values)
    slope = sp.diff(condition, phi)
    if phi in slope.free_symbols:
        raise GearsymError(d.file, "control", f"mode {mode.name}: the twist enters non-affinely")
    values[phi] = -condition.xreplace({phi: 0}) / slope
    return values


def _mode(hybrid: HybridShift, status: dict[str, tuple[str, int]]) -> Mode:
    return hybrid.modes[hybrid.mode_of(status).name]


def control_expressions(
    d: GearboxDescription, shift: str
) -> tuple[HybridShift, tuple[Variable, ...], dict[str, tuple[sp.Expr, ...]], dict]:
    """The hybrid shift, the fixed parameters, and per emitted function its outputs as
    expressions of the symbols named by :data:`CONTROL_ARGUMENTS` (module docstring)."""
    hybrid = hybrid_shift(d, shift)
    spec = hybrid.spec
    off, on = spec.off_going, spec.on_coming
    args = {n: sp.Symbol(n, real=True) for f in CONTROL_ARGUMENTS.values() for n in f}
    omega = (args["omega_in"], args["omega_out"])
    by_name = {v.name: v for v in hybrid.parameters}
    mu = {e: by_name[str(s)].symbol for e, s in hybrid.friction_coefficient.items()}
    force = dict(hybrid.normal_force)
    torque_in = hybrid.inputs[0].symbol
    known = {
        torque_in: args["T_In"],
        by_name["m_veh"].symbol: args["m_veh"],
        by_name[naming.GRADE].symbol: args["zeta"],
    }
    fixed = tuple(
        v
        for v in hybrid.parameters
        if v.name not in KNOWLEDGE_PARAMETERS and v.symbol not in mu.values()
    )
    exprs: dict[str, tuple[sp.Expr, ...]] = {}
    # the from-gear (off-going locked, on-coming open) and the to-gear
    source = hybrid.modes[hybrid.from_mode]
    u = {**known, force[off]: 0, force[on]: 0, mu[off]: 0, mu[on]: 0}
    x = _rebuilt(d, hybrid, source, omega, u)
    exprs["from_gear"] = (
        source.reaction[off].xreplace(u).xreplace(x),
        source.slip[on].xreplace(x),
    )
    target = hybrid.modes[hybrid.to_mode]
    x = _rebuilt(d, hybrid, target, omega, u)
    exprs["to_gear"] = (target.reaction[on].xreplace(u).xreplace(x),)

    def secant(
        mode: Mode, pressed: str, other: str
    ) -> tuple[dict[sp.Symbol, sp.Expr], tuple[sp.Expr, ...]]:
        """The state rebuilt in ``mode`` with element ``pressed`` at F_last, mu_last (``other``
        free), and the on-coming slip with its rate at F_N(pressed) = 0 and F_N = F_1, mu_1."""
        last = {**known, force[other]: 0, mu[other]: 0}
        x = _rebuilt(
            d,
            hybrid,
            mode,
            omega,
            {**last, force[pressed]: args["F_last"], mu[pressed]: args["mu_last"]},
        )
        states = list(mode.model.state_symbols)
        rates = []
        for value, mu_value in ((0, 0), (args["F_1"], args["mu_1"])):
            rhs = mode.model.rhs.xreplace({**last, force[pressed]: value, mu[pressed]: mu_value})
            rate = sum(sp.diff(mode.slip[on], s) * rhs[k] for k, s in enumerate(states))
            rates.append(rate.xreplace(x))
        return x, (mode.slip[on].xreplace(x), *rates)

    # off-going open, on-coming sliding: the slip, and its rate at F_N = 0 and F_N = F_1
    for sign, name in ((1, "sliding_pos"), (-1, "sliding_neg")):
        mode = _mode(hybrid, {off: ("open", 0), on: ("sliding", sign)})
        _, exprs[name] = secant(mode, on, off)
        if name == "sliding_pos":
            exprs["sliding_slip"] = exprs[name][:1]
    # off-going sliding, on-coming open: the on-coming slip and its rate at the off-going
    # F_N = 0 and F_N = F_1 (the driven shift's feed-forward, downshift.py)
    for sign, name in ((1, "driven_pos"), (-1, "driven_neg")):
        mode = _mode(hybrid, {off: ("sliding", sign), on: ("open", 0)})
        x, exprs[name] = secant(mode, off, on)
        if name == "driven_pos":
            # the off-going element's own slip: where its μ map is read
            exprs["driven_slip"] = (mode.slip[off].xreplace(x),)
    return hybrid, fixed, exprs, args


def _mu_state(d: GearboxDescription, element: str) -> str:
    """The name of an element's μ state in the EKF (4.1)."""
    return naming.friction_coefficient(element_short_name(d, element))


def is_upshift(d: GearboxDescription, spec: ShiftSpec) -> bool:
    """Whether the to-gear's ratio is the smaller (the input slows down): the input torque
    drives an upshift when it is negative (coast), a downshift when it is positive (power on),
    which picks the controller's phase order at the first tick."""
    ratio = [abs(float(gear_ratio(d, d.gear(g)).ratio)) for g in (spec.from_gear, spec.to_gear)]
    return ratio[1] < ratio[0]


def control_table(
    d: GearboxDescription, shift: str, config: CodegenConfig | None = None
) -> tuple[FunctionTable, HybridShift]:
    """The function table of the controller's model parts: ``params_default``,
    ``params_validate`` and one row per entry of :data:`CONTROL_ARGUMENTS`, ``<name>(p, v,
    out)``."""
    hybrid, fixed, exprs, args = control_expressions(d, shift)
    kind = "upshift" if is_upshift(d, hybrid.spec) else "downshift"
    if config is None:  # the ranges params_validate enforces: the parameter records' (as generate)
        records = {r.key: r.bounds for r in RECORDS if r.bounds is not None and r.section != "mu"}
        config = CodegenConfig(bounds={v.name: records[v.name] for v in fixed if v.name in records})
    config = as_config(config)
    model = Model(
        name=control_model_name(shift),
        states=(),
        inputs=(),
        parameters=fixed,
        outputs=(),
        rhs=sp.zeros(0, 1),
        output_expressions=sp.zeros(0, 1),
        metadata={
            "gearbox": d.name,
            "equations": "2.29, 2.44, 2.59, 2.69, 3.14",
            "content": f"power-on and coast {kind} controller of shift {shift} "
            f"(TCU task, {TICK:g} s)",
        },
    )
    bounds = _normalise_bounds(model, config.bounds)
    real = real_symbols(model)
    ps = tuple(real[v.symbol] for v in model.parameters)
    p_arg = Arg("p", len(ps), True, "params", ps, tuple(v.name for v in model.parameters))
    functions = parameter_functions(model, bounds, p_arg)
    changed = {old: new for old, new in real.items() if old != new}
    docs = {
        "from_gear": "The from-gear at the measured speeds (state rebuilt, twist quasi-static, "
        "2.44): out[0] the off-going element's reaction torque [N*m], out[1] the on-coming "
        "slip [rad/s] (2.59).",
        "to_gear": "The to-gear at the measured speeds (state rebuilt, twist quasi-static, "
        "2.44): out[0] the on-coming element's reaction torque [N*m].",
        "sliding_slip": "The on-coming slip [rad/s] (2.59) at the measured speeds, the "
        "off-going element open.",
        "sliding_pos": "Off-going open, on-coming sliding with positive slip: state rebuilt "
        "from the speeds, twist quasi-static at F_last, mu_last; out[0] the slip [rad/s], "
        "out[1], out[2] its acceleration [rad/s^2] at F_N = 0 and at F_N = F_1 with mu_1 "
        "(capacity 2 N_disc r_m mu F_N, 2.69/3.14).",
        "sliding_neg": "As sliding_pos with negative slip (the friction torque's sign reversed).",
        "driven_slip": "The off-going element's slip [rad/s] (2.59) at the measured speeds, "
        "the on-coming element open (where its mu map is read).",
        "driven_pos": "On-coming open, off-going sliding with positive slip (the shift the "
        "input torque drives: a coast upshift): state rebuilt from the speeds, twist "
        "quasi-static at the off-going F_last, mu_last; out[0] the on-coming slip [rad/s], "
        "out[1], out[2] its acceleration [rad/s^2] at the off-going F_N = 0 and at F_N = F_1 "
        "with mu_1.",
        "driven_neg": "As driven_pos with the off-going element sliding negatively.",
    }
    for name, arguments in CONTROL_ARGUMENTS.items():
        symbols = tuple(args[a] for a in arguments)
        v_arg = Arg("v", len(symbols), True, "vector", symbols)
        outputs = sp.ImmutableMatrix([e.xreplace(changed) for e in exprs[name]])
        doc = f"{docs[name]} v = [{', '.join(arguments)}]."
        functions.append(
            FunctionSpec(
                name, (p_arg, v_arg), (Output("out", (len(exprs[name]), 1)),), (outputs,), doc
            )
        )
    table = FunctionTable(
        model=model,
        config=config,
        prefix=function_prefix(model.name),
        macro_prefix=macro_prefix(model.name),
        states=(),
        inputs=(),
        parameters=ps,
        bounds=bounds,
        functions=tuple(functions),
    )
    return table, hybrid


def _constants(d: GearboxDescription, hybrid: HybridShift) -> tuple[ControlConstant, ...]:
    spec = hybrid.spec
    control = d.control
    out: list[ControlConstant] = []

    def add(name: str, value: float, unit: str, meaning: str) -> None:
        out.append(ControlConstant(name, _lit(value), unit, meaning))

    add("TICK", TICK, "s", "the task's period")
    add("LINE_PRESSURE", d.drive.si("shift", "line_pressure"), "Pa", "line pressure")
    add("FILL_TIME", control.si("actuator", "fill_time"), "s", "calibrated fill time")
    add("FAST_FILL", control.si("actuator", "fast_fill_pressure"), "Pa", "fast-fill pressure")
    add("SPRING", control.si("actuator", "return_spring"), "Pa", "return-spring pressure")
    add("TIME_CONSTANT", control.si("actuator", "time_constant"), "s", "chamber pressure lag")
    dead_ticks, dead_rest = dead_time_ticks(control.si("actuator", "dead_time"))
    add("DEAD_REST", dead_rest, "s", "valve dead time past its whole ticks")
    add("FILL_HOLD", control.si("shift", "fill_hold"), "Pa", "hold above the spring after fill")
    add("HOLD_AFTER_FILL", HOLD_AFTER_FILL, "s", "fill hold before the torque phase")
    add("TORQUE_PHASE", control.si("shift", "torque_phase"), "s", "torque-phase duration")
    add("INERTIA_PHASE", control.si("shift", "inertia_phase"), "s", "inertia-phase target")
    add("K_P", control.si("shift", "slip_k_p"), "Pa*s/rad", "PI gain on the slip error")
    add("T_I", control.si("shift", "slip_t_i"), "s", "PI integral time")
    add("LOCKUP_SLIP", control.si("shift", "lockup_slip"), "rad/s", "lock-up slip")
    add("MARGIN", control.si("shift", "off_going_margin"), "1", "off-going holding margin")
    lead = control.si("actuator", "dead_time") + control.si("actuator", "time_constant")
    add("LEAD", lead, "s", "valve dead time + time constant: trajectories commanded ahead")
    add("TO_LINE", TO_LINE, "s", "ramp to line pressure after lock-up")
    add("HOLD_LINE", HOLD_LINE, "s", "line pressure held before done")
    add("TIMEOUT_FACTOR", TIMEOUT_FACTOR, "1", "inertia phase gives up after this many targets")
    add("RAMP", RAMP_FRACTION, "1", "fraction of the inertia phase ramping the slip rate")
    add("SECANT_FORCE_MIN", SECANT_FORCE_MIN, "N", "least F_1 of the feed-forward's secant")
    add("MOVING", MOVING, "1", "coast: on-coming slip fall that shows the off-going slides")
    add("MU_NOMINAL", quantity(d, "friction", "mu_nominal").value, "1", "mu the map is scaled by")
    add("T_OIL", quantity(d, "friction", "T_oil").value, "degC", "oil temperature the map reads")
    for role, e in (("OFF", spec.off_going), ("ON", spec.on_coming)):
        element = d.element(e)
        if element.a_piston is None or element.n_disc is None or element.r_m is None:
            raise GearsymError(
                d.file, f'shift_element[name="{e}"]', "the controller needs a_piston, n_disc, r_m"
            )
        add(f"AREA_{role}", element.a_piston.value, "m^2", f"piston area of {e}")
        add(
            f"CAPACITY_{role}",
            2 * element.n_disc * element.r_m.value,
            "m",
            f"2 N_disc r_m of {e}: torque per newton per unit mu (2.69)",
        )
    return tuple(out)


def dead_time_ticks(dead_time: float) -> tuple[int, float]:
    """The valve's dead time (s) as whole task ticks and the rest (s, below a tick): a command
    given at a tick reaches the valve that many ticks and the rest later."""
    ticks = int(math.floor(dead_time / TICK + 1e-9))
    rest = dead_time - ticks * TICK
    return ticks, rest if rest > 1e-12 else 0.0


@dataclass(frozen=True)
class CControlView(ModelView):
    """What ``c_shift_control.{h,c}.j2`` print."""

    shift: str
    off: str
    on: str
    off_short: str
    on_short: str
    constants: tuple[ControlConstant, ...]
    functions: tuple[CFunctionView, ...]
    restrict_pointers: bool
    ekf_prefix: str
    ekf_macro: str
    ekf_header: str
    ekf_u: EkfInputs
    ekf_element_off: int  # index of the element in the EKF's modes array
    ekf_element_on: int
    #: the EKF's state of the off-going element's μ (its macro; "" where μ is not a state)
    ekf_mu_off: str
    #: the to-gear's ratio is the smaller: the input torque drives the shift when negative
    upshift: bool
    #: the valve's dead time in whole ticks (:func:`dead_time_ticks`)
    dead_ticks: int
    #: sub-intervals of the tick's mean pressure the task's filter is told (MEAN_OVER)
    mean_over: int
    #: what the task hands the EKF as y, in its output order (C expressions)
    task_y: tuple[str, ...]
    #: the task's input fields of shaft speeds only the EKF measures
    extra_speeds: tuple[str, ...]
    math_macros: tuple[MathMacro, ...]
    m_veh_default: str
    zeta_default: str


@dataclass(frozen=True)
class CasadiControlView(ModelView):
    """What ``casadi_control.py.j2`` prints."""

    functions: tuple[CasadiFunctionView, ...]
    defaults: str
    parameter_names: str
    model_name_repr: str
    sizes: tuple[tuple[str, str, int], ...]  # name, its arguments (source), outputs


@dataclass(frozen=True)
class EkfInputs:
    """The index macros of the EKF's inputs the task sets."""

    torque: str
    force_off: str
    force_on: str
    stick_off: str
    slide_off: str
    stick_on: str
    slide_on: str


def task_measurements(d: GearboxDescription, hybrid: HybridShift) -> tuple[tuple[str, str], ...]:
    """(the EKF's output, what the task hands it) in the EKF's output order: the controller's
    input and output shaft speeds, the wheel speed and, for a shaft speed only the EKF
    measures, a field ``omega_<shaft>`` of the task's inputs. An output that is no speed
    raises ValueError (:func:`ekf_mismatch` says why)."""
    from gearsym.symbolic.estimators.ekf import augmented_model

    aug = augmented_model(d, hybrid.spec.name)
    given = {
        f"y_{naming.speed(d.input_shaft)}": "in->control.omega_in",
        f"y_{naming.speed(d.output_shaft)}": "in->control.omega_out",
        f"y_{naming.WHEEL_SPEED}": "in->omega_wheel",
    }
    shafts = {f"y_{naming.speed(s.name)}": naming.speed(s.name) for s in d.shafts}
    out = []
    for v in aug.model.outputs:
        if v.name in given:
            out.append((v.name, given[v.name]))
        elif v.name in shafts:
            out.append((v.name, f"in->{shafts[v.name]}"))
        else:
            raise ValueError(f"its EKF measures {v.name}, which is no shaft or wheel speed")
    return tuple(out)


def extra_speeds(measurements: tuple[tuple[str, str], ...]) -> tuple[str, ...]:
    """The task's input fields of the shaft speeds only its EKF measures (``omega_<shaft>``)."""
    given = ("in->omega_wheel",)
    return tuple(
        c.removeprefix("in->")
        for _, c in measurements
        if c.startswith("in->omega_") and c not in given
    )


def ekf_mismatch(d: GearboxDescription, hybrid: HybridShift) -> str:
    """Why the shift's EKF (4.3) cannot run in the task, "" when it can: the task hands it the
    speeds it measures (:func:`task_measurements`) and its modes in the hybrid's element
    order."""
    from gearsym.symbolic.estimators.ekf import augmented_model

    aug = augmented_model(d, hybrid.spec.name)
    try:
        task_measurements(d, hybrid)
    except ValueError as err:
        return str(err)
    if tuple(aug.elements) != tuple(hybrid.elements):
        return (
            f"its EKF's elements are {', '.join(aug.elements)}; the task hands it "
            f"{', '.join(hybrid.elements)}"
        )
    return ""


def emit_control_files(
    d: GearboxDescription, shift: str, config: CodegenConfig | None = None
) -> dict[str, str]:
    """``{"gearsym_control_<a>_<b>.h", ".c", "_casadi.py"}``: the controller of a shift
    (power-on and coast, upshift or downshift) and the TCU task that runs it with the shift's EKF
    (``gearsym_ekf_<a>_<b>``), and its model parts as CasADi functions."""
    table, hybrid = control_table(d, shift, config)
    forms: dict[str, CseForm] = {
        spec.name: cse_function(spec, table.config) for spec in table if spec.kind == "expr"
    }
    functions, used_macros, used_helpers = _function_views(table, forms)
    if used_helpers:
        raise ValueError(f"controller {shift} needs helpers {sorted(used_helpers)}")
    if used_macros - {"sin", "cos"}:
        raise ValueError(f"controller {shift} needs math functions {sorted(used_macros)}")
    # the phase logic's own calls, and the actuator model's
    macros = sorted(used_macros | {"cos", "fabs", "exp", "log"})
    spec = hybrid.spec
    mismatch = ekf_mismatch(d, hybrid)
    if mismatch:
        raise ValueError(f"controller {shift}: {mismatch}")
    measurements = task_measurements(d, hybrid)
    base = model_view(table)
    ekf_name = "ekf_" + shift.replace("-", "_")
    states = default_parameters(d, shift)  # the EKF's augmented states (4.1)
    ekf_macro = macro_prefix(ekf_name)
    elements = list(hybrid.elements)
    defaults = {v.name: float(v.default or 0.0) for v in hybrid.parameters}
    view = CControlView(
        **vars(base),
        shift=shift,
        off=spec.off_going,
        on=spec.on_coming,
        off_short=element_short_name(d, spec.off_going),
        on_short=element_short_name(d, spec.on_coming),
        constants=_constants(d, hybrid),
        functions=tuple(functions),
        restrict_pointers=table.config.restrict_pointers,
        ekf_prefix=function_prefix(ekf_name),
        ekf_macro=ekf_macro,
        ekf_header=naming.model_file_names(ekf_name)["header"],
        ekf_u=EkfInputs(
            f"{ekf_macro}U_{hybrid.inputs[0].name}",
            f"{ekf_macro}U_{naming.normal_force(element_short_name(d, spec.off_going))}",
            f"{ekf_macro}U_{naming.normal_force(element_short_name(d, spec.on_coming))}",
            f"{ekf_macro}U_stick_{spec.off_going}",
            f"{ekf_macro}U_slide_{spec.off_going}",
            f"{ekf_macro}U_stick_{spec.on_coming}",
            f"{ekf_macro}U_slide_{spec.on_coming}",
        ),
        ekf_element_off=elements.index(spec.off_going),
        ekf_element_on=elements.index(spec.on_coming),
        ekf_mu_off=(
            f"{ekf_macro}X_{mu_off}" if (mu_off := _mu_state(d, spec.off_going)) in states else ""
        ),
        upshift=is_upshift(d, spec),
        dead_ticks=dead_time_ticks(d.control.si("actuator", "dead_time"))[0],
        mean_over=MEAN_OVER,
        task_y=tuple(c for _, c in measurements),
        extra_speeds=extra_speeds(measurements),
        math_macros=tuple(MathMacro(name.upper(), name, False) for name in macros),
        m_veh_default=_lit(defaults["m_veh"]),
        zeta_default=_lit(defaults[naming.GRADE]),
    )
    casadi_functions = []
    for row in table:
        if row.kind == "expr":
            casadi_view, used = _function_view(table, row, forms[row.name])
            if used:
                raise ValueError(f"controller {shift} needs CasADi helpers {sorted(used)}")
            casadi_functions.append(casadi_view)
    parameters = table.model.parameters
    casadi = CasadiControlView(
        **vars(base),
        functions=tuple(casadi_functions),
        defaults=python_tuple([float_repr(float(v.default or 0.0)) for v in parameters]),
        parameter_names=python_tuple([repr(v.name) for v in parameters]),
        model_name_repr=repr(table.model.name),
        sizes=tuple(
            (
                name,
                python_tuple([repr(a) for a in arguments]),
                table[name].outputs[0].size,
            )
            for name, arguments in CONTROL_ARGUMENTS.items()
        ),
    )
    return {
        base.header_name: render("c_shift_control.h.j2", view),
        base.source_name: render("c_shift_control.c.j2", view),
        base.casadi_name: render("casadi_control.py.j2", casadi),
    }


def control_files(
    d: GearboxDescription,
    spec: ShiftSpec | None,
    obstacle: str,
    c_dir: str,
    python_dir: str,
    progress: Callable[[str], None] | None = None,
) -> tuple[dict[str, str], list[str], list[str]]:
    """What ``generate`` emits of the controller of ``spec`` (the default shift, ``None`` when
    it is not emitted) into ``c_dir``: the files, their README rows, and, when it cannot be
    emitted, why in one line (``obstacle``: why its EKF is not emitted, "" when it is; the
    controller needs the swapping elements' piston areas too)."""
    if spec is None:
        return {}, [], []
    name = control_model_name(spec.name)
    lacking = [e for e in spec.swapping if d.element(e).a_piston is None]
    why = obstacle
    if not why and lacking:
        why = f"{', '.join(lacking)} has no a_piston (F_N = p a_piston)"
    if not why:
        why = ekf_mismatch(d, hybrid_shift(d, spec.name))
    if why:
        return {}, [], [f"`{name}`: {why}"]
    if progress is not None:
        progress(f"deriving the shift controller of {spec.name} (TCU task with its EKF)")
    files = {
        (f"{python_dir}/{k}" if k.endswith(".py") else f"{c_dir}/{k}"): v
        for k, v in emit_control_files(d, spec.name).items()
    }
    names = naming.model_file_names(name)
    row = (
        f"| `{name}` | {'upshift' if is_upshift(d, spec) else 'downshift'} {spec.name}, "
        f"power-on and coast: {spec.off_going} off, "
        f"{spec.on_coming} on; "
        f"task with `ekf_{spec.name.replace('-', '_')}` | {c_dir}/{names['header']}, "
        f"{c_dir}/{names['source']} | {python_dir}/{names['casadi']} (model parts) |"
    )
    return files, [row], []
