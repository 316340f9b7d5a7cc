"""Plots of a solution, matplotlib-style: every function draws on ``ax`` (a new pyplot axes
if none is given) and returns it; files are written by :mod:`cvxdual.output`.

Nothing here chooses a matplotlib backend: that is the caller's (the output layer draws on
:class:`matplotlib.figure.Figure` objects, which need none).
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import Normalize

from .exact import exact_field
from .locate import nearest_node_values
from .pieces import piece_outlines

MAX_EDGES = 60000  # above this, the deformed plot shows colours instead of every edge


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


def _add_polys(ax, groups, values=None, **kw) -> PolyCollection:
    pc = None
    for ids, poly in groups:
        pc = PolyCollection(poly, **kw)
        if values is not None:
            pc.set_array(values[ids])
        ax.add_collection(pc)
    return pc


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


def _sub_triangulation(sol):
    """The sub-triangles of an equilibrium solution, each with its own three vertices."""
    from matplotlib.tri import Triangulation
    P = sol.space.sub_points().reshape(-1, 2)
    return Triangulation(P[:, 0], P[:, 1], np.arange(len(P)).reshape(-1, 3))


def plot_stress(sol, component: str = "s22", ax=None, colorbar: bool = True, cmap: str = "viridis"):
    """One stress component (``s11``, ``s22``, ``s12`` or ``shear``) on the bodies' outlines:
    constant per piece (``p0``) or linear on every sub-triangle (``eq``)."""
    ax = _axes(ax)
    L, S = sol.scene.units
    fn, title = STRESS_COMPONENTS[component]
    if sol.stress_space == "eq":
        val = fn(sol.stress.reshape(-1, 3))
        pc = ax.tripcolor(_sub_triangulation(sol), val, shading="gouraud", cmap=cmap)
    else:
        val = fn(sol.stress)
        pc = _add_polys(ax, _polys(sol), val, cmap=cmap, norm=Normalize(val.min(), val.max()),
                        edgecolors="face", linewidths=0.1)
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
        _add_polys(ax, groups, facecolors="none", edgecolors="k", linewidths=0.3)
    else:
        mag = np.linalg.norm(sol.displacement, axis=1)[sol.pieces.nodes[:, 0]]
        pc = _add_polys(ax, groups, mag, cmap="magma", norm=Normalize(mag.min(), mag.max()),
                        edgecolors="face", linewidths=0.0)
        ax.figure.colorbar(pc, ax=ax, shrink=0.8, label=f"|u| [{L}]")
    _outlines(ax, sol, colors="tab:blue", linewidths=0.8, linestyles="--")
    ax.autoscale_view()
    ax.set_aspect("equal")
    note = "" if sol.scene.gap_profile.is_flat() else "; the gap function is not drawn"
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
    pc = PolyCollection(P, array=np.maximum(dens, floor), cmap="inferno",
                        norm=LogNorm(floor, max(float(dens.max()), 10 * floor)), edgecolors="face", linewidths=0.0)
    ax.add_collection(pc)
    _outlines(ax, sol, colors="w", linewidths=0.5)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel(f"x [{L}]")
    ax.set_title(f"G = {b['gap']:.3g} (contact edges {float(b['contributions']['contact'].sum()):.3g}); "
                 f"bound sqrt(2G) = {b['error_bound']:.3g}", fontsize=9)
    if colorbar:
        ax.figure.colorbar(pc, ax=ax, shrink=0.8, label=f"contribution to G per unit area [{S}]")
    return ax
