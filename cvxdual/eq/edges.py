"""The macro triangles' global edges: end nodes, the fixed frame of each edge (``n_g``), lookups
by end nodes, and outward normals on the boundary (used by the equilibrium space and its bounds)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import MeshError
from ..geometry.triangles import edge_keys
from ..records import Record
from .element import unit


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class MeshEdges(Record):
    """The global edges of the macro triangles (:func:`mesh_edges`), ``n_e`` of them: ``key``
    ``(n_e,)`` (``lo * n_nodes + hi``, sorted: the lookup of :func:`edge_ids`; mapping key
    ``"keys"``, as the dict it replaces had it), end nodes ``lo``, ``hi`` ``(n_e,)`` with
    ``lo < hi``, unit normals ``ng`` ``(n_e, 2)``, the edge of each local edge ``id``
    ``(n_T, 3)``, ``flip`` ``(n_T, 3)`` (the local edge runs ``hi -> lo``), ``count``
    ``(n_e,)`` (triangles holding it: 1 or 2), ``boundary`` (the edges of one triangle),
    ``owner`` ``(n_e, 2)`` (``(t, j)`` of a triangle holding it, the only one on the boundary),
    ``length`` ``(n_e,)`` [L]. ``axis`` ``(n_e, 2)``, the frame of each edge's dofs, is the
    space's (:func:`cvxdual.eq.space.guided_axes`): ``None`` and no key until it is given
    (``edges.replace(axis=...)``)."""

    OPTIONAL: ClassVar[frozenset[str]] = frozenset({"axis"})
    KEY_OF: ClassVar[dict[str, str]] = {"key": "keys"}  # a field "keys" would hide Mapping.keys()

    key: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    ng: np.ndarray
    id: np.ndarray
    flip: np.ndarray
    count: np.ndarray
    boundary: np.ndarray
    owner: np.ndarray
    length: np.ndarray
    axis: np.ndarray | None = None


def mesh_edges(tri: np.ndarray, pts: np.ndarray, n_nodes: int) -> MeshEdges:
    """Global edges of the macro triangles (:class:`MeshEdges`): end nodes ``lo < hi``, unit
    normals ``ng`` (the direction ``hi - lo`` turned clockwise), the edge of each local edge
    ``id (n_T, 3)`` (local edge ``j`` runs ``X_j -> X_{j+1}``), whether it runs ``hi -> lo``
    (``flip``) and the owner ``(t, j)`` of every edge that has one triangle (the boundary)."""
    a, b = tri, np.roll(tri, -1, axis=1)
    keys = edge_keys(a, b, n_nodes)
    uniq, inv, count = np.unique(keys.ravel(), return_inverse=True, return_counts=True)
    lo, hi = uniq // n_nodes, uniq % n_nodes
    d = pts[hi] - pts[lo]
    ng = unit(np.stack([d[:, 1], -d[:, 0]], 1))
    bnd = np.flatnonzero(count == 1)
    owner = np.full((len(uniq), 2), -1)
    owner[inv, 0], owner[inv, 1] = np.repeat(np.arange(len(tri)), 3), np.tile(np.arange(3), len(tri))
    return MeshEdges(key=uniq, lo=lo, hi=hi, ng=ng, id=inv.reshape(tri.shape), flip=a > b, count=count,
                     boundary=bnd, owner=owner, length=np.linalg.norm(d, axis=1))


def edge_ids(edges: Mapping, a: np.ndarray, b: np.ndarray, n_nodes: int, missing: bool = False) -> np.ndarray:
    """The edges between nodes ``a`` and ``b``; with ``missing``, -1 where there is none."""
    keys = edge_keys(a, b, n_nodes)
    idx = np.minimum(np.searchsorted(edges["keys"], keys), len(edges["keys"]) - 1)
    found = edges["keys"][idx] == keys
    if not missing and not found.all():
        raise MeshError("internal: a side edge is not an edge of the mesh")  # pragma: no cover
    return np.where(found, idx, -1)


def outward_normals(edges: Mapping, X: np.ndarray, pts: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals of boundary edges ``ids`` and ``s_o = n_g . n_out`` (+-1)."""
    t = edges["owner"][ids, 0]
    mid = 0.5 * (pts[edges["lo"][ids]] + pts[edges["hi"][ids]])
    s_o = np.sign(np.einsum("ij,ij->i", mid - X[t].mean(1), edges["ng"][ids]))
    return s_o[:, None] * edges["ng"][ids], s_o
