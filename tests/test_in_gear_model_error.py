"""The model error of a gear apart from a shift's (``in_gear`` in a model-error table of the
description's ``[estimator]``): a factor on the table's intensities of the filter's physical
states over a prediction interval in which no element slides, by hand on the intensities the
filter predicts with and on one covariance step."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.estimator_calibration import IN_GEAR
from gearsym.symbolic.estimators.ekf import (
    augmented_model,
    default_parameters,
    ekf_predict,
    slide_input,
)
from gearsym.symbolic.io.package_data import data_file

from gearsym.commands import load as load_description

SHIPPED = data_file("thesis_9speed.toml")
WITH_STATES = ("m_veh", "mu_38", "mu_05", "zeta", "k_ss")


def without_shift_tables(text: str) -> str:
    """A description's text without its ``[estimator.<table>.shift."<from>-<to>"]``
    sub-tables (the shipped one gives the 2-3 its own in-gear entries)."""
    kept, skipping = [], False
    for line in text.splitlines(keepends=True):
        if line.startswith("[estimator.") and ".shift." in line:
            skipping = True
        elif line.startswith("["):
            skipping = False
        if not skipping:
            kept.append(line)
    return "".join(kept)


def _without_in_gear(text: str) -> str:
    """The shipped description without its own in-gear entries (its per-shift sub-tables, and
    any table-level ``in_gear``): the tests state theirs."""
    return "".join(
        line
        for line in without_shift_tables(text).splitlines(keepends=True)
        if not line.startswith("in_gear")
    )


def _description(tmp_path: Path, entry: str, table: str = "model_error_map_scale"):
    """The shipped description with ``entry`` added to its ``[estimator.<table>]``, as map-scale
    filter (``mu_model = "map_scale"``)."""
    text = _without_in_gear(SHIPPED.read_text(encoding="utf-8"))
    header = f"\n[estimator.{table}]\n"
    assert header in text
    text = text.replace(header, header + entry + "\n", 1)
    text = text.replace("[estimator]\n", '[estimator]\nmu_model = "map_scale"\n', 1)
    path = tmp_path / "in_gear.toml"
    path.write_text(text, encoding="utf-8")
    return load_description(str(path))


def test_the_factor_is_the_filters_whose_table_states_it(tmp_path):
    d = _description(tmp_path, 'in_gear = { value = 0.1, unit = "1", source = "test" }')
    scaled = augmented_model(d, "2-3", WITH_STATES)
    assert scaled.in_gear_factor == 0.1
    assert IN_GEAR not in scaled.intensities  # not a state
    # the thesis' filter takes [estimator.model_error], which does not state it
    assert augmented_model(d, "2-3", default_parameters(d, "2-3")).in_gear_factor == 1.0


def test_the_intensities_of_an_interval_by_hand(tmp_path):
    """q = 1, 2, 3, ... per state; in a gear (no slide flag) the physical states' rates are a
    tenth, the parameters' kept and both μ at 0; with the on-coming element sliding every
    physical state's rate is its q, that μ's too, the other μ's 0."""
    d = _description(tmp_path, 'in_gear = { value = 0.1, unit = "1", source = "test" }')
    aug = augmented_model(d, "2-3", WITH_STATES)
    names = aug.state_names
    q = np.arange(1.0, len(names) + 1.0)
    mu_index = {e: names.index(mu) for e, mu in aug.mu_state.items()}
    in_gear = np.zeros(len(aug.input_names))
    rates = aug.process_rates(q, in_gear)
    for j, name in enumerate(names):
        if j < aug.n_x:
            assert rates[j] == pytest.approx(0.1 * q[j]), name
        elif j in mu_index.values():
            assert rates[j] == 0.0, name
        else:
            assert rates[j] == q[j], name
    off_going, on_coming = aug.elements
    sliding = in_gear.copy()
    sliding[aug.input_names.index(slide_input(on_coming))] = 1.0
    rates = aug.process_rates(q, sliding)
    assert np.array_equal(rates[: aug.n_x], q[: aug.n_x])
    assert rates[mu_index[on_coming]] == q[mu_index[on_coming]]
    assert rates[mu_index[off_going]] == 0.0


def test_one_prediction_adds_h_times_those_rates(tmp_path):
    """With a step whose Jacobian is the identity, P⁻ − P is h diag(rates) exactly: a tenth of
    the model error in a gear, all of it while an element slides."""
    d = _description(tmp_path, 'in_gear = { value = 0.1, unit = "1", source = "test" }')
    aug = augmented_model(d, "2-3", WITH_STATES)
    n = len(aug.state_names)
    discrete = SimpleNamespace(aug=aug, step=lambda z, u, h, p: (np.asarray(z), np.eye(n)))
    q = np.full(n, 2.0)
    P = np.eye(n)
    h = 0.01
    u = np.zeros(len(aug.input_names))
    _, P_gear = ekf_predict(discrete, np.zeros(n), P, u, h, [], q)
    u[aug.input_names.index(slide_input(aug.elements[1]))] = 1.0
    _, P_slide = ekf_predict(discrete, np.zeros(n), P, u, h, [], q)
    x = slice(0, aug.n_x)
    assert np.allclose(np.diag(P_gear - P)[x], 0.1 * h * 2.0, rtol=0, atol=1e-15)
    assert np.allclose(np.diag(P_slide - P)[x], h * 2.0, rtol=0, atol=1e-15)


def test_a_factor_with_a_unit_is_refused(tmp_path):
    with pytest.raises(GearsymError) as error:
        _description(tmp_path, 'in_gear = { value = 0.1, unit = "rad^2/s^3", source = "test" }')
    message = str(error.value)
    assert "in_gear" in message and "unit" in message and "'1'" in message, message
    assert "\n" not in message


def test_the_factor_waits_for_the_settling_time_after_a_switch(tmp_path):
    """in_gear_settle = 0.05 s: in a gear the physical states keep their full rates while the
    last mode switch lies less than 0.05 s back (the drivetrain still rings), a tenth of them
    from then on, and with no switch at all (``since_switch`` infinite, the default)."""
    d = _description(
        tmp_path,
        'in_gear = { value = 0.1, unit = "1", source = "test" }\n'
        'in_gear_settle = { value = 0.05, unit = "s", source = "test" }',
    )
    aug = augmented_model(d, "2-3", WITH_STATES)
    assert aug.in_gear_settle == 0.05
    q = np.arange(1.0, len(aug.state_names) + 1.0)
    gear = np.zeros(len(aug.input_names))
    x = slice(0, aug.n_x)
    assert np.array_equal(aug.process_rates(q, gear, 0.0)[x], q[x])
    assert np.array_equal(aug.process_rates(q, gear, 0.049)[x], q[x])
    assert np.allclose(aug.process_rates(q, gear, 0.05)[x], 0.1 * q[x], rtol=1e-15)
    assert np.allclose(aug.process_rates(q, gear)[x], 0.1 * q[x], rtol=1e-15)
    assert "in_gear_settle" not in aug.intensities  # not a state


def test_a_settling_time_in_another_unit_is_refused(tmp_path):
    with pytest.raises(GearsymError) as error:
        _description(tmp_path, 'in_gear_settle = { value = 50, unit = "ms", source = "test" }')
    message = str(error.value)
    assert "in_gear_settle" in message and "'s'" in message and "\n" not in message, message


def test_the_filter_counts_the_time_since_its_own_last_switch(
    default_description, default_scenario, monkeypatch
):
    """Over one fleet vehicle's 2-3 the prediction of each interval is told the time from the
    filter's last mode switch to the interval's start: infinite before the first switch, 0 for
    the interval that starts at a switch's sample (and for the rest of an interval in which an
    element locks up), then one sample time more per interval."""
    import gearsym.symbolic.estimators.ekf as ekf
    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    told: list[float] = []
    predict = ekf.ekf_predict

    def spy(*args, **kwargs):
        since = kwargs.get("since_switch", args[7] if len(args) > 7 else np.inf)
        told.append(float(since))
        return predict(*args, **kwargs)

    monkeypatch.setattr(ekf, "ekf_predict", spy)
    d = default_description
    (fr,) = run_fleet(d, default_scenario, load_fleet(d), runs=1, seed=700200, bound=False).runs
    run = fr.run
    h = float(run.t[1] - run.t[0])
    switch_times = sorted({s.t for s in run.switches})
    assert switch_times, "the filter switched modes"
    assert np.isinf(told[0])  # before any switch
    # the intervals that start at a switch's sample are told 0; each later one h more
    finite = np.array([s for s in told if np.isfinite(s)])
    assert finite[0] == 0.0
    steps = np.diff(finite)
    ok = np.isclose(steps, h, rtol=1e-9) | (finite[1:] == 0.0)
    assert ok.all(), finite[:20]
    assert np.sum(finite == 0.0) >= len(switch_times)


def _with_shift_table(tmp_path: Path, shift: str, entries: str):
    """The shipped description, map-scale filter, with a ``shift."<shift>"`` sub-table of its
    ``[estimator.model_error_map_scale]``."""
    text = _without_in_gear(SHIPPED.read_text(encoding="utf-8"))
    text = text.replace("[estimator]\n", '[estimator]\nmu_model = "map_scale"\n', 1)
    text += f'\n[estimator.model_error_map_scale.shift."{shift}"]\n{entries}\n'
    path = tmp_path / "per_shift.toml"
    path.write_text(text, encoding="utf-8")
    return load_description(str(path))


def test_a_shift_sub_table_overrides_the_tables_factor_for_that_shift_only(tmp_path):
    d = _with_shift_table(
        tmp_path,
        "2-3",
        'in_gear = { value = 0.1, unit = "1", source = "test" }\n'
        'in_gear_settle = { value = 0.05, unit = "s", source = "test" }',
    )
    own = augmented_model(d, "2-3", WITH_STATES)
    assert (own.in_gear_factor, own.in_gear_settle) == (0.1, 0.05)
    other = augmented_model(d, "3-4", ("m_veh", "mu_81", "mu_27", "zeta", "k_ss"))
    assert (other.in_gear_factor, other.in_gear_settle) == (1.0, 0.0)
    # the thesis' filter takes [estimator.model_error], whose sub-tables are its own
    assert augmented_model(d, "2-3", default_parameters(d, "2-3")).in_gear_factor == 1.0
    assert d.estimator.to_dict()["in_gear_by_shift"] == [
        {"table": "model_error_map_scale", "shift": "2-3", "in_gear": 0.1, "in_gear_settle": 0.05}
    ]


@pytest.mark.parametrize(
    ("shift", "entries", "reason"),
    [
        ("2-x", 'in_gear = { value = 0.1, unit = "1", source = "t" }', "two of the description"),
        ("3-3", 'in_gear = { value = 0.1, unit = "1", source = "t" }', "two of the description"),
        (
            "2-3",
            'omega_1 = { value = 0.1, unit = "rad^2/s^3", source = "t" }',
            "in_gear_settle only",
        ),
    ],
)
def test_a_bad_shift_sub_table_is_refused_in_one_line(tmp_path, shift, entries, reason):
    with pytest.raises(GearsymError) as error:
        _with_shift_table(tmp_path, shift, entries)
    message = str(error.value)
    assert "model_error_map_scale.shift" in message and reason in message, message
    assert "\n" not in message
