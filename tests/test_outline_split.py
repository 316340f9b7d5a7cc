"""A straight side split into two parts (to load or support part of it) meshes wherever the split
lies: under a column of the face too (issue 39). gmsh's part of an outline body is cut into
surfaces along vertical lines from the strip's nodes (cvxdual.geometry.outline.cuts); a cut that
ended a few ulps beside a split point (a column at x = -3.3e-15, the split at 0) gave gmsh two
points there and the mesh a zero-area triangle at levels 2-5."""

from __future__ import annotations

import copy
import math
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

import cvxdual
from cvxdual.geometry.mesh import build_mesh, column_abscissae
from cvxdual.geometry.triangles import doubled_areas
from cvxdual.scene.scenefile import scene_from_dict

# examples/punch-on-block.toml (a punch with rounded corners on a block with a hole) with the block's
# notch removed and its bottom split in two halves at x = 0 under the punch's centre, each on rollers
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "punch-on-block.toml"


def part_dict() -> dict:
    d = tomllib.loads(EXAMPLE.read_text())
    d["name"] = "punch-on-split-block"
    right, bottom_right, *_, bottom_left, left = d["bodies"]["block"]["outline"]
    bottom_right["to"] = [0.0, -25.0]
    d["bodies"]["block"]["outline"] = [right, bottom_right, bottom_left, left]
    return d


LOAD = 200.0 * 20.0  # the punch's top, 20 mm wide, pressed at 200 MPa: N/mm
HOLE_R = 2.0


def punch_on_block(split: float = 0.0, hole: bool = True, columns: int = 8, flat_punch: bool = False,
                   top_split: float | None = None):
    """The scene above, its block's bottom split at ``split``; ``flat_punch``: a flat punch 24 mm
    wide instead (an outline body, its top split at ``top_split`` if given)."""
    d = part_dict()
    d["mesh"]["columns"] = columns
    d["bodies"]["block"]["outline"][1]["to"] = [split, -25.0]
    if not hole:
        del d["bodies"]["block"]["holes"]
    if flat_punch:
        p = d["bodies"]["punch"]
        p["x"], p["face"] = [-12.0, 12.0], {"kind": "flat", "y0": 0.0}
        top = [{"name": "top", "to": [-12.0, 20.0]}] if top_split is None else \
            [{"name": "top", "to": [top_split, 20.0]}, {"name": "top-left", "to": [-12.0, 20.0]}]
        p["outline"] = [{"name": "right", "to": [12.0, 20.0]}, *top, {"name": "left", "to": [-12.0, 0.0]}]
    return scene_from_dict(d)


def tangent_polygon_area(r: float, n: int) -> float:
    """The area of the polygon of ``n`` sides tangent to a circle of radius ``r`` round it: a free
    hole is meshed inside the body, up to that polygon (docs/scenes.md, 'Free arcs are exact')."""
    return n * r * r * math.tan(math.pi / n)


def check_split_block(mesh, split: float, hole: bool) -> None:
    """The block's mesh: its area is the block's (the hole cut out up to its tangent polygon), no
    node is repeated, and the two halves of the bottom meet at the split point, one node."""
    bm = mesh.bodies[1]
    pts, tris = bm.points(), bm.triangles() - bm.offset
    area = 0.5 * doubled_areas(pts, tris).sum()
    exact = 60.0 * 25.0
    if hole:
        ring = pts[bm.rest.parts["hole"]]
        # its nodes: the polygon's n corners and the n points where it touches the circle
        exact -= tangent_polygon_area(HOLE_R, len(np.unique(ring, axis=0)) // 2)
    # 1e-12: the areas are sums of a few 1e5 triangles' areas of size 1e-3 .. 1e1 (rounding only)
    assert area == pytest.approx(exact, rel=1e-12, abs=0)
    assert len(np.unique(pts, axis=0)) == len(pts)  # a cut beside the split point gave two nodes there
    right, left = bm.rest.parts["bottom-right"], bm.rest.parts["bottom-left"]
    assert right[-1] == left[0] and tuple(pts[right[-1]]) == (split, -25.0)
    assert np.all(pts[right, 1] == -25.0) and np.all(pts[left, 1] == -25.0)


def test_a_split_under_a_column_at_rounding_distance_meshes():
    """12 columns put a column at x = -3.3e-15 (the graded columns' rounding): the cut from it ran
    to the bottom 3.3e-15 from the split at 0 and the mesh held zero-area triangles at levels 2-4
    ("inverted or zero-area triangle ... [0.0, -25.0] twice"). Now that cut is not made."""
    sc = punch_on_block(hole=False, columns=12, flat_punch=True)
    cols = column_abscissae(sc, 2)
    assert 0.0 < abs(cols[np.argmin(abs(cols))]) < 1e-14  # the column beside the split, not on it
    for level in range(0, 6):
        check_split_block(build_mesh(sc, level), 0.0, hole=False)


@pytest.mark.slow
@pytest.mark.parametrize("hole", [True, False], ids=["hole", "no-hole"])
def test_split_at_every_column_meshes(hole):
    """The block's bottom split exactly at each level-0 column (a column at every level), and one
    ulp beside it, meshed at levels 0-2; and the punch's top split alike: every mesh is built and
    is the block (its area, one node at the split)."""
    sc = punch_on_block(hole=hole, columns=12, flat_punch=True)
    cols = column_abscissae(sc, 0)
    inner = cols[(cols > -30.0) & (cols < 30.0)]
    for x in inner:
        for at in (x, np.nextafter(x, np.inf)):
            split = punch_on_block(split=float(at), hole=hole, columns=12, flat_punch=True)
            for level in range(0, 3):
                check_split_block(build_mesh(split, level), float(at), hole)
    for x in inner[(inner > -12.0) & (inner < 12.0)]:
        for at in (x, np.nextafter(x, -np.inf)):
            top = punch_on_block(hole=hole, columns=12, flat_punch=True, top_split=float(at))
            for level in range(0, 3):
                bm = build_mesh(top, level).bodies[0]
                pts = bm.points()
                assert len(np.unique(pts, axis=0)) == len(pts)
                a, b = bm.rest.parts["top"], bm.rest.parts["top-left"]
                assert a[-1] == b[0] and tuple(pts[a[-1]]) == (float(at), 20.0)


@pytest.mark.slow
def test_punch_on_split_block_levels_0_to_5():
    """The punch with rounded corners on the block with a hole, its bottom split at x = 0 (a column
    of every level, under the punch's centre): meshed at levels 0-5 (0.1-3 s a level, measured),
    the block's area every time; the contact force carries the punch's load (fast solve, level 1)."""
    sc = punch_on_block()
    took = []
    for level in range(0, 6):
        t0 = time.perf_counter()
        mesh = build_mesh(sc, level)
        took.append(time.perf_counter() - t0)
        check_split_block(mesh, 0.0, hole=True)
    sol = cvxdual.solve(sc, level=1, solver="fast")
    # 1e-9: the equilibrium residual is 1e-14 of the load; the force sums ~10 nodal forces
    assert sol.contact["total_force"] == pytest.approx(LOAD, rel=1e-9)


def test_split_scene_solves_as_the_whole_one_does():
    """A split changes nothing of the body: with the same sliding support on both halves, the
    solution is the unsplit block's (same mesh but the cut positions, so to the discretisation:
    the objective agrees to 2 % at level 1, the force exactly)."""
    d = part_dict()
    whole = copy.deepcopy(d)
    b = whole["bodies"]["block"]
    b["outline"] = [b["outline"][0], {"name": "bottom", "to": [-30.0, -25.0]}, b["outline"][3]]
    b["boundary"] = {"b": {"on": "bottom", "kind": "sliding"}}
    one, two = (cvxdual.solve(scene_from_dict(x), level=1, solver="fast") for x in (whole, d))
    # 1e-9: both carry the load to rounding (the equilibrium residual is 1e-14 of it)
    assert one.contact["total_force"] == pytest.approx(two.contact["total_force"], rel=1e-9)
    # 2e-2: the two meshes differ (the split is a geometry point for gmsh); both converge to one energy
    assert two.objective == pytest.approx(one.objective, rel=2e-2)


# -- a free arc leaving the face's end straight down along the strip's side ---------------------------

YR = 52.0 - math.sqrt(52.0**2 - 25.0**2)  # cylinder-in-groove's groove face at x = +-25


def rounded_groove(shoulder: str):
    """cylinder-in-groove with its groove in a wider block, the groove's edges rounded: ``tangent``
    (quarter arcs of radius 2 leaving the face's ends straight down, as a fillet drawn from the
    face's end would), ``line`` (a vertical line 8 long first, then the arc) or ``angled`` (an arc
    whose centre sits 1 above the face's end: it leaves at an angle)."""
    from cvxdual.scene.scenefile import builtin_data

    d = builtin_data("cylinder-in-groove")
    g = d["bodies"]["groove"]
    for k in ("far", "layers", "focus_depth"):
        del g[k]
    top, cy = {"tangent": (YR, YR), "line": (YR - 8.0, YR - 8.0), "angled": (YR, YR + 1.0)}[shoulder]
    r = math.dist((27.0, cy), (25.0, top))
    right = [{"name": "sr", "to": [27.0, cy - r], "center": [27.0, cy]}]
    left = [{"name": "sl", "to": [-25.0, top], "center": [-27.0, cy]}]
    if shoulder == "line":
        right, left = [{"name": "sr0", "to": [25.0, top]}, *right], [*left, {"name": "sl0", "to": [-25.0, YR]}]
    g["outline"] = [*right, {"name": "shoulder-r", "to": [40.0, cy - r]}, {"name": "right", "to": [40.0, -20.0]},
                    {"name": "bottom", "to": [-40.0, -20.0]}, {"name": "left", "to": [-40.0, cy - r]},
                    {"name": "shoulder-l", "to": [-27.0, cy - r]}, *left]
    g["boundary"] = {"push": {"on": "bottom", "kind": "traction", "traction": {"value": [0.0, 150.0]}},
                     "right": {"on": "right", "kind": "sliding"}, "left": {"on": "left", "kind": "sliding"}}
    return scene_from_dict(d)


def test_an_arc_leaving_the_face_along_the_strip_side_is_refused_with_the_fix():
    """A free concave arc whose tangent at the face's end is vertical: its tangent polygon's first
    edge lies on the strip's side at every level, so gmsh would get a loop that runs back on itself.
    The refusal said 'raise the level' (no level helps); it now names the reason and two fixes,
    and both fixes mesh."""
    from cvxdual.errors import MeshError

    for level in (0, 2):
        with pytest.raises(MeshError) as e:
            build_mesh(rounded_groove("tangent"), level)
        msg = str(e.value)
        assert "outline part 'sr' leaves the face's right end (25, 6.40395) along the side of the strip" in msg
        assert "overlap at every level; start it with a vertical line longer than the strip is deep" in msg
        assert "\n" not in msg and len(msg) < 300
    for level in (1, 2):  # level 0's strip is 9 deep: deeper than the line (refused as such)
        build_mesh(rounded_groove("line"), level)
    for level in (0, 1, 2):
        build_mesh(rounded_groove("angled"), level)
