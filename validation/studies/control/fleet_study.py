"""The adaptive-control study over a fleet (``gearsym control``): every vehicle shifts the same
shift ``n`` times per strategy (:func:`.study.run_vehicle`), one task per vehicle in this
process or on Dask (:mod:`gearsym.validation.studies.dask_runner`); per strategy and shift
index the fleet's percentiles of each quality metric, the shifts each strategy needs to meet
its duration target, and the shift from which it stays within 10 % of the oracle (no more
than 10 % above it: lower is as good)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.studies.control.study import OperatingPoint

__all__ = ["ControlContext", "ControlFleet", "control_vehicle", "run_control_fleet"]

WHERE = ("control", "--scheduler")
#: "Within 10 % of the oracle" (the adaptive-control issue's measure).
ORACLE_MARGIN = 0.10
#: The shift whose traces the plot shows (the second: every strategy has learned once).
TRACE_SHIFT = 2


@dataclass(frozen=True)
class ControlContext:
    """What every vehicle's task carries."""

    description: GearboxDescription
    shift: str
    point: OperatingPoint
    fleet: Any
    strategies: tuple[str, ...]
    n_shifts: int
    trace_seed: int | None = None


def _trace(record: Any, d: GearboxDescription) -> dict[str, list[float]]:
    """One shift's signals for the plot: the commands per tick, the speeds, the output
    torque and the jerk on the record's grid."""
    from gearsym.symbolic import naming
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.validation.sim.drive_shift import vehicle_jerk
    from gearsym.validation.studies.control.closed_loop import output_torque

    signals = record.signals
    spec = record.spec
    r_dyn = quantity(d, "vehicle", "r_dyn").value
    dt = float(record.t[1] - record.t[0])
    v = signals[naming.WHEEL_SPEED] * r_dyn
    return {
        "t": record.t.tolist(),
        "ticks": record.ticks.tolist(),
        "p_off": record.commands[spec.off_going].tolist(),
        "p_on": record.commands[spec.on_coming].tolist(),
        "omega_in": signals[naming.speed(d.input_shaft)].tolist(),
        "slip_on": signals[naming.slip_column(spec.on_coming)].tolist(),
        "output_torque": output_torque(d, record.values, signals).tolist(),
        "jerk": vehicle_jerk(v, dt).tolist(),
    }


def control_vehicle(context: ControlContext, seed: int) -> dict[str, Any]:
    """One vehicle ``seed`` of the fleet: every strategy's sequence of shifts (the sensors'
    noise of the estimator from the same seed). A vehicle whose simulation the model cannot
    carry through (a :class:`~gearsym.symbolic.errors.GearsymError` of the hybrid simulation:
    chattering, a failed integration) is returned with ``"failed"``, its reason, and no
    shifts: the fleet goes on and reports it (:attr:`ControlFleet.failed`)."""
    from gearsym.validation.studies.control.study import Vehicle, run_vehicle

    d = context.description
    draw = context.fleet.draw(seed)
    vehicle = Vehicle.from_draw(d, draw)
    keep = seed == context.trace_seed
    try:
        outcomes = run_vehicle(
            d,
            context.shift,
            context.point,
            vehicle,
            context.n_shifts,
            context.strategies,
            seed=seed,
            keep_records=keep,
        )
    except GearsymError as err:
        return {"seed": seed, "vehicle": draw.to_dict(), "failed": str(err)}
    out: dict[str, Any] = {
        "seed": seed,
        "vehicle": draw.to_dict(),
        "strategies": {name: [o.to_dict() for o in shifts] for name, shifts in outcomes.items()},
    }
    if keep:
        out["traces"] = {
            name: _trace(shifts[min(TRACE_SHIFT, len(shifts)) - 1].record, vehicle.description)
            for name, shifts in outcomes.items()
        }
    return out


def _p95(values: Sequence[float]) -> float | None:
    finite = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.percentile(finite, 95)) if finite else None


def _p95_or_none(values: Sequence[float]) -> float | None:
    """p95 where a value may be infinite (a shift that never locked): the nearest rank above
    (no interpolation towards infinity); None (JSON null) when that rank is infinite."""
    value = float(np.percentile(values, 95, method="higher"))
    return value if np.isfinite(value) else None


@dataclass
class ControlFleet:
    """Every vehicle's sequences and the fleet's statistics per strategy and shift."""

    shift: str
    point: OperatingPoint
    strategies: tuple[str, ...]
    n_shifts: int
    runs: list[dict[str, Any]]
    fleet_name: str
    traces: dict[str, Any] = field(default_factory=dict)

    @property
    def completed(self) -> list[dict[str, Any]]:
        """The vehicles whose every strategy's sequence ran (the statistics are theirs)."""
        return [r for r in self.runs if "failed" not in r]

    @property
    def failed(self) -> list[dict[str, Any]]:
        """The vehicles the simulation could not carry through: seed and reason."""
        return [{"seed": r["seed"], "reason": r["failed"]} for r in self.runs if "failed" in r]

    def per_shift(self, strategy: str) -> list[dict[str, Any]]:
        """Per shift index: mean and p95 of peak |jerk| (m/s³), p95 of the VDV (m/s^1.75),
        of |duration error| (relative; a shift that never locked counts as not met) and of
        the friction energy of both elements (J; the duration's p95 by the nearest rank above, None
        when that is a shift that never locked), the count of flares, of tie-ups (the
        off-going element held against the on-coming one) and of output-torque dips below
        the to-gear's steady torque, and how many shifts failed."""
        out = []
        for i in range(self.n_shifts):
            shifts = [r["strategies"][strategy][i] for r in self.completed]
            jerks = [s["peak_jerk"] for s in shifts]
            errors = [
                abs(s["duration_error"]) if np.isfinite(s["duration_error"]) else np.inf
                for s in shifts
            ]
            energy = [sum(s["friction_energy"].values()) for s in shifts]
            out.append(
                {
                    "shift": i + 1,
                    "jerk_mean": float(np.mean(jerks)),
                    "jerk_p95": _p95(jerks),
                    "vdv_p95": _p95([s["vdv"] for s in shifts]),
                    "duration_error_p95": _p95_or_none(errors),
                    "friction_energy_p95": _p95(energy),
                    "flares": int(sum(bool(s["flare"]) for s in shifts)),
                    "tie_ups": int(sum(bool(s["reversal_tie_up"]) for s in shifts)),
                    "output_dips": int(sum(bool(s["tie_up"]) for s in shifts)),
                    "failed": int(sum(not s["completed"] for s in shifts)),
                }
            )
        return out

    def shifts_to_converge(self, strategy: str) -> dict[str, Any]:
        """Per vehicle the first shift of three in a row with |duration error| < 10 %
        (:func:`.quality.shifts_to_converge`); median and p95 over the fleet by the nearest
        rank above, a vehicle that never gets there counted as beyond the sequence (None when
        that rank is such a vehicle)."""
        from gearsym.validation.studies.control.quality import shifts_to_converge

        counts = []
        for r in self.completed:
            errors = [s["duration_error"] for s in r["strategies"][strategy]]
            k = shifts_to_converge(errors)
            counts.append(np.inf if k is None else float(k))
        # nearest rank above: no interpolation towards a vehicle that never gets there
        median, p95 = (float(np.percentile(counts, q, method="higher")) for q in (50, 95))
        return {
            "median": median if np.isfinite(median) else None,
            "p95": p95 if np.isfinite(p95) else None,
            "never": int(sum(not np.isfinite(c) for c in counts)),
        }

    def near_oracle(self, strategy: str) -> int | None:
        """The first shift from which the strategy's p95 |jerk| and p95 friction energy stay
        within :data:`ORACLE_MARGIN` of the oracle's at the same shift (None: never; the
        oracle not run: None)."""
        if "oracle" not in self.strategies:
            return None
        mine, oracle = self.per_shift(strategy), self.per_shift("oracle")

        def close(a: dict[str, Any], b: dict[str, Any]) -> bool:
            return all(
                a[k] is not None and b[k] is not None and a[k] <= (1.0 + ORACLE_MARGIN) * b[k]
                for k in ("jerk_p95", "friction_energy_p95")
            )

        ok = [close(a, b) for a, b in zip(mine, oracle, strict=True)]
        for i in range(len(ok)):
            if all(ok[i:]):
                return i + 1
        return None

    def to_dict(self) -> dict[str, Any]:
        return {
            "shift": self.shift,
            "operating_point": {
                "vehicle_speed_m_s": self.point.vehicle_speed,
                "engine_Nm": self.point.engine,
                "e_machine_Nm": self.point.e_machine,
            },
            "fleet": self.fleet_name,
            "vehicles": len(self.completed),
            "seeds": [r["seed"] for r in self.completed],
            "vehicles_failed": self.failed,
            "shifts_per_vehicle": self.n_shifts,
            "strategies": {
                name: {
                    "per_shift": self.per_shift(name),
                    "shifts_to_converge": self.shifts_to_converge(name),
                    "near_oracle_from_shift": self.near_oracle(name),
                }
                for name in self.strategies
            },
        }


def run_control_fleet(
    d: GearboxDescription,
    shift: str,
    point: OperatingPoint,
    fleet: Any,
    seeds: Sequence[int],
    strategies: Sequence[str],
    n_shifts: int,
    scheduler: str | None = None,
    workers: int = 2,
    progress: Callable[[int, int], None] | None = None,
) -> ControlFleet:
    """Every vehicle of ``seeds`` (:func:`control_vehicle`), in this process (``scheduler``
    None) or on Dask (``"local"``: a LocalCluster of ``workers``; ``tcp://HOST:PORT``). The
    first vehicle's :data:`TRACE_SHIFT`-th shift is kept for the plot."""
    context = ControlContext(
        d, shift, point, fleet, tuple(strategies), n_shifts, trace_seed=seeds[0]
    )
    from gearsym.validation.studies.dask_runner import run_each

    runs = run_each(control_vehicle, context, list(seeds), scheduler, workers, WHERE, progress)
    if runs and all("failed" in r for r in runs):
        first = runs[0]
        raise GearsymError(
            "control",
            "--seed",
            f"every vehicle failed ({len(runs)}); vehicle {first['seed']}: {first['failed']}",
        )
    traces = runs[0].pop("traces", {}) if runs else {}
    return ControlFleet(
        shift,
        point,
        tuple(strategies),
        n_shifts,
        runs,
        getattr(fleet, "name", "fleet"),
        traces,
    )
