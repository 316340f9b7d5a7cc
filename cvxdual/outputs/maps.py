"""Field maps on the bodies: the stress measures (:class:`Measure`, :func:`plot_stress`), the
displacement (:class:`DisplacementComponent`, :func:`plot_displacement`) and the mesh the
stresses live on (:func:`draw_mesh`, :func:`describe_mesh`, :func:`plot_mesh`).

Signed fields are drawn on :data:`SIGNED_CMAP` with limits symmetric about zero
(:func:`signed_norm`), magnitudes on sequential maps from zero. What the stresses live on
decides how they are drawn: :func:`stress_field` and :func:`draw_mesh` dispatch on its type
(:func:`stress_support`: P0 pieces or the equilibrium space). All triangles of a map are drawn
in one collection (:class:`~cvxdual.outputs.render.Triangles`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from functools import singledispatch

import numpy as np
from matplotlib.colors import CenteredNorm, Normalize

from ..eq.columns import column_at
from ..eq.space import EquilibriumSpace
from ..geometry.pieces import Pieces, piece_outlines, slab_outlines
from ..voigt import body_factors, shear_stress
from .render import Triangles, areas, in_window, sizes, strips, triangles
from .views import add_insets, axes, bodies_window, outlines, side_room
from .vtu import stress_measures


class Measure(Enum):
    """A stress measure drawn on the bodies, as ``solution.vtu`` names it. Signed measures are
    drawn on a diverging colour map centred at zero (white), magnitudes on a sequential one from
    zero."""

    S11 = "s11"
    S22 = "s22"
    S12 = "s12"
    SHEAR = "shear"
    VON_MISES = "von_mises"
    PRINCIPAL_1 = "principal_1"
    PRINCIPAL_2 = "principal_2"

    @property
    def signed(self) -> bool:
        return self not in (Measure.SHEAR, Measure.VON_MISES)

    @property
    def title(self) -> str:
        return _MEASURE_NAMES[self][0]

    @property
    def short(self) -> str:
        return _MEASURE_NAMES[self][1]


_MEASURE_NAMES = {
    Measure.S11: ("s11", "s11"), Measure.S22: ("s22 (contact direction)", "s22"), Measure.S12: ("s12", "s12"),
    Measure.SHEAR: ("maximum shear stress", "max shear"), Measure.VON_MISES: ("von Mises stress", "von Mises"),
    Measure.PRINCIPAL_1: ("largest principal stress (in plane)", "principal 1"),
    Measure.PRINCIPAL_2: ("smallest principal stress (in plane)", "principal 2"),
}


class DisplacementComponent(Enum):
    """What :func:`plot_displacement` draws of the displacement."""

    MAGNITUDE = "magnitude"
    UX = "u_x"
    UY = "u_y"

    @property
    def signed(self) -> bool:
        return self is not DisplacementComponent.MAGNITUDE


SIGNED_CMAP = "RdBu_r"  # signed fields: blue compression, white zero, red tension
STRESS_CMAP = "viridis"  # stress magnitudes (maximum shear, von Mises)
DISPLACEMENT_CMAP = "plasma"  # |u|
BAD_COLOR = "0.8"  # where a measure is undefined (von Mises of a Hooke-matrix body in plane strain)


def measure_values(stress: np.ndarray, factor: np.ndarray, measure: Measure) -> np.ndarray:
    """``measure`` of Voigt stresses ``(m, 3)`` with ``s33 = factor (s11 + s22)``: the arrays
    of ``solution.vtu`` (:func:`cvxdual.outputs.vtu.stress_measures`, whose von Mises is
    :func:`cvxdual.voigt.von_mises`, the twin of the models' ``von_mises()``), or the maximum
    shear (:func:`cvxdual.voigt.shear_stress`)."""
    if measure is Measure.SHEAR:
        return shear_stress(stress)
    return stress_measures(stress, factor)[measure.value]


@dataclass(frozen=True)
class DrawnStress:
    """Stresses on triangles ``tris`` ``(n, 3, 2)`` covering the bodies: one Voigt stress per
    triangle, ``stress`` ``(n, 3)`` (constant on each: stress space ``p0``), or one per vertex,
    ``(n, 3, 3)`` (linear on each: ``eq``); ``body`` ``(n,)`` indexes ``scene.bodies``."""

    tris: np.ndarray
    stress: np.ndarray
    body: np.ndarray

    def values(self, measure: Measure, factors: np.ndarray) -> np.ndarray:
        """``measure`` per triangle ``(n,)`` or per vertex ``(n, 3)``; ``factors`` per body
        (:func:`cvxdual.voigt.body_factors`)."""
        per_vertex = self.stress.ndim == 3
        body = np.repeat(self.body, 3) if per_vertex else self.body
        with np.errstate(invalid="ignore"):  # a NaN factor: a NaN von Mises, drawn in BAD_COLOR
            v = measure_values(self.stress.reshape(-1, 3), factors[body], measure)
        return v.reshape(self.stress.shape[:-1])


def stress_support(sol):
    """What the stresses of ``sol`` are defined on: its :class:`~cvxdual.geometry.pieces.Pieces`
    (stress space ``p0``) or its :class:`~cvxdual.eq.space.EquilibriumSpace` (``eq``); the type
    :func:`stress_field` and :func:`draw_mesh` dispatch on. (A ``p0`` solution with bounds has a
    space too: the bounds', not its stresses'.)"""
    return sol.field.support


@singledispatch
def stress_field(support, sol) -> DrawnStress:
    """The stresses of ``sol`` on triangles covering the bodies, by ``support``
    (:func:`stress_support`)."""
    raise TypeError(f"no stress field on {type(support).__name__}")


@stress_field.register(Pieces)
def _(pieces: Pieces, sol) -> DrawnStress:
    """P0: constant on each piece; the curved ones covered by strips of their outlines."""
    tris, ids = triangles(pieces)
    return DrawnStress(tris, sol.stress[ids], pieces.body[ids])


@stress_field.register(EquilibriumSpace)
def _(space: EquilibriumSpace, sol) -> DrawnStress:
    """Equilibrium stresses: linear on every sub-triangle, and the column stress on strips of the
    curved pieces' slabs."""
    P = space.sub_points()
    stress, body = sol.stress.reshape(len(P), 3, 3), np.repeat(space.body, 3)
    if not len(space.pieces.slabs):
        return DrawnStress(P, stress, body)
    tris, slab, col = column_strips(sol)
    return DrawnStress(np.concatenate([P, tris]), np.concatenate([stress, col]),
                       np.concatenate([body, space.pieces.slabs.body[slab]]))


def column_strips(sol) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The slabs of the curved pieces of a solution with an equilibrium space cut into strips:
    triangles ``(n, 3, 2)``, their slab, and the column stress ``(0, g(x), 0)`` at their vertices
    ``(n, 3, 3)`` (``None`` for a P0 solution's bounds)."""
    space = sol.space
    cut = strips(slab_outlines(space.pieces))  # (m, t, 3, 2)
    slab = np.repeat(np.arange(len(cut)), cut.shape[1])
    tris = cut.reshape(-1, 3, 2)
    if sol.column_stress is None:  # a P0 solution's bounds: the geometry only
        return tris, slab, None
    g = column_at(space, sol.column_stress, None, tris.reshape(-1, 2), np.repeat(slab, 3))[0].reshape(-1, 3)
    return tris, slab, np.stack([np.zeros_like(g), g, np.zeros_like(g)], -1)


def signed_norm(values: np.ndarray) -> CenteredNorm:
    """Limits symmetric about zero (white on :data:`SIGNED_CMAP`): equal stresses of either
    sign equally dark, and a field constant to rounding (the patch test) one colour."""
    m = float(np.nanmax(np.abs(values), initial=0.0))
    return CenteredNorm(0.0, m if m > 0 else 1.0)


def magnitude_norm(values: np.ndarray) -> Normalize:
    """From zero to the largest value."""
    m = float(np.nanmax(values, initial=0.0))
    return Normalize(0.0, m if m > 0 else 1.0)


def _range_norm(values: np.ndarray) -> Normalize:
    """From the least to the largest value, a field constant to 0.1% in one colour (not its
    rounding noise)."""
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    scale = max(abs(lo), abs(hi))
    pad = 0.5 * max(1e-3 * scale - (hi - lo), 0.0) if scale else 1.0
    return Normalize(lo - pad, hi + pad)


def _cmap(name: str):
    from matplotlib import colormaps
    return colormaps[name].with_extremes(bad=BAD_COLOR)


def _extreme(tris: np.ndarray, values: np.ndarray, signed: bool) -> tuple[float, np.ndarray]:
    """The value of largest magnitude (signed) or the largest, and where: the vertex (values per
    vertex) or the centroid (per triangle)."""
    v = np.abs(values) if signed else values
    k = int(np.nanargmax(v))
    if values.ndim == 1:
        return float(values[k]), tris[k].mean(axis=0)
    i, j = divmod(k, 3)
    return float(values[i, j]), tris[i, j]


def _subtitle(values: np.ndarray, tris: np.ndarray, signed: bool, unit: str, L: str) -> str:
    if np.isnan(values).all():
        return "undefined"
    value, (x, y) = _extreme(tris, values, signed)
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    if hi - lo <= 1e-3 * abs(value):  # constant to rounding (the patch test): no place stands out
        return f"uniform, {value:.4g} {unit}"
    if signed:
        return f"{lo:.4g} to {hi:.4g} {unit}"
    return f"max {value:.4g} {unit} at ({x:.3g}, {y:.3g}) {L}"


def _draw_values(ax, sol, tris: np.ndarray, values: np.ndarray, cmap, norm, window=None):
    """Values on triangles (one per triangle or per vertex) and the bodies' outlines, in
    ``window`` (default: the whole bodies, :func:`~cvxdual.outputs.views.bodies_window`), equal aspect."""
    if window is None:
        window = bodies_window(sol)
    else:
        keep = in_window(tris, window)
        tris, values = tris[keep], values[keep]
    pc = ax.add_collection(Triangles(tris, array=values.ravel(), cmap=cmap, norm=norm), autolim=False)
    outlines(ax, sol, colors="k", linewidths=0.5)
    ax.set(xlim=window[:2], ylim=window[2:], aspect="equal")
    return pc


def _colorbar(ax, pc, cax, label: str, signed: bool):
    cb = ax.figure.colorbar(pc, ax=None if cax is not None else ax, cax=cax, label=label)
    cb.ax.ticklabel_format(useOffset=False)  # -99.98, not 0.02 under a "-1e2" that reads as a tick
    if signed:  # zero marked on the bar
        cb.ax.axhline(0.0, color="k", lw=0.8) if cb.orientation == "vertical" else cb.ax.axvline(0.0, color="k", lw=0.8)
    return cb


def plot_stress(sol, component: Measure | str = Measure.S22, ax=None, colorbar: bool = True, cmap: str | None = None,
                window=None, cax=None, norm=None, insets: bool = False, side: float | None = None):
    """One stress measure (:class:`Measure` or its name: ``s11``, ``s22``, ``s12``, ``shear``,
    ``von_mises``, ``principal_1``, ``principal_2``) on the bodies, equal aspect: constant per
    piece (``p0``) or linear on every sub-triangle (``eq``; von Mises and the principal stresses
    at the vertices, drawn linear between them). Signed measures on :data:`SIGNED_CMAP` with
    limits symmetric about zero, magnitudes on :data:`STRESS_CMAP` from zero (``norm``, ``cmap``
    to override). ``window`` ``(x0, x1, y0, y1)`` draws only the pieces in it; ``insets``: the
    zooms of :func:`~cvxdual.outputs.views.add_insets` (the contact zone, the field's peak), in a
    corner of the map where one hides none of the bodies, else beside it on the right (``side``
    [in] at most: leave the room, or save with ``bbox_inches="tight"``; without ``cax`` the
    colour bar goes right of them)."""
    ax = axes(ax)
    measure = Measure(component)
    L, S = sol.scene.units
    field = stress_field(stress_support(sol), sol)
    val = field.values(measure, body_factors(sol.scene))
    norm = norm or (signed_norm(val) if measure.signed else magnitude_norm(val))
    cmap = _cmap(cmap or (SIGNED_CMAP if measure.signed else STRESS_CMAP))
    pc = _draw_values(ax, sol, field.tris, val, cmap, norm, window)
    ax.set(title=f"{measure.title}\n{_subtitle(val, field.tris, measure.signed, S, L)}", xlabel=f"x [{L}]",
           ylabel=f"y [{L}]")
    if insets:
        add_insets(ax, sol, lambda a, w: _draw_values(a, sol, field.tris, val, cmap, norm, w),
                   peak=(field.tris, val, measure.signed, f"largest |{measure.short}|" if measure.signed
                         else f"largest {measure.short}"), side=side)
    if colorbar:  # a Hooke-matrix body in plane strain has no s33, so no von Mises: grey
        _colorbar(ax, pc, cax if cax is not None else _beside_zooms(ax),
                  f"{measure.short} [{S}]" + ("; grey: undefined (no nu)" if np.isnan(val).any() else ""),
                  measure.signed)
    return ax


def _beside_zooms(ax):
    """A colour bar's axes right of the zooms beside ``ax`` (:func:`~cvxdual.outputs.views.side_room`), or ``None``
    (none there: the bar takes its room from ``ax``)."""
    room = side_room(ax)
    if not room:
        return None
    w = ax.get_position().width * ax.figure.get_figwidth()
    return ax.inset_axes((1 + (room + 0.12) / w, 0.0, 0.14 / w, 1.0), label="<colorbar>")


def _node_values(sol, component: DisplacementComponent) -> np.ndarray:
    u = sol.displacement
    if component is DisplacementComponent.MAGNITUDE:
        return np.hypot(u[:, 0], u[:, 1])
    return u[:, 0] if component is DisplacementComponent.UX else u[:, 1]


def plot_displacement(sol, component: DisplacementComponent | str = DisplacementComponent.MAGNITUDE, ax=None,
                      colorbar: bool = True, cmap: str | None = None, window=None, cax=None, norm=None):
    """The displacement (``magnitude``, ``u_x`` or ``u_y``) on the mesh, linear on each triangle,
    on the undeformed bodies (a magnified deformed shape would show overlaps the solution does not
    have: :func:`~cvxdual.outputs.plots.plot_deformed` draws it at true scale). The magnitude on
    :data:`DISPLACEMENT_CMAP` from its least to its largest value, the components centred at zero.
    Stress space ``eq``: the bounds' displacement ``v_h``."""
    ax = axes(ax)
    comp = DisplacementComponent(component)
    L, _ = sol.scene.units
    tri = sol.mesh.triangles()
    tris = sol.mesh.points[tri]
    val = _node_values(sol, comp)[tri]
    norm = norm or (signed_norm(val) if comp.signed else _range_norm(val))
    cmap = _cmap(cmap or (SIGNED_CMAP if comp.signed else DISPLACEMENT_CMAP))
    pc = _draw_values(ax, sol, tris, val, cmap, norm, window)
    name = "|u|, displacement magnitude" if comp is DisplacementComponent.MAGNITUDE else comp.value
    ax.set(title=f"{name}\n{_subtitle(val, tris, comp.signed, L, L)}", xlabel=f"x [{L}]", ylabel=f"y [{L}]")
    if colorbar:
        _colorbar(ax, pc, cax, f"{'|u|' if comp is DisplacementComponent.MAGNITUDE else comp.value} [{L}]",
                  comp.signed)
    return ax


BODY_COLORS = ("tab:blue", "tab:orange")  # upper, lower: as in plot_deformed


def _edge_width(ax, tris: np.ndarray) -> tuple[float, float]:
    """Line width [pt] and opacity of triangle edges: thin and faint where the triangles are
    small on the page (lines of a fine mesh would fill it)."""
    ax.apply_aspect()
    x0, x1 = ax.get_xlim()
    width_pt = ax.get_position().width * ax.figure.get_figwidth() * 72
    size = np.sqrt(2 * areas(tris))  # ~ the edge length
    typical = float(np.median(size)) * width_pt / (x1 - x0) if len(size) else 10.0
    return float(np.clip(0.06 * typical, 0.05, 0.6)), float(np.clip(typical / 8, 0.2, 1.0))


def _polys(ax, polys: np.ndarray, body: np.ndarray, lw: tuple[float, float], edge: str, fill: bool) -> None:
    """Polygons ``(n, k, 2)`` in one collection, tinted by body, edges ``lw`` (width, opacity)."""
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import to_rgba
    face = np.array([to_rgba(BODY_COLORS[b], 0.18) for b in range(2)])[body] if fill else "none"
    ax.add_collection(PolyCollection(polys, facecolors=face, edgecolors=to_rgba(edge, lw[1]), linewidths=lw[0]),
                      autolim=False)


def _mesh_view(ax, sol, window):
    if window is None:
        window = bodies_window(sol)
    ax.set(xlim=window[:2], ylim=window[2:], aspect="equal")
    return window


@singledispatch
def draw_mesh(support, sol, ax=None, window=None):
    """Draw the triangles the stresses of ``sol`` live on (``support``: :func:`stress_support`)
    in ``window`` (default: the whole bodies) of ``ax``; return ``ax``."""
    raise TypeError(f"no mesh drawing of {type(support).__name__}")


@draw_mesh.register(Pieces)
def _(pieces: Pieces, sol, ax=None, window=None):
    """The P0 pieces: straight triangles and the curved pieces along the faces (red)."""
    ax = axes(ax)
    window = _mesh_view(ax, sol, window)
    lw = _edge_width(ax, pieces.tri_vertices)
    keep = in_window(pieces.tri_vertices, window)
    _polys(ax, pieces.tri_vertices[keep], pieces.body[pieces.tri_piece[keep]], lw, "0.2", True)
    for ids, poly in piece_outlines(pieces):
        _polys(ax, poly, pieces.body[ids], lw, "tab:red", True)
    return ax


@draw_mesh.register(EquilibriumSpace)
def _(space: EquilibriumSpace, sol, ax=None, window=None):
    """The equilibrium space: the macro triangles, each cut into three sub-triangles at its
    centroid (lighter lines), and the column slabs of the curved pieces (red)."""
    ax = axes(ax)
    window = _mesh_view(ax, sol, window)
    macro = sol.mesh.points[space.tri]
    sub = space.sub_points()
    lw = _edge_width(ax, macro)
    keep = in_window(macro, window)
    _polys(ax, sub[np.repeat(keep, 3)], np.repeat(space.body, 3)[np.repeat(keep, 3)], (0.5 * lw[0], lw[1]), "0.6",
           True)
    _polys(ax, macro[keep], space.body[keep], lw, "0.15", False)
    if len(space.pieces.slabs):
        _polys(ax, slab_outlines(space.pieces), space.pieces.slabs.body, lw, "tab:red", True)
    return ax


@singledispatch
def describe_mesh(support) -> str:
    """One line on what :func:`draw_mesh` draws of ``support``."""
    raise TypeError(f"no mesh description of {type(support).__name__}")


@describe_mesh.register(Pieces)
def _(pieces: Pieces) -> str:
    counts = ", ".join(f"{k} {n}" for k, n in pieces.counts().items() if n)
    return f"p0: {len(pieces)} pieces ({counts})"


@describe_mesh.register(EquilibriumSpace)
def _(space: EquilibriumSpace) -> str:
    slabs = len(space.pieces.slabs)
    return f"eq: {space.n_tri} macro, {3 * space.n_tri} sub-triangles" + (f", {slabs} slabs" if slabs else "")


def plot_mesh(sol, ax=None, window=None, insets: bool = False, side: float | None = None):
    """The mesh the stresses live on (:func:`draw_mesh`): the P0 pieces (curved ones red), or the
    macro and sub-triangles of the equilibrium space; the bodies tinted. ``insets``: the
    contact zone and, where it is local, the finest part of the mesh
    (:func:`~cvxdual.outputs.views.add_insets`; ``side`` as :func:`plot_stress`'s)."""
    ax = axes(ax)
    L, _ = sol.scene.units
    support = stress_support(sol)
    draw_mesh(support, sol, ax=ax, window=window)
    outlines(ax, sol, colors="k", linewidths=0.6)
    ax.set(title=f"mesh\n{describe_mesh(support)}", xlabel=f"x [{L}]", ylabel=f"y [{L}]")
    if insets:
        tris = sol.mesh.points[sol.mesh.triangles()]
        add_insets(ax, sol, lambda a, w: outlines(draw_mesh(support, sol, ax=a, window=w), sol, colors="k",
                                                   linewidths=0.6),
                   peak=(tris, 1.0 / sizes(tris), False, "finest mesh"), side=side)
    return ax
