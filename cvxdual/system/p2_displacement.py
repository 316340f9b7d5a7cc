"""A P2 displacement on a scene's mesh (:mod:`cvxdual.system.p2_system`): its values at the P2 nodes
and the condensed interior dofs of every straight triangle, with what the certificate reads from
it: strains at the sub-triangles' vertices (linear on each), the slabs' traces, the contact jumps."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .p2 import SUB_DOFS, evaluate_p2
from .p2_system import P2Layout, trace_shapes

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
        """``(n_T, 20)``: the local dofs of :mod:`cvxdual.system.p2` of every straight triangle."""
        return np.hstack([self.q[self.layout.nodes].reshape(-1, 12), self.interior])

    def sub_strains(self, X: np.ndarray) -> np.ndarray:
        """``(n_T, 3, 3, 3)``: engineering strains at the vertices ``a`` of sub-triangle ``j`` (index
        ``[t, j, a]``, the order of the equilibrium stresses' vertex values) of triangles ``X``."""
        ue = self.local()
        return np.stack([evaluate_p2(X, ue, j, VERTICES)[2] for j in range(3)], 1)

    def sub_values(self) -> np.ndarray:
        """``(n_T, 3, 6, 2)``: the values at the six P2 nodes of every sub-triangle."""
        return self.local()[:, SUB_DOFS].reshape(-1, 3, 6, 2)

    @property
    def slab_trace(self) -> np.ndarray:
        """``(n_s, 3, 2)``: each slab's trace at its (left, middle, right) nodes."""
        return self.q[self.layout.slab_nodes]

    def slab_strains(self, slab: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``(m, 3)``: the strain ``(w_x', 0, w_y')`` of slab ``slab``'s trace ``w`` at abscissae ``x``."""
        lay = self.layout
        x0, x1 = lay.slab_x[slab, 0], lay.slab_x[slab, 1]
        _, dN = trace_shapes((x - x0) / (x1 - x0))
        d = np.einsum("ma,mac->mc", dN, self.slab_trace[slab]) / (x1 - x0)[:, None]
        return np.stack([d[:, 0], np.zeros(len(d)), d[:, 1]], 1)

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
