"""The filter's μ as a scale on the calibration's μ map (``[estimator] mu_model =
"map_scale"``): μ_E = s_E · μ_map(p_E, T_oil, |Δω̂_E|).

The thesis' filter (4.1) makes μ itself a random walk; but a wet clutch's μ rises with slip
(the μ map, 2.69), so within one shift μ moves by about 0.02 and the random walk, switched
off at lock-up, keeps the low-slip value. A TCU has the map (it is calibration: the emitted
``gearsym_mu_map`` C looks it up) and what varies from vehicle to vehicle and over the life of
the clutch is its level (oil temperature, wear). So the filter estimates the scale s_E and is
told the element's torque capacity through its normal-force input: F_N,E · μ_map(p_E, T_oil,
|Δω̂_E|), the map read at the commanded pressure p_E = F_N,E / A_E, the calibration's oil
temperature and the slip of the filter's own estimate (Δω̂ linear in the speed states). The
model (4.1) and the emitted filter are unchanged: its ``mu_<E>`` state holds s_E and its F_N
input the mapped normal force. The map's slope ∂μ/∂|Δω| does not enter the filter's Jacobian
(the map is read as an input at the estimate; its slope is about 5e-4 per rad/s, so the
neglected term is small against the slip's own coefficient).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gearsym.symbolic.description import GearboxDescription

__all__ = ["MapScaleForm", "map_scale_form"]


@dataclass(frozen=True)
class MapScaleForm:
    """The F_N inputs of the swapping elements multiplied by the μ map at the filter's slip."""

    elements: tuple[str, ...]
    columns: tuple[int, ...]  # index of each element's F_N in the filter's u
    areas: tuple[float, ...]  # the calibration's piston areas (p = F_N / A)
    slip_rows: np.ndarray  # (elements × states): Δω_E = row · z
    mu_map: Any  # gearsym.symbolic.friction.MuMap
    t_oil: float
    #: index of each element's valve input (``valve_<E>``, a filter with the valves' offset
    #: state), else empty: the offset's force A θ acts through the same map value
    valve_columns: tuple[int, ...] = ()

    def factors(self, z: np.ndarray, u: np.ndarray) -> np.ndarray:
        """μ_map(p_E, T_oil, |Δω_E|) per element at the state estimate ``z`` and inputs ``u``."""
        pressure = np.array([u[c] / a for c, a in zip(self.columns, self.areas, strict=True)])
        slip = np.abs(self.slip_rows @ np.asarray(z, dtype=float))
        return np.asarray(self.mu_map(pressure, self.t_oil, slip), dtype=float)

    def __call__(self, z: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``u`` with each swapping element's F_N times its map value at ``z``."""
        out = np.array(u, dtype=float)
        factors = self.factors(z, out)
        out[list(self.columns)] *= factors
        if self.valve_columns:
            out[list(self.valve_columns)] *= factors
        return out

    def along(self, u: np.ndarray, slips: np.ndarray) -> np.ndarray:
        """The inputs along a known slip history (N × elements): the posterior bound's, which
        linearises along the truth."""
        out = np.array(u, dtype=float)
        for k, (c, a) in enumerate(zip(self.columns, self.areas, strict=True)):
            factor = np.asarray(
                self.mu_map(out[:, c] / a, self.t_oil, np.abs(slips[:, k])), dtype=float
            )
            out[:, c] *= factor
            if self.valve_columns:
                out[:, self.valve_columns[k]] *= factor
        return out


def map_scale_form(d: GearboxDescription, aug: Any) -> MapScaleForm:
    """The map-scale form of the filter ``aug`` (its augmented model (4.1)) with the
    calibration ``d``'s μ map, oil temperature and piston areas."""
    from gearsym.symbolic import naming
    from gearsym.symbolic.drivetrain import element_short_name, quantity
    from gearsym.symbolic.estimators.ekf import valve_input
    from gearsym.symbolic.friction import load_mu_map

    states = aug.model.state_symbols
    inputs = list(aug.input_names)
    columns, areas, rows = [], [], []
    for e in aug.elements:
        element = d.element(e)
        assert element.a_piston is not None
        columns.append(inputs.index(naming.normal_force(element_short_name(d, e))))
        areas.append(float(element.a_piston.value))
        rows.append([float(aug.slip[e].diff(s)) for s in states])
    return MapScaleForm(
        elements=tuple(aug.elements),
        columns=tuple(columns),
        areas=tuple(areas),
        slip_rows=np.array(rows),
        mu_map=load_mu_map(d),
        t_oil=float(quantity(d, "friction", "T_oil").value),
        valve_columns=tuple(
            inputs.index(valve_input(e)) for e in aug.elements if valve_input(e) in inputs
        ),
    )
