"""How the maps' triangles are drawn, and the triangle geometry the plots share.

:class:`Triangles` draws all triangles of a map in one collection, one colour per triangle
(flat) or per vertex (Gouraud), and on Agg fills the pieces of about a pixel as a supersampled
image (:data:`SUPERSAMPLE`, :data:`SMALL`; :func:`_locate`, :func:`_supersampled`). The
geometry: triangles covering the pieces (:func:`triangles`, the curved ones cut into
:func:`strips`), their :func:`areas` and :func:`sizes`, and which meet a window
(:func:`in_window`).
"""

from __future__ import annotations

import weakref

import numpy as np
from matplotlib import artist
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.collections import Collection
from matplotlib.path import Path
from matplotlib.transforms import IdentityTransform

from ..geometry.pieces import piece_outlines

SUPERSAMPLE = 3  # samples per pixel and direction when filling small pieces (see Triangles)
SMALL = 4.0  # pieces this wide and tall in pixels (on average) or less are supersampled


def strips(poly: np.ndarray) -> np.ndarray:
    """Triangles ``(m, t, 3, 2)`` covering outlines ``poly`` ``(m, 2k, 2)`` of :func:`piece_outlines`
    (``k`` points along the lower bound left to right, then along the upper bound right to left):
    two per strip between neighbouring abscissae, which is right for the concave pieces too."""
    k = poly.shape[1] // 2
    lo, hi = poly[:, :k], poly[:, :k - 1:-1]
    a, b, c, d = lo[:, :-1], lo[:, 1:], hi[:, 1:], hi[:, :-1]
    return np.stack([a, b, c, a, c, d], axis=2).reshape(len(poly), 2 * (k - 1), 3, 2)


def triangles(pieces) -> tuple[np.ndarray, np.ndarray]:
    """Triangles ``(n, 3, 2)`` covering the pieces (the curved ones by their outlines,
    :func:`piece_outlines`, cut into strips) and the piece of each."""
    tris, ids = [pieces.tri_vertices], [pieces.tri_piece]
    for pid, poly in piece_outlines(pieces):
        cut = strips(poly)
        tris.append(cut.reshape(-1, 3, 2))
        ids.append(np.repeat(pid, cut.shape[1]))
    return np.concatenate(tris), np.concatenate(ids)


def _bounds(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest of each row of ``v`` ``(n, 3)`` (by column: a reduction over axis 1 is 3x slower)."""
    a, b, c = v[:, 0], v[:, 1], v[:, 2]
    return np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)


def in_window(tris: np.ndarray, window) -> np.ndarray:
    """Which triangles ``(n, 3, 2)`` meet the box ``(x0, x1, y0, y1)``."""
    (lx, hx), (ly, hy) = _bounds(tris[..., 0]), _bounds(tris[..., 1])
    return (hx >= window[0]) & (lx <= window[1]) & (hy >= window[2]) & (ly <= window[3])


def areas(tris: np.ndarray) -> np.ndarray:
    """Areas of triangles ``(n, 3, 2)``."""
    d = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    return 0.5 * np.abs(d[0][:, 0] * d[1][:, 1] - d[0][:, 1] * d[1][:, 0])


def sizes(tris: np.ndarray) -> np.ndarray:
    """Sizes of triangles ``(n, 3, 2)``: the square roots of their areas."""
    return np.sqrt(areas(tris))


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
