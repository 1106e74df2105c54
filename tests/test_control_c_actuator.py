"""The emitted task's actuator model (``gearsym_control_2_3_actuator_tick``: what the task's
EKF is told each element presses) against the Python actuator it mirrors
(:meth:`~gearsym.validation.sim.actuator.ClutchActuator.at_ticks` with ``mean_over``, the Python
study's filter input), built strictly in double and float from generated/c.

The command sequences: the Python controller's own commands of a closed-loop power-on 2-3 (the
on-coming element's fast fill, hold, ramp, inertia-phase and lock-up commands; the off-going
element's hold, ramp down and vent), and a hand-made one that strokes a piston, presses, vents
it below the spring (the piston leaves the discs and retracts) and fills it again; each through
three views of the valve and piston (the nominal one, a valve 8 % strong and 80 mbar low with a
piston believed 30 ms slow, one 5 % weak and 50 mbar high)."""

from __future__ import annotations

import ctypes
from dataclasses import replace

import numpy as np
import pytest
from gearsym.symbolic.control_calibration import MEAN_OVER, TICK
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks.control_c import build_control_library, structure
from gearsym.validation.sim.actuator import ClutchActuator

from tests.test_control_c import GENERATED_C

LINE = 1.5e6
#: (valve gain, valve offset Pa, fill time the knowledge believes s)
VIEWS = ((1.0, 0.0, 0.100), (1.08, -8.0e3, 0.130), (0.95, 5.0e3, 0.090))
#: double: the same closed-form pieces, the dead time's switch instant exact in C and a sum
#: of floats in Python (1e-12 of line pressure; measured 1.9e-9 Pa)
DOUBLE_TOLERANCE = 1e-12 * LINE
#: float: 32 ulps of line pressure (the ulp of 1.5e6 in float is 0.125 Pa), as the commands
#: (measured 1.7 Pa)
FLOAT_TOLERANCE = 32 * 0.125


@pytest.fixture(scope="module")
def d():  # noqa: ANN201
    return load_description(None)


@pytest.fixture(scope="module", params=[False, True], ids=["double", "float"])
def task(request, tmp_path_factory):  # noqa: ANN001, ANN201
    single = request.param
    lib = ctypes.CDLL(
        str(build_control_library(GENERATED_C, "2-3", tmp_path_factory.mktemp("act"), single))
    )
    header = (GENERATED_C / "gearsym_control_2_3.h").read_text(encoding="utf-8")
    real = ctypes.c_float if single else ctypes.c_double
    actuator = structure(header, "gearsym_control_2_3_actuator", single)
    knowledge = structure(header, "gearsym_control_2_3_knowledge", single)
    lib.gearsym_control_2_3_actuator_init.argtypes = [ctypes.c_int, real, ctypes.c_void_p]
    lib.gearsym_control_2_3_actuator_init.restype = None
    lib.gearsym_control_2_3_actuator_tick.argtypes = [ctypes.c_void_p, real, ctypes.c_void_p]
    lib.gearsym_control_2_3_actuator_tick.restype = real
    lib.gearsym_control_2_3_knowledge_default.argtypes = [ctypes.c_void_p]
    lib.gearsym_control_2_3_knowledge_default.restype = None
    return single, lib, actuator, knowledge


def _c_means(task, view, filled: bool, commands: np.ndarray) -> np.ndarray:  # noqa: ANN001
    _, lib, actuator, knowledge = task
    k = knowledge()
    lib.gearsym_control_2_3_knowledge_default(ctypes.byref(k))
    k.valve_gain, k.valve_offset, k.fill_time = view
    a = actuator()
    lib.gearsym_control_2_3_actuator_init(int(filled), LINE if filled else 0.0, ctypes.byref(a))
    return np.array(
        [
            lib.gearsym_control_2_3_actuator_tick(ctypes.byref(k), float(c), ctypes.byref(a))
            for c in commands
        ]
    )


def _python_means(d, view, filled: bool, commands: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """The knowledge's view as the Python study builds it (FillReplay.view/parameter): the
    nominal actuator with the view's valve, its fill time the one whose piston strokes in the
    believed time at the fast-fill command."""
    gain, offset, believed = view
    nominal = ClutchActuator.from_calibration(d.control)
    valved = replace(nominal, pressure_gain=gain, pressure_offset=offset)
    above = valved.valve_pressure(nominal.fast_fill_pressure) - nominal.return_spring
    fill_time = believed * above / (nominal.fast_fill_pressure - nominal.return_spring)
    actuator = replace(valved, fill_time=fill_time)
    start = actuator.initial(filled, LINE)
    return actuator.at_ticks(start, commands, TICK, mean_over=MEAN_OVER)


def _sequences(d) -> dict[str, tuple[bool, np.ndarray]]:  # noqa: ANN001
    from gearsym.validation.checks.qemu_control import control_case

    case = control_case(d)
    spring = d.control.si("actuator", "return_spring")
    hand = np.concatenate(
        [
            np.full(15, 3.0e5),  # fast fill: strokes within the tick 10-14
            np.linspace(1.2e5, 6.0e5, 20),  # presses
            np.full(12, 0.5 * spring),  # vented below the spring: leaves the discs, retracts
            np.zeros(5),  # shut
            np.full(20, 3.0e5),  # fills again
        ]
    )
    return {
        "off-going 2-3": (True, case.commands[:, 0]),
        "on-coming 2-3": (False, case.commands[:, 1]),
        "stroke, vent, refill": (False, hand),
    }


def test_the_task_is_told_what_the_python_actuator_presses(d, task) -> None:  # noqa: ANN001
    single, *_ = task
    tolerance = FLOAT_TOLERANCE if single else DOUBLE_TOLERANCE
    for name, (filled, commands) in _sequences(d).items():
        for view in VIEWS:
            ours = _c_means(task, view, filled, commands)
            theirs = _python_means(d, view, filled, commands)
            worst = float(np.max(np.abs(ours - theirs)))
            assert worst <= tolerance, f"{name}, view {view}: {worst:.3g} Pa apart"


def test_the_sequences_reach_every_piece_of_the_model(d) -> None:  # noqa: ANN001
    """The comparison above means something: along the sequences the Python model strokes,
    presses, lags, leaves the discs and strokes again (each piece of the C model is used)."""
    sequences = _sequences(d)
    _, hand = sequences["stroke, vent, refill"]
    means = _python_means(d, VIEWS[0], False, hand)
    assert np.all(means[:10] == 0.0)  # stroking: nothing pressed
    assert means[30] > 1.0e5  # pressing, lagging behind the ramp
    # vented below the spring (commanded from tick 35): the chamber falls to the spring's
    # pressure within about 9 ticks, the piston leaves the discs and retracts
    assert means[40] > 0.0 and np.all(means[44:55] == 0.0)
    # refilled from tick 52: the retracted piston strokes again (a tick of dead time and two
    # of stroke with nothing pressed), then presses
    assert means[-1] > 1.0e5
    _, off = sequences["off-going 2-3"]
    assert _python_means(d, VIEWS[0], True, off)[0] > 1.0e6  # at line pressure at first
