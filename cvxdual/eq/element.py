"""The Johnson-Mercier (Watwood-Hartz) element on macro triangles, vectorised over triangles
(docs/equilibrium.md): the sub-triangles, the traction and divergence rows of linear Voigt
stresses on them, and the 15-parameter local basis that leaves the tractions continuous
across the three internal edges.
"""

from __future__ import annotations

import numpy as np

from ..errors import MeshError

MASS0 = (np.ones((3, 3)) + np.eye(3)) / 12.0  # int phi_a phi_b / |T| for P1 on a triangle


def traction_rows(n: np.ndarray) -> np.ndarray:
    """``(..., 2, 3)``: ``sigma n`` in terms of Voigt ``(s11, s22, s12)``."""
    z = np.zeros(n.shape[:-1])
    return np.stack([np.stack([n[..., 0], z, n[..., 1]], -1), np.stack([z, n[..., 1], n[..., 0]], -1)], -2)


def frame_rows(n: np.ndarray) -> np.ndarray:
    """``(..., 2, 3)``: ``(sigma n).n`` and ``(sigma n).t`` with ``t = (-n2, n1)``."""
    t = np.stack([-n[..., 1], n[..., 0]], -1)
    T = traction_rows(n)
    return np.stack([np.einsum("...i,...ij->...j", n, T), np.einsum("...i,...ij->...j", t, T)], -2)


def sub_vertices(X: np.ndarray) -> np.ndarray:
    """``(n_T, 3, 3, 2)``: vertices ``(X_i, X_{i+1}, c)`` of the sub-triangles of macro triangles ``X``."""
    c = np.broadcast_to(X.mean(1, keepdims=True), X.shape)
    return np.stack([X, np.roll(X, -1, axis=1), c], axis=2)


def bary_gradients(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients ``(..., 3, 2)`` of the barycentric functions and areas of triangles ``p (..., 3, 2)``."""
    d1, d2 = p[..., 1, :] - p[..., 0, :], p[..., 2, :] - p[..., 0, :]
    a2 = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
    g1 = np.stack([d2[..., 1], -d2[..., 0]], -1) / a2[..., None]
    g2 = np.stack([-d1[..., 1], d1[..., 0]], -1) / a2[..., None]
    return np.stack([-g1 - g2, g1, g2], -2), 0.5 * a2


def unit(d: np.ndarray) -> np.ndarray:
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def internal_rows(X: np.ndarray) -> np.ndarray:
    """``(n_T, 12, 27)``: jumps of ``sigma n`` across the internal edge ``(X_{i+1}, c)`` of
    sub-triangles ``i`` and ``i+1``, at both edge ends (vertex ``a = 1, 2`` of ``T_i``,
    ``a = 0, 2`` of ``T_{i+1}``)."""
    n_T = len(X)
    c = X.mean(1)
    rows = np.zeros((n_T, 3, 2, 2, 27))
    for i in range(3):  # three fixed local edges; everything inside is vectorised over triangles
        d = c - X[:, (i + 1) % 3]
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
    h = np.linalg.norm(X - np.roll(X, 1, axis=1), axis=2).max(1)
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


# a fixed generic 27 x 3 frame whose projection onto each triangle's 3-dimensional null space
# gives its bubbles (any fixed choice in general position does; this one is deterministic)
_BUBBLE_SEED = np.linalg.qr(np.random.default_rng(20261202).standard_normal((27, 3)))[0]


def local_basis(X: np.ndarray, ng: np.ndarray) -> np.ndarray:
    """``(n_T, 27, 15)``: vertex values of the 12 edge-dof basis stresses (columns 0-11, dual to
    :func:`edge_dof_rows` and free of internal jumps) and of 3 bubbles (zero internal jumps and
    zero edge dofs). The stacked ``(24, 27)`` conditions ``M`` must have full rank 24 (then the
    local space has exactly 15 = 27 - 12 dimensions). The edge stresses are the least-norm
    solutions of ``M N = [0; I]``, ``N = M^T (M M^T)^-1 [0; I]``, and the bubbles an orthonormal
    basis of the null space of ``M``, the projection ``(I - M^T (M M^T)^-1 M) E`` of a fixed frame
    ``E``: a batched 24 x 24 inverse and 27 x 3 QR factorisations. A batched SVD costs six times
    more; it serves only a triangle whose null space the frame meets at a small angle."""
    M = np.concatenate([internal_rows(X), edge_dof_rows(ng)], axis=1)
    MT = M.transpose(0, 2, 1)
    try:
        Gi = np.linalg.inv(M @ MT)  # one batched inverse serves the three products below
    except np.linalg.LinAlgError:
        raise MeshError("a macro triangle gives a singular Johnson-Mercier basis (degenerate triangle)") from None
    pinv = MT @ Gi  # (n_T, 27, 24)
    bubble, R = np.linalg.qr(_BUBBLE_SEED[None] - pinv @ (M @ _BUBBLE_SEED))
    bad = np.abs(np.diagonal(R, axis1=1, axis2=2)).min(1) < 1e-3  # the frame meets this null space badly
    if bad.any():  # rare: take those null spaces from an SVD instead
        bubble[bad] = np.linalg.svd(M[bad])[2][:, 24:].transpose(0, 2, 1)
    N = np.concatenate([pinv[:, :, 12:], bubble], axis=2)
    target = np.concatenate([np.zeros((12, 15)), np.eye(12, 15)])
    N = N + pinv @ (target[None] - M @ N)  # one step of refinement: conditions to ~1e-16
    if not np.all(np.abs(M @ N - target[None]) < 1e-10):
        raise MeshError("a macro triangle gives a singular Johnson-Mercier basis (degenerate triangle)")
    return N
