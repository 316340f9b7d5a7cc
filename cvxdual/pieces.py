"""Pieces: the sets ``P`` on which stresses (``S_h``) and strains of ``V_h`` are constant.

Every piece carries (one row per piece, arrays of one shape convention):

- ``kind``: an index into :data:`PIECE_KINDS`;
- ``body``: 0 for the upper body, 1 for the lower;
- ``nodes`` ``(n, 3)``: the nodes whose displacements determine the piece's strain;
- ``B`` ``(n, 3, 6)``: the constant strain map, ``g_P = B_P @ q[dofs(nodes)]`` with
  ``g = (e11, e22, 2 e12)`` and local dofs ordered ``(x0, y0, x1, y1, x2, y2)``;
- ``area`` ``(n,)``: ``|P|``, exact to quadrature precision;
- ``phi`` ``(n, 3)``: ``int_P phi_a dx`` of the ``V_h`` basis functions of ``nodes`` (body forces).

Straight triangles are given by their vertices. Curved pieces are unions of *slabs*
``{xl <= x <= xr, lo(x) <= y <= hi(x)}`` whose bounds are straight lines or the body's face;
each slab has its own strain (a ``T_c`` of the second triangulation has two) and the piece's
strain is their area-weighted mean. Quadrature, point location and plotting all work on
triangles and slabs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .quadrature import gauss01, triangle_rule

PIECE_KINDS = ("triangle", "segment", "concave1", "concave2")


def p1_strain(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strain maps and signed areas of straight P1 triangles; ``xy`` is ``(n, 3, 2)``.

    Returns ``B`` ``(n, 3, 6)`` and ``area`` ``(n,)``.
    """
    x, y = xy[..., 0], xy[..., 1]
    area2 = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    dx = np.stack([y[:, 1] - y[:, 2], y[:, 2] - y[:, 0], y[:, 0] - y[:, 1]], 1) / area2[:, None]
    dy = np.stack([x[:, 2] - x[:, 1], x[:, 0] - x[:, 2], x[:, 1] - x[:, 0]], 1) / area2[:, None]
    B = np.zeros((len(xy), 3, 6))
    B[:, 0, 0::2] = dx
    B[:, 1, 1::2] = dy
    B[:, 2, 0::2] = dy
    B[:, 2, 1::2] = dx
    return B, 0.5 * area2


@dataclass(frozen=True)
class Slabs:
    """Vertical slabs of curved pieces. A bound is the line through ``(xl, lo_l)`` and
    ``(xr, lo_r)`` unless ``lo_arc`` is set, in which case it is the face of body ``body``
    (likewise ``hi``)."""

    piece: np.ndarray
    body: np.ndarray
    xl: np.ndarray
    xr: np.ndarray
    lo: np.ndarray  # (m, 2) line values at xl, xr
    hi: np.ndarray
    lo_arc: np.ndarray  # (m,) bool
    hi_arc: np.ndarray

    def __len__(self) -> int:
        return len(self.piece)

    @staticmethod
    def empty() -> "Slabs":
        z = np.empty(0)
        return Slabs(z.astype(int), z.astype(int), z, z, np.empty((0, 2)), np.empty((0, 2)),
                     z.astype(bool), z.astype(bool))


@dataclass(frozen=True)
class Pieces:
    kind: np.ndarray
    body: np.ndarray
    nodes: np.ndarray
    B: np.ndarray
    area: np.ndarray
    phi: np.ndarray
    tri_vertices: np.ndarray  # (n_tri, 3, 2) vertices of the straight pieces
    tri_piece: np.ndarray  # (n_tri,) piece index of each straight triangle
    slabs: Slabs
    faces: tuple  # face profile of each body, for slabs bounded by the face

    def __len__(self) -> int:
        return len(self.kind)

    @property
    def dofs(self) -> np.ndarray:
        """Global dof indices ``(n, 6)`` of each piece's nodes (node ``k`` owns dofs ``2k, 2k+1``)."""
        return np.stack([2 * self.nodes, 2 * self.nodes + 1], axis=2).reshape(len(self), 6)

    def counts(self) -> dict[str, int]:
        return {name: int(np.sum(self.kind == k)) for k, name in enumerate(PIECE_KINDS)}

    # -- geometry of slabs -------------------------------------------------------------
    def _bound(self, x, idx, which: str):
        s = self.slabs
        line = getattr(s, which)
        t = (x - s.xl[idx]) / (s.xr[idx] - s.xl[idx])
        y = line[idx, 0] + t * (line[idx, 1] - line[idx, 0])
        arc = getattr(s, which + "_arc")[idx]
        if np.any(arc):
            for b, face in enumerate(self.faces):
                m = arc & (s.body[idx] == b)
                if np.any(m):
                    y = np.where(m, face.value(x), y)
        return y

    # -- quadrature --------------------------------------------------------------------
    def quadrature(self, n: int = 4):
        """Points ``(m, 2)``, weights ``(m,)`` and piece index ``(m,)`` of a rule with ``n``
        points per direction on every triangle and slab (``n*n`` points each)."""
        rs, w = triangle_rule(n)
        v = self.tri_vertices
        J = 2.0 * np.abs(p1_strain(v)[1])  # |det| of the affine map
        pts = (v[:, None, 0, :] + rs[None, :, 0, None] * (v[:, None, 1, :] - v[:, None, 0, :])
               + rs[None, :, 1, None] * (v[:, None, 2, :] - v[:, None, 0, :]))
        P, W, I = [pts.reshape(-1, 2)], [(J[:, None] * w[None, :]).ravel()], [np.repeat(self.tri_piece, len(w))]
        if len(self.slabs):
            sp, sw, si = self._slab_rule(n)
            P.append(sp), W.append(sw), I.append(si)
        return np.concatenate(P), np.concatenate(W), np.concatenate(I)

    def _slab_rule(self, n: int):
        s = self.slabs
        u, wu = gauss01(n)
        m = len(s)
        idx = np.repeat(np.arange(m), n)
        x = s.xl[idx] + np.tile(u, m) * (s.xr - s.xl)[idx]
        wx = np.tile(wu, m) * (s.xr - s.xl)[idx]
        lo, hi = self._bound(x, idx, "lo"), self._bound(x, idx, "hi")
        # tensor rule: n points in y between lo(x) and hi(x) at each x point
        y = lo[:, None] + u[None, :] * (hi - lo)[:, None]
        w = (wx * (hi - lo))[:, None] * wu[None, :]
        pts = np.stack([np.repeat(x, n), y.ravel()], axis=1)
        return pts, w.ravel(), np.repeat(s.piece[idx], n)

    def integrate(self, func, n: int = 4) -> np.ndarray:
        """``int_P func(x, y) dx`` for every piece; ``func`` maps points ``(m, 2)`` to ``(m, ...)``."""
        pts, w, idx = self.quadrature(n)
        vals = np.asarray(func(pts))
        out = np.zeros((len(self),) + vals.shape[1:])
        np.add.at(out, idx, w.reshape((-1,) + (1,) * (vals.ndim - 1)) * vals)
        return out


def triangle_pieces(points: np.ndarray, tris: np.ndarray, body: np.ndarray, faces) -> Pieces:
    """Pieces for a mesh of straight triangles only."""
    xy = points[tris]
    B, area = p1_strain(xy)
    n = len(tris)
    return Pieces(kind=np.zeros(n, dtype=np.int8), body=body.astype(np.int8), nodes=tris.copy(),
                  B=B, area=area, phi=np.repeat(area[:, None] / 3.0, 3, axis=1),
                  tri_vertices=xy, tri_piece=np.arange(n), slabs=Slabs.empty(), faces=tuple(faces))
