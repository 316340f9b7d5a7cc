"""``solution.vtu``: the stresses and displacements of a solution as an unstructured grid (meshio)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .locate import nearest_node_values
from .pieces import piece_outlines

# uncompressed: zlib made it 2.4x smaller at 4x the write time (1.55 s against 0.36 s at 5.9e5
# pieces), a quarter of a whole level-6 run
VTU_COMPRESSION = None


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


