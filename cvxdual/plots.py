"""Plots of a solution, matplotlib-style: every function draws on ``ax`` (a new pyplot axes
if none is given) and returns it; files are written by :mod:`cvxdual.output`.

Nothing here chooses a matplotlib backend: that is the caller's (the output layer draws on
:class:`matplotlib.figure.Figure` objects, which need none).
"""

from __future__ import annotations

import numpy as np
from matplotlib import artist
from matplotlib.collections import Collection, LineCollection
from matplotlib.colors import Normalize
from matplotlib.patches import PathPatch
from matplotlib.path import Path

from .exact import exact_field
from .locate import nearest_node_values
from .pieces import piece_outlines

MAX_EDGES = 12000  # above this (about 4000 pieces), the deformed plot shows colours instead of every edge


def _axes(ax):
    if ax is None:
        import matplotlib.pyplot as plt
        _, ax = plt.subplots()
    return ax


def _polys(sol, scale: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Groups ``(piece ids, polygons (m, v, 2))`` of all pieces (triangles, then curved pieces
    by number of vertices), displaced by ``scale`` times the displacement."""
    p = sol.pieces
    disp = sol.displacement
    tri = p.tri_vertices
    if scale:
        tri = tri + scale * disp[p.nodes[p.tri_piece]]
    groups = [(p.tri_piece, tri)]
    for ids, poly in piece_outlines(p):
        if scale:
            m, v = poly.shape[:2]
            poly = poly + scale * nearest_node_values(sol.mesh, poly.reshape(-1, 2), np.repeat(p.body[ids], v),
                                                      disp).reshape(m, v, 2)
        groups.append((ids, poly))
    return groups


def _strips(poly: np.ndarray) -> np.ndarray:
    """Triangles ``(m, t, 3, 2)`` covering outlines ``poly`` ``(m, 2k, 2)`` of :func:`piece_outlines`
    (``k`` points along the lower bound left to right, then along the upper bound right to left):
    two per strip between neighbouring abscissae, which is right for the concave pieces too."""
    k = poly.shape[1] // 2
    lo, hi = poly[:, :k], poly[:, :k - 1:-1]
    a, b, c, d = lo[:, :-1], lo[:, 1:], hi[:, 1:], hi[:, :-1]
    return np.stack([a, b, c, a, c, d], axis=2).reshape(len(poly), 2 * (k - 1), 3, 2)


def _triangles(groups) -> tuple[np.ndarray, np.ndarray]:
    """Triangles ``(n, 3, 2)`` covering the pieces of ``groups`` (:func:`_polys`; curved pieces
    cut into strips) and the piece of each."""
    (ids, tri), *curved = groups
    tris, ids = [tri], [ids]
    for pid, poly in curved:
        strips = _strips(poly)
        tris.append(strips.reshape(-1, 3, 2))
        ids.append(np.repeat(pid, strips.shape[1]))
    return np.concatenate(tris), np.concatenate(ids)


class Triangles(Collection):
    """Triangles ``(n, 3, 2)``, each with its own three vertices, coloured by ``array``: one
    value per triangle (flat, as the P0 stresses are) or one per vertex (``3 n`` values, linear:
    Gouraud shading). The renderer draws them all in one call (Agg: ``draw_gouraud_triangles``),
    with no path per triangle and no edges, so there are no seams to stroke over."""

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
        renderer.draw_gouraud_triangles(gc, self._tris, colors, self.get_transform().frozen())
        gc.restore()
        renderer.close_group(type(self).__name__)


def _extent(xy: np.ndarray) -> np.ndarray:
    """Corners ``[[x_min, y_min], [x_max, y_max]]`` of points ``(m, 2)`` (by column: a reduction
    over axis 0 of an ``(m, 2)`` array is 30x slower)."""
    x, y = xy[:, 0], xy[:, 1]
    return np.array([[x.min(), y.min()], [x.max(), y.max()]])


def _add_triangles(ax, tris: np.ndarray, values: np.ndarray, **kw) -> Triangles:
    """:class:`Triangles` ``tris`` coloured by ``values`` on ``ax``, in its data limits."""
    pc = Triangles(tris, array=values, **kw)
    if len(tris):
        ax.update_datalim(_extent(tris.reshape(-1, 2)))
    ax.add_collection(pc, autolim=False)
    return pc


def _add_polys(ax, groups, values, **kw) -> Triangles:
    """The pieces of ``groups`` (:func:`_polys`) in flat colours, ``values`` one per piece."""
    tris, ids = _triangles(groups)
    return _add_triangles(ax, tris, values[ids], **kw)


def _add_edges(ax, groups, **kw) -> PathPatch:
    """The outlines of the pieces of ``groups`` (:func:`_polys`) as one path."""
    verts, codes = [], []
    for _, poly in groups:
        m, v = poly.shape[:2]
        verts.append(np.concatenate([poly, poly[:, :1]], axis=1).reshape(-1, 2))
        c = np.full((m, v + 1), Path.LINETO, Path.code_type)
        c[:, 0], c[:, -1] = Path.MOVETO, Path.CLOSEPOLY
        codes.append(c.ravel())
    xy = np.concatenate(verts)
    patch = PathPatch(Path(xy, np.concatenate(codes)), facecolor="none", **kw)
    if len(xy):
        ax.update_datalim(_extent(xy))
    ax.add_artist(patch)
    return patch


def body_outline(body, n: int = 400) -> np.ndarray:
    """Closed outline of a body on its true (curved) face."""
    x0, x1 = body.x_range
    xs = np.linspace(x0, x1, n)
    face = np.stack([xs, body.face.value(xs)], 1)
    far = np.array([[x1, body.far], [x0, body.far]])
    return np.concatenate([face, far, face[:1]])


def _outlines(ax, sol, **kw) -> None:
    ax.add_collection(LineCollection([body_outline(bm.body) for bm in sol.mesh.bodies], **kw))


STRESS_COMPONENTS = {
    "s11": (lambda t: t[:, 0], "s11"),
    "s22": (lambda t: t[:, 1], "s22 (contact direction)"),
    "s12": (lambda t: t[:, 2], "s12"),
    "shear": (lambda t: np.sqrt(((t[:, 0] - t[:, 1]) / 2) ** 2 + t[:, 2] ** 2), "max shear"),
}


def plot_stress(sol, component: str = "s22", ax=None, colorbar: bool = True, cmap: str = "viridis"):
    """One stress component (``s11``, ``s22``, ``s12`` or ``shear``) on the bodies' outlines:
    constant per piece (``p0``) or linear on every sub-triangle (``eq``)."""
    ax = _axes(ax)
    L, S = sol.scene.units
    fn, title = STRESS_COMPONENTS[component]
    if sol.stress_space == "eq":
        val = fn(sol.stress.reshape(-1, 3))
        pc = _add_triangles(ax, sol.space.sub_points(), val, cmap=cmap, norm=Normalize(val.min(), val.max()))
    else:
        val = fn(sol.stress)
        pc = _add_polys(ax, _polys(sol), val, cmap=cmap, norm=Normalize(val.min(), val.max()))
    _outlines(ax, sol, colors="k", linewidths=0.5)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_title(f"{title} [{S}]")
    ax.set_xlabel(f"x [{L}]")
    if colorbar:
        ax.figure.colorbar(pc, ax=ax, shrink=0.8)
    return ax


def deformation_scale(sol) -> float:
    """Magnification that makes the largest displacement 5% of the scene's length scale."""
    u = np.abs(sol.displacement).max()
    return 0.05 * sol.scene.length_scale / u if u > 0 else 1.0


def plot_deformed(sol, ax=None, scale: float | None = None):
    """The deformed pieces (edges, or |u| colours above :data:`MAX_EDGES`) over the dashed
    undeformed outlines."""
    ax = _axes(ax)
    L, _ = sol.scene.units
    k = deformation_scale(sol) if scale is None else scale
    groups = _polys(sol, k)
    if sol.system.n_pieces * 3 <= MAX_EDGES:
        _add_edges(ax, groups, edgecolor="k", linewidth=0.3)
    else:
        mag = np.linalg.norm(sol.displacement, axis=1)[sol.pieces.nodes[:, 0]]
        pc = _add_polys(ax, groups, mag, cmap="magma", norm=Normalize(mag.min(), mag.max()))
        ax.figure.colorbar(pc, ax=ax, shrink=0.8, label=f"|u| [{L}]")
    _outlines(ax, sol, colors="tab:blue", linewidths=0.8, linestyles="--")
    ax.autoscale_view()
    ax.set_aspect("equal")
    note = "" if sol.scene.gap_profile.is_flat() else ";\nthe gap function is not drawn"
    ax.set_title(f"deformed mesh, displacements x {k:.3g} (dashed: undeformed){note}")
    ax.set_xlabel(f"x [{L}]")
    return ax


def plot_pressure(sol, ax=None):
    """Contact pressure at the pairs, with the closed form where the scene has one."""
    ax = _axes(ax)
    L, S = sol.scene.units
    c = sol.contact
    ax.plot(c["x"], c["pressure"], "o-", ms=3, lw=1, label="cvxdual (nodal force / tributary length)")
    if sol.exact is not None:
        xs = np.linspace(c["x"].min(), c["x"].max(), 2001)
        label = "Hertz" if sol.exact.get("kind") == "hertz" else "exact"
        ax.plot(xs, exact_field(sol.scene).pressure(xs), "k-", lw=1, label=label)
    ax.set_xlabel(f"x [{L}]")
    ax.set_ylabel(f"contact pressure [{S}]")
    ax.set_title(f"{sol.scene.name}: {c['n_active']} active pairs of {len(c['x'])}")
    ax.legend()
    ax.grid(alpha=0.3)
    return ax


def plot_bound_map(sol, ax=None, colorbar: bool = True):
    """Where the certified bound comes from: the contribution of every sub-triangle to ``G``
    per unit area (``1/2 |sigma - C e(v)|_A^2``), log scale; the contact edges' total is in
    the title."""
    from matplotlib.colors import LogNorm
    ax = _axes(ax)
    L, S = sol.scene.units
    b = sol.bounds
    P = sol.space.sub_points()
    d = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    area = 0.5 * np.abs(d[0][:, 0] * d[1][:, 1] - d[0][:, 1] * d[1][:, 0])
    dens = b["contributions"]["sub"].ravel() / area
    floor = max(float(dens.max()) * 1e-8, 1e-300)
    pc = _add_triangles(ax, P, np.maximum(dens, floor), cmap="inferno",
                        norm=LogNorm(floor, max(float(dens.max()), 10 * floor)))
    _outlines(ax, sol, colors="w", linewidths=0.5)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel(f"x [{L}]")
    ax.set_title(f"G = {b['gap']:.3g} (contact edges {float(b['contributions']['contact'].sum()):.3g}); "
                 f"bound sqrt(2G) = {b['error_bound']:.3g}", fontsize=9)
    if colorbar:
        ax.figure.colorbar(pc, ax=ax, shrink=0.8, label=f"contribution to G per unit area [{S}]")
    return ax
