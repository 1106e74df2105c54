"""Speed sensors as a TCU reads them: a toothed wheel on the shaft, a timer that counts the
period between two tooth edges, and the speed computed from the last complete period.

A Hall or inductive sensor facing a wheel of N teeth gives an edge each time the shaft turns by
the pitch 2π/N. The TCU's capture unit timestamps the edges with a timer of resolution Δ; at
each task sample it reads the last complete period T (rounded to Δ) and computes
ω̂ = (2π/N) / T. So the reading is the *mean* speed over the last tooth period, it is late by
half a period plus the transport ``latency`` (edge to sample), and it is quantised (a relative
step of Δ/T). These are the sensor's errors; no Gaussian noise is added on top.

Before the simulated window the shaft is taken to have turned at its initial speed (the vehicle
was driving), so the first sample has a period too. A shaft at standstill gives no edges: its
reading holds the last speed (a TCU times out to zero; the shifts simulated here never stop a
measured shaft)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ToothWheel", "tooth_wheel_speeds"]


@dataclass(frozen=True)
class ToothWheel:
    """One sensor: ``teeth`` edges per revolution, the period timer's resolution ``timer`` (s)
    and the ``latency`` (s) from an edge to the sample that may use it."""

    teeth: int
    timer: float
    latency: float = 0.0

    def __post_init__(self) -> None:
        if self.teeth < 1:
            raise ValueError(f"teeth must be at least 1, got {self.teeth}")
        if not (self.timer > 0 and math.isfinite(self.timer)):
            raise ValueError(f"timer must be finite and > 0, got {self.timer}")
        if not (self.latency >= 0 and math.isfinite(self.latency)):
            raise ValueError(f"latency must be finite and >= 0, got {self.latency}")

    @property
    def pitch(self) -> float:
        """The angle between two edges (rad)."""
        return 2 * math.pi / self.teeth


def _edges(t: np.ndarray, omega: np.ndarray, pitch: float) -> tuple[np.ndarray, float]:
    """Edge times of a shaft with speed ``omega`` (linear between the samples ``t``), and the
    period before the first sample (the shaft at its initial speed before ``t[0]``). The angle
    is the integral of |ω| (a sensor counts edges whichever way the shaft turns); an edge at
    angle k·pitch inside an interval is where the quadratic angle reaches it."""
    t, keep = np.unique(t, return_index=True)
    omega = np.abs(omega[keep])
    dt = np.diff(t)
    angle = np.concatenate(([0.0], np.cumsum(0.5 * (omega[:-1] + omega[1:]) * dt)))
    levels = np.arange(1, int(angle[-1] / pitch) + 1) * pitch
    i = np.clip(np.searchsorted(angle, levels, side="left") - 1, 0, len(dt) - 1)
    a, b = omega[i], (omega[i + 1] - omega[i]) / dt[i]  # ω = a + b τ in interval i
    need = levels - angle[i]  # a τ + b τ²/2 = need
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.maximum(a * a + 2 * b * need, 0.0))
        tau = np.where(np.abs(b) > 1e-12 * np.maximum(a, 1.0), 2 * need / (a + root), need / a)
    first = pitch / omega[0] if omega[0] > 0 else math.inf
    return t[i] + tau, first


def tooth_wheel_speeds(
    t: np.ndarray, omega: np.ndarray, samples: np.ndarray, sensor: ToothWheel
) -> np.ndarray:
    """The speeds the TCU reads at ``samples`` (s) from a shaft turning at ``omega`` (rad/s,
    given at ``t``, linear between): per sample the last complete tooth period that ended at
    least ``sensor.latency`` before it, rounded to the timer, as (2π/N)/T with the sign of the
    shaft's speed at that period's end. Before the first edge, the period the shaft had at its
    initial speed."""
    t = np.asarray(t, dtype=float)
    omega = np.asarray(omega, dtype=float)
    samples = np.asarray(samples, dtype=float)
    edges, first_period = _edges(t, omega, sensor.pitch)
    # edges before t[0] at the initial speed: one at t[0] itself and one a period earlier
    history = np.array([t[0] - first_period, t[0]])
    edges = np.concatenate((history, edges))
    last = np.searchsorted(edges, samples - sensor.latency, side="right") - 1
    last = np.clip(last, 1, len(edges) - 1)
    period = edges[last] - edges[last - 1]
    ticks = np.maximum(np.round(period / sensor.timer), 1.0)
    speed = sensor.pitch / (ticks * sensor.timer)
    sign = np.sign(np.interp(edges[last], t, omega))
    return np.where(np.isfinite(period), np.where(sign < 0, -speed, speed), np.nan)
