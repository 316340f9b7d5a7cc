"""Random outline bodies drawn the way users draw them, for the outline fuzzing (studies/outline_fuzzing.py).

A body's *shape* is the scene file's ``{x, face, outline, holes}`` (plus its ``position``):
:func:`shapes_of` redraws the bodies of a built-in outline scene: blocks with a flat or curved face,
straight, slanted, stepped or spline sides, rounded corners (arcs), notches (rectangular, V, arcs),
arc or spline far sides, and 0-4 holes (:func:`add_holes`: circles, triangles, rectangles, regular
and star polygons from 1/200 to 1/5 of the body, anywhere, just beyond the strip of columns, next
to another hole, next to the outline, or on a column's line), each checked clear of the rest.
:func:`geo_text` writes a shape as a gmsh ``.geo`` file in a random style, :func:`gmsh_curves`
evaluates its splines with gmsh itself (the oracle's truth for them).
"""

from __future__ import annotations

import copy
import json
import math

import numpy as np
from outline_region import dense_curve, distance, face_function, hole_curves, in_ring, region, spline

from cvxdual.geometry.mesh import column_abscissae
from cvxdual.scene.scenefile import load_scene

# per built-in scene, per body: (left side, right side, far side names), far height, parts kept at the start
TEMPLATES = {"block-with-hole": {"top": (("left", "right", "top"), 4.0, 0),
                                 "bottom": (("left", "right", "bottom"), -20.0, 0)},
             "rounded-punch": {"punch": (("symmetry", "side", "top"), 40.0, 1),
                               "block": (("symmetry", "side", "bottom"), -40.0, 0)}}


def uni(rng, a, b) -> float:
    return float(rng.uniform(a, b))


class Path:
    """An outline path under construction: parts with unique names."""

    def __init__(self, start, parts=()):
        self.parts, self.cur = [copy.deepcopy(p) for p in parts], tuple(start)

    def add(self, name, to, **kw):
        names = {p["name"] for p in self.parts}
        n, k = name, 2
        while n in names:
            n, k = f"{name}_{k}", k + 1
        self.parts.append({"name": n, "to": [float(to[0]), float(to[1])],
                           **{k: v for k, v in kw.items() if v is not None}})
        self.cur = (float(to[0]), float(to[1]))


def box_path(rng, start, end, far: float, sign: float, names, prefix=()) -> list:
    """From the face's right end (or the end of ``prefix``) round a block to the face's left end
    ``end``: right side, far side at height ``far``, left side (a straight vertical line: it holds
    the symmetry support); ``sign`` is +1 for an upper body, -1 for a lower one."""
    left, right, farname = names
    p = Path(start, prefix)
    xs, ys = p.cur
    H, W = abs(far - ys), abs(xs - end[0])
    rc_r = rc_l = 0.0
    r = rng.random()
    if r < 0.4:
        xr = xs
    elif r < 0.55:  # slanted outward
        xr = xs + uni(rng, 0.05, 0.4) * H
    elif r < 0.7:  # a step outward half way
        ym = ys + sign * uni(rng, 0.3, 0.7) * H
        p.add(right, (xs, ym))
        xr = xs + uni(rng, 0.1, 0.5) * min(H, W)
        p.add(right + "_step", (xr, ym))
    elif r < 0.85:  # a rounded far corner
        xr, rc_r = xs, uni(rng, 0.05, 0.4) * min(H, W)
    else:  # a spline bulging outward
        xr = xs + uni(rng, 0.0, 0.2) * H
        k = int(rng.integers(1, 4))
        t = (np.arange(1, k + 1) + rng.uniform(-0.1, 0.1, k)) / (k + 1)  # evenly spaced (else Catmull-Rom loops)
        bulge = uni(rng, 0.02, 0.15) * H
        through = [[float(xs + (xr - xs) * s + bulge * math.sin(math.pi * s)), float(ys + sign * s * H)] for s in t]
        p.add(right, (xr, far), through=through)
    if p.cur[1] != far:
        p.add(right, (xr, far - sign * rc_r))
        if rc_r:
            p.add(right + "_corner", (xr - rc_r, far), center=[xr - rc_r, far - sign * rc_r])
    if rng.random() < 0.3:
        rc_l = uni(rng, 0.05, 0.3) * min(H, W)
    xa, xb = p.cur[0], end[0] + rc_l
    span = xa - xb
    r = rng.random()
    if r < 0.45 or span <= 0:
        p.add(farname, (xb, far))
    elif r < 0.7:  # a notch: rectangular, V or an arc dipping into the body
        w, dn = uni(rng, 0.05, 0.3) * span, uni(rng, 0.1, 0.4) * H
        xn = uni(rng, xb + 0.6 * w, xa - 0.6 * w)
        p.add(farname, (xn + w / 2, far))
        kind = rng.integers(3)
        if kind == 0:
            p.add("notch", (xn + w / 2, far - sign * dn))
            p.add("notch", (xn - w / 2, far - sign * dn))
            p.add("notch", (xn - w / 2, far))
        elif kind == 1:
            p.add("vee", (xn, far - sign * dn))
            p.add("vee", (xn - w / 2, far))
        else:
            p.add("groove", (xn - w / 2, far), center=[xn, far + sign * uni(rng, 0.05, 1.0) * w])
        p.add(farname, (xb, far))
    elif r < 0.85:  # one arc, bulging out or dipping in (less than a half turn)
        k = uni(rng, 0.3, 3.0) * span * (1 if rng.random() < 0.7 else -1)
        p.add(farname, (xb, far), center=[0.5 * (xa + xb), far - sign * k])
    else:  # a spline wave
        n = int(rng.integers(1, 6))
        xs_ = xa - (xa - xb) * (np.arange(1, n + 1) + rng.uniform(-0.1, 0.1, n)) / (n + 1)
        p.add(farname, (xb, far), through=[[float(x), far + uni(rng, -0.1, 0.1) * H] for x in xs_])
    if rc_l:
        p.add(left + "_corner", (end[0], far - sign * rc_l), center=[end[0] + rc_l, far - sign * rc_l])
    p.add(left, end)
    return p.parts


def face_for(rng, position: str, geo: bool) -> dict:
    """A face for a block-with-hole body: flat, a circle, or (not in .geo files) a parabola."""
    r = rng.random()
    up = position == "upper"
    if r < 0.55:
        return {"kind": "flat", "y0": 0.0}
    R, xc = uni(rng, 14.0, 80.0), uni(rng, -2.0, 2.0)
    if r < 0.8 or geo:
        return {"kind": "circle", "R": R, "xc": xc, "yc": R if up else -R, "branch": "lower" if up else "upper"}
    return {"kind": "parabola", "R": R if up else -R, "xc": xc, "y0": 0.0}


def hole_shape(rng, c, r) -> dict:
    """A circle or a polygon (triangle, rectangle, regular or star polygon) about ``c``, radius ``r``."""
    k = rng.random()
    if k < 0.55:
        return {"center": [float(c[0]), float(c[1])], "radius": float(r)}
    a0 = uni(rng, 0, 2 * math.pi)
    if k < 0.7:
        n, rad = 4, np.full(4, r)
        ang = a0 + np.array([0.0, 1.0, 2.0, 3.0]) * math.pi / 2 + np.array([1, -1, 1, -1]) * uni(rng, 0.2, 0.6)
    else:
        n = int(rng.integers(3, 9))
        ang = a0 + np.arange(n) * 2 * math.pi / n
        rad = r * (rng.uniform(0.5, 1.0, n) if k > 0.85 else np.ones(n))
    pts = np.stack([c[0] + rad * np.cos(ang), c[1] + rad * np.sin(ang)], 1)
    if rng.random() < 0.5:
        pts = pts[::-1]  # clockwise is accepted too
    return {"points": pts.tolist()}


def _dense(curves) -> np.ndarray:
    """The points of closed curves, each line cut in 64 (a crossing shows as a point inside)."""
    t = np.linspace(0.0, 1.0, 65)[:-1, None]
    return np.concatenate([c.pts[0] + t * (c.pts[1] - c.pts[0]) if c.kind == "line" else c.pts[:-1] for c in curves])


def clearance(hole: dict, outer, others: list) -> float:
    """The hole's distance from the body's outline and face (the region ``outer``) and from the
    holes ``others`` (negative if it is not inside the outline, or crosses it or one of them)."""
    hc = hole_curves(hole)
    hp, rim = _dense(hc), _dense(outer.outer)
    if not in_ring(outer.rings()[0], hp).all() or in_ring(hp, rim).any():
        return -1.0
    d = min([float(distance(hp, c).min()) for c in outer.outer] + [float(distance(rim, c).min()) for c in hc])
    for o in others:
        oc = hole_curves(o)
        op = _dense(oc)
        if in_ring(op, hp).any() or in_ring(hp, op).any():
            return -1.0
        d = min([d] + [float(distance(hp, c).min()) for c in oc] + [float(distance(op, c).min()) for c in hc])
    return d


def body_region(shape: dict):
    """The region of a shape without its holes; a .geo body's splines are gmsh's own curves."""
    specs = spline_specs(shape)
    return region({**shape, "holes": []}, gmsh_curves(specs) if specs else None)


def spline_specs(shape: dict) -> dict:
    """``{part: (gmsh kind, points)}`` of a .geo body's splines (their kinds in ``geo_kinds``)."""
    kinds, out = shape.get("geo_kinds"), {}
    if kinds is None:
        return out
    cur = [shape["x"][1], float(face_function(shape["face"])(shape["x"][1]))]
    for p in shape["outline"]:
        if "through" in p:
            out[p["name"]] = (kinds.get(p["name"], "Spline"), [list(cur), *p["through"], list(p["to"])])
        cur = p["to"]
    return out


def add_holes(rng, shape: dict, n: int, cols: np.ndarray) -> list:
    """Up to ``n`` holes clear of each other and of the outline (a few tries each); most also clear
    of the strip of columns ``cols`` (one column spacing deep)."""
    x0, x1 = shape["x"]
    f = face_function(shape["face"])
    sign = 1.0 if shape["position"] == "upper" else -1.0
    reg = body_region(shape)
    ring, n_face = reg.rings()[0], len(reg.outer[0].pts)
    inward = 1.0 if sum(c.green for c in reg.outer) > 0 else -1.0  # counter-clockwise: the body on the left
    lo, hi = ring.min(0), ring.max(0)
    size = float(np.max(hi - lo))
    cols = cols[(cols >= x0) & (cols <= x1)]
    w = np.diff(cols)
    depth = np.concatenate([[w[0]], np.maximum(w[:-1], w[1:]), [w[-1]]])  # the larger adjacent spacing

    def strip(x):
        return np.interp(x, cols, depth)
    holes = []
    for _ in range(n):
        for _try in range(12):
            r = size * 10 ** uni(rng, -2.3, -0.7)
            mode, gap = rng.integers(5), 0.0
            if mode == 0 or (mode == 2 and not holes):  # anywhere
                c = rng.uniform(lo, hi)
            elif mode == 1:  # just beyond the strip
                x = uni(rng, x0 + r, x1 - r)
                c = np.array([x, float(f(x)) + sign * (float(strip(x)) * uni(rng, 1.02, 3.0) + r)])
            elif mode == 2:  # next to another hole
                o = holes[int(rng.integers(len(holes)))]
                oc = np.mean(o["points"], 0) if "points" in o else np.array(o["center"])
                ro = o.get("radius", float(np.max(np.linalg.norm(np.array(o.get("points", [oc])) - oc, axis=1))))
                gap = (r + ro) * 10 ** uni(rng, -2.5, -0.5)
                a = uni(rng, 0, 2 * math.pi)
                c = oc + (ro + r + gap) * np.array([math.cos(a), math.sin(a)])
            elif mode == 3:  # next to the outline (not the face), along its inward normal
                i = int(rng.integers(n_face, len(ring) - 1))
                t = ring[i + 1] - ring[i - 1]
                nrm = inward * np.array([-t[1], t[0]]) / max(float(np.linalg.norm(t)), 1e-300)
                gap = r * 10 ** uni(rng, -2.5, -0.3)
                c = ring[i] + (r + gap) * nrm
            else:  # on a column's line
                x = float(cols[rng.integers(len(cols))]) + (0.0 if rng.random() < 0.5 else r)  # centre or side on it
                c = np.array([x, uni(rng, lo[1], hi[1])])
            h = hole_shape(rng, c, r)
            hp = np.concatenate([q.pts for q in hole_curves(h)])
            if rng.random() < 0.97 and np.any(distance(hp, reg.outer[0]) < 1.05 * strip(hp[:, 0])):
                continue  # in the strip: refused (3 % are kept to see that)
            if clearance(h, reg, holes) > max(0.3 * gap, 1e-3 * r):
                holes.append({"name": f"hole{len(holes) + 1}", **h})
                break
    return holes


def shapes_of(data: dict, base: str, rng, geo_body: str | None, level: int) -> dict:
    """Every body's shape, redrawn (mostly) from the built-in one (holes placed for ``level``)."""
    out = {}
    cols = column_abscissae(load_scene(data), level)
    for name, (names, far, keep) in TEMPLATES[base].items():
        b = data["bodies"][name]
        shape = {"position": b["position"], "x": list(b["x"]), "face": b["face"], "outline": b["outline"],
                 "holes": copy.deepcopy(b.get("holes", []))}
        sign = 1.0 if b["position"] == "upper" else -1.0
        if base == "block-with-hole" and rng.random() < 0.35:
            shape["face"] = face_for(rng, b["position"], geo_body == name)
            xs = np.linspace(*shape["x"], 201)
            ext = float(np.max(sign * face_function(shape["face"])(xs)))
            far = sign * ext + far
        if rng.random() < 0.75 or shape["face"] is not b["face"]:
            f = face_function(shape["face"])
            x0, x1 = shape["x"]
            start = b["outline"][keep - 1]["to"] if keep else (x1, float(f(x1)))
            shape["outline"] = box_path(rng, start, (x0, float(f(x0))), far, sign, names, b["outline"][:keep])
        if name == geo_body:  # the kind of curve each spline will be in the .geo file
            shape["geo_kinds"] = {p["name"]: str(rng.choice(["Spline", "BSpline", "Bezier"]))
                                  for p in shape["outline"] if "through" in p}
        if rng.random() < 0.7:
            shape["holes"] = add_holes(rng, shape, int(rng.choice([1, 1, 2, 3, 4])), cols)
        out[name] = shape
    return out


def _num(v, rng, style: dict) -> str:
    """A coordinate as .geo text: the number, or (with variables) an expression worth it; a hostile
    value as it is (10**400 in all its digits, inf, nan)."""
    if isinstance(v, int) or not math.isfinite(v):
        return str(v)
    v = float(v)  # not numpy's scalar, whose repr is np.float64(...)
    if style["vars"] and rng.random() < 0.4:
        return f"{2 * v!r} / two" if rng.random() < 0.5 else f"({v - 10.0!r}) + ten"
    return repr(float(v))


def geo_text(shape: dict, rng) -> tuple[str, dict]:
    """A .geo file of the body ``shape`` in a random style (sizes at points, variables, reversed
    curves, loops and a surface, tag offsets); and the gmsh splines by part name ``(kind, points)``."""
    style = {"lc": rng.random() < 0.3, "vars": rng.random() < 0.25, "loops": rng.random() < 0.3,
             "reverse": float(rng.uniform(0, 0.5)), "offset": int(rng.choice([1, 1, 10, 100]))}
    out = ["// a body drawn by studies/outline_fuzzing.py"]
    if style["vars"]:
        out += ["two = 2;", "ten = 10;"]
    if style["lc"]:
        out.append("lc = 0.5;")
    pts, curves, physical, splines = {}, [], {}, {}

    def point(xy) -> int:
        key = (xy[0], xy[1])
        if key not in pts:
            pts[key] = style["offset"] + len(pts)
            lc = ", lc" if style["lc"] else ""
            out.append(f"Point({pts[key]}) = {{{_num(key[0], rng, style)}, {_num(key[1], rng, style)}, 0{lc}}};")
        return pts[key]

    def curve(name, kind, ids) -> None:
        tag = style["offset"] + len(curves)
        rev = rng.random() < style["reverse"]
        out.append(f"{kind}({tag}) = {{{', '.join(map(str, ids[::-1] if rev else ids))}}};")
        curves.append(-tag if rev else tag)
        physical.setdefault(name, []).append(tag)

    x0, x1 = shape["x"]
    f = face_function(shape["face"])
    left, right = (x0, float(f(x0))), (x1, float(f(x1)))
    face = shape["face"]
    if face["kind"] == "circle":
        curve("face", "Circle", [point(left), point((face["xc"], face["yc"])), point(right)])
    else:
        curve("face", "Line", [point(left), point(right)])
    loops, cur = [list(curves)], right
    for p in shape["outline"]:
        if "center" in p:
            curve(p["name"], "Circle", [point(cur), point(p["center"]), point(p["to"])])
        elif "through" in p:
            kind = shape.get("geo_kinds", {}).get(p["name"]) or str(rng.choice(["Spline", "BSpline", "Bezier"]))
            curve(p["name"], kind, [point(q) for q in (cur, *p["through"], p["to"])])
            splines[p["name"]] = (kind, [list(cur), *p["through"], list(p["to"])])
        else:
            curve(p["name"], "Line", [point(cur), point(p["to"])])
        cur = p["to"]
    loops[0] = list(curves)
    for h in shape["holes"]:
        n0 = len(curves)
        if "radius" in h:
            (cx, cy), r = h["center"], h["radius"]
            k = int(rng.choice([3, 4]))
            q = [(cx + r * math.cos(2 * math.pi * j / k), cy + r * math.sin(2 * math.pi * j / k)) for j in range(k)]
            for j in range(k):
                curve(h["name"], "Circle", [point(q[j]), point((cx, cy)), point(q[(j + 1) % k])])
        else:
            for a, b in zip(h["points"], h["points"][1:] + h["points"][:1], strict=True):
                curve(h["name"], "Line", [point(a), point(b)])
        loops.append(curves[n0:])
    if style["loops"]:
        for k, loop in enumerate(loops):
            out.append(f"Curve Loop({k + 1}) = {{{', '.join(map(str, loop))}}};")
        out += [f"Plane Surface(1) = {{{', '.join(str(k + 1) for k in range(len(loops)))}}};",
                'Physical Surface("body") = {1};']
    names = list(physical)
    for k in rng.permutation(len(names)):
        out.append(f'Physical Curve({json.dumps(names[k])}) = {{{", ".join(map(str, physical[names[k]]))}}};')
    return "\n".join(out) + "\n", splines


def gmsh_curves(splines: dict) -> dict:
    """gmsh's own curve of each .geo spline, densely sampled (the oracle's truth for it), with the
    distance of the refit the docs describe (a spline through 31 of its points) from it."""
    import gmsh

    out = {}
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        for name, (kind, pts) in splines.items():
            gmsh.model.add(name)
            tags = [gmsh.model.geo.addPoint(x, y, 0) for x, y in pts]
            c = getattr(gmsh.model.geo, f"add{kind}")(tags)
            gmsh.model.geo.synchronize()
            lo, hi = gmsh.model.getParametrizationBounds(1, c)
            dense = _values(gmsh, c, np.linspace(lo[0], hi[0], 4001))
            dense[0], dense[-1] = pts[0], pts[-1]
            refit = spline(pts[0], _values(gmsh, c, np.linspace(lo[0], hi[0], 33)[1:-1]).tolist(), pts[-1])
            out[name] = dense_curve(dense, extra=float(distance(dense, refit).max()))
    finally:
        gmsh.finalize()
    return out


def _values(gmsh, curve: int, t) -> np.ndarray:
    return np.asarray(gmsh.model.getValue(1, curve, list(t))).reshape(-1, 3)[:, :2]
