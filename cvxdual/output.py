"""Writing results: ``summary.json``, ``contact.csv``, ``solution.vtu`` and plots.

Every file is written atomically (to a temporary file in the same directory, then renamed),
so a crash leaves the old file or none, never half a file.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import OutputError

OUTLINE_POINTS = 12  # vertices of the polygon drawn for each curved piece
_UMASK = os.umask(0)
os.umask(_UMASK)


def nearest_node_values(sol, xy: np.ndarray, body: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` of the nearest mesh node *of the same body* for points ``xy`` (the faces of
    the two bodies share coordinates, so the body must be chosen first)."""
    from scipy.spatial import cKDTree
    out = np.zeros((len(xy),) + values.shape[1:])
    for k, bm in enumerate(sol.mesh.bodies):
        m = body == k
        if np.any(m):
            ids = bm.offset + np.arange(bm.n_nodes)
            out[m] = values[ids[cKDTree(sol.mesh.points[ids]).query(xy[m])[1]]]
    return out


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path next to ``path``; on success rename it to ``path``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    return obj


def atomic_write_json(path: str | Path, data: dict) -> None:
    atomic_write_text(path, json.dumps(_jsonable(data), indent=2) + "\n")


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
        fd, probe = tempfile.mkstemp(prefix=".probe", dir=out)
        os.close(fd)
        os.unlink(probe)
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


def piece_outlines(pieces, n: int = OUTLINE_POINTS) -> list[np.ndarray]:
    """Outline polygon of every curved piece (the union of its slabs), following the face."""
    s = pieces.slabs
    out: list[np.ndarray] = []
    if not len(s):
        return out
    order = np.argsort(s.piece, kind="stable")
    pid = s.piece[order]
    starts = np.flatnonzero(np.r_[True, pid[1:] != pid[:-1]])
    ends = np.r_[starts[1:], len(pid)]
    k = max(2, n // 2)
    for a, b in zip(starts, ends):
        idx = order[a:b]
        idx = idx[np.argsort(s.xl[idx])]
        xs = np.concatenate([np.linspace(s.xl[i], s.xr[i], k) for i in idx])
        ii = np.concatenate([np.full(k, i) for i in idx])
        lo = pieces._bound(xs, ii, "lo")
        hi = pieces._bound(xs, ii, "hi")
        out.append(np.concatenate([np.stack([xs, lo], 1), np.stack([xs, hi], 1)[::-1]]))
    return out


def write_vtu(sol, path: str | Path) -> None:
    """Straight pieces as ``triangle`` cells on the mesh vertices; curved pieces as ``polygon``
    cells (extra points along the face, displacement interpolated from the nearest vertex)."""
    import meshio
    p = sol.system.pieces
    pts = sol.mesh.points
    disp = sol.displacement
    tri = np.flatnonzero(p.kind == 0)
    cells = [("triangle", p.nodes[tri])]
    stress = [sol.stress[tri]]
    kind = [p.kind[tri].astype(np.int32)]
    curved = np.flatnonzero(p.kind != 0)
    points, pdisp = [pts], [disp]
    if len(curved):
        outlines = piece_outlines(p)
        pid = np.unique(p.slabs.piece)
        by_size: dict[int, list[int]] = {}
        for j, o in enumerate(outlines):
            by_size.setdefault(len(o), []).append(j)
        base = len(pts)
        for size, js in by_size.items():
            poly = np.concatenate([outlines[j] for j in js])
            ids = base + np.arange(len(poly)).reshape(len(js), size)
            base += len(poly)
            points.append(poly)
            pdisp.append(nearest_node_values(sol, poly, np.repeat(p.body[pid[js]], size), disp))
            cells.append(("polygon", ids))
            stress.append(sol.stress[pid[js]])
            kind.append(p.kind[pid[js]].astype(np.int32))
    P = np.concatenate(points)
    D = np.concatenate(pdisp)
    mesh = meshio.Mesh(np.c_[P, np.zeros(len(P))], cells,
                       point_data={"displacement": np.c_[D, np.zeros(len(D))]},
                       cell_data={"stress": stress, "piece_kind": kind})
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu")


def write_outputs(sol, out: str | Path, plots: bool = True) -> list[Path]:
    """Write every output of ``sol`` to directory ``out``; return the paths written."""
    out = prepare_dir(out)
    written = []
    try:
        atomic_write_json(out / "summary.json", sol.summary())
        written.append(out / "summary.json")
        with atomic_path(out / "contact.csv") as tmp:
            contact_table(sol).to_csv(tmp, index=False, float_format="%.12g")
        written.append(out / "contact.csv")
        write_vtu(sol, out / "solution.vtu")
        written.append(out / "solution.vtu")
        if plots:
            from .plots import plot_all
            written += plot_all(sol, out)
    except OSError as e:
        raise OutputError(f"cannot write outputs to {str(out)!r} ({e.strerror or e}); choose a writable --out") from None
    return written
