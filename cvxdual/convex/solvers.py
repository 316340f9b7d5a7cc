"""Solver names, options and the mapping of CVXPY statuses to cvxdual exceptions."""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import SolverError, TimeLimitError, UnknownSolverError
from ..kinds import Status
from ..solution import SolverStats
from ..validate import one_line

DEFAULT_SOLVER = "CLARABEL"  # the reference, and where every other path hands over
# from this many pieces SCS (with SOLVER_OPTIONS) is the default: 2.5-3x faster than Clarabel at
# 4e4-1.5e5 pieces, every accuracy check passed, hard cases included; below, the two tie
# within noise and Clarabel keeps the wider margins (reports/speed.md, "QP solvers")
LARGE_QP = 20_000
FAST = "FAST"  # the active-set path of cvxdual.system.displacement, not a CVXPY solver

# The QP solvers CVXPY can call for the dual, with the options that give each a chance at the
# accuracy the package promises (README): the one table the package and the speed study use.
# Clarabel's defaults (1e-8 gaps and feasibility) already do; first-order solvers need
# tighter tolerances and more iterations to get anywhere near.
SOLVER_OPTIONS: dict[str, dict] = {
    "CLARABEL": {},
    "OSQP": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iter": 200000, "polishing": True},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 200000},
    "PIQP": {}, "PROXQP": {}, "ECOS": {}, "CVXOPT": {}, "HIGHS": {}, "QOCO": {}, "DAQP": {},
}


# the option each solver reads as a wall-clock limit in seconds; the others have none (PIQP and
# ECOS reject the name, QOCO, ProxQP and CVXOPT ignore it), so a time limit is refused there
TIME_LIMIT_OPTION = {"CLARABEL": "time_limit", "SCS": "time_limit_secs", "OSQP": "time_limit"}


def default_solver(n_pieces: float) -> str:
    """The CVXPY solver used when none is named, for a mesh of ``n_pieces`` pieces."""
    if n_pieces >= LARGE_QP:
        import cvxpy as cp
        if "SCS" in cp.installed_solvers():
            return "SCS"
    return DEFAULT_SOLVER


def resolve_solver(name: str | None) -> str:
    """Normalise a solver name; raise :class:`UnknownSolverError` naming the installed ones."""
    name = DEFAULT_SOLVER if name is None else str(name).upper()
    if name == FAST:
        return FAST
    import cvxpy as cp  # 0.3 s to import: only for the CVXPY path
    installed = cp.installed_solvers()
    if name not in installed:
        raise UnknownSolverError(
            f"unknown or uninstalled solver {name!r}; installed CVXPY solvers: {', '.join(sorted(installed))}"
            " (or 'fast' for the active-set path)")
    return name


# CVXPY's status strings (cvxpy.INFEASIBLE, ...), spelled out so that this module loads without it
_ADVICE = {
    "infeasible": "no statically admissible stress field exists: check that the loads push the bodies "
                   "together and are balanced",
    "infeasible_inaccurate": "the solver suspects infeasibility but is not sure: check the loads, or try "
                              "a finer mesh or another solver",
    "unbounded": "the problem is unbounded: a body can move freely; add supports",
    "unbounded_inaccurate": "the problem looks unbounded: a body can move freely; add supports",
    "optimal_inaccurate": "the solver stopped before reaching its tolerances (inaccurate); try {other}, "
                           "a coarser mesh, or more iterations",
    "user_limit": "the solver hit an iteration or time limit; raise max_iter or use {other}",
}


def _other(solver: str) -> str:
    """A solver to suggest after ``solver`` failed: Clarabel, or after Clarabel the fast path."""
    return "the fast path (solver='fast')" if solver == DEFAULT_SOLVER else "Clarabel"


def solve_problem(problem, solver: str, what: str, advice: dict | None = None, time_limit: float | None = None,
                  verbose: bool = False, run=None, accept: tuple = (Status.OPTIMAL,), defaults: dict | None = None,
                  **options) -> SolverStats:
    """Solve the ``cvxpy.Problem`` ``problem``; return its statistics, or raise :class:`SolverError`.

    ``advice`` replaces the advice given for a status (e.g. a model that knows the user's
    changes names them); ``time_limit`` (seconds) is passed as the solver's own option
    (:data:`TIME_LIMIT_OPTION`); ``verbose`` prints the solver's log. ``run(opts)``, if given,
    solves ``problem`` in place of ``problem.solve`` and returns the compile time it spent.
    ``accept``: the statuses returned rather than raised (a caller that certifies the result
    itself may accept ``optimal_inaccurate``). ``defaults``: options the caller sets unless
    ``options`` does (not named in messages about the user's options).
    """
    import cvxpy as cp
    opts = {**SOLVER_OPTIONS.get(solver, {}), **(defaults or {}), **options}
    if time_limit is not None:
        if solver not in TIME_LIMIT_OPTION:
            raise SolverError(f"{what}: solver {solver} has no time limit; use one of "
                              f"{', '.join(TIME_LIMIT_OPTION)} or drop time_limit")
        if isinstance(time_limit, bool) or not (float(time_limit) > 0 and np.isfinite(float(time_limit))):
            raise SolverError(f"{what}: time_limit must be a positive number of seconds, got {time_limit!r}")
        opts[TIME_LIMIT_OPTION[solver]] = float(time_limit)
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            # an inaccurate status becomes a SolverError below, with advice: CVXPY's warning repeats it
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            if run is None:
                problem.solve(solver=solver, verbose=bool(verbose), **opts)
                compile_time = getattr(problem, "compilation_time", None)
            else:
                compile_time = run(opts)
    except cp.error.SolverError as e:
        msg = one_line(e, 200) if str(e) else "no message"
        if "nrecognized" in msg or "invalid keyword" in msg:  # OSQP names unknown settings this way
            raise SolverError(f"{what}: solver {solver} rejected the options {sorted(options)} ({msg}); "
                              "check their names and types in the solver's documentation") from None
        raise SolverError(f"{what}: solver {solver} failed ({msg}); try {_other(solver)} or a coarser mesh",
                          reason=f"{what}: solver {solver} failed ({msg})") from None
    except (TypeError, ValueError) as e:  # solvers reject unknown or ill-typed options this way
        msg = one_line(e, 200)
        raise SolverError(f"{what}: solver {solver} rejected the options {sorted(options)} ({msg}); "
                          "check their names and types in the solver's documentation") from None
    wall = time.perf_counter() - t0
    status = problem.status
    if status not in accept:
        ran = getattr(problem.solver_stats, "solve_time", None) or 0.0  # the solver's own clock, if it reports one
        # SCS reports a time-out as 'optimal_inaccurate'; the solver may have been given what CVXPY's
        # compile left of the limit (``run``), so the call's own wall time is the measure too
        if time_limit is not None and max(ran, wall) >= 0.99 * time_limit and status in ("user_limit",
                                                                                       "optimal_inaccurate"):
            stop = f"{what}: solver {solver} stopped at the time limit of {time_limit:g} s (status '{status}')"
            raise TimeLimitError(f"{stop}; raise time_limit or try a coarser mesh",
                                 cli=f"{stop}; raise --time-limit or lower --level")
        # the caller's advice as given (it may quote the user's own text); ours names another solver
        text = (advice or {}).get(status) or _ADVICE.get(status, "try {other}").format(other=_other(solver))
        raise SolverError(f"{what}: solver {solver} returned status '{status}': {text}",
                          reason=f"{what}: solver {solver} returned status '{status}'")
    stats = problem.solver_stats
    return SolverStats(solver=solver, status=status, iterations=getattr(stats, "num_iters", None), solve_time=wall,
                       solver_time=getattr(stats, "solve_time", None), setup_time=getattr(stats, "setup_time", None),
                       compile_time=compile_time)
