"""Helpers on arrays of triangles ``(m, 3)`` (node indices) shared by the meshes, their
refinement and the equilibrium space's edges: one integer key per undirected edge, signed
areas and edge lengths."""

from __future__ import annotations

import numpy as np


def edge_keys(a, b, n_nodes: int) -> np.ndarray:
    """One integer per undirected edge ``(a, b)`` of a mesh with ``n_nodes`` nodes: the same
    for ``(b, a)``, sorted as ``(min, max)`` pairs are."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    return np.minimum(a, b) * n_nodes + np.maximum(a, b)


def doubled_areas(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Twice the signed area of each triangle: positive counter-clockwise."""
    p = points[tris]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]


def edge_lengths(X: np.ndarray) -> np.ndarray:
    """The lengths of the edges of triangles with corners ``X`` ``(m, 3, 2)``: ``(m, 3)``, edge ``j``
    from corner ``j - 1`` to ``j`` (the longest is the triangle's diameter)."""
    return np.linalg.norm(X - np.roll(X, 1, axis=1), axis=2)
