"""Body outlines from gmsh ``.geo`` files (docs/scenes.md#outlines-from-gmsh-geo-files).

The file draws the body's whole boundary with lines and circle arcs; its *physical curves* name
the parts, one of them ``face``: a horizontal line (a flat face) or one circular arc (a circle
face, the lower branch under an upper body, the upper one over a lower body). Every other closed
loop is a hole. gmsh reads the file (``gmsh.open``) and this module turns its curves into the same
:class:`~cvxdual.scene.outline.Outline` a scene file's ``outline`` gives, so both describe, and
mesh, the same body.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import MeshError, SceneError
from ..validate import short
from .outline import MAX_PARTS, Outline, Part, Segment
from .planar import signed_area
from .profiles import Flat, LowerCircle, UpperCircle

TOL = 1e-9  # relative to the body's size: ends typed to the same point meet
GEO_SPLINE_POINTS = 31  # inner points of gmsh's spline the outline's spline passes through

# the system libraries gmsh's wheel links, and the Debian/Ubuntu packages that provide them
SYSTEM_PACKAGES = {"libGLU": "libglu1-mesa", "libXcursor": "libxcursor1", "libXft": "libxft2",
                   "libXinerama": "libxinerama1", "libX11": "libx11-6", "libXrender": "libxrender1",
                   "libfontconfig": "libfontconfig1", "libXext": "libxext6", "libXfixes": "libxfixes3",
                   "libgomp": "libgomp1"}


def import_gmsh():
    """The gmsh module, or a :class:`MeshError` naming what is missing and how to get it."""
    try:
        import gmsh
    except (ImportError, OSError) as e:  # a missing system library raises OSError from the wheel's loader
        msg = str(e)
        for lib, pkg in SYSTEM_PACKAGES.items():
            if lib in msg:
                raise MeshError(f"outline bodies need gmsh, which cannot load the system library {lib} "
                                f"({msg.split(':')[0]}); install it (Debian/Ubuntu: apt-get install {pkg}) "
                                "or use column bodies") from None
        raise MeshError(f"outline bodies need gmsh, which cannot be imported ({msg}); pip install gmsh, or use "
                        "column bodies") from None
    return gmsh


def read_geo(path: str | Path, position: str, where: str):
    """``(face, x_range, outline)`` of the body drawn in ``path``."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{where}.geo: no file {short(str(path))}; give the path of a .geo file (relative to the "
                         "scene file)")
    gmsh = import_gmsh()
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        try:
            gmsh.open(str(path))
            gmsh.model.geo.synchronize()
        except Exception as e:  # gmsh reports parse errors as plain exceptions
            raise SceneError(f"{where}.geo: gmsh cannot read {short(str(path))} ({e}); fix the file") from None
        named = _curves(gmsh, where)
    finally:
        gmsh.finalize()
    return _outline(named, position, where)


def _curves(gmsh, where: str) -> dict[str, list[Segment]]:
    """Every physical curve's segments, by name."""
    out: dict[str, list[Segment]] = {}
    n = sum(len(gmsh.model.getEntitiesForPhysicalGroup(d, t)) for d, t in gmsh.model.getPhysicalGroups(1))
    if n > MAX_PARTS:
        raise SceneError(f"{where}.geo: {n} curves in physical groups, more than {MAX_PARTS}; draw the body with "
                         "fewer, longer curves")
    points = np.array([gmsh.model.getValue(0, t, [])[:2] for _, t in gmsh.model.getEntities(0)]).reshape(-1, 2)
    for dim, tag in gmsh.model.getPhysicalGroups(1):
        name = gmsh.model.getPhysicalName(dim, tag)
        if not name:
            raise SceneError(f"{where}.geo: physical curve {tag} has no name; name every part, e.g. "
                             "Physical Curve(\"bottom\") = {...};")
        if name in out:
            raise SceneError(f"{where}.geo: physical curve {name!r} is named twice; give every part its own name")
        out[name] = [_segment(gmsh, c, name, where, points) for c in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)]
    if "face" not in out:
        raise SceneError(f"{where}.geo: no physical curve named 'face'; name the contact face Physical Curve(\"face\")")
    return out


def _segment(gmsh, curve: int, name: str, where: str, points: np.ndarray) -> Segment:
    kind = gmsh.model.getType(1, curve)
    ends = gmsh.model.getBoundary([(1, curve)], oriented=True)
    if len(ends) != 2:
        raise SceneError(f"{where}.geo: part {name!r} has a closed curve {curve}; split it into arcs below half a turn")
    a, b = (tuple(map(float, gmsh.model.getValue(0, abs(t), [])[:2])) for _, t in ends)
    if kind == "Line":
        return Segment(a, b)
    if kind == "Circle":
        lo, hi = gmsh.model.getParametrizationBounds(1, curve)
        mid = gmsh.model.getValue(1, curve, [0.5 * (lo[0] + hi[0])])[:2]
        c = np.array(_center(np.array(a), np.array(mid), np.array(b)))
        # the file's own centre point where it has one: the fit through three points rounds
        near = np.flatnonzero(np.linalg.norm(points - c, axis=1) <= 1e-9 * (1.0 + np.linalg.norm(c)))
        return Segment(a, b, tuple(map(float, points[near[0]] if len(near) else c)))
    if kind in ("BSpline", "Bezier", "Nurb", "Spline"):  # a spline through points of gmsh's curve
        lo, hi = gmsh.model.getParametrizationBounds(1, curve)
        t = np.linspace(lo[0], hi[0], GEO_SPLINE_POINTS + 2)[1:-1]
        xyz = np.asarray(gmsh.model.getValue(1, curve, list(t))).reshape(-1, 3)
        return Segment(a, b, through=tuple(map(tuple, xyz[:, :2].tolist())))
    raise SceneError(f"{where}.geo: part {name!r} is a {kind} curve; outlines take lines, circle arcs and splines")


def _center(a, m, b) -> tuple[float, float]:
    """The centre of the circle through three points."""
    d = 2.0 * (a[0] * (m[1] - b[1]) + m[0] * (b[1] - a[1]) + b[0] * (a[1] - m[1]))
    sa, sm, sb = a @ a, m @ m, b @ b
    return (float((sa * (m[1] - b[1]) + sm * (b[1] - a[1]) + sb * (a[1] - m[1])) / d),
            float((sa * (b[0] - m[0]) + sm * (a[0] - b[0]) + sb * (m[0] - a[0])) / d))


def _outline(named: dict[str, list[Segment]], position: str, where: str):
    face = named.pop("face")
    if len(face) != 1:
        raise SceneError(f"{where}.geo: the face is {len(face)} curves; draw it as one line or one arc")
    if not named:
        raise SceneError(f"{where}.geo: the face is the only named curve; name the rest of the boundary too")
    f = face[0]
    (xa, ya), (xb, yb) = f.start, f.end
    x0, x1 = sorted((float(xa), float(xb)))
    left, right = ((xa, ya), (xb, yb)) if xa < xb else ((xb, yb), (xa, ya))
    scale = max(1.0, max(abs(v) for s in (seg for segs in named.values() for seg in segs) for v in (*s.start, *s.end)))
    tol = TOL * scale
    if f.is_arc:
        cx, cy = f.center
        r = math.dist(f.start, f.center)
        profile = (LowerCircle if position == "upper" else UpperCircle)(R=r, xc=cx, yc=cy)
        if abs(float(profile.value(0.5 * (x0 + x1))) - _arc_mid_y(f)) > tol:
            raise SceneError(f"{where}.geo: the face arc is not a graph y = f(x) on the {position} body's side; "
                             "draw the branch facing the other body")
    else:
        if abs(ya - yb) > tol:
            raise SceneError(f"{where}.geo: the face line is not horizontal; a straight face must be flat (y = const)")
        profile = Flat(y0=ya)
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


def _arc_mid_y(s: Segment) -> float:
    a0, sweep = s.angles()
    r = math.dist(s.start, s.center)
    return s.center[1] + r * math.sin(a0 + 0.5 * sweep)


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
