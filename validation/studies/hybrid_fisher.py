"""Fisher information (3.25) on the hybrid shift model's sensitivities, per phase, with the
unmeasured initial states as nuisance parameters.

The output sensitivities come from :class:`gearsym.validation.sim.hybrid_simulation.HybridSimulator`
(3.7 inside each mode, the jump conditions at each switch), so a μ acts only where its element
slides, and a slip deviation disappears at lock-up (the state map projects it away). Measured
outputs (3.31): the measured shaft speeds (a shaft whose speed equals an earlier one throughout,
e.g. ω8 = ω1 while K81 stays locked, is counted once) and the wheel speed; noise (3.26) with the
relative error r and the floor of 1 % of the largest value; samples every 10 ms (assumed TCU
period, as :mod:`gearsym.validation.studies.fisher`).

Three views, each labelled in the result:

* ``"nuisance"`` (default): each window starts from the nominal state at its start with S = 0
  for the parameters θ, and the states that are not measured (the side-shaft twist φ) enter as
  unknown initial values ν. The FIM of [θ; ν] is reduced to θ by the Schur complement
  F_θθ − F_θν F_νν⁺ F_νθ, whose inverse is the θ block of the full inverse (3.22): the bound
  when φ at the window's start has to be estimated too. A window counts only what it reveals.
* ``"known"``: the same restart with the initial state known (S = 0, no ν).
* ``"continuous"``: the thesis' view (3.16): one run from t = 0 (S(0) from the quasi-static
  start, which depends on p through φ0 like the reference's start), each window summing the
  sensitivities it sees, which also carry what earlier windows excited.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import (
    FLOOR_FRACTION,
    GAMMA_MAX,
    OBSERVABILITY_PARAMETERS,
    SAMPLE_TIME,
    SPEED_ERROR,
)
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.fisher import (
    Elimination,
    FimAnalysis,
    analyse,
    eliminate,
    fisher_information,
    noise_variances,
)
from gearsym.symbolic.parameters import symbol
from gearsym.validation.sim.hybrid_result import HybridResult
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.phases import Phase, detect_phases
from gearsym.validation.sim.scenario import Scenario
from gearsym.validation.studies.sensitivity_integration import nominal_scales

VIEWS = {
    "nuisance": "per phase, unmeasured initial states (φ) unknown: Schur complement",
    "known": "per phase, initial state known (restarted, S = 0 at the phase start)",
    "continuous": "continuous from t = 0, initial state known (thesis 3.16)",
}

#: Relative tolerance of the events and states (the FIM needs S to a few digits only).
RTOL = 1e-10

#: Eigenvalues of F_N below this fraction of the largest are null directions. Where a parameter
#: has no influence its sensitivities are exact zeros here (the mode's equations do not contain
#: it), so its eigenvalue sits at double-precision rounding (≤ 1e-20 relative, measured); the
#: general default 1e-10 of gearsym.symbolic.fisher would also call a merely weak direction null
#: (2e-12 relative: μ38 during the 1 ms K38 still slides in gear 2 of the 3-2 downshift) and
#: then mark m_veh and ζ, which have components of 1e-4 in it, as not identifiable as well.
RANK_TOLERANCE = 1e-14


@dataclass(frozen=True)
class HybridWindow:
    """The FIM of one window, reduced to the parameters θ."""

    name: str
    t_start: float
    t_end: float
    samples: int
    fim: np.ndarray  # of θ (after the Schur complement in the nuisance view)
    full_fim: np.ndarray  # of [θ; ν]
    analysis: FimAnalysis
    #: the thesis' elimination (3.3) on ``fim``: what stays estimable in this window
    elimination: Elimination


@dataclass(frozen=True)
class HybridFimStudy:
    parameters: tuple[str, ...]
    nuisance: tuple[str, ...]
    scales: np.ndarray
    view: str
    outputs: tuple[str, ...]
    windows: tuple[HybridWindow, ...]
    nominal: HybridResult
    #: the shift and the measurement assumptions (3.26), (3.27) the study was run with
    settings: Mapping[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return VIEWS[self.view]

    def window(self, name: str) -> HybridWindow:
        return next(w for w in self.windows if w.name == name)


def schur_complement(fim: np.ndarray, m: int) -> np.ndarray:
    """F_θθ − F_θν F_νν⁺ F_νθ of the first m (θ) against the remaining (ν) parameters: the
    information about θ when ν is unknown (its inverse is the θ block of F⁻¹). The
    pseudo-inverse: a ν the window does not see (F_νν = 0) takes nothing away."""
    f_tt, f_tn, f_nn = fim[:m, :m], fim[:m, m:], fim[m:, m:]
    if f_nn.size == 0:
        return f_tt
    return f_tt - f_tn @ np.linalg.pinv(f_nn) @ f_tn.T


def measured_outputs(d: GearboxDescription, nominal: HybridResult) -> tuple[str, ...]:
    """ω of the measured shafts (3.31), a shaft identical to an earlier one throughout counted
    once, and ω_C."""
    chosen: list[str] = []
    for shaft in d.measured_shafts:
        key = naming.speed(shaft)
        signal = nominal.signals[key]
        scale = np.max(np.abs(signal))
        if any(np.max(np.abs(signal - nominal.signals[c])) <= 1e-9 * scale for c in chosen):
            continue
        chosen.append(key)
    return (*chosen, naming.WHEEL_SPEED)


def hybrid_fim(
    d: GearboxDescription,
    parameters: Sequence[str] = OBSERVABILITY_PARAMETERS,
    scenario: Scenario | None = None,
    view: str = "nuisance",
    windows: Sequence[Phase] | None = None,
    sample_time: float = SAMPLE_TIME,
    speed_error: float = SPEED_ERROR,
    floor_fraction: float = FLOOR_FRACTION,
    gamma_max: float = GAMMA_MAX,
    overrides: Mapping[str, float] | None = None,
    simulator: HybridSimulator | None = None,
) -> HybridFimStudy:
    """The per-window FIM of the hybrid model (module docstring). ``windows`` default to the
    phases :func:`gearsym.validation.sim.phases.detect_phases` finds in the hybrid model's own
    record (from-gear, torque and speed phase in the order they happen, to-gear)."""
    if view not in VIEWS:
        raise GearsymError(d.file, "view", f"expected one of {tuple(VIEWS)}, got {view!r}")
    simulator = simulator or HybridSimulator(d, scenario)
    scenario = simulator.scenario
    parameters = tuple(parameters)
    nominal = simulator.run(overrides, rtol=RTOL, atol=RTOL)
    if windows is None:
        windows = detect_phases(d, scenario, nominal.t, nominal.signals)
    outputs = measured_outputs(d, nominal)
    t_meas = np.arange(0.0, scenario.t_end + 1e-12, sample_time)
    floor = floor_fraction * np.array(
        [np.max(np.abs(nominal.signals[k])) for k in outputs]
    )  # over the whole record (3.26)
    values = simulator.values(overrides)
    p = simulator.parameter_vector(values)
    scales = nominal_scales(parameters, values)
    errors = [speed_error] * len(outputs)
    measured = set(outputs)

    continuous = None
    if view == "continuous":
        s0 = simulator.initial_sensitivity(p, parameters)
        continuous = simulator.run(
            overrides, RTOL, RTOL, parameters=parameters, s0=s0, t_eval=t_meas
        )

    result = []
    nuisance: tuple[str, ...] = ()
    for k, window in enumerate(windows):
        last = k == len(windows) - 1
        inside = (t_meas >= window.t_start) & (
            (t_meas < window.t_end) | (last & (t_meas <= window.t_end))
        )
        times = t_meas[inside]
        if times.size == 0:
            continue
        if continuous is not None:
            run = continuous
            index = np.flatnonzero(inside)
        else:
            mode, x0 = _state_at(simulator, nominal, window.t_start, p)
            states = [v.name for v in simulator.hybrid.modes[mode].model.states]
            columns = tuple(s for s in states if s not in measured) if view == "nuisance" else ()
            nuisance = nuisance or columns
            run = simulator.run(
                overrides,
                RTOL,
                RTOL,
                x0=x0,
                parameters=parameters,
                t_start=window.t_start,
                mode=mode,
                state_columns=columns,
                t_eval=np.concatenate([[window.t_start], times])
                if times[0] > window.t_start
                else times,
            )
            index = np.flatnonzero(np.isin(run.t, times))
        y = np.column_stack([run.signals[o][index] for o in outputs])
        dy = np.stack([run.sensitivities[o][index] for o in outputs], axis=1)
        variances = noise_variances(y, errors, floor)
        full = fisher_information(dy, variances)
        reduced = schur_complement(full, len(parameters))
        result.append(
            HybridWindow(
                name=window.name,
                t_start=window.t_start,
                t_end=window.t_end,
                samples=len(index),
                fim=reduced,
                full_fim=full,
                analysis=analyse(reduced, parameters, scales, gamma_max, RANK_TOLERANCE),
                elimination=eliminate(reduced, parameters, scales, gamma_max, RANK_TOLERANCE),
            )
        )
    return HybridFimStudy(
        parameters=parameters,
        nuisance=nuisance,
        scales=scales,
        view=view,
        outputs=outputs,
        windows=tuple(result),
        nominal=nominal,
        settings={
            "shift": scenario.shift.name,
            "sample_time_s": sample_time,
            "speed_error": speed_error,
            "floor_fraction": floor_fraction,
            "gamma_max": gamma_max,
        },
    )


def _state_at(
    simulator: HybridSimulator, nominal: HybridResult, t: float, p: np.ndarray
) -> tuple[str, np.ndarray]:
    """The nominal mode and state at t (the later piece at a switch), in that mode's
    coordinates."""
    piece = next(
        piece
        for piece in reversed(nominal.pieces)
        if piece.t_start <= t <= piece.t_end and (piece.t_end > t or piece is nominal.pieces[-1])
    )
    n = simulator.modes[piece.mode].n
    return piece.mode, piece.state(np.array([t]))[0, :n]


def format_text(study: HybridFimStudy) -> str:
    """One table per window: σ (CRB) and γ (3.27) of each parameter, labelled with the view."""
    lines = [f"Fisher information of the hybrid shift model (3.25); view: {study.label}"]
    if study.nuisance:
        lines.append(f"  nuisance (unknown initial values per window): {', '.join(study.nuisance)}")
    lines.append(f"  outputs: {', '.join(study.outputs)}")
    for w in study.windows:
        a = w.analysis
        lines.append(f"== {w.name} ({w.t_start:.3f} s – {w.t_end:.3f} s, {w.samples} samples)")
        for j, name in enumerate(a.names):
            gamma = "inf" if not np.isfinite(a.gamma[j]) else f"{a.gamma[j]:.3g}"
            ok = "✓" if a.gamma[j] <= a.gamma_max else "✗"
            lines.append(f"    {name:<8} γ = {gamma:>9} {ok}")
        dropped = [st.dropped for st in w.elimination.steps if st.dropped]
        lines.append(
            f"    elimination (3.3): drop {', '.join(dropped) or 'nothing'} → estimable: "
            f"{', '.join(w.elimination.final) or 'none'}"
        )
    return "\n".join(lines)


def summary_lines(study: HybridFimStudy) -> list[str]:
    """A few lines for ``gearsym run``: the view, then per window what stays estimable after
    the elimination (3.3)."""
    lines = [f"view: {study.label}"]
    for w in study.windows:
        lines.append(f"{w.name:<13} {', '.join(w.elimination.final) or 'none'}")
    return lines


def to_dict(study: HybridFimStudy) -> dict[str, Any]:
    """JSON-ready summary."""
    return {
        "view": study.view,
        "label": study.label,
        "parameters": list(study.parameters),
        "nuisance": list(study.nuisance),
        "outputs": list(study.outputs),
        "settings": dict(study.settings),
        "windows": [
            {
                "name": w.name,
                "t_start": w.t_start,
                "t_end": w.t_end,
                "samples": w.samples,
                **w.analysis.to_dict(),
                "elimination": w.elimination.to_dict(),
            }
            for w in study.windows
        ],
    }


def _gamma_cell(value: float | str, gamma_max: float) -> str:
    """γ to three digits, bold where it meets the limit; ∞ where the FIM is singular."""
    if value == "inf":
        return "∞"
    text = f"{value:.3g}"
    return f"**{text}**" if value <= gamma_max else text


def hybrid_fim_markdown(data: dict[str, Any], command: str) -> str:
    """The study's JSON (:func:`to_dict`, ``fim.json`` of ``gearsym fim --out DIR``) as the
    documentation's table, headed by the command that wrote it: per phase, γ (3.27) of every
    parameter and what the elimination (3.3) keeps. ``gearsym fim --out DIR`` writes it as
    ``fim.md`` beside the JSON; nobody types its numbers."""
    settings = data["settings"]
    names = data["parameters"]
    nuisance = ", ".join(symbol(n) for n in data["nuisance"])
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- the hybrid shift model of the {settings['shift']} shift (elements lock, slide and "
        f"open); view: {data['label']}"
        + (f"; unknown initial values per phase: {nuisance}" if nuisance else ""),
        f"- outputs (3.31) {', '.join(data['outputs'])}; noise (3.26): relative error "
        f"{settings['speed_error'] * 100:g} %, floor {settings['floor_fraction'] * 100:g} % of "
        f"the largest value; samples every {settings['sample_time_s'] * 1e3:g} ms",
        f"- γ (3.27) of all {len(names)} parameters together; **bold**: γ ≤ γ_max = "
        f"{settings['gamma_max']:g}; ∞: the information is singular in a direction that "
        "involves the parameter (no influence in that phase, or not separable from another)",
        "",
        "| phase | from – to | samples | "
        + " | ".join(f"γ {symbol(n)}" for n in names)
        + " | estimable after the elimination (3.3) | dropped, in order |",
        "|---|---|---|" + "---|" * len(names) + "---|---|",
    ]
    for w in data["windows"]:
        gammas = " | ".join(_gamma_cell(w["gamma"][n], w["gamma_max"]) for n in names)
        elimination = w["elimination"]
        final = ", ".join(symbol(n) for n in elimination["final"]) or "none"
        dropped = [symbol(s["dropped"]) for s in elimination["steps"] if s["dropped"]]
        out.append(
            f"| {w['name']} | {w['t_start']:.3f} – {w['t_end']:.3f} s | {w['samples']} | "
            f"{gammas} | {final} | {', '.join(dropped) or '—'} |"
        )
    return "\n".join(out) + "\n"
