"""Estimators run on the reference simulation (thesis 4.4): the UIO per phase of a shift.

The reference simulation (:mod:`gearsym.validation.sim.simulate`, full gearbox, elastic drivetrain,
elasto-plastic friction) is the truth. The TCU sees its measured speeds (3.31) every
``sample_time`` seconds, optionally with noise (3.26), and the known inputs at the same instants
(held over the sample, as a TCU applies them). The UIO of each detected phase
(:func:`~gearsym.symbolic.estimators.design_uio`) runs inside that phase; at a phase change the
next phase's observer starts from the last estimate (states the two modes share keep their
value; a state the new mode adds starts from its measurement or zero).

What the numbers mean: the linear modes are the rigid models of the phases, so their
estimates carry the reference's bristle compliance and the ZOH assumption as model error; the
unknown input's truth is the reference's road torque minus what the known grade input already
explains through the form's ζ column (r_dyn g m_veh ζ, linearised as in (5.5)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators import (
    LinearMode,
    UioDesign,
    UioExistence,
    design_uio,
    linear_modes,
    uio_existence,
)
from gearsym.validation.sim.simulate import SimulationResult

__all__ = [
    "PhaseEstimate",
    "UioRun",
    "check_unknown",
    "run_uio",
]


#: Time after a phase change left out of the phase's error statistics: the new observer
#: converges from the previous estimate (its spectral radius is printed beside), and after
#: lock-up the reference's element is still sticking (bristle transient, 2.66) while the rigid
#: to-gear model already holds it.
SETTLING_TIME = 0.025


@dataclass(frozen=True)
class PhaseEstimate:
    """Errors of one phase's UIO against the reference."""

    phase: str
    t_start: float
    t_end: float
    #: None where none of the unknown inputs acts in this phase (no observer run there).
    existence: UioExistence | None
    spectral_radius: float | None
    samples: int
    #: RMS error per state (over the phase less its first SETTLING_TIME seconds).
    state_rmse: dict[str, float]
    #: RMS error and mean truth of each unknown input over the same samples.
    input_rmse: dict[str, float]
    input_mean: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        return {
            "phase": self.phase,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "existence": None if self.existence is None else self.existence.to_dict(),
            "spectral_radius": self.spectral_radius,
            "samples": self.samples,
            "settling_time": SETTLING_TIME,
            "state_rmse": self.state_rmse,
            "unknown_input_rmse": self.input_rmse,
            "unknown_input_mean": self.input_mean,
        }


@dataclass(frozen=True)
class UioRun:
    """The UIO along one reference shift: estimates, truths, per-phase errors."""

    shift: str
    unknown: tuple[str, ...]
    sample_time: float
    noise: bool
    t: np.ndarray = field(repr=False)
    states: dict[str, np.ndarray] = field(repr=False)  # estimate per state name (NaN if absent)
    truth: dict[str, np.ndarray] = field(repr=False)
    inputs: dict[str, np.ndarray] = field(repr=False)  # estimate per unknown input
    input_truth: dict[str, np.ndarray] = field(repr=False)
    phases: tuple[PhaseEstimate, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "filter": "uio",
            "shift": self.shift,
            "unknown": list(self.unknown),
            "sample_time": self.sample_time,
            "noise": self.noise,
            "phases": [p.to_dict() for p in self.phases],
        }


def _rms(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else float("nan")


def run_uio(
    d: GearboxDescription,
    result: SimulationResult,
    unknown: Sequence[str] = (naming.RESISTANCE_INPUT,),
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | None = None,
    seed: int = 0,
) -> UioRun:
    """Run the UIO of each phase of ``result``'s shift on its samples (see the module text).

    ``relative_noise`` (one r_i per measured output, 3.26) adds Gaussian noise of standard
    deviation r_i |y_i| to the speeds the observer sees."""
    shift = result.scenario.shift.name
    modes = linear_modes(d, shift)
    gear_from, during, gear_to = modes
    check_unknown(modes, unknown)
    by_phase = {
        result.phases[0].name: gear_from,
        result.phases[1].name: during,
        result.phases[2].name: during,
        result.phases[3].name: gear_to,
    }
    span = result.t[-1] - result.t[0]
    if not (0 < sample_time <= span / 4):
        raise GearsymError(
            "estimate", "--sample-time", f"must be in (0, {span / 4:g}] s, got {sample_time!r}"
        )
    t = np.arange(result.t[0], result.t[-1] + 1e-12, sample_time)

    def sampled(name: str) -> np.ndarray:
        return np.interp(t, result.t, result.signals[name])

    output_names = gear_from.outputs
    y_true = np.column_stack([sampled(name.removeprefix("y_")) for name in output_names])
    y = y_true.copy()
    if relative_noise is not None:
        r = np.asarray(relative_noise, dtype=float)
        if r.shape == (1,):
            r = np.full(y.shape[1], r[0])
        if r.shape != (y.shape[1],) or np.any(~np.isfinite(r)) or np.any(r < 0):
            raise GearsymError(
                "estimate",
                "--noise",
                f"give one or {y.shape[1]} finite non-negative relative errors "
                f"({', '.join(output_names)})",
            )
        y = y + np.random.default_rng(seed).normal(0.0, 1.0, y.shape) * (
            r[None, :] * np.abs(y_true)
        )

    # the observer's output weights: the noise variances (3.26) when there is noise
    variances: Any = 1.0
    if relative_noise is not None:
        variances = np.maximum(np.mean((r[None, :] * y_true) ** 2, axis=0), 1e-12)
    all_states = list(dict.fromkeys(s for m in modes for s in m.form.states))
    truth = {s: sampled(s) for s in all_states}
    estimates = {s: np.full(len(t), np.nan) for s in all_states}
    m_veh = quantity(d, "vehicle", "m_veh").value
    r_dyn, g = quantity(d, "vehicle", "r_dyn").value, quantity(d, "vehicle", "g").value
    grade = sampled(naming.GRADE)
    road_truth = sampled(naming.ROAD_TORQUE) - r_dyn * g * m_veh * grade  # the ζ column's part
    input_truth = {naming.RESISTANCE_INPUT: road_truth}
    for name in unknown:
        if name != naming.RESISTANCE_INPUT:
            input_truth[name] = sampled(name)
    input_estimates = {name: np.full(len(t), np.nan) for name in unknown}

    phase_results = []
    previous: dict[str, float] = {}
    designs: dict[str, tuple[UioExistence | None, UioDesign | None]] = {}
    for phase in result.phases:
        mode = by_phase[phase.name]
        last = phase is result.phases[-1]
        inside = np.flatnonzero((t >= phase.t_start) & ((t < phase.t_end) | last))
        if mode.phase not in designs:
            acting = [u for u in unknown if u in mode.form.inputs]
            if not acting:  # e.g. clutch torques in a gear, where the clutches are locked
                designs[mode.phase] = (None, None)
            else:
                existence = uio_existence(mode, acting)
                design = (
                    design_uio(
                        mode,
                        acting,
                        sample_time,
                        measurement_weight=variances,
                        existence=existence,
                    )
                    if existence.exists
                    else None
                )
                designs[mode.phase] = (existence, design)
        existence, design = designs[mode.phase]
        if existence is None or inside.size < 2 or design is None:
            phase_results.append(
                PhaseEstimate(
                    phase.name,
                    phase.t_start,
                    phase.t_end,
                    existence,
                    None,
                    int(inside.size),
                    {},
                    {},
                    {},
                )
            )
            previous = {}
            continue
        # the known inputs at the samples, held (a TCU applies the value it has)
        u = np.column_stack(
            [grade[inside] if k == naming.GRADE else sampled(k)[inside] for k in design.known]
        )
        measured = {name.removeprefix("y_"): j for j, name in enumerate(output_names)}
        guess = np.array(
            [
                previous.get(s, y[inside[0], measured[s]] if s in measured else 0.0)
                for s in design.states
            ]
        )
        x_hat, d_hat = design.run(y[inside], u, x0_guess=guess)
        for j, s in enumerate(design.states):
            estimates[s][inside] = x_hat[:, j]
        for j, name in enumerate(design.unknown):
            input_estimates[name][inside[:-1]] = d_hat[:, j]
        previous = {s: float(x_hat[-1, j]) for j, s in enumerate(design.states)}
        scored = inside[(t[inside] >= phase.t_start + SETTLING_TIME)][:-1]
        phase_results.append(
            PhaseEstimate(
                phase=phase.name,
                t_start=phase.t_start,
                t_end=phase.t_end,
                existence=existence,
                spectral_radius=design.spectral_radius,
                samples=int(inside.size),
                state_rmse={
                    s: _rms(estimates[s][scored] - truth[s][scored]) for s in design.states
                },
                input_rmse={
                    name: _rms(input_estimates[name][scored] - input_truth[name][scored])
                    for name in design.unknown
                },
                input_mean={
                    name: float(np.mean(input_truth[name][scored])) for name in design.unknown
                },
            )
        )
    return UioRun(
        shift=shift,
        unknown=tuple(unknown),
        sample_time=float(sample_time),
        noise=relative_noise is not None,
        t=t,
        states=estimates,
        truth=truth,
        inputs=input_estimates,
        input_truth=input_truth,
        phases=tuple(phase_results),
    )


def check_unknown(modes: Sequence[LinearMode], unknown: Sequence[str]) -> None:
    """Every unknown input must be an input of some phase's form (5.3); one-line error else."""
    known = list(dict.fromkeys(name for m in modes for name in m.form.inputs))
    wrong = [u for u in unknown if u not in known]
    if wrong or not unknown:
        raise GearsymError(
            "estimate",
            "--unknown",
            f"{', '.join(wrong) or 'nothing'} is not an input of any phase "
            f"(inputs of (5.3) here: {', '.join(known)})",
        )
