"""Every name gearsym makes out of a description's names, and the check that they stay apart.

Shaft, planet, set, element and gear names become parts of SymPy symbols (``omega_<shaft>``,
``T_<element>``), model variables and C struct fields, columns of ``timeseries.csv``
(``slip_<element>``), model names and from those file names, include guards and macros
(``gearsym_shift_<from>_<to>_mu.h``, ``GEARSYM_SHIFT_<FROM>_<TO>_MU_X_…``). Two different
things with one name would silently share a SymPy symbol, interleave two signals in one CSV
column, overwrite one emitted model with another, or end in a traceback. The rules live here
so that the code that makes the names and :func:`check_names`, which runs when a description
is loaded, cannot disagree.
"""

from __future__ import annotations

import keyword
import re
from collections.abc import Sequence
from dataclasses import dataclass

from gearsym.symbolic.description import GearboxDescription
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.parameters import record
from gearsym.symbolic.set_kinds import file_key
from gearsym.symbolic.shifts import shift_spec

# ---------------------------------------------------------------------------------------------
# Symbols of the gearbox (2.26-2.39) and the drivetrain (2.42-2.58)
# ---------------------------------------------------------------------------------------------


def angle(body: str) -> str:
    """φ of a shaft or planet body."""
    return f"phi_{body}"


def speed(body: str) -> str:
    """ω of a shaft or planet body (also a state and a ``timeseries.csv`` column)."""
    return f"omega_{body}"


def inertia(body: str) -> str:
    return f"J_{body}"


def torque(name: str) -> str:
    """Torque of a shift element, or of the gearbox input/output (:data:`INPUT_TORQUE`)."""
    return f"T_{name}"


def sun_teeth(planetary_set: str) -> str:
    return f"z_S_{planetary_set}"


def planet_teeth(planetary_set: str) -> str:
    return f"z_P_{planetary_set}"


def ring_teeth(planetary_set: str) -> str:
    return f"z_H_{planetary_set}"


def carrier_radius(planetary_set: str) -> str:
    return f"r_T_{planetary_set}"


def planet_mass(planetary_set: str) -> str:
    return f"m_P_{planetary_set}"


def stationary_ratio(planetary_set: str) -> str:
    """k = z_ring / z_sun of a set (symbolic in the tooth search)."""
    return f"k_{planetary_set}"


def reflected_inertia(planetary_set: str, role: str) -> str:
    """Planet inertia of a set given by k, reflected to its sun, carrier or ring
    (``planet_inertia_reflected``): ``Jr_S_<set>``, ``Jr_T_<set>``, ``Jr_H_<set>``."""
    letter = {"sun": "S", "carrier": "T", "ring": "H"}[role]
    return f"Jr_{letter}_{planetary_set}"


def second_sun_teeth(planetary_set: str) -> str:
    """Teeth of the Ravigneaux sun meshing the short pinions."""
    return f"z_S2_{planetary_set}"


def second_ring_teeth(planetary_set: str) -> str:
    """Teeth of the ring meshing the short pinions of a Ravigneaux set with two rings."""
    return f"z_H2_{planetary_set}"


def second_planet_teeth(planetary_set: str) -> str:
    """Teeth of the second pinion (outer / short) or of the ring-side step of a stepped planet."""
    return f"z_P2_{planetary_set}"


def second_carrier_radius(planetary_set: str) -> str:
    """Orbit radius of the second pinion."""
    return f"r_T2_{planetary_set}"


def second_planet_mass(planetary_set: str) -> str:
    """Lumped mass of the second pinions of a set."""
    return f"m_P2_{planetary_set}"


def second_stationary_ratio(planetary_set: str) -> str:
    """k2 = z_ring / z_sun2 of a Ravigneaux set (its short-pinion pair); z_ring2 / z_sun of
    a Ravigneaux set with two rings."""
    return f"k2_{planetary_set}"


INPUT = "In"  # key of the input torque among the element torques (T_In)
OUTPUT = "Out"  # key of the gearbox output torque (T_Out, 2.38)
INPUT_TORQUE = torque(INPUT)
OUTPUT_TORQUE = torque(OUTPUT)
TWIST = "phi"  # side-shaft twist (2.43)
WHEEL_SPEED = speed("C")  # ω_C (2.44)
RESISTANCE_INPUT = "T_res_star"  # T_res* of the linear form (5.2)


def measured(signal: str) -> str:
    """Model output of a measured signal (3.31): ``y_omega_1``."""
    return f"y_{signal}"


def derivative(signal: str) -> str:
    """Time derivative of a signal (a ``timeseries.csv`` column): ``domega_1``."""
    return f"d{signal}"


def element_short_name(element: str, elements: Sequence[str]) -> str:
    """Thesis-style short name among ``elements``: K38 → 38, B05 → 05 (mu_38, F_N05), when
    no other K/B element has the same digits; otherwise the full name."""
    rest = element[1:]
    shorts = [e[1:] for e in elements if e[:1] in "KB"]
    if element[:1] in "KB" and rest.isdigit() and shorts.count(rest) == 1:
        return rest
    return element


def normal_force(short: str) -> str:
    """F_N of an element (2.69), by its short name."""
    return f"F_N{short}"


def friction_coefficient(element: str) -> str:
    """μ of an element (2.69): by its short name in the shift models and ``timeseries.csv``,
    by its full name in the reference model."""
    return f"mu_{element}"


def bristle(element: str) -> str:
    """Bristle deflection z of an element (2.66)."""
    return f"z_{element}"


def pressure(element: str) -> str:
    return f"p_{element}"


def slip_symbol(element: str) -> str:
    """Δω of an element as a symbol of the friction law (2.59)."""
    return f"dw_{element}"


def slip_column(element: str) -> str:
    """Δω of an element as a ``timeseries.csv`` column."""
    return f"slip_{element}"


# Columns of timeseries.csv that no description name enters (validation/sim/simulate.py).
TIME = "t"
ENGINE_TORQUE = "T_engine"
E_MACHINE_TORQUE = "T_e_machine"
SIDE_SHAFT_TORQUE = "T_ss"
DRIVETRAIN_OUTPUT_TORQUE = "T_out"  # 2 T_ss / i_D (2.52), a column beside the symbol T_Out
ROAD_TORQUE = "T_res"
RATIO = "ratio"
VEHICLE_SPEED = "v_vehicle"
#: Road grade ζ (2.49c): the drivetrain parameter, and the timeseries.csv column of ζ(t) (the
#: same quantity, so the same name).
GRADE = "zeta"
#: Input of the driven shift model: ζ(t) − ζ0, the recorded grade's deviation from the
#: parameter ζ0 (validation/studies/driven_shift.py), so that ∂/∂ζ is a constant offset.
GRADE_DEVIATION = "zeta_dev"
ENERGY_TERMS = ("W_in", "W_friction", "W_damper", "W_road")

# ---------------------------------------------------------------------------------------------
# Parameters of the elastic drivetrain and the vehicle (2.42-2.53), by description key
# ---------------------------------------------------------------------------------------------

#: Vehicle and drivetrain values that are parameters of every drivetrain model (symbols with
#: defaults). Geometry (teeth, inertias, i_D, r_dyn) is hardware and enters as exact numbers.
PARAMETER_KEYS = ("m_veh", "k_ss", "d_ss", "zeta", "I_wheel", "rho_air", "c_W", "A_front")
#: The parameters of each rolling-resistance form (2.49a): the thesis' printed form, the
#: textbook form, and a speed-dependent coefficient f_Roll(v) = f_R0 + f_R1 v + f_R2 v² that
#: contains both (f_R1 = f_roll, or f_R0 = f_R, the rest zero).
ROLLING_KEYS = {"thesis": ("f_roll",), "textbook": ("f_R",), "polynomial": ("f_R0", "f_R1", "f_R2")}

#: One line per drivetrain parameter, shown with the models' parameters (the records of
#: :mod:`gearsym.symbolic.parameters`).
DESCRIPTIONS = {
    key: record(key).description
    for key in (*PARAMETER_KEYS, *dict.fromkeys(k for ks in ROLLING_KEYS.values() for k in ks))
}

#: Parameters that may be zero or negative (real symbols, not positive ones).
SIGNED_PARAMETERS = tuple(key for key in DESCRIPTIONS if record(key).signed)

# ---------------------------------------------------------------------------------------------
# Models and what is emitted for them
# ---------------------------------------------------------------------------------------------

FULL_MODEL = "full"
REFERENCE_MODEL = "reference"
SHIFT_ELEMENT_MODEL = "shift_element"
MU_MAP = "mu_map"  # not a Model, but emitted under the same file names


def shift_model_name(from_gear: str, to_gear: str, friction_inputs: bool = False) -> str:
    """``shift_<from>_<to>``, with ``_mu`` for the friction-input variant (2.69)."""
    return f"shift_{from_gear}_{to_gear}" + ("_mu" if friction_inputs else "")


def sensitivity_model_name(model: str) -> str:
    """The augmented system [x; S] (3.7) of a model."""
    return f"{model}_sens"


def model_file_names(model: str) -> dict[str, str]:
    """Emitted files of a model: keys ``"header"``, ``"source"``, ``"casadi"``."""
    base = f"gearsym_{model}"
    return {"header": f"{base}.h", "source": f"{base}.c", "casadi": f"{base}_casadi.py"}


def function_prefix(model: str) -> str:
    """Prefix of every C function and type of a model: ``gearsym_<model>_``."""
    return f"gearsym_{model}_"


def macro_prefix(model: str) -> str:
    """Prefix of every macro of a model, include guard included: ``GEARSYM_<MODEL>_``."""
    return f"GEARSYM_{model.upper()}_"


# ---------------------------------------------------------------------------------------------
# Names C and Python keep for themselves
# ---------------------------------------------------------------------------------------------

# fmt: off
C_KEYWORDS = frozenset({
    "auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else",
    "enum", "extern", "float", "for", "goto", "if", "inline", "int", "long", "register",
    "restrict", "return", "short", "signed", "sizeof", "static", "struct", "switch", "typedef",
    "union", "unsigned", "void", "volatile", "while", "_Bool", "_Complex", "_Imaginary",
    # C11
    "_Alignas", "_Alignof", "_Atomic", "_Generic", "_Noreturn", "_Static_assert", "_Thread_local",
})
# Object-like macros of <math.h>, <stddef.h>, <stdio.h>, <errno.h> and common ECU headers: a
# struct field of that name would be macro-expanded in ``p->NAME``.
C_MACRO_NAMES = frozenset({
    "NAN", "INFINITY", "HUGE_VAL", "HUGE_VALF", "HUGE_VALL", "NULL", "EOF", "FP_NAN",
    "FP_INFINITE", "FP_ZERO", "FP_NORMAL", "FP_SUBNORMAL", "FP_FAST_FMA", "MATH_ERRNO",
    "MATH_ERREXCEPT", "math_errhandling", "errno", "TRUE", "FALSE", "bool", "true", "false",
})
# <math.h> functions (double, float and long double forms) and classification macros: the
# emitted code includes <math.h> and calls some of them through GEARSYM_<FN> macros.
_MATH_BASE = (
    "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh",
    "acosh", "atanh", "exp", "exp2", "expm1", "log", "log2", "log10", "log1p", "sqrt", "cbrt",
    "pow", "fabs", "floor", "ceil", "round", "trunc", "fmod", "fmin", "fmax", "copysign",
    "hypot", "erf", "erfc", "tgamma", "lgamma", "fma", "frexp", "ldexp", "modf", "nan",
)
C_MATH_NAMES = frozenset(
    {n + suffix for n in _MATH_BASE for suffix in ("", "f", "l")}
    | {"isnan", "isinf", "isfinite", "isnormal", "signbit", "fpclassify", "abs"}
)
# fmt: on
_C_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def c_identifier_problem(name: str) -> str | None:
    """Why ``name`` cannot be a C (and Python) identifier of the emitted code, or None."""
    if not _C_IDENTIFIER.fullmatch(name):
        return "is not a C identifier"
    if name in C_KEYWORDS or keyword.iskeyword(name):
        return "is a C keyword or a Python keyword"
    if name in C_MACRO_NAMES:
        return "is a standard C macro"
    if name in C_MATH_NAMES:
        return "is a <math.h> name the emitted code uses"
    if name.startswith("__") or re.match(r"_[A-Z]", name):
        return "is a reserved identifier (C reserves a leading '__' or '_' + capital)"
    if name.upper().startswith("GEARSYM"):
        return "is reserved for gearsym's own macros"
    if re.fullmatch(r"M_[A-Z0-9_]+", name):
        return "collides with a <math.h> constant"
    return None


# ---------------------------------------------------------------------------------------------
# The check
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Name:
    name: str
    what: str  # what it stands for, e.g. "torque of shift element 'In'"
    key: str | None  # the description key that makes it; None when built in


class _Space:
    """Names that must stay apart, also ignoring case (include guards and macros are upper
    case, and a case-insensitive file system merges files that differ only in case)."""

    def __init__(self, file: str, kind: str, consequence: str) -> None:
        self.file = file
        self.kind = kind
        self.consequence = consequence
        self.folded: dict[str, _Name] = {}

    def add(self, name: str, what: str, key: str | None, identifier: bool = True) -> None:
        new = _Name(name, what, key)
        if key is not None and identifier:
            problem = c_identifier_problem(name)
            if problem:
                raise GearsymError(self.file, key, f"{self.kind} {name!r} ({what}) {problem}")
        old = self.folded.get(name.casefold())
        if old is None:
            self.folded[name.casefold()] = new
            return
        if old.what == new.what or (old.key is None and new.key is None):
            return  # one thing under two rules, or two built-in names in different roles
        same = "is also" if old.name == name else f"differs only in case from {old.name!r},"
        raise GearsymError(
            self.file,
            key if key is not None else old.key or "",
            f"{self.kind} {name!r} ({what}) {same} the {old.what}"
            f"{'' if old.key else ', built in'}: {self.consequence}",
        )


def check_names(d: GearboxDescription) -> None:
    """Raise :class:`GearsymError` if two different things of ``d`` would get one name.

    Covers every SymPy symbol, model variable, C struct field and ``timeseries.csv`` column
    made from the description's names (also ignoring case), every model name (and with it its
    files, C function prefix, macros and include guard), and C keywords, reserved and
    standard-library identifiers. Sensitivity and input-derivative names
    (``S_<state>__<parameter>``, ``<input>__d1``) need no entry: description names contain no
    ``__``, so those names cannot meet any other. C function names ``gearsym_<model>_<fn>`` and
    macros ``GEARSYM_<MODEL>_<suffix>`` cannot meet across models unless the model names do
    (no function or macro suffix of one model starts like another's), so the model names
    stand for them.
    """
    f = d.file
    names = _Space(
        f,
        "name",
        "two different quantities would share one symbol, model variable or timeseries.csv "
        "column; rename one",
    )
    builtin = [
        (INPUT_TORQUE, "input torque T_In (engine + e-machine)"),
        (OUTPUT_TORQUE, "gearbox output torque T_Out (2.38)"),
        (TWIST, "side-shaft twist phi (2.43)"),
        (derivative(TWIST), "side-shaft twist rate column dphi (2.44)"),
        (WHEEL_SPEED, "wheel speed omega_C (2.44)"),
        (measured(WHEEL_SPEED), "measured wheel speed"),
        (measured(derivative(WHEEL_SPEED)), "measured wheel acceleration"),
        (derivative(WHEEL_SPEED), "wheel acceleration column"),
        (RESISTANCE_INPUT, "resistance input T_res* (5.2)"),
        (TIME, "time column"),
        (ENGINE_TORQUE, "engine torque column"),
        (E_MACHINE_TORQUE, "e-machine torque column"),
        (SIDE_SHAFT_TORQUE, "side-shaft torque column T_ss (2.47)"),
        (DRIVETRAIN_OUTPUT_TORQUE, "output torque column 2 T_ss / i_D (2.52)"),
        (ROAD_TORQUE, "road resistance torque column T_res (2.48)"),
        (RATIO, "ratio column"),
        (VEHICLE_SPEED, "vehicle speed column"),
        (GRADE_DEVIATION, "grade deviation input zeta(t) - zeta0"),
        *((term, f"energy column {term}") for term in ENERGY_TERMS),
        *(
            (key, f"drivetrain parameter {key}")
            for key in (*DESCRIPTIONS, *(k for ks in ROLLING_KEYS.values() for k in ks))
        ),
    ]
    for name, what in builtin:
        names.add(name, what, None)

    bodies = {s.name: (f'shaft[name="{s.name}"].name', f"shaft {s.name!r}") for s in d.shafts}
    for ps in d.planetary_sets:
        bodies[ps.planet] = (f'planetary_set[name="{ps.name}"].planet', f"planet {ps.planet!r}")
        if ps.planet2 is not None:
            key = f'planetary_set[name="{ps.name}"].{file_key(ps.kind, "planet2")}'
            bodies[ps.planet2] = (key, f"planet {ps.planet2!r}")
    for body, (key, of) in bodies.items():
        names.add(angle(body), f"angle of {of}", key)
        names.add(speed(body), f"speed of {of}", key)
        names.add(inertia(body), f"inertia of {of}", key)
        if body in d.measured_shafts:
            names.add(measured(speed(body)), f"measured speed of {of}", key)
        if body in d.coordinates:  # a state: its derivative is a timeseries.csv column
            names.add(derivative(speed(body)), f"acceleration of {of}", key)
    for ps in d.planetary_sets:
        key = f'planetary_set[name="{ps.name}"].name'
        of = f"of set {ps.name!r}"
        names.add(sun_teeth(ps.name), f"sun teeth {of}", key)
        names.add(planet_teeth(ps.name), f"planet teeth {of}", key)
        names.add(ring_teeth(ps.name), f"ring teeth {of}", key)
        names.add(carrier_radius(ps.name), f"carrier radius {of}", key)
        names.add(planet_mass(ps.name), f"planet mass {of}", key)
        names.add(stationary_ratio(ps.name), f"stationary ratio {of}", key)
        for role in ("sun", "carrier", "ring"):
            names.add(reflected_inertia(ps.name, role), f"reflected {role} inertia {of}", key)
        if ps.z_sun2 is not None:
            names.add(second_sun_teeth(ps.name), f"second sun teeth {of}", key)
            names.add(second_stationary_ratio(ps.name), f"second stationary ratio {of}", key)
        if ps.z_ring2 is not None:
            names.add(second_ring_teeth(ps.name), f"second ring teeth {of}", key)
            names.add(second_stationary_ratio(ps.name), f"second stationary ratio {of}", key)
        if ps.z_planet2 is not None:
            names.add(second_planet_teeth(ps.name), f"second planet teeth {of}", key)
        if ps.planet2 is not None:
            names.add(second_carrier_radius(ps.name), f"second carrier radius {of}", key)
            names.add(second_planet_mass(ps.name), f"second planet mass {of}", key)
    elements = [e.name for e in d.shift_elements]
    for e in elements:
        key = f'shift_element[name="{e}"].name'
        of = f"of shift element {e!r}"
        short = element_short_name(e, elements)
        names.add(torque(e), f"torque {of}", key)
        names.add(bristle(e), f"bristle deflection {of}", key)
        names.add(pressure(e), f"pressure {of}", key)
        names.add(slip_symbol(e), f"slip {of}", key)
        names.add(slip_column(e), f"slip column {of}", key)
        names.add(friction_coefficient(e), f"friction coefficient {of}", key)
        names.add(friction_coefficient(short), f"friction coefficient {of}", key)
        names.add(normal_force(short), f"normal force {of}", key)

    models = _Space(
        f,
        "model name",
        "one emitted model would overwrite the other (files gearsym_<model>.h/.c/_casadi.py, "
        "macros and include guard GEARSYM_<MODEL>_, also on case-insensitive file systems); "
        "rename a gear",
    )
    for name in (FULL_MODEL, REFERENCE_MODEL, SHIFT_ELEMENT_MODEL, MU_MAP):
        models.add(name, f"{name} model", None, identifier=False)
    drivable = [g.name for g in d.gears if not g.neutral]
    for a in drivable:
        for b in drivable:
            if a == b:
                continue
            try:
                spec = shift_spec(d, f"{a}-{b}", max_swaps=2)
            except GearsymError:
                continue  # neither a single nor a double swap: no model is ever made for it
            key = f'gear[name="{b}"].name'
            torque_model = shift_model_name(a, b)
            mu_model = shift_model_name(a, b, friction_inputs=True)
            models.add(torque_model, f"model of shift {a}-{b}", key, identifier=False)
            if not spec.single:
                continue  # a double swap has the torque-input model only
            models.add(mu_model, f"model of shift {a}-{b} with friction inputs", key, False)
            models.add(
                sensitivity_model_name(mu_model), f"sensitivity system of shift {a}-{b}", key, False
            )
