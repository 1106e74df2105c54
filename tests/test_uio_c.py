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
    from gearsym.symbolic.export.generate import uio_files
    from gearsym.validation.checks.c_check import compile_shared

    d = load_description()
    files, rows, _ = uio_files(d)
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
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

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


def _c_unknown_input(lib, prefix, design, x_hat, y, u, single):
    """d̂_k from the emitted ``_unknown_input`` for k = 0 … N−2 (x̂_k, y_{k+1}, u_k, u_{k+1})."""
    real = ctypes.c_float if single else ctypes.c_double
    dtype = np.float32 if single else np.float64
    fn = getattr(lib, f"{prefix}_unknown_input")
    keep = []

    def ptr(a):
        arr = np.ascontiguousarray(a, dtype)
        keep.append(arr)
        return arr.ctypes.data_as(ctypes.POINTER(real))

    out = np.empty((len(y) - 1, len(design.unknown)))
    for k in range(len(y) - 1):
        d = np.zeros(len(design.unknown), dtype)
        fn(ptr(x_hat[k]), ptr(y[k + 1]), ptr(u[k]), ptr(u[k + 1]), ptr(d))
        out[k] = d
    return out


def _dot_scale(design, x_hat, y, u):
    """Σ|terms| of d̂ = L (y_{k+1} − C A_d x̂_k − C B_d u_k − C B_1 Δu_k) per sample: the scale
    of its rounding error (the terms are speeds of 30–300 rad/s times a gain of about
    I_C^eff / h, their difference the road load of some 60–500 N m)."""
    a = np.abs
    du = np.diff(u, axis=0)
    inner = a(design.C) @ (
        a(design.Ad) @ a(x_hat[:-1]).T + a(design.Bd) @ a(u[:-1]).T + a(design.B1) @ a(du).T
    )
    return (a(design.left_inverse) @ (a(y[1:]).T + inner)).T


@pytest.mark.parametrize("single", [False, True], ids=["double", "float"])
def test_emitted_unknown_input_equals_the_library(emitted, samples, single):
    """The emitted d̂ (fed by the emitted observer's own x̂) against ``UioDesign.run``'s:
    double 1e-12 and float 1e-5 relative to the largest Σ|terms| of the difference."""
    from gearsym.symbolic.codegen.uio import phase_identifier, uio_set_name

    _, _, _, libs, _ = emitted
    tolerance = 1e-5 if single else 1e-12
    for design, y, u in samples.values():
        x0 = _guess(design, y)
        x_ref, d_ref = design.run(y, u, x0_guess=x0)
        prefix = f"gearsym_{uio_set_name(DEFAULT_SHIFT)}_{phase_identifier(design.phase)}"
        x_c = _c_run(libs[single], prefix, design, y, u, x0, single)
        d_c = _c_unknown_input(libs[single], prefix, design, x_c, y, u, single)
        scale = np.max(_dot_scale(design, x_ref, y, u))
        err = np.max(np.abs(d_c - d_ref)) / scale
        print(
            f"{design.phase} ({'float' if single else 'double'}): d_hat error {err:.2e} of "
            f"{scale:.3g} N m; largest |d_hat| {np.max(np.abs(d_ref)):.3g} N m"
        )
        assert err <= tolerance, design.phase
        # the library's one-step form is what run() returns
        k = len(y) // 2
        one = design.unknown_input(x_ref[k], y[k + 1], u[k], u[k + 1])
        np.testing.assert_allclose(one, d_ref[k], rtol=1e-12, atol=1e-12 * scale)


def test_library_unknown_input_against_the_reference_road_load(samples):
    """d̂ of the library's observer on the noise-free reference against the reference's road
    load T_res (2.48; ζ = 0 on the default scenario, so T_res* = T_res), over each sample
    interval (the mean of T_res over it, by the trapezoid rule on the simulation's own grid).
    Stated bounds: where the rigid mode holds (gear 2, before the shift) 0.5 N m RMS; in
    gear 3 the reference's element still sticks after lock-up (bristle transient), and in the
    torque and speed phase the clutch torques, known inputs, move within a sample: 100 N m and
    1000 N m RMS, with the first 25 ms of a phase left out (the observer converging from its
    first guess), as `gearsym estimate --filter uio` reports."""
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    d = load_description()
    result = simulate(d, load_scenario(d, None))
    bounds = {"gear 2": 0.5, "torque and speed phase": 1000.0, "gear 3": 100.0}
    t_all = np.arange(result.t[0], result.t[-1] + 1e-12, SAMPLE_TIME)
    for design, y, u in samples.values():
        x_hat, d_hat = design.run(y, u, x0_guess=_guess(design, y))
        # the sample times of this phase (as the samples fixture cut them)
        first = int(np.flatnonzero(t_all >= _phase_start(result, design))[0])
        t = t_all[first : first + len(y)]
        truth = np.array(
            [_interval_mean(result, t[k], t[k + 1], naming.ROAD_TORQUE) for k in range(len(t) - 1)]
        )
        settled = t[:-1] >= t[0] + 0.025
        rms = float(np.sqrt(np.mean((d_hat[settled, 0] - truth[settled]) ** 2)))
        print(f"{design.phase}: T_res* RMS error {rms:.3g} N m (mean truth {truth.mean():.3g})")
        assert rms < bounds[design.phase], design.phase


def _phase_start(result, design):
    phases = result.phases
    return {
        "gear 2": phases[0].t_start,
        "torque and speed phase": phases[1].t_start,
        "gear 3": phases[3].t_start,
    }[design.phase]


def _interval_mean(result, t0, t1, name):
    inside = (result.t > t0) & (result.t < t1)
    ts = np.r_[t0, result.t[inside], t1]
    vs = np.interp(ts, result.t, result.signals[name])
    return float(np.trapezoid(vs, ts) / (t1 - t0))


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


def test_generate_check_compares_the_uio_and_sees_a_changed_number(emitted, tmp_path):
    """``generate --check``'s comparison (validation/checks/uio_check.py) passes on the emitted
    files and fails when one printed gain of the unknown input moves by 1e-9 relative."""
    import re

    from gearsym.validation.checks.generated_check import comparison_ok
    from gearsym.validation.checks.uio_check import compare_uio

    d, files, _, _, _ = emitted
    designs = shift_uio_designs(d, DEFAULT_SHIFT, (naming.RESISTANCE_INPUT,), SAMPLE_TIME)

    def write(tree, root):
        for name, text in tree.items():
            path = root / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")

    write(files, tmp_path / "good")
    reports = compare_uio(DEFAULT_SHIFT, designs, tmp_path / "good", tmp_path / "b1", 50)
    assert [r.target for r in reports] == [
        "uio_2_3: C double",
        "uio_2_3: C single",
        "uio_2_3: CasADi",
    ]
    assert all(comparison_ok(r) for r in reports)
    assert len(reports[0].max_error) == 4 * len(designs)

    source = files["c/gearsym_uio_2_3.c"]
    match = re.search(r"gear_2_DY\[\d+\] = \{\n    GEARSYM_LIT\(([^)]+)\)", source)
    assert match is not None
    value = float(match.group(1))
    changed = source[: match.start(1)] + repr(value * (1 + 1e-9)) + source[match.end(1) :]
    write({**files, "c/gearsym_uio_2_3.c": changed}, tmp_path / "bad")
    bad = compare_uio(DEFAULT_SHIFT, designs, tmp_path / "bad", tmp_path / "b2", 50)
    assert not comparison_ok(bad[0])
    assert bad[0].max_error["gear_2.unknown_input"] > 1e-12
    assert bad[0].max_error["gear_2.step"] <= 1e-12
