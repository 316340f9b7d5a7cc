"""Studies as a tool: a study is a spec (TOML or Python) of scenes, triangulations, stress
spaces, levels, solvers and a grid of ``--set`` overrides, with a reference and metrics;
:func:`run` runs its cases on Dask and returns (and writes) the table, the markdown report with
fitted rates, and the plots. ``cvxdual study run SPEC`` is the command line.
"""

import importlib

# report and runner load pandas and Dask (0.3 s and more): on first use, so that the CLI's
# other commands (which build this package's argument parser) do not pay for them
_LAZY = {"fit_rate": ".report", "plot_error": ".report", "rates": ".report", "write_report": ".report",
         "run": ".runner", "Case": ".spec", "Reference": ".spec", "Study": ".spec", "StudyError": ".spec",
         "load_spec": ".spec"}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = ["Case", "Reference", "Study", "StudyError", "fit_rate", "load_spec", "plot_error", "rates", "run",
           "write_report"]
