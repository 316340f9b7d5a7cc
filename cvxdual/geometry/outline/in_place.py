"""An outline body's gmsh part refined in place, without gmsh: the cycle of a run to a tolerance
that follows a gmsh cycle (:mod:`cvxdual.adapt.cycles`, docs/adaptive.md).

The last cycle's :class:`~cvxdual.geometry.outline.readback.RestMesh` is refined locally
(:func:`~cvxdual.geometry.refine.refine_edges`): every edge of a marked triangle is halved, and
closed by longest edges (a triangle with a halved edge has its longest halved too, so a cut never
halves a small angle: at least half the least angle is kept, as bisection by longest edges keeps),
and the strip's inner chain follows the new columns: its edge over a halved column interval
gets the new column's inner node, and its old nodes move to the new strip depth
(:func:`~cvxdual.geometry.outline.sizes.strip_depth`, the mean of the adjacent spacings). Edges
on a straight outline part are halved at their midpoints; a free arc's polygon is refined where
the pieces beyond it are halved (:class:`_Pieces`); a held arc's and a spline's polygons stay whole
(gmsh remakes those), as do chain edges over intervals not halved. What cannot be done this way raises
:class:`~cvxdual.geometry.refine.FoldError` and the caller meshes with gmsh instead: columns
halved twice in one interval (the strip's closure), the columns not nested (type 2's tangent
polygons moved), a node that folds a triangle over, or an angle below half the last mesh's least
(a longest edge on the chain or a curve, which stays whole, or a chain moved far).
"""

from __future__ import annotations

import numpy as np

from ...scene.planar import point_segment_distance
from ..refine import FoldError, refine_edges
from ..triangles import doubled_areas, edge_keys, edge_lengths, edge_triangles, least_angles
from .readback import RestMesh
from .sizes import SizeField

ROUND = 1e-9  # relative to the body's size: a node this close to a straight part lies on it (gmsh's rounding)
# a triangle where the size asked shrank is halved when its longest edge is above this times the size now
# asked: gmsh's triangles are 0.8-1.3 times the size asked, most of them (measured at level 0). Runs to 1 % on
# seven scenes took the fewest pieces in all at 1.2 (at 0.8 and 1.0: within 3 % each, punch-on-block 12-18 % more)
SIZE_SLACK = 1.2
SHRINK = 0.75  # ... and the size asked there is below this times what it was
KEEP_ANGLE = 0.5  # no angle below half the last mesh's least: what bisection by longest edges keeps
CLOSURE_PASSES = 256  # each pass halves the longest edge of the triangles a halved edge reached: a few dozen do


def refine_in_place(body, prior, columns, face_y, inner, level: int, spots: tuple, marked, arcs) -> RestMesh:
    """The gmsh part of ``prior`` (the last cycle's :class:`~cvxdual.geometry.mesh.BodyMesh`)
    refined for the strip on ``columns`` (a superset of its, at most one new column per old
    interval) with face heights ``face_y`` and inner chain ``inner``: the triangles ``marked`` and
    the pieces beyond free arcs ``arcs`` (bool, one per triangle and per piece of ``prior.rest``)
    halved, and those the size field of ``level`` asks markedly less of (:func:`asks_less`; ``spots``:
    the old spots and the new, :class:`~cvxdual.geometry.outline.sizes.SizeField`)."""
    pts = prior.points()
    tri, arc = asks_less(prior, pts, columns, inner, level, *spots)
    least = float(least_angles(pts[prior.rest.triangles]).min()) if len(prior.rest.triangles) else 0.0
    return _refined(body, prior.rest, prior.columns, columns, face_y, inner, np.asarray(marked, bool) | tri,
                    np.asarray(arcs, bool) | arc, KEEP_ANGLE * least)


def asks_less(prior, pts, columns, inner, level: int, old_spots, spots) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of ``prior``'s gmsh part (its nodes ``pts``), and its pieces beyond free arcs (by
    their chords), whose size the field of the new strip ``(columns, inner)`` and ``spots`` asks to
    shrink below :data:`SHRINK` times and that are larger than :data:`SIZE_SLACK` times it: where gmsh
    would now make smaller ones."""
    rest = prior.rest
    X = pts[rest.triangles]
    ends = pts[rest.virtual_ends]
    at = np.concatenate([X.mean(1), ends.mean(1)])
    size = np.concatenate([edge_lengths(X).max(1), np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)])
    old = SizeField.of(prior.body, prior.columns, prior.inner, level, old_spots).at(at)
    new = SizeField.of(prior.body, columns, inner, level, spots).at(at)
    shrink = (new < SHRINK * old) & (size > SIZE_SLACK * new)
    return shrink[:len(X)], shrink[len(X):]


def _refined(body, rest: RestMesh, old_columns, columns, face_y, inner, marked, arcs, least: float) -> RestMesh:
    """``rest`` (meshed beyond the strip on ``old_columns``) refined for the strip on ``columns``,
    ``marked`` triangles and ``arcs`` pieces halved (:func:`refine_in_place`), no angle below ``least``."""
    old_columns, columns = np.asarray(old_columns, float), np.asarray(columns, float)
    nc0, nc, nr = len(old_columns), len(columns), len(rest.points)
    pos = np.searchsorted(columns, old_columns)
    if (np.any(pos >= nc) or not np.array_equal(columns[np.minimum(pos, nc - 1)], old_columns)
            or np.any(np.diff(pos) > 2)):
        raise FoldError("the new columns do not halve the old ones once")
    # the old local numbers (strip node (i, j) is 2 i + j, then the rest's) in the new numbering
    remap = np.concatenate([(2 * pos[:, None] + np.arange(2)).ravel(), 2 * nc + np.arange(nr)])
    strip = np.stack([np.repeat(columns, 2), np.stack([face_y, inner], 1).ravel()], 1)
    P = np.concatenate([strip, rest.points])
    T = remap[rest.triangles]
    # the chain's edges over halved intervals: their new node is the new column's inner node
    halved = np.flatnonzero(np.diff(pos) == 2)
    chain = np.stack([2 * pos[halved] + 1, 2 * pos[halved + 1] + 1], 1)
    chain_new = 2 * (pos[halved] + 1) + 1
    pieces = _Pieces.of(rest, remap, P, np.asarray(arcs, bool), 2 * nc0 + nr)
    P[pieces.corner] = pieces.tip  # a halved corner's node moves onto the arc, between the cuts
    moved = np.concatenate([chain, pieces.edges])
    split = _closed(P, T, np.asarray(marked, bool), body, nc, moved)
    ref = refine_edges(P, T, split, moved, np.concatenate([P[chain_new], pieces.to]))
    # the new nodes: the chain's become the strip's inner nodes, the others follow the rest's
    new = np.arange(len(P), len(ref.points))
    final = np.concatenate([np.arange(len(P)), np.zeros(len(new), np.int64)])
    on_chain = np.zeros(len(ref.points), bool)
    k = ref.midpoints(chain[:, 0], chain[:, 1])
    final[k], on_chain[k] = chain_new, True
    own = new[~on_chain[new]]
    final[own] = len(P) + np.arange(len(own))
    corner_new = final[ref.midpoints(*pieces.corner_edges.T)].reshape(2, -1)  # the cuts either side
    points = np.concatenate([P[2 * nc:], ref.points[own]])  # the rest's nodes, the halved corners' moved
    allp = np.concatenate([strip, points])
    tris = final[ref.triangles]
    d = allp[tris]
    e2 = np.max([np.sum((d[:, i] - d[:, i - 1]) ** 2, 1) for i in range(3)], 0)
    if np.any(doubled_areas(allp, tris) <= 2e-12 * e2):  # as check_triangles: no digits left below that
        raise FoldError("a triangle would fold over or go flat (the strip's inner chain moved across it)")
    if len(tris) and least_angles(d).min() < least:
        raise FoldError("a triangle would have an angle below half the last mesh's least (its longest edge stays "
                        "whole on the chain or a curve, or the chain moved far)")
    # a part's path may run along a strip's side, no edge of this mesh: strict=False keeps those whole
    parts = {name: final[c] for name, c in ref.chains({k: remap[np.asarray(c)] for k, c in rest.parts.items()},
                                                       strict=False).items()}
    vn, vw, va, ve = pieces.after(ref, final, tris, len(allp), corner_new, allp)
    return RestMesh(points=points, triangles=tris, parts=parts, virtual_nodes=vn, virtual_weight=vw, virtual_arc=va,
                    virtual_ends=ve)


class _Pieces:
    """The pieces beyond the free arcs (``RestMesh.virtual_*``, in the new numbering) and how the
    marked ones are halved. A segment (beyond a convex arc's chord): its chord is halved at the
    arc's midpoint, giving two segments. A corner (between a hole's tangent polygon and its circle,
    the corner node where two tangents meet): the two tangents are cut where the tangent at the
    arc's midpoint meets them, the corner node moves onto the arc's midpoint (its triangles follow;
    a kite of two triangles there instead had angles of 11 degrees round a hole of 16 edges) and two
    corners remain, each half as wide."""

    @classmethod
    def of(cls, rest: RestMesh, remap, P, marked, n_old: int) -> _Pieces:
        self = cls()
        self.nodes, self.ends = remap[rest.virtual_nodes], remap[rest.virtual_ends]
        self.arc, self.weight = rest.virtual_arc, rest.virtual_weight
        # a segment's ends are an edge of its triangle; a corner's are not an edge
        self.seg = edge_triangles(rest.triangles, *rest.virtual_ends.T, n_old) >= 0
        self.cut_seg, self.cut_corner = self.seg & marked, ~self.seg & marked
        c, r = self.arc[:, :2], self.arc[:, 2:]
        e = self.ends[self.cut_seg]
        m = 0.5 * (P[e[:, 0]] + P[e[:, 1]]) - c[self.cut_seg]
        self.seg_mid = c[self.cut_seg] + r[self.cut_seg] * m / np.linalg.norm(m, axis=1)[:, None]
        a, k, b = self.nodes[self.cut_corner].T
        cc, rc = c[self.cut_corner], r[self.cut_corner]
        out = np.linalg.norm(P[k] - cc, axis=1)[:, None]
        q = rc / (rc + out)  # tan(d / 4) / tan(d / 2): where the midpoint's tangent cuts each tangent
        self.corner_edges = np.concatenate([np.stack([a, k], 1), np.stack([k, b], 1)])
        self.corner_to = np.concatenate([P[a] + (P[k] - P[a]) * q, P[b] + (P[k] - P[b]) * q])
        self.corner = k
        self.tip = cc + rc * (P[k] - cc) / out
        self.edges = np.concatenate([e, self.corner_edges]).astype(np.int64).reshape(-1, 2)
        self.to = np.concatenate([self.seg_mid, self.corner_to]).reshape(-1, 2)
        return self

    def after(self, ref, final, tris, n, corner_new, allp):
        """The pieces' nodes, weights, arcs and ends in the refined mesh."""
        keep_c = ~self.seg & ~self.cut_corner
        a, k, b = self.nodes[self.cut_corner].T
        c_nodes = np.concatenate([self.nodes[keep_c], np.stack([a, corner_new[0], k], 1),
                                  np.stack([k, corner_new[1], b], 1)])
        c_arc = np.concatenate([self.arc[keep_c], self.arc[self.cut_corner], self.arc[self.cut_corner]])
        c_area = 0.5 * np.abs(doubled_areas(allp, c_nodes))
        keep_s = self.seg & ~self.cut_seg
        e = self.ends[self.cut_seg]
        mid = final[ref.midpoints(e[:, 0], e[:, 1])]
        s_ends = np.concatenate([self.ends[keep_s], np.stack([e[:, 0], mid], 1), np.stack([mid, e[:, 1]], 1)])
        s_arc = np.concatenate([self.arc[keep_s], self.arc[self.cut_seg], self.arc[self.cut_seg]])
        halves = s_ends[int(keep_s.sum()):]
        angle = 2 * np.arcsin(np.minimum(1.0, 0.5 * np.linalg.norm(allp[halves[:, 1]] - allp[halves[:, 0]], axis=1)
                                         / s_arc[int(keep_s.sum()):, 2]))  # each new chord's
        s_area = np.concatenate([self.weight[keep_s],
                                 0.5 * s_arc[int(keep_s.sum()):, 2] ** 2 * (angle - np.sin(angle))])
        return (np.concatenate([c_nodes, _on_edge(tris, s_ends, n)]).astype(int),
                np.concatenate([c_area, s_area]), np.concatenate([c_arc, s_arc]),
                np.concatenate([c_nodes[:, [0, 2]], s_ends]).astype(int))


def _closed(P, T, marked, body, nc, forced) -> np.ndarray:
    """The edges to halve ``(s, 2)``: the marked triangles', red-green closed, and the ``forced``
    ones (the chain's over halved intervals, the halved pieces' edges on the free arcs); no other
    fixed edge (the chain's, the outline's that are not straight)."""
    n = len(P)
    keys, inv = np.unique(edge_keys(T, np.roll(T, -1, axis=1), n), return_inverse=True)
    inv = inv.reshape(T.shape)
    a, b = keys // n, keys % n
    count = np.bincount(inv.ravel(), minlength=len(keys))
    chain = (a < 2 * nc) & (b < 2 * nc)  # both ends strip nodes: on the chain (or a face end's)
    fixed = chain.copy()
    out = np.flatnonzero(count == 1)  # the outline's edges: fixed unless straight
    fixed[out] |= ~_straight(body, P[a[out]], P[b[out]])
    split = np.zeros(len(keys), bool)
    split[inv[marked].ravel()] = True
    split &= ~fixed  # a marked triangle's fixed edges stay whole
    split[np.searchsorted(keys, edge_keys(forced[:, 0], forced[:, 1], n))] = True
    # a triangle with a halved edge has its longest halved too (so that no cut halves a small angle)
    length = np.linalg.norm(P[a] - P[b], axis=1)
    longest = inv[np.arange(len(T)), np.argmax(length[inv], axis=1)]
    for _ in range(CLOSURE_PASSES):
        more = split[inv].any(axis=1) & ~split[longest] & ~fixed[longest]
        if not more.any():
            break
        split[longest[more]] = True
    return np.stack([a[split], b[split]], 1)


def _straight(body, p, q) -> np.ndarray:
    """Whether each edge ``p -> q`` lies on a straight segment of the body's outline."""
    lines = [(s.start, s.end) for part in body.outline.parts for s in part.segments if not (s.is_arc or s.is_spline)]
    if not lines or not len(p):
        return np.zeros(len(p), bool)
    s0, s1 = (np.array(v, float)[None, :, :] for v in zip(*lines, strict=True))
    tol = ROUND * float(np.ptp(np.concatenate([s0[0], s1[0]]), axis=0).max())
    on = (point_segment_distance(p[:, None], s0, s1) <= tol) & (point_segment_distance(q[:, None], s0, s1) <= tol)
    return on.any(axis=1)


def _on_edge(tris, ends, n) -> np.ndarray:
    """The triangle of ``tris`` on each boundary edge ``ends`` ``(m, 2)`` (its one triangle)."""
    t = edge_triangles(tris, ends[:, 0], ends[:, 1], n)
    if np.any(t < 0):
        raise FoldError("internal: a chord of a free arc was halved")  # pragma: no cover - chords are fixed edges
    return tris[t]
