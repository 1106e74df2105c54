"""``estimate(request) -> report`` (validation/studies/estimation/workflow.py): one workflow for
the command line and the notebook; every option the chosen filter would not use is refused in
one line before any simulation; what the filter knows (the calibration) and the world it is
judged in (the truth) enter separately."""

from __future__ import annotations

import json
import time

import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.validation.studies.estimation.workflow import (
    Calibration,
    EstimateRequest,
    Truth,
    check_request,
)

import gearsym
from gearsym import cli


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (("--filter", "euio", "--dropout", "0.2,0.4"), "--dropout"),
        (("--filter", "euio", "--dropout-outputs", "omega_1"), "--dropout-outputs"),
        (("--filter", "euio", "--params", "m_veh"), "--params"),
        (("--filter", "euio", "--unknown", "T_K38"), "--unknown"),
        (("--filter", "uio", "--params", "m_veh"), "--params"),
        (("--filter", "uio", "--initial", "m_veh=1500"), "--initial"),
        (("--filter", "uio", "--dropout", "0.2,0.4"), "--dropout"),
        (("--filter", "uio", "--modes", "filter"), "--modes"),
        (("--filter", "ekf", "--unknown", "T_K38"), "--unknown"),
        (("--filter", "ekf", "--sample-time", "1e-9"), "--sample-time"),
        (("--filter", "uio", "--sample-time", "0.0001"), "--sample-time"),
        (("--filter", "ekf", "--drive", "upshifts", "--runs", "2"), "--runs"),
    ],
)
def test_an_option_the_filter_would_not_use_is_refused_before_any_work(
    args: tuple[str, ...],
    option: str,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from gearsym.validation.studies.estimation import workflow

    def no_simulation(*args: object) -> None:
        raise AssertionError("the reference simulation ran before the refusal")

    monkeypatch.setattr(workflow, "_simulate", no_simulation)
    assert cli.main(["estimate", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"gearsym: estimate: {option}: "), err


def test_a_drive_whose_shifts_do_not_chain_is_refused(
    tmp_path_factory: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    from gearsym.validation.sim.scenario import default_scenario_path

    folder = default_scenario_path().parent
    drive = f"{folder / 'scenario_3_4.toml'},{folder / 'scenario_1_2.toml'}"
    assert cli.main(["estimate", "--filter", "ekf", "--drive", drive]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "--drive: the shifts do not chain: 3-4 ends in gear 4" in err
    assert "starts in gear 1" in err


def test_the_request_keeps_the_calibration_apart_from_the_truth() -> None:
    """Two requests that differ only in their truth give the filter the same calibration
    object; the check reads the truth only for its time span."""
    from gearsym.validation.sim.scenario import default_scenario_path

    box = gearsym.load()
    calibration = Calibration(box.description, sample_time=0.01)
    coast = default_scenario_path().parent / "scenario_2_3_coast.toml"
    a = EstimateRequest("ekf", calibration, (Truth(box.scenario(None)),))
    b = EstimateRequest("ekf", calibration, (Truth(box.scenario(coast)),))
    check_request(a)
    check_request(b)
    assert a.calibration is b.calibration
    assert a.truth.scenario.name != b.truth.scenario.name
    with pytest.raises(GearsymError, match="--filter"):
        check_request(EstimateRequest("kalman", calibration, a.truths))


def test_the_notebook_and_the_command_line_give_the_same_report(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``gearsym.load().estimate(...)`` is the command's workflow: the same JSON, seed for
    seed (the UIO: quick and deterministic)."""
    report = gearsym.load().estimate("uio", seed=3, relative_noise=(0.01,))
    assert (
        cli.main(["estimate", "--filter", "uio", "--seed", "3", "--noise", "0.01", "--json"]) == 0
    )
    printed = json.loads(capsys.readouterr().out)
    assert printed.pop("files") == []
    assert printed == json.loads(json.dumps(report.to_dict()))
    with pytest.raises(GearsymError, match="noise"):
        gearsym.load().estimate("uio", noise=0.01)  # a misspelt option is refused


def test_a_dropout_phase_of_a_gear_named_with_underscores_is_the_detected_phase() -> None:
    """``--dropout gear_2_a`` names the phase "gear 2_a" (every underscore used to become a
    space, and the phase was not found: a traceback)."""
    from gearsym.cmd_estimate import _dropout_window

    assert _dropout_window("gear_2_a", "2_a-3") == "gear 2_a"
    assert _dropout_window("speed_phase", "2_a-3") == "speed phase"
    assert _dropout_window("0.1,0.2", "2_a-3") == (0.1, 0.2)
    with pytest.raises(GearsymError, match="gear_2_a, torque_phase, speed_phase, gear_3"):
        _dropout_window("gear_2", "2_a-3")


@pytest.mark.parametrize("noise", ["1e300", "1.5", "0.01,0.01,2"])
def test_an_absurd_relative_noise_is_refused(
    noise: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["estimate", "--filter", "ekf", "--noise", noise]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--noise: a relative speed error must be in [0, 1]" in err


def test_a_full_disk_under_out_is_one_line_and_leaves_nothing(
    tmp_path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import errno

    from gearsym.validation.studies.estimation import workflow

    def full(path, data):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(workflow, "write_json", full)  # the one the workflow calls
    out = tmp_path / "out"
    assert cli.main(["estimate", "--filter", "uio", "--out", str(out), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.splitlines()[-1] == (
        f"gearsym: {out}: cannot write: No space left on device; nothing was written"
    )
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_sigterm_turned_into_a_native_error_still_ends_in_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """CasADi's signal check raises the handler's Terminated inside its call and may hand it
    back as its own RuntimeError (seen under ``--filter euio --runs 50``): still exit 143 and
    one line, not a traceback."""
    import os
    import signal

    from gearsym.validation.studies.estimation import workflow

    def native(*args: object, **kwargs: object) -> None:
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler raises Terminated here
        except BaseException as err:  # what native code does with it
            raise RuntimeError("Error in Function::call for 'F' [IdasInterface]") from err
        raise AssertionError("SIGTERM was not delivered")

    def failing(*args: object, **kwargs: object) -> None:
        raise RuntimeError("a real error")

    monkeypatch.setattr(workflow, "_uio", native)
    assert cli.main(["estimate", "--filter", "uio"]) == 143
    assert capsys.readouterr().err == "gearsym: terminated; nothing was written\n"
    monkeypatch.setattr(workflow, "_uio", failing)
    with pytest.raises(RuntimeError, match="a real error"):  # without SIGTERM: an error
        cli.main(["estimate", "--filter", "uio"])
