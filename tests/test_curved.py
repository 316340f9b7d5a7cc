"""Curved faces: the two triangulations' pieces, geometry and V_h (issue: curved arcs)."""

import numpy as np
import pytest
from helpers import contains

import cvxdual as cd
from cvxdual.geometry.locate import locate
from cvxdual.geometry.triangulation import discretize, stretches
from cvxdual.scene import BoundaryPart, Traction
from cvxdual.system.assembly import assemble
from cvxdual.system.boundary import side_quadrature

CURVED = ["cylinder-on-block", "cylinder-in-groove", "wavy"]
CASES = [(s, t, L) for s in CURVED for t in ("type1", "type2") for L in (0, 1, 2)]


def body_area(body):
    x0, x1 = body.x_range
    return abs(body.far * (x1 - x0) - float(body.face.integral(x0, x1)))


@pytest.mark.parametrize("scene,tri,level", CASES)
def test_pieces_tile_each_body(scene, tri, level):
    sc = cd.load_scene(scene)
    mesh, pieces, _ = discretize(sc, tri, level)
    for k, body in enumerate(sc.bodies):
        a = pieces.area[pieces.body == k].sum()
        # exact areas (closed-form arc integrals): only rounding of O(n) terms remains
        assert a == pytest.approx(body_area(body), rel=1e-12)
        assert np.all(pieces.area[pieces.body == k] > 0)
    # random points of each body lie in exactly one piece, and locate() finds it
    rng = np.random.default_rng(level)
    for k, body in enumerate(sc.bodies):
        x = rng.uniform(*body.x_range, 400)
        f = body.face.value(x)
        # half the points within a thin strip along the face, where the curved pieces are
        frac = np.where(np.arange(400) % 2 == 0, rng.uniform(0, 1, 400), rng.uniform(0, 0.02, 400) ** 2)
        pts = np.stack([x, f + (body.far - f) * frac], 1)
        hit = contains(pieces, pts)
        hit &= (pieces.body == k)[None, :]
        assert np.all(hit.sum(axis=1) == 1)
        np.testing.assert_array_equal(locate(mesh, pieces, pts, k), np.argmax(hit, axis=1))


@pytest.mark.parametrize("scene,tri,level", [c for c in CASES if c[2] < 2])
def test_divergence_theorem_on_every_piece_kind(scene, tri, level):
    """E t0 equals the load of the traction t0 n on the true boundary with the V_h traces."""
    sc = cd.load_scene(scene)
    mesh, pieces, ties = discretize(sc, tri, level)
    s = assemble(mesh, pieces, ties)
    for t0 in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]):
        S = np.array([[t0[0], t0[2]], [t0[2], t0[1]]])
        ref = np.zeros(s.n_dofs)
        for k in range(2):
            for side in ("face", "far", "left", "right"):
                part = BoundaryPart(on=side, kind="traction", traction=Traction("uniform", (0.0, 0.0)))
                a, b, x, u, nds = side_quadrature(mesh, k, part, 12)
                P = nds @ S.T
                for c in (0, 1):
                    np.add.at(ref, 2 * a + c, np.sum((1 - u)[None, :] * P[..., c], axis=1))
                    np.add.at(ref, 2 * b + c, np.sum(u[None, :] * P[..., c], axis=1))
        # tie the reference the same way V_h does (a tied node's load goes to its master)
        Et = s.Z.T @ (s.E @ np.tile(t0, s.n_pieces))
        # 12 Gauss points integrate the circle and cosine faces to rounding
        np.testing.assert_allclose(Et, s.Z.T @ ref, rtol=0, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("scene,tri", [(s, t) for s in CURVED for t in ("type1", "type2")])
def test_translations_and_affine_x_fields(scene, tri):
    sc = cd.load_scene(scene)
    mesh, pieces, ties = discretize(sc, tri, 1)
    s = assemble(mesh, pieces, ties)
    p = mesh.points
    # the same displacement at tied nodes (they must move with their masters)
    for u in (np.c_[np.ones(len(p)), 0 * p[:, 0]], np.c_[0 * p[:, 0], np.ones(len(p))]):
        assert np.abs(s.strains(u.ravel())).max() < 1e-12
    # u = (a x, b x) is constant along y, so it is in V_h on every piece kind: strain (a, 0, b)
    a, b = 0.3e-3, -0.7e-3
    g = s.strains(np.c_[a * p[:, 0], b * p[:, 0]].ravel())
    np.testing.assert_allclose(g, np.tile([a, 0.0, b], (len(g), 1)), rtol=0, atol=1e-15)
    # a general affine field is exact on straight triangles
    G = np.array([[0.1, -0.2], [0.3, 0.05]]) * 1e-3
    g = s.strains((p @ G.T).ravel())[pieces.kind == 0]
    np.testing.assert_allclose(g, np.tile([G[0, 0], G[1, 1], G[0, 1] + G[1, 0]], (len(g), 1)), atol=1e-15)


def test_rotation_strains_curved_pieces_only():
    # V_h is extended constantly along y on curved pieces, so the interpolant of a rotation
    # (not in V_h there) strains them: (dv1/dx, 0, dv2/dx) = (-theta * chord slope, 0, theta)
    sc = cd.load_scene("cylinder-on-block")
    mesh, pieces, ties = discretize(sc, "type1", 1)
    s = assemble(mesh, pieces, ties)
    p = mesh.points
    g = s.strains(np.c_[-p[:, 1], p[:, 0]].ravel())
    assert np.abs(g[pieces.kind == 0]).max() < 1e-12
    seg = pieces.kind == 1
    np.testing.assert_allclose(g[seg, 2], 1.0, rtol=1e-12)
    assert np.abs(g[seg, 1]).max() == 0.0


def test_stretch_classification():
    groove = cd.load_scene("cylinder-in-groove")
    assert [k for _, _, k in stretches(groove, groove.upper)] == ["convex"]
    assert [k for _, _, k in stretches(groove, groove.lower)] == ["concave"]
    wavy = cd.load_scene("wavy")
    kinds = stretches(wavy, wavy.lower)
    ends = [lo for lo, _, _ in kinds][1:]
    np.testing.assert_allclose(ends, [-12.5, -7.5, -2.5, 2.5, 7.5, 12.5], atol=1e-12)
    assert [k for _, _, k in kinds] == ["concave", "convex", "concave", "convex", "concave", "convex", "concave"]


def test_type2_polygon_is_tangent_and_inside():
    sc = cd.load_scene("cylinder-in-groove")
    mesh, pieces, _ = discretize(sc, "type2", 2)
    bm = mesh.bodies[1]
    face = bm.body.face
    x, y = bm.columns, bm.face_y
    inner = (x > -25) & (x < 25)
    # polygon vertices lie inside the lower body (below its concave face)
    assert np.all(y[inner] < face.value(x[inner]))
    # each polygon edge touches the arc: its largest height above the edge line is zero at one point
    for i in range(len(x) - 1):
        xs = np.linspace(x[i], x[i + 1], 20001)
        line = y[i] + (y[i + 1] - y[i]) * (xs - x[i]) / (x[i + 1] - x[i])
        assert np.min(face.value(xs) - line) >= -1e-12
        assert np.min(face.value(xs) - line) <= 1e-6 * (x[i + 1] - x[i]) ** 2
    # contact pairs sit at the polygon vertices, and the gap there is the arcs' gap
    s = assemble(mesh, pieces, None)
    np.testing.assert_allclose(s.eps, sc.gap_at(mesh.pair_x), rtol=0, atol=0)
    # the polygon's segments are no longer than h (the largest triangle diameter)
    seg = np.hypot(np.diff(x), np.diff(y))
    assert seg.max() <= mesh.h


def test_type1_and_type2_identical_without_concave_stretches():
    sc = cd.load_scene("cylinder-on-block")
    a, b = cd.solve(sc, "type1", 1), cd.solve(sc, "type2", 1)
    np.testing.assert_array_equal(a.stress, b.stress)
    np.testing.assert_array_equal(a.system.pieces.kind, b.system.pieces.kind)


def test_concave_type1_ties_the_vertical_side():
    sc = cd.load_scene("cylinder-in-groove")
    mesh, pieces, ties = discretize(sc, "type1", 1)
    assert ties is not None and len(ties) == np.sum(pieces.kind == 2)
    p = mesh.points
    # the tied node is on the same vertical line as its master, one layer into the body
    np.testing.assert_array_equal(p[ties[:, 0], 0], p[ties[:, 1], 0])
    assert np.all(p[ties[:, 0], 1] < p[ties[:, 1], 1])


def test_too_coarse_for_curvature_is_a_clear_error():
    # a groove of radius 26 over +-25: the arc bulges through the first layer at level 0 ...
    sc = cd.load_scene("cylinder-in-groove", [{"bodies": {"groove": {"face": {"R": 26.0, "yc": 26.0}}}}])
    with pytest.raises(cd.MeshError, match="bulges through the first element layer"):
        discretize(sc, "type1", 0)
    # ... which type 2 handles (its polygon lies inside the body), and so does a finer level
    discretize(sc, "type2", 0)
    discretize(sc, "type1", 4)


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["cylinder-in-groove", "wavy"])
def test_both_types_converge_together(scene):
    """Both triangulations solve at 5 levels (status optimal, residuals checked by solve), and
    their stresses approach each other as h shrinks."""
    from cvxdual.system.field import piece_distance as stress_distance
    sc = cd.load_scene(scene)
    dist, hs = [], []
    for level in range(5):
        # the fast path: the same discrete problem (test_fast checks it against CVXPY on these scenes)
        a, b = cd.solve(sc, "type1", level, "fast"), cd.solve(sc, "type2", level, "fast")
        assert a.solver["status"] == b.solver["status"] == "optimal"
        dist.append(stress_distance(b, a)["l2_rel"])
        hs.append(a.mesh.h)
    assert np.all(np.diff(dist) < 0)
    # measured rate about 0.55 (groove) and 0.4-0.7 (wavy): type 1's non-convex pieces carry
    # no s22 test function, an O(h^1/2) error in the first layer (see reports/convergence.md);
    # 0.3 leaves room for the coarse levels' pre-asymptotic wobble but fails if they stall
    assert np.polyfit(np.log(hs), np.log(dist), 1)[0] > 0.3


@pytest.mark.parametrize("scene,tri", [(s, t) for s in CURVED for t in ("type1", "type2")])
def test_dual_and_primal_agree_on_curved_scenes(scene, tri):
    from cvxdual.p0.norms import l2_norm
    sol = cd.solve(cd.load_scene(scene), tri, 2)
    pm = cd.PrimalModel(sol.system)
    pm.solve()
    s = sol.system
    tp = s.stresses_from_displacement(pm.displacements())
    # type 2's primal energy uses the area-averaged strain on each T_c (the same B as the dual)
    assert l2_norm(s, tp - sol.stress) <= 1e-6 * l2_norm(s, sol.stress)
    assert sol.duality_gap <= 1e-6
    c = sol.contact
    F = c["force"]
    assert F.min() >= -1e-7 * F.max()
    np.testing.assert_allclose(c["reaction"], F, rtol=0, atol=1e-8 * F.max())


def test_wavy_contact_in_separate_patches():
    sol = cd.solve(cd.load_scene("wavy"), "type2", 3)
    act = sol.contact["active"]
    x = sol.contact["x"]
    starts = np.flatnonzero(np.diff(act.astype(int)) == 1)
    assert len(starts) + int(act[0]) == 3  # three patches, around the crests at -10, 0, 10
    for crest in (-10.0, 0.0, 10.0):
        assert act[np.argmin(np.abs(x - crest))]
    for valley in (-5.0, 5.0):
        assert not act[np.argmin(np.abs(x - valley))]


def test_curved_pieces_in_vtu(tmp_path):
    import meshio

    from cvxdual.outputs.output_set import write_vtu
    sol = cd.solve(cd.load_scene("cylinder-in-groove"), "type2", 1)
    write_vtu(sol, tmp_path / "s.vtu")
    m = meshio.read(tmp_path / "s.vtu")
    kinds = np.concatenate([k for k, b in zip(m.cell_data["piece_kind"], m.cells, strict=True)
                            if b.type != "line"])  # the line cells are the contact face
    assert len(kinds) == sol.system.n_pieces
    assert set(np.unique(kinds)) == {0, 1, 3}
    poly = [b for b in m.cells if b.type == "polygon"]
    assert sum(len(b.data) for b in poly) == np.sum(sol.system.pieces.kind != 0)
    # polygon vertices follow the true face: those on an arc lie on it
    groove = sol.scene.lower.face
    P = m.points[np.concatenate([b.data.ravel() for b in poly])][:, :2]
    on = np.abs(P[:, 1] - groove.value(np.clip(P[:, 0], -25, 25))) < 1e-9
    # a D_h outline runs along the arc for half its vertices (the other half is the polygon);
    # the cylinder's segments likewise: at least a quarter of all vertices are on the groove
    assert on.sum() > len(P) / 4


def test_type2_with_unequal_body_ranges():
    # the cylinder narrower than the groove and the contact interval narrower still: the
    # cylinder's ends lie inside the groove's concave stretch and must stay columns
    sc = cd.load_scene("cylinder-in-groove", [{"bodies": {"cylinder": {"x": [-20.0, 20.0]}},
                                               "contact": {"interval": [-10.0, 10.0]}}])
    for tri in ("type1", "type2"):
        mesh, pieces, _ = discretize(sc, tri, 1)
        for k, body in enumerate(sc.bodies):
            assert pieces.area[pieces.body == k].sum() == pytest.approx(body_area(body), rel=1e-12)
            assert mesh.bodies[k].columns[0] == body.x_range[0] and mesh.bodies[k].columns[-1] == body.x_range[1]
        sol = cd.solve(sc, tri, 1)
        assert np.all(np.abs(sol.contact["x"]) <= 10.0)
        assert sol.contact["total_force"] == pytest.approx(150.0 * 50.0, rel=1e-7)


def test_quadrature_on_a_subset_of_pieces():
    _, p, _ = discretize(cd.load_scene("cylinder-in-groove"), "type2", 1)
    only = np.zeros(len(p), bool)
    only[::3] = True
    only[p.kind != 0] = True  # every curved piece too
    _, w, idx = p.quadrature(4, only=only)
    assert set(np.unique(idx)) == set(np.flatnonzero(only))
    # the same rule as on all pieces, restricted (sums in another order: rounding only)
    _, w_all, idx_all = p.quadrature(4)
    np.testing.assert_allclose(np.bincount(idx, w, len(p))[only], np.bincount(idx_all, w_all, len(p))[only],
                               rtol=1e-14)


def test_distance_between_non_nested_meshes_refines_straddling_pieces():
    """Curved faces and type 2's contact polygon make the levels' meshes non-nested: a coarse
    rule misplaces the jumps of the studied field inside reference pieces. Re-integrating the
    pieces that straddle studied pieces with a finer rule must move the figure toward a much
    finer rule's value (measured: plain 2x2 is 1.9% off, 2x2 with 6x6 on straddlers 0.6%)."""
    from cvxdual.system.field import piece_distance as stress_distance
    sc = cd.load_scene("cylinder-in-groove")
    ref, sol = cd.solve(sc, "type2", 3, "fast"), cd.solve(sc, "type2", 1, "fast")
    truth = stress_distance(ref, sol, 6, 24)["l2_rel"]
    plain = stress_distance(ref, sol, 2)["l2_rel"]
    adaptive = stress_distance(ref, sol, 2, 6)["l2_rel"]
    assert abs(adaptive - truth) < 0.5 * abs(plain - truth)
    # and the study's check rule (3x3, 8x8 on straddlers) is within 0.5% of the truth: measured
    # 0.1% here; the study asks its figures to be stable to 1% under a finer rule
    assert abs(stress_distance(ref, sol, 3, 8)["l2_rel"] / truth - 1) < 5e-3
