"""Meshes of outline bodies: the paper's strip of columns along the face, gmsh beyond it. Along the
face of an outline body (:mod:`cvxdual.scene.outline`) the mesh is one layer of the column mesh
(:mod:`cvxdual.geometry.mesh`): face nodes on the global columns, so both bodies' contact nodes
pair on vertical lines and the curved pieces of both triangulations are built as for column
bodies. The layer's inner side is a chain of nodes at depth ``t_i`` (the local column spacing)
below (or above) the face. The rest of the body, between that chain and the outline, is meshed by
gmsh (its Python API, in gmsh's own process: :mod:`~cvxdual.geometry.outline.fence`) conforming
to the chain: one geometry point per chain node and two-node transfinite lines between them, so
gmsh adds no node on the chain and keeps the given coordinates bit for bit. :func:`mesh_body`
does it in steps: the loops (:mod:`~cvxdual.geometry.outline.loops`), the cuts into surfaces
(:mod:`~cvxdual.geometry.outline.regions`), the sizes (:mod:`~cvxdual.geometry.outline.sizes`),
gmsh's mesh, and reading it back, refined and renumbered (:mod:`~cvxdual.geometry.outline.readback`),
all on one :class:`~cvxdual.geometry.outline.build.OutlineBuild`.
"""

from __future__ import annotations

import os
import time
from functools import lru_cache

import numpy as np

from ...errors import MeshError
from ..refine import FoldError
from .build import OutlineBuild
from .fence import in_gmsh
from .loops import add_loops, check_strip, polygons_clear
from .readback import RestMesh, read_back, refined, renumbered
from .regions import cut_regions
from .sizes import steering
from .worker import import_gmsh

ALGORITHM = 6  # gmsh's Frontal-Delaunay: the best-shaped triangles of its 2D algorithms
SMALL = 64  # bodies with at most this many columns are meshed on one thread (0.1 s to start a second, seen)


def mesh_threads() -> int:
    """gmsh's threads: one per surface (at most two), within ``OMP_NUM_THREADS`` when it is set
    (the studies run each case on one thread)."""
    limit = os.environ.get("OMP_NUM_THREADS", "")
    return max(1, min(2, int(limit) if limit.isdigit() else (os.cpu_count() or 1)))


def mesh_rest(body, columns: np.ndarray, inner_y: np.ndarray, level: int, spots=None, cut_columns=None) -> RestMesh:
    """Mesh the body between the strip's inner chain ``(columns, inner_y)`` and its outline; an
    adaptive grid's ``spots`` and ``cut_columns`` as in :class:`~cvxdual.geometry.outline.build.OutlineBuild`.

    The last eight meshes are kept (read-only arrays): the size estimate meshes a small level in
    full (:func:`cvxdual.geometry.mesh.mesh_size`) and the fast path's warm start meshes coarse
    levels; a run of two bodies meets each of them again."""
    columns, inner_y = np.asarray(columns, float), np.asarray(inner_y, float)
    spots = None if spots is None or not len(spots) else np.ascontiguousarray(spots, float).reshape(-1, 3).tobytes()
    # cuts tried at the chain's own columns are the default's: one key, so that a run to a tolerance's first
    # cycle finds the mesh its size check made
    same = cut_columns is None or np.array_equal(np.asarray(cut_columns, float), columns)
    cuts = None if same else np.asarray(cut_columns, float).tobytes()
    return _cached(body, columns.tobytes(), inner_y.tobytes(), int(level), spots, cuts)


def forget_meshes() -> None:
    """Drop the kept meshes (a timing that must include gmsh's work)."""
    _cached.cache_clear()


_SPENT = [0.0]  # seconds spent meshing with gmsh in this process (studies' timings)


def gmsh_seconds() -> float:
    """Wall time spent meshing outline bodies (gmsh, reading its mesh and refining it) in this process so far:
    a run's share is the difference of two readings over the run's own time."""
    return _SPENT[0]


@lru_cache(maxsize=8)
def _cached(body, columns: bytes, inner_y: bytes, level: int, spots: bytes | None = None,
            cuts: bytes | None = None) -> RestMesh:
    t = time.perf_counter()
    try:
        rest = in_gmsh("cvxdual.geometry.outline.mesher:gmsh_mesh", body, np.frombuffer(columns),
                       np.frombuffer(inner_y), level, None if spots is None else np.frombuffer(spots).reshape(-1, 3),
                       None if cuts is None else np.frombuffer(cuts),
                       what=f"meshing body {body.name!r} at level {level}")
    finally:
        _SPENT[0] += time.perf_counter() - t
    for a in (rest.points, rest.triangles, rest.virtual_nodes, rest.virtual_weight, rest.virtual_arc,
              rest.virtual_ends, *rest.parts.values()):
        a.flags.writeable = False
    return rest


def gmsh_mesh(body, columns: np.ndarray, inner_y: np.ndarray, level: int, spots=None, cut_columns=None) -> RestMesh:
    """:func:`mesh_rest`'s work, done by gmsh: runs in gmsh's own process (:mod:`~cvxdual.geometry.outline.fence`)."""
    gmsh = import_gmsh()
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        return mesh_body(gmsh, body, columns, inner_y, level, spots=spots, cut_columns=cut_columns)
    except MeshError:
        raise
    except Exception as e:  # gmsh reports its failures as plain exceptions
        raise MeshError(f"gmsh could not mesh body {body.name!r} at level {level} ({e}); check its outline "
                        "(parts very close to the face, or to each other) or change the level") from None
    finally:
        gmsh.finalize()


def mesh_body(gmsh, body, columns, inner_y, level, halved=True, spots=None, cut_columns=None) -> RestMesh:
    """The body's mesh beyond the strip's inner chain ``(columns, inner_y)``. ``halved``: at level
    ``L >= 1`` gmsh meshes at the sizes of level ``L - 1`` and the mesh is refined once; where
    that cannot keep level ``L``'s polygons (they clash as gmsh gets them, or a fine node folds a
    triangle) the body is meshed again at level ``L``'s own sizes."""
    build = OutlineBuild(gmsh, body, columns, inner_y, level, halved, spots, cut_columns)
    check_strip(body, build.chain)
    add_loops(build)
    if not polygons_clear(build):
        return _unhalved(build)
    regions = cut_regions(build)
    surfaces = add_surfaces(build, regions)
    set_sizes(build, regions, surfaces)
    generate(build)
    xy, tris, curve_nodes = read_back(build)
    if build.step > 1:
        try:
            xy, tris, curve_nodes = refined(build, xy, tris, curve_nodes)
        except FoldError:  # a fine node crosses gmsh's coarser triangle
            return _unhalved(build)
    return renumbered(build, xy, tris, curve_nodes)


def _unhalved(build: OutlineBuild) -> RestMesh:
    build.gmsh.model.remove()
    return mesh_body(build.gmsh, build.body, build.columns, build.inner_y, build.level, halved=False,
                     spots=build.spots, cut_columns=build.cut_columns)


def add_surfaces(build: OutlineBuild, regions: list) -> list[int]:
    """One plane surface per region ``(outer loop, hole loops)``: their gmsh tags."""
    geo = build.geo
    return [geo.addPlaneSurface([geo.addCurveLoop(outer)] + [geo.addCurveLoop(cs) for cs in inner])
            for outer, inner in regions]


def set_sizes(build: OutlineBuild, regions: list, surfaces: list[int]) -> None:
    """Every point's size (the smallest any curve asked of it), the steering points embedded in
    their surfaces (:func:`~cvxdual.geometry.outline.sizes.steering`), the two-node lines fixed."""
    geo, shape = build.geo, build.shape
    steer = steering(build.body, build.field, build.glevel,
                     [(build.ring(outer), [build.ring(cs) for cs in inner]) for outer, inner in regions],
                     np.concatenate([np.stack([p[:-1], p[1:]], 1) for p, _ in shape.values()]), build.spots)
    embedded = [[build.point(q, float(lc)) for q, lc in zip(pts, lcs, strict=True)] for pts, lcs in steer]
    for tag, lc in build.sizes.items():
        geo.mesh.setSize([(0, tag)], lc)
    geo.synchronize()
    for r, tags in enumerate(embedded):
        if tags:
            build.gmsh.model.mesh.embed(0, tags, 2, surfaces[r])
    for c in build.fixed:
        build.gmsh.model.mesh.setTransfiniteCurve(c, 2)


def generate(build: OutlineBuild) -> None:
    """gmsh's mesh of every surface, each alone by a fixed algorithm: the same on any threads."""
    threads = mesh_threads() if len(build.chain_pts) > SMALL else 1  # a second thread's start costs more
    for name, value in (("Mesh.Algorithm", ALGORITHM), ("Mesh.MeshSizeExtendFromBoundary", 1),
                        ("Mesh.MeshSizeFromPoints", 1), ("Mesh.MeshSizeFromCurvature", 0),
                        ("Mesh.MeshSizeMax", build.field.cap), ("General.NumThreads", threads),
                        ("Mesh.MaxNumThreads1D", 1), ("Mesh.MaxNumThreads2D", threads), ("Mesh.MaxRetries", 3),
                        # no smoothing pass: 40 % of gmsh's time for 1.5 % of hertz's error (reports/outlines.md)
                        ("Mesh.Smoothing", 0)):
        build.gmsh.option.setNumber(name, value)
    build.gmsh.model.mesh.generate(2)
