"""Extended Kalman filter (thesis 4.1, 4.3) on the parameter-augmented shift model.

**Augmented model (4.1).** The shift model in μ form (2.55–2.58, 2.69; :func:`shift_model`
with ``friction_inputs``), x = [ω1, ω2, φ, ω_C] for 2-3, gets the chosen parameters
p = [m_veh, μ_off, μ_on, ζ] (default, as the thesis) appended as states driven by white noise,
ṗ = w_p, E[w_p w_pᵀ] = diag(q_p) (random walks of stated intensity, :data:`RANDOM_WALK`), so
z = [x; p] and ż = [f(x, u, p); 0]. The states get model-error intensities
(:data:`MODEL_ERROR`) too: the filter's model is rigid, the truth has bristle compliance.

**Element modes.** (3.14)/(3.15) hold only while an element slides. Each swapping element is,
per sample, *sliding* (torque k_sign 2 N r μ F_N, 3.14), *sticking* (torque is the constraint
force that keeps its slip rate at zero) or *open* (torque 0). The mode comes in as two
inputs per element, ``slide_<E>`` (0, or ±1: sliding in the power-on slip direction (2.70) or
against it) and ``stick_<E>`` (0/1), so that one expression serves every phase
(the TCU or a hybrid model decides the mode; at most one element sticks at a time in a
single-swap shift, else the gearbox would be tied up). The sticking torque follows from the
slip rate σ̇_e = a_e0 + a_ee T_e + a_eo T_o, affine in both element torques (2.39):
T_e = −(a_e0 + a_eo T_o)/a_ee, with T_o the other element's sliding torque.

**Discretisation.** Classical RK4 with the inputs held over the step (the TCU applies the value
it has), h = 1, 5 or 10 ms. The step's Jacobian F = ∂z_{k+1}/∂z_k is the *exact* derivative of
that discrete map, computed by the chain rule through the four stages from the symbolic
∂f/∂z (SymPy, exact; forward mode, K_i = J(z_i)(I + c_i h K_{i−1})), not the Jacobian of the
continuous model times h. Symbolic ∂f/∂z rather than SymPy differentiation of the nested RK4
expression: the nested step is four compositions of f, whose symbolic derivative swells
without bound, while f and ∂f/∂z are the small expressions the code generator already
emits (rhs, jac_x) and the chain rule is a few fixed loops in C. The tests compare this F
with CasADi's algorithmic differentiation of the same step and with central differences.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import (
    drivetrain_parts,
    element_short_name,
    power_on_slip_signs,
    shift_model,
)
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import (
    AUGMENTED_STATES,
    DAMPING,
    INERTIA_FACTOR,
    INPUT_TORQUE_GAIN,
    MODEL_ERROR_AUGMENTED,
    MODEL_ERROR_MAP_SCALE,
    STIFFNESS,
    VALVE_GAIN,
    VALVE_OFFSET,
)
from gearsym.symbolic.input_gain import with_input_torque_gain
from gearsym.symbolic.kinematics import exact
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.parameters import RECORDS
from gearsym.symbolic.shifts import shift_spec
from gearsym.symbolic.sympy_utils import smart_jacobian

if TYPE_CHECKING:  # NumPy and CasADi load with the numeric classes only
    import numpy as np

__all__ = [
    "MODEL_ERROR",
    "RANDOM_WALK",
    "SAMPLE_TIMES",
    "AugmentedModel",
    "DiscreteModel",
    "augmented_model",
    "default_parameters",
    "ekf_model_name",
]

#: The sample times the TCU runs the filter at (s).
SAMPLE_TIMES: tuple[float, ...] = (0.001, 0.005, 0.01)

#: Random-walk intensities q_p (unit²/s) of the augmented parameters (assumed; the thesis
#: states the random walk (4.1) but no numbers): the records' defaults
#: (:mod:`gearsym.symbolic.parameters`, where each value's reason is stated).
RANDOM_WALK: dict[str, float] = {r.key: r.random_walk for r in RECORDS if r.random_walk is not None}

#: Model-error intensities q_x (unit²/s) of the states: the filter's rigid model misses the
#: bristle compliance of the elements (2.66) and the ZOH of inputs that ramp. Tuned on the
#: default 2-3 shift at 10 ms (the thesis' sample time), filter's own modes, with the first
#: measurement used once (filter_run), on tuning seeds 100-199 (disjoint from the evaluation
#: seeds 0-49 of tests/test_ekf_montecarlo.py): one common factor c on the previous values
#: (12, 0.3, 3e-6, 0.03), grid c = 1, 0.7, 0.5, 0.35, 0.25, 0.15; criterion NEES/dof and
#: NIS/dof (each summed over seeds and samples, divided by its summed dof) both near 1, the
#: smallest (ln NEES/dof)² + (ln NIS/dof)². c = 0.5: NEES/dof 0.99, NIS/dof 0.998 (c = 1:
#: 0.79, 0.98; c = 0.25: 1.24, 1.01). A first grid on seeds 100-119 alone chose c = 0.06
#: (1.00, 1.02), which gave NEES mean 9.7 on the evaluation seeds: twenty runs miss the heavy
#: tail of the NEES (a few runs whose m_veh converges overconfidently), hence the hundred.
#: Per-state factors (ω1 × 2 or × 0.5, φ × 0.5 at c = 0.05) moved the criterion by less than
#: the seed scatter. Evaluated on seeds 0-49 (run_ekf_monte_carlo): NEES mean 5.42 (band
#: 5.36-7.33), NIS mean 2.965 for 3 dof (band 2.945-3.056).
MODEL_ERROR: dict[str, float] = {
    "omega_1": 6.0,
    "omega_2": 0.15,
    naming.TWIST: 1.5e-6,
    naming.WHEEL_SPEED: 0.015,
}


def ekf_model_name(shift: str) -> str:
    """``ekf_2_3`` for the shift ``2-3`` (files gearsym_ekf_2_3.{c,h})."""
    return "ekf_" + shift.replace("-", "_")


def default_parameters(d: GearboxDescription, shift: str) -> tuple[str, ...]:
    """The thesis' augmented parameters (4.1): m_veh, μ of the off-going and of the on-coming
    element (μ38, μ05 for 2-3 of the built-in gearbox), ζ."""
    spec = shift_spec(d, shift)
    mu = [
        naming.friction_coefficient(element_short_name(d, e))
        for e in (spec.off_going, spec.on_coming)
    ]
    return ("m_veh", *mu, "zeta")


def slide_input(element: str) -> str:
    """Name of the 0/1 input that says ``element`` slides."""
    return f"slide_{element}"


def stick_input(element: str) -> str:
    """Name of the 0/1 input that says ``element`` sticks."""
    return f"stick_{element}"


def valve_input(element: str) -> str:
    """Name of the 0/1 input that says ``element``'s pressure is commanded (> 0): the valve's
    offset acts on its piston then (a filter with the ``valve_offset`` state)."""
    return f"valve_{element}"


@dataclass(frozen=True)
class AugmentedModel:
    """ż = [f(x, u, p); 0] of (4.1) as a :class:`Model` (states z = [x; p]), and what the filter
    needs beside it: which states are random walks with which intensity, and which μ state
    belongs to which element (its estimate is frozen while the element does not slide)."""

    model: Model
    shift: str
    n_x: int  # physical states first, then the augmented parameters
    parameters: tuple[str, ...]
    elements: tuple[str, ...]  # off-going, on-coming
    mu_state: dict[str, str]  # element -> its μ state, if augmented
    intensities: dict[str, float]  # per state of z (unit²/s)
    jacobian: sp.Matrix = field(repr=False)  # ∂f/∂z, exact (SymPy)
    #: per element: its slip Δω_e = ω_a − ω_b (2.59) in the states, linear in the measured
    #: speeds; the constraint torque its sticking needs (the other element as its flags say);
    #: its capacity 2 N r_m μ F_N (2.60, 2.69) with μ the state where augmented; and the slip
    #: sign (2.70) of the power-on direction that a slide flag of +1 means (−1: the other way)
    slip: dict[str, sp.Expr] = field(default_factory=dict, repr=False)
    sticking_torque: dict[str, sp.Expr] = field(default_factory=dict, repr=False)
    capacity: dict[str, sp.Expr] = field(default_factory=dict, repr=False)
    slip_sign: dict[str, int] = field(default_factory=dict)
    #: the factor on the physical states' intensities over an interval in which no element
    #: slides (``in_gear`` of the description's model-error table; 1: the same as in a shift)
    in_gear_factor: float = 1.0
    #: the time (s) after the filter's last mode switch from which :attr:`in_gear_factor`
    #: acts (``in_gear_settle``; 0: at once)
    in_gear_settle: float = 0.0

    @property
    def state_names(self) -> list[str]:
        return [v.name for v in self.model.states]

    @property
    def input_names(self) -> list[str]:
        return [v.name for v in self.model.inputs]

    @property
    def output_names(self) -> list[str]:
        return [v.name for v in self.model.outputs]

    def parameter_values(self, overrides: Mapping[str, float] | None = None) -> list[float]:
        """The fixed parameters (struct p of the emitted code) at their defaults."""
        values = []
        for v in self.model.parameters:
            value = (overrides or {}).get(v.name, v.default)
            if value is None:
                raise GearsymError(self.model.name, v.name, "no value for a fixed parameter")
            values.append(float(value))
        return values

    def frozen_states(self, u: Sequence[float]) -> list[int]:
        """Indices of the μ states whose element does not slide under the inputs ``u`` (a
        slide flag of +1 or −1, either direction, slides)."""
        names = self.input_names
        index = {name: i for i, name in enumerate(self.state_names)}
        return [
            index[mu]
            for e, mu in self.mu_state.items()
            if not abs(u[names.index(slide_input(e))]) > 0.5
        ]

    def process_rates(
        self, q: Sequence[float], u: Sequence[float], since_switch: float = math.inf
    ) -> np.ndarray:
        """The intensities of one prediction interval under the inputs ``u``: ``q`` with the μ
        states of elements that do not slide at 0 (:meth:`frozen_states`) and, where no element
        slides at all and the last mode switch lies ``since_switch`` ≥ :attr:`in_gear_settle`
        seconds back, the physical states' (the model error) times :attr:`in_gear_factor`."""
        import numpy as np

        rates = np.array(q, dtype=float)
        rates[self.frozen_states(u)] = 0.0
        names = self.input_names
        sliding = any(abs(u[names.index(slide_input(e))]) > 0.5 for e in self.elements)
        if not sliding and since_switch >= self.in_gear_settle:
            rates[: self.n_x] *= self.in_gear_factor
        return rates


def _valve_offset(
    d: GearboxDescription, elements: tuple[str, ...]
) -> tuple[Variable, dict[str, Variable]]:
    """The valve's pressure offset (Pa, nominal 0) as the filter's state, and per element the
    0/1 input that says its pressure is commanded (the offset acts only then: a valve told
    nothing gives nothing). One offset for every element: the valves of one TCU share a
    supply and a calibration. A one-line error for an element without a piston area."""
    no_piston = [e for e in elements if d.element(e).a_piston is None]
    if no_piston:
        raise GearsymError(
            d.file,
            "params",
            f"{VALVE_OFFSET}: {no_piston[0]} has no a_piston, so no pressure the offset acts on",
        )
    offset = Variable(
        VALVE_OFFSET,
        sp.Symbol(VALVE_OFFSET, real=True),
        "Pa",
        "the valves' pressure over the commanded one while commanded",
        0.0,
        "assumed: the nominal valve",
    )
    valves = {
        e: Variable(
            valve_input(e),
            sp.Symbol(valve_input(e), real=True),
            "1",
            f"1 while {e}'s pressure is commanded",
        )
        for e in elements
    }
    return offset, valves


def _valve_gain() -> Variable:
    """g of p = g p_cmd (+ offset): the valves' gain, dimensionless, nominal 1."""
    return Variable(
        VALVE_GAIN,
        sp.Symbol(VALVE_GAIN, positive=True),
        "1",
        "the valves' pressure over the commanded one (a gain)",
        1.0,
        "assumed: the nominal valve",
    )


def inertia_factor() -> Variable:
    """f of J_true = f J_design for every gearbox inertia: dimensionless, nominal 1."""
    return Variable(
        INERTIA_FACTOR,
        sp.Symbol(INERTIA_FACTOR, positive=True),
        "1",
        "the gearbox's true inertias over their design values",
        1.0,
        "assumed: the design values are right on average",
    )


def augmented_model(
    d: GearboxDescription,
    shift: str = "2-3",
    parameters: Sequence[str] | None = None,
    intensities: Mapping[str, float] | None = None,
) -> AugmentedModel:
    """The parameter-augmented shift model (4.1) with element modes as inputs (module text).

    ``parameters`` are appended as random-walk states (default :func:`default_parameters`);
    ``intensities`` override :data:`RANDOM_WALK` / :data:`MODEL_ERROR` by state name (a μ state
    takes the ``"mu"`` entry unless named itself)."""
    spec = shift_spec(d, shift)
    one_way = [e for e in spec.swapping if d.element(e).one_way]
    if one_way:
        raise GearsymError(
            d.file,
            "shift",
            f"{shift}: {one_way[0]} is a one-way clutch; the estimators (4.1-4.5) decide each "
            "swapping element's mode from its normal force and estimate its mu, which a "
            "freewheel has not (its shifts run through the hybrid model: gearsym fim, "
            "gearsym observability --per-mode)",
        )
    dogs = [e for e in spec.swapping if d.element(e).dog]
    if dogs:
        raise GearsymError(
            d.file,
            "shift",
            f"{shift}: {dogs[0]} is a dog element; the estimators (4.1-4.5) decide each "
            "swapping element's mode from its normal force and estimate its mu, which a dog "
            "has not (it is locked or open, commanded: its shifts run through the hybrid model)",
        )
    base = shift_model(d, shift, friction_inputs=True)
    if parameters is None:
        parameters = default_parameters(d, shift)
    names = [v.name for v in base.parameters]
    # states that are no parameter of the model
    factors = (INPUT_TORQUE_GAIN, INERTIA_FACTOR, VALVE_OFFSET, VALVE_GAIN)
    unknown = [p for p in parameters if p not in names and p not in factors]
    if unknown or len(set(parameters)) != len(parameters) or not parameters:
        raise GearsymError(
            d.file,
            "params",
            f"{', '.join(unknown) or 'a repeated name'}: choose distinct parameters of the "
            f"{shift} model ({', '.join(names)}) or {', '.join(factors)}",
        )
    elements = (spec.off_going, spec.on_coming)
    parts = drivetrain_parts(d, spec.locked, elements)
    signs = power_on_slip_signs(d, spec)
    by_param = {v.name: v for v in base.parameters}
    sym = {v.name: v.symbol for v in (*base.states, *base.inputs, *base.parameters)}
    if INERTIA_FACTOR in parameters:
        # every gearbox inertia times a factor the filter estimates (a fleet's tolerance on
        # them): the torque model derived with f J in place of each J
        factor = inertia_factor()
        scaled = d.with_inertias(lambda q: replace(q, value=factor.symbol * exact(q.value)))
        torque_model = shift_model(scaled, shift, extra_parameters=(factor,))
        by_param[INERTIA_FACTOR] = factor
    else:
        torque_model = shift_model(d, shift)
    if INPUT_TORQUE_GAIN in parameters:
        # the input torque the TCU is told, times a gain the filter estimates: the true T_In
        # over the told one (the engine's torque model, the e-machine's command)
        torque_model = with_input_torque_gain(torque_model)
        by_param[INPUT_TORQUE_GAIN] = torque_model.variable(INPUT_TORQUE_GAIN)
    torque_rhs = torque_model.rhs

    # The element torques in terms of the modes: slide -> k_sign 2 N r μ F_N (2.69, 3.14),
    # stick -> the constraint torque that holds its slip rate at zero, open -> 0.
    offset, valves = _valve_offset(d, elements) if VALVE_OFFSET in parameters else (None, {})
    if offset is not None:
        by_param[VALVE_OFFSET] = offset
    if VALVE_GAIN in parameters:
        by_param[VALVE_GAIN] = _valve_gain()
    friction = {}
    for e in elements:
        element = d.element(e)
        assert element.n_disc is not None and element.r_m is not None
        short = element_short_name(d, e)
        gain = signs[e] * 2 * element.n_disc * sp.nsimplify(element.r_m.value)
        force = sym[naming.normal_force(short)]
        if VALVE_GAIN in parameters:  # the valve's gain on the commanded pressure
            force = by_param[VALVE_GAIN].symbol * force
        if offset is not None:  # the TCU is told A p_cmd; the piston sees A (p_cmd + offset)
            assert element.a_piston is not None
            area = sp.nsimplify(element.a_piston.value)
            force = force + area * offset.symbol * valves[e].symbol
        friction[e] = gain * sym[naming.friction_coefficient(short)] * force
    torque_symbols = {e: torque_model.variable(naming.torque(e)).symbol for e in elements}
    gearbox = torque_rhs[: len(parts.speeds), :]  # ω̇ of the kept shafts (2.39)
    slip = {}
    for e in elements:
        element = d.element(e)
        speed_a = parts.body_speeds[element.a] if element.a is not None else 0
        slip[e] = sp.expand(speed_a - parts.body_speeds[element.b])
    slip_rate = {
        e: sp.expand(
            sum(
                (slip[e].coeff(s) * gearbox[i] for i, s in enumerate(parts.speeds)),
                sp.Integer(0),
            )
        )
        for e in elements
    }
    flags = {
        e: (
            Variable(
                slide_input(e),
                sp.Symbol(slide_input(e), real=True),
                "1",
                f"+1/-1 while {e} slides with/against its power-on slip sign",
            ),
            Variable(
                stick_input(e), sp.Symbol(stick_input(e), real=True), "1", f"1 while {e} sticks"
            ),
        )
        for e in elements
    }
    zero = {torque_symbols[e]: 0 for e in elements}
    torque = {}
    sticking_torque = {}
    for e, o in (elements, elements[::-1]):
        rate = slip_rate[e]
        a_ee = rate.coeff(torque_symbols[e])
        a_eo = rate.coeff(torque_symbols[o])
        a_e0 = rate.xreplace(zero)
        sliding_other = flags[o][0].symbol * friction[o]
        sticking = -(a_e0 + a_eo * sliding_other) / a_ee
        sticking_torque[e] = sticking
        torque[e] = flags[e][0].symbol * friction[e] + flags[e][1].symbol * sticking
    rhs_x = torque_rhs.xreplace({torque_symbols[e]: torque[e] for e in elements})

    # the torque model's states and fixed parameters are those of the μ model (same derivation)
    augmented = [by_param[p] for p in parameters]
    fixed = tuple(v for v in base.parameters if v.name not in parameters)
    states = (
        *base.states,
        *(
            Variable(
                v.name, v.symbol, v.unit, f"{v.description} (random walk, 4.1)", v.default, v.source
            )
            for v in augmented
        ),
    )
    inputs = (*base.inputs, *(f for e in elements for f in flags[e]), *valves.values())
    rhs = sp.Matrix([*rhs_x, *([sp.Integer(0)] * len(augmented))])
    model = Model(
        name=ekf_model_name(spec.name),
        states=states,
        inputs=inputs,
        parameters=fixed,
        outputs=base.outputs,
        rhs=rhs,
        output_expressions=base.output_expressions,
        metadata={
            **base.metadata,
            "equations": "2.55-2.58, 2.69, 3.14, 4.1",
            "augmented": " ".join(parameters),
            "modes": "slide_<E>/stick_<E> inputs: sliding friction, constraint torque or open",
        },
    )
    # the description's [estimator] tuning where the state exists, a caller's over it
    stated = {
        name: value
        for name, value in d.estimator.intensities().items()
        if name == "mu" or name in {v.name for v in states}
    }
    if STIFFNESS in parameters:  # its random walk: the stiffness factor's times k_ss²
        k_ss = next(v.default for v in base.parameters if v.name == STIFFNESS)
        stated.setdefault(STIFFNESS, d.estimator.stiffness_factor_random_walk() * k_ss**2)
    if DAMPING in parameters:  # the same for the damping: the damping factor's times d_ss²
        d_ss = next(v.default for v in base.parameters if v.name == DAMPING)
        stated.setdefault(DAMPING, d.estimator.damping_factor_random_walk() * d_ss**2)
    if INPUT_TORQUE_GAIN in parameters:
        stated.setdefault(INPUT_TORQUE_GAIN, d.estimator.input_torque_gain_random_walk())
    if INERTIA_FACTOR in parameters:
        stated.setdefault(INERTIA_FACTOR, d.estimator.inertia_factor_random_walk())
    if VALVE_OFFSET in parameters:
        stated.setdefault(VALVE_OFFSET, d.estimator.valve_offset_random_walk())
    if VALVE_GAIN in parameters:
        stated.setdefault(VALVE_GAIN, d.estimator.valve_gain_random_walk())
    tables = ["model_error"]  # where the intensities come from, each over the one before
    if any(name in parameters for name in AUGMENTED_STATES):
        # the states take the intensities tuned for a filter that estimates more, where stated
        stated.update(d.estimator.intensities_augmented())
        tables.append(MODEL_ERROR_AUGMENTED)
        if d.estimator.mu_model == "map_scale":  # ... and with its μ states map scales
            stated.update(d.estimator.intensities_map_scale())
            tables.append(MODEL_ERROR_MAP_SCALE)
    stated.update(intensities or {})
    rates: dict[str, float] = {}
    for v in states:
        if v.name in stated:
            rates[v.name] = float(stated[v.name])
        elif v.name.startswith("mu_"):
            rates[v.name] = float(stated.get("mu", RANDOM_WALK["mu"]))
        elif v.name in RANDOM_WALK:
            rates[v.name] = RANDOM_WALK[v.name]
        elif v.name in MODEL_ERROR:
            rates[v.name] = MODEL_ERROR[v.name]
        else:
            rates[v.name] = 0.0
    for name, value in (intensities or {}).items():
        if name != "mu" and name not in rates:
            raise GearsymError(d.file, "intensities", f"{name!r} is not a state of {model.name}")
        if not (math.isfinite(value) and value >= 0):
            raise GearsymError(d.file, "intensities", f"{name}: must be finite and >= 0")
    mu_state = {
        e: naming.friction_coefficient(element_short_name(d, e))
        for e in elements
        if naming.friction_coefficient(element_short_name(d, e)) in parameters
    }
    return AugmentedModel(
        model=model,
        shift=spec.name,
        n_x=len(base.states),
        parameters=tuple(parameters),
        elements=elements,
        mu_state=mu_state,
        intensities=rates,
        jacobian=smart_jacobian(rhs, model.state_symbols),
        slip=slip,
        sticking_torque=sticking_torque,
        capacity={e: sp.expand(signs[e] * friction[e]) for e in elements},
        slip_sign={e: int(signs[e]) for e in elements},
        in_gear_factor=d.estimator.in_gear_factor(tables, spec.name),
        in_gear_settle=d.estimator.in_gear_settle(tables, spec.name),
    )


class DiscreteModel:
    """The RK4 step z_{k+1} = Φ_h(z_k, u_k) and its exact Jacobian F (module text) as CasADi
    functions of (z, u, h, p), p the fixed parameters."""

    def __init__(self, aug: AugmentedModel) -> None:
        import casadi as ca
        from gearsym.symbolic.numeric import casadi_function

        model = aug.model
        groups = [
            ("z", model.state_symbols),
            ("u", model.input_symbols),
            ("p", model.parameter_symbols),
        ]
        self.aug = aug
        self.f = casadi_function("f", groups, [("zdot", model.rhs)])
        self.J = casadi_function("J", groups, [("dfdz", aug.jacobian)])
        self.h_fn = casadi_function("h", groups, [("y", model.output_expressions)])
        self.H_fn = casadi_function(
            "H", groups, [("dhdz", smart_jacobian(model.output_expressions, model.state_symbols))]
        )
        n = len(model.states)
        z = ca.SX.sym("z", n)
        u = ca.SX.sym("u", len(model.inputs))
        p = ca.SX.sym("p", len(model.parameters))
        h = ca.SX.sym("h")
        eye = ca.SX.eye(n)
        k1, j1 = self.f(z, u, p), self.J(z, u, p)
        z2 = z + 0.5 * h * k1
        k2, d2 = self.f(z2, u, p), self.J(z2, u, p) @ (eye + 0.5 * h * j1)
        z3 = z + 0.5 * h * k2
        k3, d3 = self.f(z3, u, p), self.J(z3, u, p) @ (eye + 0.5 * h * d2)
        z4 = z + h * k3
        k4, d4 = self.f(z4, u, p), self.J(z4, u, p) @ (eye + h * d3)
        z_next = z + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
        jac = eye + (h / 6.0) * (j1 + 2.0 * (d2 + d3) + d4)
        self.step_fn = ca.Function("rk4_step", [z, u, h, p], [z_next, jac])
        #: CasADi's AD of the same step: the independent check of the chain rule (tests).
        self.step_ad = ca.Function("rk4_step_ad", [z, u, h, p], [z_next, ca.jacobian(z_next, z)])
        #: ∂z_{k+1}/∂u of the same step by CasADi's AD: for a state that acts through an input
        #: (the valve's pressure offset in the normal forces, drive EKF)
        self.step_du_fn = ca.Function("rk4_step_du", [z, u, h, p], [ca.jacobian(z_next, u)])
        #: ∂z_{k+1}/∂p likewise: for a state that scales a fixed parameter (the side shafts'
        #: stiffness over a drive)
        self.step_dp_fn = ca.Function("rk4_step_dp", [z, u, h, p], [ca.jacobian(z_next, p)])

    def step(
        self, z: Sequence[float], u: Sequence[float], h: float, p: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """(z_{k+1}, F) of one RK4 step of size h with u held."""
        import numpy as np

        z_next, jac = self.step_fn(z, u, h, p)
        return np.asarray(z_next, dtype=float).ravel(), np.asarray(jac, dtype=float)

    def step_du(
        self, z: Sequence[float], u: Sequence[float], h: float, p: Sequence[float]
    ) -> np.ndarray:
        """∂z_{k+1}/∂u of one RK4 step of size h with u held."""
        import numpy as np

        return np.asarray(self.step_du_fn(z, u, h, p), dtype=float)

    def step_dp(
        self, z: Sequence[float], u: Sequence[float], h: float, p: Sequence[float]
    ) -> np.ndarray:
        """∂z_{k+1}/∂p of one RK4 step of size h with u held."""
        import numpy as np

        return np.asarray(self.step_dp_fn(z, u, h, p), dtype=float)

    def outputs(
        self, z: Sequence[float], u: Sequence[float], p: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """(y, ∂y/∂z) at z."""
        import numpy as np

        y = np.asarray(self.h_fn(z, u, p), dtype=float).ravel()
        return y, np.asarray(self.H_fn(z, u, p), dtype=float)

    def rhs(self, z: Sequence[float], u: Sequence[float], p: Sequence[float]) -> np.ndarray:
        """ż = f(z, u, p)."""
        import numpy as np

        return np.asarray(self.f(z, u, p), dtype=float).ravel()


# ---------------------------------------------------------------------------------------------
# The filter (4.3): reference implementation, the emitted C follows it operation by operation
# ---------------------------------------------------------------------------------------------


def measurement_variance(y: float, relative: float, floor: float) -> float:
    """R_i = r_i² max(|y_i|, y_i^min)² (3.26), taken at the measured value (the TCU does not
    know the true one; the difference is r_i times smaller than σ itself)."""
    return (relative * max(abs(y), floor)) ** 2


def ekf_predict(
    discrete: DiscreteModel,
    z: np.ndarray,
    P: np.ndarray,
    u: Sequence[float],
    h: float,
    p: Sequence[float],
    q: Sequence[float],
    since_switch: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Time update: z⁻ = Φ_h(z, u), P⁻ = F P Fᵀ + h diag(q) with F the exact step Jacobian.

    A μ state whose element does not slide gets q = 0, and its row of F is the unit row (its
    right-hand side is 0 and its column does not act): estimate and variance stay bit for bit;
    where no element slides the model error is the in-gear one (:meth:`AugmentedModel.
    process_rates`).
    Returns (z⁻, P⁻), P⁻ symmetrised ((P + Pᵀ)/2, against rounding drift).
    """
    import numpy as np

    z_next, F = discrete.step(z, u, h, p)
    rates = discrete.aug.process_rates(q, u, since_switch)
    P_next = F @ P @ F.T + np.diag(h * rates)
    return z_next, 0.5 * (P_next + P_next.T)


def ekf_update(
    discrete: DiscreteModel,
    z: np.ndarray,
    P: np.ndarray,
    u: Sequence[float],
    y: Sequence[float],
    p: Sequence[float],
    relative: Sequence[float],
    floor: Sequence[float],
    consider: Sequence[int] = (),
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Measurement update, one output at a time (R is diagonal, (3.26)), Joseph form.

    For each output i with a finite measurement: ν = y_i − h_i(z), v = P h_iᵀ,
    s = h_i v + R_i, k = v / s with the entries of frozen μ states set to 0 (a Schmidt
    "consider" state: it still correlates, but is not corrected), z += k ν and
    P = (I − k h_i) P (I − k h_i)ᵀ + R_i k kᵀ. The Joseph form is the covariance of *any* gain,
    so the zeroed entries keep P exact; a frozen state's row of I − k h_i is a unit row, so its
    variance is unchanged to the bit. ``consider``: further state indices held the same way in
    this update (a μ whose element's mode is in doubt,
    :func:`~gearsym.symbolic.estimators.ekf_modes.ambiguous_mu`). A NaN (or infinite)
    measurement is skipped.
    Returns (z, P, NIS = Σ ν²/s over the used outputs, number of outputs used); sequential
    innovations of a diagonal R are independent, so this NIS is the batch one.
    """
    import numpy as np

    z = np.array(z, dtype=float)
    P = np.array(P, dtype=float)
    frozen = sorted({*discrete.aug.frozen_states(u), *consider})
    nis, used = 0.0, 0
    n = len(z)
    for i, measured in enumerate(y):
        if not np.isfinite(measured):
            continue
        y_hat, H = discrete.outputs(z, u, p)
        row = H[i]
        R = measurement_variance(float(measured), relative[i], floor[i])
        v = P @ row
        s = float(row @ v) + R
        k = v / s
        k[frozen] = 0.0
        innovation = float(measured) - y_hat[i]
        z = z + k * innovation
        A = np.eye(n) - np.outer(k, row)
        P = A @ P @ A.T + R * np.outer(k, k)
        P = 0.5 * (P + P.T)
        nis += innovation * innovation / s
        used += 1
    return z, P, nis, used
