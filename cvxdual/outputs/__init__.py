"""What a solution writes: the output set replaced whole (``output_set``: ``summary.json``,
``contact.csv``, ``solution.vtu``, the PNGs), the VTU file (``vtu``), the standard figures
(``figures``) and plotting functions that draw on a matplotlib ``ax`` and return it
(``plots``). matplotlib loads only where something is drawn."""

import importlib

from .figures import figures
from .output_set import write_outputs

_LAZY = {name: ".plots" for name in ("plot_stress", "plot_deformed", "plot_gap", "plot_pressure", "plot_bound_map")}
_LAZY["write_vtu"] = ".vtu"


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["figures", "plot_bound_map", "plot_deformed", "plot_gap", "plot_pressure", "plot_stress",
           "write_outputs", "write_vtu"]
