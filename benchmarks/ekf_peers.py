"""The 2-3 EKF (thesis 4.1, 4.3) three ways, on one measurement sequence: shared by
``bench_ekf.py`` and ``tests/test_ekf_bench_agreement.py``.

* the emitted C (``gearsym_ekf_2_3_ekf_predict`` + ``_ekf_update``), double and float, called
  in a C loop by a small driver compiled here (:func:`driver_source`);
* CasADi used as intended: one ``casadi.Function`` of a whole filter step (predict + the three
  scalar updates) built from the *emitted CasADi module*'s ``rhs`` and ``outputs``, with CasADi's
  own AD (``jacobian``) for the RK4 step's F and for H, and its CSE; called from Python and as
  ``CodeGenerator`` C in the same C loop;
* FilterPy's ``ExtendedKalmanFilter`` with NumPy functions: the model's right-hand side, its
  Jacobian ∂f/∂z and the outputs **lambdified by SymPy to NumPy** (not the CasADi functions),
  the RK4 step and its exact Jacobian by the chain rule in NumPy, FilterPy's own ``predict``
  (F P Fᵀ + Q) and ``update`` (batch over the three speeds, Joseph form).

All three are the same filter. Two places need a word:

* The emitted filter updates one speed at a time; FilterPy updates the three at once. With a
  diagonal R and outputs linear in the state (y = the three speeds) the two are the same
  update in exact arithmetic.
* A μ whose element does not slide is a Schmidt *consider* state in the emitted filter (gain
  entry 0). FilterPy has no such option; since H does not see μ (H's μ columns are 0), the
  consider update equals the optimal update with the frozen states' estimates and their
  covariance block put back afterwards (the estimated block and the cross-covariances are the
  same in both), which is what the FilterPy peer does.
"""

from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

SHIFT = "2-3"
PREFIX = "gearsym_ekf_2_3_"
SAMPLE_TIME = 0.01
SEED = 0


@dataclass
class Sequence:
    """One measurement sequence and the filter's start, the same for every implementation.

    Sample k = 0 is the project's initial update (:func:`filter_run`); the timed steps are
    k = 1 .. N-1, each a predict with u[k-1] and an update with u[k], y[k]."""

    aug: Any
    h: float
    u: np.ndarray  # (N, nu)
    y: np.ndarray  # (N, ny)
    p: np.ndarray  # fixed parameters, struct order
    q: np.ndarray  # intensities per state
    r: np.ndarray  # relative noise per output (3.26)
    floor: np.ndarray
    x1: np.ndarray  # estimate after the update at k = 0
    P1: np.ndarray
    reference: np.ndarray  # (N, nx): the project's NumPy reference filter (filter_run)
    reference_sigma: np.ndarray

    @property
    def steps(self) -> int:
        return len(self.u) - 1


def sequence(seed: int = SEED, sample_time: float = SAMPLE_TIME) -> Sequence:
    """The default 2-3 shift, speeds with 1 % noise drawn from ``seed`` as
    :func:`gearsym.validation.studies.estimation.loop.filter_run` draws them, and that run's
    estimates."""
    from gearsym.symbolic.estimators.ekf import ekf_update
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.sim.scenario import load_scenario
    from gearsym.validation.sim.simulate import simulate
    from gearsym.validation.studies.estimation.loop import filter_run, start_from_first_measurement
    from gearsym.validation.studies.estimation.setup import prepare_ekf

    d = load_description(None)
    result = simulate(d, load_scenario(d, None))
    # the peers take u as given; started 30 % light (1260 kg) so that the mass moves over the
    # shift and the agreement is not that of a still filter
    s = prepare_ekf(d, result, sample_time, initial={"m_veh": 1260.0}, modes="reference")
    y = s.y_true + np.random.default_rng(seed).normal(0.0, 1.0, s.y_true.shape) * s.sigma_y
    z, sig0 = s.initial.copy(), s.prior_sigma.copy()
    first = start_from_first_measurement(s, y[0], z, sig0)  # as filter_run starts
    P = np.diag(sig0**2)
    z, P, _, _ = ekf_update(s.discrete, z, P, s.u[0], first, s.p, s.relative, s.floor)
    run = filter_run(s, seed)
    return Sequence(
        aug=s.aug,
        h=float(s.t[1] - s.t[0]),
        u=np.asarray(s.u, dtype=float),
        y=y,
        p=np.asarray(s.p, dtype=float),
        q=np.asarray(s.q, dtype=float),
        r=np.asarray(s.relative, dtype=float),
        floor=np.asarray(s.floor, dtype=float),
        x1=z,
        P1=P,
        reference=run.estimates,
        reference_sigma=run.sigmas,
    )


def frozen_pairs(aug: Any) -> list[tuple[int, int]]:
    """(state index of a μ, input index of its slide_<E>) per augmented μ."""
    from gearsym.symbolic.estimators.ekf import slide_input

    states, inputs = aug.state_names, aug.input_names
    return [(states.index(mu), inputs.index(slide_input(e))) for e, mu in aug.mu_state.items()]


# ---------------------------------------------------------------------------------------------
# FilterPy
# ---------------------------------------------------------------------------------------------


class FilterPyPeer:
    """FilterPy's ExtendedKalmanFilter with SymPy-lambdified NumPy f, ∂f/∂z, h, ∂h/∂z.

    ``consider=False`` drops the consider-state handling (FilterPy's plain update corrects a
    frozen μ too): a different filter, for the test that the comparison can tell."""

    def __init__(self, seq: Sequence, consider: bool = True) -> None:
        import sympy as sp
        from filterpy.kalman import ExtendedKalmanFilter

        model = seq.aug.model
        args = [list(model.state_symbols), list(model.input_symbols), list(model.parameter_symbols)]
        outputs = sp.Matrix(model.output_expressions)
        self._f = sp.lambdify(args, sp.Matrix(model.rhs), "numpy")
        self._J = sp.lambdify(args, sp.Matrix(seq.aug.jacobian), "numpy")
        self._h = sp.lambdify(args, outputs, "numpy")
        self._H = sp.lambdify(args, outputs.jacobian(list(model.state_symbols)), "numpy")
        self.seq = seq
        self.consider = consider
        n = len(seq.x1)
        self._eye = np.eye(n)
        self._pairs = frozen_pairs(seq.aug)
        self.ekf = ExtendedKalmanFilter(dim_x=n, dim_z=len(seq.r))
        self._next = np.zeros((n, 1))
        self.ekf.predict_x = self._predict_x  # the nonlinear step, as FilterPy's docs advise
        self.reset()

    def reset(self) -> None:
        self.ekf.x = self.seq.x1.reshape(-1, 1).copy()
        self.ekf.P = self.seq.P1.copy()

    def _predict_x(self, u: Any = 0) -> None:
        self.ekf.x = self._next

    def _rk4(self, z: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """RK4 step and its exact Jacobian (chain rule through the stages)."""
        p, h, eye = self.seq.p, self.seq.h, self._eye
        f, J = self._f, self._J
        k1 = f(z, u, p).ravel()
        K1 = np.asarray(J(z, u, p), dtype=float)
        z2 = z + 0.5 * h * k1
        k2 = f(z2, u, p).ravel()
        K2 = np.asarray(J(z2, u, p), dtype=float) @ (eye + 0.5 * h * K1)
        z3 = z + 0.5 * h * k2
        k3 = f(z3, u, p).ravel()
        K3 = np.asarray(J(z3, u, p), dtype=float) @ (eye + 0.5 * h * K2)
        z4 = z + h * k3
        k4 = f(z4, u, p).ravel()
        K4 = np.asarray(J(z4, u, p), dtype=float) @ (eye + h * K3)
        z_next = z + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
        return z_next, eye + (h / 6.0) * (K1 + 2.0 * (K2 + K3) + K4)

    def _hx(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.asarray(self._h(x.ravel(), u, self.seq.p), dtype=float)

    def _hjac(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.asarray(self._H(x.ravel(), u, self.seq.p), dtype=float)

    def step(self, k: int) -> None:
        """Predict with u[k-1], update with u[k] and y[k]."""
        seq, ekf = self.seq, self.ekf
        u_prev, u, y = seq.u[k - 1], seq.u[k], seq.y[k]
        z_next, F = self._rk4(ekf.x.ravel(), u_prev)
        rate = seq.q.copy()
        for state, slide in self._pairs:
            if not u_prev[slide] > 0.5:
                rate[state] = 0.0
        self._next = z_next.reshape(-1, 1)
        ekf.F = F
        ekf.Q = np.diag(seq.h * rate)
        ekf.predict()
        frozen = [state for state, slide in self._pairs if self.consider and not u[slide] > 0.5]
        kept_x = ekf.x[frozen].copy()
        kept_P = ekf.P[np.ix_(frozen, frozen)].copy()
        R = np.diag((seq.r * np.maximum(np.abs(y), seq.floor)) ** 2)  # (3.26)
        ekf.update(y.reshape(-1, 1), self._hjac, self._hx, R=R, args=(u,), hx_args=(u,))
        ekf.x[frozen] = kept_x  # a consider state: no correction, its variance kept
        ekf.P[np.ix_(frozen, frozen)] = kept_P

    def run(self) -> tuple[np.ndarray, np.ndarray]:
        """Estimates and σ after each step k = 1 .. N-1."""
        self.reset()
        xs, sigmas = [], []
        for k in range(1, len(self.seq.u)):
            self.step(k)
            xs.append(self.ekf.x.ravel().copy())
            sigmas.append(np.sqrt(np.diag(self.ekf.P)))
        return np.array(xs), np.array(sigmas)


# ---------------------------------------------------------------------------------------------
# CasADi
# ---------------------------------------------------------------------------------------------


def casadi_step(module: Any, aug: Any, name: str = "cas_ekf_step") -> Any:
    """One filter step as a ``casadi.Function``:
    (x, P, u_prev, u, y, p, h, q, r, floor) -> (x_next, P_next, nis).

    From the emitted module's ``rhs`` and ``outputs``; F = ∂Φ_h/∂x and H = ∂y/∂x by CasADi's AD;
    the same frozen-μ rules and sequential Joseph updates as the emitted C; CSE on. No NaN
    skipping (the benchmark's sequence has no dropout)."""
    import casadi as ca

    fns = module.functions()
    rhs, outputs = fns["rhs"], fns["outputs"]
    nx, nu, npar, ny = module.NX, module.NU, module.NP, module.NY
    x, P = ca.SX.sym("x", nx), ca.SX.sym("P", nx, nx)
    u_prev, u, y = ca.SX.sym("u_prev", nu), ca.SX.sym("u", nu), ca.SX.sym("y", ny)
    p, h, q = ca.SX.sym("p", npar), ca.SX.sym("h"), ca.SX.sym("q", nx)
    r, floor = ca.SX.sym("r", ny), ca.SX.sym("floor", ny)
    k1 = rhs(x, u_prev, p)
    k2 = rhs(x + 0.5 * h * k1, u_prev, p)
    k3 = rhs(x + 0.5 * h * k2, u_prev, p)
    k4 = rhs(x + h * k3, u_prev, p)
    x_next = x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
    F = ca.jacobian(x_next, x)
    pairs = frozen_pairs(aug)
    rate = [q[i] for i in range(nx)]
    for state, slide in pairs:
        rate[state] = ca.if_else(u_prev[slide] > 0.5, q[state], 0.0)
    Pk = F @ P @ F.T + ca.diag(h * ca.vertcat(*rate))
    Pk = 0.5 * (Pk + Pk.T)
    xs = ca.SX.sym("xs", nx)
    H_fn = ca.Function("H", [xs, u, p], [ca.jacobian(outputs(xs, u, p), xs)])
    xk, nis = x_next, 0
    eye = ca.SX.eye(nx)
    for i in range(ny):
        y_hat = outputs(xk, u, p)
        H = H_fn(xk, u, p)[i, :]
        R = (r[i] * ca.fmax(ca.fabs(y[i]), floor[i])) ** 2  # (3.26)
        v = Pk @ H.T
        s = H @ v + R
        gain = [v[a] / s for a in range(nx)]
        for state, slide in pairs:
            gain[state] = ca.if_else(u[slide] > 0.5, gain[state], 0.0)
        k = ca.vertcat(*gain)
        innovation = y[i] - y_hat[i]
        xk = xk + k * innovation
        A = eye - k @ H
        Pk = A @ Pk @ A.T + R * (k @ k.T)
        Pk = 0.5 * (Pk + Pk.T)
        nis = nis + innovation**2 / s
    return ca.Function(
        name,
        [x, P, u_prev, u, y, p, h, q, r, floor],
        [xk, Pk, nis],
        ["x", "P", "u_prev", "u", "y", "p", "h", "q", "r", "floor"],
        ["x_next", "P_next", "nis"],
        {"cse": True},
    )


def run_casadi(step: Any, seq: Sequence) -> tuple[np.ndarray, np.ndarray]:
    """The CasADi step called from Python over the sequence: estimates and σ per step."""
    x, P = seq.x1, seq.P1
    xs, sigmas = [], []
    for k in range(1, len(seq.u)):
        args = (seq.u[k - 1], seq.u[k], seq.y[k], seq.p, seq.h, seq.q, seq.r, seq.floor)
        x, P, _ = step(x, P, *args)
        xs.append(np.asarray(x, dtype=float).ravel())
        sigmas.append(np.sqrt(np.diag(np.asarray(P, dtype=float))))
    return np.array(xs), np.array(sigmas)


def casadi_c(step: Any, out: Path, real: str) -> Path:
    """``CodeGenerator`` C of the step function, ``casadi_real`` = ``real``."""
    import casadi as ca

    name = step.name()
    cg = ca.CodeGenerator(f"{name}.c", {"with_header": True, "casadi_real": real})
    cg.add(step)
    out.mkdir(parents=True, exist_ok=True)
    cg.generate(str(out) + "/")
    return out / f"{name}.c"


# ---------------------------------------------------------------------------------------------
# The C driver
# ---------------------------------------------------------------------------------------------

#: The C implementations in the order of the driver's RUN table (its `T which ...` lines).
C_IMPLEMENTATIONS = ("gearsym double", "gearsym float", "CasADi C double", "CasADi C float")


def _array(name: str, values: np.ndarray, ctype: str = "double") -> str:
    flat = np.asarray(values, dtype=float).ravel()
    body = ", ".join(repr(float(v)) for v in flat)
    return f"static const {ctype} {name}[{len(flat)}] = {{{body}}};"


def driver_source(seq: Sequence, cas: dict[str, Any]) -> str:
    """C99 driver: ``driver values`` prints every implementation's estimates and σ per step;
    ``driver time ROUNDS PASSES`` prints ``T impl round ns_per_step`` lines, the order of the
    implementations rotated from round to round. ``cas``: real -> the CasADi step Function."""
    nx, nu, ny, npar = len(seq.x1), seq.u.shape[1], seq.y.shape[1], len(seq.p)
    n = len(seq.u)
    P1 = np.asarray(seq.P1).ravel(order="F")
    lines = [
        "#define _POSIX_C_SOURCE 199309L /* clock_gettime */",
        "#include <math.h>",
        "#include <stdio.h>",
        "#include <stdlib.h>",
        "#include <string.h>",
        "#include <time.h>",
        '#include "gearsym_ekf_2_3.h"',
        '#include "cas_ekf_step_d.h"',
        f"typedef struct {{ float v[{npar}]; }} f32_params;",
        "void f32_gearsym_ekf_2_3_ekf_predict(float *, float *, const float *, "
        "const f32_params *, float, const float *);",
        "int f32_gearsym_ekf_2_3_ekf_update(float *, float *, const float *, const f32_params *, "
        "const float *, const float *, const float *, float *);",
        "int cas_ekf_step_f(const float **, float **, long long *, float *, int);",
        f"#define NX {nx}",
        f"#define NU {nu}",
        f"#define NY {ny}",
        f"#define NP {npar}",
        f"#define N {n}",
        _array("U", seq.u),
        _array("Y", seq.y),
        _array("X1", seq.x1),
        _array("P1", P1),
        _array("PAR", seq.p),
        _array("Q", seq.q),
        _array("R", seq.r),
        _array("FLOOR", seq.floor),
        f"static const double H = {seq.h!r};",
        "static float Uf[N * NU], Yf[N * NY], X1f[NX], P1f[NX * NX], Qf[NX], Rf[NY], FLf[NY];",
        "static f32_params PARf;",
        "static gearsym_ekf_2_3_params PARd;",
        "static volatile double sink;",
        "static double now(void) {",
        "    struct timespec t;",
        "    clock_gettime(CLOCK_MONOTONIC, &t);",
        "    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;",
        "}",
        "static void show(const char *impl, int k, const double *x, const double *P) {",
        '    printf("V %s %d", impl, k);',
        '    for (int i = 0; i < NX; ++i) printf(" %.17g", x[i]);',
        '    for (int i = 0; i < NX; ++i) printf(" %.17g", sqrt(P[i + i * NX]));',
        '    printf("\\n");',
        "}",
        "static void showf(const char *impl, int k, const float *x, const float *P) {",
        "    double xd[NX], Pd[NX * NX];",
        "    for (int i = 0; i < NX; ++i) xd[i] = x[i];",
        "    for (int i = 0; i < NX * NX; ++i) Pd[i] = P[i];",
        "    show(impl, k, xd, Pd);",
        "}",
        # gearsym double
        "static double run_gs_d(long passes, int print) {",
        "    double x[NX], P[NX * NX], nis;",
        "    double t0 = now();",
        "    for (long pass = 0; pass < passes; ++pass) {",
        "        memcpy(x, X1, sizeof x); memcpy(P, P1, sizeof P);",
        "        for (int k = 1; k < N; ++k) {",
        "            gearsym_ekf_2_3_ekf_predict(x, P, &U[(k - 1) * NU], &PARd, H, Q);",
        "            gearsym_ekf_2_3_ekf_update(x, P, &U[k * NU], &PARd, &Y[k * NY], R, FLOOR,"
        " &nis);",
        '            if (print) show("gearsym_double", k, x, P);',
        "        }",
        "        sink += x[4];",
        "    }",
        "    return (now() - t0) / (double)(passes * (N - 1));",
        "}",
        # gearsym float
        "static double run_gs_f(long passes, int print) {",
        "    float x[NX], P[NX * NX], nis;",
        "    double t0 = now();",
        "    for (long pass = 0; pass < passes; ++pass) {",
        "        memcpy(x, X1f, sizeof x); memcpy(P, P1f, sizeof P);",
        "        for (int k = 1; k < N; ++k) {",
        "            f32_gearsym_ekf_2_3_ekf_predict(x, P, &Uf[(k - 1) * NU], &PARf, (float)H,"
        " Qf);",
        "            f32_gearsym_ekf_2_3_ekf_update(x, P, &Uf[k * NU], &PARf, &Yf[k * NY], Rf, FLf,"
        " &nis);",
        '            if (print) showf("gearsym_float", k, x, P);',
        "        }",
        "        sink += x[4];",
        "    }",
        "    return (now() - t0) / (double)(passes * (N - 1));",
        "}",
    ]
    for real, ctype, suffix in (("double", "double", "d"), ("float", "float", "f")):
        f = cas[real]
        data = "" if suffix == "d" else "f"
        hd = "Hd" if suffix == "d" else "Hf"
        floor_name = "FLOOR" if suffix == "d" else "FLf"
        show = "show" if suffix == "d" else "showf"
        lines += [
            f"static {ctype} cas_w_{suffix}[{f.sz_w() + 1}];",
            f"static long long cas_iw_{suffix}[{f.sz_iw() + 1}];",
            f"static double run_cas_{suffix}(long passes, int print) {{",
            f"    {ctype} xa[NX], Pa[NX * NX], xb[NX], Pb[NX * NX], nis;",
            f"    const {ctype} *arg[{f.sz_arg() + 1}];",
            f"    {ctype} *res[{f.sz_res() + 1}];",
            f"    const {ctype} {hd} = ({ctype})H;",
            "    double t0 = now();",
            "    for (long pass = 0; pass < passes; ++pass) {",
            f"        {ctype} *x = xa, *P = Pa, *xn = xb, *Pn = Pb, *tmp;",
            f"        memcpy(xa, X1{data}, sizeof xa); memcpy(Pa, P1{data}, sizeof Pa);",
            "        for (int k = 1; k < N; ++k) {",
            f"            arg[0] = x; arg[1] = P; arg[2] = &U{data}[(k - 1) * NU];",
            f"            arg[3] = &U{data}[k * NU]; arg[4] = &Y{data}[k * NY];",
            f"            arg[5] = {'PAR' if suffix == 'd' else 'PARf.v'}; arg[6] = &{hd};",
            f"            arg[7] = Q{data}; arg[8] = R{data}; arg[9] = {floor_name};",
            "            res[0] = xn; res[1] = Pn; res[2] = &nis;",
            f"            cas_ekf_step_{suffix}(arg, res, (void *)cas_iw_{suffix},"
            f" cas_w_{suffix}, 0);",
            "            tmp = x; x = xn; xn = tmp; tmp = P; P = Pn; Pn = tmp;",
            f'            if (print) {show}("casadi_c_{real}", k, x, P);',
            "        }",
            "        sink += x[4];",
            "    }",
            "    return (now() - t0) / (double)(passes * (N - 1));",
            "}",
        ]
    lines += [
        "typedef double (*runner)(long, int);",
        "static const runner RUN[4] = {run_gs_d, run_gs_f, run_cas_d, run_cas_f};",
        "int main(int argc, char **argv) {",
        "    int i;",
        "    for (i = 0; i < N * NU; ++i) Uf[i] = (float)U[i];",
        "    for (i = 0; i < N * NY; ++i) Yf[i] = (float)Y[i];",
        "    for (i = 0; i < NX; ++i) { X1f[i] = (float)X1[i]; Qf[i] = (float)Q[i]; }",
        "    for (i = 0; i < NX * NX; ++i) P1f[i] = (float)P1[i];",
        "    for (i = 0; i < NY; ++i) { Rf[i] = (float)R[i]; FLf[i] = (float)FLOOR[i]; }",
        "    for (i = 0; i < NP; ++i) PARf.v[i] = (float)PAR[i];",
        "    memcpy(&PARd, PAR, sizeof PARd);",
        '    if (argc > 1 && strcmp(argv[1], "values") == 0) {',
        "        for (i = 0; i < 4; ++i) RUN[i](1, 1);",
        "        return 0;",
        "    }",
        "    const int rounds = atoi(argv[2]);",
        "    const long passes = atol(argv[3]);",
        "    for (i = 0; i < 4; ++i) RUN[i](passes / 4 + 1, 0); /* warm-up */",
        "    for (int r = 0; r < rounds; ++r) {",
        "        for (int s = 0; s < 4; ++s) {",
        "            const int which = (r + s) % 4;",
        '            printf("T %d %d %.4f\\n", which, r, 1e9 * RUN[which](passes, 0));',
        "        }",
        "    }",
        '    printf("sink %g\\n", sink);',
        "    return 0;",
        "}",
    ]
    return "\n".join(lines) + "\n"


def run_cmd(cmd: list[str], cwd: Path | None = None) -> str:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)}\n{proc.stdout}{proc.stderr}")
    return proc.stdout


@dataclass
class Build:
    """The compiled driver and what was measured on its objects."""

    exe: Path
    objects: dict[str, Path]  # "gearsym double", "gearsym float", "CasADi C double", ...


def build_driver(seq: Sequence, build: Path, flags: tuple[str, ...] = ("-O2",)) -> Build:
    """Emit the EKF's C, generate CasADi's C of the step (double and float), compile each as
    its own translation unit with ``flags`` (the float gearsym object's symbols renamed
    ``f32_...`` so both precisions link into one program) and link the driver."""
    import importlib.util

    from gearsym.symbolic.codegen import emit_all
    from gearsym.symbolic.export.generate import ekf_model
    from gearsym.symbolic.loader import load_description
    from gearsym.symbolic.shifts import shift_spec

    d = load_description(None)
    m = ekf_model(d, shift_spec(d, SHIFT))
    files = emit_all(m.model, m.config)
    build.mkdir(parents=True, exist_ok=True)
    for rel, text in files.items():
        (build / Path(rel).name).write_text(text, encoding="utf-8")
    spec = importlib.util.spec_from_file_location(
        "gearsym_ekf_2_3_casadi", build / "gearsym_ekf_2_3_casadi.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    cas = {
        "double": casadi_step(module, seq.aug, "cas_ekf_step_d"),
        "float": casadi_step(module, seq.aug, "cas_ekf_step_f"),
    }
    casadi_c(cas["double"], build, "double")
    casadi_c(cas["float"], build, "float")
    (build / "driver.c").write_text(driver_source(seq, cas), encoding="utf-8")
    cc = ["gcc", "-std=c99", *flags, "-I", str(build)]
    objects = {
        "gearsym double": build / "gs_d.o",
        "gearsym float": build / "gs_f.o",
        "CasADi C double": build / "cas_d.o",
        "CasADi C float": build / "cas_f.o",
    }
    run_cmd([*cc, "-c", str(build / "gearsym_ekf_2_3.c"), "-o", str(objects["gearsym double"])])
    single = ["-DGEARSYM_SINGLE_PRECISION"]
    run_cmd([*cc, *single, "-c", str(build / "gearsym_ekf_2_3.c"), "-o", str(build / "f.o")])
    defined = run_cmd(["nm", "--defined-only", "-g", str(build / "f.o")]).split("\n")
    names = [line.split()[-1] for line in defined if line.strip()]
    renames = build / "renames.txt"
    renames.write_text("".join(f"{s} f32_{s}\n" for s in names), encoding="utf-8")
    run_cmd(
        [
            "objcopy",
            f"--redefine-syms={renames}",
            str(build / "f.o"),
            str(objects["gearsym float"]),
        ]
    )
    run_cmd([*cc, "-c", str(build / "cas_ekf_step_d.c"), "-o", str(objects["CasADi C double"])])
    run_cmd([*cc, "-c", str(build / "cas_ekf_step_f.c"), "-o", str(objects["CasADi C float"])])
    driver = build / "driver.o"
    run_cmd([*cc, "-c", str(build / "driver.c"), "-o", str(driver)])
    exe = build / "driver"
    run_cmd(["gcc", str(driver), *(str(o) for o in objects.values()), "-o", str(exe), "-lm"])
    return Build(exe, objects)


def c_values(build: Build) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every C implementation's estimates and σ per step, keyed by its label in the driver."""
    rows: dict[str, list[list[float]]] = {}
    for line in run_cmd([str(build.exe), "values"]).splitlines():
        fields = line.split()
        if fields and fields[0] == "V":
            rows.setdefault(fields[1], []).append([float(v) for v in fields[3:]])
    result = {}
    for impl, values in rows.items():
        a = np.array(values)
        half = a.shape[1] // 2
        result[impl] = (a[:, :half], a[:, half:])
    return result


def scaled_difference(
    x: np.ndarray, sigma: np.ndarray, x_ref: np.ndarray, sigma_ref: np.ndarray
) -> float:
    """Largest difference over every step and state, estimates against |x_ref| + σ_ref, σ
    against σ_ref (as tests/test_ekf_c.py scales them)."""
    ex = np.abs(x - x_ref) / (np.abs(x_ref) + sigma_ref)
    es = np.abs(sigma - sigma_ref) / np.maximum(sigma_ref, 1e-300)
    return float(max(ex.max(), es.max()))


def symbol_sizes(obj: Path) -> dict[str, int]:
    """Defined function symbols of an object and their sizes in bytes (``nm -S``)."""
    sizes = {}
    for line in run_cmd(["nm", "-S", "--defined-only", str(obj)]).splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "tT":
            sizes[parts[3]] = int(parts[1], 16)
    return sizes


def text_size(obj: Path) -> int:
    """The .text section of an object (``size``, Berkeley format's first column)."""
    out = run_cmd(["size", str(obj)]).splitlines()[1].split()
    return int(out[0])


def stated_operations(header: str, function: str) -> dict[str, int]:
    """The operation count that the emitted header states for ``function`` (its doc comment
    just above the declaration)."""
    at = header.index(f"void {PREFIX}{function}(") if f"void {PREFIX}{function}(" in header else -1
    if at < 0:
        at = header.index(f"int {PREFIX}{function}(")
    comment = header[header.rindex("/**", 0, at) : at]
    text = " ".join(comment.replace("*", " ").split())
    found = re.search(
        r"Operations(?: \(about\))?: (\d+) add, (\d+) mul, (\d+) div, (\d+) calls"
        r"(?: \([^)]*\))?(?:, (\d+) select)?(?:, (\d+) cmp)?",
        text,
    )
    add, mul, div, calls, select, cmp = (int(v or 0) for v in found.groups())
    return {"add": add, "mul": mul, "div": div, "calls": calls, "select": select, "cmp": cmp}
