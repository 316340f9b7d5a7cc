"""Exceptions of cvxdual.

Every error the package raises on purpose is a :class:`CvxdualError`. The message names the
problem and how to fix it; the CLI prints it as one line and exits non-zero.
"""

from __future__ import annotations

__all__ = ["AccuracyError", "CvxdualError", "MeshError", "ModelError", "NoAdmissibleStressError", "OutputError",
           "SceneError", "SolverError", "TimeLimitError", "TooLargeError", "UnbalancedLoadError", "UnknownPlotError",
           "UnknownSolverError"]


class CvxdualError(Exception):
    """Base class of all errors raised by cvxdual. ``cli`` is the same message with advice for
    the command line (``--level`` rather than ``level=``), where the two differ; ``reason`` the
    problem alone, without advice (a caller that acts on the advice itself, such as the
    fallback to Clarabel, reports the reason only)."""

    def __init__(self, message: str = "", cli: str | None = None, reason: str | None = None):
        super().__init__(message)
        self.cli = cli
        self.reason = reason


class SceneError(CvxdualError, ValueError):
    """The scene (or its TOML file) is invalid: bad numbers, unknown keys, bad geometry."""


class MeshError(CvxdualError, ValueError):
    """The mesh cannot be built or is invalid (inverted elements, misaligned contact pairs)."""


class UnbalancedLoadError(CvxdualError):
    """The loads do work on a rigid motion that keeps both bodies in contact."""


class NoAdmissibleStressError(CvxdualError):
    """No statically admissible stress field exists (e.g. a body is pulled away from contact)."""


class SolverError(CvxdualError):
    """The QP solver did not return an optimal solution (infeasible, inaccurate, max iterations)."""


class TimeLimitError(CvxdualError):
    """The run (or its solver) reached its time limit before it finished."""


class UnknownSolverError(CvxdualError, ValueError):
    """The requested solver is not known or not installed."""


class UnknownPlotError(CvxdualError, ValueError):
    """A figure name that is not one of :class:`cvxdual.outputs.figures.Plot`."""


class ModelError(CvxdualError, ValueError):
    """A CVXPY model is misused: read before it is solved, solved again unchanged, changed
    in a way it cannot take (friction twice, a non-constraint passed as a constraint)."""


class OutputError(CvxdualError, OSError):
    """An output file or directory cannot be written."""


class AccuracyError(CvxdualError):
    """A solution failed the package's own accuracy checks (residuals above the promised tolerances)."""


class TooLargeError(CvxdualError):
    """The run would need more memory than the limit allows (estimated before allocating)."""


class ToleranceError(CvxdualError):
    """A run to a certified tolerance stopped before meeting it (pieces, time or memory ran out);
    ``solution`` is its best certified result (the CLI writes it before it exits with status 1)."""

    def __init__(self, message: str = "", cli: str | None = None, solution=None):
        super().__init__(message, cli=cli)
        self.solution = solution
