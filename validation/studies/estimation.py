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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import EKF_FLOOR_FRACTION, EKF_RELATIVE_NOISE
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name, quantity
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators import (
    LinearMode,
    UioDesign,
    UioExistence,
    design_uio,
    linear_modes,
    uio_existence,
)
from gearsym.symbolic.parameters import RECORDS, axis_label, symbol
from gearsym.validation.sim.phases import Phase
from gearsym.validation.sim.simulate import SimulationResult

__all__ = [
    "BOUND_ASSUMPTION",
    "EkfBound",
    "EkfMonteCarlo",
    "EkfSetup",
    "MODE_SOURCES",
    "ModeSwitch",
    "match_switches",
    "mode_switches",
    "reference_switches",
    "ekf_bound",
    "filter_run",
    "format_measured_ekf_text",
    "measured_ekf_dict",
    "noisy_outputs",
    "format_monte_carlo_text",
    "plot_efficiency",
    "prepare_ekf",
    "run_ekf_monte_carlo",
    "EkfRun",
    "ParameterEstimate",
    "element_modes",
    "format_ekf_text",
    "plot_ekf",
    "run_ekf",
    "write_ekf_csv",
    "check_unknown",
    "PhaseEstimate",
    "UioRun",
    "format_text",
    "plot_uio",
    "run_uio",
    "start_from_first_measurement",
    "write_csv",
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


def write_csv(run: UioRun, path: Path) -> Path:
    """Every sample: t, each state's estimate and truth, each unknown input's estimate and
    truth (empty where the phase has no such state or no UIO)."""
    columns: list[tuple[str, np.ndarray]] = [("t", run.t)]
    for s in run.states:
        columns += [(f"{s}_hat", run.states[s]), (s, run.truth[s])]
    for name in run.inputs:
        columns += [(f"{name}_hat", run.inputs[name]), (name, run.input_truth[name])]
    lines = [",".join(name for name, _ in columns)]
    for k in range(len(run.t)):
        lines.append(",".join("" if not np.isfinite(v[k]) else f"{v[k]:.9g}" for _, v in columns))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def plot_uio(run: UioRun, out_dir: Path) -> list[Path]:
    """The unknown input's estimate against the reference, and the unmeasured state φ, with
    the phases shaded and the UIO's existence per phase in the legend."""
    from gearsym.validation.drawing.figures import save, subplots

    fig, axes = subplots(2, 1, (8, 6), {"top": 0.9, "bottom": 0.08, "hspace": 0.15}, sharex=True)
    for k, phase in enumerate(run.phases):
        for ax in axes:
            ax.axvspan(phase.t_start, phase.t_end, color="0.93" if k % 2 else "0.85", lw=0)
        verdict = "UIO" if phase.existence and phase.existence.exists else "no UIO"
        axes[0].annotate(
            f"{phase.phase}\n({verdict})",
            ((phase.t_start + phase.t_end) / 2, 1.02),
            xycoords=("data", "axes fraction"),
            ha="center",
            fontsize=7,
        )
    for name in run.inputs:
        axes[0].plot(run.t, run.input_truth[name], color="k", lw=1.2, label=f"{name} (reference)")
        axes[0].plot(run.t, run.inputs[name], color="C1", lw=0.9, label=f"{name} (UIO)")
    truth = run.input_truth[run.unknown[0]]
    span = float(np.nanmax(np.abs(truth))) if truth.size else 1.0
    axes[0].set_ylim(-0.5 * span, 2.5 * span)  # the lock-up transient would hide the rest
    axes[0].set_ylabel("unknown input / (N·m)")
    axes[0].legend(fontsize=7, loc="upper left")
    axes[1].plot(run.t, run.truth[naming.TWIST], color="k", lw=1.2, label="φ (reference)")
    axes[1].plot(run.t, run.states[naming.TWIST], color="C0", lw=0.9, label="φ (UIO, unmeasured)")
    axes[1].set_ylabel("side-shaft twist φ / rad")
    axes[1].set_xlabel("t / s")
    axes[1].legend(fontsize=7, loc="upper left")
    fig.suptitle(
        f"Unknown input observer (4.4), shift {run.shift}, samples every "
        f"{run.sample_time * 1e3:g} ms{', noisy speeds (3.26)' if run.noise else ''}",
        fontsize=10,
    )
    return [save(fig, out_dir / "uio.png")]


def format_text(run: UioRun) -> str:
    """Per phase: the existence verdict with its reason, and the errors against the reference."""
    lines = [
        f"Unknown input observer (4.4) of the {run.shift} shift on the reference simulation, "
        f"samples every {run.sample_time * 1e3:g} ms"
        f"{', speeds with noise (3.26)' if run.noise else ''}; unknown: "
        f"{', '.join(run.unknown)}",
        f"  errors: RMS against the reference, each phase less its first "
        f"{SETTLING_TIME * 1e3:g} ms",
    ]
    for p in run.phases:
        e = p.existence
        if e is None:
            lines.append(f"  {p.phase:<14} none of the unknown inputs acts here: no observer run")
            continue
        head = (
            f"  {p.phase:<14} rank CE = {e.rank_CE}, rank E = {e.rank_E}; zeros: "
            f"{', '.join(_zero_text(z) for z in e.invariant_zeros) or 'none'}"
        )
        if e.collinear:
            head += f"; {', '.join(e.collinear)} collinear with them (only the sum is estimable)"
        lines.append(head)
        if not e.exists:
            lines.append(f"    no UIO: {e.reason()}")
            continue
        states = ", ".join(f"{s} {v:.2g}" for s, v in p.state_rmse.items())
        inputs = ", ".join(
            f"{n} {v:.3g} N·m (mean {p.input_mean[n]:.3g})" for n, v in p.input_rmse.items()
        )
        lines.append(f"    |eig F| ≤ {p.spectral_radius:.3g}; states: {states}; {inputs}")
    return "\n".join(lines)


def _zero_text(z: complex) -> str:
    return f"{z.real:.4g}" if abs(z.imag) < 1e-12 else f"{z.real:.4g}{z.imag:+.4g}j"


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


# ---------------------------------------------------------------------------------------------
# EKF (4.3)
# ---------------------------------------------------------------------------------------------

#: Default initial estimate of the augmented parameters, relative to the description's value
#: (m_veh: 30 % light, the issue's wrong-mass case) or absolute (μ: the description's nominal
#: μ; ζ: a level road), and the prior standard deviations (stated, not the truth): the
#: parameters' from their records (:mod:`gearsym.symbolic.parameters`; m_veh's relative to its
#: value), the unmeasured state φ's here.
EKF_INITIAL_MASS_FACTOR = 0.7
EKF_PRIOR_SIGMA = {
    **{r.key: r.prior_sigma for r in RECORDS if r.prior_sigma is not None},
    "phi": 0.05,
}


def element_modes(
    d: GearboxDescription, result: SimulationResult, t: np.ndarray
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per swapping element, (slides, sticks) as 0/1 at the sample times ``t``.

    From the reference's sliding masks (:func:`sliding_masks`: pressed and transmitting its
    capacity); an element that does not slide sticks while it is pressed and is open
    otherwise. These are the *truth's* modes (``--modes reference``); by default the filter
    decides its modes itself (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`).
    """
    from gearsym.validation.studies.sensitivity_run import (
        driven_shift_model,
        reference_from_result,
        sliding_masks,
    )

    data = reference_from_result(result)
    driven = driven_shift_model(d, data.shift)
    masks = sliding_masks(d, driven, data)
    index = np.clip(np.searchsorted(data.t, t - 1e-12), 0, len(data.t) - 1)
    modes = {}
    for e in driven.elements:
        force = data.signals[naming.normal_force(element_short_name(d, e))][index]
        slides = masks[e][index]
        modes[e] = (slides.astype(float), ((~slides) & (force > 0)).astype(float))
    return modes


#: Where the EKF's element modes come from: its own mode logic (the TCU's view, default) or
#: the reference's sliding masks (the truth, for comparison).
MODE_SOURCES = ("filter", "reference")


@dataclass(frozen=True)
class ModeSwitch:
    """A mode switch of one element at time ``t``: ``kind`` break-away, lock-up, opening or
    engagement (the hybrid model's guards); ``before``/``after`` are mode codes
    (:mod:`gearsym.symbolic.estimators.ekf_modes`: 0 open, ±1 slide, 2 stick)."""

    element: str
    kind: str
    t: float
    before: int
    after: int


def _status_code(slides: np.ndarray, sticks: np.ndarray) -> np.ndarray:
    """0 open, 1 slide, 2 stick per sample from 0/1 (or ±1) flags."""
    return np.where(np.abs(slides) > 0.5, 1, np.where(sticks > 0.5, 2, 0))


def mode_switches(
    t: np.ndarray, codes: Mapping[str, np.ndarray], first: Mapping[str, int] | None = None
) -> list[ModeSwitch]:
    """The switches of per-sample mode codes (0 open, ±1 slide, 2 stick; the mode held from
    sample k on), in time order: stick → slide is a break-away, slide → stick (or a slide
    reversing its direction) a lock-up, → open an opening, open → slide or stick an
    engagement. ``first``: the mode before the first sample (the from-gear), so that a switch
    at the first sample counts too (without it the first sample's mode is the start)."""
    from gearsym.symbolic.hybrid import BREAK_AWAY, ENGAGEMENT, LOCK_UP, OPENING

    out = []
    for e, code in codes.items():
        before = int(code[0]) if first is None else int(first[e])
        for k in range(len(t)):
            now = int(code[k])
            if now == before:
                continue
            if now == 0:
                kind = OPENING
            elif before == 0:
                kind = ENGAGEMENT
            elif before == 2:
                kind = BREAK_AWAY
            else:
                kind = LOCK_UP
            out.append(ModeSwitch(e, kind, float(t[k]), before, now))
            before = now
    return sorted(out, key=lambda m: (m.t, m.element))


def reference_switches(d: GearboxDescription, result: SimulationResult) -> list[ModeSwitch]:
    """The truth's mode switches on the reference simulation's own time grid (its sliding
    masks, :func:`element_modes`): the times the filter's detected events are compared with."""
    modes = element_modes(d, result, np.asarray(result.t, dtype=float))
    codes = {e: _status_code(*flags) for e, flags in modes.items()}
    return mode_switches(np.asarray(result.t, dtype=float), codes)


def match_switches(
    detected: Sequence[ModeSwitch], truth: Sequence[ModeSwitch]
) -> list[dict[str, Any]]:
    """Per truth switch (element, kind, in order) the detected one of the same element and
    kind and rank, and the error t_detected − t_truth in ms (None: not detected); detected
    switches without a truth counterpart follow with ``t_reference`` None."""
    out: list[dict[str, Any]] = []
    used: set[int] = set()
    for e, kind in dict.fromkeys((m.element, m.kind) for m in truth):
        mine = [i for i, m in enumerate(detected) if m.element == e and m.kind == kind]
        theirs = [m for m in truth if m.element == e and m.kind == kind]
        for rank, ref in enumerate(theirs):
            hit = detected[mine[rank]] if rank < len(mine) else None
            if hit is not None:
                used.add(mine[rank])
            out.append(
                {
                    "element": e,
                    "kind": kind,
                    "t_reference": ref.t,
                    "t_detected": None if hit is None else hit.t,
                    "error_ms": None if hit is None else 1e3 * (hit.t - ref.t),
                }
            )
    for i, m in enumerate(detected):
        if i not in used:
            out.append(
                {
                    "element": m.element,
                    "kind": m.kind,
                    "t_reference": None,
                    "t_detected": m.t,
                    "error_ms": None,
                }
            )
    return out


@dataclass(frozen=True)
class ParameterEstimate:
    """One augmented parameter over one EKF run."""

    name: str
    truth: float  # at the end of the scored samples (μ: the last sliding sample)
    initial: float
    estimate: float  # at the same sample
    sigma: float
    rmse: float  # over the scored samples (μ: while its element slides)
    scored: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "truth": self.truth,
            "initial": self.initial,
            "estimate": self.estimate,
            "sigma": self.sigma,
            "rmse": self.rmse,
            "samples": self.scored,
            "crb_sigma": None,
            "efficiency": None,
        }


@dataclass(frozen=True)
class EkfRun:
    """The EKF along one reference shift: estimates, σ, truths, NEES and NIS per sample."""

    shift: str
    sample_time: float
    relative_noise: tuple[float, ...]
    seed: int
    state_names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    estimates: np.ndarray = field(repr=False)  # (N, n) after each update
    sigmas: np.ndarray = field(repr=False)  # (N, n)
    truth: np.ndarray = field(repr=False)  # (N, n), NaN where there is none
    scored: np.ndarray = field(repr=False)  # (N, n) bool: truth defined and compared
    nees: np.ndarray = field(repr=False)  # (N,)
    nees_dof: np.ndarray = field(repr=False)  # (N,)
    nis: np.ndarray = field(repr=False)  # (N,)
    nis_dof: np.ndarray = field(repr=False)  # (N,)
    phases: tuple[Phase, ...]
    parameters: tuple[ParameterEstimate, ...]
    min_eigenvalue: float  # smallest eigenvalue of P over the run (scaled), > 0: SPD
    covariance: np.ndarray | None = field(default=None, repr=False)  # P after the last sample
    #: where the element modes came from (:data:`MODE_SOURCES`), the mode codes held from each
    #: sample on (0 open, ±1 slide, 2 stick), the switches, and the truth's switches
    mode_source: str = "reference"
    modes: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    switches: tuple[ModeSwitch, ...] = ()
    reference_switches: tuple[ModeSwitch, ...] = ()

    def events(self) -> list[dict[str, Any]]:
        """The detected switches against the truth's (:func:`match_switches`)."""
        return match_switches(self.switches, self.reference_switches)

    @property
    def nees_mean(self) -> float:
        return float(np.mean(self.nees))

    def nees_band(self, probability: float = 0.95) -> tuple[float, float]:
        """Band of the time-averaged NEES if the filter were consistent: Σ NEES ~ χ²(Σ dof)
        (samples treated as independent, so the band is a narrow one), divided by N."""
        return _chi2_mean_band(self.nees_dof, probability)

    def nees_inside(self, probability: float = 0.95) -> float:
        """Fraction of samples whose NEES lies inside its χ²(dof) interval (expected:
        ``probability``)."""
        from scipy.stats import chi2

        lo = chi2.ppf((1 - probability) / 2, self.nees_dof)
        hi = chi2.ppf((1 + probability) / 2, self.nees_dof)
        return float(np.mean((self.nees >= lo) & (self.nees <= hi)))

    def to_dict(self) -> dict[str, Any]:
        band = self.nees_band()
        used = self.nis_dof > 0
        return {
            "filter": "ekf",
            "shift": self.shift,
            "runs": 1,
            "seed": self.seed,
            "sample_time": self.sample_time,
            "relative_noise": list(self.relative_noise),
            "parameters": {p.name: p.to_dict() for p in self.parameters},
            "nees_mean": self.nees_mean,
            "nees_band": list(band),
            "nees_inside_95": self.nees_inside(),
            "nees_dof_mean": float(np.mean(self.nees_dof)),
            "nis_mean": float(np.mean(self.nis[used])) if used.any() else None,
            "nis_band": list(_chi2_mean_band(self.nis_dof[used])) if used.any() else None,
            "min_covariance_eigenvalue": self.min_eigenvalue,
            "modes": self.mode_source,
            "events": self.events(),
            "phases": [p.to_dict() for p in self.phases],
        }


def _chi2_mean_band(dof: np.ndarray, probability: float = 0.95) -> tuple[float, float]:
    from scipy.stats import chi2

    total, n = float(np.sum(dof)), len(dof)
    return (
        float(chi2.ppf((1 - probability) / 2, total) / n),
        float(chi2.ppf((1 + probability) / 2, total) / n),
    )


@dataclass
class EkfSetup:
    """Everything about an EKF run that does not depend on the noise seed: the sample grid,
    the true outputs and their noise σ (3.26), the known inputs and element modes, the truth
    per augmented state, the initial estimate and the prior σ (P0 = diag(σ0²)). Built once for
    a Monte-Carlo study; only the noise draws change per run."""

    aug: Any
    discrete: Any
    shift: str
    t: np.ndarray
    y_true: np.ndarray  # (N, m)
    sigma_y: np.ndarray  # (N, m): r_i max(|y_i|, y_i^min) (3.26)
    relative: np.ndarray  # (m,)
    floor: np.ndarray  # (m,)
    u: np.ndarray  # (N, n_u), held over each sample interval
    p: list[float]
    q: list[float]
    truth: np.ndarray  # (N, n), NaN where none
    scored: np.ndarray  # (N, n) bool
    initial: np.ndarray  # (n,) initial estimate (speeds: filled in from the first measurement)
    prior_sigma: np.ndarray  # (n,)
    outputs: list[str]
    phases: tuple[Phase, ...]
    #: The outputs are a recording's (``y_true`` holds them, noise included): no noise is
    #: drawn and there is no truth.
    measured: bool = False
    #: :data:`MODE_SOURCES`: "filter" (its own mode logic, ``logic``) or "reference" (the
    #: reference's modes in ``u``); the truth's switches on the reference's own grid
    mode_source: str = "filter"
    logic: Any = None
    reference_switches: tuple[ModeSwitch, ...] = ()

    @property
    def names(self) -> list[str]:
        return self.aug.state_names

    @property
    def truth0(self) -> np.ndarray:
        """The true z0 = [x0; p] as the filter's model sees it: the reference's initial states,
        m_veh and ζ; a μ at its mean while its element slides (the model's μ is constant),
        the initial estimate where an element never slides."""
        n, n_x = len(self.names), self.aug.n_x
        z0 = np.array(
            [
                np.mean(self.truth[self.scored[:, j], j])
                if self.scored[:, j].any()
                else self.initial[j]
                for j in range(n)
            ]
        )
        z0[:n_x] = self.truth[0, :n_x]
        return z0


def prepare_ekf(
    d: GearboxDescription,
    result: SimulationResult,
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | float = EKF_RELATIVE_NOISE,
    initial: Mapping[str, float] | None = None,
    parameters: Sequence[str] | None = None,
    aug: Any = None,
    discrete: Any = None,
    measured: Mapping[str, np.ndarray] | None = None,
    modes: str = "filter",
    logic: Any = None,
) -> EkfSetup:
    """The seed-independent part of :func:`run_ekf` (its arguments of the same name).

    ``modes``: "filter" (default), the filter decides the element modes itself
    (:func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update`; ``logic`` reuses a built
    :class:`~gearsym.symbolic.estimators.ekf_modes.ModeLogic`), or "reference", the
    reference's modes (:func:`element_modes`: the truth, which a TCU does not have).

    ``measured``: per output of the filter its recorded values on the sample grid (a bench
    recording, :mod:`gearsym.validation.sim.measurement`); they replace the reference's outputs,
    no noise is drawn on them, and no state has a truth. ``result`` is then the simulation
    driven by the recorded inputs: it gives the inputs, the element modes and the phases."""
    from gearsym.symbolic.estimators.ekf import DiscreteModel, augmented_model

    shift = result.scenario.shift.name
    if modes not in MODE_SOURCES:
        raise GearsymError(
            "estimate", "--modes", f"expected one of {', '.join(MODE_SOURCES)}, got {modes!r}"
        )
    if aug is None:
        aug = augmented_model(d, shift, parameters)
    if discrete is None:
        discrete = DiscreteModel(aug)
    span = result.t[-1] - result.t[0]
    if not (0 < sample_time <= span / 4):
        raise GearsymError(
            "estimate", "--sample-time", f"must be in (0, {span / 4:g}] s, got {sample_time!r}"
        )
    if modes == "filter" and logic is None:
        from gearsym.symbolic.estimators.ekf_modes import ModeLogic

        logic = ModeLogic(d, aug)
    t = np.arange(result.t[0], result.t[-1] + 1e-12, sample_time)
    names = aug.state_names
    n = len(names)
    outputs = [name.removeprefix("y_") for name in aug.output_names]

    def sampled(name: str) -> np.ndarray:
        return np.interp(t, result.t, result.signals[name])

    if measured is None:
        y_true = np.column_stack([sampled(name) for name in outputs])
    else:
        missing = [name for name in outputs if name not in measured]
        if missing:
            raise GearsymError(
                "estimate",
                "--measurement",
                f"the recording has no channel for the filter's output {missing[0]} (map it in "
                "[measurement.channel])",
            )
        y_true = np.column_stack([np.asarray(measured[name], dtype=float) for name in outputs])
        if y_true.shape[0] != len(t):
            raise GearsymError(
                "estimate",
                "--measurement",
                f"{y_true.shape[0]} recorded samples for {len(t)} sample times",
            )
    r = np.broadcast_to(np.asarray(relative_noise, dtype=float), (len(outputs),)).copy()
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise GearsymError("estimate", "--noise", "relative errors must be finite and > 0")
    floor = EKF_FLOOR_FRACTION * np.nanmax(np.abs(y_true), axis=0)
    sigma_y = r[None, :] * np.maximum(np.abs(y_true), floor[None, :])

    reference_modes = element_modes(d, result, t)
    columns = []
    for name in aug.input_names:
        element = name.split("_", 1)[1] if name.startswith(("slide_", "stick_")) else None
        if element is not None:
            columns.append(reference_modes[element][0 if name.startswith("slide_") else 1])
        else:
            columns.append(sampled(name))
    u = np.column_stack(columns)
    p = aug.parameter_values()
    q = [aug.intensities[name] for name in names]

    # truth per augmented state (NaN where the reference has none)
    truth = np.full((len(t), n), np.nan)
    scored = np.zeros((len(t), n), dtype=bool)
    nominal = {v.name: v.default for v in aug.model.states if v.default is not None}
    for j, name in enumerate(names):
        if name in result.signals:
            truth[:, j] = sampled(name)
            scored[:, j] = True
        elif name == "m_veh":
            truth[:, j] = quantity(d, "vehicle", "m_veh").value
            scored[:, j] = True
    for e, mu in aug.mu_state.items():
        j = names.index(mu)
        scored[:, j] = reference_modes[e][0] > 0.5  # μ is defined while the truth slides
    if measured is not None:  # a recording: no state has a truth
        truth[:] = np.nan
        scored[:] = False

    # initial estimate and prior (the speeds' are set from the first measurement per run)
    z = np.zeros(n)
    sig0 = np.zeros(n)
    for j, name in enumerate(names):
        if name in outputs:
            sig0[j] = sigma_y[0, outputs.index(name)]
        elif name == naming.TWIST:
            z[j], sig0[j] = 0.0, EKF_PRIOR_SIGMA["phi"]
        elif name == "m_veh":
            z[j] = EKF_INITIAL_MASS_FACTOR * float(nominal["m_veh"])
            sig0[j] = EKF_PRIOR_SIGMA["m_veh"] * float(nominal["m_veh"])
        elif name.startswith("mu_"):
            z[j], sig0[j] = float(nominal[name]), EKF_PRIOR_SIGMA["mu"]
        elif name == naming.GRADE:
            z[j], sig0[j] = 0.0, EKF_PRIOR_SIGMA["zeta"]
        else:  # pragma: no cover - every state of the augmented model is covered above
            raise AssertionError(name)
    for name, value in (initial or {}).items():
        if name not in names:
            raise GearsymError(
                "estimate", "--initial", f"{name!r} is not a state ({', '.join(names)})"
            )
        z[names.index(name)] = float(value)
    return EkfSetup(
        aug=aug,
        discrete=discrete,
        shift=shift,
        t=t,
        y_true=y_true,
        sigma_y=sigma_y,
        relative=r,
        floor=floor,
        u=u,
        p=p,
        q=q,
        truth=truth,
        scored=scored,
        initial=z,
        prior_sigma=sig0,
        outputs=outputs,
        phases=tuple(result.phases),
        measured=measured is not None,
        mode_source=modes,
        logic=logic,
        reference_switches=tuple(reference_switches(d, result)),
    )


def run_ekf(
    d: GearboxDescription,
    result: SimulationResult,
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | float = EKF_RELATIVE_NOISE,
    seed: int = 0,
    initial: Mapping[str, float] | None = None,
    parameters: Sequence[str] | None = None,
    dropout: tuple[float, float] | None = None,
    aug: Any = None,
    discrete: Any = None,
    setup: EkfSetup | None = None,
    modes: str = "filter",
) -> EkfRun:
    """The EKF (4.3) on the augmented model (4.1) along the reference shift of ``result``.

    Measurements: the reference's speeds (3.31) every ``sample_time`` s plus Gaussian noise of
    σ_i = r_i max(|y_i|, y_i^min) (3.26), drawn with ``seed``; ``dropout`` = (t0, t1) replaces
    every measurement in [t0, t1) by NaN (a sensor dropout: the updates are skipped). Known
    inputs T_In, F_N at the samples, held; element modes decided by the filter (``modes``
    "filter", default) or the reference's (:func:`element_modes`, ``modes`` "reference").
    ``initial`` overrides the default initial estimate (m_veh 30 % light, μ nominal, ζ 0, φ 0,
    the speeds from the first measurement). ``aug``/``discrete`` reuse a built model;
    ``setup`` (from :func:`prepare_ekf`) reuses everything but the noise draws.
    """
    if setup is None:
        setup = prepare_ekf(
            d, result, sample_time, relative_noise, initial, parameters, aug, discrete, modes=modes
        )
    return filter_run(setup, seed, dropout)


def noisy_outputs(setup: EkfSetup, seed: int) -> np.ndarray:
    """The synthetic measurements: the reference's outputs plus Gaussian noise of
    σ_i = r_i max(|y_i|, y_i^min) (3.26), drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    return setup.y_true + rng.normal(0.0, 1.0, setup.y_true.shape) * setup.sigma_y


def start_from_first_measurement(
    s: EkfSetup, y0: np.ndarray, z: np.ndarray, sig0: np.ndarray
) -> np.ndarray:
    """Set the measured states of ``z`` to the first measurement ``y0`` (in place; a missing
    one: 0 with σ 1e3 in ``sig0``) and return what the first update may still use.

    The first measurement of a speed *is* its initial estimate (variance R, the prior of
    sig0): it is used once, so the update at the first sample skips it (NaN). Updating with it
    again would count one noise draw twice (the speed's σ halved for an error of one σ) and
    add innovations that are 0 by construction to the NIS (3 of its dof per run)."""
    first = np.array(y0, dtype=float)
    for k, name in enumerate(s.outputs):
        if name in s.names:
            j = s.names.index(name)
            if np.isfinite(y0[k]):
                z[j] = y0[k]
                first[k] = np.nan
            else:
                z[j], sig0[j] = 0.0, 1e3
    return first


def filter_run(
    setup: EkfSetup,
    seed: int = 0,
    dropout: tuple[float, float] | None = None,
    prior_draw: bool = False,
    dropout_outputs: Sequence[str] | None = None,
    carried: tuple[Sequence[str], np.ndarray, np.ndarray] | None = None,
) -> EkfRun:
    """One EKF run (4.3) on ``setup``'s samples with the noise (3.26) drawn from ``seed``.

    ``carried`` = (names, mean, covariance): the initial estimate and the covariance block of
    these states are taken over from a previous run (a drive of consecutive shifts: what the
    filter knows about m_veh and ζ at the end of one shift is its prior for the next).

    ``dropout`` = (t0, t1): the measurements in [t0, t1) are NaN (a sensor dropout), of every
    output or only of ``dropout_outputs`` (names of :attr:`EkfSetup.outputs`); the update
    skips each NaN speed on its own, as the emitted C does.

    ``prior_draw``: the initial estimate of every unmeasured state (φ and the parameters) is
    the truth (:attr:`EkfSetup.truth0`) plus a draw from the prior N(0, σ0²) (a second stream
    of ``seed``), the premise of the posterior bound, instead of the fixed initial estimate.

    Element modes (``setup.mode_source``): "reference" takes them from ``setup.u`` (the
    truth's); "filter" starts in the from-gear and, after each update, lets
    :func:`~gearsym.symbolic.estimators.ekf_modes.ekf_mode_update` decide the modes held over
    the next interval from the posterior, the measured speeds' estimate and F_N (a lock-up
    maps z and P through the hybrid model's state map). The estimate, σ and NEES recorded at
    a sample are the update's; a switch decided there acts from the next prediction on (at a
    lock-up the mapped covariance is singular in the slip until the prediction adds its
    model error)."""
    from gearsym.symbolic.estimators.ekf import ekf_predict, ekf_update
    from gearsym.symbolic.estimators.ekf_modes import ekf_mode_update

    s = setup
    t, names, n = s.t, s.names, len(s.names)
    sample_time = float(t[1] - t[0])
    y = s.y_true.copy() if s.measured else noisy_outputs(s, seed)
    if dropout is not None:
        lost = (t >= dropout[0]) & (t < dropout[1])
        for name in dropout_outputs if dropout_outputs is not None else s.outputs:
            if name not in s.outputs:
                raise GearsymError(
                    "estimate", "--dropout", f"{name!r} is not an output ({', '.join(s.outputs)})"
                )
            y[lost, s.outputs.index(name)] = np.nan
    z = s.initial.copy()
    sig0 = s.prior_sigma.copy()
    if prior_draw:
        unmeasured = np.array([name not in s.outputs for name in names])
        draw = np.random.default_rng([seed, 1]).normal(0.0, 1.0, len(z)) * sig0
        z[unmeasured] = s.truth0[unmeasured] + draw[unmeasured]
    first = start_from_first_measurement(s, y[0], z, sig0)
    P = np.diag(sig0**2)
    if carried is not None:
        idx = [names.index(name) for name in carried[0]]
        z[idx] = carried[1]
        P[np.ix_(idx, idx)] = carried[2]
        sig0[idx] = np.sqrt(np.diag(carried[2]))
    initial_values = z.copy()
    truth, scored = s.truth, s.scored

    estimates = np.empty((len(t), n))
    sigmas = np.empty((len(t), n))
    nis = np.zeros(len(t))
    nis_dof = np.zeros(len(t))
    nees = np.zeros(len(t))
    min_eig = np.inf
    scale = np.maximum(sig0, 1e-12)
    logic = s.logic if s.mode_source == "filter" else None
    if logic is not None:
        modes = logic.initial_modes()
        codes = {e: np.zeros(len(t), dtype=int) for e in logic.elements}
        switches: list[ModeSwitch] = []
        held = logic.inputs(s.u[0], modes)
    for k in range(len(t)):
        if logic is None:
            u_before, u_now = s.u[k - 1], s.u[k]
        else:  # the modes held since the previous sample, the known inputs of this one
            u_before, u_now = held, logic.inputs(s.u[k], modes)
        if k > 0:
            z, P = ekf_predict(s.discrete, z, P, u_before, sample_time, s.p, s.q)
        z, P, nis[k], nis_dof[k] = ekf_update(
            s.discrete, z, P, u_now, first if k == 0 else y[k], s.p, s.relative, s.floor
        )
        estimates[k] = z
        sigmas[k] = np.sqrt(np.diag(P))
        min_eig = min(min_eig, float(np.linalg.eigvalsh(P / np.outer(scale, scale))[0]))
        idx = np.flatnonzero(scored[k])
        error = z[idx] - truth[k, idx]
        nees[k] = float(error @ np.linalg.solve(P[np.ix_(idx, idx)], error))
        if logic is not None:
            z, P, modes, decided = ekf_mode_update(logic, z, P, s.u[k], s.p, modes)
            switches += [
                ModeSwitch(ev.element, ev.kind, float(t[k]), ev.before, ev.after) for ev in decided
            ]
            for e, code in modes.items():
                codes[e][k] = code
            held = logic.inputs(s.u[k], modes)
    if logic is None:
        aug, inputs = s.aug, s.aug.input_names
        codes = {
            e: _status_code(s.u[:, inputs.index(f"slide_{e}")], s.u[:, inputs.index(f"stick_{e}")])
            for e in aug.elements
        }
        switches = mode_switches(t, codes)

    estimates_by_parameter = []
    for name in s.aug.parameters:
        j = names.index(name)
        inside = np.flatnonzero(scored[:, j])
        last = inside[-1] if inside.size else len(t) - 1
        err = estimates[inside, j] - truth[inside, j]
        estimates_by_parameter.append(
            ParameterEstimate(
                name=name,
                truth=float(truth[last, j]),
                initial=float(initial_values[j]),
                estimate=float(estimates[last, j]),
                sigma=float(sigmas[last, j]),
                rmse=float(np.sqrt(np.mean(err**2))) if inside.size else float("nan"),
                scored=int(inside.size),
            )
        )
    return EkfRun(
        shift=s.shift,
        sample_time=sample_time,
        relative_noise=tuple(float(v) for v in s.relative),
        seed=seed,
        state_names=tuple(names),
        t=t,
        estimates=estimates,
        sigmas=sigmas,
        truth=truth,
        scored=scored,
        nees=nees,
        nees_dof=scored.sum(axis=1).astype(float),
        nis=nis,
        nis_dof=nis_dof,
        phases=s.phases,
        parameters=tuple(estimates_by_parameter),
        min_eigenvalue=min_eig,
        covariance=P,
        mode_source=s.mode_source,
        modes=codes,
        switches=tuple(switches),
        reference_switches=s.reference_switches,
    )


#: The parameters a drive of consecutive shifts carries from one shift to the next: they
#: belong to the vehicle and the road, not to a shift's elements.
DRIVE_CARRIED = ("m_veh", "zeta")


def run_ekf_drive(
    d: GearboxDescription,
    results: Sequence[SimulationResult],
    seed: int = 0,
    sample_time: float = 0.01,
    initial: Mapping[str, float] | None = None,
    modes: str = "filter",
) -> list[EkfRun]:
    """The EKF (4.3) through consecutive shifts, carrying m_veh and ζ (:data:`DRIVE_CARRIED`).

    Each result is one shift's reference simulation (its own scenario, simulated on its own:
    the reference does not chain shifts, so the vehicle speed at one shift's start is its
    scenario's, not the previous shift's end). The filter of shift k+1 (its own augmented
    model (4.1): the μ of its swapping elements) starts from the estimate and the covariance
    block of m_veh and ζ at the end of shift k; its other states start as in a single shift
    (μ at the prior: another element or another operating point). ``initial`` is the first
    shift's initial estimate; shift k uses noise seed ``seed`` + k. ``modes``: as
    :func:`prepare_ekf` (each shift's filter starts in its from-gear)."""
    runs: list[EkfRun] = []
    carried = None
    for k, result in enumerate(results):
        setup = prepare_ekf(
            d, result, sample_time, initial=initial if k == 0 else None, modes=modes
        )
        run = filter_run(setup, seed + k, carried=carried)
        idx = [list(run.state_names).index(name) for name in DRIVE_CARRIED]
        assert run.covariance is not None
        carried = (
            DRIVE_CARRIED,
            run.estimates[-1, idx].copy(),
            run.covariance[np.ix_(idx, idx)].copy(),
        )
        runs.append(run)
    return runs


def write_ekf_csv(run: EkfRun, path: Path) -> Path:
    """Every sample: t, phase, per augmented state its estimate, σ and truth (empty where none),
    NEES with its dof, NIS with its dof, and per element the mode held from the sample on
    (0 open, ±1 slide, 2 stick)."""
    from gearsym.validation.studies.sensitivity_run import phase_of

    header = ["t", "phase"]
    for name in run.state_names:
        header += [f"{name}_hat", f"{name}_sigma", name]
    header += ["nees", "nees_dof", "nis", "nis_dof"]
    header += [f"mode_{e}" for e in run.modes]
    lines = [",".join(header)]

    def num(v: float) -> str:
        return f"{v:.9g}" if np.isfinite(v) else ""

    for k, t in enumerate(run.t):
        row = [f"{t:.6g}", phase_of(run.phases, float(t))]
        for j in range(len(run.state_names)):
            truth = run.truth[k, j] if run.scored[k, j] else np.nan
            row += [num(run.estimates[k, j]), num(run.sigmas[k, j]), num(truth)]
        row += [num(run.nees[k]), f"{run.nees_dof[k]:g}", num(run.nis[k]), f"{run.nis_dof[k]:g}"]
        row += [str(int(codes[k])) for codes in run.modes.values()]
        lines.append(",".join(row))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def shade_phases(axes: Sequence[Any], phases: Sequence[Phase]) -> None:
    """Shade each phase on every axis and name it above the first; short phases sit side by
    side, so their names alternate between two heights and never overlap."""
    for ax in axes:
        for k, phase in enumerate(phases):
            ax.axvspan(phase.t_start, phase.t_end, color="0.93" if k % 2 else "0.85", lw=0)
    for k, phase in enumerate(phases):
        axes[0].annotate(
            phase.name,
            ((phase.t_start + phase.t_end) / 2, 1.03 + 0.1 * (k % 2)),
            xycoords=("data", "axes fraction"),
            ha="center",
            fontsize=7,
        )


def plot_ekf(run: EkfRun, path: Path) -> Path:
    """Each augmented parameter's estimate against the truth with ±3σ, the phases shaded, and
    the NEES against its per-sample 95 % χ² interval."""
    from gearsym.validation.drawing.figures import save, subplots
    from scipy.stats import chi2

    names = [p.name for p in run.parameters]
    fig, axes = subplots(
        len(names) + 1,
        1,
        (8, 2.0 * (len(names) + 1)),
        {"top": 0.93, "bottom": 0.05, "hspace": 0.12, "left": 0.1},
        sharex=True,
    )
    shade_phases(axes, run.phases)
    for ax, name in zip(axes, names, strict=False):
        j = run.state_names.index(name)
        est, sig = run.estimates[:, j], run.sigmas[:, j]
        truth = np.where(run.scored[:, j], run.truth[:, j], np.nan)
        ax.fill_between(run.t, est - 3 * sig, est + 3 * sig, color="C0", alpha=0.2, lw=0)
        ax.plot(run.t, est, color="C0", label="EKF estimate ±3σ")
        ax.plot(run.t, truth, color="k", lw=1.2, label="reference (where defined)")
        if name.startswith("mu_"):
            ax.plot(run.t, run.truth[:, j], color="k", lw=0.6, ls=":", label="reference μ map")
        finite = truth[np.isfinite(truth)]
        centre = float(np.median(finite)) if finite.size else float(np.median(est))
        spread = max(float(np.max(np.abs(est - centre))) * 1.3, 1e-3)
        ax.set_ylim(centre - spread, centre + spread)
        ax.set_ylabel(axis_label(name))
        ax.legend(fontsize=6, loc="upper right")
    ax = axes[-1]
    lo = chi2.ppf(0.025, run.nees_dof)
    hi = chi2.ppf(0.975, run.nees_dof)
    ax.fill_between(run.t, lo, hi, color="C2", alpha=0.2, lw=0, label="95 % χ² interval")
    ax.plot(run.t, run.nees, color="C3", lw=0.8, label=f"NEES (mean {run.nees_mean:.2f})")
    ax.set_yscale("log")
    ax.set_ylabel("NEES")
    ax.set_xlabel("t / s")
    ax.legend(fontsize=6, loc="upper right")
    noise = ", ".join(f"{v:g}" for v in sorted(set(run.relative_noise)))
    fig.suptitle(
        f"EKF (4.3) on the augmented {run.shift} shift model (4.1): samples every "
        f"{run.sample_time * 1e3:g} ms, speed noise r = {noise} (3.26), seed {run.seed}",
        fontsize=10,
    )
    return save(fig, path)


def format_ekf_text(run: EkfRun) -> str:
    """Per parameter: truth, initial, final estimate ± σ, RMS error; NEES and NIS."""
    lines = [
        f"EKF (4.3) of the {run.shift} shift on the reference simulation, samples every "
        f"{run.sample_time * 1e3:g} ms, speed noise (3.26) r = "
        f"{', '.join(f'{v:g}' for v in run.relative_noise)}, seed {run.seed}",
        "  parameter      truth    initial   estimate ± σ           RMS error (samples)",
    ]
    for p in run.parameters:
        lines.append(
            f"  {p.name:<8} {p.truth:>10.4g} {p.initial:>10.4g} {p.estimate:>10.4g} ± "
            f"{p.sigma:<10.3g} {p.rmse:>10.3g} ({p.scored})"
        )
    lo, hi = run.nees_band()
    d = run.to_dict()
    lines.append(
        f"  NEES mean {run.nees_mean:.2f} (dof {d['nees_dof_mean']:.2f}; 95 % band if samples "
        f"were independent {lo:.2f}..{hi:.2f}); {100 * run.nees_inside():.0f} % of samples "
        f"inside their 95 % χ² interval"
    )
    if d["nis_mean"] is not None:
        nis_lo, nis_hi = d["nis_band"]
        lines.append(f"  NIS mean {d['nis_mean']:.2f} (band {nis_lo:.2f}..{nis_hi:.2f})")
    lines.append(
        "  μ is scored while its element slides; outside that its estimate and σ are frozen"
    )
    lines += _mode_lines(run.mode_source, run.events(), len(run.switches))
    return "\n".join(lines)


_MODE_TEXT = {
    "filter": "element modes decided by the filter (estimated slip, sticking torque against "
    "2 N r_m μ̂ F_N, F_N; lock-ups mapped through the hybrid model's state map)",
    "reference": "element modes from the reference's sliding masks (the truth, not a TCU's)",
}


def _mode_lines(source: str, events: Sequence[Mapping[str, Any]], detected: int) -> list[str]:
    """The mode source and each switch against the truth's, one line each."""
    lines = [f"  {_MODE_TEXT[source]}; {detected} switches"]
    for ev in events:
        head = f"    {ev['element']} {ev['kind']}:"
        if ev["t_reference"] is None:
            lines.append(f"{head} at {ev['t_detected']:.3f} s, none in the reference")
        elif ev.get("t_detected") is None and ev.get("detected_runs") is None:
            lines.append(f"{head} reference {ev['t_reference']:.4f} s, not detected")
        elif "detected_runs" in ev:
            if ev["detected_runs"] == 0:
                lines.append(f"{head} reference {ev['t_reference']:.4f} s, not detected")
                continue
            lines.append(
                f"{head} reference {ev['t_reference']:.4f} s; detected in "
                f"{ev['detected_runs']} of {ev['runs']} runs, error mean "
                f"{ev['error_ms_mean']:+.1f} ms, max |error| {ev['error_ms_max_abs']:.1f} ms"
            )
        else:
            lines.append(
                f"{head} at {ev['t_detected']:.3f} s, reference {ev['t_reference']:.4f} s "
                f"({ev['error_ms']:+.1f} ms)"
            )
    return lines


# ---------------------------------------------------------------------------------------------
# Monte-Carlo evaluation against the matched posterior Cramér–Rao bound
# ---------------------------------------------------------------------------------------------

#: How the bound is matched to the filter, printed beside every efficiency.
BOUND_ASSUMPTION = (
    "posterior Cramér–Rao bound (3.25 with the filter's prior P0): the filter's model (4.1), "
    "element modes, sample times and speed noise (3.26), initial states unknown; parameters "
    "constant and the model exact. The filter's random walks (4.1) and model-error noise make "
    "it forget, the truth's μ follows the μ map and the reference is elastic, so efficiency "
    "RMSE / bound > 1 is expected even of a good filter. The bound averages over truths drawn "
    "from the prior; the runs keep one truth and one initial estimate (m_veh 1 prior σ off, "
    "μ and ζ closer), so below 1 is possible where the prior still dominates"
)

NOT_IDENTIFIABLE = "not identifiable in this phase"


@dataclass(frozen=True)
class EkfBound:
    """The posterior Cramér–Rao bound matched to the EKF (:mod:`.posterior_bound`), per sample,
    and what each phase's own information identifies."""

    names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    sigma: np.ndarray = field(repr=False)  # (N, n): sqrt(diag J_k⁻¹) of z0 = [x0; p]
    #: per phase name: the parameters the phase's own information identifies (the thesis'
    #: elimination (3.3) on its FIM (3.25), the states at the phase start unknown)
    identifiable: dict[str, tuple[str, ...]]
    #: per phase name: γ_j (3.27) of every parameter on the phase's own FIM, all estimated
    gamma: dict[str, dict[str, float]]
    linearised_at: np.ndarray = field(repr=False)  # z0 of the sensitivities
    #: (N, n): the bound of z_k with the filter's process noise (random walks (4.1) and model
    #: error), :func:`~gearsym.validation.studies.posterior_bound.process_noise_bound`
    sigma_process: np.ndarray = field(repr=False)


def ekf_bound(setup: EkfSetup, relative_step: float = 1e-5) -> EkfBound:
    """The posterior bound J_k = P0⁻¹ + Σ S_iᵀ R_i⁻¹ S_i (3.25, 3.26) of the EKF's problem
    (``setup``): sensitivities of the sampled speeds to z0 = [x0; p] by central differences
    of tight DOP853 trajectories of the filter's right-hand side (lambdified, not the filter's
    CasADi functions or RK4 Jacobian), linearised at the truth (the reference's initial
    states, m_veh, ζ; μ at its mean while its element slides). Per phase, the phase's own FIM
    with the states at its start as nuisance (Schur complement, restarted there) goes through
    the thesis' elimination (3.3, γ_max of :data:`GAMMA_MAX`)."""
    from gearsym.symbolic.defaults import GAMMA_MAX
    from gearsym.symbolic.fisher import eliminate
    from gearsym.validation.studies.hybrid_fisher import schur_complement
    from gearsym.validation.studies.posterior_bound import (
        bound_sigma,
        information_increments,
        lambdified,
        output_sensitivities,
        posterior_information,
        process_noise_bound,
    )
    from gearsym.validation.studies.sensitivity_run import nominal_scales

    model = setup.aug.model
    args = (model.state_symbols, model.input_symbols, model.parameter_symbols, setup.p)
    f = lambdified(list(model.rhs), *args)
    h = lambdified(list(model.output_expressions), *args)
    names = setup.names
    n, n_x = len(names), setup.aug.n_x
    z0 = setup.truth0
    steps = relative_step * np.maximum(np.abs(z0), setup.prior_sigma)
    variances = setup.sigma_y**2
    _, S, z, flow = output_sensitivities(f, h, z0, setup.t, setup.u, steps, return_flow=True)
    # the speeds' prior (σ of their first measurement) *is* that measurement (filter_run
    # initialises them from it and skips it in the first update): counted once, as the prior
    used_once = variances.copy()
    used_once[0, [k for k, name in enumerate(setup.outputs) if name in names]] = np.inf
    J = posterior_information(S, used_once, np.diag(setup.prior_sigma**2))
    # the filter's process noise over each sample interval: h q, a μ's zero while its
    # element does not slide (its random walk is switched off there, ekf_predict)
    h_step = float(setup.t[1] - setup.t[0]) if len(setup.t) > 1 else 0.0
    process = np.zeros((len(setup.t), n, n))
    for k in range(len(setup.t)):
        rates = np.array(setup.q, dtype=float)
        rates[setup.aug.frozen_states(setup.u[k])] = 0.0
        process[k] = np.diag(h_step * rates)
    sigma_process = process_noise_bound(flow, S, used_once, np.diag(setup.prior_sigma**2), process)
    parameters = list(setup.aug.parameters)
    values = {name: float(z0[names.index(name)]) for name in parameters}
    scales = nominal_scales(parameters, values)
    identifiable: dict[str, tuple[str, ...]] = {}
    gamma: dict[str, dict[str, float]] = {}
    for k, phase in enumerate(setup.phases):
        inside = _phase_samples(setup.t, phase, last=k == len(setup.phases) - 1)
        if inside.size == 0:
            identifiable[phase.name], gamma[phase.name] = (), {}
            continue
        a = inside[0]
        _, G, _ = output_sensitivities(
            f,
            h,
            z[a],
            setup.t[inside],
            setup.u[inside],
            relative_step * np.maximum(np.abs(z[a]), setup.prior_sigma),
        )
        fim = schur_complement(
            _reorder(information_increments(G, variances[inside]).sum(axis=0), n_x),
            n - n_x,
        )
        elimination = eliminate(fim, parameters, scales, gamma_max=GAMMA_MAX)
        identifiable[phase.name] = tuple(elimination.final)
        first = elimination.steps[0].analysis
        gamma[phase.name] = {
            name: float(g) for name, g in zip(first.names, first.gamma, strict=True)
        }
    return EkfBound(
        names=tuple(names),
        t=setup.t,
        sigma=bound_sigma(J),
        identifiable=identifiable,
        gamma=gamma,
        linearised_at=z0,
        sigma_process=sigma_process,
    )


def _reorder(fim: np.ndarray, n_x: int) -> np.ndarray:
    """[x; p] ordered as [p; x] (the Schur complement keeps the leading block)."""
    order = np.r_[np.arange(n_x, len(fim)), np.arange(n_x)]
    return fim[np.ix_(order, order)]


def _phase_samples(t: np.ndarray, phase: Phase, last: bool) -> np.ndarray:
    """Indices of the samples in [t_start, t_end) of ``phase`` (the last phase: its end too)."""
    return np.flatnonzero((t >= phase.t_start) & ((t < phase.t_end) | last))


@dataclass(frozen=True)
class PhaseParameterStats:
    """One parameter in one phase over the Monte-Carlo runs."""

    samples: int  # scored samples per run
    mean_error: float | None
    rmse: float | None
    sigma: float | None  # reported σ, RMS over the scored samples and runs
    crb_sigma: float | None  # the posterior bound, RMS over the same samples
    efficiency: float | None  # rmse / crb_sigma
    #: the bound with the filter's process noise (random walks, model error), and rmse over it
    crb_sigma_process: float | None
    efficiency_process: float | None
    identifiable: bool
    gamma: float | None  # (3.27) on the phase's own FIM
    #: filter σ and bound at the phase's last sample over those before it (1: no information)
    sigma_ratio: float
    crb_ratio: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "samples": self.samples,
            "mean_error": self.mean_error,
            "rmse": self.rmse,
            "sigma": self.sigma,
            "crb_sigma": self.crb_sigma,
            "efficiency": self.efficiency,
            "crb_sigma_process_noise": self.crb_sigma_process,
            "efficiency_process_noise": self.efficiency_process,
            "identifiable": self.identifiable,
            "verdict": None if self.identifiable else NOT_IDENTIFIABLE,
            "gamma": self.gamma if self.gamma is None or np.isfinite(self.gamma) else "inf",
            "sigma_ratio": self.sigma_ratio,
            "crb_ratio": self.crb_ratio,
        }


@dataclass(frozen=True)
class EkfMonteCarlo:
    """The EKF over ``len(runs)`` noise seeds of one reference shift, with the matched bound."""

    runs: tuple[EkfRun, ...]
    bound: EkfBound
    seconds_per_run: float
    #: per phase name, per parameter
    phase_stats: dict[str, dict[str, PhaseParameterStats]]
    #: initial estimates drawn from the prior around the truth (else the fixed default)
    prior_draw: bool = False

    @property
    def first(self) -> EkfRun:
        return self.runs[0]

    def _stack(self, attribute: str) -> np.ndarray:
        return np.array([getattr(r, attribute) for r in self.runs])

    def nees_run_mean(self) -> np.ndarray:
        """ε̄_k: NEES at each sample averaged over the runs."""
        return np.mean(self._stack("nees"), axis=0)

    @property
    def nees_mean(self) -> float:
        return float(np.mean(self.nees_run_mean()))

    def nees_band(self, probability: float = 0.95) -> tuple[float, float]:
        """Band of the NEES mean of a consistent filter: one sample's mean over the R runs is
        χ²(R n)/R (n its dof, the runs independent); the time average of such means, which are
        correlated in time, scatters no more than one of them. n: the mean dof."""
        from scipy.stats import chi2

        runs, dof = len(self.runs), float(np.mean(self.first.nees_dof))
        return (
            float(chi2.ppf((1 - probability) / 2, runs * dof) / runs),
            float(chi2.ppf((1 + probability) / 2, runs * dof) / runs),
        )

    def nees_inside(self, probability: float = 0.95) -> float:
        """Fraction of samples whose run-averaged NEES lies inside its χ²(R n_k)/R band."""
        from scipy.stats import chi2

        runs, dof = len(self.runs), self.first.nees_dof
        lo = chi2.ppf((1 - probability) / 2, runs * dof) / runs
        hi = chi2.ppf((1 + probability) / 2, runs * dof) / runs
        mean = self.nees_run_mean()
        return float(np.mean((mean >= lo) & (mean <= hi)))

    def parameter_summary(self, name: str) -> dict[str, Any]:
        """Over every scored sample of every run: the JSON entry of one parameter."""
        first = self.first
        j = first.state_names.index(name)
        scored = first.scored[:, j]
        errors = self._stack("estimates")[:, scored, j] - first.truth[None, scored, j]
        sigmas = self._stack("sigmas")[:, scored, j]
        crb = self.bound.sigma[scored, j]
        crb_process = self.bound.sigma_process[scored, j]
        process_rms = float(np.sqrt(np.mean(crb_process**2))) if crb_process.size else None
        final = [next(p for p in r.parameters if p.name == name) for r in self.runs]
        rmse = float(np.sqrt(np.mean(errors**2))) if errors.size else None
        crb_rms = float(np.sqrt(np.mean(crb**2))) if crb.size else None
        return {
            "truth": final[0].truth,
            "initial": float(np.mean([p.initial for p in final])),
            "estimate": float(np.mean([p.estimate for p in final])),
            "sigma": float(np.mean([p.sigma for p in final])),
            "rmse": rmse,
            "mean_error": float(np.mean(errors)) if errors.size else None,
            "sigma_rms": float(np.sqrt(np.mean(sigmas**2))) if sigmas.size else None,
            "crb_sigma": crb_rms,
            "efficiency": None if rmse is None or not crb_rms else rmse / crb_rms,
            "crb_sigma_process_noise": process_rms,
            "efficiency_process_noise": None
            if rmse is None or not process_rms
            else rmse / process_rms,
            "identifiable": [
                phase for phase, stats in self.phase_stats.items() if stats[name].identifiable
            ],
            "samples": int(np.count_nonzero(scored)),
        }

    def to_dict(self) -> dict[str, Any]:
        first = self.first
        band = self.nees_band()
        nis = self._stack("nis")
        nis_dof = first.nis_dof
        used = nis_dof > 0
        return {
            "filter": "ekf",
            "shift": first.shift,
            "runs": len(self.runs),
            "seed": first.seed,
            "seeds": [r.seed for r in self.runs],
            "sample_time": first.sample_time,
            "relative_noise": list(first.relative_noise),
            "seconds_per_run": self.seconds_per_run,
            "initial_estimate": "drawn from the prior around the truth"
            if self.prior_draw
            else "fixed",
            "parameters": {name: self.parameter_summary(name) for name in self.parameter_names},
            "bound": BOUND_ASSUMPTION,
            "nees_mean": self.nees_mean,
            "nees_band": list(band),
            "nees_dof_mean": float(np.mean(first.nees_dof)),
            "nees_inside_95": self.nees_inside(),
            "nis_mean": float(np.mean(nis[:, used])) if used.any() else None,
            "nis_band": list(_chi2_mean_band(np.tile(nis_dof[used], len(self.runs))))
            if used.any()
            else None,
            "min_covariance_eigenvalue": min(r.min_eigenvalue for r in self.runs),
            "modes": first.mode_source,
            "events": self.event_summary(),
            "phases": [
                {
                    **phase.to_dict(),
                    "parameters": {
                        name: stats.to_dict()
                        for name, stats in self.phase_stats[phase.name].items()
                    },
                }
                for phase in first.phases
            ],
        }

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.first.parameters]

    def event_summary(self) -> list[dict[str, Any]]:
        """Per truth switch: in how many runs the filter detected it and the error
        t_detected − t_truth over those runs (mean, largest magnitude, ms); then the mean
        number per run of detected switches the truth does not have."""
        per_run = [r.events() for r in self.runs]
        out: list[dict[str, Any]] = []
        for i, ev in enumerate(e for e in per_run[0] if e["t_reference"] is not None):
            errors = [
                events[i]["error_ms"] for events in per_run if events[i]["error_ms"] is not None
            ]
            out.append(
                {
                    "element": ev["element"],
                    "kind": ev["kind"],
                    "t_reference": ev["t_reference"],
                    "runs": len(self.runs),
                    "detected_runs": len(errors),
                    "error_ms_mean": float(np.mean(errors)) if errors else None,
                    "error_ms_max_abs": float(np.max(np.abs(errors))) if errors else None,
                }
            )
        extra = [sum(e["t_reference"] is None for e in events) for events in per_run]
        if any(extra):
            out.append(
                {
                    "element": "any",
                    "kind": "switches without a reference counterpart (mean per run)",
                    "t_reference": None,
                    "t_detected": None,
                    "count_mean": float(np.mean(extra)),
                }
            )
        return out


def run_ekf_monte_carlo(
    setup: EkfSetup,
    runs: int,
    seed: int = 0,
    progress: Any = None,
    bound: EkfBound | None = None,
    prior_draw: bool = False,
    dropout: tuple[float, float] | None = None,
    dropout_outputs: Sequence[str] | None = None,
) -> EkfMonteCarlo:
    """The EKF (4.3) over ``runs`` seeds ``seed``, ``seed`` + 1, …: the reference and
    everything of ``setup`` fixed, only the speed noise (3.26) drawn anew. ``progress(fraction,
    message)`` is called after each run. Per parameter and phase: mean error, RMSE and RMS
    reported σ over the scored samples of every run, the posterior bound (:func:`ekf_bound`)
    over the same samples and the efficiency RMSE / bound; the phase's own identifiability.
    ``prior_draw``: each run's initial estimate drawn from the prior around the truth
    (:func:`filter_run`), the bound's premise. ``dropout``/``dropout_outputs``: a sensor
    dropout in every run (:func:`filter_run`); the bound keeps every sample."""
    import time

    if runs < 1:
        raise GearsymError("estimate", "--runs", f"must be at least 1, got {runs}")
    done = []
    start = time.perf_counter()
    for i in range(runs):
        done.append(
            filter_run(
                setup,
                seed + i,
                dropout=dropout,
                prior_draw=prior_draw,
                dropout_outputs=dropout_outputs,
            )
        )
        if progress is not None:
            progress((i + 1) / runs, f"run {i + 1} of {runs}")
    seconds = (time.perf_counter() - start) / runs
    if bound is None:
        if progress is not None:
            progress(1.0, "posterior Cramér–Rao bound")
        bound = ekf_bound(setup)
    estimates = np.array([r.estimates for r in done])
    sigmas = np.array([r.sigmas for r in done])
    first = done[0]
    stats: dict[str, dict[str, PhaseParameterStats]] = {}
    for k, phase in enumerate(first.phases):
        inside = _phase_samples(first.t, phase, last=k == len(first.phases) - 1)
        stats[phase.name] = {}
        for p in first.parameters:
            j = first.state_names.index(p.name)
            idx = inside[first.scored[inside, j]]
            err = estimates[:, idx, j] - first.truth[None, idx, j]
            sig = sigmas[:, idx, j]
            crb = bound.sigma[idx, j]
            crb_process = bound.sigma_process[idx, j]
            before = max(int(inside[0]) - 1, 0) if inside.size else 0
            end = int(inside[-1]) if inside.size else 0
            rmse = float(np.sqrt(np.mean(err**2))) if idx.size else None
            crb_rms = float(np.sqrt(np.mean(crb**2))) if idx.size else None
            process_rms = float(np.sqrt(np.mean(crb_process**2))) if idx.size else None
            g = bound.gamma.get(phase.name, {}).get(p.name)
            stats[phase.name][p.name] = PhaseParameterStats(
                samples=int(idx.size),
                mean_error=float(np.mean(err)) if idx.size else None,
                rmse=rmse,
                sigma=float(np.sqrt(np.mean(sig**2))) if idx.size else None,
                crb_sigma=crb_rms,
                efficiency=None if rmse is None or not crb_rms else rmse / crb_rms,
                crb_sigma_process=process_rms,
                efficiency_process=None if rmse is None or not process_rms else rmse / process_rms,
                identifiable=p.name in bound.identifiable.get(phase.name, ()),
                gamma=g,
                sigma_ratio=float(np.mean(sigmas[:, end, j]) / np.mean(sigmas[:, before, j])),
                crb_ratio=float(bound.sigma[end, j] / bound.sigma[before, j]),
            )
    return EkfMonteCarlo(
        runs=tuple(done),
        bound=bound,
        seconds_per_run=seconds,
        phase_stats=stats,
        prior_draw=prior_draw,
    )


def format_monte_carlo_text(mc: EkfMonteCarlo) -> str:
    """Per phase and parameter: mean error, RMSE, σ, bound, efficiency, or "not identifiable
    in this phase" with the σ ratio; the NEES mean against its band."""
    first = mc.first
    lines = [
        f"EKF (4.3) of the {first.shift} shift, Monte-Carlo over {len(mc.runs)} noise seeds "
        f"({first.seed}..{first.seed + len(mc.runs) - 1}; the reference simulated once), "
        f"samples every {first.sample_time * 1e3:g} ms, speed noise (3.26) r = "
        f"{', '.join(f'{v:g}' for v in sorted(set(first.relative_noise)))}; "
        f"{mc.seconds_per_run * 1e3:.0f} ms per run; initial estimates "
        f"{'drawn from the prior around the truth' if mc.prior_draw else 'fixed'}",
        f"  bound: {BOUND_ASSUMPTION}",
        "  the second bound adds the filter's own process noise (random walks 4.1, model error):"
        " the best a filter with exactly these assumptions could do",
        "  phase          parameter   mean error       RMSE    σ (RMS)      bound  efficiency"
        "  | bound w/ noise  efficiency",
    ]
    for phase in first.phases:
        for name, s in mc.phase_stats[phase.name].items():
            head = f"  {phase.name:<14} {name:<8}"
            if not s.identifiable:
                note = f"{NOT_IDENTIFIABLE} (σ × {s.sigma_ratio:.3f}, bound × {s.crb_ratio:.3f})"
                if s.rmse is not None:
                    note = f"RMSE {s.rmse:.3g}, bound {s.crb_sigma:.3g}; " + note
                lines.append(f"{head} {note}")
                continue
            assert s.rmse is not None and s.crb_sigma is not None and s.sigma is not None
            assert s.mean_error is not None and s.efficiency is not None
            assert s.crb_sigma_process is not None and s.efficiency_process is not None
            lines.append(
                f"{head} {s.mean_error:>11.3g} {s.rmse:>10.3g} {s.sigma:>10.3g} "
                f"{s.crb_sigma:>10.3g} {s.efficiency:>10.2f}  | {s.crb_sigma_process:>14.3g} "
                f"{s.efficiency_process:>11.2f}"
            )
    lo, hi = mc.nees_band()
    lines.append(
        f"  NEES mean {mc.nees_mean:.2f} over {len(mc.runs)} runs (dof "
        f"{float(np.mean(first.nees_dof)):.2f}; 95 % band {lo:.2f}..{hi:.2f}): "
        f"{'inside' if lo <= mc.nees_mean <= hi else 'OUTSIDE'}; "
        f"{100 * mc.nees_inside():.0f} % of samples' run means inside their band"
    )
    d = mc.to_dict()
    if d["nis_mean"] is not None:
        nis_lo, nis_hi = d["nis_band"]
        lines.append(
            f"  NIS mean {d['nis_mean']:.2f} (95 % band {nis_lo:.2f}..{nis_hi:.2f}, innovations "
            f"white: samples independent): "
            f"{'inside' if nis_lo <= d['nis_mean'] <= nis_hi else 'OUTSIDE'}"
        )
    lines += _mode_lines(
        first.mode_source,
        [e for e in d["events"] if e["t_reference"] is not None],
        len(first.switches),
    )
    return "\n".join(lines)


def plot_efficiency(mc: EkfMonteCarlo, path: Path) -> Path:
    """Efficiency RMSE / posterior bound per parameter and phase (bars; a phase in which the
    parameter is not identifiable is left empty and labelled), the line at 1 the bound."""
    from gearsym.validation.drawing.figures import save, subplots

    names = mc.parameter_names
    phases = [p.name for p in mc.first.phases]
    fig, ax = subplots(1, 1, (8, 4.4), {"top": 0.82, "bottom": 0.1, "left": 0.08, "right": 0.98})
    width = 0.8 / len(phases)
    marked = False
    for i, phase in enumerate(phases):
        for j, name in enumerate(names):
            s = mc.phase_stats[phase][name]
            x = j + (i - (len(phases) - 1) / 2) * width
            if s.identifiable and s.efficiency is not None:
                ax.bar(x, s.efficiency, width * 0.9, color=f"C{i}", label=phase if j == 0 else None)
                ax.plot(
                    x,
                    s.efficiency_process,
                    "kD",
                    ms=4,
                    label="against the bound with the filter's process noise"
                    if not marked
                    else None,
                )
                marked = True
                ax.annotate(
                    f"{s.efficiency:.2f}", (x, s.efficiency), ha="center", va="bottom", fontsize=6
                )
            else:
                ax.annotate("n.i.", (x, 0.05), ha="center", va="bottom", fontsize=6, rotation=90)
                if j == 0:
                    ax.bar(x, 0, width * 0.9, color=f"C{i}", label=phase)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="the bound (efficiency 1)")
    ax.set_xticks(range(len(names)), [symbol(n) for n in names])
    ax.set_xlim(-0.5, len(names) - 0.5)
    ax.set_ylabel("RMSE / posterior Cramér–Rao bound")
    ax.legend(fontsize=6, loc="upper left", ncol=3)
    first = mc.first
    fig.suptitle(
        f"EKF efficiency, {first.shift} shift, {len(mc.runs)} runs, samples every "
        f"{first.sample_time * 1e3:g} ms (n.i.: not identifiable in this phase)\n"
        "bars: RMSE / bound for constant parameters (the filter's random walks make > 1 "
        "expected)\n◆: RMSE / bound with the filter's process noise; initial estimates "
        + (
            "drawn from the prior"
            if mc.prior_draw
            else "fixed (< 1 possible while the prior rules)"
        ),
        fontsize=9,
    )
    return save(fig, path)


#: What an EKF run on a recording reports instead of errors against a truth.
NO_TRUTH = (
    "the recording carries no truth channels: no RMSE, no NEES; the filter's σ and its NIS "
    "(innovations against their predicted covariance) are the consistency check"
)


def measured_ekf_dict(run: EkfRun) -> dict[str, Any]:
    """An EKF run on a recording as data: per parameter initial, estimate and σ at the end;
    NIS mean and band; no truth (:data:`NO_TRUTH`)."""
    used = run.nis_dof > 0
    return {
        "filter": "ekf",
        "shift": run.shift,
        "sample_time": run.sample_time,
        "relative_noise": list(run.relative_noise),
        "truth": None,
        "truth_note": NO_TRUTH,
        "parameters": {
            # no scored sample: ParameterEstimate holds the values at the last sample
            p.name: {"initial": p.initial, "estimate": p.estimate, "sigma": p.sigma}
            for p in run.parameters
        },
        "nis_mean": float(np.mean(run.nis[used])) if used.any() else None,
        "nis_band": list(_chi2_mean_band(run.nis_dof[used])) if used.any() else None,
        # after the first sample, whose speeds are the initial estimate (filter_run)
        "skipped_updates": int(np.count_nonzero(~used[1:])),
        "min_covariance_eigenvalue": run.min_eigenvalue,
        "modes": run.mode_source,
        "switches": [{"element": m.element, "kind": m.kind, "t": m.t} for m in run.switches],
        "phases": [p.to_dict() for p in run.phases],
    }


def format_measured_ekf_text(run: EkfRun) -> str:
    """Per parameter: initial and final estimate ± σ; the NIS mean against its band."""
    data = measured_ekf_dict(run)
    lines = [
        f"EKF (4.3) of the {run.shift} shift on a recording, samples every "
        f"{run.sample_time * 1e3:g} ms, assumed speed noise (3.26) r = "
        f"{', '.join(f'{v:g}' for v in run.relative_noise)}",
        "  parameter    initial   estimate ± σ (at the end of the recording)",
    ]
    for name, p in data["parameters"].items():
        lines.append(
            f"  {name:<8} {p['initial']:>10.4g} {p['estimate']:>10.4g} ± {p['sigma']:<10.3g}"
        )
    if data["nis_mean"] is not None:
        lo, hi = data["nis_band"]
        lines.append(
            f"  NIS mean {data['nis_mean']:.2f} (95 % band {lo:.2f}..{hi:.2f}): "
            f"{'inside' if lo <= data['nis_mean'] <= hi else 'OUTSIDE'}; "
            f"{data['skipped_updates']} later samples without an update (NaN speeds; the first "
            "sample's speeds are the initial estimate)"
        )
    lines.append(f"  {NO_TRUTH}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# Extended UIO (4.5): the road load as unknown input (symbolic/estimators/euio.py)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EuioRun:
    """The extended UIO along one reference shift: estimates and σ per sample, the estimated
    road load d̂ = T_res* against the reference's T_res (2.48), existence per phase."""

    shift: str
    sample_time: float
    seed: int
    state_names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    estimates: np.ndarray = field(repr=False)
    sigmas: np.ndarray = field(repr=False)
    truth: np.ndarray = field(repr=False)
    scored: np.ndarray = field(repr=False)
    held: np.ndarray = field(repr=False)  # (N, n) bool: estimate held at this sample
    load: np.ndarray = field(repr=False)  # (N,) d̂ over the interval ending at sample k
    load_sigma: np.ndarray = field(repr=False)
    load_truth: np.ndarray = field(repr=False)  # T_res of the reference, mid-interval
    phases: tuple[Phase, ...]
    existence: dict[str, list[Any]]  # phase name -> per parameter EuioExistence
    parameters: tuple[ParameterEstimate, ...]
    #: where the element modes came from: "reference" (run_euio) or "filter" (the EKF's
    #: mode logic, :func:`gearsym.validation.studies.euio_evaluation.euio_filter_run`)
    mode_source: str = "reference"

    def load_rmse(self, phase: Phase | None = None) -> float:
        """RMS of d̂ − T_res over the samples (of ``phase``) where d̂ exists."""
        ok = np.isfinite(self.load)
        if phase is not None:
            ok &= (self.t > phase.t_start) & (self.t <= phase.t_end)
        return _rms(self.load[ok] - self.load_truth[ok]) if ok.any() else float("nan")

    def to_dict(self) -> dict[str, Any]:
        params = {}
        for pe in self.parameters:
            entry = pe.to_dict()
            entry["identifiable"] = {
                ph: next(e.exists for e in ex if e.parameter == pe.name)
                for ph, ex in self.existence.items()
            }
            entry["held_because"] = {
                ph: next(e.reason() for e in ex if e.parameter == pe.name)
                for ph, ex in self.existence.items()
                if not next(e.exists for e in ex if e.parameter == pe.name)
            }
            params[pe.name] = entry
        return {
            "filter": "euio",
            "shift": self.shift,
            "runs": 1,
            "modes": self.mode_source,
            "seed": self.seed,
            "sample_time": self.sample_time,
            "parameters": params,
            "unknown_inputs": {
                naming.RESISTANCE_INPUT: {
                    "rmse": self.load_rmse(),
                    "rmse_per_phase": {p.name: self.load_rmse(p) for p in self.phases},
                    "absorbs": "zeta, rolling and aero resistance (2.48)",
                }
            },
            "nees_mean": None,
            "nees_band": None,
            "nis_mean": None,
            "phases": [
                {
                    "name": p.name,
                    "t_start": p.t_start,
                    "t_end": p.t_end,
                    "existence": [e.to_dict() for e in self.existence[p.name]],
                }
                for p in self.phases
            ],
        }


def run_euio(
    d: GearboxDescription,
    result: SimulationResult,
    sample_time: float = 0.01,
    relative_noise: Sequence[float] | float = EKF_RELATIVE_NOISE,
    seed: int = 0,
    initial: Mapping[str, float] | None = None,
    noise: bool = True,
) -> EuioRun:
    """The extended UIO (4.5) along the reference shift of ``result``: m_veh, μ_off, μ_on with
    the road load T_res* (absorbing ζ) as unknown input; measurements, noise (3.26), inputs,
    element modes and initial estimate as :func:`run_ekf` (``noise=False``: the true
    outputs, the noise level only sets R). Existence per phase on the linearisation at the
    phase's midpoint (truth states, nominal parameters); a parameter whose conditions fail in
    a phase is held there."""
    from gearsym.symbolic.estimators.ekf import default_parameters
    from gearsym.symbolic.estimators.euio import (
        ROAD_FREE,
        euio_existence,
        euio_step,
        load_column,
    )

    parameters = [name for name in default_parameters(d, result.scenario.shift.name)]
    parameters = [name for name in parameters if name != naming.GRADE]
    setup = prepare_ekf(d, result, sample_time, relative_noise, initial, parameters)
    aug, discrete = setup.aug, setup.discrete
    p = aug.parameter_values(ROAD_FREE)
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    i_wheel = float(p[[v.name for v in aug.model.parameters].index("I_wheel")])
    t, names, n = setup.t, setup.names, len(setup.names)
    h = float(t[1] - t[0])
    y = setup.y_true.copy() if not noise else noisy_outputs(setup, seed)
    z = setup.initial.copy()
    for k, name in enumerate(setup.outputs):
        if name in names:
            z[names.index(name)] = y[0, k]
    P = np.diag(setup.prior_sigma**2)
    initial_values = z.copy()
    q = np.array(setup.q, dtype=float)

    truth0 = setup.truth0
    existence: dict[str, list[Any]] = {}
    held_by_phase: dict[str, list[int]] = {}
    for phase in setup.phases:
        mid = int(np.argmin(np.abs(t - 0.5 * (phase.t_start + phase.t_end))))
        zop = truth0.copy()
        zop[: aug.n_x] = setup.truth[mid, : aug.n_x]
        e = load_column(discrete, zop, r_dyn, p, i_wheel)
        existence[phase.name] = euio_existence(discrete, phase.name, zop, setup.u[mid], p, e)
        held_by_phase[phase.name] = [
            names.index(x.parameter) for x in existence[phase.name] if not x.exists
        ]

    def phase_of(time: float) -> str:
        for ph in setup.phases:
            if ph.t_start <= time < ph.t_end:
                return ph.name
        return setup.phases[-1].name

    estimates = np.empty((len(t), n))
    sigmas = np.empty((len(t), n))
    held = np.zeros((len(t), n), dtype=bool)
    load = np.full(len(t), np.nan)
    load_sigma = np.full(len(t), np.nan)
    estimates[0], sigmas[0] = z, np.sqrt(np.diag(P))
    for k in range(1, len(t)):
        hold = sorted(set(held_by_phase[phase_of(t[k])]) | set(aug.frozen_states(setup.u[k - 1])))
        held[k, hold] = True
        R = (setup.relative * np.maximum(np.abs(y[k]), setup.floor)) ** 2
        e = load_column(discrete, z, r_dyn, p, i_wheel)
        z, P, load[k], load_sigma[k] = euio_step(
            discrete, z, P, setup.u[k - 1], setup.u[k], y[k], R, h, p, q, e, hold
        )
        estimates[k], sigmas[k] = z, np.sqrt(np.diag(P))
    t_mid = np.r_[t[0], 0.5 * (t[1:] + t[:-1])]
    load_truth = np.interp(t_mid, result.t, result.signals[naming.ROAD_TORQUE])

    truth, scored = setup.truth, setup.scored
    by_parameter = []
    for name in aug.parameters:
        j = names.index(name)
        inside = np.flatnonzero(scored[:, j])
        last = inside[-1] if inside.size else len(t) - 1
        err = estimates[inside, j] - truth[inside, j]
        by_parameter.append(
            ParameterEstimate(
                name=name,
                truth=float(truth[last, j]),
                initial=float(initial_values[j]),
                estimate=float(estimates[last, j]),
                sigma=float(sigmas[last, j]),
                rmse=float(np.sqrt(np.mean(err**2))) if inside.size else float("nan"),
                scored=int(inside.size),
            )
        )
    return EuioRun(
        shift=setup.shift,
        sample_time=h,
        seed=seed,
        state_names=tuple(names),
        t=t,
        estimates=estimates,
        sigmas=sigmas,
        truth=truth,
        scored=scored,
        held=held,
        load=load,
        load_sigma=load_sigma,
        load_truth=load_truth,
        phases=setup.phases,
        existence=existence,
        parameters=tuple(by_parameter),
    )


def write_euio_csv(run: EuioRun, path: Path) -> Path:
    """Every sample: t, phase, per state its estimate, σ, truth (empty where none) and whether
    it is held, then d̂ = T_res*, its σ and the reference T_res."""
    from gearsym.validation.studies.sensitivity_run import phase_of

    header = ["t", "phase"]
    for name in run.state_names:
        header += [f"{name}_hat", f"{name}_sigma", name, f"{name}_held"]
    header += ["T_res_star_hat", "T_res_star_sigma", "T_res"]
    lines = [",".join(header)]

    def num(v: float) -> str:
        return f"{v:.9g}" if np.isfinite(v) else ""

    for k, t in enumerate(run.t):
        row = [f"{t:.6g}", phase_of(run.phases, float(t))]
        for j in range(len(run.state_names)):
            truth = run.truth[k, j] if run.scored[k, j] else np.nan
            row += [num(run.estimates[k, j]), num(run.sigmas[k, j]), num(truth)]
            row.append("1" if run.held[k, j] else "0")
        row += [num(run.load[k]), num(run.load_sigma[k]), num(run.load_truth[k])]
        lines.append(",".join(row))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def plot_euio(run: EuioRun, path: Path) -> Path:
    """Each parameter's estimate against the truth with ±3σ (held samples marked), the road
    load d̂ against the reference T_res, the phases shaded."""
    from gearsym.validation.drawing.figures import save, subplots

    names = [p.name for p in run.parameters]
    fig, axes = subplots(
        len(names) + 1,
        1,
        (8, 2.0 * (len(names) + 1)),
        {"top": 0.93, "bottom": 0.05, "hspace": 0.12, "left": 0.1},
        sharex=True,
    )
    shade_phases(axes, run.phases)
    for ax, name in zip(axes, names, strict=False):
        j = run.state_names.index(name)
        est, sig = run.estimates[:, j], run.sigmas[:, j]
        truth = np.where(run.scored[:, j], run.truth[:, j], np.nan)
        ax.fill_between(run.t, est - 3 * sig, est + 3 * sig, color="C0", alpha=0.2, lw=0)
        ax.plot(run.t, est, color="C0", label="EUIO estimate ±3σ")
        held = np.where(run.held[:, j], est, np.nan)
        ax.plot(run.t, held, color="C1", lw=2.5, alpha=0.6, label="held (no UIO for it)")
        ax.plot(run.t, truth, color="k", lw=1.2, label="reference (where defined)")
        ax.set_ylabel(axis_label(name))
        ax.legend(fontsize=6, loc="upper right")
    ax = axes[-1]
    ax.plot(run.t, run.load, color="C0", lw=0.6, label="d̂ = T_res* (per sample)")
    ax.plot(run.t, run.load_truth, color="k", lw=1.2, label="reference T_res (2.48)")
    finite = run.load_truth[np.isfinite(run.load_truth)]
    spread = max(float(np.max(np.abs(finite))) * 8, 50.0)
    ax.set_ylim(-spread, spread)
    ax.set_ylabel("T_res* / N m")
    ax.set_xlabel("t / s")
    ax.legend(fontsize=6, loc="upper right")
    fig.suptitle(
        f"Extended UIO (4.5) on the {run.shift} shift model, road load unknown: samples every "
        f"{run.sample_time * 1e3:g} ms, seed {run.seed}",
        fontsize=10,
    )
    return save(fig, path)


def format_euio_text(run: EuioRun) -> str:
    """The EUIO run for a terminal: per parameter the estimate and where it is held and why,
    the road load's RMS error per phase."""
    lines = [f"extended UIO (4.5), shift {run.shift}, road load T_res* (absorbs zeta) unknown"]
    for pe in run.parameters:
        lines.append(
            f"  {pe.name}: truth {pe.truth:.6g}, initial {pe.initial:.6g}, estimate "
            f"{pe.estimate:.6g} ± {pe.sigma:.3g}, rmse {pe.rmse:.3g}"
        )
        for phase, ex in run.existence.items():
            (e,) = [x for x in ex if x.parameter == pe.name]
            lines.append(f"    {phase}: " + ("estimated" if e.exists else f"held: {e.reason()}"))
    lines.append("  T_res* rmse per phase (per-sample estimate):")
    for phase in run.phases:
        lines.append(f"    {phase.name}: {run.load_rmse(phase):.4g} N m")
    return "\n".join(lines)
