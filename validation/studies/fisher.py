"""Stage 4d: the Fisher-information study of the reference shift (thesis 3.3, Figs. 3.9–3.14).

The output sensitivities of the driven shift model
(:mod:`gearsym.validation.studies.sensitivity_run`) are sampled at the TCU's measurement period, the
noise model (3.26) is applied to the outputs (3.31) — and, with ``with_wheel_acceleration``, also to
the wheel acceleration (3.32) at a larger relative error — and the FIM (3.25) is formed per phase of
the shift and summed over the whole shift. For every window: Cramér–Rao bounds and normalised
scatter (3.22)–(3.27), eigen-analysis (3.28)–(3.30), the elimination procedure, and the parameter
combinations of Figures 3.9–3.14.

Assumed values (the thesis gives none): sampling period 10 ms, relative errors 1 % for the
speeds and 10 % for the wheel acceleration, scatter limit γ_max = 0.1.

``restart``: by default the sensitivities run continuously through the shift (the ones of
Figures 3.4–3.8), so a phase's FIM also holds what earlier phases left in the states. With
``restart`` each phase starts from the recorded state with S = 0: the information the phase's
own excitation carries (an estimator that is re-initialised from the measured state).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.defaults import (
    ACCELERATION_ERROR,
    FLOOR_FRACTION,
    GAMMA_MAX,
    SAMPLE_TIME,
    SPEED_ERROR,
)
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.fisher import (
    Elimination,
    FimAnalysis,
    analyse,
    describe_direction,
    eliminate,
    fisher_information,
    measurement_floor,
    noise_variances,
    submatrix,
)
from gearsym.symbolic.parameters import symbol
from gearsym.validation.sim.phases import Phase
from gearsym.validation.studies.driven_shift import Progress, ReferenceData, reference_data
from gearsym.validation.studies.sensitivity_run import SensitivityRun, run_sensitivities

WHEEL_ACCELERATION = "y_domega_C"

#: How the per-phase numbers were obtained, printed beside every verdict.
SENSITIVITY_VIEW = {
    True: "restarted at each phase: a phase counts only what it reveals itself",
    False: "carried over from t0 (thesis view): a phase also shows earlier phases' information",
}
WHOLE_SHIFT = "whole shift"

#: Parameter combinations of Figures 3.9–3.14, by phase position (0 from-gear, 1 torque
#: phase, 2 speed phase).
THESIS_COMBINATIONS: dict[int, tuple[tuple[str, ...], ...]] = {
    0: (("m_veh", "zeta"), ("m_veh",), ("zeta",)),  # Figs. 3.9, 3.10
    1: (("m_veh", "mu_38", "zeta"), ("m_veh", "mu_38"), ("mu_38", "zeta")),  # 3.11–3.13
    2: (("m_veh", "zeta"),),  # Fig. 3.14
}


@dataclass(frozen=True)
class OutputSetResult:
    """The FIM of one window for one set of measured outputs."""

    outputs: tuple[str, ...]
    samples: int
    full: FimAnalysis
    elimination: Elimination
    combinations: tuple[FimAnalysis, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "outputs": list(self.outputs),
            "samples": self.samples,
            "full": self.full.to_dict(),
            "elimination": self.elimination.to_dict(),
            "combinations": [
                {
                    "parameters": list(c.names),
                    "gamma": c.to_dict()["gamma"],
                    "estimable": c.estimable,
                    "singular": c.singular,
                }
                for c in self.combinations
            ],
        }


@dataclass(frozen=True)
class WindowResult:
    name: str
    t_start: float
    t_end: float
    results: tuple[OutputSetResult, ...]  # without, then (optionally) with ω̇_C

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "output_sets": [r.to_dict() for r in self.results],
        }


@dataclass(frozen=True)
class FimStudy:
    parameters: tuple[str, ...]
    scales: np.ndarray
    windows: tuple[WindowResult, ...]  # the phases, then the whole shift
    settings: dict[str, Any]
    run: SensitivityRun

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": list(self.parameters),
            "nominal": {n: float(s) for n, s in zip(self.parameters, self.scales, strict=True)},
            "settings": self.settings,
            "windows": [w.to_dict() for w in self.windows],
        }


def _in_window(t: np.ndarray, phase: Phase, last: bool) -> np.ndarray:
    return (t >= phase.t_start) & ((t < phase.t_end) | (last & (t <= phase.t_end)))


def fim_study(
    d: GearboxDescription,
    parameters: Sequence[str] | None = None,
    data: ReferenceData | None = None,
    with_wheel_acceleration: bool = False,
    sample_time: float = SAMPLE_TIME,
    speed_error: float = SPEED_ERROR,
    acceleration_error: float = ACCELERATION_ERROR,
    floor_fraction: float = FLOOR_FRACTION,
    gamma_max: float = GAMMA_MAX,
    mode: str = "detected",
    restart: bool = True,
    overrides: Mapping[str, float] | None = None,
    progress: Progress | None = None,
) -> FimStudy:
    """Fisher information per phase and over the whole shift (3.16–3.32).

    ``restart`` (default): the sensitivities start from zero at every phase, so each phase's
    FIM counts only what that phase itself reveals (the state at its start taken as known).
    ``restart=False`` carries them over from t0 as the thesis does: a μ perturbed in the torque
    phase then still shows in the speed phase and the to-gear, where its element is open or
    locked (the open-loop shift model never locks), which is information of an earlier phase.
    """
    say = progress or (lambda message: None)
    if data is None:
        say("simulating the reference shift")
        data = reference_data(d, progress=progress)
    t_meas = np.arange(data.t[0], data.t[-1] + 1e-12, sample_time)
    common = {
        "parameters": parameters,
        "overrides": overrides,
        "with_wheel_acceleration": with_wheel_acceleration,
        "mode": mode,
        "progress": progress,
    }
    run = run_sensitivities(d, data=data, t_eval=t_meas, **common)
    tr = run.trajectory
    names = tr.parameter_names
    base = [i for i, n in enumerate(tr.output_names) if n != WHEEL_ACCELERATION]
    sets = [tuple(base)]
    if with_wheel_acceleration:
        sets.append(tuple(range(len(tr.output_names))))
    errors = np.array(
        [acceleration_error if n == WHEEL_ACCELERATION else speed_error for n in tr.output_names]
    )
    floor = measurement_floor(tr.y, floor_fraction)  # over the whole record (3.26)

    pieces: list[tuple[Phase, np.ndarray, np.ndarray, np.ndarray]] = []
    for k, phase in enumerate(run.phases):
        last = k == len(run.phases) - 1
        if phase.t_end <= phase.t_start:  # an empty phase (phases.py: nothing left to move)
            continue
        if restart:
            say(f"restarting the sensitivities at the {phase.name}")
            sub = run_sensitivities(
                d,
                data=data.window(phase.t_start, phase.t_end),
                t_eval=t_meas[_in_window(t_meas, phase, last)],
                initial="stationary" if k == 0 else "zero",
                **common,
            ).trajectory
            pieces.append((phase, sub.t, sub.y, sub.dy))
        else:
            mask = _in_window(tr.t, phase, last)
            pieces.append((phase, tr.t[mask], tr.y[mask], tr.dy[mask]))

    windows = []
    for k, (phase, _, y, dy) in enumerate(pieces):
        # the thesis' combinations by what the window is (the phases come in either order)
        position = 0 if k == 0 else {"torque phase": 1, "speed phase": 2}.get(phase.name)
        windows.append(
            _window(phase, y, dy, sets, errors, floor, names, run.scales, gamma_max, position)
        )
    whole = Phase(WHOLE_SHIFT, float(tr.t[0]), float(tr.t[-1]))
    y_all = np.concatenate([p[2] for p in pieces])
    dy_all = np.concatenate([p[3] for p in pieces])
    windows.append(_window(whole, y_all, dy_all, sets, errors, floor, names, run.scales, gamma_max))
    settings = {
        "shift": data.shift,
        "source": run.source,
        "sliding": mode,
        "restart": restart,
        "sensitivities": SENSITIVITY_VIEW[restart],
        "sample_time_s": sample_time,
        "relative_errors": {n: float(e) for n, e in zip(tr.output_names, errors, strict=True)},
        "floor": {n: float(f) for n, f in zip(tr.output_names, floor, strict=True)},
        "floor_fraction": floor_fraction,
        "gamma_max": gamma_max,
        "parameter_values": {n: run.values[n] for n in names},
        "drift": run.drift(),
    }
    return FimStudy(tuple(names), run.scales, tuple(windows), settings, run)


def _window(
    phase: Phase,
    y: np.ndarray,
    dy: np.ndarray,
    sets: Sequence[tuple[int, ...]],
    errors: np.ndarray,
    floor: np.ndarray,
    names: Sequence[str],
    scales: np.ndarray,
    gamma_max: float,
    position: int | None = None,
) -> WindowResult:
    results = []
    combos = [c for c in THESIS_COMBINATIONS.get(position, ()) if set(c) <= set(names)]
    scale_of = dict(zip(names, scales, strict=True))
    for columns in sets:
        cols = list(columns)
        variances = noise_variances(y[:, cols], errors[cols], floor[cols])
        fim = fisher_information(dy[:, cols, :], variances)
        full = analyse(fim, names, scales, gamma_max)
        elimination = eliminate(fim, names, scales, gamma_max)
        combinations = tuple(
            analyse(submatrix(fim, names, c), c, [scale_of[n] for n in c], gamma_max)
            for c in combos
        )
        results.append(
            OutputSetResult(
                outputs=tuple(str(i) for i in cols),
                samples=len(y),
                full=full,
                elimination=elimination,
                combinations=combinations,
            )
        )
    return WindowResult(phase.name, phase.t_start, phase.t_end, tuple(results))


def output_set_label(study: FimStudy, result: OutputSetResult) -> str:
    names = study.run.trajectory.output_names
    labels = [names[int(i)].removeprefix("y_") for i in result.outputs]
    return "y = [" + ", ".join(labels) + "]"


def study_json(study: FimStudy) -> dict[str, Any]:
    """JSON-ready dictionary of the whole study (output indices replaced by names)."""
    data = study.to_dict()
    names = study.run.trajectory.output_names
    for window in data["windows"]:
        for result in window["output_sets"]:
            result["outputs"] = [names[int(i)] for i in result["outputs"]]
    return data


def _gamma_text(value: float) -> str:
    return "inf" if not np.isfinite(value) else f"{value:.3g}"


def _output_label(outputs: Sequence[str]) -> str:
    return ", ".join(o.removeprefix("y_") for o in outputs)


def _gamma_md(value: float | str, gamma_max: float) -> str:
    """γ of the JSON (a number or "inf") to three digits, bold where it meets the limit."""
    if value == "inf":
        return "∞"
    text = f"{value:.3g}"
    return f"**{text}**" if value <= gamma_max else text


def fim_markdown(data: dict[str, Any], command: str) -> str:
    """The study's JSON (:func:`study_json`, ``fim.json`` of ``gearsym fim --open-loop --out
    DIR``) as the documentation's tables, headed by the command that wrote it: per phase and
    set of measured outputs, what the elimination (3.3) keeps, γ (3.27) of every parameter, and
    the parameter combinations of Figures 3.9–3.14. The command writes it as ``fim.md`` beside
    the JSON; nobody types its numbers."""
    s = data["settings"]
    names = data["parameters"]
    gamma_max = s["gamma_max"]
    sets = [r["outputs"] for r in data["windows"][0]["output_sets"]]
    labels = [_output_label(o) for o in sets]
    errors = ", ".join(
        f"{k.removeprefix('y_')} {v * 100:g} %" for k, v in s["relative_errors"].items()
    )
    p0 = ", ".join(f"{symbol(n)} = {v:g}" for n, v in data["nominal"].items())
    order = " / ".join(f"[{label}]" for label in labels)
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- the open-loop shift model of the {s['shift']} shift (never locks), driven "
        f"by the reference ({s['source']}); sliding: {s['sliding']}; sensitivities "
        f"{s['sensitivities']}",
        f"- noise (3.26): relative errors {errors}, floor {s['floor_fraction'] * 100:g} % of the "
        f"largest value; samples every {s['sample_time_s'] * 1e3:g} ms; p0 (3.27): {p0}",
        f"- measured outputs (3.31), (3.32), each cell in this order: {order}",
        f"- γ (3.27); **bold**: γ ≤ γ_max = {gamma_max:g}; ∞: the information is singular in a "
        "direction that involves the parameter",
        "",
        "Estimable after the elimination (3.3):",
        "",
        "| phase | from – to | samples | " + " | ".join(f"y = [{x}]" for x in labels) + " |",
        "|---|---|---|" + "---|" * len(labels),
    ]
    for w in data["windows"]:
        finals = [
            ", ".join(symbol(n) for n in r["elimination"]["final"]) or "none"
            for r in w["output_sets"]
        ]
        out.append(
            f"| {w['name']} | {w['t_start']:.3f} – {w['t_end']:.3f} s | "
            f"{w['output_sets'][0]['samples']} | " + " | ".join(finals) + " |"
        )
    out += [
        "",
        f"γ of all {len(names)} parameters together:",
        "",
        "| phase | " + " | ".join(symbol(n) for n in names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for w in data["windows"]:
        cells = [
            " / ".join(_gamma_md(r["full"]["gamma"][n], gamma_max) for r in w["output_sets"])
            for n in names
        ]
        out.append(f"| {w['name']} | " + " | ".join(cells) + " |")
    combos = [
        (w["name"], k)
        for w in data["windows"]
        for k in range(len(w["output_sets"][0]["combinations"]))
    ]
    if combos:
        out += [
            "",
            "The parameter combinations of Figures 3.9–3.14 (the others known):",
            "",
            "| phase | estimated together | γ | estimable |",
            "|---|---|---|---|",
        ]
        windows = {w["name"]: w for w in data["windows"]}
        for name, k in combos:
            results = [r["combinations"][k] for r in windows[name]["output_sets"]]
            together = results[0]["parameters"]
            gammas = ", ".join(
                f"{symbol(n)} " + " / ".join(_gamma_md(r["gamma"][n], gamma_max) for r in results)
                for n in together
            )
            verdict = " / ".join("yes" if r["estimable"] else "no" for r in results)
            out.append(
                f"| {name} | {', '.join(symbol(n) for n in together)} | {gammas} | {verdict} |"
            )
    return "\n".join(out) + "\n"


def format_text(study: FimStudy) -> str:
    """Tables per phase, output set and parameter combination."""
    lines = []
    s = study.settings
    errors = ", ".join(f"{k.removeprefix('y_')} {v:.0%}" for k, v in s["relative_errors"].items())
    lines.append(
        f"Fisher information along the reference shift (3.25), open-loop shift model "
        f"(never locks; gearsym fim --open-loop) (reference: {s['source']}; "
        f"sliding: {s['sliding']}; "
        f"sensitivities {SENSITIVITY_VIEW[s['restart']]})"
    )
    lines.append(
        f"  samples every {s['sample_time_s'] * 1e3:g} ms; relative errors {errors}; floor "
        f"{s['floor_fraction']:.0%} of the largest value (3.26); limit γ_max = {s['gamma_max']:g}"
    )
    nominal = ", ".join(f"{n} = {v:g}" for n, v in zip(study.parameters, study.scales, strict=True))
    lines.append(f"  p0 (3.3, 3.27): {nominal}")
    for window in study.windows:
        lines.append("")
        lines.append(
            f"== {window.name}  ({window.t_start:.3f} s – {window.t_end:.3f} s, "
            f"{window.results[0].samples} samples)"
        )
        for result in window.results:
            a = result.full
            lines.append(f"  {output_set_label(study, result)}")
            lines.append(f"    {'parameter':<10} {'p0':>10} {'σ (CRB)':>11} {'γ':>9}  ok")
            for j, n in enumerate(a.names):
                ok = "✓" if a.gamma[j] <= a.gamma_max else "✗"
                sigma = "inf" if not np.isfinite(a.sigma[j]) else f"{a.sigma[j]:.3g}"
                gamma = _gamma_text(a.gamma[j])
                lines.append(f"    {n:<10} {a.scales[j]:>10.4g} {sigma:>11} {gamma:>9}  {ok}")
            eig = ", ".join(f"{v:.3g}" for v in a.eigenvalues)
            lines.append(f"    eigenvalues of F_N (3.28): {eig}; rank {a.rank}/{len(a.names)}")
            for direction in a.null_directions:
                lines.append(f"    singular: null direction {describe_direction(direction)}")
            steps = result.elimination.steps
            dropped = [st.dropped for st in steps if st.dropped]
            final = result.elimination.final
            lines.append(
                f"    elimination: drop {', '.join(dropped) or 'nothing'} → estimable: "
                f"{', '.join(final) or 'none'}"
            )
            for c in result.combinations:
                gammas = ", ".join(
                    f"γ({n}) = {_gamma_text(g)}" for n, g in zip(c.names, c.gamma, strict=True)
                )
                mark = "✓" if c.estimable else "✗"
                lines.append(f"    thesis combination {{{', '.join(c.names)}}}: {gammas} {mark}")
    return "\n".join(lines)


def summary_lines(study: FimStudy) -> list[str]:
    """A few lines: per window, the parameters that stay estimable after elimination."""
    lines = []
    for window in study.windows:
        parts = []
        for result in window.results:
            final = result.elimination.final
            label = "with ω̇C" if len(result.outputs) > 3 else "speeds"
            parts.append(f"{label}: {', '.join(final) or 'none'}")
        lines.append(f"{window.name:<13} " + "; ".join(parts))
    return lines


def plot_scatter(study: FimStudy, out_dir: Path) -> list[Path]:
    """Bar charts like Figures 3.9–3.14: normalised scatter γ_j of each parameter combination,
    with and without ω̇_C as a measured output, the limit γ_max dashed (log scale)."""
    from gearsym.validation.drawing.figures import save, subplots

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for w, window in enumerate(study.windows):
        first = window.results[0]
        combos = [first.full] + list(first.combinations)
        for c, analysis in enumerate(combos):
            fig, ax = subplots(1, 1, (6, 3.6), {"left": 0.12, "bottom": 0.1, "top": 0.9})
            width = 0.8 / len(window.results)
            positions = np.arange(len(analysis.names))
            for r, result in enumerate(window.results):
                chosen = result.full if c == 0 else result.combinations[c - 1]
                values = np.where(np.isfinite(chosen.gamma), chosen.gamma, np.nan)
                label = "with dω_C/dt" if len(result.outputs) > 3 else "without dω_C/dt"
                bars = ax.bar(
                    positions + (r - (len(window.results) - 1) / 2) * width,
                    values,
                    width,
                    label=label,
                )
                for bar, g in zip(bars, chosen.gamma, strict=True):
                    if not np.isfinite(g):
                        ax.annotate(
                            "singular",
                            (bar.get_x() + bar.get_width() / 2, study.settings["gamma_max"]),
                            ha="center",
                            fontsize=7,
                            rotation=90,
                        )
            ax.axhline(study.settings["gamma_max"], color="k", ls="--", lw=0.8, label="γ_max")
            ax.set_yscale("log")
            ax.set_xticks(positions, [symbol(n) for n in analysis.names])
            ax.set_ylabel("normalised scatter γ (3.27)")
            kind = "simultaneous" if len(analysis.names) > 1 else "single"
            ax.set_title(
                f"{window.name}: {kind} estimation of {', '.join(analysis.names)}", fontsize=9
            )
            ax.legend(fontsize=7)
            ax.grid(False, axis="x")
            slug = window.name.replace(" ", "_")
            path = out_dir / f"fim_{w}_{slug}_{'_'.join(analysis.names)}.png"
            paths.append(save(fig, path, dpi=120))
    return paths
