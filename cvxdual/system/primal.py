"""The primal cross-check: the displacement QP on the same ``V_h`` (docs/theory.md#discretisation).

``min 1/2 r.K_r r - g.r`` over ``r`` with ``r''_y(B_k) - r'_y(A_k) <= eps_k``, where
``K_r = Z^T K Z``, ``K = E A_h^-1 E^T``, ``g = Z^T f``; floating rigid motions are fixed at the
same anchor dofs the dual drops. Its stresses ``C_P B_P u_h`` must equal the dual's ``lam_h``.
Solved independently of the dual (its own CVXPY problem), in the same scaled units.
``stick`` (a boolean per pair) adds ``r''_x(B_k) - r'_x(A_k) = 0`` (no slip) at those pairs whose
``x`` dofs are free: the limit ``g -> inf`` of the dual's Tresca friction on them.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from ..convex.solvers import solve_problem
from ..errors import ModelError
from ..solution import SolverStats
from .assembly import System


class PrimalModel:
    """The displacement QP of ``system``; ``stick`` (``(n_pairs,)`` booleans) ties the
    tangential displacements of those pairs (named constraint ``stick``; pairs whose ``x`` dofs
    are fixed have no slip unknown and are skipped)."""

    def __init__(self, system: System, stick=None):
        self.system = system
        sc = system.scales
        delta = sc.displacement
        Z = system.Z
        K = (Z.T @ system.stiffness() @ Z).tocsr() / sc.modulus
        g = (Z.T @ system.f) / (sc.stress * sc.length)
        self.r = cp.Variable(system.n_r, name="r")
        cons = {"contact": self.r[system.jb] - self.r[system.ja] <= system.eps / delta}
        if stick is not None:
            n_pairs = len(system.mesh.pairs)
            mask = np.asarray(stick)
            if mask.dtype != bool or mask.shape != (n_pairs,):
                raise ModelError(f"stick must be {n_pairs} booleans (one per contact pair), got "
                                 f"{mask.dtype} of shape {mask.shape}")
            jxa, jxb, slides = system.pair_x_dofs
            k = mask & slides
            if k.any():
                cons["stick"] = self.r[jxb[k]] - self.r[jxa[k]] == 0
        if len(system.anchors):
            cons["anchors"] = self.r[system.anchors] == 0
        self.constraints = cons
        self.problem = cp.Problem(cp.Minimize(0.5 * cp.quad_form(self.r, K, assume_PSD=True) - g @ self.r),
                                  list(cons.values()))

    def solve(self, solver: str = "CLARABEL", **options) -> SolverStats:
        return solve_problem(self.problem, solver, "primal QP", **options)

    def displacements(self) -> np.ndarray:
        s = self.system
        return s.Z @ (s.scales.displacement * np.asarray(self.r.value))

    def contact_forces(self) -> np.ndarray:
        """Nodal contact forces from the multipliers of the non-penetration constraints."""
        sc = self.system.scales
        return sc.stress * sc.length * np.asarray(self.constraints["contact"].dual_value)
