"""Continuous P2 displacements on the Alfeld (barycentric) split of every macro triangle, without
contact: element matrices, static condensation, assembly, loads, evaluation and error norms,
vectorised over triangles (issue 41, first step).

The split. A macro triangle ``T`` with counter-clockwise corners ``X0, X1, X2`` is cut at its
barycentre ``c`` into the sub-triangles ``T_i = (X_i, X_{i+1}, c)``, ``i = 0, 1, 2`` (indices mod
3), the split and ordering of the Johnson-Mercier element (``cvxdual.eq.element.sub_vertices``).

The space. Each displacement component is continuous and quadratic on every ``T_i``. Its ten
local Lagrange nodes are numbered: 0-2 the corners ``X_i``, 3-5 the midpoints of the outer edges
``(X0, X1), (X1, X2), (X2, X0)``, 6 the barycentre, 7-9 the midpoints of the inner edges
``X_i - c``. Local dof ``2 k + j`` is component ``j`` (x, y) at node ``k``: dofs 0-11 lie on the
boundary of ``T``, 12-19 inside it.

The element. With the Voigt Hooke matrix ``C`` (engineering shear, ``cvxdual.scene.materials``)
the stiffness is ``K = sum_i int_{T_i} B^T C B``. Gradients of P2 functions are linear, so the
three-point edge-midpoint rule (exact for degree 2) integrates it exactly. The eight interior
dofs are condensed out triangle by triangle: with ``R = K_ii^-1 K_ib`` the Schur complement
``S = K_bb - K_bi R`` acts on the twelve boundary dofs, which are numbered as plain P2 on the
macro mesh; a load ``F`` condenses to ``F_b - R^T F_i`` and the interior dofs come back as
``u_i = K_ii^-1 F_i - R u_b``.

Why. On the Alfeld split the divergence maps continuous P2 onto discontinuous P1 with an inf-sup
constant independent of the mesh (Arnold and Qin 1992; Scott and Vogelius), so this displacement
method does not lock as ``nu -> 1/2``, where P1 on the macro mesh does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from ..geometry.quadrature import triangle_rule
from ..geometry.triangles import bary_gradients, edge_keys, sub_vertices

THIRD = np.full(3, 1.0 / 3.0)
# barycentric coordinates of the ten local nodes in the macro triangle
NODE_BARY = np.vstack([np.eye(3), 0.5 * (np.eye(3) + np.roll(np.eye(3), -1, axis=0)), THIRD,
                       0.5 * (np.eye(3) + THIRD)])
# the local nodes of sub-triangle i in P2 order: its vertices (X_i, X_{i+1}, c), then the midpoints of
# its edges (X_i, X_{i+1}) (outer), (X_{i+1}, c) and (c, X_i) (inner)
SUB_NODES = np.array([[i, (i + 1) % 3, 6, 3 + i, 7 + (i + 1) % 3, 7 + i] for i in range(3)])
SUB_DOFS = (2 * SUB_NODES[:, :, None] + np.arange(2)).reshape(3, 12)
N_BOUNDARY = 12  # condensed dofs per macro triangle (corners and outer midpoints)
P2_EDGES = ((0, 1), (1, 2), (2, 0))  # P2 edge functions 3-5 of a triangle
# three-point rule at the edge midpoints (barycentric points, weights as fractions of the area): degree 2
MIDPOINT_RULE = (0.5 * (np.eye(3) + np.roll(np.eye(3), -1, axis=0)), np.full(3, 1.0 / 3.0))

Field = Callable[[np.ndarray], np.ndarray]


def barycentric_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cvxdual.geometry.quadrature.triangle_rule` ``(n)`` (exact for degree ``2n - 2``) in
    barycentric points ``(q, 3)`` and weights summing to 1 (fractions of the area)."""
    rs, w = triangle_rule(n)
    return np.column_stack([1.0 - rs.sum(1), rs]), 2.0 * w


def p2_dofs(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The global P2 nodes of a mesh: ``(nodes (m, 6), coords (n_p2, 2))``. The mesh's vertices
    keep their ids, then comes one node per edge (in the order of :func:`edge_keys`); row ``t``
    of ``nodes`` holds the 3 corners of triangle ``t`` and its edge nodes of ``(X0, X1), (X1, X2),
    (X2, X0)``; ``coords`` the positions (edge midpoints for the edge nodes)."""
    points, tris = np.asarray(points, float), np.asarray(triangles, np.int64)
    a, b = tris, np.roll(tris, -1, axis=1)
    keys, first, inverse = np.unique(edge_keys(a, b, len(points)).ravel(), return_index=True,
                                      return_inverse=True)
    edge_nodes = len(points) + inverse.reshape(-1, 3)
    ends = np.stack([a.ravel()[first], b.ravel()[first]], 1)
    coords = np.vstack([points, 0.5 * (points[ends[:, 0]] + points[ends[:, 1]])])
    return np.hstack([tris, edge_nodes]), coords


def alfeld_nodes(X: np.ndarray) -> np.ndarray:
    """``(m, 10, 2)``: the ten local nodes of macro triangles with corners ``X (m, 3, 2)``."""
    return np.einsum("ka,tad->tkd", NODE_BARY, X)


def _shape_values(bary: np.ndarray) -> np.ndarray:
    """``(q, 6)``: the P2 Lagrange functions at barycentric points ``(q, 3)``."""
    edges = [4.0 * bary[:, a] * bary[:, b] for a, b in P2_EDGES]
    return np.column_stack([bary * (2.0 * bary - 1.0), *edges])


def _shape_gradients(bary: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``(m, q, 6, 2)``: gradients of the P2 functions at ``bary (q, 3)`` of triangles whose
    barycentric gradients are ``G (m, 3, 2)``."""
    vert = np.einsum("qa,tad->tqad", 4.0 * bary - 1.0, G)
    edges = [4.0 * (np.einsum("q,td->tqd", bary[:, a], G[:, b]) + np.einsum("q,td->tqd", bary[:, b], G[:, a]))
             for a, b in P2_EDGES]
    return np.concatenate([vert, np.stack(edges, 2)], axis=2)


def shapes_at(P: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The P2 functions ``(m, q, 6)`` and their gradients ``(m, q, 6, 2)`` of triangles ``P (m, 3, 2)``
    (vertices, then the midpoints of ``(0, 1), (1, 2), (2, 0)``) at points ``pts (m, q, 2)``, inside the
    triangle or not (a polynomial continued)."""
    G, _ = bary_gradients(P)  # (m, 3, 2)
    lam = np.eye(3)[0] + np.einsum("mad,mqd->mqa", G, pts - P[:, None, 0])
    values = np.concatenate([lam * (2 * lam - 1), np.stack([4 * lam[..., a] * lam[..., b] for a, b in P2_EDGES],
                                                           -1)], -1)
    vert = np.einsum("mqa,mad->mqad", 4 * lam - 1, G)
    edge = [4 * (lam[..., a, None] * G[:, None, b] + lam[..., b, None] * G[:, None, a]) for a, b in P2_EDGES]
    return values, np.concatenate([vert, np.stack(edge, 2)], 2)


def hessians(P: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``(m, 2, 2, 2)``: the (constant) second derivatives ``[i, j, k] = d^2 u_i / dx_j dx_k`` of the
    quadratics with ``values (m, 6, 2)`` at the P2 nodes of triangles ``P (m, 3, 2)``."""
    G, _ = bary_gradients(P)
    H = [4 * np.einsum("mj,mk->mjk", G[:, a], G[:, a]) for a in range(3)]
    H += [4 * (np.einsum("mj,mk->mjk", G[:, a], G[:, b]) + np.einsum("mj,mk->mjk", G[:, b], G[:, a]))
          for a, b in P2_EDGES]
    return np.einsum("mni,nmjk->mijk", values, np.stack(H))


def strain_matrix(dphi: np.ndarray) -> np.ndarray:
    """``(..., 3, 12)``: engineering strain ``(e11, e22, 2 e12)`` of the dofs ``2 k + j`` from the
    shape gradients ``dphi (..., 6, 2)``."""
    B = np.zeros(dphi.shape[:-2] + (3, 6, 2))
    B[..., 0, :, 0] = dphi[..., 0]
    B[..., 1, :, 1] = dphi[..., 1]
    B[..., 2, :, 0] = dphi[..., 1]
    B[..., 2, :, 1] = dphi[..., 0]
    return B.reshape(dphi.shape[:-2] + (3, 12))


def _hooke(C: np.ndarray, m: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(C, float), (m, 3, 3))


def alfeld_stiffness(X: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``(m, 20, 20)``: stiffness of continuous P2 on the split of triangles ``X (m, 3, 2)`` with
    Hooke matrices ``C`` ``(m, 3, 3)`` or ``(3, 3)``, in the local dofs of the module docstring."""
    X = np.asarray(X, float)
    C = _hooke(C, len(X))
    P = sub_vertices(X)
    bary, w = MIDPOINT_RULE
    K = np.zeros((len(X), 20, 20))
    for i in range(3):
        G, area = bary_gradients(P[:, i])
        B = strain_matrix(_shape_gradients(bary, G))  # (m, q, 3, 12)
        d = SUB_DOFS[i]
        CB = np.matmul(C[:, None], B)  # (m, q, 3, 12); as matmuls: the four-operand einsum was 20x slower
        Bw = (B * w[None, :, None, None]).reshape(len(X), -1, 12)
        K[:, d[:, None], d] += np.matmul(Bw.transpose(0, 2, 1), CB.reshape(len(X), -1, 12)) * area[:, None, None]
    return K


class Condensed(NamedTuple):
    """Condensed element matrices ``S (m, 12, 12)``, ``R = K_ii^-1 K_ib (m, 8, 12)`` and the
    interior blocks ``K_ii (m, 8, 8)`` (to recover interior dofs under a load)."""

    S: np.ndarray
    R: np.ndarray
    Kii: np.ndarray


def condense(K: np.ndarray) -> Condensed:
    """Static condensation of element matrices ``K (m, 20, 20)`` onto their 12 boundary dofs."""
    b = N_BOUNDARY
    Kii = K[:, b:, b:]
    R = np.linalg.solve(Kii, K[:, b:, :b])
    S = K[:, :b, :b] - K[:, :b, b:] @ R
    return Condensed(S=0.5 * (S + S.transpose(0, 2, 1)), R=R, Kii=Kii)


def alfeld_load(X: np.ndarray, f: Field, n_quad: int = 5) -> np.ndarray:
    """``(m, 20)``: ``int f . phi_k`` over the split of triangles ``X`` for a body force ``f``
    (``(q, 2)`` points to ``(q, 2)`` values), by :func:`barycentric_rule` ``(n_quad)`` on each
    sub-triangle (exact for ``f`` of degree ``2 n_quad - 4``)."""
    X = np.asarray(X, float)
    P = sub_vertices(X)
    bary, w = barycentric_rule(n_quad)
    phi = _shape_values(bary)
    F = np.zeros((len(X), 20))
    for i in range(3):
        _, area = bary_gradients(P[:, i])
        x = np.einsum("qa,tad->tqd", bary, P[:, i])
        fx = np.asarray(f(x.reshape(-1, 2)), float).reshape(x.shape)
        F[:, SUB_DOFS[i]] += np.einsum("q,qa,tqj,t->taj", w, phi, fx, area).reshape(len(X), 12)
    return F


@dataclass(frozen=True)
class P2Assembly:
    """The assembled condensed P2 stiffness ``K`` (CSR, ``2 n_p2`` dofs: ``2 k`` = x, ``2 k + 1`` = y
    of P2 node ``k``) with what the loads, the recovery and the evaluation need."""

    X: np.ndarray  # (m, 3, 2) macro corners
    C: np.ndarray  # (m, 3, 3) Hooke matrices
    nodes: np.ndarray  # (m, 6) global P2 nodes (see p2_dofs)
    coords: np.ndarray  # (n_p2, 2)
    element: Condensed
    K: sp.csr_matrix

    @property
    def dofs(self) -> np.ndarray:
        """``(m, 12)``: the global dofs of the 12 boundary dofs of each triangle."""
        return _global_dofs(self.nodes)

    @property
    def n_dofs(self) -> int:
        return 2 * len(self.coords)


def _global_dofs(nodes: np.ndarray) -> np.ndarray:
    return (2 * nodes[:, :, None] + np.arange(2)).reshape(len(nodes), 2 * nodes.shape[1])


def assemble_p2(points: np.ndarray, triangles: np.ndarray, C: np.ndarray) -> P2Assembly:
    """Element matrices, condensation and the global stiffness (from COO triplets at once) of
    the mesh ``points (n, 2)``, ``triangles (m, 3)`` with Hooke matrices ``C (m, 3, 3)`` or ``(3, 3)``."""
    points, triangles = np.asarray(points, float), np.asarray(triangles, np.int64)
    X = points[triangles]
    C = np.array(_hooke(C, len(X)))
    nodes, coords = p2_dofs(points, triangles)
    cond = condense(alfeld_stiffness(X, C))
    d, n = _global_dofs(nodes), 2 * len(coords)
    rows, cols = np.repeat(d, 12, axis=1), np.tile(d, (1, 12))
    K = sp.coo_matrix((cond.S.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n)).tocsr()
    # duplicates are summed in an order that differs between (i, j) and (j, i): make it exactly symmetric
    K = (0.5 * (K + K.T)).tocsr()
    return P2Assembly(X=X, C=C, nodes=nodes, coords=coords, element=cond, K=K)


def p2_load_vector(asm: P2Assembly, f: Field, n_quad: int = 5) -> np.ndarray:
    """``(n_dofs,)``: the condensed load ``F_b - R^T F_i`` of a body force ``f`` (see :func:`alfeld_load`)."""
    F = alfeld_load(asm.X, f, n_quad)
    Fb = F[:, :N_BOUNDARY] - np.einsum("tik,ti->tk", asm.element.R, F[:, N_BOUNDARY:])
    return np.bincount(asm.dofs.ravel(), Fb.ravel(), minlength=asm.n_dofs)


def recover_interior(asm: P2Assembly, u: np.ndarray, f: Field | None = None, n_quad: int = 5) -> np.ndarray:
    """``(m, 20)``: the local dofs of every macro triangle from the global solution ``u (n_dofs,)``,
    the interior ones as ``K_ii^-1 F_i - R u_b`` (``F_i`` of the body force ``f``, if any)."""
    ub = np.asarray(u, float)[asm.dofs]
    ui = -np.einsum("tik,tk->ti", asm.element.R, ub)
    if f is not None:
        Fi = alfeld_load(asm.X, f, n_quad)[:, N_BOUNDARY:]
        ui += np.linalg.solve(asm.element.Kii, Fi[:, :, None])[:, :, 0]
    return np.hstack([ub, ui])


def evaluate_p2(X: np.ndarray, ue: np.ndarray, sub: int, bary: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``(m, q, 2)``, displacements ``(m, q, 2)`` and engineering strains ``(m, q, 3)`` at
    barycentric points ``bary (q, 3)`` of sub-triangle ``sub`` of every macro triangle ``X (m, 3, 2)``
    with local dofs ``ue (m, 20)``."""
    P = sub_vertices(np.asarray(X, float))[:, sub]
    G, _ = bary_gradients(P)
    u = np.asarray(ue, float)[:, SUB_DOFS[sub]]  # (m, 12)
    x = np.einsum("qa,tad->tqd", bary, P)
    vals = np.einsum("qa,taj->tqj", _shape_values(bary), u.reshape(-1, 6, 2))
    strain = np.einsum("tqak,tk->tqa", strain_matrix(_shape_gradients(bary, G)), u)
    return x, vals, strain


def p2_errors(X: np.ndarray, ue: np.ndarray, C: np.ndarray, u_exact: Field, grad_exact: Field,
              n_quad: int = 6) -> tuple[float, float]:
    """``(||u_h - u*||_a, ||u_h - u*||_L2)`` with ``||v||_a^2 = int e(v) : C e(v)``, for local dofs
    ``ue (m, 20)`` on triangles ``X`` against ``u*`` (``u_exact``: ``(q, 2)`` points to ``(q, 2)``;
    ``grad_exact``: to ``(q, 2, 2)``, entry ``[i, j] = d u_i / d x_j``), by :func:`barycentric_rule`
    ``(n_quad)`` (degree ``2 n_quad - 2``) on every sub-triangle. ``ue = 0`` gives the norms of ``u*``."""
    X = np.asarray(X, float)
    C = _hooke(C, len(X))
    P = sub_vertices(X)
    bary, w = barycentric_rule(n_quad)
    energy = l2 = 0.0
    for i in range(3):
        _, area = bary_gradients(P[:, i])
        x, vals, strain = evaluate_p2(X, ue, i, bary)
        pts = x.reshape(-1, 2)
        du = vals - np.asarray(u_exact(pts), float).reshape(vals.shape)
        g = np.asarray(grad_exact(pts), float).reshape(x.shape[:2] + (2, 2))
        de = strain - np.stack([g[..., 0, 0], g[..., 1, 1], g[..., 0, 1] + g[..., 1, 0]], -1)
        energy += float(np.einsum("q,tqa,tab,tqb,t->", w, de, C, de, area))
        l2 += float(np.einsum("q,tqj,tqj,t->", w, du, du, area))
    return float(np.sqrt(max(energy, 0.0))), float(np.sqrt(l2))
