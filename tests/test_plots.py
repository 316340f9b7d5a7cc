"""The figures read as a paper's would: every axis labelled with its unit, no text off the
figure or on another tick label, a zoom inset that shows the contact zone and one that shows a
hole's stress concentration, signed fields centred at zero, the von Mises the models cap, a
deformed view that cannot show the bodies overlapping, fills without moire; figures chosen by
name, and a short repr of a solution. Cheap solves (levels 0-2, fast path).
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
from cvxdual.outputs.maps import plot_stress
from cvxdual.outputs.render import Triangles
from cvxdual.outputs.views import COVER_MAX, bodies_window, contact_zone
from cvxdual.solution import TOLERANCES

ALL_FIGURES = {"stress.png", "deformed.png", "pressure.png", "mesh.png", "vonmises.png", "principal.png",
               "displacement.png"}  # and bounds.png where the solution has bounds

REPORTS = Path(__file__).resolve().parents[1] / "reports"
UNIT = re.compile(r"\[[^\]]+\]")
# the roller: a light load makes a contact zone about 1/40 of the plot's width
LIGHT = [{"bodies": {"block": {"boundary": {"push": {"traction": {"kind": "uniform", "value": [0.0, 8.0]}}}}}}]
CASES = {  # id: scene, level, stress space
    "hertz": ("hertz", 1, "p0"), "hertz-eq": ("hertz", 1, "eq"), "blocks-eq": ("blocks", 1, "eq"),
    "roller": ("light roller", 2, "p0"), "cylinder-on-block": ("cylinder-on-block", 1, "p0"),
    "groove": ("cylinder-in-groove", 1, "p0"), "wavy": ("wavy", 1, "p0"), "patch": ("patch", 0, "p0"),
    "hole": ("block-with-hole", 1, "p0"), "hole-eq": ("block-with-hole", 1, "eq"),
    "patch-1": ("patch", 1, "p0"), "patch-eq": ("patch", 1, "eq"), "punch-eq": ("rounded-punch", 1, "eq"),
    # a part whose bodies fill the map: no corner is empty, the zooms go beside the maps
    "punch-on-block": (str(Path(__file__).resolve().parents[1] / "examples" / "punch-on-block.toml"), 1, "p0"),
}
_SOLVED: dict = {}


def solved(case: str):
    """The solution of ``case`` and all its figures drawn on Agg canvases (once per session)."""
    if case not in _SOLVED:
        scene, level, space = CASES[case]
        scene = cvxdual.load_scene("cylinder-on-block", LIGHT) if scene == "light roller" else scene
        sol = cvxdual.solve(scene, level=level, solver="fast", stress_space=space)
        figs = figures(sol, "all")
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


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
def test_every_axis_labelled_with_its_unit(case):
    sol, figs = solved(case)
    assert set(figs) - {"bounds.png"} == ALL_FIGURES
    assert ("bounds.png" in figs) == (sol.bounds is not None)
    for name, fig in figs.items():
        for ax in fig.axes:
            if _is_colorbar(ax):  # labelled along its bar only
                labels = [ax.get_ylabel() if ax.yaxis.get_visible() and ax.get_ylabel() else ax.get_xlabel()]
            else:
                labels = [ax.get_xlabel(), ax.get_ylabel()]
            for label in labels:
                assert UNIT.search(label), f"{name}, axes {ax.get_title()!r}: label {label!r} has no [unit]"


@pytest.mark.slow  # 25 s over its 17 scenes: the quick tier draws every figure kind elsewhere
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


def _insets(fig, label: str) -> list[tuple]:
    """``(zoom, map)``: the zooms labelled ``label`` of the maps of ``fig`` (insets in a corner
    or axes beside the map: children of the map either way)."""
    return [(c, ax) for ax in fig.axes if not _is_colorbar(ax) for c in ax.child_axes if c.get_label() == label]


def _is_inset(zoom, ax, renderer) -> bool:
    """Whether ``zoom`` lies on its map ``ax`` (an inset), to a pixel (extents are rounded
    outwards to whole pixels), rather than beside it."""
    box = ax.get_window_extent(renderer).padded(1.0)
    z = zoom.get_window_extent(renderer)
    return box.contains(*z.p0) and box.contains(*z.p1)


def _body_cover(sol, ax, zoom, renderer, n: int = 60) -> float:
    """Share of the rectangle ``zoom`` takes on its map ``ax`` (from their drawn positions)
    inside the mesh's triangles: an ``n`` x ``n`` grid of points located by matplotlib's
    trapezoid map, one per body (their faces share points), independent of the outlines
    :mod:`cvxdual.outputs.views` measures with."""
    from matplotlib.tri import Triangulation
    z = zoom.get_window_extent(renderer)
    (x0, y0), (x1, y1) = ax.transData.inverted().transform([z.p0, z.p1])
    g = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(x0 + g * (x1 - x0), y0 + g * (y1 - y0))
    tri, body = sol.mesh.triangles(), sol.mesh.triangle_body()
    inside = np.zeros(X.size, bool)
    for k in np.unique(body):
        used, t = np.unique(tri[body == k], return_inverse=True)
        p = sol.mesh.points[used]
        inside |= Triangulation(p[:, 0], p[:, 1], t.reshape(-1, 3)).get_trifinder()(X.ravel(), Y.ravel()) >= 0
    return float(inside.mean())


@pytest.mark.parametrize("case", ["hertz", "roller", "hertz-eq", "punch-eq"])
def test_zoom_shows_the_contact_zone(case):
    sol, figs = solved(case)
    a, b = contact_zone(sol)
    assert sol.contact["x_min"] is not None  # the zone is the active pairs', not the candidates'
    pairs = _insets(figs["stress.png"], "zoom")
    assert len(pairs) == 2  # s22 and maximum shear, each whole with the contact zone as an inset
    for z, w in pairs:
        (x0, x1), (y0, y1) = z.get_xlim(), z.get_ylim()
        assert x0 <= a and b <= x1
        assert y0 < sol.scene.bodies[1].face.value((a + b) / 2) < y1  # the interface is in view
        # much narrower: the zone and half its width each side (hertz: a half model, its zone a
        # sixth of the width; the roller's a fortieth, under five pair spacings at level 2)
        assert x1 - x0 <= 0.3 * np.diff(w.get_xlim())[0]
        assert z.get_aspect() == 1.0  # lengths as they are
        if b - a > 0:
            assert b - a >= 0.4 * (x1 - x0)  # the zone fills the zoom, not a corner of it
        assert w.get_xlim() == bodies_window(sol)[:2] and w.get_ylim() == bodies_window(sol)[2:]  # the whole pair
        renderer = figs["stress.png"].canvas.get_renderer()
        if _is_inset(z, w, renderer):  # in a corner that hides (almost) none of the bodies
            assert _body_cover(sol, w, z, renderer) < COVER_MAX
        else:  # beside its map, right of it, within the figure
            zb, wb = z.get_window_extent(renderer), w.get_window_extent(renderer)
            assert zb.x0 >= wb.x1 - 1 and zb.y1 <= wb.y1 + 1 and figs["stress.png"].bbox.padded(1.0).contains(*zb.p1)


def test_zooms_never_hide_the_bodies():
    """punch-on-block: the bodies fill the map, so every corner inset would paste the zoom's
    picture over the part (it covered the punch's left half). Each map still zooms on the
    contact zone; a zoom on a map covers under COVER_MAX of its rectangle with body, measured
    from the drawn positions against the mesh; one beside the map is clear of it and of its
    colour bar, which is the map's and the zoom's (one norm)."""
    sol, figs = solved("punch-on-block")
    for name in ("stress.png", "vonmises.png", "principal.png", "mesh.png"):
        fig = figs[name]
        renderer = fig.canvas.get_renderer()
        maps = _maps(fig)
        assert len(_insets(fig, "zoom")) == len(maps) >= 1, name  # each map zooms on the contact zone
        bars = [ax for ax in fig.axes if _is_colorbar(ax)]
        for z, ax in _insets(fig, "zoom") + _insets(fig, "peak"):
            if _is_inset(z, ax, renderer):
                assert _body_cover(sol, ax, z, renderer) < COVER_MAX, name
                continue
            zb = z.get_window_extent(renderer)
            assert zb.x0 >= ax.get_window_extent(renderer).x1, name  # beside the map, not on it
            assert fig.bbox.padded(1.0).contains(*zb.p0) and fig.bbox.padded(1.0).contains(*zb.p1), name
            assert not any(zb.overlaps(a.get_window_extent(renderer)) for a in maps + bars if a is not ax), name
            if name != "mesh.png":
                assert _field(z).norm is _field(ax).norm, name
    # this part leaves no corner empty: the contact zone's zoom is beside the map
    (z, ax), _ = _insets(figs["stress.png"], "zoom")
    assert not _is_inset(z, ax, figs["stress.png"].canvas.get_renderer())


def test_zoom_takes_an_empty_corner():
    """A map with room around the bodies (the view three times as wide) takes the contact
    zone's zoom as an inset in a corner, where it hides (almost) none of the bodies."""
    sol, _ = solved("punch-on-block")
    x0, x1, y0, y1 = bodies_window(sol)
    w, h = x1 - x0, y1 - y0
    fig = Figure(figsize=(8.0, 4.0))
    ax = fig.add_axes((0.1, 0.1, 0.7, 0.8))
    plot_stress(sol, "s22", ax=ax, cax=fig.add_axes((0.85, 0.1, 0.03, 0.8)), insets=True,
                window=(x0 - w, x1 + w, y0 - h, y1 + h))
    FigureCanvasAgg(fig).draw()
    renderer = fig.canvas.get_renderer()
    (z,) = [c for c in ax.child_axes if c.get_label() == "zoom"]
    assert _is_inset(z, ax, renderer) and _body_cover(sol, ax, z, renderer) < COVER_MAX


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


@pytest.mark.slow
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


# -- figures chosen by name, maps, insets, colour scales, bounds titles, repr (issue 39) --------------------


def _maps(fig) -> list:
    """The maps of ``fig``: its axes that are not colour bars (their zooms are children)."""
    return [ax for ax in fig.axes if not _is_colorbar(ax)]


def _field(ax) -> Triangles:
    (coll,) = [c for c in ax.collections if isinstance(c, Triangles)]
    return coll


@pytest.mark.slow
@pytest.mark.parametrize("case", ["hole", "hole-eq", "patch-1", "patch-eq"])
def test_every_named_figure_is_written(case, tmp_path):
    """``plots="all"`` writes every figure (bounds.png where there are bounds), each a PNG; a
    list writes those only."""
    sol, _ = solved(case)
    written = {p.name for p in cvxdual.write_outputs(sol, tmp_path / "all", plots="all")}
    want = ALL_FIGURES | ({"bounds.png"} if sol.bounds is not None else set())
    assert want <= written
    for name in want:
        assert (tmp_path / "all" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    some = {p.name for p in cvxdual.write_outputs(sol, tmp_path / "some", plots="mesh, vonmises")}
    assert {n for n in some if n.endswith(".png")} == {"mesh.png", "vonmises.png"}


@pytest.mark.parametrize("case", ["hole", "hole-eq", "patch-1", "patch-eq", "punch-eq"])
def test_von_mises_drawn_is_the_models(case):
    """The von Mises map draws :func:`cvxdual.voigt.von_mises` (the numpy twin of the models'
    ``von_mises()``, the one a cap constrains) of the solution's stresses: per piece (p0) or at
    every sub-triangle vertex (eq), in the order of the pieces and sub-triangles."""
    from cvxdual.voigt import body_factors, von_mises
    sol, figs = solved(case)
    (ax,) = _maps(figs["vonmises.png"])
    drawn = np.asarray(_field(ax).get_array())
    factors = body_factors(sol.scene)
    if sol.stress_space == "eq":
        space = sol.space
        want = von_mises(sol.stress.reshape(-1, 3), factors[np.repeat(space.body, 9)])  # 3 sub x 3 vertices
    else:
        p = sol.pieces
        assert not len(p.slabs)  # flat faces: every piece a straight triangle, drawn in tri_vertices' order
        want = von_mises(sol.stress, factors[p.body])[p.tri_piece]
    assert len(drawn) >= len(want)  # the column strips of curved pieces follow the sub-triangles
    # the same arithmetic on the same numbers: equal to the last bits
    np.testing.assert_allclose(drawn[:len(want)], want, rtol=1e-13, atol=0)
    assert drawn.min() >= 0 and _field(ax).norm.vmin == 0  # a magnitude: a sequential scale from zero
    if case.startswith("patch"):  # constant stress (0, -100, 0) MPa in plane strain, nu 0.3 and 0.2
        nu = factors[np.repeat(sol.space.body, 9)] if sol.stress_space == "eq" else factors[sol.pieces.body][
            sol.pieces.tri_piece]
        exact = 100 * np.sqrt(1 - nu + nu**2)  # sqrt(((s1-s2)^2 + (s2-s3)^2 + (s3-s1)^2)/2), s3 = -100 nu
        np.testing.assert_allclose(drawn[:len(want)], exact, rtol=1e-6)  # the solver's tolerance on the stress


@pytest.mark.parametrize("case", ["hole", "hole-eq", "hertz", "punch-eq", "patch-eq"])
def test_signed_fields_are_centred_at_zero(case):
    """s22 and the principal stresses on a diverging map whose norm is centred at zero (white)
    with symmetric limits; the maximum shear on a sequential one from zero. The insets share
    their map's colours."""
    from matplotlib.colors import CenteredNorm
    _, figs = solved(case)
    s22, shear = _maps(figs["stress.png"])
    for ax in (s22, *_maps(figs["principal.png"])):
        norm = _field(ax).norm
        assert isinstance(norm, CenteredNorm) and norm.vcenter == 0 and norm.vmax > 0 and norm.vmin == -norm.vmax
        assert _field(ax).get_cmap().name.startswith("RdBu_r")
        for inset in ax.child_axes:
            assert _field(inset).norm is norm
    assert _field(shear).norm.vmin == 0 and not isinstance(_field(shear).norm, CenteredNorm)
    p1, p2 = _maps(figs["principal.png"])
    assert _field(p1).norm is _field(p2).norm  # one colour scale for both


def test_the_hole_is_zoomed_and_its_concentration_visible():
    """block-with-hole: the whole pair, and an inset on the hole (the contact zone spans the
    block: no contact inset) where s22 reaches about -3q (Kirsch; q = 100 MPa) at its sides."""
    sol, figs = solved("hole")
    s22, _ = _maps(figs["stress.png"])
    (peak,) = [c for c in s22.child_axes if c.get_label() == "peak"]
    assert not [c for c in s22.child_axes if c.get_label() == "zoom"]
    (x0, x1), (y0, y1) = peak.get_xlim(), peak.get_ylim()
    assert x0 < -0.5 and 0.5 < x1 and y0 < -10 < y1  # the hole (radius 0.5 at (0, -10)) is in view
    assert x1 - x0 < 0.25 * np.diff(s22.get_xlim())[0]  # and magnified four times or more
    v = np.asarray(_field(peak).get_array())
    # level 1 P0 resolves 3q to within a fifth (-305 MPa at level 3)
    assert v.min() < -0.8 * 300 and v.min() == np.asarray(_field(s22).get_array()).min()


@pytest.mark.parametrize("case", ["hertz-eq", "blocks-eq", "punch-eq", "hole-eq", "hertz"])
def test_deformed_marks_exactly_the_active_pairs_off_the_curves(case):
    """The gap panel marks the pairs of the contact mask ``sol.contact["active"]`` and no
    other, in a row below every curve: with eq stresses the approach drawn is the bounds' v_h,
    open by a slack where the pressure acts, so a mark on the curve would show an active pair
    open."""
    sol, figs = solved(case)
    ax = next(ax for ax in figs["deformed.png"].axes if ax.get_title().startswith("gap"))
    (marks,) = [ln for ln in ax.lines if ln.get_gid() == "active pairs"]
    c = sol.contact
    x0, x1 = ax.get_xlim()
    view = (c["x"] >= x0) & (c["x"] <= x1)
    shown = np.asarray(marks.get_xdata())
    assert set(shown) == set(c["x"][view & c["active"]])
    assert len(shown) and set(shown) <= set(c["x"][c["active"]])  # no open pair of the mask is marked
    # the marks sit in axes coordinates below the lowest curve
    y0, y1 = ax.get_ylim()
    lowest = (min(np.min(ln.get_ydata()) for ln in ax.lines if ln is not marks) - y0) / (y1 - y0)
    assert marks.get_transform() == ax.get_xaxis_transform() and max(marks.get_ydata()) < lowest


@pytest.mark.slow
@pytest.mark.parametrize("scene", sorted(__import__("cvxdual.scene.scenefile", fromlist=["x"]).builtin_scenes()))
def test_bounds_title_inside_the_figure_on_every_builtin_scene(scene):
    """bounds.png names the scene and level and gives G in the scene's energy units (S L^2 per
    unit thickness); its title is wrapped to the figure on the narrowest scenes (it was clipped on
    rounded-punch); the log colour range spans the few decades that hold the data."""
    from cvxdual.outputs.figures import bounds_figure
    sol = cvxdual.solve(scene, level=0, solver="fast", stress_space="eq")
    fig = bounds_figure(sol)
    FigureCanvasAgg(fig).draw()
    renderer = fig.canvas.get_renderer()
    L, S = sol.scene.units
    title = fig._suptitle.get_text().replace("\n", " ")
    assert sol.scene.name in title and f"level {sol.level}" in title
    assert f"G = {sol.bounds['gap']:.3g} {S}\u00b7{L}\u00b2" in title
    frame = fig.bbox.padded(1.0)  # one pixel: extents are rounded outwards to whole pixels
    for t in _texts(fig):
        box = t.get_window_extent(renderer)
        assert frame.containsx(box.x0) and frame.containsx(box.x1) and frame.containsy(box.y0) \
            and frame.containsy(box.y1), f"{t.get_text()!r} at {box.bounds} leaves {fig.bbox.bounds}"
    (ax,) = _maps(fig)
    norm = _field(ax).norm
    decades = np.log10(norm.vmax / norm.vmin)
    assert 2 - 1e-9 <= decades <= 5 + 1e-9  # BOUND_DECADES; the rounding of log10
    assert f"top {decades:.2g} decades" in next(a for a in fig.axes if _is_colorbar(a)).get_ylabel()


def test_unknown_figure_name_is_one_error_line_and_nothing_written(tmp_path, capsys):
    from cvxdual.cli import main
    from cvxdual.errors import UnknownPlotError
    from cvxdual.outputs.figures import Plot, parse_plots
    with pytest.raises(UnknownPlotError, match="valid names: stress, deformed, pressure, bounds, mesh, vonmises"):
        parse_plots("stress,strain")
    assert parse_plots(True) == (Plot.STRESS, Plot.DEFORMED, Plot.PRESSURE, Plot.BOUNDS, Plot.CYCLES)
    assert parse_plots(" Mesh,stress,mesh") == (Plot.MESH, Plot.STRESS)
    assert parse_plots(None) == parse_plots(False) == parse_plots(()) == ()
    with pytest.raises(UnknownPlotError, match="no figure named"):
        parse_plots(",")
    out = tmp_path / "o"
    assert main(["solve", "--scene", "patch", "--level", "0", "--solver", "fast", "--out", str(out),
                 "--plots", "stress,strain"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cvxdual: error: --plots: unknown figure 'strain'")
    assert all(p.value in err[0] for p in Plot)
    assert not out.exists()
    # bounds asked for by name where none are computed: refused before solving
    assert main(["solve", "--scene", "patch", "--level", "0", "--solver", "fast", "--out", str(out),
                 "--plots", "bounds"]) == 1
    assert "--bounds or --stress-space eq" in capsys.readouterr().err and not out.exists()


def test_plots_flag_alone_keeps_the_default_set(tmp_path, capsys):
    from cvxdual.cli import main
    out = tmp_path / "o"
    assert main(["solve", "--scene", "patch", "--level", "0", "--solver", "fast", "--out", str(out), "--plots"]) == 0
    assert {p.name for p in out.glob("*.png")} == {"stress.png", "deformed.png", "pressure.png"}
    assert main(["solve", "--scene", "patch", "--level", "0", "--solver", "fast", "--out", str(out),
                 "--plots", "displacement", "--quiet"]) == 0
    assert {p.name for p in out.glob("*.png")} == {"displacement.png"}


@pytest.mark.parametrize("case", ["hole", "hole-eq"])
def test_solution_repr_is_short(case):
    import dataclasses
    sol, _ = solved(case)
    text = repr(sol)
    assert len(text) < 500 and len(text.splitlines()) <= 4
    assert all(w in text for w in (sol.scene.name, sol.stress_space, sol.triangulation, f"level {sol.level}",
                                   sol.solver.solver, sol.solver.status))
    assert ("G = " in text) == (sol.bounds is not None)
    other = dataclasses.replace(sol, level=9)  # replace still works, and the repr follows
    assert other.level == 9 and "level 9" in repr(other) and other.stress is sol.stress
