"""Dog elements (``kind = "dog"``, form-locking, issue 30 part C): description, gear table,
shift models.

The test box ``tests/data/dog_9speed.toml`` is the thesis' 9-speed with B06 a dog brake and K27
a dog clutch (its header states the sources). Expected ratios are the published ones of
Table 2.1 (the Mercedes-Benz 9G-Tronic's) at their three decimals; a dog element closes a gear
like any element, so the exact ratios equal those of the box with friction elements there.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from gearsym.symbolic.description import DOG_ENGAGE_SLIP_DEFAULT, DOG_RELEASE_TORQUE_DEFAULT
from gearsym.symbolic.drivetrain import shift_model
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.ratios import gear_ratio

from gearsym.cli import main
from tests.test_ratios import TABLE_2_1

DATA = Path(__file__).parent / "data"
BOX = DATA / "dog_9speed.toml"

#: Table 2.1 of the thesis (the published ratios), transcribed once in test_ratios.py.
PUBLISHED = {gear: ratio for gear, ratio in TABLE_2_1.items() if ratio is not None}


def _with_b06(tmp_path: Path, lines: str) -> Path:
    """The dog box with B06's table replaced by ``lines``."""
    text = BOX.read_text(encoding="utf-8")
    start = text.index('[[shift_element]]\nname = "B06"')
    end = text.index("[[shift_element]]", start + 10)
    path = tmp_path / "box.toml"
    path.write_text(text[:start] + "[[shift_element]]\n" + lines + "\n" + text[end:], "utf-8")
    return path


def test_dog_elements_parsed() -> None:
    d = load_description(BOX)
    b06, k27 = d.element("B06"), d.element("K27")
    assert b06.dog and b06.kind == "dog" and not b06.one_way
    assert (b06.a, b06.b) == (None, "6")  # a dog brake
    assert (k27.a, k27.b) == ("2", "7")  # a dog clutch
    assert b06.engage_slip is not None and b06.engage_slip.value == 3.0
    assert b06.release_torque is not None and b06.release_torque.value == 5.0
    # K27 gives neither key: the stated defaults
    assert k27.engage_slip is not None and k27.engage_slip.value == DOG_ENGAGE_SLIP_DEFAULT
    assert k27.release_torque is not None
    assert k27.release_torque.value == DOG_RELEASE_TORQUE_DEFAULT
    assert "default" in k27.engage_slip.source
    assert b06.n_disc is None and b06.a_piston is None
    assert not d.element("K81").dog


def test_published_ratios(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ratios", str(BOX), "--json", "--no-cache"]) == 0
    ratios = json.loads(capsys.readouterr().out)
    for gear, value in PUBLISHED.items():
        assert round(ratios[gear], 3) == value, gear
    # a dog element closes a gear like a friction element: the same exact ratios
    d, built_in = load_description(BOX), load_description(None)
    for gear in PUBLISHED:
        assert gear_ratio(d, d.gear(gear)).ratio == gear_ratio(built_in, built_in.gear(gear)).ratio
    # 6th closes the three clutches K81, K38 and the dog K27: every set turns as a block, 1:1
    assert gear_ratio(d, d.gear("6")).ratio == 1


@pytest.mark.parametrize(
    ("lines", "key", "reason"),
    [
        (
            'name = "B06"\nkind = "dog"\nshaft = "6"\nn_disc = 6\n',
            'shift_element[name="B06"].n_disc',
            "form-locking",
        ),
        (
            'name = "B06"\nkind = "dog"\nshaft = "6"\n'
            'a_piston = { value = 0.008, unit = "m^2", source = "x" }\n',
            'shift_element[name="B06"].a_piston',
            "no friction discs or piston",
        ),
        (
            'name = "B06"\nkind = "dog"\nshaft = "6"\n'
            'r_m = { value = 0.1, unit = "m", source = "x" }\n',
            'shift_element[name="B06"].r_m',
            "no sliding friction",
        ),
        ('name = "B06"\nkind = "dog"\n', 'shift_element[name="B06"].shafts', "missing"),
        (
            'name = "B06"\nkind = "dog"\nshaft = "6"\nlocks = "positive"\n',
            'shift_element[name="B06"].locks',
            "only a one-way clutch",
        ),
        (
            'name = "B06"\nkind = "dog"\nshafts = ["6", "6"]\n',
            'shift_element[name="B06"].shafts',
            "two different shafts",
        ),
        (
            'name = "B06"\nkind = "dog"\nshaft = "6"\n'
            'engage_slip = { value = 3.0, unit = "rpm", source = "x" }\n',
            'shift_element[name="B06"].engage_slip.unit',
            "expected 'rad/s'",
        ),
        (
            'name = "B06"\nkind = "dog"\nshaft = "6"\n'
            'release_torque = { value = -1.0, unit = "N*m", source = "x" }\n',
            'shift_element[name="B06"].release_torque.value',
            "must be positive",
        ),
        (
            'name = "B06"\nkind = "brake"\nshaft = "6"\n'
            'engage_slip = { value = 3.0, unit = "rad/s", source = "x" }\n',
            'shift_element[name="B06"].engage_slip',
            'only a dog element (kind = "dog")',
        ),
        (
            'name = "B06"\nkind = "dogg"\nshaft = "6"\n',
            'shift_element[name="B06"].kind',
            "'one_way' or 'dog'",
        ),
    ],
)
def test_bad_dog_elements_one_line(tmp_path: Path, lines: str, key: str, reason: str) -> None:
    path = _with_b06(tmp_path, lines)
    with pytest.raises(GearsymError) as info:
        load_description(path)
    message = str(info.value)
    assert "\n" not in message
    assert key in message and reason in message, message


def test_cli_refuses_a_dog_with_friction_data_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _with_b06(tmp_path, 'name = "B06"\nkind = "dog"\nshaft = "6"\nn_disc = 6\n')
    assert main(["ratios", str(path), "--no-cache"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "n_disc" in err


def test_shift_models_of_dog_shifts() -> None:
    """4-5 swaps the dog B06 (off) for K81 (on), 3-4 K81 (off) for the dog K27 (on). The
    torque form keeps T of the dog (zero unless engaged: the note says so); the μ form has the
    dog open (the shift model's premise: neither swapping element locked, and a dog cannot
    slip loaded): no μ and no F_N of it, only the friction element's."""
    d = load_description(BOX)
    for shift, dog, friction in (("4-5", "B06", "81"), ("3-4", "K27", "81")):
        torque = shift_model(d, shift)
        assert [v.name for v in torque.inputs] == ["T_In", *sorted_torques(d, shift)]
        assert "dog element " + dog in torque.metadata["dog"]
        mu_form = shift_model(d, shift, friction_inputs=True)
        assert [v.name for v in mu_form.inputs] == ["T_In", f"F_N{friction}"]
        names = [v.name for v in mu_form.parameters]
        assert f"mu_{friction}" in names and not any(dog[1:] in n for n in names if "mu" in n)
        assert "absent here" in mu_form.metadata["dog"]
        assert "overrunning" not in mu_form.metadata
    # a shift without a dog has no note
    assert "dog" not in shift_model(d, "2-3", friction_inputs=True).metadata


def sorted_torques(d: object, shift: str) -> list[str]:
    from gearsym.symbolic.shifts import shift_spec

    spec = shift_spec(d, shift)  # type: ignore[arg-type]
    return [f"T_{spec.off_going}", f"T_{spec.on_coming}"]


def test_stick_diagram_draws_dogs_with_their_own_symbol(tmp_path: Path) -> None:
    """A dog element is drawn as a claw coupling: interlocking teeth between its two plates
    (three up, two down, overlapping: engaged); friction elements keep plain plates."""
    from gearsym.validation.drawing.geometry import stick_diagram

    stick = stick_diagram(load_description(BOX))
    owners = {t.owner for t in stick.teeth}
    assert owners == {"B06", "K27"}
    for name in owners:
        teeth = [t for t in stick.teeth if t.owner == name]
        assert len(teeth) == 5
        plates = sorted(p.start[1] for p in stick.plates if p.owner == name)
        low, high = plates[0], plates[-1]
        for t in teeth:
            ys = sorted((t.start[1], t.end[1]))
            assert low - 1e-12 <= ys[0] and ys[1] <= high + 1e-12
            assert t.start[0] == t.end[0]  # vertical
        rising = [t for t in teeth if t.start[1] == low]
        hanging = [t for t in teeth if t.start[1] == high]
        assert len(rising) == 3 and len(hanging) == 2
        assert min(t.end[1] for t in rising) > max(t.end[1] for t in hanging)  # they overlap
    assert stick_diagram(load_description(None)).teeth == ()
    out = tmp_path / "stick.svg"
    assert main(["draw", str(BOX), "--what", "stick", "--out", str(out)]) == 0
    assert out.stat().st_size > 0
