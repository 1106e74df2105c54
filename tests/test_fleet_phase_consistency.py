"""NEES and NIS per phase of a fleet evaluation (``consistency_per_phase`` in its JSON, a table
in its Markdown): the phases partition every run's samples, so the per-phase sums add up to the
run's own; the NIS band per dof is the χ² one, close to its normal approximation
1 ± 1.96 √(2/D) for D summed dof."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gearsym.validation.sim.fleet import load_fleet
from gearsym.validation.studies.estimation.fleet_report import fleet_markdown


@pytest.fixture(scope="module")
def evaluation(default_description, default_scenario):
    from gearsym.validation.studies.estimation.fleet_eval import run_fleet

    d = default_description
    return run_fleet(d, default_scenario, load_fleet(d), runs=2, seed=700200, bound=False)


def test_the_phases_sums_add_up_to_the_runs(evaluation):
    per_phase = evaluation.consistency_per_phase()
    assert set(per_phase) == set(evaluation.phase_names()) and len(per_phase) >= 3
    runs = [fr.run for fr in evaluation.runs]
    assert sum(c["samples"] for c in per_phase.values()) == sum(len(r.t) for r in runs)
    nees = sum(c["nees_per_dof"] * c["nees_dof"] for c in per_phase.values())
    assert nees == pytest.approx(sum(float(np.sum(r.nees)) for r in runs), rel=1e-12)
    assert sum(c["nees_dof"] for c in per_phase.values()) == sum(
        int(np.sum(r.nees_dof)) for r in runs
    )
    nis = sum(c["nis_per_dof"] * c["nis_dof"] for c in per_phase.values())
    assert nis == pytest.approx(sum(float(np.sum(r.nis[r.nis_dof > 0])) for r in runs), rel=1e-12)


def test_the_nis_band_per_dof_is_the_chi_square_one(evaluation):
    for c in evaluation.consistency_per_phase().values():
        low, high = c["nis_band_per_dof"]
        half = 1.96 * math.sqrt(2.0 / c["nis_dof"])  # the normal approximation of χ²(D)/D
        assert low == pytest.approx(1 - half, abs=0.1 * half)
        assert high == pytest.approx(1 + half, abs=0.1 * half)


def test_the_markdown_shows_the_table_and_an_older_json_renders_without_it(evaluation):
    data = evaluation.to_dict()
    text = fleet_markdown(data, "gearsym estimate ...")
    assert "| phase | NEES/dof | NIS/dof | samples |" in text
    for phase in data["consistency_per_phase"]:
        assert f"| {phase} | " in text
    older = {k: v for k, v in data.items() if k != "consistency_per_phase"}
    assert "NEES/dof | NIS/dof" not in fleet_markdown(older, "gearsym estimate ...")
