"""Plots of a solution, matplotlib-style: every function draws on ``ax`` (a new pyplot axes
if none is given) and returns it; files are written by :mod:`cvxdual.outputs.output_set`.

Every axis is labelled in the scene's units (``L, S = sol.scene.units``). Nothing here chooses
a matplotlib backend: that is the caller's (the output layer draws on
:class:`matplotlib.figure.Figure` objects, which need none).
"""

from __future__ import annotations

import weakref

import numpy as np
from matplotlib import artist
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.collections import Collection, LineCollection
from matplotlib.colors import LogNorm, Normalize
from matplotlib.path import Path
from matplotlib.transforms import IdentityTransform

from ..geometry.pieces import piece_outlines, slab_outlines
from ..reference.exact import exact_field

SUPERSAMPLE = 3  # samples per pixel and direction when filling small pieces (see Triangles)
SMALL = 4.0  # pieces this wide and tall in pixels (on average) or less are supersampled
ZOOM_SHARE = 0.5  # a contact window wider than this share of the bodies adds nothing to the whole view
MESH_LINES = 80  # most mesh columns (or layers) in the contact view: lines 6 px or more apart at 4 in


def _axes(ax):
    if ax is None:
        import matplotlib.pyplot as plt
        _, ax = plt.subplots()
    return ax


def _strips(poly: np.ndarray) -> np.ndarray:
    """Triangles ``(m, t, 3, 2)`` covering outlines ``poly`` ``(m, 2k, 2)`` of :func:`piece_outlines`
    (``k`` points along the lower bound left to right, then along the upper bound right to left):
    two per strip between neighbouring abscissae, which is right for the concave pieces too."""
    k = poly.shape[1] // 2
    lo, hi = poly[:, :k], poly[:, :k - 1:-1]
    a, b, c, d = lo[:, :-1], lo[:, 1:], hi[:, 1:], hi[:, :-1]
    return np.stack([a, b, c, a, c, d], axis=2).reshape(len(poly), 2 * (k - 1), 3, 2)


def _triangles(pieces) -> tuple[np.ndarray, np.ndarray]:
    """Triangles ``(n, 3, 2)`` covering the pieces (the curved ones by their outlines,
    :func:`piece_outlines`, cut into strips) and the piece of each."""
    tris, ids = [pieces.tri_vertices], [pieces.tri_piece]
    for pid, poly in piece_outlines(pieces):
        strips = _strips(poly)
        tris.append(strips.reshape(-1, 3, 2))
        ids.append(np.repeat(pid, strips.shape[1]))
    return np.concatenate(tris), np.concatenate(ids)


def _locate(tris: np.ndarray, w: int, h: int, s: int, chunk: int = 1 << 17) -> tuple[np.ndarray, ...]:
    """The samples of a ``w x h`` grid of cells inside triangles ``(n, 3, 2)`` (in cells):
    ``(cell, triangle, l1, l2)`` per hit (barycentric ``l1, l2``; a sample on a shared edge is
    in both, the later last). One sample per cell, so that the ``s x s`` cells of a pixel have
    ``s**2`` different abscissae and ordinates (n-rooks: an edge along the pixel rows gets
    ``s**2`` shades, the same all along). Each triangle tests the cells of its bounding box."""
    x, y = tris[..., 0], tris[..., 1]
    ex, ey = x[:, 1:] - x[:, :1], y[:, 1:] - y[:, :1]  # edges from vertex 0
    det = ex[:, 0] * ey[:, 1] - ex[:, 1] * ey[:, 0]
    keep = det != 0
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=keep)
    # per triangle: vertex 0 and the rows of the map (px - x0, py - y0) -> barycentric (l1, l2)
    coef = np.stack([x[:, 0], y[:, 0], ey[:, 1] * inv, -ex[:, 1] * inv, -ey[:, 0] * inv, ex[:, 0] * inv], 1)

    def cells(v, n):  # first and past-the-last cell of each triangle's extent
        lo, hi = _bounds(v)
        return np.clip(np.floor(lo), 0, n).astype(np.int64), np.clip(np.floor(hi) + 1, 0, n).astype(np.int64)

    (i0, i1), (j0, j1) = cells(x, w), cells(y, h)
    nx = i1 - i0
    count = np.where(keep, nx * (j1 - j0), 0)
    ends = np.cumsum(count)
    hits, start = [], 0
    while start < len(tris):
        stop = max(int(np.searchsorted(ends, ends[start] - count[start] + chunk, side="right")), start + 1)
        c = count[start:stop]
        k = np.repeat(np.arange(start, stop), c)
        dj, di = np.divmod(np.arange(len(k)) - np.repeat(np.cumsum(c) - c, c), nx[k])
        ci, cj = i0[k] + di, j0[k] + dj
        flat = cj * w + ci
        m = coef[k]
        dx = ci + ((cj % s) + 0.5) / s - m[:, 0]
        dy = cj + ((ci % s) + 0.5) / s - m[:, 1]
        l1, l2 = m[:, 2] * dx + m[:, 3] * dy, m[:, 4] * dx + m[:, 5] * dy
        inside = (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
        hits.append((flat[inside], k[inside], l1[inside].astype(np.float32), l2[inside].astype(np.float32)))
        start = stop
    return tuple(np.concatenate(a) for a in zip(*hits, strict=True))  # one chunk at least: n > 0


# figure -> [(triangles, grid, hits)]: the maps of one figure drawn from the same pieces in the
# same frame (s22 and the maximum shear) locate their samples once; gone with the figure
_HITS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _hits(fig, tris: np.ndarray, w: int, h: int, s: int) -> tuple[np.ndarray, ...]:
    """:func:`_locate`, remembered for ``fig``."""
    seen = _HITS.setdefault(fig, [])
    for t, grid, hits in seen:  # the same to a millionth of a cell: another map's transform rounds differently
        if grid == (w, h, s) and t.shape == tris.shape and np.allclose(t, tris, rtol=0, atol=1e-6):
            return hits
    hits = _locate(tris, w, h, s)
    seen.append((tris, (w, h, s), hits))
    return hits


def _supersampled(renderer, gc, px: np.ndarray, colors: np.ndarray, flat, small: np.ndarray, clip, fig) -> None:
    """Triangles ``px`` (display pixels) drawn as an image of the pixels of ``clip`` (a display
    box), each the mean of :data:`SUPERSAMPLE` x :data:`SUPERSAMPLE` samples: Agg fills the
    large triangles at that resolution, then the ``small`` ones are point-sampled over them
    (:func:`_locate`), colours ``colors`` ``(n, 3, 4)`` at the vertices (``flat`` ``(n, 4)``
    where one per triangle). The pieces' colours by covered area, in one image: filling the
    large ones on the screen instead would leave light seams where each covers part of a pixel."""
    s = SUPERSAMPLE
    x0, y0 = max(int(np.floor(clip.x0)), 0), max(int(np.floor(clip.y0)), 0)
    w = min(int(np.ceil(clip.x1)), int(renderer.width)) - x0
    h = min(int(np.ceil(clip.y1)), int(renderer.height)) - y0
    if w <= 0 or h <= 0:
        return
    sub = (px - (x0, y0)) * s
    if small.all():
        samples = np.zeros((h * s * w * s, 4), np.float32)
    else:
        off = RendererAgg(w * s, h * s, renderer.dpi * s)
        off.draw_gouraud_triangles(off.new_gc(), sub[~small], colors[~small], IdentityTransform())
        samples = np.asarray(off.buffer_rgba())[::-1].reshape(-1, 4) / np.float32(255)  # bottom row first
        samples[:, :3] *= samples[:, 3:]  # premultiplied: means weigh colours by alpha
    cell, k, l1, l2 = _hits(fig, sub[small], w * s, h * s, s)
    if flat is not None:
        pm = flat[small] * flat[small, 3:]
        samples[cell] = pm[k]
    else:
        pm = colors[small] * colors[small, :, 3:]
        samples[cell] = pm[k, 0] * (1 - l1 - l2)[:, None] + pm[k, 1] * l1[:, None] + pm[k, 2] * l2[:, None]
    total = samples.reshape(h, s, w, s, 4).sum(axis=(1, 3))
    im = np.empty((h, w, 4), np.uint8)
    im[..., :3] = np.rint(255 * np.clip(total[..., :3] / np.maximum(total[..., 3:], 1e-12), 0, 1))
    im[..., 3] = np.rint(255 / (s * s) * total[..., 3])
    renderer.draw_image(gc, x0, y0, im)  # bottom row first, as draw_image takes it


def _bounds(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest of each row of ``v`` ``(n, 3)`` (by column: a reduction over axis 1 is 3x slower)."""
    a, b, c = v[:, 0], v[:, 1], v[:, 2]
    return np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)


class Triangles(Collection):
    """Triangles ``(n, 3, 2)``, each with its own three vertices, coloured by ``array``: one
    value per triangle (flat, as the P0 stresses are) or one per vertex (``3 n`` values, linear:
    Gouraud shading), with no path per triangle and no edges, in one ``draw_gouraud_triangles``
    call; on Agg as one supersampled image (:func:`_supersampled`) where some are under
    :data:`SMALL` pixels: Agg gives a pixel the colour of the triangle over most of it, so
    pieces of about a pixel alias into moire (levels 4-6)."""

    def __init__(self, tris: np.ndarray, **kw):
        super().__init__(**kw)
        self._tris = np.ascontiguousarray(tris, dtype=float)

    def get_paths(self):
        """One path per triangle, made only if asked (hit tests); drawing needs none."""
        if self._paths is None:
            self._paths = [Path(t) for t in self._tris]
        return self._paths

    @artist.allow_rasterization
    def draw(self, renderer):
        n = len(self._tris)
        if not self.get_visible() or not n:
            return
        renderer.open_group(type(self).__name__, gid=self.get_gid())
        self.update_scalarmappable()
        c = self._facecolors
        colors = c.reshape(n, 3, 4) if len(c) == 3 * n else np.broadcast_to(c[:, None], (n, 3, 4))
        gc = renderer.new_gc()
        self._set_gc_clip(gc)
        gc.set_linewidth(0)
        trans = self.get_transform().frozen()
        if isinstance(renderer, RendererAgg):
            px = trans.transform(self._tris.reshape(-1, 2)).reshape(n, 3, 2)
            (lx, hx), (ly, hy) = _bounds(px[..., 0]), _bounds(px[..., 1])
            small = hx - lx + hy - ly < 2 * SMALL
            if small.any():
                _supersampled(renderer, gc, px, colors, c if len(c) == n else None, small,
                              self.get_clip_box() or self.figure.bbox, self.figure)
            else:  # pieces of several pixels: Agg's own fill, as good and faster
                renderer.draw_gouraud_triangles(gc, px, colors, IdentityTransform())
        else:  # vector output: the viewer fills the shapes
            renderer.draw_gouraud_triangles(gc, self._tris, colors, trans)
        gc.restore()
        renderer.close_group(type(self).__name__)


def _in_window(tris: np.ndarray, window) -> np.ndarray:
    """Which triangles ``(n, 3, 2)`` meet the box ``(x0, x1, y0, y1)``."""
    (lx, hx), (ly, hy) = _bounds(tris[..., 0]), _bounds(tris[..., 1])
    return (hx >= window[0]) & (lx <= window[1]) & (hy >= window[2]) & (ly <= window[3])


def body_outline(body, n: int = 400) -> list[np.ndarray]:
    """Closed outlines of a body on its true (curved) face and true arcs: the boundary, then
    each hole of an outline body."""
    x0, x1 = body.x_range
    xs = np.linspace(x0, x1, n)
    face = np.stack([xs, body.face.value(xs)], 1)
    if body.is_column:
        far = np.array([[x1, body.far], [x0, body.far]])
        return [np.concatenate([face, far, face[:1]])]
    path = [s.sample() for p in body.outline.path for s in p.segments]
    holes = [np.concatenate([s.sample() for s in h.segments]) for h in body.outline.holes]
    return [np.concatenate([face, *path]), *holes]


def _outlines(ax, sol, **kw) -> None:
    lines = [line for bm in sol.mesh.bodies for line in body_outline(bm.body)]
    ax.add_collection(LineCollection(lines, **kw), autolim=False)


def bodies_window(sol) -> tuple[float, float, float, float]:
    """``(x0, x1, y0, y1)``: both bodies with a 3% margin."""
    pts = np.concatenate([line for b in sol.scene.bodies for line in body_outline(b, 3)])
    (x0, y0), (x1, y1) = pts.min(0), pts.max(0)
    m = 0.03 * max(x1 - x0, y1 - y0)
    return x0 - m, x1 + m, y0 - m, y1 + m


def contact_zone(sol) -> tuple[float, float] | None:
    """``(x_min, x_max)`` of the active pairs, or of all contact pairs when none is active
    (``None`` without pairs)."""
    c = sol.contact
    if c["x_min"] is not None:
        return c["x_min"], c["x_max"]
    return (float(c["x"].min()), float(c["x"].max())) if len(c["x"]) else None


def contact_window(sol) -> tuple[float, float, float, float] | None:
    """``(x0, x1, y0, y1)`` around the contact zone (:func:`contact_zone`): widened on each side
    by its half-width (at least two pair spacings, so that one active pair gets a window), within
    the bodies' x range, and as deep as wide, or the zone's width above and below the interface
    when more (a half model's zone starts on its edge: the stresses peak 0.8 zone widths deep)."""
    zone = contact_zone(sol)
    if zone is None:
        return None
    (a, b), x = zone, sol.contact["x"]
    i, j = np.searchsorted(x, [a, b])
    step = float(np.diff(x)[max(i - 1, 0):j + 1].max()) if len(x) > 1 else 0.0
    hw = max((b - a) / 2, 2 * step, 1e-9 * sol.scene.length_scale)
    (lo, hi), lower = sol.scene.x_extent, sol.scene.lower
    yc = float(lower.face.value((a + b) / 2))
    x0, x1 = max(a - hw, lo), min(b + hw, hi)
    depth = max((x1 - x0) / 2, b - a)
    return x0, x1, yc - depth, yc + depth


def zoom_window(sol):
    """:func:`contact_window` where it is narrower than :data:`ZOOM_SHARE` of the bodies (else
    ``None``: the whole view shows the zone as well)."""
    w, (x0, x1) = contact_window(sol), sol.scene.x_extent
    return w if w is not None and w[1] - w[0] < ZOOM_SHARE * (x1 - x0) else None


STRESS_COMPONENTS = {
    "s11": (lambda t: t[:, 0], "s11", "s11"),
    "s22": (lambda t: t[:, 1], "s22 (contact direction)", "s22"),
    "s12": (lambda t: t[:, 2], "s12", "s12"),
    "shear": (lambda t: np.sqrt(((t[:, 0] - t[:, 1]) / 2) ** 2 + t[:, 2] ** 2), "maximum shear stress",
              "max shear"),
}


def _column_strips(sol) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The slabs of the curved pieces of a solution with an equilibrium space cut into strips:
    triangles ``(n, 3, 2)``, their slab, and the column stress ``(0, g(x), 0)`` at their vertices
    ``(n, 3, 3)`` (``None`` for a P0 solution's bounds)."""
    space = sol.space
    strips = _strips(slab_outlines(space.pieces))  # (m, t, 3, 2)
    slab = np.repeat(np.arange(len(strips)), strips.shape[1])
    tris = strips.reshape(-1, 3, 2)
    if sol.column_stress is None:  # a P0 solution's bounds: the geometry only
        return tris, slab, None
    col = space.slab_column[slab]
    x0, x1 = (space.faces.x[space.columns[col], e][:, None] for e in (0, 1))
    t = (tris[..., 0] - x0) / (x1 - x0)
    g = sol.column_stress[col, 0][:, None] * (1 - t) + sol.column_stress[col, 1][:, None] * t
    return tris, slab, np.stack([np.zeros_like(g), g, np.zeros_like(g)], -1)


def _stress_field(sol, component: str) -> tuple[np.ndarray, np.ndarray]:
    """Triangles ``(n, 3, 2)`` covering the bodies and ``component`` on each: ``(n,)`` (P0) or
    ``(n, 3)`` at the vertices (``eq``: linear on every sub-triangle and column strip)."""
    fn = STRESS_COMPONENTS[component][0]
    if sol.stress_space == "eq":
        P = sol.space.sub_points()
        values = fn(sol.stress.reshape(-1, 3)).reshape(len(P), 3)
        if not len(sol.space.pieces.slabs):
            return P, values
        tris, _, col = _column_strips(sol)
        return np.concatenate([P, tris]), np.concatenate([values, fn(col.reshape(-1, 3)).reshape(len(tris), 3)])
    tris, ids = _triangles(sol.pieces)
    return tris, fn(sol.stress)[ids]


def plot_stress(sol, component: str = "s22", ax=None, colorbar: bool = True, cmap: str = "viridis",
                window=None, cax=None):
    """One stress component (``s11``, ``s22``, ``s12`` or ``shear``) on the bodies, equal
    aspect: constant per piece (``p0``) or linear on every sub-triangle (``eq``). ``window``
    ``(x0, x1, y0, y1)`` (e.g. :func:`contact_window`) zooms, drawing only the pieces in it;
    colours span the whole field either way, so zoom and whole view share a colour bar."""
    ax = _axes(ax)
    L, S = sol.scene.units
    _, title, short = STRESS_COMPONENTS[component]
    tris, val = _stress_field(sol, component)
    lo, hi = float(val.min()), float(val.max())
    scale = max(abs(lo), abs(hi))  # a field constant to 0.1% (the patch test) in one colour, not its rounding noise
    pad = 0.5 * max(1e-3 * scale - (hi - lo), 0.0) if scale else 1.0
    norm = Normalize(lo - pad, hi + pad)
    if window is None:
        window = bodies_window(sol)
    else:
        keep = _in_window(tris, window)
        tris, val = tris[keep], val[keep]
    pc = ax.add_collection(Triangles(tris, array=val.ravel(), cmap=cmap, norm=norm), autolim=False)
    _outlines(ax, sol, colors="k", linewidths=0.5)
    ax.set(xlim=window[:2], ylim=window[2:], aspect="equal", title=title, xlabel=f"x [{L}]", ylabel=f"y [{L}]")
    if colorbar:
        cb = ax.figure.colorbar(pc, ax=None if cax is not None else ax, cax=cax, label=f"{short} [{S}]")
        cb.ax.ticklabel_format(useOffset=False)  # -99.98, not 0.02 under a "-1e2" that reads as a tick
    return ax


def _nice_below(v: float) -> float:
    """The largest of 1, 2, 5 times a power of ten that is at most ``v`` (1 below 1)."""
    if v < 1:
        return 1.0
    e = 10.0 ** np.floor(np.log10(v))
    return float(max(m for m in (1.0, 2.0, 5.0, 10.0) if m * e <= v * (1 + 1e-12)) * e)


def _faces(sol, flatten: bool) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per body, ``(x, y, y + u_y)`` of its face nodes as :func:`plot_deformed` draws them: on the
    true face (where the gap ``eps = f' - f'' + g`` is measured), the upper one raised by the gap
    function ``g``, so that at every contact pair upper minus lower is ``eps`` undeformed and
    ``eps - relative_displacement >= 0`` deformed; ``flatten``: less the lower face ``f''(x)``."""
    out = []
    for bm in sol.mesh.bodies:
        y = _face_drawn(sol, bm.body, bm.columns, flatten)
        out.append((bm.columns, y, y + sol.displacement[bm.side_nodes("face"), 1]))
    return out


def _face_drawn(sol, body, x: np.ndarray, flatten: bool) -> np.ndarray:
    """The undeformed face of ``body`` at ``x`` as :func:`plot_deformed` draws it (:func:`_faces`)."""
    y = body.face.value(x) + (sol.scene.gap_profile.value(x) if body.position == "upper" else 0.0)
    return y - sol.scene.lower.face.value(x) if flatten else y


def _mesh_lines(sol, window, flatten: bool) -> list[np.ndarray]:
    """The mesh's columns and layers in ``window`` as :func:`plot_deformed` draws them (each
    column shifted as its face node, :func:`_faces`; vertical displacements), or none where
    there would be more than :data:`MESH_LINES` of either (they would fill the view)."""
    x0, x1, y0, y1 = window
    pts, u = sol.mesh.points, sol.displacement
    lines = []
    for bm in sol.mesh.bodies:
        nc, nl = bm.shape
        c = bm.columns
        span = slice(bm.offset, bm.offset + bm.n_strip_nodes)  # the columns (an outline body's strip)
        shift = _face_drawn(sol, bm.body, c, flatten) - bm.face_y
        y = pts[span, 1].reshape(nc, nl) + shift[:, None] + u[span, 1].reshape(nc, nl)
        i = np.flatnonzero((c >= x0) & (c <= x1))
        if not len(i):
            continue
        i = np.arange(max(i[0] - 1, 0), min(i[-1] + 2, nc))  # one more each side: lines reach the frame
        j = np.flatnonzero(((y[i] >= y0) & (y[i] <= y1)).any(axis=0))
        if len(i) > MESH_LINES or len(j) > MESH_LINES:
            return []
        if not len(j):
            continue
        j = np.arange(max(j[0] - 1, 0), min(j[-1] + 2, nl))
        xy = np.stack([np.broadcast_to(c[i, None], (len(i), len(j))), y[np.ix_(i, j)]], -1)
        lines += list(xy) + list(xy.transpose(1, 0, 2))
    return lines


def plot_deformed(sol, ax=None, window=None):
    """The contact zone at true displacement scale: the faces deformed (solid) and undeformed
    (dashed), the mesh columns and layers where few enough, the bodies shaded.

    Only the vertical axis is stretched (by a round factor, in its label): an affine map of
    geometry and displacement together, so no overlap appears that the solution does not have.
    Drawn with vertical displacements only, as the linearised contact condition compares the
    faces at equal x (:func:`_faces`). Where the lower face's curvature would leave the gap
    invisible (a conforming contact), heights are drawn above it, ``y - f''(x)``: a vertical
    shift at each x, which keeps the order of the faces there. ``window`` is ``(x0, x1, ...)``
    (default :func:`contact_window`)."""
    ax = _axes(ax)
    L, _ = sol.scene.units
    window = window or contact_window(sol) or bodies_window(sol)
    x0, x1 = window[:2]

    def extent(faces):
        ys = np.concatenate([np.r_[y[(x >= x0) & (x <= x1)], yd[(x >= x0) & (x <= x1)]] for x, y, yd in faces])
        return (float(ys.min()), float(ys.max())) if len(ys) else (-1.0, 1.0)

    drawn = {f: _faces(sol, f) for f in (False, True)}
    (lo, hi), (flo, fhi) = extent(drawn[False]), extent(drawn[True])
    flatten = hi - lo > 5 * (fhi - flo)  # the face's own curvature would take most of the height
    faces = drawn[flatten]
    lo, hi = (flo, fhi) if flatten else (lo, hi)
    span = max(hi - lo, 1e-6 * (x1 - x0))
    w_in, h_in = ax.get_position().size * ax.figure.get_size_inches()
    stretch = _nice_below(h_in / w_in * (x1 - x0) / (1.7 * span))  # the faces fill 1/1.7 of the height
    half = 0.5 * (x1 - x0) * h_in / w_in / stretch
    ylim = (0.5 * (lo + hi) - half, 0.5 * (lo + hi) + half)
    ax.set(xlim=(x0, x1), ylim=ylim)
    ax.set_aspect(stretch, adjustable="box")  # the limits above already fit the box: it keeps its size
    lines = _mesh_lines(sol, (x0, x1, *ylim), flatten)
    if lines:
        ax.add_collection(LineCollection(lines, colors="0.6", linewidths=0.4, label="mesh, deformed"),
                          autolim=False)
    for k, (x, y, yd) in enumerate(faces):
        color, name = ("tab:blue", "tab:orange")[k], sol.scene.bodies[k].name
        ax.fill_between(x, yd, ylim[1 - k], color=color, alpha=0.12, lw=0)
        ax.plot(x, y, "--", color="k", lw=0.8, label="faces, undeformed" if k else None)
        # the upper line wider: where the faces touch, both stay visible
        ax.plot(x, yd, "-", color=color, lw=2.4 - k, label=f"{name}, deformed", gid=f"deformed face {k}")
    lower = sol.scene.lower.name
    ax.set(xlabel=f"x [{L}]", ylabel=f"{f'y - {lower} face' if flatten else 'y'} [{L}], vertical x{stretch:g}",
           title="faces at true displacement scale")
    ax.ticklabel_format(useOffset=False)
    ax.legend(fontsize=7, loc="lower right", framealpha=0.9)
    return ax


def _y_range(ax, values: np.ndarray, above: float, scale: float) -> None:
    """y limits from zero or below up to above ``values``, ``above`` of their span more on top
    (a legend's room); a uniform field's rounding noise is not blown up to the axis height, and
    all-zero values get the span ``scale`` (of the quantity in the run)."""
    top, bottom = max(float(values.max(initial=0.0)), 0.0), min(float(values.min(initial=0.0)), 0.0)
    span = top - bottom or scale or 1.0
    ax.set_ylim(bottom - 0.05 * span, top + above * span)
    ax.ticklabel_format(axis="y", useOffset=False)


def _pairs_in(x: np.ndarray, xlim) -> np.ndarray:
    """Indices of the sorted ``x`` in ``xlim``, and one more on each side (lines reach the frame)."""
    i, j = np.searchsorted(x, xlim)
    return np.arange(max(i - 1, 0), min(j + 1, len(x)))


def plot_gap(sol, ax=None, xlim=None):
    """Along the contact pairs in ``xlim`` (default :func:`contact_window`): the initial gap,
    the faces' approach (``relative_displacement``: it closes the gap; their difference, shaded,
    is the opening, ``>= 0`` without penetration) and the active pairs."""
    ax = _axes(ax)
    L, _ = sol.scene.units
    c = sol.contact
    xlim = xlim or (contact_window(sol) or bodies_window(sol))[:2]
    k = _pairs_in(c["x"], xlim)
    x, gap, rel, act = c["x"][k], c["gap"][k], c["relative_displacement"][k], c["active"][k]
    ax.fill_between(x, rel, gap, color="tab:green", alpha=0.2, lw=0, label="opening (gap - approach)")
    ax.plot(x, gap, "k--", lw=1, label="initial gap")
    ax.plot(x, rel, "-", color="tab:blue", lw=1.2, label="approach (relative displacement)")
    ax.plot(x[act], rel[act], "o", color="tab:red", ms=3, label="active pairs")
    _y_range(ax, np.r_[gap, rel], 0.3, float(np.abs(sol.displacement).max()))
    ax.set(xlim=xlim, xlabel=f"x [{L}]", ylabel=f"normal gap and approach [{L}]",
           title="gap and approach at the contact pairs")
    ax.legend(fontsize=7, loc="upper center", ncol=2)
    ax.grid(alpha=0.3)
    return ax


def plot_pressure(sol, ax=None, xlim=None):
    """Contact pressure at the pairs in ``xlim`` (default: the contact zone widened by half its
    width each side, :func:`contact_window`), with the closed form where the scene has one."""
    ax = _axes(ax)
    L, S = sol.scene.units
    c = sol.contact
    xlim = xlim or (contact_window(sol) or bodies_window(sol))[:2]
    k = _pairs_in(c["x"], xlim)
    p = c["pressure"][k]
    ax.plot(c["x"][k], p, "o-", ms=3, lw=1, label="cvxdual (nodal force / tributary length)")
    if sol.exact is not None:
        xs = np.linspace(*xlim, 2001)
        label = "Hertz" if sol.exact.get("kind") == "hertz" else "exact"
        pe = exact_field(sol.scene).pressure(xs)
        ax.plot(xs, pe, "k-", lw=1, label=label)
        p = np.r_[p, pe]
    _y_range(ax, p, 0.12, float(np.abs(c["pressure"]).max()))
    ax.set(xlim=xlim, xlabel=f"x [{L}]", ylabel=f"contact pressure [{S}]")
    n_out = len(c["x"]) - int(((c["x"] >= xlim[0]) & (c["x"] <= xlim[1])).sum())
    ax.set_title(f"{sol.scene.name}: {c['n_active']} active pairs of {len(c['x'])}"
                 + (f" ({n_out} pairs outside the view)" if n_out else ""))
    ax.legend()
    ax.grid(alpha=0.3)
    return ax


def plot_bound_map(sol, ax=None, colorbar: bool = True, cax=None):
    """Where the certified bound comes from: the contribution of every sub-triangle to ``G``
    per unit area (``1/2 |sigma - C e(v)|_A^2``), log scale; the contact edges' total is in
    the title."""
    ax = _axes(ax)
    L, S = sol.scene.units
    b = sol.bounds
    P = sol.space.sub_points()
    d = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    area = 0.5 * np.abs(d[0][:, 0] * d[1][:, 1] - d[0][:, 1] * d[1][:, 0])
    dens = b["contributions"]["sub"].ravel() / area
    if len(sol.space.pieces.slabs):  # the columns: each slab's share over its area
        tris, slab, _ = _column_strips(sol)
        P = np.concatenate([P, tris])
        dens = np.concatenate([dens, (b["contributions"]["column"] / sol.space.pieces.slab_areas())[slab]])
    floor = max(float(dens.max()) * 1e-8, 1e-300)
    pc = ax.add_collection(Triangles(P, array=np.maximum(dens, floor), cmap="inferno",
                                     norm=LogNorm(floor, max(float(dens.max()), 10 * floor))), autolim=False)
    _outlines(ax, sol, colors="w", linewidths=0.5)
    x0, x1, y0, y1 = bodies_window(sol)
    ax.set(xlim=(x0, x1), ylim=(y0, y1), aspect="equal", xlabel=f"x [{L}]", ylabel=f"y [{L}]")
    beyond = float(b["contributions"].get("continuation", np.zeros(0)).sum())
    ax.set_title(f"G = {b['gap']:.3g} (contact edges {float(b['contributions']['contact'].sum()):.3g}"
                 + (f", beyond the free arcs {beyond:.3g}" if beyond else "")
                 + f"); bound sqrt(2G) = {b['error_bound']:.3g}", fontsize=9)
    if colorbar:
        ax.figure.colorbar(pc, ax=None if cax is not None else ax, cax=cax,
                           label=f"contribution to G per unit area [{S}]")
    return ax
