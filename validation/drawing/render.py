"""Drawing the geometry of :mod:`gearsym.validation.drawing.geometry` with matplotlib.

Every function takes a geometry dataclass (computed from the description there) and returns a
figure in the shared style of :mod:`gearsym.validation.drawing.figures`; nothing here decides where
a node or a shaft goes. Colours: the matplotlib cycle the other figures use (speeds C0, closed
elements C3), grey for what is open or only links.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from gearsym.symbolic.description import GearboxDescription
from gearsym.validation.drawing.figures import save, subplots
from gearsym.validation.drawing.geometry import (
    LEVER_HEIGHT,
    DrivetrainDiagram,
    LeverDiagram,
    SpeedPlan,
    StickDiagram,
    drivetrain_diagram,
    lever_diagram,
    speed_columns,
    speed_plans,
    stick_diagram,
)

__all__ = [
    "SPEED_SCALE",
    "drivetrain_figure",
    "lever_figure",
    "speeds_figure",
    "stick_figure",
    "write_pictures",
]

#: Display units per unit speed (ω_in = 1) in the speed plan; the lever is LEVER_HEIGHT long.
SPEED_SCALE = 1.2
_CLOSED = "C3"
_OPEN = "0.65"
_SPEED = "C0"
_MARGINS = {"left": 0.01, "right": 0.99, "bottom": 0.02, "top": 0.86}


def _node_label(members: tuple[str, ...], shaft: str) -> str:
    return f"{'/'.join(members)} ({shaft})" if members else f"({shaft})"


def _ground(ax: Any, x: float, y: float, color: str, width: float = 0.5) -> None:
    """The housing symbol: a bar with short hatches below it."""
    ax.plot([x - width / 2, x + width / 2], [y, y], color=color, lw=1.5, solid_capstyle="butt")
    for i in range(5):
        x0 = x - width / 2 + i * width / 4
        ax.plot([x0, x0 - 0.12], [y, y - 0.15], color=color, lw=0.8)


def _ground_vertical(ax: Any, x: float, y: float, color: str, height: float = 0.5) -> None:
    """The housing symbol standing upright, hatched on its left (a brake's ground)."""
    ax.plot([x, x], [y - height / 2, y + height / 2], color=color, lw=1.5, solid_capstyle="butt")
    for i in range(5):
        y0 = y - height / 2 + i * height / 4
        ax.plot([x, x - 0.15], [y0, y0 - 0.12], color=color, lw=0.8)


Spot = tuple[float, float, str, str]  # x, y (data), horizontal and vertical alignment


def _draw_levers(
    ax: Any,
    diagram: LeverDiagram,
    plan: SpeedPlan | None,
    label_nodes: bool = True,
    movable: list[tuple[Any, list[Spot]]] | None = None,
) -> None:
    """The levers, nodes, elements and in/out arrows. Element labels go to ``movable`` with
    their candidate spots (placed by :func:`_place_labels` once everything is drawn)."""
    movable = [] if movable is None else movable
    closed = set(plan.closed) if plan is not None else set()
    held = set(plan.held) if plan is not None else set()
    for _, a, b in diagram.shaft_links:
        ax.plot([a[0], b[0]], [a[1], b[1]], color=_OPEN, lw=0.6, ls=(0, (3, 2)), zorder=1)
    for lever in diagram.levers:
        ax.plot([lever.x, lever.x], [0, LEVER_HEIGHT], color="k", lw=2.2, zorder=3)
        which = "set" if len(lever.sets) == 1 else "sets"
        ax.text(
            lever.x,
            LEVER_HEIGHT + 0.35,
            f"{which} {', '.join(lever.sets)}",
            ha="center",
            va="bottom",
        )
    nodes = [n for lever in diagram.levers for n in lever.nodes] + list(diagram.free_nodes)
    for n in nodes:
        face = _CLOSED if n.shaft in held else "white"
        ax.plot(n.x, n.y, "o", ms=5, mfc=face, mec="k", zorder=5)
        if label_nodes:
            # above-left of the node: the line left of it is where a brake goes to ground
            ax.text(n.x - 0.1, n.y + 0.08, _node_label(n.members, n.shaft), ha="right", va="bottom")
    for e in diagram.elements:
        color = _CLOSED if e.name in closed else (_OPEN if plan is not None else "0.25")
        lw = 2.0 if e.name in closed else 1.0
        (x0, y0), (x1, y1) = e.start, e.end
        if len(e.shafts) == 2:  # a clutch or a one-way clutch between two shafts
            ax.plot([x0, x1], [y0, y1], color=color, lw=lw, zorder=2)
            # two plates across the line at its middle
            mx, my = (x0 + x1) / 2, (y0 + y1) / 2
            length = math.hypot(x1 - x0, y1 - y0) or 1.0
            ux, uy = (x1 - x0) / length, (y1 - y0) / length
            for s in (-0.07, 0.07):
                cx, cy = mx + s * ux, my + s * uy
                ax.plot(
                    [cx - 0.18 * uy, cx + 0.18 * uy],
                    [cy + 0.18 * ux, cy - 0.18 * ux],
                    color=color,
                    lw=2.5,
                )
            label = ax.text(0, 0, e.name, color=color)
            # beside the plates, then further along the line either way, then the other side
            spots = [
                (
                    mx + side * (0.22 * abs(uy) + 0.05) + t * (x1 - x0),
                    my + side * (0.22 * abs(ux) + 0.05) + t * (y1 - y0),
                    "left" if side > 0 else "right",
                    "bottom" if side > 0 else "top",
                )
                for side in (1, -1)
                for t in (0.0, -0.2, 0.2)
            ]
            movable.append((label, spots))
        else:
            # node → housing: a line to the left ending in a vertical ground bar
            ax.plot([x0, x1], [y0, y1], color=color, lw=lw, zorder=2)
            _ground_vertical(ax, x1, y1, color)
            label = ax.text(0, 0, e.name, color=color)
            spots = [
                ((x0 + x1) / 2, y1 - 0.08, "center", "top"),
                ((x0 + x1) / 2, y1 + 0.08, "center", "bottom"),
            ]
            movable.append((label, spots))
    start = diagram.node(diagram.input_shaft)
    end = diagram.node(diagram.output_shaft)
    arrow = {"arrowstyle": "-|>", "color": "k", "lw": 1.2}
    # From below: above a node is its label, right of it its speed arrow and value.
    ax.annotate("", xy=(start.x, start.y), xytext=(start.x - 0.9, start.y - 0.5), arrowprops=arrow)
    label = ax.text(0, 0, "in", weight="bold")
    sx, sy = start.x - 0.9, start.y - 0.5  # the arrow's tail
    movable.append(
        (label, [(sx - 0.05, sy - 0.05, "right", "top"), (sx, sy - 0.08, "center", "top")])
    )
    ax.annotate("", xy=(end.x + 0.9, end.y - 0.5), xytext=(end.x, end.y), arrowprops=arrow)
    label = ax.text(0, 0, "out", weight="bold")
    ex, ey = end.x + 0.9, end.y - 0.5  # the arrow's head
    spots = [(ex + 0.05, ey - 0.05, "left", "top"), (ex, ey - 0.1, "center", "top")]
    spots += [(ex - 0.05, ey - 0.1, "right", "top"), (ex + 0.1, ey, "left", "center")]
    spots += [(ex + 0.1, ey - 0.3, "left", "top"), (ex - 0.2, ey - 0.3, "right", "top")]
    movable.append((label, spots))


def _draw_speeds(
    ax: Any,
    diagram: LeverDiagram,
    plan: SpeedPlan,
    decimals: int,
    movable: list[tuple[Any, list[Spot]]],
) -> None:
    """Speed arrows from every node, each lever's speed line through their tips (straight:
    the lever property), values at the tips (into ``movable`` with their candidate spots)."""
    for lever in diagram.levers:
        tips = [
            (n.x + float(v) * SPEED_SCALE, n.y)
            for n in lever.nodes
            if (v := plan.speeds[n.shaft]) is not None
        ]
        if len(tips) == len(lever.nodes):
            ax.plot([t[0] for t in tips], [t[1] for t in tips], color=_SPEED, lw=1.0, ls="--")
    nodes = [n for lever in diagram.levers for n in lever.nodes] + list(diagram.free_nodes)
    for n in nodes:
        v = plan.speeds[n.shaft]
        if v is None:
            label = ax.text(0, 0, "free", color=_OPEN)
            spots = [(n.x + 0.15, n.y + 0.12, "left", "bottom")]
            movable.append((label, spots + [(n.x + 0.15, n.y - 0.12, "left", "top")]))
            continue
        tip = n.x + float(v) * SPEED_SCALE
        if v != 0:
            ax.annotate(
                "",
                xy=(tip, n.y),
                xytext=(n.x, n.y),
                arrowprops={"arrowstyle": "-|>", "color": _SPEED, "lw": 1.2, "shrinkA": 0},
                zorder=4,
            )
        # node labels sit above-left of the node: a negative speed's value goes below the line;
        # where that spot is taken, the other side of the line, then beyond the tip
        label = ax.text(0, 0, f"{float(v):.{decimals}f}", color=_SPEED)
        side = 1.0 if v >= 0 else -1.0
        h = "left" if v >= 0 else "right"
        spots = [
            (tip + 0.05 * side, n.y + 0.08 * side, h, "bottom" if v >= 0 else "top"),
            (tip + 0.05 * side, n.y - 0.08 * side, h, "top" if v >= 0 else "bottom"),
            (tip + 0.12 * side, n.y, h, "center"),
            ((n.x + tip) / 2, n.y + 0.08, "center", "bottom"),  # over the arrow's middle
            ((n.x + tip) / 2, n.y - 0.08, "center", "top"),
        ]
        movable.append((label, spots))


def _place_labels(fig: Any, movable: list[tuple[Any, list[Spot]]]) -> None:
    """Put each movable label at the first of its spots where it overlaps no other label (text
    boxes as the renderer measures them, after the axes' limits and aspect are final); where
    every spot collides, the spots moved up or down by one, two, three text heights; where
    those collide too, the first spot. Labels already placed count for the next."""
    import matplotlib.text

    if not movable:
        return
    for ax in fig.axes:
        ax.autoscale_view()
        ax.apply_aspect()
    renderer = fig.canvas.get_renderer()
    moving = {id(text) for text, _ in movable}
    boxes = [
        t.get_window_extent(renderer)
        for t in fig.findobj(matplotlib.text.Text)
        if t.get_visible() and t.get_text() and id(t) not in moving
    ]

    def put(text: Any, spot: Spot) -> Any:
        x, y, ha, va = spot
        text.set_position((x, y))
        text.set_horizontalalignment(ha)
        text.set_verticalalignment(va)
        return text.get_window_extent(renderer)

    for text, spots in movable:
        height = put(text, spots[0]).height
        to_data = text.get_transform().inverted()
        step = to_data.transform((0, height))[1] - to_data.transform((0, 0))[1]
        tries = list(spots) + [
            (x, y + sign * k * step, ha, va)
            for k in (1, 2, 3)
            for sign in (1, -1)
            for x, y, ha, va in spots
        ]
        chosen = None
        for spot in tries:
            box = put(text, spot)
            if not any(box.overlaps(other) for other in boxes):
                chosen = box
                break
        boxes.append(chosen if chosen is not None else put(text, spots[0]))


def _suptitle(fig: Any, title: str, what: str) -> None:
    """``title: what`` above the figure, on two lines where one would not fit its width."""
    text = fig.suptitle(f"{title}: {what}")
    width = text.get_window_extent(fig.canvas.get_renderer()).width
    if width > 0.98 * fig.bbox.width:
        text.set_text(f"{title}:\n{what}")


def _finish(ax: Any, levers: bool = False) -> None:
    ax.set_aspect("equal")
    ax.axis("off")
    ax.margins(0.04)
    if levers:  # room for the set names above and the grounds below (texts do not count)
        ax.set_ylim(-1.0, LEVER_HEIGHT + 0.9)


def _extent(diagram: LeverDiagram, columns: dict[str, tuple[float, float]] | None) -> float:
    xs = [n.x for lv in diagram.levers for n in lv.nodes] + [n.x for n in diagram.free_nodes]
    right = max(columns.values(), key=lambda c: 0)[1] if columns else 1.5
    return max(xs) + right + 2.5


def lever_figure(d: GearboxDescription) -> Any:
    """The lever analogy of the description (Benford & Leising, SAE 810102)."""
    diagram = lever_diagram(d)
    width = _extent(diagram, None)
    fig, ax = subplots(1, 1, (max(4.0, 0.9 * width), 4.2), _MARGINS)
    movable: list[tuple[Any, list[Spot]]] = []
    _draw_levers(ax, diagram, None, movable=movable)
    _finish(ax, levers=True)
    _suptitle(fig, d.title, "lever analogy (node spacing ∝ teeth)")
    _place_labels(fig, movable)
    return fig


def speeds_figure(d: GearboxDescription, plans: list[SpeedPlan]) -> Any:
    """Speed plan of one gear, or of every gear in ``plans`` in one figure (a panel each),
    the same layout in every panel."""
    columns = speed_columns(d, plans, SPEED_SCALE)
    diagram = lever_diagram(d, columns)
    width = _extent(diagram, columns)
    cols = 1 if len(plans) == 1 else min(3, len(plans))
    rows = math.ceil(len(plans) / cols)
    panel = (max(4.0, 0.55 * width), 3.6)
    fig, axes = subplots(
        rows,
        cols,
        (panel[0] * cols, panel[1] * rows + 0.4),
        {**_MARGINS, "top": 1 - 0.9 / (panel[1] * rows + 0.4), "hspace": 0.3, "wspace": 0.05},
        squeeze=False,
    )
    decimals = 2 if len(plans) > 1 else 3
    movable: list[tuple[Any, list[Spot]]] = []
    values: list[tuple[Any, list[Spot]]] = []  # placed first: they are the plan's data
    for ax, plan in zip(axes.flat, plans, strict=False):
        _draw_levers(ax, diagram, plan, label_nodes=True, movable=movable)
        _draw_speeds(ax, diagram, plan, decimals, values)
        closed = " ".join(plan.closed) or "nothing"
        if plan.ratio is None:
            read = "neutral (ω_out = 0)"
        else:
            out = plan.speeds[d.output_shaft]
            read = f"ω_in/ω_out = 1/{float(out):.4f} = {float(plan.ratio):.{d.ratio_decimals}f}"
            if plan.expected is not None:
                read += f" (table {plan.expected:.{d.ratio_decimals}f})"
        ax.set_title(f"gear {plan.gear}: {closed} closed\n{read}", fontsize=8)
        _finish(ax, levers=True)
    for ax in list(axes.flat)[len(plans) :]:
        ax.axis("off")
    what = "speed plan" if len(plans) == 1 else "speed plans of every gear"
    _suptitle(fig, d.title, f"{what} (ω_in = 1; closed elements red)")
    _place_labels(fig, values + movable)
    return fig


def stick_figure(d: GearboxDescription, stick: StickDiagram) -> Any:
    """The stick diagram (thesis Fig. 2.1 style)."""
    xs = [x for seg in stick.segments for x in (seg.start[0], seg.end[0])]
    width = max(xs) - min(xs) + 5
    height = 4.5 + 0.7 * len(stick.shaft_levels)
    fig, ax = subplots(1, 1, (max(5.0, 0.7 * width), max(3.5, 0.7 * height)), _MARGINS)
    from matplotlib import patches

    for shaft, (a, b) in stick.shaft_spans.items():
        y = stick.shaft_levels[shaft]
        ax.plot([a, b], [y, y], color="0.2", lw=1.4, zorder=2)
    for seg in stick.segments:
        ax.plot([seg.start[0], seg.end[0]], [seg.start[1], seg.end[1]], color="k", lw=1.6, zorder=3)
    for _, x0, y0, x1, y1 in stick.planets:
        ax.add_patch(
            patches.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="k", lw=1.6, zorder=3)
        )
    for plate in stick.plates:
        ax.plot(
            [plate.start[0], plate.end[0]],
            [plate.start[1], plate.end[1]],
            color="k",
            lw=3.0,
            solid_capstyle="butt",
        )
    for tooth in stick.teeth:  # a dog element's interlocking jaws
        ax.plot(
            [tooth.start[0], tooth.end[0]],
            [tooth.start[1], tooth.end[1]],
            color="k",
            lw=1.8,
            solid_capstyle="butt",
        )
    for _, x, y in stick.grounds:
        _ground(ax, x, y, "k")
    xs_j, ys_j = zip(*stick.junctions, strict=True) if stick.junctions else ((), ())
    ax.plot(xs_j, ys_j, "o", ms=3.5, color="k", zorder=4)
    for label in stick.labels:
        ax.text(label.x, label.y, label.text, ha=label.align, va="center", fontsize=7)
    arrow = {"arrowstyle": "-|>", "color": "k", "lw": 1.4}
    for x0, x1, y in (stick.input_arrow, stick.output_arrow):
        ax.plot([x0, x1], [y, y], color="k", lw=1.4)  # (annotations do not widen the axes)
        ax.annotate("", xy=(x1, y), xytext=(x0, y), arrowprops=arrow)
    _finish(ax)
    _suptitle(fig, d.title, "stick diagram (one line per shaft)")
    return fig


def _spring(ax: Any, x0: float, x1: float, y: float) -> None:
    n = 8
    xs = [x0 + (x1 - x0) * i / n for i in range(n + 1)]
    ys = [y] + [y + (0.12 if i % 2 else -0.12) for i in range(1, n)] + [y]
    ax.plot(xs, ys, color="k", lw=1.0)


def _damper(ax: Any, x0: float, x1: float, y: float) -> None:
    mid = (x0 + x1) / 2
    ax.plot([x0, mid + 0.1], [y, y], color="k", lw=1.0)
    ax.plot(
        [mid - 0.15, mid + 0.25, mid + 0.25, mid - 0.15],
        [y + 0.15, y + 0.15, y - 0.15, y - 0.15],
        color="k",
        lw=1.0,
    )
    ax.plot([mid + 0.1, mid + 0.1], [y - 0.1, y + 0.1], color="k", lw=1.6)
    ax.plot([mid + 0.25, x1], [y, y], color="k", lw=1.0)


def drivetrain_figure(d: GearboxDescription, dt: DrivetrainDiagram) -> Any:
    """The drivetrain of thesis Fig. 2.2 with the model's symbols and the description's
    values: (2.42)–(2.53)."""
    from matplotlib import patches

    fig, ax = subplots(1, 1, (10.0, 3.0), _MARGINS)
    y = 0.0
    blocks = {b.name: b for b in dt.blocks}
    v = dt.values
    notes = {
        "gearbox": [f"ω_{d.output_shaft}, T_out"],
        "propeller shaft": [f"J_cs = {v['J_cs']}"],
        "differential": [f"i_D = {v['i_D']}", f"J_D = {v['J_D']}"],
        "side shafts": [f"k_ss = {v['k_ss']}", f"d_ss = {v['d_ss']}", "twist φ"],
        "wheel": [f"I_wheel = {v['I_wheel']}", f"r_dyn = {v['r_dyn']}", "ω_C"],
        "vehicle": [f"m_veh = {v['m_veh']}", "F_r + F_a + F_g"],
    }
    order = list(blocks)
    for a, b in zip(order, order[1:], strict=False):
        ax.plot([blocks[a].x + blocks[a].width, blocks[b].x], [y, y], color="k", lw=1.4)
    for b in dt.blocks:
        if b.name == "side shafts":
            _spring(ax, b.x, b.x + b.width, y + 0.3)
            _damper(ax, b.x, b.x + b.width, y - 0.3)
            ax.plot([b.x, b.x], [y - 0.3, y + 0.3], color="k", lw=1.0)
            ax.plot([b.x + b.width] * 2, [y - 0.3, y + 0.3], color="k", lw=1.0)
        elif b.name == "wheel":
            ax.add_patch(patches.Circle((b.x + b.width / 2, y), 0.7, fill=False, lw=1.6))
            ax.plot([b.x, b.x + b.width], [y, y], color="k", lw=1.4)
        elif b.name == "propeller shaft":
            ax.plot([b.x, b.x + b.width], [y, y], color="k", lw=3.0)
        else:
            ax.add_patch(
                patches.Rectangle(
                    (b.x, y - 0.6), b.width, 1.2, fill=False, lw=1.6 if b.name == "gearbox" else 1.2
                )
            )
        ax.text(b.x + b.width / 2, y + 0.95, b.name, ha="center", va="bottom", weight="bold")
        for i, line in enumerate(notes.get(b.name, [])):
            ax.text(b.x + b.width / 2, y - 0.95 - 0.3 * i, line, ha="center", va="top", fontsize=7)
    _finish(ax)
    ax.set_ylim(-2.2, 1.6)
    _suptitle(fig, d.title, "drivetrain (thesis Fig. 2.2; (2.42)–(2.53))")
    return fig


#: The pictures `gearsym run` writes into its `drawings/` folder, by file name.
PICTURES = ("stick.png", "lever.png", "speeds.png", "drivetrain.png")


def write_pictures(d: GearboxDescription, folder: Path) -> list[str]:
    """The stick diagram, lever analogy, speed plan of every gear and drivetrain (Figs. 2.1,
    2.2 and the lever analogy) of ``d`` as PNG files in ``folder`` (created); their names."""
    folder.mkdir(parents=True, exist_ok=True)
    figures = {
        "stick.png": lambda: stick_figure(d, stick_diagram(d)),
        "lever.png": lambda: lever_figure(d),
        "speeds.png": lambda: speeds_figure(d, speed_plans(d)),
        "drivetrain.png": lambda: drivetrain_figure(d, drivetrain_diagram(d)),
    }
    for name in PICTURES:
        save(figures[name](), folder / name)
    return list(PICTURES)
