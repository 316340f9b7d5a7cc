"""cvxdual: dual (stress-based) finite element analysis of frictionless contact of two plane
elastic bodies with an enlarging contact zone, after Tran Van Bon (1986), on CVXPY.

Names from the paper are used where they help a reader holding it: ``lam`` (stress),
``eps`` (initial gap), ``E``, ``A_h``, ``Z``, ``T`` (the paper's ``F``), ``J0``/``J-``,
``K0h`` (the cone of admissible test displacements), ``S_h`` (piecewise-constant stresses).
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from .errors import (
    AccuracyError,
    CvxdualError,
    MeshError,
    ModelError,
    NoAdmissibleStressError,
    OutputError,
    SceneError,
    SolverError,
    TimeLimitError,
    TooLargeError,
    UnbalancedLoadError,
    UnknownSolverError,
)
from .geometry.mesh import build_mesh
from .geometry.triangulation import discretize
from .p0.assembly import System, assemble
from .pipeline import build_model, build_system, recover, solve
from .reference.exact import exact_field
from .scene.materials import Material
from .scene.scene import Body, BoundaryPart, ExactSpec, Friction, MeshSpec, Scene, Traction
from .scene.scenefile import builtin_scenes, load_scene
from .solution import Solution

try:  # the installed distribution's version: pyproject.toml is its one source
    __version__ = _version("cvxdual")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "unknown (not installed)"

# the CVXPY models load CVXPY (0.3 s): on first use, so that the fast path never pays for it
_LAZY = {"DualModel": ".dual", "EquilibriumModel": ".eqmodel", "PrimalModel": ".primal"}


def __getattr__(name):
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "AccuracyError", "Body", "BoundaryPart", "CvxdualError", "DualModel", "EquilibriumModel", "ExactSpec",
    "Friction", "Material", "MeshError", "MeshSpec", "ModelError", "NoAdmissibleStressError", "OutputError",
    "PrimalModel", "Scene", "SceneError", "Solution", "SolverError", "System", "TimeLimitError",
    "TooLargeError", "Traction", "UnbalancedLoadError", "UnknownSolverError", "assemble", "build_mesh",
    "build_model", "build_system", "builtin_scenes", "discretize", "exact_field", "load_scene", "recover",
    "solve",
]
