"""The equilibrium space on curved faces (docs/equilibrium.md, section 11): column stresses on the
curved pieces of both triangulations, tied to the Johnson-Mercier faces, exactly admissible on
the true bodies, with certified bounds; checked from ``solution.vtu`` alone too."""

from __future__ import annotations

import functools

import meshio
import numpy as np
import pytest
from test_eq_output import EXACT, _edges_of_cells, check_vtu

import cvxdual as cd
from cvxdual.cli import main
from cvxdual.eq.bounds import admissibility_residuals, contact_slack, gap_curvature_bound
from cvxdual.eq.kinematic_p2 import arc_excess, face_slabs, face_values, p2_slack
from cvxdual.eq.space import EquilibriumSpace
from cvxdual.errors import SceneError

CURVED = ["cylinder-on-block", "cylinder-in-groove", "wavy"]
TRIS = ["type1", "type2"]


@functools.lru_cache(maxsize=None)
def solved(scene: str, tri: str, level: int, solver: str = "fast", kinematic: str = "p2"):
    return cd.solve(scene, tri, level, solver, stress_space="eq", fallback=False, kinematic=kinematic)


@pytest.mark.parametrize("tri", TRIS)
@pytest.mark.parametrize("scene", CURVED)
def test_exactly_admissible_and_guaranteed(scene, tri):
    sol = solved(scene, tri, 2)
    assert sol.residuals["admissibility"] <= 1e-12  # every block to rounding (measured ~1e-14)
    b = sol.bounds
    assert b["guaranteed"] and not b["reasons"]
    # G as the sum of its non-negative terms equals the identity J(v) + L(u0) + S(sigma): the
    # column energies, the slabs' energies of v and the contact terms are all in it consistently
    assert b["gap"] == pytest.approx(b["gap_identity"], rel=1e-9, abs=1e-12 * abs(b["energy_upper"]))
    assert b["energy_lower"] <= b["energy_upper"] and b["gap"] > 0
    assert np.all(b["contributions"]["column"] >= 0) and len(b["contributions"]["column"]) > 0


@pytest.mark.parametrize("scene, tri", [("cylinder-in-groove", "type1"), ("cylinder-in-groove", "type2"),
                                        ("wavy", "type2")])
def test_fast_route_agrees_with_cvxpy(scene, tri):
    """The hybridised fast route (columns owned by their face edge's triangle) and Clarabel on the
    CVXPY model solve the same QP."""
    a, b = solved(scene, tri, 1), solved(scene, tri, 1, "CLARABEL")
    rel = lambda x, y: np.linalg.norm(x - y) / np.linalg.norm(y)  # noqa: E731
    # Clarabel stops at ~1e-8 relative gaps: the fields agree to ~1e-8-1e-6 (measured 9e-9 to 9e-7,
    # the type-2 slivers' columns, of tiny energy, the least determined); 1e-6 as for flat faces
    assert rel(a.stress, b.stress) <= 1e-6 and rel(a.column_stress, b.column_stress) <= 2e-6
    # the complementary energies to Clarabel's gap (measured <= 1.4e-9), the fast route's the lower
    assert a.bounds["energy_lower"] == pytest.approx(b.bounds["energy_lower"], rel=1e-8)
    assert a.bounds["energy_lower"] >= b.bounds["energy_lower"] - 1e-12 * abs(b.bounds["energy_lower"])


@pytest.mark.slow
@pytest.mark.parametrize("scene", CURVED)
def test_energy_brackets_share_a_point(scene):
    """Every bracket ``[-L(u0) - S(sigma_h), J(v_h)]`` contains ``J(u)``, so all of them (both
    triangulations, every level) must overlap: a check no tuning can pass by accident."""
    lower, upper = [], []
    for tri in TRIS:
        for level in (0, 1, 2, 3):
            b = solved(scene, tri, level).bounds
            lower.append(b["energy_lower"])
            upper.append(b["energy_upper"])
    assert max(lower) <= min(upper)


def test_type2_bound_below_type1_on_the_groove():
    """Type 1's concave triangles force ``s11 = s12 = 0`` on whole first-layer triangles of the
    groove; type 2 only on slivers of area ``O(h^3)``: its bound is lower."""
    for level in (2, 3):
        assert solved("cylinder-in-groove", "type2", level).bounds["error_bound"] < \
            solved("cylinder-in-groove", "type1", level).bounds["error_bound"]


@pytest.mark.parametrize("tri", TRIS)
@pytest.mark.parametrize("scene", ["cylinder-in-groove", "wavy"])
def test_solution_vtu_alone_shows_admissibility(tmp_path, scene, tri):
    """From the file alone: no divergence on the sub-triangles, no traction jump between them,
    columns with ``s11 = s12 = 0`` and ``s22`` constant along y, every Johnson-Mercier edge
    bounding a column carrying the column's traction ``(0, s22 n_y)`` (chords, polygon edges,
    type 1's slanted and vertical sides), action = reaction and compression along the contact."""
    assert main(["solve", "--scene", scene, "--level", "1", "--triangulation", tri, "--stress-space", "eq",
                 "--solver", "fast", "--out", str(tmp_path)]) == 0
    sc = cd.load_scene(scene)
    res, _ = check_vtu(tmp_path / "solution.vtu", sc)
    assert res["divergence"] <= EXACT and res["traction_jump"] <= EXACT
    col = check_columns(tmp_path / "solution.vtu", sc)
    # every column touches the straight mesh at two points at least (its straight side's ends)
    assert col["n_tied_edges"] > 0 and col["least_points_tied"] >= 2
    for key in ("column_shear", "column_along_y", "tie", "action_reaction", "tension"):
        assert col[key] <= EXACT, (key, col[key])


def test_column_checks_catch_a_broken_file(tmp_path):
    assert main(["solve", "--scene", "cylinder-in-groove", "--level", "1", "--triangulation", "type1",
                 "--stress-space", "eq", "--solver", "fast", "--out", str(tmp_path)]) == 0
    m = meshio.read(tmp_path / "solution.vtu")
    pts = m.cells_dict["polygon"]
    k = pts.shape[1]
    s = m.point_data["stress"]
    scale = np.abs(s).max()
    mid = pts[len(pts) // 2]
    s[mid[0], 0] += 1e-3 * scale  # an s11 on a column
    s[mid[k // 2 - 1], 1] += 1e-3 * scale  # s22 varying along y, and a tie broken
    meshio.write(tmp_path / "broken.vtu", m)
    col = check_columns(tmp_path / "broken.vtu", cd.load_scene("cylinder-in-groove"))
    assert col["column_shear"] > 1e-6 and col["column_along_y"] > 1e-6 and col["tie"] > 1e-6


def _point_on_segments(p, a, b, tol):
    """For points ``p (m, 2)`` and segments ``a, b (e, 2)``: index pairs (point, segment) with the
    point on the segment (distance <= tol), and the point's parameter along the segment."""
    d = b - a
    L2 = np.einsum("ei,ei->e", d, d)
    out_p, out_e, out_t = [], [], []
    for lo in range(0, len(p), 2048):  # chunks of points: bounded memory
        q = p[lo: lo + 2048]
        t = np.einsum("qei,ei->qe", q[:, None, :] - a[None], d) / L2[None]
        dist = np.linalg.norm(q[:, None, :] - (a[None] + t[..., None] * d[None]), axis=2)
        i, e = np.nonzero((dist <= tol) & (t >= -1e-9) & (t <= 1 + 1e-9))
        out_p.append(lo + i), out_e.append(e), out_t.append(t[i, e])
    return np.concatenate(out_p), np.concatenate(out_e), np.concatenate(out_t)


def _face_segments(P, s, cells, body, k, face, tol, straight):
    """Segments of body ``k``'s face in the cells ``cells`` (triangles or polygons): consecutive
    cell points on the face ``y = f(x)``, with, for ``straight`` cells, their midpoint on it too
    (a chord is not; a polygon's points follow the arc), as ``(x0, x1, v0, v1)`` of ``s22``."""
    sel = cells[body == k]
    a, b = sel, np.roll(sel, -1, axis=1)
    pa, pb = P[a], P[b]
    mid = 0.5 * (pa + pb)
    on = lambda q: np.abs(q[..., 1] - face.value(q[..., 0])) <= tol  # noqa: E731
    keep = on(pa) & on(pb) & (on(mid) | (not straight)) & (np.abs(pa[..., 0] - pb[..., 0]) > tol)
    x0, x1 = pa[..., 0][keep], pb[..., 0][keep]
    v0, v1 = s[a[keep], 1], s[b[keep], 1]
    flip = x0 > x1
    return (np.where(flip, x1, x0), np.where(flip, x0, x1), np.where(flip, v1, v0), np.where(flip, v0, v1))


def _vertical_stress(segments, x):
    x0, x1, v0, v1 = segments
    order = np.argsort(x0)
    x0, x1, v0, v1 = x0[order], x1[order], v0[order], v1[order]
    i = np.clip(np.searchsorted(x0, x, side="right") - 1, 0, len(x0) - 1)
    assert np.all((x >= x0[i] - 1e-12) & (x <= x1[i] + 1e-12)), "a sample is not on a face segment"
    t = (x - x0[i]) / (x1[i] - x0[i])
    return v0[i] * (1 - t) + v1[i] * t


def check_columns(path, scene) -> dict:
    """The column cells of ``path`` (``polygon`` cells) and their ties, from the file alone."""
    m = meshio.read(path)
    P, s = m.points[:, :2], m.point_data["stress"]
    tris, polys = m.cells_dict["triangle"], m.cells_dict["polygon"]
    blocks = [c.type for c in m.cells]
    tri_body = m.cell_data["body"][blocks.index("triangle")]
    poly_body = m.cell_data["body"][blocks.index("polygon")]
    scale = np.abs(s).max()
    tol = 1e-9 * scene.length_scale  # computed coordinates: rounding only
    out = {"n_columns": len(polys)}
    out["column_shear"] = float(np.abs(s[polys.ravel()][:, [0, 2]]).max() / scale)
    k = polys.shape[1] // 2
    low, high = polys[:, :k], polys[:, ::-1][:, :k]  # the two bounds at the same abscissae
    out["column_along_y"] = float(np.abs(s[low, 1] - s[high, 1]).max() / scale)
    # Johnson-Mercier edges with one sub-triangle (the boundary of the straight mesh) that
    # column points lie on: the sub-triangle's traction there is the column's, (0, s22 n_y)
    cell, a, b, key = _edges_of_cells(P, tris)
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    lone = count[inv.ravel()] == 1
    ea, eb = tris[cell[lone], a[lone]], tris[cell[lone], b[lone]]
    pts = polys.ravel()
    owner = np.repeat(np.arange(len(polys)), polys.shape[1])
    ip, ie, t = _point_on_segments(P[pts], P[ea], P[eb], tol)
    d = P[eb[ie]] - P[ea[ie]]
    n = np.stack([d[:, 1], -d[:, 0]], 1) / np.linalg.norm(d, axis=1, keepdims=True)
    # a column's points on a slanted edge spanning its x range (g may jump at the interval's ends,
    # where the neighbouring column's point touches the same edge), or on a vertical edge whose
    # both ends are its points (type 1's B C; a side of the body only touches its corner)
    px = P[polys, 0]
    lo_x, hi_x = px.min(1)[owner[ip]], px.max(1)[owner[ip]]
    ex0, ex1 = np.minimum(P[ea[ie], 0], P[eb[ie], 0]), np.maximum(P[ea[ie], 0], P[eb[ie], 0])
    vertical = np.abs(n[:, 1]) <= 1e-12
    ends = [np.linalg.norm(P[polys[owner[ip]]] - P[e[ie]][:, None, :], axis=2).min(1) <= tol for e in (ea, eb)]
    own = np.where(vertical, ends[0] & ends[1], (lo_x >= ex0 - tol) & (hi_x <= ex1 + tol))
    ip, ie, t, n = ip[own], ie[own], t[own], n[own]
    sj = (1 - t)[:, None] * s[ea[ie]] + t[:, None] * s[eb[ie]]  # the sub-triangle's stress at the point
    jm = np.stack([sj[:, 0] * n[:, 0] + sj[:, 2] * n[:, 1], sj[:, 2] * n[:, 0] + sj[:, 1] * n[:, 1]], 1)
    sc = s[pts[ip]]
    column = np.stack([np.zeros(len(sc)), sc[:, 1] * n[:, 1]], 1)
    out["tie"] = float(np.abs(jm - column).max() / scale)
    out["n_tied_edges"] = len(np.unique(ie))
    out["least_points_tied"] = int(np.bincount(owner[ip], minlength=len(polys)).min())
    # along the contact interval: the vertical stress of both faces, at the midpoints between the
    # line cells' points (inside the contact intervals, away from the pairs where it may jump)
    lines = m.cells_dict["line"]
    xe = np.unique(P[lines.ravel(), 0])
    x = 0.5 * (xe[:-1] + xe[1:])
    v = []
    for body in (0, 1):
        face = scene.bodies[body].face
        seg = [np.concatenate(z) for z in zip(_face_segments(P, s, tris, tri_body, body, face, tol, True),
                                               _face_segments(P, s, polys, poly_body, body, face, tol, False),
                                               strict=True)]
        v.append(_vertical_stress(seg, x))
    out["action_reaction"] = float(np.abs(v[0] - v[1]).max() / scale)
    out["tension"] = float(max(0.0, v[1].max()) / scale)
    return out


def test_curvature_bounds_hold_on_every_interval():
    """The profiles' guaranteed curvature bounds contain every sampled curvature (the slack bound
    rests on them): circles (both branches), cosines (intervals holding an extremum or not)."""
    from cvxdual.scene.profiles import Cosine, LowerCircle, Parabola, UpperCircle
    rng = np.random.default_rng(7)
    for prof in (Cosine(amplitude=0.02, wavelength=10.0, x0=0.3, y0=-0.02), Cosine(amplitude=-1.5, wavelength=2.0),
                 LowerCircle(R=50.0, xc=1.0, yc=50.0), UpperCircle(R=52.0, xc=0.0, yc=-3.0), Parabola(R=-7.0)):
        a = rng.uniform(-20, 20, 300)
        b = a + rng.uniform(0, 8, 300)
        if isinstance(prof, (LowerCircle, UpperCircle)):
            a, b = (np.clip(v, prof.xc - 0.95 * prof.R, prof.xc + 0.95 * prof.R) for v in (a, b))
        lo, hi = prof.curvature_range(a, b)
        x = a[:, None] + np.linspace(0, 1, 2001)[None, :] * (b - a)[:, None]
        c = prof.curvature(x)
        # rounding of the closed forms only: 1e-12 relative
        assert np.all(c.min(1) >= lo - 1e-12 * np.abs(lo)) and np.all(c.max(1) <= hi + 1e-12 * np.abs(hi))


def test_composite_curvature_bounds_take_each_piece_on_its_own_side():
    """A composite face's curvature jumps at its joints (mesh columns): an interval ending at a
    joint is bounded by its own piece's values (an arc whose steepest end meets a flat, the
    rounded punch's flat next to its corners), never by the neighbour's, in either direction
    (the neighbour's 1/R on the flat made the slack bound dip by b^2 / 8R and v jump by it; the
    next piece's 0 at an arc's right end under-bounded the arc)."""
    from cvxdual.scene.piecewise import Composite
    y4 = 6.0 - np.sqrt(20.0)
    prof = Composite(nodes=((-4.0, 6.0 - np.sqrt(20.0)), (0.0, 0.0), (4.0, y4), (8.0, y4)),
                     centers=((0.0, 6.0), (0.0, 6.0), None))
    rng = np.random.default_rng(3)
    joints = np.array([-4.0, 0.0, 4.0, 8.0])
    a = np.concatenate([rng.uniform(-4, 8, 200), joints[:-1], [2.0, 0.0]])
    b = np.concatenate([np.minimum(a[:200] + rng.uniform(0, 5, 200), 8.0), joints[1:], [4.0, 4.0]])
    lo, hi = prof.curvature_range(a, b)
    # the inside of each interval, sampled (the joints themselves belong to neither side)
    x = a[:, None] + np.linspace(1e-9, 1 - 1e-9, 2001)[None, :] * (b - a)[:, None]
    c = prof.curvature(x)
    # rounding of the closed forms only: 1e-12 relative
    assert np.all(c.min(1) >= lo - 1e-12 * np.abs(lo)) and np.all(c.max(1) <= hi + 1e-12 * np.abs(hi))
    # and sharp: on [-4, 0], [0, 4] the arc's own extremes; on the flat [4, 8] exactly 0
    assert np.allclose(hi[200:203], [36 / 20**1.5, 36 / 20**1.5, 0.0]) and np.allclose(lo[200:203], [1 / 6, 1 / 6, 0.0])


@pytest.mark.parametrize("scene", CURVED)
def test_slack_bound_is_below_every_sample(scene):
    """The admissible displacement's slack ``eps - [v]`` is at least its guaranteed bound at every
    point of every contact edge (sampled densely), and the bound is non-negative."""
    sol = solved(scene, "type2", 1, kinematic="p1")
    sp, v = sol.space, sol.displacement
    _, smin, exact = contact_slack(sp, v)
    assert exact and smin.min() >= 0
    x = sp.mesh.pair_x
    up, lo = sp.mesh.pairs.T
    rel = v[lo, 1] - v[up, 1]
    u = np.linspace(0, 1, 4001)
    xs = x[:-1, None] + u[None, :] * np.diff(x)[:, None]
    sampled = sp.scene.gap_at(xs) - (rel[:-1, None] * (1 - u) + rel[1:, None] * u)
    # a lower bound: never above the samples beyond rounding of the gap's values (1e-12 of it)
    assert np.all(sampled.min(1) >= smin - 1e-12 * np.abs(sp.scene.gap_at(x)).max())
    sc = sp.scene
    curv = sc.upper.face.curvature(xs) - sc.lower.face.curvature(xs) + sc.gap_profile.curvature(xs)
    M = gap_curvature_bound(sp, x[:-1], x[1:])
    assert np.all(curv.max(1) <= M + 1e-12 * np.abs(M))  # the bound holds at every sample


@pytest.mark.parametrize("tri", TRIS)
@pytest.mark.parametrize("scene", CURVED)
def test_p2_slack_bound_is_below_every_sample(scene, tri):
    """The P2 displacement of the bounds: its jump on the true faces (where it continues an element's
    quadratic off the chord, not a quadratic in x) stays below the true gap at every sample of every
    contact edge, and the guaranteed bound of each edge is below its samples and non-negative."""
    sol = solved(scene, tri, 1)
    sp, v, fix = sol.space, sol.bounds["displacement"], sol.bounds["displacement_fix"]
    _, smin = p2_slack(sp, v)
    assert fix["exact_min"] and smin.min() >= 0
    u = np.linspace(0, 1, 2001)
    a = face_values(sp, v, u, face_slabs(sp, v))
    xs = sp.contact_x[:, :1] + u[None, :] * np.diff(sp.contact_x, axis=1)
    sampled = sp.scene.gap_at(xs) - (a[1] - a[0])
    tol = 1e-12 * np.abs(sp.scene.gap_at(sp.mesh.pair_x)).max()  # rounding of the gap's values
    assert np.all(sampled.min(1) >= smin - tol)
    assert sampled.min() >= -tol
    # the bound of the jump's departure from its three-point quadratic holds at every sample
    j = a[1] - a[0]
    N = np.stack([(1 - u) * (1 - 2 * u), 4 * u * (1 - u), u * (2 * u - 1)], 1)
    q = j[:, [0, 1000, 2000]] @ N.T
    R = arc_excess(sp, v, face_slabs(sp, v))
    assert np.all(np.abs(j - q) <= R[:, None] * (u * (1 - u))[None, :] + tol)
    assert R.max() > 0 if scene != "wavy" or tri == "type1" else True  # the curved faces hold elements


def test_perturbed_column_field_is_refused_by_the_checks():
    """The admissibility blocks see a column value off its tie and a tension at a contact end."""
    sol = solved("cylinder-in-groove", "type1", 1)
    sp, scale = sol.space, np.abs(sol.column_stress).max()
    g = sol.column_stress.copy()
    g[0, 0] += 1e-6 * scale
    res = admissibility_residuals(sp, sol.stress, g=g)
    assert res["column_tie"] > 1e-8
    assert admissibility_residuals(sp, sol.stress, g=sol.column_stress)["column_tie"] <= 1e-12


def test_refusals_name_the_problem():
    """A body force on a body with a curved face, and a load on a curved stretch, are refused with
    the reason: the column stresses carry neither."""
    with pytest.raises(SceneError, match="body force"):
        EquilibriumSpace.from_scene(cd.load_scene("cylinder-on-block", [{"bodies": {"cylinder": {
            "body_force": [0.0, -1.0]}}}]), 0)
    loaded = cd.load_scene("cylinder-on-block", [{"contact": {"interval": [-10.0, 10.0]}, "bodies": {"cylinder": {
        "boundary": {"side": {"on": "face", "kind": "traction", "interval": [10.0, 20.0],
                              "traction": {"kind": "uniform", "value": [0.0, 1.0]}}}}}}])
    with pytest.raises(SceneError, match="curved stretch"):
        EquilibriumSpace.from_scene(loaded, 0)


def test_field_distance_in_chunks_equals_one_pass(monkeypatch):
    """A level-6 reference is integrated in chunks of cells; the chunks must add up to the one-pass
    integral, with straddling cells refined in whichever chunk holds them (eq against eq, eq
    against P0 with slabs)."""
    from cvxdual.system import field as fields
    a = solved("cylinder-in-groove", "type2", 2).field
    b = solved("cylinder-in-groove", "type2", 0).field
    c = cd.solve("cylinder-in-groove", "type1", 0, "fast").field
    for x, y in ((a, b), (a, c)):
        whole = fields.field_distance(x, y, 2, 6)
        monkeypatch.setattr(fields, "CHUNK_POINTS", 3000)  # dozens of chunks, most with straddling cells
        chunked = fields.field_distance(x, y, 2, 6)
        monkeypatch.undo()
        # the same sums added in another order: rounding only
        assert whole["l2"] > 0 and chunked["l2"] == pytest.approx(whole["l2"], rel=1e-12)
        assert chunked["energy"] == pytest.approx(whole["energy"], rel=1e-12)


def test_field_at_sub_triangle_centroids_is_the_vertex_mean():
    """``StressField.at`` finds the sub-triangle of a point from the macro triangle's barycentric
    coordinates: at every sub-triangle's centroid it must return the mean of that sub-triangle's
    vertex values, and name that sub-triangle as the cell."""
    f = solved("cylinder-in-groove", "type1", 1).field
    sub = f.space.sub_points()  # (n_sub, 3, 2)
    c = sub.mean(1)
    body = np.repeat(f.space.body, 3)
    vals, cell = f.at(c, body, 1e-10 * f.scene.length_scale)
    expected = f.stress.reshape(-1, 3, 3).mean(1)
    scale = np.abs(f.stress).max()
    assert np.array_equal(cell, np.arange(len(sub)))
    assert np.abs(vals - expected).max() <= 1e-12 * scale  # a linear function at a centroid: rounding only
