"""A column body as the outline body it is: how a run to a tolerance meshes every body.

A column body's mesh is a tensor product of columns and layers: refining a column splits it from
the face to the far side, refining a layer splits it across the body, so a singular corner or the
end of a contact zone costs whole rows of triangles (measured: cylinder-on-block reached a certified
1 % with 2.5 times the pieces of the same scene meshed as outline bodies). As an outline body the
same region is the strip of columns along the face and gmsh's mesh of the rest, which follows
sizes asked at points (:mod:`cvxdual.geometry.grid`). The region, the face and every boundary
part are the same: the sides become the outline parts ``right``, ``far`` and ``left`` (the path
from the face's right end to its left end), and a boundary part on an interval of a side becomes
its own part of the outline.
"""

from __future__ import annotations

from dataclasses import replace

from ..errors import SceneError
from ..scene.outline import Outline, Part, Segment
from ..scene.scene import WHY, Body, Scene

SIDE_ORDER = ("right", "far", "left")  # the outline's path: from the face's right end to its left end


def outline_scene(scene: Scene) -> Scene:
    """``scene`` with every column body given as its outline body (outline bodies as they are). The
    problem is the same, so is its exact field: declared again for the new scene where it solved the
    old one (else with the old one's reason)."""
    if all(not b.is_column for b in scene.bodies):
        return scene
    exact = scene.exact
    if exact is not None:
        why = scene.exact_mismatch
        exact = replace(exact, declared_for=None if why is None else ((WHY, why),))
    return replace(scene, bodies=tuple(outline_body(b) for b in scene.bodies), exact=exact)


def outline_body(body: Body) -> Body:
    """The outline body of the column ``body``: the same region, face and boundary parts."""
    if not body.is_column:
        return body
    x0, x1 = body.x_range
    f0, f1, far = float(body.face.value(x0)), float(body.face.value(x1)), float(body.far)
    ends = {"right": ((x1, f1), (x1, far)), "far": ((x1, far), (x0, far)), "left": ((x0, far), (x0, f0))}
    path, boundary = [], list(body.boundary)  # in their order, those on an interval renamed
    for side in SIDE_ORDER:
        index = [i for i, bp in enumerate(body.boundary) if bp.on == side]
        parts = [body.boundary[i] for i in index]
        a, b = ends[side]
        axis = 0 if side == "far" else 1
        if not any(bp.interval is not None for bp in parts):
            path.append(Part(side, (Segment(a, b),)))
            continue
        if len(parts) > 1 and any(bp.interval is None for bp in parts):
            raise _overlap(body, side)
        # stretches between the intervals' ends, in the path's direction along the side
        cuts = sorted({a[axis], b[axis], *(v for bp in parts for v in bp.interval)},
                      reverse=a[axis] > b[axis])
        named = []
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
            mid = 0.5 * (lo + hi)
            owners = [bp for bp in parts if min(bp.interval) < mid < max(bp.interval)]
            if len(owners) > 1:
                raise _overlap(body, side)
            p = (lambda v: (v, far)) if side == "far" else (lambda v, x=a[0]: (x, v))
            name = f"{side}:{owners[0].name}" if owners else f"{side}:{len(named)}"
            named.append(name)
            path.append(Part(name, (Segment(p(lo), p(hi)),)))
            for i, bp in zip(index, parts, strict=True):
                if any(bp is o for o in owners):
                    boundary[i] = replace(bp, on=name, interval=None)
    return replace(body, far=None, outline=Outline(tuple(path)), boundary=tuple(boundary))


def _overlap(body: Body, side: str) -> SceneError:
    return SceneError(f"body {body.name!r}: boundary parts overlap on its {side} side; a run to a tolerance meshes "
                      "the body by its outline, where each stretch of boundary has one part: give them disjoint "
                      "intervals")
