"""The contact plots and the bound map.

Every plot of a solution, here and in :mod:`.maps` (the field maps), is matplotlib-style: it
draws on ``ax`` (a new pyplot axes if none is given, :func:`~cvxdual.outputs.views.axes`) and
returns it; files are written by :mod:`cvxdual.outputs.output_set`. Every axis is labelled in
the scene's units (``L, S = sol.scene.units``). Nothing here chooses a matplotlib backend: that
is the caller's (the output layer draws on :class:`matplotlib.figure.Figure` objects, which
need none).

The contact zone (default :func:`~cvxdual.outputs.views.contact_window`): the faces at true
displacement scale (:func:`plot_deformed`), the gap and the faces' approach at the contact pairs
(:func:`plot_gap`), the contact pressure (:func:`plot_pressure`). The bound map
(:func:`plot_bound_map`): where the certified bound ``G`` comes from.
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import LogNorm

from ..eq.space import EquilibriumSpace
from ..reference.exact import exact_field
from .maps import column_strips, stress_support
from .render import Triangles, areas, sizes
from .views import axes, bodies_window, contact_window, outlines

MESH_LINES = 80  # most mesh columns (or layers) in the contact view: lines 6 px or more apart at 4 in


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
    (default :func:`~cvxdual.outputs.views.contact_window`)."""
    ax = axes(ax)
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


def _y_range(ax, values: np.ndarray, above: float, scale: float, below: float = 0.05) -> None:
    """y limits from zero or below up to above ``values``, ``above`` of their span more on top
    (a legend's room) and ``below`` under; a uniform field's rounding noise is not blown up to the
    axis height, and all-zero values get the span ``scale`` (of the quantity in the run)."""
    top, bottom = max(float(values.max(initial=0.0)), 0.0), min(float(values.min(initial=0.0)), 0.0)
    span = max(top - bottom, 1e-3 * scale) or 1.0  # rounding noise (1e-15 of a flat contact) is not a curve
    ax.set_ylim(bottom - below * span, top + above * span)
    ax.ticklabel_format(axis="y", useOffset=False)


def _pairs_in(x: np.ndarray, xlim) -> np.ndarray:
    """Indices of the sorted ``x`` in ``xlim``, and one more on each side (lines reach the frame)."""
    i, j = np.searchsorted(x, xlim)
    return np.arange(max(i - 1, 0), min(j + 1, len(x)))


def is_equilibrium(sol) -> bool:
    """Whether ``sol`` has equilibrium stresses (its displacement is then the bounds' ``v_h``)."""
    return isinstance(stress_support(sol), EquilibriumSpace)


def plot_gap(sol, ax=None, xlim=None):
    """Along the contact pairs in ``xlim`` (default :func:`~cvxdual.outputs.views.contact_window`): the initial gap,
    the faces' approach (``relative_displacement``: it closes the gap; their difference, shaded,
    is the opening, ``>= 0`` without penetration) and, in a row of marks along the bottom (gid
    ``active pairs``), the pairs the solution's contact mask ``sol.contact["active"]`` marks
    active: the pairs with a contact force. With equilibrium stresses the displacement drawn is
    the bounds' admissible ``v_h``, which need not close the gap where the pressure acts (that
    opening is counted in ``G``): a mark is a pair under pressure, not a point of the curve."""
    ax = axes(ax)
    L, _ = sol.scene.units
    c = sol.contact
    xlim = xlim or (contact_window(sol) or bodies_window(sol))[:2]
    k = _pairs_in(c["x"], xlim)
    x, gap, rel, act = c["x"][k], c["gap"][k], c["relative_displacement"][k], np.asarray(c["active"][k], bool)
    eq = is_equilibrium(sol)
    ax.fill_between(x, rel, gap, color="tab:green", alpha=0.2, lw=0, label="opening (gap - approach)")
    ax.plot(x, gap, "k--", lw=1, label="initial gap")
    ax.plot(x, rel, "-", color="tab:blue", lw=1.2, label="approach of v_h (bounds' field)" if eq
            else "approach (relative displacement)")
    ax.plot(x[act], np.full(int(act.sum()), 0.04), "^", color="tab:red", ms=4, transform=ax.get_xaxis_transform(),
            label="active pairs (contact force > 0)", gid="active pairs", clip_on=False)
    _y_range(ax, np.r_[gap, rel], 0.3, float(np.abs(sol.displacement).max()), below=0.15)
    ax.set(xlim=xlim, xlabel=f"x [{L}]", ylabel=f"normal gap and approach [{L}]")
    ax.set_title("gap and approach at the contact pairs", pad=14)  # above a "1e-6" of the y axis
    ax.legend(fontsize=7, loc="upper center", ncol=2)
    ax.grid(alpha=0.3)
    return ax


def plot_pressure(sol, ax=None, xlim=None):
    """Contact pressure at the pairs in ``xlim`` (default: the contact zone widened by half its
    width each side, :func:`~cvxdual.outputs.views.contact_window`), with the closed form where the scene has one."""
    ax = axes(ax)
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


BOUND_SHARE = 1e-2  # the log colour range of the bound map starts where the densities below hold this share of G
BOUND_DECADES = (2, 5)  # ... but spans this many decades at least and at most


def bound_density(sol) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The certified bound's contributions over the bodies: triangles ``(n, 3, 2)`` (the
    sub-triangles, then strips of the column slabs of curved pieces), the contribution to ``G``
    per unit area on each [S] (``1/2 |sigma - C e(v)|_A^2``; a slab's spread over its strips) and
    the contribution of each [S L^2]."""
    b = sol.bounds
    P = sol.space.sub_points()
    area = areas(P)
    part = b["contributions"]["sub"].ravel()
    dens = part / area
    if len(sol.space.pieces.slabs):  # the columns: each slab's share over its area
        tris, slab, _ = column_strips(sol)
        strip = sizes(tris) ** 2
        slab_dens = b["contributions"]["column"] / sol.space.pieces.slab_areas()
        P = np.concatenate([P, tris])
        dens = np.concatenate([dens, slab_dens[slab]])
        part = np.concatenate([part, slab_dens[slab] * strip])
    return P, dens, part


def bound_range(dens: np.ndarray, part: np.ndarray) -> tuple[float, float, float]:
    """``(floor, top, share)``: the log colour range of :func:`plot_bound_map`, from the density
    under which the pieces hold :data:`BOUND_SHARE` of the drawn ``G`` (within
    :data:`BOUND_DECADES` of the largest) to the largest, and the share of the drawn ``G`` held
    by the pieces above the floor."""
    top = float(dens.max(initial=0.0))
    if not top > 0:
        return 0.1, 1.0, 1.0
    order = np.argsort(dens)[::-1]
    cum = np.cumsum(np.maximum(part[order], 0.0))
    total = cum[-1] if len(cum) and cum[-1] > 0 else 1.0
    cut = float(dens[order][min(int(np.searchsorted(cum, (1 - BOUND_SHARE) * total)), len(order) - 1)])
    lo, hi = BOUND_DECADES
    floor = min(max(cut, top * 10.0 ** -hi), top * 10.0 ** -lo)
    share = float(np.maximum(part, 0.0)[dens >= floor].sum() / total)
    return floor, top, share


def plot_bound_map(sol, ax=None, colorbar: bool = True, cax=None):
    """Where the certified bound comes from: the contribution of every sub-triangle to ``G``
    per unit area (``1/2 |sigma - C e(v)|_A^2``), on a log scale over the decades that hold the
    data (:func:`bound_range`; less is drawn in the darkest colour, the colour bar's arrow), and
    ``G`` [S L^2, per unit thickness] in the title."""
    ax = axes(ax)
    L, S = sol.scene.units
    P, dens, part = bound_density(sol)
    floor, top, share = bound_range(dens, part)
    pc = ax.add_collection(Triangles(P, array=np.maximum(dens, floor), cmap="inferno", norm=LogNorm(floor, top)),
                           autolim=False)
    outlines(ax, sol, colors="w", linewidths=0.5)
    x0, x1, y0, y1 = bodies_window(sol)
    ax.set(xlim=(x0, x1), ylim=(y0, y1), aspect="equal", xlabel=f"x [{L}]", ylabel=f"y [{L}]")
    ax.set_title(f"G = {sol.bounds['gap']:.3g} {S}\u00b7{L}\u00b2", fontsize=10)
    if colorbar:
        decades = np.log10(top / floor)
        ax.figure.colorbar(pc, ax=None if cax is not None else ax, cax=cax, extend="min" if dens.min() < floor else
                           "neither", label=f"contribution to G per unit area [{S}]\nlog, top {decades:.2g} decades: "
                           f"{100 * share:.4g}% of the area's G")
    return ax


def plot_cycles(history, ax=None, units=("L", "S")):
    """A run to a tolerance (:class:`~cvxdual.records.AdaptiveHistory`): the certified relative
    error of every cycle against its pieces (log-log), the tolerance, and the slope ``N^-1/2``
    of uniform refinement on a smooth solution with P1 for comparison."""
    ax = axes(ax)
    n = np.array([c.pieces for c in history.cycles], float)
    rel = np.array([c.bound_rel for c in history.cycles], float)
    ax.loglog(n, 100 * rel, "o-", label="certified error, per cycle")
    ax.axhline(100 * history.tol, color="0.4", ls="--", lw=1, label=f"tolerance {100 * history.tol:.3g} %")
    if len(n) > 1:
        ax.loglog(n, 100 * rel[0] * (n / n[0]) ** -0.5, ":", color="0.5", label="slope N^-1/2")
    ax.set_xlabel("pieces N")
    ax.set_ylabel("certified relative energy error [%]")
    ax.legend(fontsize="small")
    return ax
