"""Gears that leave idle shafts free: ratios report them, the models keep them as states with
a viscous drag to the housing (README "Idle shafts").

Expected values come from hand derivation (the header of tests/data/simpson_overdrive_idle.toml),
from the closed-form decay ω(t) = ω(0) exp(−d t / J) of a shaft coupled to nothing but its
drag, integrated here with SciPy, and from the energy balance of the reference simulation
with the drag's dissipation summed independently from the simulated speeds.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import IDLE_DRAG_DEFAULT, drivetrain_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.model import Model
from gearsym.symbolic.ratios import gear_motion, gear_ratio, idle_shafts

from gearsym.cli import main

OVERDRIVE = Path("tests/data/simpson_overdrive_idle.toml")
ONE_WAY = Path("tests/data/simpson_3speed_one_way.toml")


def gear_model(d: GearboxDescription, gear: str) -> Model:
    """The steady-gear model of ``gearsym model --gear``: the gear's elements locked."""
    return drivetrain_model(
        d, f"gear_{gear}", locked=d.gear(gear).closed, torque_elements=(), keep=(d.output_shaft,)
    )


def test_ratios_and_idle_shafts_of_the_overdrive_box() -> None:
    """Header hand values: 26/11, 16/11, 1, 2/3, −2; the od set idles in 1st–3rd and R,
    the Simpson sets in 4th."""
    d = load_description(OVERDRIVE)
    hand = {"1": sp.Rational(26, 11), "2": sp.Rational(16, 11), "3": 1, "4": sp.Rational(2, 3)}
    hand["R"] = -2
    for gear, ratio in hand.items():
        result = gear_ratio(d, d.gear(gear))
        assert result.ratio == ratio
        expected = ("ring_f", "sun", "carrier_r") if gear == "4" else ("sun_od", "ring_od")
        assert result.free_shafts == expected
    assert idle_shafts(d) == ("ring_f", "sun", "carrier_r", "sun_od", "ring_od")


def test_steady_idle_speeds_by_hand() -> None:
    """Equal drag on sun_od and ring_od: on ω_S + 2 ω_H = 3 ω_in the least ω_S² + ω_H² is
    ω_S = 3/5 ω_in, ω_H = 6/5 ω_in (Lagrange), in every gear that leaves them idle."""
    d = load_description(OVERDRIVE)
    for gear in ("1", "2", "3", "R"):
        w = dict(zip(d.shaft_names, gear_motion(d, d.gear(gear)), strict=True))
        assert w["sun_od"] / w["in"] == sp.Rational(3, 5)
        assert w["ring_od"] / w["in"] == sp.Rational(6, 5)


def test_steady_idle_speeds_are_an_equilibrium_of_the_gear_model() -> None:
    """In the gear-1 model at constant speeds (T_In and the twist φ chosen so that ω_out and
    ω_C do not change, ω_C = ω_out / i_D), the idle state does not change either when it sits
    at the hand value ω_sun_od = 3/5 ω_in = 3/5 · 26/11 ω_out, and it does elsewhere."""
    d = load_description(OVERDRIVE)
    model = gear_model(d, "1")
    names = [v.name for v in model.states]
    assert names == ["omega_out", "omega_sun_od", "phi", "omega_C"]
    rhs = model.rhs.xreplace({k: sp.Float(v) for k, v in model.parameter_defaults().items()})
    out, sun_od, phi, wheel = model.state_symbols
    t_in = model.input_symbols[0]
    w_out = 40.0
    i_d = d.drivetrain["i_D"].value

    def rates(w_sun_od: float) -> list[float]:
        fixed = rhs.xreplace({out: w_out, sun_od: w_sun_od, wheel: w_out / i_d})
        solution = sp.solve([fixed[0], fixed[3]], [t_in, phi], dict=True)[0]
        return [float(e) for e in fixed.xreplace(solution)]

    steady = rates(3 / 5 * 26 / 11 * w_out)
    assert abs(steady[1]) < 1e-9 * w_out and abs(steady[2]) < 1e-9
    assert abs(rates(0.0)[1]) > 1e-3  # off the steady speed the idle shaft accelerates


def _one_way_box_with_idle_shaft(tmp_path: Path, drag: str = "") -> Path:
    """The one-way Simpson box plus a shaft 'idle' reached only through the open clutch C3."""
    text = ONE_WAY.read_text(encoding="utf-8")
    text = text.replace(
        "[[planetary_set]]",
        '[[shaft]]\nname = "idle"\ninertia = { value = 0.01, unit = "kg*m^2", '
        'source = "test" }\n\n[[planetary_set]]',
        1,
    )
    text = text.replace(
        '[[shift_element]]\nname = "C1"',
        '[[shift_element]]\nname = "C3"\nkind = "clutch"\nshafts = ["idle", "sun"]\n'
        'n_disc = 3\nr_m = { value = 0.07, unit = "m", source = "test" }\n'
        'a_piston = { value = 0.005, unit = "m^2", source = "test" }\n\n'
        '[[shift_element]]\nname = "C1"',
    )
    text = text.replace(
        'output_shaft = "out"\n',
        'output_shaft = "out"\ncoordinates = ["in", "ring_f", "sun", "idle"]\n',
        1,
    )
    if drag:
        text = text.replace("[drivetrain]\n", f"[drivetrain]\n{drag}\n")
    path = tmp_path / "idle.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("drag_line", "drag"),
    [
        ("", IDLE_DRAG_DEFAULT.value),
        ('idle_drag = { value = 0.005, unit = "N*m*s/rad", source = "test" }', 0.005),
    ],
)
def test_uncoupled_idle_shaft_decays_exponentially(
    tmp_path: Path, drag_line: str, drag: float
) -> None:
    """A shaft coupled to nothing (C3 open) feels only its drag: J ω̇ = −d ω, so
    ω(t) = ω(0) exp(−d t / J), J = 0.01 kg m²; the gear model integrated with SciPy at a
    driving input torque and a moving vehicle follows it."""
    from scipy.integrate import solve_ivp

    d = load_description(_one_way_box_with_idle_shaft(tmp_path, drag_line))
    assert idle_shafts(d) == ("idle",)
    model = gear_model(d, "1M")
    names = [v.name for v in model.states]
    assert names == ["omega_out", "omega_idle", "phi", "omega_C"]
    idle = model.state_symbols[1]
    assert sp.simplify(model.rhs[1] - (-sp.Rational(repr(drag)) / sp.Rational(1, 100)) * idle) == 0
    f = sp.lambdify(
        (model.state_symbols, model.input_symbols),
        model.rhs.xreplace(model.parameter_defaults()),
        "numpy",
    )
    x0 = [30.0, 50.0, 0.0, 30.0 / d.drivetrain["i_D"].value]
    times = np.linspace(0.0, 3.0, 7)
    sol = solve_ivp(
        lambda t, x: np.ravel(f(x, [120.0])),
        (0, 3),
        x0,
        t_eval=times,
        rtol=1e-10,
        atol=1e-10,
        method="LSODA",
    )
    assert sol.success
    hand = 50.0 * np.exp(-drag * times / 0.01)
    assert sol.y[1] == pytest.approx(hand, rel=1e-7)
    assert sol.y[0][-1] > 30.0  # the drive path is not held back: the vehicle accelerates


def _hold(tmp_path: Path, box: Path, closed: dict[str, float]) -> object:
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description(box)
    pressures = "".join(
        f'[pressure.{e}]\nunit = "Pa"\ntime = [0.0]\nvalue = [{p}]\n' for e, p in closed.items()
    )
    path = tmp_path / "hold.toml"
    path.write_text(
        '[scenario]\nshift = "1-2"\nt_end = 0.5\n'
        'vehicle_speed = { value = 5.0, unit = "m/s", source = "test" }\n'
        '[input_torque]\nunit = "N*m"\ntime = [0.0]\nengine = [100.0]\n' + pressures,
        encoding="utf-8",
    )
    return d, simulate(d, load_scenario(d, path), phases=False, check_models=False)


def test_reference_simulation_energy_balance_with_idle_drag(tmp_path: Path) -> None:
    """Gear 1 of the overdrive box held for 0.5 s at 100 N m: the energy audit closes, and
    its damper dissipation is the side-shaft dampers' ∫ 2 d_ss φ̇² dt plus the idle drag's
    ∫ d Σ ω² dt over the five idle shafts, both summed here from the simulated signals."""
    d, result = _hold(tmp_path, OVERDRIVE, {"C1": 1.5e6, "B2": 1.5e6})
    audit = result.audit
    assert audit.relative_residual < 1e-8
    s, t = result.signals, result.t
    d_ss = d.drivetrain["d_ss"].value
    drag = d.drivetrain["idle_drag"].value
    speeds = sum(s[f"omega_{shaft}"] ** 2 for shaft in idle_shafts(d))
    expected = np.trapezoid(2 * d_ss * s["dphi"] ** 2 + drag * speeds, t)
    assert audit.damper_dissipation == pytest.approx(expected, rel=2e-3)
    drag_part = np.trapezoid(drag * speeds, t)
    assert drag_part > 1e-3 * audit.damper_dissipation  # the drag term is really in it
    # starts at the hand steady state of the idle od set: ω_sun_od = 3/5 ω_in
    assert s["omega_sun_od"][0] == pytest.approx(0.6 * s["omega_in"][0], rel=1e-9)


def test_ratios_cli_marks_idle_shafts(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ratios", str(OVERDRIVE)]) == 0
    out = capsys.readouterr().out
    assert "gear 1: idle: sun_od, ring_od (speed undetermined; model assumes drag 0.002" in out
    assert "gear 4: idle: ring_f, sun, carrier_r (speed undetermined;" in out
    assert main(["ratios", str(OVERDRIVE), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["1"] == pytest.approx(26 / 11) and data["N"] is None
    assert data["_free_shafts"]["1"] == ["sun_od", "ring_od"]
    assert data["_free_shafts"]["4"] == ["ring_f", "sun", "carrier_r"]
    assert main(["ratios", "--json"]) == 0  # the built-in box: no idle shafts, no extra key
    assert "_free_shafts" not in json.loads(capsys.readouterr().out)


def test_model_cli_runs_for_an_idle_gear(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["model", str(OVERDRIVE), "--gear", "4", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    states = [v["name"] for v in data["states"]]
    assert states[0] == "omega_out" and len(states) == 4  # out, one idle shaft, φ, ω_C
    assert states[1] in {"omega_ring_f", "omega_sun", "omega_carrier_r"}
    assert "viscous drag" in data["idle"]
    assert main(["model", str(OVERDRIVE), "--shift", "1-2"]) == 0
    out = capsys.readouterr().out
    assert "omega_sun_od" in out and "assumption: idle shafts" in out


SHIFT_1_2 = """[scenario]
shift = "1-2"
t_end = 1.2
vehicle_speed = { value = 5.0, unit = "m/s", source = "test" }
[input_torque]
unit = "N*m"
time = [0.0]
engine = [100.0]
[pressure.C1]
unit = "Pa"
time = [0.0]
value = [1.5e6]
[pressure.B2]
unit = "Pa"
time = [0.0, 0.3, 0.5]
value = [1.5e6, 1.5e6, 0.0]
[pressure.B1]
unit = "Pa"
time = [0.0, 0.3, 0.7]
value = [0.0, 0.0, 1.2e6]
"""


def test_reduced_models_with_idle_state_follow_the_reference(tmp_path: Path) -> None:
    """A 1-2 power-on shift of the overdrive box through the reference simulation (every
    coordinate a state, every element a friction law): the gear-1 model and the 1-2 shift
    model, each with the idle od speed as a state, integrated from the reference state inside
    their phase, stay within 1e-3 of it (the simulate command's own model check); the energy
    audit closes."""
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description(OVERDRIVE)
    path = tmp_path / "shift.toml"
    path.write_text(SHIFT_1_2, encoding="utf-8")
    result = simulate(d, load_scenario(d, path))
    assert result.audit.relative_residual < 1e-8
    checks = {c.model: c for c in result.checks}
    for name in ("gear_1", "shift_1_2"):
        assert "omega_sun_od" in checks[name].max_abs_error
        assert checks[name].max_relative_error < 1e-3, (name, checks[name])


def test_idle_note_passes_the_ecu_source_scan() -> None:
    """The note lands in emitted C headers, whose sources the ECU check scans for the names
    of dynamic-memory functions (validation/checks/generated_check.py): none may appear in it."""
    import re

    d = load_description(OVERDRIVE)
    note = gear_model(d, "1").metadata["idle"]
    assert "sun_od" in note and "0.002" in note
    assert not re.search(r"\b(malloc|calloc|realloc|free|alloca)\b", note)


def test_run_writes_the_idle_shafts_into_ratios_json(tmp_path: Path) -> None:
    """`gearsym run` writes the same shape `ratios --json` prints, `_free_shafts` included
    (the 2-3 scenario does not fit this box, so the run stops after ratios and observability)."""
    out = tmp_path / "run"
    assert main(["run", str(OVERDRIVE), "--out", str(out)]) == 0
    data = json.loads((out / "ratios.json").read_text())
    # the same idle shafts the text and --json of `ratios` name (test above)
    assert data["_free_shafts"]["1"] == ["sun_od", "ring_od"]
    assert data["_free_shafts"]["4"] == ["ring_f", "sun", "carrier_r"]
    assert data["1"] == pytest.approx(26 / 11)
