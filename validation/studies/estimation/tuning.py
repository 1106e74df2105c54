"""Tuning the EKF's model-error intensities on a fleet, apart from any evaluation.

The filter's model is rigid and holds its inputs over a sample; the truth is elastic, its μ
follows a slip-dependent map and its inputs ramp. The model-error intensities q_x of the states
(4.1) stand for that mismatch and must be chosen on data, so they are chosen on **tuning
seeds** of a fleet (each seed its own vehicle and noise) that no evaluation uses: one common
factor c on the calibration's current q_x, the grid :data:`FACTORS`, the criterion NEES/dof and
NIS/dof (each summed over runs and samples, divided by its summed dof) both near 1: the
smallest (ln NEES/dof)² + (ln NIS/dof)². The calibration engineer copies the chosen values into
the description's ``[estimator.model_error]`` table and names the fleet and seeds in
``tuned_on``; an evaluation then runs on other seeds (``make results``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.sim.fleet import Fleet
from gearsym.validation.sim.scenario import Scenario

if TYPE_CHECKING:
    from gearsym.validation.studies.estimation.fleet_eval import FilterModel, FleetContext

__all__ = [
    "FACTORS",
    "IN_GEAR_FACTORS",
    "TWIST_FACTORS",
    "TuningResult",
    "tune_model_error",
    "tuning_sums",
]

#: The factors on the speeds' model-error intensities tried (around the description's).
FACTORS: tuple[float, ...] = (0.5, 1.0, 2.0)
#: The factors on the twist φ's model-error intensity tried: around the description's, √10
#: apart (the twist's intensity stands for errors of the fleet that the speeds' do not: the
#: stiffness tolerance and the torque errors, and moves by decades between filters with and
#: without the stiffness as a state).
TWIST_FACTORS: tuple[float, ...] = (0.01, 0.0316, 0.1, 0.316, 1.0, 3.16)
#: The factors g on the table's ``in_gear`` factor (the physical states' intensities over an
#: interval in which no element slides, :attr:`~gearsym.symbolic.estimators.ekf.AugmentedModel.
#: in_gear_factor`): by default one, the table's own (no axis); ``--tune-in-gear`` sets an axis
#: (the gears and the shift phases then get intensities of their own).
IN_GEAR_FACTORS: tuple[float, ...] = (1.0,)


@dataclass(frozen=True)
class TuningResult:
    """Per triple of factors (c on the speeds, c_φ on the twist, g on the in-gear factor):
    NEES/dof and NIS/dof over the tuning runs; the chosen triple and the intensities it gives,
    by state name (with ``in_gear`` where the grid had an in-gear axis or the table a factor)."""

    fleet: str
    seeds: tuple[int, ...]
    factors: tuple[tuple[float, float, float], ...]  # (c, c_φ, g)
    nees_per_dof: tuple[float, ...]
    nis_per_dof: tuple[float, ...]
    chosen: tuple[float, float, float]
    intensities: dict[str, float]
    base: dict[str, float]
    #: the description's table the intensities belong in (``model_error``, or
    #: ``model_error_augmented`` for a filter that estimates more than the thesis' parameters,
    #: ``model_error_map_scale`` for such a filter with its μ states map scales)
    table: str = "model_error"
    #: the known inputs over a prediction interval the filter was tuned with
    #: (:attr:`~gearsym.validation.studies.estimation.setup.EkfSetup.input_hold`)
    input_hold: str = "sample"
    #: the shifts tuned on (every tuning vehicle runs each; the sums are over all of them)
    shifts: tuple[str, ...] = ()
    #: per shift: its own NEES/dof and NIS/dof per grid point (its vehicles' sums alone)
    per_shift: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = field(default_factory=dict)
    #: how the grid point was chosen: ``"pooled"`` (the criterion of the sums over every
    #: shift) or ``"per_shift"`` (the sum over the shifts of each shift's own criterion)
    criterion_form: str = "pooled"

    def criterion(self, k: int) -> float:
        """Grid point ``k``'s criterion in :attr:`criterion_form`."""
        if self.criterion_form == "per_shift" and self.per_shift:
            return sum(_criterion(a[k], b[k]) for a, b in self.per_shift.values())
        return _criterion(self.nees_per_dof[k], self.nis_per_dof[k])

    def to_dict(self) -> dict[str, Any]:
        return {
            "fleet": self.fleet,
            "seeds": [self.seeds[0], self.seeds[-1]],
            "factors": [list(f) for f in self.factors],
            "nees_per_dof": list(self.nees_per_dof),
            "nis_per_dof": list(self.nis_per_dof),
            "chosen_factors": list(self.chosen),
            "model_error": self.intensities,
            "table": f"estimator.{self.table}",
            "from": self.base,
            "input_hold": self.input_hold,
            "shifts": list(self.shifts),
            "criterion": self.criterion_form,
            "per_shift": {
                shift: {"nees_per_dof": list(a), "nis_per_dof": list(b)}
                for shift, (a, b) in self.per_shift.items()
            },
        }

    def text(self) -> str:
        lines = [
            f"  tuned on the fleet {self.fleet}, seeds {self.seeds[0]}-{self.seeds[-1]} "
            f"({len(self.seeds)} vehicles) on the shift(s) {', '.join(self.shifts)}: factors c on "
            "the speeds' and c_phi on the twist's model-error intensities, g on their in-gear "
            f"factor (the inputs held over an interval: {self.input_hold})",
            f"    {'c':>6} {'c_phi':>7} {'g':>6} {'NEES/dof':>9} {'NIS/dof':>9} {'criterion':>10}",
        ]
        for k, (c, c_phi, g) in enumerate(self.factors):
            mark = "  <- chosen" if (c, c_phi, g) == self.chosen else ""
            lines.append(
                f"    {c:>6g} {c_phi:>7g} {g:>6g} {self.nees_per_dof[k]:>9.3f} "
                f"{self.nis_per_dof[k]:>9.3f} {self.criterion(k):>10.4f}{mark}"
            )
        chosen = self.factors.index(self.chosen)
        if len(self.per_shift) > 1:
            lines.append(f"  per shift at the chosen factors (criterion: {self.criterion_form}):")
            for shift, (a, b) in self.per_shift.items():
                lines.append(f"    {shift}: NEES/dof {a[chosen]:.3f}, NIS/dof {b[chosen]:.3f}")
        lines.append(f"  for the description's [estimator.{self.table}] table:")
        for name, value in self.intensities.items():
            lines.append(f"    {name} = {value:.3g}")
        return "\n".join(lines)


def tune_model_error(
    d: GearboxDescription,
    scenario: Scenario | Sequence[Scenario],
    fleet: Fleet,
    seeds: Sequence[int],
    sample_time: float = 0.01,
    relative_noise: Any = 0.01,
    factors: Sequence[float] = FACTORS,
    twist_factors: Sequence[float] = TWIST_FACTORS,
    in_gear_factors: Sequence[float] = IN_GEAR_FACTORS,
    progress: Callable[[float, str], None] | None = None,
    client: Any = None,
    parameters: Sequence[str] | None = None,
    input_hold: str = "sample",
    criterion: str = "pooled",
) -> TuningResult:
    """Choose the factors on the calibration's model-error intensities (module text): every
    tuning vehicle simulated once, the filter run once per pair of factors on the same
    noise. ``client``: a ``dask.distributed`` client; the vehicles then run on its workers
    (:func:`~gearsym.validation.studies.estimation.fleet_eval.each_vehicle`), the same
    numbers as without. ``parameters``: the filter's augmented parameters (``None``: the
    thesis' 4.1), e.g. with the side shafts' stiffness k_ss. ``input_hold``: the known
    inputs over a prediction interval (``"sample"`` or the interval's ``"mean"``), as the
    evaluation that will use the intensities runs. ``scenario``: one shift, or several (every
    tuning vehicle runs each, and NEES and NIS are summed over all of them): one calibration's
    intensities for every shift it serves. ``in_gear_factors``: the factors g on the table's
    in-gear factor (``in_gear``, 1 where it has none) tried, every triple (c, c_φ, g) of the
    grid on the same runs. ``criterion``: ``"pooled"``, (ln NEES/dof)² + (ln NIS/dof)² of the
    sums over every shift, or ``"per_shift"``, the sum over the shifts of each one's own: a
    shift whose NIS is low cannot hide behind another's high one."""
    if criterion not in ("pooled", "per_shift"):
        raise GearsymError("estimate", "--tune-criterion", f"unknown criterion {criterion!r}")
    from gearsym.symbolic import naming
    from gearsym.symbolic.estimator_calibration import (
        AUGMENTED_STATES,
        IN_GEAR,
        MODEL_ERROR_AUGMENTED,
        MODEL_ERROR_MAP_SCALE,
    )
    from gearsym.validation.studies.estimation.fleet_eval import (
        FleetContext,
        calibration_setup,
        each_vehicle,
        filter_model,
    )

    # a filter that estimates more than the thesis' parameters has its own table
    augmented = parameters is not None and any(p in AUGMENTED_STATES for p in parameters)
    table = MODEL_ERROR_AUGMENTED if augmented else "model_error"
    if augmented and d.estimator.mu_model == "map_scale":  # ... with μ as map scales: its own
        table = MODEL_ERROR_MAP_SCALE
    if not seeds:
        raise GearsymError("estimate", "--runs", "tuning needs at least one seed")
    report = progress or (lambda fraction, message: None)
    scenarios = (scenario,) if isinstance(scenario, Scenario) else tuple(scenario)
    if not scenarios:
        raise GearsymError("estimate", "--scenario", "tuning needs at least one shift")
    grid = [
        (float(c), float(c_phi), float(g))
        for c in factors
        for c_phi in twist_factors
        for g in in_gear_factors
    ]
    if any(g <= 0.0 or not math.isfinite(g) for _, _, g in grid):
        raise GearsymError("estimate", "--tune-in-gear", "the in-gear factors must be > 0")
    sums = np.zeros((len(grid), 4))  # NEES, its dof, NIS, its dof
    own_sums: dict[str, np.ndarray] = {}  # the same per shift
    in_gear, in_gear_settle = 1.0, 0.0  # the group's in-gear factor and settling time
    base: dict[str, float] = {}
    for number, shift_scenario in enumerate(scenarios):
        own_parameters = _shift_parameters(
            d, scenarios[0].shift.name, shift_scenario.shift.name, parameters
        )
        model = filter_model(d, shift_scenario.shift.name, parameters=own_parameters)
        aug = model.aug
        nominal = calibration_setup(d, shift_scenario, model, sample_time, relative_noise)
        n_x = aug.n_x
        names = aug.state_names[:n_x]
        own = {name: float(q) for name, q in zip(names, nominal.q, strict=False)}
        if base and own != base:  # one factor per group scales every shift's intensities
            raise GearsymError(
                "estimate",
                "--tune-scenario",
                f"the {shift_scenario.shift.name} filter's model-error states or intensities "
                f"({', '.join(own)}) differ from the {scenarios[0].shift.name} filter's "
                f"({', '.join(base)}): tune them apart",
            )
        base = own
        # the in-gear factor is one per group too: a shift type with its own (a shift."a-b"
        # sub-table) would otherwise be reported with another's
        own_gear = (aug.in_gear_factor, aug.in_gear_settle)
        if number and own_gear != (in_gear, in_gear_settle):
            raise GearsymError(
                "estimate",
                "--tune-scenario",
                f"the {shift_scenario.shift.name} filter's in-gear factor and settling time "
                f"{own_gear} differ from the {scenarios[0].shift.name} filter's "
                f"{(in_gear, in_gear_settle)}: tune them apart",
            )
        in_gear, in_gear_settle = own_gear
        context = FleetContext(
            d,
            shift_scenario,
            fleet,
            sample_time,
            relative_noise,
            "filter",
            nominal.floor,
            nominal.t,
            parameters=own_parameters,
            input_hold=input_hold,
        )

        def told(done: int, total: int, outcome: Any, number: int = number) -> None:
            overall = number * total + done
            report(
                overall / (total * len(scenarios)),
                f"vehicle {overall} of {total * len(scenarios)}",
            )

        outcomes = each_vehicle(
            list(seeds),
            lambda seed, context=context, model=model: tuning_sums(context, model, seed, grid),
            _tuning_task,
            context,
            client,
            told,
            args=(grid,),
        )
        shift_sums = np.zeros((len(grid), 4))
        for vehicle in outcomes:
            if vehicle is not None:  # a vehicle the reference cannot simulate does not tune
                shift_sums += vehicle
        name = shift_scenario.shift.name
        own_sums[name] = own_sums.get(name, np.zeros_like(shift_sums)) + shift_sums
        sums += shift_sums
    nees = tuple(float(v) for v in sums[:, 0] / sums[:, 1])
    nis = tuple(float(v) for v in sums[:, 2] / sums[:, 3])
    per_shift = {
        name: (
            tuple(float(v) for v in own[:, 0] / own[:, 1]),
            tuple(float(v) for v in own[:, 2] / own[:, 3]),
        )
        for name, own in own_sums.items()
    }
    if criterion == "per_shift":
        scores = [
            sum(_criterion(a[k], b[k]) for a, b in per_shift.values()) for k in range(len(grid))
        ]
    else:
        scores = [_criterion(a, b) for a, b in zip(nees, nis, strict=True)]
    best = int(np.argmin(scores))
    chosen = grid[best]
    intensities = {
        name: (chosen[1] if name == naming.TWIST else chosen[0]) * q for name, q in base.items()
    }
    if tuple(in_gear_factors) != IN_GEAR_FACTORS or in_gear != 1.0:
        intensities[IN_GEAR] = chosen[2] * in_gear
    return TuningResult(
        fleet=f"{fleet.name} ({fleet.file})",
        seeds=tuple(seeds),
        factors=tuple(grid),
        nees_per_dof=nees,
        nis_per_dof=nis,
        chosen=chosen,
        intensities=intensities,
        table=table,
        base=base,
        input_hold=input_hold,
        shifts=tuple(sc.shift.name for sc in scenarios),
        per_shift=per_shift,
        criterion_form=criterion,
    )


def _criterion(nees_per_dof: float, nis_per_dof: float) -> float:
    """(ln NEES/dof)² + (ln NIS/dof)²: 0 for a consistent filter, a factor too much or too
    little of either counting alike."""
    return math.log(nees_per_dof) ** 2 + math.log(nis_per_dof) ** 2


def _shift_parameters(
    d: GearboxDescription, first: str, shift: str, parameters: Sequence[str] | None
) -> tuple[str, ...] | None:
    """The augmented parameters of ``shift``'s filter given those of the ``first`` shift's: the
    off-going and the on-coming element's μ (4.1) replaced by ``shift``'s own, everything else
    (m_veh, ζ, the fleet's tolerances) kept."""
    from gearsym.symbolic.estimators.ekf import default_parameters

    if parameters is None or shift == first:
        return None if parameters is None else tuple(parameters)
    swap = dict(
        zip(default_parameters(d, first)[1:3], default_parameters(d, shift)[1:3], strict=True)
    )
    return tuple(swap.get(name, name) for name in parameters)


def tuning_sums(
    context: FleetContext,
    model: FilterModel,
    seed: int,
    grid: Sequence[tuple[float, float, float]],
) -> np.ndarray | None:
    """One tuning vehicle: per triple of factors (c, c_φ, g) of ``grid`` the filter's summed
    NEES, its dof, summed NIS and its dof over the run (one row each); ``None`` when the
    reference cannot simulate the vehicle. g multiplies the filter's in-gear factor: its
    model (prediction and bound) a copy with the factor, the compiled step shared."""
    import copy
    import dataclasses

    from gearsym.symbolic import naming
    from gearsym.validation.studies.estimation.fleet_eval import vehicle_setup
    from gearsym.validation.studies.estimation.loop import filter_run

    found = vehicle_setup(context, model, seed)
    if isinstance(found, str):
        return None
    _, setup, _ = found
    n_x = model.aug.n_x
    twist = model.aug.state_names.index(naming.TWIST)
    sums = np.zeros((len(grid), 4))
    q0 = list(setup.q)
    aug0, discrete0 = setup.aug, setup.discrete
    for k, (c, c_phi, g) in enumerate(grid):
        setup.q = [(c_phi if j == twist else c) * q if j < n_x else q for j, q in enumerate(q0)]
        setup.aug = dataclasses.replace(aug0, in_gear_factor=g * aug0.in_gear_factor)
        setup.discrete = copy.copy(discrete0)
        setup.discrete.aug = setup.aug
        run = filter_run(setup, seed)
        used = run.nis_dof > 0
        sums[k] = (
            float(np.sum(run.nees)),
            float(np.sum(run.nees_dof)),
            float(np.sum(run.nis[used])),
            float(np.sum(run.nis_dof[used])),
        )
    return sums


def _tuning_task(
    context: Any, seed: int, grid: Sequence[tuple[float, float, float]]
) -> np.ndarray | None:
    """:func:`tuning_sums` on a Dask worker, with the worker's own filter model."""
    return tuning_sums(context, context.model(), seed, grid)
