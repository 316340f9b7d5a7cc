"""The paper's stress space: one constant stress per piece (``S_h``). Assembly of ``E``,
``A_h``, ``Z`` and the contact data (``assembly``), stress norms (``norms``), the checks of a
solution (``checks``), the CVXPY dual a user may change (``dual``), an independent
displacement QP (``primal``), the fast path's linear algebra (``fast``) and the run (``run``)."""

import importlib

from .assembly import System, assemble

_LAZY = {"DualModel": ".dual", "PrimalModel": ".primal"}  # load CVXPY: on first use


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["DualModel", "PrimalModel", "System", "assemble"]
