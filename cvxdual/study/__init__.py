"""Studies as a tool: a study is a spec (TOML or Python) of scenes, triangulations, stress
spaces, levels, solvers and a grid of ``--set`` overrides, with a reference and metrics;
:func:`run` runs its cases on Dask and returns (and writes) the table, the markdown report with
fitted rates, and the plots. ``cvxdual study run SPEC`` is the command line.
"""

from .report import fit_rate, plot_error, rates, write_outputs
from .runner import run
from .spec import Case, Reference, Study, StudyError, builtin_specs, load_spec

__all__ = ["Case", "Reference", "Study", "StudyError", "builtin_specs", "fit_rate", "load_spec", "plot_error",
           "rates", "run", "write_outputs"]
