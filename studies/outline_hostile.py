"""Hostile outline bodies for the outline fuzzing (studies/outline_fuzzing.py).

:func:`mutate_shape` changes a body's shape (the scene file's ``x, face, outline, holes``) into one
a scene must refuse (touching, overlapping or nested holes, a hole outside or across the outline or
the face, a bow-tie, an out-and-back path, a half-turn arc, inf, too many parts, ...) or into an
odd but valid one it must mesh right (a scene scaled by 1e+-3..9 or moved by 1e3..1e12, tiny holes,
holes 1e-9 apart, repeated spline points, 150 parts, a nearly straight arc). :func:`mutate_geo`
breaks a ``.geo`` file's text: non-zero z, unnamed curves, forbidden statements (System, Include,
For, Exit, Merge, Save, ...; those that would touch files write into ``{DIR}``, the case's folder,
so that their effect shows), undefined or redefined points, syntax errors, 1e400, deep parentheses,
long comments, bytes that are not UTF-8. Each returns whether the result must be refused.
"""

from __future__ import annotations

import math
import re

import numpy as np
from outline_region import face_function

SHAPE_HOSTILE = ("tangent-holes", "overlapping-holes", "hole-in-hole", "collinear-hole", "repeated-hole-point",
                 "tiny-hole", "hole-touching-outline", "hole-crossing-outline", "hole-outside", "hole-crossing-face",
                 "hole-vertex-on-outline", "bowtie-hole", "holes-1e-9-apart", "negative-radius", "zero-radius",
                 "hole-bad-type", "duplicate-names", "out-and-back", "reversed-path", "bowtie-path", "arc-center-off",
                 "arc-half-turn", "near-straight-arc", "repeated-spline-points", "spline-loop", "spline-many-points",
                 "many-parts", "too-many-parts", "scaled", "scaled-extreme", "translated", "translated-far",
                 "inf-coordinate")
INVARIANT = {"scaled", "translated"}  # the same body: meshed (or refused) as the body unmoved at its size
# meaningless in a .geo file (a circle of negative radius is drawn as one of positive radius; a
# .geo file has no path order; its numbers are not typed)
SHAPE_ONLY = {"negative-radius", "reversed-path", "hole-bad-type"}
# valid, if odd, geometry: accepted or refused, a mesh must be the body
MAY_PASS = {"repeated-hole-point", "tiny-hole", "holes-1e-9-apart", "near-straight-arc", "repeated-spline-points",
            "spline-loop", "spline-many-points", "many-parts", "scaled", "translated", "translated-far"}
GEO_HOSTILE = ("geo-z", "geo-unnamed-physical", "geo-unnamed-curve", "geo-system", "geo-include", "geo-for",
               "geo-exit", "geo-merge", "geo-save", "geo-printf", "geo-macro", "geo-mesh", "geo-setfactory",
               "geo-delete", "geo-ellipse", "geo-undefined-point", "geo-duplicate-point", "geo-syntax",
               "geo-huge-number", "geo-nested-parens", "geo-long-comment", "geo-binary", "geo-two-faces",
               "geo-no-face", "geo-empty", "geo-options", "geo-crlf", "geo-bom")
GEO_MAY_PASS = {"geo-nested-parens", "geo-long-comment", "geo-binary", "geo-options", "geo-crlf", "geo-bom"}
STATEMENTS = {"geo-system": 'System "touch {DIR}/system-ran";', "geo-include": 'Include "extra.geo";',
              "geo-for": 'For i In {1:3}\n  Printf("step %g", i);\nEndFor', "geo-exit": "Exit;",
              "geo-merge": 'Merge "{DIR}/extra.geo";', "geo-save": 'Save "{DIR}/saved.msh";',
              "geo-printf": 'Printf("hello") > "{DIR}/printed.txt";',
              "geo-macro": 'Macro Hello\n  Printf("hello");\nReturn\nCall Hello;', "geo-mesh": "Mesh 2;",
              "geo-setfactory": 'SetFactory("OpenCASCADE");', "geo-delete": "Delete Model;",
              "geo-ellipse": "Point(9001) = {0, 0, 0};\nPoint(9002) = {1, 0, 0};\nPoint(9003) = {0, 0.5, 0};\n"
                             "Ellipse(9001) = {9002, 9001, 9002, 9003};\nPhysical Curve(\"oval\") = {9001};"}
EXTRA_GEO = "// included by the fuzzed file\nPoint(9999) = {0, 0, 0};\n"


def _box(shape: dict, far: float, names) -> None:
    """Make the body a plain block (its template's names): straight sides, no holes."""
    left, right, farname = names
    x0, x1 = shape["x"]
    start = shape["outline"][0]["to"] if shape["outline"][0]["name"] == "corner" else None
    keep = [shape["outline"][0]] if start is not None else []
    sx = start[0] if start else x1
    shape["outline"] = keep + [{"name": right, "to": [sx, far]}, {"name": farname, "to": [x0, far]},
                               {"name": left, "to": [x0, float(face_function(shape["face"])(x0))]}]
    shape["holes"] = []


def _transform(shapes: dict, data: dict, s: float, t) -> None:
    """Scale every shape (and the mesh focus) by ``s`` and move it by ``t``."""
    s, t = float(s), (float(t[0]), float(t[1]))

    def T(p):
        return [s * p[0] + t[0], s * p[1] + t[1]]
    for sh in shapes.values():
        sh["x"] = [T([x, 0])[0] for x in sh["x"]]
        f = sh["face"]
        if f["kind"] == "composite":
            f["start"] = T(f["start"])
            for p in f["pieces"]:
                p.update({k: T(p[k]) for k in ("to", "center") if k in p})
        else:
            f.update({k: s * f[k] for k in ("R",) if k in f})
            f.update({k: s * f.get(k, 0.0) + t[0] for k in ("xc",) if f["kind"] != "flat"})
            f.update({k: s * f.get(k, 0.0) + t[1] for k in ("y0", "yc") if k in f or (f["kind"], k) == ("flat", "y0")})
        for p in sh["outline"]:
            p.update({k: T(p[k]) for k in ("to", "center") if k in p})
            if "through" in p:
                p["through"] = [T(q) for q in p["through"]]
        for h in sh["holes"]:
            if "radius" in h:
                h.update(center=T(h["center"]), radius=s * h["radius"])
            else:
                h["points"] = [T(q) for q in h["points"]]
    if data.get("mesh", {}).get("focus"):
        data["mesh"]["focus"] = [s * v + t[0] for v in data["mesh"]["focus"]]


def _circle(c, r, name="hole"):
    return {"name": name, "center": [float(c[0]), float(c[1])], "radius": float(r)}


def mutate_shape(kind: str, rng, shapes: dict, target: str, data: dict, template) -> bool:
    """Apply ``kind`` to ``shapes[target]`` (or to all shapes); ``template`` is the target's
    ``(names, far)``. Returns whether the scene must be refused."""
    sh = shapes[target]
    names, far = template
    sign = 1.0 if sh["position"] == "upper" else -1.0
    x0, x1 = sh["x"]
    W = x1 - x0
    fy = [float(face_function(sh["face"])(x)) for x in (x0, x1)]
    if kind not in ("scaled", "scaled-extreme", "translated", "translated-far", "inf-coordinate"):
        _box(sh, far, names)
    H = abs(far - fy[0])
    c = np.array([0.5 * (x0 + x1), 0.5 * (max(fy) + far) if sign < 0 else 0.5 * (min(fy) + far)])
    r = 0.08 * min(H, W)
    holes, parts = sh["holes"], sh["outline"]
    u = np.array([math.cos(a := rng.uniform(0, 2 * math.pi)), math.sin(a)])
    if kind == "tangent-holes":
        holes += [_circle(c - r * u, r, "a"), _circle(c + 0.5 * r * u, 0.5 * r, "b")]  # both through c
    elif kind == "overlapping-holes":
        holes += [_circle(c - 0.6 * r * u, r, "a"), _circle(c + 0.6 * r * u, r, "b")]
    elif kind == "hole-in-hole":
        holes += [_circle(c, r, "outer"), _circle(c + 0.3 * r * u, 0.3 * r, "inner")]
    elif kind == "collinear-hole":
        holes.append({"name": "flat", "points": [list(c - r * u), list(c), list(c + r * u)]})
    elif kind == "repeated-hole-point":
        sq = [list(c + r * np.array(v)) for v in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
        holes.append({"name": "square", "points": sq[:2] + [sq[1]] + sq[2:]})
    elif kind == "tiny-hole":
        holes.append(_circle(c, r * 10 ** rng.uniform(-9, -5), "speck"))
    elif kind == "hole-touching-outline":
        holes.append(_circle((c[0], far - sign * r), r))
    elif kind == "hole-crossing-outline":
        holes.append(_circle((c[0], far - sign * 0.5 * r), r))
    elif kind == "hole-outside":
        holes.append(_circle((c[0], far + sign * 2 * r), r))
    elif kind == "hole-crossing-face":
        holes.append(_circle((c[0], float(face_function(sh["face"])(c[0])) + sign * 0.5 * r), r))
    elif kind == "hole-vertex-on-outline":
        holes.append({"name": "tri", "points": [[c[0], far], [c[0] + r, far - sign * r], [c[0] - r, far - sign * r]]})
    elif kind == "bowtie-hole":
        corners = ((-1, -1), (1, 1), (1, -1), (-1, 1))
        holes.append({"name": "bowtie", "points": [list(c + r * np.array(v)) for v in corners]})
    elif kind == "holes-1e-9-apart":
        holes += [_circle(c - r * u, r, "a"), _circle(c + (1 + 1e-9) * r * u, r, "b")]
    elif kind in ("negative-radius", "zero-radius"):
        holes.append(_circle(c, -r if kind == "negative-radius" else 0.0))
    elif kind == "hole-bad-type":
        holes.append(_circle(c, r))
        holes[-1][str(rng.choice(["radius", "center"]))] = [str(r), "1.0", [1.0], {"r": 1.0}][rng.integers(4)]
    elif kind == "duplicate-names":
        twin = str(rng.choice(["twin", names[0]]))
        holes += [_circle(c - 2 * r * u, r, "twin"), _circle(c + 2 * r * u, r * 0.5, twin)]
    elif kind == "out-and-back":
        k = int(rng.integers(len(parts) - 1))
        prev = parts[k - 1]["to"] if k else [x1, fy[1]]
        end = parts[k]["to"]
        spur = [end[0] + 0.3 * (end[0] - prev[0]) + 0.01, end[1] + 0.3 * (end[1] - prev[1])]
        parts[k + 1:k + 1] = [{"name": "spur", "to": spur}, {"name": "back", "to": list(end)}]
    elif kind == "reversed-path":
        pts = [[x1, fy[1]]] + [p["to"] for p in parts]
        sh["outline"] = [{"name": p["name"], "to": q} for p, q in zip(parts, pts[-2::-1], strict=True)]
    elif kind == "bowtie-path":
        parts[0]["to"], parts[1]["to"] = [x0, far], [parts[0]["to"][0], far]
    elif kind in ("arc-half-turn", "near-straight-arc", "arc-center-off"):  # the far side, an arc
        i = next(j for j, p in enumerate(parts) if p["name"] == names[2])
        a, b = parts[i - 1]["to"], parts[i]["to"]
        k = {"arc-half-turn": 0.0, "near-straight-arc": 1e6 * W, "arc-center-off": 0.3 * W}[kind]
        parts[i]["center"] = [0.5 * (a[0] + b[0]) + (0.05 * W if kind == "arc-center-off" else 0.0), far - sign * k]
    elif kind in ("repeated-spline-points", "spline-loop", "spline-many-points"):
        a = parts[-2]["to"]
        xs = np.linspace(parts[-3]["to"][0], a[0], 7)[1:-1] if len(parts) > 2 else np.linspace(x1, x0, 7)[1:-1]
        through = [[float(x), far] for x in xs]
        if kind == "repeated-spline-points":
            i = int(rng.integers(len(through)))
            through.insert(i, list(through[i]))
        elif kind == "spline-loop":
            through = [[xs[3], far], [xs[1], far - sign * 0.3 * H], [xs[2], far + sign * 0.2 * H], [xs[0], far]]
        else:
            xm = np.linspace(through[0][0], through[-1][0], 190)
            through = [[float(x), far - sign * 0.05 * H * math.sin(9 * math.pi * (x - x0) / W) ** 2] for x in xm]
        parts[-2]["through"] = through
    elif kind in ("many-parts", "too-many-parts"):
        n = 150 if kind == "many-parts" else 250
        a, b = (parts[-3]["to"] if len(parts) > 2 else [x1, far]), parts[-2]["to"]
        xs = np.linspace(a[0], b[0], n + 1)[1:]
        ys = far - sign * 0.02 * H * (np.arange(n) % 2)
        ys[-1] = b[1]
        parts[-2:-1] = [{"name": f"z{i}", "to": [float(x), float(y)]} for i, x, y in zip(range(n), xs, ys, strict=True)]
        parts[-2]["name"] = names[2]
    elif kind in ("scaled", "scaled-extreme", "translated", "translated-far"):
        if kind.startswith("translated"):  # 1e8 leaves 1e-9 of a body of size 20; 1e12 leaves 1e-5
            lo, hi = (3, 8) if kind == "translated" else (9, 12)
            _transform(shapes, data, 1.0, 10 ** rng.uniform(lo, hi, 2) * rng.choice([-1, 1], 2))
        else:
            lo, hi = (3, 9) if kind == "scaled" else (120, 200)
            _transform(shapes, data, float(10 ** (rng.uniform(lo, hi) * rng.choice([-1, 1]))), (0.0, 0.0))
    elif kind == "inf-coordinate":
        p = parts[int(rng.integers(len(parts) - 1))]
        p["to"][int(rng.integers(2))] = [math.inf, -math.inf, math.nan, 1e308, 10**400][rng.integers(5)]
    else:
        raise ValueError(kind)
    return kind not in MAY_PASS


def _sub_random(rng, pattern: str, text: str, repl) -> str:
    """``text`` with one random match of ``pattern`` replaced by ``repl(match)``."""
    found = list(re.finditer(pattern, text, flags=re.M))
    if not found:
        return text
    m = found[int(rng.integers(len(found)))]
    return text[:m.start()] + repl(m) + text[m.end():]


def mutate_geo(kind: str, rng, text: str) -> tuple[str, bool, dict]:
    """``(text, must_refuse, extra files)``: ``text`` of a .geo file broken by ``kind``."""
    lines = text.splitlines()
    extra = {}
    point = r"^Point\((\d+)\) = \{([^,]+), ([^,]+), ([^,}]+)"
    if kind == "geo-z":
        z = rng.uniform(0.1, 5)
        text = _sub_random(rng, point, text, lambda m: f"{m.group(0)[:m.start(4) - m.start()]}{z:.6g}")
    elif kind == "geo-unnamed-physical":
        text = _sub_random(rng, r'^Physical Curve\("(?!face")[^"]*"\)', text, lambda m: "Physical Curve(77)")
    elif kind == "geo-unnamed-curve":
        text = _sub_random(rng, r'^Physical Curve\("(?!face")[^"]*"\).*\n', text, lambda m: "")
    elif kind in STATEMENTS:
        at = int(rng.integers(len(lines) + 1)) if kind != "geo-ellipse" else len(lines)
        lines.insert(at, STATEMENTS[kind])
        text = "\n".join(lines) + "\n"
        if kind in ("geo-include", "geo-merge"):
            extra["extra.geo"] = EXTRA_GEO
    elif kind == "geo-undefined-point":
        text = _sub_random(rng, r"^Line\((\d+)\) = \{(\d+)", text, lambda m: f"Line({m.group(1)}) = {{99999")
    elif kind == "geo-duplicate-point":
        text = _sub_random(rng, point, text, lambda m: f"Point({m.group(1)}) = {{{m.group(2)} + 1, {m.group(3)}, 0}};\n"
                                                       f"{m.group(0)}")
    elif kind == "geo-syntax":
        text = _sub_random(rng, r"[{}(=]", text, lambda m: "")  # (a lost ';' or ',' may be forgiven)
    elif kind in ("geo-huge-number", "geo-nested-parens"):
        d = int(rng.choice([50, 5000, 200000]))
        text = _sub_random(rng, point, text, lambda m: m.group(0).replace(
            "{" + m.group(2), "{" + ("1e400" if kind == "geo-huge-number" else "(" * d + m.group(2) + ")" * d), 1))
    elif kind == "geo-long-comment":
        text = ("// " + "x" * 3_000_000 + "\n" if rng.random() < 0.5 else "/* " + "y\n" * 500_000 + "*/\n") + text
    elif kind == "geo-binary":
        lines.insert(int(rng.integers(len(lines) + 1)), "// \udcff\udcfe\udc80 not UTF-8")
        text = "\n".join(lines) + "\n"
    elif kind == "geo-two-faces":
        text = _sub_random(rng, r'^Physical Curve\("(?!face")[^"]*"\)', text, lambda m: 'Physical Curve("face")')
    elif kind == "geo-no-face":
        text = text.replace('Physical Curve("face")', 'Physical Curve("contact")')
    elif kind == "geo-empty":
        text = "" if rng.random() < 0.5 else "// nothing here\n"
    elif kind == "geo-options":
        lines.insert(int(rng.integers(len(lines) + 1)), "Mesh.CharacteristicLengthMax = 1;\nGeometry.Tolerance = 1e-8;")
        text = "\n".join(lines) + "\n"
    elif kind == "geo-crlf":
        text = text.replace("\n", "\r\n")
    elif kind == "geo-bom":
        text = "\ufeff" + text
    else:
        raise ValueError(kind)
    return text, kind not in GEO_MAY_PASS, extra
