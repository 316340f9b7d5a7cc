"""A P2 displacement on a scene's mesh (:mod:`cvxdual.system.p2_system`): its values at the P2 nodes
and the condensed interior dofs of every straight triangle, with what the certificate reads from
it: strains at the sub-triangles' vertices (linear on each), the slabs' traces, the contact jumps."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry.triangles import bary_gradients, sub_vertices
from .p2 import SUB_DOFS, evaluate_p2, shapes_at
from .p2_layout import P2Layout, trace_shapes

VERTICES = np.eye(3)  # barycentric points of a sub-triangle's vertices


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class P2Displacement:
    """``q`` ``(n_p2, 2)`` the values at the layout's nodes, ``interior`` ``(n_T, 8)`` the interior
    dofs (:data:`~cvxdual.system.p2.SUB_DOFS` 12-19) of every straight triangle."""

    layout: P2Layout
    q: np.ndarray
    interior: np.ndarray

    @property
    def vertices(self) -> np.ndarray:
        """``(n_nodes, 2)``: the values at the mesh's nodes."""
        return self.q[:self.layout.n_nodes]

    def local(self) -> np.ndarray:
        """``(n_T, 20)``: the local dofs of :mod:`cvxdual.system.p2` of every straight triangle (the
        equilibrium space's, in its order)."""
        n = self.layout.n_straight
        return np.hstack([self.q[self.layout.nodes[:n]].reshape(-1, 12), self.interior[:n]])

    def sub_strains(self, X: np.ndarray) -> np.ndarray:
        """``(n_T, 3, 3, 3)``: engineering strains at the vertices ``a`` of sub-triangle ``j`` (index
        ``[t, j, a]``, the order of the equilibrium stresses' vertex values) of the straight triangles ``X``."""
        ue = self.local()
        return np.stack([evaluate_p2(X, ue, j, VERTICES)[2] for j in range(3)], 1)

    def sub_values(self) -> np.ndarray:
        """``(n_T, 3, 6, 2)``: the values at the six P2 nodes of every sub-triangle of the straight triangles."""
        return self.local()[:, SUB_DOFS].reshape(-1, 3, 6, 2)

    @property
    def slab_trace(self) -> np.ndarray:
        """``(n_s, 3, 2)``: each slab's trace at its (left, middle, right) nodes."""
        return self.q[self.layout.slab_nodes]

    def slab_values(self, slab: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The displacement ``(m, 2)`` and its gradient ``(m, 2, 2)`` (``[i, j] = d v_i / d x_j``) at points
        ``pts (m, 2)`` of slabs ``slab``: where a slab takes an element's quadratic (a segment, continued
        beyond its chord; a ``concave1`` piece, inside its triangle), the sub-triangle's holding the point
        (or the one beyond whose outer edge it lies); on the other curved pieces, the trace ``w`` of the
        face edge continued along y (gradient ``(w', 0)``)."""
        lay = self.layout
        pts = np.asarray(pts, float)
        val, grad = np.zeros((len(slab), 2)), np.zeros((len(slab), 2, 2))
        seg = lay.slab_tri[slab] >= 0
        if np.any(~seg):
            k = slab[~seg]
            x0, x1 = lay.slab_x[k, 0], lay.slab_x[k, 1]
            N, dN = trace_shapes((pts[~seg, 0] - x0) / (x1 - x0))
            val[~seg] = np.einsum("ma,mac->mc", N, self.slab_trace[k])
            grad[~seg, :, 0] = np.einsum("ma,mac->mc", dN, self.slab_trace[k]) / (x1 - x0)[:, None]
        if np.any(seg):
            t = lay.slab_tri[slab[seg]]
            X = self.corners(t)
            G, _ = bary_gradients(X)
            lam = np.eye(3)[0] + np.einsum("mad,md->ma", G, pts[seg] - X[:, 0])
            j = (np.argmin(lam, axis=1) + 1) % 3  # the sub-triangle (X_j, X_j+1, c) holding the point, or beyond it
            P = sub_vertices(X)[np.arange(len(t)), j]
            N, dN = shapes_at(P, pts[seg][:, None])
            vals = self.sub_values_of(t, j)  # (m, 6, 2)
            val[seg] = np.einsum("mn,mnc->mc", N[:, 0], vals)
            grad[seg] = np.einsum("mnd,mnc->mcd", dN[:, 0], vals)
        return val, grad

    def slab_strains(self, slab: np.ndarray, pts: np.ndarray) -> np.ndarray:
        """``(m, 3)``: engineering strains at points ``pts (m, 2)`` of slabs ``slab`` (:meth:`slab_values`)."""
        _, g = self.slab_values(slab, pts)
        return np.stack([g[:, 0, 0], g[:, 1, 1], g[:, 0, 1] + g[:, 1, 0]], 1)

    def corners(self, t: np.ndarray) -> np.ndarray:
        """``(m, 3, 2)``: the corners of straight triangles ``t``."""
        return self.layout.coords[self.layout.tri[t]]

    def sub_values_of(self, t: np.ndarray, j: np.ndarray) -> np.ndarray:
        """``(m, 6, 2)``: the values at the six P2 nodes of sub-triangle ``j`` of triangles ``t``."""
        ue = np.hstack([self.q[self.layout.nodes[t]].reshape(-1, 12), self.interior[t]])
        return ue[np.arange(len(t))[:, None], SUB_DOFS[j]].reshape(-1, 6, 2)

    def jumps(self) -> np.ndarray:
        """``[v] = v''_y - v'_y`` at the contact pairs (vertices and midpoints, by x)."""
        up, lo = self.layout.pair_nodes.T
        return self.q[lo, 1] - self.q[up, 1]

    def moved(self, dy: np.ndarray) -> P2Displacement:
        """This displacement with ``dy`` ``(n_p2,)`` added to the y values at the nodes; the interior
        dofs kept (any interior values give a displacement of the space)."""
        q = self.q.copy()
        q[:, 1] += dy
        return replace(self, q=q)
