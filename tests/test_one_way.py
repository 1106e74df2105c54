"""One-way clutches (freewheels), ``kind = "one_way"``: description, gear table, reference
simulation, shift models.

Expected values come from hand derivations (see ``tests/data/simpson_3speed_one_way.toml``'s
header): the Simpson ratios with k_f = 11/5, k_r = 2, and the direction the rear carrier would
turn in drive and in coast.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import gear_ratio

from gearsym.cli import main

DATA = Path(__file__).parent / "data"
BOX = DATA / "simpson_3speed_one_way.toml"


def _with_element(tmp_path: Path, lines: str) -> Path:
    """The one-way Simpson box with F1's table replaced by ``lines``."""
    text = BOX.read_text(encoding="utf-8")
    start = text.index('[[shift_element]]\nname = "F1"')
    end = text.index("[gear_table]")
    path = tmp_path / "box.toml"
    path.write_text(text[:start] + "[[shift_element]]\n" + lines + "\n" + text[end:], "utf-8")
    return path


def test_one_way_parsed() -> None:
    d = load_description(BOX)
    f1 = d.element("F1")
    assert f1.one_way and f1.kind == "one_way"
    assert f1.shafts == ("carrier_r",) and f1.a is None and f1.b == "carrier_r"
    assert f1.locks == 1
    assert f1.n_disc is None
    # a friction element keeps locks = 0 and is no one-way clutch
    assert d.element("B2").locks == 0 and not d.element("B2").one_way


def test_one_way_between_two_shafts(tmp_path: Path) -> None:
    path = _with_element(
        tmp_path, 'name = "F1"\nkind = "one_way"\nshafts = ["in", "sun"]\nlocks = "negative"\n'
    )
    text = path.read_text(encoding="utf-8").replace(
        'closed = ["C1", "F1"]', 'closed = ["C1", "B2"]'
    )
    path.write_text(text, encoding="utf-8")
    f1 = load_description(path).element("F1")
    assert (f1.a, f1.b, f1.locks) == ("in", "sun", -1)


def test_gear_with_locked_one_way_has_the_hand_ratio() -> None:
    """Table 2.1 style: gear 1 (C1 + F1 locked) has the ratio of 1M (C1 + B2), both
    (1 + k_f + k_r)/k_f = (1 + 11/5 + 2)/(11/5) = 26/11 by hand."""
    d = load_description(BOX)
    for gear in ("1", "1M"):
        assert abs(float(gear_ratio(d, d.gear(gear)).ratio) - 26 / 11) < 1e-12


def test_ratios_command_accepts_the_one_way_box(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ratios", str(BOX), "--no-cache"]) == 0
    out = capsys.readouterr().out
    assert "C1 F1" in out and "2.3636" in out


@pytest.mark.parametrize(
    ("lines", "key", "reason"),
    [
        (
            'name = "F1"\nkind = "one_way"\nshaft = "carrier_r"\n',
            'shift_element[name="F1"].locks',
            "missing required key",
        ),
        (
            'name = "F1"\nkind = "one_way"\nshaft = "carrier_r"\nlocks = "forward"\n',
            'shift_element[name="F1"].locks',
            "expected 'positive' or 'negative'",
        ),
        (
            'name = "F1"\nkind = "one_way"\nshafts = ["in"]\nlocks = "positive"\n',
            'shift_element[name="F1"].shafts',
            "exactly two shafts",
        ),
        (
            'name = "F1"\nkind = "one_way"\nshafts = ["sun", "sun"]\nlocks = "positive"\n',
            'shift_element[name="F1"].shafts',
            "two different shafts",
        ),
        (
            'name = "F1"\nkind = "one_way"\nshafts = ["in", "sun"]\nshaft = "sun"\n'
            'locks = "positive"\n',
            'shift_element[name="F1"].shaft',
            "not both",
        ),
        (
            'name = "F1"\nkind = "one_way"\nshaft = "carrier_r"\nlocks = "positive"\nn_disc = 4\n',
            'shift_element[name="F1"].n_disc',
            "no discs or piston",
        ),
        (
            'name = "F1"\nkind = "one_way"\nshaft = "nowhere"\nlocks = "positive"\n',
            'shift_element[name="F1"].shaft',
            "unknown shaft",
        ),
        (
            'name = "F1"\nkind = "brake"\nshaft = "carrier_r"\nlocks = "positive"\n',
            'shift_element[name="F1"].locks',
            "only a one-way clutch",
        ),
        (
            'name = "F1"\nkind = "freewheel"\nshaft = "carrier_r"\nlocks = "positive"\n',
            'shift_element[name="F1"].kind',
            "'one_way'",
        ),
        (
            'name = "F1"\nkind = "one_way"\nshaft = "carrier_r"\nlocks = "positive"\nspeed = 1\n',
            'shift_element[name="F1"].speed',
            "",
        ),
    ],
)
def test_bad_one_way_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], lines: str, key: str, reason: str
) -> None:
    path = _with_element(tmp_path, lines)
    assert main(["ratios", str(path), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith(f"gearsym: {path}: {key}: "), err
    assert reason in err, err


def test_parse_from_string_needs_no_file() -> None:
    text = BOX.read_text(encoding="utf-8")
    assert parse_description(text).element("F1").locks == 1


# ------------------------------------------------------------------ reference simulation


def _hold_gear_1(tmp_path: Path, torque: float) -> tuple[object, object]:
    """Gear 1 (C1 pressed, F1 by itself) held for 0.5 s at a constant input torque."""
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description(BOX)
    path = tmp_path / f"hold_{torque:g}.toml"
    path.write_text(
        '[scenario]\nshift = "1-2"\nt_end = 0.5\n'
        'vehicle_speed = { value = 5.0, unit = "m/s", source = "test" }\n'
        f'[input_torque]\nunit = "N*m"\ntime = [0.0]\nengine = [{torque}]\n'
        '[pressure.C1]\nunit = "Pa"\ntime = [0.0]\nvalue = [1.5e6]\n',
        encoding="utf-8",
    )
    return d, simulate(d, load_scenario(d, path), phases=False, check_models=False)


def test_one_way_locks_in_drive(tmp_path: Path) -> None:
    """Drive (T_In = +100 N m): the reaction would turn the rear carrier backwards (slip
    0 − ω_carrier > 0, the blocked sign), so F1 locks: its slip stays ~0 (the wind-up z ~
    T/σ0 ~ 7e-4 rad is all the travel) and it carries the quasi-static torque of the file's
    header, (i_1 − 1) T_In = 15/11 · 100 N m, within the few per cent the accelerating
    gearbox inertias take; the audit closes."""
    import numpy as np

    _, result = _hold_gear_1(tmp_path, 100.0)
    s = result.signals
    late = result.t > 0.05  # after the wind-up has taken the load
    # it starts unwound (z = 0): the take-up is a wind-up of T/σ0 ~ 7e-4 rad, no more travel
    assert np.max(s["z_F1"]) < 1e-3
    # locked: in contact all along (z > 0), the slip only the rate of the elastic wind-up as
    # the driveline oscillates, below 1e-3 of the input speed
    assert np.all(s["z_F1"][late] > 0)
    assert np.all(np.abs(s["slip_F1"][late]) < 1e-3 * s["omega_in"][late])
    assert np.all(s["T_F1"][late] > 0)  # the blocked sign
    # once the driveline shuffle the torque step excites has decayed (side shafts, d_ss)
    settled = result.t > 0.3
    assert np.all(np.abs(s["T_F1"][settled] / (15 / 11 * 100.0) - 1) < 0.05)
    assert result.audit.relative_residual < 1e-6


def test_one_way_overruns_in_coast(tmp_path: Path) -> None:
    """Coast (T_In = −40 N m, engine braking): the rear carrier turns forwards, F1's slip
    takes the free (negative) sign and grows, it carries no torque (no drag modelled), so
    D1 gives no engine braking; the audit closes."""
    import numpy as np

    _, result = _hold_gear_1(tmp_path, -40.0)
    s = result.signals
    late = result.t > 0.01
    assert np.all(s["slip_F1"][late] < 0)
    assert np.all(np.diff(s["slip_F1"][late]) < 0)  # overrunning faster and faster
    assert np.max(np.abs(s["T_F1"])) == 0.0
    assert result.audit.relative_residual < 1e-6


def test_one_way_law_is_unilateral_and_passive() -> None:
    """friction.one_way_num against its definition at hand-picked points: locks = +1,
    stiffness 1000, damping 10. In contact (z = 1e-3, dw = 0.01): T = 1 + 0.1; opening fast
    (dw = −1): 1 − 10 < 0, clipped to 0; free (z = 0, dw = −1): no torque, no wind-up."""
    from gearsym.symbolic.friction import one_way_num

    zdot, t = one_way_num(1e-3, 0.01, 1, 1000.0, 10.0)
    assert (zdot, t) == pytest.approx((0.01, 1.1))
    assert one_way_num(1e-3, -1.0, 1, 1000.0, 10.0) == pytest.approx((-1.0, 0.0))
    assert one_way_num(0.0, -1.0, 1, 1000.0, 10.0) == (0.0, 0.0)
    # locks = −1 mirrors: blocked slip is negative, torque negative
    assert one_way_num(1e-3, -0.01, -1, 1000.0, 10.0) == pytest.approx((0.01, -1.1))


def test_pressure_on_a_one_way_clutch_is_refused(tmp_path: Path) -> None:
    from gearsym.symbolic.errors import GearsymError
    from gearsym.validation.sim.scenario import load_scenario

    d = load_description(BOX)
    path = tmp_path / "s.toml"
    path.write_text(
        '[scenario]\nshift = "1-2"\nt_end = 0.5\n'
        'vehicle_speed = { value = 5.0, unit = "m/s", source = "test" }\n'
        '[input_torque]\nunit = "N*m"\ntime = [0.0]\nengine = [10.0]\n'
        '[pressure.F1]\nunit = "Pa"\ntime = [0.0]\nvalue = [1.0e6]\n',
        encoding="utf-8",
    )
    with pytest.raises(GearsymError, match="one-way clutch"):
        load_scenario(d, path)


# ------------------------------------------------------------------ shift models, emitted C


def test_gear_model_locks_the_one_way_and_states_its_validity() -> None:
    """Gear 1's model has F1 locked (one gearbox state, like 1M with B2 locked: the same
    constraint ω_carrier_r = 0), and its metadata, which the emitted C header prints, says
    the model holds only while T_F1 > 0 (the blocking sign); 1M's has no such condition."""
    from gearsym.symbolic.drivetrain import drivetrain_model

    d = load_description(BOX)
    models = {
        g: drivetrain_model(d, f"gear_{g}", locked=tuple(d.gear(g).closed), keep=("out",))
        for g in ("1", "1M")
    }
    assert [v.name for v in models["1"].states] == ["omega_out", "phi", "omega_C"]
    assert models["1"].rhs.equals(models["1M"].rhs)  # same constraint, same dynamics
    note = models["1"].metadata["one_way"]
    assert "T_F1 > 0" in note and "F1 open" in note and "-omega_carrier_r" in note
    assert "one_way" not in models["1M"].metadata


def test_emitted_linear_gears_header_documents_the_switch(tmp_path: Path) -> None:
    """The emitted C of the one-way box says, in the header of the gears' linear forms (gear 1
    locks F1), that a system locking a freewheel holds only while it carries torque of its
    blocking sign and that the switch is the caller's."""
    out = tmp_path / "gen"
    assert main(["generate", str(BOX), "--out", str(out)]) == 0
    header = (out / "c" / "gearsym_linear_gears.h").read_text(encoding="utf-8")
    assert "one-way clutch (F1)" in header and "the caller switches" in header
