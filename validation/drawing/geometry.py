"""Geometry of the pictures gearbox engineers draw: lever analogy, speed plan, stick diagram,
drivetrain (``gearsym draw``).

Pure functions from a :class:`~gearsym.symbolic.description.GearboxDescription` to frozen
dataclasses of coordinates and values; nothing here imports matplotlib
(:mod:`gearsym.validation.drawing.render` draws them). Layouts are computed from the
description, never drawn by hand per gearbox.

**Lever analogy** (Benford & Leising, SAE 810102). A simple planetary set obeys (the sum of
the Willis constraints (2.22), (2.23), see :mod:`gearsym.symbolic.ratios`)

    z_S ω_S + z_H ω_H − (z_S + z_H) ω_T = 0,

so with the sun at position 0, the carrier at z_H and the ring at z_H + z_S on a straight
lever, every node's speed is the same affine function of its position:
ω_T = (z_S ω_S + z_H ω_H)/(z_S + z_H). Sun–carrier spacing ∝ ring teeth, carrier–ring
spacing ∝ sun teeth. Two sets joined in two shafts move as one rigid lever (both levers
share two points of the same affine speed field), so such sets are merged into one compound
lever, scaled to the first set's teeth; sets joined in one shaft stay separate levers linked
by that shaft.

**Speed plan**: the node speeds of a gear are the gear's motion from
:func:`gearsym.symbolic.ratios.gear_motions` (the kinematics of Table 2.1, not re-derived
here), scaled to ω_in = 1; the ratio printed on the plan is 1 / (speed of the output node).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import sympy as sp
from gearsym.symbolic.description import GearboxDescription, PlanetarySet
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.set_kinds import HOUSING
from gearsym.symbolic.set_relations import relations

__all__ = [
    "DRAW_KINDS",
    "DrivetrainDiagram",
    "ElementLink",
    "Lever",
    "LeverDiagram",
    "LeverNode",
    "SpeedPlan",
    "StickDiagram",
    "drivetrain_diagram",
    "lever_diagram",
    "speed_plan",
    "speed_plans",
    "stick_diagram",
    "to_json",
]

#: What ``gearsym draw --what`` accepts.
DRAW_KINDS = ("stick", "lever", "speeds", "drivetrain")

#: Roles of a set's members, in lever order from the bottom (sun) to the top (ring).
ROLES = ("sun", "carrier", "ring")
_ROLE_LETTER = {"sun": "S", "carrier": "C", "ring": "R"}

#: Display length of every lever (levers are scaled to it; positions keep tooth units).
LEVER_HEIGHT = 4.0
#: Horizontal room of a lever column in the lever diagram without speeds.
LEVER_COLUMN = 3.0


# ----------------------------------------------------------------------------- lever analogy


@dataclass(frozen=True)
class LeverNode:
    """One node of a lever: a shaft, the set members it is (e.g. ``("S1", "R3")``), its
    position along the lever in tooth units of the lever's first set, and its display point."""

    shaft: str
    members: tuple[str, ...]
    position: Fraction
    x: float
    y: float


@dataclass(frozen=True)
class Lever:
    """One simple set, or several sets joined in two shafts (a compound lever)."""

    name: str
    sets: tuple[str, ...]
    nodes: tuple[LeverNode, ...]  # bottom to top
    x: float

    @property
    def length(self) -> Fraction:
        return self.nodes[-1].position - self.nodes[0].position


@dataclass(frozen=True)
class ElementLink:
    """A shift element drawn between two nodes (clutch) or from a node to ground (brake)."""

    name: str
    kind: str
    shafts: tuple[str, ...]
    start: tuple[float, float]
    end: tuple[float, float]


@dataclass(frozen=True)
class LeverDiagram:
    """Levers, free shaft nodes (shafts on no set: joined only by elements), the links of
    shafts that sit on several levers, and the shift elements."""

    gearbox: str
    title: str
    levers: tuple[Lever, ...]
    free_nodes: tuple[LeverNode, ...]
    shaft_links: tuple[tuple[str, tuple[float, float], tuple[float, float]], ...]
    elements: tuple[ElementLink, ...]
    input_shaft: str
    output_shaft: str

    def nodes_of(self, shaft: str) -> list[LeverNode]:
        """Every node that is ``shaft`` (on any lever, or the free node)."""
        found = [n for lever in self.levers for n in lever.nodes if n.shaft == shaft]
        return found + [n for n in self.free_nodes if n.shaft == shaft]

    def node(self, shaft: str) -> LeverNode:
        """The node an element or the input/output arrow attaches to: the first one."""
        return self.nodes_of(shaft)[0]


def set_positions(ps: PlanetarySet) -> dict[str, Fraction]:
    """Sun 0, carrier z_H, ring z_H + z_S: the lever of one simple set (Benford & Leising;
    the spacing follows from the Willis constraints (2.22)+(2.23), module docstring).

    Any kind from its shaft relations ω_S − i0 ω_H − (1 − i0) ω_C = 0: sun 0, carrier k,
    ring k + 1 for i0 = −k and k − 1 for i0 = +k (the ring of a double pinion sits between
    sun and carrier); a Ravigneaux set's second sun lands at k + k2, the second ring of a
    Ravigneaux set with two rings at k (k2 − 1)/k2.
    Scaled by z_S so that a simple set keeps its tooth-unit positions.
    """
    rels = relations(ps)
    first = rels[0]
    scale = Fraction(ps.z_sun) if ps.given_k is None else Fraction(1)  # cosmetic
    carrier = first.k * scale
    ring = (first.k - first.sign) * scale
    positions = {first.sun: Fraction(0), first.carrier: carrier, first.ring: ring}
    for rel in rels[1:]:
        if rel.ring in positions:
            # Same carrier and ring (Ravigneaux): the second sun extrapolates the lever.
            positions[rel.sun] = carrier + rel.k * (ring - carrier) / rel.sign
        else:
            # Same sun and carrier (Ravigneaux with two rings): in the pair's own units the
            # sun is at 0, the carrier at k2 and the ring at k2 − sign.
            sun = positions[rel.sun]
            positions[rel.ring] = sun + (positions[rel.carrier] - sun) * (rel.k - rel.sign) / rel.k
    return positions


def member_name(role: str, set_name: str) -> str:
    """``S1``, ``C4`` for the thesis' numbered sets; ``S_front`` for a named set."""
    letter = _ROLE_LETTER[role]
    return f"{letter}{set_name}" if set_name.isdigit() else f"{letter}_{set_name}"


def _members(ps: PlanetarySet) -> dict[str, str]:
    members = {getattr(ps, role): member_name(role, ps.name) for role in ROLES}
    if ps.sun2 is not None:
        members[ps.sun2] = member_name("sun", f"{ps.name}_short")
    if ps.ring2 is not None:
        members[ps.ring2] = member_name("ring", f"{ps.name}_short")
    return members


def lever_groups(d: GearboxDescription) -> list[tuple[list[PlanetarySet], dict[str, Fraction]]]:
    """Sets merged into compound levers, with each shaft's position on its lever.

    A set joins a group when it shares at least two shafts with it: its scale and offset
    follow from those two positions. If it shares three and they disagree (or only one), it
    starts its own group. Groups keep the file order of their first set.
    """
    groups: list[tuple[list[PlanetarySet], dict[str, Fraction]]] = []
    for ps in d.planetary_sets:
        own = set_positions(ps)
        for members, positions in groups:
            shared = [s for s in own if s in positions]
            if len(shared) < 2:
                continue
            a, b = shared[0], shared[1]
            scale = (positions[b] - positions[a]) / (own[b] - own[a])
            mapped = {s: positions[a] + (p - own[a]) * scale for s, p in own.items()}
            if any(mapped[s] != positions[s] for s in shared):
                continue  # three shared shafts that a rigid lever cannot hold
            members.append(ps)
            positions.update(mapped)
            break
        else:
            groups.append(([ps], dict(own)))
    # Keep merging groups that became joined in two shafts through a later set.
    merged = True
    while merged:
        merged = False
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                pi, pj = groups[i][1], groups[j][1]
                shared = [s for s in pj if s in pi]
                if len(shared) < 2:
                    continue
                a, b = shared[0], shared[1]
                scale = (pi[b] - pi[a]) / (pj[b] - pj[a])
                mapped = {s: pi[a] + (p - pj[a]) * scale for s, p in pj.items()}
                if any(mapped[s] != pi[s] for s in shared):
                    continue
                groups[i][0].extend(groups[j][0])
                pi.update(mapped)
                del groups[j]
                merged = True
                break
            if merged:
                break
    normalised = []
    for members, positions in groups:
        # Sun side at the bottom, position 0 there (a merged set may have flipped the lever).
        low = min(positions.values())
        high = max(positions.values())
        first = members[0]
        flip = positions[first.ring] < positions[first.sun]
        shifted = {s: (high - p) if flip else (p - low) for s, p in positions.items()}
        normalised.append((members, shifted))
    return normalised


def lever_diagram(
    d: GearboxDescription, columns: dict[str, tuple[float, float]] | None = None
) -> LeverDiagram:
    """The lever analogy of the description (Benford & Leising; kinematics of (2.22)–(2.25)).

    Levers stand side by side, each scaled to :data:`LEVER_HEIGHT`; ``columns`` maps a lever
    name to the (left, right) room its speeds need in the speed plan (default: a fixed
    column). Shafts on no set (an input joined only by clutches, say) are free nodes in a
    column left of the levers.
    """
    groups = lever_groups(d)
    on_lever = {s for _, positions in groups for s in positions}
    free = [s.name for s in d.shafts if s.name not in on_lever]
    levers: list[Lever] = []
    x = 0.0
    free_nodes: list[LeverNode] = []
    if free:
        left, right = (columns or {}).get("free", (LEVER_COLUMN / 2, LEVER_COLUMN / 2))
        x += left
        step = LEVER_HEIGHT / max(len(free) - 1, 1)
        for i, shaft in enumerate(free):
            y = LEVER_HEIGHT / 2 if len(free) == 1 else i * step
            free_nodes.append(LeverNode(shaft, (), Fraction(0), x, y))
        x += right
    for members, positions in groups:
        name = "+".join(ps.name for ps in members)
        left, right = (columns or {}).get(name, (LEVER_COLUMN / 2, LEVER_COLUMN / 2))
        x += left
        length = max(positions.values())
        roles: dict[str, list[str]] = {}
        for ps in members:
            for shaft, member in _members(ps).items():
                roles.setdefault(shaft, []).append(member)
        order = sorted(positions, key=lambda s: (positions[s], s))
        nodes = tuple(
            LeverNode(
                shaft,
                tuple(roles[shaft]),
                positions[shaft],
                x,
                float(positions[shaft] / length) * LEVER_HEIGHT,
            )
            for shaft in order
        )
        levers.append(Lever(name, tuple(ps.name for ps in members), nodes, x))
        x += right
    diagram = LeverDiagram(
        gearbox=d.name,
        title=d.title,
        levers=tuple(levers),
        free_nodes=tuple(free_nodes),
        shaft_links=(),
        elements=(),
        input_shaft=d.input_shaft,
        output_shaft=d.output_shaft,
    )
    links = []
    for shaft in d.shaft_names:
        nodes = diagram.nodes_of(shaft)
        for a, b in zip(nodes, nodes[1:], strict=False):
            links.append((shaft, (a.x, a.y), (b.x, b.y)))
    elements = []
    for e in d.shift_elements:
        if e.a is not None:  # a clutch or a one-way clutch between two shafts
            a, b = _closest(diagram.nodes_of(e.a), diagram.nodes_of(e.b))
            elements.append(ElementLink(e.name, e.kind, e.shafts, (a.x, a.y), (b.x, b.y)))
        else:
            node = diagram.node(e.b)
            # The housing just left of the node it holds (node labels sit above the line).
            ground = (node.x - 0.7, node.y)
            elements.append(ElementLink(e.name, e.kind, e.shafts, (node.x, node.y), ground))
    return LeverDiagram(
        gearbox=d.name,
        title=d.title,
        levers=tuple(levers),
        free_nodes=tuple(free_nodes),
        shaft_links=tuple(links),
        elements=tuple(elements),
        input_shaft=d.input_shaft,
        output_shaft=d.output_shaft,
    )


def _closest(a: list[LeverNode], b: list[LeverNode]) -> tuple[LeverNode, LeverNode]:
    """The pair of nodes of two shafts nearest each other (shortest clutch line)."""
    return min(
        ((p, q) for p in a for q in b),
        key=lambda pq: abs(pq[0].x - pq[1].x) + abs(pq[0].y - pq[1].y),
    )


# ----------------------------------------------------------------------------- speed plan


@dataclass(frozen=True)
class SpeedPlan:
    """Node speeds of one gear, ω_in = 1 (the input node's speed is the unit).

    ``speeds[shaft]`` is exact (a Fraction) or ``None`` where the gear leaves the shaft free
    (a neutral gear's unloaded shafts). In a neutral gear the vehicle stands: ω_out = 0.
    ``ratio`` is what the plan shows, speed(input)/speed(output); ``expected`` the table's.
    """

    gear: str
    closed: tuple[str, ...]
    neutral: bool
    speeds: dict[str, Fraction | None]
    ratio: Fraction | None
    expected: float | None
    held: tuple[str, ...]  # shafts a closed brake holds at zero

    def ratio_text(self, decimals: int) -> str:
        if self.ratio is None:
            return "neutral"
        return f"{float(self.ratio):.{decimals}f}"


def _fraction(value: sp.Expr) -> Fraction:
    rational = sp.Rational(value)
    return Fraction(int(rational.p), int(rational.q))


def speed_plan(d: GearboxDescription, gear: str) -> SpeedPlan:
    """The speed plan of ``gear``: every shaft's speed along the gear's one motion
    (:func:`gearsym.symbolic.ratios.gear_motions`, Table 2.1), scaled to ω_in = 1."""
    from gearsym.symbolic.ratios import gear_motions, stationary_ratios

    names = [g.name for g in d.gears]
    if gear not in names:
        raise GearsymError(
            d.file, "--gear", f"unknown gear {gear!r} (the description has {', '.join(names)})"
        )
    g = d.gear(gear)
    motions = gear_motions(d, g, dict(stationary_ratios(d)))
    shafts = d.shaft_names
    i_in, i_out = shafts.index(d.input_shaft), shafts.index(d.output_shaft)
    coefficients = sp.symbols(f"c0:{len(motions)}")
    combined = sp.zeros(len(shafts), 1)
    for c, m in zip(coefficients, motions, strict=True):
        combined += c * m
    # Drive gear: ω_in = 1. Neutral: also ω_out = 0 (engine turning, vehicle standing).
    equations = [combined[i_in] - 1] + ([combined[i_out]] if g.neutral else [])
    solution = sp.solve(equations, coefficients, dict=True)
    if not solution:
        raise GearsymError(
            d.file, f'gear[name="{gear}"]', "the input cannot turn in this gear (it is held)"
        )
    chosen = solution[0]
    speeds: dict[str, Fraction | None] = {}
    for i, shaft in enumerate(shafts):
        value = sp.expand(combined[i].subs(chosen))
        speeds[shaft] = _fraction(value) if value.is_number else None
    if _uses_housing(d):
        speeds[HOUSING] = Fraction(0)  # a member fixed to the housing: a held node
    out = speeds[d.output_shaft]
    ratio = None if g.neutral or not out else speeds[d.input_shaft] / out
    held = tuple(d.element(e).b for e in g.closed if d.element(e).a is None)
    return SpeedPlan(g.name, g.closed, g.neutral, speeds, ratio, g.ratio, held)


def _uses_housing(d: GearboxDescription) -> bool:
    return any(HOUSING in ps.members for ps in d.planetary_sets)


def speed_plans(d: GearboxDescription) -> list[SpeedPlan]:
    """The speed plan of every gear, in the table's order."""
    return [speed_plan(d, g.name) for g in d.gears]


def speed_columns(
    d: GearboxDescription, plans: list[SpeedPlan], scale: float
) -> dict[str, tuple[float, float]]:
    """Room (left, right of the lever) each lever column needs for the speeds of ``plans``
    at ``scale`` display units per unit speed, so that no two columns' arrows overlap."""
    columns: dict[str, tuple[float, float]] = {}
    margin = 0.9  # node labels and speed values
    groups = lever_groups(d)
    on_lever = {s for _, positions in groups for s in positions}
    keys: list[tuple[str, list[str]]] = [
        ("+".join(ps.name for ps in members), list(positions)) for members, positions in groups
    ]
    free = [s.name for s in d.shafts if s.name not in on_lever]
    if free:
        keys.insert(0, ("free", free))
    for key, shafts in keys:
        values = [float(v) for p in plans for s in shafts if (v := p.speeds[s]) is not None]
        low = min([0.0, *values]) * scale
        high = max([0.0, *values]) * scale
        columns[key] = (margin - low, margin + high)
    return columns


# ----------------------------------------------------------------------------- stick diagram


@dataclass(frozen=True)
class Segment:
    """A line of the stick diagram, tagged with what it belongs to (for tests and JSON)."""

    owner: str
    start: tuple[float, float]
    end: tuple[float, float]


@dataclass(frozen=True)
class Label:
    text: str
    x: float
    y: float
    align: str = "center"


@dataclass(frozen=True)
class StickDiagram:
    """Half-section schematic (Fig. 2.1 style): sets above, one horizontal line per shaft
    below them, members dropping to their shaft, clutches between shaft lines, brakes to
    the housing, input and output arrows.

    The description gives topology, not the axial order or the concentric nesting of the
    shafts, so each shaft gets its own level (file order) instead of a radius.
    """

    gearbox: str
    title: str
    shaft_levels: dict[str, float]
    shaft_spans: dict[str, tuple[float, float]]
    segments: tuple[Segment, ...]
    planets: tuple[tuple[str, float, float, float, float], ...]  # set, x0, y0, x1, y1
    plates: tuple[Segment, ...]  # friction plates of clutches and brakes
    grounds: tuple[tuple[str, float, float], ...]  # brake, x, y of the housing hatch
    junctions: tuple[tuple[float, float], ...]
    labels: tuple[Label, ...]
    input_arrow: tuple[float, float, float]  # x_start, x_end, y
    output_arrow: tuple[float, float, float]
    #: the interlocking teeth of dog elements (form-locking: a claw coupling's jaws between
    #: its two plates, each half's teeth reaching past the other's; friction elements have none)
    teeth: tuple[Segment, ...] = ()


def _dog_teeth(name: str, x: float, ym: float) -> list[Segment]:
    """A dog element's symbol between its two plates at ym ± 0.1: three teeth rising from the
    lower jaw and two hanging from the upper one, interleaved and overlapping (engaged)."""
    up = [Segment(name, (x + dx, ym - 0.1), (x + dx, ym + 0.04)) for dx in (-0.2, 0.0, 0.2)]
    down = [Segment(name, (x + dx, ym + 0.1), (x + dx, ym - 0.04)) for dx in (-0.1, 0.1)]
    return up + down


#: Half-section heights of the stick symbols (display units).
SUN_Y, PLANET_Y0, PLANET_Y1, RING_Y = 1.0, 1.3, 2.7, 3.0
SHAFT_STEP = 0.7
SET_PITCH = 3.2


def stick_diagram(d: GearboxDescription) -> StickDiagram:
    """Stick diagram of any description (thesis Fig. 2.1 shows the built-in gearbox)."""
    for ps in d.planetary_sets:
        ps.require_teeth(d.file, "drawing the stick diagram (it labels the teeth)")
    # A member fixed to the housing gets its own line, drawn like a shaft (labelled housing).
    lines = d.shaft_names + ((HOUSING,) if _uses_housing(d) else ())
    levels = {s: -SHAFT_STEP * (i + 1) for i, s in enumerate(lines)}
    attach: dict[str, list[float]] = {s: [] for s in lines}
    segments: list[Segment] = []
    planets = []
    labels: list[Label] = []
    junctions: list[tuple[float, float]] = []
    x0 = 1.5
    for j, ps in enumerate(d.planetary_sets):
        xc = x0 + SET_PITCH * j
        set_segments, set_planets, stems, set_labels = _stick_set(ps, xc, levels)
        segments += set_segments
        planets += set_planets
        labels += set_labels
        for shaft, stem in stems:
            attach[shaft].append(stem)
            junctions.append((stem, levels[shaft]))
    xe = x0 + SET_PITCH * len(d.planetary_sets)
    plates: list[Segment] = []
    teeth: list[Segment] = []
    grounds = []
    bottom = min(levels.values()) - 0.9
    for k, e in enumerate(d.shift_elements):
        x = xe + 1.3 * k
        if e.a is not None:  # a clutch or a one-way clutch between two shafts
            ya, yb = levels[e.a], levels[e.b]
            ym = (ya + yb) / 2
            lo, hi = sorted((ya, yb))
            segments.append(Segment(e.name, (x, lo), (x, ym - 0.1)))
            segments.append(Segment(e.name, (x, ym + 0.1), (x, hi)))
            plates.append(Segment(e.name, (x - 0.25, ym - 0.1), (x + 0.25, ym - 0.1)))
            plates.append(Segment(e.name, (x - 0.25, ym + 0.1), (x + 0.25, ym + 0.1)))
            for shaft in e.shafts:
                attach[shaft].append(x)
                junctions.append((x, levels[shaft]))
            if e.dog:
                teeth += _dog_teeth(e.name, x, ym)
            labels.append(Label(e.name, x + 0.3, ym, "left"))
        else:
            y = levels[e.b]
            ym = (y + bottom) / 2
            segments.append(Segment(e.name, (x, y), (x, ym + 0.1)))
            segments.append(Segment(e.name, (x, ym - 0.1), (x, bottom)))
            plates.append(Segment(e.name, (x - 0.25, ym + 0.1), (x + 0.25, ym + 0.1)))
            plates.append(Segment(e.name, (x - 0.25, ym - 0.1), (x + 0.25, ym - 0.1)))
            grounds.append((e.name, x, bottom))
            if e.dog:
                teeth += _dog_teeth(e.name, x, ym)
            attach[e.b].append(x)
            junctions.append((x, y))
            labels.append(Label(e.name, x + 0.3, ym, "left"))
    right = xe + 1.3 * max(len(d.shift_elements), 1) + 0.5
    attach[d.input_shaft].append(0.0)
    attach[d.output_shaft].append(right)
    spans = {s: (min(xs), max(xs)) for s, xs in attach.items() if xs}
    for s, (a, _) in spans.items():
        if s != d.input_shaft:  # the input's name is on its arrow
            labels.append(Label(f"{s}", a - 0.15, levels[s], "right"))
    labels.append(Label(f"in ({d.input_shaft})", -0.9, levels[d.input_shaft] + 0.25, "center"))
    labels.append(Label(f"out ({d.output_shaft})", right + 0.9, levels[d.output_shaft] + 0.25))
    return StickDiagram(
        gearbox=d.name,
        title=d.title,
        shaft_levels=levels,
        shaft_spans=spans,
        segments=tuple(segments),
        planets=tuple(planets),
        plates=tuple(plates),
        grounds=tuple(grounds),
        junctions=tuple(junctions),
        labels=tuple(labels),
        input_arrow=(-1.6, 0.0, levels[d.input_shaft]),
        output_arrow=(right, right + 1.6, levels[d.output_shaft]),
        teeth=tuple(teeth),
    )


def _stick_set(
    ps: PlanetarySet, xc: float, levels: dict[str, float]
) -> tuple[
    list[Segment],
    list[tuple[str, float, float, float, float]],
    list[tuple[str, float]],
    list[Label],
]:
    """The half-section symbol of one set of any kind, centred at ``xc``: gears as bars
    (suns below, rings above), pinion bodies as boxes, the carrier joining the pinions,
    and a stem from every member down to its shaft line (``levels``).

    simple: sun – planet – ring. double pinion: inner pinion on the sun, outer pinion on
    the ring, stacked radially. stepped planet: one body of two steps, the sun-side step
    left, the ring-side step right. Ravigneaux: long pinion on the sun and the ring, short
    pinion under its right half on the second sun. Ravigneaux with two rings: long pinion on
    the sun and the ring, short pinion over its right half in the second ring.
    Returns segments, pinion boxes, (shaft, stem x) and labels.
    """
    segments: list[Segment] = []
    boxes: list[tuple[str, float, float, float, float]] = []
    stems: list[tuple[str, float]] = []
    labels = [Label(f"set {ps.name}", xc, RING_Y + 0.55)]
    n = ps.name

    def bar(owner: str, shaft: str, y: float, x0: float, x1: float, stem: float) -> None:
        segments.append(Segment(owner, (x0, y), (x1, y)))
        segments.append(Segment(owner, (stem, y), (stem, levels[shaft])))
        stems.append((shaft, stem))

    def pinion(x0: float, y0: float, x1: float, y1: float, text: str) -> None:
        boxes.append((n, x0, y0, x1, y1))
        labels.append(Label(text, x1 + 0.05, y1 - 0.12, "left"))
        # carrier arm from the box's right edge to the carrier stem
        segments.append(Segment(f"C{n}", (x1, (y0 + y1) / 2), (xc + 0.75, (y0 + y1) / 2)))

    kind = ps.kind
    if kind == "double_pinion":
        bar(f"S{n}", ps.sun, SUN_Y, xc - 0.6, xc + 0.6, xc)
        bar(f"R{n}", ps.ring, RING_Y, xc - 0.75, xc + 0.6, xc - 0.75)
        pinion(xc - 0.3, PLANET_Y0, xc + 0.3, 1.9, f"z_P={ps.z_planet}")
        pinion(xc - 0.3, 2.1, xc + 0.3, PLANET_Y1, f"z_Po={ps.z_planet2}")
    elif kind == "stepped_planet":
        bar(f"S{n}", ps.sun, SUN_Y, xc - 0.6, xc, xc - 0.3)
        bar(f"R{n}", ps.ring, RING_Y, xc - 0.75, xc + 0.6, xc - 0.75)
        boxes.append((n, xc - 0.3, PLANET_Y0, xc, 2.2))  # the sun-side step
        labels.append(Label(f"z_P={ps.z_planet}", xc - 0.25, PLANET_Y0 - 0.15, "left"))
        pinion(xc, 1.8, xc + 0.3, PLANET_Y1, f"z_P2={ps.z_planet2}")
    elif kind == "ravigneaux":
        bar(f"S{n}", ps.sun, 1.35, xc - 0.6, xc - 0.05, xc - 0.3)
        bar(f"S2{n}", ps.sun2 or "", 0.75, xc + 0.05, xc + 0.6, xc + 0.3)
        bar(f"R{n}", ps.ring, RING_Y, xc - 0.75, xc + 0.6, xc - 0.75)
        pinion(xc - 0.5, 1.65, xc + 0.5, PLANET_Y1, f"z_L={ps.z_planet}")
        pinion(xc + 0.1, 1.05, xc + 0.5, 1.55, f"z_Ps={ps.z_planet2}")
        labels.append(Label(f"z_S2={ps.z_sun2}", xc + 0.35, 0.55, "left"))
        labels.append(Label(f"z_S={ps.z_sun}", xc - 0.62, 1.2, "left"))
        labels.append(Label(f"z_R={ps.z_ring}", xc + 0.65, RING_Y + 0.12, "left"))
    elif kind == "ravigneaux_two_rings":
        bar(f"S{n}", ps.sun, SUN_Y, xc - 0.6, xc + 0.6, xc)
        bar(f"R{n}", ps.ring, 2.45, xc - 0.75, xc - 0.05, xc - 0.75)
        bar(f"R2{n}", ps.ring2 or "", 3.25, xc + 0.05, xc + 1.0, xc + 1.0)
        pinion(xc - 0.5, PLANET_Y0, xc + 0.5, 2.15, f"z_L={ps.z_planet}")
        pinion(xc + 0.1, 2.25, xc + 0.5, 2.95, f"z_Ps={ps.z_planet2}")
        labels.append(Label(f"z_R2={ps.z_ring2}", xc + 1.05, 3.35, "left"))
        labels.append(Label(f"z_S={ps.z_sun}", xc + 0.65, SUN_Y + 0.12, "left"))
        labels.append(Label(f"z_R={ps.z_ring}", xc - 0.7, 2.6, "left"))
    else:  # simple: as drawn before the compound kinds (docs/stick.png)
        labels[0] = Label(f"set {ps.name}", xc, RING_Y + 0.45)
        bar(f"R{n}", ps.ring, RING_Y, xc - 0.75, xc + 0.6, xc - 0.75)
        bar(f"S{n}", ps.sun, SUN_Y, xc - 0.6, xc + 0.6, xc)
        boxes.append((n, xc - 0.3, PLANET_Y0, xc + 0.3, PLANET_Y1))
        mid = (PLANET_Y0 + PLANET_Y1) / 2
        segments.append(Segment(f"C{n}", (xc + 0.3, mid), (xc + 0.75, mid)))
    # the carrier stem, from the highest arm down to its shaft line
    arms = [seg.start[1] for seg in segments if seg.owner == f"C{n}"]
    segments.append(Segment(f"C{n}", (xc + 0.75, max(arms)), (xc + 0.75, levels[ps.carrier])))
    stems.append((ps.carrier, xc + 0.75))
    if kind == "simple":
        labels.append(Label(f"z_R={ps.z_ring}", xc + 0.65, RING_Y + 0.12, "left"))
        labels.append(Label(f"z_P={ps.z_planet}", xc + 0.35, PLANET_Y1 - 0.1, "left"))
    if kind not in ("ravigneaux", "ravigneaux_two_rings"):
        if kind != "simple":
            labels.append(Label(f"z_R={ps.z_ring}", xc + 0.65, RING_Y + 0.12, "left"))
        labels.append(Label(f"z_S={ps.z_sun}", xc + 0.65, SUN_Y + 0.12, "left"))
    return segments, boxes, stems, labels


# ----------------------------------------------------------------------------- drivetrain


@dataclass(frozen=True)
class Block:
    """One element of the drivetrain chain (Fig. 2.2) with the model symbols it carries."""

    name: str
    symbols: tuple[str, ...]
    x: float
    width: float


@dataclass(frozen=True)
class DrivetrainDiagram:
    """Gearbox → propeller shaft → differential → side shaft (spring ∥ damper) → wheel →
    vehicle, the chain of (2.42)–(2.53), with the description's values."""

    gearbox: str
    blocks: tuple[Block, ...]
    values: dict[str, str]


def _value(q: Any) -> str:
    if q is None:
        return "—"
    return f"{q.value:g}" if q.unit == "1" else f"{q.value:g} {q.unit}"


def drivetrain_diagram(d: GearboxDescription) -> DrivetrainDiagram:
    """The drivetrain of (2.42)–(2.53) as Fig. 2.2 draws it; values from the description."""
    dt, veh = d.drivetrain, d.vehicle
    values = {
        key: _value(q)
        for key, q in (
            ("i_D", dt.get("i_D")),
            ("J_cs", dt.get("J_cs")),
            ("J_D", dt.get("J_D")),
            ("k_ss", dt.get("k_ss")),
            ("d_ss", dt.get("d_ss")),
            ("I_wheel", dt.get("I_wheel")),
            ("r_dyn", veh.get("r_dyn")),
            ("m_veh", veh.get("m_veh")),
        )
    }
    blocks = (
        Block("gearbox", (f"ω_{d.output_shaft}", "T_out"), 0.0, 2.2),
        Block("propeller shaft", ("J_cs",), 2.9, 1.2),
        Block("differential", ("i_D", "J_D"), 4.8, 1.6),
        Block("side shafts", ("k_ss", "d_ss", "φ"), 7.1, 2.0),
        Block("wheel", ("I_C^eff", "r_dyn", "ω_C"), 9.8, 1.6),
        Block("vehicle", ("m_veh", "F_r", "F_a", "F_g"), 12.1, 2.0),
    )
    return DrivetrainDiagram(d.name, blocks, values)


# ----------------------------------------------------------------------------- JSON


def _num(value: Fraction | float | None) -> float | None:
    return None if value is None else float(value)


def to_json(
    what: str,
    d: GearboxDescription,
    diagram: Any,
    plans: list[SpeedPlan] | None = None,
) -> dict[str, Any]:
    """The values a picture shows, machine-readable (``gearsym draw --json``)."""
    data: dict[str, Any] = {"gearbox": d.name, "what": what}
    if isinstance(diagram, LeverDiagram):
        data["levers"] = [
            {
                "name": lever.name,
                "sets": list(lever.sets),
                "nodes": [
                    {
                        "shaft": n.shaft,
                        "members": list(n.members),
                        "position": float(n.position),
                        "x": n.x,
                        "y": n.y,
                    }
                    for n in lever.nodes
                ],
            }
            for lever in diagram.levers
        ]
        data["free_nodes"] = [{"shaft": n.shaft, "x": n.x, "y": n.y} for n in diagram.free_nodes]
        data["elements"] = [
            {"name": e.name, "kind": e.kind, "shafts": list(e.shafts)} for e in diagram.elements
        ]
        data["input_shaft"], data["output_shaft"] = diagram.input_shaft, diagram.output_shaft
    elif isinstance(diagram, StickDiagram):
        data["shaft_levels"] = diagram.shaft_levels
        data["sets"] = [
            {"name": ps.name, "sun": ps.sun, "carrier": ps.carrier, "ring": ps.ring}
            for ps in d.planetary_sets
        ]
        data["elements"] = [
            {"name": e.name, "kind": e.kind, "shafts": list(e.shafts)} for e in d.shift_elements
        ]
        data["input_shaft"], data["output_shaft"] = d.input_shaft, d.output_shaft
    elif isinstance(diagram, DrivetrainDiagram):
        data["blocks"] = [{"name": b.name, "symbols": list(b.symbols)} for b in diagram.blocks]
        data["values"] = diagram.values
    if plans is not None:
        data["gears"] = [
            {
                "gear": p.gear,
                "closed": list(p.closed),
                "neutral": p.neutral,
                "speeds": {s: _num(v) for s, v in p.speeds.items()},
                "ratio": _num(p.ratio),
                "expected": p.expected,
                "held": list(p.held),
            }
            for p in plans
        ]
    return data
