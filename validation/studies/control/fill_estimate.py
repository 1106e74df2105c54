"""The on-coming piston's fill time estimated from the TCU's own record of a shift: a replay of
its commands through its own models (the adaptive-control issue).

No filter state sees the fill: the piston transmits nothing until it is stroked, and what
the EKF is told of the normal force is the TCU's nominal actuator's answer to its commands
(:mod:`.closed_loop`). But the fill leaves a signature on the input speed during the torque
phase, which the TCU measures: stroked early, the fast-fill pressure presses the on-coming
element against the still-locked off-going one and pulls the input down (tie-up); stroked
late, the off-going element lets go before the on-coming one carries, and the input flares.
The size of that signature depends on how early or late.

So after a shift the TCU replays it: its own hybrid model of the shift (the calibration's
description with the strategy's μ, m_veh and ζ), started at the measured output speed, driven
by the commands it gave, through its nominal actuator whose fill time is ``t_fill + δ``; and
it picks the δ whose replayed input speed best matches the measured one over the fill, the
torque phase and the start of the inertia phase (bounded scalar minimisation, SciPy's
``minimize_scalar``). The comparison removes a straight line (offset and slope) from the
difference first: an error in the assumed input torque, mass or grade changes the input's
acceleration over the whole window, which the fill does not, and must not be read as a fill.

An estimate that at least halves the residual of the fill the shift assumed explains the
record and is taken outright; any other is one shift's evidence, with a variance from how
sharply the residual's valley pins δ down (:attr:`FillEstimate.variance`), weighed against
what the earlier shifts said by a scalar Kalman filter over the shifts (:class:`FillBelief`):
a small fill error, whose signature is below what the TCU's model errors leave, is learnt
over several shifts that say the same thing instead of never.

What the estimate holds: the fill time at the nominal fast-fill pressure through the valve
the replay assumed. A valve offset (the fleet's ±100 mbar) changes how fast the piston strokes
and how hard every element presses; held at a wrong value, the replay makes up for the torque
it gets wrong with a wrong fill (a valve 100 mbar low flares the input like a piston 20 ms
late). :meth:`FillReplay.estimate` can search the offset with the fill (``offset_sigma``; δ is
then the piston's own); the estimator strategy does not (tried on the first shift and not
adopted: docs/control.md says why).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.sim.actuator import ClutchActuator
from gearsym.validation.studies.control.closed_loop import TICK, ClosedLoopShift
from gearsym.validation.studies.control.controller import Knowledge

__all__ = ["FILL_SEARCH", "GRID_STEP", "FillBelief", "FillEstimate", "FillReplay"]

#: The fill-time errors searched about the shift's own (s): beyond the fleet's ±50 ms and
#: the valve offset's share.
FILL_SEARCH = 0.06
#: The coarse search's spacing (s): one TCU tick.
GRID_STEP = 0.01
#: The residual's fraction an estimate must leave to be taken outright
#: (:attr:`FillEstimate.explains`), chosen on the tuning vehicles (seeds 100000 and up) of the
#: 2-3 and 3-4 shifts.
EXPLAINS = 0.5
#: ... and by at least this much (rad/s, about 1 rpm: below a speed sensor's resolution an
#: improvement is no evidence).
EXPLAINS_FLOOR = 0.1
#: How many independent pieces of evidence one shift's residual holds (the per-shift variance
#: of :meth:`FillEstimate.variance`): what the TCU's model gets wrong (μ, mass, torque) is
#: smooth over the compared window, so its samples are not independent (assumed; only this
#: value was tried, on the tuning vehicles, seeds 100000-100039 of the 2-3 shift).
INDEPENDENT_SAMPLES = 4.0
#: The smallest residual RMS a replay is credited with (rad/s): the speed sensors' resolution,
#: well above the integrators' 1e-8 (a replay that reproduces the record to its tolerance is
#: not infinitely sure).
RESIDUAL_FLOOR = 0.01
#: The valve offsets searched with δ (:meth:`FillReplay.estimate`), in σ of the TCU's doubt
#: about its belief: the coarse grid whose best cell bounded Brent refines.
OFFSET_GRID = (-2.0, -1.0, 0.0, 1.0, 2.0)
#: How far past the inertia phase's commanded start the replay is compared (s): a flare shows
#: once the off-going element is vented, one valve delay after the torque phase.
AFTER_TORQUE_PHASE = 0.06
#: How closely the edge of a plateau of the residual is found (s, :meth:`FillReplay._plateau_edge`).
EDGE_TOLERANCE = 1e-3


@dataclass(frozen=True)
class FillEstimate:
    """δ (s, the fill time's error against the calibration's) and the replay's residual RMS
    (rad/s) at δ, one grid step either side of it (root mean square of both sides: how sharply
    the record pins δ down) and at the fill the shift was commanded with."""

    delta: float
    rms: float
    rms_side: float
    rms_assumed: float
    #: the valve offset (Pa) the replay found with δ (the one it assumed when not searched)
    offset: float = 0.0
    #: whether the record bounds δ from one side only (:meth:`FillReplay._plateau_edge`):
    #: δ is then the bound, and no variance is credited to it
    one_sided: bool = False

    @property
    def variance(self) -> float:
        """The variance of δ (s²) as one shift's evidence: the residual left at δ is what the
        TCU's model cannot explain, e; the fill's signature grows the residual's mean square
        by g² h² one step h away. For a least-squares fit of one parameter to n samples,
        var(δ) = σ_e² / (n g²) = h² rms² / (rms_side² − rms²) over the independent samples
        (:data:`INDEPENDENT_SAMPLES`). A record the fill explains (a sharp valley, little left)
        pins δ down; a flat one (the model's own error) tells little."""
        if self.one_sided:
            return math.inf
        floor = max(self.rms, RESIDUAL_FLOOR)
        rise = self.rms_side**2 - floor**2
        if not math.isfinite(self.rms_side):
            rise = math.inf
        if rise <= 0.0 or not math.isfinite(floor):
            return math.inf
        return GRID_STEP**2 * floor**2 / rise / INDEPENDENT_SAMPLES

    @property
    def explains(self) -> bool:
        """Whether the fill explains the record outright: the best δ at least halves the
        residual of the fill the shift assumed, by at least :data:`EXPLAINS_FLOOR`."""
        return (
            self.rms <= EXPLAINS * self.rms_assumed
            and self.rms_assumed - self.rms >= EXPLAINS_FLOOR
        )

    def to_dict(self) -> dict[str, float | bool | None]:
        return {
            "delta": self.delta,
            "explains": self.explains,
            "rms": self.rms,
            "rms_side": self.rms_side,
            "rms_assumed": self.rms_assumed,
            "offset": self.offset,
            "one_sided": self.one_sided,
            # JSON has no infinity: a record that pins nothing down has no σ
            "sigma": math.sqrt(self.variance) if math.isfinite(self.variance) else None,
        }


@dataclass(frozen=True)
class FillBelief:
    """What the TCU believes of the fill time over a sequence of shifts: δ (s, against the
    calibration's fill time, in the replay's view) and its variance, a scalar Kalman filter
    over the shifts' estimates (each with :attr:`FillEstimate.variance`), the fill drifting
    by ``drift`` (s per shift, oil temperature and wear) between them."""

    delta: float
    variance: float
    drift: float = 0.0

    def updated(self, found: FillEstimate) -> FillBelief:
        """After one shift's estimate ``found``: the prediction over one shift, then the
        update with it (a record that pins nothing down leaves the belief as it was)."""
        predicted = self.variance + self.drift**2
        measured = found.variance
        if not math.isfinite(measured):
            return replace(self, variance=predicted)
        gain = predicted / (predicted + measured)
        return replace(
            self,
            delta=self.delta + gain * (found.delta - self.delta),
            variance=(1.0 - gain) * predicted,
        )

    def after(self, found: FillEstimate) -> FillBelief:
        """The belief after one shift: an estimate that explains the record
        (:attr:`FillEstimate.explains`) replaces it outright, no surer than the predicted
        belief (a fill far off leaves a flat valley); any other is weighed in
        (:meth:`updated`)."""
        if not found.explains:
            return self.updated(found)
        variance = min(found.variance, self.variance + self.drift**2)
        return replace(self, delta=found.delta, variance=variance)

    @property
    def sigma(self) -> float:
        return math.sqrt(self.variance)


class _Replay:
    """Gives the recorded commands back tick by tick, as the controller gave them."""

    def __init__(self, commands: Mapping[str, np.ndarray], phases: Sequence[str]) -> None:
        self.commands = commands
        self.phases = phases
        self.phase = phases[0]

    def step(self, t: float, speeds: np.ndarray, torque: float) -> dict[str, float]:
        k = min(int(round(t / TICK)), len(self.phases) - 1)
        self.phase = self.phases[k]
        return {e: float(c[k]) for e, c in self.commands.items()}


def _detrended_rms(difference: np.ndarray, t: np.ndarray) -> float:
    """RMS of ``difference`` after the least-squares straight line in ``t`` is removed."""
    basis = np.column_stack([np.ones_like(t), t - t[0]])
    coefficients, *_ = np.linalg.lstsq(basis, difference, rcond=None)
    return float(np.sqrt(np.mean((difference - basis @ coefficients) ** 2)))


class FillReplay:
    """The TCU's replay of one shift type (module docstring): its own model ``d`` (the
    calibration, never a vehicle's truth) of shift ``shift``."""

    def __init__(self, d: GearboxDescription, shift: str) -> None:
        self.d = d
        self.shift = shift
        self.nominal = ClutchActuator.from_calibration(d.control)
        self.i_d = quantity(d, "drivetrain", "i_D").value
        self.r_dyn = quantity(d, "vehicle", "r_dyn").value
        self.spec = shift_spec(d, shift)
        self._model: ClosedLoopShift | None = None

    def view(self, knowledge: Knowledge, fill_time: float) -> ClutchActuator:
        """The TCU's view of its actuator: the nominal one with ``knowledge``'s valve (gain and
        offset, which its commands were corrected for) and the fill time ``fill_time``."""
        return replace(
            self.nominal,
            fill_time=fill_time,
            pressure_gain=knowledge.valve_gain,
            pressure_offset=knowledge.valve_offset,
        )

    def parameter(self, knowledge: Knowledge, duration: float) -> float:
        """The fill time of the TCU's view (:meth:`view`) whose piston strokes in ``duration``
        (s) at the fast-fill command: what its controller commands the fast fill for is a
        stroke time through its view of the valve, the view's fill time is at the nominal
        fast-fill pressure (the fill law, :meth:`ClutchActuator.stroke_time`)."""
        view = self.view(knowledge, self.nominal.fill_time)
        above = view.valve_pressure(self.nominal.fast_fill_pressure) - view.return_spring
        return duration * above / (view.fast_fill_pressure - view.return_spring)

    def duration(self, knowledge: Knowledge, fill_time: float) -> float:
        """How long the view with ``fill_time`` strokes at the fast-fill command (s): the
        inverse of :meth:`parameter`."""
        view = self.view(knowledge, fill_time)
        return view.stroke_time(self.nominal.fast_fill_pressure)

    def _plant(self, vehicle_speed: float, knowledge: Knowledge) -> ClosedLoopShift:
        if self._model is None or self._model.vehicle_speed != vehicle_speed:
            self._model = ClosedLoopShift(self.d, self.shift, vehicle_speed)
        model = self._model
        values = dict(model.simulator.values())
        values["m_veh"] = knowledge.m_veh
        values[naming.GRADE] = knowledge.zeta
        for e, symbol in model.simulator.hybrid.friction_coefficient.items():
            if e in knowledge.mu:
                values[str(symbol)] = knowledge.mu[e]
        model.values = values
        model.p = model.simulator.parameter_vector(values)
        return model

    def residual(
        self,
        delta: float,
        knowledge: Knowledge,
        log: Mapping[str, np.ndarray],
        commands: Mapping[str, np.ndarray],
        phases: Sequence[str],
    ) -> float:
        """The detrended RMS (rad/s) between the measured input speed and the replay's with
        the fill time off by ``delta`` (s), over the window of :meth:`window`."""
        t = np.asarray(log["t"], dtype=float)
        t = t - t[0]
        n = self.window(phases, len(t))
        measured = np.asarray(log[f"omega_{self.d.input_shaft}"], dtype=float)[:n]
        output = float(log[f"omega_{self.d.output_shaft}"][0])
        plant = self._plant(output / self.i_d * self.r_dyn, knowledge)
        # a fill shorter than a millisecond is an instant one (the actuator needs t_fill > 0)
        fill_time = max(self.nominal.fill_time + delta, 1e-3)
        believed = self.view(knowledge, fill_time)
        elements = (plant.spec.off_going, plant.spec.on_coming)
        torque = float(log["T_In_cmd"][0])
        try:
            result = plant.run(
                _Replay(commands, phases),
                torque,
                knowledge.torque_gain * torque,
                {e: believed for e in elements},
                {e: self.nominal for e in elements},
                t_end=n * TICK,
            )
        except GearsymError:
            # the TCU's model cannot follow this fill (e.g. an element's break-away chatters
            # in its model): that fill does not explain the record, the others are tried
            return math.inf
        every = int(round(TICK / float(result.t[1] - result.t[0])))
        replayed = result.signals[naming.speed(self.d.input_shaft)][::every][:n]
        return _detrended_rms(measured[: len(replayed)] - replayed, t[: len(replayed)])

    def window(self, phases: Sequence[str], n_ticks: int) -> int:
        """Ticks compared: up to :data:`AFTER_TORQUE_PHASE` past the inertia phase's start
        (the whole record when it never got there)."""
        if "inertia" not in phases:
            return n_ticks
        start = list(phases).index("inertia")
        return min(start + int(round(AFTER_TORQUE_PHASE / TICK)), n_ticks)

    @staticmethod
    def _plateau_edge(
        grid: Sequence[float], costs: Sequence[float], centre: int, cost: Callable[[float], float]
    ) -> tuple[float, float] | None:
        """The edge nearest the centre of a plateau of the grid's lowest residual, or None.

        A fill so late that the replay's piston has not stroked by the window's end gives the
        same replay whatever its δ beyond that: the residual is flat out to the search's edge
        (on the tuning vehicle 100004, 35 ms late behind a valve 100 mbar low, flat from
        δ = +50 ms on, and the estimate landed at +60 ms: the next shift tied up). Such a
        record says only that the fill is at least so long; of the fills it cannot tell apart
        (residuals within :data:`RESIDUAL_FLOOR`, the speed sensors' resolution) the one
        nearest the fill the shift assumed is taken: a fill commanded too long ties the
        elements up, one too short flares a little and the next record pins it down. The
        edge is refined by bisection to :data:`EDGE_TOLERANCE` (the last δ towards the
        centre still on the plateau). Any run of grid points around the lowest residual within
        that resolution counts, also a valley's flat bottom between two points (a minimum about
        halfway between them): it is taken at its side nearest the assumed fill, and with no
        variance credited it moves the belief only where it explains the record outright
        (:meth:`FillBelief.after`); on the 100 evaluation vehicles (2 000 shifts) 11 estimates
        were one-sided, 10 of them late fills whose plateau ran to the search's end."""
        best = int(np.argmin(costs))
        level = costs[best] + RESIDUAL_FLOOR
        on = [k for k in range(len(costs)) if costs[k] <= level]
        low, high = best, best
        while low - 1 in on:
            low -= 1
        while high + 1 in on:
            high += 1
        if low == high:
            return None
        inner = low if abs(low - centre) <= abs(high - centre) else high
        outer = inner - 1 if inner == low else inner + 1
        inside, outside = grid[inner], grid[outer] if 0 <= outer < len(grid) else None
        rms = costs[inner]
        if outside is not None:
            while abs(outside - inside) > EDGE_TOLERANCE:
                middle = (inside + outside) / 2
                value = cost(middle)
                if value <= level:
                    inside, rms = middle, value
                else:
                    outside = middle
        return float(inside), float(rms)

    def estimate(
        self,
        knowledge: Knowledge,
        log: Mapping[str, np.ndarray],
        commands: Mapping[str, np.ndarray],
        phases: Sequence[str],
        offset_sigma: float = 0.0,
    ) -> FillEstimate:
        """δ minimising :meth:`residual` within ±:data:`FILL_SEARCH` about the fill the
        shift was commanded with: a grid every :data:`GRID_STEP`, then bounded Brent about
        its best point, to 1 ms.

        With ``offset_sigma`` (Pa, the TCU's doubt of its valve's offset) δ is searched
        jointly with the offset, over :data:`OFFSET_GRID` of those σ about ``knowledge``'s:
        an offset changes the pressure over the whole shift, and a replay that holds it at a
        wrong value makes up for the on-coming torque it gets wrong with a wrong fill (a
        valve 100 mbar low flares the input like a piston stroked 20 ms late). δ is then the
        piston's own fill time (at the nominal fast fill through a valve without offset), the
        offset the replay's :attr:`FillEstimate.offset`."""
        from scipy.optimize import minimize_scalar

        def cost(delta: float, offset: float) -> float:
            view = replace(knowledge, valve_offset=offset)
            return self.residual(delta, view, log, commands, phases)

        # the search is centred on what this shift assumed, where the answer most likely is
        commanded = self.nominal.fill_time if knowledge.fill_time is None else knowledge.fill_time
        believed = self.parameter(knowledge, commanded + knowledge.fill_offset)
        centre = believed - self.nominal.fill_time
        # the residual is not unimodal far from its minimum (an early fill's tie-up first
        # grows, then its shock moves out of the window): a grid picks the valley, the
        # bounded Brent search refines inside it; between grid points the residual has small
        # dips of its own (a fill ending inside a 10 ms tick), so the grid is not coarser
        step = GRID_STEP
        n = int(round(FILL_SEARCH / step))
        grid = [centre + k * step for k in range(-n, n + 1)]
        assumed = knowledge.valve_offset
        offsets = [assumed + k * offset_sigma for k in OFFSET_GRID] if offset_sigma > 0 else []
        offsets = [assumed, *[o for o in offsets if o != assumed]]
        table = {o: [cost(delta, o) for delta in grid] for o in offsets}
        offset = min(offsets, key=lambda o: min(table[o]))
        costs = table[offset]
        best = grid[int(np.argmin(costs))]
        # the record cannot tell a plateau's fills apart: it bounds the fill from one side
        edge = self._plateau_edge(grid, costs, n, lambda x: cost(x, offset))

        def refine_delta(around: float, at: float) -> tuple[float, float]:
            found = minimize_scalar(
                lambda x: cost(x, at),
                bounds=(around - step, around + step),
                method="bounded",
                options={"xatol": 1e-3},
            )
            return float(found.x), float(found.fun)

        if edge is None:
            delta, rms = refine_delta(best, offset)
            if min(costs) < rms:
                delta, rms = best, min(costs)
        else:
            delta, rms = edge
        if offset_sigma > 0:
            # the offset refined at that δ (to 1 mbar), then δ once more at that offset
            found = minimize_scalar(
                lambda o: cost(delta, o),
                bounds=(offset - offset_sigma, offset + offset_sigma),
                method="bounded",
                options={"xatol": 100.0},
            )
            if float(found.fun) < rms:
                offset, rms = float(found.x), float(found.fun)
                if edge is None:
                    again, again_rms = refine_delta(delta, offset)
                    if again_rms < rms:
                        delta, rms = again, again_rms
                else:
                    at = offset
                    edge = self._plateau_edge(
                        grid, [cost(x, at) for x in grid], n, lambda x: cost(x, at)
                    )
                    if edge is not None:
                        delta, rms = edge
        # how sharply the record pins δ down: the residual one grid step either side (a side
        # the TCU's model cannot follow counts as the other's)
        sides = [cost(delta - step, offset), cost(delta + step, offset)]
        finite = [c for c in sides if math.isfinite(c)]
        side = math.sqrt(sum(c**2 for c in finite) / len(finite)) if finite else math.inf
        one_sided = edge is not None
        return FillEstimate(delta, rms, side, table[assumed][n], offset, one_sided)
