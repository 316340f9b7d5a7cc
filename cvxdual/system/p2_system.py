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
from ..geometry.triangles import bary_gradients, edge_keys, sub_vertices
from ..linalg.sparse import assemble_blocks
from ..voigt import stiffnesses
from .assembly import Scales, System
from .boundary import Supports, free_dofs, prolongation, supports, to_frames, traction_stretches
from .p2 import N_BOUNDARY, SUB_NODES, Condensed, alfeld_stiffness, condense, p2_dofs
from .quadratic_gap import bernstein_gap, gap_curvature
from .rigid import balance, candidates, pivot_columns

CONCAVE1 = PIECE_KINDS.index("concave1")
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
    """Where the P2 nodes are: ``tri`` the straight triangles (as the equilibrium space orders them),
    ``nodes`` ``(n_T, 6)`` their corners and edge midpoints, ``coords`` ``(n_p2, 2)``, ``keys`` the
    sorted edge keys (edge node ``n_nodes + i``), ``slab_nodes`` ``(n_s, 3)`` the (left, middle,
    right) nodes of each slab's trace and ``slab_x`` ``(n_s, 2)`` its ends, ``pair_nodes`` ``(n_q, 2)``
    the (upper, lower) nodes of the contact pairs at ``pair_x``, ``ties`` ``(m, 2)`` (tied, master)."""

    n_nodes: int
    tri: np.ndarray
    nodes: np.ndarray
    coords: np.ndarray
    keys: np.ndarray
    slab_nodes: np.ndarray
    slab_x: np.ndarray
    pair_nodes: np.ndarray
    pair_x: np.ndarray
    ties: np.ndarray

    @property
    def n_p2(self) -> int:
        return len(self.coords)

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
    tri = pieces.nodes[pieces.kind == 0]
    nodes, coords = p2_dofs(mesh.points, tri)
    keys = np.unique(edge_keys(tri, np.roll(tri, -1, axis=1), n))  # p2_dofs numbers edges in this order
    plain = P2Layout(n, tri, nodes, coords, keys, *(np.zeros((0, k), int) for k in (3, 2, 2)), np.zeros(0),
                     np.zeros((0, 2), int))
    A, B, C = pieces.nodes[pieces.kind == CONCAVE1].T
    alt_keys, alt_node = edge_keys(A, B, n), plain.edge_node(A, C)  # a concave1 face edge's middle: mid AC
    order = np.argsort(alt_keys)

    def face_mid(a, b):
        m = plain.edge_node(a, b)
        if np.any(m < 0) and len(alt_keys):
            k = edge_keys(a, b, n)
            i = order[np.clip(np.searchsorted(alt_keys[order], k), 0, len(order) - 1)]
            m = np.where((m < 0) & (alt_keys[i] == k), alt_node[i], m)
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
    mid_bc = plain.edge_node(B, C)
    ties = np.concatenate([np.stack([C, B], 1), np.stack([mid_bc, B], 1)[mid_bc >= 0]]).astype(int)
    return P2Layout(n, tri, nodes, coords, keys, slab_nodes, mesh.points[en, 0] if len(en) else np.zeros((0, 2)),
                    pair_nodes, pair_x, ties)


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


def restriction(sup: Supports, rdof: np.ndarray) -> sp.csr_matrix:
    """``(n_r, n_dofs)``: the frame component of each r index at its first (master) node: ``r = R q``
    for a ``q`` that respects the supports and ties (``q = Z r``)."""
    free = np.flatnonzero(rdof >= 0)
    n_r = int(rdof.max()) + 1
    first = np.full(n_r, len(rdof))
    np.minimum.at(first, rdof[free], free)
    k, c = np.divmod(first, 2)
    ax = sup.frame[k, c]  # (n_r, 2)
    rows = np.repeat(np.arange(n_r), 2)
    return sp.csr_matrix((ax.ravel(), (rows, (2 * k[:, None] + np.arange(2)).ravel())), shape=(n_r, len(rdof)))


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


def triangle_elements(X: np.ndarray, C: np.ndarray, F: np.ndarray) -> tuple[Condensed, np.ndarray, np.ndarray]:
    """Condensed element matrices of the straight triangles ``X`` with Hooke matrices ``C`` and constant
    body forces ``F`` ``(n_T, 2)``, by chunks of :data:`CHUNK`: ``(Condensed, Fb (n_T, 12), K_ii^-1 F_i)``.
    A constant force's load on the split: ``area / 3`` at each sub-triangle's edge midpoints
    (P2 vertex functions integrate to zero)."""
    n = len(X)
    S, R, Fb, ui = np.zeros((n, 12, 12)), np.zeros((n, 8, 12)), np.zeros((n, 12)), np.zeros((n, 8))
    for lo in range(0, n, CHUNK):
        s = slice(lo, min(lo + CHUNK, n))
        cond = condense(alfeld_stiffness(X[s], C[s]))
        _, area = bary_gradients(sub_vertices(X[s]).reshape(-1, 3, 2))
        load = np.zeros((len(cond.S), 10, 2))
        for i in range(3):
            np.add.at(load, (slice(None), SUB_NODES[i, 3:]), (area.reshape(-1, 3)[:, i, None, None] / 3.0)
                      * F[s, None, :])
        load = load.reshape(-1, 20)
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
    functions of ``a``, its middle and ``b`` (on the face, the trace's middle)."""
    f = np.zeros(n)
    for a, b, u, P in traction_stretches(mesh):
        mid = layout.edge_node(a, b)
        if np.any(mid < 0):  # a face stretch of a concave1 piece: its trace's middle is mid AC
            mid = np.where(mid < 0, _face_mid(layout, a, b), mid)
        N, _ = trace_shapes(u)  # (g, 3)
        for k, node in enumerate((a, mid, b)):
            for c in (0, 1):
                f += np.bincount(2 * node + c, P[..., c] @ N[:, k], n)
    return f


def _face_mid(layout: P2Layout, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The middle node of face stretches ``(a, b)`` that are slab traces (their ``slab_nodes``)."""
    sn = layout.slab_nodes
    k = edge_keys(sn[:, 0], sn[:, 2], layout.n_nodes)
    order = np.argsort(k)
    want = edge_keys(a, b, layout.n_nodes)
    i = order[np.clip(np.searchsorted(k[order], want), 0, max(len(k) - 1, 0))] if len(k) else np.zeros(len(a), int)
    if not len(k) or np.any(k[i] != want):
        raise MeshError("internal: a loaded stretch without a P2 midpoint")  # pragma: no cover
    return sn[i, 1]


def assemble_p2_system(system: System) -> P2System:
    """The :class:`P2System` on the mesh and pieces of a P1 ``system`` (its scales, rigid motions)."""
    mesh, pieces = system.mesh, system.pieces
    scene = mesh.scene
    lay = p2_layout(mesh, pieces)
    n = lay.n_p2
    sup = supports(mesh, (lay.edge_node, n)).tied(lay.ties)
    used = np.zeros(n, bool)
    used[lay.nodes], used[lay.slab_nodes] = True, True
    if not used.all():  # a node of no element (gmsh keeps an arc's centre point): no energy, no load; held
        sup = Supports(fixed=sup.fixed | ~used[:, None], frame=sup.frame)
    rdof = free_dofs(sup, lay.ties)
    Z = prolongation(sup, rdof)
    stiff = stiffnesses(scene)
    force = np.array([b.body_force for b in scene.bodies], float)
    body_t = pieces.body[pieces.kind == 0].astype(int)
    cond, Fb, ui = triangle_elements(mesh.points[lay.tri], stiff[body_t], force[body_t])
    sb = pieces.slabs.body.astype(int)
    Ks, Fs = slab_elements(pieces, lay, stiff[sb], force[sb])
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
    # rigid motions: the P1 system's, interpolated (exact: they are affine)
    Ip, Rq = interpolation(lay), restriction(sup, rdof)
    to_p2 = lambda m: Rq @ (Ip @ (system.Z @ m))  # noqa: E731 - P1 motions in r to P2 motions in r
    floating, separating = to_p2(system.floating), to_p2(system.separating)
    correction = 0.0
    if floating.shape[1]:
        f, _, correction = balance(Z @ floating, f, Ip @ candidates(mesh))
    # the faces' middle y values become the middle Bernstein coefficients (module docstring)
    mid, ends = control_points(ja, jb)
    W, W_inv = bernstein_maps(mid, ends, Z.shape[1])
    local = np.where(dofs >= 0, rdof[np.maximum(dofs, 0)], -1)
    kloc = element_bernstein(kloc, local, mid, ends)
    floating, separating = W_inv @ floating, W_inv @ separating
    anchors = np.empty(0, int)
    if floating.shape[1]:
        keep = np.ones(Z.shape[1], bool)
        keep[jb] = False
        J0 = np.flatnonzero(keep)
        anchors = np.sort(J0[pivot_columns(floating[J0].T)])
    xv, ev = lay.pair_x[0::2], scene.gap_at(lay.pair_x[0::2])
    eps = np.zeros(len(lay.pair_x))
    eps[0::2], eps[1::2] = ev, bernstein_gap(xv, ev, gap_curvature(scene, xv[:-1], xv[1:]))
    return P2System(layout=lay, supports=sup, rdof=rdof, Z=(Z @ W).tocsr(), K=K, kloc=kloc, local_dofs=dofs, f=f,
                    element=cond, interior_load=ui, ja=ja, jb=jb, eps=eps, anchors=anchors,
                    floating=floating, separating=separating, load_correction=correction, scales=system.scales)


def control_points(ja: np.ndarray, jb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The r indices of the faces' middle y values (both faces, every contact interval) ``(m,)`` and of
    their intervals' end values ``(m, 2)``, from the pairs' ``ja``, ``jb`` (vertices and middles interleaved)."""
    mid = np.concatenate([ja[1::2], jb[1::2]])
    ends = np.stack([np.concatenate([ja[0:-1:2], jb[0:-1:2]]), np.concatenate([ja[2::2], jb[2::2]])], 1)
    return mid, ends


def bernstein_maps(mid: np.ndarray, ends: np.ndarray, n_r: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """``W`` and ``W^-1`` ``(n_r, n_r)``: ``r = W r'`` where ``r'`` holds, at the middles ``mid``, the middle
    Bernstein coefficient ``c = 2 q_m - (q_0 + q_1) / 2`` instead of ``q_m = c / 2 + (q_0 + q_1) / 4``."""
    def blend(diag, side):
        rows = np.concatenate([np.arange(n_r), mid, mid])
        cols = np.concatenate([np.arange(n_r), ends[:, 0], ends[:, 1]])
        d = np.ones(n_r)
        d[mid] = diag
        vals = np.concatenate([d, np.full(2 * len(mid), side)])
        return sp.csr_matrix((vals, (rows, cols)), shape=(n_r, n_r))
    return blend(0.5, 0.25), blend(2.0, -0.5)


def element_bernstein(kloc: np.ndarray, local: np.ndarray, mid: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Element matrices ``W_e^T k W_e`` in the variables of :func:`bernstein_maps`: every element holding a
    face's middle holds its ends too (the face edge's triangle, its slab), so the map is local."""
    where = np.full(int(max(local.max(initial=-1), mid.max(initial=-1))) + 1, -1)
    where[mid] = np.arange(len(mid))
    e, i = np.nonzero((local >= 0) & (where[np.maximum(local, 0)] >= 0))
    if not len(e):
        return kloc
    m = where[local[e, i]]
    pos = [np.argmax(local[e] == ends[m, k][:, None], axis=1) for k in (0, 1)]
    if any(np.any(local[e, p] != ends[m, k]) for k, p in enumerate(pos)):
        raise MeshError("internal: a face middle without its ends in an element")  # pragma: no cover
    hit = np.unique(e)
    We = np.broadcast_to(np.eye(kloc.shape[1]), (len(hit), kloc.shape[1], kloc.shape[1])).copy()
    h = np.searchsorted(hit, e)
    We[h, i, i] = 0.5
    We[h, i, pos[0]] += 0.25
    We[h, i, pos[1]] += 0.25
    out = kloc.copy()
    out[hit] = We.transpose(0, 2, 1) @ kloc[hit] @ We
    return out
