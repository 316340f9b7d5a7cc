"""The active-set core shared by both fast solvers: a primal-dual active set method
(semismooth Newton; Hintermueller, Ito and Kunisch 2002) for a convex QP whose inequality
constraints are the contact unknowns: the pairs of the P0 displacement form
(:mod:`cvxdual.system.displacement`) or the contact parameters of the equilibrium dual (:mod:`cvxdual.eq.active_set`).

A solver brings its linear algebra as an :class:`ActiveSetSolver`: ``solve_set(A)`` solves the
equality-constrained QP of the active set ``A`` (a boolean array over the contact unknowns) and
``next_set(A, state)`` reads the next set off that solution (keep the compressive ones, add the
penetrating ones; each solver knows its own signs and rounding). :func:`iterate` runs the
method to its fixed point, which makes the result exact up to the linear solves, with one
iteration limit and one cycle test for both. :func:`cover` completes a set that would leave a
body floating; :func:`coarse_start` and :func:`transfer_active` give the initial set from the
solution two levels coarser.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from ..errors import SolverError

log = logging.getLogger("cvxdual.activeset")

# Iterations before giving up (the two solvers had 60 and 50). Warm starts take 1-4 and cold
# starts about 10 on the built-in scenes (tests/test_fast.py, tests/test_eqfast.py): the limit
# leaves room for hard meshes without letting a stalled run go on.
MAX_ITER = 60


@dataclass
class ActiveSetStats:
    """Counters of one active-set solve, kept by the solver while it runs. ``schur_updates``,
    ``max_update`` and ``refinements`` are the P0 solver's (changes of the set solved with a kept
    factorisation, the largest such change, iterative refinement steps); the equilibrium
    solver factorises once per iteration."""

    iterations: int = 0
    factorizations: int = 0
    factor_time: float = 0.0  # seconds in factorisations and their solves
    backend: str | None = None  # of the last factorisation (cvxdual.linalg.factor)
    schur_updates: int = 0
    max_update: int = 0
    refinements: int = 0


class ActiveSetSolver(Protocol):
    """What :func:`iterate` needs of a solver."""

    what: str  # how messages name the solver, e.g. "fast path"
    advice: tuple[str, str]  # what to do instead, for Python callers and for the command line
    stats: ActiveSetStats

    def solve_set(self, A: np.ndarray):
        """The solution of the equality-constrained QP of the active set ``A`` (any object)."""

    def next_set(self, A: np.ndarray, state) -> np.ndarray:
        """The next active set from the solution ``state`` of set ``A``."""


def _stuck(solver: ActiveSetSolver, why: str) -> SolverError:
    api, cli = solver.advice
    reason = f"{solver.what}: {why}"
    return SolverError(f"{reason}; {api}", cli=f"{reason}; {cli}", reason=reason)


def iterate(solver: ActiveSetSolver, A: np.ndarray) -> tuple[np.ndarray, object]:
    """Iterate from the set ``A`` to the set that reproduces itself; return it and its solution.
    A set seen before (the start included) is a cycle: a solver with a ``one_change(A, state)``
    step goes on from there one change at a time (the full update swaps whole sets where few
    unknowns decide, e.g. a punch touching at one pair); a second cycle, or one without such a
    step, is reported with the solver's advice, as is no fixed point in :data:`MAX_ITER` iterations."""
    A = np.asarray(A, bool)
    seen = {A.tobytes()}
    step = solver.next_set
    for it in range(1, MAX_ITER + 1):
        state = solver.solve_set(A)
        new = step(A, state)
        solver.stats.iterations = it
        log.debug("%s: iteration %d, %d active, %d change", solver.what, it, int(A.sum()), int((new != A).sum()))
        if np.array_equal(new, A):
            return A, state
        if new.tobytes() in seen:
            if step != solver.next_set or not hasattr(solver, "one_change"):
                raise _stuck(solver, f"the active set cycles after {it} iterations")
            step, seen = solver.one_change, {A.tobytes()}
            new = step(A, state)
            if np.array_equal(new, A):
                return A, state
        seen.add(new.tobytes())
        A = new
    raise _stuck(solver, f"no convergence in {MAX_ITER} active-set iterations")


def worst_flipped(A: np.ndarray, release: np.ndarray, add: np.ndarray) -> np.ndarray:
    """``A`` with one unknown changed: the active one with the largest ``release`` violation (a
    pull) or the inactive one with the largest ``add`` violation (a penetration), whichever is
    larger (both relative to their fields' scales, as the caller gives them); ``A`` itself if
    neither is positive. The damped step of a ``one_change`` (see :func:`iterate`)."""
    r, a = np.where(A, np.maximum(release, 0.0), 0.0), np.where(~A, np.maximum(add, 0.0), 0.0)
    out = A.copy()
    if max(r.max(initial=0.0), a.max(initial=0.0)) > 0:
        k = int(np.argmax(r)) if r.max() >= a.max() else int(np.argmax(a))
        out[k] = not A[k]
    return out


def cover(A: np.ndarray, closeness: np.ndarray, jumps: np.ndarray) -> np.ndarray:
    """``A`` plus, if needed, the closest unknowns (smallest ``closeness``) that stop every motion
    separating the bodies. ``jumps (n, m)``: the relative normal motion at each contact unknown
    under each of the ``m`` rigid motions the supports allow a body; a body held only by contact
    needs active unknowns whose rows span these motions, or the set's system is singular. Greedy
    by closeness, each added unknown raising the rank (a few candidates: it stops at the rank)."""
    A = np.array(A, bool)
    if jumps.shape[1] == 0:
        return A
    scale = max(float(np.abs(jumps).max(initial=0.0)), 1e-300)
    rank = lambda rows: np.linalg.matrix_rank(rows, tol=1e-9 * scale) if len(rows) else 0  # noqa: E731
    need, r = rank(jumps), rank(jumps[A])
    for k in np.argsort(closeness, kind="stable"):
        if r == need:
            break
        if not A[k] and rank(jumps[A | (np.arange(len(A)) == k)]) > r:
            A[k], r = True, r + 1
    return A


def transfer_active(coarse_x: np.ndarray, coarse_active: np.ndarray, fine_x: np.ndarray) -> np.ndarray:
    """Initial active set at abscissae ``fine_x`` (any shape) from a coarser solution's sorted
    ``coarse_x`` and ``coarse_active``: the coarse set, its edges put halfway to the first
    inactive coarse point (the best guess a coarse solution gives)."""
    return np.interp(fine_x, coarse_x, np.asarray(coarse_active, float)) >= 0.5


Coarse = tuple[np.ndarray, np.ndarray]  # (sorted abscissae, active flags) of a converged coarse set


def coarse_start(level: int, solve_at: Callable[[int, Coarse | None], Coarse | None]) -> Coarse | None:
    """The converged active set of level ``level - 2``, as ``(x, active)`` (transfer it with
    :func:`transfer_active`), or ``None`` below level 2. ``solve_at(lv, coarser)`` solves level
    ``lv`` started from the set ``coarser`` of level ``lv - 2`` (``None``: a cold start) and
    returns its set, or ``None`` where that level gives no hint (no load, a failed solve). The
    chain runs from level 0 or 1 upwards, so every level is warm-started by the one two below:
    from all-in-contact or the first touching pairs the set changes by a few unknowns per
    iteration (~10 iterations at any level), from the coarse set, at 1/16 of the cost, by 1-2."""
    coarse = None
    for lv in range(level % 2, level - 1, 2):
        coarse = solve_at(lv, coarse)
    return coarse
