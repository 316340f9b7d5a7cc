"""The discrete dual problem as a CVXPY model (docs/theory.md#discretisation).

One stress Variable ``t`` for all pieces; the admissibility ``<lam_h, e(v_h)> >= L(v_h)``
for all ``v_h`` in the cone ``K0h`` is written through the cone's generators (the paper's
(3.5), (3.6)): with ``H = T^T Z^T E`` and ``h = T^T Z^T f``,

- ``equilibrium``: ``H[J0] t == h[J0]`` (generators ``+-e_j``, ``j`` in ``J0``),
- ``contact``: ``H[J-] t <= h[J-]`` (generators ``-e_m``: compressive contact forces),

and the objective is ``1/2 t.A_h t - t.E^T q0``. The model is nondimensionalised (lengths
by ``L``, stiffness by ``E_ref``, stresses by ``sigma_ref``; see :class:`~cvxdual.assembly.Scales`)
so that Pa/m and MPa/mm scenes give the same QP. ``stress`` is the physical stress
expression, for constraints a user adds.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np

from .assembly import System
from .solvers import solve_problem


class DualModel:
    """The CVXPY problem of the discrete dual, with named handles.

    Attributes: ``t`` (scaled stress Variable, ``3 n_pieces``), ``stress`` (physical stresses,
    an ``(n_pieces, 3)`` expression), ``constraints`` (``{"equilibrium", "contact"}``),
    ``extra`` (user constraints), ``problem`` (the :class:`cvxpy.Problem`).
    """

    def __init__(self, system: System):
        self.system = system
        sc = system.scales
        L, E0, s0 = sc.length, sc.modulus, sc.stress
        T = system.T
        ZT = system.Z.T.tocsr()
        H = (T.T @ (ZT @ system.E)).tocsr() / L
        h = (T.T @ (ZT @ system.f)) / (s0 * L)
        self.J0, self.Jm = system.index_sets
        A = (system.Ah * (E0 / L**2)).tocsr()
        c = (system.E.T @ system.q0) * (E0 / (s0 * L**2))
        n_p = system.n_pieces
        self.t = cp.Variable(3 * n_p, name="t")
        self.constraints = {
            "equilibrium": H[self.J0] @ self.t == h[self.J0],
            "contact": H[self.Jm] @ self.t <= h[self.Jm],
        }
        self.objective = cp.Minimize(0.5 * cp.quad_form(self.t, A, assume_PSD=True) - c @ self.t)
        self.extra: list[cp.Constraint] = []
        self.stress = s0 * cp.reshape(self.t, (n_p, 3), order="C")
        self._H, self._h, self._A, self._c = H, h, A, c
        self.problem = cp.Problem(self.objective, list(self.constraints.values()))

    def add_constraint(self, *constraints: cp.Constraint) -> cp.Problem:
        """Add convex constraints (e.g. on :attr:`stress`) and rebuild :attr:`problem`."""
        self.extra.extend(constraints)
        self.problem = cp.Problem(self.objective, [*self.constraints.values(), *self.extra])
        return self.problem

    def solve(self, solver: str = "CLARABEL", **options) -> dict:
        return solve_problem(self.problem, solver, "dual QP", **options)

    # -- results in physical units ------------------------------------------------------
    def stresses(self) -> np.ndarray:
        """``(n_pieces, 3)`` Voigt stresses of the last solve."""
        return self.system.scales.stress * np.asarray(self.t.value).reshape(-1, 3)

    def displacements(self) -> np.ndarray:
        """Nodal displacements ``u_h = Z (r0 - T y*)`` from the multipliers ``y*``
        (docs/theory.md#recovery-and-checks)."""
        s = self.system
        y = np.zeros(s.n_r)
        y[self.J0] = self.constraints["equilibrium"].dual_value
        y[self.Jm] = self.constraints["contact"].dual_value
        r = s.r0 - s.scales.displacement * (s.T @ y)
        return s.Z @ r

