"""The interface of a stress space (docs/theory.md): one run template, the same phases and timings
for every space, and the steps each space fills in.

:meth:`StressSpace.run` meshes and assembles the discrete system (phases ``mesh``, ``assemble``),
lets the space build its own unknowns on it (:meth:`~StressSpace.build`), solves
(:meth:`~StressSpace.solve`: phases ``solve`` and, on the CVXPY path, ``build``), recovers the
:class:`~cvxdual.solution.Solution` (:meth:`~StressSpace.recover`, phase ``recover``) and checks
it. Where nothing acts (no load, no interference) zero stresses are the solution and nothing is
solved. A space declares what it offers as class attributes, as CVXPY's solver classes do:
``certifies`` (certified bounds of its own), ``frictional`` (scenes with friction)."""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ..convex.solvers import FAST
from ..geometry.grid import Grid
from ..geometry.triangulation import discretize
from ..kinds import Space, Status
from ..progress import Deadline, phase
from ..reference.exact import exact_reference
from ..solution import Solution, SolverStats, check_solution
from .assembly import System, assemble
from .displacement import NOTHING_ACTS, nothing_acts


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class Solved:
    """What a space's :meth:`~StressSpace.solve` gives its :meth:`~StressSpace.recover`: the stresses
    (the space's layout), the column stresses where the space has them, the displacement of the
    kinematic side ``u`` (P1: ``(n_dofs,)``; P2: a ``P2Displacement``), the solver's statistics, the
    time spent building a CVXPY problem, and a finished solution where a CVXPY model recovers its own
    (friction)."""

    stress: np.ndarray
    u: object
    stats: SolverStats
    column: np.ndarray | None = None
    build_time: float = 0.0
    solution: Solution | None = None


class StressSpace(ABC):
    """A stress space's run; subclasses fill in :meth:`build`, :meth:`zero`, :meth:`solve` and
    :meth:`recover`, and :meth:`certify` where they can."""

    name: ClassVar[Space]
    certifies: ClassVar[bool] = False
    frictional: ClassVar[bool] = False

    def run(self, scene, triangulation: str, level: int | Grid, solver: str, check: bool = True,
            warm_start: bool = True, deadline: Deadline | None = None, verbose: bool = False,
            exact_error: bool = True, **solver_options) -> Solution:
        """Mesh, assemble, build, solve with ``solver`` (warm-started from level ``level - 2``, or on an
        adaptive :class:`~cvxdual.geometry.grid.Grid` from its last cycle, unless ``warm_start`` is
        false), recover and (unless ``check`` is false) check. ``exact_error`` false leaves the error
        against the scene's exact field out (a cycle of a run to a tolerance: :meth:`with_exact_error`
        adds it to the one solution returned)."""
        deadline = deadline or Deadline()
        t0 = time.perf_counter()
        with phase("mesh", deadline) as p:
            mesh, pieces, ties = discretize(scene, triangulation, level)
            on = f"adaptive grid from level {mesh.level}" if isinstance(level, Grid) else f"level {level}"
            p.detail = f"{triangulation}, {on}: {len(mesh.points)} nodes, {len(pieces.kind)} pieces"
        t1 = time.perf_counter()
        with phase("assemble", deadline) as p:
            system = assemble(mesh, pieces, ties)
            built = self.build(system, triangulation)
            p.detail = self.describe(system, built)
        t2 = time.perf_counter()
        if nothing_acts(system):  # zero stresses and displacements are the solution
            stress, column = self.zero(system, built)
            solved = Solved(stress, np.zeros(system.n_dofs),
                            SolverStats(solver=NOTHING_ACTS, status=Status.OPTIMAL, iterations=0), column)
        else:
            solved = self.solve(scene, triangulation, level, system, built, solver, warm_start, deadline, verbose,
                                solver_options)
        t3 = time.perf_counter()
        with phase("recover", deadline) as p:
            sol = solved.solution if solved.solution is not None else \
                self.recover(scene, triangulation, system.mesh.level, system, built, solved)
            t_error = 0.0
            if exact_error:
                error, t_error = self._exact_error(sol)
                sol = replace(sol, error=error)
            p.detail = self.recovered(sol)
        t4 = time.perf_counter()
        sol = replace(sol, timings={"mesh": t1 - t0, "assemble": t2 - t1, "build": solved.build_time,
                                    "solve": t3 - t2 - solved.build_time, "recover": t4 - t3, "error": t_error,
                                    "total": t4 - t0})
        if check:
            check_solution(sol)
        return sol

    @abstractmethod
    def build(self, system: System, triangulation: str):
        """The space's own discrete objects on ``system`` (None where the system is all it needs)."""

    def describe(self, system: System, built) -> str:
        """The progress line of the ``assemble`` phase."""
        return f"{system.n_dofs} dofs, {len(system.jb)} contact pairs"

    @abstractmethod
    def zero(self, system: System, built) -> tuple[np.ndarray, np.ndarray | None]:
        """Zero stresses and column stresses (None where the space has none) in the space's layout."""

    @abstractmethod
    def solve(self, scene, triangulation: str, level: int, system: System, built, solver: str, warm_start: bool,
              deadline: Deadline, verbose: bool, solver_options: dict) -> Solved:
        """The stresses and the P1 displacement (phases ``solve`` and ``build``)."""

    @abstractmethod
    def recover(self, scene, triangulation: str, level: int, system: System, built, solved: Solved) -> Solution:
        """The solution (timings left empty) without its error against an exact field (:meth:`run` adds it)."""

    def recovered(self, sol: Solution) -> str:
        """The progress line of the ``recover`` phase."""
        return "residuals" + (", error against the exact field" if sol.error is not None else "")

    def default_solver(self, n_triangles: float) -> str:
        """The solver of a run that names none, for a mesh of about ``n_triangles``."""
        return FAST

    @abstractmethod
    def model(self, system: System, triangulation: str, limit_analysis: bool = False):
        """The space's CVXPY model of ``system``, built, not solved."""

    @abstractmethod
    def exact_error(self, sol: Solution, exact, rule: int | None = None):
        """The error of ``sol``'s stresses against the exact field ``exact`` with ``rule*rule`` Gauss
        points per cell: the definition the run's own ``error`` uses (at its default rule, ``None``)."""

    def with_exact_error(self, sol: Solution) -> Solution:
        """``sol`` (run with ``exact_error`` false) with its error against the scene's exact field, as
        its run would have given it, the time added to its ``error``, ``recover`` and ``total``."""
        error, dt = self._exact_error(sol)
        timings = {**sol.timings, **{k: sol.timings[k] + dt for k in ("error", "recover", "total")}}
        return replace(sol, error=error, timings=timings)

    def _exact_error(self, sol: Solution) -> tuple:
        """``sol``'s error against its scene's exact field (``None`` where none solves it) and its seconds;
        one it already has is kept (a CVXPY model's own solution)."""
        exact, _ = exact_reference(sol.scene)
        if exact is None or sol.error is not None:
            return sol.error, 0.0
        t0 = time.perf_counter()
        return self.exact_error(sol, exact), time.perf_counter() - t0

    def certify(self, sol: Solution) -> Solution:
        """``sol`` with certified bounds of its displacement, where the space can give them."""
        raise NotImplementedError(f"the {self.name} space certifies no bounds")
