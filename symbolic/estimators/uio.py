"""Unknown input observer (thesis 4.4) on the linear form (5.1) of each phase of a shift.

A phase of a shift is a linear mode: the from-gear (its elements locked), the torque and speed
phase (the shift model 2.55–2.58 with the two swapping elements' torques as inputs) and the
to-gear. Each has ẋ = A x + B u (5.1) with the inputs of (5.3) and the measured speeds
y = C x (3.31). Some inputs are unknown to the TCU: the road load T_res* (5.2) always, the
clutch torques when no torque model is trusted. Writing them as d with the columns E of B, a
UIO estimates x without knowing d.

Existence (Darouach, Zasadzinski & Xu 1994; Hou & Müller 1992), checked exactly at the
parameter values (rational arithmetic, no rounding):

* **matching**: rank(C E) = rank(E), so that y sees every direction in which d moves x;
* **strong detectability**: the Rosenbrock system matrix P(s) = [[sI − A, −E], [C, 0]] has no
  invariant zero with Re s ≥ 0. Its invariant zeros are the roots of the greatest common
  divisor of its maximal minors (the zero polynomial).

Columns of E that are linear combinations of others (T_res* and ζ in (5.5) both act on ω̇_C
only) are not separately estimable: only their combination is. They are reported and dropped
before the rank tests.

Design (Chen, Patton & Zhang 1996, in discrete time for the TCU): with A_d = e^{A h},
Γ = ∫₀ʰ e^{A τ} dτ, E_d = Γ E (exact for an unknown input held over a sample) and the known
inputs either held (zero-order hold, B_d = Γ B_known, B_1 = 0) or linear between samples
(first-order hold, exact for the ramps of a shift: B_d = Γ B_known,
B_1 = ∫₀ʰ e^{A (h − τ)} τ/h dτ B_known, applied to u_{k+1} − u_k, both known at step k+1),

    z_{k+1} = F z_k + T (B_d u_k + B_1 (u_{k+1} − u_k)) + K y_k,   x̂_k = z_k + H y_k,

with H = E_d L, where L is the left inverse of C E_d weighted by the inverse output weights
(L C E_d = I, so (I − H C) E_d = 0; noisier outputs count less), T = I − H C, A₁ = T A_d,
F = A₁ − K₁ C and K = K₁ + F H. The estimation error then obeys e_{k+1} = F e_k whatever d
is; K₁ is the steady-state gain of the discrete Riccati equation of (A₁, C) with the state
weight ``process_weight``·I and the output weight ``measurement_weight`` (a scalar times I, or
one variance per output: a Kalman predictor's covariances, their ratio trades convergence
speed against noise), which makes F stable exactly when (A₁, C) is detectable. The unknown
input follows from the next measurement:
d̂_k = L (y_{k+1} − C A_d x̂_k − C B_d u_k − C B_1 (u_{k+1} − u_k)).
"""

from __future__ import annotations

import itertools
import random
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import sympy as sp
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import drivetrain_model, shift_model
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.linear_forms import LinearForm, gear_linear_form, shift_linear_form
from gearsym.symbolic.shifts import shift_spec

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "LinearMode",
    "UioDesign",
    "UioExistence",
    "design_uio",
    "linear_modes",
    "shift_uio_designs",
    "uio_existence",
]

#: Name of the Laplace variable in the reported zero polynomial.
S = sp.Symbol("s")


@dataclass(frozen=True)
class LinearMode:
    """One phase of a shift as a linear mode: its form (5.1) and its measured outputs (3.31)."""

    phase: str
    form: LinearForm
    C: sp.Matrix = field(repr=False)
    outputs: tuple[str, ...]


def _mode_outputs(form: LinearForm, output_expressions: sp.Matrix) -> sp.Matrix:
    states = [sp.Symbol(name) for name in form.states]
    return sp.Matrix(output_expressions).jacobian(states)


def _gear_mode(d: GearboxDescription, gear: str) -> LinearMode:
    form = gear_linear_form(d, gear)
    model = drivetrain_model(
        d,
        form.mode,
        locked=tuple(d.gear(gear).closed),
        torque_elements=(),
        keep=(d.output_shaft,),
    )
    return LinearMode(
        f"gear {gear}", form, _mode_outputs(form, model.output_expressions), _names(model)
    )


def linear_modes(d: GearboxDescription, shift: str) -> tuple[LinearMode, ...]:
    """The three linear modes of a single-swap shift: the from-gear, the torque and speed phase
    (one model: both swapping elements transmit torque, 2.55–2.58) and the to-gear."""
    spec = shift_spec(d, shift)
    form = shift_linear_form(d, shift)
    model = shift_model(d, shift)
    during = LinearMode(
        "torque and speed phase",
        form,
        _mode_outputs(form, model.output_expressions),
        _names(model),
    )
    return (_gear_mode(d, spec.from_gear), during, _gear_mode(d, spec.to_gear))


def _names(model: Any) -> tuple[str, ...]:
    return tuple(v.name for v in model.outputs)


def _exact_values(form: LinearForm, overrides: Mapping[str, float] | None) -> dict[sp.Symbol, Any]:
    """Every parameter of the form as an exact rational (from the shortest decimal of its
    float), so the rank tests do no rounding."""
    values: dict[sp.Symbol, Any] = {}
    for v in form.parameters:
        value = (overrides or {}).get(v.name, v.default)
        if value is None:
            raise GearsymError("uio", v.name, "has no default; give its value")
        values[v.symbol] = sp.Rational(repr(float(value)))
    return values


def _columns(mode: LinearMode, unknown: Sequence[str]) -> list[int]:
    index = {name: j for j, name in enumerate(mode.form.inputs)}
    missing = [u for u in unknown if u not in index]
    if missing:
        raise GearsymError(
            "uio",
            "--unknown",
            f"{', '.join(missing)} is not an input of the {mode.phase} "
            f"(inputs: {', '.join(mode.form.inputs)})",
        )
    if not unknown:
        raise GearsymError("uio", "--unknown", "name at least one unknown input")
    return [index[u] for u in unknown]


@dataclass(frozen=True)
class UioExistence:
    """The two existence conditions of a UIO for one phase and one set of unknown inputs."""

    phase: str
    unknown: tuple[str, ...]
    #: Unknown inputs whose columns of B depend on the others: only a combination is estimable.
    collinear: tuple[str, ...]
    rank_CE: int
    rank_E: int
    zero_polynomial: sp.Expr
    invariant_zeros: tuple[complex, ...]

    @property
    def matching(self) -> bool:
        """rank(C E) = rank(E)."""
        return self.rank_CE == self.rank_E

    @property
    def unstable_zeros(self) -> tuple[complex, ...]:
        """Invariant zeros with Re s ≥ 0 (an exact root at 0 included)."""
        exact_zero_root = sp.Poly(self.zero_polynomial, S).eval(0) == 0
        found = tuple(z for z in self.invariant_zeros if z.real >= -1e-9)
        if exact_zero_root and not any(abs(z) < 1e-9 for z in found):
            found = (0j, *found)
        return found

    @property
    def strongly_detectable(self) -> bool:
        """No invariant zero of the Rosenbrock matrix with Re s ≥ 0."""
        return not self.unstable_zeros

    @property
    def exists(self) -> bool:
        return self.matching and self.strongly_detectable

    def reason(self) -> str | None:
        """Why no UIO exists in this phase (the first failed condition), or ``None``."""
        if not self.matching:
            return (
                f"rank(CE) = {self.rank_CE} < rank(E) = {self.rank_E}: the measured outputs do not "
                f"see every direction in which {', '.join(self.unknown)} move the state"
            )
        if not self.strongly_detectable:
            zeros = ", ".join(_complex_text(z) for z in self.unstable_zeros)
            return (
                f"not strongly detectable: the Rosenbrock matrix has the invariant zero(s) "
                f"{zeros} with Re s >= 0"
            )
        return None

    def to_dict(self) -> dict[str, Any]:
        return {
            "phase": self.phase,
            "unknown": list(self.unknown),
            "collinear": list(self.collinear),
            "rank_CE": self.rank_CE,
            "rank_E": self.rank_E,
            "zero_polynomial": str(self.zero_polynomial),
            "invariant_zeros": [[z.real, z.imag] for z in self.invariant_zeros],
            "matching": self.matching,
            "strongly_detectable": self.strongly_detectable,
            "exists": self.exists,
            "reason": self.reason(),
        }


def _complex_text(z: complex) -> str:
    if abs(z.imag) < 1e-12:
        return f"{z.real:.6g}"
    return f"{z.real:.6g}{z.imag:+.6g}j"


def _independent_columns(e: sp.Matrix) -> list[int]:
    """Indices of the first linearly independent columns of ``e`` (exact)."""
    keep: list[int] = []
    for j in range(e.cols):
        if e[:, [*keep, j]].rank() > len(keep):
            keep.append(j)
    return keep


def uio_existence(
    mode: LinearMode, unknown: Sequence[str], parameters: Mapping[str, float] | None = None
) -> UioExistence:
    """Check rank(CE) = rank(E) and strong detectability (no invariant zero of the Rosenbrock
    matrix with Re s ≥ 0) for ``unknown`` inputs of ``mode``, exactly at the parameter values
    (defaults, or ``parameters``)."""
    columns = _columns(mode, unknown)
    values = _exact_values(mode.form, parameters)
    a = mode.form.A.xreplace(values)
    e_all = mode.form.B[:, columns].xreplace(values)
    c = mode.C
    keep = _independent_columns(e_all)
    collinear = tuple(unknown[j] for j in range(len(columns)) if j not in keep)
    e = e_all[:, keep]
    n, p, q = a.rows, c.rows, e.cols
    rosenbrock = sp.Matrix.vstack(
        sp.Matrix.hstack(S * sp.eye(n) - a, -e), sp.Matrix.hstack(c, sp.zeros(p, q))
    )
    # normal rank: the rank at a random rational point (exact; a zero there has probability 0,
    # and a second point confirms)
    rng = random.Random(2024)
    rank = max(
        rosenbrock.xreplace({S: sp.Rational(rng.randint(10**6, 10**7), 9973)}).rank()
        for _ in range(2)
    )
    gcd: sp.Poly | None = None
    for rows in itertools.combinations(range(n + p), rank):
        for cols in itertools.combinations(range(n + q), rank):
            minor = sp.Poly(rosenbrock.extract(list(rows), list(cols)).det(method="berkowitz"), S)
            if minor.is_zero:
                continue
            gcd = minor if gcd is None else sp.gcd(gcd, minor)
            if gcd.degree() == 0:
                break
        if gcd is not None and gcd.degree() == 0:
            break
    assert gcd is not None  # the normal rank is attained by some minor
    monic = gcd.monic()
    zeros = tuple(complex(z) for z in monic.nroots()) if monic.degree() > 0 else ()
    return UioExistence(
        phase=mode.phase,
        unknown=tuple(unknown[j] for j in keep),
        collinear=collinear,
        rank_CE=(c * e).rank(),
        rank_E=e.rank(),
        zero_polynomial=monic.as_expr(),
        invariant_zeros=zeros,
    )


@dataclass(frozen=True)
class UioDesign:
    """A discrete-time UIO of one phase (see the module docstring for the equations)."""

    phase: str
    unknown: tuple[str, ...]
    known: tuple[str, ...]
    states: tuple[str, ...]
    outputs: tuple[str, ...]
    sample_time: float
    hold: str
    Ad: np.ndarray = field(repr=False)
    Bd: np.ndarray = field(repr=False)
    B1: np.ndarray = field(repr=False)
    Ed: np.ndarray = field(repr=False)
    C: np.ndarray = field(repr=False)
    H: np.ndarray = field(repr=False)
    #: (C E_d)⁻ with L C E_d = I, weighted by the output weights; d̂ = L (residual).
    left_inverse: np.ndarray = field(repr=False)
    T: np.ndarray = field(repr=False)
    F: np.ndarray = field(repr=False)
    K: np.ndarray = field(repr=False)

    @property
    def spectral_radius(self) -> float:
        """Largest |eigenvalue| of F: the error shrinks by about this factor per sample."""
        import numpy as np

        return float(np.max(np.abs(np.linalg.eigvals(self.F))))

    def initial(self, y0: np.ndarray, x0_guess: np.ndarray | None = None) -> np.ndarray:
        """z₀ for a first guess of x (default: zero in the unmeasured directions)."""
        import numpy as np

        x0 = np.zeros(len(self.states)) if x0_guess is None else np.asarray(x0_guess, float)
        return self.T @ x0

    def unknown_input(
        self, x_hat: np.ndarray, y_next: np.ndarray, u: np.ndarray, u_next: np.ndarray
    ) -> np.ndarray:
        """d̂_k = L (y_{k+1} − C A_d x̂_k − C B_d u_k − C B_1 (u_{k+1} − u_k)) (4.4): the unknown
        inputs over the sample from k to k+1, one sample late (L C E_d = I: exact for a held
        input and an exact x̂_k; a differentiator, so speed noise is amplified by about |L|).
        What :meth:`run` returns per sample, and the emitted ``_unknown_input`` computes."""
        import numpy as np

        x_hat, u, u_next = (np.asarray(v, float) for v in (x_hat, u, u_next))
        predicted = self.C @ (self.Ad @ x_hat + self.Bd @ u + self.B1 @ (u_next - u))
        return self.left_inverse @ (np.asarray(y_next, float) - predicted)

    def run(
        self, y: np.ndarray, u: np.ndarray, x0_guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Estimates x̂_k (N × n) and d̂_k (N−1 × q) from the samples y_k (N × p) and the known
        inputs u_k (N × m; held over each sample or linear between samples, as designed)."""
        import numpy as np

        y, u = np.asarray(y, float), np.asarray(u, float)
        z = self.initial(y[0], x0_guess)
        x_hat = np.empty((len(y), len(self.states)))
        du = np.diff(u, axis=0)
        for k in range(len(y)):
            x_hat[k] = z + self.H @ y[k]
            if k + 1 < len(y):
                z = self.F @ z + self.T @ (self.Bd @ u[k] + self.B1 @ du[k]) + self.K @ y[k]
        predicted = (self.C @ (self.Ad @ x_hat[:-1].T + self.Bd @ u[:-1].T + self.B1 @ du.T)).T
        d_hat = (self.left_inverse @ (y[1:] - predicted).T).T
        return x_hat, d_hat


def design_uio(
    mode: LinearMode,
    unknown: Sequence[str],
    sample_time: float,
    parameters: Mapping[str, float] | None = None,
    measurement_weight: float | Sequence[float] = 1.0,
    process_weight: float = 1.0,
    existence: UioExistence | None = None,
    hold: str = "foh",
) -> UioDesign:
    """Design the discrete-time UIO of ``mode`` for ``unknown`` inputs at ``sample_time``.

    Refuses (:class:`GearsymError` naming the phase and the condition) when a UIO does not
    exist; the known inputs are the others of the form, in its order."""
    import mpmath
    import numpy as np

    existence = existence or uio_existence(mode, unknown, parameters)
    if not existence.exists:
        raise GearsymError("uio", mode.phase, f"no UIO exists: {existence.reason()}")
    if not (sample_time > 0 and np.isfinite(sample_time)):
        raise GearsymError("uio", "--sample-time", f"must be positive, got {sample_time!r}")
    if hold not in ("zoh", "foh"):
        raise GearsymError("uio", "hold", f"must be zoh or foh, got {hold!r}")
    weights = np.broadcast_to(np.asarray(measurement_weight, dtype=float), (mode.C.shape[0],))
    if np.any(~np.isfinite(weights)) or np.any(weights <= 0):
        raise GearsymError("uio", "measurement_weight", "must be positive and finite")
    values = {
        v.symbol: float((parameters or {}).get(v.name, v.default)) for v in mode.form.parameters
    }
    chosen = list(existence.unknown)
    unknown_cols = [mode.form.inputs.index(name) for name in chosen]
    dropped = set(existence.collinear)
    known = [
        j for j, name in enumerate(mode.form.inputs) if name not in chosen and name not in dropped
    ]
    # The design runs in mpmath at DESIGN_DIGITS and is rounded to doubles at the end: the
    # gains are emitted into generated/ as literals, and LAPACK's last digits follow the
    # machine's BLAS kernels (two machines gave gains differing at 1e-13), so a design in
    # floating point would make the emitted code differ from machine to machine.
    with mpmath.workdps(DESIGN_DIGITS):
        a = _mp_matrix(mode.form.A.xreplace(values))
        b = _mp_matrix(mode.form.B.xreplace(values))
        c = _mp_matrix(mode.C)
        n = a.rows
        eye = mpmath.eye(n)
        h_s = mpmath.mpf(sample_time)
        # expm of [[A, I, 0], [0, 0, I/h], [0, 0, 0]] h holds e^{Ah}, Γ = ∫₀ʰ e^{Aτ} dτ and
        # Λ = ∫₀ʰ e^{A(h−τ)} τ/h dτ (Van Loan's block form of the hold integrals)
        block = mpmath.zeros(3 * n, 3 * n)
        for i in range(n):
            for j in range(n):
                block[i, j] = a[i, j] * h_s
            block[i, n + i] = h_s
            block[n + i, 2 * n + i] = mpmath.mpf(1)
        phi = mpmath.expm(block)
        ad = phi[:n, :n]
        gamma, lam = phi[:n, n : 2 * n], phi[:n, 2 * n :]
        b_known, b_unknown = _mp_columns(b, known), _mp_columns(b, unknown_cols)
        bd, ed = gamma * b_known, gamma * b_unknown
        b1 = lam * b_known if hold == "foh" else mpmath.zeros(n, len(known))
        r_matrix = mpmath.diag([mpmath.mpf(float(w)) for w in weights])
        # decoupling with the noise-weighted left inverse of C E_d (minimum-variance among all
        # H with (I - H C) E_d = 0; the plain pseudo-inverse when all weights are equal)
        ce = c * ed
        w = r_matrix**-1
        left_inverse = (ce.T * w * ce) ** -1 * ce.T * w
        h = ed * left_inverse
        t = eye - h * c
        a1 = t * ad
        riccati = _filter_riccati(a1, c, mpmath.mpf(float(process_weight)) * eye, r_matrix)
        if riccati is None:
            raise GearsymError(
                "uio",
                mode.phase,
                "no stabilising gain for (T A_d, C): the Riccati equation's "
                "doubling iteration did not converge",
            )
        k1 = a1 * riccati * c.T * (c * riccati * c.T + r_matrix) ** -1
        f = a1 - k1 * c
        ad, bd, b1, ed, c, h, left_inverse, t, f, k = (
            _to_numpy(m) for m in (ad, bd, b1, ed, c, h, left_inverse, t, f, k1 + f * h)
        )
    return UioDesign(
        phase=mode.phase,
        unknown=tuple(chosen),
        known=tuple(mode.form.inputs[j] for j in known),
        states=tuple(mode.form.states),
        outputs=mode.outputs,
        sample_time=float(sample_time),
        hold=hold,
        Ad=ad,
        Bd=bd,
        B1=b1,
        Ed=ed,
        C=c,
        H=h,
        left_inverse=left_inverse,
        T=t,
        F=f,
        K=k,
    )


#: Decimal digits of the UIO design's arithmetic (:func:`design_uio`).
DESIGN_DIGITS = 40


def _mp_matrix(matrix: Any) -> Any:
    """A SymPy matrix of numbers as an mpmath matrix at the working precision."""
    import mpmath

    rows, cols = matrix.shape
    out = mpmath.zeros(rows, cols)
    for i in range(rows):
        for j in range(cols):
            out[i, j] = mpmath.mpmathify(str(sp.N(matrix[i, j], DESIGN_DIGITS + 10)))
    return out


def _mp_columns(matrix: Any, columns: Sequence[int]) -> Any:
    import mpmath

    out = mpmath.zeros(matrix.rows, len(columns))
    for k, j in enumerate(columns):
        for i in range(matrix.rows):
            out[i, k] = matrix[i, j]
    return out


def _to_numpy(matrix: Any) -> Any:
    import numpy as np

    return np.array(
        [[float(matrix[i, j]) for j in range(matrix.cols)] for i in range(matrix.rows)],
        dtype=float,
    ).reshape(matrix.rows, matrix.cols)


def _filter_riccati(a: Any, c: Any, q: Any, r: Any, iterations: int = 200) -> Any:
    """The stabilising solution X of the filter's discrete Riccati equation
    X = A X Aᵀ − A X Cᵀ (C X Cᵀ + R)⁻¹ C X Aᵀ + Q (what SciPy's ``solve_discrete_are(Aᵀ, Cᵀ,
    Q, R)`` returns), by the structure-preserving doubling algorithm (Chu, Fan, Lin & Wang
    2004; quadratic convergence) in mpmath; None when it does not converge."""
    import mpmath

    n = a.rows
    eye = mpmath.eye(n)
    a_k, g_k, h_k = a.T, c.T * r**-1 * c, q
    tolerance = mpmath.mpf(10) ** (-(mpmath.mp.dps - 5))
    for _ in range(iterations):
        w = (eye + g_k * h_k) ** -1
        a_next = a_k * w * a_k
        g_next = g_k + a_k * w * g_k * a_k.T
        h_next = h_k + a_k.T * h_k * w * a_k
        change = mpmath.mnorm(h_next - h_k, 1)
        a_k, g_k, h_k = a_next, g_next, h_next
        if change <= tolerance * mpmath.mnorm(h_k, 1):
            return (h_k + h_k.T) / 2
    return None


def shift_uio_designs(
    d: GearboxDescription,
    shift: str,
    unknown: Sequence[str],
    sample_time: float,
    source: str = "generate",
    key: str = "--uio-unknown",
) -> tuple[UioDesign, ...]:
    """The UIO of every phase of ``shift`` in which an ``unknown`` input acts (4.4), designed at
    the description's parameters as :func:`design_uio` does (first-order hold, unit weights).

    Refuses with one :class:`GearsymError` (``source``, ``key``) naming the phase and the first
    failed existence condition (rank(CE) = rank(E), or strong detectability) when a phase has
    no UIO: nothing is emitted for a shift whose observer cannot exist."""
    modes = linear_modes(d, shift)
    known_inputs = list(dict.fromkeys(name for m in modes for name in m.form.inputs))
    wrong = [u for u in unknown if u not in known_inputs]
    if wrong or not unknown:
        raise GearsymError(
            source,
            key,
            f"{', '.join(wrong) or 'nothing'} is not an input of any phase of shift {shift} "
            f"(inputs of (5.3): {', '.join(known_inputs)})",
        )
    designs = []
    for mode in modes:
        acting = [u for u in unknown if u in mode.form.inputs]
        if not acting:
            continue
        existence = uio_existence(mode, acting)
        if not existence.exists:
            raise GearsymError(
                source,
                key,
                f"no UIO of shift {shift} in the {mode.phase} with {', '.join(acting)} unknown: "
                f"{existence.reason()}",
            )
        designs.append(design_uio(mode, acting, sample_time, existence=existence))
    return tuple(designs)
