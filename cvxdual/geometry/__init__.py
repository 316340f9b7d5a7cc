"""The discretised geometry: column meshes of the two bodies with their contact pairs on common
vertical lines (``mesh``), the paper's pieces and both triangulations (``pieces``,
``triangulation``), quadrature on straight and curved pieces, supports and loads on the mesh
(``boundary``), rigid motions and load balance (``rigid``) and point location (``locate``)."""

from .mesh import Mesh, build_mesh
from .pieces import Pieces
from .triangulation import TRIANGULATIONS, discretize

__all__ = ["Mesh", "Pieces", "TRIANGULATIONS", "build_mesh", "discretize"]
