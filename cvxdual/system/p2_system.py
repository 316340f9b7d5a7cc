"""The P2 kinematic side on a scene's mesh (docs/equilibrium.md section 12): continuous P2 on the
Alfeld split of the straight triangles (:mod:`cvxdual.system.p2`), the curved pieces' traces,
supports, consistent loads, rigid motions and contact pairs at the face vertices and at the
midpoints of the contact intervals, in the form the active-set fast path solves
(:class:`~cvxdual.system.displacement.DisplacementSolver`).

Nodes. The mesh's nodes keep their ids, then one node per edge of the straight triangles (the
midpoint; :func:`~cvxdual.system.p2.p2_dofs`). The curved pieces carry no node of their own: ``v``
there is the quadratic trace of its face edge continued along y (the paper's rule for P1): the
chord of a segment, a polygon edge of a ``concave2`` piece; on a ``concave1`` piece ``A, B, C``
(side ``BC`` vertical) the trace is the quadratic in x through ``v(A)``, ``v(mid AC)`` and ``v(B)``,
which is ``v`` on the side ``AC``; continuity on ``BC`` then ties ``C`` *and* ``mid BC`` to ``B``.

Contact. Both faces' nodes and interval midpoints lie on common vertical lines, so the pairs are
the P1 pairs and one pair at the midpoint of every contact interval (interleaved by x): the jump
is quadratic on each interval and the constraint holds at its three points; pointwise
admissibility between them is the certificate's business (:mod:`cvxdual.system.quadratic_gap`).

Rigid motions are affine, so P2 interpolates them exactly: the P1 system's floating and
separating motions, interpolated, are the P2 system's, and its loads are balanced on them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import MeshError, SceneError
from ..geometry.pieces import PIECE_KINDS, slab_bound
from ..geometry.quadrature import gauss01
from ..geometry.triangles import bary_gradients, doubled_areas, edge_keys, sub_vertices
from ..linalg.sparse import assemble_blocks
from ..voigt import stiffnesses
from .assembly import Scales, System
from .boundary import Supports, free_dofs, prolongation, supports, to_frames, traction_stretches
from .p2 import (
    N_BOUNDARY,
    SUB_DOFS,
    SUB_NODES,
    Condensed,
    alfeld_stiffness,
    condense,
    p2_dofs,
    shapes_at,
    strain_matrix,
)
from .quadratic_gap import bernstein_gap, gap_curvature
from .rigid import balance, candidates, pivot_columns

CONCAVE1, SEGMENT = PIECE_KINDS.index("concave1"), PIECE_KINDS.index("segment")
SLAB_GAUSS = 10  # points in x per slab: h(x) times a quadratic, exact for polynomial faces of degree <= 17
CHUNK = 4096  # triangles whose 20 x 20 element matrices exist at once (about 13 MB)


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


@dataclass(frozen=True, eq=False)
class P2System:
    """The assembled P2 displacement problem of one P1 :class:`~cvxdual.system.assembly.System`'s mesh:
    element matrices in the nodes' frames (``kloc``, triangles' condensed 12 x 12 then the slabs'
    6 x 6 padded to 12), the global stiffness ``K``, loads ``f`` (balanced), supports and ties
    (``rdof``, ``Z``), the contact pairs (``ja``, ``jb``, ``eps``) and the rigid motions, with
    what the interior recovery needs (``element``, ``interior_load``)."""

    layout: P2Layout
    supports: Supports
    rdof: np.ndarray
    Z: sp.csr_matrix
    K: sp.csr_matrix
    kloc: np.ndarray
    local_dofs: np.ndarray
    f: np.ndarray
    element: Condensed
    interior_load: np.ndarray  # (n_T, 8): K_ii^-1 F_i, the interior dofs of a zero boundary
    ja: np.ndarray
    jb: np.ndarray
    eps: np.ndarray
    anchors: np.ndarray
    floating: np.ndarray
    separating: np.ndarray
    load_correction: float
    scales: Scales

    @property
    def n_r(self) -> int:
        return self.Z.shape[1]

    @property
    def n_dofs(self) -> int:
        return self.Z.shape[0]

    def frame_stiffness(self) -> np.ndarray:
        return self.kloc

    @property
    def local_rdofs(self) -> np.ndarray:
        return np.where(self.local_dofs >= 0, self.rdof[np.maximum(self.local_dofs, 0)], -1)

    @property
    def load_r(self) -> np.ndarray:
        return self.Z.T @ self.f

    def apply_stiffness(self, r: np.ndarray) -> np.ndarray:
        return self.Z.T @ (self.K @ (self.Z @ r))

    def interior(self, q: np.ndarray) -> np.ndarray:
        """``(n_T, 8)``: the condensed interior dofs of global dofs ``q`` (``K_ii^-1 F_i - R u_b``)."""
        return self.interior_load - np.einsum("tik,tk->ti", self.element.R, np.asarray(q, float)[self.layout.dofs])


def element_slab_rule(pieces, lay: P2Layout, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A tensor Gauss rule with ``n`` points per direction on the slabs that take an element's quadratic:
    ``(slab (m,), points (m, n*n, 2), weights (m, n*n))``. On a segment it covers the segment (beyond the
    chord), with positive weights; on a ``concave1`` piece the sliver between the chord ``AB`` and the
    arc (inside ``A, B, C`` but outside the body), with *negative* weights: the piece's integrals are the
    element's minus the sliver's. Exact in y for polynomials of degree ``2n - 1``; in x, a polynomial
    times the smooth arc (converged to rounding)."""
    sel = np.flatnonzero(lay.slab_tri >= 0)
    if not len(sel):
        return sel, np.zeros((0, n * n, 2)), np.zeros((0, n * n))
    s = pieces.slabs
    mask = np.zeros(len(s), bool)
    mask[sel] = True
    pts, w, _ = pieces.slab_quadrature(n, only=mask)  # grouped by slab, in slab order
    pts, w = pts.reshape(len(sel), n * n, 2), w.reshape(len(sel), n * n)
    c1 = np.flatnonzero(pieces.kind[s.piece[sel]] == CONCAVE1)
    if len(c1):
        k = sel[c1]
        u, wu = gauss01(n)
        (xa, xb), (ya, yb) = lay.coords[s.edge_nodes[k]].transpose(2, 1, 0)  # (2, m) each: x, y of A and B
        x = xa[:, None] + u[None, :] * (xb - xa)[:, None]
        chord = ya[:, None] + u[None, :] * (yb - ya)[:, None]
        arc = np.stack([pieces.faces[b].value(xx) for b, xx in zip(s.body[k], x, strict=True)])
        y = chord[:, :, None] + u[None, None, :] * (arc - chord)[:, :, None]
        pts[c1] = np.stack([np.broadcast_to(x[:, :, None], y.shape), y], -1).reshape(len(k), n * n, 2)
        w[c1] = -((xb - xa)[:, None, None] * wu[None, :, None] * np.abs(arc - chord)[:, :, None]
                  * wu[None, None, :]).reshape(len(k), n * n)
    return sel, pts, w


def segment_elements(pieces, lay: P2Layout, X: np.ndarray, C: np.ndarray,
                     F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the curved pieces add to their elements' matrices, in the element's local dofs: ``(t (m,),
    K (m, 20, 20), load (m, 20))`` (:func:`element_slab_rule`: a segment's energy added, a ``concave1``
    sliver's removed), with ``C``, ``F`` per element."""
    sel, pts, w = element_slab_rule(pieces, lay, SLAB_GAUSS)
    m = len(sel)
    if not m:
        return np.zeros(0, int), np.zeros((0, 20, 20)), np.zeros((0, 20))
    t, j = lay.slab_tri[sel], lay.slab_sub[sel]
    N, dN = shapes_at(sub_vertices(X[t])[np.arange(m), j], pts)
    B = strain_matrix(dN)  # (m, q, 3, 12)
    d = SUB_DOFS[j]  # (m, 12)
    K = np.zeros((m, 20, 20))
    K[np.arange(m)[:, None, None], d[:, :, None], d[:, None, :]] = np.einsum("mq,mqai,mab,mqbj->mij", w, B, C[t], B)
    load = np.zeros((m, 20))
    load[np.arange(m)[:, None], d] = np.einsum("mq,mqa,mc->mac", w, N, F[t]).reshape(m, 12)
    return t, K, load


def p2_rigid_modes(cand: np.ndarray, K: sp.csr_matrix, sup: Supports, rdof: np.ndarray, ja: np.ndarray,
                   jb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motions of the P2 space in r, ``floating`` (keeping the bodies together) and
    ``separating``, as :func:`cvxdual.system.rigid.rigid_modes` finds them for P1: combinations of the
    candidates ``cand`` (the bodies' translations and rotations at the P2 nodes, ``(n_dofs, 6)``) that
    respect the supports and ties and have no energy in ``K``. P2 interpolates them exactly; which are
    free differs from P1 where P1 holds a rotation that P2 does not (a segment's continued quadratic is
    not strained by a rotation, a P1 slab's trace along y is)."""
    n_dofs = len(rdof)
    n_r = int(rdof.max()) + 1
    in_frames = np.einsum("kci,kim->kcm", sup.frame, cand.reshape(-1, 2, cand.shape[1])).reshape(n_dofs, -1)
    free = np.flatnonzero(rdof >= 0)
    first = np.full(n_r, n_dofs)
    np.minimum.at(first, rdof[free], free)
    rows = np.concatenate([in_frames[rdof < 0], in_frames[free] - in_frames[first[rdof[free]]]])
    _, s, vt = np.linalg.svd(rows, full_matrices=False) if len(rows) else (None, np.zeros(0), np.eye(cand.shape[1]))
    # rounding of exact motions against O(1) entries of a genuine constraint, as in rigid_modes
    null = vt[s <= 1e-9 * s[0]].T if len(s) and s[0] > 0 else np.eye(cand.shape[1])
    empty = np.empty((n_r, 0))
    if not null.shape[1]:
        return empty, empty
    q = cand @ null
    energy = q.T @ (K @ q)
    size = np.abs(q).T @ (abs(K) @ np.abs(q))  # the sums the energies are made of: their rounding's scale
    w, U = np.linalg.eigh(0.5 * (energy + energy.T))
    null = null @ U[:, w <= 1e-11 * float(np.diag(size).max())]
    if not null.shape[1]:
        return empty, empty
    modes = in_frames[first] @ null
    D = modes[jb] - modes[ja]
    D = np.vstack([D, np.zeros((max(0, D.shape[1] - len(D)), D.shape[1]))])
    _, s2, vt2 = np.linalg.svd(D, full_matrices=False)
    rank = int(np.sum(s2 > 1e-9 * max(s2[0] if len(s2) else 0.0, 1.0)))
    return modes @ vt2[rank:].T, modes @ vt2[:rank].T


def triangle_elements(X: np.ndarray, C: np.ndarray, F: np.ndarray,
                      extra=None) -> tuple[Condensed, np.ndarray, np.ndarray]:
    """Condensed element matrices of the straight triangles ``X`` with Hooke matrices ``C`` and constant
    body forces ``F`` ``(n_T, 2)``, by chunks of :data:`CHUNK`: ``(Condensed, Fb (n_T, 12), K_ii^-1 F_i)``.
    A constant force's load on the split: ``area / 3`` at each sub-triangle's edge midpoints
    (P2 vertex functions integrate to zero). ``extra``: :func:`segment_elements`, added before the
    condensation."""
    n = len(X)
    S, R, Fb, ui = np.zeros((n, 12, 12)), np.zeros((n, 8, 12)), np.zeros((n, 12)), np.zeros((n, 8))
    et, eK, eF = extra if extra is not None else (np.zeros(0, int), np.zeros((0, 20, 20)), np.zeros((0, 20)))
    for lo in range(0, n, CHUNK):
        s = slice(lo, min(lo + CHUNK, n))
        K = alfeld_stiffness(X[s], C[s])
        here = (et >= lo) & (et < lo + len(K))
        np.add.at(K, et[here] - lo, eK[here])
        cond = condense(K)
        _, area = bary_gradients(sub_vertices(X[s]).reshape(-1, 3, 2))
        load = np.zeros((len(cond.S), 10, 2))
        for i in range(3):
            np.add.at(load, (slice(None), SUB_NODES[i, 3:]), (area.reshape(-1, 3)[:, i, None, None] / 3.0)
                      * F[s, None, :])
        load = load.reshape(-1, 20)
        np.add.at(load, et[here] - lo, eF[here])
        S[s], R[s] = cond.S, cond.R
        Fi = load[:, N_BOUNDARY:]
        Fb[s] = load[:, :N_BOUNDARY] - np.einsum("tik,ti->tk", cond.R, Fi)
        ui[s] = np.linalg.solve(cond.Kii, Fi[:, :, None])[:, :, 0]
    return Condensed(S=S, R=R, Kii=np.zeros((0, 8, 8))), Fb, ui


def slab_elements(pieces, layout: P2Layout, C: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness ``(n_s, 6, 6)`` and body-force load ``(n_s, 6)`` of every slab on the dofs of its
    trace's nodes (left, middle, right): ``v(x, y) = w(x)``, strain ``(w_x', 0, w_y')``, integrated
    by :data:`SLAB_GAUSS` Gauss points in x times the slab's height."""
    s = pieces.slabs
    u, w = gauss01(SLAB_GAUSS)
    x = s.xl[:, None] + u[None, :] * (s.xr - s.xl)[:, None]
    idx = np.repeat(np.arange(len(s)), SLAB_GAUSS)
    h = (slab_bound(s, pieces.faces, x.ravel(), idx, "hi") - slab_bound(s, pieces.faces, x.ravel(), idx, "lo"))
    wh = w[None, :] * (s.xr - s.xl)[:, None] * h.reshape(x.shape)
    dx = layout.slab_x[:, 1] - layout.slab_x[:, 0]
    N, dN = trace_shapes((x - layout.slab_x[:, :1]) / dx[:, None])
    dN = dN / dx[:, None, None]
    B = np.zeros(x.shape + (3, 6))
    B[..., 0, 0::2] = dN
    B[..., 2, 1::2] = dN
    K = np.einsum("sq,sqai,sab,sqbj->sij", wh, B, C, B)
    load = np.einsum("sq,sqa,sc->sac", wh, N, F).reshape(-1, 6)
    return K, load


def trace_loads(mesh, layout: P2Layout, n: int) -> np.ndarray:
    """The tractions' consistent P2 loads ``(n,)``: each stretch ``(a, b)`` against the quadratic
    functions of ``a``, its middle and ``b`` (on the face: in x, the trace's)."""
    f = np.zeros(n)
    for a, b, u, P in traction_stretches(mesh):
        mid = layout.edge_node(a, b)
        if np.any(mid < 0):
            raise MeshError("internal: a loaded stretch without a P2 midpoint")  # pragma: no cover
        N, _ = trace_shapes(u)  # (g, 3)
        for k, node in enumerate((a, mid, b)):
            for c in (0, 1):
                f += np.bincount(2 * node + c, P[..., c] @ N[:, k], n)
    return f


def assemble_p2_system(system: System) -> P2System:
    """The :class:`P2System` on the mesh and pieces of a P1 ``system`` (its scales, rigid motions)."""
    mesh, pieces = system.mesh, system.pieces
    scene = mesh.scene
    lay = p2_layout(mesh, pieces)
    n = lay.n_p2
    sup = supports(mesh, (lay.edge_node, n))
    used = np.zeros(n, bool)
    used[lay.nodes], used[lay.slab_nodes] = True, True
    if not used.all():  # a node of no element (gmsh keeps an arc's centre point): no energy, no load; held
        sup = Supports(fixed=sup.fixed | ~used[:, None], frame=sup.frame)
    rdof = free_dofs(sup, None)
    Z = prolongation(sup, rdof)
    stiff = stiffnesses(scene)
    force = np.array([b.body_force for b in scene.bodies], float)
    body_t = np.concatenate([pieces.body[pieces.kind == 0], pieces.body[pieces.kind == CONCAVE1]]).astype(int)
    X = mesh.points[lay.tri]
    segments = segment_elements(pieces, lay, X, stiff[body_t], force[body_t])
    cond, Fb, ui = triangle_elements(X, stiff[body_t], force[body_t], segments)
    sb = pieces.slabs.body.astype(int)
    Ks, Fs = slab_elements(pieces, lay, stiff[sb], force[sb])
    Ks[lay.slab_tri >= 0], Fs[lay.slab_tri >= 0] = 0.0, 0.0  # in their elements' matrices
    sdofs = (2 * lay.slab_nodes[:, :, None] + np.arange(2)).reshape(-1, 6)
    dofs = np.vstack([lay.dofs, np.hstack([sdofs, np.full((len(sdofs), 6), -1)])])
    kglob = np.zeros((len(dofs), 12, 12))
    kglob[:len(lay.tri)] = cond.S
    kglob[len(lay.tri):, :6, :6] = Ks
    K = assemble_blocks(dofs, dofs, kglob, (2 * n, 2 * n))
    K = (0.5 * (K + K.T)).tocsr()  # sums in different orders for (i, j) and (j, i): exactly symmetric
    kloc = np.zeros_like(kglob)
    kloc[:len(lay.tri)] = to_frames(sup, lay.nodes, cond.S)
    kloc[len(lay.tri):, :6, :6] = to_frames(sup, lay.slab_nodes, Ks)
    f = np.bincount(lay.dofs.ravel(), Fb.ravel(), 2 * n) + np.bincount(sdofs.ravel(), Fs.ravel(), 2 * n)
    f += trace_loads(mesh, lay, 2 * n)
    if not np.all(np.isfinite(f)):
        raise SceneError("the load vector is not finite; check the loads and the exact field")
    up, lo = lay.pair_nodes.T
    ja, jb = rdof[2 * up + 1], rdof[2 * lo + 1]
    if np.any(ja < 0) or np.any(jb < 0) or len(np.intersect1d(lay.pair_nodes, sup.rotated)):
        raise SceneError("a support acts on a contact node or midpoint; set a [contact] interval that stops "
                         "short of the supported part, or move the support off the contact interval")
    Ip = interpolation(lay)
    floating, separating = p2_rigid_modes(Ip @ candidates(mesh), K, sup, rdof, ja, jb)
    correction = 0.0
    if floating.shape[1]:
        f, _, correction = balance(Z @ floating, f, Ip @ candidates(mesh))
    # the faces' middle y values become the middle Bernstein coefficients (module docstring)
    faces = (scene.upper.face, scene.lower.face)
    mid, gamma, beta = face_middles((lay, sup, rdof, cond, ui, faces, Z.shape[1]), ja, jb)
    W, W_inv = middle_maps(mid, gamma)
    local = np.where(dofs >= 0, rdof[np.maximum(dofs, 0)], -1)
    local[len(lay.tri):][lay.slab_tri >= 0] = -1  # a segment's (zero) slab matrix: its triangle holds it
    kloc = element_maps(kloc, local, mid, W)
    floating, separating = W_inv @ floating, W_inv @ separating
    anchors = np.empty(0, int)
    if floating.shape[1]:
        keep = np.ones(Z.shape[1], bool)
        keep[jb] = False
        J0 = np.flatnonzero(keep)
        anchors = np.sort(J0[pivot_columns(floating[J0].T)])
    xv, ev = lay.pair_x[0::2], scene.gap_at(lay.pair_x[0::2])
    eps = np.zeros(len(lay.pair_x))
    n_c = len(xv) - 1
    # the middle's constant part moves to the gap: gamma . r + 2 beta is the coefficient
    eps[0::2], eps[1::2] = ev, bernstein_gap(xv, ev, gap_curvature(scene, xv[:-1], xv[1:])) - 2.0 * (
        beta[n_c:] - beta[:n_c])
    dofs[len(lay.tri):][lay.slab_tri >= 0] = -1
    return P2System(layout=lay, supports=sup, rdof=rdof, Z=(Z @ W).tocsr(), K=K, kloc=kloc, local_dofs=dofs, f=f,
                    element=cond, interior_load=ui, ja=ja, jb=jb, eps=eps, anchors=anchors,
                    floating=floating, separating=separating, load_correction=correction, scales=system.scales)


def face_middles(system_parts, ja: np.ndarray, jb: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
    """The faces' middle unknowns: for every contact interval and face (upper, then lower), the r index
    ``m`` of its middle's y value, the row ``gamma`` ``(len(m), n_r)`` with ``gamma . r`` the middle
    Bernstein coefficient ``2 a(x_m) - (a(x_0) + a(x_1)) / 2`` of the face's ``v_y`` on the true face
    (``a`` at the ends: the vertex values; in the middle: the trace's middle value, or on a segment its
    triangle's quadratic at the arc's point, interior dofs condensed) and its constant part ``beta``
    (the interior dofs' load) ``(len(m),)``."""
    lay, sup, rdof, cond, ui, faces, n_r = system_parts
    mid = np.concatenate([ja[1::2], jb[1::2]])
    ends = np.stack([np.concatenate([ja[0:-1:2], jb[0:-1:2]]), np.concatenate([ja[2::2], jb[2::2]])], 1)
    k = np.arange(len(mid))
    rows, cols, vals = [k, k, k], [mid, ends[:, 0], ends[:, 1]], [np.full(len(mid), 2.0), np.full(len(mid), -0.5),
                                                                 np.full(len(mid), -0.5)]
    beta = np.zeros(len(mid))
    n_c = len(ja) // 2
    slabs = middle_slabs(lay, n_c)
    seg = np.flatnonzero(lay.on_element(slabs))
    if len(seg):
        t, j = lay.slab_tri[slabs[seg]], lay.slab_sub[slabs[seg]]
        P = sub_vertices(lay.coords[lay.tri[t]])[np.arange(len(t)), j]
        xm = 0.5 * (lay.pair_x[0:-1:2] + lay.pair_x[2::2])[seg % n_c]
        ym = np.where(seg < n_c, faces[0].value(xm), faces[1].value(xm))
        N, _ = shapes_at(P, np.stack([xm, ym], 1)[:, None])
        a20 = np.zeros((len(seg), 20))
        a20[np.arange(len(seg))[:, None], 2 * SUB_NODES[j] + 1] = N[:, 0]
        a12 = a20[:, :N_BOUNDARY] - np.einsum("mik,mi->mk", cond.R[t], a20[:, N_BOUNDARY:])
        beta[seg] = np.einsum("mi,mi->m", a20[:, N_BOUNDARY:], ui[t])
        nodes = lay.nodes[t]  # (m, 6): coefficients in the nodes' frames (q_c = sum_k frame[k, c] r_k)
        coef = np.einsum("mnkc,mnc->mnk", sup.frame[nodes], a12.reshape(-1, 6, 2))
        r = rdof[2 * nodes[:, :, None] + np.arange(2)]
        live = r >= 0
        vals[0][seg] = 0.0  # the middle's own 2: now in the quadratic's coefficients
        rows.append(np.broadcast_to(seg[:, None, None], r.shape)[live])
        cols.append(r[live])
        vals.append(2.0 * coef[live])
    gamma = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(len(mid), n_r))
    return mid, gamma, beta


def middle_slabs(lay: P2Layout, n_c: int) -> np.ndarray:
    """``(2 n_c,)``: the slab under each contact interval of the upper, then the lower face, or -1."""
    out = np.full(2 * n_c, -1)
    if not len(lay.slab_nodes):
        return out
    key = edge_keys(lay.slab_nodes[:, 0], lay.slab_nodes[:, 2], lay.n_nodes)
    order = np.argsort(key)
    pn = lay.pair_nodes
    want = np.concatenate([edge_keys(pn[0:-1:2, b], pn[2::2, b], lay.n_nodes) for b in (0, 1)])
    i = order[np.clip(np.searchsorted(key[order], want), 0, len(order) - 1)]
    return np.where(key[i] == want, i, -1)


def middle_maps(mid: np.ndarray, gamma: sp.csr_matrix) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``W`` and ``W^-1`` ``(n_r, n_r)`` with ``r = W r'``: ``r'`` is ``r`` but at the middles ``mid``, where it is
    ``gamma . r``; ``r_m = (r'_m - sum_(k != m) gamma_k r_k) / gamma_m`` (the other unknowns stay)."""
    n_r = gamma.shape[1]
    g = gamma.tocoo()
    own = gamma[np.arange(len(mid)), mid].A1
    if np.any(np.abs(own) < 1e-3 * abs(gamma).max(axis=1).toarray().ravel()):
        raise MeshError("internal: a face middle's own coefficient vanishes")  # pragma: no cover
    keep = np.ones(n_r, bool)
    keep[mid] = False
    eye = sp.diags(keep.astype(float), format="csr")
    inv = eye + sp.csr_matrix((g.data, (mid[g.row], g.col)), shape=(n_r, n_r))
    off = g.col != mid[g.row]
    W = eye + sp.csr_matrix((np.concatenate([1.0 / own, -g.data[off] / own[g.row[off]]]),
                             (np.concatenate([mid, mid[g.row[off]]]), np.concatenate([mid, g.col[off]]))),
                            shape=(n_r, n_r))
    return W.tocsr(), inv.tocsr()


def element_maps(kloc: np.ndarray, local: np.ndarray, mid: np.ndarray, W: sp.csr_matrix) -> np.ndarray:
    """Element matrices ``W_e^T k W_e`` in the variables of :func:`middle_maps`: ``W_e`` the rows of ``W`` on the
    element's unknowns (each r index at its first local position). Every element holding a middle holds
    every unknown its row names (the face edge's triangle, its slab): checked."""
    where = np.full(W.shape[0], -1)
    where[mid] = np.arange(len(mid))
    hit_e, hit_i = np.nonzero((local >= 0) & (where[np.maximum(local, 0)] >= 0))
    if not len(hit_e):
        return kloc
    loc = local[hit_e]  # (h, 12)
    first = np.ones(loc.shape, bool)
    for p in range(1, loc.shape[1]):  # 12 positions: a tied node repeats its master's index
        first[:, p] = ~np.any(loc[:, :p] == loc[:, p:p + 1], axis=1)
    first &= loc >= 0
    rows = W[local[hit_e, hit_i]]  # (h, n_r)
    block = rows[np.arange(len(hit_e))[:, None], np.maximum(loc, 0)].toarray() * first
    if not np.allclose(block.sum(1), rows.sum(1).A1, rtol=1e-12, atol=1e-12 * abs(rows).max()):
        raise MeshError("internal: a face middle's map names an unknown outside its element")  # pragma: no cover
    elems = np.unique(hit_e)
    We = np.broadcast_to(np.eye(kloc.shape[1]), (len(elems), kloc.shape[1], kloc.shape[1])).copy()
    We[np.searchsorted(elems, hit_e), hit_i] = block
    out = kloc.copy()
    out[elems] = We.transpose(0, 2, 1) @ kloc[elems] @ We
    return out
