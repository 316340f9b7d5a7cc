"""Curved parts of an outline body's mesh, once their polygons are built
(:meth:`~cvxdual.geometry.outline.build.OutlineBuild.free_arc`): the pieces beyond a free arc
(section 9 of docs/theory.md) as node triples of the mesh, finding mesh nodes by
their coordinates (how gmsh's nodes are matched to the points cvxdual placed), and whether the
polygons that stand for the curves still bound one region (:func:`first_clash`). A valid
outline's curves keep clear of each other, but their polygons need not: a free arc's chords cut
inside it (``r (1 - cos(d / 2))`` deep), a hole's tangent polygon reaches outside its circle, a
spline's chords cut its bends, and at level ``L >= 1`` gmsh gets every other vertex of each (four
times as deep). A part closer to such a curve than that (a small hole by a rounded corner)
crosses the polygon, or lies beyond it: gmsh then leaves a surface empty or fills a hole, and the
refined mesh misses edges of the curves. :func:`first_clash` finds such a pair before gmsh runs:
at level ``L``'s polygons the body is refused (:func:`clash_message`), at gmsh's coarser ones it
is meshed at level ``L`` directly (:mod:`~cvxdual.geometry.outline.loops`)."""

from __future__ import annotations

import numpy as np

from ...scene.planar import inside, meeting_pairs, point_segment_distance
from ..triangles import doubled_areas, edge_triangles

CLASH_SAMPLES = 256  # points per curved segment when measuring how far a polygon strays from its curve


def match_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For each row of ``a`` ``(m, 2)``, the index of the bit-identical row of ``b``, or -1."""
    # rows as complex numbers: numpy sorts those by real then imaginary part, and fast
    av = np.ascontiguousarray(a, float).view(np.complex128).ravel()
    bv = np.ascontiguousarray(b, float).view(np.complex128).ravel()
    order = np.argsort(bv)
    pos = np.clip(np.searchsorted(bv[order], av), 0, len(bv) - 1)
    return np.where(bv[order][pos] == av, order[pos], -1)


def continuation(virtual: dict, xy: np.ndarray, idx: np.ndarray, tris: np.ndarray, allp: np.ndarray):
    """Node triples and area weights of the free arcs' continuation pieces (``OutlineBuild.free_arc``):
    their points found among gmsh's nodes ``xy`` (local indices ``idx``) by their coordinates. Then,
    for a quadrature on the exact pieces, each piece's arc ``(cx, cy, r)`` and the nodes at its
    ends on the arc: a segment's triangle may have all three nodes on the circle (two chords of one
    triangle, seen on punch-on-block), so the triple alone does not say which edge is the chord."""
    corner = np.asarray(virtual["corner"], float).reshape(-1, 3, 2)
    chord = np.asarray(virtual["segment"], float).reshape(-1, 2, 2)
    arc = np.asarray(virtual["corner_arc"] + virtual["segment_arc"], float).reshape(-1, 3)
    if not len(corner) + len(chord):
        return np.zeros((0, 3), int), np.zeros(0), arc, np.zeros((0, 2), int)
    c_nodes = idx[match_rows(corner.reshape(-1, 2), xy)].reshape(-1, 3)
    c_area = 0.5 * np.abs(doubled_areas(allp, c_nodes))
    ends = np.sort(idx[match_rows(chord.reshape(-1, 2), xy)].reshape(-1, 2), axis=1)
    t = edge_triangles(tris, ends[:, 0], ends[:, 1], int(tris.max()) + 1)  # the triangle on each chord
    return (np.concatenate([c_nodes, tris[t]]).astype(int),
            np.concatenate([c_area, np.asarray(virtual["segment_area"], float)]),
            arc, np.concatenate([c_nodes[:, [0, 2]], ends]).astype(int))


def first_clash(rings: list, owners: list) -> tuple | None:
    """The first two owners whose polylines keep the closed loops ``rings`` from bounding one
    region, or ``None``: ``rings[0]`` is the outer loop, the rest are holes, each a list of
    polylines ``(m, 2)`` in loop order, ``owners`` the same lists of labels. Two segments may meet
    only at a shared end (consecutive ones); every hole must lie inside the outer loop (the
    label of its nearest outer polyline is given when it does not) and inside no other hole."""
    polys = [p for r in rings for p in r]
    label = [o for r in owners for o in r]
    own = np.concatenate([np.full(len(p) - 1, i) for i, p in enumerate(polys)])
    segs = np.concatenate([np.stack([p[:-1], p[1:]], 1) for p in polys])
    tol = 1e-12 * float(np.ptp(segs.reshape(-1, 2), axis=0).max())
    pairs = meeting_pairs(segs, tol)
    a, b = segs[pairs[:, 0]], segs[pairs[:, 1]]
    shared = np.zeros(len(pairs), bool)
    for i in range(2):
        for j in range(2):
            shared |= np.all(a[:, i] == b[:, j], axis=1)
    bad = pairs[~shared]
    if len(bad):
        return label[own[bad[0, 0]]], label[own[bad[0, 1]]]
    loops = [np.concatenate(r) for r in rings]
    firsts = np.array([r[0][0] for r in rings[1:]]).reshape(-1, 2)  # one vertex of each hole
    out = np.flatnonzero(~inside(loops[0], firsts)) if len(firsts) else []
    if len(out):
        h = int(out[0]) + 1
        d = point_segment_distance(firsts[out[0]], segs[own < len(rings[0]), 0], segs[own < len(rings[0]), 1])
        return owners[h][0], label[own[int(np.argmin(d))]]
    for i in range(1, len(rings)):
        within = np.flatnonzero(inside(loops[i], firsts))
        within = within[within != i - 1]
        if len(within):
            return owners[int(within[0]) + 1][0], owners[i][0]
    return None


def clash_message(body, level: int, a, b, polygons: dict, strip: np.ndarray) -> str:
    """One line refusing ``body`` at ``level``: the polygons standing for parts ``a`` and ``b``
    (``polygons[name]``: its points) cross, though the parts themselves do not; how far apart to
    move them, and the level at which their polygons keep clear (their strays from the curves
    quarter a level), if that is at most four levels up. ``None`` is the strip, whose inner chain
    ``strip`` stands for itself."""
    who = f"body {body.name!r}: at level {level} the polygon"
    along = _along_strip_side(body, b if a is None else a, polygons, strip) if None in (a, b) and a != b else None
    if along:  # no level helps: the overlap is along a straight line, whatever the polygon's edges
        name, side, end, depth = along
        return (f"body {body.name!r}: outline part {name!r} leaves the face's {side} end ({end[0]:.6g}, {end[1]:.6g}) "
                "along the side of the strip of columns (it runs vertically there), so their polygons overlap at "
                f"every level; start it with a vertical line longer than the strip is deep ({depth:.3g} at level "
                f"{level}), or let it leave the face at an angle")
    if a == b:
        return f"{who} that stands for {_what(body, a)} crosses itself; raise the level, or smooth the part"
    ca, cb = _dense(body, a, strip), _dense(body, b, strip)
    gap = min(float(_distances(ca, cb).min()), float(_distances(cb, ca).min()))
    dev = _stray(body, a, polygons, strip) + _stray(body, b, polygons, strip)
    what = f"{_what(body, a)} and {_what(body, b)}"
    if not gap < dev:  # pragma: no cover - the polygons keep within their strays of the curves
        return f"{who}s that stand for {what} cross; raise the level, or move them apart"
    up = next((k for k in range(1, 5) if dev / 4**k < 0.5 * gap), None)
    return (f"{who}s that stand for {what} cross: the polygons lie up to {dev:.3g} off the curves "
            f"in all, and the parts come within {gap:.3g} of each other; move them at least {1.2 * dev:.2g} apart"
            + (f", or raise the level to {level + up}" if up else ""))


def _dense(body, name, strip: np.ndarray) -> np.ndarray:
    """The part itself (dense samples of its curves); the strip's chain for ``None``."""
    if name is None:
        return strip
    return np.concatenate([s.sample(CLASH_SAMPLES) if s.is_arc else np.array([s.start, s.end]) if not s.is_spline
                           else s.sample(max(4, CLASH_SAMPLES // (len(s.through) + 1)))
                           for s in body.outline.part(name).segments])


def _what(body, name) -> str:
    if name is None:
        return "the strip of columns along the face"
    return f"{'hole' if name in {h.name for h in body.outline.holes} else 'outline part'} {name!r}"


def _stray(body, name, polygons: dict, strip: np.ndarray) -> float:
    """How far the polygon strays from the part: at its vertices and edge midpoints."""
    if name is None:
        return 0.0
    p = polygons[name]
    return float(_distances(np.concatenate([p, 0.5 * (p[:-1] + p[1:])]), _dense(body, name, strip)).max())


def _along_strip_side(body, name, polygons: dict, strip: np.ndarray):
    """``(name, side, face end, strip depth)`` if the polygon of part ``name`` leaves a face end
    straight along the strip's vertical side, into the body (a free concave arc whose tangent is
    vertical there: its tangent polygon's first edge lies on the side), else ``None``."""
    if name is None or name in {h.name for h in body.outline.holes}:
        return None
    p = polygons[name]
    tol = 1e-12 * float(np.ptp(strip, axis=0).max())
    for side, k, inner, (e, nxt) in (("right", -1, strip[-1], (p[0], p[1])), ("left", 0, strip[0], (p[-1], p[-2]))):
        x = body.x_range[1 if k else 0]
        end = np.array([x, float(body.face.value(x))])
        if (np.hypot(*(e - end)) <= tol and abs(nxt[0] - x) <= tol
                and body.sign * (nxt[1] - end[1]) > tol):  # from the face end, down (up) along x = x_end
            return name, side, end, abs(float(inner[1] - end[1]))
    return None


def _distances(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """The distance of each point ``p`` ``(m, 2)`` to the polyline ``line``, about 1e6 pairs at once."""
    step = max(1, (1 << 20) // max(len(line) - 1, 1))
    return np.concatenate([point_segment_distance(p[k:k + step, None], line[None, :-1], line[None, 1:]).min(axis=1)
                           for k in range(0, len(p), step)])
