"""Meshes of outline bodies: the paper's strip of columns along the face, gmsh beyond it.

Along the face of an outline body (:mod:`cvxdual.scene.outline`) the mesh is one layer of the
column mesh (:mod:`cvxdual.geometry.mesh`): face nodes on the global columns, so both bodies'
contact nodes pair on vertical lines and the curved pieces of both triangulations are built as
for column bodies. The layer's inner side is a chain of nodes at depth ``t_i`` (the local column
spacing) below (or above) the face. The rest of the body, between that chain and the outline, is
meshed by gmsh (its Python API, in gmsh's own process: :mod:`~cvxdual.geometry.gmsh_fence`)
conforming to the chain: one geometry point per chain node and two-node transfinite lines
between them, so gmsh adds no node on the chain and keeps the given coordinates bit for bit.

Sizes (:mod:`~cvxdual.geometry.outline_sizes`): the chain's spacing and the arcs' edges
(``4 * 2**level`` a quarter turn), growing with the distance from them by ``0.4 / 2**level``, up
to twice the coarsest column spacing; every size halves a level, so ``--level`` halves the mesh
everywhere. gmsh reads sizes at geometry points only: the outline's, stops along the cut lines
and rings of points round the arcs embedded in the surfaces.

Since the sizes halve a level, level ``L >= 1`` is gmsh's mesh at the sizes of level ``L - 1``
refined once (:mod:`~cvxdual.geometry.refine`): gmsh gets every other node of the chain and of
each fixed polygon (a free arc's, a spline's) as two-node lines, and refinement puts the other
nodes on them (a hole's tangent corners on its chords, the arcs' vertices on the circle), so
the refined mesh conforms to the strip of level ``L`` and keeps every polygon of level ``L``;
the strip's sides stay whole. gmsh makes a quarter of the triangles: 0.22 s instead of 0.73 s
for block-with-hole's lower body at level 4 (86k triangles).

Where cuts from nodes of the chain reach a straight part of the outline
(:mod:`~cvxdual.geometry.outline_cut`, through a hole in the way), the rest is meshed as up to
eight surfaces on two threads: gmsh's frontal algorithm costs more a triangle the larger the
surface, so small surfaces on two cores take a third of the time of one surface or less. Each
surface is meshed alone by a fixed algorithm and nodes and triangles are read surface by surface:
the same input gives the same mesh, whatever the threads.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..errors import MeshError
from ..scene.planar import inside, segments_meet
from .gmsh_fence import in_gmsh
from .gmsh_worker import import_gmsh
from .outline_arcs import clash_message, continuation, first_clash, free_arc, gmsh_arc, match_rows
from .outline_cut import find_cuts
from .outline_sizes import STRIP_ASPECT, SizeField, graded_stops, steering, strip_depth
from .refine import FoldError, refine
from .triangles import doubled_areas

SPLINE_SAMPLES = 256  # points a stretch of a spline is sampled at before thinning to the sizes
ALGORITHM = 6  # gmsh's Frontal-Delaunay: the best-shaped triangles of its 2D algorithms
SMALL = 64  # bodies with at most this many columns are meshed on one thread (0.1 s to start a second, seen)


def mesh_threads() -> int:
    """gmsh's threads: one per surface (at most two), within ``OMP_NUM_THREADS`` when it is set
    (the studies run each case on one thread)."""
    limit = os.environ.get("OMP_NUM_THREADS", "")
    return max(1, min(2, int(limit) if limit.isdigit() else (os.cpu_count() or 1)))


def held_parts(body) -> set[str]:
    """The outline parts a support or a nonzero load acts on (the rest is traction free)."""
    return {bp.on for bp in body.boundary
            if bp.kind != "traction" or bp.traction.kind != "uniform" or any(bp.traction.value)}


@dataclass(frozen=True)
class RestMesh:
    """The gmsh part of an outline body's mesh, in the body's local node numbering (strip node
    ``(i, j)`` is ``2 i + j``, gmsh's own nodes follow from ``2 n_columns``): ``points`` the new
    nodes, ``triangles`` counter-clockwise, ``parts`` every outline part's nodes in path order."""

    points: np.ndarray
    triangles: np.ndarray
    parts: dict
    virtual_nodes: np.ndarray  # (m, 3): the P1 function continued beyond a free arc (outline_arcs.free_arc)
    virtual_weight: np.ndarray  # (m,): the area it covers


def mesh_rest(body, columns: np.ndarray, inner_y: np.ndarray, level: int) -> RestMesh:
    """Mesh the body between the strip's inner chain ``(columns, inner_y)`` and its outline.

    The last eight meshes are kept (read-only arrays): the size estimate meshes a small level in
    full (:func:`cvxdual.geometry.mesh.mesh_size`) and the fast path's warm start meshes coarse
    levels; a run of two bodies meets each of them again."""
    columns, inner_y = np.asarray(columns, float), np.asarray(inner_y, float)
    return _cached(body, columns.tobytes(), inner_y.tobytes(), int(level))


def forget_meshes() -> None:
    """Drop the kept meshes (a timing that must include gmsh's work)."""
    _cached.cache_clear()


_SPENT = [0.0]  # seconds spent meshing with gmsh in this process (studies' timings)


def gmsh_seconds() -> float:
    """Wall time spent meshing outline bodies (gmsh, reading its mesh and refining it) in this process so far:
    a run's share is the difference of two readings over the run's own time."""
    return _SPENT[0]


@lru_cache(maxsize=8)
def _cached(body, columns: bytes, inner_y: bytes, level: int) -> RestMesh:
    t = time.perf_counter()
    try:
        rest = in_gmsh("cvxdual.geometry.outline_mesh:gmsh_mesh", body, np.frombuffer(columns),
                       np.frombuffer(inner_y), level, what=f"meshing body {body.name!r} at level {level}")
    finally:
        _SPENT[0] += time.perf_counter() - t
    for a in (rest.points, rest.triangles, rest.virtual_nodes, rest.virtual_weight, *rest.parts.values()):
        a.flags.writeable = False
    return rest


def gmsh_mesh(body, columns: np.ndarray, inner_y: np.ndarray, level: int) -> RestMesh:
    """:func:`mesh_rest`'s work, done by gmsh: runs in gmsh's own process (:mod:`~cvxdual.geometry.gmsh_fence`)."""
    gmsh = import_gmsh()
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        return _mesh(gmsh, body, columns, inner_y, level)
    except MeshError:
        raise
    except Exception as e:  # gmsh reports its failures as plain exceptions
        raise MeshError(f"gmsh could not mesh body {body.name!r} at level {level} ({e}); check its outline "
                        "(parts very close to the face, or to each other) or change the level") from None
    finally:
        gmsh.finalize()


def _mesh(gmsh, body, columns, inner_y, level, halved=True) -> RestMesh:
    geo = gmsh.model.geo
    gmsh.model.add(body.name)
    nc = len(columns)
    face_y = body.face.value(columns)
    chain = np.stack([columns, inner_y], 1)
    # level >= 1: gmsh meshes at the sizes of level - 1 through every other chain node, refined once
    # (not ``halved``: at level's own sizes through every node, when the polygons of level - 1 clash)
    step, glevel = (2, level - 1) if level >= 1 and halved else (1, level)
    cols = columns[::step]
    w = strip_depth(cols) / STRIP_ASPECT
    side = strip_depth(columns)  # the strip's sides are kept whole: their ends get their length as size
    field = SizeField.of(body, cols, inner_y[::step], glevel)
    fine = SizeField.of(body, columns, inner_y, level) if step > 1 else field
    cap = field.cap

    def size(p) -> float:
        return float(field.at(np.array([p], float))[0])

    points: dict[tuple, int] = {}  # geometry points by coordinates: shared ends are one point
    where: dict[int, tuple] = {}  # and their coordinates by tag
    sizes: dict[int, float] = {}  # the smallest size any curve asks of a point

    def point(p, lc=None) -> int:
        key = (float(p[0]), float(p[1]))
        lc = size(key) if lc is None else lc
        if key not in points:
            points[key] = geo.addPoint(key[0], key[1], 0.0, lc)
            where[points[key]] = key
        tag = points[key]
        sizes[tag] = min(lc, sizes.get(tag, math.inf))
        return tag

    fixed = []  # two-node lines: the strip's edges, the free arcs' polygons, splines
    shape: dict[int, tuple] = {}  # every curve's polyline (a line's two ends) and whether a cut may split it
    mids: dict[int, tuple] = {}  # a two-node line's new node on refinement (the fine polygon's), None: kept whole

    def line(a, b, keep=False, mid=False) -> int:  # mid: as in ``mids``; False: halved at its midpoint
        c = geo.addLine(a, b)
        shape[c] = (np.array([where[a], where[b]]), not keep)
        if keep:
            fixed.append(c)
        if mid is not False:
            mids[c] = mid
        return c

    def polyline(pts, lc=None) -> list[int]:
        """Two-node lines through the fine polygon ``pts``: every other vertex for gmsh, the rest
        placed on refinement (the last line is halved at its midpoint if the count is odd)."""
        ids = [point(q, lc) for q in pts[::step]]
        if step > 1 and (len(pts) - 1) % 2:
            ids.append(point(pts[-1], lc))
        odd = [tuple(q) for q in pts[1:-1:2]] if step > 1 else []
        return [line(ids[j], ids[j + 1], keep=True, mid=odd[j] if j < len(odd) and step > 1 else False)
                for j in range(len(ids) - 1)]

    _check_strip(body, chain)
    chain_pts = [point(chain[i], w[k]) for k, i in enumerate(range(0, nc, step))]
    ends = {"right": (body.x_range[1], float(face_y[-1])), "left": (body.x_range[0], float(face_y[0]))}
    loop: list[int] = []  # signed curve tags of the outer loop, from the right end of the chain
    part_curves: dict[str, list[int]] = {}
    path = [(p.name, s) for p in body.outline.path for s in p.segments]
    # the path's ends are the face's ends exactly (the outline check allows rounding)
    path[0] = (path[0][0], replace(path[0][1], start=ends["right"]))
    path[-1] = (path[-1][0], replace(path[-1][1], end=ends["left"]))
    first_name, first = path[0]
    last_name, last = path[-1]
    start_pt = chain_pts[-1]
    if _continues_side(first, ends["right"], chain[-1], body.sign):
        path[0] = (first_name, replace(first, start=tuple(chain[-1])))
        part_curves[first_name] = [("strip", nc - 1)]
    else:  # the strip's side: not halved (the strip's own mesh does not split it)
        loop.append(line(start_pt, point(ends["right"], side[-1]), keep=True, mid=None))
    trim_last = _continues_side(last, ends["left"], chain[0], body.sign, at_end=True)
    if trim_last:
        path[-1] = (last_name, replace(last, end=tuple(chain[0])))
    loaded = held_parts(body)
    virtual = {"corner": [], "segment": [], "segment_area": []}  # the free arcs' pieces (outline_arcs.free_arc)
    arc_of: dict[int, tuple] = {}  # gmsh's arcs (loaded or supported): centre and radius

    def curve(name, s, concave) -> list[int]:
        if s.is_spline:  # a polygon through points of the spline, as fine as the sizes there
            pts = s.sample(SPLINE_SAMPLES)
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
            n = max(1, math.ceil(arc[-1] / float(fine.at(pts).min())))  # equal stretches no longer than the size
            keep = np.unique(np.searchsorted(arc, arc[-1] * np.arange(1, n) / n))
            pts = np.concatenate([pts[:1], pts[keep[(keep > 0) & (keep < len(pts) - 1)]], pts[-1:]])
            if step == 1:
                ids = [point(q) for q in pts]
                return [line(ids[j], ids[j + 1]) for j in range(len(ids) - 1)]
            return polyline(pts)
        if not s.is_arc:
            return [line(point(s.start), point(s.end))]
        if name in loaded:  # a supported or loaded arc: gmsh's polygon of it (not certified)
            c = gmsh_arc(geo, point, s, glevel, size)
            shape[c] = (s.sample(64), False)
            arc_of[c] = (np.asarray(s.center, float), math.dist(s.start, s.center))
            return [c]
        return free_arc(s, concave, level, step, point, line, polyline, virtual)

    ccw = body.position == "upper"  # the path runs counter-clockwise round an upper body
    for name, s in path:
        cs = curve(name, s, s.is_arc and (s.angles()[1] > 0) != ccw)
        loop += cs
        part_curves.setdefault(name, []).extend(cs)
    if trim_last:
        part_curves[last_name].append(("strip", 0))
    else:
        loop.append(line(point(ends["left"], side[0]), chain_pts[0], keep=True, mid=None))
    n_path = len(loop)
    for k in range(len(chain_pts) - 1):
        loop.append(line(chain_pts[k], chain_pts[k + 1], keep=True,
                         mid=tuple(chain[step * k + 1]) if step > 1 else False))
    holes = []
    for h in body.outline.holes:
        cs = [c for s in h.segments for c in curve(h.name, s, True)]  # the body lies outside its holes
        part_curves[h.name] = cs
        holes.append(cs)
    # the polygons must bound one region, at this level (else refused) and as gmsh gets them (else
    # meshed at this level directly): a part closer to a curve than its chords are (outline_arcs)
    label = {c: name for name, cs in part_curves.items() for c in cs if not isinstance(c, tuple)}
    rings = [loop] + holes
    owners = [[label.get(c) for c in r] for r in rings]  # None: the strip's chain and sides

    def at_level(c) -> np.ndarray:  # the curve's polyline at this level: with the node refinement puts on it
        p = shape[c][0]
        return p if mids.get(c) is None else np.array([p[0], mids[c], p[-1]])

    clash = first_clash([[at_level(c) for c in r] for r in rings], owners)
    if clash:
        def polygon(name):
            return np.concatenate([at_level(c) for r, o in zip(rings, owners, strict=True)
                                   for c, n in zip(r, o, strict=True) if n == name])
        raise MeshError(clash_message(body, level, *clash, polygon, chain))
    if step > 1 and first_clash([[shape[c][0] for c in r] for r in rings], owners):
        gmsh.model.remove()
        return _mesh(gmsh, body, columns, inner_y, level, halved=False)
    cuts = find_cuts(chain[::step], body.sign, [shape[c] for c in loop[:n_path]],
                     [[shape[c] for c in cs] for cs in holes], field.at)

    def ring(curves) -> np.ndarray:
        return np.concatenate([shape[abs(t)][0][::1 if t > 0 else -1] for t in curves])

    def straight(a, b) -> list[int]:  # a line cut through the body, with its size stops (graded_stops)
        stops, lc = graded_stops(where[a], where[b], field)
        ids = [a, *(point(q, float(s)) for q, s in zip(stops, lc, strict=True)), b]
        return [line(ids[j], ids[j + 1]) for j in range(len(ids) - 1)]

    if not cuts:
        regions = [(loop, holes)]
    else:
        regions = _surfaces(geo, cuts, loop, n_path, chain_pts, holes, shape, part_curves, point, line, straight, ring)
    surfaces = [geo.addPlaneSurface([geo.addCurveLoop(outer)] + [geo.addCurveLoop(cs) for cs in inner])
                for outer, inner in regions]
    steer = steering(body, field, glevel, [(ring(outer), [ring(cs) for cs in inner]) for outer, inner in regions],
                     np.concatenate([np.stack([p[:-1], p[1:]], 1) for p, _ in shape.values()]))
    embedded = [[point(q, float(lc)) for q, lc in zip(pts, lcs, strict=True)] for pts, lcs in steer]
    for tag, lc in sizes.items():
        geo.mesh.setSize([(0, tag)], lc)
    geo.synchronize()
    for r, tags in enumerate(embedded):
        if tags:
            gmsh.model.mesh.embed(0, tags, 2, surfaces[r])
    for c in fixed:
        gmsh.model.mesh.setTransfiniteCurve(c, 2)
    threads = mesh_threads() if len(chain_pts) > SMALL else 1  # a second thread's start costs more than a small mesh
    for name, value in (("Mesh.Algorithm", ALGORITHM), ("Mesh.MeshSizeExtendFromBoundary", 1),
                        ("Mesh.MeshSizeFromPoints", 1), ("Mesh.MeshSizeFromCurvature", 0),
                        ("Mesh.MeshSizeMax", cap), ("General.NumThreads", threads), ("Mesh.MaxNumThreads1D", 1),
                        ("Mesh.MaxNumThreads2D", threads), ("Mesh.MaxRetries", 3),
                        # no smoothing pass: 40 % of gmsh's time for 1.5 % of hertz's error (reports/outlines.md)
                        ("Mesh.Smoothing", 0)):
        gmsh.option.setNumber(name, value)
    gmsh.model.mesh.generate(2)
    tags, xyz, _ = gmsh.model.mesh.getNodes()
    xy = xyz.reshape(-1, 3)[:, :2]
    row = np.full(int(tags.max()) + 1, -1)
    row[tags] = np.arange(len(tags))  # gmsh's node tag -> its row of xy
    _, tri_nodes = gmsh.model.mesh.getElementsByType(2)
    tris = row[np.asarray(tri_nodes, np.int64).reshape(-1, 3)]
    wanted = sorted({c for cs in part_curves.values() for c in cs if not isinstance(c, tuple)} | set(arc_of))
    two = set(fixed)  # two-node lines: their ends found by coordinates, gmsh asked only for the others
    ends = match_rows(np.concatenate([shape[c][0] for c in wanted if c in two] or [np.zeros((0, 2))]), xy)
    curve_nodes = dict(zip([c for c in wanted if c in two], ends.reshape(-1, 2), strict=True))  # rows of xy
    for c in (c for c in wanted if c not in two):
        _, en = gmsh.model.mesh.getElementsByType(1, c)
        curve_nodes[c] = row[_ordered(np.asarray(en, np.int64).reshape(-1, 2), c)]
    if np.any(tris < 0) or not len(tris):
        raise MeshError(f"gmsh gave no usable mesh of body {body.name!r}")  # pragma: no cover - gmsh contract
    if step > 1:
        try:
            xy, tris, curve_nodes = _refined(xy, tris, curve_nodes, mids, arc_of, shape)
        except FoldError:  # a fine node crosses gmsh's coarser triangle: mesh at this level's sizes instead
            gmsh.model.remove()
            return _mesh(gmsh, body, columns, inner_y, level, halved=False)
    # the mesh's nodes on the chain are the strip's inner nodes (i, 1); at the face ends also (i, 0)
    known = np.concatenate([chain, [[columns[0], face_y[0]], [columns[-1], face_y[-1]]]])
    known_idx = np.concatenate([2 * np.arange(nc) + 1, [0, 2 * nc - 2]])
    hit = match_rows(xy, known)
    idx = np.where(hit >= 0, known_idx[np.maximum(hit, 0)], -1)
    new = idx < 0
    idx[new] = 2 * nc + np.arange(int(new.sum()))
    tris = idx[tris]
    allp = np.concatenate([np.zeros((2 * nc, 2)), xy[new]])
    allp[idx[~new]] = xy[~new]
    cw = doubled_areas(allp, tris) < 0
    tris[cw] = tris[cw][:, ::-1]  # counter-clockwise, as every triangle of the package
    parts = {}
    for name, curves in part_curves.items():
        chainp = []
        for c in curves:
            if isinstance(c, tuple):  # the strip's side: face node then inner node at that column
                i = c[1]
                seg = [2 * i, 2 * i + 1] if i == nc - 1 else [2 * i + 1, 2 * i]
            else:
                seg = idx[curve_nodes[c]].tolist()
            chainp = seg if not chainp else chainp + seg[1:]
        parts[name] = np.asarray(chainp)
    vn, vw = continuation(virtual, xy, idx, tris, allp)
    return RestMesh(points=xy[new], triangles=tris, parts=parts, virtual_nodes=vn, virtual_weight=vw)


def _refined(xy, tris, curve_nodes, mids, arc_of, shape):
    """gmsh's mesh at the sizes of the level below, refined once (:mod:`~cvxdual.geometry.refine`):
    the two-node lines' new nodes at the fine polygon's vertices (``mids``; ``None`` keeps the
    line whole), the new nodes of gmsh's arcs on the arc; every curve's node path refined too."""
    lines = list(mids)
    ends = match_rows(np.concatenate([shape[c][0] for c in lines]), xy).reshape(-1, 2)  # by coordinates
    keep = np.array([mids[c] is None for c in lines])
    whole, moved = ends[keep], list(ends[~keep])
    to = [mids[c] for c in lines if mids[c] is not None]
    for c, (centre, r) in arc_of.items():
        ns = curve_nodes[c]
        mid = 0.5 * (xy[ns[:-1]] + xy[ns[1:]]) - centre
        moved += list(zip(ns[:-1], ns[1:], strict=True))
        to += list(centre + r * mid / np.linalg.norm(mid, axis=1)[:, None])
    ref = refine(xy, tris, whole, moved, to)
    return ref.points, ref.triangles, ref.chains(curve_nodes)


def _surfaces(geo, cuts, loop, n_path, chain_pts, holes, shape, part_curves, point, line, straight, ring) -> list:
    """The rest as regions between ``cuts`` (left to right, :mod:`~cvxdual.geometry.outline_cut`),
    each ``(outer loop, hole loops)``: ``loop`` is the outer loop (``n_path`` curves of the outline,
    from the chain's right end round to its left end, then the chain's), each curve a cut ends on is
    split there (in its part too), a hole a cut runs through gives each side one half; a cut's
    straight stretches are ``straight(a, b)`` (lines through their size stops)."""
    def at(p) -> int:
        return point(tuple(map(float, p)))

    ends = {}  # curve index in the path -> the cuts ending on it
    for m, c in enumerate(cuts):
        ends.setdefault(c.j, []).append(m)
    path, hit_at = [], {}
    for i, c in enumerate(loop[:n_path]):
        if i not in ends:
            path.append(c)
            continue
        a = shape[c][0][0]
        ms = sorted(ends[i], key=lambda m: float(np.hypot(*(cuts[m].end - a))))
        pts = [at(a)] + [at(cuts[m].end) for m in ms] + [at(shape[c][0][1])]
        pieces = [line(pts[q], pts[q + 1]) for q in range(len(pts) - 1)]
        for q, m in enumerate(ms):
            hit_at[m] = len(path) + q + 1  # the first curve after the cut's end
        path += pieces
        geo.remove([(1, c)])
        for cs in part_curves.values():
            if c in cs:
                cs[cs.index(c):cs.index(c) + 1] = pieces
    chain = loop[n_path:]
    rest = list(holes)
    down = []  # each cut from its chain node to its end: (with the hole's left half, with its right half)
    for c in cuts:
        k_pt, h = chain_pts[c.k], at(c.end)
        if c.hole is None:
            d = straight(k_pt, h)
            down.append((d, d))
            continue
        cs = holes[c.hole]
        rest.remove(cs)
        starts = [tuple(shape[t][0][0]) for t in cs]
        i1, i2 = starts.index(tuple(c.near)), starts.index(tuple(c.far))
        a = cs[i1:i2] if i1 < i2 else cs[i1:] + cs[:i2]  # near -> far, the hole's own way round
        b = cs[i2:i1] if i2 < i1 else cs[i2:] + cs[:i1]  # far -> near
        back_b = [-t for t in reversed(b)]  # near -> far, the other way
        # a then b runs round the hole in its own direction, and down the left half then up the
        # right one is counter-clockwise: on a downward cut (a lower body) a is the left half iff
        # the hole runs counter-clockwise, on an upward one iff clockwise. (a's mean x against the
        # cut's end misjudged near and far on opposite sides: a square hole was meshed twice over.)
        hx, hy = ring(cs).T
        ccw_hole = float(np.dot(hx, np.roll(hy, -1)) - np.dot(np.roll(hx, -1), hy)) > 0
        a_right = ccw_hole != (c.end[1] < c.far[1])
        leg1, leg2 = straight(k_pt, at(c.near)), straight(at(c.far), h)
        left, right = (back_b, a) if a_right else (a, back_b)
        down.append(([*leg1, *left, *leg2], [*leg1, *right, *leg2]))

    def up(curves):
        return [-t for t in reversed(curves)]

    n = len(cuts)
    regions = [chain[cuts[-1].k:] + path[:hit_at[n - 1]] + up(down[-1][1])]  # right of the last cut
    for m in range(n - 1, 0, -1):  # between cut m - 1 and cut m
        regions.append(chain[cuts[m - 1].k:cuts[m].k] + down[m][0] + path[hit_at[m]:hit_at[m - 1]]
                       + up(down[m - 1][1]))
    regions.append(down[0][0] + path[hit_at[0]:] + chain[:cuts[0].k])  # left of the first cut
    out = []
    for r, region in enumerate(regions):
        mine = [cs for cs in rest if r == len(regions) - 1 or inside(ring(region), shape[cs[0]][0][0])]
        rest = [cs for cs in rest if cs not in mine]
        out.append((region, mine))
    return out


def _check_strip(body, chain: np.ndarray) -> None:
    """No outline part may cross the strip's inner chain or lie inside the strip (between the
    face and the chain): gmsh would fail, or mesh across the strip."""
    a0, a1 = chain[:-1].copy(), chain[1:].copy()
    a0[0] += 1e-6 * (a1[0] - a0[0])  # the chain's ends may lie on a side of the outline
    a1[-1] -= 1e-6 * (a1[-1] - a0[-1])
    scale = float(np.ptp(chain, axis=0).max())
    tol = 1e-9 * scale  # parts that run along the strip's sides lie on its boundary, to rounding
    x0, x1 = chain[0, 0], chain[-1, 0]
    for p in body.outline.parts:
        pts = np.concatenate([s.sample(64) if s.is_arc else
                              np.linspace(s.start, s.end, 65) for s in p.segments])
        x, y = pts[:, 0], pts[:, 1]
        band = (x > x0 + tol) & (x < x1 - tol)
        xc = np.clip(x, x0, x1)
        below_face = body.sign * (y - body.face.value(xc)) > tol  # on the body's side of the face
        above_chain = body.sign * (np.interp(xc, chain[:, 0], chain[:, 1]) - y) > tol  # not past the chain
        inside = band & below_face & above_chain
        # a corner of the outline on a side of the strip, past the face and up to the chain (a part
        # along the side shorter than the strip is deep): the strip would cover body and void alike
        for xs, yc in ((x0, chain[0, 1]), (x1, chain[-1, 1])):
            q = np.array([v for sg in p.segments for v in (sg.start, sg.end)])
            yf = float(body.face.value(xs))
            inside |= np.any((np.abs(q[:, 0] - xs) <= tol) & (body.sign * (q[:, 1] - yf) > tol)
                             & (body.sign * (yc - q[:, 1]) > -tol))
        if np.any(segments_meet(a0, a1, pts[:-1], pts[1:], 1e-12 * scale)) or np.any(inside):
            raise MeshError(f"body {body.name!r}: the strip of columns along its face (one column spacing deep, "
                            f"{abs(chain[:, 1] - body.face.value(chain[:, 0])).max():.3g} at most here) meets the "
                            f"outline part {p.name!r}; raise the level (the strip thins with h) or move {p.name!r} "
                            "away from the face")


def _ordered(e: np.ndarray, curve: int) -> list:
    """Node chain of a meshed curve from its line elements ``(m, 2)`` (gmsh gives them in order)."""
    if len(e) > 1 and e[0, 1] != e[1, 0]:
        raise MeshError(f"internal: gmsh's edges of curve {curve} are not in order")  # pragma: no cover
    return [int(e[0, 0]), *map(int, e[:, 1])]


def _continues_side(seg, end, inner, sign, at_end=False) -> bool:
    """Whether the outline's segment at a face end runs along the strip's side: a vertical line
    leaving the face end away from the face, longer than the strip is deep."""
    if seg.is_arc or seg.axis != "y":
        return False
    far = seg.start if at_end else seg.end
    depth = abs(inner[1] - end[1])
    return sign * (far[1] - end[1]) > depth * (1 + 1e-9)
