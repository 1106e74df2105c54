"""Extended unknown input observer (thesis 4.5) on the parameter-augmented shift model (4.1).

**Model.** The EKF's augmented model (:mod:`.ekf`) with the parameters m_veh, μ_off, μ_on as
random-walk states, but *without* a road model: ζ, f_roll and c_W are set to 0 in the filter,
and the whole road load T_res* (2.48: rolling, aero and grade, so it absorbs ζ; (5.5) has
T_res* and ζ in collinear columns, only their sum is estimable) is an unknown input d acting
on the wheel speed, I_C^eff ω̇_C = 2 T_ss − d (2.45, 2.46). Its column is
E = −e_{ω_C} / (I_wheel + m_veh r_dyn²).

**Decoupling (4.5).** The UIO's decoupling (4.4) applied to the model linearised at each step
like the EKF: the unbiased minimum-variance filter of Gillijns & De Moor (Automatica 43, 2007,
the stochastic form of the UIO). With the RK4 step z⁻ = Φ_h(z, u) and its exact Jacobian F
(:class:`.ekf.DiscreteModel`), P⁻ = F P Fᵀ + h diag(q), C = ∂h/∂z at z⁻, the discrete column
E_d = h (I + hA/2 + h²A²/6 + h³A³/24) E (A = ∂f/∂z: the RK4 series of Γ E), R̃ = C P⁻ Cᵀ + R:

    M = (E_dᵀ Cᵀ R̃⁻¹ C E_d)⁻¹ E_dᵀ Cᵀ R̃⁻¹,   d̂ = M ν,   ν = y − h(z⁻),
    K = P⁻ Cᵀ R̃⁻¹,   L = K (I − C E_d M) + E_d M,   z = z⁻ + L ν,
    P = (I − L C) P⁻ (I − L C)ᵀ + L R Lᵀ   (Joseph: the covariance of this gain).

L C E_d = E_d, so the error does not depend on d: the load may be any ramp or step. The
matching condition rank(C E) = rank(E) makes M exist; σ_d² = (E_dᵀ Cᵀ R̃⁻¹ C E_d)⁻¹.

**Existence per phase** (as for the UIO, 4.4) on the continuous linearisation (A, E, C) at the
phase's operating point, per parameter: the states are the physical ones plus the parameter;
matching rank(CE) = rank(E) and strong detectability (no invariant zero of the Rosenbrock
matrix [[sI − A, −E], [C, 0]] with Re s ≥ 0; zeros where its rank drops below its normal
rank). A parameter whose test fails in a phase is *held* there: its row of L is 0 and its
random walk stops, so estimate and σ stay unchanged (as a μ whose element does not slide).

m_veh is never decoupled from the road load: it enters ω̇_C only, through I_C^eff, in the
same row as d (the A column of m_veh is a multiple of E), so s = 0 is an invariant zero in
every phase: a mass error is indistinguishable from a road load. The EUIO therefore holds
m_veh at its prior and reports why; the μ of a sliding element acts on ω_1, ω_2 and is
decoupled.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "EuioExistence",
    "EuioStep",
    "euio_existence",
    "euio_filter_model",
    "euio_mode_existence",
    "euio_phase_masks",
    "euio_model_name",
    "euio_step",
    "euio_step_full",
    "load_column",
    "ROAD_FREE",
]

#: Filter-model parameters set to 0: the road load is the unknown input instead.
ROAD_FREE: dict[str, float] = {"zeta": 0.0, "f_roll": 0.0, "c_W": 0.0}

#: Relative rank tolerance of the numerical rank tests.
RANK_TOL = 1e-9


def load_column(
    discrete: Any, z: np.ndarray, r_dyn: float, p: Sequence[float], i_wheel: float
) -> np.ndarray:
    """E = −e_{ω_C} / (I_wheel + m_veh r_dyn²) (2.45, 2.46): ∂ż/∂d of the road load d."""
    import numpy as np

    names = discrete.aug.state_names
    e = np.zeros(len(names))
    m = float(z[names.index("m_veh")]) if "m_veh" in names else float("nan")
    e[names.index("omega_C")] = -1.0 / (i_wheel + m * r_dyn**2)
    return e


def euio_model_name(shift: str) -> str:
    """``euio_2_3`` for the shift ``2-3`` (files gearsym_euio_2_3.{c,h})."""
    return "euio_" + shift.replace("-", "_")


def euio_filter_model(d: Any, shift: str = "2-3") -> tuple[Any, tuple[tuple[int, int], ...], Any]:
    """The filter's model as ``gearsym generate`` emits it (module text): the augmented model
    (4.1) with the parameters of :func:`.ekf.default_parameters` but ζ, and the parameters of
    :data:`ROAD_FREE` substituted by 0 (no road model; the road load is the unknown input).
    Returns (model, frozen (μ state, slide input) pairs, the load column E of
    :func:`load_column` as a SymPy column in the model's symbols)."""
    import dataclasses

    import sympy as sp
    from gearsym.symbolic import naming
    from gearsym.symbolic.estimators.ekf import augmented_model, default_parameters, slide_input

    parameters = [name for name in default_parameters(d, shift) if name != naming.GRADE]
    aug = augmented_model(d, shift, parameters)
    model = aug.model
    road = {v.symbol: sp.Integer(0) for v in model.parameters if v.name in ROAD_FREE}
    symbols = {v.name: v.symbol for v in (*model.states, *model.parameters)}
    r_dyn = symbols.get("r_dyn")
    if r_dyn is None:  # a gearbox whose model has r_dyn folded in: its value
        from gearsym.symbolic.drivetrain import quantity

        r_dyn = sp.Float(quantity(d, "vehicle", "r_dyn").value)
    names = aug.state_names
    column = sp.zeros(len(names), 1)
    column[names.index(naming.WHEEL_SPEED)] = -1 / (
        symbols["I_wheel"] + symbols["m_veh"] * r_dyn**2
    )
    rhs = sp.Matrix(model.rhs.xreplace(road))
    outputs = sp.Matrix(model.output_expressions.xreplace(road))
    column = sp.Matrix(column.xreplace(road))
    used = rhs.free_symbols | outputs.free_symbols | column.free_symbols
    filtered = dataclasses.replace(
        model,
        name=euio_model_name(aug.shift),
        # those of the road model drop out with it (rho_air, A_front act through c_W only)
        parameters=tuple(v for v in model.parameters if v.symbol in used),
        rhs=rhs,
        output_expressions=outputs,
        metadata={
            **model.metadata,
            "equations": "2.55-2.58, 2.69, 3.14, 4.1, 4.5",
            "road load": "unknown input T_res* (2.48); zeta, f_roll, c_W are 0 in the filter",
        },
    )
    inputs = aug.input_names
    frozen = tuple(
        (names.index(mu), inputs.index(slide_input(e))) for e, mu in aug.mu_state.items()
    )
    return filtered, frozen, sp.ImmutableMatrix(column)


#: A generic operating point of the structural existence test (:func:`euio_phase_masks`):
#: speeds (rad/s) and twist (rad) of a car moving under load, input torque (N m) and the
#: normal force (N) of a sliding element; the tests are of rank, so any point where the
#: states, the torque and the force are nonzero serves (the tests check them against the
#: reference's phase midpoints).
GENERIC_POINT: dict[str, float] = {
    "omega_1": 300.0,
    "omega_2": 200.0,
    "phi": 0.01,
    "omega_C": 50.0,
    "T_In": 100.0,
    "F_N": 5000.0,
}


def euio_phase_masks(d: Any, shift: str = "2-3") -> tuple[tuple[str, tuple[int, ...], str], ...]:
    """The held mask of the extended UIO per phase of a single-swap power-on shift, from
    :func:`euio_existence` (4.4) on the filter's model at :data:`GENERIC_POINT` with each
    phase's element modes: the from-gear (off-going sticks, on-coming open), then for an
    upshift the torque phase (both slide) and the speed phase (on-coming slides), for a
    downshift, whose off-going element is released first, the speed phase (off-going slides,
    on-coming open) and the torque phase (off-going slides, on-coming sticks), and the to-gear
    (on-coming sticks).
    Returns (phase name, held state indices, the reasons) per phase; the state indices are
    those of :func:`euio_filter_model`'s model."""
    import numpy as np
    from gearsym.symbolic import naming
    from gearsym.symbolic.drivetrain import element_short_name
    from gearsym.symbolic.estimators.ekf import (
        DiscreteModel,
        augmented_model,
        default_parameters,
        slide_input,
        stick_input,
    )
    from gearsym.symbolic.shifts import shift_spec

    spec = shift_spec(d, shift)
    parameters = [name for name in default_parameters(d, shift) if name != naming.GRADE]
    aug = augmented_model(d, shift, parameters)
    discrete = DiscreteModel(aug)
    p = aug.parameter_values(ROAD_FREE)
    pnames = [v.name for v in aug.model.parameters]
    from gearsym.symbolic.drivetrain import quantity

    r_dyn = float(quantity(d, "vehicle", "r_dyn").value)
    i_wheel = p[pnames.index("I_wheel")]
    names = aug.state_names
    z = np.array(
        [
            GENERIC_POINT.get(name, float(aug.model.states[k].default or 0.0))
            for k, name in enumerate(names)
        ]
    )
    off, on = spec.off_going, spec.on_coming
    from gearsym.symbolic.ratios import gear_ratio

    upshift = float(gear_ratio(d, d.gear(spec.to_gear)).ratio) < float(
        gear_ratio(d, d.gear(spec.from_gear)).ratio
    )
    middle = (
        (("torque phase", {off: "slide", on: "slide"}), ("speed phase", {off: "open", on: "slide"}))
        if upshift  # power-on: the on-coming element takes the load first
        else (
            # power-on downshift: the off-going element released first, the load moves at
            # synchronism (validation/sim/phases.py)
            ("speed phase", {off: "slide", on: "open"}),
            ("torque phase", {off: "slide", on: "stick"}),
        )
    )
    phases = (
        (f"gear {spec.from_gear}", {off: "stick", on: "open"}),
        *middle,
        (f"gear {spec.to_gear}", {off: "open", on: "stick"}),
    )
    inputs = aug.input_names
    out = []
    for phase, modes in phases:
        u = np.zeros(len(inputs))
        u[inputs.index("T_In")] = GENERIC_POINT["T_In"]
        for element, mode in modes.items():
            force = naming.normal_force(element_short_name(d, element))
            u[inputs.index(force)] = GENERIC_POINT["F_N"] if mode != "open" else 0.0
            u[inputs.index(slide_input(element))] = 1.0 if mode == "slide" else 0.0
            u[inputs.index(stick_input(element))] = 1.0 if mode == "stick" else 0.0
        e = load_column(discrete, z, r_dyn, p, i_wheel)
        result = euio_existence(discrete, phase, z, u, p, e)
        held = tuple(names.index(x.parameter) for x in result if not x.exists)
        why = "; ".join(f"{x.parameter}: {x.reason()}" for x in result if not x.exists)
        out.append((phase, held, why))
    return tuple(out)


def euio_mode_existence(
    discrete: Any,
    u: Sequence[float],
    p: Sequence[float],
    r_dyn: float,
    i_wheel: float,
    normal_force: Mapping[str, int],
    phase: str = "",
) -> list[EuioExistence]:
    """:func:`euio_existence` for the element modes of ``u`` (its ``slide_<E>``/``stick_<E>``
    flags, as :meth:`.ekf_modes.ModeLogic.inputs` sets them) at :data:`GENERIC_POINT`, as
    :func:`euio_phase_masks` tests a phase: the held mask a filter that decides its modes
    itself (:func:`.ekf_modes.ekf_mode_update`) uses, without the reference's phases. The
    torque is the generic one, and an element that is not open gets the generic normal
    force (an engaged element with F_N = 0 would make its μ inactive); ``normal_force``: the
    input index of each element's F_N (:attr:`.ekf_modes.ModeLogic.normal_force`)."""
    import numpy as np
    from gearsym.symbolic.estimators.ekf import slide_input, stick_input

    aug = discrete.aug
    names = aug.state_names
    z = np.array(
        [
            GENERIC_POINT.get(name, float(aug.model.states[k].default or 0.0))
            for k, name in enumerate(names)
        ]
    )
    inputs = aug.input_names
    v = np.array(u, dtype=float)
    v[inputs.index("T_In")] = GENERIC_POINT["T_In"]
    for element in aug.elements:
        engaged = abs(v[inputs.index(slide_input(element))]) > 0.5 or (
            v[inputs.index(stick_input(element))] > 0.5
        )
        v[normal_force[element]] = GENERIC_POINT["F_N"] if engaged else 0.0
    e = load_column(discrete, z, r_dyn, p, i_wheel)
    return euio_existence(discrete, phase, z, v, p, e)


def _rank(m: np.ndarray) -> int:
    import numpy as np

    if m.size == 0:
        return 0
    s = np.linalg.svd(m, compute_uv=False)
    return int(np.sum(s > RANK_TOL * max(1.0, s[0])))


def _pencil_rank(m: np.ndarray) -> int:
    """The rank of ``m`` with its nonzero columns scaled to unit length."""
    import numpy as np

    norms = np.linalg.norm(m, axis=0)
    return _rank(m / np.where(norms > 0, norms, 1.0))


def rosenbrock(a: np.ndarray, e: np.ndarray, c: np.ndarray, s: complex) -> np.ndarray:
    """P(s) = [[sI − A, −E], [C, 0]]."""
    import numpy as np

    n, q, p = a.shape[0], e.shape[1], c.shape[0]
    return np.block([[s * np.eye(n) - a, -e], [c, np.zeros((p, q))]])


def invariant_zeros(a: np.ndarray, e: np.ndarray, c: np.ndarray) -> tuple[int, list[complex]]:
    """(normal rank, finite invariant zeros) of the Rosenbrock matrix.

    A tall pencil is squared down by two random left projections W (n+q × n+p); the zeros of
    P(s) are generalized eigenvalues of (W N, W M) for every W, spurious ones differ between
    the two draws, so the common ones are kept. A zero at s = 0 is confirmed by the rank of
    P(0) directly. Ranks of P(s) are taken with its columns scaled to unit length (which
    leaves the rank unchanged): the columns of a model in SI units differ by 1e7 (a μ's
    torque against the road load's 1/(I_wheel + m r²)), and unscaled, a direction that
    vanishes only at s = 0 falls below the tolerance at |s| ~ 1 as well (a sliding
    element's torque on a gearbox held rigid by a sticking one: parallel to the twist's)."""
    import numpy as np
    from scipy.linalg import eigvals

    n, q, p = a.shape[0], e.shape[1], c.shape[0]
    rng = np.random.default_rng(7)
    normal = max(
        _pencil_rank(rosenbrock(a, e, c, complex(rng.normal(), rng.normal()))) for _ in range(2)
    )
    mm = np.zeros((n + p, n + q))
    mm[:n, :n] = np.eye(n)
    nn = -rosenbrock(a, e, c, 0.0)  # P(s) = s M − N
    sets = []
    for _ in range(2):
        w = rng.normal(size=(n + q, n + p))
        with np.errstate(all="ignore"):
            lam = eigvals(w @ nn, w @ mm)
        sets.append([z for z in lam if np.isfinite(z)])
    common = []
    for z in sets[0]:
        if any(abs(z - y) <= 1e-6 * max(1.0, abs(z)) for y in sets[1]):
            common.append(complex(z))
    zeros = [z for z in common if _pencil_rank(rosenbrock(a, e, c, z)) < normal]
    zeros = [0j if abs(z) < 1e-9 else z for z in zeros]
    if _pencil_rank(rosenbrock(a, e, c, 0.0)) < normal and not any(abs(z) < 1e-9 for z in zeros):
        zeros.append(0j)
    return normal, zeros


@dataclass(frozen=True)
class EuioExistence:
    """The UIO conditions for one parameter in one phase, on the linearisation there."""

    phase: str
    parameter: str
    rank_CE: int
    rank_E: int
    invariant_zeros: tuple[complex, ...]
    active: bool  # False: the parameter does not act in this phase (a μ whose element is off)

    @property
    def unstable_zeros(self) -> tuple[complex, ...]:
        return tuple(z for z in self.invariant_zeros if z.real >= -1e-9)

    @property
    def exists(self) -> bool:
        return self.active and self.rank_CE == self.rank_E and not self.unstable_zeros

    def reason(self) -> str | None:
        """Why the parameter is held in this phase, or ``None``."""
        if not self.active:
            return "its element does not slide in this phase (μ has no effect)"
        if self.rank_CE != self.rank_E:
            return f"rank(CE) = {self.rank_CE} < rank(E) = {self.rank_E}"
        if self.unstable_zeros:
            zs = ", ".join(f"{z.real:.4g}{z.imag:+.4g}j" for z in self.unstable_zeros)
            return (
                f"not strongly detectable: invariant zero(s) {zs} with Re s >= 0 "
                "(indistinguishable from the road load)"
            )
        return None

    def to_dict(self) -> dict[str, Any]:
        return {
            "phase": self.phase,
            "parameter": self.parameter,
            "rank_CE": self.rank_CE,
            "rank_E": self.rank_E,
            "invariant_zeros": [[z.real, z.imag] for z in self.invariant_zeros],
            "exists": self.exists,
            "reason": self.reason(),
        }


def euio_existence(
    discrete: Any,
    phase: str,
    z: np.ndarray,
    u: Sequence[float],
    p: Sequence[float],
    e: np.ndarray,
) -> list[EuioExistence]:
    """Per augmented parameter: the UIO conditions (4.4) on the linearisation of the filter's
    model at (z, u) with the road-load column ``e`` (:func:`load_column`), the states being
    the physical ones plus that parameter."""
    import numpy as np

    aug = discrete.aug
    a_full = np.asarray(discrete.J(z, u, p), dtype=float)
    c_full = np.asarray(discrete.H_fn(z, u, p), dtype=float)
    frozen = set(aug.frozen_states(u))
    n_x = aug.n_x
    out = []
    for name in aug.parameters:
        j = aug.state_names.index(name)
        idx = [*range(n_x), j]
        a = a_full[np.ix_(idx, idx)]
        c = c_full[:, idx]
        ecol = e[idx][:, None]
        _, zeros = invariant_zeros(a, ecol, c)
        out.append(
            EuioExistence(
                phase=phase,
                parameter=name,
                rank_CE=_rank(c @ ecol),
                rank_E=_rank(ecol),
                invariant_zeros=tuple(zeros),
                active=j not in frozen and bool(np.any(a_full[:n_x, j] != 0.0)),
            )
        )
    return out


@dataclass(frozen=True)
class EuioStep:
    """One EUIO step's results: the corrected estimate and covariance, d̂ with σ_d, and the
    NIS of the innovation with d̂ removed.

    ν = C E_d d + ν₀ with ν₀ ~ N(0, R̃): the part of ν that d cannot explain is its
    R̃-orthogonal complement of C E_d, so NIS = νᵀ R̃⁻¹ ν − d̂² / σ_d² ~ χ²(m − 1) whatever d
    is (m outputs; d̂ = M ν, σ_d² = (E_dᵀ Cᵀ R̃⁻¹ C E_d)⁻¹)."""

    z: np.ndarray
    P: np.ndarray
    d_hat: float
    sigma_d: float
    nis: float
    nis_dof: int


def euio_step(
    discrete: Any,
    z: np.ndarray,
    P: np.ndarray,
    u_prev: Sequence[float],
    u: Sequence[float],
    y: np.ndarray,
    R: np.ndarray,
    h: float,
    p: Sequence[float],
    q: np.ndarray,
    e: np.ndarray,
    held: Sequence[int],
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """One EUIO step (module text): predict with ``u_prev`` held, decouple the road load,
    correct with the measurement ``y`` (variances ``R``). ``held``: state indices whose
    estimate and variance stay unchanged (no random walk, zero gain row).
    Returns (z, P, d̂, σ_d); with a non-finite measurement only the prediction is done and
    d̂ is NaN. :func:`euio_step_full` also returns the NIS."""
    s = euio_step_full(discrete, z, P, u_prev, u, y, R, h, p, q, e, held)
    return s.z, s.P, s.d_hat, s.sigma_d


def euio_step_full(
    discrete: Any,
    z: np.ndarray,
    P: np.ndarray,
    u_prev: Sequence[float],
    u: Sequence[float],
    y: np.ndarray,
    R: np.ndarray,
    h: float,
    p: Sequence[float],
    q: np.ndarray,
    e: np.ndarray,
    held: Sequence[int],
    consider: Sequence[int] = (),
) -> EuioStep:
    """:func:`euio_step` with the NIS of :class:`EuioStep` (NaN, dof 0, without an update).
    ``consider``: further states not corrected in this update but, unlike ``held``, still
    given their process noise (a μ whose element's mode is in doubt,
    :func:`~gearsym.symbolic.estimators.ekf_modes.ambiguous_mu`)."""
    import numpy as np

    z_pred, F = discrete.step(z, u_prev, h, p)
    rates = np.array(q, dtype=float)
    rates[list(held)] = 0.0
    P_pred = F @ P @ F.T + np.diag(h * rates)
    P_pred = 0.5 * (P_pred + P_pred.T)
    if not np.all(np.isfinite(y)):
        return EuioStep(z_pred, P_pred, float("nan"), float("nan"), float("nan"), 0)
    a = np.asarray(discrete.J(z, u_prev, p), dtype=float)
    ha = h * a
    ed = h * (e + ha @ e / 2 + ha @ (ha @ e) / 6 + ha @ (ha @ (ha @ e)) / 24)
    y_hat, C = discrete.outputs(z_pred, u, p)
    nu = y - y_hat
    rt = C @ P_pred @ C.T + np.diag(R)
    rt_inv = np.linalg.inv(rt)
    ce = C @ ed
    info = float(ce @ rt_inv @ ce)
    m = (ce @ rt_inv) / info
    d_hat = float(m @ nu)
    K = P_pred @ C.T @ rt_inv
    L = K @ (np.eye(len(y)) - np.outer(ce, m)) + np.outer(ed, m)
    L[sorted({*held, *consider}), :] = 0.0
    z_new = z_pred + L @ nu
    A = np.eye(len(z)) - L @ C
    P_new = A @ P_pred @ A.T + L @ np.diag(R) @ L.T
    nis = float(nu @ rt_inv @ nu) - d_hat * d_hat * info
    return EuioStep(
        z_new, 0.5 * (P_new + P_new.T), d_hat, float(np.sqrt(1.0 / info)), nis, len(y) - 1
    )
