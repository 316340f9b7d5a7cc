"""The standard figures of a solution (``stress.png``, ``deformed.png``, ``pressure.png``,
``bounds.png``) as :class:`matplotlib.figure.Figure` objects, drawn by :mod:`cvxdual.outputs.plots`.

Axes are placed in inches, with margins sized for their labels (no layout engine: constrained
layout costs more than drawing a small mesh, on every save); a map's height follows its
equal-aspect data.
"""

from __future__ import annotations

WIDTH = 10.0  # figure width [in]
LEFT, BOTTOM, TOP = 0.8, 0.55, 0.75  # room for y tick labels and label; x ones; suptitle and title
CB_PAD, CB_W, CB_TEXT = 0.12, 0.14, 0.9  # colour bar: gap, bar, tick labels and label
MAX_H = 4.2  # tallest map [in]; a taller one is narrowed instead
DPI = 130  # of the PNGs (cvxdual.outputs.output_set)


def _rect(fig, left: float, top: float, width: float, height: float) -> tuple:
    """``(left, bottom, width, height)`` in figure fractions of a box given in inches from the
    top left corner."""
    W, H = fig.get_size_inches()
    return left / W, 1 - (top + height) / H, width / W, height / H


def _ratio(window) -> float:
    x0, x1, y0, y1 = window
    return (y1 - y0) / (x1 - x0)


def _title(fig, text: str) -> None:
    fig.suptitle(text, y=1 - 0.08 / fig.get_figheight(), va="top")


def stress_figure(sol):
    """s22 and the maximum shear stress: the whole bodies and, below, the contact zone."""
    from matplotlib.figure import Figure

    from .plots import STRESS_COMPONENTS, bodies_window, contact_zone, plot_stress, zoom_window
    windows = [bodies_window(sol), zoom_window(sol)]
    windows = [w for w in windows if w is not None]
    cb = CB_PAD + CB_W + CB_TEXT
    pw = (WIDTH - 2 * (LEFT + cb)) / 2
    heights = [min(pw * _ratio(w), MAX_H) for w in windows]
    vgap = BOTTOM + 0.35  # x labels of the row above, title of the row below
    tops = [TOP, TOP + heights[0] + vgap][:len(windows)]
    fig = Figure(figsize=(WIDTH, TOP + sum(heights) + vgap * (len(windows) - 1) + BOTTOM))
    step = round((pw + cb + LEFT) * DPI) / DPI  # whole pixels apart: the maps share their sampling
    for c, comp in enumerate(("s22", "shear")):
        x = LEFT + c * step
        cax = fig.add_axes(_rect(fig, x + pw + CB_PAD, TOP, CB_W, tops[-1] + heights[-1] - TOP), label="<colorbar>")
        for r, w in enumerate(windows):
            ax = fig.add_axes(_rect(fig, x, tops[r], pw, heights[r]))
            ax.set_anchor("E")  # a narrowed map stays by its colour bar
            plot_stress(sol, comp, ax=ax, window=w if r else None, colorbar=r == 0, cax=cax)
            if r:
                ax.set_label("zoom")
                ax.set_title(f"{STRESS_COMPONENTS[comp][2]}: contact zone")
    n = 3 * sol.space.n_tri if sol.stress_space == "eq" else sol.system.n_pieces  # summary()["n_pieces"], cheaply
    what = f"stress space eq, {n} sub-triangles" if sol.stress_space == "eq" else f"{sol.triangulation}, {n} pieces"
    zone = contact_zone(sol)
    why = ("" if len(windows) > 1 else "; no contact pairs" if zone is None else
           f"; contact zone {zone[0]:.3g} to {zone[1]:.3g} {sol.scene.units[0]}: no zoom needed")
    _title(fig, f"{sol.scene.name}, level {sol.level}, {what}{why}")
    return fig


def deformed_figure(sol):
    """The contact zone at true displacement scale, and the gap and approach along it."""
    from matplotlib.figure import Figure

    from .plots import plot_deformed, plot_gap
    gap, height = 1.0, 3.6
    pw = (WIDTH - LEFT - gap - 0.25) / 2
    fig = Figure(figsize=(WIDTH, TOP + height + BOTTOM))
    left = fig.add_axes(_rect(fig, LEFT, TOP, pw, height))
    plot_deformed(sol, ax=left)  # after placing: its vertical stretch fills the axes
    right = fig.add_axes(_rect(fig, LEFT + pw + gap, TOP, pw, height))
    plot_gap(sol, ax=right, xlim=left.get_xlim())
    _clear_y_labels(fig, [left, right])
    _title(fig, f"{sol.scene.name}, level {sol.level}: the contact zone")
    return fig


def _clear_y_labels(fig, row) -> None:
    """Narrow the axes of ``row`` (left to right) from the left where their y tick labels and
    label (long where displacements are small: -0.0025) would reach off the figure or into the
    axes before; measured on the text alone, without drawing."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    renderer = FigureCanvasAgg(fig).get_renderer()
    W = fig.get_figwidth()
    edge = 0.05  # [in] kept clear of the figure's edge and of the axes before
    for ax in row:
        over = edge - ax.yaxis.get_tightbbox(renderer).x0 / fig.dpi
        if over > 0:
            x0, y0, w, h = ax.get_position().bounds
            ax.set_position((x0 + over / W, y0, w - over / W, h))
        edge = ax.get_position().x1 * W + 0.1


def pressure_figure(sol):
    """The contact pressure around the contact zone, with the closed form where there is one."""
    from matplotlib.figure import Figure

    from .plots import plot_pressure
    fig = Figure(figsize=(8.0, 4.5))
    plot_pressure(sol, ax=fig.add_axes(_rect(fig, 0.9, 0.4, 8.0 - 0.9 - 0.25, 4.5 - 0.4 - BOTTOM)))
    return fig


def bounds_figure(sol):
    """Where the certified bound comes from, on the whole bodies."""
    from matplotlib.figure import Figure

    from .plots import bodies_window, plot_bound_map
    cb, ratio = CB_PAD + CB_W + 1.0, _ratio(bodies_window(sol))  # a longer colour bar label, powers of ten
    pw = min(8.0 - LEFT - cb, (MAX_H + 1) / ratio)  # a tall map makes a narrower figure
    height = pw * ratio
    fig = Figure(figsize=(LEFT + pw + cb, 0.45 + height + BOTTOM))
    ax = fig.add_axes(_rect(fig, LEFT, 0.45, pw, height))
    plot_bound_map(sol, ax=ax, cax=fig.add_axes(_rect(fig, LEFT + pw + CB_PAD, 0.45, CB_W, height), label="<colorbar>"))
    return fig


def figures(sol) -> dict:
    """The standard plots as :class:`matplotlib.figure.Figure` objects, by file name."""
    out = {"stress.png": stress_figure(sol), "deformed.png": deformed_figure(sol), "pressure.png": pressure_figure(sol)}
    if sol.bounds is not None:
        out["bounds.png"] = bounds_figure(sol)
    return out
