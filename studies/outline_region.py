"""The exact bodies of the outline fuzzing: the oracle's geometry (studies/outline_oracle.py).

A body is rebuilt from the generator's own description, a *shape* (the scene file's ``x, face,
outline, holes``), with geometry written here anew from docs/scenes.md: lines, circular arcs (a
circular segment beyond the chord), the natural cubic spline in the chord length, gmsh's own curve
for a ``.geo`` spline, the face profile (flat, parabola, circle, composite) by quadrature. A
:class:`Region` is the closed outer loop (face, then the outline's parts) and the holes; its exact
area is Green's integral over them. Each curve has a *band*: how far the mesh's polygon of it may
stray at a level (chords or tangents of an arc at ``4 * 2**level`` edges a quarter turn, a spline's
polygon with edges up to twice the coarsest column spacing, the face's chords between columns,
docs/scenes.md "Outlines"), with a safety factor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from matplotlib.path import Path as MplPath
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

ARC_ANGLE = 2 * (math.pi / 2) / 4  # twice the documented level-0 edge angle of an arc (safety factor 2)
SPLINE_EDGE = 3.0  # spline polygon edges: 1.5 times the documented largest size, twice the column spacing
FACE_SAFETY = 1.5  # the face's band: 1.5 times the largest distance of the face from its chords
ROUNDING = 1e-9  # of the body's size: coordinates typed to the same point agree to rounding
DENSE = 256  # samples of an arc or of a stretch of a spline (2e-5 of its radius off the curve at most)
GAUSS = np.polynomial.legendre.leggauss(8)


def face_function(face: dict):
    """``f(x)`` of a profile table (flat, parabola, circle, composite), written anew from docs/scenes.md."""
    kind = face.get("kind", "flat")
    if kind == "flat":
        return lambda x: np.full_like(np.asarray(x, float), face.get("y0", 0.0))
    if kind == "parabola":
        R, xc, y0 = face.get("R", 1.0), face.get("xc", 0.0), face.get("y0", 0.0)
        return lambda x: y0 + (np.asarray(x, float) - xc) ** 2 / (2 * R)
    if kind == "circle":
        R, xc, yc = face.get("R", 1.0), face.get("xc", 0.0), face.get("yc", 1.0)
        s = 1.0 if face.get("branch", "lower") == "upper" else -1.0
        return lambda x: yc + s * np.sqrt(np.maximum(R * R - (np.asarray(x, float) - xc) ** 2, 0.0))
    if kind == "composite":
        return _composite(face)
    raise ValueError(f"the oracle has no profile {kind!r}")


def _composite(face: dict):
    pieces, cur = [], tuple(face["start"])
    for p in face["pieces"]:
        pieces.append((cur, tuple(p["to"]), p.get("center")))
        cur = tuple(p["to"])

    def f(x):
        x = np.asarray(x, float)
        y = np.full_like(x, np.nan)
        for (a, b, c) in pieces:  # a handful of pieces, each vectorised over x
            sel = (x >= a[0]) & (x <= b[0])
            if c is None:
                y[sel] = a[1] + (b[1] - a[1]) * (x[sel] - a[0]) / (b[0] - a[0])
            else:
                r, s = math.dist(a, c), 1.0 if a[1] + b[1] > 2 * c[1] else -1.0
                y[sel] = c[1] + s * np.sqrt(np.maximum(r * r - (x[sel] - c[0]) ** 2, 0.0))
        return y
    return f


@dataclass
class Curve:
    """One boundary curve of a region: ``kind`` line, arc or dense (a spline, gmsh's curve, the face);
    ``pts`` its dense points from start to end; ``green`` its share of the signed area (the integral
    of ``(x dy - y dx) / 2``); ``band`` how far its mesh polygon may stray (set by :meth:`Region.bands`)."""

    kind: str
    pts: np.ndarray
    green: float
    radius: float = 0.0
    sweep: float = 0.0
    centre: tuple | None = None
    kappa: float = 0.0  # largest curvature of a spline
    extra: float = 0.0  # a spline read from a .geo file: the refit's distance from gmsh's curve
    band: float = 0.0
    swept: float = 0.0  # the area between the curve and its mesh polygon is at most this (set with the band)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.pts, axis=0), axis=1).sum())


# Every curve's share of the area is taken about an origin ``o`` on the body: the loop's sum is the
# same about any point, and coordinates far from (0, 0) (a body moved by 1e8) keep their digits.


def _shoelace(p: np.ndarray, o=(0.0, 0.0)) -> float:
    p = p - np.asarray(o, float)
    return 0.5 * float(np.sum(p[:-1, 0] * p[1:, 1] - p[1:, 0] * p[:-1, 1]))


def line(a, b, o=(0.0, 0.0)) -> Curve:
    pts = np.array([a, b], float)
    return Curve("line", pts, _shoelace(pts, o))


def arc(a, b, c, o=(0.0, 0.0)) -> Curve:
    a, b, c = (np.asarray(v, float) for v in (a, b, c))
    d0, d1 = a - c, b - c
    sweep = math.atan2(d0[0] * d1[1] - d0[1] * d1[0], float(d0 @ d1))
    r = float(np.linalg.norm(d0))
    t = math.atan2(d0[1], d0[0]) + sweep * np.linspace(0, 1, DENSE + 1)
    pts = c + r * np.stack([np.cos(t), np.sin(t)], 1)
    pts[0], pts[-1] = a, b
    # the chord's share plus the circular segment between chord and arc, signed with the sweep
    green = _shoelace(np.stack([a, b]), o) + 0.5 * r * r * (sweep - math.sin(sweep))
    return Curve("arc", pts, green, radius=r, sweep=sweep, centre=(float(c[0]), float(c[1])))


def spline(a, through, b, o=(0.0, 0.0)) -> Curve:
    """The natural cubic spline of x and y in the chord length (docs/scenes.md); repeated
    consecutive points are dropped (they add no curve)."""
    knots = np.array([a, *through, b], float)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(knots, axis=0), axis=1) > 0])
    knots = knots[keep]
    if len(knots) == 2:
        return line(*knots, o)
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))])
    cs = CubicSpline(t, knots, bc_type="natural")
    per = max(8, DENSE * 8 // (len(t) - 1))  # a spline of many points: fewer samples a stretch
    s = np.unique(np.concatenate([np.linspace(t[k], t[k + 1], min(DENSE, per) + 1) for k in range(len(t) - 1)]))
    pts = cs(s)
    pts[0], pts[-1] = knots[0], knots[-1]
    # Gauss-Legendre on each stretch is exact for x y' - y x' (degree 5)
    x, w = GAUSS
    u = 0.5 * (t[:-1, None] + t[1:, None]) + 0.5 * np.diff(t)[:, None] * x[None]
    p, dp, ddp = cs(u) - np.asarray(o, float), cs(u, 1), cs(u, 2)
    green = 0.5 * float(np.sum(w[None] * 0.5 * np.diff(t)[:, None] * (p[..., 0] * dp[..., 1] - p[..., 1] * dp[..., 0])))
    cross = np.abs(dp[..., 0] * ddp[..., 1] - dp[..., 1] * ddp[..., 0])
    kappa = float(np.max(cross / np.maximum(np.linalg.norm(dp, axis=-1), 1e-300) ** 3))
    kappa = max(kappa, _discrete_curvature(pts))
    return Curve("dense", pts, green, kappa=kappa)


def _discrete_curvature(p: np.ndarray) -> float:
    """The largest turning angle per length of a dense polyline."""
    e = np.diff(p, axis=0)
    n = np.linalg.norm(e, axis=1)
    if len(e) < 2:
        return 0.0
    turn = np.abs(np.arctan2(e[:-1, 0] * e[1:, 1] - e[:-1, 1] * e[1:, 0], np.sum(e[:-1] * e[1:], 1)))
    return float(np.max(2 * turn / np.maximum(n[:-1] + n[1:], 1e-300)))


def dense_curve(pts, extra: float = 0.0) -> Curve:
    """A curve known by dense points (gmsh's spline of a .geo file); :func:`region` takes its
    share of the area about the body's origin."""
    pts = np.asarray(pts, float)
    return Curve("dense", pts, _shoelace(pts), kappa=_discrete_curvature(pts), extra=extra)


def face_curve(face: dict, x0: float, x1: float, o=(0.0, 0.0)) -> Curve:
    """The face from ``x0`` to ``x1``: its share of the area is ``(x1 f1 - x0 f0) / 2 - int f``
    (about ``o``: with ``x - ox`` and ``f - oy``)."""
    g = face_function(face)

    def f(x):
        return g(x) - o[1]
    brk = [x0, x1] + [p["to"][0] for p in face.get("pieces", [])]
    brk = np.unique(np.clip(brk, x0, x1))
    edges = np.unique(np.concatenate([np.linspace(a, b, 65) for a, b in zip(brk[:-1], brk[1:], strict=True)]))
    x, w = GAUSS
    h = np.diff(edges)[:, None]
    integral = float(np.sum(0.5 * h * w[None] * f(0.5 * (edges[:-1, None] + edges[1:, None]) + 0.5 * h * x[None])))
    xs = np.unique(np.concatenate([np.linspace(x0, x1, 2049), brk]))
    pts = np.stack([xs, g(xs)], 1)
    return Curve("face", pts, 0.5 * ((x1 - o[0]) * float(f(x1)) - (x0 - o[0]) * float(f(x0))) - integral)


def part_curve(start, part: dict, o=(0.0, 0.0)) -> Curve:
    if "center" in part:
        return arc(start, part["to"], part["center"], o)
    if "through" in part:
        return spline(start, part["through"], part["to"], o)
    return line(start, part["to"], o)


def hole_curves(hole: dict, o=(0.0, 0.0)) -> list[Curve]:
    if "radius" in hole:
        (cx, cy), r = hole["center"], hole["radius"]
        q = [(cx + r, cy), (cx, cy + r), (cx - r, cy), (cx, cy - r)]
        return [arc(q[j], q[(j + 1) % 4], (cx, cy), o) for j in range(4)]
    p = hole["points"]
    return [line(p[j], p[(j + 1) % len(p)], o) for j in range(len(p))]


@dataclass
class Region:
    """A body: ``outer`` the closed loop (face left to right, then the outline's parts), ``holes``
    closed loops; ``face`` the face's profile table (its band needs the mesh's columns)."""

    outer: list
    holes: list
    face: dict

    @property
    def curves(self) -> list:
        return self.outer + [c for h in self.holes for c in h]

    @property
    def area(self) -> float:
        return abs(sum(c.green for c in self.outer)) - sum(abs(sum(c.green for c in h)) for h in self.holes)

    @property
    def scale(self) -> float:
        return float(np.ptp(np.concatenate([c.pts for c in self.outer]), axis=0).max())

    def rings(self) -> list:
        return [np.concatenate([c.pts for c in loop]) for loop in [self.outer, *self.holes]]

    def bands(self, level: int, columns: np.ndarray, h_max: float) -> None:
        """Each curve's band at ``level`` with the body's face nodes at ``columns`` (its own
        sorted column abscissae) and the coarsest column spacing ``h_max``."""
        # rounding: of the body's size, and of the coordinates' own size (a body 1e10 from the origin)
        eps = ROUNDING * self.scale + 16 * float(np.spacing(np.abs(self.rings()[0]).max()))
        alpha = ARC_ANGLE / 2**level
        f = face_function(self.face)
        t = np.linspace(0, 1, 17)[1:-1]
        xs = columns[:-1, None] + np.diff(columns)[:, None] * t[None]
        chord = f(columns[:-1])[:, None] + (f(columns[1:]) - f(columns[:-1]))[:, None] * t[None]
        dev = np.max(np.abs(f(xs) - chord), axis=1) if len(columns) > 1 else np.zeros(1)
        for c in self.curves:
            if c.kind == "arc":
                half = min(alpha, abs(c.sweep)) / 2  # the tangent polygon of a hole strays furthest: r (1/cos - 1)
                c.band = c.radius * (1 / math.cos(half) - 1) + eps
            elif c.kind == "dense":
                c.band = c.kappa * (SPLINE_EDGE * h_max) ** 2 / 8 + 2 * c.extra + eps
            elif c.kind == "face":
                c.band = FACE_SAFETY * float(dev.max()) + eps
                # the face's own chords: the deviation of each column's chord over its width
                c.swept = FACE_SAFETY * float(np.sum(dev * np.diff(columns))) + eps * c.length
                continue
            else:
                c.band = eps
            c.swept = c.length * c.band

    @property
    def area_tolerance(self) -> float:
        """The mesh polygon of a curve lies within its band: the areas differ by at most the band
        swept along each curve; plus rounding of the sum (1e-9 of the body's squared size)."""
        return sum(c.swept for c in self.curves) + ROUNDING * self.scale**2


def region(shape: dict, gmsh_curves: dict | None = None) -> Region:
    """The region of a shape ``{x, face, outline, holes}`` (the scene file's form); a part or hole
    with an entry in ``gmsh_curves`` (its name) takes that curve instead (a .geo spline)."""
    x0, x1 = shape["x"]
    f = face_function(shape["face"])
    o = (x0, float(f(x0)))  # the face's left end: every share of the area is taken about it
    outer = [face_curve(shape["face"], x0, x1, o)]
    cur = (x1, float(f(x1)))
    for p in shape["outline"]:
        if gmsh_curves and p["name"] in gmsh_curves:
            c = gmsh_curves[p["name"]]
            outer.append(Curve(c.kind, c.pts, _shoelace(c.pts, o), kappa=c.kappa, extra=c.extra))
        else:
            outer.append(part_curve(cur, p, o))
        cur = tuple(p["to"])
    return Region(outer, [hole_curves(h, o) for h in shape.get("holes", [])], shape["face"])


def in_ring(ring: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Whether points ``p`` lie inside the closed polyline ``ring`` (matplotlib's crossing test, in C)."""
    if len(p) == 0:
        return np.zeros(0, bool)
    return MplPath(np.asarray(ring, float)).contains_points(np.asarray(p, float))


def distance(p: np.ndarray, c: Curve) -> np.ndarray:
    """Distance of points ``p`` from the curve ``c``: exact for a line or an arc; a lower bound for
    a dense curve (the nearest of its points, less half its longest step: safe both ways here)."""
    if c.kind == "line":
        a, d = c.pts[0], c.pts[1] - c.pts[0]
        t = np.clip((p - a) @ d / max(float(d @ d), 1e-300), 0.0, 1.0)
        return np.linalg.norm(p - a - t[:, None] * d, axis=1)
    if c.kind == "arc":
        centre = np.array(c.centre)
        a0 = math.atan2(*(c.pts[0] - centre)[::-1])
        ang = (np.arctan2(p[:, 1] - centre[1], p[:, 0] - centre[0]) - a0) * np.sign(c.sweep) % (2 * math.pi)
        ends = np.minimum(np.linalg.norm(p - c.pts[0], axis=1), np.linalg.norm(p - c.pts[-1], axis=1))
        on = np.abs(np.linalg.norm(p - centre, axis=1) - c.radius)
        return np.where(ang <= abs(c.sweep), np.minimum(on, ends), ends)
    step = float(np.linalg.norm(np.diff(c.pts, axis=0), axis=1).max(initial=0.0))
    return np.maximum(cKDTree(c.pts).query(p)[0] - 0.5 * step, 0.0)


