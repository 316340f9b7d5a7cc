"""Stress norms and errors (docs/theory.md#errors-norms-and-benchmarks).

``||lam||_0^2 = int lam:lam dx`` (with ``lam:lam = s11^2 + s22^2 + 2 s12^2``) and the energy
norm ``(A lam, lam)^(1/2)``, integrated piece by piece (curved pieces included) with a
tensor Gauss rule of ``n`` points per direction.
"""

from __future__ import annotations

import numpy as np

from ..records import ErrorNorms, FieldDistance
from ..system.assembly import System
from ..voigt import VOIGT_WEIGHT

# points per direction for a solution's error against an exact field: 16 points a piece change
# hertz's relative errors by ~1e-5 relative against an 8x8 rule, at under half a 6x6 rule's time
# (reports/speed.md, "The quadrature rule's own error"); studies choose their own rule
DEFAULT_QUAD = 4
CHUNK_POINTS = 1 << 20  # quadrature points evaluated at once: bounds the temporaries (~15 arrays)


def _accumulate(d: np.ndarray, r: np.ndarray, w: np.ndarray, A: np.ndarray, acc: np.ndarray) -> None:
    """Add ``sum w d:d``, ``sum w r:r``, ``sum w d.A d``, ``sum w r.A r`` to ``acc`` (one pass each)."""
    acc[0] += w @ np.einsum("mi,mi,i->m", d, d, VOIGT_WEIGHT)
    acc[1] += w @ np.einsum("mi,mi,i->m", r, r, VOIGT_WEIGHT)
    acc[2] += w @ np.einsum("mi,ij,mj->m", d, A, d)
    acc[3] += w @ np.einsum("mi,ij,mj->m", r, A, r)


def _result(acc: np.ndarray, n: int) -> ErrorNorms:
    l2, ref_l2, en, ref_en = np.sqrt(acc)
    return ErrorNorms(l2=float(l2), l2_rel=float(l2 / ref_l2) if ref_l2 > 0 else float("nan"),
                      energy=float(en), energy_rel=float(en / ref_en) if ref_en > 0 else float("nan"),
                      rule=int(n))  # quadrature points per direction


def stress_error(system: System, t: np.ndarray, reference, n: int = DEFAULT_QUAD) -> ErrorNorms:
    """Errors (:class:`~cvxdual.records.ErrorNorms`) of piecewise-constant stresses ``t``
    ``(n_pieces, 3)`` against ``reference``, which maps ``(body, points)`` to stresses (an exact
    field's ``stress`` method)."""
    pieces = system.pieces
    n_pieces = len(pieces)
    step = max(1, CHUNK_POINTS // (n * n))
    acc = np.zeros(4)
    for start in range(0, n_pieces, step):  # a few chunks: memory, not speed, sets their number
        only = None
        if step < n_pieces:
            only = np.zeros(n_pieces, bool)
            only[start:start + step] = True
        pts, w, idx = pieces.quadrature(n, only)
        body = pieces.body[idx]
        for k, b in enumerate(system.mesh.scene.bodies):
            m = np.flatnonzero(body == k)
            if len(m):
                r = reference(k, pts[m])
                _accumulate(t[idx[m]] - r, r, w[m], b.material.compliance, acc)
    return _result(acc, n)


def l2_norm(system: System, t: np.ndarray) -> float:
    """``||t||_0`` of piecewise-constant stresses."""
    return float(np.sqrt(np.sum(system.pieces.area * np.sum(VOIGT_WEIGHT * t**2, axis=1))))


def stress_distance(a, b, n: int = 2, n_fine: int | None = None) -> FieldDistance:
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
    from ..geometry.locate import common_part
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
            _accumulate(ta - b.stress[loc[m]], ta, w[m], bd.material.compliance, acc)
    # a dict: the norms and common_part's measures of the meshes' overlap, one row for a study
    return FieldDistance(**_result(acc, n),
                         **common_part(a.mesh, b.mesh, dropped, float(pa.area.sum()), float(b.pieces.area.sum())))


def _locate_in(a, b, pts: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Pieces of ``b`` holding the points ``pts`` of ``a``'s pieces ``idx`` (-1: outside ``b``)."""
    from ..geometry.locate import locate
    # Gauss points are interior; the tolerance only absorbs rounding where a's and b's faces
    # are the same curve evaluated at different points
    return locate(b.mesh, b.pieces, pts, a.pieces.body[idx], 1e-10 * a.scene.length_scale)
