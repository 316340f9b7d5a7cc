"""Plane geometry predicates on polylines, vectorised: signed area, segments meeting, the
segment pairs of one set that meet or come near (a sweep over ``x``), distances, point in polygon.

Used by the outline checks (:mod:`cvxdual.scene.outline`) and by the meshing of outline bodies
(:mod:`cvxdual.geometry`); numpy only, so checking a scene imports nothing heavy.
"""

from __future__ import annotations

import numpy as np

PAIR_BLOCK = 1 << 20  # candidate pairs tested at once: ~100 MB of temporaries at most


def signed_area(pts: np.ndarray) -> float:
    """The area of the closed polygon through ``pts`` ``(m, 2)``: positive counter-clockwise."""
    return 0.5 * float(np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1]))


def _cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def meet(a0, a1, b0, b1, tol):
    """Whether segment ``a0 -> a1`` meets ``b0 -> b1`` (touching counts, up to ``tol``),
    elementwise over broadcast arrays of points ``(..., 2)``."""
    da, db = a1 - a0, b1 - b0
    t1, t2 = tol * np.linalg.norm(da, axis=-1), tol * np.linalg.norm(db, axis=-1)  # orientations as distances
    sides_a = _cross(da, b0 - a0) * _cross(da, b1 - a0) <= t1**2
    sides_b = _cross(db, a0 - b0) * _cross(db, a1 - b0) <= t2**2
    boxes = np.all((np.minimum(a0, a1) <= np.maximum(b0, b1) + tol)
                   & (np.minimum(b0, b1) <= np.maximum(a0, a1) + tol), axis=-1)
    return sides_a & sides_b & boxes


def segments_meet(a0, a1, b0, b1, tol):
    """``(m, n)``: whether segment ``a_i`` and ``b_j`` meet (touching counts, up to ``tol``)."""
    return meet(a0[:, None], a1[:, None], b0[None], b1[None], tol)


def meeting_pairs(segs: np.ndarray, tol: float) -> np.ndarray:
    """``(k, 2)`` index pairs ``i < j`` of the segments ``segs`` ``(n, 2, 2)`` that meet, sorted.

    Only pairs whose ``x`` ranges overlap are tested: sorted by their left ends, segment ``i``'s
    candidates are the run of segments starting before its right end, so an outline (mostly
    short, disjoint pieces) costs about linear time, in blocks of :data:`PAIR_BLOCK` pairs."""
    found = []
    for a, b in _boxes_meeting(segs, tol):
        hit = meet(segs[a, 0], segs[a, 1], segs[b, 0], segs[b, 1], tol)
        found.append(np.sort(np.stack([a[hit], b[hit]], 1), axis=1))
    pairs = np.concatenate(found) if found else np.zeros((0, 2), int)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def near_pairs(segs: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """``(k, 2)`` index pairs ``i < j`` of the segments ``segs`` ``(n, 2, 2)`` at most
    ``reach[i] + reach[j]`` apart (crossing, touching or closer), sorted; as :func:`meeting_pairs`."""
    found = []
    for a, b in _boxes_meeting(segs, 2 * float(np.max(reach, initial=0.0))):
        close = segment_distance(segs[a, 0], segs[a, 1], segs[b, 0], segs[b, 1]) <= reach[a] + reach[b]
        found.append(np.sort(np.stack([a[close], b[close]], 1), axis=1))
    pairs = np.concatenate(found) if found else np.zeros((0, 2), int)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _boxes_meeting(segs: np.ndarray, tol: float):
    """Blocks ``(a, b)`` of index pairs of the segments whose bounding boxes meet (up to ``tol``)."""
    lo, hi = segs.min(axis=1), segs.max(axis=1)
    order = np.argsort(lo[:, 0], kind="stable")
    stop = np.searchsorted(lo[order, 0], hi[order, 0] + tol, side="right")
    count = np.maximum(stop - np.arange(len(segs)) - 1, 0)
    total = np.concatenate([[0], np.cumsum(count)])
    k = 0
    while k < len(segs):  # rows k .. e - 1 hold at most PAIR_BLOCK pairs (or one row)
        e = max(k + 1, int(np.searchsorted(total, total[k] + PAIR_BLOCK, side="right")) - 1)
        rows = np.repeat(np.arange(k, e), count[k:e])
        cols = rows + 1 + np.arange(len(rows)) - np.repeat(total[k:e] - total[k], count[k:e])
        a, b = order[rows], order[cols]
        near = np.all((lo[a] <= hi[b] + tol) & (lo[b] <= hi[a] + tol), axis=1)
        yield a[near], b[near]
        k = e


def point_segment_distance(p, a, b):
    """The distance of the points ``p`` to the segments ``a -> b`` (broadcast arrays ``(..., 2)``)."""
    d = b - a
    t = np.clip(np.sum((p - a) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - a - t[..., None] * d, axis=-1)


def segment_distance(a0, a1, b0, b1):
    """The distance between the segments ``a0 -> a1`` and ``b0 -> b1`` (broadcast arrays
    ``(..., 2)``): zero where they cross, else the least of their ends' distances to the other."""
    da, db = a1 - a0, b1 - b0
    cross = (_cross(da, b0 - a0) * _cross(da, b1 - a0) < 0) & (_cross(db, a0 - b0) * _cross(db, a1 - b0) < 0)
    d = np.minimum(np.minimum(point_segment_distance(a0, b0, b1), point_segment_distance(a1, b0, b1)),
                   np.minimum(point_segment_distance(b0, a0, a1), point_segment_distance(b1, a0, a1)))
    return np.where(cross, 0.0, d)


def inside(ring: np.ndarray, p):
    """Whether ``p`` lies inside the closed polyline ``ring`` (even-odd rule); ``p`` one point
    ``(2,)`` (a bool) or many ``(m, 2)`` (a bool array)."""
    q = np.asarray(p, float)
    pts = q.reshape(-1, 1, 2)
    a, b = ring[None], np.roll(ring, -1, axis=0)[None]
    up = (a[..., 1] > pts[..., 1]) != (b[..., 1] > pts[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        x = a[..., 0] + (pts[..., 1] - a[..., 1]) / (b[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0])
    odd = np.count_nonzero(up & (x > pts[..., 0]), axis=1) % 2 == 1
    return bool(odd[0]) if q.ndim == 1 else odd
