"""Refinement in place of an outline body's gmsh part (cvxdual.geometry.outline.in_place): the local
red-green cut conforms and keeps area and orientation; a body refined in place is the same body
(its mesh and the pieces beyond its free arcs cover what they covered), passes every check of a
mesh and is finer where asked; where in place cannot be done gmsh meshes the body; a run to a
tolerance alternates gmsh and in place. The patch test and the paired structure on such meshes
are in test_adaptive.py (its refined grids alternate the same way)."""

from __future__ import annotations

import numpy as np
import pytest

import cvxdual
from cvxdual.adapt.outline_view import outline_scene
from cvxdual.cli import main
from cvxdual.geometry.grid import InPlace
from cvxdual.geometry.refine import refine_edges
from cvxdual.geometry.triangles import doubled_areas, edge_keys, least_angles
from cvxdual.geometry.triangulation import discretize, uniform_grid
from cvxdual.kinds import Meshed
from cvxdual.pipeline import as_scene

ROUNDING = 1e-12  # areas are sums of ~1e3 products of O(1) coordinates: rounding only


def _square_mesh(n):
    x = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(x, x, indexing="ij")
    P = np.stack([X.ravel(), Y.ravel()], 1)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
    return P, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def test_refine_edges_conforms_and_keeps_area():
    P, T = _square_mesh(6)
    e = np.stack([T, np.roll(T, -1, axis=1)], -1).reshape(-1, 2)
    rng = np.random.default_rng(0)
    pick = e[rng.random(len(e)) < 0.25]  # any pattern: triangles with 0, 1, 2 and 3 halved edges
    ref = refine_edges(P, T, pick)
    halved = np.isin(edge_keys(e[:, 0], e[:, 1], len(P)), edge_keys(pick[:, 0], pick[:, 1], len(P))).reshape(-1, 3)
    assert set(halved.sum(1)) == {0, 1, 2, 3}
    assert len(ref.triangles) == len(T) + int(halved.sum())  # a triangle with k halved edges gives k + 1
    area = doubled_areas(ref.points, ref.triangles)
    assert np.all(area > 0)  # orientation kept, nothing flat
    assert abs(0.5 * area.sum() - 1.0) < ROUNDING
    # conforming: an edge with one triangle lies on the square's boundary (a hanging node would leave one inside)
    t = ref.triangles
    k = np.sort(edge_keys(t, np.roll(t, -1, axis=1), len(ref.points)).ravel())
    once = np.setdiff1d(k, k[np.flatnonzero(k[1:] == k[:-1])])
    a, b = ref.points[once // len(ref.points)], ref.points[once % len(ref.points)]
    on_side = lambda p: (np.minimum(p, 1.0 - p) < ROUNDING).any(axis=1)  # noqa: E731
    assert np.all(on_side(a) & on_side(b) & ((np.abs(a - b) < ROUNDING).any(axis=1)))


def _covered(mesh, pieces, k):
    """Body ``k``'s pieces' area (the curved ones' exact) and the exact area of its pieces beyond free arcs."""
    _, _, body = mesh.continuation()
    return float(pieces.area[pieces.body == k].sum()), float(mesh.continuation_rule().weights[body == k].sum())


# a hole's corners (block-with-hole's thin upper body is meshed by gmsh: test_a_body_that_would_thin_is_meshed_by_gmsh);
# a fillet's segments and the strip's chain following new columns
@pytest.mark.parametrize("name, split, how", [("block-with-hole", 0.0, (Meshed.GMSH, Meshed.IN_PLACE)),
                                              ("rounded-punch", 0.3, (Meshed.IN_PLACE, Meshed.IN_PLACE))])
def test_a_body_refined_in_place_is_the_same_body(name, split, how):
    scene = outline_scene(as_scene(name))
    grid = uniform_grid(scene, 0)
    mesh, old, _ = discretize(scene, "type2", grid)
    rng = np.random.default_rng(1)
    tris = tuple(rng.random(len(bm.rest.triangles)) < 0.3 for bm in mesh.bodies)
    arcs = tuple(np.ones(len(bm.rest.virtual_weight), bool) for bm in mesh.bodies)
    cols = rng.random(len(grid.columns) - 1) < split
    fine = grid.refined(scene, cols, tuple(np.zeros((0, 3)) for _ in mesh.bodies),
                        InPlace(mesh.bodies, tris, arcs, grid.spots))
    new, pieces, _ = discretize(scene, "type2", fine)  # every check of a mesh runs here (strip, pairs, region)
    assert tuple(bm.meshed for bm in new.bodies) == how
    up, lo = new.pairs.T
    assert np.array_equal(new.points[up, 0], new.points[lo, 0])
    for k, bm in enumerate(mesh.bodies):
        before, after = _covered(mesh, old, k), _covered(new, pieces, k)
        # the body is what it was: the mesh grows into the pieces beyond the arcs by what they lose
        assert abs(sum(after) - sum(before)) < 1e-12 * sum(before)
        n = len(bm.rest.virtual_weight)
        assert len(new.bodies[k].rest.virtual_weight) == 2 * n  # every piece halved
        if n:
            assert after[1] < 0.5 * before[1]  # a piece halved keeps about a quarter of its area (a fillet: an eighth)
        if how[k] is Meshed.IN_PLACE:  # a marked triangle gives at least four
            assert len(new.bodies[k].rest.triangles) >= len(bm.rest.triangles) + 3 * int(tris[k].sum())
        # shape kept: bisection by longest edges keeps at least half the smallest angle (Rosenberg and Stenger);
        # a closure that cut the edge facing a small angle halved it again every cycle (11 degrees, seen)
        least = [
            least_angles(m.points[b.offset + b.rest.triangles]).min()
            for m, b in ((mesh, bm), (new, new.bodies[k]))]
        assert least[1] >= 0.5 * least[0]
    assert np.all(pieces.area > 0)


def test_a_body_that_would_thin_is_meshed_by_gmsh():
    """block-with-hole's upper body beyond its strip is one row of triangles whose longest edges lie on
    the strip's chain, which only a column's split halves: a closure would halve their smaller angles."""
    scene = outline_scene(as_scene("block-with-hole"))
    grid = uniform_grid(scene, 0)
    mesh, _, _ = discretize(scene, "type2", grid)
    rng = np.random.default_rng(1)
    tris = tuple(rng.random(len(bm.rest.triangles)) < 0.3 for bm in mesh.bodies)
    arcs = tuple(np.zeros(len(bm.rest.virtual_weight), bool) for bm in mesh.bodies)
    new, _, _ = discretize(scene, "type2", grid.refined(scene, np.zeros(len(grid.columns) - 1, bool),
                                                         (np.zeros((0, 3)),) * 2,
                                                         InPlace(mesh.bodies, tris, arcs, grid.spots)))
    assert [bm.meshed for bm in new.bodies] == [Meshed.GMSH, Meshed.IN_PLACE]
    for old, bm in zip(mesh.bodies, new.bodies, strict=True):
        assert least_angles(new.points[bm.offset + bm.rest.triangles]).min() >= 0.5 * least_angles(
            mesh.points[old.offset + old.rest.triangles]).min()


def test_columns_halved_twice_are_meshed_by_gmsh():
    scene = outline_scene(as_scene("block-with-hole"))
    grid = uniform_grid(scene, 0)
    mesh, _, _ = discretize(scene, "type2", grid)
    none = tuple(np.zeros(len(bm.rest.triangles), bool) for bm in mesh.bodies)
    arcs = tuple(np.zeros(len(bm.rest.virtual_weight), bool) for bm in mesh.bodies)
    cols = np.zeros(len(grid.columns) - 1, bool)
    cols[len(cols) // 2] = True
    once = grid.refined(scene, cols, (np.zeros((0, 3)),) * 2, InPlace(mesh.bodies, none, arcs, grid.spots))
    twice = once.refined(scene, np.isin(np.arange(len(once.columns) - 1), [len(cols) // 2, len(cols) // 2 + 1]),
                         (np.zeros((0, 3)),) * 2, InPlace(mesh.bodies, none, arcs, grid.spots))
    m1, _, _ = discretize(scene, "type2", once)
    m2, _, _ = discretize(scene, "type2", twice)  # one old interval now holds three new columns
    assert all(bm.meshed is Meshed.IN_PLACE for bm in m1.bodies)
    assert all(bm.meshed is Meshed.GMSH for bm in m2.bodies)


def test_a_run_alternates_gmsh_and_in_place():
    sol = cvxdual.solve("cylinder-on-block", triangulation="type2", tol=0.03)
    meshed = [c.meshed for c in sol.adaptive.cycles]
    assert len(meshed) >= 3
    assert all(m == (Meshed.GMSH,) * 2 if i % 2 == 0 else m == (Meshed.IN_PLACE,) * 2 for i, m in enumerate(meshed))
    assert sol.adaptive.met and sol.bounds["guaranteed"]


def test_the_progress_says_which_cycles_were_refined_in_place(capsys):
    assert main(["solve", "--scene", "block-with-hole", "--triangulation", "type2", "--tol", "1%", "--no-output"]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ": cycle " in ln]
    assert len(lines) == 2 and "in place" not in lines[0] and "(refined in place)" in lines[1]
