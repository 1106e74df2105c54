"""Shift models of double swaps (two elements off, two on): 1-5 of the built-in 9-speed.

Expected values come from routes independent of the projection (2.55) under test:

* the kinematics are built here with NumPy from the Willis equation of each simple set,
  z_S ω_S + z_R ω_R − (z_S + z_R) ω_H = 0 (2.20), and the element slips ω_a − ω_b (2.59);
* the reduced model's accelerations equal those of the full model (2.53) with the common
  element's lock imposed by a Lagrange multiplier: its torque input is the constraint force,
  solved from "slip acceleration = 0" (the full model locks nothing and projects nothing);
* in each end gear, with the two elements that close it driven by the reaction torques that
  keep their slips at zero (solved here from the model's own accelerations, the other two
  open), the model holds the gear's ratio of the thesis' gear table (Table 2.1) while the
  vehicle accelerates;
* the emitted C equals SymPy (as tests/test_generate_shifts.py does for 3-2 and 5-3), and the
  overdrive test box's 3-4, which swaps two elements with none in common, generates.
"""

from __future__ import annotations

import subprocess
import sys
from itertools import permutations
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.drivetrain import full_model, shift_model
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.export.generate import generate_tree, hybrid_shift_names, selected_shifts
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks import generated_check
from scipy.integrate import solve_ivp

OVERDRIVE = Path(__file__).parent / "data" / "simpson_overdrive_idle.toml"


@pytest.fixture(scope="module")
def d():
    return load_description()


# ---------------------------------------------------------------------------------------------
# Independent kinematics (NumPy, from the teeth)
# ---------------------------------------------------------------------------------------------


class Kinematics:
    """Willis rows W (W ω = 0 over every shaft speed ω) and element slip rows, by hand."""

    def __init__(self, d) -> None:
        self.shafts = [s.name for s in d.shafts]
        self.index = {s: i for i, s in enumerate(self.shafts)}
        rows = []
        for ps in d.planetary_sets:
            assert ps.kind == "simple"
            row = np.zeros(len(self.shafts))
            row[self.index[ps.sun]] += ps.z_sun
            row[self.index[ps.ring]] += ps.z_ring
            row[self.index[ps.carrier]] -= ps.z_sun + ps.z_ring
            rows.append(row)
        self.willis = np.array(rows)
        self.elements = {e.name: e for e in d.shift_elements}

    def slip(self, element: str) -> np.ndarray:
        e = self.elements[element]
        row = np.zeros(len(self.shafts))
        row[self.index[e.b]] -= 1.0
        if e.a is not None:
            row[self.index[e.a]] += 1.0
        return row

    def select(self, shafts) -> np.ndarray:
        rows = np.zeros((len(shafts), len(self.shafts)))
        for k, s in enumerate(shafts):
            rows[k, self.index[s]] = 1.0
        return rows

    def solve(self, locked, shafts, values) -> np.ndarray:
        """Every shaft's speed (or acceleration) from the Willis rows, zero slip of ``locked``
        and the given values of ``shafts``."""
        a = np.vstack([self.willis, *(self.slip(e) for e in locked), self.select(shafts)])
        b = np.concatenate([np.zeros(len(self.willis) + len(locked)), values])
        assert a.shape[0] == a.shape[1]
        return np.linalg.solve(a, b)

    def gear_speeds(self, closed, output: str, omega_out: float) -> np.ndarray:
        return self.solve(closed, [output], [omega_out])


class Numeric:
    """A model's right-hand side as a NumPy function of (state, input) at given parameters."""

    def __init__(self, model, parameters: dict[str, float]) -> None:
        self.model = model
        symbols = [v.symbol for v in (*model.states, *model.inputs, *model.parameters)]
        self.f = sp.lambdify(symbols, list(model.rhs), "numpy")
        self.p = [parameters[v.name] for v in model.parameters]
        self.states = [v.name for v in model.states]
        self.inputs = [v.name for v in model.inputs]

    def __call__(self, x, u) -> np.ndarray:
        return np.array(self.f(*x, *u, *self.p), dtype=float)


def random_parameters(model, rng) -> dict[str, float]:
    """The defaults, each scaled by a random factor in [0.8, 1.2]; ζ in ±0.05 rad."""
    values = {}
    for v in model.parameters:
        if v.name == "zeta":
            values[v.name] = rng.uniform(-0.05, 0.05)
        else:
            values[v.name] = float(v.default) * rng.uniform(0.8, 1.2)
    return values


# ---------------------------------------------------------------------------------------------
# The spec and the model's layout
# ---------------------------------------------------------------------------------------------


def test_1_5_swaps_two_elements_each_way(d):
    spec = shift_spec(d, "1-5", max_swaps=2)
    # gear 1 closes B05, K38, B06; gear 5 K81, B05, K27 (thesis gear table)
    assert spec.locked == ("B05",)
    assert set(spec.off_elements) == {"K38", "B06"} and set(spec.on_elements) == {"K81", "K27"}
    assert not spec.single and spec.off_going == "" and spec.on_coming == ""
    single = shift_spec(d, "2-3")
    assert single.single and (single.off_elements, single.on_elements) == (("K38",), ("B05",))
    with pytest.raises(GearsymError, match="a shift model needs exactly one of each"):
        shift_spec(d, "1-5")  # every analysis that needs a single swap still refuses it


def test_1_5_model_layout(d):
    m = shift_model(d, "1-5")
    # one locked element leaves 4 - 1 = 3 gearbox degrees of freedom: three shaft speeds
    assert len(m.states) == 3 + 2 and [v.name for v in m.states][-2:] == ["phi", "omega_C"]
    assert [v.name for v in m.states][:2] == ["omega_1", "omega_2"]
    assert sorted(v.name for v in m.inputs) == sorted(["T_In", "T_K38", "T_B06", "T_K81", "T_K27"])
    with pytest.raises(GearsymError, match="torque-input model only"):
        shift_model(d, "1-5", friction_inputs=True)


# ---------------------------------------------------------------------------------------------
# Against the full model with the lock as a Lagrange multiplier
# ---------------------------------------------------------------------------------------------


def test_1_5_equals_full_model_with_the_common_element_locked(d):
    kin = Kinematics(d)
    spec = shift_spec(d, "1-5", max_swaps=2)
    (common,) = spec.locked
    reduced, full = shift_model(d, "1-5"), full_model(d)
    rng = np.random.default_rng(15)
    coordinates = list(d.coordinates)
    kept = [v.name.removeprefix("omega_") for v in reduced.states[:-2]]
    # the motions the lock allows: null space of [W; slip of the common element]
    constraint = np.vstack([kin.willis, kin.slip(common)])
    _, sv, vt = np.linalg.svd(constraint)
    basis = vt[np.sum(sv > 1e-9) :].T
    assert basis.shape[1] == 3
    # coordinates -> every shaft: ω = N y (Willis rows with the coordinates given)
    n_map = np.column_stack(
        [kin.solve((), coordinates, np.eye(len(coordinates))[k]) for k in range(len(coordinates))]
    )
    worst = 0.0
    for _ in range(20):
        params = random_parameters(full, rng)
        fr, ff = Numeric(reduced, params), Numeric(full, params)
        omega = basis @ rng.uniform(-300.0, 300.0, basis.shape[1])
        phi, omega_c = rng.uniform(-0.02, 0.02), rng.uniform(0.0, 60.0)
        torques = {"T_In": rng.uniform(-200.0, 400.0)}
        torques |= {f"T_{e}": rng.uniform(-600.0, 600.0) for e in spec.swapping}
        x_full = [*(omega[kin.index[s]] for s in coordinates), phi, omega_c]

        def full_rhs(reaction: float, torques=torques, x_full=x_full, ff=ff) -> np.ndarray:
            u = [reaction if n == f"T_{common}" else torques.get(n, 0.0) for n in ff.inputs]
            return ff(x_full, u)  # an element neither swapping nor locked is open (2.54)

        f0 = full_rhs(0.0)
        g = full_rhs(1.0) - f0  # the reaction enters linearly (2.36)
        slip = kin.slip(common) @ n_map
        nc = len(coordinates)
        reaction = -(slip @ f0[:nc]) / (slip @ g[:nc])
        expected_full = f0 + reaction * g
        expected_shafts = n_map @ expected_full[:nc]
        assert abs(kin.slip(common) @ expected_shafts) < 1e-9 * np.abs(expected_shafts).max()
        expected = [*(expected_shafts[kin.index[s]] for s in kept), *expected_full[nc:]]
        x_red = [*(omega[kin.index[s]] for s in kept), phi, omega_c]
        got = fr(x_red, [torques[n] for n in fr.inputs])
        scale = np.abs(expected) + 1.0
        worst = max(worst, float(np.max(np.abs(got - expected) / scale)))
    assert worst < 1e-9, worst


# ---------------------------------------------------------------------------------------------
# End gears: the reaction of the closing elements holds the gear's ratio
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("gear", ["1", "5"])
def test_1_5_in_each_end_gear_holds_its_ratio(d, gear):
    kin = Kinematics(d)
    spec = shift_spec(d, "1-5", max_swaps=2)
    reduced = shift_model(d, "1-5")
    params = {v.name: float(v.default) for v in reduced.parameters}
    f = Numeric(reduced, params)
    kept = [v.name.removeprefix("omega_") for v in reduced.states[:-2]]
    closing = spec.on_elements if gear == spec.to_gear else spec.off_elements
    table = {g.name: g for g in d.gears}[gear]
    assert set(closing) | set(spec.locked) == set(table.closed)
    i_d = float(d.drivetrain["i_D"].value)

    def shafts(x) -> np.ndarray:
        return kin.solve(spec.locked, kept, x[: len(kept)])

    def accelerations(x, torques) -> np.ndarray:
        return f(x, [torques.get(n, 0.0) for n in f.inputs])

    def with_reaction(x) -> np.ndarray:
        """ẋ with T_In = 150 N m, the other pair open and the closing pair's torques solving
        'slip acceleration of each = 0' (the rhs is affine in them)."""
        base = {"T_In": 150.0}
        a0 = accelerations(x, base)

        def slip_acc(xdot) -> np.ndarray:
            all_acc = kin.solve(spec.locked, kept, xdot[: len(kept)])
            return np.array([kin.slip(e) @ all_acc for e in closing])

        s0 = slip_acc(a0)
        columns = [slip_acc(accelerations(x, base | {f"T_{e}": 1.0}) - a0) for e in closing]
        reaction = np.linalg.solve(np.column_stack(columns), -s0)
        solved = {f"T_{e}": r for e, r in zip(closing, reaction, strict=True)}
        return accelerations(x, base | solved)

    omega_out = 100.0  # rad/s
    speeds = kin.gear_speeds(table.closed, d.output_shaft, omega_out)
    ratio = speeds[kin.index[d.input_shaft]] / omega_out
    assert abs(ratio - table.ratio) <= 0.5 * 10.0 ** (-d.ratio_decimals)  # gear table (2.1)
    # the side shafts untwisted and the wheel at the propeller-shaft speed / i_D
    x0 = np.array([*(speeds[kin.index[s]] for s in kept), 0.0, omega_out / i_d])
    sol = solve_ivp(lambda t, x: with_reaction(x), (0.0, 1.0), x0, rtol=1e-11, atol=1e-9)
    assert sol.success
    for x in sol.y.T:
        all_speeds = shafts(x)
        w_in = all_speeds[kin.index[d.input_shaft]]
        w_out = all_speeds[kin.index[d.output_shaft]]
        assert abs(w_in / w_out - ratio) < 1e-8 * ratio
        for e in closing:
            assert abs(kin.slip(e) @ all_speeds) < 1e-7 * abs(w_in)
    assert sol.y[-1, -1] > sol.y[-1, 0]  # the vehicle gains speed: the drive path carries load
    # The ratio above holds by the way the reactions are solved; what the reduced model itself
    # contributes is checked against the full model (2.53) with all three closed elements
    # locked by Lagrange multipliers, its reactions solved from the three slip accelerations
    # (the kinematics from the test's own Willis rows), at states along the run.
    full = full_model(d)
    ff = Numeric(full, {v.name: float(v.default) for v in full.parameters})
    coordinates = list(d.coordinates)
    nc = len(coordinates)
    n_map = np.column_stack([kin.solve((), coordinates, np.eye(nc)[k]) for k in range(nc)])
    locked_all = [*spec.locked, *closing]

    def full_with_reactions(x_red) -> np.ndarray:
        omega = shafts(x_red)
        x_full = [*(omega[kin.index[c]] for c in coordinates), *x_red[len(kept) :]]

        def rhs(reactions: dict[str, float]) -> np.ndarray:
            torques = {"T_In": 150.0} | reactions
            return ff(x_full, [torques.get(n, 0.0) for n in ff.inputs])

        f0 = rhs({})
        slips = np.array([kin.slip(e) @ n_map for e in locked_all])
        g = np.column_stack([rhs({f"T_{e}": 1.0}) - f0 for e in locked_all])
        reactions = np.linalg.solve(slips @ g[:nc], -(slips @ f0[:nc]))
        acc = f0 + g @ reactions
        all_acc = n_map @ acc[:nc]
        return np.array([*(all_acc[kin.index[c]] for c in kept), *acc[nc:]])

    for x in sol.y.T[:: max(1, sol.y.shape[1] // 10)]:
        expected = full_with_reactions(x)
        got = with_reaction(x)
        assert np.max(np.abs(got - expected) / (np.abs(expected) + 1.0)) < 1e-9


# ---------------------------------------------------------------------------------------------
# Selection and emitted code
# ---------------------------------------------------------------------------------------------


def _swaps(d, n: int) -> set[str]:
    driven = {g.name: set(g.closed) for g in d.gears if not g.neutral}
    return {
        f"{a}-{b}"
        for a, b in permutations(driven, 2)
        if len(driven[a] - driven[b]) == n and len(driven[b] - driven[a]) == n
    }


def test_all_holds_the_double_swaps_after_the_single_ones(d):
    chosen = selected_shifts(d, "all")
    names = [s.name for s in chosen]
    singles, doubles = _swaps(d, 1), _swaps(d, 2)
    assert doubles and "1-5" in doubles and "2-4" in doubles
    assert set(names) == singles | doubles and len(names) == len(set(names))
    assert set(names[: len(singles)]) == singles
    assert all(not s.single for s in chosen[len(singles) :])
    # hybrid models exist for single swaps only
    assert set(hybrid_shift_names(d, "all")) == singles
    with pytest.raises(GearsymError, match="two elements each way"):
        hybrid_shift_names(d, "2-3,1-5")


def test_emitted_double_swap_compiles_and_equals_sympy(d, tmp_path):
    tree = generate_tree(d, shifts="1-5", hybrid_shifts="none")
    shift_models = [m for m in tree.models if m.shift is not None]
    assert [m.model.name for m in shift_models] == ["shift_1_5"]  # no mu form, no sensitivities
    assert {e.set.name for e in tree.linear_sets} == {"linear_gears"}
    readme = tree.files["README.md"]
    assert "`shift_1_5`: K38 and B06 off, K81 and K27 on" in readme
    assert "torque-input model only" in readme
    root = tmp_path / "gen"
    for relative, text in tree.files.items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_text(text)
    reports = generated_check.compare_models(shift_models, root, tmp_path / "build", n_points=50)
    assert reports
    for r in reports:
        assert generated_check.comparison_ok(r), str(r)


def test_overdrive_3_4_swaps_two_with_none_common_and_generates(tmp_path):
    d = load_description(OVERDRIVE)
    spec = shift_spec(d, "3-4", max_swaps=2)
    assert spec.locked == () and set(spec.swapping) == {"C1", "C2", "C3", "B3"}
    tree = generate_tree(d, shifts="3-4", hybrid_shifts="none")
    (model,) = [m for m in tree.models if m.shift is not None]
    # nothing locked: every degree of freedom a state (4 coordinates), then phi, omega_C
    assert len(model.model.states) == len(d.coordinates) + 2
    root = tmp_path / "gen"
    for relative, text in tree.files.items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_text(text)
    reports = generated_check.compare_models([model], root, tmp_path / "build", n_points=50)
    assert reports
    for r in reports:
        assert generated_check.comparison_ok(r), str(r)


def _gearsym(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "gearsym", *args], capture_output=True, text=True, check=False
    )


def test_model_shift_prints_a_double_swap():
    result = _gearsym("model", "--shift", "1-5")
    assert result.returncode == 0, result.stderr
    assert "model shift_1_5" in result.stdout and "T_K27" in result.stdout
    result = _gearsym("model", "--shift", "1-5", "--friction-inputs")
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gearsym: ")
    assert "gears '1' and '5'" in lines[0] and "torque-input model only" in lines[0]
    assert "Traceback" not in result.stderr
