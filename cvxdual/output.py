"""Writing results: ``summary.json``, ``contact.csv``, ``solution.vtu`` and plots, as one set.

Files are staged beside their final names and renamed into place only when every one was
written (see :func:`write_outputs`), through the helpers of :mod:`cvxdual.files`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import OutputError
from .files import json_text, temp_beside
from .locate import nearest_node_values
from .pieces import piece_outlines


def check_writable(out: str | Path) -> Path:
    """Check, without creating anything, that directory ``out`` can be created and written."""
    out = Path(out)
    p = out
    while not p.exists():
        if p.parent == p:
            break
        p = p.parent
    if p.exists() and not p.is_dir():
        raise OutputError(f"cannot write to output directory {str(out)!r}: {str(p)!r} is not a directory; "
                          "choose another --out")
    if not os.access(p, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write to output directory {str(out)!r}: {str(p)!r} is not writable; "
                          "choose another --out")
    return out


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
    """Write every output of ``sol`` to directory ``out``; return the paths written.

    All files are written to temporaries first and renamed into place only when every one of
    them succeeded: a failure leaves the previous set of outputs (or none), never a mix."""
    out = prepare_dir(out)
    writers = {
        "summary.json": lambda p: p.write_text(json_text(sol.summary())),
        "contact.csv": lambda p: contact_table(sol).to_csv(p, index=False, float_format="%.12g"),
        "solution.vtu": lambda p: write_vtu(sol, p),
    }
    if plots:
        for name, fig in figures(sol).items():  # noqa: B007 - fig is bound in the lambda
            writers[name] = lambda p, fig=fig: fig.savefig(p, dpi=130, format="png")
    staged: list[tuple[Path, Path]] = []
    try:
        for name, write in writers.items():
            staged.append((temp_beside(out / name), out / name))
            write(staged[-1][0])
        for tmp, final in staged:
            os.replace(tmp, final)
    except Exception as e:  # noqa: BLE001 - any failure: remove the temporaries, keep the old set
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)
        what = e.strerror if isinstance(e, OSError) and e.strerror else f"{type(e).__name__}: {e}"
        raise OutputError(f"cannot write outputs to {str(out)!r} ({what}); nothing was changed there; "
                          "choose a writable --out") from None
    return [final for _, final in staged]

