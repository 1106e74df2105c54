"""The emitted hybrid sensitivities, driven through a shift, against the hybrid reference.

:class:`HybridFunctions` binds the compiled ``gearsym_hybrid_<a>_<b>_sens`` C functions
(ctypes). :func:`run_emitted` integrates a scenario with them alone, as a TCU would: classical
Runge-Kutta steps of each mode's augmented right-hand side (3.7) with the inputs evaluated at
the stages, the state-dependent guards (break-away, lock-up) located inside the step by Brent's
method on the Runge-Kutta interpolant, the switches at the scenario's breakpoints (opening,
engagement) taken as :class:`~gearsym.validation.sim.hybrid_simulation.HybridSimulator` takes them,
and every switch applied by the emitted jump function. The result is compared with the
simulator's sensitivities, which differentiate the mode models with CasADi's AD and apply the
jump formula numerically (an independent derivation of the same mathematics).
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gearsym.symbolic.codegen.hybrid import hybrid_table
from gearsym.symbolic.hybrid import ENGAGEMENT, OPEN, OPENING, STATE_GUARDS
from gearsym.symbolic.hybrid_sensitivity import HybridSensitivity
from gearsym.symbolic.naming import model_file_names
from gearsym.validation.checks import c_check
from gearsym.validation.checks.c_binding import load_casadi_module
from scipy.optimize import brentq

__all__ = ["EmittedRun", "HybridFunctions", "run_emitted"]

#: Guard kinds that depend on the state: located inside a step.
CONTINUOUS = STATE_GUARDS


class HybridFunctions:
    """The compiled C functions of one hybrid sensitivity set, called with NumPy vectors."""

    def __init__(self, lib_path: Path, hs: HybridSensitivity, single: bool = False) -> None:
        self.hs = hs
        self.real = ctypes.c_float if single else ctypes.c_double
        self.dtype = np.float32 if single else np.float64
        lib = ctypes.CDLL(str(lib_path))
        table = hybrid_table(hs)
        self.prefix = table.prefix
        fields = [(v.name, self.real) for v in table.model.parameters]
        self.Params = type("Params", (ctypes.Structure,), {"_fields_": fields})
        pointer = ctypes.POINTER(self.real)
        self._functions: dict[str, Any] = {}
        self._specs = {spec.name: spec for spec in table if spec.kind == "expr"}
        for name, spec in self._specs.items():
            fn = getattr(lib, table.prefix + name)
            fn.argtypes = [
                ctypes.POINTER(self.Params) if a.kind == "params" else pointer for a in spec.args
            ] + [pointer] * len(spec.outputs)
            fn.restype = None
            self._functions[name] = fn
        self._steps = {}
        for mode in hs.modes:
            fn = getattr(lib, f"{table.prefix}m{mode.index}_step")
            fn.argtypes = [pointer, pointer, ctypes.POINTER(self.Params), self.real, pointer]
            fn.restype = None
            self._steps[mode.index] = fn
        self._params: Any = None

    def set_parameters(self, p: Sequence[float]) -> None:
        """The parameter vector (the set's parameter order) every later call uses."""
        self._params = self.Params(*[self.real(v) for v in p])

    def _vector(self, values: Any) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(values, dtype=self.dtype))

    def call(self, name: str, **arrays: Any) -> list[np.ndarray]:
        """The outputs of function ``name`` (``m<i>_rhs``, ``m<i>_guards``, ``jump_<i>_<j>``)
        for the arguments given by name (``x``, ``u``, ``u_rate``; ``p`` from
        :meth:`set_parameters`)."""
        spec = self._specs[name]
        pointer = ctypes.POINTER(self.real)
        keep = []
        args: list[Any] = []
        for a in spec.args:
            if a.kind == "params":
                args.append(ctypes.byref(self._params))
            else:
                v = self._vector(arrays[a.name])
                assert v.shape == (a.size,), (name, a.name, v.shape)
                keep.append(v)
                args.append(v.ctypes.data_as(pointer))
        outputs = [np.zeros(max(o.size, 1), dtype=self.dtype) for o in spec.outputs]
        self._functions[name](*args, *(o.ctypes.data_as(pointer) for o in outputs))
        return [o[: s.size].astype(np.float64) for o, s in zip(outputs, spec.outputs, strict=True)]

    def step(self, mode: int, x: Any, u: Any, h: float) -> np.ndarray:
        """``m<i>_step``: one Runge-Kutta step with u held."""
        pointer = ctypes.POINTER(self.real)
        xv, uv = self._vector(x), self._vector(u)
        out = np.zeros_like(xv)
        self._steps[mode](
            xv.ctypes.data_as(pointer),
            uv.ctypes.data_as(pointer),
            ctypes.byref(self._params),
            self.real(h),
            out.ctypes.data_as(pointer),
        )
        return out.astype(np.float64)


@dataclass(frozen=True)
class EmittedRun:
    """Samples of :func:`run_emitted`: the augmented state [x; vec S] and mode index at each
    time of ``t``, and the switches (time, source index, target index, guard kind)."""

    t: np.ndarray
    states: tuple[np.ndarray, ...]
    modes: tuple[int, ...]
    events: tuple[tuple[float, int, int, str], ...]


def _locate(rk4: Any, guards: Any, mode: int, t: float, x: np.ndarray, dt: float, k: int) -> float:
    """θ in (0, 1] where guard k crosses zero on the Runge-Kutta step from (t, x): Brent's
    method on g(RK4(x, θ dt)) (a step of θ dt is as accurate as the full one)."""

    def value(theta: float) -> float:
        y = rk4(mode, t, x, theta * dt)
        return float(guards(mode, t + theta * dt, y)[0][k])

    return float(brentq(value, 0.0, 1.0, xtol=1e-14, rtol=1e-14))


def run_emitted(
    functions: HybridFunctions,
    simulator: Any,
    p: np.ndarray,
    s0: np.ndarray,
    t_eval: np.ndarray,
    h: float = 1e-4,
) -> EmittedRun:
    """Integrate the simulator's scenario with the emitted functions alone (module docstring).

    ``simulator`` supplies only the scenario: its inputs u(t), breakpoints, normal forces and
    the from-gear initial state; ``s0`` is S(0) (states × sensitivity parameters). The emitted u
    has no entry for a one-way swapping element (the simulator's slot for it, 0, is dropped),
    and its release and lock-up are state guards like break-away and lock-up."""
    hs = functions.hs
    elements = hs.hybrid.elements
    slots = [0, *(1 + k for k, e in enumerate(elements) if e not in hs.hybrid.one_way)]
    slots.append(1 + len(elements))

    def inputs(t: float) -> np.ndarray:
        return simulator.inputs(t)[slots]

    functions.set_parameters(p)
    index = {m.mode.name: m.index for m in hs.modes}
    mode = index[hs.hybrid.from_mode]
    x = np.concatenate([simulator.initial_state(p), s0.T.ravel()])
    scenario = simulator.scenario
    breakpoints = [0.0, *(b for b in scenario.breakpoints() if b > 0.0)]
    samples: dict[int, tuple[np.ndarray, int]] = {}
    events: list[tuple[float, int, int, str]] = []
    pending = list(enumerate(t_eval))

    def rhs(m: int, t: float, y: np.ndarray) -> np.ndarray:
        return functions.call(f"m{m}_rhs", x=y, u=inputs(t))[0]

    def rk4(m: int, t: float, y: np.ndarray, dt: float) -> np.ndarray:
        k1 = rhs(m, t, y)
        k2 = rhs(m, t + dt / 2, y + dt / 2 * k1)
        k3 = rhs(m, t + dt / 2, y + dt / 2 * k2)
        k4 = rhs(m, t + dt, y + dt * k3)
        return y + dt / 6 * (k1 + 2 * (k2 + k3) + k4)

    def guards(m: int, t: float, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g, c = functions.call(f"m{m}_guards", x=y, u=inputs(t))
        return g, c

    def jump(source: int, target: int, t: float, y: np.ndarray, rate: np.ndarray) -> np.ndarray:
        return functions.call(f"jump_{source}_{target}", x=y, u=inputs(t), u_rate=rate)[0]

    def record(t0: float, t1: float, m: int, y0: np.ndarray) -> None:
        # samples inside [t0, t1] by a Runge-Kutta step from t0 (a sample at a switch takes
        # the later piece, as the simulator's do)
        while pending and pending[0][1] <= t1:
            k, ts = pending.pop(0)
            samples[k] = (rk4(m, t0, y0, ts - t0) if ts > t0 else y0.copy(), m)

    for ta, tb in zip(breakpoints[:-1], breakpoints[1:], strict=True):
        # switches at the breakpoint (opening, engagement), decided on the next segment
        forces = simulator.normal_forces((ta + tb) / 2)
        for k, e in enumerate(elements):
            if e in hs.hybrid.one_way:  # not pressed: its guards depend on the state
                continue
            source = hs.modes[mode]
            status = source.mode.status[e][0]
            pressed = forces[k] > 0
            kind = ENGAGEMENT if status == OPEN and pressed else None
            if status != OPEN and not pressed:
                kind = OPENING
            if kind is None:
                continue
            (g_index,) = [
                i for i, g in enumerate(source.guards) if g.element == e and g.kind == kind
            ]
            guard = source.guards[g_index]
            target = index[guard.target]
            if guard.otherwise is not None and guards(mode, ta, x)[1][g_index] < 0:
                target = index[guard.otherwise]
            x = jump(mode, target, ta, x, np.zeros(len(hs.inputs)))
            events.append((ta, mode, target, kind))
            mode = target
        rate = (inputs(tb) - inputs(ta)) / (tb - ta)
        t = ta
        while t < tb - 1e-14:
            dt = min(h, tb - t)
            y_next = rk4(mode, t, x, dt)
            source = hs.modes[mode]
            g0, _ = guards(mode, t, x)
            g1, _ = guards(mode, t + dt, y_next)
            crossing = []
            for k, g in enumerate(source.guards):
                if g.kind not in CONTINUOUS:
                    continue
                if (g.direction > 0 and g0[k] < 0 <= g1[k]) or (
                    g.direction < 0 and g0[k] > 0 >= g1[k]
                ):
                    crossing.append((_locate(rk4, guards, mode, t, x, dt, k), k))
            if not crossing:
                # a sample at the breakpoint tb belongs to the next segment (after its switches)
                record(t, t + dt if t + dt < tb else np.nextafter(tb, -np.inf), mode, x)
                x, t = y_next, t + dt
                continue
            theta, k = min(crossing)
            t_event = t + theta * dt
            x_event = rk4(mode, t, x, theta * dt)
            record(t, np.nextafter(t_event, -np.inf), mode, x)
            guard = source.guards[k]
            target = index[guard.target]
            if guard.otherwise is not None and guards(mode, t_event, x_event)[1][k] < 0:
                target = index[guard.otherwise]
            x = jump(mode, target, t_event, x_event, rate)
            events.append((t_event, mode, target, guard.kind))
            mode, t = target, t_event
    record(breakpoints[-1], np.inf, mode, x)
    missing = [k for k in range(len(t_eval)) if k not in samples]
    if missing:
        raise RuntimeError(f"samples not reached: {t_eval[missing[:3]]}")
    return EmittedRun(
        np.asarray(t_eval, dtype=float),
        tuple(samples[k][0] for k in range(len(t_eval))),
        tuple(samples[k][1] for k in range(len(t_eval))),
        tuple(events),
    )


def _reference(spec: Any, columns: Sequence[np.ndarray]) -> np.ndarray:
    """SymPy's values of one function (lambdify on whole columns of points)."""
    import sympy as sp

    symbols = [s for a in spec.args for s in a.symbols]
    flat = [e for matrix in spec.expressions for e in matrix]
    f = sp.lambdify(symbols, flat, "numpy")
    n = len(columns[0])
    values = [np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in f(*columns)]
    return np.column_stack(values)


#: Sample points of a jump whose crossing rate g_x f⁻ + g_u u̇ is below this fraction of its
#: median over the sample are drawn again: there the crossing is grazing and
#: ∂τ/∂p = −(…)/rate amplifies rounding by the inverse (the check compares arithmetic, not
#: the conditioning of a near-tangential event).
GRAZING = 1e-2


def _well_conditioned(
    hs: HybridSensitivity,
    arrays: dict[str, dict[str, np.ndarray]],
    points: np.ndarray,
    rng: np.random.Generator,
    tries: int = 50,
) -> None:
    """Redraw, in place, the states and input rates of the event-time jumps' sample points
    where the guard crossing is grazing (:data:`GRAZING`)."""
    import sympy as sp

    low, high = c_check_range()
    parameters = [v.symbol for v in hs.hybrid.parameters]
    for jump in hs.jumps:
        if not jump.event_time:
            continue
        name = f"jump_{jump.source}_{jump.target}"
        x = [v.symbol for v in hs.modes[jump.source].states]
        u = [v.symbol for v in hs.inputs]
        u_dot = [v.symbol for v in hs.input_rates]
        f = sp.lambdify([*x, *u, *u_dot, *parameters], jump.rate, "numpy")
        given = arrays[name]

        def rates(given: dict[str, np.ndarray] = given, f: Any = f) -> np.ndarray:
            value = f(*given["x"].T, *given["u"].T, *given["u_rate"].T, *points.T)
            return np.abs(np.broadcast_to(np.asarray(value, dtype=float), (len(points),)))

        typical = float(np.median(rates()))
        for _ in range(tries):
            bad = rates() < GRAZING * typical
            if not bad.any():
                break
            for key in ("x", "u_rate"):
                given[key][bad] = rng.uniform(low, high, (int(bad.sum()), given[key].shape[1]))
        else:
            raise RuntimeError(f"{name}: no well-conditioned sample points in {tries} draws")


def c_check_range() -> tuple[float, float]:
    """The sampling range of states and inputs of the model checks."""

    return c_check.STATE_RANGE


def compare_hybrid_sets(
    sets: Sequence[tuple[HybridSensitivity, Any]],
    root: Path,
    build_dir: Path,
    n_points: int = 200,
    seed: int = 0,
) -> list[Any]:
    """C double, C single and CasADi of every function of every hybrid set under ``root``
    against the SymPy expressions at random points (states and inputs uniform in
    :data:`~gearsym.validation.checks.c_check.STATE_RANGE`, parameters as
    :func:`~gearsym.validation.checks.c_check.sample_points` draws them), with the metric and floors
    of the model checks."""

    reports = []
    for k, (hs, config) in enumerate(sets):
        table = hybrid_table(hs, config)
        names = model_file_names(table.model.name)
        sources = {
            names[key]: (root / "c" / names[key]).read_text(encoding="utf-8")
            for key in ("header", "source")
        }
        _, _, points = c_check.sample_points(table.model, n_points, seed + k, config.bounds)
        rng = np.random.default_rng(seed + k)
        low, high = c_check.STATE_RANGE
        specs = [spec for spec in table if spec.kind == "expr"]
        arrays = {
            spec.name: {
                a.name: rng.uniform(low, high, (n_points, a.size))
                for a in spec.args
                if a.kind != "params"
            }
            for spec in specs
        }
        _well_conditioned(hs, arrays, points, rng)
        reference = {}
        for spec in specs:
            columns = [
                column
                for a in spec.args
                for column in (points.T if a.kind == "params" else arrays[spec.name][a.name].T)
            ]
            reference[spec.name] = _reference(spec, columns)
        computed: dict[str, dict[str, np.ndarray]] = {}
        libraries = {}
        for single in (False, True):
            path = c_check.compile_shared(sources, build_dir / table.model.name, single=single)
            lib = HybridFunctions(path, hs, single)
            libraries[single] = lib
            computed["C single" if single else "C double"] = {
                spec.name: _evaluate(lib, spec.name, arrays[spec.name], points) for spec in specs
            }
        functions = load_casadi_module(root / "python" / names["casadi"]).functions()
        casadi_values = {}
        for spec in specs:
            mapped = functions[spec.name].map(n_points)
            args = [
                points.T if a.kind == "params" else arrays[spec.name][a.name].T for a in spec.args
            ]
            out = mapped(*args)
            out = out if isinstance(out, (list, tuple)) else [out]
            casadi_values[spec.name] = np.vstack([np.asarray(o.full(), dtype=float) for o in out]).T
        computed["CasADi"] = casadi_values
        for target, values_of in computed.items():
            floor = c_check.FLOOR["single" if "single" in target else "double"]
            report = c_check._report(target, values_of, reference, floor)
            report.target = f"{table.model.name}: {target}"
            if target == "C single":
                tolerance = c_check.TOLERANCE["single"]
                for name, err in report.max_error.items():
                    if err > tolerance:
                        report.conditioned[name] = _conditioned_error(
                            libraries[False],
                            name,
                            arrays[name],
                            points,
                            values_of[name],
                            reference[name],
                            rng,
                        )
            reports.append(report)
    return reports


def _evaluate(
    lib: HybridFunctions, name: str, given: dict[str, np.ndarray], points: np.ndarray
) -> np.ndarray:
    rows = []
    for i, p in enumerate(points):
        lib.set_parameters(p)
        rows.append(np.concatenate(lib.call(name, **{a: v[i] for a, v in given.items()})))
    return np.array(rows)


def _conditioned_error(
    double: HybridFunctions,
    name: str,
    given: dict[str, np.ndarray],
    points: np.ndarray,
    computed: np.ndarray,
    reference: np.ndarray,
    rng: np.random.Generator,
    n_perturbations: int = 8,
) -> float:
    """The single-precision error that allows for the function's own conditioning, as
    :func:`gearsym.validation.checks.generated_check.conditioned_error` defines it for the models:
    the spread of the (double) function when every input moves by one float ulp sets the
    denominator's lower bound, times its factor (e.g. the difference A f⁻ − f⁺ of a jump
    cancels where the two fields nearly agree)."""

    tolerance = c_check.TOLERANCE["single"]
    floor = c_check.FLOOR["single"]
    eps = c_check.PERTURBATION_ULPS * float(np.finfo(np.float32).eps)
    spread = np.zeros_like(reference)
    for _ in range(n_perturbations):
        moved = {a: v * (1.0 + eps * rng.uniform(-1.0, 1.0, v.shape)) for a, v in given.items()}
        moved_points = points * (1.0 + eps * rng.uniform(-1.0, 1.0, points.shape))
        spread = np.fmax(spread, np.abs(_evaluate(double, name, moved, moved_points) - reference))
    magnitude = np.abs(reference)
    scale = magnitude.max(axis=0)
    denominator = np.maximum(magnitude, np.maximum(floor * scale, np.finfo(np.float64).tiny))
    denominator = np.maximum(denominator, c_check.CONDITIONED_FACTOR * spread / tolerance)
    return float((np.abs(computed - reference) / denominator).max(initial=0.0))
