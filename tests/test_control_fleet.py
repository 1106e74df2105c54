"""The adaptive-control study's statistics over a fleet, on hand-made vehicles whose answers are
known: percentiles per shift, counts, shifts to converge, the shift from which a strategy stays
near the oracle."""

from __future__ import annotations

import pytest
from gearsym.validation.studies.control.fleet_study import ControlFleet
from gearsym.validation.studies.control.study import OperatingPoint


def _shift(jerk: float, energy: float, error: float, **flags: bool) -> dict:
    return {
        "peak_jerk": jerk,
        "vdv": jerk / 10.0,
        "duration_error": error,
        "friction_energy": {"A": energy / 2, "B": energy / 2},
        "flare": flags.get("flare", False),
        "reversal_tie_up": flags.get("tie_up", False),
        "tie_up": flags.get("dip", False),
        "completed": flags.get("completed", True),
    }


def _fleet(runs: list[dict], strategies: tuple[str, ...], n: int) -> ControlFleet:
    return ControlFleet("2-3", OperatingPoint(8.0, 120.0, 30.0), strategies, n, runs, "test")


def test_per_shift_percentiles_and_counts() -> None:
    """Twenty vehicles with jerks 1..20 at one shift: p95 by NumPy's linear rule is 19.05, the
    mean 10.5. A vehicle that never locked counts as an infinite duration error: one in twenty
    is the 20th rank, which the nearest-rank-above p95 (rank ceil(0.95 * 19) + 1 = 20) reaches,
    so no p95 is given; with it locking, the p95 is the worst of the others."""
    runs = [
        {
            "seed": k,
            "strategies": {
                "fixed": [
                    _shift(
                        float(k + 1),
                        100.0 * (k + 1),
                        0.05 if k else float("nan"),
                        flare=k < 3,
                        tie_up=k == 4,
                        completed=k != 0,
                    )
                ]
            },
        }
        for k in range(20)
    ]
    (row,) = _fleet(runs, ("fixed",), 1).per_shift("fixed")
    assert row["jerk_p95"] == pytest.approx(19.05)
    assert row["jerk_mean"] == pytest.approx(10.5)
    assert row["friction_energy_p95"] == pytest.approx(1905.0)
    assert row["duration_error_p95"] is None
    assert (row["flares"], row["tie_ups"], row["failed"]) == (3, 1, 1)
    runs[0]["strategies"]["fixed"][0]["duration_error"] = -0.5
    (row,) = _fleet(runs, ("fixed",), 1).per_shift("fixed")
    assert row["duration_error_p95"] == pytest.approx(0.5)


def test_shifts_to_converge_and_near_oracle() -> None:
    """Vehicle 0 meets the duration target from its 3rd shift on, vehicle 1 never: the median
    over two vehicles with one infinite is infinite (None). The rule's p95 jerk equals the
    oracle's from shift 4 on (within 10 %) and its energy from shift 2: near from shift 4. A
    strategy below the oracle is as good: the fixed one at half the oracle's jerk and energy
    is near from shift 1."""
    errors = {0: [0.5, 0.3, 0.05, 0.02, 0.01, 0.0], 1: [0.5] * 6}
    jerks = [30.0, 20.0, 15.0, 10.5, 10.0, 10.0]
    runs = [
        {
            "seed": k,
            "strategies": {
                "rule": [_shift(jerks[i], 100.0, errors[k][i]) for i in range(6)],
                "oracle": [_shift(10.0, 100.0, 0.0) for _ in range(6)],
                "fixed": [_shift(5.0, 50.0, 0.0) for _ in range(6)],
            },
        }
        for k in (0, 1)
    ]
    fleet = _fleet(runs, ("rule", "oracle", "fixed"), 6)
    converge = fleet.shifts_to_converge("rule")
    assert converge["never"] == 1 and converge["median"] is None
    assert fleet.shifts_to_converge("oracle") == {"median": 1.0, "p95": 1.0, "never": 0}
    assert fleet.near_oracle("rule") == 4
    assert fleet.near_oracle("oracle") == 1
    assert fleet.near_oracle("fixed") == 1


def test_a_failing_vehicle_is_reported_and_left_out_of_the_statistics() -> None:
    """A vehicle whose simulation failed carries no shifts: the statistics are the others',
    the JSON names it with its reason and the Markdown says so above the table."""
    from gearsym.validation.studies.control.report import control_markdown

    ok = {"seed": 0, "vehicle": {}, "strategies": {"fixed": [_shift(4.0, 100.0, 0.0)]}}
    failed = {"seed": 1, "vehicle": {}, "failed": "scenario: more than 200 mode switches"}
    fleet = _fleet([ok, failed], ("fixed",), 1)
    (row,) = fleet.per_shift("fixed")
    assert row["jerk_p95"] == 4.0 and row["friction_energy_p95"] == 100.0
    data = fleet.to_dict()
    assert data["vehicles"] == 1 and data["seeds"] == [0]
    assert data["vehicles_failed"] == [{"seed": 1, "reason": failed["failed"]}]
    text = control_markdown(data, "gearsym control --fleet")
    assert "1 more vehicle(s) failed" in text and "seed 1: scenario: more than 200" in text


def test_a_simulation_failure_ends_the_vehicle_not_the_fleet(monkeypatch) -> None:
    """control_vehicle turns the hybrid simulation's GearsymError into a failed vehicle; a
    fleet where every vehicle failed is an error, not an empty table."""
    from gearsym.symbolic.errors import GearsymError
    from gearsym.validation.studies.control import fleet_study, study

    def broken(*_args, **_kwargs):
        raise GearsymError("scenario.toml", "scenario", "hybrid integration failed at t = 1 s")

    class Draw:
        def to_dict(self) -> dict:
            return {"seed": 7}

    class Fleet:
        name = "test"

        def draw(self, seed: int) -> Draw:
            return Draw()

    monkeypatch.setattr(study, "run_vehicle", broken)
    monkeypatch.setattr(study.Vehicle, "from_draw", classmethod(lambda cls, d, draw: None))
    point = OperatingPoint(8.0, 120.0, 30.0)
    context = fleet_study.ControlContext(None, "2-3", point, Fleet(), ("fixed",), 2)
    out = fleet_study.control_vehicle(context, 7)
    assert out["seed"] == 7 and "hybrid integration failed" in out["failed"]
    assert "strategies" not in out
    with pytest.raises(GearsymError, match="every vehicle failed"):
        fleet_study.run_control_fleet(None, "2-3", point, Fleet(), [7, 8], ("fixed",), 2)
