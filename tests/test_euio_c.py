"""The emitted extended UIO (gearsym_euio_2_3.c, thesis 4.5) against the library's filter.

Expected values: :func:`gearsym.symbolic.estimators.euio.euio_step_full` (CasADi evaluation of
the SymPy model, dense NumPy linear algebra with ``np.linalg.inv``), step by step along the
default 2-3 shift as :func:`gearsym.validation.studies.estimation.euio.run_euio` runs it (its held
masks: m_veh in every phase, a μ where its element does not slide or its UIO conditions fail), with
sensor dropouts (NaN) added. From the library's state before each step: the C double build to
1e-12 and the float build to 2e-5 (about 170 float epsilons; measured 1.02e-5 with the
description's [estimator] prior, whose μ σ is half the former default) in each quantity's own
scale (x_i against |x_i| + σ_i, P_ij
against σ_i σ_j, d̂ against |d̂| + σ_d, σ_d² relative, the NIS νᵀS⁻¹ν − d̂²/σ_d² against its
first term νᵀS⁻¹ν + 1, from which float cancels the second). And the float filter on its own along
the whole run: P exactly symmetric and positive definite after every step.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from gearsym.symbolic.codegen import emit_all
from gearsym.symbolic.estimators.euio import ROAD_FREE, euio_step_full, load_column
from gearsym.symbolic.export.generate import euio_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks.c_check import compile_shared

PREFIX = "gearsym_euio_2_3_"
H = 0.01
OK, ERR_NONFINITE, ERR_SINGULAR = 0, 1, 3


@pytest.fixture(scope="module")
def emitted():
    d = load_description()
    return d, euio_model(d, shift_spec(d, "2-3"))


@pytest.fixture(scope="module")
def libraries(emitted, tmp_path_factory):
    _, m = emitted
    files = {k: v for k, v in emit_all(m.model, m.config).items() if not k.endswith(".py")}
    out = tmp_path_factory.mktemp("euio_c")
    return {
        single: ctypes.CDLL(str(compile_shared(files, out, single=single)))
        for single in (False, True)
    }


@pytest.fixture(scope="module")
def run(emitted):
    """The library's run (run_euio's loop, dropouts added): per step the inputs of the step."""
    from gearsym.symbolic.defaults import EKF_RELATIVE_NOISE
    from gearsym.symbolic.drivetrain import quantity
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.euio import run_euio
    from gearsym.validation.studies.estimation.loop import noisy_outputs
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    d, m = emitted
    result = simulate(d, load_scenario(d, None))
    reference = run_euio(d, result, sample_time=H, seed=3)  # its held masks per sample
    parameters = [name for name in reference.state_names[4:]]
    setup = prepare_ekf(d, result, H, EKF_RELATIVE_NOISE, None, parameters)
    aug, discrete = setup.aug, setup.discrete
    assert list(reference.state_names) == aug.state_names == [v.name for v in m.model.states]
    p = aug.parameter_values(ROAD_FREE)
    names = [v.name for v in aug.model.parameters]
    p_c = [p[names.index(v.name)] for v in m.model.parameters]
    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    i_wheel = p[names.index("I_wheel")]
    y = noisy_outputs(setup, 3)
    for k in range(17, len(y), 23):
        y[k, k % y.shape[1]] = np.nan  # a dropout of one sensor
    z = setup.initial.copy()
    for j, name in enumerate(setup.outputs):
        if name in aug.state_names:
            z[aug.state_names.index(name)] = y[0, j]
    P = np.diag(setup.prior_sigma**2)
    q = np.array(setup.q, dtype=float)
    steps = []
    for k in range(1, len(setup.t)):
        hold = np.flatnonzero(reference.held[k])
        R = (setup.relative * np.maximum(np.abs(y[k]), setup.floor)) ** 2
        e = load_column(discrete, z, r_dyn, p, i_wheel)
        s = euio_step_full(discrete, z, P, setup.u[k - 1], setup.u[k], y[k], R, H, p, q, e, hold)
        steps.append((z, P, setup.u[k - 1], setup.u[k], y[k], reference.held[k], s))
        z, P = s.z, s.P
    masks = {
        phase: {x.parameter for x in ex if not x.exists}
        for phase, ex in reference.existence.items()
    }
    return {
        "steps": steps,
        "p": p_c,
        "q": q,
        "r": setup.relative,
        "floor": setup.floor,
        "masks": masks,
    }


def _step(lib, single, z, P, u_prev, u, p, q, y, r, floor, held):
    real = ctypes.c_float if single else ctypes.c_double
    dtype = np.float32 if single else np.float64
    n = len(z)
    x = np.array(z, dtype=dtype)
    Pc = np.array(P, dtype=dtype).ravel(order="F")
    bufs = [np.array(v, dtype=dtype) for v in (u_prev, u, q, y, r, floor, held)]
    load = np.zeros(3, dtype=dtype)
    Params = type(
        "Params", (ctypes.Structure,), {"_fields_": [(f"p{i}", real) for i in range(len(p))]}
    )
    fn = getattr(lib, PREFIX + "euio_step")
    fn.restype = ctypes.c_int

    def ptr(a):
        return a.ctypes.data_as(ctypes.POINTER(real))

    status = fn(
        ptr(x),
        ptr(Pc),
        ptr(bufs[0]),
        ptr(bufs[1]),
        ctypes.byref(Params(*p)),
        real(H),
        *(ptr(b) for b in bufs[2:]),
        ptr(load),
    )
    return status, x.astype(float), Pc.reshape(n, n, order="F").astype(float), load.astype(float)


def test_emitted_euio_step_equals_the_library(libraries, run):
    worst = {False: 0.0, True: 0.0}
    held_seen = np.zeros(len(run["steps"][0][0]), dtype=bool)
    free_seen = np.zeros_like(held_seen)
    dropouts = 0
    for z, P, u_prev, u, y, held, s in run["steps"]:
        held_seen |= held
        free_seen |= ~held
        dropped = not np.all(np.isfinite(y))
        dropouts += dropped
        sigma = np.sqrt(np.diag(s.P))
        for single, lib in libraries.items():
            status, x_c, P_c, load = _step(
                lib, single, z, P, u_prev, u, run["p"], run["q"], y, run["r"], run["floor"], held
            )
            err = max(
                float(np.max(np.abs(x_c - s.z) / (np.abs(s.z) + sigma))),
                float(np.max(np.abs(P_c - s.P) / np.outer(sigma, sigma))),
            )
            if dropped:  # the update is skipped, as the library's: the prediction stands
                assert status == ERR_NONFINITE and np.all(np.isnan(load)) and np.isnan(s.d_hat)
            else:
                assert status == OK
                err = max(
                    err,
                    abs(load[0] - s.d_hat) / (abs(s.d_hat) + s.sigma_d),
                    abs(load[1] - s.sigma_d**2) / s.sigma_d**2,
                    # NIS = nu^T S^-1 nu - d^2 / sigma_d^2: a difference, scaled by its terms
                    abs(load[2] - s.nis) / (abs(s.nis) + s.d_hat**2 / s.sigma_d**2 + 1.0),
                )
            assert np.all(P_c == P_c.T)
            worst[single] = max(worst[single], err)
    print(f"worst scaled difference: double {worst[False]:.3g}, float {worst[True]:.3g}")
    # the run exercised every held mask: m_veh always held, both μ held and estimated somewhere
    assert held_seen[4] and not free_seen[4], "m_veh is held in every phase (module text)"
    assert held_seen[5] and free_seen[5] and held_seen[6] and free_seen[6]
    assert dropouts >= 5
    assert worst[False] < 1e-12, worst
    assert worst[True] < 2e-5, worst


def test_float_euio_keeps_its_covariance_symmetric_positive_definite(libraries, run):
    """The float filter on its own state along the whole run (dropouts included)."""
    z, P = run["steps"][0][0], run["steps"][0][1]
    x, Pf = z.astype(np.float32).astype(float), P.astype(np.float32).astype(float)
    finals = None
    for _, _, u_prev, u, y, held, s in run["steps"]:
        status, x, Pf, load = _step(
            libraries[True],
            True,
            x,
            Pf,
            u_prev,
            u,
            run["p"],
            run["q"],
            y,
            run["r"],
            run["floor"],
            held,
        )
        assert status in (OK, ERR_NONFINITE)
        assert np.all(Pf == Pf.T)
        np.linalg.cholesky(Pf.astype(np.float32))  # raises unless positive definite
        finals = (x, s.z, np.sqrt(np.diag(s.P)))
    assert finals is not None
    x, z_ref, sigma = finals
    # and it tracks the double library filter: within a tenth of its σ at the end
    assert np.all(np.abs(x - z_ref) < 0.1 * sigma + 1e-6 * np.abs(z_ref)), (x, z_ref)


def test_a_covariance_that_is_not_positive_definite_is_refused(libraries, run):
    """S = C P C^T + R not positive definite (here P with a negative variance on a measured
    speed): ERR_SINGULAR, the prediction stands, the load is NaN."""
    z, P, u_prev, u, y, held, s = next(st for st in run["steps"] if np.all(np.isfinite(st[4])))
    bad = P.copy()
    bad[0, 0] = -1e6
    for single, lib in libraries.items():
        status, x_c, _, load = _step(
            lib, single, z, bad, u_prev, u, run["p"], run["q"], y, run["r"], run["floor"], held
        )
        assert status == ERR_SINGULAR and np.all(np.isnan(load))
        assert np.all(np.isfinite(x_c))


def test_the_header_masks_are_those_of_the_reference_run(emitted, run):
    """The per-phase held masks the header states (existence at a generic operating point)
    equal those of run_euio (existence at each phase's midpoint of the reference simulation)."""
    _, m = emitted
    names = [v.name for v in m.model.states]
    stated = {phase: {names[i] for i in held} for phase, held, _ in m.euio.held_phases}
    assert stated == run["masks"]
    assert all("m_veh" in held for held in stated.values())


def test_casadi_euio_step_equals_the_library(emitted, run, tmp_path):
    """The CasADi module's euio_step (symbolic inverse of S, SX graph) against the library
    (NumPy inverse) along the same run: 1e-12 in the scales above; a dropout gives the
    prediction and a NaN load."""
    from gearsym.validation.checks.c_binding import load_casadi_module

    _, m = emitted
    name = f"gearsym_{m.model.name}_casadi.py"
    (tmp_path / name).write_text(emit_all(m.model, m.config)[name], encoding="utf-8")
    step = load_casadi_module(tmp_path / name).euio_step()
    worst = 0.0
    for z, P, u_prev, u, y, held, s in run["steps"]:
        args = (z, P, u_prev, u, run["p"], H, run["q"], y, run["r"], run["floor"], held)
        x_n, P_n, load = (np.asarray(v, dtype=float) for v in step(*args))
        x_n = x_n.ravel()
        load = load.ravel()
        sigma = np.sqrt(np.diag(s.P))
        worst = max(
            worst,
            float(np.max(np.abs(x_n - s.z) / (np.abs(s.z) + sigma))),
            float(np.max(np.abs(P_n - s.P) / np.outer(sigma, sigma))),
        )
        if np.all(np.isfinite(y)):
            worst = max(
                worst,
                abs(load[0] - s.d_hat) / (abs(s.d_hat) + s.sigma_d),
                abs(load[1] - s.sigma_d**2) / s.sigma_d**2,
                abs(load[2] - s.nis) / (abs(s.nis) + s.d_hat**2 / s.sigma_d**2 + 1.0),
            )
        else:
            assert np.all(np.isnan(load))
    print(f"CasADi: worst scaled difference {worst:.3g}")
    assert worst < 1e-12, worst
