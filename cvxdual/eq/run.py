"""The run in the equilibrium stress space (docs/equilibrium.md): the P1 displacement of the P0
fast path, the exactly admissible equilibrium stresses of the same mesh (the fast route of
:mod:`cvxdual.eq.active_set` or the CVXPY model :class:`~cvxdual.eq.model.EquilibriumModel`), the
certified bounds between the two and the errors against an exact field, as one
:class:`~cvxdual.solution.Solution` (:class:`EquilibriumStresses`, a
:class:`~cvxdual.system.stress_space.StressSpace`). Its ``certify`` adds the same bounds to a P0 solution.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..convex.solvers import FAST, TIME_LIMIT_OPTION
from ..errors import SolverError
from ..kinds import Space
from ..progress import phase
from ..records import Bounds, CertifiedErrors, ExactErrors
from ..reference.exact import exact_reference
from ..solution import Solution, SolverStats, skipped_error
from ..system.kinematic import P2, KinematicSide
from ..system.p2_displacement import P2Displacement
from ..system.stress_space import Solved, StressSpace
from .bounds import (
    EQ_QUAD,
    certified_bounds,
    contact_slack,
    contact_tractions,
    edge_constraints,
    exact_errors,
)
from .contact import edge_contact
from .fields import EquilibriumField
from .kinematic_p2 import p2_slack
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


class EquilibriumStresses(StressSpace):
    """The equilibrium space: the P1 displacement of the fast path, then the exactly admissible
    stresses of the same mesh (the fast route, or a CVXPY solver), certified bounds between them;
    frictionless."""

    name = Space.EQ
    certifies = True

    def __init__(self, kinematic: KinematicSide | None = None):
        self.kinematic = kinematic or P2()  # the displacement of the bounds' upper side

    def build(self, system, triangulation: str) -> EquilibriumSpace:
        return EquilibriumSpace.from_pieces(system.mesh, system.pieces, triangulation)

    def describe(self, system, space) -> str:
        return (f"{system.n_dofs} dofs of the P1 displacement ({self.kinematic.name.upper()} for the bounds); "
                f"equilibrium space: {space.n_y} stress unknowns on "
                f"{3 * space.n_tri} sub-triangles" + (f" and {len(space.columns)} columns" if len(space.columns)
                                                      else ""))

    def default_solver(self, n_triangles: float) -> str:
        return FAST  # the same QP exactly, ~20x sooner than Clarabel (punch-on-block, level 2)

    def model(self, system, triangulation: str, limit_analysis: bool = False):
        from .model import EquilibriumModel  # loads CVXPY: only for a model
        return EquilibriumModel(self.build(system, triangulation), limit_analysis, system)

    def exact_error(self, sol: Solution, exact, rule: int | None = None):
        # the certificate's displacement (a P2 one is not its nodal values, sol.displacement)
        return error_summary(exact_errors(sol.space, sol.stress, sol.bounds["displacement"], exact,
                                          n=EQ_QUAD if rule is None else rule, g=sol.column_stress), sol.bounds)

    def zero(self, system, space):
        return np.zeros((3 * space.n_tri, 3, 3)), np.zeros((len(space.columns), 2))

    def solve(self, scene, triangulation, level, system, space, solver, warm_start, deadline, verbose,
              solver_options) -> Solved:
        name = "fast path" if solver == FAST else solver
        with phase("solve", deadline, start=f"the {self.kinematic.name.upper()} displacement, then the equilibrium "
                   f"stresses ({name})") as p:
            kin = self.kinematic.solve(scene, triangulation, level, system, solver, warm_start, deadline)
            if solver != FAST:
                solver_options = {"time_limit": deadline.remaining() if solver in TIME_LIMIT_OPTION else None,
                                  "verbose": verbose, **solver_options}
            try:
                sigma, g, stats = eq_stresses(space, solver, kin.pairs, **solver_options)
            except SolverError as e:
                raise sliver_error(space) or e from None
            p.detail = f"{stats.solver}: {stats.status}, iterations {stats.iterations}"
        return Solved(sigma, kin.u if kin.v is None else kin.v, stats, g)

    def recover(self, scene, triangulation, level, system, space, solved):
        return eq_solution(scene, triangulation, level, system, space, solved.stress, solved.column, solved.u,
                           solved.stats)

    def recovered(self, sol) -> str:
        return "exact admissibility, certified bounds" + (", error against the exact field" if sol.error else "")

    def certify(self, sol: Solution) -> Solution:
        """``sol`` (a P0 solution on a flat-face scene) with the certified bounds of its
        displacement against the equilibrium stresses of the same mesh (solved by the fast route
        whatever solved ``sol``: the same QP, exact), the time added to its recovery."""
        t0 = time.perf_counter()
        space = self.build(sol.system, sol.triangulation)
        pairs = (sol.mesh.pair_x, sol.contact["active"])
        sigma, g, _ = eq_stresses(space, FAST, pairs)
        bounds = certified_bounds(space, sigma, self.kinematic.certificate(sol.system, sol.displacement, pairs), g=g)
        dt = time.perf_counter() - t0
        timings = {**sol.timings, "recover": sol.timings["recover"] + dt, "total": sol.timings["total"] + dt}
        return replace(sol, bounds=bounds, space=space, timings=timings)


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


def nodal_values(v) -> np.ndarray:
    """``(n_nodes, 2)``: a certificate's displacement at the mesh's nodes (P1: itself)."""
    return v.vertices if isinstance(v, P2Displacement) else v


def error_summary(e: ExactErrors, bounds: Bounds) -> CertifiedErrors:
    """A solution's ``error`` entry from :func:`~cvxdual.eq.bounds.exact_errors` and its bounds."""
    return CertifiedErrors(l2=e["l2"], l2_rel=e["l2_rel"], energy=e["stress_A"],
                           energy_rel=e["stress_A"] / e["reference_A"], combined=e["combined"],
                           displacement_energy=e["displacement_a"], rule=e["rule"],
                           effectivity=bounds["error_bound"] / e["combined"] if e["combined"] > 0 else None)


def eq_solution(scene, triangulation, level, system, space, sigma, g, u, stats: SolverStats) -> Solution:
    """The eq run's :class:`Solution` (timings empty, no error against an exact field: the run adds
    it, :meth:`~cvxdual.system.stress_space.StressSpace.run`): bounds and residuals of ``sigma``,
    ``g`` and ``u``."""
    blocks = edge_constraints(space)
    b = certified_bounds(space, sigma, u.reshape(-1, 2) if isinstance(u, np.ndarray) else u, blocks=blocks, g=g)
    v = b["displacement"]
    nodal = nodal_values(v)
    res = dict(b["residuals"])
    sc = space.scales
    delta = max(float(np.abs(nodal).max()), float(np.abs(system.eps).max()), sc.displacement)
    smin = p2_slack(space, v)[1] if isinstance(v, P2Displacement) else contact_slack(space, v)[1]
    res = {"admissibility": max(res.values()), **res,
           "penetration": float(max(0.0, -smin.min(initial=0.0)) / delta)}
    exact, why = exact_reference(scene)
    energy = max(abs(b["energy_upper"]), abs(b["energy_lower"]), sc.energy * 1e-12)
    contact = edge_contact(system, -contact_tractions(space, sigma, blocks, g), nodal)
    return Solution(scene=scene, triangulation=triangulation, level=int(level), system=system,
                    field=EquilibriumField.of_space(space, sigma, g), displacement=nodal, solver=stats,
                    timings={},
                    objective=-b["energy_lower"], duality_gap=b["gap"] / energy, residuals=res, contact=contact,
                    exact=exact.data() if exact is not None else None, error=None, bounds=b, space=space,
                    checks=skipped_error(res, why))
