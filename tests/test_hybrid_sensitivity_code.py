"""The emitted hybrid sensitivities (``generated/c/gearsym_hybrid_2_3_sens.{h,c}``).

Independent checks:

* driven through the default 2-3 shift by the emitted functions alone (Runge-Kutta steps of each
  mode's (3.7), guards located by Brent's method, the emitted jump at every switch:
  :func:`gearsym.validation.checks.hybrid_code_check.run_emitted`), the states and sensitivities
  equal those of :class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator`, which
  differentiates the mode models by CasADi's AD and applies the jump formula numerically (DOP853,
  tolerances 1e-12). The run crosses the break-away of K38, the engagement of B05, the opening of
  K38 and the lock-up of B05; both runs switch at the same times to 1e-9 s. Tolerance: RK4 at h =
  1e-4 s has a global error of order h⁴ times the fourth derivative; measured 5e-11 of each column's
  peak, asserted 1e-7;
* the comparison is discriminating: with the Euclidean instead of the M-metric projection as
  the map it fails by more than 1 % of a peak;
* at the run's break-away and lock-up A f⁻ = f⁺ (physics: the friction torque acts along the
  slip, which the target's constraints annihilate), so the event-time term vanishes there though
  ∂τ/∂p does not; the term is therefore checked on its own at random points, where it is not
  zero, against the formula assembled from the simulator's CasADi functions;
* C (double, float) and CasADi equal the SymPy expressions at random points for the functions of
  the modes and switches the run visits; ``m<i>_step`` is one classical RK4 step of ``m<i>_rhs``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.codegen.hybrid import hybrid_table
from gearsym.symbolic.export.generate import hybrid_sensitivity_sets
from gearsym.symbolic.hybrid import BREAK_AWAY, ENGAGEMENT, LOCK_UP, OPENING
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks import c_check
from gearsym.validation.checks.c_binding import load_casadi_module
from gearsym.validation.checks.hybrid_code_check import HybridFunctions, run_emitted
from gearsym.validation.sim.hybrid_simulation import HybridSimulator

GENERATED = Path(__file__).resolve().parents[1] / "generated"
NAME = "gearsym_hybrid_2_3_sens"
SAMPLE = 0.01  # s


@pytest.fixture(scope="module")
def d():
    return load_description()


@pytest.fixture(scope="module")
def hs(d):
    (emitted,) = hybrid_sensitivity_sets(d)
    return emitted.sensitivity


@pytest.fixture(scope="module")
def libraries(hs, tmp_path_factory):
    sources = {
        f"{NAME}{ext}": (GENERATED / "c" / f"{NAME}{ext}").read_text() for ext in (".h", ".c")
    }
    build = tmp_path_factory.mktemp("hybrid")
    double = c_check.compile_shared(sources, build / "double")
    single = c_check.compile_shared(sources, build / "single", single=True)
    return HybridFunctions(double, hs), HybridFunctions(single, hs, single=True)


@pytest.fixture(scope="module")
def simulator(d, hs):
    return HybridSimulator(d, hybrid=hs.hybrid, mu="constant")


@pytest.fixture(scope="module")
def runs(hs, simulator, libraries):
    names = [v.name for v in hs.parameters]
    p = simulator.parameter_vector(simulator.values())
    s0 = simulator.initial_sensitivity(p, names)
    grid = np.arange(0.0, simulator.scenario.t_end + 1e-12, SAMPLE)
    reference = simulator.run(None, 1e-12, 1e-12, parameters=names, s0=s0, t_eval=grid)
    emitted = run_emitted(libraries[0], simulator, p, s0, grid, h=1e-4)
    return reference, emitted, p, s0, grid


def _columns(hs, mode_index, y):
    """{(state name, column): value} of an augmented state (column 0: x, j ≥ 1: S_j)."""
    mode = hs.modes[mode_index]
    n = mode.nx
    names = [v.name for v in mode.mode.model.states]
    return {
        (name, j): y[j * n + i]
        for j in range(len(hs.parameters) + 1)
        for i, name in enumerate(names)
    }


@pytest.mark.slow
def test_the_run_crosses_every_kind_of_switch_at_the_reference_times(hs, runs):
    reference, emitted, *_ = runs
    index = {m.mode.name: m.index for m in hs.modes}
    expected = [(e.t, index[e.source], index[e.target], e.kind) for e in reference.events]
    assert {BREAK_AWAY, ENGAGEMENT, OPENING, LOCK_UP} <= {e[3] for e in expected}
    assert [e[1:] for e in emitted.events] == [e[1:] for e in expected]
    assert np.allclose([e[0] for e in emitted.events], [e[0] for e in expected], rtol=0, atol=1e-9)


def _compare(hs, reference, emitted, grid):
    index = {m.mode.name: m.index for m in hs.modes}
    ref_values: dict = {}
    got_values: dict = {}
    for k, t in enumerate(grid):
        piece = [pc for pc in reference.pieces if pc.t_start <= t <= pc.t_end][-1]
        assert index[piece.mode] == emitted.modes[k], f"mode at t = {t}"
        ref = _columns(hs, emitted.modes[k], piece.state(np.array([t]))[0])
        got = _columns(hs, emitted.modes[k], emitted.states[k])
        for key in ref:
            ref_values.setdefault(key, []).append(ref[key])
            got_values.setdefault(key, []).append(got[key])
    worst = 0.0
    for key, values in ref_values.items():
        peak = np.max(np.abs(values))
        if peak > 0:
            worst = max(worst, np.max(np.abs(np.subtract(got_values[key], values))) / peak)
    return worst


def test_emitted_sensitivities_equal_the_reference_across_switches(hs, runs):
    reference, emitted, _, _, grid = runs
    assert _compare(hs, reference, emitted, grid) < 1e-7


def test_the_comparison_sees_a_wrong_jump(hs, simulator, libraries, runs):
    """Mapped by the Euclidean instead of the M-metric projection (2.34), the sensitivities after
    the switches differ from the reference by more than 1 % of their peak."""
    reference, _, p, s0, grid = runs
    functions = libraries[0]
    original = functions.call
    m = len(hs.parameters)

    def euclidean_jump(name, **arrays):
        if not name.startswith("jump_"):
            return original(name, **arrays)
        source, target = (hs.modes[int(v)] for v in name.split("_")[1:])
        old, new = source.mode.projection, target.mode.projection
        gearbox = np.array((new.T * new).inv() * (new.T * old), dtype=float)
        a = np.zeros((target.nx, source.nx))
        a[: gearbox.shape[0], : gearbox.shape[1]] = gearbox
        a[-2, -2] = a[-1, -1] = 1.0  # φ and ω_C
        y = np.asarray(arrays["x"])
        n = source.nx
        return [np.concatenate([a @ y[j * n : (j + 1) * n] for j in range(m + 1)])]

    functions.call = euclidean_jump
    try:
        wrong = run_emitted(functions, simulator, p, s0, grid, h=1e-4)
    finally:
        functions.call = original
    assert _compare(hs, reference, wrong, grid) > 1e-2


def test_jump_formula_at_random_points(hs, simulator, libraries, runs):
    """Away from an event A f⁻ ≠ f⁺, so the event-time term of every state-dependent jump of
    the run is checked where it is not zero: the emitted jump against
    S⁺ = A S⁻ + (A f⁻ − f⁺) ∂τ/∂p, ∂τ/∂p = −(g_x S⁻ + g_p)/(g_x f⁻ + g_u u̇), assembled from
    the simulator's CasADi functions (AD of the mode models, not the emitted expressions)."""
    emitted = runs[1]
    functions = libraries[0]
    p = runs[2]
    functions.set_parameters(p)
    columns = [simulator.parameter_names.index(v.name) for v in hs.parameters]
    rng = np.random.default_rng(11)
    checked = 0
    for _, i, j, kind in emitted.events:
        if kind not in (BREAK_AWAY, LOCK_UP):
            continue
        source, target = hs.modes[i], hs.modes[j]
        jump = hs.jump(source.mode.name, target.mode.name)
        assert jump.event_time
        compiled = simulator.modes[source.mode.name]
        k = [g for g in compiled.continuous].index(jump.guard)
        a = np.array(hs.hybrid.maps[(source.mode.name, target.mode.name)].matrix, dtype=float)
        n, m = source.nx, len(hs.parameters)
        x = rng.uniform(-1.0, 1.0, n) * np.array([300.0] * (n - 2) + [0.05, 40.0])
        sens = rng.uniform(-1.0, 1.0, (n, m))
        u = simulator.inputs(0.7) * rng.uniform(0.8, 1.2, 4)
        rate = rng.uniform(-1.0, 1.0, 4) * np.array([1e3, 1e5, 1e5, 0.1])
        f_minus = compiled.rhs(x, u, p)
        f_plus = simulator.modes[target.mode.name].rhs(a @ x, u, p)
        g_x, g_u, g_p = (
            np.asarray(v.full(), dtype=float) for v in compiled.guard_gradient(k)(x, u, p)
        )
        tau_p = -(g_x @ sens + g_p[:, columns]).ravel() / float((g_x @ f_minus + g_u @ rate)[0])
        term = np.outer(a @ f_minus - f_plus, tau_p)
        assert np.max(np.abs(term)) > 1e-6 * np.max(np.abs(a @ sens))  # the term is not zero here
        expected = np.concatenate([a @ x, (a @ sens + term).T.ravel()])
        y = np.concatenate([x, sens.T.ravel()])
        got = functions.call(f"jump_{i}_{j}", x=y, u=u, u_rate=rate)[0]
        assert np.allclose(got, expected, rtol=1e-9, atol=1e-9 * np.max(np.abs(expected)))
        checked += 1
    assert checked == 2  # the break-away of K38 and the lock-up of B05


def test_at_the_events_the_field_is_continuous_through_the_map(hs, simulator, runs):
    """At break-away (the reaction equals the capacity) and at lock-up (zero slip) A f⁻ = f⁺: the
    friction torque acts along the slip, which the target's constraint projection annihilates.
    So the event-time term, though ∂τ/∂p is not zero, adds nothing at the true events, and the
    comparison with the reference checks the map A and (3.7) in each mode."""
    reference = runs[0]
    p = runs[2]
    assert reference.event_time_sensitivities is not None
    for event, tau_p in zip(reference.events, reference.event_time_sensitivities, strict=True):
        if event.kind not in (BREAK_AWAY, LOCK_UP):
            continue
        assert np.max(np.abs(tau_p)) > 1e-3
        piece = next(
            pc for pc in reference.pieces if pc.mode == event.source and pc.t_end == event.t
        )
        n = len(hs.mode(event.source).mode.model.states)
        x = piece.state(np.array([event.t]))[0][:n]
        u = simulator.inputs(event.t)
        a = np.array(hs.hybrid.maps[(event.source, event.target)].matrix, dtype=float)
        f_minus = simulator.modes[event.source].rhs(x, u, p)
        f_plus = simulator.modes[event.target].rhs(a @ x, u, p)
        assert np.max(np.abs(a @ f_minus - f_plus)) < 1e-6 * np.max(np.abs(f_plus))


def _sympy_values(spec, points):
    symbols = [s for a in spec.args for s in a.symbols]
    flat = [e for matrix in spec.expressions for e in matrix]
    f = sp.lambdify([symbols], flat, "numpy")
    return np.array([np.asarray(f(point), dtype=float) for point in points])


def test_c_and_casadi_equal_sympy_at_random_points(hs, libraries, runs):
    emitted = runs[1]
    table = hybrid_table(hs)
    specs = {spec.name: spec for spec in table if spec.kind == "expr"}
    visited = sorted(set(emitted.modes))
    names = [f"m{i}_rhs" for i in visited] + [f"m{i}_guards" for i in visited]
    names += [f"jump_{a}_{b}" for _, a, b, _ in emitted.events]
    casadi = load_casadi_module(GENERATED / "python" / f"{NAME}_casadi.py").functions()
    rng = np.random.default_rng(7)
    p0 = np.array([v.default for v in hs.hybrid.parameters], dtype=float)
    for name in names:
        spec = specs[name]
        sizes = {a.name: a.size for a in spec.args if a.kind != "params"}
        points = []
        for _ in range(5):
            p = p0 * rng.uniform(0.8, 1.2, len(p0))
            arrays = {a: rng.uniform(-1.0, 1.0, size) * 50.0 for a, size in sizes.items()}
            arrays["u"] = np.array([200.0, 8000.0, 9000.0, 0.01]) * rng.uniform(0.5, 1.5, 4)
            points.append((arrays, p))
        flat_points = [
            np.concatenate([arrays[a.name] if a.kind != "params" else p for a in spec.args])
            for arrays, p in points
        ]
        expected = _sympy_values(spec, flat_points)
        for (arrays, p), want in zip(points, expected, strict=True):
            scale = np.maximum(np.abs(want), 1.0)
            for functions, tolerance in zip(libraries, (1e-12, 1e-4), strict=True):
                functions.set_parameters(p)
                got = np.concatenate(functions.call(name, **arrays))
                assert np.max(np.abs(got - want) / scale) < tolerance, name
            args = {a.name: (p if a.kind == "params" else arrays[a.name]) for a in spec.args}
            out = casadi[name](*(args[a.name] for a in spec.args))
            out = out if isinstance(out, (list, tuple)) else [out]
            got = np.concatenate([np.asarray(o.full(), dtype=float).ravel() for o in out])
            assert np.max(np.abs(got - want) / scale) < 1e-12, name


def test_step_is_one_runge_kutta_step_of_rhs(hs, simulator, libraries, runs):
    functions = libraries[0]
    p = runs[2]
    functions.set_parameters(p)
    mode = hs.modes[0]
    rng = np.random.default_rng(3)
    x = rng.uniform(-1.0, 1.0, len(mode.states)) * 20.0
    u = simulator.inputs(0.3)
    h = 1e-3

    def f(y):
        return functions.call(f"m{mode.index}_rhs", x=y, u=u)[0]

    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)
    expected = x + h / 6 * (k1 + 2 * (k2 + k3) + k4)
    assert np.allclose(functions.step(mode.index, x, u, h), expected, rtol=1e-13, atol=1e-13)


def test_generate_refuses_a_bad_hybrid_shift_list(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "gen"
    result = subprocess.run(
        [sys.executable, "-m", "gearsym", "generate", "--out", str(out), "--hybrid-shifts", "2-9"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "'2' and '9'" in lines[0] and "one of each" in lines[0]
    assert "Traceback" not in result.stderr and not out.exists()
