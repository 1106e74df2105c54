"""Stage 4b: sensitivities along the reference shift (thesis 3.2–3.4, Figures 3.4–3.8).

The 2↔3 shift model (2.55)–(2.58) is driven open-loop by the signals the reference simulation
(:mod:`gearsym.validation.sim.simulate`) recorded, from the recorded initial state, and integrated
together with its sensitivity ODE (3.7) (:mod:`gearsym.symbolic.sensitivity`).

The pieces: the driven shift model and the record that drives it
(:mod:`~gearsym.validation.studies.driven_shift`), its integration with the sensitivities
(:mod:`~gearsym.validation.studies.sensitivity_integration`), the independent peers of the
sensitivities (:mod:`~gearsym.validation.studies.sensitivity_peers`) and the CSV and figures of
a run (:mod:`~gearsym.validation.studies.sensitivity_output`); this module runs them along the
reference shift (:func:`run_sensitivities`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.sensitivity import sensitivity_equations
from gearsym.validation.sim.phases import Phase
from gearsym.validation.studies.driven_shift import (
    Progress,
    ReferenceData,
    driven_shift_model,
    driving_inputs,
    initial_state,
    reference_data,
    sliding_masks,
    thesis_parameters,
)
from gearsym.validation.studies.sensitivity_integration import (
    CompiledModel,
    Interpolated,
    SensitivityTrajectory,
    initial_sensitivities,
    integrate_sensitivities,
    nominal_scales,
    parameter_values,
)

__all__ = [
    "SensitivityRun",
    "run_sensitivities",
]


@dataclass(frozen=True)
class SensitivityRun:
    """Sensitivities of the driven shift model along the reference shift (3.2–3.4)."""

    trajectory: SensitivityTrajectory
    phases: tuple[Phase, ...]
    values: dict[str, float]  # parameter values used
    scales: np.ndarray  # p_j0 (3.3) per chosen parameter
    nominal_states: np.ndarray  # x_i0 = max |x_i(t)| (3.4)
    reference_states: np.ndarray  # recorded x at the same samples
    sliding: dict[str, np.ndarray]  # element -> sliding mask at the samples
    mode: str
    source: str
    timings: dict[str, float]

    @property
    def normalised(self) -> np.ndarray:
        """S_N,ij = S_ij p_j0 / x_i0 (3.3), (N, n, m)."""
        tr = self.trajectory
        return tr.S * self.scales[None, None, :] / self.nominal_states[None, :, None]

    @property
    def normalised_rate(self) -> np.ndarray:
        """d S_N,ij / dt = Ṡ_ij p_j0 / x_i0, (N, n, m)."""
        tr = self.trajectory
        return tr.dS * self.scales[None, None, :] / self.nominal_states[None, :, None]

    def drift(self) -> dict[str, float]:
        """max |x_driven − x_recorded| / x_i0 per state: how well the open-loop driven shift
        model reproduces the reference."""
        error = np.max(np.abs(self.trajectory.x - self.reference_states), axis=0)
        return {
            name: float(e / s)
            for name, e, s in zip(
                self.trajectory.state_names, error, self.nominal_states, strict=True
            )
        }


def run_sensitivities(
    d: GearboxDescription,
    parameters: Sequence[str] | None = None,
    data: ReferenceData | None = None,
    overrides: Mapping[str, float] | None = None,
    with_wheel_acceleration: bool = False,
    mode: str = "detected",
    t_eval: np.ndarray | None = None,
    max_step: float = 5e-4,
    initial: str = "stationary",
    progress: Progress | None = None,
) -> SensitivityRun:
    """Derive and integrate the sensitivities of the driven shift model along the reference.

    ``t_eval`` defaults to the record's samples; the integration starts at the first record
    sample whatever ``t_eval`` is. ``initial`` chooses S(t0) (:func:`initial_sensitivities`).
    """
    import time

    say = progress or (lambda message: None)
    timings = {}
    if data is None:
        say("simulating the reference shift")
        start = time.perf_counter()
        data = reference_data(d, progress=progress)
        timings["reference_s"] = time.perf_counter() - start
    start = time.perf_counter()
    driven = driven_shift_model(d, data.shift, with_wheel_acceleration)
    if parameters is None:
        parameters = thesis_parameters(driven)
    eqs = sensitivity_equations(driven.model, parameters, file=d.file)
    compiled = CompiledModel(eqs.augmented)
    timings["derive_s"] = time.perf_counter() - start
    values = parameter_values(driven.model, overrides)
    masks = sliding_masks(d, driven, data, mode)
    u = driving_inputs(driven, data, masks, values)
    inputs = Interpolated(data.t, u)
    x0 = initial_state(driven.model, data)
    samples = data.t if t_eval is None else np.asarray(t_eval, dtype=float)
    if samples[0] != data.t[0]:
        samples = np.concatenate([[data.t[0]], samples])
    say(
        f"integrating x and {len(eqs.parameters)} sensitivity columns "
        f"({len(eqs.augmented.states)} states) over {data.t[-1] - data.t[0]:.3g} s"
    )
    start = time.perf_counter()
    s0 = initial_sensitivities(eqs, x0, u[0], values, initial)
    trajectory = integrate_sensitivities(eqs, inputs, x0, values, samples, max_step, compiled, s0)
    timings["integrate_s"] = time.perf_counter() - start
    reference = np.column_stack(
        [np.interp(samples, data.t, data.signals[name]) for name in trajectory.state_names]
    )
    nominal = np.max(np.abs(trajectory.x), axis=0)  # (3.4)
    nominal[nominal == 0] = 1.0
    index = np.clip(np.searchsorted(data.t, samples), 0, len(data.t) - 1)
    return SensitivityRun(
        trajectory=trajectory,
        phases=data.phases,
        values=values,
        scales=nominal_scales(trajectory.parameter_names, values),
        nominal_states=nominal,
        reference_states=reference,
        sliding={e: m[index] for e, m in masks.items()},
        mode=mode,
        source=data.source,
        timings=timings,
    )
