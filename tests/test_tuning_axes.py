"""The tuning's grid and criterion from the command line (``gearsym estimate --fleet --tune
--tune-factors --tune-twist-factors --tune-in-gear --tune-criterion``): each factor g tried on
the table's ``in_gear`` gives the NEES and NIS sums of an evaluation whose description states
that ``in_gear`` (two code paths: the tuning's copy of the filter's model and the description
read from TOML), the chosen ``in_gear`` is g times the table's, each shift's own sums are its
evaluation's, and the options are refused where they cannot act."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.io.package_data import data_file

from gearsym.commands import load as load_description
from tests.test_cli import gearsym

SHIPPED = data_file("thesis_9speed.toml")
SEED = 500004


def _with_in_gear(tmp_path: Path, value: float) -> object:
    """The shipped description with ``in_gear = value`` in ``[estimator.model_error]`` (the
    thesis' filter's table)."""
    text = SHIPPED.read_text(encoding="utf-8")
    header = "\n[estimator.model_error]\n"
    assert header in text
    entry = f'in_gear = {{ value = {value!r}, unit = "1", source = "test" }}\n'
    path = tmp_path / f"in_gear_{value}.toml"
    path.write_text(text.replace(header, header + entry, 1), encoding="utf-8")
    return load_description(str(path))


def _tuned(d, scenario, in_gear_factors, **options):
    """The tuning on vehicle :data:`SEED` of the default fleet, c = c_φ = 1, the in-gear axis
    ``in_gear_factors``."""
    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.studies.estimation.tuning import tune_model_error

    return tune_model_error(
        d,
        scenario,
        load_fleet(d),
        [SEED],
        factors=(1.0,),
        twist_factors=(1.0,),
        in_gear_factors=in_gear_factors,
        **options,
    )


def _evaluation_sums(d, scenario, fleet) -> tuple[float, float]:
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    (run,) = run_fleet(d, scenario, fleet, runs=1, seed=SEED, bound=False).runs
    used = run.run.nis_dof > 0
    nees = float(np.sum(run.run.nees)) / float(np.sum(run.run.nees_dof))
    nis = float(np.sum(run.run.nis[used])) / float(np.sum(run.run.nis_dof[used]))
    return nees, nis


def test_each_in_gear_factor_is_an_evaluation_with_that_in_gear(
    default_description, default_scenario, tmp_path
):
    from gearsym.validation.sim.fleet import load_fleet

    d = default_description
    fleet = load_fleet(d)
    tuned = _tuned(d, default_scenario, (1.0, 0.1))
    assert tuned.factors == ((1.0, 1.0, 1.0), (1.0, 1.0, 0.1))
    for k, description in enumerate((d, _with_in_gear(tmp_path, 0.1))):
        nees, nis = _evaluation_sums(description, default_scenario, fleet)
        assert tuned.nees_per_dof[k] == pytest.approx(nees, rel=1e-12), k
        assert tuned.nis_per_dof[k] == pytest.approx(nis, rel=1e-12), k
    # the factor reaches the filter: a tenth of the gears' model error moves both sums
    assert tuned.nees_per_dof[1] != pytest.approx(tuned.nees_per_dof[0], rel=1e-6)
    assert tuned.nis_per_dof[1] != pytest.approx(tuned.nis_per_dof[0], rel=1e-6)
    assert tuned.intensities["in_gear"] == tuned.chosen[2]
    assert " g " in tuned.text().splitlines()[1] + " "
    assert tuned.to_dict()["model_error"]["in_gear"] == tuned.chosen[2]


def test_the_chosen_in_gear_is_g_times_the_tables(default_scenario, tmp_path):
    """A table stating in_gear = 0.5 tried at g = 0.2 gives in_gear = 0.1, and the sums are an
    evaluation's with in_gear = 0.1."""
    from gearsym.validation.sim.fleet import load_fleet

    d = _with_in_gear(tmp_path, 0.5)
    fleet = load_fleet(d)
    tuned = _tuned(d, default_scenario, (0.2,))
    assert tuned.intensities["in_gear"] == pytest.approx(0.1, rel=1e-12)
    nees, nis = _evaluation_sums(_with_in_gear(tmp_path, 0.1), default_scenario, fleet)
    assert tuned.nees_per_dof[0] == pytest.approx(nees, rel=1e-12)
    assert tuned.nis_per_dof[0] == pytest.approx(nis, rel=1e-12)


@pytest.mark.parametrize(
    ("arguments", "reason"),
    [
        (("--tune-in-gear", "0.1,1"), "--tune"),  # without --tune
        (("--tune-factors", "0.1,1"), "--tune"),
        (("--fleet", "--tune", "--tune-in-gear", "0,1"), "greater than 0"),
        (("--fleet", "--tune", "--tune-twist-factors", "-1"), "greater than 0"),
        (("--fleet", "--tune", "--tune-in-gear", "0.1,x"), "x"),
        (("--fleet", "--tune", "--tune-factors", "0.1,0.1"), "twice"),
        (("--tune-criterion", "per-shift"), "--tune"),
    ],
)
def test_bad_tuning_axes_are_refused_in_one_line(arguments, reason):
    result = gearsym("estimate", "--filter", "ekf", *arguments)
    assert result.returncode == 2 and result.stdout == ""
    (line,) = result.stderr.strip().splitlines()
    option = next(a for a in arguments if a.startswith("--tune-"))  # the axis named
    assert option in line and reason in line, line


def test_the_axes_reach_the_tuning(monkeypatch, capsys):
    import gearsym.validation.studies.estimation.tuning as tuning

    from gearsym.cli import main

    seen = {}

    def recorder(d, scenario, fleet, seeds, **options):  # the real one's signature
        seen.update(options)
        return tuning.TuningResult(
            fleet="f",
            seeds=tuple(seeds),
            factors=((1.0, 1.0, 0.3),),
            nees_per_dof=(1.0,),
            nis_per_dof=(1.0,),
            chosen=(1.0, 1.0, 0.3),
            intensities={"in_gear": 0.3},
            base={},
        )

    monkeypatch.setattr(tuning, "tune_model_error", recorder)
    code = main(
        ["estimate", "--filter", "ekf", "--fleet", "--tune", "--runs", "1"]
        + ["--tune-in-gear", "0.3,1", "--tune-factors", "2", "--tune-criterion", "per-shift"]
        + ["--json"]
    )
    assert code == 0
    assert seen["in_gear_factors"] == (0.3, 1.0) and seen["factors"] == (2.0,)
    assert seen["twist_factors"] == tuning.TWIST_FACTORS  # the default axis
    assert seen["criterion"] == "per_shift"
    assert json.loads(capsys.readouterr().out)["tuning"]["model_error"]["in_gear"] == 0.3


def test_per_shift_sums_and_the_per_shift_criterion(default_description, default_scenario):
    """Tuned on the 2-3 and the 3-4 (one vehicle, two in-gear factors): each shift's own
    NEES/dof and NIS/dof are its evaluation's alone (the 2-3 against run_fleet), the pooled ones
    lie between the two shifts' (a dof-weighted mean), and ``criterion="per_shift"`` chooses
    the grid point with the smallest sum of the shifts' own criteria."""
    import math

    from gearsym.validation.sim.fleet import load_fleet
    from gearsym.validation.sim.scenario import load_scenario

    d = default_description
    fleet = load_fleet(d)
    scenarios = (default_scenario, load_scenario(d, data_file("scenario_3_4.toml")))
    tuned = _tuned(d, scenarios, (1.0, 0.1), criterion="per_shift")
    assert set(tuned.per_shift) == {"2-3", "3-4"}
    nees, nis = _evaluation_sums(d, default_scenario, fleet)
    assert tuned.per_shift["2-3"][0][0] == pytest.approx(nees, rel=1e-12)
    assert tuned.per_shift["2-3"][1][0] == pytest.approx(nis, rel=1e-12)
    for k in range(2):
        for pooled, own in ((tuned.nees_per_dof, 0), (tuned.nis_per_dof, 1)):
            values = [tuned.per_shift[s][own][k] for s in ("2-3", "3-4")]
            assert min(values) <= pooled[k] <= max(values)
    scores = [
        sum(math.log(a[k]) ** 2 + math.log(b[k]) ** 2 for a, b in tuned.per_shift.values())
        for k in range(2)
    ]
    assert tuned.chosen == tuned.factors[int(np.argmin(scores))]
    assert tuned.to_dict()["criterion"] == "per_shift"
    assert "3-4: NEES/dof" in tuned.text()


def test_shifts_with_in_gear_entries_of_their_own_are_tuned_apart(default_scenario, tmp_path):
    """The shipped description gives the 2-3's map-scale filter its own in-gear factor; tuned
    together with the 3-4 (factor 1) the result could name only one: refused in one line
    when the second shift's filter is built."""
    import dataclasses

    from gearsym.symbolic.errors import GearsymError
    from gearsym.validation.sim.scenario import load_scenario

    d = dataclasses.replace(
        load_description(str(SHIPPED)),
        estimator=dataclasses.replace(
            load_description(str(SHIPPED)).estimator, mu_model="map_scale"
        ),
    )
    scenarios = (default_scenario, load_scenario(d, data_file("scenario_3_4.toml")))
    with pytest.raises(GearsymError) as error:
        _tuned(d, scenarios, (1.0,), parameters=("m_veh", "mu_38", "mu_05", "zeta", "k_ss"))
    message = str(error.value)
    assert "--tune-scenario" in message and "in-gear factor" in message, message
    assert "\n" not in message
