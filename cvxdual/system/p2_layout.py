"""Where the P2 kinematic side's nodes are on a scene's mesh (:class:`P2Layout`, :func:`p2_layout`): the
elements (the straight triangles, then type 1's concave triangles ``A, B, C``), one node per element
edge, the curved pieces' traces or elements, the contact pairs at the face vertices and at the
midpoints of the contact intervals. The system on it: :mod:`cvxdual.system.p2_system`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import MeshError
from ..geometry.pieces import PIECE_KINDS
from ..geometry.triangles import doubled_areas, edge_keys
from .p2 import p2_dofs

CONCAVE1, SEGMENT = PIECE_KINDS.index("concave1"), PIECE_KINDS.index("segment")


def trace_shapes(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The quadratic Lagrange functions on ``[0, 1]`` with nodes ``0, 1/2, 1`` and their derivatives
    at ``t`` (``(..., 3)`` each, in that node order)."""
    t = np.asarray(t, float)[..., None]
    N = np.concatenate([(1 - t) * (1 - 2 * t), 4 * t * (1 - t), t * (2 * t - 1)], -1)
    dN = np.concatenate([4 * t - 3, 4 - 8 * t, 4 * t - 1], -1)
    return N, dN


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class P2Layout:
    """Where the P2 nodes are: ``tri`` the elements (the straight triangles as the equilibrium space
    orders them, then the triangles ``A, B, C`` of the ``concave1`` pieces), ``nodes`` ``(n_e, 6)``
    their corners and edge midpoints, ``coords`` ``(n_p2, 2)``, ``keys`` the sorted edge keys (edge
    node ``n_nodes + i``), ``slab_nodes`` ``(n_s, 3)`` the (left, middle, right) nodes of each slab's
    face edge and ``slab_x`` ``(n_s, 2)`` its ends, ``pair_nodes`` ``(n_q, 2)`` the (upper, lower)
    nodes of the contact pairs at ``pair_x``, ``slab_tri``, ``slab_sub`` (:func:`slab_triangles`)."""

    n_nodes: int
    n_straight: int  # the first rows of tri: the equilibrium space's straight triangles, in its order
    tri: np.ndarray
    nodes: np.ndarray
    coords: np.ndarray
    keys: np.ndarray
    slab_nodes: np.ndarray
    slab_x: np.ndarray
    pair_nodes: np.ndarray
    pair_x: np.ndarray
    slab_tri: np.ndarray  # (n_s,): the element whose quadratic gives v on the slab, or -1 (the trace along y)
    slab_sub: np.ndarray  # (n_s,): its sub-triangle on the face edge (X_j, X_j+1)

    @property
    def n_p2(self) -> int:
        return len(self.coords)

    def on_element(self, slab: np.ndarray) -> np.ndarray:
        """Which of the slabs ``slab`` (-1: none) take an element's quadratic (:func:`slab_triangles`)."""
        slab = np.asarray(slab)
        if not len(self.slab_tri):
            return np.zeros(slab.shape, bool)
        return (slab >= 0) & (self.slab_tri[np.maximum(slab, 0)] >= 0)

    def edge_node(self, a, b) -> np.ndarray:
        """The node at the midpoint of each edge ``(a, b)`` of the straight triangles, -1 where there is none."""
        k = edge_keys(a, b, self.n_nodes)
        i = np.clip(np.searchsorted(self.keys, k), 0, max(len(self.keys) - 1, 0))
        return np.where(self.keys[i] == k, self.n_nodes + i, -1) if len(self.keys) else np.full(k.shape, -1)

    @property
    def dofs(self) -> np.ndarray:
        """``(n_T, 12)``: the global dofs ``2 k + c`` of each triangle's corners and midpoints."""
        return (2 * self.nodes[:, :, None] + np.arange(2)).reshape(len(self.nodes), 12)


def p2_layout(mesh, pieces) -> P2Layout:
    """The :class:`P2Layout` of a mesh and its pieces (module docstring)."""
    n = mesh.n_nodes
    straight = pieces.nodes[pieces.kind == 0]
    abc = pieces.nodes[pieces.kind == CONCAVE1]
    abc = np.where((doubled_areas(mesh.points, abc) < 0)[:, None], abc[:, [0, 2, 1]], abc)  # counter-clockwise
    tri = np.vstack([straight, abc])
    nodes, coords = p2_dofs(mesh.points, tri)
    keys = np.unique(edge_keys(tri, np.roll(tri, -1, axis=1), n))  # p2_dofs numbers edges in this order
    plain = P2Layout(n, len(straight), tri, nodes, coords, keys, *(np.zeros((0, k), int) for k in (3, 2, 2)),
                     np.zeros(0), np.zeros(0, int), np.zeros(0, int))

    def face_mid(a, b):
        m = plain.edge_node(a, b)
        if np.any(m < 0):
            raise MeshError("internal: a face edge without a P2 midpoint")  # pragma: no cover
        return m

    en = pieces.slabs.edge_nodes
    slab_nodes = np.stack([en[:, 0], face_mid(en[:, 0], en[:, 1]), en[:, 1]], 1) if len(en) else \
        np.zeros((0, 3), int)
    up, lo = mesh.pairs.T
    q = len(up)
    pair_nodes = np.zeros((max(2 * q - 1, 0), 2), int)
    pair_nodes[0::2] = mesh.pairs
    pair_x = np.zeros(len(pair_nodes))
    pair_x[0::2] = mesh.pair_x
    if q > 1:
        pair_nodes[1::2] = np.stack([face_mid(up[:-1], up[1:]), face_mid(lo[:-1], lo[1:])], 1)
        pair_x[1::2] = 0.5 * (mesh.pair_x[:-1] + mesh.pair_x[1:])
    slab_tri, slab_sub = slab_triangles(pieces, tri, n)
    return P2Layout(n, len(straight), tri, nodes, coords, keys, slab_nodes,
                    mesh.points[en, 0] if len(en) else np.zeros((0, 2)), pair_nodes, pair_x, slab_tri, slab_sub)


def slab_triangles(pieces, tri: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """For every slab: the element whose quadratic gives ``v`` there, and the sub-triangle of its split on
    the face edge ``AB``, or -1 (and 0) where ``v`` is the face edge's trace continued along y
    (``concave2``). A segment (between the chord ``AB`` of ``T0 = (A, B, C)`` and a convex arc) takes
    ``T0``'s quadratic continued beyond the chord; a ``concave1`` piece (``A, B, C`` less the sliver
    between its chord and the concave arc) is the element ``A, B, C`` itself, its energy taken over the
    body only (module docstring)."""
    s = pieces.slabs
    out_t, out_j = np.full(len(s), -1), np.zeros(len(s), int)
    sel = np.flatnonzero(np.isin(pieces.kind[s.piece], (SEGMENT, CONCAVE1))) if len(s) else np.zeros(0, int)
    if not len(sel):
        return out_t, out_j
    code = lambda t: np.sort(np.asarray(t, np.int64), 1) @ np.array([n * n, n, 1], np.int64)  # noqa: E731
    tcode = code(tri)
    order = np.argsort(tcode)
    want = code(pieces.nodes[s.piece[sel]])
    t = order[np.clip(np.searchsorted(tcode[order], want), 0, len(order) - 1)]
    if np.any(tcode[t] != want):
        raise MeshError("internal: a curved piece without its element")  # pragma: no cover
    a, b = s.edge_nodes[sel].T
    corners = tri[t]
    on = (corners == a[:, None]) | (corners == b[:, None])  # (m, 3): the face edge's ends among X0, X1, X2
    # the face edge is (X_j, X_j+1): the corner not on it is X_(j+2)
    out_t[sel], out_j[sel] = t, (np.argmin(on, axis=1) + 1) % 3
    return out_t, out_j


def interpolation(layout: P2Layout) -> sp.csr_matrix:
    """``(2 n_p2, 2 n_nodes)``: P1 nodal values to the P2 nodes (midpoints: the mean of the ends),
    exact for affine displacements (rigid motions)."""
    n, m = layout.n_nodes, len(layout.keys)
    a, b = layout.keys // n, layout.keys % n
    rows = np.concatenate([np.arange(n), n + np.arange(m), n + np.arange(m)])
    cols = np.concatenate([np.arange(n), a, b])
    vals = np.concatenate([np.ones(n), np.full(2 * m, 0.5)])
    rows, cols = (np.stack([2 * r, 2 * r + 1], 1).ravel() for r in (rows, cols))
    return sp.csr_matrix((np.repeat(vals, 2), (rows, cols)), shape=(2 * layout.n_p2, 2 * n))
