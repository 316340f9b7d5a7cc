"""Point location in the pieces of a column mesh, vectorised.

A point of body ``k`` falls in column ``i`` by its x; in that column the straight mesh is a
stack of quads whose sides are the lines ``eta = const`` of the map
``y = F(x) + (far - F(x)) eta`` (``F`` the chord through the face nodes), so its layer follows
from ``eta``; the quad's diagonal picks the triangle. Points between the chord and the arc
(``eta < 0``) lie in a segment or a ``D_h`` piece, found among the body's slabs, which never
overlap in x. Used for errors against a reference on another mesh.
"""

from __future__ import annotations

import numpy as np

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
