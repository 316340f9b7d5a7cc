"""Dorfler marking of the certificate's contributions on an adaptive grid (docs/adaptive.md).

The gap ``G`` is a sum of non-negative parts (:class:`~cvxdual.records.BoundContributions`): one
per macro triangle, per slab of a curved piece, per contact edge and per piece beyond a free arc.
Each is located in the grid by its point: near the face, its column interval (by ``x``); beyond
the strip, a *spot* asking gmsh for half the triangle's size there. Dorfler's rule marks the
largest contributions until they hold a share ``theta`` of ``G``;
:meth:`~cvxdual.geometry.grid.Grid.refined` halves their intervals and adds their spots.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CvxdualError
from ..geometry.grid import Grid
from ..validate import short

THETA = 0.5  # Dorfler's fraction: 0.3-0.6 is the usual range; 0.5 halved G's cycles count against 0.3 here


@dataclass(frozen=True, eq=False)
class Marks:
    """What to refine: column intervals to halve ``columns`` (bool), per body the ``spots`` ``(m, 3)``
    (``x, y, size`` asked beyond the strip), the marked triangles of its gmsh part (``rest``, bool;
    empty for a body without one) and pieces beyond its free arcs (``arcs``, bool), and the ``share``
    of ``G`` the marked contributions hold."""

    columns: np.ndarray
    spots: tuple
    share: float
    rest: tuple = ()
    arcs: tuple = ()


@dataclass(frozen=True, eq=False)
class Located:
    """Contributions ``weight`` with their ``body``, point ``x``, ``y``, ``face`` (on the face: the
    first layer) and ``size`` (a triangle's longest edge; NaN for the others)."""

    weight: np.ndarray
    body: np.ndarray
    x: np.ndarray
    y: np.ndarray
    face: np.ndarray
    size: np.ndarray


def located(space, contributions) -> Located:
    """Every part of ``G`` with a point: triangles at their centroid, slabs and contact edges at their
    middle on the face (a contact edge's part halved between the two bodies), pieces beyond free arcs
    at their nodes' centroid."""
    mesh = space.mesh
    c = contributions
    slabs = space.pieces.slabs
    n_s = 0 if slabs is None else len(slabs.xl)
    xs = np.zeros(0) if slabs is None else 0.5 * (slabs.xl + slabs.xr)
    bs = np.zeros(0, int) if slabs is None else slabs.body
    xc = space.contact_x.mean(1)
    nodes, _, cbody = mesh.continuation()
    xb = mesh.points[nodes].mean(1) if len(nodes) else np.zeros((0, 2))
    cen = space.X.mean(1)
    n_c = len(xc)
    weight = np.concatenate([c["element"], c["column"], 0.5 * c["contact"], 0.5 * c["contact"],
                             c["continuation"]])
    body = np.concatenate([space.body, bs, np.zeros(n_c, int), np.ones(n_c, int), cbody]).astype(int)
    x = np.concatenate([cen[:, 0], xs, xc, xc, xb[:, 0]])
    y = np.concatenate([cen[:, 1], np.full(n_s + 2 * n_c, np.nan), xb[:, 1]])
    face = np.concatenate([np.zeros(len(cen), bool), np.ones(n_s + 2 * n_c, bool), np.zeros(len(xb), bool)])
    edges = np.linalg.norm(space.X - np.roll(space.X, 1, axis=1), axis=2).max(1)
    vb = mesh.points[nodes] if len(nodes) else np.zeros((0, 3, 2))
    size = np.concatenate([edges, np.full(n_s + 2 * n_c, np.nan),
                           np.linalg.norm(vb - np.roll(vb, 1, axis=1), axis=2).max(1) if len(vb) else np.zeros(0)])
    return Located(np.maximum(weight, 0.0), body, x, y, face, size)


def parse_tolerance(tol) -> float:
    """A relative tolerance from ``0.01``, ``"0.01"`` or ``"1%"``: above 0 and below 1."""
    text = str(tol).strip()
    try:
        value = float(text[:-1]) / 100.0 if text.endswith("%") else float(text)
        ok = not isinstance(tol, bool) and 0.0 < value < 1.0
    except ValueError:
        ok = False
    if not ok:
        raise CvxdualError(f"tol must be a relative error between 0 and 1 such as 0.01 or '1%', got {short(tol)}",
                           cli=f"--tol must be a relative error such as 1% or 0.01, got {short(tol)}")
    return value


def parse_theta(theta) -> float:
    """Dorfler's fraction from ``0.3`` or ``"0.3"``: above 0 and at most 1 (1 marks every part of ``G``)."""
    try:
        value = float(str(theta).strip())
        ok = not isinstance(theta, bool) and 0.0 < value <= 1.0
    except ValueError:
        ok = False
    if not ok:
        raise CvxdualError(f"theta must be Dorfler's fraction of G to mark, above 0 and at most 1 (0.3-0.6 is usual), "
                           f"got {short(theta)}",
                           cli=f"--theta must be Dorfler's fraction of G to mark, above 0 and at most 1 (0.3-0.6 is "
                               f"usual), got {short(theta)}")
    return value


def dorfler(weight: np.ndarray, theta: float) -> np.ndarray:
    """The smallest set of the largest ``weight`` holding at least ``theta`` of their sum (bool)."""
    order = np.argsort(weight)[::-1]
    total = weight.sum()
    out = np.zeros(len(weight), bool)
    if total <= 0:
        return out
    n = int(np.searchsorted(np.cumsum(weight[order]), theta * total)) + 1
    out[order[:n]] = True
    return out


def mark(grid: Grid, space, contributions, theta: float = THETA) -> Marks:
    """The :class:`Marks` of a solution's certificate ``contributions`` on ``grid`` (its mesh's
    ``space``, an :class:`~cvxdual.eq.space.EquilibriumSpace`)."""
    loc = located(space, contributions)
    chosen = dorfler(loc.weight, theta)
    cols = np.zeros(len(grid.columns) - 1, bool)
    spots = []
    for k, b in enumerate(space.scene.bodies):
        sel = chosen & (loc.body == k)
        x, y, face, size = loc.x[sel], loc.y[sel], loc.face[sel], loc.size[sel]
        bm = space.mesh.bodies[k]
        depth = np.abs(np.interp(x, bm.columns, bm.inner - bm.face_y))
        height = np.where(face, 0.0, np.abs(y - b.face.value(x)))
        # within a few strip depths of the face gmsh's sizes are the columns' (its sources): halve those
        near = height <= 4.0 * depth
        cols[np.clip(np.searchsorted(grid.columns, x[near]) - 1, 0, len(cols) - 1)] = True
        # beyond the strip (1.5 depths: its inner chain is a polyline), ask half the triangle's size
        beyond = (height > 1.5 * depth) & (size > 0)  # a spot of size 0 would ask gmsh for no mesh
        spots.append(np.stack([x[beyond], y[beyond], 0.5 * size[beyond]], 1))
    share = float(loc.weight[chosen].sum() / loc.weight.sum()) if loc.weight.sum() > 0 else 0.0
    _, _, cbody = space.mesh.continuation()
    beyond = chosen[len(chosen) - len(cbody):]  # the pieces beyond free arcs come last (located)
    arcs = tuple(beyond[cbody == k] for k in range(len(space.mesh.bodies)))
    return Marks(cols, tuple(spots), share, _rest_marks(space, chosen[:len(space.tri)]), arcs)


def _rest_marks(space, chosen: np.ndarray) -> tuple:
    """Per body, which triangles of its gmsh part the ``chosen`` triangles of ``space`` are (bool)."""
    bodies = space.mesh.bodies
    rests = [np.sort(bm.offset + bm.rest.triangles, axis=1) for bm in bodies if bm.rest is not None]
    picked = np.sort(space.tri[chosen], axis=1)
    # one id per node triple, whatever its corners' order
    _, ids = np.unique(np.concatenate([picked, *rests]).astype(np.int64), axis=0, return_inverse=True)
    ids = ids.ravel()
    hit, at, out = ids[:len(picked)], len(picked), []
    for bm in bodies:
        if bm.rest is None:
            out.append(np.zeros(0, bool))
            continue
        m = len(bm.rest.triangles)
        out.append(np.isin(ids[at:at + m], hit))
        at += m
    return tuple(out)
