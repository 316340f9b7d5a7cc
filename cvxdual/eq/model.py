"""The dual problem on the equilibrium stress space as a CVXPY modelling object
(docs/equilibrium.md, docs/reformulate.md).

``sigma = S y + load_factor sigma0`` at the vertices of every sub-triangle (Johnson-Mercier,
:class:`~cvxdual.eq.space.EquilibriumSpace`): tractions are continuous and the boundary
data hold by construction; the rows are ``div sigma + load_factor F = 0`` and compressive
frictionless contact ``sigma_nn <= 0``. The default objective is ``S(sigma) + L(u0)``: the
complementary energy with the gap term. After every solve the field is made exactly
admissible (:func:`~cvxdual.eq.balance.make_exact`, per unit load), so its stresses are
statically admissible to rounding whatever the user changed: a user's convex constraint on
them (``shear_cap(k)``) holds at the vertices, where a convex function of a linear
field is largest, hence everywhere.
"""

from __future__ import annotations

import time

import cvxpy as cp
import numpy as np

from ..convex.base import USER_TOLERANCE, ConvexModel
from ..errors import AccuracyError, ModelError
from ..kinds import Status
from ..records import Checks
from ..solution import EQ_TOLERANCES, Solution, SolverStats, failed_checks
from ..voigt import out_of_plane_factor
from .balance import make_exact
from .contact import edge_contact
from .fields import EquilibriumField
from .space import EquilibriumSpace


class EquilibriumModel(ConvexModel):
    """The equilibrium-space dual with named handles: ``y`` (parameters over the stress scale),
    ``load_factor``, ``constraints`` (``equilibrium``, ``contact``), ``problem``; expressions
    ``stress`` ``(9 n_T, 3)`` (Voigt values at the vertices of sub-triangle ``3 t + i``, in the
    order of :meth:`EquilibriumSpace.stresses`), ``vertex_body``, ``contact_pressure``
    ``(n_c, 2)`` (at both ends of each contact edge), ``total_contact_force``,
    :meth:`shear_stress`, :meth:`von_mises` (per vertex). ``limit_analysis=True``: no energy,
    ``load_factor`` a Variable, maximised (the static theorem; its values are lower bounds once
    the field is exact and inside the yield set).

    An interior-point solver may stop at ``optimal_inaccurate`` on the degenerate problems of
    limit analysis; that status is accepted there (only) because :meth:`solve` makes the field
    exact and :meth:`solution` checks it and the user's constraints at that exact field, and a
    load factor short of the optimum is still a lower bound.
    """

    what = "equilibrium dual"

    def __init__(self, space: EquilibriumSpace, limit_analysis: bool = False, system=None):
        self._start(limit_analysis)
        # limit analysis' degenerate optimum: Clarabel may stop short of its tolerances; the field
        # is made exact and checked anyway, and a load factor below the optimum is still a bound
        self._accept = (Status.OPTIMAL, Status.OPTIMAL_INACCURATE) if self.limit_analysis else (Status.OPTIMAL,)
        self.space = space
        self.system = system  # the P0 system of the same mesh, for Solution (built on demand)
        sc = space.scales
        s = sc.stress
        S, sigma0 = space.stress_map, space.sigma0
        lf = self.load_factor
        ci = space.contact_y.ravel()
        self.y = cp.Variable(space.n_y, name="y")
        B = (space.div @ S).tocsr()
        rhs = (space.div_rhs - space.div @ sigma0) / s
        self._constraints = {"equilibrium": B @ self.y == lf * rhs, "contact": self.y[ci] <= 0}
        self._vertex = S @ self.y + lf * (sigma0 / s)  # vertex values over s
        self._column = space.column_map @ self.y + lf * (space.column0 / s)  # column values over s
        if self.limit_analysis:
            self._default = cp.Maximize(lf)
            self.constant = 0.0
        else:
            F, f0, Q = space.field_map, space.field0, space.field_energy_matrix()
            e_ref = sc.energy
            H = (F.T @ (Q @ F)).tocsr() * (s**2 / e_ref)
            lin_load = (F.T @ (Q @ f0)) * (s / e_ref)
            lin_gap = np.zeros(space.n_y)
            lin_gap[ci] = -space.gap_weights().ravel() * (s / e_ref)
            energy = 0.5 * cp.quad_form(self.y, H, assume_PSD=True) + lf * (lin_load @ self.y) + lin_gap @ self.y
            self._default = cp.Minimize(energy)
            self.constant = 0.5 * float(f0 @ (Q @ f0))  # objective offset at load_factor 1 (physical)
        self._objective = self._default
        self.y_exact: np.ndarray | None = None  # parameters of the exact field per unit load (physical)

    # -- expressions in physical units -----------------------------------------------------
    @property
    def stress(self):
        """Voigt stresses at the stress points: the vertices of every sub-triangle, then both ends of
        every column (``(0, g, 0)``: a column's stress is linear in ``x`` and constant in ``y``, so a
        convex function of it is largest at one of them)."""
        vertex = cp.reshape(self._vertex, (9 * self.space.n_tri, 3), order="C")
        n = 2 * len(self.space.columns)
        if not n:
            return self.space.scales.stress * vertex
        zero = np.zeros((n, 1))
        column = cp.hstack([zero, cp.reshape(self._column, (n, 1), order="C"), zero])
        return self.space.scales.stress * cp.vstack([vertex, column])

    @property
    def vertex_body(self) -> np.ndarray:
        """Body index (0 upper, 1 lower) of every row of :attr:`stress`."""
        sp = self.space
        return np.concatenate([np.repeat(sp.body, 9), np.repeat(sp.faces.body[sp.columns], 2)])

    @property
    def contact_pressure(self):
        """``(n_c, 2)`` contact pressure ``-sigma_nn`` at both ends of every contact edge."""
        return -self.space.scales.stress * self.y[self.space.contact_y]

    @property
    def total_contact_force(self):
        """The contact force: the pressure (linear on each edge) integrated along the face."""
        d = np.diff(self.space.contact_x, axis=1).ravel()
        return cp.sum(cp.multiply(0.5 * d, cp.sum(self.contact_pressure, axis=1)))

    def _out_of_plane(self) -> np.ndarray:
        return out_of_plane_factor(self.space.scene, self.vertex_body)

    # -- solving -------------------------------------------------------------------------
    def solve(self, solver: str = "CLARABEL", time_limit: float | None = None, verbose: bool = False,
              **options) -> SolverStats:
        """Solve (see :meth:`ConvexModel.solve`), then make the field exactly admissible:
        divided by the load factor (the exactness step is written for the unit load), made
        exact, multiplied back. Returns the solver's statistics with the sizes and the exactness
        step's changes."""
        stats = super().solve(solver, time_limit, verbose, **options)
        try:
            lf = float(self.load_factor.value)
            if not lf > 0:
                raise ModelError("the load factor came out 0: nothing is carried (limit analysis with yield "
                                 "constraints that admit no load?)")
            t1 = time.perf_counter()
            self.y_exact, post = make_exact(self.space, self.y.value * self.space.scales.stress / lf)
        except Exception:
            self._solved = None  # no exact field: nothing to read
            raise
        self.info = stats.replace(post_time=time.perf_counter() - t1, n_variables=self.space.n_y,
                                  n_equalities=self._constraints["equilibrium"].size,
                                  n_inequalities=self._constraints["contact"].size, **post)
        return self.info

    def stresses(self) -> np.ndarray:
        """``(n_sub, 3, 3)`` exactly admissible vertex stresses of the last solve."""
        self._require_solved()
        return float(self.load_factor.value) * self.space.stresses(self.y_exact)

    def column_stresses(self) -> np.ndarray:
        """``(n_col, 2)`` the columns' vertical stress ``g`` at both ends, of the last solve."""
        self._require_solved()
        return float(self.load_factor.value) * self.space.column_values(self.y_exact)

    def solution(self, check: bool = True) -> Solution:
        """A :class:`~cvxdual.Solution` (stress space ``eq``) of the exact field: admissibility
        and the user's constraints checked at it; the bounds, the displacement and the error
        against an exact field are not computed here (``cvxdual.solve(..., stress_space="eq")``
        gives them for the scene's own problem) and are listed in ``checks["skipped"]``."""
        from ..geometry.triangulation import discretize
        from ..system.assembly import assemble
        from .bounds import admissibility_residuals, constraint_blocks
        self._require_solved()
        t0 = time.perf_counter()
        space, s = self.space, self.space.scales.stress
        lf = float(self.load_factor.value)
        sigma, g = self.stresses(), self.column_stresses()
        blocks = constraint_blocks(space)
        res = admissibility_residuals(space, sigma / lf, blocks, g / lf)  # the blocks hold the unit load's data
        applied = {"admissibility": max(res.values())}
        if self._user:
            solved = self.y.value
            self.y.value = lf * self.y_exact / s  # the user's constraints at the exact field
            try:
                applied["user_constraints"] = max(self._violation(c) for _, c in self._user)
            finally:
                self.y.value = solved
        why = "cvxdual.solve(..., stress_space='eq') computes it for the scene's own problem"
        skipped = {"bounds": f"the bounds need the P1 displacement; {why}",
                   "displacement": "the equilibrium space has no displacement (zero is stored)",
                   "error": f"not computed here; {why}"}
        tri = space.triangulation
        system = self.system or assemble(*discretize(space.scene, tri, space.mesh.level))
        contact = edge_contact(system, -lf * self.y_exact[space.contact_y], None, lf)
        sol = Solution(scene=space.scene, triangulation=tri, level=int(space.mesh.level), system=system,
                       field=EquilibriumField.of_space(space, sigma, g), displacement=np.zeros((space.mesh.n_nodes, 2)),
                       solver=self.info,
                       timings=self._timings(time.perf_counter() - t0),
                       objective=float("nan"), duality_gap=float("nan"), residuals={**applied, **res},
                       contact=contact, exact=None, error=None, space=space,
                       checks=Checks(applied=applied, skipped=skipped))
        if check:
            tol = {**EQ_TOLERANCES, "user_constraints": USER_TOLERANCE}
            txt = failed_checks(applied, tol)
            if txt:
                raise AccuracyError(f"the exact field fails the checks that apply to this model ({txt}); tighten the "
                                    "solver's tolerances, or model.solution(check=False) to inspect it")
        return sol


