"""The known inputs over a prediction interval (``--input-hold``): "sample" holds their values
at the interval's start (as the emitted C filter); "mean" takes the mean of the interval's two
samples for T_In and each F_N, while the element modes and valve flags stay held. A lock-up
ramp of 1.3 to 15 bar in 50 ms held at its start for 10 ms is what made the 3-4's on-coming μ
end 10 σ high (docs/fleet.md)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from gearsym.validation.studies.estimation.loop import interval_mean

from tests.test_cli import gearsym

#: The calibration's own vehicle (the description's mass, nothing drawn) and its noise seed.
OWN_VEHICLE = '[fleet]\nname = "own"\nm_veh = { value = 1800.0, unit = "kg", source = "t" }\n'
OWN_SEED = 700002


def _shipped_scenario(d, name: str):
    from gearsym.symbolic.io.package_data import data_file
    from gearsym.validation.sim.scenario import load_scenario

    return load_scenario(d, data_file(name))


def _final_rows_per_hold(d, scenario_name: str, parameters=None) -> dict:
    """The filter's final (estimate, σ, truth) per parameter on the calibration's own vehicle
    and the shipped scenario, once per input hold ("sample", "mean")."""
    from gearsym.validation.sim.fleet import parse_fleet
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    scenario = _shipped_scenario(d, scenario_name)
    fleet = parse_fleet(OWN_VEHICLE, "own.toml", d)
    rows = {}
    for hold in ("sample", "mean"):
        ev = run_fleet(
            d,
            scenario,
            fleet,
            runs=1,
            seed=OWN_SEED,
            bound=False,
            input_hold=hold,
            parameters=parameters,
        )
        rows[hold] = ev.final_rows(ev.runs[0])
    return rows


def test_the_mean_averages_the_known_inputs_and_holds_the_flags():
    """Inputs T_In, F_N27, slide_K27, stick_K27, valve_K27 at samples 4 and 5: the ramp's
    F_N27 from 910 to 2 828 N gives 1 869 N, T_In from 150 to 140 gives 145; the flags keep the
    held values handed in (the modes decided at sample 4), whatever sample 5 says."""
    names = ("T_In", "F_N27", "slide_K27", "stick_K27", "valve_K27")
    u = np.zeros((6, 5))
    u[4] = [150.0, 910.0, 1.0, 0.0, 1.0]
    u[5] = [140.0, 2828.0, 0.0, 1.0, 0.0]
    setup = SimpleNamespace(aug=SimpleNamespace(input_names=names, elements=("K27",)), u=u)
    held = np.array([150.0, 910.0, 1.0, 0.0, 1.0])
    got = interval_mean(setup, held, 5)
    assert got == pytest.approx([145.0, 1869.0, 1.0, 0.0, 1.0])
    assert held == pytest.approx([150.0, 910.0, 1.0, 0.0, 1.0])  # not modified


def test_the_mean_is_refused_where_it_is_not_built():
    """Without --fleet the option would be ignored: one line, exit 2."""
    result = gearsym("estimate", "--filter", "ekf", "--input-hold", "mean")
    assert result.returncode == 2 and result.stdout == ""
    (line,) = result.stderr.strip().splitlines()
    assert "--input-hold" in line and "fleet" in line, line


def test_on_the_3_4_the_mean_keeps_the_on_coming_mu_within_its_sigma(default_description):
    """The calibration's own vehicle on the shipped 3-4 (its K27 lock-up ramp 1.3 to 15 bar in
    50 ms): held at the interval's start the filter's μ27 after the shift is more than 4 σ
    above the mean true μ while K27 slid; with the interval's mean within 2 σ of it."""
    rows = _final_rows_per_hold(default_description, "scenario_3_4.toml")
    z_scores = {}
    for hold, final in rows.items():
        estimate, sigma, truth = final["mu_27"]
        z_scores[hold] = (estimate - truth) / sigma
    assert z_scores["sample"] > 4.0, z_scores
    assert abs(z_scores["mean"]) < 2.0, z_scores


def test_on_the_1_2_the_mean_removes_the_on_coming_scales_and_the_stiffness_bias(
    default_description,
):
    """The calibration's own vehicle on the shipped 1-2 with μ as map scales and the side
    shafts' stiffness as a state: held at the interval's start, the on-coming K81's rising
    force is under-predicted over every interval of its ramp, and the filter ends the shift with
    K81's scale more than 3 σ and the stiffness more than 2 σ high (the 1-2 fleet table's K81
    scale read 0.165 high); with the interval's mean both lie within 2 σ of the truth."""
    from dataclasses import replace

    d = default_description
    d = replace(d, estimator=replace(d.estimator, mu_model="map_scale"))
    rows = _final_rows_per_hold(
        d, "scenario_1_2.toml", parameters=("m_veh", "mu_05", "mu_81", "zeta", "k_ss")
    )
    z_scores = {
        hold: {
            name: (final[name][0] - final[name][2]) / final[name][1] for name in ("mu_81", "k_ss")
        }
        for hold, final in rows.items()
    }
    assert z_scores["sample"]["mu_81"] > 3.0 and z_scores["sample"]["k_ss"] > 2.0, z_scores
    assert max(abs(z) for z in z_scores["mean"].values()) < 2.0, z_scores


def test_tuning_runs_the_filter_with_the_hold_it_is_told(default_description, default_scenario):
    """The tuning's sums at the factors (1, 1) are the evaluation's NEES and NIS sums of the
    same vehicle with the same input hold (two code paths: run_fleet and tuning_sums), and the
    mean's sums differ from the held inputs' (so the hold reaches the filter)."""
    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet
    from gearsym.validation.studies.estimation.tuning import tune_model_error

    d, seed = default_description, 500002
    fleet = load_fleet(d)
    sums = {}
    for hold in ("sample", "mean"):
        tuned = tune_model_error(
            d,
            default_scenario,
            fleet,
            [seed],
            factors=(1.0,),
            twist_factors=(1.0,),
            input_hold=hold,
        )
        assert tuned.input_hold == hold and tuned.to_dict()["input_hold"] == hold
        (run,) = run_fleet(
            d, default_scenario, fleet, runs=1, seed=seed, bound=False, input_hold=hold
        ).runs
        used = run.run.nis_dof > 0
        nees = float(np.sum(run.run.nees)) / float(np.sum(run.run.nees_dof))
        nis = float(np.sum(run.run.nis[used])) / float(np.sum(run.run.nis_dof[used]))
        assert tuned.nees_per_dof[0] == pytest.approx(nees, rel=1e-12)
        assert tuned.nis_per_dof[0] == pytest.approx(nis, rel=1e-12)
        sums[hold] = (nees, nis)
    assert sums["mean"] != pytest.approx(sums["sample"], rel=1e-6), sums


def test_under_the_map_scale_the_mean_is_taken_before_the_map(
    default_description, default_scenario, monkeypatch
):
    """With μ = s μ_map the prediction's F_N input is the interval's mean force times the map
    value (a μ, 0.05-0.3), not the raw mean: the mean is taken of the told forces, then read
    through the map. Checked on every prediction of the 2-3 where F_N05 rises."""
    import dataclasses

    import gearsym.symbolic.estimators.ekf as ekf
    from gearsym.validation.sim.fleet import parse_fleet
    from gearsym.validation.studies.estimation.loop import filter_run

    from tests.test_tooth_wheel import one_vehicle

    d = dataclasses.replace(
        default_description,
        estimator=dataclasses.replace(default_description.estimator, mu_model="map_scale"),
    )
    scenario = default_scenario
    fleet = parse_fleet(
        '[fleet]\nname = "own"\nm_veh = { value = 1950.0, unit = "kg", source = "t" }\n',
        "own.toml",
        d,
    )
    _, setup = one_vehicle(d, scenario, fleet, 1)
    setup = dataclasses.replace(setup, input_hold="mean")
    assert setup.input_form is not None
    column = list(setup.aug.input_names).index("F_N05")
    seen: list[float] = []
    predict = ekf.ekf_predict

    def spy(discrete, z, P, u, *args):
        seen.append(float(u[column]))
        return predict(discrete, z, P, u, *args)

    monkeypatch.setattr(ekf, "ekf_predict", spy)
    filter_run(setup, 0)
    told = setup.u[:, column]
    means = 0.5 * (told[:-1] + told[1:])
    rising = np.flatnonzero((means > 100.0) & (np.diff(told) > 0))
    assert rising.size > 3
    ratios = np.array(seen)[rising] / means[rising]
    assert np.all((ratios > 0.05) & (ratios < 0.3)), ratios


def test_tuning_over_several_shifts_sums_their_nees_and_nis(default_description, default_scenario):
    """--tune-scenario: each tuning vehicle runs every shift, each shift's filter with its own
    elements' μ in place of the first shift's, and the NEES/dof and NIS/dof at a factor pair
    are the sums over all shifts' samples over the summed dof, here checked against the
    evaluation (run_fleet) of each shift on its own for the same vehicle."""

    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet
    from gearsym.validation.studies.estimation.tuning import tune_model_error

    d, seed = default_description, 500003
    fleet = load_fleet(d)
    scenarios = (default_scenario, _shipped_scenario(d, "scenario_3_4.toml"))
    own = {
        "2-3": ("m_veh", "mu_38", "mu_05", "zeta", "k_ss"),
        "3-4": ("m_veh", "mu_81", "mu_27", "zeta", "k_ss"),  # each shift's own μ (4.1)
    }
    tuned = tune_model_error(
        d,
        scenarios,
        fleet,
        [seed],
        factors=(1.0,),
        twist_factors=(1.0,),
        parameters=own["2-3"],
        input_hold="mean",
    )
    assert tuned.shifts == ("2-3", "3-4") and tuned.to_dict()["shifts"] == ["2-3", "3-4"]
    sums = np.zeros(4)
    for scenario in scenarios:
        (run,) = run_fleet(
            d,
            scenario,
            fleet,
            runs=1,
            seed=seed,
            bound=False,
            input_hold="mean",
            parameters=own[scenario.shift.name],
        ).runs
        used = run.run.nis_dof > 0
        sums += [
            np.sum(run.run.nees),
            np.sum(run.run.nees_dof),
            np.sum(run.run.nis[used]),
            np.sum(run.run.nis_dof[used]),
        ]
    assert tuned.nees_per_dof[0] == pytest.approx(sums[0] / sums[1], rel=1e-12)
    assert tuned.nis_per_dof[0] == pytest.approx(sums[2] / sums[3], rel=1e-12)


def test_tune_scenario_is_refused_without_tune():
    result = gearsym("estimate", "--filter", "ekf", "--tune-scenario", "any.toml")
    assert result.returncode == 2 and result.stdout == ""
    (line,) = result.stderr.strip().splitlines()
    assert "--tune-scenario" in line and "--tune" in line, line


def test_the_command_hands_the_tuning_every_shift_and_the_hold(monkeypatch, capsys):
    """`gearsym estimate --fleet --tune --input-hold mean --tune-scenario F` reaches the tuning
    with the --scenario's shift first, then F's, and the mean hold (the tuning itself replaced
    by a recorder: the plumbing from the command line, not the numbers, which the tests above
    check)."""
    import json

    import gearsym.validation.studies.estimation.tuning as tuning
    from gearsym.symbolic.io.package_data import data_file

    from gearsym.cli import main

    seen = {}

    def recorder(d, scenario, fleet, seeds, **options):  # the real one's signature
        seen.update(shifts=[s.shift.name for s in scenario], seeds=list(seeds), **options)
        return tuning.TuningResult(
            fleet="f",
            seeds=tuple(seeds),
            factors=((1.0, 1.0, 1.0),),
            nees_per_dof=(1.0,),
            nis_per_dof=(1.0,),
            chosen=(1.0, 1.0, 1.0),
            intensities={},
            base={},
            input_hold=options["input_hold"],
            shifts=tuple(seen["shifts"]),
        )

    monkeypatch.setattr(tuning, "tune_model_error", recorder)
    code = main(
        [
            "estimate",
            "--filter",
            "ekf",
            "--fleet",
            "--tune",
            "--runs",
            "2",
            "--seed",
            "123",
            "--input-hold",
            "mean",
            "--scenario",
            str(data_file("scenario_1_2.toml")),
            "--tune-scenario",
            str(data_file("scenario_3_4.toml")),
            "--json",
        ]
    )
    assert code == 0
    assert seen["shifts"] == ["1-2", "3-4"] and seen["seeds"] == [123, 124]
    assert seen["input_hold"] == "mean"
    printed = json.loads(capsys.readouterr().out)
    assert printed["tuning"]["shifts"] == ["1-2", "3-4"]
