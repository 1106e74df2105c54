"""The TCU task of a shift whose EKF measures a speed beside the input, output and wheel speeds
(the 3-4: the EKF also measures shaft 8): its inputs carry that speed (``omega_8``), its y is
built in the EKF's output order, and along the Python controller's closed-loop power-on 3-4 on
the calibration's vehicle it gives the Python controller's commands and its filter follows the
shift (:func:`tests.test_control_c.check_filter_tracking`). Emitted into a temporary folder:
``generated/`` holds the default shift's task only."""

from __future__ import annotations

import pytest
from gearsym.symbolic.codegen.control import extra_speeds, task_measurements
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks import qemu_control
from gearsym.validation.checks.control_c import emit_task_sources

from tests.test_control_c import GENERATED_C, check_task_on_host

SHIFT = "3-4"


@pytest.fixture(scope="module")
def d():  # noqa: ANN201
    return load_description(None)


def test_the_task_hands_its_ekf_every_speed_it_measures(d) -> None:  # noqa: ANN001
    measurements = task_measurements(d, hybrid_shift(d, SHIFT))
    assert [c for _, c in measurements] == [
        "in->control.omega_in",
        "in->control.omega_out",
        "in->omega_8",
        "in->omega_wheel",
    ]
    assert extra_speeds(measurements) == ("omega_8",)


def test_the_3_4_task_on_the_host_gives_the_python_commands_and_follows(d, tmp_path) -> None:  # noqa: ANN001
    c_dir = emit_task_sources(d, SHIFT, tmp_path / "c", GENERATED_C)
    header = (c_dir / "gearsym_control_3_4.h").read_text(encoding="utf-8")
    assert "gearsym_real omega_8;" in header
    case = qemu_control.control_case(d, kind="power-on", shift=SHIFT)
    assert case.extra == ("omega_8",) and case.inputs.shape[1] == 6
    check_task_on_host(c_dir, case, tmp_path / "build")
