"""Every outline body's mesh is checked against its outline (cvxdual.geometry.mesh_check), and the
outline checks refuse what docs/scenes.md refuses (touching, nested, empty or retraced parts, bad
radii, a spline through a repeated point), each in one line."""

import math

import numpy as np
import pytest
from helpers import without_progress

import cvxdual as cd
from cvxdual.cli import main
from cvxdual.errors import MeshError, SceneError
from cvxdual.geometry import mesh_check
from cvxdual.geometry.mesh import build_mesh
from cvxdual.geometry.mesh_check import check_body_mesh
from cvxdual.scene import load_scene

PATCH = """base = "patch"
name = "patch-outline"
[bodies.top]
outline = [{name = "right", to = [10.0, 6.0]}, {name = "far", to = [0.0, 6.0]}, {name = "left", to = [0.0, 0.0]}]
[bodies.bottom]
outline = [{name = "right", to = [10.0, -4.0]}, {name = "far", to = [0.0, -4.0]}, {name = "left", to = [0.0, 0.0]}]
"""

# the outline scenes and their bodies' areas in closed form
AREAS = [
    ("block-with-hole", {"top": 80.0, "bottom": 400.0 - math.pi / 4}),  # 20 x 4; 20 x 20 less a circle of radius 0.5
    # 23 x 40 less the corner square 20 x 20 outside its quarter circle of radius 20; a 40 x 40 block
    ("rounded-punch", {"punch": 920.0 - (400.0 - 100.0 * math.pi), "block": 1600.0}),
    ("patch-outline", {"top": 60.0, "bottom": 40.0}),
    ("examples/hertz-outline.toml", {"cylinder": 900.0, "block": 900.0}),
    ("examples/roller-on-block.toml", {"cylinder": 1250.0 * math.pi}),  # the lower half of a disc of radius 50
    ("examples/wedge-on-rollers.toml", {"block": 276.0}),  # a trapezoid: sides 20 and 26, 12 high
]


def _scene(name, tmp_path):
    if name == "patch-outline":
        f = tmp_path / "patch-outline.toml"
        f.write_text(PATCH)
        name = str(f)
    return load_scene(name)


def _check(bm, points=None, tris=None, parts=None) -> None:
    """The check of body mesh ``bm``, on its own arrays or doctored ones."""
    check_body_mesh(bm.body, bm.points() if points is None else points,
                    bm.triangles() - bm.offset if tris is None else tris,
                    bm.side_nodes("face") - bm.offset, bm.rest.parts if parts is None else parts)


def _area(points, tris) -> float:
    p = points[tris]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return 0.5 * float(np.sum(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]))


@pytest.mark.parametrize(("name", "areas"), AREAS, ids=[a[0] for a in AREAS])
def test_outline_scenes_pass_the_check_with_their_exact_areas(name, areas, tmp_path):
    """build_mesh checks every outline body (it would raise); the check's exact areas are the
    closed forms (1e-12 relative: arcs and the face integrated exactly, only rounding differs)."""
    scene = _scene(name, tmp_path)
    for level in (0, 1, 2):
        mesh = build_mesh(scene, level)
        for bm in mesh.bodies:
            if bm.rest is None:
                continue
            assert mesh_check._area(bm.body) == pytest.approx(areas[bm.body.name], rel=1e-12)
            _check(bm)  # again, directly: it reads only


def test_kirsch_block_mesh_area_is_the_tangent_polygons():
    """The hole is a free arc: meshed as the polygon of the tangents at its 16 * 2^level chord ends,
    so the mesh's area is 400 - R^2 n tan(pi / n) (1e-12 relative: rounding of the triangle sums)."""
    scene = load_scene("block-with-hole")
    for level in (0, 1, 2):
        bm = build_mesh(scene, level).bodies[1]
        n = 16 * 2**level
        area = _area(bm.points(), bm.triangles() - bm.offset)
        assert area == pytest.approx(400.0 - 0.25 * n * math.tan(math.pi / n), rel=1e-12)


@pytest.mark.parametrize(("points", "area"), [([[-1, -11], [1, -11], [1, -9], [-1, -9]], 396.0),
                                              ([[-1, -11], [1, -11], [0, -9]], 398.0)], ids=["square", "triangle"])
def test_polygon_hole_crossed_by_a_cut_is_meshed_once(points, area):
    """A cut runs down x = 0 through the hole; its two halves went to the wrong sides (the square was
    meshed twice over: area 404; the triangle 402). Polygons are meshed exactly: 1e-12 relative."""
    scene = load_scene("block-with-hole", [{"bodies": {"bottom": {"holes": [{"name": "hole", "points": points}]}}}])
    for level in (0, 1, 2, 3):
        bm = build_mesh(scene, level).bodies[1]
        assert _area(bm.points(), bm.triangles() - bm.offset) == pytest.approx(area, rel=1e-12)


HOLE = 'base = "block-with-hole"\n[bodies.bottom]\n'
RIGHT, LEFT = '{name = "right", to = [10.0, -20.0]}', '{name = "left", to = [-10.0, 0.0]}'


def _holes(*holes) -> str:
    return HOLE + "holes = [" + ", ".join(holes) + "]\n"


def _outline(*parts) -> str:
    return HOLE + "outline = [" + ", ".join(parts) + "]\n"


REFUSED = [
    ("tangent holes", _holes('{name = "a", center = [0.0, -10.0], radius = 1.0}',
                             '{name = "b", center = [2.0, -10.0], radius = 1.0}'), "parts 'a' and 'b' cross or touch"),
    # tangent where neither circle has a sampled point: their polygons stay a sagitta apart
    ("tangent holes at 45 degrees", _holes('{name = "a", center = [0.0, -10.0], radius = 1.0}',
                                           '{name = "b", center = [1.4142135623730951, -8.585786437626905], '
                                           'radius = 1.0}'), "parts 'a' and 'b' cross or touch"),
    ("hole tangent to the bottom", _holes('{name = "a", center = [0.3, -19.0], radius = 1.0}'),
     "parts 'bottom' and 'a' cross or touch"),
    ("hole along the bottom", _holes('{name = "a", points = [[-1.0, -20.0], [1.0, -20.0], [1.0, -18.0], '
                                     '[-1.0, -18.0]]}'), "parts 'bottom' and 'a' cross or touch"),
    ("holes sharing a corner", _holes('{name = "a", points = [[-1.0, -11.0], [0.0, -11.0], [0.0, -10.0], '
                                      '[-1.0, -10.0]]}', '{name = "b", points = [[0.0, -10.0], [1.0, -10.0], '
                                      '[1.0, -9.0], [0.0, -9.0]]}'), "parts 'a' and 'b' cross or touch"),
    ("hole inside a hole", _holes('{name = "a", center = [0.0, -10.0], radius = 2.0}',
                                  '{name = "b", center = [0.0, -10.0], radius = 1.0}'), "'b' lies inside hole 'a'"),
    ("collinear hole", _holes('{name = "a", points = [[-1.0, -11.0], [0.0, -10.0], [1.0, -9.0]]}'),
     "encloses no area"),
    ("repeated corner", _holes('{name = "a", points = [[-1.0, -11.0], [1.0, -11.0], [1.0, -11.0], [0.0, -9.0]]}'),
     "repeats the point (1, -11)"),
    ("negative radius", _holes('{name = "a", center = [0.0, -10.0], radius = -1.0}'), "radius must be positive"),
    ("zero radius", _holes('{name = "a", center = [0.0, -10.0], radius = 0.0}'), "radius must be positive"),
    ("path out and back", _outline(RIGHT, '{name = "bottom", to = [0.0, -20.0]}', '{name = "spur", to = [0.0, -15.0]}',
                                   '{name = "back", to = [0.0, -20.0]}', '{name = "rest", to = [-10.0, -20.0]}', LEFT),
     "parts 'bottom' and 'back' cross or touch"),
    ("path past its corner and back", _outline(RIGHT, '{name = "bottom", to = [-10.0, -20.0]}',
                                               '{name = "out", to = [-15.0, -20.0]}',
                                               '{name = "in", to = [-10.0, -20.0]}', LEFT),
     "parts 'bottom' and 'in' cross or touch"),
    ("spline through a point twice", _outline(RIGHT, '{name = "bottom", to = [-10.0, -20.0], '
                                                     'through = [[0.0, -21.0], [0.0, -21.0]]}', LEFT),
     "passes through (0, -21) twice in a row"),
]


@pytest.mark.parametrize(("text", "words"), [c[1:] for c in REFUSED], ids=[c[0] for c in REFUSED])
def test_bad_outlines_are_refused_in_one_line(text, words, tmp_path, monkeypatch, capsys):
    _refused(tmp_path, monkeypatch, capsys, text, [], words)


def test_negative_radius_by_set_is_refused(tmp_path, monkeypatch, capsys):
    """The audit's route: the built-in hole's radius set to -1 on the command line (it was meshed as 1)."""
    _refused(tmp_path, monkeypatch, capsys, 'base = "block-with-hole"\n', ["--set", "bodies.bottom.holes.0.radius=-1"],
             "radius must be positive, got -1")


def _refused(tmp_path, monkeypatch, capsys, text, extra, words) -> None:
    """``cvxdual solve`` exits 1 with one error line holding ``words``."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text(text)
    rc = main(["solve", "--scene", "bad.toml", "--level", "1", "--no-output", *extra])
    err = without_progress(capsys.readouterr().err)
    assert rc == 1
    assert len(err) == 1 and err[0].startswith("cvxdual: error:") and words in err[0], err


def test_narrow_face_continued_by_a_large_arc_is_accepted():
    """The face's samples (1e-3 apart) lie closer to the flank's first chords than their sagitta
    (0.9^2 / 400 = 2e-3): consecutive parts need not keep clear by it, only by rounding."""
    w = 2.0
    y = 50.0 - math.sqrt(2500.0 - w * w)
    flanks = [{"name": "flank-right", "to": [50.0, 50.0], "center": [0.0, 50.0]}, {"name": "far", "to": [-50.0, 50.0]},
              {"name": "flank-left", "to": [-w, y], "center": [0.0, 50.0]}]
    scene = load_scene("examples/roller-on-block.toml", [{"bodies": {"cylinder": {"x": [-w, w], "outline": flanks}},
                                                          "contact": {"interval": [-1.8, 1.8]}}])
    assert scene.bodies[0].outline.names == ("flank-right", "far", "flank-left")


def test_api_refuses_bad_holes():
    from cvxdual.scene.outline import circle

    with pytest.raises(SceneError, match="radius must be positive"):
        circle("h", (0.0, 0.0), -1.0)


@pytest.fixture(scope="module")
def kirsch():
    """block-with-hole's lower body at level 1."""
    return build_mesh(load_scene("block-with-hole"), 1).bodies[1]


def test_check_finds_a_missing_triangle(kirsch):
    tris = kirsch.triangles() - kirsch.offset
    edge = np.concatenate([kirsch.side_nodes("face") - kirsch.offset, *kirsch.rest.parts.values()])
    inner = np.flatnonzero(~np.isin(tris, edge).any(axis=1))  # a triangle with no node on the boundary
    with pytest.raises(MeshError, match="a region of the body is missing"):
        _check(kirsch, tris=np.delete(tris, inner[len(inner) // 2], axis=0))


def test_check_finds_a_doubled_triangle(kirsch):
    tris = kirsch.triangles() - kirsch.offset
    with pytest.raises(MeshError, match="covers a region twice"):
        _check(kirsch, tris=np.concatenate([tris, tris[len(tris) // 2:][:1]]))


def test_check_finds_a_filled_hole(kirsch):
    """A fan of triangles from the hole's centre over its polygon: the hole's edges turn interior."""
    points, tris = kirsch.points(), kirsch.triangles() - kirsch.offset
    ring = kirsch.rest.parts["hole"]
    fan = np.stack([np.full(len(ring) - 1, len(points)), ring[1:], ring[:-1]], 1)
    filled = np.concatenate([points, [[0.0, -10.0]]])
    if _area(filled, fan) < 0:
        fan = fan[:, ::-1]
    with pytest.raises(MeshError, match="outline part 'hole' is not on the mesh's boundary"):
        _check(kirsch, points=filled, tris=np.concatenate([tris, fan]))
    # the hole's own test, alone: its centre is covered
    tx, ty = filled[:, 0][fan], filled[:, 1][fan]
    allow = np.full(1, 1e-3)  # any allowance far below the hole's radius 0.5
    with pytest.raises(MeshError, match="hole 'hole' is meshed over"):
        mesh_check._holes_empty("body 'bottom'", tx, ty, kirsch.body.outline, allow, np.array([3]), ["right", "bottom",
                                                                                                      "left", "hole"])


def test_check_finds_a_node_off_its_part(kirsch):
    points = kirsch.points().copy()
    bottom = kirsch.rest.parts["bottom"]
    points[bottom[len(bottom) // 2], 1] -= 0.01  # off the straight bottom: its allowance is rounding (1e-8 here)
    with pytest.raises(MeshError, match="on outline part 'bottom' lies 0.01 off it"):
        _check(kirsch, points=points)


def test_check_finds_a_wrong_area(kirsch, monkeypatch):
    """Regions meshed twice over whole (the square hole's bug: 8 too much) keep the boundary right:
    only the area tells. 0.05 off is beyond the slack at level 1 (6e-3: the hole's tangent polygon
    differs from the circle by 2.5e-3, bounded by its edges' offsets and bulges)."""
    exact = mesh_check._area(kirsch.body)
    monkeypatch.setattr(mesh_check, "_area", lambda body: exact + 0.05)
    with pytest.raises(MeshError, match="is not the body's"):
        _check(kirsch)


def test_a_level_is_not_refused_for_its_coarser_size_probe():
    """The size estimate meshes an outline body at a coarser probe level (at most 32 columns); a
    hole 0.4 under the face meets that level's strip (0.625 deep at level 2) but not level 3's: the
    probe climbs to the level that meshes, so level 3 solves (it was refused by the probe) and its
    contact force is the applied load (to rounding: 1e-9 relative)."""
    d = cd.scene.scenefile.builtin_data("block-with-hole")
    d["bodies"]["bottom"]["holes"] = [{"name": "hole", "center": [0.3, -0.6], "radius": 0.2}]
    scene = cd.load_scene(d)
    with pytest.raises(cd.MeshError, match="strip of columns"):
        build_mesh(scene, 2)
    assert cd.solve(scene, level=3, solver="fast").contact["total_force"] == pytest.approx(2000.0, rel=1e-9)
