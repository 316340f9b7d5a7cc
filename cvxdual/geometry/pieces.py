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

from dataclasses import dataclass, field

import numpy as np

from .quadrature import gauss01, triangle_rule

PIECE_KINDS = ("triangle", "segment", "concave1", "concave2")
OUTLINE_POINTS = 12  # vertices of the polygon drawn for each curved piece


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
    # (m, 2) the nodes of the face edge whose V_h trace is extended along y over the slab (left, right)
    edge_nodes: np.ndarray = field(default_factory=lambda: np.empty((0, 2), int))

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
    tri_map: np.ndarray  # (n_mesh_triangles,) piece covering each mesh triangle's region

    def __len__(self) -> int:
        return len(self.kind)

    @property
    def dofs(self) -> np.ndarray:
        """Global dof indices ``(n, 6)`` of each piece's nodes (node ``k`` owns dofs ``2k, 2k+1``)."""
        return np.stack([2 * self.nodes, 2 * self.nodes + 1], axis=2).reshape(len(self), 6)

    def counts(self) -> dict[str, int]:
        return {name: int(np.sum(self.kind == k)) for k, name in enumerate(PIECE_KINDS)}

    def _bound(self, x, idx, which: str):
        return slab_bound(self.slabs, self.faces, x, idx, which)

    def polygons(self, n: int = OUTLINE_POINTS) -> tuple[list[np.ndarray], np.ndarray]:
        """Polygons of every piece, for drawing: the straight triangles, then the curved pieces
        along the face (``n`` vertices per arc, :func:`piece_outlines`), and the piece of each."""
        polys, ids = list(self.tri_vertices), [self.tri_piece]
        for pid, poly in piece_outlines(self, n):
            polys += list(poly)
            ids.append(pid)
        return polys, np.concatenate(ids)

    # -- quadrature --------------------------------------------------------------------
    def quadrature(self, n: int = 4, only: np.ndarray | None = None):
        """Points ``(m, 2)``, weights ``(m,)`` and piece index ``(m,)`` of a rule with ``n``
        points per direction on every triangle and slab (``n*n`` points each); ``only`` (a
        boolean mask over pieces) restricts it to those pieces."""
        rs, w = triangle_rule(n)
        tri = np.arange(len(self.tri_piece)) if only is None else np.flatnonzero(only[self.tri_piece])
        v = self.tri_vertices[tri]
        J = 2.0 * np.abs(p1_strain(v)[1])  # |det| of the affine map
        pts = (v[:, None, 0, :] + rs[None, :, 0, None] * (v[:, None, 1, :] - v[:, None, 0, :])
               + rs[None, :, 1, None] * (v[:, None, 2, :] - v[:, None, 0, :]))
        P, W, ids = [pts.reshape(-1, 2)], [(J[:, None] * w[None, :]).ravel()], [np.repeat(self.tri_piece[tri], len(w))]
        if len(self.slabs):
            sel = None if only is None else only[self.slabs.piece]
            sp, sw, si = self.slab_quadrature(n, sel)
            P.append(sp), W.append(sw), ids.append(self.slabs.piece[si])
        return np.concatenate(P), np.concatenate(W), np.concatenate(ids)

    def slab_quadrature(self, n: int = 4, only: np.ndarray | None = None):
        """Points ``(m, 2)``, weights ``(m,)`` and slab index ``(m,)`` of a tensor Gauss rule with
        ``n`` points per direction on every slab (``only``: a boolean mask over slabs)."""
        s = self.slabs
        u, wu = gauss01(n)
        sel = np.arange(len(s)) if only is None else np.flatnonzero(only)
        m = len(sel)
        idx = np.repeat(sel, n)
        x = s.xl[idx] + np.tile(u, m) * (s.xr - s.xl)[idx]
        wx = np.tile(wu, m) * (s.xr - s.xl)[idx]
        lo, hi = self._bound(x, idx, "lo"), self._bound(x, idx, "hi")
        # tensor rule: n points in y between lo(x) and hi(x) at each x point
        y = lo[:, None] + u[None, :] * (hi - lo)[:, None]
        w = (wx * (hi - lo))[:, None] * wu[None, :]
        pts = np.stack([np.repeat(x, n), y.ravel()], axis=1)
        return pts, w.ravel(), np.repeat(idx, n)

    def slab_areas(self) -> np.ndarray:
        """``|S|`` of every slab, exactly (:func:`slab_bound_integral`)."""
        s = self.slabs
        return slab_bound_integral(s, self.faces, "hi") - slab_bound_integral(s, self.faces, "lo")


def slab_bound(slabs: Slabs, faces, x, idx, which: str) -> np.ndarray:
    """The ``lo`` or ``hi`` bound of slabs ``idx`` at abscissae ``x`` (same shape)."""
    line = getattr(slabs, which)
    t = (x - slabs.xl[idx]) / (slabs.xr[idx] - slabs.xl[idx])
    y = line[idx, 0] + t * (line[idx, 1] - line[idx, 0])
    arc = getattr(slabs, which + "_arc")[idx]
    if np.any(arc):
        for b, face in enumerate(faces):
            m = arc & (slabs.body[idx] == b)
            if np.any(m):
                y = np.where(m, face.value(x), y)
    return y


def slab_bound_integral(slabs: Slabs, faces, which: str) -> np.ndarray:
    """``int_{xl}^{xr} bound(x) dx`` exactly: trapezoid for lines, the profile's integral for arcs."""
    line = getattr(slabs, which)
    val = 0.5 * (line[:, 0] + line[:, 1]) * (slabs.xr - slabs.xl)
    arc = getattr(slabs, which + "_arc")
    for b, face in enumerate(faces):
        m = arc & (slabs.body == b)
        if np.any(m):
            val[m] = face.integral(slabs.xl[m], slabs.xr[m])
    return val


def build_pieces(points, tris, tri_body, faces, keep=None, curved=None) -> Pieces:
    """Pieces from straight mesh triangles (those with ``keep`` true) and curved pieces.

    ``curved`` is a dict with per-piece ``kind``, ``body``, ``nodes`` ``(n, 3)``, ``replaces``
    (mesh triangle whose region the piece takes over, or -1) and per-slab ``slabs`` (a
    :class:`Slabs` with piece indices local to ``curved``), ``edge`` ``(m, 2)`` local node
    positions and ``edge_x`` ``(m, 2)`` abscissae of the face edge whose ``V_h`` trace is
    extended along y over the slab. A slab's strain is ``(du_x/dx, 0, du_y/dx)`` along that
    edge; the piece's strain is the area-weighted mean over its slabs.
    """
    keep = np.ones(len(tris), bool) if keep is None else keep
    kept = np.flatnonzero(keep)
    xy = points[tris[kept]]
    B, area = p1_strain(xy)
    n_s = len(kept)
    tri_map = np.full(len(tris), -1)
    tri_map[kept] = np.arange(n_s)
    kinds, bodies, nodes = [np.zeros(n_s, np.int8)], [tri_body[kept].astype(np.int8)], [tris[kept]]
    Bs, areas, phis = [B], [area], [np.repeat(area[:, None] / 3.0, 3, axis=1)]
    slabs = Slabs.empty()
    if curved is not None and len(curved["kind"]):
        c = curved
        s = c["slabs"]
        n_c = len(c["kind"])
        edge_nodes = np.asarray(c["nodes"])[s.piece[:, None], c["edge"]]
        gl = Slabs(piece=s.piece + n_s, edge_nodes=edge_nodes, **{k: getattr(s, k) for k in
                                                                 ("body", "xl", "xr", "lo", "hi", "lo_arc", "hi_arc")})
        a_s = slab_bound_integral(s, faces, "hi") - slab_bound_integral(s, faces, "lo")
        a_p = np.bincount(s.piece, weights=a_s, minlength=n_c)
        dx = c["edge_x"][:, 1] - c["edge_x"][:, 0]
        Bsl = np.zeros((len(s), 3, 6))
        r = np.arange(len(s))
        k0, k1 = c["edge"][:, 0], c["edge"][:, 1]
        Bsl[r, 0, 2 * k0] = -1.0 / dx
        Bsl[r, 0, 2 * k1] = 1.0 / dx
        Bsl[r, 2, 2 * k0 + 1] = -1.0 / dx
        Bsl[r, 2, 2 * k1 + 1] = 1.0 / dx
        Bc = np.zeros((n_c, 3, 6))
        np.add.at(Bc, s.piece, a_s[:, None, None] * Bsl)
        Bc /= a_p[:, None, None]
        # phi_a(x) is the edge's hat function (v_h is constant along y); Gauss in x is exact
        # for polynomial bounds and converges fast for the smooth arcs
        u, w = gauss01(8)
        x = s.xl[:, None] + u[None, :] * (s.xr - s.xl)[:, None]
        idx = np.repeat(r, len(u))
        height = (slab_bound(s, faces, x.ravel(), idx, "hi")
                  - slab_bound(s, faces, x.ravel(), idx, "lo")).reshape(x.shape)
        wh = w[None, :] * (s.xr - s.xl)[:, None] * height
        t = (x - c["edge_x"][:, :1]) / dx[:, None]
        phi = np.zeros((n_c, 3))
        np.add.at(phi, (s.piece, k0), np.sum(wh * (1 - t), axis=1))
        np.add.at(phi, (s.piece, k1), np.sum(wh * t, axis=1))
        kinds.append(np.asarray(c["kind"], np.int8))
        bodies.append(np.asarray(c["body"], np.int8))
        nodes.append(np.asarray(c["nodes"]))
        Bs.append(Bc), areas.append(a_p), phis.append(phi)
        rep = np.asarray(c["replaces"])
        tri_map[rep[rep >= 0]] = n_s + np.flatnonzero(rep >= 0)
        slabs = gl
    return Pieces(kind=np.concatenate(kinds), body=np.concatenate(bodies), nodes=np.concatenate(nodes),
                  B=np.concatenate(Bs), area=np.concatenate(areas), phi=np.concatenate(phis),
                  tri_vertices=xy, tri_piece=np.arange(n_s), slabs=slabs, faces=tuple(faces), tri_map=tri_map)


def slab_outlines(pieces: Pieces, n: int = OUTLINE_POINTS) -> np.ndarray:
    """``(n_slabs, n, 2)`` polygons of the slabs: ``n // 2`` points along the lower bound left to
    right, then as many along the upper bound right to left (the arc followed where it bounds)."""
    s = pieces.slabs
    k = max(2, n // 2)
    x = s.xl[:, None] + np.linspace(0.0, 1.0, k)[None, :] * (s.xr - s.xl)[:, None]
    idx = np.broadcast_to(np.arange(len(s))[:, None], x.shape)
    lo, hi = slab_bound(s, pieces.faces, x, idx, "lo"), slab_bound(s, pieces.faces, x, idx, "hi")
    return np.concatenate([np.stack([x, lo], -1), np.stack([x, hi], -1)[:, ::-1]], axis=1)


def piece_outlines(pieces: Pieces, n: int = OUTLINE_POINTS) -> list[tuple[np.ndarray, np.ndarray]]:
    """Outlines of the curved pieces, following the face: ``[(piece ids (m,), polygons (m, v, 2))]``,
    one entry per number of slabs (pieces of one entry have the same number of vertices)."""
    s = pieces.slabs
    if not len(s):
        return []
    order = np.lexsort((s.xl, s.piece))
    counts = np.bincount(s.piece)
    k = max(2, n // 2)
    t = np.linspace(0.0, 1.0, k)
    out = []
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])  # first slab (in `order`) of each piece
    for c in np.unique(counts[counts > 0]):
        ids = np.flatnonzero(counts == c)
        sl = order[start[ids][:, None] + np.arange(c)[None, :]]  # (m, c) slabs left to right
        x = s.xl[sl][..., None] + t * (s.xr - s.xl)[sl][..., None]  # (m, c, k)
        idx = np.broadcast_to(sl[..., None], x.shape)
        lo = slab_bound(s, pieces.faces, x, idx, "lo").reshape(len(ids), -1)
        hi = slab_bound(s, pieces.faces, x, idx, "hi").reshape(len(ids), -1)
        xf = x.reshape(len(ids), -1)
        poly = np.concatenate([np.stack([xf, lo], -1), np.stack([xf, hi], -1)[:, ::-1]], axis=1)
        out.append((ids, poly))
    return out
