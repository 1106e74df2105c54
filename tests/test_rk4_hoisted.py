"""The emitted rk4_step with the right-hand side inlined and its u/p-only terms computed once.

Expected values: the classical RK4 formula composed in NumPy from the emitted ``rhs`` (four
calls, the textbook stages), an independent route to the same step; and the structure known by
hand (in the 2-3 shift model the grade ζ is a parameter, so sin ζ and cos ζ do not depend on
the state and belong before the stage loop).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from gearsym.symbolic.codegen import emit_c
from gearsym.symbolic.export.generate import gearbox_models
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks.c_binding import load_functions
from gearsym.validation.checks.c_check import compile_shared

MODELS = ("shift_2_3", "shift_2_3_mu", "full")


@pytest.fixture(scope="module")
def emitted():
    d = load_description()
    return {m.model.name: m for name in MODELS for m in gearbox_models(d, only=name)}


@pytest.mark.parametrize("name", MODELS)
def test_rk4_step_equals_four_rhs_calls(emitted, name, tmp_path):
    m = emitted[name]
    files = emit_c(m.model, m.config)
    lib = load_functions(compile_shared(files, tmp_path), m.model, False, m.config)
    p = lib.params_default()
    rng = np.random.default_rng(5)
    nx, nu = len(m.model.states), len(m.model.inputs)
    for _ in range(20):
        x = rng.uniform(-50.0, 200.0, nx)
        u = rng.uniform(0.0, 2000.0, nu)
        h = 1e-3
        k1 = lib.evaluate("rhs", x, u, p)
        k2 = lib.evaluate("rhs", x + 0.5 * h * k1, u, p)
        k3 = lib.evaluate("rhs", x + 0.5 * h * k2, u, p)
        k4 = lib.evaluate("rhs", x + h * k3, u, p)
        expected = x + h / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)
        got = lib.step("rk4_step", x, u, p, h)
        scale = np.abs(x) + h * np.abs(k1) + 1.0
        assert np.max(np.abs(got - expected) / scale) < 1e-13


def test_parameter_terms_are_outside_the_stages(emitted):
    m = emitted["shift_2_3"]
    source = emit_c(m.model, m.config)["gearsym_shift_2_3.c"]
    start = source.index("gearsym_shift_2_3_rk4_step(\n")
    body = source[start : source.index("\n}\n", start)]
    loop = body.index("{ /* k1 = f(x, u, p) */")  # the first of the four unrolled stages
    assert body.count("const gearsym_real *const xs = ") == 4
    assert re.search(r"GEARSYM_SIN\(p->zeta\)", body[:loop])
    assert re.search(r"GEARSYM_COS\(p->zeta\)", body[:loop])
    assert "GEARSYM_SIN" not in body[loop:] and "GEARSYM_COS" not in body[loop:]
    assert "gearsym_shift_2_3_rhs(" not in body  # inlined
