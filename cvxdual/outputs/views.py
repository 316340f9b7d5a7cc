"""What a plot shows of the bodies: its axes (:func:`axes`), the bodies' outlines, the windows
(the whole bodies, the contact zone, a field's peak) and the zooms on them.

Maps show the whole body pair; :func:`add_insets` adds zooms on a narrow contact zone
(:func:`zoom_window`) and on a local peak (:func:`peak_window`: a hole's stress concentration):
insets in a corner of the map where one hides (almost) none of the bodies (:func:`_corner`),
else axes beside the map, right of it (:func:`_side_rects`; :func:`side_room` the room they
take).
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.path import Path

from .render import sizes

ZOOM_SHARE = 0.5  # a contact window wider than this share of the bodies adds nothing to the whole view
ZOOM_MIN = 1.5  # a zoom shows its region at least this many times larger than the whole view does
INSET_SHARES = (0.6, 0.46, 0.36)  # an inset's longer side, as a share of the map's longer side: the largest that fits
INSET_MAX = 0.6  # most of the map's width and height an inset takes
# most of an inset's rectangle the bodies may take: the bodies' window has a 3% margin and an
# inset sits 2% in from the frame, so one in an empty corner can still graze a body's edge or a
# rounded corner; more than that pastes the zoom's picture over the part itself
COVER_MAX = 0.03
COVER_GRID = 40  # samples per side of an inset's rectangle measuring what it covers (3% ~ 48 of 1600)
SIDE_GAP = 0.15  # [in] between a map and the zooms beside it, and between those
SIDE_MAX = 0.7  # a zoom beside a map is at most this share of the map's longer side wide
PEAK_RATIO = 1.5  # a field's extreme stands out where it is this many times its (area) median or more
PEAK_SHARE = 0.3  # ... and the region above half-way to it, 2.5 times over, is narrower than this share of the bodies


def axes(ax):
    """``ax``, or a new pyplot axes if ``None``: what every plot draws on."""
    if ax is None:
        import matplotlib.pyplot as plt
        _, ax = plt.subplots()
    return ax


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


def outlines(ax, sol, **kw) -> None:
    """Draw the bodies' outlines (:func:`body_outline`) on ``ax`` in one collection (``kw``: its style)."""
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


def _weighted_median(v: np.ndarray, w: np.ndarray) -> float:
    order = np.argsort(v)
    c = np.cumsum(w[order])
    return float(v[order][min(int(np.searchsorted(c, 0.5 * c[-1])), len(v) - 1)])


def peak_window(sol, tris: np.ndarray, values: np.ndarray, signed: bool):
    """``(x0, x1, y0, y1)`` around the extreme of a field on triangles (values per triangle or
    per vertex; by magnitude where ``signed``) where it stands out: at least :data:`PEAK_RATIO`
    times the area median, and the region above half-way from the median to it, near it, 2.5
    times over, narrower than :data:`PEAK_SHARE` of the bodies (a hole's stress concentration);
    else ``None``, the whole view shows it."""
    v = np.abs(values) if signed else np.asarray(values, float)
    v = v if v.ndim == 1 else v.max(axis=1)
    ok = np.isfinite(v)  # a measure undefined somewhere (NaN) is left out
    if not ok.any():
        return None
    v = np.where(ok, v, -np.inf)
    area = sizes(tris) ** 2
    background, k = _weighted_median(v[ok], area[ok]), int(np.argmax(v))
    peak = float(v[k])
    if not peak > PEAK_RATIO * max(background, 0.0):
        return None
    bx0, bx1, by0, by1 = bodies_window(sol)
    D = max(bx1 - bx0, by1 - by0)
    c = tris[k].mean(axis=0)
    near = (v >= background + 0.5 * (peak - background)) & (np.abs(tris.mean(axis=1) - c).max(axis=1) <= 0.1 * D)
    near[k] = True
    pts = tris[near].reshape(-1, 2)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    side = max(2.5 * float((hi - lo).max()), 6.0 * float(np.sqrt(area[k])))
    if side > PEAK_SHARE * D:
        return None
    mid = 0.5 * (lo + hi)
    x0 = float(np.clip(mid[0] - side / 2, bx0, max(bx1 - side, bx0)))
    y0 = float(np.clip(mid[1] - side / 2, by0, max(by1 - side, by0)))
    return x0, x0 + side, y0, y0 + side


def _body_paths(sol):
    out = []
    for b in sol.scene.bodies:
        outer, *holes = body_outline(b, 200)
        out.append((Path(outer), [Path(h) for h in holes]))
    return out


def _covered(paths, box) -> float:
    """Share of the box ``(x0, x1, y0, y1)`` inside the bodies: the share of a
    :data:`COVER_GRID` x :data:`COVER_GRID` grid of points at its cell centres inside a body's
    outline and out of its holes (one vectorised point-in-polygon test per outline)."""
    g = (np.arange(COVER_GRID) + 0.5) / COVER_GRID
    X, Y = np.meshgrid(box[0] + g * (box[1] - box[0]), box[2] + g * (box[3] - box[2]))
    p = np.c_[X.ravel(), Y.ravel()]
    inside = np.zeros(len(p), bool)
    for outer, holes in paths:
        i = outer.contains_points(p)
        for h in holes:
            i &= ~h.contains_points(p)
        inside |= i
    return float(inside.mean())


def _overlap(a, b) -> float:
    """Share of box ``a`` inside box ``b`` (``(x0, x1, y0, y1)``)."""
    w = max(min(a[1], b[1]) - max(a[0], b[0]), 0.0)
    h = max(min(a[3], b[3]) - max(a[2], b[2]), 0.0)
    return w * h / max((a[1] - a[0]) * (a[3] - a[2]), 1e-300)


CORNERS = {"NE": (1, 1), "NW": (0, 1), "SE": (1, 0), "SW": (0, 0)}
ZOOM_LABELS = ("zoom", "peak")  # the labels of the zoom axes add_insets makes


def _box(rect) -> tuple:
    """``(x0, x1, y0, y1)`` of ``(x, y, width, height)``."""
    return rect[0], rect[0] + rect[2], rect[1], rect[1] + rect[3]


def _corner(win, view, size, paths, taken, windows):
    """``(corner, rect)``: where an inset of ``win`` goes on a map of ``view`` ``(x0, x1, y0, y1)``
    and ``size`` ``(W, H)`` [in] (``rect`` in axes coordinates), or ``None``: the largest of
    :data:`INSET_SHARES` that still magnifies by :data:`ZOOM_MIN`, in the corner that covers the
    least of the bodies among those that cover under :data:`COVER_MAX` of its rectangle, off the
    insets ``taken`` and the zoomed ``windows``."""
    (x0, x1, y0, y1), (W, H) = view, size
    r = (win[3] - win[2]) / (win[1] - win[0])
    for share in INSET_SHARES:
        s = share * max(W, H)
        w_in, h_in = (s, s * r) if r <= 1 else (s / r, s)
        fit = min(INSET_MAX * W / w_in, INSET_MAX * H / h_in, 1.0)  # within INSET_MAX of each side
        fw, fh, m = fit * w_in / W, fit * h_in / H, 0.02
        if fw * (x1 - x0) < ZOOM_MIN * (win[1] - win[0]):
            return None  # the whole view shows the region about as large (and smaller shares too)
        best = None
        for corner, (cx, cy) in CORNERS.items():
            rect = ((1 - m - fw) if cx else m, (1 - m - fh) if cy else m, fw, fh)
            if any(_overlap(_box(rect), _box(t)) > 0 for t in taken):
                continue
            box = (x0 + rect[0] * (x1 - x0), x0 + (rect[0] + fw) * (x1 - x0), y0 + rect[1] * (y1 - y0),
                   y0 + (rect[1] + fh) * (y1 - y0))
            if any(_overlap(box, w) > 0 for w in windows):
                continue  # it would hide a zoomed region's frame
            cover = _covered(paths, box)
            if cover < COVER_MAX and (best is None or cover < best[0]):
                best = cover, corner, rect
        if best is not None:
            return best[1:]
    return None


def _side_rects(wins, view, size, side) -> list:
    """Rects (axes coordinates) of zooms of ``wins`` beside a map of ``view`` and ``size`` (as
    :func:`_corner`), right of it, stacked from its top :data:`SIDE_GAP` apart, one width, as
    large as the map's height allows and at most ``side`` [in] with their gap (default
    :data:`SIDE_MAX` of the map's longer side). Taken in order (the contact zone first): one
    is left out (``None``) where the stack would then magnify one of them less than
    :data:`ZOOM_MIN`."""
    (x0, x1, _, _), (W, H) = view, size
    ratios = [(w[3] - w[2]) / (w[1] - w[0]) for w in wins]
    cap = SIDE_MAX * max(W, H) if side is None else side - SIDE_GAP

    def width(keep):
        return min(cap, (H - (len(keep) - 1) * SIDE_GAP) / sum(ratios[i] for i in keep))

    keep: list[int] = []
    for i in range(len(wins)):
        zw = width([*keep, i])
        if all(zw / W * (x1 - x0) >= ZOOM_MIN * (wins[j][1] - wins[j][0]) for j in (*keep, i)):
            keep.append(i)
    out, top = [None] * len(wins), H
    if keep:
        zw = width(keep)
        for i in keep:
            h = zw * ratios[i]
            out[i] = (1 + SIDE_GAP / W, (top - h) / H, zw / W, h / H)
            top -= h + SIDE_GAP
    return out


def side_room(ax) -> float:
    """[in] the zooms beside the map ``ax`` (:func:`add_insets`) take right of it, with their gap
    (0 without any): the room a figure leaves for them."""
    fig_w = ax.figure.get_figwidth()
    right = ax.get_position().x1
    ends = [c.get_axes_locator()(c, None).x1 for c in ax.child_axes if c.get_label() in ZOOM_LABELS]
    return max([(e - right) * fig_w for e in ends if e > right + 1e-9], default=0.0)


def _zoom_axes(ax, rect, label, draw, win, text, L, anchor):
    """A zoom of ``ax`` on ``win``: a child axes at ``rect`` (axes coordinates, in or beside the
    map) drawn by ``draw``, equal aspect, labelled ``text`` and its width."""
    zoom = ax.inset_axes(rect, label=label)
    draw(zoom, win)
    zoom.set(xlim=win[:2], ylim=win[2:], aspect="equal", xticks=[], yticks=[])
    zoom.set_anchor(anchor)
    zoom.text(0.03, 0.97, f"{text}\n{win[1] - win[0]:.3g} {L} wide", transform=zoom.transAxes, ha="left",
              va="top", fontsize=7, bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 1.5})
    return zoom


def add_insets(ax, sol, draw, peak=None, side=None) -> list:
    """Zooms of the map ``ax`` (the whole bodies, equal aspect): the contact zone where it is
    narrow (:func:`zoom_window`, label ``zoom``) and, with ``peak`` ``(tris, values, signed,
    text)``, the neighbourhood of the field's extreme where it stands out off the contact zone
    (:func:`peak_window`, label ``peak``). ``draw(zoom_ax, window)`` draws the content, on the
    map's colours.

    A zoom is an inset (``ax.inset_axes``) in a corner of the map only where that hides
    (almost) nothing of the bodies (:func:`_corner`): an inset over a body pastes a magnified
    picture onto the part, and the reader cannot tell which is which. Otherwise it goes beside
    the map, right of it (:func:`_side_rects`; still a child axes of ``ax``, past its right edge
    in axes coordinates): whoever lays out the figure leaves that room (``side`` [in] at most,
    :func:`side_room` what was taken; :mod:`cvxdual.outputs.figures` widens the figure). Either
    way the zoom is labelled in its upper left and its region is framed on the map (with lines
    to an inset, ``indicate_inset_zoom``; the frame alone for a zoom beside, as lines to it would
    cross the bodies); one that would not magnify by :data:`ZOOM_MIN` is left out. Returns the
    zooms."""
    L, _ = sol.scene.units
    wanted = []
    zoom = zoom_window(sol)
    if zoom is not None:
        wanted.append(("zoom", "contact zone", zoom))
    if peak is not None:
        w = peak_window(sol, *peak[:3])
        # not where it mostly shows the contact zone's zoom again (either inside the other)
        if w is not None and not (zoom is not None and max(_overlap(w, zoom), _overlap(zoom, w)) > 0.5):
            wanted.append(("peak", peak[3], w))
    if not wanted:
        return []
    ax.apply_aspect()
    view = (*ax.get_xlim(), *ax.get_ylim())
    pos = ax.get_position()
    size = (pos.width * ax.figure.get_figwidth(), pos.height * ax.figure.get_figheight())
    paths, taken, out, beside = _body_paths(sol), [], [], []
    windows = [w for *_, w in wanted]
    for label, text, win in wanted:
        placed = _corner(win, view, size, paths, taken, windows)
        if placed is None:
            beside.append((label, text, win))
            continue
        corner, rect = placed
        taken.append(rect)
        out.append(_zoom_axes(ax, rect, label, draw, win, text, L, corner))
        ax.indicate_inset_zoom(out[-1], edgecolor="0.1", alpha=0.9, linewidth=0.8)
    if beside and side != 0:
        for (label, text, win), rect in zip(beside, _side_rects([w for *_, w in beside], view, size, side),
                                            strict=True):
            if rect is None:
                continue
            out.append(_zoom_axes(ax, rect, label, draw, win, text, L, "NW"))
            # the frame on the map alone: lines to the zoom beside would cross the bodies
            ax.indicate_inset((win[0], win[2], win[1] - win[0], win[3] - win[2]), edgecolor="0.1", alpha=0.9,
                              linewidth=0.8)
    return out
