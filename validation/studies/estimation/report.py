"""The estimators' results as files and text: CSV time series and the printed summaries of the
UIO, EKF, Monte-Carlo and EUIO runs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.validation.studies.estimation.bounds import BOUND_ASSUMPTION, NOT_IDENTIFIABLE
from gearsym.validation.studies.estimation.euio import EuioRun
from gearsym.validation.studies.estimation.loop import EkfRun, _chi2_mean_band
from gearsym.validation.studies.estimation.montecarlo import EkfMonteCarlo
from gearsym.validation.studies.estimation.uio import SETTLING_TIME, UioRun

__all__ = [
    "format_ekf_text",
    "format_measured_ekf_text",
    "format_monte_carlo_text",
    "format_text",
    "measured_ekf_dict",
    "write_csv",
    "write_ekf_csv",
]


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


def write_ekf_csv(run: EkfRun, path: Path) -> Path:
    """Every sample: t, phase, per augmented state its estimate, σ and truth (empty where none),
    NEES with its dof, NIS with its dof, and per element the mode held from the sample on
    (0 open, ±1 slide, 2 stick)."""
    from gearsym.validation.sim.phases import phase_of

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


def write_euio_csv(run: EuioRun, path: Path) -> Path:
    """Every sample: t, phase, per state its estimate, σ, truth (empty where none) and whether
    it is held, then d̂ = T_res*, its σ and the reference T_res."""
    from gearsym.validation.sim.phases import phase_of

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
