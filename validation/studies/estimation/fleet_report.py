"""What a fleet evaluation (:mod:`.fleet_eval`) prints and writes: the text of ``gearsym
estimate --fleet``, its CSV (one row per vehicle), its Markdown table (the documentation's
result tables are these files, written by the command, never typed) and its picture."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.parameters import axis_label, record, symbol
from gearsym.validation.studies.estimation.fleet_eval import FleetEvaluation

__all__ = [
    "COVERAGE_RANGE",
    "MASS_EFFICIENCY_LIMIT",
    "MU_KEPT_SHARE",
    "criteria",
    "fleet_markdown",
    "format_fleet_text",
    "plot_fleet",
    "write_fleet_csv",
]

#: The coverage of a 95 % interval a consistent filter shows over a fleet (the estimation
#: issue's acceptance range: 200 runs put the sampling error of 95 % at about 1.5 %).
COVERAGE_RANGE = (0.90, 0.98)
#: The estimation issue's bound on the mass's efficiency (RMSE over the posterior bound).
MASS_EFFICIENCY_LIMIT = 1.3
#: The share of vehicles whose μ the filter keeps after the shift within 1.96 σ of the truth
#: that the issue's "μ kept after the shift within 2 σ" asks of a fleet: the coverage range's
#: lower end (more is conservative, never a miss).
MU_KEPT_SHARE = COVERAGE_RANGE[0]


def _unit(name: str) -> str:
    try:
        unit = record(name).unit
    except KeyError:
        return ""
    return "" if unit == "1" else f" {unit}"


def _name(name: str, data: dict[str, Any], label: Any = symbol) -> str:
    """A parameter's label; under ``mu_model = "map_scale"`` a μ state is its map's scale."""
    if data.get("mu_model") == "map_scale" and name.startswith("mu_"):
        return f"{symbol(name)} map scale"
    return str(label(name))


def _g(value: float | None, digits: int = 3) -> str:
    return "—" if value is None else f"{value:.{digits}g}"


def _coverage(stats: dict[str, Any]) -> str:
    value = stats.get("coverage_95")
    if value is None:
        return "—"
    lo, hi = COVERAGE_RANGE
    flag = "" if lo <= value <= hi else (" LOW" if value < lo else " HIGH")
    return f"{100 * value:.0f} %{flag} of {stats['samples']}"


def _inside(value: float | None, band: Sequence[float] | None) -> bool:
    """A consistency statistic inside its χ² band (the edges included)."""
    return value is not None and band is not None and band[0] <= value <= band[1]


def _band(value: float | None, band: Sequence[float] | None) -> str:
    if value is None or band is None:
        return "—"
    inside = _inside(value, band)
    return f"{value:.3g} in [{band[0]:.3g}, {band[1]:.3g}]: {'inside' if inside else 'OUTSIDE'}"


def _over_vehicles(data: dict[str, Any]) -> list[str]:
    """The NEES mean's bootstrap interval over the vehicles, where the JSON has it."""
    spread = data.get("nees_over_vehicles")
    if not spread:
        return []
    low, high = spread["interval"]
    expected = spread["expected"]
    verdict = "inside" if low <= expected <= high else "OUTSIDE"
    return [
        f"NEES mean over the vehicles drawn again ({spread['resamples']} bootstrap draws): "
        f"95 % interval [{low:.3g}, {high:.3g}]; a consistent filter's {expected:.3g} (the mean "
        f"dof) {verdict} (the χ² band assumes every vehicle the same filter with an exact model)"
    ]


def _has_bound(data: dict[str, Any]) -> bool:
    return any(
        stats.get("bound") is not None
        for entry in data["parameters"].values()
        for stats in entry["phases"].values()
    )


def _entry(entry: dict[str, Any]) -> str:
    """A fleet entry as a value or a range, with its unit."""
    unit = "" if entry.get("unit") in (None, "1") else f" {entry['unit']}"
    if "value" in entry:
        return f"{_g(entry['value'], 4)}{unit}"
    if entry.get("dist") == "uniform":
        return f"{_g(entry['low'], 4)}-{_g(entry['high'], 4)}{unit}"
    return f"normal {_g(entry['mean'], 4)} ± {_g(entry['sd'], 3)}{unit}"


def _assumptions(data: dict[str, Any]) -> list[str]:
    seeds = data["seeds"]
    prior = ", ".join(
        f"{_name(n, data)} {_g(v['value'], 4)} ± {_g(v['sigma'], 3)}{_unit(n)}"
        for n, v in data["initial"].items()
    )
    mu_model = (
        "a scale s per element on the calibration's mu map read at the commanded pressure and "
        "the filter's own slip estimate (mu = s mu_map; scored against the draw's factor)"
        if data.get("mu_model") == "map_scale"
        else "mu itself a random walk (thesis 4.1)"
    )
    fleet = data["fleet"]
    lines = [
        f"the fleet {fleet['name']} ({fleet['file']}): {data['runs']} vehicles drawn with seeds "
        f"{seeds[0]}-{seeds[-1]}, each simulated by the reference on the scenario "
        f"{data['scenario']}; the filter knows the calibration only and is told the commanded "
        "inputs (T_In as commanded, F_N = commanded pressure x piston area)",
        "the filter's start (the description's [estimator] prior, the same for every vehicle): "
        f"{prior}",
        f"tuned on: {data['tuning']['tuned_on']}",
        f"the filter's mu: {mu_model}",
        "scores: at the end of the shift the filter's own last estimate against the vehicle's "
        "truth (mu: against the mean true mu over the samples the filter judged its element "
        "sliding); per phase over the samples with a truth (mu: while the truth slides); "
        "coverage: the share of scored samples whose error lies within 1.96 sigma, judged "
        f"against {100 * COVERAGE_RANGE[0]:.0f}-{100 * COVERAGE_RANGE[1]:.0f} %",
    ]
    sensors = {k: v for k, v in fleet["entries"].items() if k.startswith("speed_sensor_")}
    if sensors:
        lines.append(
            "the speeds: read from tooth wheels ("
            + ", ".join(
                f"{k.removeprefix('speed_sensor_')} {_entry(v)}" for k, v in sensors.items()
            )
            + "; validation/sim/tooth_wheel.py: the pitch over the last tooth period, late by up "
            "to 1.5 periods plus the latency, rounded to the timer), with no Gaussian noise; "
            "the filter keeps the calibration's noise model (3.26)"
        )
    if data.get("input_hold") == "mean":
        lines.append(
            "the known inputs (T_In, F_N) in each prediction: the mean of the interval's two "
            "samples (--input-hold mean: the TCU knows the ramps it commands), the mode flags "
            "held; the emitted C filter holds the inputs at the interval's start"
        )
    considered = data.get("considered") or []
    if considered:
        lines.append(
            "considered, not estimated (Schmidt consider states: their prior in the covariance, "
            "so in the sigma of what they are confounded with; no measurement corrects them): "
            + ", ".join(_name(n, data) for n in considered)
        )
    if _has_bound(data):
        lines.append(
            "bound: the posterior Cramer-Rao bound along each vehicle's truth under the "
            "filter's own model and prior (constant parameters, exact model); efficiency = "
            "RMSE / bound, > 1 expected with random walks and the elastic truth"
        )
    return lines


def _phase_rows(data: dict[str, Any]) -> list[tuple[str, str, dict[str, Any]]]:
    names = list(data["parameters"])
    phases: list[str] = []
    for name in names:
        for phase in data["parameters"][name]["phases"]:
            if phase not in phases:
                phases.append(phase)
    return [
        (phase, name, data["parameters"][name]["phases"][phase])
        for phase in phases
        for name in names
        if data["parameters"][name]["phases"].get(phase, {}).get("samples")
    ]


def _identifiable(stats: dict[str, Any]) -> str:
    value = stats.get("identifiable")
    if value is None:
        return "—"
    there = stats.get("coverage_95_identifiable")
    # a report written before the key existed keeps its column as it was
    covered = "" if there is None else f" (coverage {100 * there:.0f} % there)"
    return f"{100 * value:.0f} % of runs{covered}"


def criteria(data: dict[str, Any]) -> list[str]:
    """The estimation issue's acceptance criteria judged on a fleet evaluation's JSON: NEES
    and NIS inside their bands; every estimated parameter's coverage within
    :data:`COVERAGE_RANGE` over the runs whose phase identifies it; the mass's efficiency at
    most :data:`MASS_EFFICIENCY_LIMIT` in every phase; the μ the filter keeps after the shift
    within 1.96 σ on at least :data:`MU_KEPT_SHARE` of the vehicles. Empty for a report
    written before the identifiable runs' coverage was recorded."""
    rows = _phase_rows(data)
    if not any("coverage_95_identifiable" in s for _, _, s in rows):
        return []
    lo, hi = COVERAGE_RANGE
    considered = set(data.get("considered") or [])
    misses = []
    judged = 0
    for phase, name, s in rows:
        there = s.get("coverage_95_identifiable")
        if name in considered or there is None:
            continue
        judged += 1
        if not lo <= there <= hi:
            # one decimal: a miss must not print as the range's own end (89.7 % as "90 %")
            misses.append(f"{_name(name, data)} in {phase} {100 * there:.1f} %")
    efficiency = [s["efficiency"] for _, name, s in rows if name == "m_veh" and s.get("efficiency")]
    mu = {
        name: entry["final"]["coverage_95"]
        for name, entry in data["parameters"].items()
        if name.startswith("mu_") and entry["final"].get("coverage_95") is not None
    }
    nees = _inside(data.get("nees_mean"), data.get("nees_band"))
    nis = _inside(data.get("nis_mean"), data.get("nis_band"))
    worst = max(efficiency) if efficiency else None
    mu_missed = [n for n, v in mu.items() if v < MU_KEPT_SHARE]
    return [
        "the estimation issue's criteria: "
        + "; ".join(
            (
                f"NEES {'inside' if nees else 'OUTSIDE'} and NIS {'inside' if nis else 'OUTSIDE'}"
                " their bands",
                f"coverage within {100 * lo:.0f}-{100 * hi:.0f} % over the runs whose phase "
                f"identifies the parameter: {judged - len(misses)} of {judged} (phase, "
                "parameter) pairs"
                + (f", MISSED: {', '.join(misses)}" if misses else "")
                + (
                    f" (consider states not judged: {', '.join(sorted(considered))})"
                    if considered
                    else ""
                ),
                "m_veh efficiency at most "
                f"{MASS_EFFICIENCY_LIMIT:g} in every phase: "
                + (
                    "—"
                    if worst is None
                    else f"{_g(worst)} at most"
                    + ("" if worst <= MASS_EFFICIENCY_LIMIT else ", MISSED")
                ),
                f"mu kept after the shift within 1.96 sigma on at least "
                f"{100 * MU_KEPT_SHARE:.0f} % of the vehicles: "
                + ", ".join(f"{_name(n, data)} {100 * v:.0f} %" for n, v in mu.items())
                + (
                    f", MISSED: {', '.join(_name(n, data) for n in mu_missed)}" if mu_missed else ""
                ),
            )
        )
    ]


def _separability(data: dict[str, Any]) -> list[str]:
    """What one shift cannot separate, from the JSON's ``separability``: the γ (3.27) of each
    parameter over the whole shift with the input-torque gain known and unknown."""
    study = data.get("separability", {}).get("input_torque_gain")
    if not study or "shift" not in study:
        return []
    whole = study["shift"]
    known, unknown = whole["gamma_gain_known"], whole["gamma_gain_unknown"]
    pairs = ", ".join(
        f"{_name(n, data)} {_g(known[n], 2)} -> {_g(unknown.get(n), 2)}" for n in known
    )
    phases = ", ".join(
        f"{phase} {_g(v['gamma_gain_unknown'].get('input_torque_gain'), 2)}"
        for phase, v in study.items()
        if phase != "shift"
    )
    correlation = whole.get("correlation_m_veh_gain")
    return [
        "what one shift cannot separate (Fisher information (3.25) of the filter's problem on "
        "the calibration's own vehicle, states at the start unknown, gamma (3.27), > 0.1 not "
        f"identifiable): with an input-torque gain unknown beside the parameters, gamma over "
        f"the whole shift {pairs}; the gain's own {_g(unknown.get('input_torque_gain'), 2)}"
        + (f", its correlation with m_veh {correlation:.2f}" if correlation is not None else "")
        + f"; the gain within a single phase: {phases}",
    ]


def _per_phase(data: dict[str, Any]) -> list[tuple[str, str, str, str]]:
    """(phase, NEES/dof, NIS/dof with its band and verdict, samples) per phase; none for a
    JSON written before the per-phase consistency was recorded."""
    rows = []
    for phase, c in (data.get("consistency_per_phase") or {}).items():
        nis = c["nis_per_dof"]
        rows.append(
            (
                phase,
                _g(c["nees_per_dof"]),
                "-" if nis is None else _band(nis, c["nis_band_per_dof"]),
                str(c["samples"]),
            )
        )
    return rows


def format_fleet_text(data: dict[str, Any]) -> str:
    """The printed report of a fleet evaluation, from its JSON."""
    lines = [f"  assumes {line}" for line in _assumptions(data)]
    lines += [f"  {line}" for line in _separability(data)]
    lines.append("")
    lines.append("  at the end of the shift (the value an adaptation reads):")
    lines.append(f"    {'parameter':<10} {'bias':>10} {'RMSE':>10} {'mean σ':>10}  coverage 95 %")
    for name, entry in data["parameters"].items():
        s = entry["final"]
        lines.append(
            f"    {_name(name, data):<10} {_g(s['bias']):>10} {_g(s['rmse']):>10} "
            f"{_g(s['mean_sigma']):>10}  {_coverage(s)}"
        )
    lines.append("")
    lines.append("  per phase (samples with a truth):")
    lines.append(
        f"    {'phase':<13} {'parameter':<9} {'bias':>9} {'RMSE':>9} {'mean σ':>9} "
        f"{'bound':>9} {'eff.':>6}  coverage 95 %; identifiable in"
    )
    for phase, name, s in _phase_rows(data):
        lines.append(
            f"    {phase:<13} {_name(name, data):<9} {_g(s['bias']):>9} {_g(s['rmse']):>9} "
            f"{_g(s['mean_sigma']):>9} {_g(s['bound']):>9} {_g(s['efficiency']):>6}  "
            f"{_coverage(s)}; {_identifiable(s)}"
        )
    lines.append("")
    lines.append(f"  NEES mean {_band(data['nees_mean'], data['nees_band'])}")
    lines += [f"  {line}" for line in _over_vehicles(data)]
    lines.append(f"  NIS mean {_band(data['nis_mean'], data['nis_band'])}")
    for phase, nees, nis, samples in _per_phase(data):
        lines.append(f"    {phase}: NEES/dof {nees}, NIS/dof {nis} ({samples} samples)")
    lines += [f"  {line}" for line in criteria(data)]
    if data["failed"]:
        lines.append(
            f"  {len(data['failed'])} vehicle(s) could not be simulated and are not scored: "
            + "; ".join(f"seed {f['seed']}: {f['reason']}" for f in data["failed"][:3])
        )
    lines.append(f"  {data['seconds_per_run']:.2f} s per vehicle (simulation, filter, bound)")
    return "\n".join(lines)


def write_fleet_csv(ev: FleetEvaluation, path: Path) -> None:
    """One row per vehicle: its seed, its draw, and per parameter the filter's final
    estimate, σ and the truth it is scored against."""
    import csv

    draw_names = sorted({name for fr in ev.runs for name, _ in fr.draw.values})
    names = ev.parameter_names
    header = ["seed", *draw_names]
    for name in names:
        header += [f"{name}_estimate", f"{name}_sigma", f"{name}_truth"]
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for fr in ev.runs:
            values = dict(fr.draw.values)
            row: list[Any] = [fr.draw.seed, *(repr(values.get(n, "")) for n in draw_names)]
            finals = ev.final_rows(fr)
            for name in names:
                estimate, sigma, truth = finals[name]
                row += [repr(estimate), repr(sigma), "" if truth is None else repr(truth)]
            writer.writerow(row)


def fleet_markdown(data: dict[str, Any], command: str) -> str:
    """The evaluation's JSON as Markdown tables for the documentation, headed by the command
    that wrote it (the docs include this file; nobody types its numbers)."""
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
    ]
    out += [f"- {line}" for line in _assumptions(data)]
    out += [
        f"- NEES mean {_band(data['nees_mean'], data['nees_band'])}; "
        f"NIS mean {_band(data['nis_mean'], data['nis_band'])}",
        *(f"- {line}" for line in _over_vehicles(data)),
        f"- {len(data['failed'])} vehicle(s) not simulated"
        if data["failed"]
        else "- every vehicle simulated",
        *(f"- {line}" for line in _separability(data)),
        *(f"- {line}" for line in criteria(data)),
        "",
        "At the end of the shift (the value an adaptation reads):",
        "",
        "| parameter | bias | RMSE | mean σ | coverage of the 95 % interval |",
        "|---|---|---|---|---|",
    ]
    for name, entry in data["parameters"].items():
        s = entry["final"]
        out.append(
            f"| {_name(name, data, axis_label)} | {_g(s['bias'])} | {_g(s['rmse'])} | "
            f"{_g(s['mean_sigma'])} | {_coverage(s)} |"
        )
    out += [
        "",
        "Per phase (samples with a truth):",
        "",
        "| phase | parameter | bias | RMSE | mean σ | coverage 95 % | bound | efficiency | "
        "identifiable in |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for phase, name, s in _phase_rows(data):
        out.append(
            f"| {phase} | {_name(name, data, axis_label)} | {_g(s['bias'])} | {_g(s['rmse'])} | "
            f"{_g(s['mean_sigma'])} | {_coverage(s)} | {_g(s['bound'])} | "
            f"{_g(s['efficiency'])} | {_identifiable(s)} |"
        )
    per_phase = _per_phase(data)
    if per_phase:
        out += [
            "",
            "Consistency per phase (summed over the vehicles, divided by the summed dof; the NIS "
            "against its 95 % band, the NEES without one: its samples are correlated in time):",
            "",
            "| phase | NEES/dof | NIS/dof | samples |",
            "|---|---|---|---|",
            *(
                f"| {phase} | {nees} | {nis} | {samples} |"
                for phase, nees, nis, samples in per_phase
            ),
        ]
    return "\n".join(out) + "\n"


def plot_fleet(ev: FleetEvaluation, path: Path) -> None:
    """Per parameter, the filter's final estimate against each vehicle's truth with its
    ±1.96 σ interval: points on the diagonal are right, bars that miss it are overconfident."""
    from gearsym.validation.drawing.figures import save, subplots

    names = [n for n in ev.parameter_names if ev.final_stats(n).runs]
    fig, axes = subplots(
        1,
        len(names),
        (3.4 * len(names), 3.4),
        {"left": 0.07, "right": 0.99, "bottom": 0.16, "top": 0.9, "wspace": 0.42},
    )
    axes = np.atleast_1d(axes)
    for ax, name in zip(axes, names, strict=True):
        rows = [ev.final_rows(fr)[name] for fr in ev.runs]
        rows = [r for r in rows if r[2] is not None]
        est = np.array([r[0] for r in rows])
        sig = np.array([r[1] for r in rows])
        truth = np.array([r[2] for r in rows])
        covered = np.abs(est - truth) <= 1.959963984540054 * sig
        for mask, colour in ((covered, "tab:blue"), (~covered, "tab:red")):
            ax.errorbar(
                truth[mask],
                est[mask],
                yerr=1.96 * sig[mask],
                fmt="o",
                ms=3,
                lw=0.8,
                color=colour,
            )
        lo, hi = float(min(truth.min(), est.min())), float(max(truth.max(), est.max()))
        ax.plot([lo, hi], [lo, hi], color="0.4", lw=0.8)
        ax.set_xlabel(f"truth {axis_label(name)}")
        ax.set_ylabel("estimate at the end")
        ax.set_title(f"{symbol(name)}: {100 * np.mean(covered):.0f} % covered", fontsize=9)
    save(fig, path)
