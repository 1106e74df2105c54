"""Geometry of ``gearsym draw``: lever analogy, speed plan, stick diagram, drivetrain.

Every expected value is derived by hand in the test (from the tooth counts and the shift
logic of the description files), never read from the code under test.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import pytest
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.loader import load_description
from gearsym.validation.drawing.geometry import (
    drivetrain_diagram,
    lever_diagram,
    set_positions,
    speed_plan,
    speed_plans,
    stick_diagram,
    to_json,
)

DATA = Path(__file__).parent / "data"
SIMPSON = DATA / "simpson_3speed.toml"

# Table 2.1 of the thesis, transcribed by hand (None: neutral).
TABLE_2_1 = {
    "1": 5.354,
    "2": 3.243,
    "3": 2.252,
    "4": 1.636,
    "5": 1.211,
    "6": 1.000,
    "7": 0.865,
    "8": 0.717,
    "9": 0.601,
    "N": None,
    "R": -4.798,
}
# Shafts a closed brake holds (B08 → 8, B05 → 5, B06 → 6), from the shift logic of Table 2.1.
HELD = {
    "1": {"5", "6"},
    "2": {"6"},
    "3": {"5", "6"},
    "4": {"5", "6"},
    "5": {"5"},
    "6": set(),
    "7": {"5"},
    "8": {"8"},
    "9": {"5", "8"},
    "N": {"5", "6"},
    "R": {"5", "8", "6"},
}


@pytest.fixture(scope="module")
def thesis():
    return load_description()


@pytest.fixture(scope="module")
def simpson():
    return load_description(SIMPSON)


# ----------------------------------------------------------------------------- levers


def test_simple_set_lever_spacing_is_ring_teeth_then_sun_teeth(thesis):
    # Set 1: z_S = 46, z_H = 98 (sun 1, carrier 8, ring 4). Sun at 0, carrier at z_H = 98,
    # ring at z_H + z_S = 144.
    set1 = thesis.planetary_sets[0]
    assert set_positions(set1) == {"1": 0, "8": 98, "4": 144}
    lever = lever_diagram(thesis).levers[0]
    assert [(n.shaft, n.members, n.position) for n in lever.nodes] == [
        ("1", ("S1",), 0),
        ("8", ("C1",), 98),
        ("4", ("R1",), 144),
    ]


def test_node_spacings_equal_the_stationary_ratios(thesis):
    # (carrier − sun)/(ring − carrier) = z_H/z_S = k of (2.22)+(2.23); teeth of the file:
    k = {
        "1": Fraction(98, 46),
        "2": Fraction(100, 44),
        "3": Fraction(83, 37),
        "4": Fraction(86, 34),
    }
    levers = lever_diagram(thesis).levers
    assert [lv.sets for lv in levers] == [("1",), ("2",), ("3",), ("4",)]  # no two share 2
    for lever in levers:
        s, c, r = (n.position for n in lever.nodes)
        assert (c - s) / (r - c) == k[lever.sets[0]]
        # displayed: every lever has the same height, nodes in the same proportion
        ys = [n.y for n in lever.nodes]
        assert ys[0] == 0 and ys[2] == pytest.approx(4.0)
        assert ys[1] / ys[2] == pytest.approx(float(c / r))


def test_simpson_sets_merge_into_one_compound_lever_as_derived_by_hand(simpson):
    # Front: sun 0, carrier (out) 66, ring_f 66+30 = 96 (z_S 30, z_H 66).
    # Rear: sun 0, carrier_r 60·a, out (its ring) 90·a (z_S 30, z_H 60). Sharing sun and out:
    # 90·a = 66 → a = 11/15, carrier_r at 44. One lever sun 0, carrier_r 44, out 66, ring_f 96;
    # the input shaft is on no set: a free node.
    diagram = lever_diagram(simpson)
    assert len(diagram.levers) == 1
    lever = diagram.levers[0]
    assert lever.sets == ("front", "rear")
    assert [(n.shaft, n.position) for n in lever.nodes] == [
        ("sun", 0),
        ("carrier_r", 44),
        ("out", 66),
        ("ring_f", 96),
    ]
    assert dict((n.shaft, n.members) for n in lever.nodes)["out"] == ("C_front", "R_rear")
    assert [n.shaft for n in diagram.free_nodes] == ["in"]
    # Ratios read off the lever by hand: gear 1 holds carrier_r (44) and drives ring_f (96):
    # (96 − 44)/(66 − 44) = 26/11, the file's 2.3636.
    assert Fraction(96 - 44, 66 - 44) == Fraction(26, 11)


def test_elements_join_the_nodes_of_their_shafts_or_ground(thesis):
    diagram = lever_diagram(thesis)
    points = {(n.x, n.y): n.shaft for lv in diagram.levers for n in lv.nodes}
    by_name = {e.name: e for e in diagram.elements}
    assert {points[by_name["K81"].start], points[by_name["K81"].end]} == {"8", "1"}
    assert {points[by_name["K27"].start], points[by_name["K27"].end]} == {"2", "7"}
    assert points[by_name["B05"].start] == "5" and by_name["B05"].end not in points
    # shaft 3 is the sun of sets 3, 4 and the ring of set 2: linked across three levers
    assert sum(1 for link in diagram.shaft_links if link[0] == "3") == 2


# ----------------------------------------------------------------------------- speed plan


@pytest.mark.parametrize("gear", list(TABLE_2_1))
def test_speed_plan_reproduces_table_2_1_and_brakes_hold_at_zero(thesis, gear):
    plan = speed_plan(thesis, gear)
    assert plan.speeds["1"] == 1  # ω_in = 1 is the plan's unit
    if TABLE_2_1[gear] is None:
        assert plan.ratio is None and plan.speeds["2"] == 0  # neutral: the vehicle stands
    else:
        assert round(1 / float(plan.speeds["2"]), 3) == TABLE_2_1[gear]
        assert round(float(plan.ratio), 3) == TABLE_2_1[gear]
    assert set(plan.held) == HELD[gear]
    for shaft in HELD[gear]:
        assert plan.speeds[shaft] == 0


def test_gear_2_speeds_by_hand(thesis):
    # K81, K38: ω1 = ω8 = ω3 = 1; set 1 turns as a block, so ω4 = 1; set 2 then too: ω5 = 1.
    # B06 holds ring 6 of set 3 (sun 3 = 1): ω2 = z_S/(z_S + z_H) = 37/120.
    plan = speed_plan(thesis, "2")
    assert plan.speeds == {
        "1": 1,
        "2": Fraction(37, 120),
        "3": 1,
        "4": 1,
        "5": 1,
        "6": 0,
        "7": 1,
        "8": 1,
    }
    assert plan.ratio == Fraction(120, 37)


def test_every_lever_is_straight_in_every_gear(thesis, simpson):
    # The lever property: node speeds are affine in the node positions (Willis).
    for d in (thesis, simpson):
        diagram = lever_diagram(d)
        for plan in speed_plans(d):
            for lever in diagram.levers:
                pts = [(n.position, plan.speeds[n.shaft]) for n in lever.nodes]
                (p0, w0), (p1, w1) = pts[0], pts[-1]
                for p, w in pts[1:-1]:
                    assert w == w0 + (w1 - w0) * (p - p0) / (p1 - p0), (d.name, plan.gear)


def test_simpson_speed_plan_by_hand(simpson):
    # Gear 1 on the lever sun 0, carrier_r 44, out 66, ring_f 96: carrier_r = 0, ring_f = 1,
    # slope 1/52: out = 22/52 = 11/26, sun = −44/52 = −11/13. Reverse: sun = 1, carrier_r = 0,
    # slope −1/44: out = −22/44 = −1/2, ring_f = −52/44 = −13/11.
    first = speed_plan(simpson, "1")
    assert first.speeds == {
        "in": 1,
        "ring_f": 1,
        "sun": Fraction(-11, 13),
        "out": Fraction(11, 26),
        "carrier_r": 0,
    }
    reverse = speed_plan(simpson, "R")
    assert reverse.speeds["out"] == Fraction(-1, 2) and reverse.ratio == -2
    assert reverse.speeds["ring_f"] == Fraction(-13, 11)
    # Neutral (B2 only): the input turns alone, everything behind the open clutches stands.
    neutral = speed_plan(simpson, "N")
    assert neutral.speeds == {"in": 1, "ring_f": 0, "sun": 0, "out": 0, "carrier_r": 0}


def test_unknown_gear_names_the_key(thesis):
    with pytest.raises(GearsymError) as err:
        speed_plan(thesis, "10")
    assert err.value.key == "--gear" and "'10'" in err.value.reason and "R" in err.value.reason


# ----------------------------------------------------------------------------- stick, drivetrain


def test_stick_diagram_joins_every_member_to_its_shaft_line(thesis, simpson):
    for d in (thesis, simpson):
        stick = stick_diagram(d)
        assert len(stick.planets) == len(d.planetary_sets)
        levels = stick.shaft_levels
        assert len(set(levels.values())) == len(d.shaft_names)  # one level per shaft
        junctions = set(stick.junctions)
        for ps in d.planetary_sets:
            for role, letter in (("sun", "S"), ("carrier", "C"), ("ring", "R")):
                shaft = getattr(ps, role)
                owner = f"{letter}{ps.name}"
                ends = [seg.end for seg in stick.segments if seg.owner == owner]
                stem = [e for e in ends if e[1] == levels[shaft]]
                assert len(stem) == 1 and stem[0] in junctions, (d.name, owner)
        assert len(stick.grounds) == sum(1 for e in d.shift_elements if e.kind == "brake")
        assert stick.input_arrow[2] == levels[d.input_shaft]
        assert stick.output_arrow[2] == levels[d.output_shaft]


def test_drivetrain_carries_the_model_symbols_and_values(thesis):
    dt = drivetrain_diagram(thesis)
    names = [b.name for b in dt.blocks]
    assert names == [
        "gearbox",
        "propeller shaft",
        "differential",
        "side shafts",
        "wheel",
        "vehicle",
    ]
    assert dt.values["i_D"] == "2.469" and dt.values["k_ss"] == "10000 N*m/rad"
    blocks = {b.name: b for b in dt.blocks}
    assert {"k_ss", "d_ss", "φ"} <= set(blocks["side shafts"].symbols)


def test_json_holds_what_the_speed_plan_shows(thesis):
    plans = speed_plans(thesis)
    data = to_json("speeds", thesis, lever_diagram(thesis), plans)
    gears = {g["gear"]: g for g in data["gears"]}
    assert round(1 / gears["3"]["speeds"]["2"], 3) == 2.252
    assert [n["position"] for n in data["levers"][0]["nodes"]] == [0.0, 98.0, 144.0]


@pytest.mark.parametrize(
    "kind", ["simple", "double_pinion", "ravigneaux", "ravigneaux_two_rings", "stepped_planet"]
)
def test_stick_diagram_of_each_set_kind(kind):
    """The README sketches (docs/set_kinds/): one box per pinion body (a stepped planet's two
    steps are two boxes of one body), and every member of the kind, the second sun or second
    ring included, has one stem ending on its own shaft line at a junction dot."""
    sketch = Path(__file__).parents[1] / "docs" / "set_kinds" / f"{kind}.toml"
    d = load_description(sketch)
    (ps,) = d.planetary_sets
    stick = stick_diagram(d)
    boxes = {"simple": 1, "double_pinion": 2, "ravigneaux": 2, "ravigneaux_two_rings": 2}
    assert len(stick.planets) == boxes.get(kind, 2)
    owners = {"sun": "S", "carrier": "C", "ring": "R", "sun2": "S2", "ring2": "R2"}
    for role in owners:
        shaft = getattr(ps, role)
        if shaft is None:
            continue
        ends = [seg.end for seg in stick.segments if seg.owner == f"{owners[role]}{ps.name}"]
        stem = [e for e in ends if e[1] == stick.shaft_levels[shaft]]
        assert len(stem) == 1 and stem[0] in set(stick.junctions), (kind, role)
    assert len({stick.shaft_levels[m] for m in ps.members}) == len(ps.members)


def test_lever_of_a_ravigneaux_set_with_two_rings():
    """docs/set_kinds/ravigneaux_two_rings.toml (z_S 30, z_H 66, z_H2 78), by hand: sun 0,
    carrier z_H = 66, ring z_H + z_S = 96; the second ring at 66·(k2 − 1)/k2 with
    k2 = 78/30, i.e. 528/13, between sun and carrier. Check by speeds linear along the lever:
    carrier held (0 at 66), sun 1 at 0 → ω_H2 = (66 − 528/13)/66 = 5/13, so
    ω_S/ω_H2 = 13/5 = +78/30 (the short pair's positive stationary ratio)."""
    d = load_description(Path(__file__).parents[1] / "docs/set_kinds/ravigneaux_two_rings.toml")
    positions = set_positions(d.planetary_sets[0])
    assert positions == {"S": 0, "T": 66, "H": 96, "H2": Fraction(528, 13)}
    assert (66 - positions["H2"]) / 66 == Fraction(5, 13)
    plan = speed_plan(d, "1")
    assert plan.ratio == pytest.approx(-66 / 30)
