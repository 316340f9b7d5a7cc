"""The two triangulations of the paper (MATH.md section 4) on column meshes.

- ``type1`` (Haslinger-Hlavacek): convex face stretches give a straight triangle ``T0`` and
  the segment ``Ts`` between chord and arc; non-convex stretches give curved triangles
  ``Tc`` with a vertical side, on which ``v_h`` is constant along y (tying the third vertex).
- ``type2`` (Hlavacek-Krizek): convex stretches as type 1; non-convex stretches are replaced
  by a polygon of tangent segments whose vertices are the contact nodes, and the sliver
  ``D_h`` between polygon and arc is made of curved pieces ``Tc``.

On flat faces both are the plain triangle mesh.
"""

from __future__ import annotations

from .errors import CvxdualError
from .mesh import Mesh, build_mesh
from .pieces import Pieces, triangle_pieces
from .scene import Scene

TRIANGULATIONS = ("type1", "type2")


def check_triangulation(name: str) -> str:
    name = str(name).lower()
    if name not in TRIANGULATIONS:
        raise CvxdualError(f"unknown triangulation {name!r}; choose 'type1' or 'type2'")
    return name


def discretize(scene: Scene, triangulation: str = "type1", level: int | None = None):
    """Mesh and pieces of ``scene``: returns ``(mesh, pieces, ties)``."""
    triangulation = check_triangulation(triangulation)
    mesh = build_mesh(scene, level)
    if all(b.face.is_flat() for b in scene.bodies):
        return mesh, _flat_pieces(mesh), None
    raise CvxdualError("curved faces are not supported yet")


def _flat_pieces(mesh: Mesh) -> Pieces:
    return triangle_pieces(mesh.points, mesh.triangles(), mesh.triangle_body(),
                           [b.face for b in mesh.scene.bodies])
