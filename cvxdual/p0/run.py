"""The paper's run in the P0 stress space: scene -> mesh and pieces -> assembly -> the CVXPY dual
(:class:`~cvxdual.p0.dual.DualModel`) or its displacement form on the fast path
(:mod:`cvxdual.system.displacement`) -> a checked :class:`~cvxdual.solution.Solution`.

The fast path starts from the active set of level ``L - 2`` (:func:`warm_start_pairs`, through
:func:`cvxdual.activeset.core.coarse_start`), solved the same way.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np

from ..convex.solvers import FAST, TIME_LIMIT_OPTION
from ..geometry.triangulation import discretize
from ..progress import Deadline, phase
from ..scene import Scene
from ..solution import Solution, SolverStats, check_solution
from ..system.assembly import System, assemble
from ..system.displacement import NOTHING_ACTS, nothing_acts, solve_fast
from ..system.warm_start import warm_start_pairs
from .checks import evaluate

log = logging.getLogger(__name__)

def dual_model(system: System, triangulation: str, limit_analysis: bool = False):
    """The :class:`~cvxdual.p0.dual.DualModel` of ``system`` with its scene's friction, if any."""
    from .dual import DualModel  # loads CVXPY: only for the CVXPY path
    model = DualModel(system, triangulation, limit_analysis)
    friction = system.mesh.scene.friction
    if friction is not None:
        model.add_friction(friction.g)
    return model


def solve_p0(scene: Scene, triangulation: str, level: int, solver: str, check: bool = True,
             warm_start: bool = True, deadline: Deadline | None = None, verbose: bool = False,
             **solver_options) -> Solution:
    """The P0 run (see :func:`cvxdual.solve`): the CVXPY dual with ``solver``, or the fast path
    (``solver == "FAST"``) warm-started from level ``level - 2`` unless ``warm_start`` is false."""
    deadline = deadline or Deadline()
    t0 = time.perf_counter()
    with phase("mesh", deadline) as p:
        mesh, pieces, ties = discretize(scene, triangulation, level)
        p.detail = f"{triangulation}, level {level}: {len(mesh.points)} nodes, {len(pieces.kind)} pieces"
    t1 = time.perf_counter()
    with phase("assemble", deadline) as p:
        system = assemble(mesh, pieces, ties)
        p.detail = f"{3 * system.n_pieces} stress unknowns, {system.n_dofs} dofs, {len(system.jb)} contact pairs"
    t2 = time.perf_counter()
    build = 0.0
    if nothing_acts(system):
        u = np.zeros(system.n_dofs)
        t = np.zeros((system.n_pieces, 3))
        stats = SolverStats(solver=NOTHING_ACTS, status="optimal", iterations=0)
    elif solver == FAST:
        with phase("solve", deadline, start=f"fast path on {system.n_r} displacement unknowns") as p:
            active = warm_start_pairs(scene, triangulation, level, mesh.pair_x) if warm_start else None
            t_warm = time.perf_counter() - t2
            u, stats = solve_fast(system, active)
            # the warm start is part of the fast path's work: counted in "solve"
            stats = stats.replace(warm_start="coarse level" if warm_start else None, warm_start_time=t_warm,
                                  solve_time=stats.solve_time + t_warm)
            t = system.stresses_from_displacement(u)
            p.detail = (f"fast path: active-set iterations {stats.iterations}, factorisations "
                        f"{stats.factorizations} ({stats.backend}), of which the warm start {t_warm:.2f} s")
    else:
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
        build = t_built - t2 + (stats.compile_time or 0.0)
        if scene.friction is not None:  # the model's own rows and checks (docs/reformulate.md)
            t3 = time.perf_counter()
            with phase("recover", deadline) as p:
                sol = model.solution(check=False)
                p.detail = "displacements from the multipliers, residuals"
            t4 = time.perf_counter()
            sol = replace(sol, timings={"mesh": t1 - t0, "assemble": t2 - t1, "build": build, "solve": t3 - t2 - build,
                                        "recover": t4 - t3, "error": 0.0, "total": t4 - t0})
            if check:
                check_solution(sol)  # the checks the model applied, with advice for solve() and the CLI
            return sol
        t, u = model.stresses(), model.displacements()
    t4 = time.perf_counter()
    with phase("recover", deadline) as p:
        fields = evaluate(system, t, u, stats)
        p.detail = "residuals" + (", error against the exact field" if fields["error"] is not None else "")
    t5 = time.perf_counter()
    timings = {"mesh": t1 - t0, "assemble": t2 - t1, "build": build, "solve": t4 - t2 - build,
               "recover": t5 - t4, "error": fields.pop("timings")["error"], "total": t5 - t0}
    sol = Solution(triangulation=triangulation, stress_space="p0", level=int(level), timings=timings, **fields)
    if check:
        check_solution(sol)
    return sol
