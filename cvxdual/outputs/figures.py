"""The figures of a solution as :class:`matplotlib.figure.Figure` objects, one per
:class:`Plot` (``stress.png``, ``deformed.png``, ``pressure.png``, ``bounds.png``, ``mesh.png``,
``vonmises.png``, ``principal.png``, ``displacement.png``), drawn by :mod:`cvxdual.outputs.maps`
and :mod:`cvxdual.outputs.plots`. The maps show the whole body pair, with zooms on the contact
zone and on a local peak of the field (a hole's stress concentration, :mod:`cvxdual.outputs.views`):
insets in an empty corner of the map, or, where every corner would hide part of the bodies, axes
beside the map between it and its colour bar (the figure widened for them, up to :data:`WIDE`).

Axes are placed in inches, with margins sized for their labels (no layout engine: constrained
layout costs more than drawing a small mesh, on every save); a map's height follows its
equal-aspect data, and a figure's title is wrapped to its width (measured, not guessed) with
the room it needs above the axes.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import Enum

from ..errors import UnknownPlotError

WIDTH = 10.0  # width [in] of a figure of two maps side by side
SINGLE = 6.6  # ... of one map
LEFT, BOTTOM = 0.8, 0.55  # room for y tick labels and label; x ones
AX_TITLE = 0.6  # [in] above a map: its title of two lines
TITLE_SIZE = 12  # [pt] of the figure's title
CB_PAD, CB_W, CB_TEXT = 0.12, 0.14, 0.9  # colour bar: gap, bar, tick labels and label
MAX_H = 5.2  # tallest map [in] beside another; a taller one is narrowed instead
MAX_H_SINGLE = 6.4  # ... alone
WIDE, WIDE_SINGLE = 14.0, 10.0  # widest [in] zooms beside the maps (none of their corners empty) make a figure
DPI = 130  # of the PNGs (cvxdual.outputs.output_set)


class Plot(Enum):
    """A figure a solution can be drawn as; its file is ``<value>.png``."""

    STRESS = "stress"  # s22 and the maximum shear
    DEFORMED = "deformed"  # the contact zone at true displacement scale, gap and approach
    PRESSURE = "pressure"  # contact pressure at the pairs, and the closed form
    BOUNDS = "bounds"  # where the certified gap G comes from (where bounds are computed)
    MESH = "mesh"  # the pieces (p0) or macro and sub-triangles (eq)
    VONMISES = "vonmises"  # von Mises stress
    PRINCIPAL = "principal"  # the in-plane principal stresses
    DISPLACEMENT = "displacement"  # |u| and u_y
    CYCLES = "cycles"  # a run to a tolerance: the certified error of every cycle against its pieces

    @property
    def file(self) -> str:
        return f"{self.value}.png"


# `--plots` alone, `plots=True`: the figures cvxdual drew before figures could be chosen
# (bounds.png only where the solution has bounds), and cycles.png of a run to a tolerance
DEFAULT_PLOTS = (Plot.STRESS, Plot.DEFORMED, Plot.PRESSURE, Plot.BOUNDS, Plot.CYCLES)
ALL = "all"  # every figure


def plot_names() -> str:
    return ", ".join(p.value for p in Plot)


def parse_plots(spec) -> tuple[Plot, ...]:
    """The figures asked for: none (``None``, ``False``), :data:`DEFAULT_PLOTS` (``True``), or
    names: a comma-separated string (``"stress,mesh"``, as ``--plots`` takes it) or an iterable
    of names or :class:`Plot` (empty: none); ``all``: every figure. In order, each once. An unknown name raises
    :class:`UnknownPlotError`, which lists the valid ones."""
    if spec is None or spec is False:
        return ()
    if spec is True:
        return DEFAULT_PLOTS
    items = spec.split(",") if isinstance(spec, str) else list(spec) if isinstance(spec, Iterable) else [spec]
    out: list[Plot] = []
    for item in items:
        if isinstance(item, Plot):
            out.append(item)
            continue
        name = str(item).strip().lower()
        if not name:  # "stress," or a doubled comma
            continue
        if name == ALL:
            out += list(Plot)
            continue
        try:
            out.append(Plot(name))
        except ValueError:
            msg = f"unknown figure {str(item).strip()!r}; valid names: {plot_names()} (or {ALL}), comma-separated"
            raise UnknownPlotError(msg, cli=f"--plots: {msg}, e.g. --plots stress,mesh") from None
    if not out and isinstance(spec, str):  # "" or ",": a name was meant
        raise UnknownPlotError(f"no figure named; valid names: {plot_names()} (or {ALL})",
                               cli=f"--plots: no figure named; valid names: {plot_names()} (or {ALL})")
    return tuple(dict.fromkeys(out))


def names_plot(spec, plot: Plot) -> bool:
    """Whether ``spec`` (as :func:`parse_plots` takes it) names ``plot`` itself, not through
    ``True`` (the default set) or ``all``: a figure asked for by name must be drawn."""
    if spec is None or isinstance(spec, bool):
        return False
    items = spec.split(",") if isinstance(spec, str) else spec if isinstance(spec, Iterable) else [spec]
    return any(item is plot or str(item).strip().lower() == plot.value for item in items)


def _rect(fig, left: float, top: float, width: float, height: float) -> tuple:
    """``(left, bottom, width, height)`` in figure fractions of a box given in inches from the
    top left corner."""
    W, H = fig.get_size_inches()
    return left / W, 1 - (top + height) / H, width / W, height / H


def _ratio(window) -> float:
    x0, x1, y0, y1 = window
    return (y1 - y0) / (x1 - x0)


def wrap_title(text: str, width: float, size: float = TITLE_SIZE) -> list[str]:
    """``text`` in lines no wider than ``width`` [in] at ``size`` points (measured with the Agg
    renderer, in the default font), broken between words; one word too long stays whole."""
    from matplotlib.backends.backend_agg import RendererAgg
    from matplotlib.font_manager import FontProperties
    renderer, font = RendererAgg(8, 8, 72), FontProperties(size=size)

    def fits(s: str) -> bool:
        return renderer.get_text_width_height_descent(s, font, ismath=False)[0] <= width * 72

    lines: list[str] = []
    for word in text.split():
        if lines and fits(f"{lines[-1]} {word}"):
            lines[-1] += f" {word}"
        else:
            lines.append(word)
    return lines or [""]


def _title_height(lines: list[str], size: float = TITLE_SIZE) -> float:
    """[in] a title of ``lines`` takes, with its margin above."""
    return 0.12 + len(lines) * 1.25 * size / 72


def _title(fig, lines: list[str], size: float = TITLE_SIZE) -> None:
    fig.suptitle("\n".join(lines), y=1 - 0.08 / fig.get_figheight(), va="top", fontsize=size)


def _describe(sol) -> str:
    from .plots import is_equilibrium
    if is_equilibrium(sol):
        return f"stress space eq, {3 * sol.space.n_tri} sub-triangles"
    return f"{sol.triangulation}, {sol.system.n_pieces} pieces"  # summary()["n_pieces"], cheaply


def _maps(sol, draws, title: str, colorbar: bool = True):
    """A figure of maps of the whole bodies side by side, one per ``draws`` entry
    (``draw(ax, cax, side)``, ``cax`` its colour bar's axes or ``None``, ``side`` the most room
    [in] right of the map its zooms may take where no corner of it is empty:
    :func:`cvxdual.outputs.views.add_insets`), under ``title`` (wrapped). The maps are drawn at
    their final size; then the figure is widened by the room their zooms took, each map's colour
    bar moved past them (it serves both)."""
    from matplotlib.figure import Figure

    from .views import bodies_window, side_room
    n = len(draws)
    width = WIDTH if n > 1 else SINGLE
    cb = CB_PAD + CB_W + CB_TEXT if colorbar else 0.25
    pw = (width - n * (LEFT + cb)) / n
    ratio = _ratio(bodies_window(sol))
    height = min(pw * ratio, MAX_H if n > 1 else MAX_H_SINGLE)
    mw = height / ratio  # a tall map is narrowed, by its colour bar
    side = ((WIDE if n > 1 else WIDE_SINGLE) - width) / n
    fig = Figure(figsize=(width, height))
    axes = [(fig.add_axes((0, 0, 1, 1)), fig.add_axes((0, 0, 1, 1), label="<colorbar>") if colorbar else None)
            for _ in draws]
    _place(fig, axes, (pw, mw, height, cb), width, title, [0.0] * n)
    for (ax, cax), draw in zip(axes, draws, strict=True):
        draw(ax, cax, side)
    rooms = [round(side_room(ax) * DPI) / DPI for ax, _ in axes]  # whole pixels: see _place
    _title(fig, _place(fig, axes, (pw, mw, height, cb), width + sum(rooms), title, rooms))
    return fig


def _place(fig, axes, sizes, width: float, title: str, rooms) -> list[str]:
    """Size ``fig`` ``width`` [in] wide and place its maps and colour bars ``axes`` in a row
    (``sizes``: slot, map width, map height, colour bar room [in]), ``rooms`` [in] right of each
    map for its zooms, under ``title``; returns the title's lines."""
    pw, mw, height, cb = sizes
    lines = wrap_title(title, width - 0.3)
    top = _title_height(lines) + AX_TITLE
    fig.set_size_inches(width, top + height + BOTTOM)
    x = LEFT
    for (ax, cax), room in zip(axes, rooms, strict=True):
        # a narrowed map stays by its colour bar (its zooms between), or centred without one
        ax.set_position(_rect(fig, x + (pw - mw if cax is not None else (pw - mw) / 2), top, mw, height))
        if cax is not None:
            cax.set_position(_rect(fig, x + pw + room + CB_PAD, top, CB_W, height))
        x += round((pw + room + cb + LEFT) * DPI) / DPI  # whole pixels apart: the maps share their sampling
    return lines


def _zone_note(sol) -> str:
    """Why the contact zone has no inset, if it has none."""
    from .views import contact_zone, zoom_window
    if zoom_window(sol) is not None:
        return ""
    zone = contact_zone(sol)
    return ("; no contact pairs" if zone is None else
            f"; contact zone {zone[0]:.3g} to {zone[1]:.3g} {sol.scene.units[0]}: no contact inset needed")


def stress_figure(sol):
    """s22 and the maximum shear stress on the whole bodies, with insets on the contact zone
    and on a local peak."""
    from .maps import Measure, plot_stress
    draws = [lambda ax, cax, side, m=m: plot_stress(sol, m, ax=ax, cax=cax, insets=True, side=side)
             for m in (Measure.S22, Measure.SHEAR)]
    return _maps(sol, draws, f"{sol.scene.name}, {sol.mesh_name}, {_describe(sol)}{_zone_note(sol)}")


def von_mises_figure(sol):
    """The von Mises stress on the whole bodies, with insets."""
    from .maps import Measure, plot_stress
    plane = sol.scene.upper.material.plane  # both bodies' (the scene checks)
    s33 = "s33 = nu (s11 + s22)" if plane == "strain" else "s33 = 0"
    return _maps(sol, [lambda ax, cax, side: plot_stress(sol, Measure.VON_MISES, ax=ax, cax=cax, insets=True,
                                                              side=side)],
                 f"{sol.scene.name}, {sol.mesh_name}, {_describe(sol)}: von Mises stress, plane {plane} "
                 f"({s33}){_zone_note(sol)}")


def principal_figure(sol):
    """The in-plane principal stresses on one colour scale, centred at zero."""
    import numpy as np

    from ..voigt import body_factors
    from .maps import Measure, plot_stress, signed_norm, stress_field, stress_support
    field = stress_field(stress_support(sol), sol)
    factors = body_factors(sol.scene)
    norm = signed_norm(np.concatenate([field.values(m, factors).ravel()
                                       for m in (Measure.PRINCIPAL_1, Measure.PRINCIPAL_2)]))
    draws = [lambda ax, cax, side, m=m: plot_stress(sol, m, ax=ax, cax=cax, insets=True, norm=norm, side=side)
             for m in (Measure.PRINCIPAL_1, Measure.PRINCIPAL_2)]
    return _maps(sol, draws, f"{sol.scene.name}, {sol.mesh_name}, {_describe(sol)}: principal stresses, "
                 f"one colour scale{_zone_note(sol)}")


def displacement_figure(sol):
    """|u| and u_y on the undeformed bodies."""
    from .maps import DisplacementComponent, plot_displacement
    from .plots import is_equilibrium
    draws = [lambda ax, cax, _, c=c: plot_displacement(sol, c, ax=ax, cax=cax)
             for c in (DisplacementComponent.MAGNITUDE, DisplacementComponent.UY)]
    what = ("the bounds' admissible displacement v_h (linear on the mesh)" if is_equilibrium(sol)
            else "displacement, linear on the mesh")
    return _maps(sol, draws, f"{sol.scene.name}, {sol.mesh_name}, {_describe(sol)}: {what}, drawn on the "
                 "undeformed bodies")


def mesh_figure(sol):
    """The mesh the stresses live on, with insets on the contact zone and the finest part."""
    from .maps import plot_mesh
    return _maps(sol, [lambda ax, cax, side: plot_mesh(sol, ax=ax, insets=True, side=side)],
                 f"{sol.scene.name}, {sol.mesh_name}, {_describe(sol)}", colorbar=False)


def deformed_figure(sol):
    """The contact zone at true displacement scale, and the gap and approach along it."""
    from matplotlib.figure import Figure

    from .plots import is_equilibrium, plot_deformed, plot_gap
    title = f"{sol.scene.name}, {sol.mesh_name}: the contact zone"
    if is_equilibrium(sol):
        title += ("; stress space eq: the displacement drawn is the bounds' admissible v_h, whose opening "
                  "where the pressure acts is counted in G")
    lines = wrap_title(title, WIDTH - 0.3)
    top = _title_height(lines) + 0.45
    gap, height = 1.0, 3.6
    pw = (WIDTH - LEFT - gap - 0.25) / 2
    fig = Figure(figsize=(WIDTH, top + height + BOTTOM))
    left = fig.add_axes(_rect(fig, LEFT, top, pw, height))
    plot_deformed(sol, ax=left)  # after placing: its vertical stretch fills the axes
    right = fig.add_axes(_rect(fig, LEFT + pw + gap, top, pw, height))
    plot_gap(sol, ax=right, xlim=left.get_xlim())
    _clear_y_labels(fig, [left, right])
    _title(fig, lines)
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
    """Where the certified bound comes from, on the whole bodies; the title names the scene,
    level and stress space and gives ``G`` and the error bound in the scene's units."""
    import numpy as np
    from matplotlib.figure import Figure

    from .plots import is_equilibrium, plot_bound_map
    from .views import bodies_window
    L, S = sol.scene.units
    b = sol.bounds
    cb, ratio = CB_PAD + CB_W + 1.15, _ratio(bodies_window(sol))  # a colour bar label of two lines
    pw = min(8.0 - LEFT - cb, (MAX_H + 1) / ratio)  # a tall map makes a narrower figure
    height = pw * ratio
    width = max(LEFT + pw + cb, 5.5)  # room for the title's lines on the narrowest
    contact = float(b["contributions"]["contact"].sum())
    beyond = float(b["contributions"].get("continuation", np.zeros(0)).sum())
    energy = f"{S}\u00b7{L}\u00b2"
    space = "stress space eq" if is_equilibrium(sol) else f"p0 ({sol.triangulation}) certified against eq"
    title = (f"{sol.scene.name}, {sol.mesh_name}, {space}: G = {b['gap']:.3g} {energy} per unit thickness "
             f"(contact edges {contact:.3g}" + (f", beyond the free arcs {beyond:.3g}" if beyond else "")
             + f"); error bound \u221a(2G) = {b['error_bound']:.3g} \u221a({energy})")
    lines = wrap_title(title, width - 0.3)
    head = _title_height(lines) + 0.4  # and the axes' title
    fig = Figure(figsize=(width, head + height + BOTTOM))
    ax = fig.add_axes(_rect(fig, LEFT, head, pw, height))
    plot_bound_map(sol, ax=ax, cax=fig.add_axes(_rect(fig, LEFT + pw + CB_PAD, head, CB_W, height),
                                                label="<colorbar>"))
    _title(fig, lines)
    return fig


def cycles_figure(sol):
    """A run to a tolerance: the certified error of its cycles against their pieces."""
    from matplotlib.figure import Figure

    from .plots import plot_cycles
    h = sol.adaptive
    fig = Figure(figsize=(6.0, 4.5))
    plot_cycles(h, ax=fig.add_axes(_rect(fig, 0.9, 0.7, 6.0 - 0.9 - 0.25, 4.5 - 0.7 - BOTTOM)))
    _title(fig, wrap_title(f"{sol.scene.name}: {len(h.cycles)} cycles to a certified {100 * h.tol:.3g} %, {h.state}",
                           5.7))
    return fig


BUILDERS = {Plot.STRESS: stress_figure, Plot.DEFORMED: deformed_figure, Plot.PRESSURE: pressure_figure,
            Plot.BOUNDS: bounds_figure, Plot.MESH: mesh_figure, Plot.VONMISES: von_mises_figure,
            Plot.PRINCIPAL: principal_figure, Plot.DISPLACEMENT: displacement_figure, Plot.CYCLES: cycles_figure}


def _applies(sol, p: Plot) -> bool:
    """Whether ``p`` can be drawn of ``sol``: bounds where it has bounds, cycles where it ran to a tolerance."""
    return {Plot.BOUNDS: sol.bounds is not None, Plot.CYCLES: sol.adaptive is not None}.get(p, True)


def figures(sol, plots=DEFAULT_PLOTS) -> dict:
    """The figures ``plots`` (:func:`parse_plots`: names, :class:`Plot` members, ``True`` for
    :data:`DEFAULT_PLOTS`) as :class:`matplotlib.figure.Figure` objects, by file name;
    ``bounds`` only where the solution has bounds, ``cycles`` only for a run to a tolerance."""
    return {p.file: BUILDERS[p](sol) for p in parse_plots(plots) if _applies(sol, p)}
