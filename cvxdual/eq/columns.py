"""The faces of the equilibrium space: every face interval's edge into the straight mesh, and the
column stresses of the curved pieces (docs/equilibrium.md, section 11).

A *face interval* of a body lies between two consecutive columns of its face. Its *face edge*
is the straight edge that separates it from the Johnson-Mercier mesh: the face edge itself on a
flat stretch, the chord of a convex segment, the tangent-polygon edge of type 2, or the slanted
side ``A C`` of a type-1 concave triangle (whose vertical side ``B C`` then bounds a
traction-free piece: a vertical cut through a column field carries nothing). Where the
interval holds curved pieces (a *column interval*), the stress there is the column field
``sigma = g(x) e_y (x) e_y`` with ``g`` linear on the interval: divergence-free, its traction
on any curve is ``(0, g n_y)``, vertical, and on the arc it is exactly the paper's vertical
contact traction ``g dx``. Its values at the interval's ends are two parameters; the face edge's
Johnson-Mercier traction is tied to them, ``sigma n = (0, g n_y)``.

The energy of a column is ``1/2 A_22 int g(x)^2 h(x) dx`` with ``h`` the pieces' vertical extent
at ``x`` (arc minus chord or polygon: not a polynomial on circles and cosines), integrated by
:data:`N_GAUSS` Gauss points per slab.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..geometry.mesh import Mesh
from ..geometry.pieces import Pieces, slab_bound
from ..geometry.quadrature import gauss01
from ..system.field import slab_of
from ..voigt import compliances

# Gauss points per slab: h is smooth on a slab (the arc minus a line), so 10 points integrate
# g^2 h to rounding (checked against 20 points on the built-in scenes: relative changes ~1e-16)
N_GAUSS = 10
CONCAVE1 = 2  # pieces.kind of a type-1 concave triangle (cvxdual.geometry.pieces.PIECE_KINDS)


@dataclass(frozen=True)
class FaceIntervals:
    """Every face interval of both bodies, in body order, then by ``x``. ``left``, ``right``:
    the end nodes of the interval's face edge (``right`` is ``C`` above the column's face node
    for a type-1 concave triangle); ``column``: the interval holds curved pieces; ``vertical``
    ``(m,)``: the bottom node of the vertical side ``B C`` of a type-1 concave triangle (-1 if
    none)."""

    body: np.ndarray
    x: np.ndarray  # (m, 2) the interval's ends
    left: np.ndarray
    right: np.ndarray
    column: np.ndarray
    vertical: np.ndarray

    def __len__(self) -> int:
        return len(self.body)


def face_intervals(mesh: Mesh, pieces: Pieces) -> FaceIntervals:
    """The face intervals of ``mesh`` with the curved pieces of ``pieces`` (either triangulation)."""
    out = {k: [] for k in ("body", "x", "left", "right", "column", "vertical")}
    s = pieces.slabs
    for k, bm in enumerate(mesh.bodies):
        c = bm.columns
        i = np.arange(len(c) - 1)
        sel = s.body == k
        mid = 0.5 * (s.xl[sel] + s.xr[sel])
        cols = np.zeros(len(i), bool)
        cols[np.searchsorted(c, mid) - 1] = True
        concave1 = np.zeros(len(i), bool)
        kinds = pieces.kind[s.piece[sel]]
        concave1[np.searchsorted(c, mid[kinds == CONCAVE1]) - 1] = True
        right = np.where(concave1, bm.node(i + 1, 1), bm.node(i + 1, 0))
        out["body"].append(np.full(len(i), k))
        out["x"].append(np.stack([c[:-1], c[1:]], 1))
        out["left"].append(bm.node(i, 0))
        out["right"].append(right)
        out["column"].append(cols)
        out["vertical"].append(np.where(concave1, bm.node(i + 1, 0), -1))
    return FaceIntervals(**{k: np.concatenate(v) for k, v in out.items()})


def slab_interval(mesh: Mesh, pieces: Pieces, faces: FaceIntervals) -> np.ndarray:
    """The face interval (an index into ``faces``) of every slab of ``pieces``."""
    s = pieces.slabs
    start = np.cumsum([0] + [len(bm.columns) - 1 for bm in mesh.bodies])
    out = np.empty(len(s), int)
    for k, bm in enumerate(mesh.bodies):
        sel = s.body == k
        out[sel] = start[k] + np.searchsorted(bm.columns, 0.5 * (s.xl[sel] + s.xr[sel])) - 1
    return out


def slab_abscissae(pieces: Pieces) -> np.ndarray:
    """``(n_slabs, N_GAUSS)``: the Gauss abscissae of every slab, where :func:`slab_points` weighs."""
    u, _ = gauss01(N_GAUSS)
    s = pieces.slabs
    return s.xl[:, None] + u[None, :] * (s.xr - s.xl)[:, None]


def slab_points(pieces: Pieces, faces: FaceIntervals, slab_iv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gauss abscissae on every slab and what a column integral needs there: ``wh (m, N)``, the
    weight times the slab's height ``h(x)`` (so ``int_S f(x) dx dy = sum wh f``), and ``phi (m, N,
    2)``, the end hats of the slab's face interval (``g(x) = phi @ g_ends``)."""
    s = pieces.slabs
    _, w = gauss01(N_GAUSS)
    x = slab_abscissae(pieces)
    idx = np.repeat(np.arange(len(s)), N_GAUSS)
    h = (slab_bound(s, pieces.faces, x.ravel(), idx, "hi") - slab_bound(s, pieces.faces, x.ravel(), idx, "lo"))
    wh = (w[None, :] * (s.xr - s.xl)[:, None]) * h.reshape(x.shape)
    x0, x1 = faces.x[slab_iv, :1], faces.x[slab_iv, 1:]
    t = (x - x0) / (x1 - x0)
    return wh, np.stack([1 - t, t], -1)


def column_energy(pieces: Pieces, faces: FaceIntervals, slab_iv: np.ndarray, compliance: np.ndarray) -> np.ndarray:
    """``(m, 2, 2)``: ``Q`` with ``1/2 g.Q g = 1/2 int A_22 g^2 h dx`` over each face interval, ``g``
    its end values (zero on intervals without curved pieces); ``compliance`` ``(2, 3, 3)`` per body."""
    wh, phi = slab_points(pieces, faces, slab_iv)
    blocks = np.einsum("sq,sqa,sqb->sab", wh, phi, phi) * compliance[faces.body[slab_iv], 1, 1][:, None, None]
    Q = np.zeros((len(faces), 2, 2))
    np.add.at(Q, slab_iv, blocks)
    return Q


def check_column_data(scene, faces: FaceIntervals) -> None:
    """Refuse what the column field cannot carry: a body force on a body with curved pieces (a
    column field is divergence-free)."""
    for k, body in enumerate(scene.bodies):
        if faces.column[faces.body == k].any() and np.any(np.asarray(body.body_force) != 0):
            raise SceneError(f"body {body.name!r}: the equilibrium stress space takes no body force on a body with a "
                             "curved face (its column stresses are divergence-free); drop the body force or use the "
                             "P0 stress space")


def column_gap(space, g: np.ndarray, ce: np.ndarray) -> np.ndarray:
    """``1/2 int_S (sigma - c):A(sigma - c)`` on every slab ``S`` ``(n_slabs,)``, ``sigma = g(x) e_y (x) e_y``
    the column field (``g`` ``(n_col, 2)``: :meth:`~cvxdual.eq.space.EquilibriumSpace.column_values`)
    and ``c`` ``(n_slabs, 3)`` a constant Voigt stress per slab (``C e(v)`` of the slab's strain), or
    ``(n_slabs, N_GAUSS, 3)`` its values at the slab's Gauss abscissae (:func:`slab_abscissae`)."""
    pieces, slab_col = space.pieces, space.slab_column
    wh, phi = slab_points(pieces, space.faces, space.columns[slab_col])
    gx = np.einsum("sqa,sa->sq", phi, g[slab_col])
    d = np.broadcast_to(-(ce[:, None, :] if ce.ndim == 2 else ce), gx.shape + (3,)).copy()
    d[..., 1] += gx
    A = compliances(space.scene)[pieces.slabs.body]
    return 0.5 * np.einsum("sq,sqi,sij,sqj->s", wh, d, A, d)


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
