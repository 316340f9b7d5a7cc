"""The one place where cvxdual calls CVXPY below its documented modelling API: the load sweep
(:meth:`cvxdual.convex.base.ConvexModel._runner`) keeps a solver's data and solves it again with a
new right-hand side, skipping CVXPY's recompilation. That needs CVXPY's solving chain: the list of
conic solvers, the chain's solver, ``SolvingChain.solve_via_data`` and ``Problem.unpack_results``.
They are not covered by CVXPY's deprecation policy, so ``pyproject.toml`` caps CVXPY at the major
version tested and ``tests/test_cvxpy_internals.py`` fails loudly if any of them changes.
"""

from __future__ import annotations


def conic_solvers() -> frozenset[str]:
    """The names of CVXPY's conic solvers (those whose data are ``A``, ``b``, ``c`` and cones)."""
    from cvxpy.reductions.solvers.defines import CONIC_SOLVERS
    return frozenset(CONIC_SOLVERS)


def problem_data(problem, solver: str, opts: dict) -> tuple[dict, object, object]:
    """``(data, chain, inverse_data)`` of ``problem`` compiled for ``solver`` (CVXPY's public
    ``Problem.get_problem_data``, with the chain this module's other calls take)."""
    return problem.get_problem_data(solver, solver_opts=opts)


def is_conic(chain) -> bool:
    """Whether the chain hands its solver conic data (a solver on both of CVXPY's lists may get QP
    data instead, whose right-hand sides are split differently)."""
    from cvxpy.reductions.solvers.conic_solvers.conic_solver import ConicSolver
    return isinstance(chain.solver, ConicSolver)


def solve_data(problem, chain, data: dict, inverse, verbose: bool, opts: dict) -> None:
    """Solve the kept ``data`` (its ``b`` possibly replaced) with the chain's solver and write the
    result into ``problem`` as ``Problem.solve`` would (values, status, multipliers)."""
    problem.unpack_results(chain.solve_via_data(problem, data, False, bool(verbose), opts), chain, inverse)


def rhs_key() -> str:
    """The key of the right-hand side ``b`` in conic solver data."""
    from cvxpy import settings
    return settings.B
