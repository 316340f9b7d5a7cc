"""The equilibrium stress space (docs/equilibrium.md): the Johnson-Mercier element on macro
triangles (``element``), the exactly admissible space of a mesh and its exactness step
(``space``), admissibility checks and certified two-sided bounds (``bounds``), contact
quantities (``contact``), the CVXPY model (``model``), the fast route (``fast``) and the run
(``run``)."""

import importlib

from . import kinematic_p2  # noqa: F401 - registers the P2 displacement's certificate terms
from .space import EquilibriumSpace

_LAZY = {"EquilibriumModel": ".model"}  # loads CVXPY: on first use


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["EquilibriumModel", "EquilibriumSpace"]
