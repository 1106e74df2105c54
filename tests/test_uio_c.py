"""The emitted UIO (thesis 4.4) of the default shift: C (double and float) and CasADi against
the library's NumPy observer, and ``generate`` refusing an observer that cannot exist.

Reference: :meth:`gearsym.symbolic.estimators.uio.UioDesign.run` (NumPy, double) on the samples
of the reference simulation of the 2-3 shift, the way ``gearsym estimate --filter uio`` feeds
it; the emitted code prints the same design's numbers, so the runs must agree to rounding:
1e-12 (double) and 1e-5 (float) relative to the largest state. The refusal: with T_K38, T_B05
and T_res* unknown the torque and speed phase has an invariant zero at s = 0 (hand-checked in
the digest of the thesis, tests/test_uio.py), so no UIO exists there.
"""

from __future__ import annotations

import ctypes
import subprocess
import sys

import numpy as np
import pytest
from gearsym.symbolic import naming
from gearsym.symbolic.defaults import DEFAULT_SHIFT, SAMPLE_TIME
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimators.uio import shift_uio_designs
from gearsym.symbolic.loader import load_description


@pytest.fixture(scope="module")
def emitted(tmp_path_factory):
    from gearsym.symbolic.generate import uio_files
    from gearsym.validation.c_check import compile_shared

    d = load_description()
    files, rows = uio_files(d)
    out = tmp_path_factory.mktemp("uio_c")
    c_files = {k.split("/")[-1]: v for k, v in files.items() if not k.endswith(".py")}
    libs = {
        single: ctypes.CDLL(str(compile_shared(c_files, out, single=single)))
        for single in (False, True)
    }
    py = next(k for k in files if k.endswith(".py"))
    module_path = out / py.split("/")[-1]
    module_path.write_text(files[py], encoding="utf-8")
    return d, files, rows, libs, module_path


@pytest.fixture(scope="module")
def samples():
    """Per phase of the UIO: the measured speeds y and the known inputs u of the reference
    simulation at the sample time, over the phases the mode serves."""
    from gearsym.validation.scenario import load_scenario
    from gearsym.validation.simulate import simulate

    d = load_description()
    result = simulate(d, load_scenario(d, None))
    designs = shift_uio_designs(d, DEFAULT_SHIFT, (naming.RESISTANCE_INPUT,), SAMPLE_TIME)
    t = np.arange(result.t[0], result.t[-1] + 1e-12, SAMPLE_TIME)
    phases = result.phases
    windows = {  # the UIO's phase -> the simulation's phases it runs in
        designs[0].phase: [phases[0]],
        designs[1].phase: [phases[1], phases[2]],
        designs[2].phase: [phases[3]],
    }
    data = {}
    for design in designs:
        inside = np.flatnonzero(
            (t >= windows[design.phase][0].t_start) & (t <= windows[design.phase][-1].t_end)
        )
        y = np.column_stack(
            [
                np.interp(t[inside], result.t, result.signals[n.removeprefix("y_")])
                for n in design.outputs
            ]
        )
        u = np.column_stack(
            [np.interp(t[inside], result.t, result.signals[n]) for n in design.known]
        )
        data[design.phase] = (design, y, u)
    return data


def _c_run(lib, prefix: str, design, y: np.ndarray, u: np.ndarray, x0: np.ndarray, single: bool):
    real = ctypes.c_float if single else ctypes.c_double
    dtype = np.float32 if single else np.float64
    nx = len(design.states)

    def ptr(a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(real))

    init, step, estimate = (getattr(lib, f"{prefix}_{f}") for f in ("init", "step", "estimate"))
    z = np.zeros(nx, dtype)
    init(ptr(np.ascontiguousarray(x0, dtype)), ptr(z))
    yc, uc = np.ascontiguousarray(y, dtype), np.ascontiguousarray(u, dtype)
    x_hat = np.empty((len(y), nx))
    for k in range(len(y)):
        xk = np.zeros(nx, dtype)
        estimate(ptr(z), ptr(np.ascontiguousarray(yc[k])), ptr(xk))
        x_hat[k] = xk
        if k + 1 < len(y):
            z_next = np.zeros(nx, dtype)
            step(
                ptr(z),
                ptr(np.ascontiguousarray(yc[k])),
                ptr(np.ascontiguousarray(uc[k])),
                ptr(np.ascontiguousarray(uc[k + 1])),
                ptr(z_next),
            )
            z = z_next
    return x_hat


def _guess(design, y: np.ndarray) -> np.ndarray:
    """A first guess that is not the truth: the measured speeds, zero twist."""
    measured = {n.removeprefix("y_"): j for j, n in enumerate(design.outputs)}
    return np.array([y[0, measured[s]] if s in measured else 0.0 for s in design.states])


@pytest.mark.parametrize("single", [False, True], ids=["double", "float"])
def test_emitted_c_step_equals_the_library_observer(emitted, samples, single):
    from gearsym.symbolic.codegen.uio import phase_identifier, uio_set_name

    _, _, _, libs, _ = emitted
    tolerance = 1e-5 if single else 1e-12
    for design, y, u in samples.values():
        x0 = _guess(design, y)
        reference, _ = design.run(y, u, x0_guess=x0)
        prefix = f"gearsym_{uio_set_name(DEFAULT_SHIFT)}_{phase_identifier(design.phase)}"
        got = _c_run(libs[single], prefix, design, y, u, x0, single)
        scale = np.max(np.abs(reference))
        assert len(y) > 10, design.phase
        assert np.max(np.abs(got - reference)) <= tolerance * scale, design.phase


def test_casadi_equals_c(emitted, samples):
    import importlib.util

    from gearsym.symbolic.codegen.uio import phase_identifier, uio_set_name

    _, _, _, libs, module_path = emitted
    spec = importlib.util.spec_from_file_location("gearsym_uio_casadi_test", module_path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    functions = module.functions()
    for design, y, u in samples.values():
        ph = phase_identifier(design.phase)
        f = functions[ph]
        x0 = _guess(design, y)
        z = np.array(f["init"](x0)).ravel()
        x_hat = np.empty((len(y), len(design.states)))
        for k in range(len(y)):
            x_hat[k] = np.array(f["estimate"](z, y[k])).ravel()
            if k + 1 < len(y):
                z = np.array(f["step"](z, y[k], u[k], u[k + 1])).ravel()
        got = _c_run(
            libs[False], f"gearsym_{uio_set_name(DEFAULT_SHIFT)}_{ph}", design, y, u, x0, False
        )
        assert np.max(np.abs(got - x_hat)) <= 1e-12 * np.max(np.abs(x_hat)), design.phase


def test_the_readme_rows_name_every_phase(emitted):
    _, files, rows, _, _ = emitted
    assert len(rows) == 3
    assert sorted(files) == [
        "c/gearsym_uio_2_3.c",
        "c/gearsym_uio_2_3.h",
        "python/gearsym_uio_2_3_casadi.py",
    ]


def test_generate_refuses_an_observer_that_cannot_exist():
    d = load_description()
    with pytest.raises(GearsymError) as err:
        shift_uio_designs(d, DEFAULT_SHIFT, ("T_res_star", "T_K38", "T_B05"), SAMPLE_TIME)
    text = str(err.value)
    assert "\n" not in text
    assert "--uio-unknown" in text
    assert "torque and speed phase" in text
    assert "not strongly detectable" in text and "invariant zero(s) 0 " in text


def test_generate_command_refuses_with_exit_code_2(tmp_path):
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "gearsym",
            "generate",
            "--out",
            str(tmp_path / "out"),
            "--shifts",
            "2-3",
            "--uio-unknown",
            "T_res_star,T_K38,T_B05",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr
    lines = [line for line in run.stderr.splitlines() if "torque and speed phase" in line]
    assert len(lines) == 1 and "invariant zero" in lines[0]
    assert not (tmp_path / "out").exists()
