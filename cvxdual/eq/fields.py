"""The equilibrium space's stress field (:class:`EquilibriumField`: linear on every sub-triangle of
the straight pieces, the column stress ``(0, g(x), 0)`` on the curved ones) behind the interface of
:class:`cvxdual.system.field.StressField`, and ``C e(v)`` of a certificate's displacement as a field
(:func:`kinematic_field`): piecewise constant for P1, linear on every sub-triangle for P2
(:class:`P2KinematicField`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..geometry.quadrature import triangle_rule
from ..geometry.triangles import bary_gradients
from ..kinds import Space
from ..system.field import PieceField, StressField, cell_mask
from ..voigt import stiffnesses
from .columns import column_at


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class EquilibriumField(StressField):
    """The equilibrium field of ``space``: ``stress`` holds the Voigt values at the vertices of
    every sub-triangle ``(n_sub, 3, 3)`` (linear on each), ``g`` the column stress ``(0, g(x), 0)``
    at both ends of every column ``(n_col, 2)`` on the curved pieces."""

    space_name: ClassVar[Space] = Space.EQ
    space: object = None
    g: np.ndarray | None = None

    @classmethod
    def of_space(cls, space, sigma: np.ndarray, g: np.ndarray) -> EquilibriumField:
        """The equilibrium stresses ``sigma`` (vertex values) and ``g`` (column values) of ``space``."""
        return cls(space.scene, space.mesh, space.pieces, sigma, space=space, g=g,
                   balance=(space.load_imbalance, space.load_correction))

    @property
    def column(self) -> np.ndarray:
        return self.g

    @property
    def support(self):
        return self.space

    @property
    def n_pieces(self) -> int:
        return 3 * self.space.n_tri

    @property
    def n_unknowns(self) -> int:
        return self.space.n_y

    def piece_kinds(self) -> dict:
        return {"sub_triangle": 3 * self.space.n_tri}

    def in_pieces(self, pts: np.ndarray, loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values at points of known pieces ``loc``: a sub-triangle ``3 t + i`` of a straight piece,
        ``-1 - slab`` on a curved one."""
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
        return np.concatenate([np.arange(3 * self.space.n_tri), -1 - np.arange(len(self.space.pieces.slabs))])

    def rule(self, n: int, cells: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """``n*n`` points per sub-triangle and slab (:meth:`StressField.rule`)."""
        straight = slabs = None  # None: all
        if cells is not None:
            cells = np.asarray(cells, int)
            straight, slabs = cells[cells >= 0], -1 - cells[cells < 0]
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
            spt, sw, si = sp.pieces.slab_quadrature(n, None if slabs is None else cell_mask(slabs, n_slabs))
            g, _ = column_at(sp, self.column, None, spt, si)
            pts, w = np.concatenate([pts, spt]), np.concatenate([w, sw])
            vals = np.concatenate([vals, np.stack([np.zeros(len(g)), g, np.zeros(len(g))], 1)])
            cell = np.concatenate([cell, -1 - si])
            body = np.concatenate([body, sp.pieces.slabs.body[si].astype(int)])
        return pts, w, body, vals, cell


def kinematic_field(space, v) -> StressField:
    """``C e(v)`` of a certificate's displacement ``v``: P1 nodal values ``(n_nodes, 2)`` give a
    :class:`~cvxdual.system.field.PieceField`, constant on every straight triangle and on every slab of
    the curved pieces (its strain along the slab's face edge); a
    :class:`~cvxdual.system.p2_displacement.P2Displacement` gives a :class:`P2KinematicField`."""
    if not isinstance(v, np.ndarray):
        return P2KinematicField.of_displacement(space, v)
    from .bounds import slab_strains, strains
    stiff = stiffnesses(space.scene)
    pieces = space.pieces
    per_piece = np.zeros((len(pieces), 3))
    per_piece[:space.n_tri] = np.einsum("tij,tj->ti", stiff[space.body], strains(space, v))
    slab = np.einsum("sij,sj->si", stiff[pieces.slabs.body], slab_strains(space, v))
    return PieceField(space.scene, space.mesh, pieces, per_piece, slab=slab)


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class P2KinematicField(EquilibriumField):
    """``C e(v)`` of a P2 displacement ``v`` (:class:`~cvxdual.system.p2_displacement.P2Displacement`),
    exact everywhere on the space's pieces. On the straight pieces ``e(v)`` of a quadratic on each
    sub-triangle is linear there and ``C`` is constant per body: the vertex values ``C e(v)`` at the
    sub-triangles' vertices (``v.sub_strains``, the equilibrium stresses' layout) interpolate it exactly,
    as :class:`EquilibriumField` does. On the curved pieces ``v`` is an element's quadratic (a segment, a
    type-1 concave piece) or its face edge's trace continued along ``y`` (type 2): ``e(v)`` is evaluated
    at every point (``v.slab_strains``), not as a column stress, so it is exact there too (the only
    error of a distance to it is that of the quadrature that integrates it)."""

    displacement: object = None

    @classmethod
    def of_displacement(cls, space, v) -> P2KinematicField:
        stiff = stiffnesses(space.scene)
        ce = np.einsum("tij,tsaj->tsai", stiff[space.body], v.sub_strains(space.X)).reshape(-1, 3, 3)
        return cls(space.scene, space.mesh, space.pieces, ce, space=space, g=np.zeros((len(space.columns), 2)),
                   displacement=v)

    def _slab_values(self, slab: np.ndarray, pts: np.ndarray) -> np.ndarray:
        stiff = stiffnesses(self.scene)[self.space.pieces.slabs.body[slab]]
        return np.einsum("mij,mj->mi", stiff, self.displacement.slab_strains(slab, pts))

    def in_pieces(self, pts: np.ndarray, loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out, cell = super().in_pieces(pts, loc)  # the straight pieces' values; the slab of each curved point
        cu = np.flatnonzero(cell < 0)
        if len(cu):
            out[cu] = self._slab_values(-1 - cell[cu], pts[cu])
        return out, cell

    def rule(self, n: int, cells: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        pts, w, body, vals, cell = super().rule(n, cells)
        cu = np.flatnonzero(cell < 0)
        if len(cu):
            vals = vals.copy()
            vals[cu] = self._slab_values(-1 - cell[cu], pts[cu])
        return pts, w, body, vals, cell
