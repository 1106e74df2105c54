"""The emitted task's filter at the off-going element's break-away (the power-on 4-3 at
qemu_tasks' operating point: 3rd gear turns the input at 195 rad/s, 120 + 30 N·m).

The plant's μ is the map's, 0.106-0.112 at zero slip; the filter's μ state is a constant (the
calibration's 0.12), frozen while the element sticks, and its break-away test compares the
sticking torque with the capacity it gives. Told 0.12, the filter held the element stuck for
seven ticks after the plant's broke away: 5.6 rad/s behind the measured input speed, 3.7 % off
in mass. The task now sets that μ, until the element first slides, to the TCU's map at zero
slip at the element's force (the controller's ``mu_off``): the filter follows the shift
(:func:`tests.test_control_c.check_task_on_host`: speeds within 1 rad/s, mass within 1 %).
"""

from __future__ import annotations

from gearsym.symbolic.loader import load_description
from gearsym.validation.checks import qemu_control, qemu_tasks
from gearsym.validation.checks.control_c import emit_task_sources

from tests.test_control_c import check_task_on_host
from tests.test_cortex_m4_qemu import GENERATED_C

SHIFT = "4-3"


def test_the_filter_follows_the_off_going_elements_break_away(tmp_path):
    d = load_description()
    point = qemu_tasks.generic_point(d, SHIFT, "power-on")
    case = qemu_control.control_case(d, kind="power-on", shift=SHIFT, point=point)
    c_dir = emit_task_sources(d, SHIFT, tmp_path / "c", GENERATED_C)
    phases = check_task_on_host(c_dir, case, tmp_path / "host")
    assert phases.index("inertia") < phases.index("torque")  # the off-going slides first
