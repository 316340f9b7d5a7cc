"""Solver failures read as one short line whose advice fits what already failed: Clarabel's
failure does not advise Clarabel, and the fast path's failure followed by Clarabel's names both
without repeating the advice the fallback already acted on."""

from __future__ import annotations

import types

import pytest

import cvxdual as cd
import cvxdual.pipeline as pipeline
from cvxdual.convex.solvers import FAST, solve_problem
from cvxdual.errors import SolverError

SHORT = 200  # characters: an error line a user reads at once (issue 39)


class FakeProblem:
    """Stands for a cvxpy.Problem whose solver ends with ``status``."""

    def __init__(self, status: str):
        self.status = None
        self._status = status
        self.solver_stats = types.SimpleNamespace(solve_time=0.01, num_iters=5, setup_time=0.0)

    def solve(self, **_):
        self.status = self._status


@pytest.mark.parametrize("status", ["optimal_inaccurate", "user_limit", "solver_error"])
def test_clarabel_failure_advises_another_path(status):
    with pytest.raises(SolverError) as e:
        solve_problem(FakeProblem(status), "CLARABEL", "eq model")
    text = str(e.value)
    advice = text.split(":", 2)[-1]
    assert "clarabel" not in advice.lower() and "fast" in advice, text
    assert len(text) < SHORT and e.value.reason and "try" not in e.value.reason


def test_other_solvers_failure_advises_clarabel():
    with pytest.raises(SolverError, match="try Clarabel"):
        solve_problem(FakeProblem("optimal_inaccurate"), "SCS", "eq model")


def test_fast_then_clarabel_failure_is_one_short_line(monkeypatch):
    """Both paths fail: the line names both reasons, not the fast path's advice (use Clarabel),
    which the fallback already followed, and stays short."""
    def attempt(scene, triangulation, level, stress_space, bounds, kinematic, solver, **options):
        if solver == FAST:
            why = "eq fast path: the condensed system is singular or ill-conditioned (relative residual 3.1e-02)"
            raise SolverError(f"{why}; use the CVXPY path (EquilibriumModel, or solver='CLARABEL')",
                              cli=f"{why}; use the CVXPY path (--solver CLARABEL)", reason=why)
        solve_problem(FakeProblem("optimal_inaccurate"), solver, "eq model")

    monkeypatch.setattr(pipeline, "_attempt", attempt)
    with pytest.raises(SolverError) as e:
        cd.solve("blocks", level=0, stress_space="eq")
    text, cli = str(e.value), e.value.cli
    for line in (text, cli):
        assert len(line) < SHORT, line
        assert "the fast path failed" in line and "CLARABEL" in line and "use the CVXPY path" not in line
        assert "try the fast path" not in line  # it failed first
