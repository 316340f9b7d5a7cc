"""CVXPY's internal calls that cvxdual makes (cvxdual/convex/cvxpy_internals.py, the load sweep's
cached re-solve): each must exist and behave as used. When a CVXPY release changes one of them,
this file fails first, naming the call, before any solve goes wrong."""

import cvxpy as cp
import numpy as np
import pytest

from cvxdual.convex import cvxpy_internals as internals


def _problem():
    """A small conic problem with a DPP parameter in the right-hand side only, like the load factor."""
    x = cp.Variable(3)
    lf = cp.Parameter(nonneg=True, value=1.0)
    A = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]])
    cons = [A @ x == lf * np.array([1.0, 2.0]), x >= -1.0]
    return cp.Problem(cp.Minimize(cp.sum_squares(x) + x[0]), cons), x, lf


def test_conic_solvers_list_has_clarabel():
    names = internals.conic_solvers()
    assert "CLARABEL" in names and "SCS" in names, "cvxpy.reductions.solvers.defines.CONIC_SOLVERS changed"


def test_problem_data_is_conic_with_a_right_hand_side():
    prob, _, _ = _problem()
    data, chain, inverse = internals.problem_data(prob, "CLARABEL", {})
    assert internals.is_conic(chain), "the chain's solver is no longer a ConicSolver (chain.solver)"
    assert internals.rhs_key() in data, "conic solver data have no right-hand side under cvxpy.settings.B"
    assert {"A", "c"} <= set(data), "conic solver data lost A or c"


@pytest.mark.parametrize("value", [1.0, 0.3])
def test_solving_kept_data_with_a_new_rhs_matches_cvxpy(value):
    """The sweep's trick: data at 0 and at 1 differ in ``b`` only, so ``b(lf) = b0 + lf b1`` solved
    through ``solve_via_data`` and ``unpack_results`` gives what ``Problem.solve`` gives."""
    prob, x, lf = _problem()
    key = internals.rhs_key()
    lf.value = 1.0
    data, chain, inverse = internals.problem_data(prob, "CLARABEL", {})
    lf.value = 0.0
    zero = internals.problem_data(prob, "CLARABEL", {})[0]
    for k in data:
        if k != key and isinstance(data[k], np.ndarray):
            assert np.array_equal(data[k], zero[k]), f"solver data {k!r} depend on a right-hand-side parameter"
    lf.value = value
    internals.solve_data(prob, chain, {**data, key: zero[key] + value * (data[key] - zero[key])}, inverse, False, {})
    assert prob.status == "optimal", "Problem.unpack_results no longer sets the status"
    kept = np.array(x.value)
    assert prob.constraints[0].dual_value is not None, "Problem.unpack_results no longer sets the multipliers"
    prob.solve(solver="CLARABEL")
    # both are Clarabel's solve of the same data: equal to its tolerance (1e-8), far below 1e-6
    np.testing.assert_allclose(kept, x.value, atol=1e-6)
