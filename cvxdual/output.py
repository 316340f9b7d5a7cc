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


def piece_outlines(pieces, n: int = OUTLINE_POINTS) -> list[tuple[np.ndarray, np.ndarray]]:
    """Outlines of the curved pieces, following the face: ``[(piece ids (m,), polygons (m, v, 2))]``,
    one entry per number of slabs (pieces of one entry have the same number of vertices)."""
    from .pieces import slab_bound
    s = pieces.slabs
    if not len(s):
        return []
    order = np.lexsort((s.xl, s.piece))
    counts = np.bincount(s.piece)
    k = max(2, n // 2)
    t = np.linspace(0.0, 1.0, k)
    out = []
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])  # first slab (in `order`) of each piece
    for c in np.unique(counts[counts > 0]):
        ids = np.flatnonzero(counts == c)
        sl = order[start[ids][:, None] + np.arange(c)[None, :]]  # (m, c) slabs left to right
        x = s.xl[sl][..., None] + t * (s.xr - s.xl)[sl][..., None]  # (m, c, k)
        idx = np.broadcast_to(sl[..., None], x.shape)
        lo = slab_bound(s, pieces.faces, x, idx, "lo").reshape(len(ids), -1)
        hi = slab_bound(s, pieces.faces, x, idx, "hi").reshape(len(ids), -1)
        xf = x.reshape(len(ids), -1)
        poly = np.concatenate([np.stack([xf, lo], -1), np.stack([xf, hi], -1)[:, ::-1]], axis=1)
        out.append((ids, poly))
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
    points, pdisp = [pts], [disp]
    base = len(pts)
    for ids, poly in piece_outlines(p):
        m, v = poly.shape[:2]
        xy = poly.reshape(-1, 2)
        points.append(xy)
        pdisp.append(nearest_node_values(sol, xy, np.repeat(p.body[ids], v), disp))
        cells.append(("polygon", base + np.arange(m * v).reshape(m, v)))
        base += m * v
        stress.append(sol.stress[ids])
        kind.append(p.kind[ids].astype(np.int32))
    P = np.concatenate(points)
    D = np.concatenate(pdisp)
    mesh = meshio.Mesh(np.c_[P, np.zeros(len(P))], cells,
                       point_data={"displacement": np.c_[D, np.zeros(len(D))]},
                       cell_data={"stress": stress, "piece_kind": kind})
    meshio.write(path, mesh, file_format="vtu")


def write_outputs(sol, out: str | Path, plots: bool = True) -> list[Path]:
    """Write every output of ``sol`` to directory ``out``; return the paths written.

    All files are written to temporaries first and renamed into place only when every one of
    them succeeded: a failure leaves the previous set of outputs (or none), never a mix."""
    out = prepare_dir(out)
    writers = {
        "summary.json": lambda p: p.write_text(json.dumps(_jsonable(sol.summary()), indent=2) + "\n"),
        "contact.csv": lambda p: contact_table(sol).to_csv(p, index=False, float_format="%.12g"),
        "solution.vtu": lambda p: write_vtu(sol, p),
    }
    if plots:
        from .plots import PLOTS
        writers.update({name: (lambda p, f=f: f(sol, p)) for name, f in PLOTS.items()})
    staged: list[tuple[Path, Path]] = []
    try:
        for name, write in writers.items():
            fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=out)
            os.close(fd)
            staged.append((Path(tmp), out / name))
            write(Path(tmp))
            os.chmod(tmp, 0o666 & ~_UMASK)
        for tmp, final in staged:
            os.replace(tmp, final)
    except Exception as e:  # noqa: BLE001 - any failure: remove the temporaries, keep the old set
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)
        what = e.strerror if isinstance(e, OSError) and e.strerror else f"{type(e).__name__}: {e}"
        raise OutputError(f"cannot write outputs to {str(out)!r} ({what}); nothing was changed there; "
                          "choose a writable --out") from None
    return [final for _, final in staged]
