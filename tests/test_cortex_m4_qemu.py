"""The emitted float EKF, extended UIO and models (2-3 shift, its μ form, full) bare-metal on a
Cortex-M4F.

QEMU's ``mps2-an386`` board (Cortex-M4F) runs the project's harness (validation/checks/cortex_m4/:
start-up, linker script, semihosting, driver) built with arm-none-eabi-gcc and newlib; the same
driver built for the host in float prints the same lines. Expected: every printed float equal
bit for bit (both builds IEEE single with ``-ffp-contract=off``; see
gearsym.validation.checks.qemu_m4 for why equality is a fair expectation). That the runs are not
trivially equal is checked against physics and an independent integrator: the filter's estimates
stay within 4σ of the reference simulation's truth, and the RK4 trajectories of the 2-3 and the full
model within 1 % of the reference simulation's (the hybrid model, integrated by CVODES) states, the
μ form's run within 2e-5 of the same model integrated in process while the elements slide; the
float EUIO, run on its own state, ends within a tenth of its σ of the library's double filter
(:func:`~gearsym.symbolic.estimators.euio.euio_step_full`) and its estimates stay within 4σ of
the truth. Without the
tools the tests skip, except under CI, where they fail (.ci/run installs them).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks import qemu_m4

pytestmark = pytest.mark.slow  # QEMU runs on the emulated Cortex-M4F: `make check`

GENERATED_C = Path(__file__).resolve().parents[1] / "generated" / "c"


def require_qemu_tools() -> None:
    """Skip where the cross tools or QEMU are missing, but fail under CI: CI installs them
    (.ci/run), and a skip there would pass silently."""
    missing = qemu_m4.missing_tools()
    if missing:
        reason = f"not installed: {', '.join(missing)} (CI installs them: .ci/run)"
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)


def _runs(tmp_path_factory: pytest.TempPathFactory, same_trig: bool):
    require_qemu_tools()
    case = qemu_m4.reference_case(load_description())
    out = tmp_path_factory.mktemp("m4")
    elf, host = qemu_m4.build(GENERATED_C, case, out, same_trig=same_trig)
    return case, qemu_m4.run_host(host), qemu_m4.run_qemu(elf)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory):
    """Both sides with the harness' sine and cosine: equal by construction."""
    return _runs(tmp_path_factory, same_trig=True)


@pytest.fixture(scope="module")
def library_runs(tmp_path_factory: pytest.TempPathFactory):
    """Each side with its own C library's sinf/cosf (newlib, glibc), as the benchmark builds."""
    return _runs(tmp_path_factory, same_trig=False)


#: Per tag: leading values (NIS, load ...) and the filter's state count (P follows the state).
_FILTER_LINES = {"ekf": (1, 8), "euio": (3, 7)}


def _value_scales(tag: str, values: np.ndarray) -> np.ndarray:
    """Each value's own scale: a filter state |x| + σ and a covariance entry σ_i σ_j (σ from
    the line's own P), a leading statistic |v| + 1, an RK4 state |x| + 1e-6."""
    if tag not in _FILTER_LINES:
        return np.abs(values) + 1e-6
    lead, n = _FILTER_LINES[tag]
    x, P = values[lead : lead + n], values[lead + n :].reshape(n, n)
    sigma = np.sqrt(np.abs(np.diag(P)))
    return np.concatenate(
        [np.abs(values[:lead]) + 1.0, np.abs(x) + sigma, np.outer(sigma, sigma).ravel()]
    )


def _largest_line_difference(ours: list[str], theirs: list[str]) -> float:
    """max over every value of |a - b| / its own scale (:func:`_value_scales`)."""
    assert len(ours) == len(theirs)
    worst = 0.0
    for a, b in zip(ours, theirs, strict=True):
        if a == b:
            continue
        assert a.split()[:2] == b.split()[:2]  # same tag and step
        fa, fb = qemu_m4.floats(a), qemu_m4.floats(b)
        assert (np.isnan(fa) == np.isnan(fb)).all(), (a, b)
        ok = ~np.isnan(fa)
        scale = _value_scales(a.split()[0], np.where(ok, fa, 0.0))
        worst = max(worst, float(np.max(np.abs(fa[ok] - fb[ok]) / scale[ok], initial=0.0)))
    return worst


def test_with_each_sides_own_sinf_the_results_agree_to_float_precision(runs, library_runs) -> None:
    """glibc's and newlib's sinf/cosf may differ in the last bit (qemu_m4's docstring): with
    them the target still follows the host to float precision, and the harness' stand-in
    sine/cosine changes the host's results by no more than that either."""
    _, host, target = library_runs
    ours, theirs = qemu_m4.result_lines(host), qemu_m4.result_lines(target)
    # 1e-4 of each value's own scale: a last-bit difference of sinf grows by float rounding
    # over the 150 filter steps (measured: the stand-in against glibc's 3.7e-5 of a σ)
    assert _largest_line_difference(ours, theirs) < 1e-4
    assert _largest_line_difference(ours, qemu_m4.result_lines(runs[1])) < 1e-4


def test_the_emulated_target_prints_the_hosts_float_results_bit_for_bit(runs) -> None:
    case, host, target = runs
    ours, theirs = qemu_m4.result_lines(host), qemu_m4.result_lines(target)
    n_ekf, n_rk4 = len(case.u) - 1, len(case.shift_u)
    assert sum(ln.startswith("ekf ") for ln in ours) == n_ekf
    assert sum(ln.startswith("euio ") for ln in ours) == len(case.euio_u) - 1
    for tag in qemu_m4.RK4_TAGS:
        assert sum(ln.startswith(tag + " ") for ln in ours) == n_rk4
    words = {
        "ekf": 3 + 1 + 8 + 64,
        "euio": 3 + 3 + 7 + 49,
        "rk4": 2 + 4,
        "rk4mu": 2 + 4,
        "rk4full": 2 + 6,
    }
    assert all(len(ln.split()) == words[ln.split()[0]] for ln in ours)  # none cut short
    assert len(theirs) == len(ours)
    differing = [(a, b) for a, b in zip(ours, theirs, strict=True) if a != b]
    assert not differing, f"{len(differing)} lines differ, first:\n{differing[0]}"


def test_the_runs_estimate_and_integrate_the_reference_shift(runs) -> None:
    case, host, _ = runs
    lines = qemu_m4.result_lines(host)
    ekf = np.array([qemu_m4.floats(ln) for ln in lines if ln.startswith("ekf ")])
    x, P = ekf[:, 1:9], ekf[:, 9:].reshape(-1, 8, 8, order="F")
    assert np.all(np.isfinite(ekf))
    sigma = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    assert np.max(np.abs(x - case.truth[1:]) / sigma) < 4.0
    rk4 = np.array([qemu_m4.floats(ln) for ln in lines if ln.startswith("rk4 ")])
    scale = np.abs(case.shift_truth).max(axis=0)
    speeds = [0, 1, 3]  # omega_1, omega_2, omega_C
    assert np.max(np.abs(rk4 - case.shift_truth[1:])[:, speeds] / scale[speeds]) < 0.01
    full = np.array([qemu_m4.floats(ln) for ln in lines if ln.startswith("rk4full ")])
    scale = np.abs(case.full_truth).max(axis=0)
    assert np.max(np.abs(full - case.full_truth[1:]) / scale) < 0.01


def test_the_mu_form_run_equals_the_in_process_model_while_the_elements_slide(runs) -> None:
    """The μ form (2.69: T = k 2 N_disc r_m μ F_N, power-on slip directions, μ = 0.12 as a
    parameter) runs open loop from the shift's start, so it leaves the reference once K38
    would stick; by value it is judged against the same model evaluated in process: its
    SymPy right-hand side through CasADi (not the C printer), classic RK4 in double at the
    float32 inputs, start and step the driver used. Compared while the elements slide (the
    reference's torque and speed phases, 629 steps of 0.5 ms), each state relative to its
    largest magnitude there: float RK4 over the about 1 760 steps up to the speed phase's end
    accumulates rounding, measured 6.4e-6 at most (φ; the speeds 1.0e-6 to 1.7e-6); the
    tolerance 2e-5 is about 300 float ulps. A μ 0.1 % off in the reference moves it by
    1.4e-3 (μ_38, in ω_1) and 8e-4 (μ_05, in φ): 40 to 70 times the tolerance."""
    from gearsym.symbolic.drivetrain import shift_model
    from gearsym.symbolic.numeric import casadi_function
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate

    case, host, _ = runs
    d = load_description()
    model = shift_model(d, "2-3", friction_inputs=True)
    assert [v.name for v in model.inputs] == ["T_In", "F_N38", "F_N05"]  # case.mu_u's columns
    f = casadi_function(
        "f",
        [("x", model.state_symbols), ("u", model.input_symbols), ("p", model.parameter_symbols)],
        [("xdot", model.rhs)],
    )
    p = np.array([v.default for v in model.parameters], dtype=float)
    h = float(np.float32(case.shift_h))  # the driver's CASE_SHIFT_H
    x = np.asarray(case.shift_x0, dtype=float)
    reference = []
    for u in np.asarray(case.mu_u, dtype=float):

        def rhs(state: np.ndarray, u: np.ndarray = u) -> np.ndarray:
            return np.asarray(f(state, u, p), dtype=float).ravel()

        k1 = rhs(x)
        k2 = rhs(x + h / 2 * k1)
        k3 = rhs(x + h / 2 * k2)
        k4 = rhs(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        reference.append(x)
    reference = np.array(reference)
    mu = np.array(
        [qemu_m4.floats(ln) for ln in qemu_m4.result_lines(host) if ln.startswith("rk4mu ")]
    )
    assert mu.shape == reference.shape
    result = simulate(d, load_scenario(d, None))
    t = result.t[1 : len(mu) + 1]  # the time after each step
    sliding = (t >= result.phase("torque phase").t_start) & (t <= result.phase("speed phase").t_end)
    assert sliding.sum() > 500
    scale = np.abs(reference[sliding]).max(axis=0)
    error = np.abs(mu[sliding] - reference[sliding]) / scale
    print("μ form, largest error per state while sliding:", error.max(axis=0))
    assert np.max(error) < 2e-5


def test_the_euio_run_follows_the_library_and_the_truth(runs) -> None:
    """The float EUIO on its own state: the update is skipped exactly at the dropouts, its
    covariance stays symmetric positive definite, the estimate ends within 0.1 σ of the
    library's double filter and never leaves 4 σ of the truth (μ where its element slides)."""
    case, host, _ = runs
    lines = [ln for ln in qemu_m4.result_lines(host) if ln.startswith("euio ")]
    status = np.array([int(ln.split()[2], 16) for ln in lines])
    values = np.array([qemu_m4.floats(ln) for ln in lines])
    load, x = values[:, :3], values[:, 3:10]
    P = values[:, 10:].reshape(-1, 7, 7, order="F")
    dropped = ~np.all(np.isfinite(case.euio_y[1:]), axis=1)
    assert dropped.sum() >= 5
    assert np.array_equal(status != 0, dropped) and np.all(status[dropped] == 1)
    assert np.all(np.isnan(load[dropped])) and np.all(np.isfinite(load[~dropped]))
    for Pk in P:
        assert np.array_equal(Pk, Pk.T)
        np.linalg.cholesky(Pk)
    sigma = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    lib, lib_sigma = case.euio_library, case.euio_library_sigma
    assert np.all(np.abs(x[-1] - lib[-1]) < 0.1 * lib_sigma[-1] + 1e-6 * np.abs(lib[-1]))
    scored = np.isfinite(case.euio_truth)
    assert np.all(np.abs(x - case.euio_truth)[scored] < 4 * sigma[scored])


def test_systick_counts_instructions_and_the_timed_loop_repeats_the_printed_run(runs) -> None:
    """Under ``-icount shift=0`` one instruction is 1 ns of virtual time; SysTick runs on the
    board's 25 MHz processor clock, so a tick is 40 instructions (calibrated by a loop of two
    instructions per turn). Each timed RK4 loop ends in the state its printed run ended in."""
    _, host, target = runs
    t = qemu_m4.timing(target)
    assert t.instructions_per_tick == 40.0
    for tag in qemu_m4.RK4_TAGS:
        last = [ln for ln in qemu_m4.result_lines(host) if ln.startswith(tag + " ")][-1]
        check = next(ln for ln in target.splitlines() if ln.startswith(tag + "_check "))
        assert check.split()[1:] == last.split()[2:]
    print(
        f"instructions per step: EKF {t.ekf_step:.0f} (predict {t.ekf_predict:.0f}, update "
        f"{t.ekf_update:.0f}), EUIO {t.euio:.0f} ({t.euio_steps} steps), RK4: 2-3 "
        f"{t.rk4:.0f}, 2-3 μ form {t.rk4mu:.0f}, full {t.rk4full:.0f}"
    )


# ------------------------------------------------------------------ the TCU task (issue 29)


@pytest.fixture(
    scope="module",
    params=[
        *((shift, kind) for shift in ("2-3", "3-2") for kind in ("power-on", "coast")),
        *(("3-4", kind) for kind in ("power-on", "coast")),
    ],
    ids=lambda p: f"{p[0]}-{p[1]}",
)
def control_runs(request, tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN001
    """The emitted TCU task (controller + EKF, float) of the 2-3 upshift (generated/c), of the
    3-2 downshift and of the 3-4 (its EKF measures shaft 8 besides; both emitted here), along
    the Python controller's closed-loop shift, power-on and coast (whichever the input torque
    drives runs the inertia phase first), on the host and on the
    emulated target."""
    from gearsym.validation.checks import qemu_control
    from gearsym.validation.checks.control_c import emit_task_sources

    require_qemu_tools()
    shift, kind = request.param
    d = load_description()
    c_dir = GENERATED_C
    if shift != "2-3":
        c_dir = emit_task_sources(d, shift, tmp_path_factory.mktemp("m4_c"), GENERATED_C)
    case = qemu_control.control_case(d, kind=kind, shift=shift)
    out = tmp_path_factory.mktemp("m4_control")
    elf, host, objects = qemu_control.build(c_dir, case, out)
    return case, qemu_m4.run_host(host), qemu_m4.run_qemu(elf), elf, objects


def test_the_tcu_task_on_the_target_gives_the_python_controllers_commands(control_runs) -> None:
    """Tick by tick the target's task commands what the Python controller commanded on the
    same measurements, within 32 float ulps of line pressure (the ulp of 1.5e6 Pa is 0.125 Pa;
    the ctypes comparison, tests/test_control_c.py, measures 4 ulps), in the same phase, and
    the host build (glibc's sinf/cosf against newlib's) prints the same to 1e-4 of each value's
    scale; the EKF follows the shift (:func:`tests.test_control_c.check_filter_tracking`)."""
    from gearsym.validation.checks import qemu_control
    from gearsym.validation.studies.control.controller import PHASES

    from tests.test_control_c import check_filter_tracking

    case, host, target, _, _ = control_runs
    lines = qemu_control.control_lines(target)
    assert len(lines) == len(case.inputs)
    results = [qemu_control.values(ln) for ln in lines]
    assert all(status == 0 for status, _, _ in results)
    # the same phase every tick, but where the lock-up's hold ends on a tick (float and
    # double round either side of it: line pressure either way)
    phases = tuple(PHASES[phase] for _, phase, _ in results)
    assert qemu_control.lockup_end_ties(case, phases) in (0, 1)
    commands = np.array([v[:2] for _, _, v in results])
    assert np.max(np.abs(commands - case.commands)) <= 32 * 0.125
    x = np.array([v[2:] for _, _, v in results])
    check_filter_tracking(case, x)
    theirs = [qemu_control.values(ln)[2] for ln in qemu_control.control_lines(host)]
    ours = [v for _, _, v in results]
    worst = max(
        float(np.max(np.abs(a - b) / (np.abs(b) + 1.0))) for a, b in zip(ours, theirs, strict=True)
    )
    assert worst < 1e-4


def test_the_tcu_task_fits_its_instruction_budget(control_runs) -> None:
    """The 10 ms task (EKF predict, update and mode update, the controller's step) under the
    issue's budget of 20 000 instructions per call at its largest (the inertia phase: the
    sliding mode's model and the μ map twice); its code size printed (bytes of the functions
    it links, and arm-none-eabi-size of each object)."""
    from gearsym.validation.checks import qemu_control

    case, _, target, elf, objects = control_runs
    t = qemu_control.timing(target)
    functions, objects_size = qemu_control.code_size(elf, objects, case.shift)
    assert t.instructions_per_tick == 40.0 and t.calls > 100
    assert functions, "no function of the task found in the ELF"
    print(
        f"TCU task {case.shift}: {t.mean:.0f} instructions per call on average, "
        f"{t.largest:.0f} at most (budget {qemu_control.BUDGET}); code of the linked "
        f"functions {sum(functions.values())} bytes; objects (text + data + bss): {objects_size}"
    )
    assert t.largest < qemu_control.BUDGET
