"""The run in the equilibrium stress space (docs/equilibrium.md): the P1 displacement of the P0
fast path, the exactly admissible equilibrium stresses of the same mesh (the fast route of
:mod:`cvxdual.eq.active_set` or the CVXPY model :class:`~cvxdual.eq.model.EquilibriumModel`), the
certified bounds between the two and the errors against an exact field, as one
:class:`~cvxdual.solution.Solution`. :func:`certify` adds the same bounds to a P0 solution.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..convex.solvers import FAST, TIME_LIMIT_OPTION
from ..errors import SolverError
from ..geometry.triangulation import discretize
from ..progress import Deadline, phase
from ..reference.exact import exact_reference
from ..scene import Scene
from ..solution import Solution, SolverStats, check_solution, skipped_error
from ..system.assembly import assemble
from ..system.displacement import NOTHING_ACTS, nothing_acts, solve_fast
from ..system.warm_start import warm_start_pairs
from .bounds import (
    certified_bounds,
    contact_slack,
    contact_tractions,
    edge_constraints,
    exact_errors,
)
from .contact import edge_contact
from .space import EquilibriumSpace


def eq_stresses(space: EquilibriumSpace, solver: str, pairs: tuple | None = None,
                **solver_options) -> tuple[np.ndarray, np.ndarray, SolverStats]:
    """Exactly admissible stresses on ``space``: vertex values ``(n_sub, 3, 3)``, column values
    ``(n_col, 2)``, and the solver's statistics. The fast route starts from the active contact
    ``pairs = (x, active)`` of a P0 solve on the same mesh (one iteration when the P0 contact zone
    is right, a few more where P0 locks), or from the coarser levels without them."""
    if solver == FAST:
        from .active_set import active_from_pairs, solve_eq_fast
        start = None if pairs is None else active_from_pairs(space, *pairs)
        y, stats = solve_eq_fast(space, start)
        return space.stresses(y), space.column_values(y), stats
    from .model import EquilibriumModel  # loads CVXPY: only for the CVXPY path
    model = EquilibriumModel(space)
    stats = model.solve(solver, **solver_options)
    return model.stresses(), model.column_stresses(), stats


def certify(sol: Solution) -> Solution:
    """``sol`` (a P0 solution on a flat-face scene) with the certified bounds of its displacement
    against the equilibrium stresses of the same mesh (solved by the fast route whatever solved
    ``sol``: the same QP, exact), the time added to its recovery."""
    t0 = time.perf_counter()
    space = EquilibriumSpace.from_pieces(sol.mesh, sol.pieces, sol.triangulation)
    sigma, g, _ = eq_stresses(space, FAST, (sol.mesh.pair_x, sol.contact["active"]))
    bounds = certified_bounds(space, sigma, sol.displacement, g=g)
    dt = time.perf_counter() - t0
    timings = {**sol.timings, "recover": sol.timings["recover"] + dt, "total": sol.timings["total"] + dt}
    return replace(sol, bounds=bounds, space=space, timings=timings)


def solve_eq(scene: Scene, triangulation: str, level: int, solver: str, check: bool = True,
             warm_start: bool = True, deadline: Deadline | None = None, verbose: bool = False,
             **solver_options) -> Solution:
    """The "eq" run (see :func:`cvxdual.solve`): the displacement of ``V_h`` from the fast path,
    the equilibrium stresses on the same pieces (column stresses on the curved ones), the
    certified bounds between them and the errors against an exact field."""
    deadline = deadline or Deadline()
    t0 = time.perf_counter()
    with phase("mesh", deadline) as p:
        system = assemble(*discretize(scene, triangulation, level))
        p.detail = f"level {level}: {len(system.mesh.points)} nodes, {system.n_dofs} dofs of the P1 displacement"
    t1 = time.perf_counter()
    with phase("assemble", deadline) as p:
        space = EquilibriumSpace.from_pieces(system.mesh, system.pieces, triangulation)
        p.detail = (f"equilibrium space: {space.n_y} stress unknowns on {3 * space.n_tri} sub-triangles"
                    + (f" and {len(space.columns)} columns" if len(space.columns) else ""))
    t2 = time.perf_counter()
    if nothing_acts(system):  # zero stresses and displacements are the solution
        u = np.zeros(system.n_dofs)
        sigma, g = np.zeros((3 * space.n_tri, 3, 3)), np.zeros((len(space.columns), 2))
        stats = SolverStats(solver=NOTHING_ACTS, status="optimal", iterations=0)
    else:
        name = "fast path" if solver == FAST else solver
        with phase("solve", deadline, start=f"the P1 displacement, then the equilibrium stresses ({name})") as p:
            try:
                start = warm_start_pairs(scene, triangulation, level, system.mesh.pair_x) if warm_start else None
                u, p0_stats = solve_fast(system, start)
                pairs = (system.mesh.pair_x, p0_stats.active)
            except SolverError:
                if solver == FAST:
                    raise
                from ..system.primal import (
                    PrimalModel,  # the CVXPY path was asked for: the P1 displacement by CVXPY too
                )
                model = PrimalModel(system)
                model.solve(solver, time_limit=deadline.remaining() if solver in TIME_LIMIT_OPTION else None)
                u, pairs = model.displacements(), None
            if solver != FAST:
                solver_options = {"time_limit": deadline.remaining() if solver in TIME_LIMIT_OPTION else None,
                                  "verbose": verbose, **solver_options}
            try:
                sigma, g, stats = eq_stresses(space, solver, pairs, **solver_options)
            except SolverError as e:
                raise sliver_error(space) or e from None
            p.detail = f"{stats.solver}: {stats.status}, iterations {stats.iterations}"
    t3 = time.perf_counter()
    with phase("recover", deadline) as p:
        times = {"mesh": t1 - t0, "assemble": t2 - t1, "build": 0.0, "solve": t3 - t2}
        sol = eq_solution(scene, triangulation, level, system, space, sigma, g, u, stats, times)
        p.detail = "exact admissibility, certified bounds" + (", error against the exact field" if sol.error else "")
    if check:
        check_solution(sol)
    return sol


# (longest edge)^2 / area of a triangle past which the equilibrium space's local systems lose the
# digits exactness needs: a column 1e-3 wide beside 1.25-high layers (2500) made the condensed system
# indefinite (fast path) and Clarabel inaccurate; at 833 admissibility was 6e-10, at 250 1.7e-13
SLIVER = 500.0


def sliver_error(space: EquilibriumSpace) -> SolverError | None:
    """Where the mesh holds a sliver (:data:`SLIVER`), the error that names it and its fix, for a
    failed solve (a rounding failure, not the scene's: the P0 space solves such a mesh)."""
    X = space.X
    e2 = (np.diff(X, axis=1, append=X[:, :1]) ** 2).sum(2).max(1)
    a = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    ratio = e2 / np.maximum(0.5 * np.abs(a[0][:, 0] * a[1][:, 1] - a[0][:, 1] * a[1][:, 0]), 1e-300)
    k = int(np.argmax(ratio))
    if ratio[k] <= SLIVER:
        return None
    x, y = X[k].mean(0)
    why = (f"eq space: a sliver at ({x:.4g}, {y:.4g}) (edge^2/area {ratio[k]:.2g}, over {SLIVER:g}): break points "
           "in x (body ends, interval, focus) nearly coincide; make them equal or farther apart")
    return SolverError(f"{why}, or use stress_space='p0'", cli=f"{why}, or drop --stress-space eq", reason=why)


def error_summary(e: dict, bounds: dict) -> dict:
    """A solution's ``error`` entry from :func:`~cvxdual.eq.bounds.exact_errors` and its bounds."""
    return {"l2": e["l2"], "l2_rel": e["l2_rel"], "energy": e["stress_A"],
            "energy_rel": e["stress_A"] / e["reference_A"], "combined": e["combined"],
            "displacement_energy": e["displacement_a"], "rule": e["rule"],
            "effectivity": bounds["error_bound"] / e["combined"] if e["combined"] > 0 else None}


def eq_solution(scene, triangulation, level, system, space, sigma, g, u, stats: SolverStats,
                times: dict) -> Solution:
    """The eq run's :class:`Solution`: bounds, residuals and errors of ``sigma``, ``g`` and ``u``;
    ``times`` of the phases before (the recovery's and the total are added)."""
    t3 = time.perf_counter()
    blocks = edge_constraints(space)
    b = certified_bounds(space, sigma, u.reshape(-1, 2), blocks=blocks, g=g)
    v = b["displacement"]
    res = dict(b["residuals"])
    sc = space.scales
    delta = max(float(np.abs(v).max()), float(np.abs(system.eps).max()), sc.displacement)
    _, smin, _ = contact_slack(space, v)
    res = {"admissibility": max(res.values()), **res,
           "penetration": float(max(0.0, -smin.min(initial=0.0)) / delta)}
    exact, why = exact_reference(scene)
    error = None
    t_err = time.perf_counter()
    if exact is not None:
        error = error_summary(exact_errors(space, sigma, v, exact, g=g), b)
    t4 = time.perf_counter()
    t_err = t4 - t_err
    energy = max(abs(b["energy_upper"]), abs(b["energy_lower"]), sc.energy * 1e-12)
    contact = edge_contact(system, -contact_tractions(space, sigma, blocks, g), v)
    return Solution(scene=scene, triangulation=triangulation, stress_space="eq", level=int(level), system=system,
                    stress=sigma, displacement=v, solver=stats,
                    timings={**times, "recover": t4 - t3, "error": t_err, "total": sum(times.values()) + t4 - t3},
                    objective=-b["energy_lower"], duality_gap=b["gap"] / energy, residuals=res, contact=contact,
                    exact=exact.data() if exact is not None else None, error=error, bounds=b, space=space,
                    column_stress=g, checks=skipped_error(res, why))
