"""Simulation of the hybrid shift model (:mod:`gearsym.symbolic.hybrid`) with event detection.

Inside a mode the model is an ODE without stiff friction states (the locked elements are
constraints, not bristles), integrated by SciPy's ``solve_ivp`` (DOP853, explicit order 8) with
the mode's continuous guards — break-away and lock-up — as terminal events; SciPy locates each
event (a bracketing root finder on the dense output), this module only applies it: the guard's
condition picks the target mode (stick or reverse at a lock-up), the state map
(:class:`gearsym.symbolic.hybrid.StateMap`) gives the state in the target's coordinates, and the
integration restarts.

The normal forces F_N = p · a_piston come from the scenario's pressures, piecewise linear and
never negative: they vanish only at a breakpoint of their profile or over a whole segment. The
integration restarts at every breakpoint (as the reference does), and there the opening and
engagement guards (F_N falls to / rises from zero) are evaluated on the next segment, so those
events are located exactly without a root search.

μ of a sliding element: with ``mu="map"`` (default) the friction coefficient is the μ map at the
element's pressure, the oil temperature and the current |slip|, scaled by the parameter,
μ_e,eff = μ_e · map(p_e, T_oil, |Δω_e|) / μ_nominal: at the nominal μ_e it is exactly what the
reference reads (2.69), and ∂/∂μ_e is a relative change of the whole map, as in
:mod:`gearsym.validation.studies.driven_shift`. ``mu="constant"`` uses the parameter alone. The
grade enters as ζ + Δζ(t), ζ the parameter and Δζ(t) the scenario's profile minus the description's
ζ (zero without a profile), like the driven shift model of the sensitivity runs.

A one-way clutch among the swapping elements (:mod:`gearsym.symbolic.hybrid`, module
docstring) has no pressure, F_N or μ: its slot in u is 0, its guards (release, lock-up) are
state guards like break-away and lock-up, and its torque signal is the reaction while it is
locked and 0 while it overruns.

A dog element among the swapping elements (``kind = "dog"``) has no F_N or μ either (slot 0
in u). Its scenario table ``[pressure.<dog>]`` is its actuation command: commanded engaged
while the profile is > 0 (the value does not matter). The command changes only at the
profile's breakpoints, where the simulation restarts anyway; there an open dog whose command
is on engages if |Δω| ≤ ``engage_slip`` (the M-metric map, its loss ½ Δẏᵀ M Δẏ in
:attr:`Event.energy_loss <gearsym.validation.sim.hybrid_result.Event>`), and otherwise the
simulation **ends with a stated failure** (a :class:`GearsymError` naming the dog, the time,
the slip and the window: the teeth would clash), as it does for a command while the other
swapping element is locked (a tie-up). A locked dog whose command is off opens when
|T_req| ≤ ``release_torque`` (at once, or at the crossing, a state event armed only while
the command is off); until then it holds, loaded.

**Compiled C** (``compiled=True``, opt-in; the reference is CasADi's calls): each mode's
right-hand side and continuous guards emitted as C and called through ``ctypes``
(:mod:`~gearsym.validation.sim.compiled_c`), built once per simulator at first use. A CasADi
call from Python costs more than a mode's arithmetic; the emitted C is the same operations in
the same order. A compiled run also evaluates a segment's inputs as one line and tries the
rest of the segment as its first step (both in :meth:`HybridSimulator.run`), so it is the
reference's integration up to rounding, and to the integrator's tolerance where SciPy's own
first step would have been shorter (tests/test_closed_loop_fast.py). Without a C compiler
(:func:`~gearsym.validation.sim.compiled_c.compiler_available`) the simulator keeps CasADi's
calls. Sensitivities (``parameters``) always run through CasADi.

Beside this module: each mode compiled to CasADi (:mod:`~gearsym.validation.sim.hybrid_modes`),
the records a run returns (:mod:`~gearsym.validation.sim.hybrid_result`), the energy audit
of a run (:mod:`~gearsym.validation.sim.hybrid_energy`) and the sliding elements' slips at the
switches (:mod:`~gearsym.validation.sim.hybrid_slips`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.dynamics import gearbox_dynamics
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.friction import load_mu_map
from gearsym.symbolic.hybrid import (
    DISENGAGEMENT,
    ENGAGEMENT,
    LOCKED,
    OPEN,
    OPENING,
    RELEASE,
    Guard,
    HybridShift,
    drivetrain_mass,
    hybrid_shift,
)
from gearsym.symbolic.numeric import to_casadi
from gearsym.validation.sim.compiled_c import CompiledFunctions, compiler_available
from gearsym.validation.sim.hybrid_modes import CompiledMode
from gearsym.validation.sim.hybrid_result import Event, HybridResult, Piece
from gearsym.validation.sim.hybrid_sample import sample_signals, signal_name
from gearsym.validation.sim.hybrid_slips import check_slip_signs, onto_sliding_side
from gearsym.validation.sim.scenario import SAMPLE_TIME, Scenario, load_scenario
from scipy.integrate import solve_ivp

MU_MODES = ("map", "constant")

#: Most switches one simulation follows: a guard that chatters (slip crossing zero back and
#: forth at the capacity limit) is a modelling problem to report, not to integrate for ever.
EVENTS_MAX = 200


class HybridSimulator:
    """Compiled modes, the scenario's inputs and the switching logic of one hybrid shift."""

    def __init__(
        self,
        d: GearboxDescription,
        scenario: Scenario | None = None,
        hybrid: HybridShift | None = None,
        mu: str = "map",
        compiled: bool = False,
    ) -> None:
        if mu not in MU_MODES:
            raise ValueError(f"mu must be one of {MU_MODES}, got {mu!r}")
        self.d = d
        self.scenario = scenario if scenario is not None else load_scenario(d)
        self.hybrid = hybrid if hybrid is not None else hybrid_shift(d, self.scenario.shift.name)
        mu_map = load_mu_map(d)
        p_grid, _, dw_grid = mu_map.grid
        t_oil = quantity(d, "friction", "T_oil").value
        plane = mu_map(p_grid[:, None], t_oil, dw_grid[None, :])
        self.modes = {
            name: CompiledMode(self.hybrid, mode, d, mu, (p_grid, dw_grid, plane))
            for name, mode in self.hybrid.modes.items()
        }
        self.area = {}
        for e in self.hybrid.friction_elements:
            area = d.element(e).a_piston
            if area is None:
                raise GearsymError(
                    d.file, f'shift_element[name="{e}"].a_piston', "missing (F_N = p a_piston)"
                )
            self.area[e] = area.value
        self.parameter_names = [v.name for v in self.hybrid.parameters]
        zeta = next(v for v in self.hybrid.parameters if v.name == naming.GRADE)
        self.zeta0 = float(zeta.default or 0.0)
        self._speeds: dict[str, Any] = {}
        self._mass: np.ndarray | None = None
        #: the modes' right-hand sides and guards run as emitted C (module docstring); may be
        #: switched per run (the drive's shifts: fast or reference)
        self.compiled = compiled
        self._compiled_c: CompiledFunctions | None = None
        #: further functions of (x, u, p) compiled with the modes (name → CasADi function;
        #: the drive's energy audit adds each mode's powers), set before the first compile
        self.also_compiled: dict[str, Any] = {}

    def compiled_functions(self) -> CompiledFunctions | None:
        """Every mode's right-hand side and continuous guards emitted as C and compiled (built
        once, at first use: the compile, or the cache's load, is paid only by a simulator that
        runs compiled), with what :meth:`_sample` reads at every sample and :attr:`also_compiled`;
        None without a C compiler (the callers keep CasADi's calls). Two libraries: the
        functions that hold the description's numbers (inertias, r_dyn: a fleet's vehicles
        each compile their own), and the kinematic ones (shaft speeds, slips, μ: the same
        source for every vehicle of a gearbox, so compiled once and then loaded from the
        cache)."""
        if self._compiled_c is None and compiler_available():
            numbers = dict(self.also_compiled)
            kinematic = {}
            for name, mode in self.modes.items():
                numbers[name] = mode.f
                for k, guard in enumerate(mode.guard):
                    numbers[guard_name(name, k)] = guard
                numbers[signal_name(name, "torques")] = mode.torques
                kinematic[signal_name(name, "speeds")] = self.shaft_speeds(name)
                for signal in ("slips", "mu"):
                    kinematic[signal_name(name, signal)] = getattr(mode, signal)
            library = CompiledFunctions(numbers)
            library.functions.update(CompiledFunctions(kinematic).functions)
            self._compiled_c = library
        return self._compiled_c

    def _c(self) -> CompiledFunctions | None:
        """The compiled C when this simulator runs compiled and a compiler is there, else None."""
        if not self.compiled or self._compiled_c is not None:
            return self._compiled_c if self.compiled else None
        return self.compiled_functions()

    # ------------------------------------------------------------------ inputs and parameters

    def values(self, overrides: Mapping[str, float] | None = None) -> dict[str, float]:
        """Every parameter's value: its default, or the override."""
        values = {v.name: float(v.default) for v in self.hybrid.parameters if v.default is not None}
        for name, value in (overrides or {}).items():
            if name not in values:
                raise GearsymError(self.d.file, "set", f"unknown parameter {name!r}")
            values[name] = float(value)
        return values

    def parameter_vector(self, values: Mapping[str, float]) -> np.ndarray:
        return np.array([values[n] for n in self.parameter_names], dtype=float)

    def normal_forces(self, t: float) -> np.ndarray:
        """F_N = p a_piston of each swapping element (0 for a one-way clutch)."""
        return np.array(
            [
                self.scenario.pressure[e](t) * self.area[e] if e in self.area else 0.0
                for e in self.hybrid.elements
            ]
        )

    def inputs(self, t: float) -> np.ndarray:
        """u(t) = [T_In, F_N of each swapping element (0 for a one-way clutch), Δζ]."""
        grade = self.scenario.grade
        deviation = 0.0 if grade is None else grade(t) - self.zeta0
        return np.array([self.scenario.input_torque(t), *self.normal_forces(t), deviation])

    def inputs_many(self, times: np.ndarray) -> np.ndarray:
        """:meth:`inputs` at every time of ``times`` (rows), the same values without a Python
        call per time (the samples and the energy audit read thousands per shift)."""
        scenario, grade = self.scenario, self.scenario.grade
        times = np.asarray(times, dtype=float)
        columns = [scenario.engine.many(times) + scenario.e_machine.many(times)]
        for e in self.hybrid.elements:
            if e in self.area:
                columns.append(scenario.pressure[e].many(times) * self.area[e])
            else:
                columns.append(np.zeros(len(times)))
        columns.append(np.zeros(len(times)) if grade is None else grade.many(times) - self.zeta0)
        return np.column_stack(columns)

    # ------------------------------------------------------------------ initial state

    def initial_state(self, p: np.ndarray) -> np.ndarray:
        """The from-gear at the scenario's vehicle speed, accelerating as one rigid gear: the
        side-shaft twist φ solves d(φ̇)/dt = 0 (2.44), the condition the reference's
        quasi-static start imposes too (affine in φ: two evaluations solve it)."""
        mode = self.modes[self.hybrid.from_mode]
        names = [v.name for v in mode.mode.model.states]
        r_dyn = quantity(self.d, "vehicle", "r_dyn").value
        i_d = quantity(self.d, "drivetrain", "i_D").value
        omega_c = self.scenario.vehicle_speed / r_dyn
        x = np.zeros(mode.n)
        x[names.index(naming.WHEEL_SPEED)] = omega_c
        (out,) = [
            k
            for k, v in enumerate(mode.mode.model.states)
            if v.name.startswith("omega_") and v.name != naming.WHEEL_SPEED
        ]
        x[out] = i_d * omega_c  # φ̇ = ω_out / i_D − ω_C = 0
        x[names.index(naming.TWIST)] = self.quasi_static_twist(
            self.hybrid.from_mode, x, self.inputs(0.0), p
        )
        return x

    def quasi_static_twist(self, mode: str, x: np.ndarray, u: np.ndarray, p: np.ndarray) -> float:
        """The side-shaft twist φ at which the output shaft and the wheel accelerate together,
        d(φ̇)/dt = 0 with φ̇ = ω_out / i_D − ω_C (2.44), at the speeds of ``x`` in ``mode``:
        what a gear settles to under a steady load (affine in φ: two evaluations solve it;
        ω_out is linear in the state, so its rate is the shaft-speed map of ẋ)."""
        compiled = self.modes[mode]
        names = [v.name for v in compiled.mode.model.states]
        wheel, phi = names.index(naming.WHEEL_SPEED), names.index(naming.TWIST)
        i_d = quantity(self.d, "drivetrain", "i_D").value
        out = [s.name for s in self.d.shafts].index(self.d.output_shaft)
        speeds = self.shaft_speeds(mode)

        def twist_acceleration(value: float) -> float:
            y = np.array(x, dtype=float)
            y[phi] = value
            xdot = compiled.rhs(y, u, p)
            return float(np.asarray(speeds(xdot)).ravel()[out] / i_d - xdot[wheel])

        a0, a1 = twist_acceleration(0.0), twist_acceleration(1e-2)
        return -a0 * 1e-2 / (a1 - a0)

    def initial_sensitivity(self, p: np.ndarray, parameters: Sequence[str]) -> np.ndarray:
        """S(0) = ∂x(0)/∂p of :meth:`initial_state`: the speeds are given by the vehicle speed
        (S = 0), the twist solves c(φ, p) = d(φ̇)/dt = 0, so ∂φ/∂p = −(∂c/∂p)/(∂c/∂φ) (as
        :func:`gearsym.symbolic.sensitivity.stationary_initial_sensitivity` does for the
        shift model)."""
        import casadi as ca

        mode = self.modes[self.hybrid.from_mode]
        names = [v.name for v in mode.mode.model.states]
        i_d = quantity(self.d, "drivetrain", "i_D").value
        out = next(
            k
            for k, name in enumerate(names)
            if name.startswith("omega_") and name != naming.WHEEL_SPEED
        )
        condition = mode.rhs_sx[out] / i_d - mode.rhs_sx[names.index(naming.WHEEL_SPEED)]
        phi = names.index(naming.TWIST)
        gradient = ca.Function(
            "dc",
            [mode.x, mode.u, mode.p],
            [ca.jacobian(condition, mode.x[phi]), ca.jacobian(condition, mode.p)],
        )
        c_phi, c_p = (
            np.asarray(v.full(), dtype=float)
            for v in gradient(self.initial_state(p), self.inputs(0.0), p)
        )
        columns = [self.parameter_names.index(n) for n in parameters]
        result = np.zeros((mode.n, len(columns)))
        result[phi] = -c_p[0, columns] / c_phi[0, 0]
        return result

    # ------------------------------------------------------------------ switching

    def switch(
        self, guard: Guard, t: float, x: np.ndarray, p: np.ndarray
    ) -> tuple[str, np.ndarray]:
        """Target mode and state map (x⁺ = A x⁻) after ``guard`` fired at (t, x)."""
        target = guard.target
        if guard.condition is not None:
            compiled = self.modes[guard.source]
            value = compiled.value(compiled.condition[id(guard)], x, self.inputs(t), p)[0]
            if value < 0:
                assert guard.otherwise is not None
                target = guard.otherwise
        return target, np.array(self.hybrid.maps[(guard.source, target)].matrix, dtype=float)

    def normal_force_switches(
        self, mode: str, t: float, t_next: float, x: np.ndarray, p: np.ndarray
    ) -> list[tuple[Guard, str, np.ndarray]]:
        """Opening and engagement at a breakpoint t: the element's F_N on the next segment (its
        midpoint) is zero for an element that is not open, or positive for an open one.
        Returns (guard, target, map matrix) in order."""
        switches = []
        middle = (t + t_next) / 2
        forces = self.normal_forces(middle)
        for k, e in enumerate(self.hybrid.elements):
            if e in self.hybrid.one_way or e in self.hybrid.dog:  # not pressed
                continue
            status = self.hybrid.modes[mode].status[e][0]
            pressed = forces[k] > 0
            kind = ENGAGEMENT if status == OPEN and pressed else None
            if status != OPEN and not pressed:
                kind = OPENING
            if kind is None:
                continue
            (guard,) = [
                g for g in self.hybrid.guards_from(mode) if g.element == e and g.kind == kind
            ]
            target = guard.target
            if kind == ENGAGEMENT:
                slip = self.modes[mode].value(self.modes[mode].slips, x, self.inputs(t), p)[k]
                target = guard.target if slip >= 0 else str(guard.otherwise)
            matrix = np.array(self.hybrid.maps[(mode, target)].matrix, dtype=float)
            x = matrix @ x
            switches.append((guard, target, matrix))
            mode = target
        return switches

    def pending_releases(
        self, mode: str, t: float, x: np.ndarray, p: np.ndarray, t_next: float | None = None
    ) -> list[tuple[Guard, str, np.ndarray]]:
        """One-way clutches that are locked in ``mode`` but would carry torque of the sign they
        cannot carry at (t, x): their release is due now, not at a later zero crossing (the
        start of a coast shift in a gear that locks a freewheel, or a switch after which the
        reaction has the wrong sign). Returns (guard, target, map matrix) in order; empty
        without one-way clutches."""
        switches = []
        done: set[str] = set()
        # a dog's command as it holds on the segment ahead (it changes at breakpoints only)
        middle = t if t_next is None else (t + t_next) / 2
        while True:
            compiled = self.modes[mode]
            due = [
                (k, g)
                for k, g in enumerate(compiled.continuous)
                if (
                    g.kind == RELEASE
                    or (g.kind == DISENGAGEMENT and not self.commanded(g.element, middle))
                )
                and g.element not in done
                and compiled.value(compiled.guard[k], x, self.inputs(t), p)[0] < 0
            ]
            if not due:
                return switches
            guard = due[0][1]
            matrix = np.array(self.hybrid.maps[(mode, guard.target)].matrix, dtype=float)
            x = matrix @ x
            switches.append((guard, guard.target, matrix))
            done.add(guard.element)
            mode = guard.target

    def commanded(self, element: str, t: float) -> bool:
        """A dog element's command at t (its ``[pressure.<dog>]`` profile > 0)."""
        return self.scenario.pressure[element](t) > 0

    def impulse_loss(self, source: str, target: str, x: np.ndarray, matrix: np.ndarray) -> float:
        """½ Δẏᵀ M Δẏ of the switch source → target at x (Δẏ = P⁻ z⁻ − P⁺ z⁺, M of (2.34)
        with the output-side inertias): the kinetic energy the state map takes out."""
        if self._mass is None:
            self._mass = np.array(drivetrain_mass(self.d, gearbox_dynamics(self.d)), dtype=float)
        before, after = self.hybrid.modes[source], self.hybrid.modes[target]
        z_old, z_new = x[: len(before.keep)], (matrix @ x)[: len(after.keep)]
        dy = np.array(before.projection, dtype=float) @ z_old
        dy -= np.array(after.projection, dtype=float) @ z_new
        return float(0.5 * dy @ self._mass @ dy)

    def dog_switches(
        self, mode: str, t: float, t_next: float, x: np.ndarray, p: np.ndarray
    ) -> list[tuple[Guard, str, np.ndarray]]:
        """A dog's command at a breakpoint t (its value on the next segment, at the midpoint):
        an open dog commanded engages if |Δω| ≤ ``engage_slip``, else the simulation ends
        with a stated failure (module docstring); a locked dog no longer commanded opens now
        if |T_req| ≤ ``release_torque`` (else its state event does it later). Returns (guard,
        target, map matrix) in order."""
        switches = []
        middle = (t + t_next) / 2
        for k, e in enumerate(self.hybrid.elements):
            if e not in self.hybrid.dog:
                continue
            engage_slip, release_torque = self.hybrid.dog[e]
            status = self.hybrid.modes[mode].status[e][0]
            compiled = self.modes[mode]
            on = self.commanded(e, middle)
            if status == OPEN and on:
                slip = compiled.value(compiled.slips, x, self.inputs(t), p)[k]
                found = [
                    g
                    for g in self.hybrid.guards_from(mode)
                    if g.element == e and g.kind == ENGAGEMENT
                ]
                if not found:
                    other = next(o for o in self.hybrid.elements if o != e)
                    raise GearsymError(
                        self.scenario.file,
                        f"pressure.{e}",
                        f"dog {e} commanded engaged at t = {t:.6g} s while {other} is locked: "
                        "a tie-up (both gears' elements closed); simulation ended",
                    )
                if abs(slip) > engage_slip:
                    raise GearsymError(
                        self.scenario.file,
                        f"pressure.{e}",
                        f"dog {e} commanded engaged at t = {t:.6g} s at slip {slip:.4g} rad/s, "
                        f"outside its engage_slip {engage_slip:g} rad/s: the teeth would clash "
                        "away from synchronism; simulation ended",
                    )
                guard = found[0]
            elif status == LOCKED and not on:
                (guard,) = [
                    g
                    for g in self.hybrid.guards_from(mode)
                    if g.element == e and g.kind == DISENGAGEMENT
                ]
                torque = compiled.value(compiled.torques, x, self.inputs(t), p)[k]
                if abs(torque) > release_torque:
                    continue  # loaded: held until the state event
            else:
                continue
            matrix = np.array(self.hybrid.maps[(mode, guard.target)].matrix, dtype=float)
            switches.append((guard, guard.target, matrix))
            x = matrix @ x
            mode = guard.target
        return switches

    def input_slope(self, ta: float, tb: float) -> np.ndarray:
        """du/dt inside the segment [ta, tb], where every profile is linear."""
        return (self.inputs(tb) - self.inputs(ta)) / (tb - ta)

    # ------------------------------------------------------------------ integration

    def run(
        self,
        overrides: Mapping[str, float] | None = None,
        rtol: float = 1e-10,
        atol: float = 1e-10,
        sample_time: float = SAMPLE_TIME,
        x0: np.ndarray | None = None,
        parameters: Sequence[str] = (),
        t_start: float = 0.0,
        mode: str | None = None,
        s0: np.ndarray | None = None,
        state_columns: Sequence[str] = (),
        t_eval: np.ndarray | None = None,
    ) -> HybridResult:
        """Integrate through the scenario from the quasi-static from-gear (or ``x0`` in the
        from-gear's coordinates); see the module docstring.

        With ``parameters`` the sensitivities S = ∂x/∂p ride along: (3.7) inside each mode, and
        at each switch the jump of hybrid sensitivity analysis (Hiskens & Pai 2000; Galán,
        Feehery & Barton 1999),

            S⁺ = A S⁻ + (A f⁻ − f⁺) ∂τ/∂p,   ∂τ/∂p = −(∂g/∂x S⁻ + ∂g/∂p) / (∂g/∂x f⁻ + ∂g/∂u u̇),

        A the (constant, linear) state map, f∓ the source and target right-hand sides at the
        event, g the guard; ∂g/∂u u̇ is there because the guards depend on time through T_In and
        F_N. Switches at breakpoints happen at fixed times (∂τ/∂p = 0): S⁺ = A S⁻. S(t0) is
        ``s0`` (states × parameters; default 0: the initial state known and independent of p,
        (3.7) from t = 0 as the thesis does).

        A restart inside the shift: ``t_start``, ``mode`` and ``x0`` in that mode's
        coordinates. ``state_columns`` names states of that mode whose initial values are
        further parameters (columns ∂x/∂x_s(t0), starting as unit vectors, without ∂f/∂p): the
        nuisance parameters of the Fisher information. ``t_eval``: the sample times (default:
        every ``sample_time`` and the breakpoints).
        """
        values = self.values(overrides)
        p = self.parameter_vector(values)
        unknown = [name for name in parameters if name not in self.parameter_names]
        if unknown:
            raise GearsymError(self.d.file, "params", f"unknown parameters {unknown}")
        scenario = self.scenario
        mode = self.hybrid.from_mode if mode is None else mode
        x = self.initial_state(p) if x0 is None else np.asarray(x0, dtype=float)
        names = [v.name for v in self.hybrid.modes[mode].model.states]
        indices: tuple[int | None, ...] = tuple(
            self.parameter_names.index(name) for name in parameters
        ) + (None,) * len(state_columns)
        m = len(indices)
        sens = np.zeros((len(x), m))
        if s0 is not None:
            sens[:, : len(parameters)] = s0
        for k, name in enumerate(state_columns):
            sens[names.index(name), len(parameters) + k] = 1.0
        breakpoints = [t_start] + [b for b in scenario.breakpoints() if b > t_start]
        events: list[Event] = []
        tau_p: list[np.ndarray] = []
        pieces: list[Piece] = []
        nfev = 0
        for ta, tb in zip(breakpoints[:-1], breakpoints[1:], strict=True):
            switches = self.normal_force_switches(mode, ta, tb, x, p)
            for guard, target, matrix in switches:
                events.append(Event(ta, guard.kind, guard.element, mode, target))
                tau_p.append(np.zeros(m))
                mode, x, sens = target, matrix @ x, matrix @ sens
                x = onto_sliding_side(self, mode, guard.element, x, ta, p)
            dogs = self.dog_switches(mode, ta, tb, x, p) if self.hybrid.dog else []
            for guard, target, matrix in dogs:
                loss = self.impulse_loss(mode, target, x, matrix)
                events.append(Event(ta, guard.kind, guard.element, mode, target, loss))
                tau_p.append(np.zeros(m))
                mode, x, sens = target, matrix @ x, matrix @ sens
            switches += dogs
            if ta == t_start or switches:
                # a one-way clutch whose reaction has the wrong sign already releases now
                for guard, target, matrix in self.pending_releases(mode, ta, x, p, tb):
                    events.append(Event(ta, guard.kind, guard.element, mode, target))
                    tau_p.append(np.zeros(m))
                    mode, x, sens = target, matrix @ x, matrix @ sens
            t = ta
            inputs = self.segment_inputs(ta, tb)
            while t < tb:
                compiled = self.modes[mode]
                n = compiled.n
                fun = self._right_hand_side(compiled, indices, p, inputs)
                functions = []
                for index, guard in enumerate(compiled.continuous):
                    armed = guard.kind != DISENGAGEMENT or not self.commanded(
                        guard.element, (t + tb) / 2
                    )
                    value_of = self._guard_function(compiled, index, p)

                    def event(
                        time: float,
                        y: np.ndarray,
                        g: Any = value_of,
                        n: int = n,
                        armed: bool = armed,
                        u_of: Any = inputs,
                    ) -> float:
                        # a dog's disengagement waits for its command to fall
                        return g(y[:n], u_of(time)) if armed else 1.0

                    event.terminal = True  # type: ignore[attr-defined]
                    event.direction = guard.direction  # type: ignore[attr-defined]
                    functions.append(event)
                # S rides in the same error control as x (its columns in units of x per unit p)
                y0 = np.concatenate([x, sens.T.ravel()])
                # compiled: the first step tried is the rest of the segment (SciPy's estimate
                # of it is capped there and mostly is it; a step too long is rejected and
                # shortened by the same error control), which saves the estimate's
                # evaluation and arithmetic at each of a closed loop's many restarts
                first = {"first_step": tb - t} if self._c() is not None else {}
                sol = solve_ivp(
                    fun,
                    (t, tb),
                    y0,
                    method="DOP853",
                    rtol=rtol,
                    atol=atol,
                    events=functions or None,
                    dense_output=True,
                    **first,
                )
                if sol.status == -1:
                    raise GearsymError(
                        scenario.file,
                        "scenario",
                        f"hybrid integration failed at t = {sol.t[-1]:.6g} s in {mode}: "
                        f"{sol.message}",
                    )
                nfev += sol.nfev
                pieces.append(Piece(mode, t, float(sol.t[-1]), sol.sol, y0.copy()))
                t = float(sol.t[-1])
                check_slip_signs(self, mode, sol.y[:n, -1], t, p)
                if sol.status != 1:
                    x, sens = sol.y[:n, -1], sol.y[n:, -1].reshape(m, n).T
                    break
                k = next(k for k, times in enumerate(sol.t_events) if len(times))
                y_event = sol.y_events[k][0]
                x, sens = y_event[:n], y_event[n:].reshape(m, n).T
                guard = compiled.continuous[k]
                target, matrix = self.switch(guard, t, x, p)
                x_plus = matrix @ x
                dtau = np.zeros(m)
                if m:
                    u = self.inputs(t)
                    f_minus = compiled.rhs(x, u, p)
                    f_plus = self.modes[target].rhs(x_plus, u, p)
                    g_x, g_u, g_p = (
                        np.asarray(v.full(), dtype=float)
                        for v in compiled.guard_gradient(k)(x, u, p)
                    )
                    rate = float((g_x @ f_minus + g_u @ self.input_slope(ta, tb))[0])
                    g_theta = np.array([g_p[0, i] if i is not None else 0.0 for i in indices])[
                        None, :
                    ]
                    dtau = -(g_x @ sens + g_theta).ravel() / rate
                    sens = matrix @ sens + np.outer(matrix @ f_minus - f_plus, dtau)
                x = onto_sliding_side(self, target, guard.element, x_plus, t, p)
                events.append(Event(t, guard.kind, guard.element, mode, target))
                tau_p.append(dtau)
                mode = target
                for guard, target, matrix in self.pending_releases(mode, t, x, p, tb):
                    events.append(Event(t, guard.kind, guard.element, mode, target))
                    tau_p.append(np.zeros(m))
                    mode, x, sens = target, matrix @ x, matrix @ sens
                if len(events) > EVENTS_MAX:
                    raise GearsymError(
                        scenario.file,
                        "scenario",
                        f"more than {EVENTS_MAX} mode switches by t = {t:.6g} s (chattering "
                        f"{guard.kind} of {guard.element})",
                    )
        if t_eval is None:
            grid = np.unique(
                np.concatenate([np.arange(0.0, scenario.t_end, sample_time), breakpoints])
            )
            grid = grid[grid >= t_start]
        else:
            grid = np.asarray(t_eval, dtype=float)
        signals, modes, sensitivities = self._sample(pieces, grid, p, m)
        return HybridResult(
            t=grid,
            signals=signals,
            modes=modes,
            events=tuple(events),
            pieces=tuple(pieces),
            hybrid=self.hybrid,
            scenario=scenario,
            values=values,
            stats={"nfev": float(nfev), "events": float(len(events))},
            parameters=(*parameters, *(f"{name}(t0)" for name in state_columns)),
            sensitivities=sensitivities,
            event_time_sensitivities=np.array(tau_p).reshape(len(events), m),
        )

    def _guard_function(self, compiled: CompiledMode, k: int, p: np.ndarray) -> Any:
        """(x, u) → the value of the mode's k-th continuous guard, for the event functions."""
        c = self._c()
        if c is not None:
            g_c = c[guard_name(compiled.mode.name, k)]
            return lambda x, u: float(g_c(x, u, p)[0])
        g = compiled.guard[k]
        return lambda x, u: float(compiled.value(g, x, u, p)[0])

    def _right_hand_side(
        self,
        compiled: CompiledMode,
        indices: tuple[int, ...],
        p: np.ndarray,
        inputs: Callable[[float], np.ndarray] | None = None,
    ) -> Any:
        """(t, y) → ẏ for solve_ivp: the mode's f, or the augmented [f; ∂f/∂x S + ∂f/∂p];
        ``inputs``: t → u(t) (default :meth:`inputs`)."""
        inputs = self.inputs if inputs is None else inputs
        c = self._c()
        if c is not None and not indices:
            # the same arithmetic through ctypes (module docstring)
            f = c[compiled.mode.name]
            return lambda time, y: f(y, inputs(time), p)
        if not indices:
            return lambda time, y: compiled.rhs(y, inputs(time), p)
        augmented = compiled.augmented(indices)
        return lambda time, y: np.asarray(augmented(y, inputs(time), p).full(), dtype=float).ravel()

    def segment_inputs(self, ta: float, tb: float) -> Callable[[float], np.ndarray]:
        """t → u(t) inside the segment [ta, tb] between two breakpoints: :meth:`inputs`, or
        when running compiled the same line as u(ta) + (t − ta) u̇ (every profile is linear
        there; equal up to rounding, 1e-16 relative), one NumPy expression instead of a
        Python call per profile: at a few µs per right-hand side, the profiles' lookup was
        what was left to pay."""
        if self._c() is None:
            return self.inputs
        start = self.inputs(ta)
        slope = (self.inputs(tb) - start) / (tb - ta)
        return lambda time: start + (time - ta) * slope

    def shaft_speeds(self, mode: str) -> Any:
        """CasADi function x → every shaft's speed in ``mode`` (ẏ = P z, then s(y), 2.29)."""
        if mode not in self._speeds:
            import casadi as ca

            compiled = self.modes[mode]
            m = self.hybrid.modes[mode]
            dyn = gearbox_dynamics(self.d)
            index = {b: i for i, b in enumerate(self.d.body_names)}
            z = sp.Matrix(m.model.state_symbols[: len(m.keep)])
            y_dot = m.projection * z
            exprs = [(dyn.kinematics.transform[index[s.name], :] * y_dot)[0] for s in self.d.shafts]
            out = ca.vertcat(*[to_casadi(e, compiled.mapping) for e in exprs])
            self._speeds[mode] = ca.Function("speeds", [compiled.x], [out])
        return self._speeds[mode]

    def _sample(
        self, pieces: Sequence[Piece], grid: np.ndarray, p: np.ndarray, m: int = 0
    ) -> tuple[dict[str, np.ndarray], tuple[str, ...], dict[str, np.ndarray]]:
        """Every signal (and its sensitivities) at the grid
        (:func:`~gearsym.validation.sim.hybrid_sample.sample_signals`)."""
        return sample_signals(self, pieces, grid, p, m)


def guard_name(mode: str, k: int) -> str:
    """The name of mode ``mode``'s k-th continuous guard among a simulator's compiled C."""
    return f"{mode}#guard{k}"


def simulate_hybrid(
    d: GearboxDescription,
    scenario: Scenario | None = None,
    overrides: Mapping[str, float] | None = None,
    mu: str = "map",
    rtol: float = 1e-10,
    atol: float = 1e-10,
) -> HybridResult:
    """Integrate the hybrid shift model through the scenario (default: the built-in 2-3)."""
    return HybridSimulator(d, scenario, mu=mu).run(overrides, rtol=rtol, atol=atol)
