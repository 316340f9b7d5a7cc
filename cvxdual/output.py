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


def contact_table(sol):
    import pandas as pd
    c = sol.contact
    return pd.DataFrame({"x": c["x"], "gap": c["gap"], "relative_displacement": c["relative_displacement"],
                         "pressure": c["pressure"], "active": c["active"].astype(int),
                         "force": c["force"]})


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
    meshio.write(path, mesh, file_format="vtu")


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
    meshio.write(path, mesh, file_format="vtu")


def figures(sol) -> dict:
    """The standard plots as :class:`matplotlib.figure.Figure` objects, by file name."""
    from matplotlib.figure import Figure

    from .plots import plot_deformed, plot_pressure, plot_stress

    pts = sol.mesh.points
    aspect = min(max(np.ptp(pts[:, 1]) / np.ptp(pts[:, 0]), 0.3), 2.5)
    stress = Figure(figsize=(12.0, 1.0 + 6.0 * aspect * 0.85), layout="constrained")
    for ax, comp in zip(stress.subplots(1, 2), ("s22", "shear"), strict=True):
        plot_stress(sol, comp, ax=ax)
    n = sol.summary()["n_pieces"]
    what = f"stress space eq: {n} sub-triangles" if sol.stress_space == "eq" else f"{sol.triangulation}: {n} pieces"
    stress.suptitle(f"{sol.scene.name}, level {sol.level}, {what}")
    deformed = Figure(figsize=(6.0, 1.0 + 6.0 * aspect * 0.85), layout="constrained")
    plot_deformed(sol, ax=deformed.add_subplot())
    pressure = Figure(figsize=(8, 4.5), layout="constrained")
    plot_pressure(sol, ax=pressure.add_subplot())
    out = {"stress.png": stress, "deformed.png": deformed, "pressure.png": pressure}
    if sol.bounds is not None:
        from .plots import plot_bound_map
        bounds = Figure(figsize=(8.0, 1.0 + 8.0 * aspect * 0.85), layout="constrained")
        plot_bound_map(sol, ax=bounds.add_subplot())
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
        "contact.csv": lambda p: contact_table(sol).to_csv(p, index=False, float_format="%.12g"),
        "solution.vtu": lambda p: write_vtu(sol, p),
    }
    if plots:
        for name, fig in figures(sol).items():  # noqa: B007 - fig is bound in the lambda
            writers[name] = lambda p, fig=fig: fig.savefig(p, dpi=130, format="png")
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
