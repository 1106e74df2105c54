"""A shift the input torque drives, slower than its target: the 5-4 power-on at 15.9 m/s
(qemu_tasks' operating point: 4th gear turns the input at 195 rad/s), 120 + 30 N·m.

With the off-going element released the input torque moves the on-coming slip no faster than
about 100 rad/s², and the input must rise by about 50 rad/s: more than the calibration's
0.35 s target allows. The controller used to run its target on past its end, whose zero rate
then asked the off-going element to hold the input where it was: it clamped again at 0.44 s
with the input 23 rad/s short of synchronism, and the phase gave up at its limit (twice the
target, 0.7 s after the fill). Now the target waits while the element is released and the
slip behind it (:class:`~gearsym.validation.studies.control.downshift.DownshiftController`,
and the emitted C): the inertia phase ends at synchronism, later than the target and before
the limit; and the emitted task does the same on the host.
"""

from __future__ import annotations

import numpy as np
import pytest
from gearsym.symbolic.control_calibration import TIMEOUT_FACTOR
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks import qemu_control, qemu_tasks
from gearsym.validation.checks.control_c import emit_task_sources

from tests.test_control_c import check_task_on_host
from tests.test_cortex_m4_qemu import GENERATED_C

SHIFT = "5-4"


@pytest.fixture(scope="module")
def case():
    d = load_description()
    point = qemu_tasks.generic_point(d, SHIFT, "power-on")
    return d, qemu_control.control_case(d, kind="power-on", shift=SHIFT, point=point)


def test_the_inertia_phase_ends_at_synchronism_after_its_target(case):
    d, c = case
    target = d.control.si("shift", "inertia_phase")
    phases = c.phases
    inertia = phases.count("inertia") * 0.01
    assert "done" in phases
    # slower than the target (the input torque cannot do it in 0.35 s) ...
    assert inertia > target + 0.05
    # ... but at synchronism, not at the limit
    assert inertia < TIMEOUT_FACTOR * target - 0.05
    # the off-going element is not clamped again while the input is short of synchronism:
    # its command does not rise by more than a bar over the inertia phase's first 0.4 s
    at = [i for i, p in enumerate(phases) if p == "inertia"]
    off = c.commands[at[0] : at[0] + 40, 0]
    assert np.max(off - np.minimum.accumulate(off)) < 1.0e5


def test_the_emitted_task_does_the_same(case, tmp_path):
    d, c = case
    c_dir = emit_task_sources(d, SHIFT, tmp_path / "c", GENERATED_C)
    phases = check_task_on_host(c_dir, c, tmp_path / "host")
    assert phases.count("inertia") == c.phases.count("inertia")
