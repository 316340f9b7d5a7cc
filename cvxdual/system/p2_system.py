"""The P2 kinematic side's system on a scene's mesh (docs/equilibrium.md section 12): continuous P2 on
the Alfeld split of the elements of :mod:`cvxdual.system.p2_layout`, supports and consistent loads,
rigid motions, and the contact pairs with their middle unknowns (:mod:`cvxdual.system.p2_contact`),
in the form the active-set fast path solves (:class:`~cvxdual.system.displacement.DisplacementSolver`).

Curved pieces. A segment (between a chord and a convex arc) takes its straight triangle's quadratic
continued beyond the chord, its energy added to that element's matrix; a type-1 concave piece is the
element ``A, B, C`` less the sliver between its chord and the arc (the sliver's energy subtracted);
a type-2 piece keeps the trace of its polygon edge continued along y (6 x 6 slab matrices). Only the
last has ``e_yy = 0`` (the paper's P1 rule, which locks as ``nu -> 1/2``).

Rigid motions are found in the P2 space itself (:func:`p2_rigid_modes`): affine motions interpolate
exactly, and which are free can differ from P1's (a rotating segment strains P1's trace along y).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import MeshError, SceneError
from ..geometry.pieces import slab_bound
from ..geometry.quadrature import gauss01
from ..geometry.triangles import bary_gradients, sub_vertices
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
    shapes_at,
    strain_matrix,
)
from .p2_contact import element_maps, face_middles, middle_maps
from .p2_layout import CONCAVE1, P2Layout, interpolation, p2_layout, trace_shapes
from .quadratic_gap import bernstein_gap, gap_curvature
from .rigid import balance, candidates, pivot_columns

SLAB_GAUSS = 10  # points in x per slab: h(x) times a quadratic, exact for polynomial faces of degree <= 17
CHUNK = 4096  # triangles whose 20 x 20 element matrices exist at once (about 13 MB)


@dataclass(frozen=True, eq=False)
class P2System:
    """The assembled P2 displacement problem of one P1 :class:`~cvxdual.system.assembly.System`'s mesh:
    element matrices in the nodes' frames (``kloc``, triangles' condensed 12 x 12 then the slabs'
    6 x 6 padded to 12), the global stiffness ``K``, loads ``f`` (balanced), supports
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
    respect the supports and have no energy in ``K``. P2 interpolates them exactly; which are
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


def slab_elements(pieces, layout: P2Layout, C: np.ndarray, F: np.ndarray,
                  sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness ``(m, 6, 6)`` and body-force load ``(m, 6)`` of the slabs ``sel`` (a mask) on the dofs
    of their trace's nodes (left, middle, right): ``v(x, y) = w(x)``, strain ``(w_x', 0, w_y')``,
    integrated by :data:`SLAB_GAUSS` Gauss points in x times the slab's height (``C``, ``F`` per slab)."""
    s = pieces.slabs
    k = np.flatnonzero(sel)
    u, w = gauss01(SLAB_GAUSS)
    x = s.xl[k, None] + u[None, :] * (s.xr - s.xl)[k, None]
    idx = np.repeat(k, SLAB_GAUSS)
    h = (slab_bound(s, pieces.faces, x.ravel(), idx, "hi") - slab_bound(s, pieces.faces, x.ravel(), idx, "lo"))
    wh = w[None, :] * (s.xr - s.xl)[k, None] * h.reshape(x.shape)
    dx = layout.slab_x[k, 1] - layout.slab_x[k, 0]
    N, dN = trace_shapes((x - layout.slab_x[k, :1]) / dx[:, None])
    dN = dN / dx[:, None, None]
    B = np.zeros(x.shape + (3, 6))
    B[..., 0, 0::2] = dN
    B[..., 2, 1::2] = dN
    K = np.einsum("sq,sqai,sab,sqbj->sij", wh, B, C[k], B)
    load = np.einsum("sq,sqa,sc->sac", wh, N, F[k]).reshape(-1, 6)
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
    trace = lay.slab_tri < 0  # the others are in their elements' matrices
    Ks, Fs = np.zeros((len(sb), 6, 6)), np.zeros((len(sb), 6))
    if trace.any():
        Ks[trace], Fs[trace] = slab_elements(pieces, lay, stiff[sb], force[sb], trace)
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
