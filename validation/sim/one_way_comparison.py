"""The hybrid model of a shift with a one-way clutch (freewheel) against hand values and the
reference simulation: the table of ``docs/hybrid.md`` (*One-way clutches*), written by this
module, never typed.

``python -m gearsym.validation.sim.one_way_comparison --out DIR`` runs, on the Simpson box with
the low freewheel F1 (``tests/data/simpson_3speed_one_way.toml``), the 1-2 upshift, the 2-1
downshift and a coast in gear 1 through the hybrid simulator, the 1-2 and the 2-1 through the
reference simulation (CVODES; for the 2-1 the first of :data:`DOWNSHIFT_INTEGRATORS` that
completes, see :func:`reference_downshift`) and the 1-2 once more
through a reference with a ten times stiffer sprag and bristles (σ0 × 10, σ1 × √10); it writes
the measured values into ``DIR/one_way.json`` and the table rendered from them into
``DIR/one_way.md``. ``tests/test_hybrid_one_way.py`` asserts the bounds these values must keep;
``tests/test_docs_results_analyses.py`` renders the table again from the JSON.
"""

from __future__ import annotations

import json
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "DOWNSHIFT_INTEGRATORS",
    "main",
    "one_way_comparison",
    "one_way_markdown",
    "reference_downshift",
]

#: The reference integrators tried on the 2-1, in order (:func:`reference_downshift`).
DOWNSHIFT_INTEGRATORS: tuple[dict[str, Any], ...] = (
    {"method": "Radau"},
    {"method": "cvodes"},
    {"method": "Radau", "analytic_jacobian": False},
)

COMMAND = "python -m gearsym.validation.sim.one_way_comparison"
DATA = Path("tests/data")
#: The speeds compared with the reference (their largest difference relative to the peak).
SPEEDS = ("omega_in", "omega_out", "omega_sun", "omega_carrier_r")
#: The reference's stiffer sprag and bristles: σ0 × 10 and σ1 × √10 in the box's text.
STIFFER = (
    ("sigma0 = { value = 2.0e5,", "sigma0 = { value = 2.0e6,"),
    ("sigma1 = { value = 150.0,", "sigma1 = { value = 474.3,"),
)
#: The comparison with the reference starts here (its F1 starts unwound and shuffles before).
COMPARE_FROM = 0.4


def _differences(hybrid: Any, reference: Any, window: np.ndarray) -> dict[str, float]:
    """max |hybrid − reference| / max |reference| of each compared signal over the window."""
    keys = (*SPEEDS, "phi", "omega_C")
    return {
        k: float(
            np.max(np.abs(hybrid.signals[k][window] - reference.signals[k][window]))
            / np.max(np.abs(reference.signals[k][window]))
        )
        for k in keys
    }


def _event(result: Any, kind: str, element: str) -> float:
    (t,) = [e.t for e in result.events if e.kind == kind and e.element == element]
    return float(t)


def reference_downshift(d: Any, scenario: Any) -> tuple[Any, str]:
    """The reference simulation of the 2-1 by the first of :data:`DOWNSHIFT_INTEGRATORS` that
    completes, and its name. Which stiff integrator gets through the scenario's first
    microseconds (the freewheel's contact law max(0, k z + c ż) has a kink the Newton
    iterations straddle) depends on the machine's rounding: one machine's CVODES failed at
    6e-5 s (CV_CONV_FAILURE) where its Radau passed; another's Radau failed at 1e-6 s unless
    OpenBLAS ran its Haswell kernels, and its CVODES passed. All of them integrate the same
    model to the same tolerances. Raises the last failure when none completes."""
    from gearsym.symbolic.errors import GearsymError
    from gearsym.validation.sim.simulate import simulate

    failure: GearsymError | None = None
    for options in DOWNSHIFT_INTEGRATORS:
        try:
            result = simulate(d, scenario, check_models=False, phases=False, **options)
        except GearsymError as error:
            failure = error
            continue
        name = options["method"] if options["method"] == "Radau" else "CVODES"
        if options.get("analytic_jacobian") is False:
            name += ", differenced Jacobian"
        return result, name
    assert failure is not None
    raise failure


def one_way_comparison(box: Path, upshift: Path, downshift: Path, coast: Path) -> dict[str, Any]:
    """Every value of the table (see the module text), as plain JSON data."""
    from gearsym.symbolic.loader import load_description
    from gearsym.symbolic.ratios import ratio_table
    from gearsym.validation.sim.hybrid_energy import energy_audit
    from gearsym.validation.sim.hybrid_simulation import HybridSimulator
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description(box)
    ratios = {g.gear: float(g.ratio) for g in ratio_table(d) if g.ratio is not None}

    def hybrid(path: Path) -> tuple[Any, Any]:
        simulator = HybridSimulator(d, load_scenario(d, path))
        return simulator, simulator.run()

    runs = {"upshift": hybrid(upshift), "downshift": hybrid(downshift), "coast": hybrid(coast)}
    up, down, coasting = (runs[k][1] for k in ("upshift", "downshift", "coast"))
    reference = simulate(d, load_scenario(d, upshift), check_models=False)
    text = box.read_text(encoding="utf-8")
    for old, new in STIFFER:
        if old not in text:
            raise ValueError(f"{box}: no {old!r} to make the reference stiffer")
        text = text.replace(old, new)
    with tempfile.TemporaryDirectory() as folder:
        stiff_path = Path(folder) / Path(box).name
        stiff_path.write_text(text, encoding="utf-8")
        stiff_box = load_description(stiff_path)
    stiff = simulate(stiff_box, load_scenario(stiff_box, upshift), check_models=False, phases=False)
    reference_down, integrator = reference_downshift(d, load_scenario(d, downshift))

    t_in = float(runs["upshift"][0].scenario.input_torque(0.0))
    t = reference.t
    window = t >= COMPARE_FROM
    release = _event(up, "release", "F1")
    lock = _event(up, "lock-up", "B1")

    def synchronous(run: Any) -> float:
        times = run.t[(np.abs(run.signals["slip_B1"]) < 1e-2) & (run.t > release)]
        return float(times[0])

    soft = _differences(up, reference, window)
    hard = _differences(up, stiff, window)
    whole = np.ones(len(reference_down.t), dtype=bool)
    f1_lock = _event(down, "lock-up", "F1")
    return {
        "box": str(box),
        "scenarios": {
            "upshift": str(upshift),
            "downshift": str(downshift),
            "coast": str(coast),
        },
        "T_In": t_in,
        "ratios": {"1": ratios["1"], "2": ratios["2"]},
        "compare_from": COMPARE_FROM,
        "upshift": {
            "T_F1_gear_1": float(up.signals["T_F1"][0]),
            "release": release,
            "T_B1_at_release": float(abs(np.interp(release, up.t, up.signals["T_B1"]))),
            "reference_F1_free": float(t[(reference.signals["T_F1"] == 0) & window][0]),
            "lock_up_B1": lock,
            "reference_synchronous": synchronous(reference),
            "stiff_reference_synchronous": synchronous(stiff),
            "differences": soft,
            "differences_stiff": hard,
        },
        "downshift": {
            "reference_integrator": integrator,
            "lock_up_F1": f1_lock,
            "reference_F1_takes_torque": float(
                reference_down.t[reference_down.signals["T_F1"] > 0][0]
            ),
            "differences": _differences(down, reference_down, whole),
        },
        "coast": {
            "T_In": float(runs["coast"][0].scenario.input_torque(0.0)),
            "events": [[e.kind, e.element, float(e.t)] for e in coasting.events],
            "T_F1_max_abs": float(np.max(np.abs(coasting.signals["T_F1"]))),
        },
        "energy_residual": {
            name: float(energy_audit(*runs[name]).relative_residual)
            for name in ("upshift", "downshift", "coast")
        },
    }


def _sci(value: float) -> str:
    """2.1e-09 as 2.1·10⁻⁹ (the page's style)."""
    mantissa, exponent = f"{value:.1e}".split("e")
    digits = str(int(exponent)).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"{mantissa}·10{digits}"


def _percent_or_sci(value: float) -> str:
    return f"{value * 100:.2g} %" if value >= 1e-3 else f"{_sci(value)} of peak"


def one_way_markdown(data: dict[str, Any], command: str) -> str:
    """The JSON of :func:`one_way_comparison` as the page's table, headed by its command."""
    up, down, coast = data["upshift"], data["downshift"], data["coast"]
    t_in = data["T_In"]
    i1, i2 = data["ratios"]["1"], data["ratios"]["2"]
    static_f1, static_b1 = (i1 - 1) * t_in, (i2 - 1) * t_in
    inertia = 1 - up["T_F1_gear_1"] / static_f1
    d_up, d_stiff, d_down = up["differences"], up["differences_stiff"], down["differences"]
    speeds_up = max(d_up[k] for k in SPEEDS)
    speeds_down = max(d_down[k] for k in SPEEDS)
    energy = data["energy_residual"]
    events = ", ".join(f"{kind} {element} at {t:g} s" for kind, element, t in coast["events"])
    locks = any(kind == "lock-up" for kind, _, _ in coast["events"])
    rows = [
        (
            "1-2: T_F1 in gear 1",
            f"{up['T_F1_gear_1']:.2f} N·m",
            f"(i₁ − 1) T_In = {static_f1:.2f} N·m (quasi-static; the inertias take "
            f"{inertia * 100:.1f} %)",
        ),
        (
            "1-2: F1 releases",
            f"{up['release']:.4f} s, \\|T_B1\\| = {up['T_B1_at_release']:.2f} N·m then",
            f"(i₂ − 1) T_In = {static_b1:.2f} N·m; reference's F1 torque 0 at "
            f"{up['reference_F1_free']:.4f} s",
        ),
        (
            "1-2: B1 locks up",
            f"{up['lock_up_B1']:.4f} s",
            f"reference synchronous at {up['reference_synchronous']:.4f} s "
            f"({up['stiff_reference_synchronous']:.4f} s with σ0 ×10)",
        ),
        (
            f"1-2: states from {data['compare_from']:g} s",
            f"ω {_percent_or_sci(speeds_up)}, φ {_percent_or_sci(d_up['phi'])}, ω_C "
            f"{_percent_or_sci(d_up['omega_C'])}",
            f"×10 σ0: ω_in {_sci(d_up['omega_in'])} → {_sci(d_stiff['omega_in'])}, φ "
            f"{_sci(d_up['phi'])} → {_sci(d_stiff['phi'])}, ω_C {_sci(d_up['omega_C'])} → "
            f"{_sci(d_stiff['omega_C'])}",
        ),
        (
            "2-1: F1 locks up",
            f"{down['lock_up_F1']:.4f} s",
            f"reference ({down.get('reference_integrator', 'Radau')}) takes torque at "
            f"{down['reference_F1_takes_torque']:.4f} s; "
            f"ω {_percent_or_sci(speeds_down)}, φ {_percent_or_sci(d_down['phi'])}",
        ),
        (
            f"coast gear 1 (T_In = {coast['T_In']:g} N·m)".replace("-", "−"),
            f"{events}; {'locks' if locks else 'never locks'}, max \\|T_F1\\| = "
            f"{coast['T_F1_max_abs']:g} N·m",
            "(reference: overruns, `test_one_way.py`)",
        ),
        (
            "energy audit residual",
            f"{_sci(energy['upshift'])} (1-2), {_sci(energy['downshift'])} (2-1), "
            f"{_sci(energy['coast'])} (coast)",
            "tests assert 10⁻⁷ as for the 2-3",
        ),
    ]
    out = [
        f"<!-- written by `{command}`; do not edit by hand: run the command again -->",
        "",
        f"*Written by `{command}`.*",
        "",
        f"- `{data['box']}`, scenarios `{data['scenarios']['upshift']}` (1-2), "
        f"`{data['scenarios']['downshift']}` (2-1), `{data['scenarios']['coast']}` (coast); "
        f"T_In = {t_in:g} N·m; differences: largest |hybrid − reference| over the run (the 1-2 "
        f"from {data['compare_from']:g} s) relative to the reference's peak, ω the largest of "
        f"the speeds",
        "",
        "| | hybrid model | hand value / reference simulation |",
        "|---|---|---|",
        *(f"| {a} | {b} | {c} |" for a, b, c in rows),
    ]
    return "\n".join(out) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m gearsym.validation.sim.one_way_comparison --out DIR``."""
    import argparse

    parser = argparse.ArgumentParser(
        prog=COMMAND,
        description="the freewheel shifts' hybrid model against hand values and the reference",
    )
    parser.add_argument("--out", required=True, help="folder for one_way.json and one_way.md")
    parser.add_argument("--box", default=str(DATA / "simpson_3speed_one_way.toml"))
    parser.add_argument("--upshift", default=str(DATA / "simpson_one_way_1_2.toml"))
    parser.add_argument("--downshift", default=str(DATA / "simpson_one_way_2_1.toml"))
    parser.add_argument("--coast", default=str(DATA / "simpson_one_way_coast.toml"))
    args = parser.parse_args(argv)
    paths = [Path(p) for p in (args.box, args.upshift, args.downshift, args.coast)]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        print(f"{COMMAND}: no such file: {', '.join(missing)}", file=sys.stderr)
        return 2
    data = one_way_comparison(*paths)
    command = " ".join([COMMAND, *(argv if argv is not None else sys.argv[1:])])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "one_way.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    (out / "one_way.md").write_text(one_way_markdown(data, command), encoding="utf-8")
    print(f"wrote {out / 'one_way.json'} and {out / 'one_way.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
