"""The defaults a command starts from, in one light module (no SymPy, NumPy or SciPy), so that
building the command line costs nothing. Each value says where it comes from.
"""

from __future__ import annotations

#: The shift the thesis studies (chapters 3-5): the power-on 2-3 upshift.
DEFAULT_SHIFT = "2-3"

#: Parameters of the sensitivity study (3.2) of the built-in gearbox's 2-3 shift: vehicle mass,
#: side-shaft stiffness and damping, μ of the off-going clutch K38, road grade. For another
#: shift or gearbox the μ is that of its off-going element.
SENSITIVITY_PARAMETERS: tuple[str, ...] = ("m_veh", "k_ss", "d_ss", "mu_38", "zeta")

#: p of the augmented model (4.1) for the 2-3 shift: m_veh, μ38, μ05, ζ.
OBSERVABILITY_PARAMETERS: tuple[str, ...] = ("m_veh", "mu_38", "mu_05", "zeta")

SAMPLE_TIME = 0.01  # s, TCU measurement period (assumed)
SPEED_ERROR = 0.01  # relative error r_i of ω1, ω2, ω_C (3.26), assumed
ACCELERATION_ERROR = 0.10  # relative error of ω̇_C (3.32), "deutlich höher", assumed
FLOOR_FRACTION = 0.01  # y_min = 1 % of the largest measured value (3.26)
GAMMA_MAX = 0.1  # limit of the normalised scatter (3.27), assumed

#: Default relative speed-sensor error r_i (3.26) of the EKF's measurements (assumed, as in the
#: Fisher study: 1 % on every output), and the floor fraction y_min = 1 % of the largest value
#: (:mod:`gearsym.validation.studies.estimation`; the synthetic recording of
#: :mod:`gearsym.validation.sim.measurement` draws the same noise).
EKF_RELATIVE_NOISE = 0.01
EKF_FLOOR_FRACTION = 0.01

#: How μ acts on a swapping element's torque in the sensitivity runs: "detected" from the
#: record (|T| at the friction capacity) or the thesis' "phases" (torque and speed phase).
SLIDING_MODES = ("detected", "phases")
SLIDING_PHASES = ("torque phase", "speed phase")

#: s, spacing of the simulated time series (gearsym.validation.sim.simulate)
RECORD_SAMPLE_TIME = 5e-4

#: Largest base sample count N of a sweep, in a definition file as on the command line
#: (N (d + 2) shift runs: 100 000 with five parameters is 700 000 runs).
SWEEP_MAX_SAMPLES = 100_000
