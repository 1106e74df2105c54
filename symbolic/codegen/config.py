"""Every language decision of the emitters, on one object.

A :class:`CodegenConfig` says which integrator steps a model gets, which ranges its
``params_validate`` enforces, how numbers are printed so that one source is exact in float and
double, how the Jacobians are laid out and how the CSE runs. The model (the IR,
:mod:`gearsym.symbolic.model`) carries none of this: the same model can be emitted with another
config, and no emitter reads ``model.metadata`` for a decision.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

__all__ = [
    "INTEGRATORS",
    "Bounds",
    "CodegenConfig",
    "EkfLayout",
    "EkfModeElement",
    "UPDATE_FORMS",
    "EuioLayout",
    "Precision",
    "Sparsity",
    "as_config",
]

Bounds = Mapping[str, tuple[float | None, float | None]]

#: Integrator steps the C emitter knows, in the order they are emitted.
INTEGRATORS: tuple[str, ...] = ("rk4", "linearly_implicit_euler")


@dataclass(frozen=True)
class Precision:
    """How constants and powers are printed, so that one source builds exactly in both precisions.

    * ``exact_integer_limit``: a rational p/q with |p|, q at most this (2**24, the largest range
      of integers that float holds exactly) prints as the constant quotient ``(p/q)``, which the
      compiler folds into the correctly rounded value; larger ones print as decimals (an integer
      literal beyond 2**24 would be rounded, beyond ~3.4e38 overflow, in float);
    * ``decimal_digits``: significant digits of such decimals and of pi, e, ...: 21 digits are
      correctly rounded in float and double alike;
    * ``max_inline_power``: integer powers up to this magnitude print as products (``b*b*b``),
      larger ones through ``pow``.
    """

    exact_integer_limit: int = 2**24
    decimal_digits: int = 21
    max_inline_power: int = 8

    def __post_init__(self) -> None:
        if self.exact_integer_limit < 1 or self.decimal_digits < 17 or self.max_inline_power < 1:
            raise ValueError(f"implausible precision settings: {self}")


@dataclass(frozen=True)
class Sparsity:
    """Layout of the Jacobians jac_x, jac_u, jac_p.

    ``"sparse"`` (default): each Jacobian gets ``<jac>_sparse``, which computes only its
    structural nonzeros in compressed-column order (pattern in the header), and the dense
    ``<jac>`` of the stable API spreads those values into the full column-major matrix (one
    expression body, no second copy of the code). ``"dense"``: only ``<jac>``, computing every
    entry inline, zeros included.
    """

    layout: Literal["sparse", "dense"] = "sparse"

    def __post_init__(self) -> None:
        if self.layout not in ("sparse", "dense"):
            raise ValueError(f"unknown Jacobian layout {self.layout!r}")

    @property
    def sparse(self) -> bool:
        return self.layout == "sparse"


@dataclass(frozen=True)
class EkfModeElement:
    """One swapping element of the EKF's own mode logic
    (:mod:`gearsym.symbolic.estimators.ekf_modes`) as the emitted ``ekf_mode_update`` needs it:
    input indices of its normal force and mode flags, the power-on slip sign, the state index
    of its μ (−1: not augmented) and the lock-up map's gearbox block A (``n`` x ``n``,
    row-major, ``n`` the physical states), exact rationals or floats."""

    name: str
    normal_force: int
    slide: int
    stick: int
    slip_sign: int
    mu: int
    lock_map: tuple[tuple[Any, ...], ...]


#: The EKF measurement update's covariance forms (``EkfLayout.update_form``).
UPDATE_FORMS = ("symmetric", "joseph")


@dataclass(frozen=True)
class EkfLayout:
    """What the EKF rows (thesis 4.3) need beyond the model: which states are frozen by which
    input. ``frozen`` holds (state index, input index) pairs: while ``u[input] > 0.5`` is false
    (the element does not slide), that state's process noise and gain entry are zero (a
    Schmidt consider state: its estimate and variance stay unchanged).

    ``modes`` (optional) emits the filter's own mode logic: ``mode_quantities`` are, per
    element in ``modes`` order, its slip, its sticking torque and its capacity (an
    ``ImmutableMatrix`` of 3 x len(modes) rows in the model's symbols), ``lock_up_confidence``
    the σ multiples of μ̂ the lock-up test takes off.

    ``update_form`` is the covariance form of the measurement update when the outputs are a
    selection of states: ``"symmetric"`` (the Schmidt update P - v wᵀ, equal to the Joseph form
    for the Schmidt gain, see :mod:`gearsym.symbolic.codegen.c.ekf_code`) or ``"joseph"`` (the
    Joseph form expanded). The default was chosen by measurement
    (``benchmarks/bench_ekf_forms.py``, README "operations per EKF step"): in float both stay
    exactly symmetric and positive definite over 10⁶ steps and within 1e-4 of the double
    filter along the default shift, and the symmetric form needs 264 fewer operations."""

    frozen: tuple[tuple[int, int], ...] = ()
    modes: tuple[EkfModeElement, ...] = ()
    mode_quantities: Any = None
    lock_up_confidence: float = 1.0
    update_form: str = "symmetric"

    def __post_init__(self) -> None:
        if self.update_form not in UPDATE_FORMS:
            raise ValueError(
                f"EkfLayout.update_form: {self.update_form!r} is not one of {UPDATE_FORMS}"
            )


@dataclass(frozen=True)
class EuioLayout:
    """What the extended UIO rows (thesis 4.5, :mod:`gearsym.symbolic.estimators.euio`) need
    beyond the model: ``frozen`` as in :class:`EkfLayout` (a μ state is held while its element
    does not slide under the inputs of the predict), ``load_column`` the road-load column
    E = ∂ż/∂d (an ``ImmutableMatrix`` of NX x 1 in the model's symbols), and ``held_phases``
    the per-phase held masks of the library's existence result as (phase name, state indices
    held there, reason) for the header."""

    frozen: tuple[tuple[int, int], ...] = ()
    load_column: Any = None
    held_phases: tuple[tuple[str, tuple[int, ...], str], ...] = ()


@dataclass(frozen=True)
class CodegenConfig:
    """The decisions one emission of a model makes (see the module docstring).

    ``bounds`` maps parameter names to ``(min, max)`` (either may be ``None``) for the emitted
    ``params_validate``. ``integrators`` selects the step functions: the sensitivity systems
    (3.7) take ``("rk4",)``, since they are not stiff and an NX x NX implicit solve of 24 states
    would put kilobytes on an ECU's stack. ``cse_optimizations`` is the ``optimizations``
    argument of :func:`sympy.cse`: measured on the test models (pendulum, friction with
    Piecewise/sign/exp, 4-state linear), ``None`` gave 303 operations in 0.12 s and ``"basic"``
    327 in 0.27 s, hence ``None``. ``restrict_pointers`` qualifies the pointers of the
    expression functions ``restrict`` in their definitions (outputs never alias inputs there):
    measured with gcc 12 on x86-64 it makes all 6 functions of
    ``benchmarks/bench_codegen_speed.py`` 2-13 % faster at ``-O2``, but at
    ``-O3 -march=native`` it lets the SLP vectorizer pack the stores of the right-hand sides of
    the 2-3 shift and its sensitivity system, which then run 14 % and 32 % slower (README,
    Benchmarks).
    """

    bounds: Bounds = field(default_factory=dict)
    integrators: tuple[str, ...] = INTEGRATORS
    precision: Precision = field(default_factory=Precision)
    sparsity: Sparsity = field(default_factory=Sparsity)
    cse_optimizations: str | None = None
    restrict_pointers: bool = True
    #: Emit the EKF rows (output Jacobian, ekf_predict, ekf_update) for an augmented model.
    ekf: EkfLayout | None = None
    #: Emit the extended UIO rows (output Jacobian, load column, euio_step).
    euio: EuioLayout | None = None

    def __post_init__(self) -> None:
        unknown = [name for name in self.integrators if name not in INTEGRATORS]
        if unknown or not self.integrators or len(set(self.integrators)) != len(self.integrators):
            raise ValueError(
                f"integrators must be distinct names out of {INTEGRATORS}, got {self.integrators}"
            )

    @property
    def implicit_step(self) -> bool:
        """Whether ``linearly_implicit_euler_step`` is emitted."""
        return "linearly_implicit_euler" in self.integrators

    @property
    def rk4_step(self) -> bool:
        """Whether ``rk4_step`` is emitted."""
        return "rk4" in self.integrators


def as_config(config: CodegenConfig | Bounds | None) -> CodegenConfig:
    """``config`` itself; a bare bounds mapping (the emitters' former second argument) is the
    default config with those bounds; ``None`` the default config."""
    if config is None:
        return CodegenConfig()
    if isinstance(config, CodegenConfig):
        return config
    return CodegenConfig(bounds=dict(config))
