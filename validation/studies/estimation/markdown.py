"""Markdown of a Monte-Carlo evaluation's JSON (the EKF's and the extended UIO's share the
per-phase keys, :class:`~gearsym.validation.studies.estimation.montecarlo.ScoredStats`): the
documentation's result tables, written by ``gearsym estimate --runs N --out DIR``
(``monte_carlo.md`` beside the JSON) and copied by ``make results``; nobody types them."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from gearsym.symbolic.parameters import axis_label

__all__ = ["monte_carlo_markdown", "uio_markdown"]


def _g(value: Any, digits: int = 3) -> str:
    return "—" if value is None or isinstance(value, str) else f"{value:.{digits}g}"


def _band(value: float | None, band: Sequence[float] | None) -> str:
    if value is None or band is None:
        return "—"
    inside = band[0] <= value <= band[1]
    return f"{value:.3g} in [{band[0]:.3g}, {band[1]:.3g}]: {'inside' if inside else 'OUTSIDE'}"


def monte_carlo_markdown(data: dict[str, Any], command: str) -> str:
    """The per-phase table of a Monte-Carlo JSON (EKF or EUIO) with its NEES and NIS, headed by
    the command that wrote it."""
    seeds = data.get("seeds") or [data.get("seed", 0)]
    filter_name = {"ekf": "EKF", "euio": "extended UIO"}.get(data["filter"], data["filter"])
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- the {filter_name} on the {data['shift']} shift: {data['runs']} runs over noise seeds "
        f"{seeds[0]}-{seeds[-1]}, one truth (the description's own vehicle), "
        f"{data['sample_time'] * 1e3:g} ms, relative speed noise "
        f"{', '.join(f'{r:g}' for r in data['relative_noise'])}; element modes: "
        f"{data.get('modes', 'filter')}; initial estimate: {data.get('initial_estimate', '—')}",
        f"- NEES mean {_band(data.get('nees_mean'), data.get('nees_band'))}; NIS mean "
        f"{_band(data.get('nis_mean'), data.get('nis_band'))}{_nees_inside(data)}",
        f"- one run {_g(data.get('seconds_per_run'), 2)} s on the machine that ran the command"
        f"{_switches_per_run(data)}",
        "- bound: the posterior Cramér–Rao bound under the filter's own assumptions (constant "
        "parameters, exact model); with process noise: the filter's own random walks and model "
        "error; efficiency = RMSE / bound",
        "",
        "| phase | parameter | mean error | RMSE | σ (RMS) | bound | efficiency | "
        "bound with process noise | efficiency | identifiable |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for phase in data["phases"]:
        for name, s in phase["parameters"].items():
            if not s.get("samples"):
                continue
            out.append(
                f"| {phase['name']} | {axis_label(name)} | {_g(s['mean_error'])} | "
                f"{_g(s['rmse'])} | {_g(s['sigma'])} | {_g(s['crb_sigma'])} | "
                f"{_g(s['efficiency'])} | {_g(s['crb_sigma_process_noise'])} | "
                f"{_g(s['efficiency_process_noise'])} | "
                f"{'yes' if s['identifiable'] else 'no'} |"
            )
    out += _events_table(data.get("events") or [])
    return "\n".join(out) + "\n"


def _nees_inside(data: dict[str, Any]) -> str:
    share = data.get("nees_inside_95")
    if share is None:
        return ""
    return f"; samples whose {data['runs']}-run mean NEES lies inside its band: {share * 100:.0f} %"


def _switches_per_run(data: dict[str, Any]) -> str:
    mean = data.get("mode_switches_mean")
    if mean is None or data.get("modes") != "filter":
        return ""
    return f"; mode switches decided per run: {mean:g} (mean)"


def _events_table(events: Sequence[dict[str, Any]]) -> list[str]:
    """Each switch of the truth: in how many runs the filter found it and how late (the
    filter's time minus the reference's, in ms); then the switches the truth does not have."""
    if not events:
        return []
    out = [
        "",
        "| switch of the reference | at | detected in | error mean | largest error |",
        "|---|---|---|---|---|",
    ]
    extra = "none"
    for ev in events:
        if ev.get("t_reference") is None:
            extra = f"{ev['count_mean']:.3g} per run (mean)"
            continue
        detected = ev["detected_runs"]
        errors = (
            f"{ev['error_ms_mean']:+.1f} ms | {ev['error_ms_max_abs']:.1f} ms"
            if detected
            else "— | —"
        )
        out.append(
            f"| {ev['element']} {ev['kind']} | {ev['t_reference']:.4f} s | "
            f"{detected} of {ev['runs']} runs | {errors} |"
        )
    out += ["", f"Switches the filter decided that the reference does not have: {extra}."]
    return out


def uio_markdown(data: dict[str, Any], command: str) -> str:
    """The UIO run's JSON (one observer per phase, 4.4) as a table per phase: existence, the
    RMS errors of the states it estimates and of the unknown inputs, headed by the command."""
    noise = data.get("noise")
    if not noise:
        noise_text = "no speed noise"
    elif isinstance(noise, list):
        noise_text = "relative speed noise " + ", ".join(f"{r:g}" for r in noise)
    else:
        noise_text = "speed noise (3.26) as the command's --noise states"
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- the UIO of each phase of the {data['shift']} shift, unknown inputs "
        f"{', '.join(data['unknown'])}, {data['sample_time'] * 1e3:g} ms, {noise_text}; RMS "
        "errors against the reference",
        "",
        "| phase | exists | states: RMS error | unknown inputs: RMS error (mean of the truth) |",
        "|---|---|---|---|",
    ]
    for phase in data["phases"]:
        existence = phase["existence"]
        exists = "yes" if existence["exists"] else f"no: {existence.get('reason') or '—'}"
        states = ", ".join(f"{n} {_g(v, 2)}" for n, v in (phase.get("state_rmse") or {}).items())
        means = phase.get("unknown_input_mean") or {}
        inputs = ", ".join(
            f"{n} {_g(v, 2)} ({_g(means.get(n), 3)})"
            for n, v in (phase.get("unknown_input_rmse") or {}).items()
        )
        out.append(f"| {phase['phase']} | {exists} | {states or '—'} | {inputs or '—'} |")
    return "\n".join(out) + "\n"
