"""The outline mesher: an outline body's mesh beyond the strip of columns along its face, made by
gmsh in a process of its own. :func:`mesh_rest` is the entry (kept meshes, timed);
:mod:`~cvxdual.geometry.outline.mesher` runs the steps on one
:class:`~cvxdual.geometry.outline.build.OutlineBuild`: the loops (``loops``), the cuts into
surfaces (``cuts``, ``regions``), the sizes (``sizes``), gmsh's mesh, and reading it back, refined
and renumbered (``readback``); ``in_place`` refines a mesh made so without gmsh (a run to a
tolerance's every other cycle); ``arcs`` holds the curved parts' polygons, ``fence`` and
``worker`` the gmsh process, ``quadrature`` a rule on the exact pieces beyond the free arcs."""

from .build import SPLINE_SAMPLES, held_parts
from .in_place import refine_in_place
from .mesher import SMALL, forget_meshes, gmsh_mesh, gmsh_seconds, mesh_rest, mesh_threads
from .quadrature import ContinuationRule, continuation_rule
from .readback import RestMesh
from .sizes import strip_depth

__all__ = ["SMALL", "SPLINE_SAMPLES", "ContinuationRule", "RestMesh", "continuation_rule", "forget_meshes",
           "gmsh_mesh", "gmsh_seconds", "held_parts", "mesh_rest", "mesh_threads", "refine_in_place", "strip_depth"]
