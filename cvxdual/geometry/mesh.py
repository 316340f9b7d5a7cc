"""Structured "column" meshes of the two bodies.

Every vertex lies on a vertical line ``x = x_i`` of one global set of columns, so the face
nodes of both bodies are paired across the gap on the contact interval (the paper's
requirement that contact nodes lie on lines parallel to the xi axis). Along a column the
vertices run from the face (layer 0) to the far side; each quad is split into two triangles,
so that the triangle with two face nodes has a vertical side (the paper's rule for
non-convex curved triangles).

Refinement is by level: the columns and layers of level ``L`` are those of level 0 split
``2**L`` times in a fixed graded map, so ``h`` halves per level and meshes are nested.

Array conventions: ``points`` is ``(n_nodes, 2)``; triangles are ``(n_tri, 3)`` node indices,
counter-clockwise; node ``(i, j)`` (column ``i``, layer ``j``) of a body has index
``offset + i * (n_layers + 1) + j``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import MeshError
from ..kinds import Meshed
from ..progress import log
from ..records import MeshSize
from ..scene.scene import Body, Scene
from ..validate import short
from .mesh_check import check_body_mesh
from .outline import ContinuationRule, RestMesh, continuation_rule, held_parts, mesh_rest, refine_in_place, strip_depth
from .triangles import edge_lengths

MAX_COUNTED_COLUMNS = 1e12  # beyond this, an outline body is counted by its strip alone (already too large)
PROBE_COLUMNS = 32  # outline bodies are counted on a mesh of at most this many columns, scaled up (0.01-0.06 s)
_MAP_SAMPLES = 8001  # resolution of the numerically inverted grading map (sizes vary smoothly)


def grading_map(x0: float, x1: float, focus: tuple[float, float] | None, ratio: float):
    """Return ``xi(x)`` on a fine grid: the normalised integral of ``1 / size(x)``.

    The target element size is 1 inside ``focus`` and grows linearly with the distance ``d``
    from it, ``1 + d / l``, up to ``ratio``; ``l`` is the focus width (or a tenth of the
    interval for a point focus), so the size at most doubles over one focus width.
    """
    xs = np.linspace(x0, x1, _MAP_SAMPLES)
    if focus is None or ratio == 1.0:
        return xs, (xs - x0) / (x1 - x0)
    lo, hi = focus
    ell = max(hi - lo, 0.1 * (x1 - x0))
    d = np.maximum(np.maximum(lo - xs, xs - hi), 0.0)
    size = np.minimum(1.0 + d / ell, ratio)
    dens = 1.0 / size
    xi = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(xs))])
    return xs, xi / xi[-1]


def graded_points(x0: float, x1: float, n0: int, level: int, focus=None, ratio: float = 1.0,
                  required=()) -> np.ndarray:
    """Points ``x0 = p_0 < ... < p_n = x1`` graded by :func:`grading_map`.

    ``required`` points become break points: each stretch between break points gets
    ``max(1, round(n0 * its share of xi)) * 2**level`` intervals, uniform in ``xi``, so that
    every level is a refinement of the previous one and required points are always nodes.
    """
    brk, xib, counts, (xs, xi) = _stretches(x0, x1, n0, focus, ratio, required)
    pts = [brk[:1]]
    for k in range(len(brk) - 1):
        m = int(counts[k]) * 2**level
        t = np.linspace(xib[k], xib[k + 1], m + 1)[1:]
        pts.append(np.interp(t, xi, xs))
        pts[-1][-1] = brk[k + 1]
    return np.concatenate(pts)


def _stretches(x0, x1, n0, focus, ratio, required):
    """Break points, their graded parameters and the level-0 interval count of each stretch."""
    xs, xi = grading_map(x0, x1, focus, ratio)
    brk = np.unique(np.clip(np.concatenate([[x0, x1], np.asarray(required, float)]), x0, x1))
    xib = np.interp(brk, xs, xi)
    counts = np.maximum(1.0, np.round(float(n0) * np.diff(xib)))  # floats: a hostile n0 must not wrap around
    return brk, xib, counts, (xs, xi)


# break points closer than this share of the scene's width, but not equal, are refused: a column
# a few ulps wide (bodies' ends typed as 12.095145599881887 and ...889) cannot pair its nodes
BREAK_RESOLUTION = 1e-9


def _required(scene: Scene, extra) -> list:
    """The break points of the global columns: body ends, the contact interval's ends, the
    focus ends and ``extra``; two that differ by less than :data:`BREAK_RESOLUTION` of the
    scene's width are refused, naming both."""
    named = [*((v, f"the end of body {b.name!r}") for b in scene.bodies for v in b.x_range),
             *((v, "the contact interval's end") for v in scene.contact),
             *((v, "the focus's end") for v in (scene.mesh.focus or ())),
             *((float(v), "a face's break or a boundary interval's end") for v in extra)]
    x, first = np.unique(np.array([v for v, _ in named], float), return_index=True)  # each named where first met
    x0, x1 = scene.x_extent
    close = np.flatnonzero(np.diff(x) < BREAK_RESOLUTION * (x1 - x0))
    if len(close):
        (a, wa), (b, wb) = (named[first[close[0] + i]] for i in (0, 1))
        raise MeshError(f"{wa} x = {a!r} and {wb} x = {b!r} are {b - a:.2g} apart: too close for two mesh "
                        "columns; make them equal")
    return [v for v, _ in named]


def mesh_size(scene: Scene, level: int, extra=()) -> MeshSize:
    """Triangles and nodes of the mesh of ``scene`` at ``level`` with the break points ``extra``
    (as :func:`column_abscissae`), counted without building it (floats: a hostile level must
    give a huge count, not an allocation or an overflow)."""
    x0, x1 = scene.x_extent
    spec = scene.mesh
    brk, _, counts, _ = _stretches(x0, x1, spec.columns, spec.focus, spec.grading, _required(scene, extra))
    scale = 2.0**level if level < 1000 else np.inf  # a hostile level: an infinite count, not an error
    n_tri = n_nodes = 0.0
    for body in scene.bodies:
        inside = (brk[:-1] >= body.x_range[0]) & (brk[1:] <= body.x_range[1])
        cols, layers = float(counts[inside].sum()) * scale, float(body.layers) * scale
        if body.is_column:
            n_tri += 2.0 * cols * layers
            n_nodes += (cols + 1.0) * (layers + 1.0)
            continue
        if not cols <= MAX_COUNTED_COLUMNS:  # more columns than any mesh that fits: the strip alone says so
            n_tri, n_nodes = n_tri + 2.0 * cols, n_nodes + 2.0 * (cols + 1.0)
            continue
        rest = _probe_rest(scene, body, level, cols, extra)
        n_tri += 2.0 * cols + rest
        n_nodes += 2.0 * (cols + 1.0) + 0.5 * rest  # a triangle mesh has about half as many nodes as triangles
    return MeshSize(triangles=n_tri, nodes=n_nodes)


def _probe_rest(scene: Scene, body: Body, level: int, cols: float, extra) -> float:
    """gmsh's triangles beyond the strip of an outline body at ``level``, estimated without
    meshing at that level: meshed at the highest level with at most :data:`PROBE_COLUMNS`
    columns, times 4 per level above it (every size halves per level, so the count grows by
    about 4: 3.0-4.1 measured; the estimate is 1.0-1.9 times the count, reports/outlines.md)."""
    probe = level - max(0, math.ceil(math.log2(max(cols, 1.0) / PROBE_COLUMNS)))
    probe = max(probe, 0)
    while True:
        c = column_abscissae(scene, probe, extra)
        c = c[(c >= body.x_range[0]) & (c <= body.x_range[1])]
        try:
            n = len(mesh_rest(body, c, body.face.value(c) + body.sign * strip_depth(c), probe).triangles)
            return n * 4.0 ** (level - probe)
        except MeshError:
            if probe >= level:
                raise
            probe += 1  # a coarse level a body cannot be meshed at (a thick strip meets a hole) says nothing of level


@dataclass(frozen=True)
class BodyMesh:
    """The column mesh of one body. ``columns`` are the x coordinates of its columns,
    ``eta`` the layer parameters (0 at the face, 1 at the far side) and ``face_y`` the height
    of the face node of each column (on the face, or on a tangent polygon, see
    :mod:`~cvxdual.geometry.triangulation`).

    An outline body has one layer of columns (the strip) whose inner side is at ``inner_y``
    instead of the far side, and gmsh's mesh of the rest (``rest``,
    :mod:`~cvxdual.geometry.outline`); its nodes and triangles follow the strip's."""

    body: Body
    offset: int
    columns: np.ndarray
    eta: np.ndarray
    face_y: np.ndarray
    inner_y: np.ndarray | None = None
    rest: RestMesh | None = None
    meshed: Meshed | None = None  # how ``rest`` was made

    @property
    def inner(self) -> np.ndarray:
        """Height of the last layer's nodes at each column: the far side, or the strip's inner side."""
        return np.full(len(self.columns), self.body.far) if self.inner_y is None else self.inner_y

    @cached_property
    def rest_finder(self):
        """Point location in gmsh's triangles: ``finder(x, y)`` gives each point's triangle among
        ``rest.triangles`` or -1 (matplotlib's trapezoid map; built once, on first use)."""
        from matplotlib.tri import Triangulation

        pts = self.points()
        return Triangulation(pts[:, 0], pts[:, 1], self.rest.triangles).get_trifinder()

    @property
    def n_strip_nodes(self) -> int:
        return len(self.columns) * len(self.eta)

    @property
    def shape(self) -> tuple[int, int]:
        return len(self.columns), len(self.eta)

    def node(self, i, j):
        return self.offset + np.asarray(i) * len(self.eta) + np.asarray(j)

    @property
    def n_nodes(self) -> int:
        return self.n_strip_nodes + (0 if self.rest is None else len(self.rest.points))

    def points(self) -> np.ndarray:
        f = self.face_y
        y = f[:, None] + (self.inner - f)[:, None] * self.eta[None, :]
        x = np.broadcast_to(self.columns[:, None], y.shape)
        strip = np.stack([x.ravel(), y.ravel()], axis=1)
        return strip if self.rest is None else np.concatenate([strip, self.rest.points])

    def triangles(self) -> np.ndarray:
        """Counter-clockwise triangles: the strip's first, two per quad (in layer 0 the first
        triangle of each quad is ``(i,0), (i+1,0), (i+1,1)``: two face nodes and a vertical side),
        then gmsh's."""
        strip = self.strip_triangles()
        return strip if self.rest is None else np.concatenate([strip, self.offset + self.rest.triangles])

    def strip_triangles(self) -> np.ndarray:
        nc, nl = self.shape
        i, j = np.meshgrid(np.arange(nc - 1), np.arange(nl - 1), indexing="ij")
        i, j = i.ravel(), j.ravel()
        a, b, c, d = self.node(i, j), self.node(i + 1, j), self.node(i + 1, j + 1), self.node(i, j + 1)
        if self.body.position == "upper":
            t1, t2 = np.stack([a, b, c], 1), np.stack([a, c, d], 1)
        else:  # layers run downward: reverse to keep counter-clockwise order
            t1, t2 = np.stack([a, c, b], 1), np.stack([a, d, c], 1)
        return np.concatenate([t1, t2])

    def side_nodes(self, side: str) -> np.ndarray:
        """Nodes along a side, in order of increasing x (face, far) or distance from the face (left,
        right); along an outline part, in the outline's order."""
        nc, nl = self.shape
        if side == "face":
            return self.node(np.arange(nc), 0)
        if self.rest is not None:
            return self.offset + self.rest.parts[side]
        if side == "far":
            return self.node(np.arange(nc), nl - 1)
        if side == "left":
            return self.node(0, np.arange(nl))
        if side == "right":
            return self.node(nc - 1, np.arange(nl))
        raise ValueError(side)


@dataclass(frozen=True)
class Mesh:
    """Column meshes of both bodies and the contact pairs.

    ``pairs`` is ``(n_pairs, 2)``: upper face node, lower face node, sharing ``x``
    (``pair_x``), ordered by ``x``.
    """

    scene: Scene
    level: int
    bodies: tuple[BodyMesh, BodyMesh]
    points: np.ndarray
    pairs: np.ndarray
    pair_x: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    def _edges(self) -> np.ndarray:
        """Edge lengths of every triangle ``(n_tri, 3)``."""
        return edge_lengths(self.points[self.triangles()])

    @property
    def h(self) -> float:
        """The mesh size ``h``: the largest triangle diameter (longest edge)."""
        return float(self._edges().max())

    @property
    def h_min(self) -> float:
        """The shortest triangle edge."""
        return float(self._edges().min())

    def triangles(self) -> np.ndarray:
        return np.concatenate([bm.triangles() for bm in self.bodies])

    def triangle_body(self) -> np.ndarray:
        return np.concatenate([np.full(len(bm.triangles()), k) for k, bm in enumerate(self.bodies)])

    def continuation(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where the bodies extend beyond the mesh (free arcs of outline bodies,
        :func:`~cvxdual.geometry.outline.mesh_rest`): node triples ``(m, 3)`` whose P1
        interpolant continues the displacement there, the area each covers ``(m,)`` and its
        body ``(m,)``. Zero stress is admissible there; the displacement's energy is not zero."""
        out = [(bm.offset + bm.rest.virtual_nodes, bm.rest.virtual_weight, np.full(len(bm.rest.virtual_weight), k))
               for k, bm in enumerate(self.bodies) if bm.rest is not None]
        if not out:
            return np.zeros((0, 3), int), np.zeros(0), np.zeros(0, int)
        return tuple(np.concatenate(v) for v in zip(*out, strict=True))

    def continuation_rule(self, n: int = 12) -> ContinuationRule:
        """A quadrature on the exact pieces of :meth:`continuation` (the same rows), exact for
        polynomials of degree 2 in ``x, y``: a P2 displacement's strain is not constant there, so
        the areas do not give its energy (:func:`~cvxdual.geometry.outline.continuation_rule`,
        ``n`` angles a half piece). A corner's third node (where the tangents meet) lies beyond its
        chord, away from the centre; a segment's triangle is in the body, on the centre's side."""
        out = [(bm.offset + bm.rest.virtual_nodes, bm.offset + bm.rest.virtual_ends, bm.rest.virtual_arc)
               for bm in self.bodies if bm.rest is not None]
        nodes, ends, arc = ((np.concatenate(v) for v in zip(*out, strict=True)) if out
                            else (np.zeros((0, 3), int), np.zeros((0, 2), int), np.zeros((0, 3))))
        a, b = self.points[ends[:, 0]], self.points[ends[:, 1]]
        third = self.points[nodes[(nodes != ends[:, :1]) & (nodes != ends[:, 1:])]]  # one a row
        mid = 0.5 * (a + b)
        corner = np.einsum("ij,ij->i", third - mid, mid - arc[:, :2]) > 0
        return continuation_rule(a, b, arc, corner, n)

    def polygonal_parts(self) -> list[str]:
        """``body.part`` names of the curved outline parts meshed as polygons (supported or loaded
        arcs, and splines: the mesh's domain is not the body's there)."""
        out = []
        for bm in self.bodies:
            if bm.rest is None:
                continue
            held = held_parts(bm.body)
            out += [f"{bm.body.name}.{p.name}" for p in bm.body.outline.parts
                    if p.has_spline or (p.is_curved and p.name in held)]
        return out


def column_abscissae(scene: Scene, level: int, extra=()) -> np.ndarray:
    """The global columns: graded over the union of the bodies' x ranges, with the break points
    of :func:`_required`."""
    x0, x1 = scene.x_extent
    spec = scene.mesh
    return graded_points(x0, x1, spec.columns, level, spec.focus, spec.grading, _required(scene, extra))


def check_level(level) -> int:
    try:
        ok = not isinstance(level, bool) and int(level) == level and level >= 0
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise MeshError(f"mesh level must be a non-negative integer, got {short(level)}")
    return int(level)


def side_breaks(body: Body, f0: float, f1: float) -> list[float]:
    """The layer parameters the ends of traction intervals on the left and right sides need: a
    traction acts on the edges between the side's nodes inside its interval, so its ends must be
    nodes, or part of the load is lost (40 on 1 mm became 24.7); ``f0``, ``f1`` the face nodes'
    heights at the two sides. (A support acts on the nodes inside its interval, as documented.)"""
    out = []
    for part in body.boundary:
        if part.interval is not None and part.on in ("left", "right") and part.kind == "traction":
            f = f0 if part.on == "left" else f1
            out += [(y - f) / (body.far - f) for y in part.interval]
    return [e for e in out if 0.0 < e < 1.0]


def build_mesh(scene: Scene, level: int | None = None, columns: np.ndarray | None = None,
               face_y=(None, None), spots=(None, None), cut_columns=None, in_place=None) -> Mesh:
    """Build the column mesh of ``scene`` at ``level`` (default: the scene's default level).

    ``columns`` replaces the graded global columns; ``face_y[k]`` (a function of the column
    abscissae) replaces the face heights of body ``k``'s face nodes. An adaptive grid
    (:class:`~cvxdual.geometry.grid.Grid`) gives ``spots[k]`` ``(m, 3)``, sizes ``(x, y, size)``
    asked of outline body ``k``'s part beyond the strip, and ``cut_columns``, the global columns
    of the level it started from, where gmsh's surfaces are cut as on that level's mesh, and may give
    ``in_place`` (:class:`~cvxdual.geometry.grid.InPlace`): the last mesh's bodies, refined in place
    where that can be done (:func:`~cvxdual.geometry.outline.in_place.refine_in_place`), else meshed.
    """
    level = check_level(scene.mesh.default_level if level is None else level)
    cols = column_abscissae(scene, level) if columns is None else np.asarray(columns, float)
    bms, pts, offset = [], [], 0
    for k, body in enumerate(scene.bodies):
        x0, x1 = body.x_range
        c = cols[(cols >= x0) & (cols <= x1)]
        if len(c) < 2 or c[0] != x0 or c[-1] != x1:
            raise MeshError(f"internal: the columns of body {body.name!r} do not reach its ends "
                            f"[{x0:g}, {x1:g}]")  # pragma: no cover - the ends are always break points
        fy = body.face.value(c) if face_y[k] is None else face_y[k](c)
        if body.is_column:
            xm = 0.5 * (x0 + x1) if scene.mesh.focus is None else 0.5 * sum(scene.mesh.focus)
            H = float(body.height(np.clip(xm, x0, x1)))
            depth = body.focus_depth
            eta = graded_points(0.0, 1.0, body.layers, level,
                                None if depth is None else (0.0, min(depth / H, 1.0)),
                                scene.mesh.grading, side_breaks(body, fy[0], fy[-1]))
            bm = BodyMesh(body, offset, c, eta, fy)
        else:
            inner = body.face.value(c) + body.sign * strip_depth(c)
            bm = _in_place(body, offset, c, fy, inner, level, spots[k], in_place, k)
            if bm is None:
                cuts = None if cut_columns is None else cut_columns[(cut_columns >= x0) & (cut_columns <= x1)]
                rest = mesh_rest(body, c, inner, level, spots[k], cuts)
                bm = BodyMesh(body, offset, c, np.array([0.0, 1.0]), fy, inner, rest, Meshed.GMSH)
                # a wrong loop handed to gmsh meshes the wrong region without an error: check it against the outline
                check_body_mesh(body, bm.points(), bm.triangles() - offset, bm.side_nodes("face") - offset, rest.parts)
        bms.append(bm)
        pts.append(bm.points())
        offset += bm.n_nodes
    points = np.concatenate(pts)
    pairs, pair_x = _pairs(scene, bms, points)
    mesh = Mesh(scene, int(level), tuple(bms), points, pairs, pair_x)
    check_triangles(points, mesh.triangles())
    return mesh


def _in_place(body, offset: int, c, fy, inner, level: int, spots, in_place, k: int) -> BodyMesh | None:
    """Body ``k``'s mesh refined in place from ``in_place`` and checked, or None: gmsh meshes it."""
    prior = None if in_place is None else in_place.bodies[k]
    if prior is None or prior.rest is None:
        return None
    try:
        rest = refine_in_place(body, prior, c, fy, inner, level, (in_place.spots[k], spots), in_place.marked[k],
                               in_place.arcs[k])
        bm = BodyMesh(body, offset, c, np.array([0.0, 1.0]), fy, inner, rest, Meshed.IN_PLACE)
        check_body_mesh(body, bm.points(), bm.triangles() - offset, bm.side_nodes("face") - offset, rest.parts)
    except MeshError as e:  # a fold, or columns that moved: gmsh meshes it, as any cycle's
        log.info("body %r meshed by gmsh: %s", body.name, e)
        return None
    return bm


def _pairs(scene: Scene, bms, points) -> tuple[np.ndarray, np.ndarray]:
    a, b = scene.contact
    up, lo = (bm.side_nodes("face") for bm in bms)
    tol = 1e-12 * scene.length_scale  # columns are shared exactly; only rounding may differ
    sel_u = up[(points[up, 0] >= a - tol) & (points[up, 0] <= b + tol)]
    sel_l = lo[(points[lo, 0] >= a - tol) & (points[lo, 0] <= b + tol)]
    if len(sel_u) != len(sel_l) or np.any(np.abs(points[sel_u, 0] - points[sel_l, 0]) > tol):
        raise MeshError("contact nodes of the two bodies are not aligned on vertical lines over the "
                        "contact interval; use a column mesh with shared columns")
    if len(sel_u) < 2:
        raise MeshError("fewer than two contact pairs; refine the mesh (raise level or columns)")
    return np.stack([sel_u, sel_l], axis=1), points[sel_u, 0].copy()


def check_triangles(points: np.ndarray, tris: np.ndarray, what: str = "triangle") -> np.ndarray:
    """Signed areas of counter-clockwise triangles; raise :class:`MeshError` on an inverted or
    degenerate one (relative to the squared longest edge)."""
    p = points[tris]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    edge2 = np.max(np.stack([np.sum(d1**2, 1), np.sum(d2**2, 1), np.sum((p[:, 2] - p[:, 1])**2, 1)]), 0)
    # 1e-12: an area below this fraction of the squared edge has lost all significant digits
    bad = area <= 1e-12 * edge2
    if np.any(bad):
        k = int(np.argmax(bad))
        raise MeshError(f"{int(bad.sum())} inverted or zero-area {what}(s), first at "
                        f"{np.round(p[k], 6).tolist()}; the face is too curved for the first layer or "
                        "the mesh too coarse: raise the level, the layers, or the body height")
    return area
