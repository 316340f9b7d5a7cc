"""The standard figures of a solution (``stress.png``, ``deformed.png``, ``pressure.png``,
``bounds.png``) as :class:`matplotlib.figure.Figure` objects, drawn by :mod:`cvxdual.plots`."""

from __future__ import annotations


def figures(sol) -> dict:
    """The standard plots as :class:`matplotlib.figure.Figure` objects, by file name.

    Margins are fixed in inches (no layout engine: constrained layout costs more than drawing
    a small mesh, on every save) and every map's height is fitted to its equal-aspect data."""
    from matplotlib.figure import Figure

    from .plots import plot_deformed, plot_pressure, plot_stress

    def fit(fig, ax, top: float, right: float, left: float = 0.65, bottom: float = 0.5, gap: float = 0.0,
            n: int = 1) -> None:
        """Margins in inches (``gap`` between ``n`` panels side by side), widened where colour bar
        labels need it, and the figure height at which the equal-aspect data of ``ax`` fill its
        panel (aspect ratio clipped to 0.3-2.5)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        ratio = min(max(abs(y1 - y0) / abs(x1 - x0), 0.3), 2.5) if x1 != x0 else 1.0
        caxes = [a for a in fig.axes if a.get_label() == "<colorbar>"]
        for _ in range(2):
            w = fig.get_figwidth()
            panel = (w - left - right - gap * (n - 1)) / n
            fig.subplots_adjust(left=left / w, right=1 - right / w, wspace=gap / panel)
            h = top + bottom + ratio * ax.get_position(original=True).width * w
            fig.set_figheight(h)
            fig.subplots_adjust(bottom=bottom / h, top=1 - top / h)
            if not any(len(t.get_text()) > 6 for cax in caxes for t in cax.yaxis.get_majorticklabels()):
                return  # short tick labels fit the margins: measuring them would cost a draw of the axes
            renderer = FigureCanvasAgg(fig).get_renderer()
            over = 0.0  # how far colour bar labels reach into the next panel's tick labels or off the figure
            for cax in caxes:
                cax.apply_aspect()
                i = min(int((cax.get_position().x0 * w - left) // (panel + gap)), n - 1)
                limit = left + (i + 1) * panel + i * gap + (gap - 0.55 if i < n - 1 else right - 0.05)
                over = max(over, cax.yaxis.get_tightbbox(renderer).x1 / fig.dpi - limit)
            if over <= 0.01:
                return
            right, gap = right + over, gap + over if n > 1 else gap

    stress = Figure(figsize=(10.0, 5.0))
    for ax, comp in zip(stress.subplots(1, 2), ("s22", "shear"), strict=True):
        plot_stress(sol, comp, ax=ax)
    n = 3 * sol.space.n_tri if sol.stress_space == "eq" else sol.system.n_pieces  # summary()["n_pieces"], cheaply
    what = f"stress space eq: {n} sub-triangles" if sol.stress_space == "eq" else f"{sol.triangulation}: {n} pieces"
    fit(stress, stress.axes[0], top=0.75, right=0.55, gap=0.75, n=2)
    stress.suptitle(f"{sol.scene.name}, level {sol.level}, {what}", y=1 - 0.08 / stress.get_figheight(), va="top")
    deformed = Figure(figsize=(6.0, 5.0))
    ax = deformed.add_subplot()
    plot_deformed(sol, ax=ax)
    if len(deformed.axes) > 1:  # a colour bar: keep the axes (and the title above them) as wide
        deformed.set_figwidth(7.2)
    fit(deformed, ax, top=0.42 + 0.22 * ax.get_title().count("\n"), right=0.95 if len(deformed.axes) > 1 else 0.3)
    pressure = Figure(figsize=(8, 4.5))
    plot_pressure(sol, ax=pressure.add_subplot())
    pressure.subplots_adjust(left=0.9 / 8, right=1 - 0.25 / 8, bottom=0.5 / 4.5, top=1 - 0.4 / 4.5)
    out = {"stress.png": stress, "deformed.png": deformed, "pressure.png": pressure}
    if sol.bounds is not None:
        from .plots import plot_bound_map
        bounds = Figure(figsize=(8.0, 5.0))
        ax = bounds.add_subplot()
        plot_bound_map(sol, ax=ax)
        fit(bounds, ax, top=0.4, right=1.1)
        out["bounds.png"] = bounds
    return out


