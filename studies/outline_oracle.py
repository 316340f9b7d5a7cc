"""The oracle of the outline fuzzing (studies/outline_fuzzing.py): is a mesh the body that was drawn?

Independent of the package's own checks: the body is the generator's own (studies/outline_region.py:
the exact region of its shape and the bands within which the mesh's polygon of each curved
boundary may stray), and a mesh's triangles of that body are compared with it (:func:`check_body`):

- *area*: the triangles' total area against the region's exact area, within the area between each
  curved boundary and its mesh polygon (its band swept along it);
- *coverage*: no inverted triangle, no edge of more than two triangles, every boundary edge on the
  region's boundary, every triangle's centroid in exactly one triangle and in the region, random
  points of the region in exactly one triangle, random points of the holes and outside in none.

Points within a band are not sampled. Everything is vectorised: no loop over triangles or points
(point location by a grid of cells over the triangles' bounding boxes).
"""

from __future__ import annotations

import numpy as np
from outline_region import ROUNDING, Region, distance, in_ring


def beyond_bands(reg: Region, p: np.ndarray) -> np.ndarray:
    """Points farther than its band from every curve (where the mesh must be exactly the region)."""
    ok = np.ones(len(p), bool)
    for c in reg.curves:  # a few dozen curves, each vectorised over the points
        ok &= distance(p, c) > c.band
    return ok


def hits(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """How many of the triangles ``tri`` ``(m, 3, 2)`` contain each point of ``p`` ``(n, 2)``:
    triangles binned on a grid of cells by their bounding boxes, points tested against their
    cell's triangles only (barycentric coordinates, inclusive to 1e-12)."""
    n = len(p)
    if not len(tri) or not n:
        return np.zeros(n, int)
    lo, hi = tri.min(1), tri.max(1)
    org = np.minimum(lo.min(0), p.min(0))
    top = np.maximum(hi.max(0), p.max(0))
    # cells about the size of the small triangles (graded meshes: a cell of large ones holds few
    # small ones), coarser where a few huge triangles would span too many of them
    cell = max(float(np.quantile(np.max(hi - lo, 1), 0.1)), float(np.max(top - org)) / 4096, 1e-300)
    while True:
        c0, c1 = np.floor((lo - org) / cell).astype(np.int64), np.floor((hi - org) / cell).astype(np.int64)
        w = c1 - c0 + 1
        per = w[:, 0] * w[:, 1]
        if per.sum() <= 4_000_000:
            break
        cell *= 2
    ny = int(c1[:, 1].max()) + 2
    t_of = np.repeat(np.arange(len(tri)), per)
    k = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
    keys = (c0[t_of, 0] + k // w[t_of, 1]) * ny + c0[t_of, 1] + k % w[t_of, 1]
    order = np.argsort(keys, kind="stable")
    keys, t_of = keys[order], t_of[order]
    cp = np.floor((p - org) / cell).astype(np.int64)
    kp = np.where((cp[:, 1] >= 0) & (cp[:, 1] < ny), cp[:, 0] * ny + cp[:, 1], -1)
    first, last = np.searchsorted(keys, kp, "left"), np.searchsorted(keys, kp, "right")
    out = np.zeros(n, int)
    cum = np.cumsum(last - first)
    if cum[-1] == 0:  # no point in any triangle's cell
        return out
    bounds = np.searchsorted(cum, np.arange(2_000_000, int(cum[-1]) + 2_000_000, 2_000_000), "right")
    for a_, b_ in zip(np.concatenate([[0], bounds[:-1]]), bounds, strict=True):  # ~2e6 (point, triangle) pairs at once
        if b_ > a_:
            out[a_:b_] = _inside(p[a_:b_], tri, t_of, first[a_:b_], last[a_:b_])
    return out


def _inside(p, tri, t_of, first, last) -> np.ndarray:
    """Triangles among ``t_of[first:last]`` holding each point (barycentric, inclusive to 1e-12)."""
    m = last - first
    p_of = np.repeat(np.arange(len(p)), m)
    cand = t_of[np.repeat(first, m) + np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m)]
    a, e1, e2 = tri[cand, 0], tri[cand, 1] - tri[cand, 0], tri[cand, 2] - tri[cand, 0]
    q = p[p_of] - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = (q[:, 0] * e2[:, 1] - q[:, 1] * e2[:, 0]) / det
        l2 = (e1[:, 0] * q[:, 1] - e1[:, 1] * q[:, 0]) / det
    inside = (l1 >= -1e-12) & (l2 >= -1e-12) & (1 - l1 - l2 >= -1e-12)
    return np.bincount(p_of[inside], minlength=len(p))


def _first(p: np.ndarray, sel: np.ndarray) -> str:
    return "" if not sel.any() else f", first near ({p[sel][0][0]:.6g}, {p[sel][0][1]:.6g})"


def sample_points(reg: Region, rng, n: int = 300) -> dict:
    """Random points beyond the bands: ``body`` (in the region), ``hole`` (in a hole), ``outside``
    (in the region's bounding box, outside its outer loop)."""
    rings = reg.rings()
    lo, hi = rings[0].min(0), rings[0].max(0)
    span = hi - lo
    cand = rng.uniform(lo - 0.05 * span, hi + 0.05 * span, size=(10 * n, 2))
    in_holes = [rng.uniform(r.min(0), r.max(0), size=(n, 2)) for r in rings[1:]]
    cand = np.concatenate([cand, *(c[in_ring(r, c)] for c, r in zip(in_holes, rings[1:], strict=True))])
    cand = cand[beyond_bands(reg, cand)]
    outer = in_ring(rings[0], cand)
    holed = np.zeros(len(cand), bool)
    for r in rings[1:]:
        holed |= in_ring(r, cand)
    return {"body": cand[outer & ~holed][:n], "hole": cand[outer & holed][:n], "outside": cand[~outer][: n // 3]}


def check_body(points: np.ndarray, tris: np.ndarray, reg: Region, rng) -> list[tuple[str, str]]:
    """The findings ``(area|coverage, detail)`` of the mesh ``(points, tris)`` of one body
    against its region (whose bands are set)."""
    out = []
    t = points[tris]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    signed = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    area, exact, tol = float(signed.sum()), reg.area, reg.area_tolerance
    if not abs(area - exact) <= tol:
        out.append(("area", f"mesh area {area:.10g}, exact {exact:.10g}: off by {area - exact:.3g}, "
                            f"more than {tol:.3g}"))
    bad = signed <= 0
    if bad.any():
        out.append(("coverage", f"{int(bad.sum())} inverted or zero-area triangles{_first(t.mean(1), bad)}"))
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    if (count > 2).any():
        mid = points[uniq[count > 2]].mean(1)
        out.append(("coverage", f"{int((count > 2).sum())} edges of more than two triangles (overlap)"
                                f"{_first(mid, np.ones(len(mid), bool))}"))
    mid = points[uniq[count == 1]].mean(1)
    off = np.ones(len(mid), bool)
    for c in reg.curves:
        off &= distance(mid, c) > c.band + ROUNDING * reg.scale
    if off.any():
        out.append(("coverage", f"{int(off.sum())} boundary edges off the body's boundary (a gap, a crack or a "
                                f"wrong boundary){_first(mid, off)}"))
    cen = t.mean(1)
    hc = hits(cen, t)
    if (hc != 1).any():
        out.append(("coverage", f"{int((hc != 1).sum())} triangle centroids in {sorted(set(hc[hc != 1].tolist()))} "
                                f"triangles (overlap){_first(cen, hc != 1)}"))
    rings = reg.rings()
    inside = in_ring(rings[0], cen)
    for r in rings[1:]:
        inside &= ~in_ring(r, cen)
    stray = ~inside & beyond_bands(reg, cen)
    if stray.any():
        out.append(("coverage", f"{int(stray.sum())} triangles outside the body or in a hole{_first(cen, stray)}"))
    pts = sample_points(reg, rng)
    for what, want in (("body", 1), ("hole", 0), ("outside", 0)):
        h = hits(pts[what], t)
        wrong = h != want
        if wrong.any():
            name = {"body": "points of the body", "hole": "points in holes", "outside": "points outside the body"}[what]
            out.append(("coverage", f"{int(wrong.sum())} of {len(h)} {name} in {sorted(set(h[wrong].tolist()))} "
                                    f"triangles instead of {want}{_first(pts[what], wrong)}"))
    return out


def check_mesh(mesh, regions: dict, rng) -> list[tuple[str, str]]:
    """Findings of every body of ``mesh`` that has a region in ``regions`` (by body name)."""
    cols = np.unique(np.concatenate([bm.columns for bm in mesh.bodies]))
    h_max = float(np.diff(cols).max())
    out = []
    for bm in mesh.bodies:
        reg = regions.get(bm.body.name)
        if reg is None:
            continue
        reg.bands(mesh.level, np.asarray(bm.columns, float), h_max)
        out += [(k, f"body {bm.body.name!r}: {d}") for k, d in check_body(mesh.points, bm.triangles(), reg, rng)]
    return out
