"""Fisher information (3.16)–(3.30): closed-form cases computed by hand, then the study along
the reference shift (structure and findings, no printed numbers exist: Figures 3.9–3.14 are
missing from the thesis)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import sympy as sp
from gearsym.symbolic.fisher import (
    analyse,
    describe_direction,
    eliminate,
    fisher_information,
    measurement_floor,
    noise_variances,
)
from gearsym.symbolic.model import Model, Variable

# ----------------------------------------------------------------------------- noise (3.26)


def test_noise_model():
    """σ² = r² max(|y|, y_min)², y_min = 1 % of the largest |z| (here 20 → 0.2)."""
    z = np.array([[0.5], [10.0], [-20.0], [0.1]])
    floor = measurement_floor(z, 0.01)
    assert floor == pytest.approx([0.2])
    variances = noise_variances(z, [0.1], floor)
    assert variances[:, 0] == pytest.approx([0.05**2, 1.0, 4.0, 0.02**2])


def test_noise_model_without_signal_carries_no_information():
    variances = noise_variances(np.zeros((3, 1)), [0.1], np.zeros(1))
    assert np.all(np.isinf(variances))
    assert np.all(fisher_information(np.ones((3, 1, 1)), variances) == 0)


# ----------------------------------------------------------------------------- (3.25), (3.22)


def test_straight_line_fit():
    """y_k = a t_k + b with constant σ: F = [[Σt², Σt], [Σt, N]]/σ² and the Cramér–Rao bound of
    a is the least-squares variance σ² N / (N Σt² − (Σt)²)."""
    t = np.linspace(0.0, 1.0, 11)
    sigma = 0.3
    dy = np.stack([t, np.ones_like(t)], axis=1)[:, None, :]  # (N, 1, 2)
    fim = fisher_information(dy, np.full((len(t), 1), sigma**2))
    n, st, st2 = len(t), t.sum(), (t**2).sum()
    assert fim == pytest.approx(np.array([[st2, st], [st, n]]) / sigma**2)
    a = analyse(fim, ["a", "b"], [2.0, 1.0], gamma_max=1.0)
    var_a = sigma**2 * n / (n * st2 - st**2)
    var_b = sigma**2 * st2 / (n * st2 - st**2)
    assert a.sigma == pytest.approx([np.sqrt(var_a), np.sqrt(var_b)])
    assert a.gamma == pytest.approx([np.sqrt(var_a) / 2.0, np.sqrt(var_b) / 1.0])  # (3.27)
    assert not a.singular and a.rank == 2


def test_eigen_analysis():
    """F_N = diag(4, 1/4): λ = (1/4, 4), γ = (1/2, 2); γ_i² = Σ_j v_ij²/λ_j (3.29)–(3.30); the
    weakest direction is the second parameter."""
    a = analyse(np.diag([4.0, 0.25]), ["p", "q"], [1.0, 1.0], gamma_max=1.0)
    assert a.eigenvalues == pytest.approx([0.25, 4.0])
    assert a.gamma == pytest.approx([0.5, 2.0])
    assert a.contributions.sum(axis=1) == pytest.approx(a.gamma**2)
    assert a.weakest() == "q"
    assert not a.estimable
    # the normalisation (3.3): scaling p by 10 scales F_pp by 100, γ unchanged
    b = analyse(np.diag([4.0 / 100, 0.25]), ["p", "q"], [10.0, 1.0], gamma_max=1.0)
    assert b.gamma == pytest.approx(a.gamma)
    assert b.sigma == pytest.approx([5.0, 2.0])


def test_singular_fim_is_a_finding():
    """y1 = (a + b) t, y2 = c t: a and b enter only as a + b. F is singular with the null
    direction (a − b)/√2; c stays identifiable with its own bound σ²/Σt²."""
    t = np.linspace(0.1, 1.0, 10)
    dy = np.zeros((len(t), 2, 3))
    dy[:, 0, 0] = dy[:, 0, 1] = t
    dy[:, 1, 2] = t
    fim = fisher_information(dy, np.full((len(t), 2), 0.01))
    a = analyse(fim, ["a", "b", "c"], [1.0, 1.0, 1.0])
    assert a.singular and a.rank == 2
    (direction,) = a.null_directions
    assert direction == pytest.approx({"a": 1 / np.sqrt(2), "b": -1 / np.sqrt(2)})
    assert describe_direction(direction) == "0.707·a − 0.707·b"
    assert np.isinf(a.gamma[0]) and np.isinf(a.gamma[1])
    assert a.gamma[2] == pytest.approx(np.sqrt(0.01 / (t**2).sum()))
    json.dumps(a.to_dict())  # infinite values are serialisable


def test_elimination_procedure():
    """F_N = [[2, 1.4, 0], [1.4, 1, 0], [0, 0, 1e4]], γ_max = 0.1, by hand:
    step 1: inverse diagonal of the 2×2 block (1, 2)/0.04 → γ = (5, 7.07, 0.01); the smallest
    eigenvalue's vector ∝ (1.4, −1.987) is dominated by b → drop b;
    step 2: γ_a = 1/√2 = 0.707 > 0.1, weakest direction is a → drop a;
    step 3: γ_c = 0.01 ≤ 0.1 → done."""
    fim = np.array([[2.0, 1.4, 0.0], [1.4, 1.0, 0.0], [0.0, 0.0, 1e4]])
    result = eliminate(fim, ["a", "b", "c"], [1.0, 1.0, 1.0], gamma_max=0.1)
    steps = result.steps
    assert steps[0].analysis.gamma == pytest.approx([5.0, np.sqrt(50.0), 0.01])
    assert [s.dropped for s in steps] == ["b", "a", None]
    assert steps[1].analysis.gamma == pytest.approx([1 / np.sqrt(2), 0.01])
    assert result.final == ("c",)


def test_elimination_of_a_singular_fim_down_to_nothing():
    result = eliminate(np.zeros((2, 2)), ["a", "b"], [1.0, 1.0])
    assert result.final == ()
    assert all(s.dropped for s in result.steps)
    assert "singular" in result.steps[0].reason


def test_fim_of_a_linear_in_parameter_ode():
    """ẋ = a, y = x, x(0) = 0: ∂y/∂a = t, so with σ constant F = Σ t_k² / σ² (by hand),
    through the sensitivity equations and their integration."""
    from gearsym.symbolic.sensitivity import sensitivity_equations
    from gearsym.validation.studies.sensitivity_integration import (
        Interpolated,
        integrate_sensitivities,
    )

    x, a = sp.symbols("x a")
    model = Model(
        "ramp",
        (Variable("x", x),),
        (),
        (Variable("a", a, default=2.0),),
        (Variable("y", sp.Symbol("y")),),
        sp.Matrix([a]),
        sp.Matrix([x]),
    )
    t = np.linspace(0.0, 1.0, 21)
    tr = integrate_sensitivities(
        sensitivity_equations(model, ["a"]),
        Interpolated(t, np.zeros((len(t), 0))),
        np.zeros(1),
        {"a": 2.0},
        t,
        max_step=0.05,
    )
    fim = fisher_information(tr.dy, np.full((len(t), 1), 0.04))
    assert fim[0, 0] == pytest.approx((t**2).sum() / 0.04, rel=1e-12)


# ----------------------------------------------------------------------------- the shift


@pytest.fixture(scope="module")
def study():
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.studies.driven_shift import reference_data
    from gearsym.validation.studies.fisher import fim_study

    d = load_description()
    return fim_study(d, data=reference_data(d), with_wheel_acceleration=True)


def test_study_structure(study):
    from gearsym.symbolic.parameters import symbol
    from gearsym.validation.studies.fisher import (
        WHOLE_SHIFT,
        fim_markdown,
        format_text,
        study_json,
        summary_lines,
    )

    names = [w.name for w in study.windows]
    assert names == ["gear 2", "torque phase", "speed phase", "gear 3", WHOLE_SHIFT]
    for w in study.windows:
        assert len(w.results) == 2  # without and with the wheel acceleration (3.32)
    data = study_json(study)
    json.dumps(data)
    assert data["windows"][0]["output_sets"][1]["outputs"][-1] == "y_domega_C"
    assert "gear 2" in format_text(study)
    assert len(summary_lines(study)) == 5
    # the documentation's table: headed by the command, one row per window in each table,
    # what the elimination keeps per output set
    table = fim_markdown(json.loads(json.dumps(data)), "gearsym fim --open-loop --out x")
    assert table.startswith("<!-- written by `gearsym fim --open-loop --out x`; do not edit")
    for w in study.windows:
        finals = [", ".join(symbol(n) for n in r.elimination.final) for r in w.results]
        assert f"| {' | '.join(finals)} |" in table, w.name
        assert table.count(f"| {w.name} |") >= 2


def test_whole_shift_is_the_sum_of_the_phases(study):
    for k in range(2):
        total = sum(w.results[k].full.fim for w in study.windows[:-1])
        assert study.windows[-1].results[k].full.fim == pytest.approx(total, rel=1e-12)


def test_gear_2_findings(study):
    """Gear 2 (thesis 3.3.1): μ38 has no sensitivity at all (K38 sticks: a null direction of
    exactly μ38, no crash); m_veh and ζ cannot be estimated together (steady acceleration
    lets them act only as m_veh (a + g sin ζ)), but m_veh alone can (Figs. 3.9, 3.10)."""
    gear2 = study.windows[0]
    for result in gear2.results:
        full = result.full
        assert full.singular
        assert {"mu_38": 1.0} in [
            {k: round(v, 6) for k, v in d.items()} for d in full.null_directions
        ]
        both, m_only, _ = result.combinations
        assert both.names == ("m_veh", "zeta") and not both.estimable
        assert m_only.names == ("m_veh",) and m_only.estimable
        assert "m_veh" in result.elimination.final
        assert "mu_38" not in result.elimination.final


def test_wheel_acceleration_lowers_every_scatter(study):
    """(3.32): an extra measured output can only add information."""
    for w in study.windows:
        without, with_acc = w.results
        finite = np.isfinite(without.full.gamma)
        assert np.all(with_acc.full.gamma[finite] <= without.full.gamma[finite] * (1 + 1e-9))


def _null(result, name):
    """True when ``name`` alone spans a null direction of the window's FIM."""
    return {name: 1.0} in [
        {k: round(abs(v), 6) for k, v in d.items()} for d in result.full.null_directions
    ]


@pytest.fixture(scope="module")
def four_parameters():
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.studies.driven_shift import reference_data
    from gearsym.validation.studies.fisher import fim_study

    d = load_description()
    data = reference_data(d)
    names = ["m_veh", "mu_38", "mu_05", "zeta"]
    return {restart: fim_study(d, names, data=data, restart=restart) for restart in (True, False)}


def test_a_phase_claims_no_friction_information_where_its_element_carries_none(
    four_parameters,
):
    """Issue 9: K38 is open in the speed phase and gear 3, so μ38 cannot act on the outputs
    there (μ acts only through the sliding torque μ·F_N, 3.14): by default each phase counts
    only its own information, and μ38 is an exact null direction. μ05 is not called
    estimable in gear 3 (B05 sticks; see the next test for the little it reveals)."""
    study = four_parameters[True]
    by_name = {w.name: w.results[0] for w in study.windows}
    assert study.settings["restart"] is True
    assert "restarted at each phase" in study.settings["sensitivities"]
    for phase in ("speed phase", "gear 3"):
        assert _null(by_name[phase], "mu_38"), phase
        assert "mu_38" not in by_name[phase].elimination.final
    mu_05 = list(study.parameters).index("mu_05")
    assert by_name["gear 3"].full.gamma[mu_05] > study.settings["gamma_max"]
    assert "mu_05" not in by_name["gear 3"].elimination.final
    assert "mu_38" in by_name["torque phase"].elimination.final  # where K38 slides


def test_the_carried_over_view_is_labelled_as_such(four_parameters):
    """The thesis' continuous view (sensitivities from t0) remains available, labelled: there
    μ38's torque-phase perturbation is still seen in the speed phase."""
    from gearsym.validation.studies.fisher import format_text

    carried = four_parameters[False]
    assert "carried over from t0" in format_text(carried)
    speed = next(w for w in carried.windows if w.name == "speed phase").results[0]
    assert not _null(speed, "mu_38")


def test_gear_3_sees_mu_05_only_while_b05_still_slides():
    """The evidence behind μ05's finite scatter in gear 3: the phase starts when B05's slip
    has fallen below its threshold, but B05 still slides at capacity for about a millisecond.
    From the first sample at which it sticks on, μ05 has no influence at all (S ≡ 0)."""
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.studies.driven_shift import (
        driven_shift_model,
        reference_data,
        sliding_masks,
    )
    from gearsym.validation.studies.sensitivity_run import run_sensitivities

    d = load_description()
    data = reference_data(d)
    gear3 = next(p for p in data.phases if p.name == "gear 3")
    window = data.window(gear3.t_start, gear3.t_end)
    sliding = window.t[sliding_masks(d, driven_shift_model(d, "2-3"), window)["B05"]]
    assert 0 < sliding.size and sliding.max() < gear3.t_start + 2e-3
    after = data.window(float(sliding.max()) + 1e-3, gear3.t_end)
    run = run_sensitivities(d, ["m_veh", "mu_05", "zeta"], data=after, initial="zero")
    assert np.all(run.trajectory.S[:, :, 1] == 0.0)
    assert np.any(run.trajectory.S[:, :, 0] != 0.0)  # m_veh still acts
