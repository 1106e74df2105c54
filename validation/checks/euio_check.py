"""The emitted extended UIO (thesis 4.5) of a generated tree against the library's filter, for
``gearsym generate --check`` (:func:`gearsym.validation.checks.generated_check.check_tree`).

The step ``gearsym_euio_<a>_<b>_euio_step`` of the files on disk (C double, C single) and the
CasADi module's ``euio_step()`` are run from the library's state before every step of the
default shift's EUIO run (:func:`reference_steps`: the reference simulation sampled at 10 ms,
1 % speed noise (3.26), the reference's element modes, the held masks of
:func:`~gearsym.validation.studies.euio_evaluation.prepare_euio`, a one-sensor dropout every 23
samples) and compared with :func:`~gearsym.symbolic.estimators.euio.euio_step_full` (CasADi
evaluation of the SymPy model, dense NumPy algebra with ``np.linalg.inv``), the same metric
as ``tests/test_euio_c.py``: each quantity in its own scale (x_i against |x_i| + σ_i, P_ij
against σ_i σ_j, d̂ against |d̂| + σ_d, σ_d² relative, the NIS νᵀS⁻¹ν − d̂²/σ_d² against
|NIS| + d̂²/σ_d² + 1). The single build is compared with the library run on the same
arguments rounded to float (as :mod:`.uio_check` does), so that only its own rounding counts.
A status other than the library's (OK; ERR_NONFINITE with a NaN load at a dropout) is an
error of ∞. Targets 1e-12 (double, CasADi) and 1e-5 (single).
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.validation.checks import c_check

__all__ = ["EuioCase", "EuioCaseStep", "compare_euio", "reference_steps"]

OK, ERR_NONFINITE = 0, 1
SAMPLE_TIME = 0.01
SEED = 3
#: Every this many samples one speed sensor drops out (a NaN: the update is skipped).
DROPOUT_EVERY = 23


@dataclass(frozen=True)
class EuioCaseStep:
    """The arguments of one step (held as 0/1 per state) and the library's result."""

    z: np.ndarray
    P: np.ndarray
    u_prev: np.ndarray
    u: np.ndarray
    y: np.ndarray
    held: np.ndarray
    result: Any  # EuioStep


@dataclass(frozen=True)
class EuioCase:
    """The library's EUIO run as the emitted step sees it: ``p`` in the C struct's order."""

    steps: tuple[EuioCaseStep, ...]
    p: np.ndarray  # the emitted model's parameter values, in its order
    p_names: tuple[str, ...]  # their names
    p_library: list[float]  # the library model's parameter values (its order)
    q: np.ndarray
    r: np.ndarray
    floor: np.ndarray
    h: float
    setup: Any = None  # the EuioSetup (discrete model, load column constants)


def reference_steps(
    d: Any,
    model: Any = None,
    sample_time: float = SAMPLE_TIME,
    seed: int = SEED,
    dropout_every: int = DROPOUT_EVERY,
    result: Any = None,
) -> EuioCase:
    """The library's EUIO run along the default shift of ``d`` (module text), step by step.
    ``model``: the emitted EUIO model (its parameter order; ``None``: the library's order);
    ``result`` reuses a reference simulation."""
    from gearsym.symbolic.estimators.euio import euio_step_full, load_column
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.loop import noisy_outputs
    from gearsym.validation.studies.euio_evaluation import prepare_euio

    if result is None:
        result = simulate(d, load_scenario(d, None))
    # the reference path: s.u holds the reference's element modes, held(k) its phases' masks
    setup = prepare_euio(d, result, sample_time, modes="reference")
    s = setup.ekf
    aug, discrete = s.aug, s.discrete
    names = [v.name for v in aug.model.parameters]
    if model is not None:
        if [v.name for v in model.states] != aug.state_names:
            raise ValueError(f"emitted EUIO states {[v.name for v in model.states]} differ")
        p_names = tuple(v.name for v in model.parameters)
    else:
        p_names = tuple(names)
    p_c = np.array([setup.p[names.index(name)] for name in p_names])
    y = noisy_outputs(s, seed)
    for k in range(17, len(y), dropout_every) if dropout_every > 0 else ():  # 0: none
        y[k, k % y.shape[1]] = np.nan
    z = s.initial.copy()
    for j, name in enumerate(s.outputs):
        if name in aug.state_names:
            z[aug.state_names.index(name)] = y[0, j]
    P = np.diag(s.prior_sigma**2)
    q = np.array(s.q, dtype=float)
    h = float(s.t[1] - s.t[0])
    steps = []
    for k in range(1, len(s.t)):
        hold = setup.held(k)
        mask = np.zeros(len(z))
        mask[hold] = 1.0
        R = (s.relative * np.maximum(np.abs(y[k]), s.floor)) ** 2
        e = load_column(discrete, z, setup.r_dyn, setup.p, setup.i_wheel)
        step = euio_step_full(discrete, z, P, s.u[k - 1], s.u[k], y[k], R, h, setup.p, q, e, hold)
        steps.append(EuioCaseStep(z, P, s.u[k - 1], s.u[k], y[k].copy(), mask, step))
        z, P = step.z, step.P
    return EuioCase(
        steps=tuple(steps),
        p=p_c,
        p_names=p_names,
        p_library=list(setup.p),
        q=q,
        r=np.array(s.relative, dtype=float),
        floor=np.array(s.floor, dtype=float),
        h=h,
        setup=setup,
    )


def _rounded(case: EuioCase, step: EuioCaseStep) -> tuple[dict[str, np.ndarray], Any]:
    """The step's arguments rounded to float and the library's step on them (the reference
    of the single build)."""
    from gearsym.symbolic.estimators.euio import euio_step_full, load_column

    def f32(v: Any) -> np.ndarray:
        return np.asarray(v, dtype=np.float32).astype(np.float64)

    setup = case.setup
    s = setup.ekf
    args = {
        "z": f32(step.z),
        "P": f32(step.P),
        "u_prev": f32(step.u_prev),
        "u": f32(step.u),
        "y": f32(step.y),
        "q": f32(case.q),
        "r": f32(case.r),
        "floor": f32(case.floor),
        "p": f32(case.p),
        "h": f32(case.h),
    }
    names = [v.name for v in s.aug.model.parameters]
    p_lib = list(case.p_library)
    emitted = dict(zip(case.p_names, args["p"], strict=True))
    p_lib = [float(emitted.get(n, v)) for n, v in zip(names, p_lib, strict=True)]
    i_wheel = float(emitted.get("I_wheel", setup.i_wheel))
    R = (args["r"] * np.maximum(np.abs(args["y"]), args["floor"])) ** 2
    e = load_column(s.discrete, args["z"], setup.r_dyn, p_lib, i_wheel)
    held = list(np.flatnonzero(step.held > 0.5))
    result = euio_step_full(
        s.discrete,
        args["z"],
        args["P"],
        args["u_prev"],
        args["u"],
        args["y"],
        R,
        float(args["h"]),
        p_lib,
        args["q"],
        e,
        held,
    )
    return args, result


def _errors(x: np.ndarray, P: np.ndarray, load: np.ndarray, s: Any) -> dict[str, float]:
    """Scaled differences of one step's results (module text)."""
    sigma = np.sqrt(np.diag(s.P))
    out = {
        "x": float(np.max(np.abs(x - s.z) / (np.abs(s.z) + sigma))),
        "P": float(np.max(np.abs(P - s.P) / np.outer(sigma, sigma))),
    }
    if np.isfinite(s.d_hat):
        out["load"] = abs(load[0] - s.d_hat) / (abs(s.d_hat) + s.sigma_d)
        out["sigma_d2"] = abs(load[1] - s.sigma_d**2) / s.sigma_d**2
        out["nis"] = abs(load[2] - s.nis) / (abs(s.nis) + s.d_hat**2 / s.sigma_d**2 + 1.0)
    return {k: float(np.nan_to_num(v, nan=np.inf)) for k, v in out.items()}


def c_step(
    lib: ctypes.CDLL,
    prefix: str,
    single: bool,
    args: dict[str, np.ndarray],
    held: np.ndarray,
) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """Call ``<prefix>euio_step`` of a compiled EUIO: (status, x, P, load) in double."""
    real = ctypes.c_float if single else ctypes.c_double
    dtype = np.float32 if single else np.float64
    n = len(args["z"])
    x = np.array(args["z"], dtype=dtype)
    Pc = np.array(args["P"], dtype=dtype).ravel(order="F")
    keys = ("u_prev", "u", "q", "y", "r", "floor")
    bufs = {key: np.array(args[key], dtype=dtype) for key in keys}
    held_buf = np.array(held, dtype=dtype)
    load = np.zeros(3, dtype=dtype)
    fields = [(f"p{i}", real) for i in range(len(args["p"]))]
    params = type("Params", (ctypes.Structure,), {"_fields_": fields})(*map(float, args["p"]))
    fn = getattr(lib, prefix + "euio_step")
    fn.restype = ctypes.c_int

    def ptr(a: np.ndarray) -> Any:
        return a.ctypes.data_as(ctypes.POINTER(real))

    status = fn(
        ptr(x),
        ptr(Pc),
        ptr(bufs["u_prev"]),
        ptr(bufs["u"]),
        ctypes.byref(params),
        real(float(args["h"])),
        ptr(bufs["q"]),
        ptr(bufs["y"]),
        ptr(bufs["r"]),
        ptr(bufs["floor"]),
        ptr(held_buf),
        ptr(load),
    )
    P = Pc.reshape(n, n, order="F").astype(float)
    return int(status), x.astype(float), P, load.astype(float)


def _arguments(case: EuioCase, step: EuioCaseStep) -> dict[str, np.ndarray]:
    return {
        "z": step.z,
        "P": step.P,
        "u_prev": step.u_prev,
        "u": step.u,
        "y": step.y,
        "q": case.q,
        "r": case.r,
        "floor": case.floor,
        "p": case.p,
        "h": np.float64(case.h),
    }


def _status_error(status: int, load: np.ndarray, s: Any) -> float:
    """0 if the status and the load's NaN-ness are the library's, else ∞."""
    dropped = not np.isfinite(s.d_hat)
    if dropped:
        return 0.0 if status == ERR_NONFINITE and np.all(np.isnan(load)) else float("inf")
    return 0.0 if status == OK else float("inf")


def compare_euio(
    name: str,
    case: EuioCase,
    root: Path,
    build_dir: Path,
    targets: Sequence[str] = ("C double", "C single", "CasADi"),
) -> list[c_check.ComparisonReport]:
    """Reports ``<name> step: C double|C single|CasADi`` (``name`` e.g. ``euio_2_3``) with the
    largest scaled difference per quantity (``x``, ``P``, ``load``, ``sigma_d2``, ``nis``,
    ``status``) over the steps of ``case``, of the files under ``root``."""
    c_dir = root / "c"
    sources = {
        f: (c_dir / f).read_text(encoding="utf-8")
        for f in (f"gearsym_{name}.h", f"gearsym_{name}.c")
    }
    prefix = f"gearsym_{name}_"
    rounded = None
    reports = []
    for target in targets:
        single = target == "C single"
        report = c_check.ComparisonReport(f"{name} step: {target}", len(case.steps), 0.0)
        worst = dict.fromkeys(("x", "P", "load", "sigma_d2", "nis", "status"), 0.0)
        if target == "CasADi":
            module = c_check.load_casadi_module(root / "python" / f"gearsym_{name}_casadi.py")
            fn = module.euio_step()
        else:
            lib = ctypes.CDLL(str(c_check.compile_shared(sources, build_dir / name, single=single)))
        if single and rounded is None:
            rounded = [_rounded(case, st) for st in case.steps]
        for k, st in enumerate(case.steps):
            if single:
                assert rounded is not None
                args, want = rounded[k]
            else:
                args, want = _arguments(case, st), st.result
            if target == "CasADi":
                out = fn(
                    args["z"],
                    args["P"],
                    args["u_prev"],
                    args["u"],
                    args["p"],
                    float(args["h"]),
                    args["q"],
                    args["y"],
                    args["r"],
                    args["floor"],
                    st.held,
                )
                x, P, load = (np.asarray(v, dtype=float) for v in out)
                x, load = x.ravel(), load.ravel()
                status = OK if np.all(np.isfinite(load)) else ERR_NONFINITE
            else:
                status, x, P, load = c_step(lib, prefix, single, args, st.held)
            errors = _errors(x, P, load, want)
            errors["status"] = _status_error(status, load, want)
            for key, value in errors.items():
                if value > worst[key]:
                    worst[key] = value
                    report.worst_point[key] = k
        report.max_error.update(worst)
        reports.append(report)
    return reports
