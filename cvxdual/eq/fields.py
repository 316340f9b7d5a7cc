"""Stress fields of either stress space as functions on the bodies, and distances between fields
on different meshes of one scene (a solution against a finer reference).

A :class:`StressField` is piecewise constant on the pieces (``p0``; or on the slabs of the
curved pieces, as ``C e(v)`` of a displacement of ``V_h``: :meth:`StressField.kinematic`) or the
equilibrium field (``eq``: linear on every sub-triangle of the straight pieces, the column stress
``(0, g(x), 0)`` on the curved ones). :meth:`StressField.at` evaluates it at points; :meth:`StressField.rule`
gives a quadrature of it; :func:`field_distance` integrates the difference of two fields over
the common part of the first one's cells and the second's pieces, every point located in the second's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CvxdualError
from ..geometry.locate import common_part, locate
from ..geometry.quadrature import triangle_rule
from ..voigt import VOIGT_WEIGHT
from .element import bary_gradients


@dataclass(frozen=True)
class StressField:
    """The stress of a solution: ``stress`` per piece ``(n_pieces, 3)`` (``space`` None; with
    ``slab`` ``(n_slabs, 3)`` the curved pieces are constant per slab instead), or the vertex values
    ``(n_sub, 3, 3)`` and column values ``column`` ``(n_col, 2)`` of ``space``."""

    scene: object
    mesh: object
    pieces: object
    stress: np.ndarray
    space: object | None = None
    column: np.ndarray | None = None
    slab: np.ndarray | None = None
    bound: float | None = None  # a certified relative energy bound of the field, where known

    @classmethod
    def kinematic(cls, space, v: np.ndarray) -> StressField:
        """``C e(v)`` of a displacement ``v (n_nodes, 2)`` of ``V_h``: constant on every straight
        triangle and on every slab of the curved pieces (its strain along the slab's face edge)."""
        from .bounds import slab_strains, strains
        stiff = np.stack([b.material.stiffness for b in space.scene.bodies])
        pieces = space.pieces
        per_piece = np.zeros((len(pieces), 3))
        per_piece[:space.n_tri] = np.einsum("tij,tj->ti", stiff[space.body], strains(space, v))
        slab = np.einsum("sij,sj->si", stiff[pieces.slabs.body], slab_strains(space, v))
        return cls(space.scene, space.mesh, pieces, per_piece, slab=slab)

    @classmethod
    def of(cls, sol) -> StressField:
        """The field of a :class:`~cvxdual.solution.Solution`."""
        if sol.stress_space == "eq":
            return cls(sol.scene, sol.mesh, sol.pieces, np.asarray(sol.stress, float), sol.space,
                       np.asarray(sol.column_stress, float))
        return cls(sol.scene, sol.mesh, sol.pieces, np.asarray(sol.stress, float))

    def at(self, pts: np.ndarray, body: np.ndarray, tol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Voigt stresses ``(m, 3)`` at points ``pts`` of the bodies ``body``, and the cell each lies
        in (a piece, or for ``eq`` a sub-triangle ``3 t + i`` or ``-1 - slab`` on a curved piece):
        a point on a cell boundary takes one side. Points outside every piece are refused."""
        loc = locate(self.mesh, self.pieces, pts, body, tol)
        if np.any(loc < 0):
            raise CvxdualError(f"{int(np.sum(loc < 0))} points lie outside the pieces of the field: the fields are "
                               "not of the same scene")
        return self.in_pieces(pts, loc)

    def in_pieces(self, pts: np.ndarray, loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`at` for points whose pieces ``loc`` are known (:func:`~cvxdual.geometry.locate.locate`)."""
        if self.space is None:
            out = self.stress[loc]
            curved = np.flatnonzero(self.pieces.kind[loc] > 0) if self.slab is not None else []
            if len(curved):
                slab = slab_of(self.pieces, loc[curved], pts[curved])
                out[curved] = self.slab[slab]
                loc = loc.copy()
                loc[curved] = -1 - slab
            return out, loc
        sp = self.space
        n_straight = sp.n_tri  # the straight pieces come first, in the order of the macro triangles
        out, cell = np.empty((len(pts), 3)), np.empty(len(pts), int)
        st = np.flatnonzero(loc < n_straight)
        if len(st):
            t = loc[st]
            # barycentric coordinates in the macro triangle; the point lies in the sub-triangle
            # (X_i, X_i+1, c) opposite the smallest one, lam_k (k = i + 2), where its own are
            # (lam_i - lam_k, lam_i+1 - lam_k, 3 lam_k): x = sum lam_j X_j and c is the mean
            X = sp.X[t]
            d1, d2, p = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], pts[st] - X[:, 0]
            det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
            l1 = (p[:, 0] * d2[:, 1] - p[:, 1] * d2[:, 0]) / det
            l2 = (d1[:, 0] * p[:, 1] - d1[:, 1] * p[:, 0]) / det
            lam = np.stack([1.0 - l1 - l2, l1, l2], 1)
            k = np.argmin(lam, axis=1)
            i = (k + 1) % 3
            rows = np.arange(len(st))
            lk = lam[rows, k]
            li = np.stack([lam[rows, i] - lk, lam[rows, (i + 1) % 3] - lk, 3.0 * lk], 1)
            vals = self.stress.reshape(sp.n_tri, 3, 3, 3)[t, i]  # (m, 3 vertices, 3)
            out[st] = np.einsum("ma,mai->mi", li, vals)
            cell[st] = 3 * t + i
        cu = np.flatnonzero(loc >= n_straight)
        if len(cu):
            g, slab = column_at(sp, self.column, loc[cu], pts[cu])
            out[cu] = np.stack([np.zeros(len(cu)), g, np.zeros(len(cu))], 1)
            cell[cu] = -1 - slab
        return out, cell

    def cells(self) -> np.ndarray:
        """Every cell of the field, numbered as :meth:`at` returns them (pieces; or sub-triangles
        ``3 t + i`` and ``-1 - slab`` on the curved pieces)."""
        if self.space is None:
            if self.slab is None:
                return np.arange(len(self.pieces))
            return np.concatenate([np.flatnonzero(self.pieces.kind == 0), -1 - np.arange(len(self.slab))])
        return np.concatenate([np.arange(3 * self.space.n_tri), -1 - np.arange(len(self.space.pieces.slabs))])

    def rule(self, n: int, cells: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                                   np.ndarray]:
        """A quadrature of the field: points, weights, body, values ``(m, 3)`` and cell (as
        :meth:`at`), with ``n*n`` Gauss points per piece (``p0``) or per sub-triangle and slab
        (``eq``); on the ``cells`` of :meth:`cells` only, if given."""
        straight = slabs = None  # None: all
        if cells is not None:
            cells = np.asarray(cells, int)
            straight, slabs = cells[cells >= 0], -1 - cells[cells < 0]
        if self.space is None:
            if self.slab is None:
                only = None if straight is None else _mask(straight, len(self.pieces))
                pts, w, idx = self.pieces.quadrature(n, only=only)
                return pts, w, self.pieces.body[idx].astype(int), self.stress[idx], idx
            only = self.pieces.kind == 0
            if straight is not None:
                only &= _mask(straight, len(self.pieces))
            pts, w, idx = self.pieces.quadrature(n, only=only)
            spt, sw, si = self.pieces.slab_quadrature(n, None if slabs is None else _mask(slabs, len(self.slab)))
            return (np.concatenate([pts, spt]), np.concatenate([w, sw]),
                    np.concatenate([self.pieces.body[idx], self.pieces.slabs.body[si]]).astype(int),
                    np.concatenate([self.stress[idx], self.slab[si]]), np.concatenate([idx, -1 - si]))
        sp = self.space
        sub = np.arange(3 * sp.n_tri) if straight is None else straight
        rs, wr = triangle_rule(n)
        lam = np.stack([1 - rs.sum(1), rs[:, 0], rs[:, 1]], 1)
        P = sp.sub_points()[sub]
        _, area = bary_gradients(P)
        pts = np.einsum("qa,sai->sqi", lam, P).reshape(-1, 2)
        w = (2.0 * area[:, None] * wr[None, :]).ravel()
        vals = np.einsum("qa,sai->sqi", lam, self.stress.reshape(-1, 3, 3)[sub]).reshape(-1, 3)
        cell = np.repeat(sub, len(wr))
        body = np.repeat(sp.body[sub // 3], len(wr))
        n_slabs = len(sp.pieces.slabs)
        if n_slabs and (slabs is None or len(slabs)):
            spt, sw, si = sp.pieces.slab_quadrature(n, None if slabs is None else _mask(slabs, n_slabs))
            g, _ = column_at(sp, self.column, None, spt, si)
            pts, w = np.concatenate([pts, spt]), np.concatenate([w, sw])
            vals = np.concatenate([vals, np.stack([np.zeros(len(g)), g, np.zeros(len(g))], 1)])
            cell = np.concatenate([cell, -1 - si])
            body = np.concatenate([body, sp.pieces.slabs.body[si].astype(int)])
        return pts, w, body, vals, cell


def _mask(idx: np.ndarray, n: int) -> np.ndarray:
    m = np.zeros(n, bool)
    m[idx] = True
    return m


def slab_of(pieces, piece: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """The slab of each point ``pts`` of the curved pieces ``piece``: the one whose x range holds it
    (a type-2 piece has two, side by side)."""
    s = pieces.slabs
    order = np.lexsort((s.xl, s.piece))
    first = np.searchsorted(s.piece[order], piece)
    second = np.minimum(first + 1, len(order) - 1)
    use_second = (s.piece[order[second]] == piece) & (pts[:, 0] >= s.xl[order[second]])
    return order[np.where(use_second, second, first)]


def column_at(space, g: np.ndarray, piece: np.ndarray | None, pts: np.ndarray,
              slab: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The column stress ``g(x)`` at points ``pts`` of the curved pieces ``piece`` (or of the slabs
    ``slab``, when known), and the slab of each point."""
    if slab is None:
        slab = slab_of(space.pieces, piece, pts)
    col = space.slab_column[slab]
    x0, x1 = space.faces.x[space.columns[col], 0], space.faces.x[space.columns[col], 1]
    t = (pts[:, 0] - x0) / (x1 - x0)
    return g[col, 0] * (1 - t) + g[col, 1] * t, slab


CHUNK_POINTS = 2_000_000  # quadrature points per pass of field_distance: ~1 GB of temporaries
OUTSIDE = np.iinfo(np.int64).min  # the cell of a point outside every piece (cells are pieces, or -1 - slab)


def field_distance(a: StressField, b: StressField, n: int = 3, n_fine: int | None = 8) -> dict:
    """``||sigma_a - sigma_b||`` (L2 and energy) integrated over the common part of ``a``'s cells
    (``n*n`` points each) and ``b``'s pieces, every point evaluated in ``b``; relative measures are
    against ``a`` (integrate over the finer field). A cell of ``a`` whose points fall in several
    cells of ``b``, or partly outside ``b`` (the meshes are not nested: the integrand jumps inside
    it), is integrated again with ``n_fine*n_fine`` points. Points outside ``b`` (the polygons
    standing for an outline body's curves differ between levels) are dropped: ``dropped_area``
    and ``dropped_share`` say what the integral leaves out of either mesh, and more than those
    polygons explain is refused (:func:`~cvxdual.geometry.locate.common_part`). The cells are
    taken in chunks of about :data:`CHUNK_POINTS` points (a level-6 reference has millions)."""
    tol = 1e-10 * a.scene.length_scale  # Gauss points are interior; rounding where the faces coincide
    A_body = np.stack([bd.material.compliance for bd in a.scene.bodies])
    sums = np.zeros(4)  # |d|^2, |a|^2 in L2; d:A d, a:A a
    dropped = 0.0
    cells = a.cells()
    per = max(1, CHUNK_POINTS // max(n, n_fine or n) ** 2)
    for lo in range(0, len(cells), per):  # chunks of cells, each pass vectorised
        chunk = cells[lo:lo + per]
        pts, w, body, va, cell = a.rule(n, chunk)
        vb, cb = _values_in(b, pts, body, tol)
        if n_fine is not None:
            ids, first, inv = np.unique(cell, return_index=True, return_inverse=True)
            straddles = np.zeros(len(ids), bool)
            np.logical_or.at(straddles, inv, cb != cb[first][inv])  # a point in another host than the first
            bad = ids[straddles]
            if len(bad):
                keep = ~np.isin(cell, bad)
                fp, fw, fb, fv, _ = a.rule(n_fine, bad)
                fvb, fcb = _values_in(b, fp, fb, tol)
                w, body, va, vb, cb = (np.concatenate([x[keep], y]) for x, y in
                                       ((w, fw), (body, fb), (va, fv), (vb, fvb), (cb, fcb)))
        out = cb == OUTSIDE
        if out.any():
            dropped += float(w[out].sum())
            w, body, va, vb = w[~out], body[~out], va[~out], vb[~out]
        d = va - vb
        A = A_body[body]
        sums += [np.sum(w * np.einsum("mi,mi,i->m", d, d, VOIGT_WEIGHT)),
                 np.sum(w * np.einsum("mi,mi,i->m", va, va, VOIGT_WEIGHT)),
                 np.sum(w * np.einsum("mi,mij,mj->m", d, A, d)), np.sum(w * np.einsum("mi,mij,mj->m", va, A, va))]
    l2, ref, en, ref_en = np.sqrt(sums)
    return {"l2": float(l2), "l2_rel": float(l2 / ref) if ref > 0 else float("nan"), "energy": float(en),
            "energy_rel": float(en / ref_en) if ref_en > 0 else float("nan"),
            **common_part(a.mesh, b.mesh, dropped, float(a.pieces.area.sum()), float(b.pieces.area.sum()))}


def _values_in(b: StressField, pts: np.ndarray, body: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``b``'s values and cells at points (:meth:`StressField.at`); outside its pieces NaN and :data:`OUTSIDE`."""
    loc = locate(b.mesh, b.pieces, pts, body, tol)
    inside = loc >= 0
    if inside.all():
        return b.in_pieces(pts, loc)
    vals, cell = np.full((len(pts), 3), np.nan), np.full(len(pts), OUTSIDE)
    if inside.any():
        vals[inside], cell[inside] = b.in_pieces(pts[inside], loc[inside])
    return vals, cell
