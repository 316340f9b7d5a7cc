"""The kinematic side: the displacement that carries the certificate's upper bound and warm-starts
the stress solve. One small interface (:class:`KinematicSide`): :class:`P1`, the continuous P1
displacement of ``V_h``, and :class:`P2`, continuous P2 on the Alfeld split
(:mod:`cvxdual.system.p2_system`), which does not lock and is as accurate as the equilibrium stresses."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..convex.solvers import FAST, TIME_LIMIT_OPTION
from ..errors import SolverError
from ..kinds import Kinematic
from ..progress import Deadline
from .assembly import System
from .displacement import solve_fast
from .p2_displacement import P2Displacement
from .p2_system import assemble_p2_system
from .warm_start import warm_start_pairs


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class KinematicSolution:
    """A displacement ``u`` ``(n_dofs,)`` (P1 nodal values) and, where its solver found them, its
    active contact pairs ``(pair_x, active)`` (a warm start for the stress solve; None otherwise);
    ``v`` the displacement of the certificate where it is not ``u`` (a :class:`P2Displacement`)."""

    u: np.ndarray
    pairs: tuple[np.ndarray, np.ndarray] | None
    v: P2Displacement | None = None


class KinematicSide(ABC):
    """A kinematically admissible displacement of a scene's discrete system."""

    name: ClassVar[Kinematic]

    @abstractmethod
    def solve(self, scene, triangulation: str, level: int, system: System, solver: str, warm_start: bool,
              deadline: Deadline) -> KinematicSolution:
        """The displacement of ``system``: by the fast path, and where that fails and ``solver`` is a
        CVXPY solver, by that solver."""

    @abstractmethod
    def certificate(self, system: System, u: np.ndarray, pairs: tuple[np.ndarray, np.ndarray] | None):
        """The displacement that carries the certificate, given a P1 displacement ``u`` of ``system``
        and its active pairs (a P0 run's, for its bounds)."""


class P1(KinematicSide):
    """The continuous P1 displacement on the mesh's nodes: the fast path's displacement form
    (warm-started from level ``level - 2``), or the displacement QP by CVXPY where the fast path
    fails and a CVXPY solver was asked for."""

    name = Kinematic.P1

    def solve(self, scene, triangulation, level, system, solver, warm_start, deadline) -> KinematicSolution:
        try:
            start = warm_start_pairs(scene, triangulation, level, system.mesh.pair_x) if warm_start else None
            u, stats = solve_fast(system, start)
            return KinematicSolution(u, (system.mesh.pair_x, stats.active))
        except SolverError:
            if solver == FAST:
                raise
            from .primal import PrimalModel  # the CVXPY path was asked for: the displacement by CVXPY too
            model = PrimalModel(system)
            model.solve(solver, time_limit=deadline.remaining() if solver in TIME_LIMIT_OPTION else None)
            return KinematicSolution(model.displacements(), None)

    def certificate(self, system, u, pairs) -> np.ndarray:
        return np.asarray(u, float).reshape(-1, 2)


class P2(KinematicSide):
    """Continuous P2 on the Alfeld split of the mesh's triangles (:mod:`cvxdual.system.p2_system`),
    solved by the fast path from the active set of the P1 displacement (solved first: cheap, and the
    stress solve's warm start); the P1 displacement is kept as ``u``."""

    name = Kinematic.P2

    def solve(self, scene, triangulation, level, system, solver, warm_start, deadline) -> KinematicSolution:
        p1 = P1().solve(scene, triangulation, level, system, solver, warm_start, deadline)
        return KinematicSolution(p1.u, p1.pairs, self.certificate(system, p1.u, p1.pairs))

    def certificate(self, system, u, pairs) -> P2Displacement:
        """The P2 displacement of ``system`` by the fast path, from the active ``pairs`` of a P1 or P0
        solve (a midpoint pair starts closed where both its ends are), or cold without them."""
        ps = assemble_p2_system(system)
        start = None
        if pairs is not None:
            a1 = np.asarray(pairs[1], bool)
            start = np.zeros(len(ps.jb), bool)
            start[0::2] = a1
            start[1::2] = a1[:-1] & a1[1:]
        q, _ = solve_fast(ps, start)
        return P2Displacement(ps.layout, q.reshape(-1, 2), ps.interior(q))


SIDES = {Kinematic.P1: P1, Kinematic.P2: P2}


def kinematic_side(name) -> KinematicSide:
    """The :class:`KinematicSide` named ``name`` (``"p1"`` or ``"p2"``)."""
    return SIDES[Kinematic.parse(name)]()
