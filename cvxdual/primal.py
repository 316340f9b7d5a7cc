"""The primal cross-check: the displacement QP on the same ``V_h`` (docs/theory.md#discretisation).

``min 1/2 r.K_r r - g.r`` over ``r`` with ``r''_y(B_k) - r'_y(A_k) <= eps_k``, where
``K_r = Z^T K Z``, ``K = E A_h^-1 E^T``, ``g = Z^T f``; floating rigid motions are fixed at the
same anchor dofs the dual drops. Its stresses ``C_P B_P u_h`` must equal the dual's ``lam_h``.
Solved independently of the dual (its own CVXPY problem), in the same scaled units.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from .assembly import System
from .solvers import solve_problem


class PrimalModel:
    def __init__(self, system: System):
        self.system = system
        sc = system.scales
        delta = sc.displacement
        Z = system.Z
        K = (Z.T @ system.stiffness() @ Z).tocsr() / sc.modulus
        g = (Z.T @ system.f) / (sc.stress * sc.length)
        self.r = cp.Variable(system.n_r, name="r")
        cons = {"contact": self.r[system.jb] - self.r[system.ja] <= system.eps / delta}
        if len(system.anchors):
            cons["anchors"] = self.r[system.anchors] == 0
        self.constraints = cons
        self.problem = cp.Problem(cp.Minimize(0.5 * cp.quad_form(self.r, K, assume_PSD=True) - g @ self.r),
                                  list(cons.values()))

    def solve(self, solver: str = "CLARABEL", **options) -> dict:
        return solve_problem(self.problem, solver, "primal QP", **options)

    def displacements(self) -> np.ndarray:
        s = self.system
        return s.Z @ (s.scales.displacement * np.asarray(self.r.value))

    def contact_forces(self) -> np.ndarray:
        """Nodal contact forces from the multipliers of the non-penetration constraints."""
        sc = self.system.scales
        return sc.stress * sc.length * np.asarray(self.constraints["contact"].dual_value)
