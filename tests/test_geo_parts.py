"""``.geo`` bodies on a par with scene-file outlines (issue 39): sizes in the file are refused (or,
for a point's size, accepted and not read) with the reason; a ``geo`` body replaces a base's body
geometry; a face of several lines and arcs is a composite face; a face arc of either branch is
taken as a scene file's circle face is. Each ``.geo`` twin gives its scene-file body's mesh and
results."""

from __future__ import annotations

import copy
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_outline_split import part_dict  # a punch with a composite face on a block

import cvxdual
from cvxdual.errors import SceneError
from cvxdual.geometry.mesh import build_mesh
from cvxdual.scene import load_scene
from cvxdual.scene.geo import read_geo
from cvxdual.scene.geo_lang import parse_geo
from cvxdual.scene.piecewise import Composite
from cvxdual.scene.profiles import LowerCircle, UpperCircle
from cvxdual.scene.scenefile import builtin_data

ROOT = Path(__file__).resolve().parents[1]
BLOCK = """Point(1) = {10, 0, 0}; Point(2) = {10, -20, 0}; Point(3) = {-10, -20, 0}; Point(4) = {-10, 0, 0};
Line(1) = {4, 1}; Line(2) = {1, 2}; Line(3) = {2, 3}; Line(4) = {3, 4};
Physical Curve("face") = {1}; Physical Curve("right") = {2}; Physical Curve("bottom") = {3};
Physical Curve("left") = {4};
"""
# the same objective and force from a .geo twin: the meshes agree to a few ulps (gmsh's nodes move
# by 4e-15 where a scene file's outline starts at face.value(x1), one ulp off the typed point), and
# the solver's answers to its own rounding, 1e-14-1e-13 seen; 1e-10 leaves room for another BLAS
RESULTS = 1e-10


def twin(tmp_path, monkeypatch, data: dict, body: str, geo: str):
    """The scene ``data`` and the same scene with body ``body`` drawn in a .geo file instead."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "b.geo").write_text(geo)
    other = copy.deepcopy(data)
    b = other["bodies"][body]
    for k in ("x", "far", "face", "outline", "holes"):
        b.pop(k, None)
    b["geo"] = "b.geo"
    return load_scene(data), load_scene(other)


def same_mesh(a, b, levels) -> None:
    for level in levels:
        ma, mb = build_mesh(a, level), build_mesh(b, level)
        assert np.array_equal(ma.triangles(), mb.triangles())
        # 1e-12 of the scene's size: gmsh's nodes moved by a few ulps (see RESULTS)
        assert np.allclose(ma.points, mb.points, rtol=0, atol=1e-12 * a.length_scale)


def same_results(a, b, levels) -> None:
    for level in levels:
        sa, sb = (cvxdual.solve(s, level=level, solver="fast") for s in (a, b))
        assert len(sa.pieces.kind) == len(sb.pieces.kind)
        assert sb.objective == pytest.approx(sa.objective, rel=RESULTS)
        assert sb.contact["total_force"] == pytest.approx(sa.contact["total_force"], rel=RESULTS)


# -- sizes in the file: refused with the [mesh] keys to use, a point's size accepted unread ----------

@pytest.mark.parametrize("statement,name", [
    ("Mesh.CharacteristicLengthMax = 1;", "Mesh.CharacteristicLengthMax"),
    ("Mesh.MeshSizeFactor = 0.5;", "Mesh.MeshSizeFactor"),
    ("Mesh.Algorithm = 5;", "Mesh.Algorithm"),
    ("Characteristic Length {1, 2} = 0.5;", "Characteristic Length"),
    ("MeshSize {1, 2} = 0.5;", "MeshSize"),
    ("Field[1] = Distance;", "Field"),
    ("Background Field = 1;", "Background Field"),
    ("Transfinite Curve {1} = 10;", "Transfinite Curve"),
    ("Recombine Surface {1};", "Recombine Surface"),
])
def test_size_statements_are_refused_naming_the_mesh_keys(statement, name):
    with pytest.raises(SceneError) as e:
        parse_geo(BLOCK + statement, "bodies.bottom")
    msg = str(e.value)
    assert f"line 5: {name!r} is not allowed in a .geo outline; cvxdual sizes the mesh itself" in msg, msg
    assert "[mesh] columns, focus and grading" in msg and "\n" not in msg and len(msg) < 300


def test_a_point_size_is_accepted_and_not_read(tmp_path):
    """``Point(t) = {x, y, 0, lc}``: the body and its mesh are those without ``lc`` (the sizes are
    cvxdual's, a family that halves a level: docs/scenes.md)."""
    plain, sized = tmp_path / "a.geo", tmp_path / "b.geo"
    plain.write_text(BLOCK)
    sized.write_text(BLOCK.replace(", 0};", ", 0, 0.01};"))
    assert sized.read_text().count("0.01") == 4
    assert read_geo(plain, "lower", "b") == read_geo(sized, "lower", "b")


# -- a geo body through base: it replaces the base body's geometry, keeps the rest --------------------

def test_geo_replaces_a_base_outline_body(tmp_path):
    """``base = "block-with-hole"`` and the block drawn in a .geo: the built-in's body (x, face,
    outline, holes replaced; material and supports kept), mesh and objective, bit for bit."""
    shutil.copy(ROOT / "examples" / "block-with-hole.geo", tmp_path / "block.geo")
    (tmp_path / "s.toml").write_text('base = "block-with-hole"\n[bodies.bottom]\ngeo = "block.geo"\n')
    ours, builtin = load_scene(str(tmp_path / "s.toml")), load_scene("block-with-hole")
    assert ours.bodies == builtin.bodies
    a, b = build_mesh(ours, 1), build_mesh(builtin, 1)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.triangles(), b.triangles())


LOWER = BLOCK.replace("-20", "-10").replace('"bottom"', '"far"')  # blocks' lower block, its bottom named far


def test_geo_replaces_a_base_column_body(tmp_path, monkeypatch):
    """``base = "blocks"`` (column bodies: x, far, face) and its lower block drawn in a .geo whose
    bottom part is named ``far``: the base's supports and load (on left, right, far) and material
    apply to the outline body; the contact force is the load. A --set of geo does the same."""
    (tmp_path / "lower.geo").write_text(LOWER)
    (tmp_path / "s.toml").write_text('base = "blocks"\n[bodies.lower]\ngeo = "lower.geo"\n')
    ours, base = load_scene(str(tmp_path / "s.toml")), load_scene("blocks")
    lo, blo = ours.bodies[1], base.bodies[1]
    assert not lo.is_column and blo.is_column
    assert (lo.x_range, lo.material, lo.boundary) == (blo.x_range, blo.material, blo.boundary)
    assert lo.outline.part("far").segments[0].start == (10.0, -10.0)
    monkeypatch.chdir(tmp_path)
    assert load_scene("blocks", overrides=[{"bodies": {"lower": {"geo": "lower.geo"}}}]).bodies == ours.bodies
    sol = cvxdual.solve(ours, level=1, solver="fast")
    # 1e-9: blocks' push, 50 MPa over 20 mm, carried to the equilibrium residual (1e-14 of it)
    assert sol.contact["total_force"] == pytest.approx(50.0 * 20.0, rel=1e-9)


def test_geo_with_geometry_keys_in_the_same_file_is_still_refused(tmp_path):
    (tmp_path / "lower.geo").write_text(LOWER)
    (tmp_path / "s.toml").write_text('base = "blocks"\n[bodies.lower]\ngeo = "lower.geo"\nx = [-10.0, 10.0]\n')
    with pytest.raises(SceneError, match=r"give either geo \(the body's whole boundary\) or x, not both"):
        load_scene(str(tmp_path / "s.toml"))


# -- a composite face: lines and arcs end to end ------------------------------------------------------

PUNCH_GEO = """// a punch: a flat with rounded corners (a composite face) and rounded shoulders
yc = 2.683375209644599;  // 6 - Sqrt(25 - 1), typed as the scene file's
Point(1) = {-9, yc, 0}; Point(2) = {-4, 0, 0}; Point(3) = {4, 0, 0}; Point(4) = {9, yc, 0};
Point(5) = {-4, 6, 0}; Point(6) = {4, 6, 0};
Point(7) = {10, 6, 0}; Point(8) = {10, 20, 0}; Point(9) = {-10, 20, 0}; Point(10) = {-10, 6, 0};
Circle(1) = {1, 5, 2}; Line(2) = {2, 3}; Circle(3) = {3, 6, 4};
Circle(4) = {4, 6, 7}; Line(5) = {7, 8}; Line(6) = {8, 9}; Line(7) = {9, 10}; Circle(8) = {10, 5, 1};
Physical Curve("face") = {3, 1, 2};  // in any order: chained from the left end
Physical Curve("corner-right") = {4}; Physical Curve("right") = {5}; Physical Curve("top") = {6};
Physical Curve("left") = {7}; Physical Curve("corner-left") = {8};
"""


def _punch_on_block() -> dict:
    return part_dict()  # the scene file PUNCH_GEO's punch is drawn from


def test_composite_face_twin(tmp_path, monkeypatch):
    """The punch drawn in a .geo (its face three curves: arc, line, arc) is the scene file's
    composite-face punch: the same profile, mesh (levels 0-2) and results (levels 1-2)."""
    toml, geo = twin(tmp_path, monkeypatch, _punch_on_block(), "punch", PUNCH_GEO)
    assert isinstance(geo.bodies[0].face, Composite) and geo.bodies[0].face == toml.bodies[0].face
    assert geo.bodies[0].x_range == toml.bodies[0].x_range == (-9.0, 9.0)
    same_mesh(toml, geo, (0, 1, 2))
    same_results(toml, geo, (1, 2))


@pytest.mark.parametrize("change", [
    # a gap: the flat ends at (3, 0), short of the arc from (4, 0)
    ("Line(2) = {2, 3};", "Point(11) = {3, 0, 0}; Line(2) = {2, 11};"),
    # a fork: a third face curve leaves (-4, 0)
    ("Line(2) = {2, 3};", "Point(11) = {-4, -1, 0}; Line(2) = {2, 3}; Line(9) = {2, 11};"),
])
def test_face_curves_that_are_not_one_chain_are_refused(tmp_path, change):
    text = PUNCH_GEO.replace(*change)
    if "Line(9)" in text:
        text = text.replace('Physical Curve("face") = {3, 1, 2};', 'Physical Curve("face") = {3, 1, 2, 9};')
    (tmp_path / "b.geo").write_text(text)
    with pytest.raises(SceneError, match=r"b\.geo: the face's [34] curves do not run end to end in one chain") as e:
        read_geo(tmp_path / "b.geo", "upper", "b")
    assert "\n" not in str(e.value)


def test_a_composite_face_that_runs_back_is_refused(tmp_path):
    """A face chained end to end that is not a graph y = f(x) (it turns back): the composite
    profile's own rule, named for the .geo."""
    geo = """Point(1) = {-10, 0, 0}; Point(2) = {2, 0, 0}; Point(3) = {-2, 0.5, 0}; Point(4) = {10, 0.5, 0};
Point(5) = {10, 10, 0}; Point(6) = {-10, 10, 0};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 5}; Line(5) = {5, 6}; Line(6) = {6, 1};
Physical Curve("face") = {1, 2, 3}; Physical Curve("right") = {4}; Physical Curve("top") = {5};
Physical Curve("left") = {6};
"""
    (tmp_path / "b.geo").write_text(geo)
    with pytest.raises(SceneError, match=r"b\.geo: the face: the pieces must run left to right"):
        read_geo(tmp_path / "b.geo", "upper", "b")


def test_a_slanted_face_line_is_a_composite_face(tmp_path):
    """One slanted line: a composite face of one piece, as ``{ kind = "composite" }`` takes it."""
    (tmp_path / "b.geo").write_text(BLOCK.replace("Point(4) = {-10, 0, 0}", "Point(4) = {-10, 1, 0}"))
    face, x, _ = read_geo(tmp_path / "b.geo", "lower", "b")
    assert face == Composite(((-10.0, 1.0), (10.0, 0.0)), (None,)) and x == (-10.0, 10.0)


# -- a face arc of either branch, composite arcs on either side: as in a scene file -------------------

YR = 52.0 - math.sqrt(52.0**2 - 25.0**2)  # the groove's face at x = +-25
GROOVE_GEO = """// cylinder-in-groove's groove as an outline body: a concave arc (the lower branch) over a lower body
yr = 52 - Sqrt(52^2 - 25^2);
Point(1) = {-25, yr, 0}; Point(2) = {25, yr, 0}; Point(3) = {0, 52, 0};
Point(4) = {25, -20, 0}; Point(5) = {-25, -20, 0};
Circle(1) = {1, 3, 2}; Line(2) = {2, 4}; Line(3) = {4, 5}; Line(4) = {5, 1};
Physical Curve("face") = {1}; Physical Curve("right") = {2}; Physical Curve("bottom") = {3};
Physical Curve("left") = {4};
"""


def test_groove_twin(tmp_path, monkeypatch):
    """A groove's face (a lower body under the lower branch: concave) was refused in a .geo as 'not
    a graph' while the scene file's circle face solves: now both give one body, mesh and result."""
    d = builtin_data("cylinder-in-groove")
    d["mesh"]["default_level"] = 1
    g = d["bodies"]["groove"]
    for k in ("far", "layers", "focus_depth"):
        del g[k]
    g["outline"] = [{"name": "right", "to": [25.0, -20.0]}, {"name": "bottom", "to": [-25.0, -20.0]},
                    {"name": "left", "to": [-25.0, YR]}]
    g["boundary"] = {"left": {"on": "left", "kind": "sliding"}, "right": {"on": "right", "kind": "sliding"},
                     "push": {"on": "bottom", "kind": "traction", "traction": {"value": [0.0, 150.0]}}}
    toml, geo = twin(tmp_path, monkeypatch, d, "groove", GROOVE_GEO)
    assert isinstance(geo.bodies[1].face, LowerCircle) and geo.bodies[1].face == toml.bodies[1].face
    same_mesh(toml, geo, (0, 1, 2))
    same_results(toml, geo, (1,))


Y8 = -12.0 + math.sqrt(144.0 - 64.0)  # the cap's face at x = +-8
CAP = {  # an upper body over a bump, its face the upper branch (concave for it), on a bump (convex)
    "name": "cap-on-bump", "units": ["mm", "MPa"], "mesh": {"columns": 8},
    "bodies": {
        "cap": {"position": "upper", "x": [-8.0, 8.0], "face": {"kind": "circle", "R": 12.0, "xc": 0.0, "yc": -12.0,
                                                               "branch": "upper"},
                "material": {"E": 70000.0, "nu": 0.3},
                "outline": [{"name": "right", "to": [8.0, 5.0]}, {"name": "top", "to": [-8.0, 5.0]},
                            {"name": "left", "to": [-8.0, Y8]}],
                "boundary": {"press": {"on": "top", "kind": "traction", "traction": {"value": [0.0, -50.0]}}}},
        "bump": {"position": "lower", "x": [-8.0, 8.0], "far": -20.0,
                 "face": {"kind": "circle", "R": 10.0, "xc": 0.0, "yc": -10.0, "branch": "upper"},
                 "material": {"E": 210000.0, "nu": 0.3},
                 "boundary": {"base": {"on": "far", "kind": "clamped"}}}}}
CAP_GEO = """y8 = -12 + Sqrt(144 - 64);
Point(1) = {-8, y8, 0}; Point(2) = {8, y8, 0}; Point(3) = {0, -12, 0}; Point(4) = {8, 5, 0}; Point(5) = {-8, 5, 0};
Circle(1) = {2, 3, 1}; Line(2) = {2, 4}; Line(3) = {4, 5}; Line(4) = {5, 1};
Physical Curve("face") = {1}; Physical Curve("right") = {2}; Physical Curve("top") = {3};
Physical Curve("left") = {4};
"""


def test_cap_over_a_bump_twin(tmp_path, monkeypatch):
    """An upper body whose face is the upper branch (it sits over a bump): refused in a .geo before,
    as the other branch for that body; the same body, mesh and result as the scene file's."""
    toml, geo = twin(tmp_path, monkeypatch, CAP, "cap", CAP_GEO)
    assert isinstance(geo.bodies[0].face, UpperCircle) and geo.bodies[0].face == toml.bodies[0].face
    same_mesh(toml, geo, (0, 1, 2))
    same_results(toml, geo, (1,))
    sol = cvxdual.solve(geo, level=1, solver="fast")
    # 1e-9: the cap's load, 50 MPa over 16 mm, to the equilibrium residual (1e-14 of it)
    assert sol.contact["total_force"] == pytest.approx(50.0 * 16.0, rel=1e-9)


ROUND_GROOVE = {  # a lower body with a rounded groove in its flat: a composite face with a concave arc
    "name": "roll-in-groove", "units": ["mm", "MPa"], "mesh": {"columns": 8},
    "bodies": {
        "roll": {"position": "upper", "x": [-10.0, 10.0], "far": 12.0,
                 "face": {"kind": "circle", "R": 12.5, "xc": 0.0, "yc": 11.5, "branch": "lower"},
                 "material": {"E": 210000.0, "nu": 0.3},
                 "boundary": {"press": {"on": "far", "kind": "traction", "traction": {"value": [0.0, -50.0]}}}},
        "plate": {"position": "lower", "x": [-20.0, 20.0],
                  "face": {"kind": "composite", "start": [-20.0, 0.0],
                           "pieces": [{"to": [-5.0, 0.0]}, {"to": [5.0, 0.0], "center": [0.0, 12.0]},
                                      {"to": [20.0, 0.0]}]},
                  "material": {"E": 70000.0, "nu": 0.3},
                  "outline": [{"name": "right", "to": [20.0, -20.0]}, {"name": "bottom", "to": [-20.0, -20.0]},
                              {"name": "left", "to": [-20.0, 0.0]}],
                  "boundary": {"base": {"on": "bottom", "kind": "clamped"}}}}}
ROUND_GROOVE_GEO = """Point(1) = {-20, 0, 0}; Point(2) = {-5, 0, 0}; Point(3) = {5, 0, 0}; Point(4) = {20, 0, 0};
Point(5) = {0, 12, 0}; Point(6) = {20, -20, 0}; Point(7) = {-20, -20, 0};
Line(1) = {1, 2}; Circle(2) = {2, 5, 3}; Line(3) = {3, 4}; Line(4) = {4, 6}; Line(5) = {6, 7}; Line(6) = {7, 1};
Physical Curve("face") = {1, 2, 3}; Physical Curve("right") = {4}; Physical Curve("bottom") = {5};
Physical Curve("left") = {6};
"""


def test_composite_face_with_a_concave_arc_twin(tmp_path, monkeypatch):
    """A composite face's arc may lie on either side of its body (a groove's arc dips below the
    flat, concave for the lower body) as long as it does not cross its centre's height."""
    toml, geo = twin(tmp_path, monkeypatch, ROUND_GROOVE, "plate", ROUND_GROOVE_GEO)
    assert isinstance(geo.bodies[1].face, Composite) and geo.bodies[1].face == toml.bodies[1].face
    same_mesh(toml, geo, (0, 1, 2))
    same_results(toml, geo, (1,))
