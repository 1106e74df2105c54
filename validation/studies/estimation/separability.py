"""What one shift cannot separate: the vehicle's parameters against an input-torque gain.

A TCU knows the input torque only from the engine's torque model and the e-machine's command;
a gain error k_T on it (the fleet's ``input_torque_gain``, ``engine_torque_gain``) acts on the
speeds much as a heavier or lighter vehicle on another grade does. Whether the filter could
estimate k_T beside its parameters is a question of the Fisher information (3.25) of the
filter's own problem: the speeds' sensitivities to z0 = [x0; p] (as the posterior bound
computes them, central differences of DOP853 trajectories of the filter's lambdified model)
and to k_T (T_In scaled by 1 ± δ), per detected phase with the states at the phase's start
unknown (Schur complement), then (3.27): the normalised scatter γ of each parameter with k_T
known and with k_T unknown, and the correlation of m_veh and k_T where the information is
invertible. γ > 0.1 (the thesis' γ_max) means not identifiable in that phase.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["GAIN", "Separability", "fim_correlation", "torque_gain_separability"]

#: The name of the input-torque gain in the reports.
GAIN = "input_torque_gain"


@dataclass(frozen=True)
class Separability:
    """Per phase (and ``"shift"`` for all samples): γ per parameter with the gain known and
    with it unknown, the gain's own γ, and the m_veh–gain correlation (``None`` where the
    information is singular)."""

    phases: dict[str, dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        return self.phases


def fim_correlation(fim: np.ndarray, a: int, b: int) -> float | None:
    """The correlation of parameters ``a`` and ``b`` in the inverse of the Fisher information
    ``fim`` (the Cramér-Rao covariance, 3.25); ``None`` where ``fim`` is singular: a window that
    cannot tell a parameter from the others has no covariance, and the inverse of a singular
    matrix is rounding (a "correlation" beyond ±1 or a negative variance)."""
    try:
        cov = np.linalg.inv(fim)
    except np.linalg.LinAlgError:
        return None
    if not (cov[a, a] > 0 and cov[b, b] > 0):
        return None
    value = float(cov[a, b] / np.sqrt(cov[a, a] * cov[b, b]))
    return value if abs(value) <= 1.0 else None


def _gamma(fim: np.ndarray, names: list[str], scales: np.ndarray) -> dict[str, float | None]:
    from gearsym.symbolic.fisher import analyse

    analysis = analyse(fim, names, scales)
    return {
        n: (float(g) if np.isfinite(g) else None)
        for n, g in zip(names, analysis.gamma, strict=True)
    }


def torque_gain_separability(
    setup: Any, relative_step: float = 1e-5, gain_step: float = 1e-4
) -> Separability:
    """The Fisher analysis of the module text on the filter's problem ``setup`` (an
    :class:`~gearsym.validation.studies.estimation.setup.EkfSetup` with a truth), linearised
    at its truth."""
    from gearsym.symbolic import naming
    from gearsym.validation.studies.estimation.bounds import _phase_samples, truth_problem
    from gearsym.validation.studies.hybrid_fisher import schur_complement
    from gearsym.validation.studies.posterior_bound import output_sensitivities
    from gearsym.validation.studies.sensitivity_integration import nominal_scales

    f, h, z0, u, steps = truth_problem(setup, relative_step)
    names = setup.names
    n, n_x = len(names), setup.aug.n_x
    _, S, _ = output_sensitivities(f, h, z0, setup.t, u, steps)
    column = list(setup.aug.input_names).index(naming.INPUT_TORQUE)
    ys = []
    for sign in (1.0, -1.0):
        scaled = np.array(u, dtype=float)
        scaled[:, column] *= 1.0 + sign * gain_step
        ys.append(output_sensitivities(f, h, z0, setup.t, scaled, steps)[0])
    S_gain = (ys[0] - ys[1]) / (2 * gain_step)
    full = np.concatenate([S, S_gain[:, :, None]], axis=2)  # (N, m, n + 1)
    weights = 1.0 / setup.sigma_y**2
    weights[0] = 0.0  # the first measurement initialises the speeds (filter_run)
    parameters = list(setup.aug.parameters)
    values = {name: float(z0[names.index(name)]) for name in parameters}
    scales = np.append(nominal_scales(parameters, values), 1.0)
    order = np.r_[np.arange(n_x, n), n, np.arange(n_x)]  # [p; k_T; x0]
    windows = [("shift", np.arange(len(setup.t)))]
    for k, phase in enumerate(setup.phases):
        windows.append(
            (phase.name, _phase_samples(setup.t, phase, last=k == len(setup.phases) - 1))
        )
    out: dict[str, dict[str, Any]] = {}
    for name, inside in windows:
        if inside.size == 0:
            continue
        fim = np.einsum("kip,ki,kiq->pq", full[inside], weights[inside], full[inside])
        fim = fim[np.ix_(order, order)]
        count = len(parameters)
        # the parameters the window informs at all (a μ whose element does not slide has no
        # row: its equations do not contain it there), then the gain, then the states
        seen = [
            j for j in range(count) if fim[j, j] * scales[j] ** 2 > 1e-12 * np.max(np.diag(fim))
        ]
        keep = [*seen, count, *range(count + 1, len(order))]
        fim = fim[np.ix_(keep, keep)]
        m = len(seen)
        with_gain = schur_complement(fim, m + 1)
        without = [*range(m), *range(m + 1, len(keep))]
        known = schur_complement(fim[np.ix_(without, without)], m)
        shown = [parameters[j] for j in seen]
        gamma_known = _gamma(known, shown, scales[seen])
        gamma_unknown = _gamma(with_gain, [*shown, GAIN], np.append(scales[seen], 1.0))
        correlation = None
        if "m_veh" in shown:
            correlation = fim_correlation(with_gain, shown.index("m_veh"), m)
        out[name] = {
            "gamma_gain_known": gamma_known,
            "gamma_gain_unknown": gamma_unknown,
            "correlation_m_veh_gain": correlation,
        }
    return Separability(out)
