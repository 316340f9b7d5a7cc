"""Helpers on arrays of triangles ``(m, 3)`` (node indices) shared by the meshes, their
refinement and the equilibrium space's edges: one integer key per undirected edge, the triangle on an edge, signed
areas, edge lengths and least angles; and on arrays of corners ``(m, 3, 2)``: the barycentric (Alfeld) split the
Johnson-Mercier element and the P2 displacement share, barycentric gradients."""

from __future__ import annotations

import numpy as np


def edge_keys(a, b, n_nodes: int) -> np.ndarray:
    """One integer per undirected edge ``(a, b)`` of a mesh with ``n_nodes`` nodes: the same
    for ``(b, a)``, sorted as ``(min, max)`` pairs are."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    return np.minimum(a, b) * n_nodes + np.maximum(a, b)


def edge_triangles(tris: np.ndarray, a, b, n_nodes: int) -> np.ndarray:
    """A triangle of ``tris`` on each edge ``(a[i], b[i])`` (the one, on a boundary edge), -1 where
    none has it; only the triangles at those nodes are searched."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    near = np.flatnonzero(np.isin(tris, np.concatenate([a, b])).any(axis=1))
    keys = edge_keys(tris[near], np.roll(tris[near], -1, axis=1), n_nodes).ravel()  # edge j of i at 3 i + j
    order = np.argsort(keys)
    k = edge_keys(a, b, n_nodes)
    if not len(keys):
        return np.full(len(k), -1)
    at = np.clip(np.searchsorted(keys[order], k), 0, len(keys) - 1)
    return np.where(keys[order][at] == k, near[order[at] // 3], -1)


def doubled_areas(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Twice the signed area of each triangle: positive counter-clockwise."""
    p = points[tris]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]


def edge_lengths(X: np.ndarray) -> np.ndarray:
    """The lengths of the edges of triangles with corners ``X`` ``(m, 3, 2)``: ``(m, 3)``, edge ``j``
    from corner ``j - 1`` to ``j`` (the longest is the triangle's diameter)."""
    return np.linalg.norm(X - np.roll(X, 1, axis=1), axis=2)


def least_angles(X: np.ndarray) -> np.ndarray:
    """The smallest angle (radians) of each triangle with corners ``X`` ``(m, 3, 2)``."""
    u, v = np.roll(X, -1, axis=1) - X, np.roll(X, 1, axis=1) - X  # the two edges at each corner
    cos = np.sum(u * v, axis=2) / (np.linalg.norm(u, axis=2) * np.linalg.norm(v, axis=2))
    return np.arccos(np.clip(cos, -1.0, 1.0)).min(axis=1)


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
