"""The kinematic side: the displacement that carries the certificate's upper bound and warm-starts
the stress solve. One small interface (:class:`KinematicSide`), so that a second side (P2 on the
Alfeld split) is one class; today :class:`P1`, the continuous P1 displacement of ``V_h``."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from enum import StrEnum
from typing import ClassVar

import numpy as np

from ..convex.solvers import FAST, TIME_LIMIT_OPTION
from ..errors import SolverError
from ..progress import Deadline
from .assembly import System
from .displacement import solve_fast
from .warm_start import warm_start_pairs


class Kinematic(StrEnum):
    """The kinematic sides, by the names users write."""

    P1 = "p1"


@dataclass(frozen=True, eq=False)  # arrays: identity, not elementwise ==
class KinematicSolution:
    """A displacement ``u`` ``(n_dofs,)`` and, where its solver found them, its active contact
    pairs ``(pair_x, active)`` (a warm start for the stress solve; None otherwise)."""

    u: np.ndarray
    pairs: tuple[np.ndarray, np.ndarray] | None


class KinematicSide(ABC):
    """A kinematically admissible displacement of a scene's discrete system."""

    name: ClassVar[Kinematic]

    @abstractmethod
    def solve(self, scene, triangulation: str, level: int, system: System, solver: str, warm_start: bool,
              deadline: Deadline) -> KinematicSolution:
        """The displacement of ``system``: by the fast path, and where that fails and ``solver`` is a
        CVXPY solver, by that solver."""


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
