"""Outline bodies (general plane bodies meshed by gmsh beyond the strip of columns along the face):
exactness of both stress spaces on unstructured meshes, Kirsch's hole, the certified bounds with free
arcs, determinism of the meshes, the outline checks and the refusals of malformed outlines."""

import math
import os
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest
from helpers import GEO_SCENE, without_progress

import cvxdual as cd
from cvxdual.cli import main
from cvxdual.errors import MeshError
from cvxdual.geometry.mesh import build_mesh
from cvxdual.geometry.outline import SMALL, fence, forget_meshes
from cvxdual.geometry.triangulation import discretize
from cvxdual.scene import load_scene, parse_assignment
from cvxdual.system.boundary import supports

PATCH = """base = "patch"
name = "patch-outline"
[exact]
kind = "uniform"
stress = [0.0, -100.0, 0.0]
any_material = true
[bodies.top]
outline = [{name = "right", to = [10.0, 6.0]}, {name = "far", to = [0.0, 6.0]}, {name = "left", to = [0.0, 0.0]}]
[bodies.bottom]
outline = [{name = "right", to = [10.0, -4.0]}, {name = "far", to = [0.0, -4.0]}, {name = "left", to = [0.0, 0.0]}]
"""


@pytest.fixture(scope="module")
def patch_outline(tmp_path_factory):
    f = tmp_path_factory.mktemp("scenes") / "patch-outline.toml"
    f.write_text(PATCH)
    return load_scene(str(f))


@pytest.mark.parametrize("space", ["p0", "eq"])
@pytest.mark.parametrize("level", [1, 2, 3])
def test_patch_on_unstructured_meshes_is_exact(patch_outline, space, level):
    """The uniform stress lies in both spaces, so both reproduce it on gmsh's meshes: 1e-8 relative
    leaves 1e3 times the direct solves' rounding (1e-12 to 1e-11 seen)."""
    sol = cd.solve(patch_outline, level=level, stress_space=space, solver="fast")
    assert sol.mesh.bodies[0].rest is not None  # gmsh meshed beyond the strip
    assert sol.error["l2_rel"] <= 1e-8


def test_patch_outline_mesh_is_unstructured_and_conforming(patch_outline):
    mesh = build_mesh(patch_outline, 2)
    bm = mesh.bodies[1]
    # gmsh adds nodes off the columns: not a column mesh
    assert not np.all(np.isin(np.round(mesh.points[bm.offset + bm.n_strip_nodes:, 0], 12), np.round(bm.columns, 12)))
    # conforming: every interior edge is shared by exactly two triangles, boundary edges by one, and
    # the boundary edges are exactly those of the named parts and the face
    tris = bm.triangles()
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    keys, count = np.unique(e[:, 0] * mesh.n_nodes + e[:, 1], return_counts=True)
    assert set(count) <= {1, 2}
    boundary = set(keys[count == 1])
    named = set()
    for side in ("face", "right", "far", "left"):
        n = bm.side_nodes(side)
        named |= set(np.minimum(n[:-1], n[1:]) * mesh.n_nodes + np.maximum(n[:-1], n[1:]))
    assert boundary == named
    d1, d2 = mesh.points[tris[:, 1]] - mesh.points[tris[:, 0]], mesh.points[tris[:, 2]] - mesh.points[tris[:, 0]]
    area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    assert area.sum() == pytest.approx(40.0, rel=1e-12)  # the 10 x 4 block, to rounding


def test_gmsh_time_is_reported_for_outline_scenes_only(patch_outline):
    """``timings["gmsh"]``: gmsh's time in the whole call (size probe, warm start), within its wall
    time; none for column scenes, none spent when every mesh is kept."""
    forget_meshes()
    t = time.perf_counter()
    sol = cd.solve(patch_outline, level=3, solver="fast")
    wall = time.perf_counter() - t
    assert 0 < sol.timings["gmsh"] < wall
    assert cd.solve(patch_outline, level=3, solver="fast").timings["gmsh"] == 0  # the meshes are kept
    assert "gmsh" not in cd.solve("patch", level=0, solver="fast").timings


@pytest.mark.slow
@pytest.mark.parametrize(("scene", "level"), [("patch-outline", 5), ("block-with-hole", 4)])
def test_meshes_are_deterministic_across_processes_and_threads(patch_outline, tmp_path, scene, level):
    """Same input, same mesh: in a fresh process, on one gmsh thread or two (each body is cut in
    surfaces, meshed side by side; nodes and triangles are read surface by surface). The levels
    give 129 columns, so gmsh gets a chain of 65 nodes (every other column): more than
    outline.SMALL, so two threads are used where allowed (at 65 columns gmsh's chain had 33 nodes
    and one thread: the test compared one thread with one thread)."""
    f = tmp_path / "p.toml"
    f.write_text(PATCH)
    source = str(f) if scene == "patch-outline" else scene
    code = ("import hashlib, sys; from cvxdual.pipeline import as_scene; from cvxdual.geometry.mesh import build_mesh;"
            f"m = build_mesh(as_scene({source!r}), {level});"
            "print(hashlib.sha256(m.points.tobytes() + m.triangles().tobytes()).hexdigest())")
    runs = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "OMP_NUM_THREADS": threads}).stdout
            for threads in ("1", "2", "2")}
    assert len(runs) == 1
    columns = len(build_mesh(cd.load_scene(source), level).bodies[0].columns)
    assert (columns + 1) // 2 > SMALL  # gmsh's chain (every other column): two threads were asked


def test_rest_is_cut_into_surfaces_along_columns(patch_outline):
    """The middle column's vertical line runs from the strip to the far side in both blocks:
    gmsh's nodes lie on it (a cut between two surfaces), and triangles on both sides of it share
    its edges (conforming: the edge test above holds on the whole body)."""
    mesh = build_mesh(patch_outline, 2)
    for bm in mesh.bodies:
        x = bm.columns[round(0.5 * (len(bm.columns) - 1))]
        far = 6.0 if bm.body.position == "upper" else -4.0
        on = bm.rest.points[bm.rest.points[:, 0] == x]  # a vertical line: x exactly, no rounding
        assert len(on) >= 3
        assert np.isclose(np.abs(on[:, 1]).max(), abs(far), rtol=0, atol=1e-12)


def test_hole_body_is_cut_through_its_hole():
    """block-with-hole's lower block is cut along x = 0: from the strip to the hole's top, round
    the hole (each surface keeps one half) and from its bottom to the block's bottom. The mesh
    conforms (every edge in one or two triangles) and its boundary edges are exactly the named
    parts' and the face's: the cut leaves no seam."""
    mesh = build_mesh(load_scene("block-with-hole"), 2)
    bm = next(b for b in mesh.bodies if b.body.name == "bottom")
    on = bm.rest.points[bm.rest.points[:, 0] == 0.0]  # vertical legs: x exactly
    assert np.any(on[:, 1] > -9.5) and np.any(on[:, 1] < -10.5)  # above and below the hole
    assert np.isclose(on[:, 1].min(), -20.0, rtol=0, atol=1e-12)  # down to the bottom
    tris = bm.triangles()
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    keys, count = np.unique(e[:, 0] * mesh.n_nodes + e[:, 1], return_counts=True)
    assert set(count) <= {1, 2}
    named = set()
    for side in ("face", "right", "bottom", "left", "hole"):
        n = bm.side_nodes(side)
        named |= set(np.minimum(n[:-1], n[1:]) * mesh.n_nodes + np.maximum(n[:-1], n[1:]))
    assert bm.side_nodes("hole")[0] == bm.side_nodes("hole")[-1]  # the hole's chain closes on itself
    assert set(keys[count == 1]) == named


def test_sliding_supports_on_named_parts(patch_outline):
    mesh = build_mesh(patch_outline, 1)
    fixed = supports(mesh).fixed
    bottom = mesh.bodies[1]
    left, far = bottom.side_nodes("left"), bottom.side_nodes("far")
    assert np.all(fixed[left, 0]) and np.all(fixed[far, 1])  # u_x on the vertical line, u_y on the horizontal
    assert not np.any(fixed[bottom.side_nodes("right")[1:-1]])


def _hoop(sol):
    """sigma_yy at the hole's sides and sigma_xx at its top and bottom, just inside the body."""
    r, eps = 0.5, 1e-7
    pts = np.array([[r + eps, -10.0], [-r - eps, -10.0], [0.0, -10.0 + r + eps], [0.0, -10.0 - r - eps]])
    s, _ = sol.field.at(pts, np.ones(4, int))
    return s[:2, 1], s[2:, 0]


@pytest.mark.slow
def test_kirsch_hole_hoop_stress_and_certified_bounds():
    """Kirsch: -3 q at the hole's sides, +q at its top and bottom (q = 100). The eq space at the
    finest level gets the sides within 2 % (the issue's acceptance; 1.1 % seen at level 3: 128
    edges round the hole); the free hole keeps the bounds certified for the round hole."""
    sol = cd.solve("block-with-hole", level=3, stress_space="eq", solver="fast")
    sides, poles = _hoop(sol)
    assert np.all(np.abs(sides / -300.0 - 1) <= 0.02)
    assert np.all(np.abs(poles / 100.0 - 1) <= 0.03)  # +q: a smaller stress, a coarser relative fit (1 % seen)
    b = sol.bounds
    assert b["guaranteed"], b["reasons"]
    assert b["energy_lower"] <= b["energy_upper"]


def test_kirsch_converges_from_below():
    """The peak stress is resolved better with each level: the sides' error falls level by level."""
    err = [np.max(np.abs(_hoop(cd.solve("block-with-hole", level=L, stress_space="eq", solver="fast"))[0] / -300 - 1))
           for L in (1, 2)]
    assert err[1] < err[0] < 0.06  # 4.8 % and 2.2 % seen at levels 1 and 2


def test_free_arcs_keep_bounds_certified_and_nested():
    """The roller's free flanks (convex arcs: chords) and the hole (concave: tangent polygon) are
    exact: every bracket is certified and consecutive brackets share a point."""
    scene = load_scene("examples/roller-on-block.toml")
    brackets = []
    for level in (1, 2):
        b = cd.solve(scene, level=level, stress_space="eq", solver="fast").bounds
        assert b["guaranteed"], b["reasons"]
        brackets.append((b["energy_lower"], b["energy_upper"]))
    assert max(lo for lo, _ in brackets) <= min(hi for _, hi in brackets)


def test_continuation_energy_is_counted():
    """The displacement's energy beyond the free arcs is part of J(v): without it the upper end
    would be the energy of a smaller body, not a bound for the round one."""
    mesh, _, _ = discretize(load_scene("block-with-hole"), "type1", 1)
    nodes, weight, body = mesh.continuation()
    assert len(weight) == 4 * 4 * 2  # four quarter arcs, 4 * 2**level corners each
    assert np.all(body == 1) and np.all(weight > 0)
    # the corners lie between the tangent polygon and the circle: outside the radius, inside r / cos
    p = mesh.points[nodes[:, 1]] - np.array([0.0, -10.0])
    rad = np.hypot(p[:, 0], p[:, 1])
    assert np.all(rad > 0.5) and np.allclose(rad, 0.5 / np.cos(np.pi / 32), rtol=1e-12)


def test_loaded_curved_part_is_not_certified():
    """A loaded arc is meshed as gmsh's polygon: the bounds say why they are not guaranteed."""
    scene = load_scene("examples/roller-on-block.toml")
    b0 = scene.bodies[0]
    part = cd.BoundaryPart(on="flank-right", kind="traction", traction=cd.Traction("uniform", (0.0, -1.0)), name="push")
    scene = replace(scene, bodies=(replace(b0, boundary=b0.boundary + (part,)), scene.bodies[1]))
    b = cd.solve(scene, level=1, stress_space="eq", solver="fast").bounds
    assert not b["guaranteed"] and any("flank-right" in r for r in b["reasons"])


def test_missing_gmsh_is_one_line(monkeypatch, tmp_path, patch_outline):
    """Where gmsh's wheel cannot load a system library, an outline scene gets one line naming it
    and its package (gmsh is imported in its own process: a stand-in module first on the path
    raises the loader's error there); column scenes do not need gmsh at all."""
    (tmp_path / "gmsh.py").write_text('raise OSError("libGLU.so.1: cannot open shared object file: No such file")\n')
    monkeypatch.syspath_prepend(str(tmp_path))  # the fence hands the caller's path to gmsh's process
    fence.stop()  # a new process, which finds the stand-in
    forget_meshes()  # a kept mesh would need no gmsh
    try:
        with pytest.raises(MeshError, match="libGLU.*apt-get install libglu1-mesa"):
            build_mesh(patch_outline, 0)
        build_mesh(load_scene("patch"), 0)  # a column scene needs no gmsh
    finally:
        fence.stop()  # the next process finds the real gmsh


# -- malformed outlines: one line, exit 1, nothing written ---------------------------------------

HOLE = 'base = "block-with-hole"\n'
LOWER = "[bodies.bottom]\n"


def _outline(*parts):
    return "outline = [" + ", ".join(parts) + "]\n"


RIGHT, BOTTOM, LEFT = ('{name = "right", to = [10.0, -20.0]}', '{name = "bottom", to = [-10.0, -20.0]}',
                       '{name = "left", to = [-10.0, 0.0]}')
MALFORMED = [
    ("open", _outline(RIGHT, BOTTOM, '{name = "left", to = [-10.0, -1.0]}'), "is open"),
    ("self-intersecting", _outline('{name = "right", to = [-10.0, -20.0]}', '{name = "bottom", to = [10.0, -20.0]}',
                                   '{name = "left", to = [-10.0, 0.0]}'), "self-intersecting"),
    ("named twice", _outline(RIGHT, '{name = "right2", to = [-10.0, -20.0]}', '{name = "right", to = [-10.0, 0.0]}'),
     "named twice"),
    ("named face", _outline(RIGHT, '{name = "face", to = [-10.0, -20.0]}', LEFT), "own name"),
    ("unknown part", '[bodies.bottom.boundary.support]\non = "base"\n', "not a part of its outline"),
    ("column side name", '[bodies.bottom.boundary.support]\non = "far"\n', "name one of its parts"),
    ("arc radii", _outline(RIGHT, '{name = "bottom", to = [-10.0, -20.0], center = [1.0, -10.0]}', LEFT),
     "different distances"),
    ("half turn", _outline('{name = "right", to = [10.0, -20.0], center = [10.0, -10.0]}', BOTTOM, LEFT),
     "half a circle"),
    ("hole outside", 'holes = [{name = "hole", center = [0.0, -30.0], radius = 0.5}]\n', "not inside"),
    ("hole crossing", 'holes = [{name = "hole", center = [0.0, -19.8], radius = 0.5}]\n', "self-intersecting"),
    ("holes overlapping", 'holes = [{name = "a", center = [0.0, -10.0], radius = 0.5}, '
     '{name = "b", center = [0.5, -10.0], radius = 0.5}]\n', "self-intersecting"),
    ("zero length", _outline(RIGHT, '{name = "dot", to = [10.0, -20.0]}', BOTTOM, LEFT), "zero length"),
    ("wrong way", _outline('{name = "right", to = [10.0, 20.0]}', '{name = "bottom", to = [-10.0, 20.0]}', LEFT),
     "does not enclose"),
    ("sliding on an arc", _outline(RIGHT, '{name = "bottom", to = [-10.0, -20.0], center = [0.0, 0.0]}', LEFT),
     "not one straight line"),
    ("interval on a part", '[bodies.bottom.boundary.support]\ninterval = [-5.0, 5.0]\n', "split the part"),
    ("outline not a list", 'outline = "box"\n', "non-empty list"),
    ("part without to", _outline(RIGHT, '{name = "bottom"}', LEFT), "missing key 'to'"),
    ("unknown part key", _outline(RIGHT, '{name = "bottom", to = [-10.0, -20.0], radius = 1.0}', LEFT),
     "unknown key 'radius'"),
    ("hole keys", 'holes = [{name = "hole", center = [0.0, -10.0]}]\n', "give center and radius"),
    ("two-point polygon", 'holes = [{name = "slot", points = [[0.0, -10.0], [1.0, -10.0]]}]\n', "at least 3"),
    ("far disagrees", "far = -30.0\n", "but its outline reaches"),
    ("too many parts", _outline(RIGHT, *(f'{{name = "b{i}", to = [{10 - 20 * (i + 1) / 300}, -20.0]}}'
                                           for i in range(300)), LEFT), "more than 200"),
    ("holes not a list", "holes = 3\n", "must be a list"),
    ("arc and spline", _outline(RIGHT, '{name = "bottom", to = [-10.0, -20.0], center = [0.0, -20.0], '
                                       'through = [[0.0, -21.0]]}', LEFT), "not both"),
    ("spline without points", _outline(RIGHT, '{name = "bottom", to = [-10.0, -20.0], through = 5}', LEFT),
     "through must list"),
    ("side shorter than the strip", _outline('{name = "step", to = [10.0, -0.2]}',
                                             '{name = "right", to = [11.0, -20.0]}', BOTTOM, LEFT),
     "meets the outline part 'step'"),
    ("strip meets a hole", 'holes = [{name = "hole", center = [0.0, -0.8], radius = 0.5}]\n',
     "meets the outline part 'hole'"),
]


GEO_BLOCK = """Point(1) = {10, 0, 0}; Point(2) = {10, -20, 0}; Point(3) = {-10, -20, 0}; Point(4) = {-10, 0, 0};
Line(1) = {4, 1}; Line(2) = {1, 2}; Line(3) = {2, 3}; Line(4) = {3, 4};
"""
NAMES = 'Physical Curve("face") = {1};\nPhysical Curve("right") = {2};\nPhysical Curve("bottom") = {3};\n'
GEO_BAD = [
    ("geo without face", GEO_BLOCK + 'Physical Curve("top") = {1};\nPhysical Curve("bottom") = {3};', "named 'face'"),
    ("geo unnamed curve", GEO_BLOCK + NAMES + "Physical Curve(7) = {4};", "has no name"),
    ("geo face curves apart", GEO_BLOCK.replace("Line(1) = {4, 1};", "Point(9) = {0, 0, 0};\nPoint(8) = {1, 0, 0};\n"
                                                "Line(1) = {4, 9};\nLine(5) = {8, 1};")
     + NAMES.replace("{1}", "{1, 5}") + 'Physical Curve("left") = {4};', "do not run end to end"),
    ("geo open", GEO_BLOCK + NAMES, "curve 4 is in no physical curve"),
    ("geo syntax", "Point(1) = {10, 0", "cannot read"),
]


@pytest.mark.parametrize("geo,words", [(g, w) for _, g, w in GEO_BAD], ids=[i for i, _, _ in GEO_BAD])
def test_malformed_geo_is_refused_in_one_line(tmp_path, monkeypatch, capsys, geo, words):
    _refused(tmp_path, monkeypatch, capsys, {"b.geo": geo, "bad.toml": GEO_SCENE}, words)


def _refused(tmp_path, monkeypatch, capsys, files: dict, words: str) -> None:
    """``cvxdual solve --scene bad.toml`` exits 1 with one error line holding ``words``, writing nothing."""
    monkeypatch.chdir(tmp_path)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    before = set(tmp_path.rglob("*"))
    rc = main(["solve", "--scene", "bad.toml", "--level", "0", "--no-plots"])
    err = without_progress(capsys.readouterr().err)
    assert rc == 1
    assert len(err) == 1 and err[0].startswith("cvxdual: error:") and words in err[0], err
    assert set(tmp_path.rglob("*")) == before


def test_geo_and_outline_keys_together_are_refused(tmp_path):
    (tmp_path / "b.geo").write_text(GEO_BLOCK + NAMES + 'Physical Curve("left") = {4};')
    (tmp_path / "s.toml").write_text(GEO_SCENE.replace('geo = "b.geo"', 'geo = "b.geo"\nx = [-10.0, 10.0]'))
    with pytest.raises(cd.errors.SceneError, match="either geo"):
        load_scene(str(tmp_path / "s.toml"))


def test_geo_body_is_the_toml_body():
    """examples/block-with-hole-geo.toml reads its lower block from a .geo file: the same mesh (bit
    for bit: the file's own centre point is taken for the hole's arcs) and the same solution."""
    a, b = load_scene("block-with-hole"), load_scene("examples/block-with-hole-geo.toml")
    assert a.bodies[1].outline == b.bodies[1].outline and a.bodies[1].face == b.bodies[1].face
    ma, mb = build_mesh(a, 2), build_mesh(b, 2)
    assert np.array_equal(ma.points, mb.points) and np.array_equal(ma.triangles(), mb.triangles())
    sa, sb = (cd.solve(s, level=1, stress_space="eq", solver="fast") for s in (a, b))
    assert np.array_equal(np.asarray(sa.stress), np.asarray(sb.stress))


@pytest.mark.parametrize("body,words", [(b, w) for _, b, w in MALFORMED], ids=[i for i, _, _ in MALFORMED])
def test_malformed_outline_is_refused_in_one_line(tmp_path, monkeypatch, capsys, body, words):
    _refused(tmp_path, monkeypatch, capsys, {"bad.toml": HOLE + (body if body.startswith("[") else LOWER + body)},
             words)


def test_polygon_holes_run_counter_clockwise():
    from cvxdual.scene.outline import outline_from_dict
    o = outline_from_dict([{"name": "a", "to": [0.0, -1.0]}], [{"name": "h", "points": [[0, 0], [0, 1], [1, 0]]}],
                          (1.0, 0.0), "t")
    p = np.array([s.start for s in o.holes[0].segments])
    assert np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]) > 0


def test_plots_draw_the_true_outline():
    """The drawn outline of an outline body follows its arcs (the hole round, not the mesh's
    polygon) and closes on the face."""
    from cvxdual.outputs.views import body_outline
    body = load_scene("block-with-hole").bodies[1]
    outer, hole = body_outline(body)
    assert np.allclose(outer[0], outer[-1])  # closed: back at the face's left end
    r = np.hypot(hole[:, 0], hole[:, 1] + 10.0)
    assert np.allclose(r, 0.5, rtol=1e-14)


SPLINE = """base = "block-with-hole"
name = "spline-block"
[bodies.bottom]
outline = [
    { name = "right", to = [10.0, -20.0] },
    { name = "bottom", to = [-10.0, -20.0], through = [[5.0, -22.0], [0.0, -23.0], [-5.0, -22.0]] },
    { name = "left", to = [-10.0, 0.0] },
]
[bodies.bottom.boundary.support]
on = "bottom"
kind = "clamped"
"""


def test_spline_parts_are_meshed_on_the_spline(tmp_path):
    """A spline part (the natural cubic spline through its points) is meshed as a polygon whose
    nodes lie on it; the eq stresses stay exactly admissible, and the bounds say they hold for the
    polygonal body (a clamped spline has no exact pair)."""
    f = tmp_path / "s.toml"
    f.write_text(SPLINE)
    scene = load_scene(str(f))
    seg = scene.bodies[1].outline.part("bottom").segments[0]
    knots = seg.sample(1)
    assert np.allclose(knots, [[10, -20], [5, -22], [0, -23], [-5, -22], [-10, -20]])  # through its points
    sol = cd.solve(scene, level=2, stress_space="eq", solver="fast")
    nodes = sol.mesh.points[sol.mesh.bodies[1].side_nodes("bottom")]
    from scipy.spatial import cKDTree
    dist, _ = cKDTree(seg.sample(20000)).query(nodes)
    # nodes are spline points, or lie on chords between them 1.2 mm apart on a curve of radius
    # >= 10 mm: a sag below 0.02 mm; the dense sampling itself is 3e-4 mm fine
    assert dist.max() <= 0.02
    assert max(sol.bounds["residuals"].values()) <= 1e-12  # exact admissibility: rounding only
    assert not sol.bounds["guaranteed"] and any("bottom.bottom" in r for r in sol.bounds["reasons"])


def test_geo_splines_become_spline_parts(tmp_path):
    geo = GEO_BLOCK.replace("Line(3) = {2, 3};", "Point(9) = {0, -23, 0}; BSpline(3) = {2, 9, 3};")
    (tmp_path / "b.geo").write_text(geo + NAMES + 'Physical Curve("left") = {4};\n')
    (tmp_path / "s.toml").write_text(GEO_SCENE)
    scene = load_scene(str(tmp_path / "s.toml"))
    seg = scene.bodies[1].outline.part("bottom").segments[0]
    assert seg.is_spline and seg.start == (10.0, -20.0) and seg.end == (-10.0, -20.0)
    mesh = build_mesh(scene, 1)
    assert len(mesh.bodies[1].side_nodes("bottom")) > 2


def test_set_changes_one_item_of_an_outline_list():
    """``--set`` reaches into outline lists by index (from 0): one hole's radius, the ends of two
    parts; the rest of each list and item stays. An index past the end is one line."""
    s = load_scene("block-with-hole", [parse_assignment("bodies.bottom.holes.0.radius=1.0"),
                                       parse_assignment("bodies.bottom.outline.0.to=[10.0, -24.0]"),
                                       parse_assignment("bodies.bottom.outline.1.to=[-10.0, -24.0]")])
    bottom = next(b for b in s.bodies if b.name == "bottom").outline
    hole = bottom.holes[0].segments[0]
    assert hole.center == (0.0, -10.0) and math.dist(hole.start, hole.center) == 1.0
    assert [p.name for p in bottom.path] == ["right", "bottom", "left"]
    assert [p.segments[0].end for p in bottom.path] == [(10.0, -24.0), (-10.0, -24.0), (-10.0, 0.0)]
    with pytest.raises(cd.errors.SceneError, match="cannot change item '1' of 'holes'") as e:
        load_scene("block-with-hole", [parse_assignment("bodies.bottom.holes.1.radius=1.0")])
    assert "\n" not in str(e.value) and "numbered from 0" in str(e.value)


@pytest.mark.slow
def test_study_grid_over_an_outline(client, tmp_path):
    """A study's ``set`` grid over a number inside an outline list (here the hole's radius, by its
    index), as ``--set`` does: each case runs on its own mesh, both certified."""
    from cvxdual.study.runner import run
    (tmp_path / "g.toml").write_text(
        'name = "g"\nscenes = ["block-with-hole"]\nlevels = [1]\nsolvers = ["fast"]\nstress_spaces = ["eq"]\n'
        'reference = "none"\n[set]\n"bodies.bottom.holes.0.radius" = [0.5, 1.0]\n')
    df = run(str(tmp_path / "g.toml"), tmp_path / "out", client=client, cache=tmp_path / "cache", quiet=True)
    assert len(df) == 2 and (df.status == "optimal").all() and df.guaranteed.astype(bool).all()
    assert df.n_pieces.nunique() == 2  # two meshes


@pytest.mark.parametrize("scene", ["block-with-hole", "examples/roller-on-block.toml"])
def test_gap_counts_the_pieces_beyond_free_arcs(scene):
    """``G`` (the sum of its local terms) equals ``J(v) - lower``: the pieces beyond the free arcs,
    where the stress is zero and ``v`` continues, are terms of both. 1e-9 relative: the two sides
    sum the same terms in another order, plus the contact work (rounding of ~1e-12 seen)."""
    b = cd.solve(load_scene(scene), level=1, stress_space="eq", solver="fast").bounds
    assert len(b["contributions"]["continuation"]) and b["contributions"]["continuation"].min() >= 0
    assert b["gap"] == pytest.approx(b["energy_upper"] - b["energy_lower"], rel=1e-9)
