"""``solution.vtu``: the stresses and displacements of a solution, and its contact face, as one
unstructured grid (meshio, VTK XML, uncompressed binary).

Cells (in this order):

* the stress pieces. Stress space ``p0``: the straight pieces as ``triangle`` cells on the mesh
  vertices, in piece order, then the curved pieces as ``polygon`` cells (extra points along the
  face), grouped by outline size as :func:`cvxdual.geometry.pieces.piece_outlines` lists them. Stress
  space ``eq``: every sub-triangle a ``triangle`` cell with its own three vertices (the stress
  is linear on it and discontinuous between cells).
* the contact face: one ``line`` cell per contact pair, in pair order, so line cell ``i`` is row
  ``i`` of ``contact.csv``. It spans the pair's tributary interval on the lower body's face,
  from the midpoint with the previous pair to the midpoint with the next (the first and last
  from their own pair), so the lines cover the candidate contact interval once and their
  lengths in ``x`` are the tributary widths ``w_k`` of the pressures. Their end points lie on
  the lower face ``y = f''(x)``; they are extra points.

Cell data (a VTU array has a value on every cell, so each is filled where it does not apply):

* ``piece_kind`` (int): the piece kind, an index into :data:`cvxdual.geometry.pieces.PIECE_KINDS` (0
  triangle, 1 segment, 2 concave1, 3 concave2; 0 for the sub-triangles of ``eq``), **-1 on the
  contact line cells**. In ParaView, *Threshold* on ``piece_kind >= 0`` keeps the bodies,
  ``piece_kind = -1`` the contact face (or *Extract Cells By Type* on lines).
* ``body`` (int): index of the body (``scene.bodies``: 0 upper, 1 lower); the lower body on
  the line cells.
* ``p0`` only: ``s11``, ``s22``, ``s12`` (Voigt stress components, constant per piece),
  ``von_mises``, ``principal_1``, ``principal_2`` (in-plane principal stresses,
  ``principal_1 >= principal_2``), and ``stress`` (the three components as one vector, kept for
  older readers); all NaN on the line cells.
* ``bound_contribution`` (where bounds were computed): the certified bound's contribution of
  each cell, NaN on the line cells.
* the contact data, the columns of ``contact.csv`` (:meth:`cvxdual.Solution.contact_columns`):
  ``pressure``, ``gap`` (initial gap), ``relative_normal`` (the faces' normal approach, the
  ``relative_displacement`` column: ``gap - relative_normal >= 0``), and with friction
  ``tangential_force`` and ``slip``; float, **NaN on the area cells**. ``active`` (int, 0/1 on
  the line cells) is **-1 on the area cells** (an integer has no NaN).

Point data:

* ``displacement`` (3 components, z = 0). Curved-piece outline points take the nearest mesh
  node of their body; the line points the lower face nodes' displacement linearly interpolated
  along the face (the P1 field on the face edge). ``eq`` with the P2 kinematic side: on the
  sub-triangle cells, the P2 displacement of the bounds at the cell's vertices, and its values
  at the midpoints of the cell's edges ``(X_i, X_i+1)``, ``(X_i+1, c)``, ``(c, X_i)`` as the cell
  array ``displacement_midpoints`` (6 components: x, y at each; NaN on the other cells): the
  quadratic on every cell, so ``J(v)``, the strains and the contact jumps of the certificate are
  reproducible from the file: on a segment of a convex face the displacement is its chord's cell's
  quadratic continued beyond the chord, on a type-2 tangent polygon's slab the trace of its edge's
  cell continued along y; the line points interpolate the vertex values linearly. Not in the file:
  the P2 side's elements ``A, B, C`` of type 1's concave pieces (the certificate's ``v`` there; the
  slab polygon cells hold the stress).
* ``eq`` only: ``s11``, ``s22``, ``s12``, ``stress`` (the components, exactly linear on each
  cell), ``von_mises``, ``principal_1``, ``principal_2`` (of the vertex values; a viewer
  interpolates them linearly, they are not linear themselves). On the line points: the lower
  body's face stress, linear along its face edges (the trace from the lower side; at a mesh
  vertex the stress jumps between cells, and one adjacent face edge's value is taken).

Von Mises uses ``s33`` (:func:`cvxdual.voigt.von_mises`): ``nu (s11 + s22)`` in plane
strain, 0 in plane stress. A body given by a Hooke matrix alone (no ``nu``) in plane strain has
no ``s33``: its ``von_mises`` is NaN (the principal stresses are in-plane and always written).
"""

from __future__ import annotations

from functools import singledispatch
from pathlib import Path

import numpy as np

from ..eq.columns import column_at
from ..eq.fields import EquilibriumField
from ..geometry.locate import nearest_node_values
from ..geometry.pieces import piece_outlines, slab_outlines
from ..system.field import PieceField
from ..voigt import body_factors, shear_stress, von_mises

# uncompressed: zlib makes it 2.1x smaller at 7x the write time (hertz level 6, 5.9e5 pieces:
# 66 MB in 1.74 s against 135 MB in 0.25 s), a large part of a whole level-6 run
VTU_COMPRESSION = None
LINE_KIND = -1  # piece_kind of the contact line cells
INT_FILL = -1  # integer cell arrays where they do not apply (active on the area cells)


def stress_measures(stress: np.ndarray, factor: np.ndarray) -> dict:
    """The named stress arrays of Voigt stresses ``(n, 3)``: components, von Mises (``s33 =
    factor (s11 + s22)``) and in-plane principal stresses ``c +- r`` (centre ``c``, radius ``r``
    of Mohr's circle)."""
    s = np.asarray(stress, float)
    c = 0.5 * (s[:, 0] + s[:, 1])
    r = shear_stress(s)
    with np.errstate(invalid="ignore"):  # a NaN factor gives a NaN von Mises, as documented
        vm = von_mises(s, factor)
    return {"s11": s[:, 0], "s22": s[:, 1], "s12": s[:, 2], "von_mises": vm, "principal_1": c + r,
            "principal_2": c - r}


def _face_interp(x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Values ``v`` at the pairs ``x``, at the line points: the ends and the midpoints."""
    return np.concatenate([v[:1], 0.5 * (v[:-1] + v[1:]), v[-1:]])


def contact_lines(sol) -> dict:
    """The contact line cells: ``points (n + 1, 2)`` on the lower face, ``cells (n, 2)`` (local
    point indices), ``displacement (n + 1, 2)`` and the contact ``data`` of the ``n`` pairs."""
    mesh, scene = sol.mesh, sol.scene
    x = mesh.pair_x
    xe = _face_interp(x, x)
    lower = scene.bodies.index(scene.lower)
    n = len(x)
    col = sol.contact_columns()
    data = {"pressure": col["pressure"].astype(float), "gap": col["gap"].astype(float),
            "relative_normal": col["relative_displacement"].astype(float),
            "active": col["active"].astype(np.int32)}
    if scene.friction is not None:
        data["tangential_force"] = col["tangential_force"].astype(float)
        data["slip"] = col["slip"].astype(float)
    return {"points": np.c_[xe, scene.bodies[lower].face.value(xe)],
            "cells": np.c_[np.arange(n), np.arange(1, n + 1)],
            "displacement": _face_interp(x, sol.displacement[mesh.pairs[:, 1]]),
            "data": data, "body": lower}


def _fill(like: np.ndarray, n: int) -> np.ndarray:
    """``n`` values of the dtype and width of ``like`` meaning "does not apply": NaN or -1."""
    value = INT_FILL if np.issubdtype(like.dtype, np.integer) else np.nan
    return np.full((n,) + like.shape[1:], value, dtype=like.dtype)


def _write(path, points, disp, point, blocks, cell, lines) -> None:
    """Write the area ``blocks`` ``[(type, cells)]`` with ``cell`` data (one array per block)
    and the contact ``lines``; the line points are appended after ``points``, so ``point`` data
    (besides the displacement) must cover both."""
    import meshio
    n_lines = len(lines["cells"])
    sizes = [len(c) for _, c in blocks]
    base = len(points)
    cells = [*blocks, ("line", base + lines["cells"])]
    data = {k: [*v, _fill(v[0], n_lines)] for k, v in cell.items()}
    data["piece_kind"][-1][:] = LINE_KIND
    data["body"][-1][:] = lines["body"]
    for k, v in lines["data"].items():
        data[k] = [_fill(v, m) for m in sizes] + [v]
    P = np.concatenate([points, lines["points"]])
    D = np.concatenate([disp, lines["displacement"]])
    pdata = {"displacement": np.c_[D, np.zeros(len(D))], **point}
    mesh = meshio.Mesh(np.c_[P, np.zeros(len(P))], cells, point_data=pdata, cell_data=data)
    meshio.write(path, mesh, file_format="vtu", compression=VTU_COMPRESSION)


def _lower_face_stress(P: np.ndarray, s: np.ndarray, lower: int, cell_body: np.ndarray, face, xe: np.ndarray,
                       tol: float) -> np.ndarray:
    """Discontinuous P1 stresses ``s`` at the points ``P`` (three per cell, in cell order) at
    abscissae ``xe`` of the lower face: linear along the lower body's cell edges on the face."""
    cells = np.arange(len(P)).reshape(-1, 3)[cell_body == lower]
    a, b = cells[:, 0], cells[:, 1]  # (X_i, X_i+1): the macro-triangle edge; the third is the centroid
    on = (np.abs(P[a, 1] - face.value(P[a, 0])) <= tol) & (np.abs(P[b, 1] - face.value(P[b, 0])) <= tol)
    a, b = a[on], b[on]
    a, b = np.where(P[a, 0] <= P[b, 0], a, b), np.where(P[a, 0] <= P[b, 0], b, a)
    if not len(a):  # a curved face: the column stresses give its trace (see _write_eq_vtu)
        return np.zeros((len(xe), 3))
    order = np.argsort(P[a, 0], kind="stable")
    a, b = a[order], b[order]
    k = np.clip(np.searchsorted(P[a, 0], xe, side="right") - 1, 0, len(a) - 1)
    t = np.clip((xe - P[a[k], 0]) / (P[b[k], 0] - P[a[k], 0]), 0.0, 1.0)[:, None]
    return (1 - t) * s[a[k]] + t * s[b[k]]


def _eq_cells(space, sigma: np.ndarray) -> dict:
    """Discontinuous P1 output: ``points (3 n_sub, 2)`` (each sub-triangle its own vertices),
    ``cells (n_sub, 3)``, ``point_stress (3 n_sub, 3)`` Voigt, ``cell_body`` and ``cell_triangle``."""
    n_sub = 3 * space.n_tri
    return {"points": space.sub_points().reshape(-1, 2), "cells": np.arange(3 * n_sub).reshape(n_sub, 3),
            "point_stress": np.asarray(sigma, float).reshape(-1, 3), "cell_body": np.repeat(space.body, 3),
            "cell_triangle": np.repeat(np.arange(space.n_tri), 3)}


def column_stress_at(space, g: np.ndarray, body: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The column field's vertical stress at abscissae ``x`` of ``body``'s face, and which ``x``
    lie under a column (elsewhere the value is 0)."""
    faces = space.faces
    cols = space.columns[faces.body[space.columns] == body]
    g_b = g[faces.body[space.columns] == body]
    if not len(cols):
        return np.zeros(len(x)), np.zeros(len(x), bool)
    x0, x1 = faces.x[cols, 0], faces.x[cols, 1]
    i = np.clip(np.searchsorted(x0, x, side="right") - 1, 0, len(cols) - 1)
    inside = (x >= x0[i]) & (x <= x1[i])
    t = (x - x0[i]) / (x1[i] - x0[i])
    return np.where(inside, g_b[i, 0] * (1 - t) + g_b[i, 1] * t, 0.0), inside


def _column_cells(sol) -> dict:
    """The columns of the curved pieces: every slab a ``polygon`` cell with its own points, the
    stress ``(0, g(x), 0)`` at them (linear in x, constant in y), the displacement of ``V_h`` (its
    face edge's value extended along y), the slab's piece kind and body."""
    space = sol.space
    pieces = space.pieces
    s = pieces.slabs
    poly = slab_outlines(pieces)
    m, k = poly.shape[:2]
    gx = column_at(space, sol.column_stress, None, poly.reshape(-1, 2), np.repeat(np.arange(m), k))[0].reshape(m, k)
    stress = np.stack([np.zeros_like(gx), gx, np.zeros_like(gx)], -1)
    a, b = s.edge_nodes.T
    xa, xb = sol.mesh.points[a, 0][:, None], sol.mesh.points[b, 0][:, None]
    te = ((poly[..., 0] - xa) / (xb - xa))[..., None]
    v = sol.displacement
    disp = v[a][:, None, :] * (1 - te) + v[b][:, None, :] * te
    return {"points": poly.reshape(-1, 2), "cells": np.arange(m * k).reshape(m, k),
            "point_stress": stress.reshape(-1, 3), "displacement": disp.reshape(-1, 2),
            "cell_body": s.body.astype(np.int32), "cell_kind": pieces.kind[s.piece].astype(np.int32)}


def _write_eq_vtu(sol, path) -> None:
    """Equilibrium stresses: every sub-triangle a cell with its own vertices (discontinuous),
    then every slab of the curved pieces a polygon cell with its column stress, point data the
    stresses (linear on each cell), so admissibility can be checked from the file alone."""
    c = _eq_cells(sol.space, sol.stress)
    tri = sol.space.tri
    v = sol.displacement
    p2 = sol.bounds is not None and sol.bounds["kinematic"] == "p2"
    if p2:  # the P2 displacement at the sub-triangle vertices, its midpoint values as cell data
        sv = sol.bounds["displacement"].sub_values()  # (n_T, 3, 6, 2)
        corner = sv[:, :, :3]
    else:  # the P1 displacement at the sub-triangle vertices (X_i, X_i+1, centroid), in cell order
        corner = np.stack([v[tri], np.roll(v[tri], -1, axis=1), np.broadcast_to(v[tri].mean(axis=1)[:, None],
                                                                                (len(tri), 3, 2))], axis=2)
    lines = contact_lines(sol)
    cb = c["cell_body"]
    face = sol.scene.bodies[lines["body"]].face
    xe = lines["points"][:, 0]
    # face points are computed coordinates (rounding only); other vertices are a layer away
    s_line = _lower_face_stress(c["points"], c["point_stress"], lines["body"], cb, face, xe,
                                1e-9 * sol.scene.length_scale)
    gx, under = column_stress_at(sol.space, sol.column_stress, lines["body"], xe)
    s_line[under] = np.stack([np.zeros(int(under.sum())), gx[under], np.zeros(int(under.sum()))], 1)
    blocks = [("triangle", c["cells"])]
    points, disp, s, pbody = [c["points"]], [corner.reshape(-1, 2)], [c["point_stress"]], [np.repeat(cb, 3)]
    cell = {"piece_kind": [np.zeros(len(cb), np.int32)], "body": [cb.astype(np.int32)]}
    if sol.bounds is not None:
        cell["bound_contribution"] = [sol.bounds["contributions"]["sub"].ravel()]
    if p2:
        cell["displacement_midpoints"] = [np.ascontiguousarray(sv[:, :, 3:].reshape(-1, 6))]
    if len(sol.space.pieces.slabs):
        col = _column_cells(sol)
        k = col["cells"].shape[1]
        blocks.append(("polygon", len(c["points"]) + col["cells"]))
        points.append(col["points"]), disp.append(col["displacement"]), s.append(col["point_stress"])
        pbody.append(np.repeat(col["cell_body"], k))
        cell["piece_kind"].append(col["cell_kind"]), cell["body"].append(col["cell_body"])
        if sol.bounds is not None:
            cell["bound_contribution"].append(sol.bounds["contributions"]["column"])
        if p2:  # a slab's displacement is its face edge's trace, continued along y
            cell["displacement_midpoints"].append(np.full((len(col["cells"]), 6), np.nan))
    s = np.concatenate([*s, s_line])
    pbody = np.concatenate([*pbody, np.full(len(s_line), lines["body"])])
    # point data on the cells' points and then the line points (the order _write puts them in)
    point = {k: np.ascontiguousarray(val)
             for k, val in {**stress_measures(s, body_factors(sol.scene)[pbody]), "stress": s}.items()}
    _write(path, np.concatenate(points), np.concatenate(disp), point, blocks, cell, lines)


def write_vtu(sol, path: str | Path) -> None:
    """``solution.vtu`` of ``sol``: the arrays of the module docstring, by the kind of its stress field."""
    _write_field(sol.field, sol, path)


@singledispatch
def _write_field(field, sol, path) -> None:
    raise TypeError(f"no solution.vtu for a {type(field).__name__}")


@_write_field.register(EquilibriumField)
def _(field, sol, path) -> None:
    _write_eq_vtu(sol, path)


@_write_field.register(PieceField)
def _(field, sol, path) -> None:
    """P0: every straight piece a triangle cell, every curved one a polygon, values per cell."""
    p = sol.system.pieces
    pts = sol.mesh.points
    disp = sol.displacement
    tri = np.flatnonzero(p.kind == 0)
    blocks = [("triangle", p.nodes[tri])]
    ids = [tri]
    points, pdisp = [pts], [disp]
    base = len(pts)
    for pid, poly in piece_outlines(p):
        m, v = poly.shape[:2]
        xy = poly.reshape(-1, 2)
        points.append(xy)
        pdisp.append(nearest_node_values(sol.mesh, xy, np.repeat(p.body[pid], v), disp))
        blocks.append(("polygon", base + np.arange(m * v).reshape(m, v)))
        base += m * v
        ids.append(pid)
    # one gather into cell order (no copy when all pieces are straight), then views per block
    order = ids[0] if len(ids) == 1 else np.concatenate(ids)
    identity = len(order) == len(p) and np.array_equal(order, np.arange(len(p)))
    take = (lambda a: a) if identity else (lambda a: a[order])  # noqa: E731
    stress = take(sol.stress)
    body = take(p.body).astype(np.int32)
    per = {**stress_measures(stress, body_factors(sol.scene)[body]), "stress": stress, "body": body,
           "piece_kind": take(p.kind).astype(np.int32)}
    if sol.bounds is not None:  # the straight pieces are the macro triangles, in order; curved ones sum their slabs
        c = sol.bounds["contributions"]
        curved = np.bincount(p.slabs.piece, weights=c["column"], minlength=len(p))[len(c["element"]):]
        per["bound_contribution"] = take(np.concatenate([c["element"], curved]))
    split = np.cumsum([len(i) for i in ids])[:-1]
    cell = {k: np.split(np.ascontiguousarray(v), split) for k, v in per.items()}
    _write(path, np.concatenate(points), np.concatenate(pdisp), {}, blocks, cell, contact_lines(sol))
