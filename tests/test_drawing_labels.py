"""The pictures as an engineer sees them: every SVG parses, renders to PNG (CairoSVG, a renderer
independent of matplotlib), and no two labels overlap, none is cut off at the edge.

Text bounding boxes are computed here from the SVG itself, not from matplotlib's layout: each
label is a ``<g id="text_N">`` of glyph outlines (``svg.fonttype = "path"``), placed by nested
``translate``/``scale`` transforms and ``<use>`` references; the box of a label is the box of its
glyphs' outline points (control points included, so a box can only be too large, never too
small). The boxes are checked against the raster: the labels alone, rendered by CairoSVG, put
ink inside every box and nowhere outside the boxes.
"""

from __future__ import annotations

import copy
import functools
import io
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

SVG = "{http://www.w3.org/2000/svg}"
XLINK = "{http://www.w3.org/1999/xlink}href"
SIMPSON = Path(__file__).parent / "data" / "simpson_3speed.toml"
#: Raster pixels per SVG unit (pt), and the anti-aliasing fringe allowed around a box.
SCALE = 2.0
FRINGE = 2.0

Box = tuple[float, float, float, float]  # x0, y0, x1, y1 in SVG units, y down


# ----------------------------------------------------------------------------- SVG geometry


def parse(svg: bytes) -> ET.Element:
    """The SVG's element tree, comments kept (matplotlib writes each label's text as one)."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    return ET.fromstring(svg, parser=parser)


def _transform(text: str | None) -> np.ndarray:
    """The 3×3 matrix of an SVG ``transform`` attribute (translate, scale, rotate, matrix)."""
    m = np.eye(3)
    for name, args in re.findall(r"(\w+)\s*\(([^)]*)\)", text or ""):
        v = [float(a) for a in re.split(r"[\s,]+", args.strip()) if a]
        if name == "translate":
            t = np.array([[1, 0, v[0]], [0, 1, v[1] if len(v) > 1 else 0.0], [0, 0, 1]])
        elif name == "scale":
            t = np.diag([v[0], v[1] if len(v) > 1 else v[0], 1.0])
        elif name == "rotate":
            a = math.radians(v[0])
            t = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
            if len(v) == 3:
                shift = np.array([[1, 0, v[1]], [0, 1, v[2]], [0, 0, 1]])
                t = shift @ t @ np.linalg.inv(shift)
        elif name == "matrix":
            t = np.array([[v[0], v[2], v[4]], [v[1], v[3], v[5]], [0, 0, 1]])
        else:
            raise AssertionError(f"unexpected transform {name}")
        m = m @ t
    return m


@functools.lru_cache(maxsize=4096)
def _path_points(d: str) -> np.ndarray:
    """Every point of an absolute M/L/Q/C/Z path (matplotlib writes no other commands)."""
    letters = set(re.findall(r"[A-Za-z]", d))
    assert letters <= set("MLQCZz"), letters
    numbers = [float(x) for x in re.findall(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?", d)]
    return np.array(numbers, dtype=float).reshape(-1, 2)


def _points(element: ET.Element, matrix: np.ndarray, ids: dict[str, ET.Element]) -> list:
    """The outline points below ``element`` in SVG units (``<defs>`` skipped, uses followed)."""
    if not isinstance(element.tag, str):  # a comment
        return []
    tag = element.tag.removeprefix(SVG)
    if tag in ("defs", "clipPath", "style", "metadata"):
        return []
    matrix = matrix @ _transform(element.get("transform"))
    out = []
    if tag == "path" and element.get("d"):
        p = _path_points(element.get("d"))
        out.append((np.c_[p, np.ones(len(p))] @ matrix.T)[:, :2])
    elif tag == "use":
        target = ids[element.get(XLINK).removeprefix("#")]
        shift = _transform(f"translate({element.get('x', 0)} {element.get('y', 0)})")
        out += _points(target, matrix @ shift, ids)
    elif tag == "rect":
        x, y = float(element.get("x", 0)), float(element.get("y", 0))
        w, h = float(element.get("width")), float(element.get("height"))
        p = np.array([[x, y], [x + w, y + h]])
        out.append((np.c_[p, np.ones(2)] @ matrix.T)[:, :2])
    for child in element:
        out += _points(child, matrix, ids)
    return out


def text_boxes(svg: bytes) -> dict[str, tuple[str, Box]]:
    """``{group id: (the label's text, its bounding box)}`` of every label in the SVG."""
    root = parse(svg)
    ids = {e.get("id"): e for e in root.iter() if e.get("id")}
    parents = {child: parent for parent in root.iter() for child in parent}
    boxes = {}
    for group in root.iter(f"{SVG}g"):
        gid = group.get("id") or ""
        if not gid.startswith("text_"):
            continue
        matrix = np.eye(3)
        node = parents.get(group)
        chain = []
        while node is not None:
            chain.append(node)
            node = parents.get(node)
        for ancestor in reversed(chain):
            matrix = matrix @ _transform(ancestor.get("transform"))
        points = _points(group, matrix, ids)
        if not points:
            continue
        p = np.vstack(points)
        label = "".join(c.text or "" for c in group.iter() if c.tag is ET.Comment).strip()
        boxes[gid] = (label, (p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max()))
    return boxes


def canvas(svg: bytes) -> tuple[float, float]:
    view = parse(svg).get("viewBox").split()
    return float(view[2]), float(view[3])


def overlaps(boxes: dict[str, tuple[str, Box]]) -> list[tuple[str, str]]:
    """Pairs of labels whose boxes share area."""
    items = list(boxes.values())
    found = []
    for i, (a, (ax0, ay0, ax1, ay1)) in enumerate(items):
        for b, (bx0, by0, bx1, by1) in items[i + 1 :]:
            if min(ax1, bx1) > max(ax0, bx0) and min(ay1, by1) > max(ay0, by0):
                found.append((a, b))
    return found


# ----------------------------------------------------------------------------- rendering


def render(svg: bytes) -> np.ndarray:
    """The SVG rasterised by CairoSVG at SCALE pixels per unit, on white: (h, w) grey levels."""
    import cairosvg
    from PIL import Image

    width, height = canvas(svg)
    png = cairosvg.svg2png(
        bytestring=svg,
        output_width=round(width * SCALE),
        output_height=round(height * SCALE),
        background_color="white",
    )
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    image = Image.open(io.BytesIO(png)).convert("L")
    assert image.size == (round(width * SCALE), round(height * SCALE))
    return np.asarray(image)


def _serialise(root: ET.Element) -> bytes:
    ET.register_namespace("", SVG[1:-1])
    ET.register_namespace("xlink", XLINK[1:].split("}")[0])
    return ET.tostring(root)


def expand_uses(svg: bytes) -> bytes:
    """The same picture with every ``<use>`` replaced by a copy of what it references (the
    same drawing: CairoSVG re-reads the whole document at each ``<use>``, which makes the
    thousands of glyph references of a speed plan take seconds)."""
    root = parse(svg)
    ids = {e.get("id"): e for e in root.iter() if e.get("id")}
    for parent in list(root.iter()):
        for k, child in enumerate(list(parent)):
            if child.tag != f"{SVG}use":
                continue
            target = copy.deepcopy(ids[child.get(XLINK).removeprefix("#")])
            target.attrib.pop("id", None)
            shift = f"translate({child.get('x', 0)} {child.get('y', 0)})"
            parts = (child.get("transform", ""), shift, target.get("transform", ""))
            target.set("transform", " ".join(p for p in parts if p))
            parent.remove(child)
            parent.insert(k, target)
    return _serialise(root)


def labels_only(svg: bytes) -> bytes:
    """The SVG with every drawn element outside the label groups removed."""
    root = parse(svg)

    def prune(element: ET.Element) -> None:
        for child in list(element):
            tag = child.tag.removeprefix(SVG) if isinstance(child.tag, str) else ""
            if tag in ("defs", "metadata", "style"):
                continue
            if tag == "g" and (child.get("id") or "").startswith("text_"):
                continue
            if tag == "g":
                prune(child)
            else:
                element.remove(child)

    prune(root)
    return _serialise(root)


def check_picture(svg: bytes, original: bool = True) -> None:
    """Parses, renders, labels where the boxes say, inside the canvas, pairwise apart.
    ``original``: rasterise the SVG as written (else with its ``<use>`` references expanded,
    the same drawing, for speed); the labels alone are always rendered expanded."""
    parse(svg)  # parses (raises on malformed XML)
    full = render(svg if original else expand_uses(svg))
    assert (full < 128).sum() > 100, "the rendered picture is blank"
    boxes = text_boxes(svg)
    assert boxes, "no labels found"
    width, height = canvas(svg)
    ink = render(expand_uses(labels_only(svg))) < 200
    covered = np.zeros_like(ink)
    for label, (x0, y0, x1, y1) in boxes.values():
        assert x0 >= 0 and y0 >= 0 and x1 <= width and y1 <= height, f"{label!r} cut off"
        r0, r1 = math.floor(y0 * SCALE - FRINGE), math.ceil(y1 * SCALE + FRINGE)
        c0, c1 = math.floor(x0 * SCALE - FRINGE), math.ceil(x1 * SCALE + FRINGE)
        assert ink[max(r0, 0) : r1, max(c0, 0) : c1].any(), f"no ink inside the box of {label!r}"
        covered[max(r0, 0) : r1, max(c0, 0) : c1] = True
    stray = ink & ~covered
    assert not stray.any(), f"{stray.sum()} label pixels outside every computed box"
    assert overlaps(boxes) == [], overlaps(boxes)


# ----------------------------------------------------------------------------- the pictures


def _pictures(config: Path | None) -> dict[str, Callable[[], object]]:
    from gearsym.symbolic.loader import load_description
    from gearsym.validation.drawing import render as render_
    from gearsym.validation.drawing.geometry import drivetrain_diagram, speed_plans, stick_diagram

    d = load_description(config) if config else load_description()
    plans = speed_plans(d)
    pictures = {
        "stick": lambda: render_.stick_figure(d, stick_diagram(d)),
        "lever": lambda: render_.lever_figure(d),
        "speeds": lambda: render_.speeds_figure(d, plans),
        "drivetrain": lambda: render_.drivetrain_figure(d, drivetrain_diagram(d)),
    }
    for plan in plans:
        pictures[f"speeds gear {plan.gear}"] = lambda p=plan: render_.speeds_figure(d, [p])
    return pictures


def _svg(figure: object) -> bytes:
    from gearsym.validation.drawing.figures import to_bytes

    return to_bytes(figure, "svg")


@pytest.mark.slow
@pytest.mark.parametrize("config", [None, SIMPSON], ids=["built-in", "simpson_3speed"])
def test_no_label_overlaps_in_any_picture(config):
    failures = []
    for name, make in _pictures(config).items():
        try:
            # the four pictures `gearsym draw` makes by default rasterised as written
            check_picture(_svg(make()), original=" gear " not in name)
        except AssertionError as error:
            failures.append(f"{name}: {error}")
    assert not failures, "\n".join(failures)


def test_the_check_finds_overlapping_and_cut_off_labels():
    """The checker is not vacuous: two labels drawn on top of each other are found, with their
    texts, and so is a label running off the canvas."""
    from gearsym.validation.drawing.figures import subplots

    fig, ax = subplots(1, 1, (3.0, 2.0))
    ax.axis("off")
    ax.text(0.2, 0.5, "K38 closed")
    ax.text(0.25, 0.52, "B05 open")
    ax.text(0.2, 0.1, "apart")
    boxes = text_boxes(_svg(fig))
    assert sorted(label for label, _ in boxes.values()) == ["B05 open", "K38 closed", "apart"]
    assert [tuple(sorted(p)) for p in overlaps(boxes)] == [("B05 open", "K38 closed")]
    with pytest.raises(AssertionError, match="K38 closed"):
        check_picture(_svg_of_texts([(0.2, 0.5, "K38 closed"), (0.25, 0.52, "B05 open")]))
    with pytest.raises(AssertionError, match="cut off"):
        check_picture(_svg_of_texts([(0.9, 0.5, "a label running off the canvas")]))
    check_picture(_svg_of_texts([(0.1, 0.8, "one"), (0.1, 0.2, "two")]))


def _svg_of_texts(texts: list[tuple[float, float, str]]) -> bytes:
    from gearsym.validation.drawing.figures import subplots

    fig, ax = subplots(1, 1, (3.0, 2.0))
    ax.axis("off")
    ax.plot([0, 1], [0, 1], color="k")
    for x, y, text in texts:
        ax.text(x, y, text)
    return _svg(fig)
