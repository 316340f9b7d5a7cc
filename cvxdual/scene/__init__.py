"""What the user describes: two bodies, their materials, faces and gaps, supports and loads,
the contact interval, an optional exact field and the mesh's sizes (:class:`Scene`, frozen
dataclasses), and how it is read (TOML scene files with ``base = ...`` and ``--set``
overrides, the built-in scenes in ``data/``)."""

from .materials import Material
from .scene import Body, BoundaryPart, ExactSpec, Friction, MeshSpec, Scene, Traction, convert_units
from .scenefile import builtin_scenes, load_scene, parse_assignment

__all__ = ["Body", "BoundaryPart", "ExactSpec", "Friction", "Material", "MeshSpec", "Scene", "Traction",
           "builtin_scenes", "convert_units", "load_scene", "parse_assignment"]
