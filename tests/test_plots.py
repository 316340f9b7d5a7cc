"""The standard figures read as a paper's would: every axis labelled with its unit, no text off
the figure or on another tick label, a zoom that shows the contact zone, a deformed view that
cannot show the bodies overlapping, and fills without moire. Cheap solves (levels 0-2, fast path).
"""

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

import cvxdual
from cvxdual.outputs.figures import figures
from cvxdual.outputs.plots import Triangles, contact_zone
from cvxdual.solution import TOLERANCES

REPORTS = Path(__file__).resolve().parents[1] / "reports"
UNIT = re.compile(r"\[[^\]]+\]")
# the roller: a light load makes a contact zone about 1/40 of the plot's width
LIGHT = [{"bodies": {"block": {"boundary": {"push": {"traction": {"kind": "uniform", "value": [0.0, 8.0]}}}}}}]
CASES = {  # id: scene, level, stress space
    "hertz": ("hertz", 1, "p0"), "hertz-eq": ("hertz", 1, "eq"), "blocks-eq": ("blocks", 1, "eq"),
    "roller": ("light roller", 2, "p0"), "cylinder-on-block": ("cylinder-on-block", 1, "p0"),
    "groove": ("cylinder-in-groove", 1, "p0"), "wavy": ("wavy", 1, "p0"), "patch": ("patch", 0, "p0"),
}
_SOLVED: dict = {}


def solved(case: str):
    """The solution of ``case`` and its figures drawn on Agg canvases (once per session)."""
    if case not in _SOLVED:
        scene, level, space = CASES[case]
        scene = cvxdual.load_scene("cylinder-on-block", LIGHT) if scene == "light roller" else scene
        sol = cvxdual.solve(scene, level=level, solver="fast", stress_space=space)
        figs = figures(sol)
        for fig in figs.values():
            FigureCanvasAgg(fig).draw()
        _SOLVED[case] = sol, figs
    return _SOLVED[case]


def _is_colorbar(ax) -> bool:
    return ax.get_label() == "<colorbar>"


def _drawn_tick_labels(axis) -> list[Text]:
    """The tick labels drawn on ``axis`` (its tick objects beyond the current ones keep stale text)."""
    lo, hi = sorted(axis.get_view_interval())
    pad = 1e-9 * (hi - lo)  # a tick exactly on a limit is drawn
    out = []
    for locs, ticks in ((axis.get_majorticklocs(), axis.get_major_ticks), (axis.get_minorticklocs(),
                                                                           axis.get_minor_ticks)):
        out += [t.label1 for t in ticks(len(locs)) if lo - pad <= t.get_loc() <= hi + pad
                and t.label1.get_visible() and t.label1.get_text().strip()]
    return out


def _texts(fig) -> list[Text]:
    """Every text drawn on ``fig``: titles, labels, legends, notes and the tick labels drawn."""
    ticks = {id(t) for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)
             for tick in axis.get_major_ticks() + axis.get_minor_ticks() for t in (tick.label1, tick.label2)}
    out = [t for t in fig.findobj(Text) if id(t) not in ticks and t.get_visible() and t.get_text().strip()]
    return out + [t for ax in fig.axes for axis in (ax.xaxis, ax.yaxis) for t in _drawn_tick_labels(axis)]


def _overlapping_ticks(fig) -> list[str]:
    renderer = fig.canvas.get_renderer()
    bad = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            labels = _drawn_tick_labels(axis)
            # shrunk by half a pixel: neighbouring extents may share their rounded edge pixel
            boxes = [t.get_window_extent(renderer).padded(-0.5) for t in labels]
            bad += [f"{ax.get_title() or ax.get_label()}: {a.get_text()!r} on {b.get_text()!r}"
                    for i, (a, p) in enumerate(zip(labels, boxes, strict=True))
                    for b, q in zip(labels[i + 1:], boxes[i + 1:], strict=True) if p.overlaps(q)]
    return bad


@pytest.mark.parametrize("case", CASES)
def test_every_axis_labelled_with_its_unit(case):
    sol, figs = solved(case)
    assert {"stress.png", "deformed.png", "pressure.png"} <= set(figs)
    assert ("bounds.png" in figs) == (sol.bounds is not None)
    for name, fig in figs.items():
        for ax in fig.axes:
            if _is_colorbar(ax):  # labelled along its bar only
                labels = [ax.get_ylabel() if ax.yaxis.get_visible() and ax.get_ylabel() else ax.get_xlabel()]
            else:
                labels = [ax.get_xlabel(), ax.get_ylabel()]
            for label in labels:
                assert UNIT.search(label), f"{name}, axes {ax.get_title()!r}: label {label!r} has no [unit]"


@pytest.mark.parametrize("case", CASES)
def test_no_text_leaves_the_figure(case):
    _, figs = solved(case)
    for name, fig in figs.items():
        renderer = fig.canvas.get_renderer()
        frame = fig.bbox.padded(1.0)  # one pixel: extents are rounded outwards to whole pixels
        for t in _texts(fig):
            box = t.get_window_extent(renderer)
            assert frame.containsx(box.x0) and frame.containsx(box.x1) and frame.containsy(box.y0) \
                and frame.containsy(box.y1), f"{name}: {t.get_text()!r} at {box.bounds} leaves {fig.bbox.bounds}"


@pytest.mark.parametrize("case", CASES)
def test_tick_labels_do_not_overlap(case):
    _, figs = solved(case)
    for name, fig in figs.items():
        assert not _overlapping_ticks(fig), name


@pytest.mark.parametrize("case", CASES)
def test_texts_do_not_overlap(case):
    """No title, label, tick label or legend entry on another: a colour bar's labels stay off
    the next map's, a long tick label off its axis label."""
    _, figs = solved(case)
    for name, fig in figs.items():
        renderer = fig.canvas.get_renderer()
        texts = _texts(fig)
        boxes = [t.get_window_extent(renderer).padded(-0.5) for t in texts]  # as in _overlapping_ticks
        bad = [f"{a.get_text()!r} on {b.get_text()!r}" for i, (a, p) in enumerate(zip(texts, boxes, strict=True))
               for b, q in zip(texts[i + 1:], boxes[i + 1:], strict=True) if p.overlaps(q)]
        assert not bad, name


@pytest.mark.parametrize("case", ["hertz", "roller", "hertz-eq"])
def test_zoom_shows_the_contact_zone(case):
    sol, figs = solved(case)
    a, b = contact_zone(sol)
    assert sol.contact["x_min"] is not None  # the zone is the active pairs', not the candidates'
    axes = [ax for ax in figs["stress.png"].axes if not _is_colorbar(ax)]
    zooms = [ax for ax in axes if ax.get_label() == "zoom"]
    whole = [ax for ax in axes if ax.get_label() != "zoom"]
    assert len(zooms) == len(whole) == 2  # s22 and maximum shear, each whole and zoomed
    for z, w in zip(zooms, whole, strict=True):
        (x0, x1), (y0, y1) = z.get_xlim(), z.get_ylim()
        assert x0 <= a and b <= x1
        assert y0 < sol.scene.bodies[1].face.value((a + b) / 2) < y1  # the interface is in view
        # much narrower: the zone and half its width each side (hertz: a half model, its zone a
        # sixth of the width; the roller's a fortieth, under five pair spacings at level 2)
        assert x1 - x0 <= 0.3 * np.diff(w.get_xlim())[0]
        assert z.get_aspect() == 1.0  # lengths as they are
        if b - a > 0:
            assert b - a >= 0.4 * (x1 - x0)  # the zone fills the zoom, not a corner of it


@pytest.mark.parametrize("case", CASES)
def test_deformed_view_never_shows_interpenetration(case):
    """The faces drawn are apart (or touching) at every x in view, and their distance at the
    contact pairs is the solution's own opening ``gap - relative_displacement``."""
    sol, figs = solved(case)
    ax = next(ax for ax in figs["deformed.png"].axes if ax.get_title().startswith("faces"))
    faces = {ln.get_gid(): (ln.get_xdata(), ln.get_ydata()) for ln in ax.lines if ln.get_gid()}
    (xu, yu), (xl, yl) = faces["deformed face 0"], faces["deformed face 1"]
    x0, x1 = ax.get_xlim()
    x = np.union1d(xu, xl)
    x = x[(x >= x0) & (x <= x1) & (x >= max(xu[0], xl[0])) & (x <= min(xu[-1], xl[-1]))]
    gap = np.interp(x, xu, yu) - np.interp(x, xl, yl)  # both faces are polylines: exact between vertices
    # the penetration the solver may leave (relative to the scene's displacements), far below a pixel
    tol = TOLERANCES["penetration"] * np.diff(ax.get_ylim())[0]
    assert len(x) and gap.min() >= -tol
    c = sol.contact
    at = (c["x"] >= x0) & (c["x"] <= x1)
    drawn = np.interp(c["x"][at], xu, yu) - np.interp(c["x"][at], xl, yl)
    opening = c["gap"][at] - c["relative_displacement"][at]
    assert np.allclose(drawn, opening, rtol=0, atol=1e-9 * np.abs(c["gap"]).max(initial=1.0))  # rounding
    stretch = float(re.search(r"vertical x([0-9.e+]+)", ax.get_ylabel()).group(1))
    assert ax.get_aspect() == pytest.approx(stretch)  # the stretch stated is the one drawn


def test_fill_is_an_area_average_without_moire():
    """Pieces far below a pixel (a checkerboard of black and white triangles 0.37 px across,
    incommensurate with the pixels, listed first halves then second halves as the meshes list
    them) are drawn as their area average, mid-grey: not the colour under each pixel's centre,
    nor the one drawn last, nor a beat pattern between the pieces and the pixels."""
    n = 270
    g = np.linspace(0.0, 1.0, n + 1)
    p = np.stack(np.meshgrid(g, g, indexing="ij"), -1)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 2), np.stack([a, c, d], -2).reshape(-1, 3, 2)])
    fig = Figure(figsize=(1.0, 1.0), dpi=96)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_axis_off()
    ax.add_collection(Triangles(tris, array=np.r_[np.zeros(n * n), np.ones(n * n)], cmap="gray"), autolim=False)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    grey = np.asarray(canvas.buffer_rgba())[:, :, 0].astype(float)
    # sampled, not painted in order: the mean within 1% of the range (the last drawn, white,
    # took 99% of it when Agg filled these pieces itself)
    assert abs(grey.mean() - 127.5) <= 2.55
    # seen from afar (4 x 4 px blocks, 144 samples each), uniform to a fifth of the range,
    # where one sample per pixel (or a beat between pieces and pixels) swings black to white
    blocks = grey.reshape(24, 4, 24, 4).mean(axis=(1, 3))
    assert np.abs(blocks - 127.5).max() <= 255 / 5


def test_report_plots_have_units_and_no_overlapping_ticks():
    """The convergence report's plots, redrawn from the committed table, over their four
    decades of time and two of h."""
    from cvxdual.study.report import error_figure
    df = pd.read_csv(REPORTS / "convergence.csv")
    for x in ("h", "t_total"):
        fig = error_figure(df, x)
        FigureCanvasAgg(fig).draw()
        assert not _overlapping_ticks(fig), x
        assert all(UNIT.search(ax.get_xlabel()) and UNIT.search(ax.get_ylabel()) for ax in fig.axes)


def test_speed_plot_draws_memory_only_where_measured(tmp_path):
    from run_study import SPECS  # studies/, on the path by conftest.py

    from cvxdual.study.spec import load_module
    speed = load_module(SPECS / "speed.py")
    _paths, _plots = speed._paths, speed._plots
    from PIL import Image
    d = _paths(pd.read_csv(REPORTS / "speed.csv"))
    scan, pareto = d[d.part == "scan"], d[d.part == "pareto"]
    _plots(scan, pareto, tmp_path)
    with_memory = Image.open(tmp_path / "speed_scaling.png").size
    _plots(scan.assign(peak_mb=np.nan), pareto, tmp_path)  # as a run that measured no memory
    assert Image.open(tmp_path / "speed_scaling.png").size[0] < with_memory[0]  # two panels, not three
