"""The two triangulations of the paper (docs/theory.md#the-two-triangulations) on column meshes.

A face stretch is *convex* for its body where the body lies on the convex side of the arc
(``sign * f'' > 0``: upper body above a convex ``f'``, lower body below a concave ``f''``),
*concave* where ``sign * f'' < 0``. Stretches end at the body's ends, the contact interval's
ends and the inflexion points, which are always columns.

- ``type1`` (Haslinger-Hlavacek, the paper's section 2):

  - convex: the layer-0 triangle with two face nodes ``A``, ``B`` is split by its chord into
    the straight ``T0`` and the *segment* ``Ts`` between chord and arc, on which ``v_h`` is the
    chord's value extended along y: strain ``(dv1/dx, 0, dv2/dx)`` along the chord;
  - concave: that triangle ``A, B, C`` (vertical side ``BC``) loses the sliver outside the
    body and becomes the curved ``Tc`` (``concave1``), on which ``v_h`` is constant along y and
    linear in x between ``A`` and ``B``; continuity ties ``C`` to ``B``.

- ``type2`` (Hlavacek-Krizek, section 4): convex stretches as type 1; a concave stretch is
  replaced by the polygon of the tangents at the graded columns ``s_0 .. s_m`` (its ends
  included): its vertices ``A_i`` (tangents at ``s_i`` and ``s_{i+1}`` meet) become the
  columns, so they are the contact nodes, aligned with the other body's nodes. The straight
  mesh covers the body cut along the polygon; the sliver ``D_h`` between polygon and arc is
  made of the curved ``Tc`` (``concave2``) with vertex ``A_i`` over ``[s_i, s_{i+1}]``, cut by
  the vertical through ``A_i`` into two slabs under the two polygon edges at ``A_i``, with
  ``v_h`` the polygon's value extended along y; one stress constant per ``Tc`` (the
  area-weighted mean strain).

On flat faces both are the plain triangle mesh, and with no concave stretch they coincide.
"""

from __future__ import annotations

import numpy as np

from ..errors import CvxdualError, MeshError, SceneError
from ..scene.scene import Body, Scene
from .grid import Grid
from .mesh import Mesh, build_mesh, check_level, column_abscissae
from .pieces import Pieces, Slabs, build_pieces

TRIANGULATIONS = ("type1", "type2")
KIND = {"segment": 1, "concave1": 2, "concave2": 3}


def check_triangulation(name: str) -> str:
    name = str(name).lower()
    if name not in TRIANGULATIONS:
        raise CvxdualError(f"unknown triangulation {name!r}; choose 'type1' or 'type2'")
    return name


def break_points(scene: Scene, body: Body) -> np.ndarray:
    """Ends of the face stretches of ``body``: its ends, the contact ends, the other body's
    ends (columns both bodies need) and the inflexion points."""
    x0, x1 = body.x_range
    ends = [*scene.contact, *(v for b in scene.bodies for v in b.x_range)]
    pts = [x0, x1, *(c for c in ends if x0 < c < x1), *body.face.inflexions(x0, x1)]
    return np.unique(pts)


def column_breaks(scene: Scene) -> np.ndarray:
    """Abscissae every mesh column set must contain: the bodies' stretch ends and the ends of
    boundary intervals on faces and far sides."""
    intervals = [v for b in scene.bodies for part in b.boundary
                 if part.interval is not None and part.on in ("face", "far") for v in part.interval]
    return np.concatenate([*(break_points(scene, b) for b in scene.bodies), intervals])


def stretches(scene: Scene, body: Body) -> list[tuple[float, float, str]]:
    """``(x_start, x_end, kind)`` with kind ``flat``, ``convex`` or ``concave`` for the body."""
    b = break_points(scene, body)
    out = []
    for lo, hi in zip(b[:-1], b[1:], strict=True):
        if body.face.is_flat():
            kind = "flat"
        else:
            k = body.sign * float(body.face.curvature(0.5 * (lo + hi)))
            kind = "convex" if k > 0 else "concave" if k < 0 else "flat"
        out.append((float(lo), float(hi), kind))
    return out


def tangent_vertices(face, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Intersections ``(x, y)`` of the tangents to ``face`` at consecutive points ``s``."""
    a, b = s[:-1], s[1:]
    fa, fb, da, db = face.value(a), face.value(b), face.slope(a), face.slope(b)
    dd = da - db
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (fb - fa + da * a - db * b) / dd
    # nearly parallel tangents (almost no curvature between them): the midpoint is exact to
    # first order and avoids cancellation
    flat = np.abs(dd) <= 1e-12 * (1.0 + np.abs(da) + np.abs(db))
    x = np.where(flat, 0.5 * (a + b), x)
    if np.any(~((x > a) & (x < b))):
        raise MeshError("tangent polygon: consecutive tangents do not meet between their points; "
                        "the stretch is not strictly concave or the mesh is too coarse")
    return x, fa + da * (x - a)


def discretize(scene: Scene, triangulation: str = "type1", level: int | Grid | None = None):
    """Mesh and pieces of ``scene`` at a uniform ``level`` or on an adaptive
    :class:`~cvxdual.geometry.grid.Grid`: returns ``(mesh, pieces, ties)``; ``ties`` is ``(m, 2)``
    node pairs ``(tied, master)`` or ``None``."""
    tri = check_triangulation(triangulation)
    grid = level if isinstance(level, Grid) else None
    if grid is None:
        level = check_level(scene.mesh.default_level if level is None else level)
        cols = column_abscissae(scene, level, column_breaks(scene))
    else:
        level, cols = grid.level, grid.columns
    polygons: list[list] = [[], []]
    face_y = [None, None]
    base = None if grid is None else grid.base
    if tri == "type2":
        cols, polygons = _tangent_polygons(scene, cols)
        base = None if grid is None else _tangent_polygons(scene, base)[0]  # the start level's columns, as meshed
        for k, body in enumerate(scene.bodies):
            if polygons[k]:
                face_y[k] = _polygon_heights(body, polygons[k])
    mesh = build_mesh(scene, level, columns=cols, face_y=face_y, spots=(None, None) if grid is None else grid.spots,
                      cut_columns=base, in_place=None if grid is None else grid.in_place)
    return (mesh, *_pieces(mesh, tri, polygons))


def uniform_grid(scene: Scene, level: int) -> Grid:
    """The :class:`~cvxdual.geometry.grid.Grid` of the uniform ``level``: an adaptive run's start."""
    return Grid.uniform(scene, check_level(level), column_abscissae(scene, level, column_breaks(scene)))


def _tangent_polygons(scene: Scene, cols: np.ndarray):
    concave = [(k, lo, hi) for k, b in enumerate(scene.bodies) for lo, hi, kind in stretches(scene, b)
               if kind == "concave"]
    for i, (k, lo, hi) in enumerate(concave):
        for k2, lo2, hi2 in concave[i + 1:]:
            if k2 != k and min(hi, hi2) > max(lo, lo2):
                raise SceneError(f"both faces are concave on [{max(lo, lo2):g}, {min(hi, hi2):g}]; "
                                 "type 2 needs one of the faces convex or flat there: use type1")
    polygons: list[list] = [[], []]
    for k, lo, hi in concave:
        inside = (cols > lo) & (cols < hi)
        s = np.concatenate([[lo], cols[inside], [hi]])
        xa, ya = tangent_vertices(scene.bodies[k].face, s)
        cols = np.sort(np.concatenate([cols[~inside], xa]))
        polygons[k].append((s, xa, ya))
    return cols, polygons


def _polygon_heights(body: Body, polys):
    """Face-node heights: on the arc, except at tangent-polygon vertices (sorted abscissae)."""
    xa = np.concatenate([p[1] for p in polys])
    ya = np.concatenate([p[2] for p in polys])

    def face_y(c):
        y = body.face.value(c)
        hit = np.isin(c, xa)
        y[hit] = ya[np.searchsorted(xa, c[hit])]
        return y

    return face_y


class _Curved:
    """Collects curved pieces and their slabs (arrays appended per stretch, never per element)."""

    def __init__(self):
        self.p = {k: [] for k in ("kind", "body", "nodes", "replaces")}
        self.s = {k: [] for k in ("piece", "body", "xl", "xr", "lo", "hi", "lo_arc", "hi_arc", "edge", "edge_x")}
        self.n = 0

    def add(self, kind, body, nodes, replaces, slabs: list[dict]):
        """``n`` pieces with their slabs; slab entries are arrays over the pieces, except
        ``edge`` (the two local node positions, shared)."""
        n = len(nodes)
        self.p["kind"].append(np.full(n, KIND[kind]))
        self.p["body"].append(np.full(n, body))
        self.p["nodes"].append(nodes)
        self.p["replaces"].append(np.broadcast_to(replaces, (n,)))
        for sl in slabs:
            self.s["piece"].append(self.n + np.arange(n))
            self.s["body"].append(np.full(n, body))
            self.s["edge"].append(np.broadcast_to(sl["edge"], (n, 2)))
            for key in ("xl", "xr", "lo", "hi", "lo_arc", "hi_arc", "edge_x"):
                self.s[key].append(sl[key])
        self.n += n

    def result(self):
        if not self.n:
            return None
        cat = {k: np.concatenate(v) for k, v in self.s.items()}
        slabs = Slabs(piece=cat["piece"], body=cat["body"], xl=cat["xl"], xr=cat["xr"], lo=cat["lo"],
                      hi=cat["hi"], lo_arc=cat["lo_arc"].astype(bool), hi_arc=cat["hi_arc"].astype(bool))
        return {**{k: np.concatenate(v) for k, v in self.p.items()}, "slabs": slabs,
                "edge": cat["edge"].astype(int), "edge_x": cat["edge_x"]}


def _bounds(upper: bool, line_at):
    """Slab bounds: the arc is below the other bound for the upper body, above for the lower."""
    n = len(line_at)
    arc = np.ones(n, bool)
    if upper:
        return {"lo": np.zeros((n, 2)), "lo_arc": arc, "hi": line_at, "hi_arc": ~arc}
    return {"lo": line_at, "lo_arc": ~arc, "hi": np.zeros((n, 2)), "hi_arc": arc}


def _segments(cur: _Curved, k: int, lay: dict, sel: np.ndarray) -> None:
    """Convex stretches: the segment between chord and arc of each layer-0 triangle ``A, B, C``."""
    A, B, C, c = lay["A"], lay["B"], lay["C"], lay["c"]
    chord = np.stack([lay["pts"][A, 1], lay["pts"][B, 1]], 1)
    cur.add("segment", k, np.stack([A, B, C], 1)[sel], -1,
            [{"xl": c[sel], "xr": c[sel + 1], **_bounds(lay["upper"], chord[sel]),
              "edge": np.array([0, 1]), "edge_x": lay["ex"][sel]}])


def _concave1(cur: _Curved, k: int, lay: dict, sel: np.ndarray, face) -> np.ndarray:
    """Type 1 on concave stretches: the layer-0 triangle becomes the curved ``T_c`` (``v_h``
    constant along y); returns the ties ``(C, B)`` that continuity imposes."""
    A, B, C, c, pts = lay["A"], lay["B"], lay["C"], lay["c"], lay["pts"]
    line = np.stack([pts[A[sel], 1], pts[C[sel], 1]], 1)  # the side A-C of the triangle
    _check_inside(face, c[sel], c[sel + 1], line, lay["upper"])
    cur.add("concave1", k, np.stack([A, B, C], 1)[sel], lay["t1"][sel],
            [{"xl": c[sel], "xr": c[sel + 1], **_bounds(lay["upper"], line),
              "edge": np.array([0, 1]), "edge_x": lay["ex"][sel]}])
    return np.stack([C[sel], B[sel]], 1)


def _concave2(cur: _Curved, k: int, bm, pts: np.ndarray, polygon) -> None:
    """Type 2: the pieces ``T_c`` of ``D_h`` between a tangent polygon and the arc, each cut by
    the vertical through its vertex ``A_i`` into two slabs under the polygon edges at ``A_i``."""
    s, xa, _ = polygon
    c = bm.columns
    xs = np.concatenate([[s[0]], xa, [s[-1]]])  # face nodes P_0 .. P_{m+1}: s_0, the vertices, s_m
    col = np.searchsorted(c, xs)
    if np.any(c[col] != xs):
        raise MeshError("internal: tangent polygon vertices are not columns")  # pragma: no cover
    P = bm.node(col, 0)
    Px, Py = pts[P, 0], pts[P, 1]
    j = np.arange(len(xa))
    upper = bm.body.position == "upper"

    def line(a, b, x0, x1):
        slope = (Py[b] - Py[a]) / (Px[b] - Px[a])
        return np.stack([Py[a] + slope * (x0 - Px[a]), Py[a] + slope * (x1 - Px[a])], 1)

    left = {"xl": s[j], "xr": xa, **_bounds(upper, line(j, j + 1, s[j], xa)),
            "edge": np.array([0, 1]), "edge_x": np.stack([Px[j], Px[j + 1]], 1)}
    right = {"xl": xa, "xr": s[j + 1], **_bounds(upper, line(j + 1, j + 2, xa, s[j + 1])),
             "edge": np.array([1, 2]), "edge_x": np.stack([Px[j + 1], Px[j + 2]], 1)}
    cur.add("concave2", k, np.stack([P[j], P[j + 1], P[j + 2]], 1), -1, [left, right])


def _pieces(mesh: Mesh, tri: str, polygons) -> tuple[Pieces, np.ndarray | None]:
    """Straight triangles, and the curved pieces of every face stretch by its kind."""
    tris = mesh.triangles()
    keep = np.ones(len(tris), bool)
    cur = _Curved()
    ties = []
    toff = 0
    for k, bm in enumerate(mesh.bodies):
        face = bm.body.face
        c = bm.columns
        nc, nl = bm.shape
        i = np.arange(nc - 1)
        mid = 0.5 * (c[:-1] + c[1:])
        kappa = bm.body.sign * face.curvature(mid) if not face.is_flat() else np.zeros(len(mid))
        in_poly = np.zeros(len(mid), bool)
        for s, _, _ in polygons[k]:
            in_poly |= (mid > s[0]) & (mid < s[-1])
        # the layer-0 triangle (i,0), (i+1,0), (i+1,1) of each column: two face nodes, a vertical side
        lay = {"A": bm.node(i, 0), "B": bm.node(i + 1, 0), "C": bm.node(i + 1, 1), "c": c, "pts": mesh.points,
               "upper": bm.body.position == "upper", "t1": toff + i * (nl - 1), "ex": np.stack([c[:-1], c[1:]], 1)}
        convex = np.flatnonzero((kappa > 0) & ~in_poly)
        if len(convex):
            _segments(cur, k, lay, convex)
        concave = np.flatnonzero((kappa < 0) & ~in_poly)
        if len(concave):
            if tri == "type2":
                raise MeshError("internal: a concave stretch without tangent polygon")  # pragma: no cover
            ties.append(_concave1(cur, k, lay, concave, face))
            keep[lay["t1"][concave]] = False
        for polygon in polygons[k]:
            _concave2(cur, k, bm, mesh.points, polygon)
        toff += len(bm.triangles())
    pieces = build_pieces(mesh.points, tris, mesh.triangle_body(), [b.face for b in mesh.scene.bodies],
                          keep, cur.result())
    if np.any(pieces.area <= 0):
        bad = int(np.argmin(pieces.area))
        raise MeshError(f"a piece has non-positive area {pieces.area[bad]:.3g} (kind "
                        f"{pieces.kind[bad]}); the mesh is too coarse for the face's curvature")
    return pieces, (np.concatenate(ties) if ties else None)


def _check_inside(face, xl, xr, line, upper: bool) -> None:
    """The arc of a non-convex curved triangle must stay inside the triangle (below its side
    A-C for the upper body): otherwise the face bulges through the first layer."""
    t = np.linspace(0.0, 1.0, 9)[1:-1]
    x = xl[:, None] + t[None, :] * (xr - xl)[:, None]
    lin = line[:, :1] + t[None, :] * (line[:, 1:] - line[:, :1])
    d = (lin - face.value(x)) if upper else (face.value(x) - lin)
    if np.any(d <= 0):
        raise MeshError("the face bulges through the first element layer of a non-convex curved "
                        "triangle; raise the level (the bulge shrinks like h^2, the layer like h), "
                        "or use type2")
