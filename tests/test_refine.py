"""Uniform refinement (cvxdual.geometry.refine): four similar triangles from each, the same
region, a conforming mesh, chosen new nodes moved, chosen edges kept whole, paths refined."""

import numpy as np
import pytest

from cvxdual.errors import MeshError
from cvxdual.geometry.refine import refine


def _square(n=3):
    """A structured mesh of the unit square: ``n * n`` cells, two triangles each (counter-clockwise)."""
    x = np.linspace(0.0, 1.0, n + 1)
    p = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    b, c, d = a + (n + 1), a + (n + 2), a + 1
    return p, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _areas(p, t):
    d1, d2 = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])


def _edge_uses(t):
    e = np.sort(np.stack([t, np.roll(t, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return counts


def test_four_similar_children_cover_the_parent():
    """Every triangle gives four of a quarter its area, counter-clockwise; nodes: the old ones
    first, then one per edge; interior edges are shared by two triangles, boundary edges by one
    (a hanging node would leave an edge used once inside). Areas to rounding (1e-15 of 1)."""
    p, t = _square()
    r = refine(p, t)
    assert len(r.triangles) == 4 * len(t)
    assert np.array_equal(r.points[:len(p)], p)
    n_edges = len(np.unique(np.sort(np.stack([t, np.roll(t, -1, axis=1)], -1).reshape(-1, 2), axis=1), axis=0))
    assert len(r.points) == len(p) + n_edges
    a = _areas(r.points, r.triangles)
    assert np.all(a > 0) and a.sum() == pytest.approx(1.0, abs=1e-15)
    assert np.allclose(np.sort(a), 1.0 / (2 * 9 * 4))  # all similar to their parents: one area here
    counts = _edge_uses(r.triangles)
    assert set(counts) == {1, 2} and (counts == 1).sum() == 2 * 4 * 3  # the boundary: 12 edges, halved


def test_whole_edges_are_not_split_and_moved_nodes_sit_where_asked():
    """An edge kept whole stays an edge (its triangle cut in three, no node on it); a moved new
    node sits exactly at its target, and the path through it is refined through that node."""
    p, t = _square(2)
    whole = np.array([[0, 3]])  # the bottom side's left half: (0, 0) - (0.5, 0)
    moved, to = np.array([[2, 5]]), np.array([[0.25, 1.05]])  # the top side's left half, pushed out
    r = refine(p, t, whole, moved, to)
    assert len(r.triangles) == 4 * len(t) - 1
    assert r.midpoints([0], [3])[0] == -1 and r.midpoints([3], [0])[0] == -1
    m = r.midpoints([5], [2])[0]
    assert np.array_equal(r.points[m], [0.25, 1.05])
    assert np.array_equal(r.chain([2, 5, 8]), [2, m, 5, r.midpoints([5], [8])[0], 8])
    assert np.all(_areas(r.points, r.triangles) > 0)
    # the region grew by the triangle under the pushed-out node: 0.5 * 0.5 * 0.05
    assert _areas(r.points, r.triangles).sum() == pytest.approx(1.0 + 0.5 * 0.5 * 0.05, abs=1e-15)
    e = np.sort(np.stack([r.triangles, np.roll(r.triangles, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    assert any((e == [0, 3]).all(axis=1))  # still one edge of the refined mesh


def test_a_triangle_with_two_whole_edges_is_refused():
    p, t = _square(1)
    with pytest.raises(MeshError, match="two edges"):
        refine(p, t, whole=np.array([[0, 1], [1, 3]]))


def test_a_node_moved_across_its_triangle_is_refused():
    """Moving the top side's new node below the cell's diagonal folds a child over: refused in
    one line, not returned as a mesh with a triangle turned inside out."""
    p, t = _square(1)
    with pytest.raises(MeshError, match="folds a triangle over") as e:
        refine(p, t, moved=np.array([[1, 3]]), to=np.array([[0.5, 0.2]]))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(("a1", "diagonal"), [((2.0, 0.0), (0, 4)), ((4.0, 3.0), (3, 2))])
def test_a_triangle_with_a_whole_edge_is_cut_along_the_shorter_diagonal(a1, diagonal):
    """Corners 0, 1, 2 with edge 2 -> 0 whole: the quadrilateral 0, m01 (node 3), m12 (node 4), 2
    is cut along its shorter diagonal (0 - m12 for the first shape, m01 - 2 for the second), which
    keeps the sharp corners of a wedge by the strip's side from getting sharper (the rounded
    punch's worst triangle: quality 0.30 with a fixed cut, 0.45 with this one)."""
    p = np.array([[0.0, 0.0], a1, [0.0, 1.0 if a1[1] else 3.0]])
    r = refine(p, np.array([[0, 1, 2]]), whole=np.array([[2, 0]]))
    assert len(r.triangles) == 3 and np.all(_areas(r.points, r.triangles) > 0)
    edges = {tuple(sorted(e)) for t in r.triangles for e in zip(t, np.roll(t, -1), strict=True)}
    other = (0, 4) if diagonal == (3, 2) else (3, 2)
    assert tuple(sorted(diagonal)) in edges and tuple(sorted(other)) not in edges
    assert _areas(r.points, r.triangles).sum() == pytest.approx(_areas(p, np.array([[0, 1, 2]]))[0], rel=1e-15)


def _punch_with_hole(gap, angle):
    """rounded-punch with a 0.2 square hole in the punch whose outer corner lies ``gap`` inside the free
    corner arc (radius 20 about (3, 20), from -30 to 0 degrees) at ``angle`` degrees."""
    import math
    import tomllib
    from pathlib import Path

    import cvxdual as cd

    data = tomllib.loads((Path(cd.__file__).parent / "scene" / "data" / "rounded-punch.toml").read_text())
    t = math.radians(angle)
    u, v = np.array([math.cos(t), math.sin(t)]), np.array([-math.sin(t), math.cos(t)])
    c = np.array([3.0, 20.0]) + (20.0 - gap) * u
    square = [c, c + 0.2 * v, c + 0.2 * v - 0.2 * u, c - 0.2 * u]  # counter-clockwise
    data["bodies"]["punch"]["holes"] = [{"name": "speck", "points": [[float(x), float(y)] for x, y in square]}]
    return cd.load_scene(data)


def test_a_hole_beyond_gmsh_s_coarser_polygon_is_meshed_at_the_level_itself():
    """Level 1 gives gmsh every other vertex of the free corner's polygon (15 degree chords, 0.171
    inside the arc at -7.5 degrees) and refines; a hole 0.1 inside the arc there lies across those
    chords though level 1's own polygon (a vertex at -7.5 degrees) keeps clear of it. gmsh left that
    surface empty and refinement asked for edges of a mesh without them ("internal: an edge asked of
    the refined mesh is not one of its edges", fuzz cases 168, 229, 242, 445): the body is now meshed
    at level 1 directly, and build_mesh's check of areas and coverage passes."""
    from cvxdual.geometry.mesh import build_mesh

    mesh = build_mesh(_punch_with_hole(0.1, -7.5), 1)
    punch = next(b for b in mesh.bodies if b.body.name == "punch")
    speck = punch.rest.parts["speck"]
    assert speck[0] == speck[-1] and len(speck) >= 5  # the hole's closed chain of nodes


def test_a_hole_across_the_level_s_own_polygon_is_refused_in_one_line():
    """A hole 0.005 inside the corner arc, in the middle of level 1's 7.5 degree chord (0.043 deep):
    no polygon of level 1 can bound the body. One line names both parts and a fix (fuzz case 226)."""
    from cvxdual.geometry.mesh import build_mesh

    with pytest.raises(MeshError) as e:
        build_mesh(_punch_with_hole(0.005, -3.75), 1)
    msg = str(e.value)
    assert "internal" not in msg and "\n" not in msg
    assert "hole 'speck'" in msg and "outline part 'corner'" in msg and "raise the level to" in msg


def test_a_mesh_refinement_would_fold_is_made_at_the_level_itself():
    """block-with-hole with a notch up from its bottom and a small hole by its corner (fuzz seed
    3939763642): at level 2 a node refinement places on the hole's circle crosses gmsh's coarser
    triangle ("refining the mesh folds a triangle over", refused before); the body is meshed at
    level 2's own sizes instead, and build_mesh's check of areas and coverage passes."""
    import cvxdual as cd
    from cvxdual.geometry.mesh import build_mesh

    bottom = {"outline": [{"name": "right", "to": [10.0, -20.0]}, {"name": "bottom", "to": [3.36556161353517, -20.0]},
                          {"name": "notch", "to": [3.36556161353517, -12.032644465586682]},
                          {"name": "notch_2", "to": [-0.7911676056682238, -12.032644465586682]},
                          {"name": "notch_3", "to": [-0.7911676056682238, -20.0]},
                          {"name": "bottom_2", "to": [-10.0, -20.0]}, {"name": "left", "to": [-10.0, 0.0]}],
              "holes": [{"name": "hole", "center": [7.376314772373342, -17.17548518380147],
                         "radius": 0.5013147723733423}]}
    data = cd.scene.scenefile.builtin_data("block-with-hole")
    data["bodies"]["bottom"].update(bottom)
    data["bodies"]["bottom"]["boundary"] = {k: v for k, v in data["bodies"]["bottom"]["boundary"].items()
                                            if v.get("on") in ("right", "left", "bottom_2", "face")}
    mesh = build_mesh(cd.load_scene(data), 2)
    block = next(b for b in mesh.bodies if b.body.name == "bottom")
    assert block.rest.parts["hole"][0] == block.rest.parts["hole"][-1]  # the hole's closed chain
