"""Element sizes of an outline body's gmsh part, and the points that make gmsh follow them.
:class:`SizeField` is the size asked at a point: the strip's inner chain (each node's column
spacing) and every arc's vertices are its sources, and the size grows by :data:`GROWTH` times
the distance from them, up to twice the coarsest column spacing; every size halves a level, so
``--level`` halves the mesh everywhere. gmsh, though, only reads sizes at its geometry points and
interpolates them linearly: along a line between its two ends, and inside a surface over a
triangulation of the boundary's points. Round a small hole far from everything else that
interpolation spans the whole surface, and the hole's fine size reaches far out (at level 5 of
``block-with-hole``, sizes grew a quarter as fast as asked and the hole's surfaces held two
thirds of the body's triangles). So the size field is handed to gmsh at a few more points, about
:data:`STEER` sizes apart, where it varies: along the lines cut through the body
(:func:`graded_stops`) and on rings round each arc, embedded in the surfaces
(:func:`steering_points`). Background size fields do this too, but cost gmsh 25-35 us a
triangle against its 6-9 (measured, reports/outlines.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ...scene.planar import inside

GROWTH = 0.4  # at level 0 the size grows by 0.4 times the distance from a source; halved a level
STRIP_ASPECT = 1.0  # strip depth over the local column spacing: square cells
ARC_EDGES = 4  # edges per quarter turn of an arc at level 0 (doubling per level)
NEAREST = 16  # sources compared at each point of the size field
STEER = 3.0  # steering points lie about three element sizes apart (and from the boundary)
OCTAVE = 2.0  # a steering ring or stop each time the size doubles: the field is linear in between


def strip_depth(columns: np.ndarray) -> np.ndarray:
    """Depth of the strip at each column: the mean of the adjacent column spacings."""
    w = np.diff(columns)
    return STRIP_ASPECT * np.concatenate([[w[0]], 0.5 * (w[:-1] + w[1:]), [w[-1]]])


def arc_size(seg, level: int) -> float:
    """Edge length on an arc: ``ARC_EDGES * 2**level`` edges a quarter turn."""
    return math.dist(seg.start, seg.center) * (math.pi / 2) / (ARC_EDGES * 2**level)


def arc_edges(seg, level: int) -> int:
    """Edges of an arc's polygon: ``ARC_EDGES`` a quarter turn at level 0 (at least one), doubled
    a level, so that each level's polygon halves every edge of the last (:mod:`~cvxdual.geometry.refine`)."""
    return max(1, math.ceil(abs(seg.angles()[1]) / (math.pi / 2) * ARC_EDGES - 1e-9)) * 2**level


def growth(level: int) -> float:
    """How fast the size grows with the distance from a source at ``level`` (:data:`GROWTH` halved a level)."""
    return GROWTH / 2**level


def spot_edges(seg, level: int, spots) -> int:
    """Edges of a free arc's polygon: :func:`arc_edges`, or more where an adaptive run's ``spots``
    (``x, y, size``) ask smaller sizes on the arc (equal edges, none longer than the least asked)."""
    n = arc_edges(seg, level)
    if spots is None or not len(spots):
        return n
    q = seg.sample(max(64, n))
    d = np.hypot(q[:, None, 0] - spots[None, :, 0], q[:, None, 1] - spots[None, :, 1])
    s = spots[None, :, 2]
    least = float(np.min(s + growth(level) * np.maximum(d - s, 0.0)))
    length = math.dist(seg.start, seg.center) * abs(seg.angles()[1])
    return max(n, math.ceil(length / least - 1e-9))


@dataclass(frozen=True)
class SizeField:
    """The element size asked at points of an outline body: the smallest of
    ``s + growth * max(0, d - s)`` over the nearby sources (size ``s``, distance ``d``), at most
    ``cap`` (twice the coarsest column spacing); ``growth`` is ``GROWTH / 2**level``. Every term
    halves a level, so a level's sizes are half the last one's everywhere and the meshes refine as
    one graded family, as the column meshes do (a growth that stayed put leaves the graded zone
    unrefined: hertz's fitted rate fell from 0.94 to 0.56 with it, reports/outlines.md)."""

    points: np.ndarray
    sizes: np.ndarray
    cap: float
    growth: float

    @classmethod
    def of(cls, body, columns: np.ndarray, inner_y: np.ndarray, level: int, spots=None) -> SizeField:
        """The field of the strip's chain and the arcs at ``level``, and of the ``spots`` ``(m, 3)``
        (``x, y, size``: an adaptive run's sizes asked where its certificate was large)."""
        w = strip_depth(columns) / STRIP_ASPECT
        src, size = [np.stack([columns, inner_y], 1)], [w]
        if spots is not None and len(spots):
            src.append(spots[:, :2])
            size.append(spots[:, 2])
        for seg in arcs(body):  # a source at every vertex of the arc's polygon
            q = seg.sample(arc_edges(seg, level))
            src.append(q)
            size.append(np.full(len(q), arc_size(seg, level)))
        return cls(np.concatenate(src), np.concatenate(size), 2.0 * float(np.diff(columns).max()), growth(level))

    @cached_property
    def _tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.points)

    def at(self, pts: np.ndarray) -> np.ndarray:
        pts = np.asarray(pts, float).reshape(-1, 2)
        k = min(NEAREST, len(self.points))
        d, i = self._tree.query(pts, k=k)
        d, i = d.reshape(len(pts), k), i.reshape(len(pts), k)
        s = self.sizes[i]
        return np.minimum(self.cap, np.min(s + self.growth * np.maximum(d - s, 0.0), axis=1))


def arcs(body) -> list:
    """Every arc segment of the body's outline and holes."""
    return [s for p in body.outline.parts for s in p.segments if s.is_arc]


def graded_stops(p, q, field: SizeField) -> tuple[np.ndarray, np.ndarray]:
    """Points strictly between ``p`` and ``q`` (and their sizes) where the straight line between
    them should carry a geometry point so that gmsh's linear interpolation follows the size field:
    where the field's size crosses a power of :data:`OCTAVE` times its smallest on the line, at
    least :data:`STEER` sizes from either end."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    length = float(np.hypot(*(q - p)))
    s_end = field.at(np.array([p, q]))
    # samples: uniform, and finer near either end (where a small size starts to grow)
    near = float(s_end.min()) / length * OCTAVE ** np.arange(0.0, 60.0, 0.25)
    near = near[near < 0.5]
    t = np.unique(np.concatenate([np.linspace(0.0, 1.0, 257), near, 1.0 - near]))
    s = field.at(p + t[:, None] * (q - p))
    band = np.floor(np.log(s / s.min()) / math.log(OCTAVE) + 1e-9)
    cross = np.flatnonzero(band[1:] != band[:-1]) + 1
    far = (t[cross] * length >= STEER * s[cross]) & ((1 - t[cross]) * length >= STEER * s[cross])
    cross = cross[far]
    return p + t[cross, None] * (q - p), s[cross]


def steering_points(body, field: SizeField, level: int, spots=None) -> np.ndarray:
    """Candidate points on rings round every arc, on both sides, and round every spot (``x, y,
    size``), where the size has grown by a power of :data:`OCTAVE` (out to the cap), :data:`STEER`
    sizes apart along each ring; the caller keeps those inside a surface and clear of its boundary
    (:func:`clear_of`)."""
    out = [] if spots is None else [spot_points(spots, field)]  # gmsh reads sizes at its points only
    for seg in arcs(body):
        s0 = arc_size(seg, level)
        a0, sweep = seg.angles()
        r = math.dist(seg.start, seg.center)
        c = np.asarray(seg.center, float)
        sizes = s0 * OCTAVE ** np.arange(1, max(1, math.ceil(math.log(field.cap / s0) / math.log(OCTAVE))) + 1)
        for s in np.minimum(sizes, field.cap):
            d = (s - s0) / field.growth
            for rho in (r + d, r - d):
                if rho < STEER * s:
                    continue
                n = max(1, math.ceil(abs(sweep) * rho / (STEER * s)))
                a = a0 + sweep * (np.arange(n) + 0.5) / n
                out.append(c + rho * np.stack([np.cos(a), np.sin(a)], 1))
    return np.concatenate(out) if out else np.zeros((0, 2))


def clear_of(pts: np.ndarray, sizes: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Which points keep their own size times :data:`STEER` from every segment ``(n, 2, 2)`` and
    from the points kept before them (a steering point too close to a line or to another point
    would make gmsh put small triangles there)."""
    keep = np.ones(len(pts), bool)
    for lo in range(0, len(pts), 512):  # point-segment distances in blocks of 512 points
        p = pts[lo:lo + 512, None]
        a, d = segs[None, :, 0], segs[None, :, 1] - segs[None, :, 0]
        t = np.clip(np.sum((p - a) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-300), 0.0, 1.0)
        dist = np.hypot(*np.moveaxis(p - a - t[..., None] * d, -1, 0)).min(axis=1)
        keep[lo:lo + 512] = dist >= STEER * sizes[lo:lo + 512]
    from scipy.spatial import cKDTree

    idx = np.flatnonzero(keep)
    pairs = cKDTree(pts[idx]).query_pairs(float(STEER * sizes[idx].max()) if len(idx) else 0.0, output_type="ndarray")
    if len(pairs):
        i, j = idx[pairs[:, 0]], idx[pairs[:, 1]]
        near = np.hypot(*(pts[i] - pts[j]).T) < 0.5 * STEER * np.minimum(sizes[i], sizes[j])
        for a, b in sorted(zip(np.minimum(i, j)[near], np.maximum(i, j)[near], strict=True)):
            if keep[a]:
                keep[b] = False  # the later of two close points goes
    return keep


def spot_points(spots: np.ndarray, field: SizeField) -> np.ndarray:
    """Every spot ``(x, y, size)`` and points on rings round it where its size has grown by a power of
    :data:`OCTAVE` (out to the cap), :data:`STEER` sizes apart along each ring; spot by spot (the order
    decides which of two close points :func:`clear_of` keeps), all at once."""
    s0 = spots[:, 2]
    k = np.maximum(1, np.ceil(np.log(field.cap / s0) / math.log(OCTAVE))).astype(int)  # rings a spot
    spot = np.repeat(np.arange(len(spots)), k)
    octave = np.arange(len(spot)) - np.repeat(np.cumsum(k) - k, k) + 1
    s = np.minimum(s0[spot] * OCTAVE**octave, field.cap)
    rho = (s - s0[spot]) / field.growth
    n = np.maximum(3, np.ceil(2 * math.pi * rho / (STEER * s))).astype(int)  # points a ring
    ring = np.repeat(np.arange(len(n)), n)
    a = 2 * math.pi * (np.arange(len(ring)) - np.repeat(np.cumsum(n) - n, n) + 0.5) / n[ring]
    pts = np.concatenate([spots[:, :2], spots[spot[ring], :2] + rho[ring, None] * np.stack([np.cos(a), np.sin(a)], 1)])
    owner = np.concatenate([np.arange(len(spots)), spot[ring]])
    return pts[np.argsort(owner, kind="stable")]  # each spot, then its rings


def steering(body, field: SizeField, level: int, rings: list, segs: np.ndarray, spots=None) -> list:
    """The steering points each region ``(outer ring, hole rings)`` holds, clear of every boundary
    segment ``segs`` ``(n, 2, 2)``, and their sizes: ``[(points, sizes), ...]``, region by region."""
    cand = steering_points(body, field, level, spots)
    region = np.full(len(cand), -1)
    for r, (outer, holes) in enumerate(rings):
        mine = inside(outer, cand) if len(cand) else np.zeros(0, bool)
        for h in holes:
            mine &= ~inside(h, cand)
        region[mine & (region < 0)] = r
    cand, region = cand[region >= 0], region[region >= 0]
    size = field.at(cand)
    keep = clear_of(cand, size, segs) if len(cand) else np.zeros(0, bool)
    return [(cand[keep & (region == r)], size[keep & (region == r)]) for r in range(len(rings))]
