"""PNG plots of a solution: stress maps, the deformed mesh and the contact pressure."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402

from .output import nearest_node_values, piece_outlines  # noqa: E402

MAX_EDGES = 60000  # above this, the deformed plot shows colours instead of every edge


def _polys(sol, scale: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Groups ``(piece ids, polygons (m, v, 2))`` of all pieces (triangles, then curved pieces
    by number of vertices), displaced by ``scale`` times the displacement."""
    p = sol.system.pieces
    disp = sol.displacement
    tri = p.tri_vertices
    if scale:
        tri = tri + scale * disp[p.nodes[p.tri_piece]]
    groups = [(p.tri_piece, tri)]
    for ids, poly in piece_outlines(p):
        if scale:
            m, v = poly.shape[:2]
            poly = poly + scale * nearest_node_values(sol, poly.reshape(-1, 2), np.repeat(p.body[ids], v),
                                                      disp).reshape(m, v, 2)
        groups.append((ids, poly))
    return groups


def _collections(groups, values=None, **kw) -> list[PolyCollection]:
    cols = []
    for ids, poly in groups:
        pc = PolyCollection(poly, **kw)
        if values is not None:
            pc.set_array(values[ids])
        cols.append(pc)
    return cols


def _figsize(sol, panels: int = 1) -> tuple[float, float]:
    pts = sol.mesh.points
    w, h = np.ptp(pts[:, 0]), np.ptp(pts[:, 1])
    aspect = min(max(h / w, 0.3), 2.5)
    return (min(6.0 * panels, 14.0), 1.0 + min(6.0 * panels, 14.0) / panels * aspect * 0.85)


def _save(fig, path: Path) -> Path:
    try:
        fig.savefig(path, dpi=130, format="png")
    finally:
        plt.close(fig)
    return path


def _units(sol):
    return sol.scene.units


def plot_stress(sol, path: Path) -> Path:
    L, S = _units(sol)
    t = sol.stress
    tau = np.sqrt(((t[:, 0] - t[:, 1]) / 2) ** 2 + t[:, 2] ** 2)
    groups = _polys(sol)
    fig, axes = plt.subplots(1, 2, figsize=_figsize(sol, 2), constrained_layout=True)
    for ax, val, title in ((axes[0], t[:, 1], "s22 (contact direction)"), (axes[1], tau, "max shear")):
        norm = matplotlib.colors.Normalize(val.min(), val.max())
        for pc in _collections(groups, val, cmap="viridis", norm=norm, edgecolors="face", linewidths=0.1):
            ax.add_collection(pc)
        ax.autoscale_view()
        ax.set_aspect("equal")
        for bm in sol.mesh.bodies:
            ax.add_collection(LineCollection([body_outline(bm.body)], colors="k", linewidths=0.5))
        ax.set_title(f"{title} [{S}]")
        ax.set_xlabel(f"x [{L}]")
        fig.colorbar(pc, ax=ax, shrink=0.8)
    fig.suptitle(f"{sol.scene.name}, {sol.triangulation}, level {sol.level}: {len(t)} pieces")
    return _save(fig, path)


def body_outline(body, n: int = 400) -> np.ndarray:
    """Closed outline of a body on its true (curved) face."""
    x0, x1 = body.x_range
    xs = np.linspace(x0, x1, n)
    face = np.stack([xs, body.face.value(xs)], 1)
    far = np.array([[x1, body.far], [x0, body.far]])
    return np.concatenate([face, far, face[:1]])


def deformation_scale(sol) -> float:
    u = np.abs(sol.displacement).max()
    return 0.05 * sol.scene.length_scale / u if u > 0 else 1.0


def plot_deformed(sol, path: Path) -> Path:
    L, _ = _units(sol)
    k = deformation_scale(sol)
    disp = sol.displacement
    groups = _polys(sol, k)
    fig, ax = plt.subplots(figsize=_figsize(sol), constrained_layout=True)
    if sol.system.n_pieces * 3 <= MAX_EDGES:
        for pc in _collections(groups, facecolors="none", edgecolors="k", linewidths=0.3):
            ax.add_collection(pc)
    else:
        mag = np.linalg.norm(disp, axis=1)[sol.system.pieces.nodes[:, 0]]
        norm = matplotlib.colors.Normalize(mag.min(), mag.max())
        for pc in _collections(groups, mag, cmap="magma", norm=norm, edgecolors="face", linewidths=0.0):
            ax.add_collection(pc)
        fig.colorbar(pc, ax=ax, shrink=0.8, label=f"|u| [{L}]")
    for bm in sol.mesh.bodies:
        ax.add_collection(LineCollection([body_outline(bm.body)], colors="tab:blue", linewidths=0.8,
                                         linestyles="--"))
    ax.autoscale_view()
    ax.set_aspect("equal")
    note = "" if sol.scene.gap_profile.is_flat() else "; the gap function is not drawn"
    ax.set_title(f"deformed mesh, displacements x {k:.3g} (dashed: undeformed){note}")
    ax.set_xlabel(f"x [{L}]")
    return _save(fig, path)


def plot_pressure(sol, path: Path) -> Path:
    L, S = _units(sol)
    c = sol.contact
    fig, ax = plt.subplots(figsize=(8, 4.5), constrained_layout=True)
    ax.plot(c["x"], c["pressure"], "o-", ms=3, lw=1, label="cvxdual (nodal force / tributary length)")
    if sol.exact is not None:
        from .exact import exact_field
        ex = exact_field(sol.scene)
        xs = np.linspace(c["x"].min(), c["x"].max(), 2001)
        label = "Hertz" if sol.exact.get("kind") == "hertz" else "exact"
        ax.plot(xs, ex.pressure(xs), "k-", lw=1, label=label)
    ax.set_xlabel(f"x [{L}]")
    ax.set_ylabel(f"contact pressure [{S}]")
    ax.set_title(f"{sol.scene.name}: {c['n_active']} active pairs of {len(c['x'])}")
    ax.legend()
    ax.grid(alpha=0.3)
    return _save(fig, path)


PLOTS = {"stress.png": plot_stress, "deformed.png": plot_deformed, "pressure.png": plot_pressure}
