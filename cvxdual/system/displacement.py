"""The P1 displacement on the fast path (the P0 dual in its condensed displacement form,
the kinematic side both stress spaces share
(docs/theory.md#the-displacement-form-and-the-fast-path), solved by the active-set method of
:mod:`cvxdual.activeset.core` with sparse SPD factorisations; this module is its linear algebra.

``min 1/2 r.K r - g.r`` subject to ``r''_y(B_k) - r'_y(A_k) <= eps_k``, with
``K = Z^T E A_h^-1 E^T Z``: for type 1 this is exactly the Lagrangian dual of the stress QP, so
``lam_h = C_P B_P u_h`` (for type 2 the energy uses the same area-averaged strain on ``T_c``
as the dual's ``E``). Given an active set ``A`` the constraints of ``A`` are equalities: the
lower node's dof is eliminated, ``r_b = r_a + eps``, and the reduced stiffness ``K_A`` is SPD
(floating modes are fixed at the anchors). The new active set keeps the pairs with
compressive force and adds the penetrating ones; the method stops when the set reproduces
itself, which makes the result exact up to the factorisation.

One factorisation serves several iterations: pairs that change relative to the factorised
set enter through a small Schur complement (a bordered system solved with the factor),
so an iteration costs a few solves, not a factorisation. Warm starts (the active set of a
coarser level) make the changes few.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..activeset.core import ActiveSetStats, cover, iterate, worst_flipped
from ..errors import SolverError
from ..kinds import Status
from ..linalg.factor import SPDFactor, backends, one_blas_thread, start_up
from ..linalg.sparse import assemble_lower
from ..solution import SolverStats
from .assembly import System

MAX_UPDATE = 48  # changed pairs handled by the Schur complement before refactorising
REFINE_STEPS = 3  # iterative refinement of each solve, ...
# ... while the relative residual exceeds this: well-conditioned solves end at 1e-12 to 2e-11
# (hertz levels 3-6), where a refinement step costs a whole solve for a factor of 2; the
# ill-conditioned ones it exists for start at 1e-7 to 1e-5 (the checks' limit is 1e-6)
REFINE_TOL = 1e-10


class _Base:
    """The factorised reduced stiffness of one active set."""

    def __init__(self, ps: DisplacementSolver, active: np.ndarray, factorize: bool = True):
        s = ps.system
        n_r = s.n_r
        self.active = active.copy()
        zmap = np.arange(n_r)
        zmap[s.jb[active]] = s.ja[active]  # r_b = r_a + eps on active pairs
        fixed = ps.anchored[zmap]
        own = (zmap == np.arange(n_r)) & ~fixed
        zi = np.full(n_r, -1)
        zi[own] = np.arange(int(own.sum()))
        self.zidx = np.where(fixed, -1, zi[zmap])
        self.n_z = int(own.sum())
        self.r_e = np.zeros(n_r)
        self.r_e[s.jb[active]] = s.eps[active]
        rd = ps.rd
        zd = np.where(rd >= 0, self.zidx[np.maximum(rd, 0)], -1)
        self.K_lower = assemble_lower(zd, ps.kloc, self.n_z)  # K_A's lower triangle: Cholesky reads no more
        self.b_r = ps.g - ps.apply_k(self.r_e)  # r-space right-hand side with the gap moved over
        self.rhs = self.project(self.b_r)
        t0 = time.perf_counter()
        self.factor = SPDFactor(self.K_lower, lower=True) if factorize else None
        self.factor_time = time.perf_counter() - t0
        self.y0 = None  # the solution of the base's own system, once solved
        self.solved = {}  # ("rel" | "add", pair) -> the factor's solve of its border column

    def project(self, v: np.ndarray) -> np.ndarray:
        """``P0^T v`` for r-space vectors or ``(n_r, m)`` arrays."""
        m = self.zidx >= 0
        out = np.zeros((self.n_z,) + v.shape[1:])
        np.add.at(out, self.zidx[m], v[m])
        return out

    def expand(self, z: np.ndarray) -> np.ndarray:
        return np.where(self.zidx >= 0, z[np.maximum(self.zidx, 0)], 0.0) + self.r_e


class DisplacementSolver:
    """The linear algebra of the active-set method (:mod:`cvxdual.activeset.core`) on the displacement
    form of one assembled :class:`~cvxdual.system.assembly.System` (P1), or of any system with the
    same contact data (``n_r``, ``ja``, ``jb``, ``eps``, ``anchors``, ``separating``, ``scales``) and
    stiffness (``frame_stiffness()``, ``local_rdofs``, ``load_r``, ``apply_stiffness``, ``Z``): the P2
    kinematic side's :class:`~cvxdual.system.p2_system.P2System`."""

    what = "fast path"
    advice = ("use the CVXPY path (solver='CLARABEL')", "use the CVXPY path (--solver CLARABEL)")

    def __init__(self, system: System):
        self.system = s = system
        self.kloc = s.frame_stiffness()  # on the components r indexes; reused by every factorisation
        self.rd = s.local_rdofs
        self.g = s.load_r
        self.anchored = np.zeros(s.n_r, bool)
        self.anchored[s.anchors] = True
        self.jumps = s.separating[s.jb] - s.separating[s.ja]  # each pair's relative motion, per separating mode
        self.fscale = max(float(np.abs(self.g).max()), 1e-300)
        self.base: _Base | None = None
        self.stats = ActiveSetStats()

    def apply_k(self, r: np.ndarray) -> np.ndarray:
        return self.system.apply_stiffness(r)

    def k_columns(self, j: np.ndarray) -> sp.csc_matrix:
        """``K e_j`` for r indices ``j``: ``(n_r, len(j))``, from the pieces around them."""
        pos = np.full(self.system.n_r, -1)
        pos[j] = np.arange(len(j))
        hit_p, hit_l = np.nonzero((self.rd >= 0) & (pos[np.maximum(self.rd, 0)] >= 0))
        vals = self.kloc[hit_p, :, hit_l]  # (h, 6): column hit_l of the local matrix
        rows = self.rd[hit_p]
        cols = np.broadcast_to(pos[self.rd[hit_p, hit_l]][:, None], rows.shape)
        ok = rows >= 0
        return sp.csc_matrix((vals[ok], (rows[ok], cols[ok])), shape=(self.system.n_r, len(j)))

    def _solve(self, base: _Base, rel: np.ndarray, add: np.ndarray, b_r: np.ndarray | None = None,
               gap: np.ndarray | None = None) -> np.ndarray:
        """``r`` of the active set ``base.active - rel + add``. With ``b_r`` and ``gap``: the
        correction of the same system for right-hand side ``b_r`` and gaps ``gap`` instead of
        ``g`` and ``eps`` (iterative refinement; the ties of ``base`` are then homogeneous).
        Solves with the factor are the cost: the base's own solution and the solved border
        column of every changed pair are kept with the base and solved once (iterations
        revisit the same pairs), in one multi-column solve with whatever else is new."""
        s = self.system
        if b_r is None:
            b_r, gap, rhs, expand = base.b_r, s.eps, None, base.expand
        else:
            rhs, expand = base.project(b_r), lambda z: base.expand(z) - base.r_e
        jb_rel = s.jb[rel]
        keys = [("rel", k) for k in rel] + [("add", k) for k in add]
        M = self._border(base, rel, add) if keys else None
        new = [i for i, k in enumerate(keys) if k not in base.solved]
        need_y0 = rhs is not None or base.y0 is None
        first = [base.rhs if rhs is None else rhs] if need_y0 else []
        if first or new:
            t0 = time.perf_counter()
            sol = base.factor.solve(np.column_stack(first + [M[:, i] for i in new])).reshape(base.n_z, -1)
            self.stats.factor_time += time.perf_counter() - t0
            for i, x in zip(new, sol[:, len(first):].T, strict=True):
                base.solved[keys[i]] = x
            if need_y0:
                y0 = sol[:, 0]
                if rhs is None:
                    base.y0 = y0
        if not need_y0:
            y0 = base.y0
        if not keys:
            return expand(y0)
        X = np.column_stack([base.solved[k] for k in keys])
        m1 = len(rel)
        N = np.zeros((len(keys), len(keys)))
        N[:m1, :m1] = self.k_columns(jb_rel)[jb_rel, :].toarray()
        S = N - M.T @ X
        rw = np.concatenate([b_r[jb_rel], gap[add]])
        try:
            w = np.linalg.solve(S, rw - M.T @ y0)
        except np.linalg.LinAlgError:
            raise SolverError("fast path: singular update (the active set leaves a body free to move)") from None
        r = expand(y0 - X @ w)
        r[jb_rel] += w[:m1]
        self.stats.schur_updates += 1
        self.stats.max_update = max(self.stats.max_update, len(keys))
        return r

    def _border(self, base: _Base, rel: np.ndarray, add: np.ndarray) -> np.ndarray:
        """The border ``[U W]`` of the bordered system of the changed pairs: ``U`` the stiffness
        columns of released pairs' lower dofs, ``W`` the tie of each added pair."""
        s = self.system
        U = base.project(self.k_columns(s.jb[rel]).toarray())
        W = np.zeros((base.n_z, len(add)))
        for c, sign in ((s.jb[add], 1.0), (s.ja[add], -1.0)):
            zi = base.zidx[c]
            m = zi >= 0
            W[zi[m], np.flatnonzero(m)] = sign
        return np.hstack([U, W])

    def _refine(self, base: _Base, rel: np.ndarray, add: np.ndarray, A: np.ndarray, r: np.ndarray,
                scale: float) -> tuple[np.ndarray, np.ndarray]:
        """Iterative refinement of ``r`` for the active set ``A``: the residual of the
        equilibrium rows (the two rows of an active pair summed: its force is unknown) and of
        the active gaps is solved again with the same factor, while that reduces it. An
        ill-conditioned ``K`` (extreme materials or shapes) loses digits in one solve.
        Returns ``r`` and its residual ``g - K r`` (whose pair rows are the contact forces)."""
        s = self.system

        def residual(r):
            res = self.g - self.apply_k(r)
            tied = res.copy()
            tied[s.ja[A]] += tied[s.jb[A]]  # the pair's rows summed: the contact force cancels
            tied[s.jb[A]] = 0.0
            tied[self.anchored] = 0.0
            gap = np.where(A, s.eps - (r[s.jb] - r[s.ja]), 0.0)
            return res, max(float(np.abs(tied).max()) / scale, float(np.abs(gap).max()) / s.scales.displacement), gap

        res, size, gap = residual(r)
        for _ in range(REFINE_STEPS):
            if size <= REFINE_TOL:
                break
            r_new = r + self._solve(base, rel, add, res, gap)
            res_new, size_new, gap_new = residual(r_new)
            if not size_new < 0.5 * size:  # stalls: the factor has nothing more to give
                break
            r, res, size, gap = r_new, res_new, size_new, gap_new
            self.stats.refinements += 1
        return r, res

    def initial(self) -> np.ndarray:
        """Cold start: the pairs at the smallest gap (the first to touch)."""
        s = self.system
        tol = 1e-9 * max(float(np.abs(s.eps).max()), s.scales.displacement)
        return cover(s.eps <= s.eps.min() + tol, s.eps, self.jumps)

    def solve_set(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(r, res)``: free displacements of the set ``A`` and the residual ``g - K r`` (its pair
        rows are the contact forces). Pairs that changed since the last factorisation enter
        through the Schur complement, until there are too many; then ``K_A`` is factorised anew."""
        base = self.base
        rel = np.flatnonzero(base.active & ~A) if base is not None else None
        add = np.flatnonzero(A & ~base.active) if base is not None else None
        if base is None or len(rel) + len(add) > MAX_UPDATE or len(base.solved) > MAX_UPDATE:
            self.base = base = _Base(self, A)
            self.stats.factor_time += base.factor_time
            self.stats.backend = base.factor.method
            self.stats.factorizations += 1
            rel = add = np.empty(0, int)
        return self._refine(base, rel, add, A, self._solve(base, rel, add), self.fscale)

    def next_set(self, A: np.ndarray, state: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Keep the pairs with compressive force, add the penetrating ones; rounding-level forces
        and penetrations do not change the set (equivalent sets at a degenerate contact edge
        would otherwise alternate)."""
        force, opening, tol_f, tol_o = self._violations(A, state)
        return cover(np.where(A, force > -tol_f, opening < -tol_o), opening, self.jumps)

    def one_change(self, A: np.ndarray, state: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """:meth:`next_set` damped to one change, a cycle's way out: release the pair pulling
        hardest or add the one penetrating deepest, whichever is larger against its own scale."""
        force, opening, tol_f, tol_o = self._violations(A, state)
        sf, so = (max(float(np.abs(v).max(initial=0.0)), 1e-300) for v in (force, opening))
        keep = worst_flipped(A, np.where(force < -tol_f, -force / sf, 0.0),
                             np.where(opening < -tol_o, -opening / so, 0.0))
        return cover(keep, opening, self.jumps)

    def _violations(self, A: np.ndarray, state: tuple[np.ndarray, np.ndarray]) -> tuple:
        """Forces of the active pairs, openings of all, and the rounding levels that do not count."""
        s = self.system
        r, res = state
        force = np.where(A, res[s.jb], 0.0)
        opening = s.eps - (r[s.jb] - r[s.ja])
        return force, opening, 1e-12 * self.fscale, 1e-12 * s.scales.displacement

    def solve(self, active: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(r, active)``: free displacements and the converged active set, from ``active`` (or
        the first pairs to touch), completed by :func:`~cvxdual.activeset.core.cover`."""
        s = self.system
        A = self.initial() if active is None else cover(np.asarray(active, bool), s.eps, self.jumps)
        A, (r, _) = iterate(self, A)
        return r, A


def limit(system: System) -> dict:
    """The speed "limit": factorise and solve ``K`` with every contact pair closed (the bodies
    tied, floating modes at the anchors): SPD, the same size and sparsity as the fast path's
    matrices. Nothing solves the discrete problem faster than about this. Every backend of
    :func:`cvxdual.linalg.factor.backends` is timed, each after a small factorisation
    that pays its one-time start-up; the fastest is the limit."""
    t0 = time.perf_counter()
    base = _Base(DisplacementSolver(system), np.ones(len(system.jb), bool), factorize=False)
    t1 = time.perf_counter()
    K = base.K_lower
    times = {}
    with one_blas_thread():
        for m in backends():
            start_up(m)  # one-time library start-up, not counted
            ta = time.perf_counter()
            factor = SPDFactor(K, m, lower=True)
            tb = time.perf_counter()
            factor.solve(base.rhs)
            times[m] = (tb - ta, time.perf_counter() - tb)
            factor.close()
    best = min(times, key=lambda m: sum(times[m]))
    return {"n_dofs": int(K.shape[0]), "nnz": int(2 * K.nnz - K.shape[0]), "t_matrix": t1 - t0,
            "t_factor": times[best][0], "t_solve_lin": times[best][1], "t_limit": sum(times[best]), "backend": best,
            **{f"t_limit_{m}": sum(t) for m, t in times.items()}}


def solve_fast(system: System, active: np.ndarray | None = None) -> tuple[np.ndarray, SolverStats]:
    """Displacements ``u`` (all dofs) and the solver's statistics (its final active set in
    ``active``), from the initial active set ``active`` (default: the first pairs to touch)."""
    t0 = time.perf_counter()
    solver = DisplacementSolver(system)
    with one_blas_thread():
        r, A = solver.solve(active)
    st = solver.stats
    return system.Z @ r, SolverStats(
        solver="fast", status=Status.OPTIMAL, iterations=st.iterations, solve_time=time.perf_counter() - t0,
        backend=st.backend, factorizations=st.factorizations, factor_time=st.factor_time,
        schur_updates=st.schur_updates, max_update=st.max_update, refinements=st.refinements, active=A)


NOTHING_ACTS = "none (no load, no interference)"  # the solver of a scene where nothing acts


def nothing_acts(system: System) -> bool:
    """No load and no interference: ``lam = 0`` is admissible and ``S(lam) >= S(0)`` for every
    admissible ``lam`` (contact forces are compressive, gaps ``>= 0``), so zero is the solution."""
    return not np.any(system.f) and np.all(system.eps >= 0)
