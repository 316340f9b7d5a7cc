"""The rest of an outline body as surfaces between cuts, which gmsh meshes side by side. Where
cuts from nodes of the strip's chain reach a straight part of the outline
(:mod:`~cvxdual.geometry.outline.cuts`, through a hole in the way), the rest is meshed as up to
eight surfaces on two threads: gmsh's frontal algorithm costs more a triangle the larger the
surface, so small surfaces on two cores take a third of the time of one surface or less. Each
surface is meshed alone by a fixed algorithm and nodes and triangles are read surface by surface:
the same input gives the same mesh, whatever the threads. A region is ``(outer loop, hole loops)``
of signed curve tags; each curve a cut ends on is split there (in its part too), a hole a cut
runs through gives each side one half, and a cut's straight stretches are lines through their
size stops (:meth:`~cvxdual.geometry.outline.build.OutlineBuild.straight`)."""

from __future__ import annotations

import numpy as np

from ...scene.planar import inside
from .build import OutlineBuild
from .cuts import find_cuts


def cut_regions(build: OutlineBuild) -> list:
    """The regions of the rest, left to right: one (the whole loop with its holes) where no cut fits."""
    b = build
    cuts = find_cuts(b.chain[::b.step], b.body.sign, [b.shape[c] for c in b.loop[:b.n_path]],
                     [[b.shape[c] for c in cs] for cs in b.holes], b.field.at,
                     None if b.cut_columns is None else b.cut_columns[::b.step])
    if not cuts:
        return [(b.loop, b.holes)]
    path, hit_at = _split_path(b, cuts)
    rest = list(b.holes)
    down = [_down(b, c, rest) for c in cuts]
    return _holes_within(b, _between(cuts, b.loop[b.n_path:], path, hit_at, down), rest)


def _split_path(b: OutlineBuild, cuts: list) -> tuple[list, dict]:
    """The outer loop's path with every curve a cut ends on split there (in its part too), and
    for each cut the index in it of the first curve after the cut's end."""
    ends = {}  # curve index in the path -> the cuts ending on it
    for m, c in enumerate(cuts):
        ends.setdefault(c.j, []).append(m)
    path, hit_at = [], {}
    for i, c in enumerate(b.loop[:b.n_path]):
        if i not in ends:
            path.append(c)
            continue
        a = b.shape[c][0][0]
        ms = sorted(ends[i], key=lambda m: float(np.hypot(*(cuts[m].end - a))))
        pts = [b.point(a)] + [b.point(cuts[m].end) for m in ms] + [b.point(b.shape[c][0][1])]
        pieces = [b.line(pts[q], pts[q + 1]) for q in range(len(pts) - 1)]
        for q, m in enumerate(ms):
            hit_at[m] = len(path) + q + 1
        path += pieces
        b.geo.remove([(1, c)])
        for cs in b.part_curves.values():
            if c in cs:
                cs[cs.index(c):cs.index(c) + 1] = pieces
    return path, hit_at


def _down(b: OutlineBuild, c, rest: list) -> tuple[list, list]:
    """Cut ``c`` from its chain node to its end: (with the hole's left half, with its right half);
    a hole it runs through leaves ``rest``."""
    k_pt, h = b.chain_pts[c.k], b.point(c.end)
    if c.hole is None:
        d = b.straight(k_pt, h)
        return d, d
    cs = b.holes[c.hole]
    rest.remove(cs)
    starts = [tuple(b.shape[t][0][0]) for t in cs]
    i1, i2 = starts.index(tuple(c.near)), starts.index(tuple(c.far))
    a = cs[i1:i2] if i1 < i2 else cs[i1:] + cs[:i2]  # near -> far, the hole's own way round
    other = cs[i2:i1] if i2 < i1 else cs[i2:] + cs[:i1]  # far -> near
    back = [-t for t in reversed(other)]  # near -> far, the other way
    # a then other runs round the hole in its own direction, and down the left half then up the
    # right one is counter-clockwise: on a downward cut (a lower body) a is the left half iff
    # the hole runs counter-clockwise, on an upward one iff clockwise. (a's mean x against the
    # cut's end misjudged near and far on opposite sides: a square hole was meshed twice over.)
    hx, hy = b.ring(cs).T
    ccw_hole = float(np.dot(hx, np.roll(hy, -1)) - np.dot(np.roll(hx, -1), hy)) > 0
    a_right = ccw_hole != (c.end[1] < c.far[1])
    leg1, leg2 = b.straight(k_pt, b.point(c.near)), b.straight(b.point(c.far), h)
    left, right = (back, a) if a_right else (a, back)
    return [*leg1, *left, *leg2], [*leg1, *right, *leg2]


def _up(curves: list) -> list:
    return [-t for t in reversed(curves)]


def _between(cuts: list, chain: list, path: list, hit_at: dict, down: list) -> list:
    """The outer loops of the regions: right of the last cut, between each two, left of the first."""
    n = len(cuts)
    regions = [chain[cuts[-1].k:] + path[:hit_at[n - 1]] + _up(down[-1][1])]
    for m in range(n - 1, 0, -1):  # between cut m - 1 and cut m
        regions.append(chain[cuts[m - 1].k:cuts[m].k] + down[m][0] + path[hit_at[m]:hit_at[m - 1]]
                       + _up(down[m - 1][1]))
    regions.append(down[0][0] + path[hit_at[0]:] + chain[:cuts[0].k])
    return regions


def _holes_within(b: OutlineBuild, regions: list, rest: list) -> list:
    """Each region with the holes no cut runs through that lie in it (the last region takes the rest)."""
    out = []
    for r, region in enumerate(regions):
        mine = [cs for cs in rest if r == len(regions) - 1 or inside(b.ring(region), b.shape[cs[0]][0][0])]
        rest = [cs for cs in rest if cs not in mine]
        out.append((region, mine))
    return out
