"""The check of an outline body's whole mesh (strip and gmsh's part) against its outline.

gmsh meshes loops that cvxdual assembles (cuts, halves of holes, free arcs' polygons): a wrong loop
gives a wrong mesh and no error (a region meshed twice, a hole filled, a band missing), and a solve
on it still balances its forces exactly. :func:`check_body_mesh` raises :class:`MeshError` in one
line unless (a) the mesh is a consistently oriented manifold: triangles counter-clockwise with
positive areas, every directed edge used once (an interior edge has two triangles, one each way),
no pinched node; (b) its boundary edges are exactly the face's and the outline parts' node chains
(which supports and loads use), each chain from its part's start to its end, every edge within
``ROUND`` of the body's size of its part plus the polygon's own distance from a curve: ``e^2 /
(2 R)`` for an edge of length ``e`` on an arc of radius ``R`` (a free hole's tangent polygon
reaches that far at its corners, chords a quarter of it), a spline's chords measured against its
samples (:func:`_splines`), the face's from ``f''`` (:func:`_face`); (c) its area is the body's
(face and arcs integrated exactly, splines by the mesher's samples, holes subtracted) within the
area between those polygons and their curves, and no triangle covers a point deep inside a hole.
It reads only. On ``block-with-hole``'s lower block it takes 0.022-0.027 s at level 4 (86k
triangles) and 0.08-0.09 s at level 5 (330k), 7-12 % of meshing that block (0.19-0.34 s, 0.7-1.3
s, as the machine is loaded): mostly one sort of the directed edges.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import MeshError
from ..scene.planar import inside, point_segment_distance
from .outline import SPLINE_SAMPLES

ROUND = 1e-9  # of the body's size: the rounding the outline check allows (coordinates copied from the face)
PROBES = 16  # chords across a hole whose midpoints are tried as points deep inside it
FIX = "try another level; if every level fails, simplify the outline there and report the scene"


def _fail(who: str, what: str, at, fix: str = FIX):
    return MeshError(f"{who}: {what} near ({at[0]:.6g}, {at[1]:.6g}); {fix}")


def check_body_mesh(body, points: np.ndarray, tris: np.ndarray, face_nodes: np.ndarray, parts: dict) -> None:
    """Raise :class:`MeshError` unless ``points``, ``tris`` (the body's own node numbers) mesh the
    outline body ``body`` (module docstring); ``face_nodes``: the face's nodes left to right,
    ``parts``: every outline part's node chain (:class:`~cvxdual.geometry.outline.RestMesh`)."""
    who, outline = f"body {body.name!r}", body.outline
    tol = ROUND * float(np.ptp(points, axis=0).max())
    tx, ty = points[:, 0][tris], points[:, 1][tris]
    area2 = (tx[:, 1] - tx[:, 0]) * (ty[:, 2] - ty[:, 0]) - (tx[:, 2] - tx[:, 0]) * (ty[:, 1] - ty[:, 0])
    bu, bv = _manifold(who, points, tris, area2)
    names = list(outline.names)
    face_nodes, chains = np.asarray(face_nodes), [np.asarray(parts[n]) for n in names]
    cu, cv = np.concatenate([c[:-1] for c in chains]), np.concatenate([c[1:] for c in chains])
    k = np.repeat(np.arange(len(chains)), [len(c) - 1 for c in chains])  # each edge's part
    _same_edges(who, points, bu, bv, np.concatenate([face_nodes[:-1], cu]), np.concatenate([face_nodes[1:], cv]),
                np.concatenate([np.full(len(face_nodes) - 1, -1), k]), names)
    face_slack = _face(who, body, points[face_nodes], tol)
    p, q = points[cu], points[cv]
    e = np.hypot(*(q - p).T)
    inv_r, extra, pieces = _parts(outline)
    spline, chord_off, chord_area = _splines(who, points, chains, outline, tol)
    allow = np.where(spline, tol + chord_off, tol + 0.5 * e**2 * inv_r[k] + extra[k])
    d = _on_parts(who, p, q, k, allow, pieces, names)
    ends = np.array([[*pt.segments[0].start, *pt.segments[-1].end] for pt in outline.parts]).reshape(-1, 2, 2)
    off = np.hypot(*np.moveaxis(points[[[c[0], c[-1]] for c in chains]] - ends, -1, 0))
    if np.any(off > 2 * tol):  # the mesher puts a part's ends where the outline has them (at the face: rounding)
        j, end = divmod(int(np.argmax(off > 2 * tol)), 2)
        raise _fail(who, f"the mesh's nodes on outline part {names[j]!r} stop short of its end", ends[j, end])
    # the area between an edge and its curve: its ends' offsets, linearly, plus the bulge of an arc
    # over it (a circular segment); on a spline, the edge's share of its chord's (_splines)
    curve = np.where(spline, chord_area, e * (0.5 * (d[:, 0] + d[:, 1]) + extra[k]) + _bulge(e, inv_r[k]))
    mesh_area, exact = 0.5 * float(area2.sum()), _area(body)
    # and the sums' rounding; the face's integral is a difference of its antiderivative's values,
    # which far from the origin (a body at x = 4e7) are large: their rounding counts too
    x0, x1 = body.x_range
    far = float(np.abs(body.face.antiderivative(np.array([x0, x1], float))).sum())
    slack = face_slack + float(np.sum(curve + e * tol)) + ROUND * exact + 8 * np.finfo(float).eps * far
    if abs(mesh_area - exact) > slack:
        raise MeshError(f"{who}: the mesh's area {mesh_area:.9g} is not the body's {exact:.9g} (off by "
                        f"{mesh_area - exact:.3g}, more than the {slack:.2g} its polygons allow): a region is "
                        f"meshed twice or missing; {FIX}")
    _holes_empty(who, tx, ty, outline, allow, k, names)


def _manifold(who, points, tris, area2):
    """Check (a) but pinches (after (b): a missing region is told better there); the boundary's
    directed edges ``(u, v)``. Edges are keys ``2 (lo n + hi) + (u > v)``, sorted once: a key twice
    is an edge used twice one way, an edge with one key has one triangle (the boundary)."""
    n = len(points)
    if not np.all(area2 > 0):  # (flat ones, relative to their edges: check_triangles on the whole mesh)
        raise _fail(who, f"{int(np.sum(~(area2 > 0)))} mesh triangle(s) inverted or flat, first",
                    points[tris[int(np.argmax(~(area2 > 0)))]].mean(0), "raise the level, or move the outline's "
                    "parts there apart")
    u = tris.ravel().astype(np.int64, copy=False)
    v = np.roll(tris, -1, axis=1).ravel().astype(np.int64, copy=False)
    key = np.sort((np.minimum(u, v) * n + np.maximum(u, v)) * 2 + (u > v), kind="stable")
    edge = key >> 1
    twice = np.flatnonzero(key[1:] == key[:-1])
    if len(twice):
        lo, hi = divmod(int(edge[twice[0]]), n)
        raise _fail(who, "the mesh covers a region twice (two triangles on the same side of one edge)",
                    0.5 * (points[lo] + points[hi]))
    same = edge[1:] == edge[:-1]
    alone = key[~(np.r_[False, same] | np.r_[same, False])]
    lo, hi = np.divmod(alone >> 1, n)
    back = (alone & 1).astype(bool)  # the triangle's edge runs from hi to lo
    return np.where(back, hi, lo), np.where(back, lo, hi)


def _same_edges(who, points, bu, bv, cu, cv, owner, names) -> None:
    """The mesh's boundary edges are the chains' edges, each once; no node pinched."""
    n = len(points)
    kb, kc = np.minimum(bu, bv) * n + np.maximum(bu, bv), np.minimum(cu, cv) * n + np.maximum(cu, cv)
    extra = np.flatnonzero(~np.isin(kb, kc))
    if len(extra):
        raise _fail(who, "the mesh has a boundary that is none of the face's or the outline's: a region of the "
                    "body is missing there", 0.5 * (points[bu[extra[0]]] + points[bv[extra[0]]]))
    lost = np.flatnonzero(~np.isin(kc, kb))
    u, first = np.unique(kc, return_index=True)
    if not len(lost) and len(u) < len(kc):
        lost = np.setdiff1d(np.arange(len(kc)), first)[:1]  # one mesh edge in two chains
    if len(lost):
        i = lost[0]
        part = "the face" if owner[i] < 0 else f"outline part {names[owner[i]]!r}"
        raise _fail(who, f"{part} is not on the mesh's boundary (a hole filled, or a region meshed twice over it)",
                    0.5 * (points[cu[i]] + points[cv[i]]))
    pinch = np.flatnonzero(np.bincount(bu, minlength=n) > 1)  # two boundary edges leave a node: the loops touch
    if len(pinch):
        raise _fail(who, "the mesh pinches (two pieces of it meet at one node)", points[pinch[0]],
                    "move the outline's parts there apart, or " + FIX)


def _face(who, body, fp: np.ndarray, tol: float) -> float:
    """Check the face's nodes and edges; the area their polygon may differ from the face by. A
    face node is on the face or (type 2) where the tangents at ``s_i < x_i < s_{i+1}`` meet, at
    most ``K (s_{i+1} - s_i)^2 / 2`` off it (``K`` bounds ``|f''|``; ``s_i``, ``s_{i+1}`` lie within
    its neighbours); an edge is off by its ends' offsets plus ``K dx^2 / 8`` (``K dx^3 / 12`` of
    area). Offsets are vertical: they bound the distance."""
    x, y, face = fp[:, 0], fp[:, 1], body.face

    def most(lo, hi):  # |f''| at most, over each [lo, hi] (the profile's own bound, guaranteed)
        return np.max(np.abs(face.curvature_range(lo, hi)), axis=0)

    dx = np.diff(x)
    x0, x1 = body.x_range
    if np.any(dx <= 0) or abs(x[0] - x0) > tol or abs(x[-1] - x1) > tol:
        raise _fail(who, f"the mesh's face nodes do not run from x = {x0:g} to {x1:g} left to right", fp[0])
    i = np.arange(len(x))
    lo, hi = x[np.maximum(i - 1, 0)], x[np.minimum(i + 1, len(x) - 1)]
    off = np.abs(y - face.value(x))
    allow = tol + 0.5 * most(lo, hi) * (hi - lo) ** 2
    at = fp
    if np.all(off <= allow):
        k = most(x[:-1], x[1:])
        at = 0.5 * (fp[:-1] + fp[1:])
        mid, allow = np.abs(at[:, 1] - face.value(at[:, 0])), tol + 0.5 * (off[:-1] + off[1:]) + k * dx**2 / 8
        if np.all(mid <= allow):
            return float(np.sum(dx * (tol + 0.5 * (off[:-1] + off[1:])) + k * dx**3 / 12))
        off = mid
    j = int(np.argmax(off > allow))
    raise _fail(who, f"the mesh's face lies {off[j]:.3g} off the face (more than {allow[j]:.2g})", at[j])


def _parts(outline):
    """Per part: its arcs' curvature and ends' radius mismatch (an allowance); the pieces: lines
    ``(part, p0, p1)`` (splines' samples too), arcs ``(part, centre, radius, angle, sweep, p0, p1)``."""
    inv_r, extra = np.zeros(len(outline.parts)), np.zeros(len(outline.parts))
    lines, arcs = [], []
    for k, part in enumerate(outline.parts):
        for s in part.segments:
            if s.is_arc:
                r0, r1 = math.dist(s.start, s.center), math.dist(s.end, s.center)
                inv_r[k] = max(inv_r[k], 1.0 / r0)
                extra[k] = max(extra[k], abs(r1 - r0))  # the arc check allows its ends 1e-6 apart in radius
                arcs.append((k, *s.center, r0, *s.angles(), *s.start, *s.end))
            else:  # a line's two ends, a spline's dense polygon (the mesher's samples: allowances by chord)
                pts = s.sample(SPLINE_SAMPLES)
                lines += [(k, *a, *b) for a, b in zip(pts[:-1], pts[1:], strict=True)]
    return inv_r, extra, (np.array(lines, float).reshape(-1, 5), np.array(arcs, float).reshape(-1, 10))


def _splines(who, points, chains, outline, tol):
    """Edges on splines: which, how far each may lie from its spline, the area it may differ by.
    A spline's polygon runs through the mesher's samples, at level 0 with nodes on its chords too
    (gmsh's, cuts' ends): each chord between two sample nodes is measured against the samples
    between: its distance ``D`` from them (the farthest sample's from its line: a chord point's
    perpendicular meets the stretch), the area between (at most the stretch's chord-aligned box)."""
    lens = np.array([len(c) - 1 for c in chains])
    first = np.concatenate([[0], np.cumsum(lens)[:-1]])
    spline, off, area = np.zeros(lens.sum(), bool), np.zeros(lens.sum()), np.zeros(lens.sum())
    for j in (j for j, part in enumerate(outline.parts) if part.has_spline):
        dense = np.concatenate([sg.sample(SPLINE_SAMPLES) for sg in outline.parts[j].segments])
        xy = points[chains[j]]
        node, at = _box_pairs(xy - 2 * tol, xy + 2 * tol, dense, dense)  # samples to rounding (the face's ends)
        index = np.full(len(xy), -1)
        np.maximum.at(index, node, at)
        index[0], index[-1] = 0, len(dense) - 1
        vertex = np.flatnonzero(index >= 0)
        vi = index[vertex]
        ce = np.searchsorted(vertex, np.arange(len(xy) - 1), side="right") - 1  # each edge's chord
        a, b = dense[vi[:-1]], dense[vi[1:]]
        length = np.hypot(*(b - a).T)
        u = (b - a) / np.maximum(length, 1e-300)[:, None]
        if np.any(np.diff(vi) <= 0) or np.any(np.abs(_cross(u[ce], xy[1:] - a[ce])) > 2 * tol):  # on its chord
            raise _fail(who, f"the mesh's nodes on outline part {outline.parts[j].name!r} leave its polygon", xy[0])
        c = np.minimum(np.searchsorted(vi, np.arange(len(dense)), side="right") - 1, len(vi) - 2)
        along, across = np.sum((dense - a[c]) * u[c], axis=1), _cross(u[c], dense - a[c])
        up, down = np.maximum.reduceat(across, vi[:-1]), -np.minimum.reduceat(across, vi[:-1])
        extent = (np.maximum(np.maximum.reduceat(along, vi[:-1]), length)
                  - np.minimum(np.minimum.reduceat(along, vi[:-1]), 0.0))
        sl = slice(first[j], first[j] + lens[j])
        spline[sl], off[sl] = True, np.maximum(up, down)[ce]
        area[sl] = (extent * (up + down))[ce] * np.hypot(*np.diff(xy, axis=0).T) / length[ce]
    return spline, off, area


def _cross(u, v) -> np.ndarray:
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def _bulge(e: np.ndarray, inv_r: np.ndarray) -> np.ndarray:
    """The area between a chord of length ``e`` and a circle of curvature ``inv_r`` (0: none)."""
    t = 2 * np.arcsin(np.minimum(1.0, 0.5 * e * inv_r))  # the angle the chord subtends
    f = np.where(t < 1e-2, t**3 / 6 * (1 - t * t / 20), t - np.sin(t))  # theta - sin(theta): its series if small
    return np.where(inv_r > 0, 0.5 * f / np.where(inv_r > 0, inv_r, 1.0) ** 2, 0.0)


def _on_parts(who, p, q, k, allow, pieces, names) -> np.ndarray:
    """Check that edge ``p -> q`` lies on its part ``k``: ends and midpoint within ``allow`` of the
    part's pieces (candidates by boxes, the edge's grown by its length); its ends' distances."""
    lines, arcs = pieces
    pts = np.stack([p, q, 0.5 * (p + q)], 1)  # (m, 3, 2)
    grow = (np.hypot(*(q - p).T) + allow)[:, None]
    best = np.full((len(p), 3), np.inf)
    ends = lines[:, 1:3], lines[:, 3:5]
    for rows, lo, hi, dist in ((lines, np.minimum(*ends), np.maximum(*ends), _to_line),
                               (arcs, arcs[:, 1:3] - arcs[:, 3:4], arcs[:, 1:3] + arcs[:, 3:4], _to_arc)):
        i, j = _box_pairs(np.minimum(p, q) - grow, np.maximum(p, q) + grow, lo, hi)
        i, j = i[k[i] == rows[j, 0]], j[k[i] == rows[j, 0]]
        np.minimum.at(best, i, dist(pts[i], rows[j]))
    off = best.max(axis=1)
    bad = np.flatnonzero(~(off <= allow))
    if len(bad):
        b = bad[0]
        far = "far" if not np.isfinite(off[b]) else f"{off[b]:.3g}"
        raise _fail(who, f"the mesh's edge on outline part {names[k[b]]!r} lies {far} off it (more than "
                    f"{allow[b]:.2g})", 0.5 * (p[b] + q[b]))
    return best[:, :2]


def _to_line(x, rows):  # the distances of points x (m, 3, 2) to the segments rows (m, 5)
    return point_segment_distance(x, rows[:, None, 1:3], rows[:, None, 3:5])


def _to_arc(x, rows):
    """Distances of ``x`` to the arcs ``rows``: to the circle within the arc's angles, else to an end."""
    c, r, a0, sweep = rows[:, None, 1:3], rows[:, None, 3], rows[:, None, 4], rows[:, None, 5]
    v = x - c
    t = np.arctan2(v[..., 1], v[..., 0]) - a0
    within = np.mod(np.where(sweep < 0, -t, t), 2 * np.pi) <= np.abs(sweep)
    ends = np.minimum(np.linalg.norm(x - rows[:, None, 6:8], axis=-1), np.linalg.norm(x - rows[:, None, 8:10], axis=-1))
    return np.where(within, np.abs(np.linalg.norm(v, axis=-1) - r), ends)


def _box_pairs(lo_a, hi_a, lo_b, hi_b):
    """Index pairs of boxes ``a_i``, ``b_j`` that overlap: ``b_j``'s left side within ``a_i``'s ``x``
    range or ``a_i``'s strictly within ``b_j``'s (sorted, as ranges), then ``y`` ranges compared."""
    out = []
    for l1, h1, l2, swap in ((lo_a, hi_a, lo_b, False), (lo_b, hi_b, lo_a, True)):
        order = np.argsort(l2[:, 0], kind="stable")
        start = np.searchsorted(l2[order, 0], l1[:, 0], side="right" if swap else "left")
        count = np.maximum(np.searchsorted(l2[order, 0], h1[:, 0], side="right") - start, 0)
        rows = np.repeat(np.arange(len(l1)), count)
        cols = order[np.repeat(start, count) + np.arange(len(rows)) - np.repeat(np.cumsum(count) - count, count)]
        out.append((cols, rows) if swap else (rows, cols))
    i, j = np.concatenate([out[0][0], out[1][0]]), np.concatenate([out[0][1], out[1][1]])
    keep = (lo_a[i, 1] <= hi_b[j, 1]) & (lo_b[j, 1] <= hi_a[i, 1])
    return i[keep], j[keep]


def _area(body) -> float:
    """The body's exact area: half of ``x dy - y dx`` round its outer loop less its holes'."""
    x0, x1 = body.x_range
    f0, f1 = (float(body.face.value(v)) for v in (x0, x1))
    xr, yr = 0.5 * (x0 + x1), 0.5 * (f0 + f1)  # about a point of the body: less rounding
    face = 0.5 * ((x1 - xr) * f1 - (x0 - xr) * f0 - 2 * float(body.face.integral(x0, x1)) + yr * (x1 - x0))

    def loop(part) -> float:
        total = 0.0
        for s in part.segments:
            if s.is_arc:
                cx, cy, r = s.center[0] - xr, s.center[1] - yr, math.dist(s.start, s.center)
                a0, sweep = s.angles()
                a1 = a0 + sweep
                total += 0.5 * r * (r * sweep + cx * (math.sin(a1) - math.sin(a0)) - cy * (math.cos(a1) - math.cos(a0)))
            else:  # a line's two ends, a spline's dense polygon
                pts = s.sample(SPLINE_SAMPLES) - [xr, yr]
                total += 0.5 * float(np.sum(pts[:-1, 0] * pts[1:, 1] - pts[1:, 0] * pts[:-1, 1]))
        return total

    return abs(face + sum(loop(p) for p in body.outline.path)) - sum(abs(loop(h)) for h in body.outline.holes)


def _holes_empty(who, tx, ty, outline, allow, k, names) -> None:
    """No triangle covers a hole's probe (of its centroid and chords' midpoints, the one inside and
    deepest) if it lies deeper than the mesh may stray: twice the allowance (the samples' own chord
    error, 1e-4 of an arc's radius, is far less; a thinner hole is left to the area check)."""
    n_path, box = len(outline.path), None
    for j, hole in enumerate(outline.holes):
        ring = np.concatenate([s.sample() for s in hole.segments])
        i = (np.arange(PROBES) * len(ring)) // PROBES
        cand = np.concatenate([ring.mean(0)[None], 0.5 * (ring[i] + ring[(i + len(ring) // 2) % len(ring)])])
        cand = cand[inside(ring, cand)]
        depth = point_segment_distance(cand[:, None], ring[None, :-1], ring[None, 1:]).min(axis=1)
        if not len(cand) or depth.max() <= 2 * allow[k == n_path + j].max():
            continue
        x = cand[int(np.argmax(depth))]
        if box is None:  # column by column: a reduction along an axis of 3 is slow
            box = [f(f(t[:, 0], t[:, 1]), t[:, 2]) for t in (tx, ty) for f in (np.minimum, np.maximum)]
        near = np.flatnonzero((box[0] <= x[0]) & (box[1] >= x[0]) & (box[2] <= x[1]) & (box[3] >= x[1]))
        px, py = tx[near], ty[near]
        ex, ey = np.roll(px, -1, axis=1) - px, np.roll(py, -1, axis=1) - py
        if np.any(np.all(ex * (x[1] - py) - ey * (x[0] - px) >= 0, axis=1)):  # left of its three edges, or on one
            raise _fail(who, f"hole {names[n_path + j]!r} is meshed over (the mesh fills it)", x)
