"""The emitted EKF (gearsym_ekf_2_3.c, thesis 4.3) against the NumPy reference filter.

Expected values: the reference implementation in :mod:`gearsym.symbolic.estimators.ekf`
(CasADi evaluation of the SymPy model, dense NumPy linear algebra), step by step along the
reference shift: the C double build to 1e-12, the float build to 1e-5, in each quantity's own
scale (x_i against |x_i| + σ_i, P_ij against σ_i σ_j). And a compiled harness: 10⁶ float steps
keep P exactly symmetric and positive definite.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.codegen import emit_all
from gearsym.symbolic.estimators.ekf import DiscreteModel, ekf_predict, ekf_update
from gearsym.symbolic.export.generate import ekf_model
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks.c_check import compile_shared, run_with_harness

HARNESS = Path(__file__).parent / "data" / "ekf_spd_harness.c"


@pytest.fixture(scope="module")
def emitted():
    d = load_description()
    return d, ekf_model(d, shift_spec(d, "2-3"))


@pytest.fixture(scope="module")
def libraries(emitted, tmp_path_factory):
    _, m = emitted
    files = {k: v for k, v in emit_all(m.model, m.config).items() if not k.endswith(".py")}
    out = tmp_path_factory.mktemp("ekf_c")
    return (
        {
            single: ctypes.CDLL(str(compile_shared(files, out, single=single)))
            for single in (False, True)
        },
        files,
        out,
    )


def _trajectory(d, m):
    """(u_k, y_k, z_k, P_k) before each step of the reference filter on the reference shift."""
    from gearsym.symbolic.estimators.ekf import augmented_model
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.loop import run_ekf

    result = simulate(d, load_scenario(d, None))
    aug = augmented_model(d, "2-3")
    run = run_ekf(d, result, sample_time=0.01, seed=3, aug=aug)
    return aug, run


class _Ekf:
    def __init__(self, lib, prefix: str, single: bool, nx: int, npar: int) -> None:
        self.real = ctypes.c_float if single else ctypes.c_double
        self.dtype = np.float32 if single else np.float64
        self.predict_fn = getattr(lib, prefix + "ekf_predict")
        self.update_fn = getattr(lib, prefix + "ekf_update")
        self.update_fn.restype = ctypes.c_int
        self.nx = nx
        self.Params = type(
            "Params", (ctypes.Structure,), {"_fields_": [(f"p{i}", self.real) for i in range(npar)]}
        )

    def _ptr(self, a):
        return a.ctypes.data_as(ctypes.POINTER(self.real))

    def predict(self, z, P, u, p, h, q):
        x = np.array(z, dtype=self.dtype)
        Pc = np.array(P, dtype=self.dtype).ravel(order="F")
        ub, qb = np.array(u, dtype=self.dtype), np.array(q, dtype=self.dtype)
        params = self.Params(*p)
        self.predict_fn(
            self._ptr(x),
            self._ptr(Pc),
            self._ptr(ub),
            ctypes.byref(params),
            self.real(h),
            self._ptr(qb),
        )
        return x.astype(float), Pc.reshape(self.nx, self.nx, order="F").astype(float)

    def update(self, z, P, u, p, y, r, floor):
        x = np.array(z, dtype=self.dtype)
        Pc = np.array(P, dtype=self.dtype).ravel(order="F")
        bufs = [np.array(v, dtype=self.dtype) for v in (u, y, r, floor)]
        nis = self.real(0)
        params = self.Params(*p)
        used = self.update_fn(
            self._ptr(x),
            self._ptr(Pc),
            self._ptr(bufs[0]),
            ctypes.byref(params),
            self._ptr(bufs[1]),
            self._ptr(bufs[2]),
            self._ptr(bufs[3]),
            ctypes.byref(nis),
        )
        return (
            x.astype(float),
            Pc.reshape(self.nx, self.nx, order="F").astype(float),
            nis.value,
            used,
        )


def _scaled_error(x, P, x_ref, P_ref):
    sigma = np.sqrt(np.diag(P_ref))
    ex = np.max(np.abs(x - x_ref) / (np.abs(x_ref) + sigma))
    eP = np.max(np.abs(P - P_ref) / np.outer(sigma, sigma))
    return max(float(ex), float(eP))


def test_emitted_ekf_step_equals_the_reference_filter(emitted, libraries):
    d, m = emitted
    libs, _, _ = libraries
    aug, run = _trajectory(d, m)
    discrete = DiscreteModel(aug)
    p = aug.parameter_values()
    q = [aug.intensities[n] for n in aug.state_names]
    r, floor = [0.01] * 3, [2.0, 0.7, 0.27]
    prefix = "gearsym_ekf_2_3_"
    filters = {
        single: _Ekf(libs[single], prefix, single, len(aug.state_names), len(p))
        for single in (False, True)
    }
    rng = np.random.default_rng(7)
    worst = {False: 0.0, True: 0.0}
    inputs = _inputs(d, aug, run)
    for k in range(1, len(run.t)):
        # the reference filter's state after the update at k-1, rebuilt exactly: a covariance
        # with the run's σ and a random correlation, so every entry of P takes part
        z = run.estimates[k - 1]
        C = np.corrcoef(rng.normal(size=(len(z), 3 * len(z))))
        P = C * np.outer(run.sigmas[k - 1], run.sigmas[k - 1])
        u_prev, u = inputs[k - 1], inputs[k]
        y = run.truth[k, [0, 1, 3]] * (1 + 0.01 * rng.normal(size=3))
        if k % 17 == 0:
            y[1] = np.nan  # a dropout of one sensor
        z_ref, P_ref = ekf_predict(discrete, z, P, u_prev, 0.01, p, q)
        z_up, P_up, nis_ref, used_ref = ekf_update(discrete, z_ref, P_ref, u, y, p, r, floor)
        for single, ekf in filters.items():
            x_c, P_c = ekf.predict(z, P, u_prev, p, 0.01, q)
            worst[single] = max(worst[single], _scaled_error(x_c, P_c, z_ref, P_ref))
            # the update from the reference's predicted state
            x_c, P_c, nis_c, used_c = ekf.update(z_ref, P_ref, u, p, y, r, floor)
            assert used_c == used_ref
            worst[single] = max(worst[single], _scaled_error(x_c, P_c, z_up, P_up))
            assert nis_c == pytest.approx(nis_ref, rel=1e-10 if not single else 1e-4, abs=1e-6)
    print(f"worst scaled difference: double {worst[False]:.3g}, float {worst[True]:.3g}")
    assert worst[False] < 1e-12, worst
    assert worst[True] < 1e-5, worst


def _inputs(d, aug, run):
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.modes import element_modes

    result = simulate(d, load_scenario(d, None))
    modes = element_modes(d, result, run.t)
    columns = []
    for name in aug.input_names:
        if name.startswith(("slide_", "stick_")):
            element = name.split("_", 1)[1]
            columns.append(modes[element][0 if name.startswith("slide_") else 1])
        else:
            columns.append(np.interp(run.t, result.t, result.signals[name]))
    return np.column_stack(columns)


def test_float_covariance_stays_symmetric_positive_definite_for_a_million_steps(libraries):
    _, files, out = libraries
    result = run_with_harness(files, out, HARNESS, "gearsym_ekf_2_3.c", timeout=300)
    assert result.returncode == 0 and result.stdout.startswith("ok"), result.stdout
    words = result.stdout.split()
    # and the float filter still estimates: the mass of the harness' truth (1800 kg) within 3σ
    mass, sigma = float(words[3]), float(words[5])
    assert abs(mass - 1800.0) < 3 * sigma


@pytest.fixture(scope="module")
def mode_cases(emitted):
    """(setup, logic, cases) of the mode-update tests: (z, P, u, modes before) on the filter's
    own run of the default shift (seed 2) and on states built around each element's lock-up
    and break-away (slip just either side of zero, every mode of the other element), P with a
    random correlation and the run's σ."""
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.loop import filter_run
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    d, _ = emitted
    result = simulate(d, load_scenario(d, None))
    setup = prepare_ekf(d, result, sample_time=0.01)
    logic = setup.logic
    aug = setup.aug
    run = filter_run(setup, 2)
    rng = np.random.default_rng(5)
    elements = list(logic.elements)
    cases = []
    for k in range(len(run.t)):
        before = {e: int(run.modes[e][k - 1]) if k else logic.initial_modes()[e] for e in elements}
        cases.append((run.estimates[k], run.sigmas[k], setup.u[k], before))
    # around the lock-up of each element: slip just either side of zero, every mode of the other
    for element in elements:
        c = np.array([float(aug.slip[element].coeff(s)) for s in aug.model.state_symbols[:2]])
        for k in rng.choice(len(run.t), 12, replace=False):
            z = run.estimates[k].copy()
            z[0] = (-c[1] * z[1] + rng.normal(0.0, 0.5)) / c[0]
            u = setup.u[k].copy()
            u[logic.normal_force[element]] = max(u[logic.normal_force[element]], 2000.0)
            for code in (1, -1, 2):
                other = elements[1 - elements.index(element)]
                for other_code in (0, 1, 2) if code != 2 else (0, 1):
                    cases.append((z, run.sigmas[k], u, {element: code, other: other_code}))
    with_P = []
    for z, sigma, u, before in cases:
        C = np.corrcoef(rng.normal(size=(len(z), 3 * len(z))))
        with_P.append((z, C * np.outer(sigma, sigma), u, before))
    return setup, logic, with_P


def test_emitted_mode_update_equals_the_reference_mode_logic(libraries, mode_cases):
    """``ekf_mode_update`` in C against :func:`ekf_mode_update` (NumPy/CasADi) on the filter's
    own run of the default shift and on states built around each element's lock-up and
    break-away: the same modes and switch count; x and P to 1e-12 in double (scaled as above)
    and 1e-5 in float, the float decisions compared where the deciding margin (slip against
    zero, |torque| against the capacity) exceeds float rounding."""
    from gearsym.symbolic.estimators.ekf_modes import ekf_mode_update

    libs, _, _ = libraries
    setup, logic, cases = mode_cases
    p = setup.p
    elements = list(logic.elements)
    fn = {single: libs[single].gearsym_ekf_2_3_ekf_mode_update for single in libs}
    checked = {False: 0, True: 0}
    worst = {False: 0.0, True: 0.0}
    switched = 0
    for z, P, u, before in cases:
        z_ref, P_ref, after, events = ekf_mode_update(logic, z, P, u, p, before)
        switched += len(events)
        slip, torque, capacity = logic._evaluate(np.asarray(z), logic.inputs(u, before), p)
        # relative margins of the decisions (float carries about 7 digits)
        margin = min(
            float(np.min(np.abs(slip))) / (abs(z[0]) + abs(z[1])),
            float(np.min(np.abs(np.abs(torque) - capacity) / (np.abs(torque) + capacity + 1.0))),
        )
        for single, f in fn.items():
            real = ctypes.c_float if single else ctypes.c_double
            dtype = np.float32 if single else np.float64
            x = np.array(z, dtype=dtype)
            Pc = np.array(P, dtype=dtype).ravel(order="F")
            ub = np.array(u, dtype=dtype)
            modes = (ctypes.c_int * 2)(*[before[e] for e in elements])
            Params = type(
                "Params",
                (ctypes.Structure,),
                {"_fields_": [(f"p{i}", real) for i in range(len(p))]},
            )
            f.restype = ctypes.c_int
            count = f(
                x.ctypes.data_as(ctypes.POINTER(real)),
                Pc.ctypes.data_as(ctypes.POINTER(real)),
                ub.ctypes.data_as(ctypes.POINTER(real)),
                ctypes.byref(Params(*p)),
                modes,
            )
            if single and margin < 1e-5:
                continue  # a float decision this close to its threshold may go either way
            assert [modes[i] for i in range(2)] == [after[e] for e in elements], (single, before)
            assert count == len(events)
            P_c = Pc.reshape(len(z), len(z), order="F").astype(float)
            worst[single] = max(worst[single], _scaled_error(x.astype(float), P_c, z_ref, P_ref))
            checked[single] += 1
    print(f"mode update: {checked} cases, {switched} switches, worst {worst}")
    assert switched >= 20 and checked[False] == len(cases) and checked[True] > 0.9 * len(cases)
    assert worst[False] < 1e-12, worst
    assert worst[True] < 1e-5, worst


def test_emitted_casadi_mode_update_equals_the_reference_mode_logic(emitted, mode_cases, tmp_path):
    """The emitted CasADi module's ``ekf_mode_update`` (if_else logic in SX, the lock-up maps
    as constants) against :func:`ekf_mode_update` of the library on the cases of the C test:
    the same modes and switch count, x and P to 1e-12 (scaled as above)."""
    import importlib.util

    from gearsym.symbolic.estimators.ekf_modes import STICK, ekf_mode_update
    from gearsym.symbolic.hybrid import BREAK_AWAY, ENGAGEMENT, LOCK_UP, OPENING

    _, m = emitted
    files = emit_all(m.model, m.config)
    name = next(k for k in files if k.endswith("_casadi.py"))
    path = tmp_path / Path(name).name
    path.write_text(files[name])
    spec = importlib.util.spec_from_file_location("emitted_ekf_casadi", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    f = module.ekf_mode_update()
    setup, logic, cases = mode_cases
    p = setup.p
    elements = list(logic.elements)
    assert [e["name"] for e in module.EKF_MODE_ELEMENTS] == elements
    worst, switched, kinds, locked = 0.0, 0, set(), 0
    for z, P, u, before in cases:
        z_ref, P_ref, after, events = ekf_mode_update(logic, z, P, u, p, before)
        x, P_new, modes, count = f(z, P, u, p, [before[e] for e in elements])
        assert [int(v) for v in np.asarray(modes).ravel()] == [after[e] for e in elements], before
        assert int(count) == len(events)
        switched += len(events)
        kinds |= {ev.kind for ev in events}
        locked += any(ev.kind == LOCK_UP and ev.after == STICK for ev in events)
        worst = max(
            worst,
            _scaled_error(np.asarray(x).ravel(), np.asarray(P_new), z_ref, P_ref),
        )
    print(
        f"CasADi mode update: {len(cases)} cases, {switched} switches ({locked} mapping "
        f"lock-ups), worst {worst:.2e}"
    )
    # every kind of switch taken, including lock-ups that map x and P
    assert kinds == {BREAK_AWAY, LOCK_UP, OPENING, ENGAGEMENT}, kinds
    assert locked >= 5, locked  # lock-ups that map x and P through A
    assert switched >= 20
    assert worst < 1e-12, worst
