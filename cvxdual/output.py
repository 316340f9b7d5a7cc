"""Writing results: ``summary.json``, ``contact.csv``, ``solution.vtu`` and plots, as one set.

The output directory holds one set and is replaced whole (:func:`write_outputs`): the set is
written into a hidden staging directory beside it and swapped in atomically by
:func:`cvxdual.files.replace_dir`, so it is always the previous set or the new one, never a mix,
and files of an earlier set that the new one lacks (plots after ``--no-plots``) are gone.
Because the directory is replaced, a directory holding anything else is refused
(:func:`check_output_dir`), and so are the filesystem root, the current and the home directory.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .errors import OutputError
from .files import json_text, replace_dir, staged_dir, temp_beside
from .locate import nearest_node_values
from .pieces import piece_outlines
from .validate import short

# solution.vtu uncompressed: zlib made it 2.4x smaller at 4x the write time (1.55 s against 0.36 s
# at 5.9e5 pieces), a quarter of a whole level-6 run; PNGs with fast compression (files 20-35%
# larger, half the compression time)
VTU_COMPRESSION = None
PNG_OPTIONS = {"compress_level": 1}
SET_FILES = ("summary.json", "contact.csv", "solution.vtu", "stress.png", "deformed.png", "pressure.png",
             "bounds.png")
# per-file temporaries of earlier versions (files.temp_beside), removed with the set they are in
_OLD_TEMP = re.compile(r"\.(" + "|".join(re.escape(n) for n in (*SET_FILES, "probe")) + r")\.[^/]+\.tmp")


def check_writable(out: str | Path, what: str = "output directory", option: str = "--out") -> Path:
    """Check, without creating anything, that directory ``out`` can be created and written."""
    out = Path(out)
    p = out
    while not p.exists():
        if p.parent == p:
            break
        p = p.parent
    if p.exists() and not p.is_dir():
        raise OutputError(f"cannot write to {what} {str(out)!r}: {str(p)!r} is not a directory; "
                          f"choose another {option}")
    if not os.access(p, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write to {what} {str(out)!r}: {str(p)!r} is not writable; "
                          f"choose another {option}")
    return out


def foreign_entries(out: str | Path) -> list[str]:
    """The entries of directory ``out`` that are not files of an output set (directories end in '/')."""
    bad = []
    for e in os.scandir(out):
        if not ((e.name in SET_FILES or _OLD_TEMP.fullmatch(e.name)) and e.is_file(follow_symlinks=False)):
            bad.append(e.name + ("/" if e.is_dir(follow_symlinks=False) else ""))
    return sorted(bad)


def _check_owned(out: Path, shown: str) -> None:
    bad = foreign_entries(out)
    if bad:
        names = [short(b, 30) for b in bad[:3]]
        more = f" and {len(bad) - 3} more" if len(bad) > 3 else ""
        raise OutputError(f"refusing to write outputs to {shown!r}: it holds {', '.join(names)}{more}, not written "
                          "by cvxdual, and the output directory is replaced whole; nothing was changed there; "
                          "choose an empty or cvxdual-written --out")


def check_output_dir(out: str | Path) -> Path:
    """Check, creating nothing, that ``out`` can take an output set (:func:`write_outputs`): a new
    or empty directory or one holding an output set only, writable, with a writable parent, and
    not the filesystem root, the current directory (or above it) or the home directory. Returns
    the real path (symbolic links resolved): the directory that will be replaced."""
    check_writable(out)
    shown = str(out)
    real = Path(out).resolve()
    try:
        home = Path.home().resolve()
    except RuntimeError:  # no home directory known
        home = None
    special = ("the filesystem root" if real == Path(real.anchor) else
               "the current directory or above it" if Path.cwd().resolve().is_relative_to(real) else
               "the home directory" if real == home else None)
    if special:
        raise OutputError(f"refusing to write outputs to {shown!r}: it is {special}, and the output directory is "
                          "replaced whole; choose an empty or cvxdual-written --out")
    if real.exists():
        if not os.access(real.parent, os.W_OK | os.X_OK):
            raise OutputError(f"cannot replace output directory {shown!r}: its parent {str(real.parent)!r} is not "
                              "writable; choose another --out")
        _check_owned(real, shown)
    return real


def prepare_dir(out: str | Path) -> Path:
    """Create ``out`` (and parents) and check it is writable."""
    out = check_writable(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        temp_beside(out / "probe").unlink()
    except OSError as e:
        raise OutputError(f"cannot write to output directory {str(out)!r} ({e.strerror or e}); "
                          "choose a writable --out") from None
    return out


# tangential_force: x force of the upper body on the lower one at each pair (0 where undefined);
# slip: relative tangential displacement u''_x - u'_x; stick: 1 where the pair sticks
CONTACT_COLUMNS = ("x", "gap", "relative_displacement", "pressure", "active", "force", "tangential_force", "slip",
                   "stick")
FLAG_COLUMNS = ("active", "stick")  # booleans, written as 0/1


def _contact_columns(sol) -> dict:
    """``sol.contact``'s arrays for :data:`CONTACT_COLUMNS`, flags as integers. A missing column is
    an error, never filled in: a made-up 0 would read as a computed result."""
    c = sol.contact
    missing = [k for k in CONTACT_COLUMNS if k not in c]
    if missing:
        raise KeyError(f"the solution's contact data lacks {', '.join(missing)} (columns of contact.csv)")
    return {k: np.asarray(c[k]).astype(int) if k in FLAG_COLUMNS else c[k] for k in CONTACT_COLUMNS}


def contact_table(sol):
    """The contact pairs as a pandas DataFrame (the columns of ``contact.csv``)."""
    import pandas as pd
    return pd.DataFrame(_contact_columns(sol))


def write_contact_csv(sol, path) -> None:
    """``contact.csv``, one row per pair (written without pandas: it costs 0.2 s to import)."""
    cols = np.column_stack(list(_contact_columns(sol).values())).astype(float)
    fmt = ["%d" if k in FLAG_COLUMNS else "%.12g" for k in CONTACT_COLUMNS]
    np.savetxt(path, cols, fmt=fmt, delimiter=",", header=",".join(CONTACT_COLUMNS), comments="")


def _write_eq_vtu(sol, path) -> None:
    """Equilibrium stresses: every sub-triangle a cell with its own vertices (discontinuous),
    point data the linear stresses, so equilibrium can be checked from the file alone."""
    import meshio

    from .bounds import vtu_cells
    c = vtu_cells(sol.space, sol.stress)
    tri = sol.mesh.triangles()
    v = sol.displacement
    # the P1 displacement at the sub-triangle vertices (X_i, X_i+1, centroid), in cell order
    corner = np.stack([v[tri], np.roll(v[tri], -1, axis=1), np.broadcast_to(v[tri].mean(axis=1)[:, None],
                                                                            (len(tri), 3, 2))], axis=2)
    s = c["point_stress"]
    cell = {"body": [c["cell_body"].astype(np.int32)]}
    if sol.bounds is not None:
        cell["bound_contribution"] = [sol.bounds["contributions"]["sub"].ravel()]
    point = {"s11": s[:, 0], "s22": s[:, 1], "s12": s[:, 2], "stress": s,
             "displacement": np.c_[corner.reshape(-1, 2), np.zeros(len(s))]}
    mesh = meshio.Mesh(np.c_[c["points"], np.zeros(len(s))], [("triangle", c["cells"])], point_data=point,
                       cell_data=cell)
    meshio.write(path, mesh, file_format="vtu", compression=VTU_COMPRESSION)


def write_vtu(sol, path: str | Path) -> None:
    """Straight pieces as ``triangle`` cells on the mesh vertices; curved pieces as ``polygon``
    cells (extra points along the face, displacement interpolated from the nearest vertex).
    Equilibrium stresses: see :func:`_write_eq_vtu`."""
    if sol.stress_space == "eq":
        return _write_eq_vtu(sol, path)
    import meshio
    p = sol.system.pieces
    pts = sol.mesh.points
    disp = sol.displacement
    tri = np.flatnonzero(p.kind == 0)
    cells = [("triangle", p.nodes[tri])]
    stress = [sol.stress[tri]]
    kind = [p.kind[tri].astype(np.int32)]
    points, pdisp = [pts], [disp]
    base = len(pts)
    for ids, poly in piece_outlines(p):
        m, v = poly.shape[:2]
        xy = poly.reshape(-1, 2)
        points.append(xy)
        pdisp.append(nearest_node_values(sol.mesh, xy, np.repeat(p.body[ids], v), disp))
        cells.append(("polygon", base + np.arange(m * v).reshape(m, v)))
        base += m * v
        stress.append(sol.stress[ids])
        kind.append(p.kind[ids].astype(np.int32))
    P = np.concatenate(points)
    D = np.concatenate(pdisp)
    cell = {"stress": stress, "piece_kind": kind}
    if sol.bounds is not None:  # flat faces only: the pieces are the mesh triangles, in order
        cell["bound_contribution"] = [sol.bounds["contributions"]["element"][tri]]
    mesh = meshio.Mesh(np.c_[P, np.zeros(len(P))], cells, point_data={"displacement": np.c_[D, np.zeros(len(D))]},
                       cell_data=cell)
    meshio.write(path, mesh, file_format="vtu", compression=VTU_COMPRESSION)


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


def write_outputs(sol, out: str | Path, plots: bool = True) -> list[Path]:
    """Write every output of ``sol`` as the set in directory ``out``; return the paths written.

    The set replaces ``out`` whole (see the module docstring): any failure leaves the previous
    set (or none), never a mix, and the error says so."""
    out = Path(out)
    real = check_output_dir(out)
    writers = {
        "summary.json": lambda p: p.write_text(json_text(sol.summary())),
        "contact.csv": lambda p: write_contact_csv(sol, p),
        "solution.vtu": lambda p: write_vtu(sol, p),
    }
    if plots:
        for name, fig in figures(sol).items():  # noqa: B007 - fig is bound in the lambda
            writers[name] = lambda p, fig=fig: fig.savefig(p, dpi=130, format="png", pil_kwargs=PNG_OPTIONS)
    assert set(writers) <= set(SET_FILES)
    try:
        real.parent.mkdir(parents=True, exist_ok=True)
        with staged_dir(real) as stage:
            for name, write in writers.items():
                write(stage / name)
            replace_dir(stage, real, check=lambda d: _check_owned(d, str(out)))
    except OutputError:
        raise  # says itself what was changed
    except Exception as e:  # noqa: BLE001 - any failure before the swap: the staging directory is gone
        what = e.strerror if isinstance(e, OSError) and e.strerror else f"{type(e).__name__}: {e}"
        raise OutputError(f"cannot write outputs to {str(out)!r} ({what}); nothing was changed in {str(out)!r}; "
                          "choose a writable --out") from None
    return [out / name for name in writers]
