"""Curved parts of an outline body's mesh: a free arc's exact polygon and the pieces beyond it
(section 9 of docs/theory.md), a gmsh arc for a loaded or supported one, and finding mesh nodes
by their coordinates (how gmsh's nodes are matched to the points cvxdual placed)."""

from __future__ import annotations

import math

import numpy as np

from .outline_sizes import arc_edges, arc_size
from .triangles import doubled_areas, edge_keys


def match_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For each row of ``a`` ``(m, 2)``, the index of the bit-identical row of ``b``, or -1."""
    # rows as complex numbers: numpy sorts those by real then imaginary part, and fast
    av = np.ascontiguousarray(a, float).view(np.complex128).ravel()
    bv = np.ascontiguousarray(b, float).view(np.complex128).ravel()
    order = np.argsort(bv)
    pos = np.clip(np.searchsorted(bv[order], av), 0, len(bv) - 1)
    return np.where(bv[order][pos] == av, order[pos], -1)


def free_arc(s, concave, level, step, point, line, polyline, virtual) -> list[int]:
    """A traction-free arc as a polygon inside the body (section 9 of docs/theory.md): chords of
    a convex arc, or, round a concave one (a hole), the tangents at the chords' ends. The pieces of
    the body beyond it (segments, or the tangent polygon's corners) carry zero stress; the
    displacement continues there as a P1 function, recorded in ``virtual`` for the energy bound:
    the adjacent triangle's polynomial on a segment (``"segment"``: the chord's ends, and
    ``"segment_area"``), or the interpolant on the triangle of a corner (``"corner"``). The polygon
    is the one of ``level``; meshed at the level below (``step`` 2), gmsh gets every other vertex
    of it and refinement places the rest."""
    a0, sweep = s.angles()
    r = math.dist(s.start, s.center)
    n = arc_edges(s, level)
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
        return polyline(np.array(on), lc)
    rv = r / math.cos(0.5 * d)
    corners = [tuple(c + rv * np.array([math.cos(q + 0.5 * d), math.sin(q + 0.5 * d)])) for q in t[:-1]]
    virtual["corner"] += [(on[j], corners[j], on[j + 1]) for j in range(n)]
    ids = [point(q, lc) for q in on]
    if step > 1:  # gmsh meshes the chords; refinement puts the corners on them
        return [line(ids[j], ids[j + 1], keep=True, mid=corners[j]) for j in range(n)]
    curves = []
    for j in range(n):
        v = point(corners[j], lc)
        curves += [line(ids[j], v, keep=True), line(v, ids[j + 1], keep=True)]
    return curves


def continuation(virtual: dict, xy: np.ndarray, idx: np.ndarray, tris: np.ndarray, allp: np.ndarray):
    """Node triples and area weights of the free arcs' continuation pieces (:func:`free_arc`):
    their points found among gmsh's nodes ``xy`` (local indices ``idx``) by their coordinates."""
    corner = np.asarray(virtual["corner"], float).reshape(-1, 3, 2)
    chord = np.asarray(virtual["segment"], float).reshape(-1, 2, 2)
    if not len(corner) + len(chord):
        return np.zeros((0, 3), int), np.zeros(0)
    c_nodes = idx[match_rows(corner.reshape(-1, 2), xy)].reshape(-1, 3)
    c_area = 0.5 * np.abs(doubled_areas(allp, c_nodes))
    # the triangle on each chord: its edge key among the edges of the triangles at the chords' ends
    n = int(tris.max()) + 1
    ends = np.sort(idx[match_rows(chord.reshape(-1, 2), xy)].reshape(-1, 2), axis=1)
    near = np.flatnonzero(np.isin(tris, ends).any(axis=1))
    keys = edge_keys(tris[near], np.roll(tris[near], -1, axis=1), n).ravel()  # edge j of triangle i at 3 i + j
    order = np.argsort(keys)
    t = near[order[np.searchsorted(keys[order], edge_keys(ends[:, 0], ends[:, 1], n))] // 3]
    return (np.concatenate([c_nodes, tris[t]]).astype(int),
            np.concatenate([c_area, np.asarray(virtual["segment_area"], float)]))


def gmsh_arc(geo, point, s, level, size) -> int:
    lc = arc_size(s, level)
    a = point(s.start, min(size(s.start), lc))
    b = point(s.end, min(size(s.end), lc))
    c = point(s.center, lc)
    return geo.addCircleArc(a, c, b)
