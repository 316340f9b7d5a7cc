"""One outline body's gmsh geometry while it is built: :class:`OutlineBuild` holds the gmsh
handle, the strip's chain and the size fields, and every point, line and loop added so far with
what the later steps need of them (their polylines, the nodes refinement puts on them, the free
arcs' pieces beyond the mesh, gmsh's arcs); its methods add points and curves to the model.
Points are shared by coordinates (shared ends are one point) and keep the smallest size any
curve asks of them. At level ``L >= 1`` (``step`` 2) gmsh gets every other vertex of each fixed
polygon (the chain's, a free arc's, a spline's) as two-node lines at the sizes of level ``L - 1``
and refinement places the rest (:mod:`~cvxdual.geometry.outline.readback`)."""

from __future__ import annotations

import math

import numpy as np

from .sizes import STRIP_ASPECT, SizeField, arc_size, graded_stops, spot_edges, strip_depth

SPLINE_SAMPLES = 256  # points a stretch of a spline is sampled at before thinning to the sizes


def held_parts(body) -> set[str]:
    """The outline parts a support or a nonzero load acts on (the rest is traction free)."""
    return {bp.on for bp in body.boundary
            if bp.kind != "traction" or bp.traction.kind != "uniform" or any(bp.traction.value)}


class OutlineBuild:
    """The gmsh model of ``body`` beyond the strip's inner chain ``(columns, inner_y)`` at
    ``level``, as it is built. ``halved``: gmsh meshes at the sizes of ``level - 1`` through every
    other chain node (``step`` 2, ``glevel`` the level gmsh's sizes are of), to be refined once.
    ``spots`` and ``cut_columns``: an adaptive grid's sizes asked beyond the strip, and the columns
    of the level it started from, where the cuts into surfaces are tried
    (:func:`~cvxdual.geometry.outline.cuts.find_cuts`)."""

    def __init__(self, gmsh, body, columns, inner_y, level: int, halved: bool = True, spots=None, cut_columns=None):
        self.gmsh, self.geo = gmsh, gmsh.model.geo
        gmsh.model.add(body.name)
        self.body, self.columns, self.inner_y, self.level = body, columns, inner_y, level
        self.nc = len(columns)
        self.face_y = body.face.value(columns)
        self.chain = np.stack([columns, inner_y], 1)
        # halved through every other chain node needs both ends among them: an odd node count (every
        # uniform level from 1 has one; an adaptive grid's may not, and is meshed at its own sizes)
        halved = halved and (len(columns) - 1) % 2 == 0 and spots is None
        self.spots = spots  # an adaptive run's sizes (x, y, size), or None
        self.cut_columns = cut_columns
        self.step, self.glevel = (2, level - 1) if level >= 1 and halved else (1, level)
        cols = columns[::self.step]
        self.w = strip_depth(cols) / STRIP_ASPECT  # the chain points' sizes
        self.side = strip_depth(columns)  # the strip's sides are kept whole: their ends get their length as size
        self.field = SizeField.of(body, cols, inner_y[::self.step], self.glevel, spots)
        self.fine = SizeField.of(body, columns, inner_y, level) if self.step > 1 else self.field
        self.ends = {"right": (body.x_range[1], float(self.face_y[-1])),
                     "left": (body.x_range[0], float(self.face_y[0]))}
        self.loaded = held_parts(body)
        self.points: dict[tuple, int] = {}  # geometry points by coordinates: shared ends are one point
        self.where: dict[int, tuple] = {}  # and their coordinates by tag
        self.sizes: dict[int, float] = {}  # the smallest size any curve asks of a point
        self.fixed: list[int] = []  # two-node lines: the strip's edges, the free arcs' polygons, splines
        self.shape: dict[int, tuple] = {}  # every curve's polyline (a line's two ends) and whether a cut may split it
        self.mids: dict[int, tuple] = {}  # a two-node line's node added on refinement (the fine polygon's); None: whole
        # the free arcs' pieces (free_arc), each with its arc (cx, cy, r): the exact region for a quadrature
        self.virtual = {"corner": [], "segment": [], "segment_area": [], "corner_arc": [], "segment_arc": []}
        self.arc_of: dict[int, tuple] = {}  # gmsh's arcs (loaded or supported): centre and radius
        self.chain_pts: list[int] = []  # the points of the chain gmsh gets, left to right
        self.loop: list[int] = []  # signed curve tags of the outer loop, from the right end of the chain
        self.n_path = 0  # the outer loop's curves before the chain's
        self.holes: list[list[int]] = []  # each hole's curves
        self.part_curves: dict[str, list] = {}  # every part's curves (("strip", i): the strip's side at column i)

    def size(self, p) -> float:
        return float(self.field.at(np.array([p], float))[0])

    def point(self, p, lc=None) -> int:
        key = (float(p[0]), float(p[1]))
        lc = self.size(key) if lc is None else lc
        if key not in self.points:
            self.points[key] = self.geo.addPoint(key[0], key[1], 0.0, lc)
            self.where[self.points[key]] = key
        tag = self.points[key]
        self.sizes[tag] = min(lc, self.sizes.get(tag, math.inf))
        return tag

    def line(self, a, b, keep=False, mid=False) -> int:
        """A line from point ``a`` to ``b``; ``keep``: a two-node line; ``mid`` as in ``mids``
        (False: halved at its midpoint on refinement)."""
        c = self.geo.addLine(a, b)
        self.shape[c] = (np.array([self.where[a], self.where[b]]), not keep)
        if keep:
            self.fixed.append(c)
        if mid is not False:
            self.mids[c] = mid
        return c

    def polyline(self, pts, lc=None) -> list[int]:
        """Two-node lines through the fine polygon ``pts``: every other vertex for gmsh, the rest
        placed on refinement (the last line is halved at its midpoint if the count is odd)."""
        step = self.step
        ids = [self.point(q, lc) for q in pts[::step]]
        if step > 1 and (len(pts) - 1) % 2:
            ids.append(self.point(pts[-1], lc))
        odd = [tuple(q) for q in pts[1:-1:2]] if step > 1 else []
        return [self.line(ids[j], ids[j + 1], keep=True, mid=odd[j] if j < len(odd) and step > 1 else False)
                for j in range(len(ids) - 1)]

    def curve(self, name, s, concave) -> list[int]:
        """The curves of segment ``s`` of part ``name`` (``concave``: the body lies outside its arc)."""
        if s.is_spline:
            return self.spline(s)
        if not s.is_arc:
            return [self.line(self.point(s.start), self.point(s.end))]
        if name in self.loaded:
            return [self.held_arc(s)]
        return self.free_arc(s, concave)

    def free_arc(self, s, concave) -> list[int]:
        """A traction-free arc as a polygon inside the body (section 9 of docs/theory.md): chords of
        a convex arc, or, round a concave one (a hole), the tangents at the chords' ends. The pieces of
        the body beyond it (segments, or the tangent polygon's corners) carry zero stress; the
        displacement continues there as a P1 function, recorded in ``self.virtual`` for the energy
        bound: the adjacent triangle's polynomial on a segment (``"segment"``: the chord's ends, and
        ``"segment_area"``), or the interpolant on the triangle of a corner (``"corner"``); each with its
        arc's centre and radius (``"segment_arc"``, ``"corner_arc"``), which bound the piece. The polygon
        is the one of ``self.level``; meshed at the level below (``self.step`` 2), gmsh gets every
        other vertex of it and refinement places the rest."""
        step, virtual = self.step, self.virtual
        a0, sweep = s.angles()
        r = math.dist(s.start, s.center)
        n = spot_edges(s, self.level, self.spots)
        d = sweep / n
        t = a0 + d * np.arange(n + 1)
        c = np.array(s.center)
        on = [tuple(c + r * np.array([math.cos(q), math.sin(q)])) for q in t]
        on[0], on[-1] = s.start, s.end  # the ends exactly as given: shared with the neighbours
        # a hole's chords are already the fine polygon's (refinement adds their corners): their length as
        # size; twice that left slivers by the hole on block-with-hole (quality 0.07, bounds lost)
        lc = (1 if concave else step) * r * abs(d)
        if not concave:
            seg_area = 0.5 * r * r * (abs(d) - math.sin(abs(d)))
            for j in range(n):
                virtual["segment"].append((on[j], on[j + 1]))
                virtual["segment_area"].append(seg_area)
                virtual["segment_arc"].append((c[0], c[1], r))
            return self.polyline(np.array(on), lc)
        rv = r / math.cos(0.5 * d)
        corners = [tuple(c + rv * np.array([math.cos(q + 0.5 * d), math.sin(q + 0.5 * d)])) for q in t[:-1]]
        virtual["corner"] += [(on[j], corners[j], on[j + 1]) for j in range(n)]
        virtual["corner_arc"] += [(c[0], c[1], r)] * n
        ids = [self.point(q, lc) for q in on]
        if step > 1:  # gmsh meshes the chords; refinement puts the corners on them
            return [self.line(ids[j], ids[j + 1], keep=True, mid=corners[j]) for j in range(n)]
        curves = []
        for j in range(n):
            v = self.point(corners[j], lc)
            curves += [self.line(ids[j], v, keep=True), self.line(v, ids[j + 1], keep=True)]
        return curves

    def gmsh_arc(self, s) -> int:
        """gmsh's circle arc through segment ``s``, its ends at most the arc's size of gmsh's level."""
        lc = arc_size(s, self.glevel)
        a = self.point(s.start, min(self.size(s.start), lc))
        b = self.point(s.end, min(self.size(s.end), lc))
        c = self.point(s.center, lc)
        return self.geo.addCircleArc(a, c, b)

    def spline(self, s) -> list[int]:
        """A polygon through points of the spline, as fine as the sizes there."""
        pts = s.sample(SPLINE_SAMPLES)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        n = max(1, math.ceil(arc[-1] / float(self.fine.at(pts).min())))  # equal stretches no longer than the size
        keep = np.unique(np.searchsorted(arc, arc[-1] * np.arange(1, n) / n))
        pts = np.concatenate([pts[:1], pts[keep[(keep > 0) & (keep < len(pts) - 1)]], pts[-1:]])
        if self.step == 1:
            ids = [self.point(q) for q in pts]
            return [self.line(ids[j], ids[j + 1]) for j in range(len(ids) - 1)]
        return self.polyline(pts)

    def held_arc(self, s) -> int:
        """A supported or loaded arc: gmsh's polygon of it (not certified)."""
        c = self.gmsh_arc(s)
        self.shape[c] = (s.sample(64), False)
        self.arc_of[c] = (np.asarray(s.center, float), math.dist(s.start, s.center))
        return c

    def straight(self, a, b) -> list[int]:
        """A line cut through the body from point ``a`` to ``b``, with its size stops (graded_stops)."""
        stops, lc = graded_stops(self.where[a], self.where[b], self.field)
        ids = [a, *(self.point(q, float(s)) for q, s in zip(stops, lc, strict=True)), b]
        return [self.line(ids[j], ids[j + 1]) for j in range(len(ids) - 1)]

    def ring(self, curves) -> np.ndarray:
        """The closed polyline of signed curve tags ``curves``."""
        return np.concatenate([self.shape[abs(t)][0][::1 if t > 0 else -1] for t in curves])

    def at_level(self, c) -> np.ndarray:
        """Curve ``c``'s polyline at this level: with the node refinement puts on it."""
        p = self.shape[c][0]
        return p if self.mids.get(c) is None else np.array([p[0], self.mids[c], p[-1]])
