"""Body outlines: the boundary of a general plane body, in named parts (docs/scenes.md#outlines).

A column body is bounded by its face, a straight far side and two vertical sides. A body with an
*outline* keeps its contact face ``y = f(x)`` over its ``x`` range (a profile, as before), and the
rest of its boundary is a *path* of named parts from the face's right end back to its left end,
plus optional *holes*. A part is a line segment or a circular arc (less than a half turn, given
by its end and centre); a circular hole is one part of four quarter arcs. Supports and loads name
the parts (``on = "bottom"``).

The paper only asks the contact arcs to be graphs with paired face nodes (its ``Omega'``,
``Omega''`` are any plane regions): the mesh keeps a strip of columns along the face and meshes
the rest with gmsh (:mod:`cvxdual.geometry.outline`).

Validation here is geometric and complete before any meshing: the path must close on the face,
no two segments (face included) may cross, touch or be tangent except consecutive ones at their
shared end, and those must not run back over each other; holes must enclose an area, lie inside
the body and not inside each other; names must be unique.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..validate import number, pair, short, text
from .planar import inside, near_pairs, point_segment_distance, segment_distance, signed_area

ARC_SAMPLES = 64  # points per arc when checking crossings and drawing (a chord error of 1e-4 of the radius)
FACE_SAMPLES = 2001  # points of the face in the crossing checks
PART_KINDS = ("line", "arc", "spline")
MAX_PARTS = 200  # parts and holes of one body (and points of a spline): bounds the checks' and gmsh's work


@dataclass(frozen=True)
class Segment:
    """A line from ``start`` to ``end``; a circular arc from ``start`` to ``end`` about
    ``center`` (the shorter way round: less than a half turn); or a spline from ``start``
    ``through`` points to ``end``: the natural cubic spline of ``x`` and ``y`` in the chord length."""

    start: tuple[float, float]
    end: tuple[float, float]
    center: tuple[float, float] | None = None
    through: tuple[tuple[float, float], ...] | None = None

    @property
    def is_arc(self) -> bool:
        return self.center is not None

    @property
    def is_spline(self) -> bool:
        return self.through is not None

    def sample(self, n: int = ARC_SAMPLES) -> np.ndarray:
        """``(n + 1, 2)`` points from start to end (``2`` points for a line; ``n`` per stretch
        between given points for a spline)."""
        p0, p1 = np.array(self.start), np.array(self.end)
        if self.is_spline:
            return self._spline(n)
        if not self.is_arc:
            return np.stack([p0, p1])
        c = np.array(self.center)
        a0, sweep = self.angles()
        t = a0 + sweep * np.linspace(0.0, 1.0, n + 1)
        r = float(np.linalg.norm(p0 - c))
        pts = c + r * np.stack([np.cos(t), np.sin(t)], 1)
        pts[0], pts[-1] = p0, p1  # the ends exactly as given: they are shared with the neighbours
        return pts

    def angles(self) -> tuple[float, float]:
        """Start angle and signed sweep of an arc (``|sweep| < pi``)."""
        c = np.array(self.center)
        d0, d1 = np.array(self.start) - c, np.array(self.end) - c
        a0 = math.atan2(d0[1], d0[0])
        sweep = math.atan2(d0[0] * d1[1] - d0[1] * d1[0], float(d0 @ d1))
        return a0, sweep

    def reversed(self) -> Segment:
        """The same curve from ``end`` to ``start``."""
        return Segment(self.end, self.start, self.center, None if self.through is None else self.through[::-1])

    def _spline(self, n: int) -> np.ndarray:
        from scipy.interpolate import CubicSpline

        knots = np.array([self.start, *self.through, self.end], float)
        t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))])
        s = np.concatenate([np.linspace(t[k], t[k + 1], n + 1)[:-1] for k in range(len(t) - 1)] + [t[-1:]])
        pts = CubicSpline(t, knots, bc_type="natural")(s)
        pts[0], pts[-1] = knots[0], knots[-1]
        return pts

    @property
    def length(self) -> float:
        p0, p1 = np.array(self.start), np.array(self.end)
        if self.is_spline:
            return float(np.linalg.norm(np.diff(self.sample(), axis=0), axis=1).sum())
        if not self.is_arc:
            return float(np.linalg.norm(p1 - p0))
        return abs(self.angles()[1]) * float(np.linalg.norm(p0 - np.array(self.center)))

    @property
    def axis(self) -> str | None:
        """``"x"`` for a horizontal line, ``"y"`` for a vertical one, else ``None``."""
        if self.is_arc or self.is_spline:
            return None
        dx, dy = abs(self.end[0] - self.start[0]), abs(self.end[1] - self.start[1])
        tol = 1e-12 * (dx + dy)  # a line typed axis-aligned: its two coordinates agree to rounding
        return "x" if dy <= tol else "y" if dx <= tol else None


@dataclass(frozen=True)
class Part:
    """A named stretch of boundary: one segment, or the four quarter arcs of a circular hole."""

    name: str
    segments: tuple[Segment, ...]

    @property
    def is_curved(self) -> bool:
        return any(s.is_arc or s.is_spline for s in self.segments)

    @property
    def has_spline(self) -> bool:
        return any(s.is_spline for s in self.segments)


@dataclass(frozen=True)
class Outline:
    """The boundary of a body beyond its face: ``path`` from the face's right end to its left
    end, and ``holes`` (closed parts). Built by :func:`outline_from_dict` or directly; checked
    against the face by :func:`check_outline` (the body does it)."""

    path: tuple[Part, ...]
    holes: tuple[Part, ...] = ()

    @property
    def parts(self) -> tuple[Part, ...]:
        return self.path + self.holes

    def part(self, name: str) -> Part:
        for p in self.parts:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parts)

    def points(self) -> np.ndarray:
        """Every sampled point of the outline (path and holes), for extents and scales."""
        return np.concatenate([s.sample() for p in self.parts for s in p.segments])

    def scaled(self, length: float) -> Outline:
        def seg(s: Segment) -> Segment:
            def sc(q):
                return None if q is None else (q[0] * length, q[1] * length)
            through = None if s.through is None else tuple(map(sc, s.through))
            return Segment(sc(s.start), sc(s.end), sc(s.center), through)
        return Outline(tuple(Part(p.name, tuple(map(seg, p.segments))) for p in self.path),
                       tuple(Part(p.name, tuple(map(seg, p.segments))) for p in self.holes))


def _point(v, what: str) -> tuple[float, float]:
    return pair(v, what)


def outline_from_dict(path, holes, start: tuple[float, float], where: str) -> Outline:
    """The outline of a scene file: ``path`` a list of ``{name, to}`` (a line to ``to``) or
    ``{name, to, center}`` (an arc), starting at ``start`` (the face's right end); ``holes`` a list
    of ``{name, center, radius}`` (circles) or ``{name, points}`` (closed polygons)."""
    if not isinstance(path, list) or not path:
        raise SceneError(f"{where}.outline must be a non-empty list of parts, e.g. "
                         "[{name = \"bottom\", to = [x, y]}, ...], got " + short(path))
    n_parts = len(path) + (len(holes) if isinstance(holes, list) else 0)
    if n_parts > MAX_PARTS:
        raise SceneError(f"{where}: {n_parts} outline parts and holes, more than {MAX_PARTS}; draw the body with "
                         "fewer, longer parts")
    parts, cur = [], start
    for i, d in enumerate(path):
        w = f"{where}.outline[{i}]"
        if not isinstance(d, dict):
            raise SceneError(f"{w} must be a table {{name, to}} or {{name, to, center}}, got {short(d)}")
        extra = set(d) - {"name", "to", "center", "through"}
        if extra:
            raise SceneError(f"{w}: unknown key {sorted(extra)[0]!r}; a part has name, to and (for an arc) center or "
                             "(for a spline) through")
        if "center" in d and "through" in d:
            raise SceneError(f"{w}: give center (an arc) or through (a spline), not both")
        if "name" not in d or "to" not in d:
            raise SceneError(f"{w}: missing key {'name' if 'name' not in d else 'to'!r}")
        end = _point(d["to"], f"{w}.to")
        center = None if "center" not in d else _point(d["center"], f"{w}.center")
        through = None
        if "through" in d:
            if not isinstance(d["through"], list) or not d["through"] or len(d["through"]) > MAX_PARTS:
                raise SceneError(f"{w}.through must list 1 to {MAX_PARTS} points [[x, y], ...], got "
                                 f"{short(d['through'])}")
            through = tuple(_point(q, f"{w}.through[{j}]") for j, q in enumerate(d["through"]))
            twice = _repeated_knot((cur, *through, end))
            if twice is not None:
                raise SceneError(f"{w}: the spline passes through ({twice[0]:g}, {twice[1]:g}) twice in a row; "
                                 "give each of its points once")
        parts.append(Part(text(d["name"], f"{w}.name"), (Segment(cur, end, center, through),)))
        cur = end
    if holes is None:
        holes = []
    if not isinstance(holes, list):
        raise SceneError(f"{where}.holes must be a list of {{name, center, radius}} or {{name, points}}, "
                         f"got {short(holes)}")
    hs = []
    for i, d in enumerate(holes):
        w = f"{where}.holes[{i}]"
        if not isinstance(d, dict) or "name" not in d:
            raise SceneError(f"{w} must be a table with a name: {{name, center, radius}} or {{name, points}}")
        keys = set(d) - {"name"}
        name = text(d["name"], f"{w}.name")
        if keys == {"center", "radius"}:
            r = number(d["radius"], f"{w}.radius", "positive")
            if r <= 0:
                raise SceneError(f"{w}.radius must be positive, got {r:g}; give the hole's radius")
            hs.append(circle(name, _point(d["center"], f"{w}.center"), r))
        elif keys == {"points"}:
            pts = d["points"]
            if not isinstance(pts, list) or len(pts) < 3:
                raise SceneError(f"{w}.points must list at least 3 corners, got {short(pts)}")
            p = [_point(q, f"{w}.points[{j}]") for j, q in enumerate(pts)]
            if signed_area(np.array(p)) < 0:
                p = p[::-1]  # holes run counter-clockwise (the body on their right)
            hs.append(Part(name, tuple(Segment(p[j], p[(j + 1) % len(p)]) for j in range(len(p)))))
        else:
            raise SceneError(f"{w}: give center and radius (a circle) or points (a polygon), got keys "
                             f"{sorted(keys)}")
    return Outline(tuple(parts), tuple(hs))


def circle(name: str, center, radius: float) -> Part:
    """A circular hole as four quarter arcs, starting at its right-most point."""
    if not radius > 0:  # a negative one would draw the circle of its magnitude
        raise SceneError(f"hole {short(name)}: radius must be positive, got {radius!r}; give the hole's radius")
    cx, cy = center
    q = [(cx + radius, cy), (cx, cy + radius), (cx - radius, cy), (cx, cy - radius)]
    return Part(name, tuple(Segment(q[j], q[(j + 1) % 4], (cx, cy)) for j in range(4)))


def _repeated_knot(knots) -> tuple[float, float] | None:
    """A spline's point that equals the next one (no chord length to run along), or None."""
    k = np.asarray(knots, float)
    same = np.hypot(*np.diff(k, axis=0).T) <= 1e-12 * np.abs(k).max()  # equal to rounding
    return tuple(k[int(np.argmax(same))]) if np.any(same) else None


def _loops(face_pts: np.ndarray, outline: Outline):
    """The closed boundary as sampled polylines: ``(chains, follow)``: every chain is ``(points,
    name)`` (the face, each segment of the path, each of the holes'; ``"face"`` the face's
    name), ``follow`` the pairs of chains where one ends and the next starts along a loop (the
    face, the path and back; round each hole)."""
    chains = [(face_pts, "face")] + [(s.sample(), p.name) for p in outline.parts for s in p.segments]
    n = sum(len(p.segments) for p in outline.path)
    follow = [(i, i + 1) for i in range(n)] + [(n, 0)]
    k = n + 1
    for h in outline.holes:
        m = len(h.segments)
        follow += [(k + j, k + (j + 1) % m) for j in range(m)]
        k += m
    return chains, follow


def check_outline(outline: Outline, face, x_range, position: str, body: str) -> None:
    """Raise :class:`SceneError` (one line) unless the outline closes on the face, encloses a
    region on the body's side of the face, every hole encloses an area inside it (not inside
    another hole), and no two of its segments cross, touch or run back over each other."""
    x0, x1 = x_range
    left, right = (x0, float(face.value(x0))), (x1, float(face.value(x1)))
    names = outline.names
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SceneError(f"body {short(body)}: outline part {dup[0]!r} is named twice; give every part its own name")
    if "face" in names:
        raise SceneError(f"body {short(body)}: 'face' is the contact face's own name; name the outline part otherwise")
    for p in outline.parts:  # before anything samples a spline: scipy refuses a repeated point with a traceback
        for s in p.segments:
            twice = _repeated_knot((s.start, *s.through, s.end)) if s.is_spline else None
            if twice is not None:
                raise SceneError(f"body {short(body)}: spline {p.name!r} passes through ({twice[0]:g}, {twice[1]:g}) "
                                 "twice in a row; give each of its points once")
    xs = np.linspace(x0, x1, FACE_SAMPLES)
    face_pts = np.stack([xs, face.value(xs)], 1)
    scale = float(np.ptp(np.concatenate([face_pts, outline.points()]), axis=0).max())
    tol = 1e-9 * scale  # coordinates copied from the face's own numbers agree to rounding
    start, end = outline.path[0].segments[0].start, outline.path[-1].segments[-1].end
    if math.dist(start, right) > tol:
        raise SceneError(f"body {short(body)}: the outline starts at ({start[0]:g}, {start[1]:g}), not at the face's "
                         f"right end ({right[0]:g}, {right[1]:g}); start the path there")
    if math.dist(end, left) > tol:
        raise SceneError(f"body {short(body)}: the outline is open: its last part {outline.path[-1].name!r} ends at "
                         f"({end[0]:g}, {end[1]:g}), not at the face's left end ({left[0]:g}, {left[1]:g}); "
                         "end the path there")
    holes = set(outline.holes)
    for p in outline.parts:
        for s in p.segments:
            if math.dist(s.start, s.end) <= tol:
                if p in holes and s.is_arc:
                    raise SceneError(f"body {short(body)}: hole {p.name!r} is too small for the body (radius "
                                     f"{math.dist(s.start, s.center):.3g}); enlarge it or drop it")
                if p in holes:
                    raise SceneError(f"body {short(body)}: hole {p.name!r} repeats the point ({s.start[0]:g}, "
                                     f"{s.start[1]:g}); give each of its corners once")
                raise SceneError(f"body {short(body)}: outline part {p.name!r} has zero length; drop it")
            if s.is_arc:
                r0, r1 = math.dist(s.start, s.center), math.dist(s.end, s.center)
                if abs(r0 - r1) > 1e-6 * max(r0, r1):  # a centre typed to 6 digits
                    raise SceneError(f"body {short(body)}: arc {p.name!r} has its ends at different distances from "
                                     f"its center ({r0:g} and {r1:g}); move the center or the end")
                if abs(s.angles()[1]) > math.pi * (1 - 1e-9):
                    raise SceneError(f"body {short(body)}: arc {p.name!r} turns half a circle or more; split it into "
                                     "two parts (each arc turns less than 180 degrees)")
    rings = [np.concatenate([s.sample() for s in h.segments]) for h in outline.holes]
    for h, r in zip(outline.holes, rings, strict=True):
        if abs(signed_area(r)) <= 1e-9 * float(np.ptp(r, axis=0).max()) ** 2:  # zero to rounding, at its size
            raise SceneError(f"body {short(body)}: hole {h.name!r} encloses no area (its points lie on one line); "
                             "give it a width or drop it")
    _check_crossings(*_loops(face_pts, outline), tol, body)
    # area sign of the closed path (face left-to-right, then the path): lower bodies run clockwise
    ring = np.concatenate([face_pts] + [s.sample()[1:] for p in outline.path for s in p.segments])
    area = signed_area(ring)
    if (area > 0) != (position == "upper") or abs(area) <= tol * scale:
        side = "above" if position == "upper" else "below"
        raise SceneError(f"body {short(body)}: the outline does not enclose a region {side} the face (a {position} "
                         "body); start at the face's right end and go round the body back to its left end")
    for h, pts in zip(outline.holes, rings, strict=True):
        if not np.all(inside(ring, pts)):
            raise SceneError(f"body {short(body)}: hole {h.name!r} is not inside the body; move it inside the outline")
    # no hole inside another: with no crossings, one point of a hole tells (the region between is not the body's)
    firsts = np.array([r[0] for r in rings]).reshape(-1, 2)
    for j, (h, r) in enumerate(zip(outline.holes, rings, strict=True)):
        within = np.flatnonzero(inside(r, firsts) & (np.arange(len(rings)) != j))
        if len(within):
            raise SceneError(f"body {short(body)}: hole {outline.holes[within[0]].name!r} lies inside hole {h.name!r} "
                             f"(an island, not part of the body); drop {outline.holes[within[0]].name!r}")


def _check_crossings(chains, follow, tol, body) -> None:
    """No two segments of the sampled outline meet, but consecutive ones along a loop, which meet
    at their shared end and must not run back over each other there. Segments of parts that are not
    consecutive must also keep clear of each other by the samples' chord error (two tangent circles'
    polygons stay a sagitta apart); consecutive parts only by rounding (a face's fine samples lie
    closer than a large arc's sagitta to the arc that continues it). The first pair is named."""
    segs, owner, chain, pos, sag = [], [], [], [], []
    for k, (pts, name) in enumerate(chains):
        d = np.diff(pts, axis=0)
        length = np.hypot(*d.T)
        # a segment's chord error: its length times the turn at its ends over 8 (c^2 / (8 R) on an arc)
        turn = np.abs(np.arctan2(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], np.sum(d[:-1] * d[1:], axis=1)))
        turn = np.maximum(np.concatenate([[0.0], turn]), np.concatenate([turn, [0.0]]))
        segs.append(np.stack([pts[:-1], pts[1:]], 1))
        owner += [name] * len(d)
        chain.append(np.full(len(d), k))
        pos.append(np.arange(len(d)))
        sag.append(length * turn / 8)
    S = np.concatenate(segs)
    chain, pos = np.concatenate(chain), np.concatenate(pos)
    # twice the chord error: the curvature varies along a spline's or the face's samples
    reach = tol + 2 * np.concatenate(sag)
    first = np.cumsum([0] + [len(s) for s in segs[:-1]])
    last = first + np.array([len(s) for s in segs]) - 1
    n = len(S)
    # consecutive segments (lead, next): along each chain, and from a chain's last to the next one's first
    inner = np.flatnonzero(np.concatenate([np.diff(chain) == 0, [False]]))
    lead = np.concatenate([inner, [last[u] for u, _ in follow]]).astype(np.int64)
    nxt = np.concatenate([inner + 1, [first[v] for _, v in follow]]).astype(np.int64)
    pairs = near_pairs(S, reach)
    a, b = pairs[:, 0], pairs[:, 1]
    adjacent = np.isin(a * n + b, np.minimum(lead, nxt) * n + np.maximum(lead, nxt))
    m = len(chains)
    linked = (chain[a] == chain[b]) | np.isin(np.minimum(chain[a], chain[b]) * m + np.maximum(chain[a], chain[b]),
                                               [min(u, v) * m + max(u, v) for u, v in follow])
    thr = np.where(linked, 2 * tol, reach[a] + reach[b])
    bad = np.flatnonzero(~adjacent & (segment_distance(S[a, 0], S[a, 1], S[b, 0], S[b, 1]) <= thr))
    if len(bad):
        i, j = int(a[bad[0]]), int(b[bad[0]])
        what = (f"part {owner[i]!r} touches itself" if owner[i] == owner[j] else
                f"parts {owner[i]!r} and {owner[j]!r} cross or touch")
        where = _closest(S[i], S[j])
        raise SceneError(f"body {short(body)}: the outline is self-intersecting: {what} near ({where[0]:.6g}, "
                         f"{where[1]:.6g}); move them apart (a boundary passes each point once)")
    # consecutive segments fold when either's far end lies on the other: the boundary runs back over itself
    fold = np.flatnonzero((point_segment_distance(S[lead, 0], S[nxt, 0], S[nxt, 1]) <= 2 * tol)
                          | (point_segment_distance(S[nxt, 1], S[lead, 0], S[lead, 1]) <= 2 * tol))
    if len(fold):
        i, j = int(lead[fold[0]]), int(nxt[fold[0]])
        what = f"part {owner[i]!r}" if owner[i] == owner[j] else f"parts {owner[i]!r} and {owner[j]!r}"
        where = S[i, 1]
        raise SceneError(f"body {short(body)}: the outline runs back over itself: {what} retrace each other at "
                         f"({where[0]:.6g}, {where[1]:.6g}); redraw them so that the boundary passes each point once")


def _closest(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Where the segments ``a`` and ``b`` ``(2, 2)`` come nearest: their crossing, or the end of
    either nearest the other."""
    da, db = a[1] - a[0], b[1] - b[0]
    den = da[0] * db[1] - da[1] * db[0]
    if den != 0:
        w = b[0] - a[0]
        t, u = (w[0] * db[1] - w[1] * db[0]) / den, (w[0] * da[1] - w[1] * da[0]) / den
        if 0 <= t <= 1 and 0 <= u <= 1:
            return a[0] + t * da
    ends = np.concatenate([a, b])
    d = np.concatenate([point_segment_distance(a, b[0], b[1]), point_segment_distance(b, a[0], a[1])])
    return ends[int(np.argmin(d))]
