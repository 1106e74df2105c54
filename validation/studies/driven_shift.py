"""The driven shift model and the record that drives it (thesis 3.1, 3.14–3.15): the 2↔3 shift
model (2.55)–(2.58) driven open-loop by the signals the reference simulation
(:mod:`gearsym.validation.sim.simulate`) recorded, from the recorded initial state; its
sensitivities along the shift are :mod:`gearsym.validation.studies.sensitivity_run`'s.

How the recorded element torques drive the shift model (the *driven* shift model): each
swapping element's torque is the recorded transmitted torque T_e (sign of 2.36), split in two
inputs so that μ enters exactly where it acts physically (3.14)–(3.15):

* while the element **slides** its torque is sliding friction, k_sign 2 N_disc r_m μ_e F_N,e
  (3.14), with the *effective* normal force F_N,e = T_e / (k_sign 2 N_disc r_m μ_e0) that
  reproduces the recorded torque at the nominal μ_e0: ∂T_e/∂μ_e = T_e/μ_e0, i.e. a 1 % change of
  μ changes the friction torque by 1 %;
* while it **sticks** its torque is a constraint force, an input ``T_<element>`` that does not
  depend on μ (the thesis: (3.15) holds only while Δω ≠ 0).

Sliding is either ``"detected"`` from the record (the element is pressed and transmits at least
``capacity_fraction`` of its capacity 2 N_disc r_m μ F_N, the elasto-plastic model's sliding
condition) or taken from the ``"phases"`` as the thesis assumes in 3.1 (both swapping elements
slide from the start of the torque phase to the end of the speed phase).

The road grade: the reference simulation records ζ(t) (the scenario's ``[grade]`` profile, or
the description's constant ζ0). The driven model keeps ζ as a *parameter* and gets the recorded
deviation Δζ(t) = ζ_rec(t) − ζ0 as a further input ``zeta_dev``: its road load (2.49) sees
ζ + Δζ(t), which is ζ_rec(t) at the nominal ζ = ζ0, and ∂/∂ζ is the sensitivity to a constant
offset of the whole grade profile. That keeps (3.7), Ṡ = ∂f/∂x S + ∂f/∂p, correct: p must be
constant in time for S = ∂x/∂p to be a derivative with respect to a finite set of numbers, and
a constant offset of an otherwise recorded (known) profile is exactly what the FIM (3.25) can
ask about. Making ζ an input instead would drop it from the parameters (inputs are known), so
the FIM could no longer tell how well the grade is estimable; and evaluating ∂f/∂ζ at the
constant ζ0 while the reference drove ζ(t) would linearise at the wrong point. Without a
profile Δζ ≡ 0 and nothing changes. ``--set zeta=…`` shifts the whole profile by the same
offset.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import SLIDING_MODES, SLIDING_PHASES
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name, power_on_slip_signs, shift_model
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.shifts import ShiftSpec, shift_spec
from gearsym.validation.sim.phases import Phase

#: Progress callback: a message for stderr.
Progress = Callable[[str], None]

# ----------------------------------------------------------------------------- reference data


@dataclass(frozen=True)
class ReferenceData:
    """The recorded signals the shift model is driven with (``SimulationResult`` subset)."""

    t: np.ndarray
    signals: dict[str, np.ndarray]
    phases: tuple[Phase, ...]
    shift: str
    source: str

    def window(self, t_start: float, t_end: float) -> ReferenceData:
        """The record restricted to [t_start, t_end] (both ends kept as samples)."""
        inside = (self.t > t_start) & (self.t < t_end)
        t = np.concatenate([[t_start], self.t[inside], [t_end]])
        signals = {k: np.interp(t, self.t, v) for k, v in self.signals.items()}
        phases = tuple(
            Phase(p.name, max(p.t_start, t_start), min(p.t_end, t_end), p.criterion)
            for p in self.phases
            if p.t_end > t_start and p.t_start < t_end
        )
        return ReferenceData(t, signals, phases, self.shift, self.source)


def reference_data(
    d: GearboxDescription,
    scenario: Any = None,
    progress: Progress | None = None,
) -> ReferenceData:
    """Run the reference simulation (:func:`gearsym.validation.sim.simulate.simulate`) and keep its
    record.

    ``scenario`` is a :class:`gearsym.validation.sim.scenario.Scenario` (default: the built-in one).
    """
    from gearsym.validation.sim.simulate import simulate

    kwargs: dict[str, Any] = {}
    if progress is not None:
        kwargs["progress"] = lambda *args: progress(str(args[-1]))
    if "check_models" in inspect.signature(simulate).parameters:
        kwargs["check_models"] = False  # the model checks are not needed here
    return reference_from_result(simulate(d, scenario, **kwargs))


def reference_from_result(result: Any) -> ReferenceData:
    """The record of a :class:`gearsym.validation.sim.simulate.SimulationResult` (t, signals,
    phases)."""
    shift = getattr(getattr(result, "scenario", None), "shift", None)
    return ReferenceData(
        t=np.asarray(result.t, dtype=float),
        signals={k: np.asarray(v, dtype=float) for k, v in result.signals.items()},
        phases=tuple(result.phases),
        shift=shift.name if shift is not None else "2-3",
        source="gearsym.validation.sim.simulate",
    )


# ----------------------------------------------------------------------------- driven model


@dataclass(frozen=True)
class DrivenShift:
    """The shift model with sliding-friction and sticking-torque inputs per swapping element.

    ``gain[e]`` is k_sign 2 N_disc r_m (torque per unit μ and unit normal force, 3.14).
    """

    model: Model
    spec: ShiftSpec
    elements: tuple[str, ...]
    gain: dict[str, float]
    mu: dict[str, str]  # element -> μ parameter name
    normal_force: dict[str, str]  # element -> effective normal-force input name
    stick_torque: dict[str, str]  # element -> sticking-torque input name


def driven_shift_model(
    d: GearboxDescription, shift: str = "2-3", with_wheel_acceleration: bool = False
) -> DrivenShift:
    """ẋ = f(x, p) + B(p) u of the shift model (2.55–2.58, 3.5) with
    u = [T_In, F_N,off, F_N,on, T_off, T_on, Δζ]: element torque = k_sign 2 N r μ F_N + T_stick,
    and the road load (2.49) at the grade ζ + Δζ(t) (see the module docstring: ζ stays a
    parameter, a constant offset of the recorded profile)."""
    spec = shift_spec(d, shift)
    friction = shift_model(d, shift, with_wheel_acceleration, friction_inputs=True)
    torque = shift_model(d, shift, with_wheel_acceleration, friction_inputs=False)
    elements = (spec.off_going, spec.on_coming)
    by_name = {v.name: v for v in torque.inputs}
    rhs = friction.rhs
    stick: list[Variable] = []
    for e in elements:
        v = by_name[naming.torque(e)]
        column = torque.rhs.diff(v.symbol)
        if column.free_symbols & set(torque.input_symbols):
            raise AssertionError(f"shift model is not affine in T_{e}")
        rhs = rhs + column * v.symbol
        stick.append(
            Variable(v.name, v.symbol, "N*m", f"{e} torque while it sticks (sign of 2.36)")
        )
    signs = power_on_slip_signs(d, spec)
    gain = {}
    for e in elements:
        element = d.element(e)
        assert element.n_disc is not None and element.r_m is not None
        gain[e] = float(signs[e] * 2 * element.n_disc * element.r_m.value)
    short = {e: element_short_name(d, e) for e in elements}
    (zeta,) = (v.symbol for v in friction.parameters if v.name == naming.GRADE)
    deviation = Variable(
        naming.GRADE_DEVIATION,
        sp.Symbol(naming.GRADE_DEVIATION, real=True),
        "rad",
        "recorded grade minus the parameter's nominal value, zeta_rec(t) - zeta0 (2.49)",
    )
    rhs = rhs.xreplace({zeta: zeta + deviation.symbol})
    model = Model(
        name=f"{friction.name.removesuffix('_mu')}_driven",
        states=friction.states,
        inputs=(*friction.inputs, *stick, deviation),
        parameters=friction.parameters,
        outputs=friction.outputs,
        rhs=rhs,
        output_expressions=friction.output_expressions,
        metadata={**friction.metadata, "driven": "sliding friction (3.14) + sticking torque"},
    )
    return DrivenShift(
        model=model,
        spec=spec,
        elements=elements,
        gain=gain,
        mu={e: naming.friction_coefficient(short[e]) for e in elements},
        normal_force={e: naming.normal_force(short[e]) for e in elements},
        stick_torque={e: naming.torque(e) for e in elements},
    )


def thesis_parameters(driven: DrivenShift) -> tuple[str, ...]:
    """The thesis' parameter set (3.2) for this shift: m_veh, k_ss, d_ss, μ of the off-going
    element (μ38 for the 2-3 shift of the built-in gearbox), ζ."""
    return ("m_veh", "k_ss", "d_ss", driven.mu[driven.spec.off_going], "zeta")


def sliding_masks(
    d: GearboxDescription,
    driven: DrivenShift,
    data: ReferenceData,
    mode: str = "detected",
    capacity_fraction: float = 0.98,
) -> dict[str, np.ndarray]:
    """Per element, the samples at which it slides (see the module docstring)."""
    if mode not in SLIDING_MODES:
        raise GearsymError(d.file, "sliding", f"expected one of {SLIDING_MODES}, got {mode!r}")
    masks = {}
    for e in driven.elements:
        short = element_short_name(d, e)
        force = data.signals[naming.normal_force(short)]
        if mode == "phases":
            inside = np.zeros(len(data.t), dtype=bool)
            for p in data.phases:
                if p.name in SLIDING_PHASES:
                    inside |= (data.t >= p.t_start) & (data.t < p.t_end)
            masks[e] = inside & (force > 0)
            continue
        element = d.element(e)
        assert element.n_disc is not None and element.r_m is not None
        mu = data.signals[naming.friction_coefficient(short)]
        capacity = 2 * element.n_disc * element.r_m.value * mu * force
        torque = np.abs(data.signals[naming.torque(e)])
        masks[e] = (force > 0) & (torque >= capacity_fraction * capacity)
    return masks


def driving_inputs(
    driven: DrivenShift,
    data: ReferenceData,
    masks: Mapping[str, np.ndarray],
    values: Mapping[str, float],
) -> np.ndarray:
    """Input samples (N, n_u) of the driven model in its input order, from the record."""
    columns: dict[str, np.ndarray] = {"T_In": data.signals["T_In"]}
    for e in driven.elements:
        torque = data.signals[naming.torque(e)]
        slide = masks[e]
        mu0 = values[driven.mu[e]]
        columns[driven.normal_force[e]] = np.where(slide, torque / (driven.gain[e] * mu0), 0.0)
        columns[driven.stick_torque[e]] = np.where(slide, 0.0, torque)
    # Δζ = ζ_rec(t) − ζ0 with ζ0 the description's value, the one the reference used when it
    # had no profile (a record without the ζ column: a level road at ζ0, Δζ = 0)
    zeta0 = driven.model.variable(naming.GRADE).default
    assert zeta0 is not None
    recorded = data.signals.get(naming.GRADE)
    columns[naming.GRADE_DEVIATION] = (
        np.zeros(len(data.t)) if recorded is None else recorded - float(zeta0)
    )
    return np.column_stack([columns[v.name] for v in driven.model.inputs])


def initial_state(model: Model, data: ReferenceData) -> np.ndarray:
    """The recorded state at the first sample (states are named like the signals)."""
    missing = [v.name for v in model.states if v.name not in data.signals]
    if missing:
        raise GearsymError(data.source, "signals", f"no recorded signal for states {missing}")
    return np.array([data.signals[v.name][0] for v in model.states], dtype=float)
