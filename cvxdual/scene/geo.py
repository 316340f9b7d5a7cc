"""Body outlines from ``.geo`` files (docs/scenes.md#outlines-from-gmsh-geo-files).

The file draws the body's whole boundary with lines, circle arcs and splines; its *physical
curves* name the parts, one of them ``face``: a horizontal line (a flat face), one circular arc
(a circle face, either branch for either body, as in a scene file) or several lines and arcs end
to end (a composite face: a flat with rounded corners). Every other closed loop is a hole.
:mod:`cvxdual.scene.geo_lang` reads the file (the part of gmsh's language an outline needs,
executing nothing; gmsh is not involved) and this module turns its curves into the same
:class:`~cvxdual.scene.outline.Outline` a scene file's ``outline`` gives, splines evaluated with
gmsh's own formulas, so both describe, and mesh, the same body.
"""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..validate import short
from .geo_lang import GeoFile, parse_geo
from .outline import MAX_PARTS, Outline, Part, Segment
from .piecewise import Composite
from .planar import signed_area
from .profiles import Flat, LowerCircle, UpperCircle

MAX_BYTES = 1_000_000  # an outline takes a few kB; a larger file is refused unread
TOL = 1e-9  # relative to the body's size: ends typed to the same point meet
GEO_SPLINE_POINTS = 31  # inner points of gmsh's spline the outline's spline passes through
U = np.linspace(0.0, 1.0, GEO_SPLINE_POINTS + 2)[1:-1]  # their parameters (gmsh's curves run over [0, 1])


def read_geo(path: str | Path, position: str, where: str):
    """``(face, x_range, outline)`` of the body drawn in ``path``. ``position`` (the body's) does not
    change the face: any face that is a graph ``y = f(x)`` is taken, as a scene file's is, and the
    outline check (:func:`~cvxdual.scene.outline.check_outline`) places the body on its side."""
    del position
    geo = parse_geo(_read_text(Path(path), where), where)
    named, tol = _curves(geo, where)
    return _outline(named, where, tol)


def _read_text(path: Path, where: str) -> str:
    """The text of a regular ``.geo`` file of at most :data:`MAX_BYTES`, read without following it
    into a FIFO or a device."""
    name = short(str(path))
    if path.suffix.lower() != ".geo":
        raise SceneError(f"{where}.geo: {name} is not a .geo file; draw the body in a .geo file (docs/scenes.md)")
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))  # opening a FIFO must not wait for a writer
    except FileNotFoundError:
        raise SceneError(f"{where}.geo: no file {name}; give the path of a .geo file (relative to the scene "
                         "file)") from None
    except OSError as e:
        raise SceneError(f"{where}.geo: cannot open {name} ({e.strerror}); give a readable .geo file") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise SceneError(f"{where}.geo: {name} is not a regular file; give a .geo file")
        data = b""
        while len(data) <= MAX_BYTES:
            chunk = os.read(fd, MAX_BYTES + 1 - len(data))
            if not chunk:
                break
            data += chunk
    except OSError as e:
        raise SceneError(f"{where}.geo: cannot read {name} ({e.strerror}); give a readable .geo file") from None
    finally:
        os.close(fd)
    if len(data) > MAX_BYTES:
        raise SceneError(f"{where}.geo: {name} is larger than {MAX_BYTES // 1000} kB; an outline takes a few kB: "
                         "draw it with fewer statements")
    try:
        return data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise SceneError(f"{where}.geo: line {line}: byte 0x{data[e.start]:02x} is not UTF-8 text; save the file as "
                         "UTF-8") from None


def _curves(geo: GeoFile, where: str) -> tuple[dict[str, list[Segment]], float]:
    """Every physical curve's segments, by name, in gmsh's order (by physical tag, each group's
    curves by tag), and the tolerance of the body's size."""
    groups = sorted(geo.physicals)
    for tag, name, curves, line in groups:
        missing = next((c for c in curves if c not in geo.curves), None)
        if missing is not None:
            raise SceneError(f"{where}.geo: line {line}: physical curve {name or tag!r} lists curve {missing}, which "
                             "is not defined; define it or drop it from the list")
    members = {tag: sorted(set(curves)) for tag, _, curves, _ in groups}
    n = sum(map(len, members.values()))
    if n > MAX_PARTS:
        raise SceneError(f"{where}.geo: {n} curves in physical groups, more than {MAX_PARTS}; draw the body with "
                         "fewer, longer curves")
    for tag, name, _, line in groups:
        if name is None:
            raise SceneError(f"{where}.geo: line {line}: physical curve {tag} has no name; name every part, e.g. "
                             "Physical Curve(\"bottom\") = {...};")
    if "face" not in {name for _, name, _, _ in groups}:
        raise SceneError(f"{where}.geo: no physical curve named 'face'; name the contact face Physical Curve(\"face\")")
    owner: dict[int, str] = {}
    for tag, name, _, line in groups:
        for c in members[tag]:
            if c in owner:
                raise SceneError(f"{where}.geo: line {line}: curve {c} is in physical curves {owner[c]!r} and "
                                 f"{name!r}; put each curve in one physical curve")
            owner[c] = name
    for c, (_, _, line) in geo.curves.items():
        if c not in owner:
            raise SceneError(f"{where}.geo: line {line}: curve {c} is in no physical curve; name it, e.g. "
                             f"Physical Curve(\"hole\") = {{{c}}};")
    if not geo.curves:
        raise SceneError(f"{where}.geo: the file draws no curves; draw the body's boundary with Line, Circle and "
                         "Spline statements")
    drawn = np.array([geo.points[p] for k, pts, _ in geo.curves.values() for p in (pts[::2] if k == "Circle" else pts)])
    centres = np.array([geo.points[pts[1]] for k, pts, _ in geo.curves.values() if k == "Circle"]).reshape(-1, 2)
    # the body's size (its points, not the centres of its arcs), and the rounding of coordinates far from the origin
    tol = TOL * float(np.ptp(drawn, axis=0).max()) + 64 * np.finfo(float).eps * float(np.abs([*drawn, *centres]).max())
    return {name: [_segment(geo, c, where, tol) for c in members[tag]] for tag, name, _, _ in groups}, tol


def _segment(geo: GeoFile, curve: int, where: str, tol: float) -> Segment:
    """The curve as a segment from its end of the lower point tag to the other (the order the
    gmsh-based reader had: a hole's ring starts, and runs, as it did)."""
    seg = _drawn(geo, curve, where, tol)
    _, pts, _ = geo.curves[curve]
    return seg.reversed() if pts[-1] < pts[0] else seg


def _drawn(geo: GeoFile, curve: int, where: str, tol: float) -> Segment:
    """The curve as a segment from its first point to its last."""
    kind, pts, line = geo.curves[curve]
    at = f"{where}.geo: line {line}: {kind}({curve})"
    a, b = geo.points[pts[0]], geo.points[pts[-1]]
    if pts[0] == pts[-1] or math.dist(a, b) <= tol:
        raise SceneError(f"{at} starts and ends at ({a[0]:g}, {a[1]:g}); split it into curves with two different ends")
    if kind == "Line":
        return Segment(a, b)
    if kind == "Circle":
        c = geo.points[pts[1]]
        r0, r1 = math.dist(a, c), math.dist(b, c)
        if abs(r0 - r1) > 1e-6 * max(r0, r1):  # a centre typed to 6 digits, as outlines allow
            raise SceneError(f"{at} has its ends at different distances from its centre ({r0:g} and {r1:g}); move "
                             "the centre or an end")
        a0, sweep = Segment(a, b, c).angles()
        if abs(sweep) > math.pi * (1 - 1e-9):
            raise SceneError(f"{at} turns half a circle or more; split it into two arcs")
        if abs(r0 - r1) <= tol:
            return Segment(a, b, c)
        # a centre typed to a few digits: gmsh's arc runs at the start's radius; the arc through the
        # ends and its midpoint has its ends at one distance from its centre
        mid = np.array(c) + r0 * np.array([math.cos(a0 + 0.5 * sweep), math.sin(a0 + 0.5 * sweep)])
        lo, hi = (a, b) if pts[0] < pts[-1] else (b, a)
        return Segment(a, b, _center(np.array(lo), mid, np.array(hi)))
    if kind == "Bezier" and len(pts) > MAX_PARTS:  # its work grows as the square of its points
        raise SceneError(f"{at} has {len(pts)} points, more than {MAX_PARTS}; split it into several curves")
    p = np.array([geo.points[t] for t in pts])
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    if np.any(step <= tol):
        k = int(np.argmax(step <= tol))
        raise SceneError(f"{at} repeats the point ({p[k, 0]:g}, {p[k, 1]:g}) (points {pts[k]} and {pts[k + 1]}); drop "
                         "one of them")
    xy = _bezier(p) if kind == "Bezier" else np.array([(_bspline if kind == "BSpline" else _catmull_rom)(p, u)
                                                       for u in U])
    through = tuple((float(x), float(y)) for x, y in xy)
    if np.any(np.linalg.norm(np.diff(np.array([a, *through, b]), axis=0), axis=1) <= tol):
        raise SceneError(f"{at} runs through one place twice at its sample points; move its points")
    return Segment(a, b, through=through)


# gmsh's built-in curves (Geo/GeoInterpolation.cpp), evaluated in its order of operations so the points
# agree to rounding: Spline is a Catmull-Rom spline, BSpline a uniform cubic B-spline whose first and last
# two pieces are changed to end at the end points, Bezier one Bezier curve of all its points
def _catmull_rom(p: np.ndarray, u: float) -> np.ndarray:
    n = len(p)
    i = min(max(int((n - 1) * u), 0), n - 2)
    t1, t2 = i / (n - 1), (i + 1) / (n - 1)
    t = (u - t1) / (t2 - t1)
    v1, v2 = p[i], p[i + 1]
    v0 = p[i - 1] if i else 2.0 * v1 - v2  # the ends continue straight
    v3 = p[i + 2] if i < n - 2 else 2.0 * v2 - v1
    sq, cu = t * t, t * t * t
    s = (-0.5 * cu + sq - 0.5 * t, 1.5 * cu - 2.5 * sq + 1, -1.5 * cu + 2 * sq + 0.5 * t, 0.5 * cu - 0.5 * sq)
    return s[0] * v0 + s[1] * v1 + s[2] * v2 + s[3] * v3


def _m(*rows):
    return tuple(tuple(float(x) for x in r) for r in rows)


_MAT = {  # rows: the coefficients of t^3, t^2, t, 1 on the piece's 4 points
    "bs": _m(*[[x / 6.0 for x in r] for r in ((-1, 3, -3, 1), (3, -6, 3, 0), (-3, 0, 3, 0), (1, 4, 1, 0))]),
    2: _m((0, 0, 0, 0), (0, 0, 0, 0), (-1, 1, 0, 0), (1, 0, 0, 0)),
    3: _m((0, 0, 0, 0), (1, -2, 1, 0), (-2, 2, 0, 0), (1, 0, 0, 0)),
    4: _m((-1, 3, -3, 1), (3, -6, 3, 0), (-3, 3, 0, 0), (1, 0, 0, 0)),
    5: _m((-1, 7. / 4, -1, 1. / 4), (3, -4.5, 1.5, 0), (-3, 3, 0, 0), (1, 0, 0, 0)),
    6: _m((-1, 7. / 4, -11. / 12, 2. / 12), (3, -4.5, 1.5, 0), (-3, 3, 0, 0), (1, 0, 0, 0)),
    "ext1": _m((-1, 7. / 4, -11. / 12, 1. / 6), (3, -4.5, 1.5, 0), (-3, 3, 0, 0), (1, 0, 0, 0)),
    "6b": _m((-1. / 4, 7. / 12, -7. / 12, 1. / 4), (3. / 4, -5. / 4, 1. / 2, 0), (-3. / 4, 1. / 4, 1. / 2, 0),
             (1. / 4, 7. / 12, 1. / 6, 0)),
    "7b": _m((-1. / 4, 7. / 12, -1. / 2, 1. / 6), (3. / 4, -5. / 4, 1. / 2, 0), (-3. / 4, 1. / 4, 1. / 2, 0),
             (1. / 4, 7. / 12, 1. / 6, 0)),
    "ext2": _m((-1. / 4, 7. / 12, -.5, 1. / 6), (3. / 4, -5. / 4, .5, 0), (-3. / 4, 1. / 4, .5, 0),
               (1. / 4, 7. / 12, 1. / 6, 0)),
}


def _bspline(p: np.ndarray, u: float) -> np.ndarray:
    n = len(p)
    pieces = max(n - 3, 1)
    k = min(int(math.floor(u * pieces)), pieces - 1)
    t1, t2 = k / pieces, (k + 1) / pieces
    t = (u - t1) / (t2 - t1)
    v = [p[min(k + j, n - 1)] for j in range(4)]
    if (n > 6 and k >= pieces - 2) or (n > 4 and k == pieces - 1):  # the last pieces: the first ones, reversed
        v, t, k = v[::-1], 1 - t, pieces - 1 - k
    if k == 0:
        mat = _MAT.get(n, _MAT["ext1"])
    elif k == 1:
        mat = _MAT["6b"] if n == 6 else _MAT["7b"] if n == 7 else _MAT["ext2"]
    else:
        mat = _MAT["bs"]
    tt = (t * t * t, t * t, t, 1.0)
    out = np.zeros(2)
    for d in range(2):
        for i in range(4):
            acc = 0.0
            for j in range(4):
                acc += mat[i][j] * v[j][d]
            out[d] += tt[i] * acc
    return out


def _bezier(p: np.ndarray) -> np.ndarray:
    """De Casteljau's construction at every parameter of :data:`U` at once."""
    c = np.repeat(p[None], len(U), axis=0)
    w = U[:, None, None]
    for n in range(len(p) - 1, 0, -1):
        c = (1 - w) * c[:, :n] + w * c[:, 1:n + 1]
    return c[:, 0]


def _center(a, m, b) -> tuple[float, float]:
    """The centre of the circle through three points."""
    d = 2.0 * (a[0] * (m[1] - b[1]) + m[0] * (b[1] - a[1]) + b[0] * (a[1] - m[1]))
    sa, sm, sb = a @ a, m @ m, b @ b
    return (float((sa * (m[1] - b[1]) + sm * (b[1] - a[1]) + sb * (a[1] - m[1])) / d),
            float((sa * (b[0] - m[0]) + sm * (a[0] - b[0]) + sb * (m[0] - a[0])) / d))


def _outline(named: dict[str, list[Segment]], where: str, tol: float):
    face = named.pop("face")
    if not named:
        raise SceneError(f"{where}.geo: the face is the only named curve; name the rest of the boundary too")
    if any(f.is_spline for f in face):
        raise SceneError(f"{where}.geo: the face is or holds a spline; the face must be a line or a circle arc, or "
                         "lines and arcs end to end (a flat, circle or composite face)")
    pieces = _face_chain(face, where, tol)
    (xa, ya), (xb, yb) = left, right = pieces[0].start, pieces[-1].end
    x0, x1 = float(xa), float(xb)
    f = face[0]  # as drawn: the radius from its first end, as before faces of several curves
    if len(pieces) == 1 and f.is_arc:
        cx, cy = f.center
        # an arc of less than half a turn with both ends on or below its centre lies on the lower half
        # circle, on or above on the upper one: a graph y = f(x) either way, as a scene file's circle
        # face of either branch under either body (a cylinder's face, a groove's, a bump's)
        if max(ya, yb) - cy <= tol:
            profile = LowerCircle(R=math.dist(f.start, f.center), xc=cx, yc=cy)
        elif cy - min(ya, yb) <= tol:
            profile = UpperCircle(R=math.dist(f.start, f.center), xc=cx, yc=cy)
        else:
            raise SceneError(f"{where}.geo: the face arc crosses the height of its centre, so it is not a graph "
                             "y = f(x) (it turns back at its leftmost or rightmost point); draw the face on one "
                             "side of the centre's height")
    elif len(pieces) == 1 and abs(ya - yb) <= tol:
        profile = Flat(y0=f.start[1])
    else:  # lines and arcs end to end, or one slanted line: a composite face, as a scene file's
        try:
            profile = Composite(tuple([pieces[0].start, *(p.end for p in pieces)]),
                                tuple(p.center for p in pieces))
        except SceneError as e:
            raise SceneError(f"{where}.geo: the face: {str(e).removeprefix('composite profile: ')}") from None
    # the other segments, chained into loops; the one through the face's ends is the path
    segs = [(name, s) for name, ss in named.items() for s in ss]
    path = _chain(segs, right, left, tol, where)
    rest = [x for k, x in enumerate(segs) if k not in {i for i, _, _ in path}]
    path = [(n, s) for _, n, s in path]
    holes = []
    while rest:
        loop = _chain(rest, rest[0][1].start, rest[0][1].start, tol, where, first=0)
        rest = [x for k, x in enumerate(rest) if k not in {i for i, _, _ in loop}]
        loop = [(n, s) for _, n, s in loop]
        names = {n for n, _ in loop}
        if len(names) != 1:
            raise SceneError(f"{where}.geo: a hole is drawn by parts {sorted(names)}; name a hole's curves alike")
        ring = [s for _, s in loop]
        if signed_area(np.array([s.start for s in ring])) < 0:
            ring = [s.reversed() for s in reversed(ring)]  # holes run counter-clockwise
        holes.append(Part(names.pop(), tuple(ring)))
    parts: list[Part] = []
    for name, s in path:  # consecutive segments of one name are one part only in holes: here one each
        parts.append(Part(name, (s,)))
    names = [p.name for p in parts]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SceneError(f"{where}.geo: part {dup[0]!r} has several curves on the boundary; give each curve its own "
                         "physical name (a named part is one line or one arc)")
    return profile, (x0, x1), Outline(tuple(parts), tuple(holes))


def _face_chain(face: list[Segment], where: str, tol: float) -> list[Segment]:
    """The face's curves end to end from its left end to its right end, each running left to right."""
    ends = np.array([p for s in face for p in (s.start, s.end)])
    shared = (np.hypot(*(ends[:, None] - ends[None]).transpose(2, 0, 1)) <= tol).sum(axis=1)
    free = np.flatnonzero(shared == 1)  # the face's two ends: each the end of one curve only
    if len(free) != 2 or np.any(shared > 2):
        raise SceneError(f"{where}.geo: the face's {len(face)} curves do not run end to end in one chain; draw the "
                         "face as lines and arcs, each starting where the last ends")
    a, b = sorted((tuple(ends[i]) for i in free), key=lambda p: p[0])
    chain = [s for _, _, s in _chain([("face", s) for s in face], a, b, tol, where)]
    if len(chain) != len(face):
        raise SceneError(f"{where}.geo: the face's curves do not all lie on one chain from its left end to its "
                         "right end; draw the face as one chain of lines and arcs")
    return chain


def _chain(segs, start, end, tol, where, first=None) -> list[tuple[int, str, Segment]]:
    """``(index in segs, name, segment)`` from ``start`` to ``end``, each segment reversed as
    needed, following shared ends (``first``: the index of the segment to start with)."""
    pool = dict(enumerate(segs))
    out, cur = [], start
    if first is not None:
        n, s = pool.pop(first)
        out.append((first, n, s))
        cur = s.end
    while math.dist(cur, end) > tol or not out:
        nxt = None
        for k, (n, s) in pool.items():
            if math.dist(s.start, cur) <= tol:
                nxt = (k, n, s)
            elif math.dist(s.end, cur) <= tol:
                nxt = (k, n, s.reversed())
            if nxt is not None:
                del pool[k]
                break
        if nxt is None:
            raise SceneError(f"{where}.geo: the outline is open at ({cur[0]:g}, {cur[1]:g}); close the curves there")
        out.append(nxt)
        cur = nxt[2].end
    return out
