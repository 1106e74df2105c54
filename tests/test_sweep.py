"""Sobol sweeps on Dask (validation/studies/sweep.py, `gearsym sweep`).

Expected values: the closed-form Sobol indices of the Ishigami function (Ishigami & Homma 1990;
Sobol' & Levitan 1999), and for the shift model the local sensitivities of chapter 3 (hybrid
(3.7) with event jumps), themselves checked here against central differences of the evaluator.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError

from gearsym.cli import main

pytest.importorskip("SALib")
distributed = pytest.importorskip("dask.distributed")


@pytest.fixture(scope="module")
def client():
    """One small LocalCluster for the module (threads: quick to start, no pickling trips)."""
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0"
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def test_ishigami_closed_form_values():
    """The closed forms give the values the literature prints (a = 7, b = 0.1)."""
    from gearsym.validation.studies.sweep import Ishigami

    s1, st = Ishigami().exact()
    assert np.allclose(s1, [0.3139, 0.4424, 0.0], atol=5e-5)
    assert np.allclose(st, [0.5576, 0.4424, 0.2437], atol=5e-5)


def test_ishigami_sobol_indices_on_a_local_cluster(client):
    """S1, ST of the Ishigami function through the whole path (SALib sample, Dask batches,
    SALib analysis) against the closed form. Tolerance: twice the 95 % bootstrap half-width
    (about 3.9 standard errors, so a correct estimator fails with probability ~1e-4 per index);
    the half-widths themselves must be small, or the check would say nothing."""
    from gearsym.validation.studies.sweep import Ishigami, SweepDefinition, run_sweep

    pi = math.pi
    definition = SweepDefinition({f"x{k}": (-pi, pi) for k in (1, 2, 3)}, samples=4096, seed=7)
    calls = []
    result = run_sweep(
        definition,
        Ishigami(),
        batch=2048,
        client=client,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert len(result.points) == 4096 * 5
    assert calls[-1] == (10, 10)  # one progress report per batch, the last one complete
    s1, st = Ishigami().exact()
    si = result.indices["f"]
    for k in range(3):
        assert si["S1_conf"][k] < 0.05 and si["ST_conf"][k] < 0.05
        assert abs(si["S1"][k] - s1[k]) <= 2 * si["S1_conf"][k], (k, si)
        assert abs(si["ST"][k] - st[k]) <= 2 * si["ST_conf"][k], (k, si)
    # the Monte-Carlo view: E[f] = a/2 = 3.5 over the cube (sin x1 terms average to zero)
    assert result.statistics["f"]["mean"] == pytest.approx(3.5, abs=0.1)


@pytest.fixture(scope="module")
def shift():
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.studies.sweep import ShiftEvaluator

    return ShiftEvaluator(load_description(None))


NAMES = ["mu_05", "mu_38", "m_veh"]


def test_local_shift_duration_sensitivity_matches_central_differences(shift):
    """∂(shift duration)/∂μ05 of the hybrid sensitivities (the lock-up event's ∂τ/∂p) against
    central differences of two evaluator runs (±1 %); a faster-gripping on-coming clutch ends
    the speed phase sooner, so the sign must be negative."""
    from gearsym.validation.studies.sweep import local_sensitivities

    derivative = local_sensitivities(shift, NAMES)["shift_duration"]["mu_05"]
    h = 0.0012
    plus, minus = shift(np.array([[0.12 + h], [0.12 - h]]), ["mu_05"])["shift_duration"]
    assert derivative < 0
    assert derivative == pytest.approx((plus - minus) / (2 * h), rel=2e-3)


def test_shift_ranking_by_total_index_agrees_with_local_sensitivities(shift, client):
    """±10 % around the nominal μ05, μ38, m_veh: the ranking by total-order index of the shift
    duration and of the final input speed equals the ranking by the local sensitivities (the
    linearised indices (∂Q/∂p σ)²/Σ). Over ±10 % the quantities are close to linear in the
    parameters, so the global view must not reorder them; the dominant parameter's share must
    agree with the linearised one within its interval.

    The ranking is only worth something if the bootstrap intervals (SALib's 95 % ST_conf)
    separate what it ranks: with 8 base samples the shift duration's μ38 (ST 0.035 ± 0.058)
    and m_veh (0.004 ± 0.004) overlapped, and the final speed's μ05 (0.013 ± 0.019) reached
    μ38's. 32 base samples (160 runs, 26-37 s on two workers of a shared machine) separate
    every adjacent pair: measured, shift duration μ05 0.96 ± 0.29, μ38 0.039 ± 0.018, m_veh
    0.0033 ± 0.0018; final input speed m_veh 0.96 ± 0.37, μ05 0.017 ± 0.010, μ38 2.7e-5 ±
    2e-5."""
    from gearsym.validation.studies.sweep import (
        SweepDefinition,
        linearised_indices,
        local_sensitivities,
        run_sweep,
    )

    nominal = {"mu_05": 0.12, "mu_38": 0.12, "m_veh": 1800.0}
    ranges = {n: (0.9 * v, 1.1 * v) for n, v in nominal.items()}
    definition = SweepDefinition(ranges, samples=32, seed=3)
    result = run_sweep(definition, shift, batch=16, client=client)
    local = local_sensitivities(shift, NAMES)
    # physics: the on-coming clutch's friction decides how fast its slip closes; the vehicle
    # mass decides the speeds at the end of the scenario
    for quantity, dominant in (("shift_duration", "mu_05"), ("final_omega_in", "m_veh")):
        lin = linearised_indices(local[quantity], ranges)
        st = dict(zip(NAMES, result.indices[quantity]["ST"], strict=True))
        conf = dict(zip(NAMES, result.indices[quantity]["ST_conf"], strict=True))
        print(
            quantity, {n: f"{st[n]:.4g} ± {conf[n]:.2g} (linearised {lin[n]:.4g})" for n in NAMES}
        )
        ranked = sorted(NAMES, key=st.get, reverse=True)
        assert ranked == sorted(NAMES, key=lin.get, reverse=True), (quantity, st, lin)
        # adjacent ranks apart: the lower end of each interval above the upper end of the next
        for upper, lower in zip(ranked[:-1], ranked[1:], strict=True):
            assert st[upper] - conf[upper] > st[lower] + conf[lower], (quantity, upper, lower)
        assert max(NAMES, key=lin.get) == dominant and lin[dominant] > 0.9
        assert abs(st[dominant] - lin[dominant]) <= conf[dominant], (quantity, st, lin)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--param", "m_veh=2000:1000", "--param", "k_ss=1:2"], "LO must be below HI"),
        (["--param", "m_veh=1000", "--param", "k_ss=1:2"], "expected NAME=LO:HI"),
        (["--param", "m_veh=1000:nan", "--param", "k_ss=1:2"], "must be finite"),
        (["--param", "m_vehx=1:2", "--param", "k_ss=1:2"], "unknown parameter 'm_vehx'"),
        (["--param", "m_veh=1:2", "--scheduler", "udp://x"], "expected local or tcp://"),
        (["--param", "m_veh=1:2", "--samples", "10"], "samples: must be a power of two"),
        (
            ["--param", "m_veh=1000:2000", "--param", "k_ss=1:2", "--scheduler", "tls://h:1"],
            "TLS needs certificates gearsym does not configure",
        ),
        (
            ["--param", "m_veh=1000:2000", "--param", "k_ss=1:2", "--scheduler", "tcp://h:1"]
            + ["--workers", "4"],
            "workers: is for --scheduler local",
        ),
        # a sample must pass the description's checks (the parameter records): negative mass
        # and friction ran and printed S1 = 2.09
        (
            ["--param", "m_veh=-2000:-1000", "--param", "mu_05=-0.2:-0.1"],
            "m_veh=-2000:-1000: m_veh must be positive, got LO -2000",
        ),
        (
            ["--param", "m_veh=1600:2000", "--param", "mu_05=0.1:1.5"],
            "mu_05=0.1:1.5: above the plausible range of μ (at most 1)",
        ),
        (
            ["--param", "m_veh=50:2000", "--param", "mu_05=0.1:0.2"],
            "m_veh=50:2000: below the plausible range of m_veh (at least 100 kg)",
        ),
        (
            [
                "--param",
                "m_veh=1000:2000",
                "--param",
                "k_ss=1:2",
                "--scheduler",
                "tcp://127.0.0.1:9",
            ],
            "cannot reach tcp://127.0.0.1:9",
        ),
    ],
)
def test_cli_errors_are_one_line_exit_2_nothing_written(tmp_path, capsys, args, needle):
    out = tmp_path / "sweep"
    status = main(["sweep", *args, "--out", str(out)])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("gearsym:")]
    assert status == 2
    assert len(lines) == 1 and needle in lines[0], err
    assert "Traceback" not in err
    assert not out.exists()


def test_definition_file_errors(tmp_path, capsys):
    bad = tmp_path / "s.toml"
    bad.write_text("[sweep]\nsamples = 8\n[sweep.parameters]\nm_veh = [1000]\n", "utf-8")
    status = main(["sweep", "--definition", str(bad), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status == 2
    assert f"gearsym: {bad}: sweep.parameters.m_veh: expected [LO, HI]" in err


def test_cli_end_to_end_writes_tables_and_figures(tmp_path, capsys):
    """A tiny sweep through the command (its own LocalCluster, one worker process): --json,
    the CSV and the Parquet file hold the same numbers, the MANIFEST lists every file."""
    import json

    import pyarrow.parquet as pq

    out = tmp_path / "sweep"
    argv = ["sweep", "--param", "mu_05=0.108:0.132", "--param", "m_veh=1620:1980"]
    argv += ["--samples", "2", "--workers", "1", "--batch", "4", "--out", str(out), "--json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["runs"] == 2 * (2 + 2)
    table = pq.read_table(out / "samples.parquet").to_pydict()
    rows = np.genfromtxt(out / "samples.csv", delimiter=",", names=True)
    assert np.allclose(rows["shift_duration"], table["shift_duration"], rtol=1e-11)
    assert np.all((rows["mu_05"] >= 0.108) & (rows["mu_05"] <= 0.132))
    manifest = (out / "MANIFEST").read_text("utf-8")
    for name in ("samples.csv", "samples.parquet", "indices.csv", "sweep.json"):
        assert name in manifest
    assert (out / "sobol_shift_duration.png").exists()
    # a faster-gripping on-coming clutch shortens the shift in every run pair
    assert summary["local_derivatives"]["shift_duration"]["mu_05"] < 0


def test_definition_file_and_params_merge(tmp_path):
    """A [sweep] table is read as written; --param parses NAME=LO:HI."""
    from gearsym.validation.studies.sweep import load_definition, parse_range

    path = tmp_path / "s.toml"
    path.write_text(
        "[sweep]\nsamples = 16\nseed = 4\n[sweep.parameters]\nm_veh = [1600, 2000.5]\n", "utf-8"
    )
    definition = load_definition(path)
    assert definition.ranges == {"m_veh": (1600.0, 2000.5)}
    assert (definition.samples, definition.seed) == (16, 4)
    assert parse_range("k_ss=9e3:1.1e4") == ("k_ss", (9000.0, 11000.0))


class _HalfFails:
    """An evaluator that fails (NaN) wherever x1 > 0.5 for one quantity."""

    quantities = ("ok", "broken")

    def __call__(self, points, names):
        x1 = points[:, 0]
        return {"ok": x1 + 2 * points[:, 1], "broken": np.where(x1 > 0.5, np.nan, x1)}


def test_failed_runs_are_counted_and_get_no_indices(client):
    """A quantity with failed runs keeps statistics (with the count) but no indices; the other
    quantity's indices are those of the linear f = x1 + 2 x2 on the unit square: S = (1, 4)/5."""
    from gearsym.validation.studies.sweep import SweepDefinition, run_sweep

    definition = SweepDefinition({"x1": (0.0, 1.0), "x2": (0.0, 1.0)}, samples=256, seed=2)
    result = run_sweep(definition, _HalfFails(), batch=256, client=client)
    assert "broken" not in result.indices and "runs gave no value" in result.skipped["broken"]
    assert result.statistics["broken"]["failed"] == int(np.sum(result.points[:, 0] > 0.5))
    si = result.indices["ok"]
    for k, exact in enumerate((0.2, 0.8)):
        assert abs(si["ST"][k] - exact) <= 2 * si["ST_conf"][k] + 1e-9


def test_a_definition_files_samples_are_bounded_as_the_options(tmp_path, capsys):
    """``[sweep] samples`` had no upper bound (the option has one)."""
    from gearsym.validation.studies.sweep import load_definition

    path = tmp_path / "sweep.toml"
    path.write_text("[sweep]\nsamples = 1048576\n[sweep.parameters]\nm_veh = [1600, 2000]\n")
    with pytest.raises(GearsymError, match="sweep.samples: must be at most 100000, got 1048576"):
        load_definition(path)


@pytest.mark.parametrize(
    ("body", "key"),
    [
        ("[sweep]\nparameters = 5\n", "sweep.parameters"),
        ("[sweep]\nparameters = [1, 2]\n", "sweep.parameters"),
        ("sweep = 3\n", "sweep"),
        ('[sweep]\nsamples = "many"\n', "sweep.samples"),
    ],
)
def test_a_definition_of_the_wrong_type_is_one_line(tmp_path, body, key):
    from gearsym.validation.studies.sweep import load_definition

    path = tmp_path / "sweep.toml"
    path.write_text(body)
    with pytest.raises(GearsymError, match=f"^{path}: {key}: "):
        load_definition(path)


def test_indices_outside_zero_one_beyond_their_interval_are_flagged():
    """S1 = 2.09 ± 0.3 (the negative-mass sweep's) is no index; -0.05 ± 0.1 is noise."""
    from gearsym.validation.studies.sweep import implausible_indices

    indices = {
        "shift_duration": {
            "S1": [2.09, 0.5, -0.05],
            "S1_conf": [0.3, 0.1, 0.1],
            "ST": [0.4, 1.05, -0.3],
            "ST_conf": [0.1, 0.1, 0.2],
        }
    }
    flagged = implausible_indices(indices, ["m_veh", "mu_05", "zeta"])
    assert len(flagged) == 2
    assert flagged[0].startswith("shift_duration: S1 of m_veh = 2.090 ± 0.300 lies outside")
    assert flagged[1].startswith("shift_duration: ST of zeta = -0.300 ± 0.200 lies outside")


def test_a_scheduler_without_workers_is_one_line(monkeypatch):
    """A reachable scheduler that has no worker would wait for ever: refused after a wait."""
    from dask.distributed import LocalCluster
    from gearsym.validation.studies import sweep

    monkeypatch.setattr(sweep, "WORKER_WAIT", 1.0)
    with LocalCluster(
        n_workers=0, processes=False, protocol="tcp://", dashboard_address=":0"
    ) as cluster:
        with pytest.raises(GearsymError, match="has no workers"):
            sweep.connect(cluster.scheduler_address, workers=1)


def test_a_worker_that_dies_is_one_line(capsys):
    """A task that kills its worker process (as a crash in native code or the kernel's OOM
    killer would): the scheduler gives up on it and the sweep says so in one line, not with
    Dask's traceback."""
    import dask
    from gearsym.validation.studies.sweep import Evaluator, SweepDefinition, run_sweep

    class Dies(Evaluator):  # defined here: it travels to the worker process by value
        quantities = ("f",)

        def __call__(self, points, names):
            import os

            os._exit(3)

    definition = SweepDefinition({"x1": (0.0, 1.0), "x2": (0.0, 1.0)}, samples=2, seed=1)
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        with pytest.raises(GearsymError) as err:
            run_sweep(definition, Dies(), workers=1, batch=64)
    text = str(err.value)
    assert text.startswith("sweep: scheduler: a Dask worker died") and "\n" not in text, text
