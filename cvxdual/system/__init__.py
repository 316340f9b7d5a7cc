"""The discrete system both stress spaces share: supports, node frames and loads on the mesh
(``boundary``), rigid motions and load balance (``rigid``), the assembly of ``E``, ``A_h``, ``Z``
and the contact data (``assembly``), the P1 displacement's fast path with the warm start from
coarser levels (``displacement``) and an independent CVXPY displacement QP (``primal``); the
kinematic sides of the certificate as classes (``kinematic``: P1, and P2 on the Alfeld split: the
element and its condensation ``p2``, its nodes on a scene ``p2_layout``, the faces' middle unknowns
``p2_contact``, its system ``p2_system``, the solved field ``p2_displacement``) with the guaranteed
pointwise check of a quadratic contact jump against the true gap (``quadratic_gap``); the
stress-space interface (``stress_space``) and the stress field a solution holds (``field``)."""

import importlib

from .assembly import System, assemble

_LAZY = {"PrimalModel": ".primal"}  # loads CVXPY: on first use


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["PrimalModel", "System", "assemble"]
