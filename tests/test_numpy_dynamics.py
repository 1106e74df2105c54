"""Two independent derivations of the dynamics agree: the symbolic models (SymPy: mesh rows,
transform (2.29), mass matrix (2.34), projection (2.55)) against the plain-NumPy reference of
:mod:`gearsym.validation.checks.numpy_dynamics` (published Willis relations per set kind,
body speeds by one linear solve, M from the kinetic energy, Q from virtual power, the
drivetrain written out from 2.42–2.53).

Compared at random states, inputs and parameters (fixed seeds), to 1e-9 relative per entry of
ẋ: for every description the repository ships (the built-in 9-speed, ``tests/data``, the
examples, the set-kind sketches ``docs/set_kinds``, sets given by ``k``, and the built-in
gearbox with the textbook and the polynomial rolling resistance), the full model
(2.53), every drivable gear, every adjacent shift (single swaps in the torque and the μ form,
double swaps in the torque form) and every mode of every adjacent single-swap hybrid shift.
Descriptions without a drivetrain (the sketches, ``simpson_3speed.toml``) borrow the built-in
gearbox's ``[drivetrain]``, ``[vehicle]`` and ``[friction]`` sections.

The comparison has teeth: the NumPy route with the planets' orbital term left out
(``orbital=False``, the bug the older tests missed) disagrees with the models in every gear
where a carrier turns, and still agrees where none does.
"""

from __future__ import annotations

import ast
import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic import naming
from gearsym.symbolic.description import GearboxDescription, default_config_text
from gearsym.symbolic.description_parser import parse_description
from gearsym.symbolic.drivetrain import (
    adjacent_shifts,
    drivetrain_model,
    element_short_name,
    full_model,
    shift_model,
)
from gearsym.symbolic.hybrid import LOCKED, SLIDING, hybrid_shift
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.model import Model
from gearsym.symbolic.ratios import idle_shafts
from gearsym.validation.checks import numpy_dynamics as nd

from tests.test_reflected_inertia import k_reflected_text, reflected_by_numpy

ROOT = Path(__file__).resolve().parents[1]
MODULE = ROOT / "validation" / "checks" / "numpy_dynamics.py"
#: Every description the repository ships (scenario files in tests/data are not descriptions).
FILES = {
    "thesis_9speed": None,
    "simpson_3speed": ROOT / "tests" / "data" / "simpson_3speed.toml",
    "simpson_3speed_one_way": ROOT / "tests" / "data" / "simpson_3speed_one_way.toml",
    "simpson_overdrive_idle": ROOT / "tests" / "data" / "simpson_overdrive_idle.toml",
    "thesis_9speed_alt_teeth": ROOT / "tests" / "data" / "thesis_9speed_alt_teeth.toml",
    "dog_9speed": ROOT / "tests" / "data" / "dog_9speed.toml",
    "lepelletier_6speed": ROOT / "gearsym" / "data" / "examples" / "lepelletier_6speed.toml",
    "mercedes_7g_tronic": ROOT / "gearsym" / "data" / "examples" / "mercedes_7g_tronic.toml",
    **{
        f"sketch_{kind}": ROOT / "docs" / "set_kinds" / f"{kind}.toml"
        for kind in ("simple", "double_pinion", "ravigneaux", "ravigneaux_two_rings")
        + ("stepped_planet",)
    },
}
#: Sets given by k with their planets as reflected inertias (tests/test_reflected_inertia.py).
K_KINDS = ("simple", "double_pinion", "stepped_planet")
#: The built-in gearbox with the other two rolling-resistance forms (2.49a).
THESIS_FORM = 'rolling_resistance = "thesis"'
ROLLING_FORMS = {
    "textbook": 'rolling_resistance = "textbook"',
    "polynomial": (
        'f_R0 = { value = 0.008, unit = "1", source = "test" }\n'
        'f_R1 = { value = 0.0002, unit = "s/m", source = "test" }\n'
        'f_R2 = { value = 0.00001, unit = "s^2/m^2", source = "test" }\n'
        'rolling_resistance = "polynomial"'
    ),
}
TOLERANCE = 1e-9
POINTS = 4  # random points per model


def with_drivetrain(d: GearboxDescription) -> GearboxDescription:
    """``d``, with the built-in gearbox's drivetrain, vehicle and friction values if it has
    none (a model needs them; the gearbox part is ``d``'s own)."""
    if d.drivetrain:
        return d
    builtin = load_description()
    return dataclasses.replace(
        d,
        drivetrain=builtin.drivetrain,
        vehicle=builtin.vehicle,
        friction=builtin.friction,
        rolling_resistance=builtin.rolling_resistance,
    )


def description(name: str) -> GearboxDescription:
    if name.startswith("rolling_"):
        text = default_config_text()
        assert THESIS_FORM in text
        form = ROLLING_FORMS[name.removeprefix("rolling_")]
        return parse_description(text.replace(THESIS_FORM, form), f"{name}.toml")
    if name.startswith("k_"):
        kind = name.removeprefix("k_")
        text = k_reflected_text(kind, reflected_by_numpy(kind))
        return with_drivetrain(parse_description(text, f"{name}.toml"))
    return with_drivetrain(load_description(FILES[name]))


# ---------------------------------------------------------------------------------------------
# The cases: a symbolic model and how the NumPy route builds the same one
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Case:
    """A symbolic model, the elements the NumPy route locks, and how each of the model's
    inputs becomes an element torque (``torques``: element -> function of the input and
    parameter values by name)."""

    label: str
    model: Model
    locked: tuple[str, ...]
    torques: Mapping[str, Callable[[Mapping[str, float]], float]]


def kept_shafts(model: Model) -> tuple[str, ...]:
    """The shafts whose speeds are the model's gearbox states (its layout; the dynamics of
    the NumPy route do not depend on which shafts they are)."""
    return tuple(v.name.removeprefix("omega_") for v in model.states[:-2])


def torque_inputs(elements: Sequence[str]) -> dict[str, Callable[[Mapping[str, float]], float]]:
    return {e: (lambda v, e=e: v[naming.torque(e)]) for e in elements}


def friction_inputs(
    d: GearboxDescription, signs: Mapping[str, int]
) -> dict[str, Callable[[Mapping[str, float]], float]]:
    """Element torques k_sign 2 N_disc r_m μ F_N (2.69, 3.14) from the model's F_N input and μ
    parameter of each element (names only from the model's naming)."""
    result = {}
    for e, sign in signs.items():
        short = element_short_name(d, e)
        force, mu = naming.normal_force(short), naming.friction_coefficient(short)
        result[e] = lambda v, e=e, s=sign, f=force, m=mu: nd.friction_torque(
            d.element(e), v[m], v[f], s
        )
    return result


def model_cases(d: GearboxDescription) -> list[Case]:
    """The full model, every drivable gear, every adjacent shift (torque form; μ form for a
    single swap whose elements have friction data)."""
    cases = [Case("full", full_model(d), (), torque_inputs([e.name for e in d.shift_elements]))]
    for g in d.gears:
        if g.neutral:
            continue
        model = drivetrain_model(
            d, f"gear_{g.name}", locked=g.closed, torque_elements=(), keep=(d.output_shaft,)
        )
        cases.append(Case(f"gear {g.name}", model, g.closed, {}))
    for a, b in nd.adjacent_shifts(d):
        locked, off, on = nd.shift_elements(d, a, b)
        model = shift_model(d, f"{a}-{b}")
        cases.append(Case(f"shift {a}-{b}", model, locked, torque_inputs([*off, *on])))
        swapping = [d.element(e) for e in (*off, *on)]
        if len(off) == len(on) == 1 and all(e.n_disc and e.r_m for e in swapping):
            signs = nd.power_on_slip_signs(d, a, b)
            model = shift_model(d, f"{a}-{b}", friction_inputs=True)
            cases.append(Case(f"shift {a}-{b} mu", model, locked, friction_inputs(d, signs)))
    return cases


def hybrid_cases(d: GearboxDescription) -> list[Case]:
    """Every mode of every adjacent single-swap shift whose friction elements have friction
    data: the shared elements and the mode's locked swapping element locked, a sliding
    element's torque in the μ form with the mode's slip sign, an open or overrunning one
    absent (2.54)."""
    cases = []
    for a, b in nd.adjacent_shifts(d):
        locked, off, on = nd.shift_elements(d, a, b)
        swapping = [d.element(e) for e in (*off, *on)]
        if len(off) != 1 or len(on) != 1 or all(e.one_way for e in swapping):
            continue
        if not all(e.one_way or (e.n_disc and e.r_m) for e in swapping):
            continue
        for mode in hybrid_shift(d, f"{a}-{b}").modes.values():
            status = mode.status
            mode_locked = (*locked, *(e for e in (*off, *on) if status[e][0] == LOCKED))
            signs = {e: k for e, (s, k) in status.items() if s == SLIDING}
            cases.append(Case(mode.name, mode.model, mode_locked, friction_inputs(d, signs)))
    return cases


# ---------------------------------------------------------------------------------------------
# The comparison
# ---------------------------------------------------------------------------------------------


def random_values(model: Model, rng: np.random.Generator) -> dict[str, float]:
    """States, inputs and parameters by name: speeds ±300 rad/s, twist ±0.02 rad, wheel
    0–60 rad/s, T_In −200…400 N·m, element torques ±600 N·m, F_N 0–2·10⁴ N; parameters at
    their defaults times 0.8–1.2, ζ in ±0.05 rad."""
    values: dict[str, float] = {}
    for v in model.states:
        if v.name == naming.TWIST:
            values[v.name] = rng.uniform(-0.02, 0.02)
        elif v.name == naming.WHEEL_SPEED:
            values[v.name] = rng.uniform(0.0, 60.0)
        else:
            values[v.name] = rng.uniform(-300.0, 300.0)
    for v in model.inputs:
        if v.name == naming.INPUT_TORQUE:
            values[v.name] = rng.uniform(-200.0, 400.0)
        elif v.unit == "N":
            values[v.name] = rng.uniform(0.0, 2e4)
        else:
            values[v.name] = rng.uniform(-600.0, 600.0)
    for v in model.parameters:
        if v.name == naming.GRADE:
            values[v.name] = rng.uniform(-0.05, 0.05)
        else:
            assert v.default is not None
            values[v.name] = float(v.default) * rng.uniform(0.8, 1.2)
    return values


def relative_difference(got: np.ndarray, expected: np.ndarray) -> float:
    """Largest |got − expected| relative to |expected| entry by entry (an entry below 10⁻⁶ of
    the vector's largest counts as that floor, so that a chance cancellation is not a
    failure)."""
    floor = 1e-6 * float(np.abs(expected).max())
    return float(np.max(np.abs(got - expected) / np.maximum(np.abs(expected), floor)))


def worst_difference(
    d: GearboxDescription, case: Case, rng: np.random.Generator, orbital: bool = True
) -> float:
    """Largest relative difference of the model's ẋ and the NumPy route's over random points."""
    model = case.model
    symbols = [v.symbol for v in (*model.states, *model.inputs, *model.parameters)]
    names = [v.name for v in (*model.states, *model.inputs, *model.parameters)]
    f = sp.lambdify(symbols, list(model.rhs), "numpy")
    reference = nd.numpy_model(d, case.locked, kept_shafts(model), orbital=orbital)
    parameters = {v.name for v in model.parameters}
    worst = 0.0
    for _ in range(POINTS):
        values = random_values(model, rng)
        got = np.array(f(*(values[n] for n in names)), dtype=float)
        expected = reference.rhs(
            [values[v.name] for v in model.states],
            values[naming.INPUT_TORQUE],
            {e: torque(values) for e, torque in case.torques.items()},
            {k: v for k, v in values.items() if k in parameters},
        )
        worst = max(worst, relative_difference(got, expected))
    return worst


DESCRIPTIONS = [
    *FILES,
    *(f"k_{kind}" for kind in K_KINDS),
    *(f"rolling_{form}" for form in ROLLING_FORMS),
]


@pytest.mark.parametrize("name", DESCRIPTIONS)
def test_two_derivations_agree_on_every_gear_and_shift(name: str) -> None:
    d = description(name)
    rng = np.random.default_rng(2024)
    cases = model_cases(d)
    differences = {case.label: worst_difference(d, case, rng) for case in cases}
    print(
        f"{name}: {len(cases)} models, largest relative difference {max(differences.values()):.2e}"
    )
    assert max(differences.values()) < TOLERANCE, differences


@pytest.mark.parametrize(
    "name",
    [
        "thesis_9speed",
        "simpson_3speed_one_way",
        "simpson_overdrive_idle",
        "thesis_9speed_alt_teeth",
        "lepelletier_6speed",
        "mercedes_7g_tronic",
    ],
)
def test_two_derivations_agree_on_every_hybrid_mode(name: str) -> None:
    d = description(name)
    rng = np.random.default_rng(2025)
    cases = hybrid_cases(d)
    assert cases
    differences = {case.label: worst_difference(d, case, rng) for case in cases}
    print(
        f"{name}: {len(cases)} modes, largest relative difference {max(differences.values()):.2e}"
    )
    assert max(differences.values()) < TOLERANCE, differences


@pytest.mark.parametrize("name", DESCRIPTIONS)
def test_two_derivations_find_the_same_shifts_ratios_and_idle_shafts(name: str) -> None:
    """The NumPy route's own shift list, gear ratios and idle shafts are the derivation's."""
    d = description(name)
    symbolic = adjacent_shifts(d)
    assert [f"{a}-{b}" for a, b in nd.adjacent_shifts(d)] == [s.name for s in symbolic]
    for spec in symbolic:
        locked, off, on = nd.shift_elements(d, spec.from_gear, spec.to_gear)
        assert (locked, off, on) == (spec.locked, spec.off_elements, spec.on_elements)
    assert nd.idle_shafts(d) == idle_shafts(d)
    for g in d.gears:
        if not g.neutral:
            ratio = nd.gear_ratio(d, g.name)
            assert abs(ratio - g.ratio) <= 0.5 * 10.0 ** (-d.ratio_decimals) * (1 + 1e-9)


def test_every_shipped_description_is_compared() -> None:
    """A description added to the repository joins the comparison (or this test says so)."""
    shipped = {
        path.resolve()
        for folder in ("tests/data", "gearsym/data", "docs/set_kinds")
        for path in (ROOT / folder).rglob("*.toml")
        if "\n[gearbox]\n" in "\n" + path.read_text(encoding="utf-8")
    }
    listed = {p.resolve() for p in FILES.values() if p is not None}
    assert shipped - {(ROOT / "gearsym" / "data" / "thesis_9speed.toml").resolve()} == listed


# ---------------------------------------------------------------------------------------------
# Teeth: a wrong mass matrix in one route makes the comparison fail
# ---------------------------------------------------------------------------------------------


def carrier_turns(d: GearboxDescription, case: Case) -> bool:
    """Whether some set's carrier turns in the case's motions (its orbital term matters)."""
    reference = nd.numpy_model(d, case.locked, kept_shafts(case.model))
    index = {b: i for i, b in enumerate(reference.bodies)}
    carriers = {ps.carrier for ps in d.planetary_sets if ps.carrier != nd.HOUSING}
    return any(np.abs(reference.speed_map[index[c]]).max() > 1e-12 for c in carriers)


def test_comparison_fails_without_the_orbital_term_where_a_carrier_turns() -> None:
    """The planted bug the older tests missed, planted into the NumPy route: with the planets'
    orbit ½ n m_p r_p² ω_C² left out of the kinetic energy (``orbital=False``) the two
    derivations disagree in every gear and shift of the built-in gearbox (a carrier turns in
    each) far beyond the tolerance, so the comparison above would catch the same omission in
    the symbolic mass matrix (2.34)."""
    d = description("thesis_9speed")
    rng = np.random.default_rng(7)
    cases = [c for c in model_cases(d) if not c.label.endswith("mu")]
    assert all(carrier_turns(d, c) for c in cases)
    differences = {c.label: worst_difference(d, c, rng, orbital=False) for c in cases}
    print({k: f"{v:.2e}" for k, v in differences.items()})
    assert min(differences.values()) > 1e3 * TOLERANCE, differences


def test_without_the_orbital_term_a_held_carrier_still_agrees() -> None:
    """The flag removes the orbit and nothing else: in the set-kind sketches' one gear (the
    carrier braked, so its planets do not orbit) the route without the orbital term still
    agrees, while the full model of each (the carrier free) does not."""
    rng = np.random.default_rng(8)
    for kind in ("simple", "double_pinion", "ravigneaux", "ravigneaux_two_rings"):
        d = description(f"sketch_{kind}")
        full, gear = model_cases(d)[:2]
        assert gear.label == "gear 1" and not carrier_turns(d, gear) and carrier_turns(d, full)
        assert worst_difference(d, gear, rng, orbital=False) < TOLERANCE
        assert worst_difference(d, full, rng, orbital=False) > 1e3 * TOLERANCE


# ---------------------------------------------------------------------------------------------
# Independence of the NumPy route
# ---------------------------------------------------------------------------------------------


def test_numpy_reference_imports_nothing_of_the_derivation() -> None:
    """The reference reads the parsed description and NumPy only: no SymPy, no CasADi, no
    module of the derivation (kinematics, dynamics, drivetrain, ratios, set_kinds)."""
    imported = set()
    for node in ast.walk(ast.parse(MODULE.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            imported |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add(node.module or "")
    allowed = {
        "__future__",
        "collections.abc",
        "dataclasses",
        "numpy",
        "gearsym.symbolic.description",
    }
    assert imported <= allowed, imported - allowed
