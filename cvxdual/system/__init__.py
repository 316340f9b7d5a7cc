"""The discrete system both stress spaces share: supports, node frames and loads on the mesh
(``boundary``), rigid motions and load balance (``rigid``), the assembly of ``E``, ``A_h``, ``Z``
and the contact data (``assembly``), and the kinematic side, the P1 displacement: its fast path
with the warm start from coarser levels (``displacement``) and an independent CVXPY displacement
QP (``primal``); the kinematic side as a class (``kinematic``: P1 today) and the continuous P2
displacement on the Alfeld split without contact (``p2``: the element, its condensation and
assembly, the first step of a second kinematic side) with the guaranteed pointwise check of a
quadratic contact jump against the true gap (``quadratic_gap``); the stress-space interface
(``stress_space``) and the stress field a solution holds (``field``)."""

import importlib

from .assembly import System, assemble

_LAZY = {"PrimalModel": ".primal"}  # loads CVXPY: on first use


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["PrimalModel", "System", "assemble"]
