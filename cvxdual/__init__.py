"""cvxdual: dual (stress-based) finite element analysis of frictionless contact of two plane
elastic bodies with an enlarging contact zone, after Tran Van Bon (1986), on CVXPY.

Names from the paper are used where they help a reader holding it: ``lam`` (stress),
``eps`` (initial gap), ``E``, ``A_h``, ``Z``, ``T`` (the paper's ``F``), ``J0``/``J-``,
``K0h`` (the cone of admissible test displacements), ``S_h`` (piecewise-constant stresses).

The package's folders are its data flow: ``scene`` (what the user describes) -> ``reference``
(closed forms) -> ``geometry`` (meshes, pieces, loads) -> ``linalg`` -> the stress spaces ``p0``
(the paper's) and ``eq`` (equilibrium stresses and certified bounds), each with its CVXPY model
(over ``model``) and its fast solver (over ``fast``) -> ``solution`` -> ``pipeline`` (the entry
points) -> ``outputs`` -> ``study`` and ``cli``. :data:`__all__` is the documented API; the public
modules are this one, ``cvxdual.scene``, ``cvxdual.reference``, ``cvxdual.voigt`` (stress measures),
``cvxdual.outputs``, ``cvxdual.study`` and ``cvxdual.errors``, each with its ``__all__``.
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
    ToleranceError,
    TooLargeError,
    UnbalancedLoadError,
    UnknownSolverError,
)
from .geometry import build_mesh, discretize
from .outputs import write_outputs
from .pipeline import build_model, build_system, solve
from .reference import HertzData, exact_field, exact_reference, hertz_line_contact, hertz_pressure, mcewen_stress
from .scene import (
    Body,
    BoundaryPart,
    ExactSpec,
    Friction,
    Material,
    MeshSpec,
    Scene,
    Traction,
    builtin_scenes,
    load_scene,
    parse_assignment,
)
from .solution import Solution, SolverStats
from .system import System, assemble

try:  # the installed distribution's version: pyproject.toml is its one source
    __version__ = _version("cvxdual")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "unknown (not installed)"

# the CVXPY models load CVXPY (0.3 s): on first use, so that the fast path never pays for it
_LAZY = {"DualModel": ".p0.dual", "EquilibriumModel": ".eq.model", "PrimalModel": ".system.primal"}


def __getattr__(name):
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    # solving
    "solve", "build_model", "build_system", "Solution", "SolverStats",
    # scenes
    "Scene", "Body", "BoundaryPart", "ExactSpec", "Friction", "Material", "MeshSpec", "Traction", "load_scene",
    "builtin_scenes", "parse_assignment",
    # the CVXPY models
    "DualModel", "EquilibriumModel", "PrimalModel",
    # meshes and assembly
    "build_mesh", "discretize", "assemble", "System",
    # closed forms
    "exact_field", "exact_reference", "HertzData", "hertz_line_contact", "hertz_pressure", "mcewen_stress",
    # outputs
    "write_outputs",
    # errors
    "CvxdualError", "AccuracyError", "MeshError", "ModelError", "NoAdmissibleStressError", "OutputError", "SceneError",
    "SolverError", "TimeLimitError", "ToleranceError", "TooLargeError", "UnbalancedLoadError", "UnknownSolverError",
]
