"""Dog elements in the hybrid shift model and its simulation (issue 30 part C).

Box ``tests/data/dog_9speed.toml`` (B06 a dog brake, K27 a dog clutch), scenarios
``tests/data/dog_5_4.toml`` (power-on downshift, dog on-coming, its command added here) and
``tests/data/dog_4_5.toml`` (power-on upshift, dog off-going). Expected values from physics:

* a dog engaging at slip Δω is a perfectly plastic impact on the one relative motion it
  stops. Its impulse Λ changes the slip by g Λ, g = ∂(dΔω/dt)/∂T < 0 the inverse effective
  inertia the element sees (``slip_acceleration_gain``), so Λ = −Δω/g and the kinetic energy
  lost is ½ Δω²/(−g): zero at synchronism, ½ (2 rad/s)²/(−g) two rad/s away;
* the energy audit W_in = ΔE + W_friction + W_damper + W_road closes, with the impact's loss
  counted in W_friction;
* the ratios after the shifts are the published ones (Table 2.1: 1.636 in 4th, 1.211 in 5th);
* a dog commanded off while loaded holds; it opens when |T| has fallen to its release_torque.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.hybrid import (
    BREAK_AWAY,
    DISENGAGEMENT,
    ENGAGEMENT,
    LOCKED,
    OPEN,
    hybrid_shift,
    slip_acceleration_gain,
)
from gearsym.symbolic.loader import load_description
from gearsym.validation.sim.hybrid_energy import energy_audit
from gearsym.validation.sim.hybrid_simulation import HybridSimulator
from gearsym.validation.sim.scenario import load_scenario
from scipy.optimize import brentq

DATA = Path(__file__).parent / "data"
BOX = DATA / "dog_9speed.toml"
DOWN = DATA / "dog_5_4.toml"
UP = DATA / "dog_4_5.toml"
CLUTCH = DATA / "dog_3_4.toml"


@pytest.fixture(scope="module")
def box():  # type: ignore[no-untyped-def]
    return load_description(BOX)


@pytest.fixture(scope="module")
def free_flare(box):  # type: ignore[no-untyped-def]
    """The 5-4 without a dog command: the simulator and its run (K81 released, the input
    flares through gear 4's speed)."""
    simulator = HybridSimulator(box, load_scenario(box, DOWN))
    return simulator, simulator.run()


def _slip_time(simulator: HybridSimulator, result, value: float, dog: str = "B06") -> float:  # type: ignore[no-untyped-def]
    """When the dog's slip passes ``value`` in the last piece (both elements open)."""
    piece = result.pieces[-1]
    compiled = simulator.modes[piece.mode]
    k = simulator.hybrid.elements.index(dog)
    p = simulator.parameter_vector(result.values)

    def slip(t: float) -> float:
        x = piece.state(np.array([t]))[0, : compiled.n]
        return compiled.value(compiled.slips, x, simulator.inputs(t), p)[k] - value

    return brentq(slip, piece.t_start, piece.t_end, xtol=1e-15, rtol=1e-15)


def _commanded(  # type: ignore[no-untyped-def]
    box, tmp_path: Path, t_command: float, scenario: Path = DOWN, dog: str = "B06"
) -> HybridSimulator:
    """The scenario (default the 5-4) with the dog commanded engaged from ``t_command`` on."""
    table = f'[pressure.{dog}]\nunit = "Pa"\ntime = [0.0, {t_command!r}, 1.2]\n'
    text = scenario.read_text(encoding="utf-8") + "\n" + table + "value = [0.0, 0.0, 1.0]\n"
    path = tmp_path / "dog_5_4_commanded.toml"
    path.write_text(text, encoding="utf-8")
    return HybridSimulator(box, load_scenario(box, path))


def test_dog_modes_and_guards(box) -> None:  # type: ignore[no-untyped-def]
    """A dog is locked or open (2 × 4 statuses less the tie-up: 7 modes), has no μ and no
    F_N, never breaks away; engagement is commanded (condition: the window, no otherwise),
    disengagement is |T_req| falling through release_torque."""
    for shift, dog in (("5-4", "B06"), ("4-5", "B06"), ("3-4", "K27")):
        hybrid = hybrid_shift(box, shift)
        assert len(hybrid.modes) == 7
        assert {m.status[dog] for m in hybrid.modes.values()} == {(LOCKED, 0), (OPEN, 0)}
        assert [v.name for v in hybrid.inputs] == ["T_In", "F_N81"]
        assert "mu_81" in [v.name for v in hybrid.parameters]
        assert hybrid.friction_elements == ("K81",) and hybrid.dog == {dog: (3.0, 5.0)}
        kinds = {g.kind for g in hybrid.guards if g.element == dog}
        assert kinds == {ENGAGEMENT, DISENGAGEMENT} and BREAK_AWAY not in kinds
        for guard in hybrid.guards:
            if guard.element == dog and guard.kind == ENGAGEMENT:
                assert guard.otherwise is None and guard.condition is not None
                assert hybrid.modes[guard.target].status[dog] == (LOCKED, 0)


def test_engagement_at_synchronism_loses_nothing(box, free_flare, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    simulator, flare = free_flare
    t_sync = _slip_time(simulator, flare, 0.0)
    assert 0.35 < t_sync < 1.2
    commanded = _commanded(box, tmp_path, t_sync)
    result = commanded.run()
    engagement = [e for e in result.events if e.element == "B06"]
    assert len(engagement) == 1 and engagement[0].kind == ENGAGEMENT
    assert engagement[0].t == pytest.approx(t_sync, abs=1e-12)
    assert engagement[0].target == commanded.hybrid.to_mode
    # ½ Δω²/(−g) with Δω = 0 (to the root finder's time): no impulse loss
    assert engagement[0].energy_loss < 1e-9
    audit = energy_audit(commanded, result)
    assert audit.relative_residual < 1e-8
    after = result.t > t_sync + 1e-3
    assert np.max(np.abs(result.signals["slip_B06"][after])) < 1e-9
    ratio = result.signals["ratio"][after]
    assert np.allclose(ratio, 1.636, atol=5e-4)  # 4th gear, Table 2.1
    # the dog carries gear 4's reaction torque after the engagement
    assert np.all(np.abs(result.signals["T_B06"][after]) > 5.0)


def test_engagement_inside_the_window_is_a_plastic_impact(box, free_flare, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    simulator, flare = free_flare
    slip = -2.0  # rad/s, inside engage_slip = 3 rad/s
    t_command = _slip_time(simulator, flare, slip)
    commanded = _commanded(box, tmp_path, t_command)
    result = commanded.run()
    (event,) = [e for e in result.events if e.element == "B06"]
    gain = float(slip_acceleration_gain(box, "5-4", "B06"))
    assert gain < 0
    expected = 0.5 * slip**2 / -gain
    assert event.energy_loss == pytest.approx(expected, rel=1e-6)
    audit = energy_audit(commanded, result)
    assert audit.relative_residual < 1e-8
    # without the impact's loss the audit would miss exactly that energy
    assert abs(audit.residual + event.energy_loss) > 0.99 * event.energy_loss


def test_engagement_away_from_synchronism_ends_with_a_stated_failure(box, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """Commanded at 0.4 s, the input has only begun to flare: |slip| ≫ 3 rad/s."""
    commanded = _commanded(box, tmp_path, 0.4)
    with pytest.raises(GearsymError) as info:
        commanded.run()
    message = str(info.value)
    assert "\n" not in message
    assert "dog B06 commanded engaged at t = 0.4 s at slip" in message
    assert "outside its engage_slip 3 rad/s" in message and "simulation ended" in message
    assert "pressure.B06" in message


def test_engagement_while_the_other_element_is_locked_is_a_tie_up(box, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    commanded = _commanded(box, tmp_path, 0.1)  # K81 still at line pressure, locked
    with pytest.raises(GearsymError, match="while K81 is locked: a tie-up"):
        commanded.run()


def test_loaded_dog_holds_until_unloaded(box) -> None:  # type: ignore[no-untyped-def]
    """4-5: the command falls at 0.2 s while B06 carries gear 4's reaction; it stays locked
    until K81 has taken the load, opens at |T_B06| = release_torque, and K81 finishes the
    shift; no impulse anywhere, the audit closes, 5th gear's ratio at the end."""
    simulator = HybridSimulator(box, load_scenario(box, UP))
    result = simulator.run()
    kinds = [(e.kind, e.element) for e in result.events]
    assert kinds == [("engagement", "K81"), ("disengagement", "B06"), ("lock-up", "K81")]
    t_open = result.events[1].t
    assert t_open > 0.3  # not at the command (0.2 s): loaded until K81 takes over
    held = (result.t > 0.2001) & (result.t < 0.3)
    assert np.all(np.abs(result.signals["T_B06"][held]) > 5.0)
    assert np.max(np.abs(result.signals["slip_B06"][result.t < t_open])) < 1e-9
    # at the event its reaction is the release threshold
    piece = next(p for p in result.pieces if p.t_end == t_open)
    compiled = simulator.modes[piece.mode]
    x = piece.state(np.array([t_open]))[0, : compiled.n]
    p = simulator.parameter_vector(result.values)
    torque = compiled.value(compiled.torques, x, simulator.inputs(t_open), p)[0]
    assert abs(torque) == pytest.approx(5.0, abs=1e-6)
    assert all(e.energy_loss == 0.0 for e in result.events)
    assert energy_audit(simulator, result).relative_residual < 1e-8
    assert result.signals["ratio"][-1] == pytest.approx(1.211, abs=5e-4)
    assert result.modes[-1] == simulator.hybrid.to_mode


def test_dog_clutch_synchronised_by_the_input_torque(box, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """3-4: the dog clutch K27 (between shafts 2 and 7) comes on. K81 is released and the
    e-machine's −8 N·m pulls the input down to gear 4's speed; commanded at the instant its
    slip ω_2 − ω_7 crosses zero, the dog engages without loss and holds 4th (1.636)."""
    free = HybridSimulator(box, load_scenario(box, CLUTCH))
    flare = free.run()
    assert [e.kind for e in flare.events] == ["break-away", "opening"]
    t_sync = _slip_time(free, flare, 0.0, "K27")
    commanded = _commanded(box, tmp_path, t_sync, CLUTCH, "K27")
    result = commanded.run()
    (event,) = [e for e in result.events if e.element == "K27"]
    assert event.kind == ENGAGEMENT and event.target == commanded.hybrid.to_mode
    assert event.energy_loss < 1e-9
    assert energy_audit(commanded, result).relative_residual < 1e-8
    after = result.t > t_sync + 1e-3
    assert np.max(np.abs(result.signals["slip_K27"][after])) < 1e-9
    assert np.allclose(result.signals["ratio"][after], 1.636, atol=5e-4)
    # engaged, it carries the load: the e-machine's torque now brakes the vehicle through it
    assert np.all(np.abs(result.signals["T_K27"][after]) > 1.0)
