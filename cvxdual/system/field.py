"""Stress fields as functions on the bodies, whatever space made them, and the distance between
two fields on different meshes of one scene (a solution against a finer reference).

:class:`StressField` is the interface a :class:`~cvxdual.solution.Solution` holds and outputs and
studies query: :meth:`~StressField.at` evaluates it at points, :meth:`~StressField.rule` gives a
quadrature of it on its cells, :meth:`~StressField.cells` numbers them. :class:`PieceField` is
piecewise constant on the pieces (the paper's ``p0``; or on the slabs of the curved pieces, as
``C e(v)`` of a displacement); the equilibrium field is :class:`cvxdual.eq.fields.EquilibriumField`.
:func:`field_distance` integrates the difference of two fields over the common part of the first
one's cells and the second's pieces, every point located in the second's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import CvxdualError
from ..geometry.locate import common_part, locate
from ..kinds import Space
from ..records import ErrorNorms, FieldDistance
from ..voigt import VOIGT_WEIGHT, compliances


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class StressField:
    """A stress field on the pieces of ``mesh``: ``stress`` holds its values (the layout is the
    subclass's), ``bound`` a certified relative energy bound where known, ``balance`` the
    ``(load_imbalance, load_correction)`` of the loads it equilibrates, where it came from a solve."""

    space_name: ClassVar[Space]
    scene: object
    mesh: object
    pieces: object
    stress: np.ndarray
    bound: float | None = None
    balance: tuple[float, float] | None = None

    @property
    def column(self) -> np.ndarray | None:
        """The column stresses ``g`` at both ends of every column ``(n_col, 2)``; None where the
        field has none."""
        return None

    @property
    def support(self):
        """What the field is defined on (the type drawing dispatches on)."""
        return self.pieces

    @property
    def n_pieces(self) -> int:
        """Its cells as a user counts pieces."""
        raise NotImplementedError

    @property
    def n_unknowns(self) -> int:
        raise NotImplementedError

    def piece_kinds(self) -> dict:
        raise NotImplementedError

    def at(self, pts: np.ndarray, body: np.ndarray, tol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Voigt stresses ``(m, 3)`` at points ``pts`` of the bodies ``body``, and the cell each lies
        in (:meth:`cells`); a point on a cell boundary takes one side. Points outside every piece
        are refused."""
        loc = locate(self.mesh, self.pieces, pts, body, tol)
        if np.any(loc < 0):
            raise CvxdualError(f"{int(np.sum(loc < 0))} points lie outside the pieces of the field: the fields are "
                               "not of the same scene")
        return self.in_pieces(pts, loc)

    def in_pieces(self, pts: np.ndarray, loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`at` for points whose pieces ``loc`` are known (:func:`~cvxdual.geometry.locate.locate`)."""
        raise NotImplementedError

    def cells(self) -> np.ndarray:
        """Every cell of the field, numbered as :meth:`at` returns them (pieces, sub-triangles;
        ``-1 - slab`` on the curved pieces)."""
        raise NotImplementedError

    def rule(self, n: int, cells: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """A quadrature of the field: points, weights, body, values ``(m, 3)`` and cell (as
        :meth:`at`), ``n*n`` Gauss points per cell; on the ``cells`` of :meth:`cells` only, if given."""
        raise NotImplementedError


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class PieceField(StressField):
    """Constant on every piece, ``stress`` ``(n_pieces, 3)``; with ``slab`` ``(n_slabs, 3)`` the
    curved pieces are constant per slab instead (``C e(v)`` of a displacement of ``V_h``)."""

    space_name: ClassVar[Space] = Space.P0
    slab: np.ndarray | None = None

    @classmethod
    def of_system(cls, system, t: np.ndarray) -> PieceField:
        """The P0 stresses ``t`` ``(n_pieces, 3)`` that equilibrate the loads of ``system``."""
        return cls(system.mesh.scene, system.mesh, system.pieces, t,
                   balance=(system.load_imbalance, system.load_correction))

    @property
    def n_pieces(self) -> int:
        return len(self.pieces.kind)

    @property
    def n_unknowns(self) -> int:
        return 3 * len(self.pieces.kind)

    def piece_kinds(self) -> dict:
        return self.pieces.counts()

    def in_pieces(self, pts, loc):
        out = self.stress[loc]
        curved = np.flatnonzero(self.pieces.kind[loc] > 0) if self.slab is not None else []
        if len(curved):
            slab = slab_of(self.pieces, loc[curved], pts[curved])
            out[curved] = self.slab[slab]
            loc = loc.copy()
            loc[curved] = -1 - slab
        return out, loc

    def cells(self):
        if self.slab is None:
            return np.arange(len(self.pieces))
        return np.concatenate([np.flatnonzero(self.pieces.kind == 0), -1 - np.arange(len(self.slab))])

    def rule(self, n, cells=None):
        straight = slabs = None  # None: all
        if cells is not None:
            cells = np.asarray(cells, int)
            straight, slabs = cells[cells >= 0], -1 - cells[cells < 0]
        if self.slab is None:
            only = None if straight is None else cell_mask(straight, len(self.pieces))
            pts, w, idx = self.pieces.quadrature(n, only=only)
            return pts, w, self.pieces.body[idx].astype(int), self.stress[idx], idx
        only = self.pieces.kind == 0
        if straight is not None:
            only &= cell_mask(straight, len(self.pieces))
        pts, w, idx = self.pieces.quadrature(n, only=only)
        spt, sw, si = self.pieces.slab_quadrature(n, None if slabs is None else cell_mask(slabs, len(self.slab)))
        return (np.concatenate([pts, spt]), np.concatenate([w, sw]),
                np.concatenate([self.pieces.body[idx], self.pieces.slabs.body[si]]).astype(int),
                np.concatenate([self.stress[idx], self.slab[si]]), np.concatenate([idx, -1 - si]))


def cell_mask(idx: np.ndarray, n: int) -> np.ndarray:
    """A boolean mask of length ``n``, true at ``idx``."""
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


def accumulate_norms(d: np.ndarray, r: np.ndarray, w: np.ndarray, A: np.ndarray, acc: np.ndarray) -> None:
    """Add ``sum w d:d``, ``sum w r:r``, ``sum w d.A d``, ``sum w r.A r`` to ``acc`` (one pass each)."""
    acc[0] += w @ np.einsum("mi,mi,i->m", d, d, VOIGT_WEIGHT)
    acc[1] += w @ np.einsum("mi,mi,i->m", r, r, VOIGT_WEIGHT)
    acc[2] += w @ np.einsum("mi,ij,mj->m", d, A, d)
    acc[3] += w @ np.einsum("mi,ij,mj->m", r, A, r)


def error_norms(acc: np.ndarray, n: int) -> ErrorNorms:
    """The norms of :func:`accumulate_norms`'s sums, ``n`` points per direction."""
    l2, ref_l2, en, ref_en = np.sqrt(acc)
    return ErrorNorms(l2=float(l2), l2_rel=float(l2 / ref_l2) if ref_l2 > 0 else float("nan"),
                      energy=float(en), energy_rel=float(en / ref_en) if ref_en > 0 else float("nan"),
                      rule=int(n))  # quadrature points per direction


def piece_distance(a, b, n: int = 2, n_fine: int | None = None) -> FieldDistance:
    """``||lam_a - lam_b||`` (L2 and energy) between two solutions of the same scene on different
    meshes, integrated over the common part of ``a``'s pieces (``n*n`` points each) and ``b``'s,
    every point located in ``b``'s pieces; relative measures are against ``a``. Integrate over
    the finer mesh: both fields are then constant on most of its pieces and the rule is nearly exact.

    Where the meshes are not nested (curved faces move nodes between levels, type 2 moves the
    contact polygon), a piece of ``a`` can straddle pieces of ``b`` and the integrand jumps
    inside it. With ``n_fine``, every piece of ``a`` whose ``n*n`` points fall in more than one
    piece of ``b`` (or partly outside ``b``) is integrated again with ``n_fine*n_fine`` points.

    The polygons standing for an outline body's curves differ between levels: points of ``a``
    outside ``b`` are dropped, and what the integral leaves out of either mesh is reported as
    ``dropped_area`` and ``dropped_share`` (of ``a``'s area); more than those polygons explain
    (:func:`~cvxdual.geometry.locate.common_part`) is refused: the solutions are of different scenes."""
    pa = a.pieces
    pts, w, idx = pa.quadrature(n)
    loc = _locate_in(a, b, pts, idx)
    if n_fine is not None:
        some = np.empty(len(pa), dtype=loc.dtype)
        some[idx] = loc  # one of each piece's hosts (-1: outside b); a piece straddles if any point differs
        straddle = np.zeros(len(pa), bool)
        straddle[idx[loc != some[idx]]] = True
        keep = ~straddle[idx]
        fp, fw, fi = pa.quadrature(n_fine, only=straddle)
        pts, w, idx = np.concatenate([pts[keep], fp]), np.concatenate([w[keep], fw]), np.concatenate([idx[keep], fi])
        loc = np.concatenate([loc[keep], _locate_in(a, b, fp, fi)])
    out = loc < 0
    dropped = float(w[out].sum())
    if out.any():
        w, idx, loc = w[~out], idx[~out], loc[~out]
    body = pa.body[idx]
    acc = np.zeros(4)
    for k, bd in enumerate(a.scene.bodies):
        m = np.flatnonzero(body == k)
        if len(m):
            ta = a.stress[idx[m]]
            accumulate_norms(ta - b.stress[loc[m]], ta, w[m], bd.material.compliance, acc)
    return FieldDistance(**error_norms(acc, n),
                         **common_part(a.mesh, b.mesh, dropped, float(pa.area.sum()), float(b.pieces.area.sum())))


def _locate_in(a, b, pts: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Pieces of ``b`` holding the points ``pts`` of ``a``'s pieces ``idx`` (-1: outside ``b``)."""
    # Gauss points are interior; the tolerance only absorbs rounding where a's and b's faces
    # are the same curve evaluated at different points
    return locate(b.mesh, b.pieces, pts, a.pieces.body[idx], 1e-10 * a.scene.length_scale)


CHUNK_POINTS = 2_000_000  # quadrature points per pass of field_distance: ~1 GB of temporaries
OUTSIDE = np.iinfo(np.int64).min  # the cell of a point outside every piece (cells are pieces, or -1 - slab)


def field_distance(a: StressField, b: StressField, n: int = 3, n_fine: int | None = 8) -> FieldDistance:
    """``||sigma_a - sigma_b||`` (L2 and energy) integrated over the common part of ``a``'s cells
    (``n*n`` points each) and ``b``'s pieces, every point evaluated in ``b``; relative measures are
    against ``a`` (integrate over the finer field). A cell of ``a`` whose points fall in several
    cells of ``b``, or partly outside ``b`` (the meshes are not nested: the integrand jumps inside
    it), is integrated again with ``n_fine*n_fine`` points. Points outside ``b`` (the polygons
    standing for an outline body's curves differ between levels) are dropped: ``dropped_area``
    and ``dropped_share`` say what the integral leaves out of either mesh, and more than those
    polygons explain is refused (:func:`~cvxdual.geometry.locate.common_part`). The cells are
    taken in chunks of about :data:`CHUNK_POINTS` points (a level-6 reference has millions).
    Between two fields constant on their pieces it is :func:`piece_distance` (the P0 studies' own
    measure since they began: their tables stay comparable)."""
    if all(type(f) is PieceField and f.slab is None for f in (a, b)):
        return piece_distance(a, b, n, n_fine)
    tol = 1e-10 * a.scene.length_scale  # Gauss points are interior; rounding where the faces coincide
    A_body = compliances(a.scene)
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
    return FieldDistance(l2=float(l2), l2_rel=float(l2 / ref) if ref > 0 else float("nan"), energy=float(en),
                         energy_rel=float(en / ref_en) if ref_en > 0 else float("nan"),
                         **common_part(a.mesh, b.mesh, dropped, float(a.pieces.area.sum()), float(b.pieces.area.sum())))


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
