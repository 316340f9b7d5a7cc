"""The paper's stress space: one constant stress per piece (``S_h``). Stress norms (``norms``),
the checks of a solution (``checks``), the CVXPY dual a user may change (``dual``) and the run
(``run``); the assembly and the P1 displacement it shares with the equilibrium space live in
:mod:`cvxdual.system`."""

import importlib

_LAZY = {"DualModel": ".dual"}  # loads CVXPY: on first use


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["DualModel"]
