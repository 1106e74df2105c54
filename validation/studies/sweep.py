"""Global sensitivity (Sobol indices, SALib) and Monte-Carlo robustness of a shift, on Dask.

A sweep is a box of parameter ranges (:class:`SweepDefinition`, from ``--param NAME=LO:HI`` or
a ``[sweep]`` table). SALib's Sobol' sequence with Saltelli's cross-sampling
(``SALib.sample.sobol``, N (d + 2) points without second-order terms) fills the box; each point
is one run of the **hybrid shift model** (:class:`gearsym.validation.sim.hybrid_simulation.
HybridSimulator`: the modes' right-hand sides and guards compiled to CasADi functions, stepped
by SciPy's DOP853 with the guards as events). That evaluator is chosen because it is the only
fast one in which the shift *ends by itself*: the on-coming element locks up when its slip
reaches zero, so the shift duration and the slip energy are outcomes, not inputs (the driven
open-loop model of :mod:`gearsym.validation.studies.driven_shift` is driven with recorded element
torques, and the emitted C shift models take the element torques or μ F_N as inputs: neither
has lock-up logic). One run takes about 0.3 s at
rtol = 10⁻⁶ on the development machine.

Quantities of interest per run (:data:`QUANTITIES`): the shift duration (lock-up of the
on-coming element minus the start of the torque phase: the last scenario breakpoint before the
swapping elements' normal forces first leave their initial values), the slip energy
dissipated in the on-coming element ∫ T_on Δω_on dt, the peak output (side-shaft) torque
2 (k_ss φ + d_ss φ̇) (2.47), and the final speeds ω_in, ω_C. (No jerk: the hybrid model's
acceleration jumps at every lock-up and break-away, so a sampled jerk measures the sample
time, not the shift.)
The local sensitivities of chapter 3 of the same quantities at the nominal point come from the
hybrid sensitivities (3.7) with their jumps at events: ∂τ/∂p of the lock-up event and
∂ω/∂p at the end (:func:`local_sensitivities`).

Batches of points go to a dask.distributed ``Client`` (a ``LocalCluster`` by default, or the
address of a running scheduler); every worker builds the simulator once and keeps it. Sobol
first- and total-order indices with bootstrap confidence intervals (``SALib.analyze.sobol``);
the results go to CSV and Parquet (pyarrow) through the caller's output folder.

Oil temperature is not a parameter of the models: the μ map is read at the description's
``friction.T_oil`` when the simulator is built, and μ_e scales the whole map; so a sweep over
T_oil is not offered (a μ_e range covers a relative change of the friction level).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.defaults import SWEEP_MAX_SAMPLES
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.parameters import symbol, zero_scale
from gearsym.validation.studies import dask_runner

#: The quantities of interest of one shift run, with units.
QUANTITIES: dict[str, str] = {
    "shift_duration": "s",
    "slip_energy_on": "J",
    "peak_output_torque": "N*m",
    "final_omega_in": "rad/s",
    "final_omega_C": "rad/s",
}

#: The quantities whose local (chapter 3) sensitivities are available.
LOCAL_QUANTITIES = ("shift_duration", "final_omega_in", "final_omega_C")

#: Progress callback: (done, total).
Progress = Callable[[int, int], None]


# ----------------------------------------------------------------------------- definition


@dataclass(frozen=True)
class SweepDefinition:
    """Parameter ranges (name → (lo, hi)), the base sample count N and the seed."""

    ranges: dict[str, tuple[float, float]]
    samples: int = 64
    seed: int = 1
    source: str = "--param"

    def problem(self) -> dict[str, Any]:
        """The SALib problem dictionary."""
        return {
            "num_vars": len(self.ranges),
            "names": list(self.ranges),
            "bounds": [list(b) for b in self.ranges.values()],
        }


def parse_range(item: str, file: str = "sweep") -> tuple[str, tuple[float, float]]:
    """``NAME=LO:HI`` → (NAME, (LO, HI)); LO < HI, both finite."""
    name, sep, rest = item.partition("=")
    lo_text, colon, hi_text = rest.partition(":")
    try:
        if not sep or not colon or not name.strip():
            raise ValueError
        lo, hi = float(lo_text), float(hi_text)
    except ValueError:
        raise GearsymError(file, "param", f"expected NAME=LO:HI, got {item!r}") from None
    return name.strip(), _checked(name.strip(), lo, hi, file, "param")


def _checked(name: str, lo: float, hi: float, file: str, key: str) -> tuple[float, float]:
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise GearsymError(file, key, f"{name}: the range must be finite, got {lo}:{hi}")
    if not lo < hi:
        raise GearsymError(file, key, f"{name}: LO must be below HI, got {lo:g}:{hi:g}")
    return (lo, hi)


def load_definition(path: str | Path) -> SweepDefinition:
    """A ``[sweep]`` table: ``samples``, ``seed`` and ``[sweep.parameters]`` NAME = [LO, HI]."""
    from gearsym.symbolic.io.input_files import parse_toml, read_text

    file = str(path)
    data = parse_toml(read_text(path, file), file)
    unknown = sorted(set(data) - {"sweep"})
    if unknown or "sweep" not in data:
        raise GearsymError(file, unknown[0] if unknown else "sweep", "expected one [sweep] table")
    table = data["sweep"]
    if not isinstance(table, dict):
        raise GearsymError(file, "sweep", "expected a table [sweep]")
    extra = sorted(set(table) - {"samples", "seed", "parameters"})
    if extra:
        raise GearsymError(file, f"sweep.{extra[0]}", "unknown key (samples, seed, parameters)")
    ranges = {}
    parameters = table.get("parameters", {})
    if not isinstance(parameters, dict):
        raise GearsymError(file, "sweep.parameters", "expected a table of NAME = [LO, HI]")
    for name, pair in parameters.items():
        key = f"sweep.parameters.{name}"
        if (
            not isinstance(pair, list)
            or len(pair) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in pair)
        ):
            raise GearsymError(file, key, "expected [LO, HI]")
        ranges[name] = _checked(name, float(pair[0]), float(pair[1]), file, key)
    samples = table.get("samples", 64)
    seed = table.get("seed", 1)
    for key, value in (("samples", samples), ("seed", seed)):
        if (
            not isinstance(value, int)
            or isinstance(value, bool)
            or value < (1 if key == "samples" else 0)
        ):
            raise GearsymError(file, f"sweep.{key}", f"expected a positive integer, got {value!r}")
    check_samples(samples, file, "sweep.samples")
    return SweepDefinition(ranges, samples, seed, file)


MAX_SAMPLES = SWEEP_MAX_SAMPLES


def check_samples(samples: int, file: str, key: str) -> None:
    """N must be a power of two: the balance properties of the Sobol' points (and SALib's
    estimators) need it; at most :data:`MAX_SAMPLES`."""
    if samples > MAX_SAMPLES:
        raise GearsymError(file, key, f"must be at most {MAX_SAMPLES}, got {samples}")
    if samples < 2 or samples & (samples - 1):
        raise GearsymError(file, key, f"must be a power of two (Sobol' points), got {samples}")


def check_parameters(definition: SweepDefinition, known: Sequence[str], file: str) -> None:
    """Every swept name is a parameter of the model; at least two parameters."""
    for name in definition.ranges:
        if name not in known:
            raise GearsymError(
                file, "param", f"unknown parameter {name!r} (known: {', '.join(known)})"
            )
    if len(definition.ranges) < 2:
        raise GearsymError(file, "param", "a sweep needs at least two parameters")


def check_ranges(definition: SweepDefinition, file: str) -> None:
    """:func:`check_range` for every swept parameter (before any model is built)."""
    for name, (lo, hi) in definition.ranges.items():
        check_range(name, lo, hi, file)


def check_range(name: str, lo: float, hi: float, file: str) -> None:
    """Every sample of a swept parameter passes the checks its value in a description passes
    (:mod:`gearsym.symbolic.parameters`: positive unless signed, inside the plausibility
    range the emitted ``params_validate`` enforces); a one-line error names the bound."""
    from gearsym.symbolic.parameters import is_mu, record

    try:
        r = record(name)
    except KeyError:
        return  # a parameter gearsym states nothing about: the model's own checks apply
    shown = f"{name}={lo:g}:{hi:g}"
    if not r.signed and lo <= 0:
        raise GearsymError(file, "param", f"{shown}: {name} must be positive, got LO {lo:g}")
    low, high = r.bounds or (None, None)
    what = "μ" if is_mu(name) else name
    unit = "" if r.unit == "1" else f" {r.unit}"
    if low is not None and lo < low:
        raise GearsymError(
            file, "param", f"{shown}: below the plausible range of {what} (at least {low:g}{unit})"
        )
    if high is not None and hi > high:
        raise GearsymError(
            file, "param", f"{shown}: above the plausible range of {what} (at most {high:g}{unit})"
        )


def implausible_indices(
    indices: Mapping[str, Mapping[str, Sequence[float]]], names: Sequence[str]
) -> list[str]:
    """Sobol indices outside [0, 1] beyond their confidence interval: a sample too small for
    the quantity, or a quantity that jumps; said where the indices are printed."""
    found = []
    for quantity, si in indices.items():
        for kind in ("S1", "ST"):
            for j, name in enumerate(names):
                value, conf = float(si[kind][j]), float(si[f"{kind}_conf"][j])
                if value - conf > 1.0 or value + conf < 0.0:
                    found.append(
                        f"{quantity}: {kind} of {name} = {value:.3f} ± {conf:.3f} lies outside "
                        "[0, 1] beyond its confidence interval (too few samples, or a quantity "
                        "that jumps): not a valid index"
                    )
    return found


# ----------------------------------------------------------------------------- evaluators


class Evaluator:
    """Maps points (k × d, columns in the definition's order) to quantity arrays (k each)."""

    quantities: tuple[str, ...] = ()

    def __call__(self, points: np.ndarray, names: Sequence[str]) -> dict[str, np.ndarray]:
        raise NotImplementedError


class Ishigami(Evaluator):
    """f = sin x1 + a sin² x2 + b x3⁴ sin x1 (Ishigami & Homma 1990), x_i ∈ [−π, π]: the
    analytic test function with closed-form Sobol indices."""

    quantities = ("f",)

    def __init__(self, a: float = 7.0, b: float = 0.1) -> None:
        self.a, self.b = a, b

    def __call__(self, points: np.ndarray, names: Sequence[str]) -> dict[str, np.ndarray]:
        x1, x2, x3 = points.T
        return {"f": np.sin(x1) + self.a * np.sin(x2) ** 2 + self.b * x3**4 * np.sin(x1)}

    def exact(self) -> tuple[np.ndarray, np.ndarray]:
        """Closed-form (S1, ST): V1 = ½(1 + bπ⁴/5)², V2 = a²/8, V13 = b²π⁸(1/18 − 1/50)."""
        a, b, pi = self.a, self.b, math.pi
        v1 = 0.5 * (1 + b * pi**4 / 5) ** 2
        v2 = a**2 / 8
        v13 = b**2 * pi**8 * (1 / 18 - 1 / 50)
        v = v1 + v2 + v13
        return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v


class ShiftEvaluator(Evaluator):
    """One hybrid shift run per point (see the module docstring); picklable: the description
    and scenario travel, the simulator is built once per worker process and cached."""

    quantities = tuple(QUANTITIES)

    def __init__(self, d: Any, scenario: Any = None, rtol: float = 1e-6) -> None:
        self.d, self.scenario, self.rtol = d, scenario, rtol
        self.key = dask_runner.content_key(d, scenario, rtol)

    def simulator(self) -> Any:
        return dask_runner.worker_cached(self.key, self._build)

    def _build(self) -> Any:
        from gearsym.validation.sim.hybrid_simulation import HybridSimulator

        return HybridSimulator(self.d, self.scenario)

    def parameter_names(self) -> list[str]:
        return list(self.simulator().parameter_names)

    def __call__(self, points: np.ndarray, names: Sequence[str]) -> dict[str, np.ndarray]:
        sim = self.simulator()
        out = {q: np.full(len(points), np.nan) for q in self.quantities}
        for k, row in enumerate(points):
            try:
                result = sim.run(
                    dict(zip(names, map(float, row), strict=True)), rtol=self.rtol, atol=self.rtol
                )
            except (GearsymError, RuntimeError, ValueError, ArithmeticError):
                continue  # a failed run (chattering, integrator failure) stays NaN: reported
            for q, v in shift_quantities(sim, result).items():
                out[q][k] = v
        return out


def torque_phase_start(sim: Any) -> float:
    """The start of the torque phase: the last breakpoint before the swapping elements' normal
    forces first leave their initial values (0.5 s in the built-in 2-3 scenario)."""
    scenario = sim.scenario
    points = [b for b in scenario.breakpoints() if b > 0]
    f0 = sim.normal_forces(0.0)
    for b in points:
        if not np.allclose(sim.normal_forces(b + 1e-9), f0):
            previous = [p for p in [0.0, *points] if p < b]
            return float(previous[-1]) if previous else 0.0
    return 0.0


def shift_quantities(sim: Any, result: Any) -> dict[str, float]:
    """The quantities of interest (:data:`QUANTITIES`) of one hybrid run."""
    from gearsym.symbolic import naming

    on = sim.hybrid.spec.on_coming
    lock = [e.t for e in result.events if e.kind == "lock-up" and e.element == on]
    t0 = torque_phase_start(sim)
    t, s = result.t, result.signals
    power = s[naming.torque(on)] * s[naming.slip_column(on)]
    values = result.values
    phi = s[naming.TWIST]
    phi_dot = np.gradient(phi, t)
    torque = 2 * (values["k_ss"] * phi + values["d_ss"] * phi_dot)
    return {
        "shift_duration": (lock[0] - t0) if lock else math.nan,
        "slip_energy_on": float(abs(np.trapezoid(power, t))),
        "peak_output_torque": float(np.max(np.abs(torque))),
        "final_omega_in": float(s[naming.speed(sim.d.input_shaft)][-1]),
        "final_omega_C": float(s[naming.WHEEL_SPEED][-1]),
    }


def local_sensitivities(
    evaluator: ShiftEvaluator, names: Sequence[str], nominal: Mapping[str, float] | None = None
) -> dict[str, dict[str, float]]:
    """∂Q/∂p of :data:`LOCAL_QUANTITIES` at ``nominal`` (default: the description's values),
    from the hybrid sensitivities (3.7) with the event jumps: ∂τ/∂p of the on-coming element's
    lock-up and ∂ω/∂p at the last sample. quantity → parameter → derivative."""
    from gearsym.symbolic import naming

    sim = evaluator.simulator()
    result = sim.run(nominal, parameters=list(names))
    on = sim.hybrid.spec.on_coming
    index = [k for k, e in enumerate(result.events) if e.kind == "lock-up" and e.element == on]
    tau = result.event_time_sensitivities
    out: dict[str, dict[str, float]] = {}
    if index and tau is not None:
        out["shift_duration"] = {n: float(tau[index[0], j]) for j, n in enumerate(names)}
    for q, key in (
        ("final_omega_in", naming.speed(sim.d.input_shaft)),
        ("final_omega_C", naming.WHEEL_SPEED),
    ):
        out[q] = {n: float(result.sensitivities[key][-1, j]) for j, n in enumerate(names)}
    return out


# ----------------------------------------------------------------------------- the sweep


@dataclass
class SweepResult:
    """Points, quantities per point, Sobol indices and robustness statistics."""

    definition: SweepDefinition
    points: np.ndarray
    values: dict[str, np.ndarray]
    indices: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    statistics: dict[str, dict[str, float]] = field(default_factory=dict)
    seconds: float = 0.0
    workers: int = 0
    scheduler: str = ""


def _evaluate_batch(evaluator: Evaluator, points: np.ndarray, names: list[str]) -> dict:
    return evaluator(points, names)


#: The command and option a scheduler error names.
WHERE = ("sweep", "scheduler")


def check_scheduler(scheduler: str) -> None:
    """``local`` or ``tcp://HOST:PORT``, refused in one line before any work otherwise
    (:func:`~gearsym.validation.studies.dask_runner.check_scheduler`)."""
    dask_runner.check_scheduler(scheduler, WHERE)


#: How long a remote scheduler may take to show one worker (s).
WORKER_WAIT = dask_runner.WORKER_WAIT


def connect(scheduler: str, workers: int, processes: bool = True) -> tuple[Any, Any]:
    """(client, cluster or None): a new LocalCluster for ``"local"``, else the scheduler at
    ``scheduler`` (``tcp://HOST:PORT``); an unreachable one is a one-line error
    (:func:`~gearsym.validation.studies.dask_runner.connect`)."""
    return dask_runner.connect(scheduler, workers, processes, WHERE, wait=WORKER_WAIT)


def text_progress(done: int, total: int) -> None:
    """A progress bar on stderr (one line, redrawn)."""
    if total > 40 and done % max(1, total // 40) and done < total:
        return  # about 40 redraws
    width = 30
    filled = int(width * done / max(total, 1))
    end = "\n" if done >= total else ""
    print(
        f"\r  [{'#' * filled}{'.' * (width - filled)}] {done}/{total} batches",
        end=end,
        file=sys.stderr,
        flush=True,
    )


def run_sweep(
    definition: SweepDefinition,
    evaluator: Evaluator,
    scheduler: str = "local",
    workers: int = 2,
    batch: int = 16,
    processes: bool = True,
    progress: Progress | None = None,
    client: Any = None,
) -> SweepResult:
    """Sample (Saltelli/Sobol'), evaluate in batches on Dask, analyse (Sobol S1, ST with 95 %
    bootstrap confidence intervals) and summarise (mean, std, 5/50/95 % quantiles, min, max
    over every evaluated point: the Monte-Carlo robustness view)."""
    from SALib.analyze import sobol as analyze
    from SALib.sample import sobol as sample

    problem = definition.problem()
    names = list(problem["names"])
    points = sample.sample(
        problem, definition.samples, calc_second_order=False, seed=definition.seed
    )
    start = time.perf_counter()
    own = client is None
    cluster = None
    if own:
        client, cluster = connect(scheduler, workers, processes)
    try:
        chunks = [points[k : k + batch] for k in range(0, len(points), batch)]
        futures = dask_runner.submit_each(client, _evaluate_batch, evaluator, chunks, names)
        results: dict[int, dict] = {}
        for done, (i, values) in enumerate(dask_runner.completed(futures, WHERE), 1):
            results[i] = values
            if progress is not None:
                progress(done, len(chunks))
        n_workers = len(client.scheduler_info().get("workers", {}))
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    values = {
        q: np.concatenate([results[i][q] for i in range(len(chunks))]) for q in evaluator.quantities
    }
    result = SweepResult(
        definition,
        points,
        values,
        seconds=time.perf_counter() - start,
        workers=n_workers,
        scheduler=scheduler,
    )
    for q, y in values.items():
        finite = np.isfinite(y)
        if finite.any():
            yf = y[finite]
            result.statistics[q] = {
                "mean": float(np.mean(yf)),
                "std": float(np.std(yf, ddof=1)) if yf.size > 1 else 0.0,
                "p05": float(np.quantile(yf, 0.05)),
                "p50": float(np.quantile(yf, 0.50)),
                "p95": float(np.quantile(yf, 0.95)),
                "min": float(np.min(yf)),
                "max": float(np.max(yf)),
                "failed": int((~finite).sum()),
            }
        if not finite.all():
            result.skipped[q] = f"{int((~finite).sum())} of {len(y)} runs gave no value"
            continue
        if np.ptp(y) == 0:
            result.skipped[q] = "constant over the sweep (no variance to apportion)"
            continue
        si = analyze.analyze(
            problem, y, calc_second_order=False, conf_level=0.95, seed=definition.seed
        )
        result.indices[q] = {
            key: [float(v) for v in si[key]] for key in ("S1", "S1_conf", "ST", "ST_conf")
        }
    return result


# ----------------------------------------------------------------------------- output


def linearised_indices(
    derivatives: Mapping[str, float], ranges: Mapping[str, tuple[float, float]]
) -> dict[str, float]:
    """The local sensitivities as the first-order indices of the linearised model,
    (∂Q/∂p_j σ_j)² / Σ_k (∂Q/∂p_k σ_k)², σ_j = (hi − lo)/√12 (uniform p_j): what S1 = ST would be
    if Q were linear over the box."""
    terms = {n: (derivatives[n] * (hi - lo)) ** 2 / 12 for n, (lo, hi) in ranges.items()}
    total = sum(terms.values())
    return {n: (v / total if total > 0 else 0.0) for n, v in terms.items()}


def write_tables(result: SweepResult, out: Path) -> list[Path]:
    """``samples.csv`` and ``samples.parquet`` (one row per point: parameters, quantities) and
    ``indices.csv`` (quantity, parameter, S1, S1_conf, ST, ST_conf)."""
    import csv

    import pyarrow as pa
    import pyarrow.parquet as pq

    names = list(result.definition.ranges)
    columns = {n: result.points[:, j] for j, n in enumerate(names)}
    columns.update(result.values)
    pq.write_table(pa.table(columns), out / "samples.parquet")
    with (out / "samples.csv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(list(columns))
        for k in range(len(result.points)):
            writer.writerow([f"{columns[c][k]:.12g}" for c in columns])
    with (out / "indices.csv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["quantity", "parameter", "S1", "S1_conf", "ST", "ST_conf"])
        for q, si in result.indices.items():
            for j, n in enumerate(names):
                writer.writerow(
                    [q, n, *(f"{si[k][j]:.6g}" for k in ("S1", "S1_conf", "ST", "ST_conf"))]
                )
    return [out / "samples.parquet", out / "samples.csv", out / "indices.csv"]


def plot_indices(
    result: SweepResult,
    quantity: str,
    local: Mapping[str, float] | None,
    nominal: Mapping[str, float] | None,
    path: Path,
) -> Path:
    """One figure: left, S1 and ST bars with their 95 % intervals beside the linearised local
    indices (:func:`linearised_indices`); right, the normalised local sensitivities (3.3)
    ∂Q/∂p · p0/Q0 of chapter 3 (p0 = |nominal| or the ζ scale 0.05)."""
    from gearsym.validation.drawing.figures import save, subplots

    names = list(result.definition.ranges)
    si = result.indices[quantity]
    cols = 2 if local else 1
    fig, axes = subplots(
        1,
        cols,
        (4.2 * cols, 3.2),
        {"left": 0.1, "right": 0.97, "bottom": 0.16, "top": 0.86, "wspace": 0.3},
        squeeze=False,
    )
    x = np.arange(len(names))
    ax = axes[0, 0]
    width = 0.27 if local else 0.38
    ax.bar(x - width, si["S1"], width, yerr=si["S1_conf"], capsize=2, label="S1 (first order)")
    ax.bar(x, si["ST"], width, yerr=si["ST_conf"], capsize=2, label="ST (total)")
    if local:
        lin = linearised_indices(local, result.definition.ranges)
        ax.bar(x + width, [lin[n] for n in names], width, label="local, linearised")
    ax.set_xticks(x, [symbol(n) for n in names])
    ax.set_ylabel("share of variance")
    ax.set_title(f"Sobol indices of {quantity} (95 % CI)")
    ax.legend()
    if local and nominal is not None:
        q0 = float(np.median(result.values[quantity]))
        scale = [abs(nominal[n]) or zero_scale(n) for n in names]
        sn = [local[n] * s / q0 for n, s in zip(names, scale, strict=True)]
        axes[0, 1].bar(x, sn, 0.5, color="C2")
        axes[0, 1].set_xticks(x, [symbol(n) for n in names])
        axes[0, 1].set_ylabel("∂Q/∂p · p0/Q0")
        axes[0, 1].set_title("normalised local sensitivity (3.3), nominal point")
    fig.suptitle(
        f"{quantity}: global (Sobol, N = {result.definition.samples}) and local", fontsize=9
    )
    return save(fig, path, dpi=110)
