"""The EKF's own mode logic (thesis 4.3 on the hybrid shift model, :mod:`..hybrid`).

A TCU does not know when an element of the real gearbox locks up or breaks away; it has its
filter's estimate, the measured speeds and the inputs it commands (T_In, the normal forces
F_N). :func:`ekf_mode_update` decides each swapping element's mode from exactly these, after
each measurement update, for the sample interval that follows (the mode is held over it, like
the inputs):

* **opening / engagement** from F_N (a known input, 2.54): F_N ≤ 0 opens the element; an open
  element with F_N > 0 engages and slides in the direction of its estimated slip (2.70).
* **lock-up** of a sliding element: its estimated slip has reached zero or crossed it
  (s Δω̂_e ≤ 0, s the slip sign of its sliding direction). The state is mapped through the
  hybrid model's lock-up map z⁺ = A z (the M-metric projection onto the locked set, 2.34:
  conserves the momentum of the motion that is left and makes the slip exactly zero), the
  covariance P⁺ = A P Aᵀ (the parameter block untouched, so every μ keeps its estimate and
  variance, a Schmidt consider state as in :func:`~.ekf.ekf_update`). It sticks if the torque
  the locked mode needs, evaluated at z⁺, is within its capacity 2 N r_m μ̂ F_N (2.60, 2.69)
  with the filter's own μ̂, lowered by :data:`LOCK_UP_CONFIDENCE` of its σ (the filter sticks
  an element only if it is that sure the element can hold); else it goes on sliding in the
  direction of that torque (as a break-away would) and the state is not mapped.
* **break-away** of a sticking element: the sticking torque the filter's estimate needs
  exceeds the capacity with μ̂: it slides in the direction of that torque (2.70; the torque is
  continuous there, |T| = capacity). The EKF's coordinates (both elements' speeds free) already
  span the larger motion space, so the hybrid model's map there (an embedding) is the identity.

While an element slides towards synchronism and its estimated slip is within
:data:`MU_AMBIGUITY_SIGMA` of its σ from zero, the filter is unsure whether it has already
locked up; :func:`ambiguous_mu` names its μ, which the next measurement update then does not
correct (``consider`` of :func:`~.ekf.ekf_update`), so a lock-up decided a sample late does
not bias it.

Why the *estimated* slip and not the measured one: the slips are linear in the measured
speeds (Δω_B05 = −3.27 ω_1 + 7.37 ω_2 on the built-in 2-3), so both are available, but the
measured slip carries the sensors' noise (3.26) of both speeds, amplified by those
coefficients; the posterior slip has the filter's model-smoothed σ. Measured on the default
2-3 at 10 ms, seeds 0-9, over the 100 ms before the on-coming element's lock-up: σ of the
measured slip 8.0 rad/s, of the posterior slip 4.3 rad/s; the measured slip changed sign before
the lock-up in 3 of the 10 seeds, the estimated one in 1. And the posterior is what the filter
propagates and maps at the switch.

At most one element sticks at a time (two would tie the gearbox up, :mod:`..hybrid`): a
sliding element whose slip crosses zero while the other sticks goes on sliding.

Mode codes per element: :data:`OPEN` 0, :data:`SLIDE_POS` +1 / :data:`SLIDE_NEG` −1 (sliding
with, or against, the power-on slip sign :attr:`~.ekf.AugmentedModel.slip_sign`), and
:data:`STICK` 2; the filter's inputs ``slide_<E>`` = ±1/0 and ``stick_<E>`` = 1/0 follow from
them (:meth:`ModeLogic.inputs`).

The same logic is emitted as C beside ``ekf_predict``/``ekf_update``
(``ekf_mode_quantities``: slip, sticking torque and capacity per element from the same
expressions; ``ekf_mode_update``: this function, the lock-up maps as constants;
:func:`gearsym.symbolic.export.generate.ekf_model`), and ``tests/test_ekf_c.py`` holds the two
equal.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy as sp
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.drivetrain import element_short_name
from gearsym.symbolic.estimators.ekf import AugmentedModel, slide_input, stick_input
from gearsym.symbolic.hybrid import (
    BREAK_AWAY,
    ENGAGEMENT,
    LOCK_UP,
    LOCKED,
    OPENING,
    SLIDING,
    hybrid_shift,
    mode_name,
)
from gearsym.symbolic.hybrid import (
    OPEN as HYBRID_OPEN,
)

if TYPE_CHECKING:  # NumPy and CasADi load with the numeric classes only
    import numpy as np

__all__ = [
    "LOCK_UP_CONFIDENCE",
    "MU_AMBIGUITY_SIGMA",
    "OPEN",
    "SLIDE_NEG",
    "SLIDE_POS",
    "STICK",
    "ModeEvent",
    "ModeLogic",
    "ambiguous_mu",
    "ekf_mode_update",
    "lock_up_map",
    "mode_label",
]

OPEN = 0
SLIDE_POS = 1
SLIDE_NEG = -1
STICK = 2

#: σ multiples of μ̂ taken off the capacity in the lock-up test (a break-away tests μ̂ itself).
#: Measured on the default 2-3 shift: without it, in 3 of 10 noise seeds the off-going element
#: re-locked one sample after its break-away and broke away again one or two samples later:
#: its first sliding update raises μ̂_38 from 0.12 to 0.13-0.15 (σ 0.028) while the slip is
#: still near zero and noisy, so 2 N r_m μ̂ F_N briefly exceeds the torque again. With one σ,
#: none of 50 seeds chatters, and a genuine lock-up (the on-coming element at the end of the
#: speed phase, F_N several times what it must hold) is not delayed.
LOCK_UP_CONFIDENCE = 1.0

#: σ multiples of an element's estimated slip within which the filter is unsure whether the
#: element still slides (:func:`ambiguous_mu`): its μ is then not corrected in that update. The
#: friction model (2.60) holds only while the element slides; near synchronism the filter
#: cannot tell a slide from a lock-up, and an update with the sliding model while the gearbox
#: already sticks blames μ for the missing friction torque. Measured with the filter on its own
#: stated model (tests/test_filter_consistency.py: a torque phase, a break-away, the opening
#: of the off-going element and the on-coming element's lock-up, 200 runs per seed): without
#: the rule a lock-up the filter decided a sample after the truth left μ_05 at −1.5 to −2.9 of
#: its σ, the mean normalised squared error of μ_05 was 1.27-1.89 (χ² band 0.76-1.28) and the
#: NEES/dof 1.02-1.17 over eight seeds (band 0.91-1.09); with two σ, μ_05's 0.90-1.18 and the
#: NEES/dof 0.97-1.03 on five of them. Only a *closing* slip counts: the off-going element
#: just after its break-away slides with a slip near zero too, and whether it slides is what
#: its μ is learnt from (on the default 2-3 reference, 50 runs, applied to it as well the rule
#: raised μ_38's efficiency against the bound from 1.03 to 1.34; closing only, unchanged).
#: It costs the on-coming μ one or two updates per lock-up.
MU_AMBIGUITY_SIGMA = 2.0

_LABELS = {OPEN: "open", SLIDE_POS: "slide_pos", SLIDE_NEG: "slide_neg", STICK: "stick"}


def mode_label(code: int) -> str:
    """``open``, ``slide_pos``, ``slide_neg`` or ``stick``."""
    return _LABELS[int(code)]


@dataclass(frozen=True)
class ModeEvent:
    """One switch the filter decided: ``element`` went from mode ``before`` to ``after``;
    ``kind`` is the hybrid model's name of the guard (break-away, lock-up, opening,
    engagement)."""

    element: str
    kind: str
    before: int
    after: int


def lock_up_map(d: GearboxDescription, aug: AugmentedModel, element: str) -> sp.Matrix:
    """A of z⁺ = A z when ``element`` locks up, in the EKF's states z = [x; p]: the hybrid
    model's state map (:func:`~gearsym.symbolic.hybrid.hybrid_shift`, M-metric projection onto
    the locked set, 2.34) from the mode with ``element`` sliding and the other element open to
    the mode with ``element`` locked (the map depends only on the locked set), re-expressed in
    the EKF's gearbox speeds through the locked mode's kinematics; identity on φ, ω_C and the
    parameters."""
    from gearsym.symbolic.dynamics import gearbox_dynamics

    hs = hybrid_shift(d, aug.shift)
    other = next(e for e in hs.elements if e != element)
    source = mode_name(hs.spec, hs.elements, {element: (SLIDING, 1), other: (HYBRID_OPEN, 0)})
    target = mode_name(hs.spec, hs.elements, {element: (LOCKED, 0), other: (HYBRID_OPEN, 0)})
    state_map = hs.maps[(source, target)]
    src, tgt = hs.modes[source], hs.modes[target]
    names = [v.name for v in src.model.states]
    if names != aug.state_names[: aug.n_x]:  # pragma: no cover - both come from drivetrain_parts
        raise AssertionError(f"hybrid mode states {names} differ from the EKF's")
    dyn = gearbox_dynamics(d)
    index = {b: i for i, b in enumerate(d.body_names)}
    # the EKF's gearbox speeds (the source mode's shafts) in the locked mode's states
    speeds = sp.Matrix.vstack(*(dyn.kinematics.transform[index[s], :] for s in src.keep))
    embed = speeds * tgt.projection
    n_new = embed.cols
    back = sp.zeros(aug.n_x, n_new + 2)
    back[: embed.rows, :n_new] = embed
    back[embed.rows, n_new] = 1  # φ
    back[embed.rows + 1, n_new + 1] = 1  # ω_C
    n = len(aug.state_names)
    A = sp.eye(n)
    A[: aug.n_x, : aug.n_x] = back * state_map.matrix
    return A


class ModeLogic:
    """The numeric pieces :func:`ekf_mode_update` needs, built once per augmented model:
    CasADi functions of (z, u, p) for every element's slip, sticking torque and capacity
    (:class:`~.ekf.AugmentedModel`), the lock-up maps (:func:`lock_up_map`) and the input
    indices of the normal forces and the mode flags."""

    def __init__(self, d: GearboxDescription, aug: AugmentedModel) -> None:
        import numpy as np
        from gearsym.symbolic import naming
        from gearsym.symbolic.numeric import casadi_function
        from gearsym.symbolic.sympy_utils import smart_jacobian

        model = aug.model
        groups = [
            ("z", model.state_symbols),
            ("u", model.input_symbols),
            ("p", model.parameter_symbols),
        ]
        self.aug = aug
        self.elements: tuple[str, ...] = aug.elements
        order = list(self.elements)
        self.slip_fn = casadi_function("slip", groups, [("s", [aug.slip[e] for e in order])])
        self.torque_fn = casadi_function(
            "sticking_torque", groups, [("T", [aug.sticking_torque[e] for e in order])]
        )
        self.capacity_fn = casadi_function(
            "capacity", groups, [("c", [aug.capacity[e] for e in order])]
        )
        # ∂slip/∂z (the slips are linear in the gearbox speeds): σ of the estimated slip, and
        # its rate along the model, (∂slip/∂z) ż
        gradient = smart_jacobian([aug.slip[e] for e in order], model.state_symbols)
        self.slip_gradient_fn = casadi_function(
            "slip_gradient", groups, [("g", gradient), ("r", gradient * model.rhs)]
        )
        inputs = aug.input_names
        self.normal_force = {
            e: inputs.index(naming.normal_force(element_short_name(d, e))) for e in order
        }
        self.slide = {e: inputs.index(slide_input(e)) for e in order}
        self.stick = {e: inputs.index(stick_input(e)) for e in order}
        self.maps = {e: np.array(lock_up_map(d, aug, e), dtype=float) for e in order}
        self.n_x = aug.n_x
        states = aug.state_names
        self.mu_index = {e: states.index(mu) for e, mu in aug.mu_state.items()}

    def inputs(self, u: Sequence[float], modes: Mapping[str, int]) -> np.ndarray:
        """``u`` with every element's ``slide_<E>``/``stick_<E>`` set from ``modes``."""
        import numpy as np

        out = np.array(u, dtype=float)
        for e, code in modes.items():
            out[self.slide[e]] = float(code) if code in (SLIDE_POS, SLIDE_NEG) else 0.0
            out[self.stick[e]] = 1.0 if code == STICK else 0.0
        return out

    def initial_modes(self) -> dict[str, int]:
        """The from-gear the TCU knows it is in: the off-going element sticks, the on-coming
        one is open (the first :func:`ekf_mode_update` corrects either from F_N)."""
        off, on = self.elements
        return {off: STICK, on: OPEN}

    def _evaluate(
        self, z: np.ndarray, u: np.ndarray, p: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        import numpy as np

        # entries after the model's states (a state the filter appends outside the model,
        # e.g. the valve's pressure offset of the drive EKF) are not the model's
        z = np.asarray(z, dtype=float)[: len(self.aug.state_names)]

        def run(fn: object) -> np.ndarray:
            return np.asarray(fn(z, u, p), dtype=float).ravel()  # type: ignore[operator]

        return run(self.slip_fn), run(self.torque_fn), run(self.capacity_fn)

    def map_state(
        self, element: str, z: np.ndarray, P: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """z⁺ = A z, P⁺ = A P Aᵀ of a lock-up of ``element``, by blocks: A is the identity on
        the parameters, whose estimates and covariance block are copied, not recomputed (to
        the bit)."""
        import numpy as np

        n = self.n_x
        A = self.maps[element][:n, :n]
        z_new = np.array(z, dtype=float)
        P_new = np.array(P, dtype=float)
        z_new[:n] = A @ z[:n]
        P_new[:n, :n] = A @ P[:n, :n] @ A.T
        P_new[:n, n:] = A @ P[:n, n:]
        P_new[n:, :n] = P_new[:n, n:].T
        P_new[:n, :n] = 0.5 * (P_new[:n, :n] + P_new[:n, :n].T)
        return z_new, P_new


def ambiguous_mu(
    logic: ModeLogic,
    z: np.ndarray,
    P: np.ndarray,
    u: Sequence[float],
    p: Sequence[float],
    modes: Mapping[str, int],
    sigmas: float = MU_AMBIGUITY_SIGMA,
) -> list[int]:
    """The μ states the next measurement update must not correct (``consider`` of
    :func:`~.ekf.ekf_update`): those of the elements the filter holds sliding (``modes``)
    towards synchronism (the slip closing along the model) whose estimated slip, taken in
    their sliding direction, is below ``sigmas`` times its σ (σ² = g P gᵀ, g = ∂slip/∂z): the
    filter cannot tell whether the element has locked up, so the speeds may not be explained
    by its friction (:data:`MU_AMBIGUITY_SIGMA`). An element that has just broken away (slip
    near zero but opening) keeps its updates: whether it slides is what its μ is learnt from.
    ``z``, ``P`` are the prediction at the sample, ``u`` the known inputs there (their mode
    flags are set from ``modes``)."""

    inputs = logic.inputs(u, modes)
    slip, _, _ = logic._evaluate(z, inputs, p)
    sigma, rate = _slip_spread(logic, z, P, inputs, p)
    out = []
    for i, e in enumerate(logic.elements):
        code = modes[e]
        j = logic.mu_index.get(e)
        if code not in (SLIDE_POS, SLIDE_NEG) or j is None:
            continue
        direction = code * logic.aug.slip_sign[e]
        if not direction * float(rate[i, 0]) < 0.0:  # not closing
            continue
        if direction * slip[i] < sigmas * sigma[i]:
            out.append(j)
    return out


def _slip_spread(
    logic: ModeLogic, z: np.ndarray, P: np.ndarray, inputs: np.ndarray, p: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Per element: σ of its estimated slip (σ² = g P gᵀ, g = ∂slip/∂z) and the slip's rate,
    over the model's states only (a state appended outside the model, e.g. the drive EKF's
    stiffness factor, has no slip of its own). ``inputs`` carry the mode flags."""
    import numpy as np

    n = len(logic.aug.state_names)
    z = np.asarray(z, dtype=float)[:n]
    P = np.asarray(P, dtype=float)[:n, :n]
    gradient, rate = (np.asarray(v, dtype=float) for v in logic.slip_gradient_fn(z, inputs, p))
    sigma = np.array([np.sqrt(max(float(g @ P @ g), 0.0)) for g in gradient])
    return sigma, rate


def _direction(value: float, slip_sign: int) -> int:
    """The slide code whose slip sign (2.70) is the sign of ``value`` (+1 at zero)."""
    return SLIDE_NEG if value * slip_sign < 0 else SLIDE_POS


def ekf_mode_update(
    logic: ModeLogic,
    z: np.ndarray,
    P: np.ndarray,
    u: Sequence[float],
    p: Sequence[float],
    modes: Mapping[str, int],
    sync_band: float = 0.0,
    lock_ups_only: bool = False,
    passed_sigmas: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, dict[str, int], list[ModeEvent]]:
    """One decision of the filter's own mode logic (module text), after the measurement update
    at a sample: from the posterior (``z``, ``P``), the known inputs ``u`` at the sample (its
    mode flags are ignored) and the fixed parameters ``p``, the modes held over the next sample
    interval. Returns (z, P, modes, events); z and P change only at a lock-up (the hybrid
    model's map). ``sync_band`` (rad/s, default 0: the emitted C's rule): a sliding element's
    estimated slip within this distance of zero counts as having reached it (a TCU's
    synchronisation window: at 10 ms a slip closing at 1000 rad/s² is 10 rad/s from zero one
    sample before it crosses, and the on-coming pressure the TCU raises at synchronism then
    drives the filter's μ down if the sliding model stays). The elements are taken in turn
    (off-going first), each seeing the other's mode as already decided. Pure: the arguments
    are not modified.

    ``lock_ups_only``: only a sliding element that locks up (sticks) switches; every other
    decision (opening, engagement, break-away, a slip that reaches zero but cannot stick) is
    left to the decision after the update. This is the check on the *predicted* state before
    the measurement update (:func:`~gearsym.validation.studies.estimation.loop.filter_run`):
    an element that locked up inside the interval is mapped before the sample's measurement
    is weighed, not one sample later. ``passed_sigmas``: a lock-up also needs the slip to
    have passed zero by this many of its σ (σ² = g P gᵀ, g = ∂slip/∂z), i.e. the filter is that
    sure the element has locked up (a prediction's slip has the σ of a prediction)."""
    import numpy as np

    z = np.array(z, dtype=float)
    P = np.array(P, dtype=float)
    new = dict(modes)
    events: list[ModeEvent] = []
    aug = logic.aug
    for i, e in enumerate(logic.elements):
        other = logic.elements[1 - i]
        code = new[e]
        sign = aug.slip_sign[e]
        force = float(u[logic.normal_force[e]])
        if lock_ups_only and (code in (OPEN, STICK) or not force > 0):
            continue
        if not force > 0:
            if code != OPEN:
                new[e] = OPEN
                events.append(ModeEvent(e, OPENING, code, OPEN))
            continue
        slip, torque, capacity = logic._evaluate(z, logic.inputs(u, new), p)
        if code == OPEN:
            new[e] = _direction(slip[i], sign)
            events.append(ModeEvent(e, ENGAGEMENT, code, new[e]))
        elif code == STICK:
            if abs(torque[i]) > capacity[i]:
                new[e] = _direction(torque[i], sign)
                events.append(ModeEvent(e, BREAK_AWAY, code, new[e]))
        elif code * sign * slip[i] <= sync_band - (
            passed_sigmas * _slip_spread(logic, z, P, logic.inputs(u, new), p)[0][i]
            if passed_sigmas
            else 0.0
        ):  # sliding, and the slip has reached zero (passed it by passed_sigmas σ)
            candidate = {**new, e: STICK}
            if new[other] == STICK:  # a tie-up: it cannot stick, it slides on
                direction = _direction(torque[i], sign)
            else:
                z_plus, P_plus = logic.map_state(e, z, P)
                sure = z_plus.copy()  # μ̂ lowered by LOCK_UP_CONFIDENCE σ (module text)
                j = logic.mu_index.get(e)
                if j is not None:
                    sure[j] -= LOCK_UP_CONFIDENCE * float(np.sqrt(max(P_plus[j, j], 0.0)))
                needed = logic._evaluate(z_plus, logic.inputs(u, candidate), p)[1]
                cap = logic._evaluate(sure, logic.inputs(u, candidate), p)[2]
                if abs(needed[i]) <= cap[i]:
                    z, P = z_plus, P_plus
                    new[e] = STICK
                    events.append(ModeEvent(e, LOCK_UP, code, STICK))
                    continue
                direction = _direction(needed[i], sign)
            if direction != code and not lock_ups_only:
                new[e] = direction
                events.append(ModeEvent(e, LOCK_UP, code, direction))
    return z, P, new, events
