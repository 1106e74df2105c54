"""The emitted shift controller (``generated/c/gearsym_control_2_3.c``, issue 29 item 5)
against the Python controller (:class:`~gearsym.validation.studies.control.controller.
ShiftController`) on the closed loop of :mod:`gearsym.validation.studies.control.closed_loop`.

Both controllers get the same measured speeds and commanded torque every tick (the Python one
closes the loop, the C one rides along): the double build gives the same commands to rounding
(its model parts are the same equations in closed form: exact-rational least squares for the
state, the twist solved symbolically instead of a two-point secant, so about 1e-16 relative
apart), the float build within a few float ulps of line pressure. Then the C controller
closes the loop itself, and the shift it makes is the Python controller's.

A vehicle that is not the calibration (heavier, on a grade, μ of both elements off) and a
strategy's knowledge with every field away from its default (valve view, learned offsets,
torque gain) exercise every input of the step. The coast 2-3 upshift (the input torque drives
it: :class:`~gearsym.validation.studies.control.downshift.DownshiftController`'s order) is
checked the same way.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic import naming
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks.control_c import CShiftController, build_control_library
from gearsym.validation.sim.actuator import ClutchActuator
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import load_scenario
from gearsym.validation.studies.control.closed_loop import ClosedLoopShift
from gearsym.validation.studies.control.controller import Knowledge, ShiftController
from gearsym.validation.studies.control.downshift import DownshiftController
from gearsym.validation.studies.control.study import OperatingPoint, make_controller

GENERATED_C = Path(__file__).resolve().parents[1] / "generated" / "c"
#: the coast 2-3 upshift (-40 N*m: the input torque drives the shift, inertia phase first)
COAST = Path(__file__).resolve().parents[1] / "gearsym" / "data" / "scenario_2_3_coast.toml"
HEADER = GENERATED_C / "gearsym_control_2_3.h"
LINE = 1.5e6  # [drive.shift] line_pressure (Pa), checked below
#: float: 32 ulps of line pressure (the ulp of 1.5e6 in float is 0.125 Pa): the commands are
#: sums of a few rounded terms, the PI's integral adds one rounding per tick
FLOAT_TOLERANCE = 32 * 0.125
#: double: 1e-9 of line pressure, far above the 1e-16 relative the two forms differ by
DOUBLE_TOLERANCE = 1e-9 * LINE


@pytest.fixture(scope="module")
def d():  # noqa: ANN201
    return load_description(None)


@pytest.fixture(scope="module")
def libraries(d, tmp_path_factory):  # noqa: ANN001, ANN201
    """The controller, the μ map and the EKF compiled strictly, in double and in float."""
    assert d.drive.si("shift", "line_pressure") == LINE
    out = tmp_path_factory.mktemp("control_c")
    return {
        single: build_control_library(GENERATED_C, "2-3", out, single) for single in (False, True)
    }


def _truth(d):  # noqa: ANN001, ANN202
    vehicle = dict(d.vehicle)
    vehicle["m_veh"] = replace(vehicle["m_veh"], value=2050.0)
    return replace(d, vehicle=vehicle)


KNOWLEDGE = Knowledge(
    mu={"K38": 0.11, "B05": 0.13},
    m_veh=1950.0,
    zeta=0.02,
    torque_gain=1.02,
    valve_gain=0.97,
    valve_offset=3e3,
    fill_offset=0.01,
    pressure_offset=2e3,
)


def _c_knowledge(controller: ShiftController) -> dict[str, float]:
    k = controller.knowledge
    return {
        "mu_off": k.mu[controller.off],
        "mu_on": k.mu[controller.on],
        "m_veh": k.m_veh,
        "zeta": k.zeta,
        "torque_gain": k.torque_gain,
        "valve_gain": k.valve_gain,
        "valve_offset": k.valve_offset,
        "fill_time": controller.fill_time,
        "fill_offset": k.fill_offset,
        "pressure_offset": k.pressure_offset,
    }


class Twin:
    """The Python and the C controller fed the same speeds and torque each tick; ``drive``
    says whose commands go to the plant."""

    def __init__(self, python: ShiftController, c: CShiftController, drive: str) -> None:
        self.python, self.c, self.drive = python, c, drive
        self.ticks: list[tuple[float, str, str, dict, dict]] = []

    @property
    def phase(self) -> str:
        return self.python.phase if self.drive == "python" else self.c.phase

    def step(self, t: float, speeds: np.ndarray, torque: float) -> dict[str, float]:
        py = self.python.step(t, speeds, torque)
        c = self.c.step(t, speeds, torque, tuple(self.python.measured))
        self.ticks.append((t, self.python.phase, self.c.phase, py, c))
        return py if self.drive == "python" else c


def _run(d, lib: Path, single: bool, drive: str, coast: bool = False):  # noqa: ANN001, ANN202
    truth = _truth(d)
    point = OperatingPoint.from_scenario(load_scenario(d, COAST if coast else None))
    plant = ClosedLoopShift(truth, "2-3", point.vehicle_speed, {"K38": 0.95, "B05": 1.05})
    model = HybridSimulator(d, plant.scenario(1.0, {}, 0.0), hybrid_shift(d, "2-3"))
    python = make_controller(d, model, KNOWLEDGE, point.torque)
    assert isinstance(python, DownshiftController) == coast
    c = CShiftController(lib, HEADER, "2-3", "K38", "B05", _c_knowledge(python), single=single)
    twin = Twin(python, c, drive)
    nominal = ClutchActuator.from_calibration(d.control)
    actuators = {"K38": nominal, "B05": nominal}
    result = plant.run(twin, point.torque, point.torque, actuators, actuators, t_end=1.2)
    return twin, result


#: the phase order of each kind of shift: power-on (the torque phase first) and coast (the
#: input torque drives the shift: the inertia phase first)
ORDER = {"power_on": ("torque", "inertia"), "coast": ("inertia", "torque")}
_LOOPS: dict[str, tuple] = {}


def _python_loops(d, libraries, kind: str) -> tuple:  # noqa: ANN001
    """The Python controller closing the loop, the double and the float C builds riding
    along (each kind simulated once per module)."""
    if kind not in _LOOPS:
        _LOOPS[kind] = tuple(
            _run(d, libraries[single], single, "python", coast=kind == "coast")
            for single in (False, True)
        )
    return _LOOPS[kind]


@pytest.fixture(scope="module", params=sorted(ORDER))
def python_loop(request, d, libraries):  # noqa: ANN001, ANN201
    return request.param, _python_loops(d, libraries, request.param)


def _differences(twin: Twin) -> np.ndarray:
    return np.array([[abs(py[e] - c[e]) for e in ("K38", "B05")] for _, _, _, py, c in twin.ticks])


def check_double_build(twin: Twin, result, order: tuple[str, str], label: str) -> None:  # noqa: ANN001
    """The double build rode along the Python loop ``result``: every phase, ``order``'s first
    before its second, tick by tick as the Python controller gave it, and its commands within
    :data:`DOUBLE_TOLERANCE` (also tests/test_control_c_downshift.py)."""
    assert result.completed and all(a == b for _, a, b, _, _ in twin.ticks)
    phases = [a for _, a, _, _, _ in twin.ticks]
    assert {"fill", "torque", "inertia", "lockup", "done"} <= set(phases)
    first, then = order
    assert phases.index(first) < phases.index(then)
    worst = _differences(twin).max()
    print(f"{label}, double build: largest command difference {worst:.3g} Pa")
    assert worst <= DOUBLE_TOLERANCE


def test_double_build_gives_the_python_commands_tick_by_tick(python_loop) -> None:  # noqa: ANN001
    """Every phase, in the kind's order, tick by tick as the Python controller gives it."""
    kind, ((twin, result), _) = python_loop
    check_double_build(twin, result, ORDER[kind], kind)


def test_float_build_gives_the_python_commands_within_float_rounding(python_loop) -> None:  # noqa: ANN001
    kind, (_, (twin, _)) = python_loop
    assert all(a == b for _, a, b, _, _ in twin.ticks)
    worst = _differences(twin).max()
    print(
        f"{kind}, float build: largest command difference {worst:.3g} Pa ({worst / 0.125:.1f} ulps)"
    )
    assert worst <= FLOAT_TOLERANCE


def test_the_float_c_controller_closes_the_loop_like_the_python_one(d, libraries) -> None:  # noqa: ANN001
    """The C controller (float) drives the plant: it ends locked in the to-gear at the Python
    loop's lock-up time (the plant's event, located to 1e-8 by the integrator) within 1 ms,
    and the on-coming slip follows the Python loop's within 0.1 rad/s (5 % of the lock-up
    slip, which is 5 rad/s)."""
    (_, reference), _ = _python_loops(d, libraries, "power_on")
    twin, result = _run(d, libraries[True], True, "c")
    assert result.completed and twin.c.status == 0
    slip = naming.slip_column("B05")
    lock_diff = abs(result.t_lockup - reference.t_lockup)
    slip_diff = float(np.max(np.abs(result.signals[slip] - reference.signals[slip])))
    print(
        f"C loop: lock-up at {result.t_lockup:.4f} s (Python {reference.t_lockup:.4f} s), "
        f"largest on-coming slip difference {slip_diff:.3g} rad/s"
    )
    assert lock_diff < 1e-3
    assert slip_diff < 0.1


def test_the_float_c_controller_closes_a_coast_shift_like_the_python_one(d, libraries) -> None:  # noqa: ANN001
    """The C controller (float) drives the coast shift: the plant's events (B05 engages, K38
    breaks away, B05 locks up at synchronism, K38 opens) in the Python loop's order, each
    within 1 ms of it, and both elements' slips within 0.1 rad/s of it."""
    (_, reference), _ = _python_loops(d, libraries, "coast")
    twin, result = _run(d, libraries[True], True, "c", coast=True)
    check_same_loop(twin, result, reference, "B05", "C coast loop")


def check_same_loop(twin: Twin, result, reference, locks: str, label: str) -> None:  # noqa: ANN001
    """The C controller's loop ``result`` against the Python one's ``reference``: completed
    without an error, the plant's events in the same order (``locks`` locking up among them),
    each within 1 ms, both swapping elements' slips within 0.1 rad/s (also
    tests/test_control_c_downshift.py)."""
    assert result.completed and twin.c.status == 0
    ours = [(e.kind, e.element) for e in result.events]
    assert ours == [(e.kind, e.element) for e in reference.events]
    assert ("lock-up", locks) in ours
    shift = max(abs(a.t - b.t) for a, b in zip(result.events, reference.events, strict=True))
    slips = [naming.slip_column(e) for e in ("K38", "B05")]
    slip_diff = max(float(np.max(np.abs(result.signals[c] - reference.signals[c]))) for c in slips)
    print(f"{label}: events within {shift:.2g} s, slips within {slip_diff:.3g} rad/s")
    assert shift < 1e-3
    assert slip_diff < 0.1


def test_a_shift_without_torque_is_refused_and_the_from_gear_held(libraries) -> None:  # noqa: ANN001
    """A commanded torque of zero (neither power-on nor coast: the phase order depends on its
    sign): ERR_NO_TORQUE (3), the off-going element at line pressure, the on-coming vented,
    the plan not made."""
    c = CShiftController(libraries[False], HEADER, "2-3", "K38", "B05", {})
    speeds = np.full(8, 100.0)
    commands = c.step(0.0, speeds, 0.0)
    assert c.status == 3
    assert commands == {"K38": LINE, "B05": 0.0}
    assert c.state.planned == 0 and c.phase == "fill"


@pytest.mark.parametrize("kind", ["power-on", "coast"])
def test_the_tcu_task_on_the_host_gives_the_python_controllers_commands(d, tmp_path, kind) -> None:  # noqa: ANN001
    """The whole 10 ms task (EKF and controller, float, the Cortex-M4F driver built for the
    host) along the Python controller's closed-loop shift on the calibration's vehicle,
    power-on and coast: the Python controller's commands within FLOAT_TOLERANCE and its phase
    at every tick but where the lock-up's hold ends on a tick (a float tie, at most one), the
    EKF following the shift (the emulated target's run: tests/test_cortex_m4_qemu.py)."""
    from gearsym.validation.checks import qemu_control

    check_task_on_host(GENERATED_C, qemu_control.control_case(d, kind=kind), tmp_path)


def check_task_on_host(c_dir, case, out) -> tuple[str, ...]:  # noqa: ANN001
    """The task of ``c_dir`` (the Cortex-M4F driver built for the host, float) along a recorded
    case (:func:`gearsym.validation.checks.qemu_control.control_case`): every call succeeds,
    the Python controller's phase at every tick but a lock-up hold's float tie (at most one),
    its commands within FLOAT_TOLERANCE, the EKF following the shift
    (:func:`check_filter_tracking`). Returns the task's phases."""
    from gearsym.validation.checks import qemu_control, qemu_m4
    from gearsym.validation.studies.control.controller import PHASES

    host = qemu_control.build_host(c_dir, case, out)
    results = [qemu_control.values(ln) for ln in qemu_control.control_lines(qemu_m4.run_host(host))]
    assert len(results) == len(case.inputs) and all(s == 0 for s, _, _ in results)
    phases = tuple(PHASES[phase] for _, phase, _ in results)
    assert qemu_control.lockup_end_ties(case, phases) in (0, 1)
    commands = np.array([v[:2] for _, _, v in results])
    assert np.max(np.abs(commands - case.commands)) <= FLOAT_TOLERANCE
    check_filter_tracking(case, np.array([v[2:] for _, _, v in results]))
    return phases


def check_filter_tracking(case, states: np.ndarray) -> None:  # noqa: ANN001
    """The task's EKF follows a closed-loop shift of the calibration's own vehicle with its
    knowledge exact: its speeds within 1 rad/s of the measured ones over the whole shift (the
    measurement's noise model allows 1 %: about 2 rad/s of input speed) and 0.05 rad/s after
    it, its mass within 1 % throughout, and the on-coming element's μ learnt from its slide
    (moved by more than 1e-3 from the prior). A task that told its filter the commanded
    forces without the valve's lag and fill, and never set the filter's mode flags, measured
    1.7 rad/s after a power-on 3-2, m_veh 21 % light and μ exactly its prior."""
    from gearsym.validation.checks import qemu_control

    assert np.all(np.isfinite(states))
    tracking = qemu_control.filter_tracking(case, states)
    assert tracking.speed_error < 1.0, tracking
    assert tracking.speed_error_done < 0.05, tracking
    assert tracking.mass_error < 0.01, tracking
    assert tracking.mu_on_moved > 1e-3, tracking


def test_the_casadi_model_parts_equal_the_c_ones(libraries) -> None:  # noqa: ANN001
    """generated/python/gearsym_control_2_3_casadi.py (the same CSE'd expressions through the
    CasADi printer) against the double C build at random points of the operating range: to
    1e-12 of each output's scale (the printers differ only in how they print)."""
    import importlib.util

    path = GENERATED_C.parent / "python" / "gearsym_control_2_3_casadi.py"
    spec = importlib.util.spec_from_file_location("gearsym_control_2_3_casadi", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    functions = module.functions()
    c = CShiftController(libraries[False], HEADER, "2-3", "K38", "B05", {})
    p = module.parameter_defaults()
    ranges = {
        "omega_in": (50.0, 400.0),
        "omega_out": (20.0, 150.0),
        "T_In": (20.0, 400.0),
        "m_veh": (1500.0, 2500.0),
        "zeta": (-0.1, 0.1),
        "F_last": (0.0, 1e4),
        "mu_last": (0.08, 0.16),
        "F_1": (1e3, 1e4),
        "mu_1": (0.08, 0.16),
    }
    rng = np.random.default_rng(5)
    assert set(functions) == set(module.ARGUMENTS)
    for name, (arguments, n_out) in module.ARGUMENTS.items():
        for _ in range(50):
            v = [float(rng.uniform(*ranges[a])) for a in arguments]
            ours = c.evaluate(name, v, n_out)
            theirs = np.asarray(functions[name](p, v)).ravel()
            assert np.allclose(ours, theirs, rtol=1e-12, atol=1e-12 * np.max(np.abs(theirs))), name


def test_generate_says_why_a_shift_gets_no_controller(d) -> None:  # noqa: ANN001
    """When the EKF the task runs with is not emitted, generate emits no controller and says
    so in one line; a downshift's is emitted (tests/test_control_c_downshift.py runs it) and
    its README row says it is one."""
    from gearsym.symbolic.codegen.control import control_files
    from gearsym.symbolic.shifts import shift_spec

    files, rows, skipped = control_files(d, shift_spec(d, "3-2"), "", "c", "python")
    assert sorted(files) == [
        "c/gearsym_control_3_2.c",
        "c/gearsym_control_3_2.h",
        "python/gearsym_control_3_2_casadi.py",
    ]
    assert not skipped and rows[0].startswith("| `control_3_2` | downshift 3-2, power-on and coast")
    files, rows, skipped = control_files(d, shift_spec(d, "2-3"), "no EKF here", "c", "python")
    assert not files and skipped == ["`control_2_3`: no EKF here"]
    assert control_files(d, None, "", "c", "python") == ({}, [], [])


def test_params_validate_accepts_the_defaults_and_names_a_bad_one(libraries) -> None:  # noqa: ANN001
    """The vehicle's parameters are checked against the parameter records' ranges, as every
    emitted model's are: the defaults pass, a non-positive stiffness is ERR_RANGE at its index."""
    import ctypes

    c = CShiftController(libraries[False], HEADER, "2-3", "K38", "B05", {})
    validate = c.lib[c.prefix + "params_validate"]
    bad = ctypes.c_int(7)
    assert validate(ctypes.byref(c.params), ctypes.byref(bad)) == 0 and bad.value == -1
    c.params.k_ss = 0.0
    assert validate(ctypes.byref(c.params), ctypes.byref(bad)) == 2 and bad.value == 0
