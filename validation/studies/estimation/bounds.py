"""The posterior Cramér–Rao bound matched to the EKF (thesis 3.25, 3.26, 4.1, 4.3) on its own
set-up (:func:`ekf_bound`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gearsym.validation.sim.phases import Phase
from gearsym.validation.studies.estimation.setup import EkfSetup

__all__ = [
    "BOUND_ASSUMPTION",
    "EkfBound",
    "ekf_bound",
]


#: How the bound is matched to the filter, printed beside every efficiency.
BOUND_ASSUMPTION = (
    "posterior Cramér–Rao bound (3.25 with the filter's prior P0): the filter's model (4.1), "
    "element modes, sample times and speed noise (3.26), initial states unknown; parameters "
    "constant and the model exact. The filter's random walks (4.1) and model-error noise make "
    "it forget, the truth's μ follows the μ map and the reference is elastic, so efficiency "
    "RMSE / bound > 1 is expected even of a good filter. The bound averages over truths drawn "
    "from the prior; the runs keep one truth and one initial estimate (m_veh 1 prior σ off, "
    "μ and ζ closer), so below 1 is possible where the prior still dominates"
)


NOT_IDENTIFIABLE = "not identifiable in this phase"


@dataclass(frozen=True)
class EkfBound:
    """The posterior Cramér–Rao bound matched to the EKF (:mod:`.posterior_bound`), per sample,
    and what each phase's own information identifies."""

    names: tuple[str, ...]
    t: np.ndarray = field(repr=False)
    sigma: np.ndarray = field(repr=False)  # (N, n): sqrt(diag J_k⁻¹) of z0 = [x0; p]
    #: per phase name: the parameters the phase's own information identifies (the thesis'
    #: elimination (3.3) on its FIM (3.25), the states at the phase start unknown)
    identifiable: dict[str, tuple[str, ...]]
    #: per phase name: γ_j (3.27) of every parameter on the phase's own FIM, all estimated
    gamma: dict[str, dict[str, float]]
    linearised_at: np.ndarray = field(repr=False)  # z0 of the sensitivities
    #: (N, n): the bound of z_k with the filter's process noise (random walks (4.1) and model
    #: error), :func:`~gearsym.validation.studies.posterior_bound.process_noise_bound`
    sigma_process: np.ndarray = field(repr=False)


def truth_problem(setup: EkfSetup, relative_step: float = 1e-5) -> tuple[Any, Any, Any, Any, Any]:
    """The filter's problem linearised along the truth, as the bound and the separability
    analysis take it: f and h of the filter's model (4.1) lambdified to NumPy (not the
    filter's CasADi functions), z0 = the truth, the inputs along the truth (``bound_u`` under
    the μ-map scale form) and the central-difference steps per state."""
    from gearsym.validation.studies.posterior_bound import lambdified

    model = setup.aug.model
    args = (model.state_symbols, model.input_symbols, model.parameter_symbols, setup.p)
    f = lambdified(list(model.rhs), *args)
    h = lambdified(list(model.output_expressions), *args)
    z0 = setup.truth0
    u = setup.u if setup.bound_u is None else setup.bound_u
    steps = relative_step * np.maximum(np.abs(z0), setup.prior_sigma)
    return f, h, z0, u, steps


def ekf_bound(setup: EkfSetup, relative_step: float = 1e-5) -> EkfBound:
    """The posterior bound J_k = P0⁻¹ + Σ S_iᵀ R_i⁻¹ S_i (3.25, 3.26) of the EKF's problem
    (``setup``): sensitivities of the sampled speeds to z0 = [x0; p] by central differences
    of tight DOP853 trajectories of the filter's right-hand side (lambdified, not the filter's
    CasADi functions or RK4 Jacobian), linearised at the truth (the reference's initial
    states, m_veh, ζ; μ at its mean while its element slides). Per phase, the phase's own FIM
    with the states at its start as nuisance (Schur complement, restarted there) goes through
    the thesis' elimination (3.3, γ_max of :data:`GAMMA_MAX`)."""
    from gearsym.symbolic.defaults import GAMMA_MAX
    from gearsym.symbolic.estimators.ekf import slide_input
    from gearsym.symbolic.fisher import eliminate
    from gearsym.validation.studies.hybrid_fisher import schur_complement
    from gearsym.validation.studies.posterior_bound import (
        bound_sigma,
        information_increments,
        output_sensitivities,
        posterior_information,
        process_noise_bound,
    )
    from gearsym.validation.studies.sensitivity_integration import nominal_scales

    f, h, z0, u, steps = truth_problem(setup, relative_step)
    names = setup.names
    n, n_x = len(names), setup.aug.n_x
    variances = setup.sigma_y**2
    _, S, z, flow = output_sensitivities(f, h, z0, setup.t, u, steps, return_flow=True)
    # the speeds' prior (σ of their first measurement) *is* that measurement (filter_run
    # initialises them from it and skips it in the first update): counted once, as the prior
    used_once = variances.copy()
    used_once[0, [k for k, name in enumerate(setup.outputs) if name in names]] = np.inf
    J = posterior_information(S, used_once, np.diag(setup.prior_sigma**2))
    # the filter's process noise over each sample interval: h q, a μ's zero while its
    # element does not slide (its random walk is switched off there, ekf_predict)
    h_step = float(setup.t[1] - setup.t[0]) if len(setup.t) > 1 else 0.0
    process = np.zeros((len(setup.t), n, n))
    slides = [setup.aug.input_names.index(slide_input(e)) for e in setup.aug.elements]
    last_switch = -np.inf  # the truth's last change of an element's slide flag (settling)
    for k in range(len(setup.t)):
        if k > 0 and np.any(np.asarray(u[k])[slides] != np.asarray(u[k - 1])[slides]):
            last_switch = float(setup.t[k])
        since = float(setup.t[k] - last_switch)
        process[k] = np.diag(h_step * setup.aug.process_rates(setup.q, u[k], since))
    sigma_process = process_noise_bound(flow, S, used_once, np.diag(setup.prior_sigma**2), process)
    parameters = list(setup.aug.parameters)
    values = {name: float(z0[names.index(name)]) for name in parameters}
    scales = nominal_scales(parameters, values)
    identifiable: dict[str, tuple[str, ...]] = {}
    gamma: dict[str, dict[str, float]] = {}
    for k, phase in enumerate(setup.phases):
        inside = _phase_samples(setup.t, phase, last=k == len(setup.phases) - 1)
        if inside.size == 0:
            identifiable[phase.name], gamma[phase.name] = (), {}
            continue
        a = inside[0]
        _, G, _ = output_sensitivities(
            f,
            h,
            z[a],
            setup.t[inside],
            u[inside],
            relative_step * np.maximum(np.abs(z[a]), setup.prior_sigma),
        )
        fim = schur_complement(
            _reorder(information_increments(G, variances[inside]).sum(axis=0), n_x),
            n - n_x,
        )
        elimination = eliminate(fim, parameters, scales, gamma_max=GAMMA_MAX)
        identifiable[phase.name] = tuple(elimination.final)
        first = elimination.steps[0].analysis
        gamma[phase.name] = {
            name: float(g) for name, g in zip(first.names, first.gamma, strict=True)
        }
    return EkfBound(
        names=tuple(names),
        t=setup.t,
        sigma=bound_sigma(J),
        identifiable=identifiable,
        gamma=gamma,
        linearised_at=z0,
        sigma_process=sigma_process,
    )


def _reorder(fim: np.ndarray, n_x: int) -> np.ndarray:
    """[x; p] ordered as [p; x] (the Schur complement keeps the leading block)."""
    order = np.r_[np.arange(n_x, len(fim)), np.arange(n_x)]
    return fim[np.ix_(order, order)]


def _phase_samples(t: np.ndarray, phase: Phase, last: bool) -> np.ndarray:
    """Indices of the samples in [t_start, t_end) of ``phase`` (the last phase: its end too)."""
    return np.flatnonzero((t >= phase.t_start) & ((t < phase.t_end) | last))
