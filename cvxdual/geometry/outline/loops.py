"""The loops gmsh meshes between: the outer loop runs from the strip's inner chain at its right end
along the outline's path to the face's left end, back along the strip's side and the chain (the
sides are left out where the path itself runs down them, :func:`continues_side`); each hole is a
loop of its own. No outline part may cross the strip (:func:`check_strip`), and the polygons that
stand for the curves must still bound one region (:func:`polygons_clear`): at this level's
polygons the body is refused, at gmsh's coarser ones it is meshed at this level directly."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...errors import MeshError
from ...scene.planar import segments_meet
from .arcs import clash_message, first_clash
from .build import OutlineBuild


def add_loops(build: OutlineBuild) -> None:
    """The outer loop (``build.loop``: the path's ``build.n_path`` curves, then the chain's) and
    the holes' loops, every curve recorded in its part."""
    b = build
    b.chain_pts = [b.point(b.chain[i], b.w[k]) for k, i in enumerate(range(0, b.nc, b.step))]
    path, trim_last = _path(b)
    ccw = b.body.position == "upper"  # the path runs counter-clockwise round an upper body
    for name, s in path:
        cs = b.curve(name, s, s.is_arc and (s.angles()[1] > 0) != ccw)
        b.loop += cs
        b.part_curves.setdefault(name, []).extend(cs)
    if trim_last:
        b.part_curves[path[-1][0]].append(("strip", 0))
    else:
        b.loop.append(b.line(b.point(b.ends["left"], b.side[0]), b.chain_pts[0], keep=True, mid=None))
    b.n_path = len(b.loop)
    for k in range(len(b.chain_pts) - 1):
        b.loop.append(b.line(b.chain_pts[k], b.chain_pts[k + 1], keep=True,
                             mid=tuple(b.chain[b.step * k + 1]) if b.step > 1 else False))
    for h in b.body.outline.holes:
        cs = [c for s in h.segments for c in b.curve(h.name, s, True)]  # the body lies outside its holes
        b.part_curves[h.name] = cs
        b.holes.append(cs)


def _path(b: OutlineBuild) -> tuple[list, bool]:
    """The outline's ``(part name, segment)`` path from the face's right end to its left end,
    starting (ending) at the chain's end where it runs down the strip's side; else the side's
    line at the right end is added to the loop. Also whether the last segment was trimmed."""
    path = [(p.name, s) for p in b.body.outline.path for s in p.segments]
    # the path's ends are the face's ends exactly (the outline check allows rounding)
    path[0] = (path[0][0], replace(path[0][1], start=b.ends["right"]))
    path[-1] = (path[-1][0], replace(path[-1][1], end=b.ends["left"]))
    first_name, first = path[0]
    last_name, last = path[-1]
    if continues_side(first, b.ends["right"], b.chain[-1], b.body.sign):
        path[0] = (first_name, replace(first, start=tuple(b.chain[-1])))
        b.part_curves[first_name] = [("strip", b.nc - 1)]
    else:  # the strip's side: not halved (the strip's own mesh does not split it)
        b.loop.append(b.line(b.chain_pts[-1], b.point(b.ends["right"], b.side[-1]), keep=True, mid=None))
    trim_last = continues_side(last, b.ends["left"], b.chain[0], b.body.sign, at_end=True)
    if trim_last:
        path[-1] = (last_name, replace(last, end=tuple(b.chain[0])))
    return path, trim_last


def polygons_clear(build: OutlineBuild) -> bool:
    """Whether the polygons bound one region as gmsh gets them; a :class:`MeshError` if they do
    not at this level's (a part closer to a curve than its chords are, :mod:`~cvxdual.geometry.outline.arcs`)."""
    b = build
    label = {c: name for name, cs in b.part_curves.items() for c in cs if not isinstance(c, tuple)}
    rings = [b.loop] + b.holes
    owners = [[label.get(c) for c in r] for r in rings]  # None: the strip's chain and sides
    clash = first_clash([[b.at_level(c) for c in r] for r in rings], owners)
    if clash:
        polygons = {name: np.concatenate([b.at_level(c) for r, o in zip(rings, owners, strict=True)
                                          for c, n in zip(r, o, strict=True) if n == name])
                    for name in {n for o in owners for n in o} - {None}}
        raise MeshError(clash_message(b.body, b.level, *clash, polygons, b.chain))
    return not (b.step > 1 and first_clash([[b.shape[c][0] for c in r] for r in rings], owners))


def check_strip(body, chain: np.ndarray) -> None:
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


def continues_side(seg, end, inner, sign, at_end=False) -> bool:
    """Whether the outline's segment at a face end runs along the strip's side: a vertical line
    leaving the face end away from the face, longer than the strip is deep."""
    if seg.is_arc or seg.axis != "y":
        return False
    far = seg.start if at_end else seg.end
    depth = abs(inner[1] - end[1])
    return sign * (far[1] - end[1]) > depth * (1 + 1e-9)
