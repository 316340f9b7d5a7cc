"""The Johnson-Mercier (Watwood-Hartz) element on macro triangles, vectorised over triangles
(docs/equilibrium.md): the sub-triangles, the traction and divergence rows of linear Voigt
stresses on them, and the 15-parameter local basis that leaves the tractions continuous
across the three internal edges.
"""

from __future__ import annotations

import numpy as np

from ..errors import MeshError
from ..geometry.triangles import bary_gradients, edge_lengths, sub_vertices

MASS0 = (np.ones((3, 3)) + np.eye(3)) / 12.0  # int phi_a phi_b / |T| for P1 on a triangle


def traction_rows(n: np.ndarray) -> np.ndarray:
    """``(..., 2, 3)``: ``sigma n`` in terms of Voigt ``(s11, s22, s12)``."""
    z = np.zeros(n.shape[:-1])
    return np.stack([np.stack([n[..., 0], z, n[..., 1]], -1), np.stack([z, n[..., 1], n[..., 0]], -1)], -2)


def frame_rows(n: np.ndarray, a: np.ndarray | None = None) -> np.ndarray:
    """``(..., 2, 3)``: ``(sigma n).a`` and ``(sigma n).t`` with ``t = (-a2, a1)``; the axis ``a``
    is ``n`` unless given (an edge of a sliding support guided across its line)."""
    a = n if a is None else a
    t = np.stack([-a[..., 1], a[..., 0]], -1)
    T = traction_rows(n)
    return np.stack([np.einsum("...i,...ij->...j", a, T), np.einsum("...i,...ij->...j", t, T)], -2)


def unit(d: np.ndarray) -> np.ndarray:
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def internal_rows(X: np.ndarray) -> np.ndarray:
    """``(n_T, 12, 27)``: jumps of ``sigma n`` across the internal edge ``(X_{i+1}, c)`` of
    sub-triangles ``i`` and ``i+1``, at both edge ends (vertex ``a = 1, 2`` of ``T_i``,
    ``a = 0, 2`` of ``T_{i+1}``)."""
    n_T = len(X)
    rows = np.zeros((n_T, 3, 2, 2, 27))
    for i in range(3):  # three fixed local edges; everything inside is vectorised over triangles
        # c - X_{i+1} from the edge vectors (nearby coordinates subtract exactly): through the centroid
        # it lost |X| / h_T digits, 5e-11 of the stress scale on a triangle 1e-3 of the body wide
        d = ((X[:, i] - X[:, (i + 1) % 3]) + (X[:, (i + 2) % 3] - X[:, (i + 1) % 3])) / 3.0
        T = traction_rows(unit(np.stack([d[:, 1], -d[:, 0]], -1)))  # (n_T, 2, 3)
        j = (i + 1) % 3
        for end, (a_i, a_j) in enumerate(((1, 0), (2, 2))):
            rows[:, i, end, :, 9 * i + 3 * a_i: 9 * i + 3 * a_i + 3] = T
            rows[:, i, end, :, 9 * j + 3 * a_j: 9 * j + 3 * a_j + 3] -= T
    return rows.reshape(n_T, 12, 27)


def edge_dof_rows(ng: np.ndarray) -> np.ndarray:
    """``(n_T, 12, 27)``: the JM edge dofs ``(sigma n_g).n_g``, ``(sigma n_g).t_g`` at the local
    ends ``X_j`` (vertex 0 of ``T_j``) and ``X_{j+1}`` (vertex 1) of macro edge ``j``; row
    ``4 j + 2 e + k``. ``ng (n_T, 3, 2)`` are the global edge normals."""
    n_T = len(ng)
    rows = np.zeros((n_T, 3, 2, 2, 27))
    R = frame_rows(ng)  # (n_T, 3, 2, 3)
    for j in range(3):
        for e in range(2):
            rows[:, j, e, :, 9 * j + 3 * e: 9 * j + 3 * e + 3] = R[:, j]
    return rows.reshape(n_T, 12, 27)


def divergence_rows(X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(n_T, 6, 27)`` rows of ``h_T div sigma`` on each sub-triangle (row ``2 i + k``), the
    sub-triangle areas ``(n_T, 3)`` and ``h_T`` (longest edge). Scaling by ``h_T`` makes the rows
    O(1) per unit stress."""
    g, area = bary_gradients(sub_vertices(X))  # (n_T, 3, 3, 2)
    h = edge_lengths(X).max(1)
    rows = np.zeros((len(X), 3, 2, 3, 3))  # sub i, component k, vertex a, Voigt
    rows[:, :, 0, :, 0] = g[..., 0]  # d s11/dx
    rows[:, :, 0, :, 2] = g[..., 1]  # d s12/dy
    rows[:, :, 1, :, 2] = g[..., 0]  # d s12/dx
    rows[:, :, 1, :, 1] = g[..., 1]  # d s22/dy
    rows = rows.reshape(len(X), 3, 2, 9) * h[:, None, None, None]
    full = np.zeros((len(X), 3, 2, 27))
    for i in range(3):
        full[:, i, :, 9 * i: 9 * i + 9] = rows[:, i]
    return full.reshape(len(X), 6, 27), area, h


def least_norm_basis(X: np.ndarray, ng: np.ndarray) -> np.ndarray:
    """``(n_T, 27, 15)``: vertex values of the 12 edge-dof basis stresses (columns 0-11, dual to
    :func:`edge_dof_rows` and free of internal jumps; the least-norm ones) and of 3 orthonormal
    bubbles (zero internal jumps and zero edge dofs), from one batched SVD of the stacked
    ``(24, 27)`` conditions, which must have full rank 24 (then the local space has exactly
    ``15 = 27 - 12`` dimensions). The reference element's basis; on a mesh
    :func:`local_basis` maps it (six times faster), and tests compare the two."""
    M = np.concatenate([internal_rows(X), edge_dof_rows(ng)], axis=1)
    U, s, Vt = np.linalg.svd(M)
    if np.any(s[:, -1] < 1e-10 * s[:, 0]):
        raise MeshError("a macro triangle gives a singular Johnson-Mercier basis (degenerate triangle)")
    pinv = np.einsum("tki,tk,tjk->tij", Vt[:, :24], 1.0 / s, U)  # (n_T, 27, 24)
    N = np.concatenate([pinv[:, :, 12:], Vt[:, 24:].transpose(0, 2, 1)], axis=2)
    target = np.concatenate([np.zeros((12, 15)), np.eye(12, 15)])
    return N + pinv @ (target[None] - M @ N)  # one step of refinement: conditions to ~1e-16


def outward_edge_normals(X: np.ndarray) -> np.ndarray:
    """``(n_T, 3, 2)`` outward unit normals of the macro edges ``X_j -> X_{j+1}``."""
    d = np.roll(X, -1, axis=1) - X
    n = unit(np.stack([d[..., 1], -d[..., 0]], -1))
    out = np.sign(np.einsum("tji,tji->tj", n, X - X.mean(1, keepdims=True)))  # X_j lies on edge j
    return n * out[..., None]


# -- the reference element and the double Piola map ------------------------------------------
#
# With F(x^) = X_0 + J x^, J = [X_1 - X_0, X_2 - X_0], the map sigma = J sigma^ J^T / det J takes
# the local space of the reference triangle onto that of T: linear fields stay linear on the
# (mapped) sub-triangles, sigma n ds = J sigma^ n^ ds^ keeps tractions continuous where they were,
# and div sigma = J div^ sigma^ / det J keeps self-equilibrated fields self-equilibrated. The
# traction of a mapped field on an edge depends only on the reference traction at the same point
# of the same edge, so the edge dofs of the mapped reference basis form one 2 x 2 block per edge
# end (:func:`edge_blocks`), and the mapped bubbles keep zero edge dofs.

REF_X = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]])
REF_BASIS = least_norm_basis(REF_X, outward_edge_normals(REF_X))[0]  # (27, 15)
# the 9 self-equilibrated combinations of the 15 reference parameters (div onto R^6: rank 6)
REF_DIVFREE = np.linalg.svd(divergence_rows(REF_X)[0][0] @ REF_BASIS)[2][6:].T  # (15, 9), orthonormal
SYM_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # the 6 entries of a symmetric 3 x 3 matrix


def _energy_templates() -> np.ndarray:
    """``(6, 15, 15)``: ``G_p`` with ``sum_p A_p G_p`` the energy ``sum_i N_i^T (MASS0 (x) A) N_i``
    of the reference basis on its three sub-triangles for a compliance ``A`` (entry ``A_p`` of
    ``SYM_PAIRS``), per unit sub-triangle area."""
    G = np.zeros((6, 15, 15))
    for p, (a, b) in enumerate(SYM_PAIRS):
        E = np.zeros((3, 3))
        E[a, b] = E[b, a] = 1.0
        K9 = np.kron(MASS0, E)
        for i in range(3):
            Ni = REF_BASIS[9 * i: 9 * i + 9]
            G[p] += Ni.T @ K9 @ Ni
    return G


REF_ENERGY = _energy_templates()
REF_ENERGY_DIVFREE = np.einsum("ia,pij,jb->pab", REF_DIVFREE, REF_ENERGY, REF_DIVFREE)  # (6, 9, 9)
REF_ENERGY_MIXED = np.einsum("ia,pij->paj", REF_DIVFREE, REF_ENERGY)  # (6, 9, 15): Z^T G_p
REF_DIV = divergence_rows(REF_X)[0][0] @ REF_BASIS  # (6, 15): h div of the reference parameters
REF_DIV_PINV = np.linalg.pinv(REF_DIV)  # (15, 6): the least-norm reference field of given divergence


def piola(X: np.ndarray) -> np.ndarray:
    """``(n_T, 3, 3)``: the double Piola map ``sigma^ -> J sigma^ J^T / det J`` on Voigt values."""
    J = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], -1)
    a, b, c, e = J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1]
    det = a * e - b * c
    if np.any(np.abs(det) <= 1e-14 * np.einsum("tij,tij->t", J, J)):
        raise MeshError("a macro triangle gives a singular Johnson-Mercier basis (degenerate triangle)")
    Q = np.stack([np.stack([a * a, b * b, 2 * a * b], -1), np.stack([c * c, e * e, 2 * c * e], -1),
                  np.stack([a * c, b * e, a * e + b * c], -1)], -2)
    return Q / det[:, None, None]


def divergence_to_reference(X: np.ndarray, g: np.ndarray) -> np.ndarray:
    """The reference divergence rows' values ``(n, 6)`` of fields whose rows ``h_T div`` on ``T``
    are ``g (n, 6)``: ``div sigma = J div^ sigma^ / det J``, so ``h^ div^ = (h^ / h_T) adj(J) h_T div``
    on every sub-triangle (``h`` the longest edge, as in :func:`divergence_rows`)."""
    J = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], -1)
    adj = np.stack([np.stack([J[:, 1, 1], -J[:, 0, 1]], -1), np.stack([-J[:, 1, 0], J[:, 0, 0]], -1)], -2)
    h = edge_lengths(X).max(1)
    gr = np.einsum("tab,tib->tia", adj, g.reshape(-1, 3, 2)) * (np.sqrt(2.0) / h)[:, None, None]
    return gr.reshape(-1, 6)


def edge_blocks(Q: np.ndarray, ng: np.ndarray, axis: np.ndarray | None = None) -> np.ndarray:
    """``(n_T, 6, 2, 2)``: block ``2 j + e`` holds the edge dofs (traction on ``ng`` in the frame of
    ``axis``, by default ``ng``) at end ``e`` of macro edge ``j`` of the mapped reference parameters
    ``4 j + 2 e + (0, 1)``."""
    R = frame_rows(ng, axis)  # (n_T, 3, 2, 3)
    D = np.empty((len(Q), 6, 2, 2))
    for j in range(3):
        for e in range(2):
            v = REF_BASIS[9 * j + 3 * e: 9 * j + 3 * e + 3, 4 * j + 2 * e: 4 * j + 2 * e + 2]  # (3, 2)
            D[:, 2 * j + e] = R[:, j] @ (Q @ v)
    return D


def inverse2(D: np.ndarray) -> np.ndarray:
    """Inverses of ``(..., 2, 2)`` blocks (closed form)."""
    det = D[..., 0, 0] * D[..., 1, 1] - D[..., 0, 1] * D[..., 1, 0]
    inv = np.stack([np.stack([D[..., 1, 1], -D[..., 0, 1]], -1), np.stack([-D[..., 1, 0], D[..., 0, 0]], -1)], -2)
    return inv / det[..., None, None]


def mapped_values(Q: np.ndarray, C: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Vertex values ``(n, 27)`` of local parameters ``z (n, 15)`` of triangles with Piola maps
    ``Q`` and edge coefficient blocks ``C (n, 6, 2, 2)`` (parameters -> reference parameters)."""
    zr = np.concatenate([(C @ z[:, :12].reshape(-1, 6, 2, 1)).reshape(-1, 12), z[:, 12:]], 1)
    return ((zr @ REF_BASIS.T).reshape(-1, 9, 3) @ Q.transpose(0, 2, 1)).reshape(-1, 27)  # matmul: 10x einsum


def local_basis(Q: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``(n, 27, 15)``: vertex values of the local basis ``(I (x) Q) N^ diag(C, I_3)`` (edge
    columns dual to the edge dofs where ``C`` inverts :func:`edge_blocks`)."""
    edge = (REF_BASIS[:, :12].reshape(27, 6, 2).transpose(1, 0, 2)[None] @ C)  # (n, 6, 27, 2)
    N = np.concatenate([edge.transpose(0, 2, 1, 3).reshape(-1, 27, 12),
                        np.broadcast_to(REF_BASIS[:, 12:], (len(Q), 27, 3))], 2).reshape(-1, 9, 3, 15)
    return (Q[:, None] @ N).reshape(-1, 27, 15)


def energy_coefficients(Q: np.ndarray, A: np.ndarray, area: np.ndarray) -> np.ndarray:
    """``(n, 6)``: the entries ``A'_p |T| / 3`` (``SYM_PAIRS``) of ``A' = Q^T A Q``, the compliance
    seen by the reference element, times the sub-triangle area: with the templates,
    ``sum_p coef_p REF_ENERGY[p]`` is the energy matrix of the reference parameters of ``T``
    (``REF_ENERGY_DIVFREE``: of its self-equilibrated ones)."""
    Ap = Q.transpose(0, 2, 1) @ A @ Q
    return np.stack([Ap[:, a, b] for a, b in SYM_PAIRS], 1) * (area / 3.0)[:, None]


def reference_energy(coef: np.ndarray, templates: np.ndarray) -> np.ndarray:
    """``sum_p coef_p templates[p]`` for every triangle (:func:`energy_coefficients`)."""
    m = templates.shape[1]
    return (coef @ templates.reshape(6, m * m)).reshape(-1, m, m)
