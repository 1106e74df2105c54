"""The emitted shift controller of a downshift (3-2, B05 off-going, K38 on-coming) against the
Python controller, as ``tests/test_control_c.py`` checks the default 2-3 upshift: emitted here
with its EKF into a temporary folder (``generated/`` holds the default shift's only), compiled
strictly in double and float, and fed the Python loop's speeds and torque every tick.

A power-on downshift is the shift the input torque drives (the engine speeds the input up once
the off-going element lets go: :class:`~gearsym.validation.studies.control.downshift.
DownshiftController`'s order, inertia phase first); a coast downshift needs the on-coming
element to pull the input up against the drag (:class:`~gearsym.validation.studies.control.
controller.ShiftController`'s order, torque phase first, every direction from the model)."""

from __future__ import annotations

import pytest
from gearsym.symbolic.control_calibration import HOLD_LINE, TO_LINE
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks import qemu_control
from gearsym.validation.checks.control_c import (
    CShiftController,
    build_control_library,
    emit_task_sources,
)
from gearsym.validation.sim.actuator import ClutchActuator
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.studies.control.closed_loop import ClosedLoopShift
from gearsym.validation.studies.control.downshift import DownshiftController
from gearsym.validation.studies.control.study import make_controller

from tests.test_control_c import (
    FLOAT_TOLERANCE,
    GENERATED_C,
    KNOWLEDGE,
    Twin,
    _c_knowledge,
    _differences,
    _truth,
    check_double_build,
    check_same_loop,
    check_task_on_host,
)

SHIFT = "3-2"
#: the phase order of each kind: power on, the input torque drives the downshift (inertia
#: phase first); coast, the on-coming element pulls the input up (torque phase first)
ORDER = {"power_on": ("inertia", "torque"), "coast": ("torque", "inertia")}


@pytest.fixture(scope="module")
def d():  # noqa: ANN201
    return load_description(None)


@pytest.fixture(scope="module")
def emitted(d, tmp_path_factory):  # noqa: ANN001, ANN201
    """The 3-2 controller, its EKF and the μ map, and their double and float builds."""
    out = emit_task_sources(d, SHIFT, tmp_path_factory.mktemp("control_3_2"), GENERATED_C)
    builds = {single: build_control_library(out, SHIFT, out / "build", single) for single in (0, 1)}
    return out / "gearsym_control_3_2.h", builds


def _run(d, emitted, kind: str, single: bool, drive: str, tmp_path_factory):  # noqa: ANN001, ANN202
    header, builds = emitted
    spec = shift_spec(d, SHIFT)
    # the shipped power-on 3-2, or at its speed with drag instead of drive torque (engine
    # −20 N·m, the machine recuperating −20 N·m): a coast downshift
    point = qemu_control.operating_point(d, SHIFT, kind.replace("_", "-"))
    plant = ClosedLoopShift(_truth(d), SHIFT, point.vehicle_speed, {"K38": 0.95, "B05": 1.05})
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, SHIFT))
    python = make_controller(d, model, KNOWLEDGE, point.torque)
    assert isinstance(python, DownshiftController) == (kind == "power_on")
    c = CShiftController(
        builds[int(single)],
        header,
        SHIFT,
        spec.off_going,
        spec.on_coming,
        _c_knowledge(python),
        single=single,
    )
    twin = Twin(python, c, drive)
    nominal = ClutchActuator.from_calibration(d.control)
    actuators = {e: nominal for e in spec.swapping}
    result = plant.run(twin, point.torque, point.torque, actuators, actuators, t_end=1.5)
    return twin, result


_LOOPS: dict[str, tuple] = {}


def _python_loops(d, emitted, kind: str, tmp_path_factory) -> tuple:  # noqa: ANN001
    """The Python controller closing the loop, the double and the float builds riding along
    (each kind simulated once per module)."""
    if kind not in _LOOPS:
        _LOOPS[kind] = tuple(
            _run(d, emitted, kind, single, "python", tmp_path_factory) for single in (False, True)
        )
    return _LOOPS[kind]


@pytest.fixture(scope="module", params=sorted(ORDER))
def python_loop(request, d, emitted, tmp_path_factory):  # noqa: ANN001, ANN201
    return request.param, _python_loops(d, emitted, request.param, tmp_path_factory)


def test_the_downshift_controller_is_emitted_as_one(d, emitted) -> None:  # noqa: ANN001
    """The header says what it is: a downshift whose power-on order is the driven one."""
    header, _ = emitted
    text = header.read_text(encoding="utf-8")
    assert "The TCU's downshift 3-2 (B05 off-going, K38 on-coming)" in text
    source = header.with_suffix(".c").read_text(encoding="utf-8")
    assert "if (in->torque > GEARSYM_LIT(0.0)) {" in source
    assert "if (in->torque < GEARSYM_LIT(0.0)) {" not in source


def test_double_build_gives_the_python_commands_tick_by_tick(python_loop) -> None:  # noqa: ANN001
    """Every phase, in the kind's order, tick by tick as the Python controller gives it."""
    kind, ((twin, result), _) = python_loop
    check_double_build(twin, result, ORDER[kind], f"3-2 {kind}")


def test_float_build_gives_the_python_commands_within_float_rounding(python_loop) -> None:  # noqa: ANN001
    """The same phase every tick but where the lock-up's hold ends exactly on a tick: there
    the time since lock-up equals TO_LINE + HOLD_LINE to rounding, and float and double may
    round either side of it (the command is line pressure either way)."""
    kind, (_, (twin, _)) = python_loop
    ties = [t for t, a, b, _, _ in twin.ticks if a != b]
    end = TO_LINE + HOLD_LINE
    assert all(abs(t - twin.python._t_lock - end) < 1e-6 for t in ties)
    worst = _differences(twin).max()
    print(f"3-2 {kind}, float build: largest command difference {worst:.3g} Pa")
    assert worst <= FLOAT_TOLERANCE


@pytest.mark.parametrize("kind", sorted(ORDER))
def test_the_float_c_controller_closes_a_downshift_like_the_python_one(
    d, emitted, kind, tmp_path_factory
) -> None:  # noqa: ANN001
    """The C controller (float) drives the plant: the plant's events in the Python loop's
    order, each within 1 ms of it, both elements' slips within 0.1 rad/s of it, and the
    on-coming element locked."""
    (_, reference), _ = _python_loops(d, emitted, kind, tmp_path_factory)
    twin, result = _run(d, emitted, kind, True, "c", tmp_path_factory)
    check_same_loop(twin, result, reference, "K38", f"C 3-2 {kind} loop")


@pytest.mark.parametrize("kind", ["power-on", "coast"])
def test_the_downshift_tcu_task_on_the_host_gives_the_python_controllers_commands(
    d, emitted, tmp_path, kind
) -> None:  # noqa: ANN001
    """The whole 3-2 task (EKF and controller, float, the Cortex-M4F driver built for the
    host) along the Python controller's closed-loop 3-2 on the calibration's vehicle, as
    tests/test_control_c.py checks the 2-3's: its commands within FLOAT_TOLERANCE, its phase
    at every tick but a lock-up hold's float tie, its EKF following the shift."""
    header, _ = emitted
    case = qemu_control.control_case(d, kind=kind, shift=SHIFT)
    phases = check_task_on_host(header.parent, case, tmp_path)
    assert phases.index("inertia") < phases.index("lockup")
