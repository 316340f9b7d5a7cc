"""Adaptive grids: the meshes of a run to a certified tolerance (docs/adaptive.md).

A :class:`Grid` is what a level is for a uniform run, made local, for scenes whose bodies are
outline bodies (a run to a tolerance gives a column body as its outline body,
:mod:`cvxdual.adapt.outline_view`): the global columns, on which both bodies' strips stand, and
per body the *spots*, sizes asked at points beyond the strip, which gmsh meshes with the spots
among the sources of its size field (:class:`~cvxdual.geometry.outline.sizes.SizeField`; a free
arc's polygon gets edges no longer than the sizes asked on it), and every other cycle the last mesh
to refine in place instead (:class:`InPlace`). Halving a column interval
splits the face in *both* bodies at the same ``x``, so contact pairs stay on common vertical lines
and the curved pieces follow their chords by the type 1 / type 2 rules, exactly as on a uniform
level: :func:`~cvxdual.geometry.triangulation.discretize` builds a grid's mesh with the same code
and the same checks (strip, pairs, areas, orientation, the region against the outline).

Neighbouring column intervals differ by at most a factor :data:`BALANCE` (the strip's depth is the
mean of the adjacent spacings: a sudden change would make flat cells); a refinement that breaks it
also halves the wider neighbour, until none does.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import MeshError
from ..scene.scene import Scene
from .outline.sizes import NEAREST, SizeField, growth

BALANCE = 2.0  # neighbouring column widths differ by at most this factor: a graded strip
CLOSURE_PASSES = 64  # each pass only splits; a marking closes in a few (the grading spreads one step a pass)
MIN_WIDTH = 1e-7  # relative to the scene's width: narrower intervals are not split (rounding would pair them)


@dataclass(frozen=True, eq=False)
class InPlace:
    """The last cycle's body meshes (:class:`~cvxdual.geometry.mesh.BodyMesh`), per body the
    triangles of its gmsh part and the pieces beyond its free arcs to halve (bool) and the spots it
    was meshed for: the next mesh refines them in place instead of meshing the body with gmsh again
    (:func:`~cvxdual.geometry.outline.in_place.refine_in_place`)."""

    bodies: tuple
    marked: tuple
    arcs: tuple
    spots: tuple


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class Grid:
    """An adaptive mesh plan: ``level`` (the uniform level it started from: the arcs' polygons and
    how fast gmsh's sizes grow, :attr:`growth`), the global ``columns`` (before type 2's
    tangent polygons), ``spots`` per body (sizes asked beyond the strip, ``(m, 3)``: ``x, y,
    size``), ``base``: the columns of that level, where gmsh's surfaces are cut as on its mesh
    (refinement crowds the columns where ``G`` lives; cuts crowded there leave slivers between
    them far from the face), and ``start``: the contact set ``(pair_x, active)`` of the last
    cycle, the fast paths' warm start. ``in_place``: the last mesh to refine in place where it can
    be (the spots are kept all the same: the next gmsh mesh asks for them)."""

    level: int
    columns: np.ndarray
    spots: tuple
    base: np.ndarray
    start: tuple | None = None
    in_place: InPlace | None = None

    @classmethod
    def uniform(cls, scene: Scene, level: int, columns: np.ndarray) -> Grid:
        """The grid of the uniform ``level`` with its global ``columns``
        (:func:`~cvxdual.geometry.triangulation.uniform_grid`): its mesh is the level's, node for node."""
        if any(b.is_column for b in scene.bodies):
            raise MeshError("internal: an adaptive grid meshes outline bodies only (adapt.outline_view)")
        columns = np.asarray(columns, float)
        return cls(int(level), columns, tuple(np.zeros((0, 3)) for _ in scene.bodies), columns)

    @property
    def growth(self) -> float:
        return growth(self.level)

    def with_start(self, pair_x: np.ndarray, active: np.ndarray) -> Grid:
        return replace(self, start=(np.asarray(pair_x, float), np.asarray(active)))

    def same_mesh(self, other: Grid) -> bool:
        """Whether this grid asks for the mesh of ``other`` (the same columns and spots, nothing to halve in place)."""
        halves = self.in_place is not None and any(m.any() for m in (*self.in_place.marked, *self.in_place.arcs))
        return not halves and np.array_equal(self.columns, other.columns) and all(
            np.array_equal(a, b) for a, b in zip(self.spots, other.spots, strict=True))

    def refined(self, scene: Scene, columns: np.ndarray, spots: tuple, in_place: InPlace | None = None) -> Grid:
        """The grid with the column intervals ``columns`` (bool, one per interval of
        :attr:`columns`) halved, closed by :data:`BALANCE`, and the ``spots[k]`` ``(m, 3)`` added to
        body ``k``'s, each at most half the size the old spots ask there (gmsh may have made
        triangles larger than asked), keeping the spots no smaller spot's field already covers;
        ``in_place`` as in :class:`Grid`."""
        x0, x1 = scene.x_extent
        floor = MIN_WIDTH * (x1 - x0)
        cols = _split(self.columns, np.asarray(columns, bool), floor)
        for _ in range(CLOSURE_PASSES):
            wide = _unbalanced(cols, floor)
            if not wide.any():
                break
            cols = _split(cols, wide, floor)
        else:  # pragma: no cover - each pass halves a ratio above BALANCE
            raise MeshError("internal: the refinement's closure did not settle")
        new = tuple(s if not len(n) else _covered(np.concatenate([s, _halved(s, np.asarray(n, float), self.growth)]),
                                                  self.growth)
                    for s, n in zip(self.spots, spots, strict=True))
        return replace(self, columns=cols, spots=new, in_place=in_place)


def _halved(spots: np.ndarray, new: np.ndarray, rate: float) -> np.ndarray:
    """The ``new`` spots, each at most half the size the old ``spots`` ask at its place."""
    if not len(spots):
        return new
    asked = SizeField(spots[:, :2], spots[:, 2], np.inf, rate).at(new[:, :2])
    return np.concatenate([new[:, :2], np.minimum(new[:, 2], 0.5 * asked)[:, None]], 1)


def _covered(spots: np.ndarray, rate: float) -> np.ndarray:
    """The spots whose size no smaller spot's field (size + ``rate`` * distance, among the
    :data:`~cvxdual.geometry.outline.sizes.NEAREST` nearest) already asks for."""
    from scipy.spatial import cKDTree

    spots = spots[np.lexsort((spots[:, 1], spots[:, 0], spots[:, 2]))]  # smallest first, ties by place
    k = min(NEAREST + 1, len(spots))
    d, j = cKDTree(spots[:, :2]).query(spots[:, :2], k=k)
    d, j = d.reshape(len(spots), k), j.reshape(len(spots), k)
    s = spots[j, 2]
    asks = s + rate * np.maximum(d - s, 0.0)
    earlier = j < np.arange(len(spots))[:, None]  # smaller, or as small and first
    return spots[~np.any(earlier & (asks <= spots[:, 2:3]), axis=1)]


def _split(points: np.ndarray, marked: np.ndarray, floor: float) -> np.ndarray:
    """``points`` with the midpoint of every marked interval wider than ``2 * floor`` added."""
    m = marked & (np.diff(points) > 2 * floor)
    return np.sort(np.concatenate([points, 0.5 * (points[:-1] + points[1:])[m]]))


def _unbalanced(points: np.ndarray, floor: float) -> np.ndarray:
    """The intervals more than :data:`BALANCE` times wider than a neighbour (to be halved)."""
    w = np.diff(points)
    out = np.zeros(len(w), bool)
    out[:-1] |= w[:-1] > BALANCE * w[1:]
    out[1:] |= w[1:] > BALANCE * w[:-1]
    return out & (w > 2 * floor)
