"""One record per named quantity of a description: unit, description, plausibility range, sign,
plot symbol, and, for the parameters the estimators augment (4.1), the default random walk and
prior.

Every stage reads these records: the description parser (section and unit), the drivetrain
models (description, sign), the emitted ``params_validate`` and the A2L limits (range), the EKF
(random walk), the estimation studies (prior, plot labels) and the sensitivity plots (symbol).
Nothing here imports SymPy or NumPy: the description's data layer stands on it.

The friction coefficients are one family, ``mu_<element>`` (one μ parameter per friction
element, (2.59)-(2.70)); :func:`record` resolves any such name to the family's record.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "MU_PREFIX",
    "ParameterRecord",
    "RECORDS",
    "axis_label",
    "is_mu",
    "record",
    "section_units",
    "symbol",
    "zero_scale",
]

MU_PREFIX = "mu_"

_SUBSCRIPTS = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")


@dataclass(frozen=True)
class ParameterRecord:
    """Everything gearsym states about one quantity, defined once."""

    key: str
    #: Description table the value lives in ("vehicle", "drivetrain", "friction"); "element"
    #: for a field of a friction element's table, "mu" for the μ family.
    section: str
    #: Unit the description must state (``unit = ...``); "1" is dimensionless.
    unit: str
    #: Plain Unicode symbol for plots ("ζ", "m_veh"); mathtext parsing was a large share of
    #: the plotting time.
    symbol: str
    #: One line with the thesis' equation, shown with the models' parameters ("" when none).
    description: str = ""
    #: Closed plausibility range the emitted ``params_validate`` enforces and the A2L file
    #: states (``None``: unbounded; the record is then not checked there).
    bounds: tuple[float | None, float | None] | None = None
    #: May be zero or negative (everything else must be positive).
    signed: bool = False
    #: Default random-walk intensity q_p (unit²/s) when the EKF augments it (4.1): assumed, the
    #: thesis states the random walk but no numbers. ``None``: never augmented.
    random_walk: float | None = None
    #: Default prior standard deviation of the filter's start (stated, not the truth): relative
    #: to the calibration's value when ``prior_relative``, else in the record's unit.
    prior_sigma: float | None = None
    prior_relative: bool = False
    #: Reference scale p_j0 of the normalisation (3.3), (3.27) when the nominal value is zero
    #: (``None``: 1 in the record's unit).
    zero_scale: float | None = None
    #: Sampling range of a parameter without a default, for the emitted code's random checks.
    sample_range: tuple[float, float] | None = None


#: In the order of the description's tables (the parser reads them in this order).
RECORDS: tuple[ParameterRecord, ...] = (
    # drivetrain (2.42-2.53)
    ParameterRecord("i_D", "drivetrain", "1", "i_D"),
    ParameterRecord(
        "k_ss",
        "drivetrain",
        "N*m/rad",
        "k_ss",
        "side-shaft torsional stiffness, per shaft (2.47)",
        (1.0, 1.0e7),
    ),
    ParameterRecord(
        "d_ss",
        "drivetrain",
        "N*m*s/rad",
        "d_ss",
        "side-shaft torsional damping, per shaft (2.47)",
        (0.0, 1.0e5),
    ),
    ParameterRecord("J_cs", "drivetrain", "kg*m^2", "J_cs"),
    ParameterRecord("J_D", "drivetrain", "kg*m^2", "J_D"),
    ParameterRecord(
        "I_wheel",
        "drivetrain",
        "kg*m^2",
        "I_wheel",
        "wheel-side inertia: wheels, side shafts, half the differential (2.46)",
        (0.01, 1000.0),
    ),
    # viscous drag of each idle shaft to the housing (docs: idle shafts), optional
    ParameterRecord("idle_drag", "drivetrain", "N*m*s/rad", "idle_drag"),
    # vehicle and road loads (2.48-2.49)
    ParameterRecord(
        "m_veh",
        "vehicle",
        "kg",
        "m_veh",
        "vehicle mass",
        (100.0, 100000.0),
        # 1 kg/√s: constant within a drive; lets the filter follow a load change over
        # minutes, not within a shift
        random_walk=1.0,
        prior_sigma=0.3,
        prior_relative=True,
    ),
    ParameterRecord("r_dyn", "vehicle", "m", "r_dyn"),
    ParameterRecord("g", "vehicle", "m/s^2", "g"),
    ParameterRecord("rho_air", "vehicle", "kg/m^3", "ρ_air", "air density (2.49b)", (0.5, 2.0)),
    ParameterRecord("c_W", "vehicle", "1", "c_W", "drag coefficient (2.49b)", (0.05, 2.0)),
    ParameterRecord("A_front", "vehicle", "m^2", "A_front", "frontal area (2.49b)", (0.1, 20.0)),
    ParameterRecord(
        "f_roll",
        "vehicle",
        "s/m",
        "f_roll",
        "rolling-resistance factor of the thesis' form F_r = v f_roll cos(zeta) m g (2.49a)",
        (0.0, 0.1),
    ),
    ParameterRecord(
        "f_R",
        "vehicle",
        "1",
        "f_R",
        "rolling-resistance coefficient, F_r = f_R cos(zeta) m g",
        (0.0, 0.1),
    ),
    ParameterRecord(
        "f_R0",
        "vehicle",
        "1",
        "f_R0",
        "rolling resistance f_Roll(v) = f_R0 + f_R1 v + f_R2 v^2, constant part (2.49a)",
        (-0.05, 0.1),  # a fit may dip below zero
        signed=True,
    ),
    ParameterRecord(
        "f_R1",
        "vehicle",
        "s/m",
        "f_R1",
        "rolling resistance f_Roll(v), coefficient of v (2.49a)",
        (-0.01, 0.01),
        signed=True,
    ),
    ParameterRecord(
        "f_R2",
        "vehicle",
        "s^2/m^2",
        "f_R2",
        "rolling resistance f_Roll(v), coefficient of v^2 (2.49a)",
        (-1.0e-3, 1.0e-3),
        signed=True,
    ),
    ParameterRecord(
        "zeta",
        "vehicle",
        "rad",
        "ζ",
        "road grade angle (2.49)",
        (-0.5, 0.5),
        signed=True,
        # 0.005 rad/√s: a grade changes over tens of metres
        random_walk=2.5e-5,
        prior_sigma=0.05,
        zero_scale=0.05,  # level road: a 5 % grade (0.05 rad, assumed) stands in for p_j0
    ),
    # friction (2.59-2.70)
    ParameterRecord("sigma0", "friction", "N*m/rad", "σ₀", bounds=(1.0, 1.0e9)),
    ParameterRecord("sigma1", "friction", "N*m*s/rad", "σ₁", bounds=(0.0, 1.0e6)),
    ParameterRecord("z_ba_ratio", "friction", "1", "z_ba/z_ss", bounds=(0.0, 0.99), signed=True),
    ParameterRecord("T_oil", "friction", "degC", "T_oil", signed=True),
    ParameterRecord("mu_nominal", "friction", "1", "μ_nominal"),
    # fields of a friction element's table and of the emitted friction model
    ParameterRecord("t_ss_min", "element", "N*m", "T_ss,min", bounds=(1.0e-9, 1.0e3)),
    ParameterRecord(
        "n_disc", "element", "1", "n_disc", bounds=(1.0, 50.0), sample_range=(2.0, 8.0)
    ),
    ParameterRecord("r_m", "element", "m", "r_m", bounds=(0.005, 1.0), sample_range=(0.05, 0.12)),
    # the friction coefficient of each element, mu_<element>
    ParameterRecord(
        "mu",
        "mu",
        "1",
        "μ",
        bounds=(0.0, 1.0),
        # the wet-clutch μ moves with slip and temperature by about 0.02 within a 0.1 s speed
        # phase (the reference's μ map), so σ grows by 0.02 in 0.1 s: q = 0.02²/0.1
        random_walk=4.0e-3,
        prior_sigma=0.03,
    ),
)

_BY_KEY = {r.key: r for r in RECORDS}


def is_mu(name: str) -> bool:
    """``mu_<element>``: a friction coefficient of the μ family."""
    return name.startswith(MU_PREFIX) and name not in _BY_KEY


def record(name: str) -> ParameterRecord:
    """The record of ``name`` (``mu_<element>`` resolves to the μ family); KeyError if none."""
    return _BY_KEY["mu"] if is_mu(name) else _BY_KEY[name]


def symbol(name: str) -> str:
    """Plot symbol of ``name``: ``μ₃₈`` for ``mu_38``, ``ζ`` for ``zeta``; the name itself
    when gearsym states nothing about it."""
    if is_mu(name):
        suffix = name[len(MU_PREFIX) :]
        return "μ" + (suffix.translate(_SUBSCRIPTS) if suffix.isdigit() else f"_{suffix}")
    return _BY_KEY[name].symbol if name in _BY_KEY else name


def axis_label(name: str) -> str:
    """Axis label: the symbol and its unit (``m_veh / kg``, ``ζ / rad``; ``μ₃₈`` alone)."""
    unit = record(name).unit if (is_mu(name) or name in _BY_KEY) else "1"
    return symbol(name) if unit == "1" else f"{symbol(name)} / {unit}"


def zero_scale(name: str) -> float:
    """p_j0 of (3.3), (3.27) for a parameter whose nominal value is zero."""
    r = record(name) if (is_mu(name) or name in _BY_KEY) else None
    return r.zero_scale if r is not None and r.zero_scale is not None else 1.0


def section_units() -> dict[str, dict[str, str]]:
    """Description table -> key -> required unit, in the order the tables are read."""
    sections: dict[str, dict[str, str]] = {}
    for r in RECORDS:
        if r.section in ("drivetrain", "vehicle", "friction"):
            sections.setdefault(r.section, {})[r.key] = r.unit
    return sections
