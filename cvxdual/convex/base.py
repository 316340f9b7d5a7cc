"""What every CVXPY model of cvxdual shares (docs/reformulate.md): a problem a user changes only
through explicit calls, kept consistent with its solve.

:class:`ConvexModel` holds the user's constraints and objective, builds the
:class:`cvxpy.Problem` from them and the subclass's named rows, solves it (statuses mapped to
:class:`~cvxdual.errors.SolverError`, naming the user's changes), and refuses misuse with
:class:`~cvxdual.errors.ModelError`: reading before a solve or after a change, solving again
unchanged, replacing the problem. Its ``load_factor`` multiplies the applied loads; a sweep over
it compiles once (see :meth:`ConvexModel._runner`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..errors import ModelError
from ..kinds import Status
from ..solution import SolverStats
from . import cvxpy_internals as internals
from .solvers import DEFAULT_SOLVER, TIME_LIMIT_OPTION, resolve_solver, solve_problem

# a user constraint may be violated by this much relative to the size of its terms: the
# interior-point solvers stop at 1e-8 relative feasibility, so 1e-6 leaves a margin of 100
USER_TOLERANCE = 1e-6

# Clarabel's defaults (tol_gap_abs 1e-8, tol_gap_rel, tol_feas 1e-8, tol_ktratio 1e-6) are set
# for data of size one, which the model's scales give at load_factor 1. Below 1 the solution
# shrinks with the load while the data do not, so they shrink with it (measured on hertz,
# blocks and cylinder-on-block at level 1: the duality gap check then holds to load_factor
# 1e-2-1e-3 instead of failing from 1e-2); smaller factors than this floor are refused by the
# checks, with advice.
SCALED_TOLERANCES = {"tol_gap_abs": 2, "tol_gap_rel": 1, "tol_feas": 1, "tol_ktratio": 1}  # powers of lf
CLARABEL_DEFAULTS = {"tol_gap_abs": 1e-8, "tol_gap_rel": 1e-8, "tol_feas": 1e-8, "tol_ktratio": 1e-6}
SMALLEST_SCALED = 1e-4

# keywords of cvxpy.Problem.solve itself, not of a solver: a solve with any of them goes through
# CVXPY (the cached re-solve hands options to the solver alone)
CVXPY_OPTIONS = {"gp", "qcp", "requires_grad", "enforce_dpp", "ignore_dpp", "canon_backend", "warm_start",
                 "solver_path", "bounds"}


@dataclass
class _RhsCache:
    """A load_factor sweep's solver data (see :meth:`ConvexModel._runner`): those of the first
    solve, at load factor ``value``; ``affine`` None until a re-solve has checked that only the
    right-hand side changes with the load factor (then ``b0``, ``b1``), False where not."""

    key: tuple
    data: dict
    chain: object
    inverse: object
    value: float
    affine: bool | None = None
    b0: np.ndarray | None = None
    b1: np.ndarray | None = None


class ConvexModel:
    """Base of the CVXPY models. A subclass calls :meth:`_start` first, sets ``_constraints``
    (its named rows) and ``_default`` (its objective), and may name its own changes in
    :meth:`_own_changes`."""

    what = "convex problem"  # how messages name the problem
    _accept = (Status.OPTIMAL,)  # solver statuses taken as solved (see solvers.solve_problem)

    def _start(self, limit_analysis: bool) -> None:
        self.limit_analysis = bool(limit_analysis)
        if self.limit_analysis:
            self.load_factor = cp.Variable(nonneg=True, name="load_factor")
        else:
            self.load_factor = cp.Parameter(nonneg=True, value=1.0, name="load_factor")
        self._user: list[tuple[str, cp.Constraint]] = []
        self._version = 0  # bumped by every change of the problem
        self._solved = None  # (version, parameter values, solver, options) of the last solve
        self._problem = None
        self._rhs: _RhsCache | None = None  # re-solves that change load_factor only
        self.info: SolverStats | None = None  # of the last solve

    def _changed(self) -> None:
        self._version += 1
        self._problem = None

    # -- the problem, read-only ---------------------------------------------------------
    @property
    def constraints(self) -> dict:
        """The package's named constraints (a copy)."""
        return dict(self._constraints)

    @property
    def user_constraints(self) -> dict:
        """The constraints added by :meth:`add_constraint`, by name."""
        return dict(self._user)

    @property
    def objective(self):
        return self._objective

    @property
    def problem(self) -> cp.Problem:
        """The current :class:`cvxpy.Problem` (rebuilt after every change; do not replace it)."""
        if self._problem is None:
            self._problem = cp.Problem(self._objective, [*self._constraints.values(), *(c for _, c in self._user)])
        return self._problem

    @problem.setter
    def problem(self, value):
        raise ModelError("model.problem cannot be replaced (a later change would silently rebuild the old one); "
                         "use model.set_objective(...) and model.add_constraint(...)")

    def changes(self) -> list[str]:
        """The changes made to the package's problem, as short phrases (for messages)."""
        out = ["limit analysis (maximise load_factor)"] if self.limit_analysis else []
        if self._objective is not self._default:
            out.append("set_objective")
        return out + [f"add_constraint {name!r}" for name, _ in self._user] + self._own_changes()

    def _own_changes(self) -> list[str]:
        """The changes a subclass makes to its rows (friction, adhesion)."""
        return []

    # -- changes ---------------------------------------------------------------------------
    def add_constraint(self, *constraints, name: str | None = None) -> ConvexModel:
        """Add convex constraints (e.g. on :attr:`stress`, :meth:`von_mises`). ``name`` (default
        ``constraint N``) appears in :attr:`user_constraints`, ``solution.checks`` and errors."""
        if not constraints:
            raise ModelError("add_constraint needs at least one constraint, e.g. model.von_mises() <= 500")
        for c in constraints:
            if not isinstance(c, cp.constraints.Constraint):
                raise ModelError(f"add_constraint takes cvxpy constraints (such as model.shear_cap(k)), got "
                                 f"{type(c).__name__}: build it from the model's expressions, not from numbers")
            if not c.is_dcp():
                raise ModelError(f"constraint {c!s:.80} is not convex (not DCP); only convex constraints keep "
                                 "the problem solvable")
        n = len(self._user)
        labels = [(name if len(constraints) == 1 else f"{name}[{i}]") if name else f"constraint {n + i + 1}"
                  for i in range(len(constraints))]
        taken = set(dict(self._user)) & set(labels)
        if taken:  # checked before adding any: a refused call leaves the model as it was
            raise ModelError(f"a constraint named {sorted(taken)[0]!r} exists already; choose another name")
        self._user += list(zip(labels, constraints, strict=True))
        self._changed()
        return self

    def set_objective(self, objective) -> ConvexModel:
        """Replace the objective (a ``cp.Minimize`` or ``cp.Maximize``), kept until set again.
        :attr:`complementary_energy` is the default one in physical units."""
        if not isinstance(objective, (cp.Minimize, cp.Maximize)):
            raise ModelError("set_objective takes cp.Minimize(...) or cp.Maximize(...), "
                             f"got {type(objective).__name__}")
        if not objective.is_dcp():
            raise ModelError("the objective is not convex (not DCP): minimise a convex or maximise a concave "
                             "expression")
        self._objective = objective
        self._changed()
        return self

    # -- stress measures on ``stress`` (rows: the subclass's stress points) ----------------
    def shear_stress(self):
        """In-plane maximum shear ``sqrt(((s11 - s22)/2)^2 + s12^2)`` per stress point (convex)."""
        s = self.stress
        return cp.norm(cp.vstack([0.5 * (s[:, 0] - s[:, 1]), s[:, 2]]), 2, axis=0)

    def von_mises(self):
        """Von Mises stress per stress point (convex), with ``s33 = nu (s11 + s22)`` in plane
        strain and 0 in plane stress."""
        return cp.norm(self._von_mises_rows(), 2, axis=0) / np.sqrt(2.0)

    def _von_mises_rows(self):
        s = self.stress
        s33 = cp.multiply(self._out_of_plane(), s[:, 0] + s[:, 1])
        return cp.vstack([s[:, 0] - s[:, 1], s[:, 1] - s33, s33 - s[:, 0], np.sqrt(6.0) * s[:, 2]])

    # Caps as one second-order cone per point. ``shear_stress() <= k`` is the same set, but CVXPY
    # writes it with a bound variable per point: at level 1 of the punch 83 Clarabel iterations
    # against 31, and on the equilibrium space Clarabel reported a feasible von Mises cap
    # infeasible in that form (docs/reformulate.md).
    def shear_cap(self, k, where=None) -> cp.Constraint:
        """The constraint ``shear_stress() <= k`` at the points ``where`` (a mask or indices;
        all by default), ``k`` a number or one per point, as direct cones."""
        s = self.stress
        rows = self._at(cp.vstack([0.5 * (s[:, 0] - s[:, 1]), s[:, 2]]), where, "shear_cap")
        return cp.SOC(self._bound(k, rows.shape[1], "shear_cap"), rows, axis=0)

    def von_mises_cap(self, k, where=None) -> cp.Constraint:
        """The constraint ``von_mises() <= k`` at the points ``where`` (a mask or indices; all by
        default), ``k`` a number or one per point, as direct cones."""
        rows = self._at(self._von_mises_rows(), where, "von_mises_cap")
        return cp.SOC(np.sqrt(2.0) * self._bound(k, rows.shape[1], "von_mises_cap"), rows, axis=0)

    @staticmethod
    def _at(rows, where, what: str):
        """The columns (points) ``where`` of ``rows``: all, a boolean mask of every point, or
        integer indices of some."""
        if where is None:
            return rows
        n = rows.shape[1]
        w = np.asarray(where)
        if w.dtype == bool:
            if w.shape != (n,):
                raise ModelError(f"{what}: where= as a mask needs one boolean per point ({n}), got shape {w.shape}")
            w = np.flatnonzero(w)
        elif w.ndim != 1 or w.dtype.kind not in "iu" or (len(w) and (w.min() < -n or w.max() >= n)):
            raise ModelError(f"{what}: where= takes a boolean mask of the {n} points or a 1-d array of integer "
                             f"indices below {n}, got {where!r:.60}")
        if not len(w):
            raise ModelError(f"{what}: where= selects no point; give at least one")
        return rows[:, w]

    @staticmethod
    def _bound(k, n: int, what: str):
        """``k`` broadcast to ``n`` points: a non-negative number or array, or a non-negative
        Parameter of shape () or (n,)."""
        if isinstance(k, cp.Expression):
            if k.shape not in ((), (n,)):
                raise ModelError(f"{what}: k as a cvxpy expression must have shape () or ({n},), got {k.shape}")
            return k if k.shape == (n,) else cp.multiply(k, np.ones(n))
        if isinstance(k, (str, bytes, bool)):
            raise ModelError(f"{what}: k must be a number, got {k!r}")
        try:
            b = np.broadcast_to(np.asarray(k, dtype=float), (n,))
        except (TypeError, ValueError):
            raise ModelError(f"{what}: k must be a number or one value per capped point ({n}), got "
                             f"{type(k).__name__}") from None
        if not np.all(np.isfinite(b)) or np.any(b < 0):
            raise ModelError(f"{what}: k must be finite and non-negative, got {k!r}")
        return b

    # -- solving ------------------------------------------------------------------------
    def _state(self) -> tuple:
        values = tuple(np.asarray(p.value).tobytes() if p.value is not None else None
                       for p in self.problem.parameters())
        return self._version, values

    def solve(self, solver: str = DEFAULT_SOLVER, time_limit: float | None = None, verbose: bool = False,
              **options) -> SolverStats:
        """Solve; returns the solver's statistics. ``time_limit`` in seconds (Clarabel, SCS,
        OSQP), ``verbose`` prints the solver's log, ``options`` go to the solver.
        Raises :class:`~cvxdual.errors.SolverError` naming the model's changes when they make
        the problem infeasible or unbounded."""
        solver = resolve_solver(solver)
        if solver == "FAST":
            raise ModelError("the fast path solves the package's own problem, not a model; use solver='CLARABEL'")
        if self.limit_analysis and not self._user:
            raise ModelError("limit analysis needs yield constraints, e.g. model.add_constraint(model.shear_cap(k)); "
                             "without them any load is carried")
        for p in self.problem.parameters():
            if p.value is None:
                raise ModelError(f"parameter {p.name()!r} has no value; set {p.name()}.value before solving")
        if not self.limit_analysis and not float(self.load_factor.value) > 0:
            raise ModelError("load_factor must be positive: with no load nothing acts and the stresses are zero "
                             "(the checks are relative to the load)")
        for p in self.problem.parameters():
            if not np.all(np.isfinite(p.value)):
                raise ModelError(f"parameter {p.name()!r} has a non-finite value; give a finite one (a stuck pair "
                                 "is g = inf in a plain array, not in a Parameter)")
        key = (*self._state(), solver, repr(sorted(options.items())), time_limit, bool(verbose))
        if self._solved == key:
            raise ModelError("the model was solved already with these data; read model.solution(), or change "
                             "load_factor, a parameter or the model before solving again")
        self._solved = None
        changes = self.changes()
        advice = None
        if changes:
            what = ", ".join(changes)
            advice = {"infeasible": f"no stress field satisfies the model with your changes ({what}); the "
                                    "scene's own constraints are satisfiable, so relax those changes (a cap "
                                    "written as von_mises() <= k may be misreported: use model.von_mises_cap(k))",
                      "infeasible_inaccurate": f"the solver suspects your changes ({what}) leave no admissible "
                                               "stress field; relax them, or try another solver",
                      "unbounded": f"the objective is unbounded over the admissible stresses with your changes "
                                   f"({what}); bound it with constraints",
                      "unbounded_inaccurate": f"the objective looks unbounded with your changes ({what}); "
                                              "bound it with constraints"}
        run = self._runner(solver, verbose, options, time_limit)
        self.info = solve_problem(self.problem, solver, self.what, advice, time_limit, verbose, run=run,
                                  accept=self._accept, defaults=self._scaled_tolerances(solver, options), **options)
        self._solved = key
        return self.info

    def _scaled_tolerances(self, solver: str, options: dict) -> dict:
        """Clarabel's tolerances scaled to a load_factor below 1 (see :data:`SCALED_TOLERANCES`),
        unless the user set tolerances."""
        lf = self.load_factor.value
        if solver != "CLARABEL" or self.limit_analysis or lf is None or lf >= 1.0 or set(options) & set(
                SCALED_TOLERANCES):
            return {}
        f = max(float(lf), SMALLEST_SCALED)
        return {k: CLARABEL_DEFAULTS[k] * f ** SCALED_TOLERANCES[k] for k in SCALED_TOLERANCES}

    def _runner(self, solver: str, verbose: bool, options: dict, time_limit: float | None = None):
        """``run(opts)`` for :func:`solve_problem`. In a DPP problem whose ``load_factor`` enters
        the solver's right-hand side alone, the solver's data at any load factor differ in
        ``b = b0 + load_factor b1`` only (DPP problems are affine in their parameters). The first
        solve compiles (CVXPY) and keeps the solver's data; the first re-solve that changes only
        ``load_factor`` applies ``load_factor = 0`` to CVXPY's cached program for ``b0`` and checks
        that nothing else changed; from then on the solver gets the kept data with the new ``b``,
        skipping CVXPY's recompile (the parameter applied to the whole canonical tensor,
        ``O(nnz)``). A single solve does no more than CVXPY's own. Anything else (a change of the
        model or of another parameter, CVXPY's own keywords, a QP solver, a non-DPP problem)
        goes through CVXPY. The cache is keyed on the user's ``options``: the tolerances scaled to
        the load factor steer the solver, not its data. A ``time_limit`` covers the compile too:
        the solver is given what the compile left of it."""
        problem = self.problem
        lf = self.load_factor
        cacheable = (not self.limit_analysis and solver in internals.conic_solvers()
                     and not set(options) & CVXPY_OPTIONS and problem.is_dpp())

        def run(opts: dict) -> float:
            if not cacheable:
                problem.solve(solver=solver, verbose=bool(verbose), **opts)
                return problem.compilation_time
            others = tuple(np.asarray(p.value).tobytes() for p in problem.parameters() if p is not lf)
            key = (self._version, others, solver, repr(sorted(options.items())))
            t0 = time.perf_counter()
            cache = self._rhs if self._rhs is not None and self._rhs.key == key else None
            if cache is None:
                data, chain, inverse = internals.problem_data(problem, solver, opts)
                cache = self._rhs = _RhsCache(key, data, chain, inverse, float(lf.value))
            elif cache.affine is None:
                cache.affine = self._affine_rhs(problem, solver, opts, cache)
            if cache.affine is False:  # load_factor is not in b alone: CVXPY from now on
                problem.solve(solver=solver, verbose=bool(verbose), **opts)
                return problem.compilation_time
            data = (cache.data if cache.affine is None else
                    {**cache.data, internals.rhs_key(): cache.b0 + float(lf.value) * cache.b1})
            compile_time = time.perf_counter() - t0
            if time_limit is not None:
                name = TIME_LIMIT_OPTION[solver]
                opts = {**opts, name: max(opts[name] - compile_time, 1e-3)}
            internals.solve_data(problem, cache.chain, data, cache.inverse, bool(verbose), opts)
            return compile_time

        return run

    def _affine_rhs(self, problem, solver: str, opts: dict, cache: _RhsCache) -> bool:
        """Whether the kept data (at load factor ``cache.value``) and the data at 0 differ in
        ``b`` alone; if so ``cache.b0``, ``cache.b1 = (b(value) - b0) / value`` are set. Not where
        the solver takes QP data, or a user's constraint multiplies a variable by ``load_factor``."""
        if not internals.is_conic(cache.chain):
            return False
        v = float(self.load_factor.value)
        try:
            self.load_factor.value = 0.0
            zero = internals.problem_data(problem, solver, opts)[0]
        finally:
            self.load_factor.value = v
        b = internals.rhs_key()
        for k, a in cache.data.items():
            z = zero[k]
            changed = (a != z).nnz if sp.issparse(a) else isinstance(a, np.ndarray) and not np.array_equal(a, z)
            if k != b and changed:
                return False
        cache.b0, cache.b1 = zero[b], (cache.data[b] - zero[b]) / cache.value
        return True

    def _require_solved(self) -> None:
        if self._solved is None:
            raise ModelError("the model has not been solved (or its last solve failed); call model.solve() first")
        if self._solved[:2] != self._state():
            raise ModelError("the model or a parameter changed since the last solve; call model.solve() again")

    # -- results ---------------------------------------------------------------------------
    def value(self, expression) -> np.ndarray:
        """The value of an expression of this model at the last solve."""
        self._require_solved()
        if not isinstance(expression, cp.Expression):
            raise ModelError(f"value() takes a cvxpy expression of this model (e.g. model.contact_force, or "
                             f"model.von_mises() called), got {type(expression).__name__}")
        if not set(expression.variables()) <= set(self.problem.variables()):
            raise ModelError("the expression uses variables that are not in this model's problem; build it from "
                             "this model's handles (model.stress, model.contact_force, ...)")
        return np.asarray(expression.value, dtype=float)

    def _timings(self, recover: float) -> dict:
        """``Solution.timings`` of the last solve: the model's own phases (meshing and assembly
        happened before the model was built, and are not timed here)."""
        build = self.info.compile_time or 0.0
        solve = (self.info.solve_time or 0.0) - build
        return {"mesh": 0.0, "assemble": 0.0, "build": build, "solve": solve, "recover": recover, "error": 0.0,
                "total": build + solve + recover}

    def _elastic(self) -> bool:
        """Whether the multipliers are the displacements of an elastic problem: the default
        objective and no added constraint (friction, adhesion and load_factor keep it)."""
        return self._objective is self._default and not self._user and not self.limit_analysis

    @staticmethod
    def _violation(c) -> float:
        """Largest violation of a user constraint relative to the size of its terms: the larger
        of its sides' values and of ``sum |d side / d x| max |x|`` (a side forced to 0, such as
        ``stress[:, 2] == 0``, is judged against the size of the stresses, whose rounding the
        solver leaves in it)."""
        size = 0.0
        for a in c.args:
            if a.value is None:
                continue
            size = max(size, float(np.abs(a.value).max(initial=0.0)))
            for var, G in (a.grad or {}).items():  # G: (var.size, a.size), None where not differentiable
                if G is not None:
                    x = float(np.abs(np.asarray(var.value, dtype=float)).max(initial=0.0))
                    size = max(size, x * float(np.asarray(abs(sp.csr_matrix(G)).sum(axis=0)).max(initial=0.0)))
        return float(np.max(c.violation(), initial=0.0)) / max(size, 1e-300)
