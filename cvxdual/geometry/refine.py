"""Uniform refinement of a triangle mesh: every edge halved, every triangle cut into four similar
ones, with the new node of chosen edges moved onto the true boundary and chosen edges left whole.

An outline body's gmsh part at level ``L >= 1`` is gmsh's mesh at the sizes of level ``L - 1``
refined once (:mod:`~cvxdual.geometry.outline`): the size field halves everywhere a level
(:mod:`~cvxdual.geometry.outline.sizes`), so the refined mesh has the sizes of level ``L`` and
gmsh makes a quarter of the triangles. A triangle with one edge left whole (the strip's sides,
which the strip's own mesh does not split) is cut into three instead: the corner between the
halved edges, and the rest along the shorter diagonal.

:func:`refine_edges` halves chosen edges only (local refinement: a triangle with one halved edge
is cut in two from its new node to the opposite corner), for a run to a tolerance's cycles that
refine the last mesh in place (:mod:`~cvxdual.geometry.outline.in_place`, which chooses the edges).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import MeshError
from .triangles import doubled_areas, edge_keys


class FoldError(MeshError):
    """Refinement would turn a child triangle against its parent (the caller may mesh the level directly)."""

@dataclass(frozen=True)
class Refined:
    """The refined mesh: ``points`` (the old nodes first, in their order, then one new node per
    halved edge), ``triangles`` (orientation kept) and the halved edges' keys and new nodes, for
    :meth:`midpoints`."""

    points: np.ndarray
    triangles: np.ndarray
    n_old: int
    edge_keys: np.ndarray  # sorted
    edge_mid: np.ndarray  # the new node of each edge, -1 for an edge left whole

    def midpoints(self, a, b, strict: bool = True) -> np.ndarray:
        """The new node on each old edge ``(a[i], b[i])`` (-1 if it was left whole); ``strict``:
        a pair that is no edge of the mesh is an error, else -1 too (a strip's side, in place)."""
        k = edge_keys(a, b, self.n_old)
        pos = np.clip(np.searchsorted(self.edge_keys, k), 0, max(len(self.edge_keys) - 1, 0))
        found = self.edge_keys[pos] == k if len(self.edge_keys) else np.zeros(len(k), bool)
        if strict and not found.all():
            raise MeshError("internal: an edge asked of the refined mesh is not one of its edges")
        return np.where(found, self.edge_mid[pos] if len(self.edge_keys) else -1, -1)

    def chain(self, nodes) -> np.ndarray:
        """A path of old nodes with the new node of each of its edges between its ends."""
        return self.chains({0: nodes})[0]

    def chains(self, paths: dict, strict: bool = True) -> dict:
        """:meth:`chain` of every path of ``paths`` (any keys), with one lookup for all their edges
        (``strict`` as in :meth:`midpoints`)."""
        paths = {k: np.asarray(v, np.int64) for k, v in paths.items()}
        mid = self.midpoints(*(np.concatenate([np.zeros(0, np.int64)] + [p[s] for p in paths.values()])
                               for s in (slice(None, -1), slice(1, None))), strict=strict)
        out, at = {}, 0
        for k, p in paths.items():
            seq = np.stack([p[:-1], mid[at:at + max(len(p) - 1, 0)]], 1).ravel()
            at += max(len(p) - 1, 0)
            out[k] = np.append(seq[seq >= 0], p[-1:])
        return out


def refine(points: np.ndarray, triangles: np.ndarray, whole=None, moved=None, to=None) -> Refined:
    """Halve every edge of ``triangles`` (on ``points`` ``(n, 2)``) except the edges ``whole``
    ``(w, 2)``; the new node of edge ``moved[i]`` ``(q, 2)`` lies at ``to[i]`` instead of the
    edge's midpoint. Triangles with every edge halved give four, with one edge whole three; a
    triangle with two or three whole edges is refused (no outline mesh has one)."""
    tri = np.asarray(triangles, np.int64)
    keys, inv = _edges(tri, len(points))
    split = np.ones(len(keys), bool)
    if whole is not None and len(whole):
        w = np.asarray(whole, np.int64).reshape(-1, 2)
        split[np.searchsorted(keys, edge_keys(w[:, 0], w[:, 1], len(points)))] = False
    if np.any(np.sum(~split[inv], axis=1) > 1):
        raise MeshError("internal: a triangle to refine has two edges that must stay whole")
    return _cut(np.asarray(points, float), tri, keys, inv, split, moved, to)


def refine_edges(points: np.ndarray, triangles: np.ndarray, edges, moved=None, to=None) -> Refined:
    """Halve the edges ``edges`` ``(s, 2)`` of ``triangles`` only (local refinement; ``moved``,
    ``to`` as in :func:`refine`): a triangle with three halved edges gives four, with two three,
    with one two (cut from the halved edge's new node to the opposite corner), with none itself.
    Which edges keep the shapes is the caller's choice (the in-place cycles halve longest edges)."""
    tri = np.asarray(triangles, np.int64)
    keys, inv = _edges(tri, len(points))
    split = np.zeros(len(keys), bool)
    s = np.asarray(edges, np.int64).reshape(-1, 2)
    k = edge_keys(s[:, 0], s[:, 1], len(points))
    pos = np.clip(np.searchsorted(keys, k), 0, max(len(keys) - 1, 0))
    if len(k) and not np.array_equal(keys[pos], k):
        raise MeshError("internal: an edge to halve is not an edge of the mesh")
    split[pos] = True
    return _cut(np.asarray(points, float), tri, keys, inv, split, moved, to)


def _edges(tri: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The sorted keys of the mesh's edges and each triangle's edge ``j`` (corner ``j`` to ``j + 1``) among them."""
    keys, inv = np.unique(edge_keys(tri, np.roll(tri, -1, axis=1), n), return_inverse=True)
    return keys, inv.reshape(tri.shape)


def _cut(points, tri, keys, inv, split, moved, to) -> Refined:
    """Each triangle cut by the new nodes on its ``split`` edges (4, 3, 2 or 1 children)."""
    n = len(points)
    a, b = keys // n, keys % n
    xy = 0.5 * (points[a] + points[b])
    if moved is not None and len(moved):
        q = np.asarray(moved, np.int64).reshape(-1, 2)
        xy[np.searchsorted(keys, edge_keys(q[:, 0], q[:, 1], n))] = np.asarray(to, float).reshape(-1, 2)
    mid = np.full(len(keys), -1, np.int64)
    mid[split] = n + np.arange(int(split.sum()))
    m = mid[inv]  # (m, 3): the new node on edge j of each triangle
    n_whole = np.sum(m < 0, axis=1)
    v0, v1, v2 = tri.T
    m0, m1, m2 = m.T
    four = n_whole == 0
    out = [np.stack(c, 1)[four] for c in ((v0, m0, m2), (m0, v1, m1), (m2, m1, v2), (m0, m1, m2))]
    # one edge whole: turn each such triangle so that it is edge 2 (v2 -> v0), then cut in three
    three = np.flatnonzero(n_whole == 1)
    r = np.argmax(m[three] < 0, axis=1)  # which edge is whole
    turn = (np.arange(3)[None, :] + (r[:, None] + 1)) % 3  # corners so that the whole edge is 2
    t3, m3 = np.take_along_axis(tri[three], turn, 1), np.take_along_axis(m[three], turn, 1)
    a0, a1, a2 = t3.T
    b0, b1 = m3[:, 0], m3[:, 1]
    new = np.concatenate([points, xy[split]])
    # the quadrilateral a0 b0 b1 a2 is cut along its shorter diagonal
    short = (np.linalg.norm(new[a0] - new[b1], axis=1) <= np.linalg.norm(new[b0] - new[a2], axis=1))[:, None]
    out += [np.stack([b0, a1, b1], 1), np.where(short, np.stack([a0, b0, b1], 1), np.stack([a0, b0, a2], 1)),
            np.where(short, np.stack([a0, b1, a2], 1), np.stack([b0, b1, a2], 1))]
    # one edge halved: turn it to edge 0 (v0 -> v1), then cut from its node to corner 2
    two = np.flatnonzero(n_whole == 2)
    r = np.argmax(m[two] >= 0, axis=1)
    turn = (np.arange(3)[None, :] + r[:, None]) % 3
    t2, c0 = np.take_along_axis(tri[two], turn, 1), np.take_along_axis(m[two], turn, 1)[:, 0]
    out += [np.stack([t2[:, 0], c0, t2[:, 2]], 1), np.stack([c0, t2[:, 1], t2[:, 2]], 1)]
    one = np.flatnonzero(n_whole == 3)
    out.append(tri[one])
    children = np.concatenate(out)
    # a moved node must not fold a triangle over: every child keeps its parent's orientation
    parent = np.concatenate([np.flatnonzero(four)] * 4 + [three] * 3 + [two] * 2 + [one])
    if np.any(np.sign(doubled_areas(new, children)) != np.sign(doubled_areas(points, tri[parent]))):
        raise FoldError("refining the mesh folds a triangle over (a node placed on a curved part or on the strip "
                        "crosses it); raise the level, or move the part away from the others")
    return Refined(points=new, triangles=children, n_old=n, edge_keys=keys, edge_mid=mid)
