"""The emitted linear forms (5.1): C and CasADi as functions of the parameters.

Independent checks:

* A and B of the compiled C (from ``generated/``) at the defaults equal central finite
  differences of the nonlinear drivetrain model (2.42–2.58) in the same mode: the route of
  ``tests/test_linear_forms.py`` (rolling and aerodynamic load removed, T_res* entering like the
  grade torque), for the full model, a gear and every mode of the 2-3 shift;
* C (double, float) and CasADi equal the SymPy expressions at random parameter points;
* the light mode path of :mod:`gearsym.symbolic.linear_forms` gives exactly the forms of the
  hybrid model's modes (:func:`mode_linear_form`), and every hybrid mode is served by one system;
* A scales with the parameters as the physics says: the side-shaft stiffness k_ss enters A
  linearly, so doubling it doubles the twist column of the speed rows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.export.generate import linear_system_sets
from gearsym.symbolic.hybrid import hybrid_shift
from gearsym.symbolic.linear_forms import gear_linear_forms, mode_linear_form, shift_linear_forms
from gearsym.symbolic.loader import load_description
from gearsym.symbolic.shifts import shift_spec
from gearsym.validation.checks import c_check
from gearsym.validation.checks.linear_check import LinearFunctions, compare_linear_sets

from tests.test_linear_forms import fd_jacobians

GENERATED = Path(__file__).resolve().parents[1] / "generated"


@pytest.fixture(scope="module")
def d():
    return load_description()


@pytest.fixture(scope="module")
def emitted(d):
    return {e.set.name: e for e in linear_system_sets(d)}


@pytest.fixture(scope="module")
def libraries(emitted, tmp_path_factory):
    build = tmp_path_factory.mktemp("linear")
    libs = {}
    for name in ("linear_gears", "linear_2_3"):
        sources = {
            f"gearsym_{name}{ext}": (GENERATED / "c" / f"gearsym_{name}{ext}").read_text()
            for ext in (".h", ".c")
        }
        path = c_check.compile_shared(sources, build / name)
        libs[name] = LinearFunctions(path, emitted[name].set)
    return libs


def _defaults(s):
    return [v.default for v in s.parameters]


@pytest.mark.parametrize("system", ["full", "gear_2", "gear_R"])
def test_emitted_gear_forms_equal_finite_differences(d, libraries, system):
    group = {f.name: f for f in gear_linear_forms(d).forms}
    named = group[system]
    lib = libraries["linear_gears"]
    a, b = lib.evaluate(system, _defaults(lib.set))
    a_fd, b_fd = fd_jacobians(d, named.form, named.locked, named.torque_elements, named.keep)
    np.testing.assert_allclose(a, a_fd, rtol=1e-6, atol=1e-6 * np.abs(a_fd).max())
    np.testing.assert_allclose(b, b_fd, rtol=1e-6, atol=1e-6 * np.abs(b_fd).max())


def test_emitted_mode_forms_of_2_3_equal_finite_differences(d, libraries):
    lib = libraries["linear_2_3"]
    forms = shift_linear_forms(d, shift_spec(d, "2-3")).forms
    assert len(forms) == 8  # 3 x 3 statuses of the two swapping elements, minus the tie-up
    for named in forms:
        a, b = lib.evaluate(named.name, _defaults(lib.set))
        a_fd, b_fd = fd_jacobians(d, named.form, named.locked, named.torque_elements, named.keep)
        np.testing.assert_allclose(a, a_fd, rtol=1e-6, atol=1e-6 * np.abs(a_fd).max())
        np.testing.assert_allclose(b, b_fd, rtol=1e-6, atol=1e-6 * max(np.abs(b_fd).max(), 1))


def test_every_hybrid_mode_is_served_by_its_emitted_system(d):
    hybrid = hybrid_shift(d, "2-3")
    forms = shift_linear_forms(d, shift_spec(d, "2-3")).forms
    served = {mode: named for named in forms for mode in named.modes}
    assert sorted(served) == sorted(hybrid.modes)  # 15 modes, each in exactly one system
    assert sum(len(named.modes) for named in forms) == len(hybrid.modes)
    for mode, named in served.items():
        reference = mode_linear_form(d, "2-3", mode)
        assert reference.states == named.form.states
        assert reference.inputs == named.form.inputs
        assert (reference.A - named.form.A).expand() == reference.A * 0
        assert (reference.B - named.form.B).expand() == reference.B * 0


def test_stiffness_enters_a_linearly(libraries):
    """(2.47): the side-shaft torque is k_ss φ + d_ss φ̇, so ∂ω̇/∂φ ∝ k_ss."""
    lib = libraries["linear_2_3"]
    names = [v.name for v in lib.set.parameters]
    p = np.array(_defaults(lib.set), dtype=float)
    system = next(x for x in lib.set.systems if x.name == "K38_sliding_B05_sliding")
    twist = system.states.index("phi")
    a1, _ = lib.evaluate(system.name, p)
    p2 = p.copy()
    p2[names.index("k_ss")] *= 2
    a2, _ = lib.evaluate(system.name, p2)
    assert np.count_nonzero(a1[:, twist]) >= 2  # both gearbox speeds and the wheel feel it
    np.testing.assert_allclose(a2[:, twist], 2 * a1[:, twist], rtol=1e-14)
    others = [j for j in range(a1.shape[1]) if j != twist]
    np.testing.assert_array_equal(a2[:, others], a1[:, others])


def test_c_and_casadi_equal_sympy_at_random_parameters(emitted, tmp_path):
    chosen = [emitted["linear_gears"], emitted["linear_2_3"], emitted["linear_8_9"]]
    reports = compare_linear_sets(
        [(e.set, e.config) for e in chosen], GENERATED, tmp_path, n_points=100
    )
    assert len(reports) == 9  # three sets x (C double, C single, CasADi)
    for r in reports:
        tolerance = c_check.TOLERANCE["single" if "single" in r.target else "double"]
        assert r.max_error, r.target
        assert r.ok(tolerance), str(r)


def test_parameters_are_the_drivetrain_ones(emitted):
    """(2.42)-(2.53) linearised: the gearbox inertias are numbers, so A and B depend on the
    vehicle mass (wheel row, 2.49), the side-shaft stiffness and damping (2.47) and the wheel
    inertia only; rolling and air resistance went into T_res* (5.2), ζ is an input (5.3)."""
    for e in emitted.values():
        assert [v.name for v in e.set.parameters] == ["m_veh", "k_ss", "d_ss", "I_wheel"]


def test_a_set_that_cannot_be_emitted_is_refused(emitted):
    from dataclasses import replace

    import sympy as sp
    from gearsym.symbolic.codegen.linear import linear_table

    good = emitted["linear_2_3"].set
    system = good.systems[0]
    bad_name = replace(good, systems=(replace(system, name="2x"),))
    with pytest.raises(ValueError, match="'2x' is not a C identifier"):
        linear_table(bad_name)
    stray = replace(good, systems=(replace(system, A=system.A + sp.Symbol("q") * sp.eye(3)),))
    with pytest.raises(ValueError, match="non-parameters \\['q'\\]"):
        linear_table(stray)
