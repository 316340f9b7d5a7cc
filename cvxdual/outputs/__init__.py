"""What a solution writes: the output set replaced whole (``output_set``: ``summary.json``,
``contact.csv``, ``solution.vtu``, the PNGs), the VTU file (``vtu``), the figures
(``figures``, chosen by :class:`Plot`) and plotting functions that draw on a matplotlib ``ax`` and return it
(``maps``: the stress, displacement and mesh maps; ``plots``: the contact plots and the bound map; with the
windows and zooms of ``views`` and the triangle drawing of ``render``). matplotlib loads only where something is
drawn."""

import importlib

from .figures import Plot, figures
from .output_set import write_outputs

_LAZY = {**dict.fromkeys(("plot_stress", "plot_mesh", "plot_displacement", "Measure", "DisplacementComponent"),
                         ".maps"),
         **dict.fromkeys(("plot_deformed", "plot_gap", "plot_pressure", "plot_bound_map"), ".plots"),
         "write_vtu": ".vtu"}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["DisplacementComponent", "Measure", "Plot", "figures", "plot_bound_map", "plot_deformed",
           "plot_displacement", "plot_gap", "plot_mesh", "plot_pressure", "plot_stress", "write_outputs", "write_vtu"]
