"""Where the rest of an outline body is cut into surfaces, which gmsh meshes side by side. gmsh's
frontal algorithm meshes one surface on one thread and costs more a triangle the larger the
surface (8.6 us a triangle for one surface of 9e4 uniform triangles, 5.7 us at 2e4): cut in up to
eight surfaces, on two threads, a body meshes 2.5-3.5 times faster. A cut leaves the strip's
inner chain at a node and runs away from the face: straight to the outline, or, when a hole is in
the way, to the hole's nearest vertex, round the hole (each side keeps one half of it) and on
from its far vertex. It ends inside a straight, splittable part of the outer loop (not a strip
edge, not an arc's polygon), crosses nothing and keeps half an element size clear of every other
outline vertex; cuts are tried from eight evenly spaced chain nodes (of the level an adaptive grid
started from: its nodes keep the cuts as spread as there, where refinement crowds the chain), and a
body no cut fits stays one surface. Curves come as ``(polyline, splittable)``: a line's two ends,
an arc's samples. Pure geometry: :mod:`~cvxdual.geometry.outline.regions` builds the gmsh loops
from a :class:`Cut`."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from ...scene.planar import inside, segments_meet

PIECES = 8  # surfaces a body is cut into at most: cuts tried at chain fractions 1/8 .. 7/8


@dataclass(frozen=True)
class Cut:
    """A cut from chain node ``k`` to ``end`` on the outer loop's curve ``j`` (index in the path);
    through ``hole`` (index) when set: to its curve start ``near``, then from ``far`` to ``end``."""

    k: int
    j: int
    end: np.ndarray
    hole: int | None = None
    near: np.ndarray | None = None
    far: np.ndarray | None = None


def find_cuts(chain: np.ndarray, sign: int, path: list, holes: list, size, cut_columns=None) -> list[Cut]:
    """The clean cuts from the candidate chain nodes, left to right (none: one surface). ``sign``
    points from the face into the body, ``holes`` holds each hole's curves in loop order,
    ``size(points)`` is the element size asked there. The candidates are the chain nodes at
    fractions 1/8 .. 7/8 of the nodes of ``cut_columns`` (default: the chain's abscissae), each the chain
    node nearest in ``x``. Cuts through one hole, or ending in an order along the outline that
    differs from their order along the chain, are dropped."""
    curves = path + [c for h in holes for c in h]
    owner = np.concatenate([np.full(len(p) - 1, i) for i, (p, _) in enumerate(curves)])
    segs = np.concatenate([np.stack([p[:-1], p[1:]], 1) for p, _ in curves])
    hole_of = np.concatenate([[-1] * len(path)] + [[i] * len(h) for i, h in enumerate(holes)])
    nc = len(chain)
    base = chain[:, 0] if cut_columns is None else np.asarray(cut_columns, float)
    at = base[[int(round(i * (len(base) - 1) / PIECES)) for i in range(1, PIECES)]]
    cuts, used = [], set()
    for k in sorted({int(np.argmin(np.abs(chain[:, 0] - x))) for x in at}):
        cut = _try(k, chain[k], sign, path, holes, segs, owner, hole_of, size) if 1 <= k <= nc - 2 else None
        if cut is not None and (cut.hole is None or cut.hole not in used):
            cuts.append(cut)
            used.add(cut.hole)
    # along the outline (right end, far side, left end) the ends must come in the reverse order
    where = [(c.j, float(np.hypot(*(c.end - path[c.j][0][0])))) for c in cuts]
    return cuts if all(a > b for a, b in pairwise(where)) else []


def _try(k, start, sign, path, holes, segs, owner, hole_of, size) -> Cut | None:
    """The cut from chain node ``k`` at ``start``, if it is clean (:func:`find_cuts`)."""
    hits = _ray(segs, start, sign)
    if not len(hits):
        return None
    i, y = hits[0]
    h = int(hole_of[owner[i]])
    if h < 0:
        end = np.array([start[0], y])
        return Cut(k, int(owner[i]), end) if _clean(path, owner[i], start, end, segs, size, ()) else None
    starts = np.array([p[0] for p, _ in holes[h]])  # the hole's curve starts: gmsh points
    out = max((yy for ii, yy in hits if hole_of[owner[ii]] == h), key=lambda v: sign * v)  # where the ray leaves it
    near = starts[np.argmin(np.hypot(*(starts - [start[0], y]).T))]
    far = starts[np.argmin(np.hypot(*(starts - [start[0], out]).T))]
    if np.array_equal(near, far):
        return None  # no two halves to share out
    after = [(ii, yy) for ii, yy in _ray(segs, far, sign) if sign * (yy - far[1]) > 0]
    if not after or hole_of[owner[after[0][0]]] >= 0:
        return None
    j, end = int(owner[after[0][0]]), np.array([far[0], after[0][1]])
    ring = np.concatenate([p for p, _ in holes[h]])
    legs_outside = not (inside(ring, near + 1e-6 * (start - near)) or inside(ring, far + 1e-6 * (end - far)))
    ok = legs_outside and _clean(path, None, start, near, segs, size, (near,), hole=ring) and \
        _clean(path, j, far, end, segs, size, (far,), hole=ring)
    return Cut(k, j, end, h, near, far) if ok else None


def _ray(segs: np.ndarray, start: np.ndarray, sign: int) -> list:
    """The segments the vertical ray from ``start`` (towards ``sign``) crosses, nearest first:
    ``(segment index, y)``."""
    a, b = segs[:, 0], segs[:, 1]
    span = b[:, 0] - a[:, 0]
    crosses = ((a[:, 0] - start[0]) * (b[:, 0] - start[0]) <= 0) & (span != 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        y = a[:, 1] + (start[0] - a[:, 0]) / span * (b[:, 1] - a[:, 1])
    ahead = np.flatnonzero(crosses & (sign * (y - start[1]) >= 0))
    ahead = ahead[np.argsort(sign * (y[ahead] - start[1]), kind="stable")]
    return [(int(i), float(y[i])) for i in ahead]


def _clean(path, j, p, q, segs, size, own, hole=None) -> bool:
    """Whether the leg ``p -> q`` ends inside the splittable curve ``j`` (or at a hole vertex,
    ``j`` None), crosses no segment but those at its own ends, and keeps half an element size
    clear of every outline vertex but the hole's it runs round (its end too: a cut that would end
    at or beside a part's end, a split under a column, is not made)."""
    if j is not None and not path[j][1]:
        return False  # a strip edge or an arc's polygon: not split
    h = 0.5 * float(np.min(size(np.array([p, q]))))
    verts = np.concatenate([segs[:, 0], segs[:, 1]])
    if hole is not None:
        verts = verts[~np.isin(verts.view(complex).ravel(), np.asarray(hole).view(complex).ravel())]
    d = q - p
    t = np.clip(((verts - p) @ d) / max(float(d @ d), 1e-300), 0.0, 1.0)
    dist = np.hypot(*(verts - p - t[:, None] * d).T)  # every vertex's distance to the leg
    # no vertex is exempt, not even one within rounding of the leg's end: a cut ending a few ulps
    # beside a part's end (a split under a column at x = -3e-15 against 0) gave gmsh two points
    # there and a zero-area triangle; the leg's own ends are never outline vertices but a hole's
    if np.any(dist < h):
        return False
    touch = np.any([np.all(segs == e, axis=-1) for e in own], axis=0).any(axis=1) if own else np.zeros(len(segs), bool)
    meets = segments_meet(np.array([p]), np.array([q]), segs[:, 0], segs[:, 1], 0.0)[0]
    if j is not None:
        meets &= ~_of_curve(segs, path[j][0])
    return not np.any(meets & ~touch)


def _of_curve(segs, poly) -> np.ndarray:
    """Which segments belong to the polyline ``poly``."""
    mine = np.stack([poly[:-1], poly[1:]], 1)
    return np.any(np.all(segs[:, None] == mine[None], axis=(-1, -2)), axis=1)
