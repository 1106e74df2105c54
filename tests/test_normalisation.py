"""The normalisation (3.3), (3.4) on its own, on a system with a closed-form sensitivity.

ẋ = −a x + b u, u = 1, x(0) = x0: x(t) = b/a + (x0 − b/a) e^{−a t}, so by hand
∂x/∂a = −b/a² (1 − e^{−a t}) − t (x0 − b/a) e^{−a t}. With a = 3, b = 1, x0 = 2 the state falls
monotonically from 2, so (3.4) gives x_0 = max |x(t)| = 2, and (3.3)
S_N = ∂x/∂a · a / x_0. The project's sensitivity integration (3.5)–(3.7) and
:attr:`SensitivityRun.normalised` must reproduce it at every sample.
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from gearsym.symbolic.model import Model, Variable
from gearsym.symbolic.sensitivity import sensitivity_equations
from gearsym.validation.studies.sensitivity_integration import Interpolated, integrate_sensitivities
from gearsym.validation.studies.sensitivity_run import SensitivityRun


def test_normalised_sensitivity_of_a_first_order_lag():
    x, u, a, b = sp.symbols("x u a b", real=True)
    model = Model(
        name="lag",
        states=(Variable("x", x),),
        inputs=(Variable("u", u),),
        parameters=(Variable("a", a, default=3.0), Variable("b", b, default=1.0)),
        outputs=(Variable("y", sp.Symbol("y")),),
        rhs=sp.Matrix([-a * x + b * u]),
        output_expressions=sp.Matrix([x]),
    )
    eqs = sensitivity_equations(model, ["a"])
    t = np.linspace(0.0, 2.0, 201)
    inputs = Interpolated(np.array([0.0, 2.0]), np.array([[1.0], [1.0]]))
    tr = integrate_sensitivities(eqs, inputs, np.array([2.0]), {"a": 3.0, "b": 1.0}, t)
    nominal = np.max(np.abs(tr.x), axis=0)  # (3.4)
    assert nominal[0] == 2.0
    run = SensitivityRun(
        trajectory=tr,
        phases=(),
        values={"a": 3.0, "b": 1.0},
        scales=np.array([3.0]),  # p_0 = a
        nominal_states=nominal,
        reference_states=tr.x,
        sliding={},
        mode="test",
        source="closed form",
        timings={},
    )
    e = np.exp(-3.0 * t)
    ds_da = -(1 / 9) * (1 - e) - t * (2 - 1 / 3) * e
    np.testing.assert_allclose(run.normalised[:, 0, 0], ds_da * 3.0 / 2.0, atol=1e-10)
    # its rate: d/dt of the closed form, times a / x_0
    rate = -(1 / 3) * e - (2 - 1 / 3) * e + 3 * t * (2 - 1 / 3) * e
    np.testing.assert_allclose(run.normalised_rate[:, 0, 0], rate * 3.0 / 2.0, atol=1e-9)
