"""Every adjacent shift's TCU task on the emulated Cortex-M4F
(:mod:`gearsym.validation.checks.qemu_tasks`): its operating points, the shifts it runs, what
it counts as unfit, its one-line errors, and (slow tier: QEMU) one shift run end to end.

Expected values: the shipped scenarios' speeds (scenario_2_3.toml 8 m/s, scenario_3_4.toml
11.5 m/s, both chosen by hand), the thesis' gear table (adjacent forward gears 1 to 9) and the
closed form r_dyn ω_ref / (i_D i) with the thesis' 8th-gear ratio 0.717 (SPEC gear table);
phase sequences written by hand.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks import qemu_m4, qemu_tasks

from tests.test_cortex_m4_qemu import require_qemu_tools

GENERATED_C = Path(__file__).resolve().parents[1] / "generated" / "c"


def test_the_generic_point_puts_the_lower_gear_where_the_shipped_scenarios_do():
    d = load_description()
    for shift, shipped in (("2-3", 8.0), ("3-2", 8.0), ("3-4", 11.5), ("4-3", 11.5)):
        point = qemu_tasks.generic_point(d, shift, "power-on")
        assert abs(point.vehicle_speed - shipped) / shipped < 5e-3, (shift, point)
        assert (point.engine, point.e_machine) == (120.0, 30.0)
    # 8-9: the lower gear is 8th (i = 0.717, the thesis' gear table as SPEC.md prints it, to
    # its three digits), r_dyn 0.3287 m, i_D 2.469 (the description)
    point = qemu_tasks.generic_point(d, "8-9", "coast")
    assert point.vehicle_speed == pytest.approx(195.0 * 0.3287 / (2.469 * 0.717), rel=1e-3)
    assert (point.engine, point.e_machine) == (-20.0, -20.0)


def test_every_adjacent_shift_runs_up_and_down():
    expected = []
    for a in range(1, 9):
        expected += [f"{a}-{a + 1}", f"{a + 1}-{a}"]
    assert qemu_tasks.task_shifts(load_description()) == expected


def test_a_give_up_and_its_tie_are_told_from_the_phases():
    tick, limit = 0.01, 0.05  # the inertia phase may last 5 ticks
    fill, inertia, torque = ("fill",) * 2, ("inertia",), ("torque",) * 3
    gave = fill + inertia * 5 + torque  # ran to its limit, left it at tick 7
    # the task a tick later: a tie at the give-up
    late = fill + inertia * 6 + torque[:2]
    assert qemu_tasks.inertia_give_up(gave, late, limit, tick) == (True, True)
    # the same phases: gave up, no tie to excuse
    assert qemu_tasks.inertia_give_up(gave, gave, limit, tick) == (True, False)
    # the task apart elsewhere (in the fill): not the give-up's tie
    early = ("fill", "inertia") + inertia * 5 + torque
    assert qemu_tasks.inertia_give_up(gave, early, limit, tick) == (True, False)
    # synchronism before the limit (4 ticks), the task a tick later: no give-up, no excuse
    synced = fill + inertia * 4 + torque + ("torque",)
    lagging = fill + inertia * 5 + torque
    assert qemu_tasks.inertia_give_up(synced, lagging, limit, tick) == (False, False)


def _kind(**changes) -> dict:
    row = {
        "instructions_max": 9000,
        "failed_calls": 0,
        "phases_agree": True,
        "lockup_end_ties": 0,
        "apart_from_give_up": False,
        "completed": True,
        "inertia_gave_up": False,
    }
    return row | changes


def test_what_makes_a_task_unfit():
    budget = 20_000
    assert qemu_tasks.task_failures(_kind(), budget) == []
    assert qemu_tasks.task_failures(_kind(instructions_max=20_000), budget) == ["over budget"]
    assert qemu_tasks.task_failures(_kind(failed_calls=2), budget) == ["2 calls failed"]
    assert qemu_tasks.task_failures(_kind(completed=False), budget) == ["not locked up in 1.2 s"]
    # phases apart: a failure unless at a tie (the lock-up's hold end, the inertia's give-up)
    apart = _kind(phases_agree=False, lockup_end_ties=None)
    assert qemu_tasks.task_failures(apart, budget) == ["phases differ"]
    assert qemu_tasks.task_failures(apart | {"lockup_end_ties": 1}, budget) == []
    gave_up = apart | {"apart_from_give_up": True, "inertia_gave_up": True}
    assert qemu_tasks.task_failures(gave_up, budget) == []
    verdict = qemu_tasks._verdict(gave_up, budget)
    assert "gave up at its limit" in verdict and "a tick later" in verdict
    assert qemu_tasks._verdict(_kind(), budget) == "fits"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--shifts", "1-3"], "--shifts: '1-3' is not an adjacent single-swap shift"),
        (["--shifts", "2-3", "--c-dir", "nowhere"], "--c-dir: nowhere: no gearsym_mu_map.c"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(args, message, tmp_path, capsys):
    if message.startswith("--c-dir") and qemu_m4.missing_tools():
        pytest.skip("the tools are checked before --c-dir")
    out = tmp_path / "tasks"
    assert qemu_tasks.main(["--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.slow
def test_one_shift_end_to_end_fits_and_its_table_is_its_json(tmp_path):
    """The 8-9 (its EKF measures shaft 8, which both gears hold still) on the board: within the
    budget (it took 19 034 instructions before a zero row of H got the constant-H update),
    every call succeeds, the same phases as the Python controller along the power-on upshift,
    and the table is its JSON rendered."""
    require_qemu_tools()
    out = tmp_path / "tcu_tasks"
    argv = ["--out", str(out), "--shifts", "8-9", "--c-dir", str(GENERATED_C)]
    assert qemu_tasks.main(argv) == 0
    data = json.loads((out / "tcu_tasks.json").read_text(encoding="utf-8"))
    (row,) = data["shifts"]
    assert row["shift"] == "8-9" and [k["kind"] for k in row["kinds"]] == ["power-on", "coast"]
    for kind in row["kinds"]:
        assert kind["instructions_max"] < qemu_tasks.qemu_control.BUDGET
        assert kind["failed_calls"] == 0 and kind["calls"] > 100
    assert row["kinds"][0]["phases_agree"]
    command = " ".join([qemu_tasks.COMMAND, *argv])
    assert (out / "tcu_tasks.md").read_text(encoding="utf-8") == qemu_tasks.tasks_markdown(
        data, command
    )
