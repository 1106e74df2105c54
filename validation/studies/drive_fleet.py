"""Drives of a fleet (``gearsym drive --fleet --runs N``): each vehicle of the fleet drives the
cycle with the TCU's calibration, the EKF runs on each TCU log, and the mass error is gathered
over time as percentiles over the fleet. Each vehicle is one task, in this process or on Dask
(:mod:`gearsym.validation.studies.dask_runner`), as the fleet evaluation of the estimation
chapter does."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic.description import GearboxDescription
from gearsym.validation.sim.cycles import Cycle, GradeProfile
from gearsym.validation.sim.fleet import R_DYN_FACTOR, wheel_side_mass

__all__ = ["DriveFleet", "drive_vehicle", "fleet_aggregates", "fleet_targets", "run_drive_fleet"]

WHERE = ("drive", "--scheduler")

#: The times (s) at which the mass error is reported, beside the end.
REPORT_TIMES = (60.0, 300.0)

#: The drive issue's targets for the fleet's mass (p95 of the relative |error| at a report
#: time): 3 % after 300 s and 2 % at the end of WLTC 3b, without a grade sensor and with the
#: fleet's engine-torque error, against the literature's 5 % after minutes of driving.
MASS_TARGETS = {"300": 0.03, "end": 0.02}

#: Spacing of the error trace kept per vehicle (s).
TRACE_STEP = 1.0


@dataclass(frozen=True)
class DriveContext:
    """What every vehicle's task carries: the calibration, the cycle, the grade, the fleet."""

    description: GearboxDescription
    cycle: Cycle
    grade: GradeProfile | None
    fleet: Any


def drive_vehicle(context: DriveContext, seed: int) -> dict[str, Any]:
    """One vehicle ``seed`` of the fleet: its drive and the EKF on its TCU log (the sensors'
    noise from the same seed). Returns the drive's and the estimates' summaries and the mass
    error's trace every :data:`TRACE_STEP`."""
    from gearsym.validation.sim.drive import MIN_DWELL, DriveSimulator, DriveTruth
    from gearsym.validation.sim.drive_schedule import missed_shifts
    from gearsym.validation.studies.dask_runner import content_key, worker_cached
    from gearsym.validation.studies.estimation.drive_ekf import FilterModels, ekf_over_drive

    d = context.description
    draw = context.fleet.draw(seed)
    truth = DriveTruth.from_draw(d, draw, constant_grade=context.grade is None)
    # the calibration's models (the TCU's shift plans, the filter's) once per process: every
    # vehicle of the fleet has the same calibration
    planners = worker_cached(content_key("drive planners", d), dict)
    models = worker_cached(content_key("drive filter models", d), lambda: FilterModels.of(d))
    result = DriveSimulator(d, context.cycle, context.grade, truth=truth, planners=planners).run()
    out: dict[str, Any] = {"seed": seed, "vehicle": draw.to_dict(), "drive": result.to_dict()}
    out["drive"].pop("shift_list")
    out["drive"]["missed_shifts"] = len(missed_shifts(result, d.drive.schedule, MIN_DWELL))
    if result.failure or result.log is None:
        return out
    estimates = ekf_over_drive(d, result, seed, models=models)
    out["estimates"] = estimates.to_dict()
    out["estimator"] = estimates.summary()
    grid = np.arange(0.0, estimates.t[-1] + 1e-9, TRACE_STEP)
    index = np.searchsorted(estimates.t, grid)
    truth_mass = result.values["m_veh"]
    wheel_mass = wheel_side_mass(truth_mass, draw.get(R_DYN_FACTOR, 1.0))
    estimate = estimates.mean["m_veh"][index]
    out["wheel_side_mass"] = {"truth": wheel_mass, "final": float(estimates.mean["m_veh"][-1])}
    out["trace_t"] = grid.tolist()
    out["trace_mass_error"] = ((estimate - truth_mass) / truth_mass).tolist()
    out["trace_mass_sigma"] = (estimates.sigma["m_veh"][index] / truth_mass).tolist()
    out["trace_wheel_mass_error"] = ((estimate - wheel_mass) / wheel_mass).tolist()
    return out


@dataclass
class DriveFleet:
    """Every vehicle's summary and the fleet's percentiles of |mass error| over time."""

    cycle: Cycle
    runs: list[dict[str, Any]]
    fleet_name: str
    #: the whole fleet's wall time (s) and where it ran ("in one process", or on a Dask
    #: scheduler with its workers)
    wall_s: float = float("nan")
    ran_on: str = ""

    def percentiles(self, trace: str = "trace_mass_error") -> dict[str, Any]:
        """p50 and p95 of the relative |m_veh error| at :data:`REPORT_TIMES` and at the end,
        and over time (every :data:`TRACE_STEP`); ``trace="trace_wheel_mass_error"``: of the
        error against the wheel-side mass
        (:func:`~gearsym.validation.sim.fleet.wheel_side_mass`)."""
        done = [r for r in self.runs if trace in r]
        if not done:
            return {}
        length = min(len(r[trace]) for r in done)
        errors = np.abs(np.array([r[trace][:length] for r in done]))
        t = np.asarray(done[0]["trace_t"][:length])
        out: dict[str, Any] = {
            "vehicles": len(done),
            "t": t.tolist(),
            "p50": np.percentile(errors, 50, axis=0).tolist(),
            "p95": np.percentile(errors, 95, axis=0).tolist(),
            "error_at": {},
        }
        for time_ in (*REPORT_TIMES, None):
            k = len(t) - 1 if time_ is None else int(np.searchsorted(t, time_))
            if k >= len(t):
                continue
            key = "end" if time_ is None else f"{time_:g}"
            out["error_at"][key] = {
                "p50": float(np.percentile(errors[:, k], 50)),
                "p95": float(np.percentile(errors[:, k], 95)),
            }
        return out

    def grade_rms(self) -> dict[str, Any]:
        """p50 and p95 over the vehicles of each drive's RMS grade error (rad; over the whole
        drive and from :data:`~.estimation.drive_ekf.GRADE_RMS_FROM` on)."""
        from gearsym.symbolic import naming

        done = [r["estimates"][naming.GRADE]["rms_rad"] for r in self.runs if "estimates" in r]
        if not done:
            return {}
        return {
            key: {
                "p50": float(np.percentile([r[key] for r in done], 50)),
                "p95": float(np.percentile([r[key] for r in done], 95)),
            }
            for key in done[0]
        }

    def to_dict(self) -> dict[str, Any]:
        mass, wheel_side = self.percentiles(), self.percentiles("trace_wheel_mass_error")
        return {
            "cycle": self.cycle.to_dict(),
            "fleet": self.fleet_name,
            "runs": [{k: v for k, v in r.items() if not k.startswith("trace")} for r in self.runs],
            "failed": [r["seed"] for r in self.runs if r["drive"]["failure"]],
            "mass_error": mass,
            "wheel_side_mass_error": wheel_side,
            **fleet_aggregates(self.runs),
            "fleet_wall_s": self.wall_s,
            "ran_on": self.ran_on,
            "grade_rms_rad": self.grade_rms(),
            "targets": fleet_targets(mass, wheel_side),
        }


def fleet_targets(mass: dict[str, Any], wheel_side: dict[str, Any]) -> list[dict[str, Any]]:
    """Each of :data:`MASS_TARGETS` judged on the fleet's p95 of |m_veh error| and of the
    wheel-side mass's (``mass`` and ``wheel_side``: :meth:`DriveFleet.percentiles`): what,
    the bound, the value and ``met``/``missed`` (``not reached`` when the drive ended before
    the report time)."""
    out = []
    for label, stats in (("m_veh", mass), ("wheel-side mass", wheel_side)):
        for key, bound in MASS_TARGETS.items():
            entry = stats.get("error_at", {}).get(key)
            value = None if entry is None else float(entry["p95"])
            verdict = "not reached" if value is None else "met" if value <= bound else "missed"
            out.append(
                {"what": label, "at": key, "p95_bound": bound, "p95": value, "verdict": verdict}
            )
    return out


def end_normalized_errors(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The filter's consistency where the samples are independent: each vehicle's squared
    error over its own variance at the end of its drive, (x̂ − x)² / σ², for m_veh against its
    truth, against the wheel-side mass (the product the speeds carry, ``wheel_side_mass`` of
    each run) and for ζ; the mean over the N vehicles is χ²(N)/N for a consistent filter, so
    its two-sided 95 % band is [χ²₀.₀₂₅(N), χ²₀.₉₇₅(N)] / N (each vehicle its own draw and noise,
    one sample each: no correlation between them)."""
    from gearsym.symbolic import naming
    from scipy.stats import chi2

    values: dict[str, list[float]] = {"m_veh": [], "wheel-side mass": [], naming.GRADE: []}
    for run in runs:
        estimates = run["estimates"]
        mass = estimates["m_veh"]
        if not mass.get("sigma"):
            continue
        values["m_veh"].append(((mass["final"] - mass["truth"]) / mass["sigma"]) ** 2)
        wheel = run.get("wheel_side_mass")
        if wheel:
            values["wheel-side mass"].append(
                ((mass["final"] - wheel["truth"]) / mass["sigma"]) ** 2
            )
        grade = estimates.get(naming.GRADE, {})
        if grade.get("sigma"):
            values[naming.GRADE].append(((grade["final"] - grade["truth"]) / grade["sigma"]) ** 2)
    out = {}
    for name, squares in values.items():
        if not squares:
            continue
        n = len(squares)
        low, high = (float(chi2.ppf(q, n) / n) for q in (0.025, 0.975))
        mean = float(np.mean(squares))
        out[name] = {
            "mean": mean,
            "band": [low, high],
            "vehicles": n,
            "verdict": "inside" if low <= mean <= high else "above" if mean > high else "below",
        }
    return out


def error_against_engine_gain(runs: Sequence[dict[str, Any]]) -> dict[str, float]:
    """The wheel-side mass's relative error at the end of each drive against the vehicle's
    engine-torque gain (its truth, for scoring only): the least-squares line error = slope
    (gain − 1) + intercept and the correlation r over the vehicles. The filter is told the
    commanded torque, so an engine that gives more than its torque model says reads as less
    mass where the engine drives (a slope near −1 if all the mass's information came from
    the engine's torque, 0 if none did). Empty with fewer than three vehicles or one gain."""
    pairs = [
        (
            run["vehicle"]["engine_torque_gain"] - 1.0,
            run["wheel_side_mass"]["final"] / run["wheel_side_mass"]["truth"] - 1.0,
        )
        for run in runs
        if "engine_torque_gain" in run.get("vehicle", {}) and run.get("wheel_side_mass")
    ]
    if len(pairs) < 3:
        return {}
    gain, error = (np.array(v, dtype=float) for v in zip(*pairs, strict=True))
    if np.ptp(gain) == 0.0:
        return {}
    slope, intercept = np.polyfit(gain, error, 1)
    return {
        "slope": float(slope),
        "intercept": float(intercept),
        "r": float(np.corrcoef(gain, error)[0, 1]),
        "vehicles": len(pairs),
    }


def _p50_p95(values: Sequence[float]) -> dict[str, float]:
    return {"p50": float(np.percentile(values, 50)), "p95": float(np.percentile(values, 95))}


def fleet_aggregates(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """What the drive issue asks of a fleet beyond the mass, from each run's summary: the
    on-coming μ after each element's third slide (how many of the (vehicle, element) pairs
    that slid three times have their error inside 2 σ, per element and over all), NEES and
    NIS per degree of freedom (p50 and p95 over the vehicles; the drive's samples are
    correlated, so no band is claimed), and the drives' real-time factor and wall time (the
    fast drive, one vehicle per core)."""
    done = [r for r in runs if "estimates" in r]
    mu: dict[str, dict[str, int]] = {}
    for run in done:
        for name, entry in run["estimates"].items():
            third = entry.get("after_third_slide") if isinstance(entry, dict) else None
            if not third:
                continue
            counts = mu.setdefault(name, {"pairs": 0, "inside_2_sigma": 0})
            counts["pairs"] += 1
            counts["inside_2_sigma"] += int(bool(third["inside_2_sigma"]))
    drives = [r["drive"] for r in runs if not r["drive"].get("failure")]
    out: dict[str, Any] = {
        "mu_after_third_slide": {
            "per_element": mu,
            "pairs": sum(c["pairs"] for c in mu.values()),
            "inside_2_sigma": sum(c["inside_2_sigma"] for c in mu.values()),
        },
    }
    normalized = end_normalized_errors(done)
    if normalized:
        out["normalized_error_end"] = normalized
    against_gain = error_against_engine_gain(done)
    if against_gain:
        out["wheel_side_error_against_engine_gain"] = against_gain
    if done:
        out["nees_per_dof"] = _p50_p95([r["estimator"]["nees_per_dof_mean"] for r in done])
        out["nis_per_dof"] = _p50_p95([r["estimator"]["nis_per_dof"] for r in done])
    if drives:
        factors = [d["real_time_factor"] for d in drives]
        out["real_time_factor"] = {
            "p50": float(np.percentile(factors, 50)),
            "min": float(np.min(factors)),
        }
        out["drive_wall_s"] = float(sum(d["wall_s"] for d in drives))
        out["missed_shifts"] = int(sum(d.get("missed_shifts", 0) for d in drives))
    return out


def run_drive_fleet(
    d: GearboxDescription,
    cycle: Cycle,
    grade: GradeProfile | None,
    fleet: Any,
    seeds: Sequence[int],
    scheduler: str | None = None,
    workers: int = 2,
    progress: Callable[[int, int], None] | None = None,
) -> DriveFleet:
    """Every vehicle of ``seeds`` (:func:`drive_vehicle`), in this process (``scheduler``
    None) or on Dask (``"local"``: a LocalCluster of ``workers``; ``tcp://HOST:PORT``)."""
    from gearsym.validation.studies.dask_runner import run_each

    context = DriveContext(d, cycle, grade, fleet)
    started = time.perf_counter()
    runs = run_each(drive_vehicle, context, list(seeds), scheduler, workers, WHERE, progress)
    wall = time.perf_counter() - started
    if scheduler is None:
        ran_on = "in one process"
    elif scheduler == "local":
        ran_on = f"on a local Dask cluster of {workers} workers"
    else:
        ran_on = f"on the Dask scheduler {scheduler}"
    return DriveFleet(cycle, runs, getattr(fleet, "name", "fleet"), wall, ran_on)


def drive_fleet_markdown(data: dict[str, Any], command: str) -> str:
    """The fleet's drive as Markdown for the documentation, headed by its command."""
    mass = data["mass_error"]
    cycle = data["cycle"]
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- {mass.get('vehicles', 0)} vehicles of the {data['fleet']} fleet on {cycle['name']} "
        f"({cycle['duration_s']:.0f} s); {len(data['failed'])} drive(s) failed"
        + (
            f"; samples where a drive sat beyond its schedule's shift speeds "
            f"(validation/sim/drive_schedule.py): {data['missed_shifts']}"
            if "missed_shifts" in data
            else ""
        ),
        "- the TCU's view: commanded torque (the fleet's engine and machine torque errors), "
        "noisy speeds, no grade sensor",
        "",
        "- m_veh is known only as well as the tyres' dynamic radius: the wheel equation (2.49) "
        "has m_veh r_dyn², and the TCU measures wheel speed, not the vehicle's speed, so the "
        "filter (with the calibration's r_dyn) identifies the wheel-side mass "
        "m_veh (r_dyn / r_dyn,cal)², the inertia a shift's feed-forward needs; a tyre 1 % "
        "larger than calibrated reads as 2 % more mass",
        "",
        "| time | m_veh: p50 of \\|error\\| | m_veh: p95 | wheel-side mass: p50 "
        "| wheel-side: p95 |",
        "|---|---|---|---|---|",
    ]
    wheel = data.get("wheel_side_mass_error", {}).get("error_at", {})
    for key, entry in mass.get("error_at", {}).items():
        label = "end" if key == "end" else f"{key} s"
        other = wheel.get(key)
        right = f"{100 * other['p50']:.1f} % | {100 * other['p95']:.1f} %" if other else "– | –"
        out.append(
            f"| {label} | {100 * entry['p50']:.1f} % | {100 * entry['p95']:.1f} % | {right} |"
        )
    targets = data.get("targets") or []
    if targets:
        judged = "; ".join(
            f"{t['what']} {'at the end' if t['at'] == 'end' else 'after ' + t['at'] + ' s'} "
            + (
                f"{100 * t['p95']:.1f} % against {100 * t['p95_bound']:g} %: {t['verdict']}"
                if t["p95"] is not None
                else t["verdict"]
            )
            for t in targets
        )
        out += [
            "",
            "- against the drive issue's targets on the p95 of |error| (no grade sensor, the "
            f"fleet's engine-torque error): {judged}",
        ]
    mu = data.get("mu_after_third_slide") or {}
    if mu.get("pairs"):
        per = ", ".join(
            f"{name} {c['inside_2_sigma']} of {c['pairs']}" for name, c in mu["per_element"].items()
        )
        out += [
            "",
            f"- each element's μ after its third slide inside 2 σ of the truth: "
            f"{mu['inside_2_sigma']} of {mu['pairs']} (vehicle, element) pairs ({per})",
        ]
    normalized = data.get("normalized_error_end") or {}
    if normalized:
        parts = "; ".join(
            f"{name} {entry['mean']:.2f} in [{entry['band'][0]:.2f}, {entry['band'][1]:.2f}]: "
            f"{entry['verdict']}"
            for name, entry in normalized.items()
        )
        out.append(
            "- the squared error over the filter's own variance at the end of each drive, mean "
            "over the vehicles (one independent sample each: χ²(N)/N, its 95 % band): " + parts
        )
    against = data.get("wheel_side_error_against_engine_gain")
    if against:
        out.append(
            "- the wheel-side mass's error at the end against the vehicle's engine-torque gain "
            f"(the truth, for scoring): least squares error = {against['slope']:+.2f} (gain − 1) "
            f"{100 * against['intercept']:+.1f} %, r = {against['r']:+.2f} over "
            f"{against['vehicles']} vehicles (−1: the mass takes the engine's whole error)"
        )
    for key, label in (("nees_per_dof", "NEES/dof of (m_veh, ζ)"), ("nis_per_dof", "NIS/dof")):
        if key in data:
            out.append(
                f"- {label}, time mean per drive: p50 {data[key]['p50']:.2f}, p95 "
                f"{data[key]['p95']:.2f} over the vehicles (samples correlated: no band claimed)"
            )
    if "real_time_factor" in data:
        out.append(
            f"- the fast drive's real-time factor in this run: p50 "
            f"{data['real_time_factor']['p50']:.0f}x, slowest "
            f"{data['real_time_factor']['min']:.0f}x; {data['drive_wall_s']:.0f} s of drive wall "
            "time in all (each drive beside the other worker's drive or filter, and building "
            "its shifts' C in its first drives; the EKF over each log not counted)"
        )
    if data.get("fleet_wall_s") is not None and math.isfinite(data["fleet_wall_s"]):
        out.append(
            f"- the whole fleet, drives and filters: {data['fleet_wall_s'] / 60:.1f} min "
            f"{data['ran_on']}"
        )
    grade = data.get("grade_rms_rad") or {}
    if grade:
        out += ["", "| grade's RMS error | p50 | p95 |", "|---|---|---|"]
        for key, entry in grade.items():
            label = "over the drive" if key == "all" else f"from {key.removeprefix('after_')} s on"
            out.append(f"| {label} | {entry['p50']:.4f} rad | {entry['p95']:.4f} rad |")
    return "\n".join(out) + "\n"


def plot_drive_fleet(fleet: DriveFleet, path: Any) -> Any:
    """Each vehicle's relative mass error over time, with the fleet's p50 and p95 of |error|
    and the p95 of the error against the wheel-side mass
    (:func:`~gearsym.validation.sim.fleet.wheel_side_mass`)."""
    from gearsym.validation.drawing.figures import save, subplots

    fig, ax = subplots(1, 1, size=(9.0, 4.5))
    for run in fleet.runs:
        if "trace_mass_error" in run:
            ax.plot(run["trace_t"], 100 * np.asarray(run["trace_mass_error"]), lw=0.5, alpha=0.5)
    stats = fleet.percentiles()
    if stats:
        ax.plot(stats["t"], 100 * np.asarray(stats["p95"]), color="k", lw=1.5, label="p95 |error|")
        ax.plot(stats["t"], -100 * np.asarray(stats["p95"]), color="k", lw=1.5)
        ax.plot(stats["t"], 100 * np.asarray(stats["p50"]), color="k", ls="--", label="p50 |error|")
    wheel = fleet.percentiles("trace_wheel_mass_error")
    if wheel:
        ax.plot(
            wheel["t"],
            100 * np.asarray(wheel["p95"]),
            color="tab:red",
            lw=1.5,
            label="p95 |error| of the wheel-side mass m_veh (r_dyn/r_dyn,cal)²",
        )
    ax.set_xlabel("t (s)")
    ax.set_ylabel("m_veh error (%)")
    ax.set_title(f"{fleet.cycle.name}: mass estimate over the drive, {len(fleet.runs)} vehicles")
    ax.legend(loc="upper right")
    return save(fig, path)
