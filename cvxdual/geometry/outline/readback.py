"""gmsh's mesh read back into the body's numbering (:class:`RestMesh`), refined once first at level
``L >= 1``. Since the sizes halve a level, level ``L >= 1`` is gmsh's mesh at the sizes of level
``L - 1`` refined once (:mod:`~cvxdual.geometry.refine`): gmsh gets every other node of the chain
and of each fixed polygon (a free arc's, a spline's) as two-node lines, and refinement puts the
other nodes on them (a hole's tangent corners on its chords, the arcs' vertices on the circle),
so the refined mesh conforms to the strip of level ``L`` and keeps every polygon of level ``L``;
the strip's sides stay whole. gmsh makes a quarter of the triangles: 0.22 s instead of 0.73 s for
block-with-hole's lower body at level 4 (86k triangles). The mesh's nodes on the chain become
the strip's inner nodes, its others follow the strip's ``2 n_columns``, and every outline part
gets its node chain in path order."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import MeshError
from ..refine import refine
from ..triangles import doubled_areas
from .arcs import continuation, match_rows
from .build import OutlineBuild


@dataclass(frozen=True)
class RestMesh:
    """The gmsh part of an outline body's mesh, in the body's local node numbering (strip node
    ``(i, j)`` is ``2 i + j``, gmsh's own nodes follow from ``2 n_columns``): ``points`` the new
    nodes, ``triangles`` counter-clockwise, ``parts`` every outline part's nodes in path order."""

    points: np.ndarray
    triangles: np.ndarray
    parts: dict
    virtual_nodes: np.ndarray  # (m, 3): the P1 function continued beyond a free arc (build.OutlineBuild.free_arc)
    virtual_weight: np.ndarray  # (m,): the area it covers
    virtual_arc: np.ndarray  # (m, 3): the arc (cx, cy, r) that bounds it (a quadrature on the exact piece)
    virtual_ends: np.ndarray  # (m, 2): its nodes at the ends of that arc


def read_back(build: OutlineBuild) -> tuple[np.ndarray, np.ndarray, dict]:
    """gmsh's nodes ``xy``, triangles (rows of ``xy``) and the node rows along every curve of a
    part or of gmsh's arcs (``{curve: rows}``, in the curve's direction)."""
    mesh = build.gmsh.model.mesh
    tags, xyz, _ = mesh.getNodes()
    xy = xyz.reshape(-1, 3)[:, :2]
    row = np.full(int(tags.max()) + 1, -1)
    row[tags] = np.arange(len(tags))  # gmsh's node tag -> its row of xy
    _, tri_nodes = mesh.getElementsByType(2)
    tris = row[np.asarray(tri_nodes, np.int64).reshape(-1, 3)]
    wanted = sorted({c for cs in build.part_curves.values() for c in cs if not isinstance(c, tuple)}
                    | set(build.arc_of))
    two = set(build.fixed)  # two-node lines: their ends found by coordinates, gmsh asked only for the others
    ends = match_rows(np.concatenate([build.shape[c][0] for c in wanted if c in two] or [np.zeros((0, 2))]), xy)
    curve_nodes = dict(zip([c for c in wanted if c in two], ends.reshape(-1, 2), strict=True))
    for c in (c for c in wanted if c not in two):
        _, en = mesh.getElementsByType(1, c)
        curve_nodes[c] = row[_ordered(np.asarray(en, np.int64).reshape(-1, 2), c)]
    if np.any(tris < 0) or not len(tris):
        raise MeshError(f"gmsh gave no usable mesh of body {build.body.name!r}")  # pragma: no cover - gmsh contract
    return xy, tris, curve_nodes


def refined(build: OutlineBuild, xy, tris, curve_nodes) -> tuple[np.ndarray, np.ndarray, dict]:
    """gmsh's mesh at the sizes of the level below, refined once (:mod:`~cvxdual.geometry.refine`):
    the two-node lines' new nodes at the fine polygon's vertices (``mids``; ``None`` keeps the
    line whole), the new nodes of gmsh's arcs on the arc; every curve's node path refined too."""
    mids = build.mids
    lines = list(mids)
    ends = match_rows(np.concatenate([build.shape[c][0] for c in lines]), xy).reshape(-1, 2)  # by coordinates
    keep = np.array([mids[c] is None for c in lines])
    whole, moved = ends[keep], list(ends[~keep])
    to = [mids[c] for c in lines if mids[c] is not None]
    for c, (centre, r) in build.arc_of.items():
        ns = curve_nodes[c]
        mid = 0.5 * (xy[ns[:-1]] + xy[ns[1:]]) - centre
        moved += list(zip(ns[:-1], ns[1:], strict=True))
        to += list(centre + r * mid / np.linalg.norm(mid, axis=1)[:, None])
    ref = refine(xy, tris, whole, moved, to)
    return ref.points, ref.triangles, ref.chains(curve_nodes)


def renumbered(build: OutlineBuild, xy, tris, curve_nodes) -> RestMesh:
    """The mesh in the body's local numbering: triangles counter-clockwise, parts' node chains,
    the free arcs' continuation pieces."""
    nc, chain, face_y, columns = build.nc, build.chain, build.face_y, build.columns
    # the mesh's nodes on the chain are the strip's inner nodes (i, 1); at the face ends also (i, 0)
    known = np.concatenate([chain, [[columns[0], face_y[0]], [columns[-1], face_y[-1]]]])
    known_idx = np.concatenate([2 * np.arange(nc) + 1, [0, 2 * nc - 2]])
    hit = match_rows(xy, known)
    idx = np.where(hit >= 0, known_idx[np.maximum(hit, 0)], -1)
    new = idx < 0
    idx[new] = 2 * nc + np.arange(int(new.sum()))
    tris = idx[tris]
    allp = np.concatenate([np.zeros((2 * nc, 2)), xy[new]])
    allp[idx[~new]] = xy[~new]
    cw = doubled_areas(allp, tris) < 0
    tris[cw] = tris[cw][:, ::-1]  # counter-clockwise, as every triangle of the package
    parts = _part_chains(build.part_curves, nc, idx, curve_nodes)
    vn, vw, va, ve = continuation(build.virtual, xy, idx, tris, allp)
    return RestMesh(points=xy[new], triangles=tris, parts=parts, virtual_nodes=vn, virtual_weight=vw,
                    virtual_arc=va, virtual_ends=ve)


def _part_chains(part_curves: dict, nc: int, idx: np.ndarray, curve_nodes: dict) -> dict:
    """Every part's nodes in path order, in the local numbering ``idx``."""
    parts = {}
    for name, curves in part_curves.items():
        chainp = []
        for c in curves:
            if isinstance(c, tuple):  # the strip's side: face node then inner node at that column
                i = c[1]
                seg = [2 * i, 2 * i + 1] if i == nc - 1 else [2 * i + 1, 2 * i]
            else:
                seg = idx[curve_nodes[c]].tolist()
            chainp = seg if not chainp else chainp + seg[1:]
        parts[name] = np.asarray(chainp)
    return parts


def _ordered(e: np.ndarray, curve: int) -> list:
    """Node chain of a meshed curve from its line elements ``(m, 2)`` (gmsh gives them in order)."""
    if len(e) > 1 and e[0, 1] != e[1, 0]:
        raise MeshError(f"internal: gmsh's edges of curve {curve} are not in order")  # pragma: no cover
    return [int(e[0, 0]), *map(int, e[:, 1])]
