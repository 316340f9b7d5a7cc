"""Piecewise profiles, and profiles from scene-file tables.

- ``punch``: the gap of a rounded flat punch, ``g(x) = (|x - xc| - b)_+^2 / (2 R)`` (zero on the
  flat ``|x - xc| <= b``, a parabola of radius ``R`` beyond: the linearised corner);
- ``composite``: a face drawn as a chain of line segments and circular arcs from ``start``, each
  a graph over its own ``x`` interval (e.g. a flat with rounded corners). Its *breaks* (where
  one piece meets the next) are reported as :meth:`~cvxdual.scene.profiles.Profile.inflexions`,
  so that mesh columns fall on them and every column interval lies on one piece: the curved
  pieces of both triangulations then see one line or one circle, as on the other kinds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import get_args

import numpy as np

from ..errors import SceneError
from ..validate import pair, short, table
from .profiles import Branch, Circle, Cosine, Flat, LowerCircle, Parabola, Profile, ProfileKind, UpperCircle, parameter


@dataclass(frozen=True)
class Punch(Profile, kind="punch"):
    b: float = parameter(0.0, "nonnegative")
    R: float = parameter(1.0, "positive")
    xc: float = 0.0

    def _u(self, x):
        u = np.asarray(x, float) - self.xc
        return u, np.maximum(np.abs(u) - self.b, 0.0)

    def value(self, x):
        _, e = self._u(x)
        return e * e / (2 * self.R)

    def slope(self, x):
        u, e = self._u(x)
        return np.sign(u) * e / self.R

    def curvature(self, x):
        _, e = self._u(x)
        return np.where(e > 0, 1.0 / self.R, 0.0)

    def curvature_range(self, x0, x1):
        x0, x1 = np.broadcast_arrays(np.asarray(x0, float), np.asarray(x1, float))
        # 1/R on the corners, 0 on the flat: an interval reaching past |u| = b holds 1/R
        lo = np.where((x0 - self.xc >= self.b) | (x1 - self.xc <= -self.b), 1.0 / self.R, 0.0)
        hi = np.where((x1 - self.xc > self.b) | (x0 - self.xc < -self.b), 1.0 / self.R, 0.0)
        return lo, hi

    def antiderivative(self, x):
        u, e = self._u(x)
        return np.sign(u) * e**3 / (6 * self.R)

    def inflexions(self, x0, x1):
        xs = np.array([self.xc - self.b, self.xc + self.b])
        return np.unique(xs[(xs > x0) & (xs < x1)])


@dataclass(frozen=True)
class Composite(Profile, kind="composite"):
    """Lines and arcs joined end to end, left to right: ``nodes`` ``((x, y), ...)`` the ends of
    the pieces, ``centers`` one per piece (``None`` for a line). Each arc is a graph: its ``x``
    interval lies within its circle's and it stays on one side of the centre's height."""

    nodes: tuple = ()
    centers: tuple = ()

    def __post_init__(self):  # the numbers are checked by composite_from_dict
        x = np.array([p[0] for p in self.nodes], float)
        if len(x) < 2 or not np.all(np.diff(x) > 0):
            raise SceneError("composite profile: the pieces must run left to right (each 'to' right of the last)")
        for k, c in enumerate(self.centers):
            if c is None:
                continue
            (x0, y0), (x1, y1) = self.nodes[k], self.nodes[k + 1]
            r0, r1 = math.dist((x0, y0), c), math.dist((x1, y1), c)
            if abs(r0 - r1) > 1e-6 * max(r0, r1):  # a centre typed to 6 digits
                raise SceneError(f"composite profile: arc {k} has its ends at different distances from its centre "
                                 f"({r0:g} and {r1:g}); move the centre")
            s0, s1 = np.sign(y0 - c[1]), np.sign(y1 - c[1])
            if s0 * s1 < 0 or (s0 == 0 and s1 == 0):
                raise SceneError(f"composite profile: arc {k} crosses the height of its centre, where it turns back "
                                 "in x: not a graph y = f(x); end the face's arc before that height (the rest "
                                 "of the circle can be an outline part)")

    @property
    def _x(self) -> np.ndarray:
        return np.array([p[0] for p in self.nodes], float)

    def _piece(self, x):
        x = np.asarray(x, float)
        k = np.clip(np.searchsorted(self._x, x, side="right") - 1, 0, len(self.centers) - 1)
        return x, k

    def _eval(self, x, what: str):
        x, k = self._piece(x)
        out = np.zeros(np.shape(x))
        for j in range(len(self.centers)):
            m = k == j
            if np.any(m):
                out[m] = self._on_piece(j, x[m], what)
        return out

    def _on_piece(self, j: int, xm: np.ndarray, what: str) -> np.ndarray:
        """``what`` (value, slope, curvature, or ``anti``: the integral from the piece's start)
        of piece ``j`` at ``xm``."""
        (x0, y0), (x1, y1) = self.nodes[j], self.nodes[j + 1]
        c = self.centers[j]
        if c is None:
            s = (y1 - y0) / (x1 - x0)
            return {"value": y0 + s * (xm - x0), "slope": np.full(xm.shape, s), "curvature": np.zeros(xm.shape),
                    "anti": y0 * (xm - x0) + 0.5 * s * (xm - x0) ** 2}[what]
        r, sg = math.dist((x0, y0), c), self._branch(j)
        u = xm - c[0]
        w = np.sqrt(np.maximum(r * r - u * u, 0.0))
        if what == "value":
            return c[1] + sg * w
        if what == "slope":
            return -sg * u / w
        if what == "curvature":
            return -sg * r * r / w**3

        def prim(v):  # an antiderivative of c_y + sg sqrt(r^2 - v^2)
            return c[1] * v + sg * 0.5 * (v * np.sqrt(np.maximum(r * r - v * v, 0.0))
                                          + r * r * np.arcsin(np.clip(v / r, -1.0, 1.0)))
        return prim(u) - prim(x0 - c[0])

    def _branch(self, j: int) -> float:
        (_, y0), (_, y1) = self.nodes[j], self.nodes[j + 1]
        c = self.centers[j]
        return 1.0 if (y0 - c[1]) + (y1 - c[1]) > 0 else -1.0

    def value(self, x):
        return self._eval(x, "value")

    def slope(self, x):
        return self._eval(x, "slope")

    def curvature(self, x):
        return self._eval(x, "curvature")

    def curvature_range(self, x0, x1):
        x0, x1 = np.broadcast_arrays(np.asarray(x0, float), np.asarray(x1, float))
        lo, hi = np.full(x0.shape, np.inf), np.full(x0.shape, -np.inf)
        xs = self._x
        for j, c in enumerate(self.centers):
            a, b = np.maximum(x0, xs[j]), np.minimum(x1, xs[j + 1])
            # a piece counts where it overlaps the interval's inside: f'' jumps at the pieces' ends
            # (mesh columns), so a neighbour touching an end bounds nothing of the inside
            m = (a < b) | ((a == b) & (x0 == x1))
            if c is None:
                k = np.zeros(m.sum())
                lo[m], hi[m] = np.minimum(lo[m], k), np.maximum(hi[m], k)
                continue
            # |f''| = r^2 / w^3 grows with |x - cx|: extreme at the ends or (for the least) at cx
            # piece j's own formula at both ends (self.curvature would take the next piece at its right end)
            ka, kb = (self._on_piece(j, np.clip(e[m], xs[j], xs[j + 1]), "curvature") for e in (a, b))
            inner = (a[m] <= c[0]) & (b[m] >= c[0])
            r = math.dist(self.nodes[j], c)
            kc = -self._branch(j) / r
            cand_lo = np.minimum(np.minimum(ka, kb), np.where(inner, kc, np.inf))
            cand_hi = np.maximum(np.maximum(ka, kb), np.where(inner, kc, -np.inf))
            lo[m], hi[m] = np.minimum(lo[m], cand_lo), np.maximum(hi[m], cand_hi)
        return lo, hi

    def antiderivative(self, x):
        x, k = self._piece(x)
        xs = self._x
        whole = [float(self._on_piece(j, np.array([xs[j + 1]]), "anti")[0]) for j in range(len(self.centers))]
        offset = np.concatenate([[0.0], np.cumsum(whole)])  # the integral of the pieces before each
        return offset[k] + self._eval(x, "anti")

    def inflexions(self, x0, x1):
        xs = self._x[1:-1]
        return xs[(xs > x0) & (xs < x1)]

    def domain(self):
        return (float(self._x[0]), float(self._x[-1]))

    def scaled(self, length: float) -> Composite:
        return Composite(tuple((x * length, y * length) for x, y in self.nodes),
                         tuple(None if c is None else (c[0] * length, c[1] * length) for c in self.centers))


def composite_from_dict(d: dict, where: str) -> Composite:
    """``{kind = "composite", start = [x, y], pieces = [{to = [x, y]}, {to = [x, y], center = [cx, cy]}]}``."""
    unknown = sorted(set(d) - {"start", "pieces"})
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {unknown} for a composite profile; allowed: ['pieces', 'start']")
    if "start" not in d or "pieces" not in d:
        raise SceneError(f"{where}: a composite profile needs start = [x, y] and pieces = [{{to = [x, y]}}, ...]")
    nodes, centers = [pair(d["start"], f"{where}.start")], []
    pieces = d["pieces"]
    if not isinstance(pieces, list) or not pieces:
        raise SceneError(f"{where}.pieces must be a non-empty list of {{to}} or {{to, center}}, got {short(pieces)}")
    for i, p in enumerate(pieces):
        w = f"{where}.pieces[{i}]"
        table(p, w)
        if set(p) - {"to", "center"} or "to" not in p:
            raise SceneError(f"{w}: a piece is {{to = [x, y]}} (a line) or {{to = [x, y], center = [cx, cy]}} (an arc)")
        nodes.append(pair(p["to"], f"{w}.to"))
        centers.append(pair(p["center"], f"{w}.center") if "center" in p else None)
    return Composite(tuple(nodes), tuple(centers))


# by the names of their class statements (ProfileKind)
PROFILE_KINDS: dict[ProfileKind, type[Profile]] = {
    cls.kind: cls for cls in (Flat, Parabola, Circle, Cosine, Punch, Composite)}


def profile_from_dict(d: dict, where: str) -> Profile:
    """Build a profile from a scene-file table such as ``{kind = "parabola", R = 50}``."""
    d = dict(table(d, where))
    kind = d.pop("kind", None)
    if not isinstance(kind, str) or kind not in PROFILE_KINDS:
        raise SceneError(f"{where}: unknown profile kind {short(kind)}; choose one of {sorted(PROFILE_KINDS)}")
    if kind == "composite":
        return composite_from_dict(d, where)
    cls: type[Profile] = PROFILE_KINDS[kind]
    if kind == "circle":
        branch = d.pop("branch", "lower")
        if branch not in get_args(Branch):
            raise SceneError(f"{where}: circle branch must be 'lower' or 'upper', got {branch!r}")
        cls = LowerCircle if branch == "lower" else UpperCircle
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - names)
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {unknown} for a {kind} profile; allowed: {sorted(names)}")
    return cls(**d)
