"""Point location in the pieces of a column mesh, vectorised.

A point of body ``k`` falls in column ``i`` by its x; in that column the straight mesh is a
stack of quads whose sides are the lines ``eta = const`` of the map
``y = F(x) + (far - F(x)) eta`` (``F`` the chord through the face nodes), so its layer follows
from ``eta``; the quad's diagonal picks the triangle. Points between the chord and the arc
(``eta < 0``) lie in a segment or a ``D_h`` piece, found among the body's slabs, which never
overlap in x. Used for errors against a reference on another mesh, integrated over the part both
meshes cover: :func:`common_part` says what that leaves out, and refuses more than two meshes of
one scene can differ by (:func:`curve_band`: the polygons standing for an outline body's curves).
"""

from __future__ import annotations

import numpy as np

from ..records import CommonPart
from .mesh import Mesh
from .pieces import Pieces, slab_bound


def inside_body(mesh: Mesh, k: int, pts: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """Whether points lie in body ``k`` (between its face and far side, within its x range; an
    outline body: in its mesh, the strip's curved pieces included)."""
    body = mesh.bodies[k].body
    if not body.is_column:
        return np.ones(len(pts), bool)  # decided by the location itself
    x, y = pts[:, 0], pts[:, 1]
    x0, x1 = body.x_range
    ok = (x >= x0 - tol) & (x <= x1 + tol)
    f = body.face.value(np.clip(x, x0, x1))
    if body.position == "upper":
        return ok & (y >= f - tol) & (y <= body.far + tol)
    return ok & (y <= f + tol) & (y >= body.far - tol)


def locate(mesh: Mesh, pieces: Pieces, pts: np.ndarray, body: np.ndarray | int, tol: float = 0.0) -> np.ndarray:
    """Piece index of each point ``(m, 2)`` of body ``body`` (array or int), ``-1`` outside.

    ``tol`` (a length) lets points that lie on the boundary to rounding count as inside.
    """
    pts = np.asarray(pts, float)
    body = np.broadcast_to(np.asarray(body), (len(pts),))
    out = np.full(len(pts), -1)
    toff = 0
    for k, bm in enumerate(mesh.bodies):
        ntri = len(bm.triangles())
        sel = np.flatnonzero((body == k) & inside_body(mesh, k, pts, tol))
        if len(sel):
            out[sel] = _locate_body(mesh, pieces, k, toff, pts[sel])
        toff += ntri
    return out


def _locate_body(mesh: Mesh, pieces: Pieces, k: int, toff: int, p: np.ndarray) -> np.ndarray:
    bm = mesh.bodies[k]
    c, eta, F, inner = bm.columns, bm.eta, bm.face_y, bm.inner
    nc, nl = bm.shape
    x, y = p[:, 0], p[:, 1]
    i = np.clip(np.searchsorted(c, x, side="right") - 1, 0, nc - 2)
    t = (x - c[i]) / (c[i + 1] - c[i])
    Fc = (1 - t) * F[i] + t * F[i + 1]
    e = (y - Fc) / ((1 - t) * inner[i] + t * inner[i + 1] - Fc)
    res = np.full(len(p), -1)
    if bm.rest is not None:  # beyond the strip (or beside it): gmsh's triangles
        off = (x < c[0]) | (x > c[-1])
        beyond = off | (e > 1)
        found = bm.rest_finder(x[beyond], y[beyond])
        ntri = len(bm.strip_triangles())
        res[beyond] = np.where(found >= 0, pieces.tri_map[np.maximum(toff + ntri + found, 0)], -1)
        e = np.where(off, np.nan, np.where(beyond, np.inf, e))
    straight = (e >= 0) & np.isfinite(e)
    j = np.clip(np.searchsorted(eta, e, side="right") - 1, 0, nl - 2)
    y_a = F[i] + (inner[i] - F[i]) * eta[j]  # vertex (i, j)
    y_b = F[i + 1] + (inner[i + 1] - F[i + 1]) * eta[j + 1]  # vertex (i+1, j+1)
    y_diag = (1 - t) * y_a + t * y_b
    in_t1 = bm.body.sign * (y_diag - y) >= 0  # t1 holds (i+1, j), on the face side of the diagonal
    nq = (nc - 1) * (nl - 1)
    tri = toff + np.where(in_t1, 0, nq) + i * (nl - 1) + j
    res[straight] = pieces.tri_map[tri[straight]]
    below = np.flatnonzero(e < 0)
    if len(below):
        s = pieces.slabs
        mine = np.flatnonzero(s.body == k)
        order = mine[np.argsort(s.xl[mine])]
        cand = order[np.clip(np.searchsorted(s.xl[order], x[below], side="right") - 1, 0, len(order) - 1)] \
            if len(order) else np.zeros(len(below), int)
        if len(order):
            xb = x[below]
            lo = slab_bound(s, pieces.faces, xb, cand, "lo")
            hi = slab_bound(s, pieces.faces, xb, cand, "hi")
            scale = np.abs(hi - lo).max() if len(hi) else 0.0
            ok = ((xb >= s.xl[cand]) & (xb <= s.xr[cand]) & (y[below] >= lo - 1e-12 * scale)
                  & (y[below] <= hi + 1e-12 * scale))
            res[below[ok]] = s.piece[cand[ok]]
    return res


def nearest_node_values(mesh: Mesh, xy: np.ndarray, body: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` of the nearest mesh node *of the same body* for points ``xy`` (the faces of
    the two bodies share coordinates, so the body must be chosen first)."""
    from scipy.spatial import cKDTree  # imported here: only output of curved pieces needs it

    out = np.zeros((len(xy),) + values.shape[1:])
    for k, bm in enumerate(mesh.bodies):
        m = body == k
        if np.any(m):
            ids = bm.offset + np.arange(bm.n_nodes)
            out[m] = values[ids[cKDTree(mesh.points[ids]).query(xy[m])[1]]]
    return out


# -- the common part of two meshes of one scene ----------------------------------------------

# The polygons standing for an outline body's curves (free arcs' chords and tangent polygons,
# gmsh's arcs, splines' chords) change with the level, so two levels' meshes of one body differ
# by thin slivers along those curves; faces (exact curved pieces) and straight parts do not move.
# Each mesh lies within ``curve_band`` of the true body, so the two differ by at most the sum of
# their bands; twice that absorbs what the bands' edge-by-edge estimate and the quadrature of the
# slivers (a rule of a few points across a cell the sliver cuts) leave out.
BAND_SAFETY = 2.0
AREA_ROUND = 1e-10  # of the body's area: what the sums of piece areas and of weights round off
CURVE_SAMPLES = 256  # points per spline stretch when measuring a polygon's distance from it


def curve_band(mesh: Mesh) -> float:
    """An upper bound on the area between the mesh's boundary polygons and the curved outline
    parts they stand for: ``sum |e| max(d_p, d_q, d_mid)`` over the boundary edges ``p -> q`` on
    a curved part, ``d`` a point's distance from the part (the region between an edge and its
    stretch of curve lies within that distance of the edge). Zero for column bodies and
    straight parts."""
    total = 0.0
    for bm in mesh.bodies:
        if bm.rest is None:
            continue
        pts = bm.points()
        for part in bm.body.outline.parts:
            if not part.is_curved:
                continue
            chain = pts[np.asarray(bm.rest.parts[part.name])]
            p, q = chain[:-1], chain[1:]
            d = np.stack([_part_distance(part, x) for x in (p, q, 0.5 * (p + q))]).max(axis=0)
            total += float(np.sum(np.hypot(*(q - p).T) * d))
    return total


def _part_distance(part, x: np.ndarray) -> np.ndarray:
    """The distance of points ``x`` ``(m, 2)`` from an outline part: exact on arcs (radial within
    the arc's angles, else to its nearer end) and lines, to a dense polygon on splines."""
    from ..scene.planar import point_segment_distance
    best = np.full(len(x), np.inf)
    for s in part.segments:
        a, b = np.asarray(s.start, float), np.asarray(s.end, float)
        if s.is_arc:
            c = np.asarray(s.center, float)
            a0, sweep = s.angles()
            v = x - c
            t = np.arctan2(v[:, 1], v[:, 0]) - a0
            within = np.mod(np.sign(sweep) * t, 2 * np.pi) <= abs(sweep)
            ends = np.minimum(np.hypot(*(x - a).T), np.hypot(*(x - b).T))
            d = np.where(within, np.abs(np.hypot(*v.T) - np.hypot(*(a - c))), ends)
        elif s.is_spline:
            line = s.sample(max(4, CURVE_SAMPLES // (len(s.through) + 1)))
            step = max(1, (1 << 20) // len(line))  # about 1e6 point-segment pairs at once
            d = np.concatenate([point_segment_distance(x[k:k + step, None], line[None, :-1], line[None, 1:]).min(axis=1)
                                for k in range(0, len(x), step)]) if len(x) else np.zeros(0)
        else:
            d = point_segment_distance(x, a, b)
        best = np.minimum(best, d)
    return best


def common_part(mesh_a: Mesh, mesh_b: Mesh, dropped: float, area_a: float, area_b: float) -> CommonPart:
    """What an integral over the common part of two meshes of one scene leaves out: ``dropped``
    (the measure of the quadrature points of ``a`` that lie outside ``b``) and the part of ``b``
    outside ``a`` (``|B| - |A| + dropped``, from the pieces' areas ``area_a``, ``area_b``), in all
    ``dropped_area`` (at least ``||A| - |B||``), with
    ``dropped_share`` (of ``|A|``) and the most two meshes of one scene can differ by,
    ``dropped_bound``. More than that is not the slivers of two levels' polygons along curves
    (:func:`curve_band`) but two different bodies: refused."""
    from ..errors import CvxdualError
    rnd = AREA_ROUND * max(area_a, area_b)
    # |A - B| + |B - A| from the quadrature's |A - B| and the exact areas; at least ||A| - |B||
    # (exact where one mesh holds the other, as nested polygons do: the rule's few points across a
    # cell the sliver cuts miss some of it)
    total = max(dropped + max(area_b - area_a + dropped, 0.0), abs(area_a - area_b))
    if dropped == 0 and total <= rnd:
        total = 0.0  # no point dropped, and the areas agree to their sums' rounding
    bound = BAND_SAFETY * (curve_band(mesh_a) + curve_band(mesh_b)) + rnd
    share = total / area_a if area_a > 0 else float("nan")
    if not total <= bound:
        raise CvxdualError(f"the two solutions' meshes differ by an area of {total:.3g} ({100 * share:.2g}% of the "
                           f"body), more than the {bound:.2g} the polygons standing for their curves can account for: "
                           "they are not meshes of one scene; compare solutions of the same scene (file, overrides "
                           "and units)")
    return CommonPart(dropped_area=float(total), dropped_share=float(share), dropped_bound=float(bound))
