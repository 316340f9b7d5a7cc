"""The paper's run in the P0 stress space (:class:`P0Stresses`, a
:class:`~cvxdual.system.stress_space.StressSpace`): scene -> mesh and pieces -> assembly -> the
CVXPY dual (:class:`~cvxdual.p0.dual.DualModel`) or its displacement form on the fast path
(:mod:`cvxdual.system.displacement`) -> a checked :class:`~cvxdual.solution.Solution`.

The fast path starts from the active set of level ``L - 2`` (:func:`warm_start_pairs`, through
:func:`cvxdual.activeset.core.coarse_start`), solved the same way.
"""

from __future__ import annotations

import time

import numpy as np

from ..convex.solvers import FAST, TIME_LIMIT_OPTION, default_solver
from ..kinds import Space
from ..progress import phase
from ..solution import Solution
from ..system.assembly import System
from ..system.displacement import solve_fast
from ..system.field import PieceField
from ..system.stress_space import Solved, StressSpace
from ..system.warm_start import warm_start_pairs
from .checks import evaluate
from .norms import DEFAULT_QUAD, stress_error


def dual_model(system: System, triangulation: str, limit_analysis: bool = False):
    """The :class:`~cvxdual.p0.dual.DualModel` of ``system`` with its scene's friction, if any."""
    from .dual import DualModel  # loads CVXPY: only for the CVXPY path
    model = DualModel(system, triangulation, limit_analysis)
    friction = system.mesh.scene.friction
    if friction is not None:
        model.add_friction(friction.g)
    return model


class P0Stresses(StressSpace):
    """The paper's space: the CVXPY dual with a CVXPY solver, or the fast path (``FAST``) on its
    displacement form, warm-started from level ``L - 2``; solves scenes with friction (CVXPY)."""

    name = Space.P0
    frictional = True

    def build(self, system: System, triangulation: str):
        return None

    def describe(self, system: System, built) -> str:
        return f"{3 * system.n_pieces} stress unknowns, {system.n_dofs} dofs, {len(system.jb)} contact pairs"

    def default_solver(self, n_triangles: float) -> str:
        return default_solver(n_triangles)

    def model(self, system: System, triangulation: str, limit_analysis: bool = False):
        return dual_model(system, triangulation, limit_analysis)

    def exact_error(self, sol: Solution, exact, rule: int | None = None):
        return stress_error(sol.system, sol.stress, exact.stress, DEFAULT_QUAD if rule is None else rule)

    def zero(self, system: System, built):
        return np.zeros((system.n_pieces, 3)), None

    def solve(self, scene, triangulation, level, system, built, solver, warm_start, deadline, verbose,
              solver_options) -> Solved:
        if solver == FAST:
            with phase("solve", deadline, start=f"fast path on {system.n_r} displacement unknowns") as p:
                t0 = time.perf_counter()
                active = warm_start_pairs(scene, triangulation, level, system.mesh.pair_x) if warm_start else None
                t_warm = time.perf_counter() - t0
                u, stats = solve_fast(system, active)
                # the warm start is part of the fast path's work: counted in "solve"
                stats = stats.replace(warm_start="coarse level" if warm_start else None, warm_start_time=t_warm,
                                      solve_time=stats.solve_time + t_warm)
                p.detail = (f"fast path: active-set iterations {stats.iterations}, factorisations "
                            f"{stats.factorizations} ({stats.backend}), of which the warm start {t_warm:.2f} s")
            return Solved(system.stresses_from_displacement(u), u, stats)
        t0 = time.perf_counter()
        with phase("build", deadline) as p:
            model = dual_model(system, triangulation)
            p.detail = "the CVXPY model; CVXPY compiles it at the start of the solve"
        t_built = time.perf_counter()
        limit = deadline.remaining() if solver in TIME_LIMIT_OPTION else None  # others: the alarm alone
        with phase("solve", deadline, start=f"{solver} on {3 * system.n_pieces} stress unknowns") as p:
            stats = model.solve(solver, time_limit=limit, verbose=verbose, **solver_options)
            p.detail = (f"{solver}: {stats.status}, iterations {stats.iterations}; of this time CVXPY's "
                        f"compile {stats.compile_time or 0.0:.2f} s, which the summary counts as build")
        # CVXPY canonicalises inside solve(); count that as building the problem
        build = t_built - t0 + (stats.compile_time or 0.0)
        # with friction the model's own rows and checks (docs/reformulate.md)
        own = model.solution(check=False) if scene.friction is not None else None
        return Solved(model.stresses(), model.displacements(), stats, build_time=build, solution=own)

    def recover(self, scene, triangulation, level, system, built, solved):
        fields = evaluate(system, solved.stress, solved.u, solved.stats, exact_error=False)
        del fields["timings"]  # the run times the error itself
        return Solution(triangulation=triangulation, level=int(level), timings={},
                        field=PieceField.of_system(system, fields.pop("stress")), **fields)
