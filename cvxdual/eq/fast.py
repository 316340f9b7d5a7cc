"""The fast path of the equilibrium (Johnson-Mercier) dual (docs/equilibrium.md, section 10):
the active-set method of :mod:`cvxdual.fast.core` on the KKT system of the QP of
:class:`~cvxdual.eq.model.EquilibriumModel`, condensed by hybridisation to an SPD system; this
module is its linear algebra.

Hybridisation. Every parameter ``y`` that two triangles share (an interior edge dof, or a
contact normal traction in contact, shared by the two faces) gets a copy in each triangle,
and the copies are tied by a multiplier ``mu`` (an edge "displacement"). Per triangle the
local KKT system ``[[H_T, B_T^T], [B_T, 0]]`` (15 parameters, 6 divergence rows; fixed
parameters held at their value) is non-singular, so the local parameters and divergence
multipliers are affine in ``mu``, and continuity of the copies leaves
``S mu = f`` with ``S = sum_T N_T^T (K_T^-1)_yy N_T`` symmetric positive semi-definite. Its
kernel is the floating rigid motions (``rigid_motions(joint=True)``; hertz: 1): one ``mu`` per
motion is pinned to 0 (the motion's multiplier gauge) and its continuity equation dropped,
which the balanced loads imply, so the result stays exact. ``S`` has ~6 unknowns per
triangle (4 per interior edge), ~40% of ``[[M, D^T], [D, 0]]``, and is SPD (Cholesky).

Active set: a contact parameter ``p = sigma_nn`` is *in contact* (free, two tied copies) or
*separated* (fixed at 0). With ``nu = -(grad q + B^T lam)`` at ``p`` (the gap weight minus
the work of the displacement jump: ``nu >= 0`` means open), the update keeps in contact the
compressive ones (``p <= 0``) and adds the separated ones with ``nu < 0`` (penetration). Only
triangles on the contact faces depend on the set: the rest of ``S`` is assembled once.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..errors import SolverError
from ..fast.core import ActiveSetStats, coarse_start, cover, iterate, transfer_active
from ..linalg.factor import SPDFactor
from ..solution import SolverStats
from .element import MASS0, bary_gradients, divergence_rows, sub_vertices
from .space import EquilibriumSpace, make_exact, rigid_motions

CHUNK = 16384  # triangles per batched local inversion: bounds the temporaries (21 x 21 each)
SET_TOL = 1e-10  # relative size of p or nu below which the contact state is left as it is (rounding)
RESIDUAL_TOL = 1e-8  # relative residual of the condensed solve above which it is not trusted
REFINE_STEPS, REFINE_TOL = 3, 1e-15  # iterative refinement of the condensed solve, until rounding


def triangle_dofs(space: EquilibriumSpace) -> np.ndarray:
    """``(n_T, 15)``: the raw parameter of each local basis column (as in ``vertex_map``)."""
    ed, n_T = space.edges, space.n_tri
    e = np.arange(2)[None, None, :, None] ^ ed["flip"][:, :, None, None]  # global end of each local end
    edof = 4 * ed["id"][:, :, None, None] + 2 * e + np.arange(2)[None, None, None, :]
    bubbles = 4 * len(ed["keys"]) + 3 * np.arange(n_T)[:, None] + np.arange(3)[None, :]
    return np.concatenate([edof.reshape(n_T, 12), bubbles], axis=1)


def local_blocks(space: EquilibriumSpace) -> tuple[np.ndarray, np.ndarray]:
    """Energy ``H (n_T, 15, 15)`` (``1/2 z.H z = 1/2 int sigma:A sigma``, exact P1 mass per
    sub-triangle) and divergence rows ``B (n_T, 6, 15)`` in the local parameters, physical units.
    A column's energy goes to the triangle of its face edge, whose tied normal slots hold its
    ``g`` (:func:`cvxdual.eq.space.tie_basis`): each column then belongs to one triangle."""
    n_T = space.n_tri
    _, area = bary_gradients(sub_vertices(space.X))
    A = np.stack([b.material.compliance for b in space.scene.bodies])[space.body]
    K9 = (MASS0[None, :, None, :, None] * A[:, None, :, None, :]).reshape(n_T, 9, 9)
    H = np.zeros((n_T, 15, 15))
    for i in range(3):  # three sub-triangles; vectorised over the mesh
        Ni = space.basis[:, 9 * i: 9 * i + 9, :]
        H += area[:, i, None, None] * (Ni.transpose(0, 2, 1) @ (K9 @ Ni))
    t, slots = column_slots(space)
    np.add.at(H, (t[:, None, None], slots[:, :, None], slots[:, None, :]), space.column_energy_blocks)
    return H, divergence_rows(space.X)[0] @ space.basis


def column_slots(space: EquilibriumSpace) -> tuple[np.ndarray, np.ndarray]:
    """The triangle of each column's face edge and the local slots ``(n_col, 2)`` of its ``g`` at
    the left and right end (the tied normal slots)."""
    ed = space.edges
    eid = space.face_edge[space.columns]
    t, j = ed["owner"][eid].T
    left_end = (ed["hi"][eid] == space.faces.left[space.columns]).astype(int)  # global end of the left end
    ge = np.stack([left_end, 1 - left_end], 1)
    return t, 4 * j[:, None] + 2 * (ge ^ ed["flip"][t, j][:, None])


def gauge_pins(space: EquilibriumSpace, ys: np.ndarray, pair_y: np.ndarray, first: np.ndarray) -> np.ndarray:
    """``y`` indices (among the interior pairs ``pair_y``) whose multiplier is pinned, one per
    floating motion ``r``: the kernel of ``S`` is ``mu_y = s_o * int phi_e (frame . r)`` (the
    work of the parameter on ``r``, signed by the outward normal of its first triangle); QR
    with column pivoting picks entries where these vectors are independent."""
    r = rigid_motions(space.mesh, joint=True)
    if r.shape[2] == 0:
        return np.empty(0, int)
    ed = space.edges
    t, slot = np.divmod(first[pair_y], 15)
    edge = slot < 12
    t, slot, yy = t[edge], slot[edge], pair_y[edge]
    j, e, k = slot // 4, (slot % 4) // 2, slot % 2
    g = ed["id"][t, j]
    E = e ^ ed["flip"][t, j]  # global end
    ends = np.stack([ed["lo"][g], ed["hi"][g]], 1)
    r_near, r_far = r[ends[np.arange(len(g)), E]], r[ends[np.arange(len(g)), 1 - E]]  # (m_p, 2, m)
    n = ed["ng"][g]
    frame = np.where(k[:, None] == 0, n, np.stack([-n[:, 1], n[:, 0]], 1))
    s_o = 1.0 - 2.0 * ed["flip"][t, j]  # n_out = n_g when the local edge runs lo -> hi
    W = (s_o * ed["length"][g] / 6.0)[:, None] * np.einsum("pi,pim->pm", frame, 2 * r_near + r_far)
    _, _, piv = sla.qr(W.T, pivoting=True, mode="economic")
    return yy[piv[: r.shape[2]]]


def pair_jumps(space: EquilibriumSpace) -> np.ndarray:
    """``(n_c, 2, m)``: jump ``[r_y]`` at each contact parameter of the rigid motions of each
    body alone; the parameters in contact must stop every motion that separates the bodies."""
    r = rigid_motions(space.mesh, joint=False)
    up, lo = space.mesh.pairs.T
    dk = r[lo, 1] - r[up, 1]  # (n_pairs, m)
    n_c = len(space.contact_y)
    return np.stack([dk[:n_c], dk[1: n_c + 1]], 1)


def active_from_pairs(space: EquilibriumSpace, x: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Contact parameters ``(n_c, 2)`` in contact for an active set ``active`` given at abscissae
    ``x`` (the P0 fast path's pairs, or the ``contact_x`` of a coarser equilibrium solve):
    :func:`cvxdual.fast.core.transfer_active` on the sorted points."""
    x, a = np.asarray(x, float).ravel(), np.asarray(active, bool).ravel()
    order = np.argsort(x, kind="stable")
    return transfer_active(x[order], a[order], space.contact_x)


class HybridSolver:
    """The linear algebra of the active-set method (:mod:`cvxdual.fast.core`) on the equilibrium
    dual of one :class:`EquilibriumSpace`, in the nondimensional variables of
    :class:`~cvxdual.eq.model.EquilibriumModel`."""

    what = "eq fast path"
    advice = ("use the CVXPY path (EquilibriumModel, or solver='CLARABEL')",
              "use the CVXPY path (--solver CLARABEL)")

    def __init__(self, space: EquilibriumSpace):
        t0 = time.perf_counter()
        self.space = space
        sc = space.scales
        n_T, n_y = space.n_tri, space.n_y
        raw = triangle_dofs(space)
        coo = space.Tm.tocoo()
        ycol = np.full(space.Tm.shape[0], -1)
        ycol[coo.row] = coo.col
        self.ys = ycol[raw]  # y index of each local parameter, -1 if fixed
        self.zfix = np.where(self.ys < 0, space.z_fix[raw], 0.0) / sc.stress
        H, B = local_blocks(space)
        self.H, self.B = H * (sc.stress**2 / sc.energy), B  # y / s as unknowns: B per unit stress
        self.g = space.div_rhs.reshape(n_T, 6) / sc.stress
        self.contact = space.contact_y.ravel()
        self.cy = np.zeros(n_y)
        self.cy[self.contact] = -space.gap_weights().ravel() * (sc.stress / sc.energy)
        self._occurrences()
        self.c_slot = np.zeros(n_T * 15)
        has = self.count > 0
        self.c_slot[self.first[has]] = self.cy[has]  # the gap term on one copy
        self.c_slot = self.c_slot.reshape(n_T, 15)
        is_contact = np.zeros(n_y, bool)
        is_contact[self.contact] = True
        interior = np.flatnonzero((self.count == 2) & ~is_contact)
        self.pins = gauge_pins(space, self.ys, interior, self.first)
        interior = np.setdiff1d(interior, self.pins)
        self.mu_int = np.full(n_y, -1)
        self.mu_int[interior] = np.arange(len(interior))
        self.n_int = len(interior)
        on_face = is_contact[np.maximum(self.ys, 0)] & (self.ys >= 0)
        self.tri_c = np.flatnonzero(on_face.any(1))
        rest = np.setdiff1d(np.arange(n_T), self.tri_c)
        self.jumps = pair_jumps(space).reshape(len(self.contact), -1)
        self.stats = ActiveSetStats()
        self.n_mu = self.nnz = 0  # size and nonzeros of the last condensed system
        self.S_rest, self.f_rest = self.condense(rest, np.zeros(n_y, bool), self.mu_int, self.n_int)
        self.setup_time = time.perf_counter() - t0

    def _occurrences(self) -> None:
        """Each ``y`` appears in one or two local slots: ``first`` (flat slot index) and the
        copy signs (+1 first, -1 second) of the continuity rows ``z_first - z_second = 0``."""
        flat = self.ys.ravel()
        live = np.flatnonzero(flat >= 0)
        order = live[np.argsort(flat[live], kind="stable")]
        self.count = np.bincount(flat[live], minlength=self.space.n_y)
        if self.count.max(initial=0) > 2:  # pragma: no cover - a parameter is shared by two faces at most
            raise SolverError("internal: a stress parameter appears in more than two triangles")
        start = np.concatenate([[0], np.cumsum(self.count)[:-1]])
        self.first = order[np.minimum(start, len(order) - 1)]
        self.second = order[np.minimum(start + 1, len(order) - 1)]  # meaningful where count == 2
        self.sign = np.zeros(flat.shape)
        two = self.count == 2
        self.sign[order[start[two]]], self.sign[order[start[two] + 1]] = 1.0, -1.0
        self.sign = self.sign.reshape(self.ys.shape)

    def local_system(self, tri: np.ndarray, sep: np.ndarray) -> tuple:
        """Local KKT matrices ``(n, 21, 21)`` and right-hand sides (``mu = 0``) of triangles
        ``tri``; fixed parameters (and separated contact ones, ``sep`` over ``y``) become identity
        rows holding their value. ``B`` is scaled by ``beta = max|H| / max|B|`` per triangle so
        both blocks are O(1) on small elements (the divergence multipliers come out times ``beta``)."""
        H, B, ys = self.H[tri], self.B[tri], self.ys[tri]
        free = (ys >= 0) & ~sep[np.maximum(ys, 0)]
        zx = np.where(free, 0.0, self.zfix[tri])
        beta = np.abs(H).max((1, 2)) / np.abs(B).max((1, 2))
        Bf = B * free[:, None, :] * beta[:, None, None]
        K = np.zeros((len(tri), 21, 21))
        K[:, :15, :15] = H * free[:, :, None] * free[:, None, :]
        K[:, 15:, :15], K[:, :15, 15:] = Bf, Bf.transpose(0, 2, 1)
        d = np.arange(15)
        K[:, d, d] += ~free
        rhs_y = np.where(free, -self.c_slot[tri] - np.einsum("tij,tj->ti", H, zx), zx)
        rhs_l = beta[:, None] * (self.g[tri] - np.einsum("tij,tj->ti", B, zx))
        return K, np.concatenate([rhs_y, rhs_l], 1), beta, free

    def slot_mu(self, tri: np.ndarray, free: np.ndarray, mu_of_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Multiplier index (or -1) and sign of the local slots of ``tri``."""
        m = np.where(free, mu_of_y[np.maximum(self.ys[tri], 0)], -1)
        return m, np.where(m >= 0, self.sign[tri], 0.0)

    def condense(self, tri: np.ndarray, sep: np.ndarray, mu_of_y: np.ndarray, n_mu: int):
        """``S = sum N^T (K^-1)_yy N`` and ``f = sum N^T z(mu=0)`` of triangles ``tri`` (by chunks)."""
        S = sp.csr_matrix((n_mu, n_mu))
        f = np.zeros(n_mu)
        for lo in range(0, len(tri), CHUNK):
            t = tri[lo: lo + CHUNK]
            K, rhs, _, free = self.local_system(t, sep)
            try:
                Kinv = np.linalg.inv(K)
            except np.linalg.LinAlgError:
                raise SolverError("eq fast path: a triangle's local system is singular (every edge of it "
                                  "fixed?); use the CVXPY path (EquilibriumModel)") from None
            a = np.einsum("tij,tj->ti", Kinv[:, :15], rhs)
            m, sg = self.slot_mu(t, free, mu_of_y)
            vals = Kinv[:, :15, :15] * sg[:, :, None] * sg[:, None, :]
            keep = (m[:, :, None] >= 0) & (m[:, None, :] >= 0)
            rows = np.broadcast_to(m[:, :, None], keep.shape)[keep]
            cols = np.broadcast_to(m[:, None, :], keep.shape)[keep]
            S = S + sp.csr_matrix((vals[keep], (rows, cols)), shape=(n_mu, n_mu))
            f += np.bincount(m[m >= 0], weights=(sg * a)[m >= 0], minlength=n_mu)
        return S, f

    def recover(self, tri: np.ndarray, sep: np.ndarray, mu_of_y: np.ndarray, mu: np.ndarray) -> tuple:
        """Local parameters ``z (n, 15)``, divergence multipliers ``lam (n, 6)`` and the gradient
        ``H z + c + B^T lam`` (``= -N mu`` on free slots) of triangles ``tri``, by chunks."""
        out = []
        for lo in range(0, len(tri), CHUNK):
            t = tri[lo: lo + CHUNK]
            K, rhs, beta, free = self.local_system(t, sep)
            m, sg = self.slot_mu(t, free, mu_of_y)
            rhs[:, :15] -= sg * mu[np.maximum(m, 0)]
            sol = np.linalg.solve(K, rhs[..., None])[..., 0]
            z, lam = sol[:, :15], beta[:, None] * sol[:, 15:]
            grad = (np.einsum("tij,tj->ti", self.H[t], z) + self.c_slot[t]
                    + np.einsum("tji,tj->ti", self.B[t], lam))
            out.append((z, lam, grad))
        return tuple(np.concatenate(v) for v in zip(*out, strict=True)) if out else (np.zeros((0, 15)),) * 3

    def numbering(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Separated ``y`` mask, multiplier index of each ``y`` and their count for the set ``A``."""
        sep = np.zeros(self.space.n_y, bool)
        sep[self.contact[~A]] = True
        mu_of_y = self.mu_int.copy()
        mu_of_y[self.contact[A]] = self.n_int + np.arange(int(A.sum()))
        return sep, mu_of_y, self.n_int + int(A.sum())

    def factor_set(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Multipliers ``mu`` of the equality-constrained QP of contact set ``A`` (one Cholesky)."""
        sep, mu_of_y, n_mu = self.numbering(A)
        S_c, f_c = self.condense(self.tri_c, sep, mu_of_y, n_mu)
        R = self.S_rest  # padded with the contact multipliers' empty rows
        S = sp.csr_matrix((R.data, R.indices, np.concatenate([R.indptr, np.full(n_mu - self.n_int, R.nnz)])),
                          shape=(n_mu, n_mu)) + S_c
        f = np.concatenate([self.f_rest, np.zeros(n_mu - self.n_int)]) + f_c
        t0 = time.perf_counter()
        factor = SPDFactor(S)
        self.stats.backend = factor.method
        mu = factor.solve(f)
        scale = max(float(np.abs(f).max(initial=0.0)), float((abs(S) @ np.abs(mu)).max(initial=0.0)), 1e-300)
        res = float(np.abs(S @ mu - f).max(initial=0.0)) / scale
        # iterative refinement with the same factor: the copies of a parameter differ by the
        # residual, and each copy's triangle then misses equilibrium by as much (1e-9 of the stress
        # scale after one solve at level 3, which the exactness step's projection would then have
        # to factorise for); a step costs one solve
        for _ in range(REFINE_STEPS):
            if res <= REFINE_TOL:
                break
            step = mu + factor.solve(f - S @ mu)
            res_step = float(np.abs(S @ step - f).max(initial=0.0)) / scale
            if not res_step < 0.5 * res:  # stalled: the factor has nothing more to give
                break
            mu, res = step, res_step
        factor.close()
        self.stats.factor_time += time.perf_counter() - t0
        self.stats.factorizations += 1
        self.n_mu, self.nnz = n_mu, int(S.nnz)
        if not res <= RESIDUAL_TOL:
            why = f"the condensed system is singular or ill-conditioned (relative residual {res:.1e})"
            raise SolverError(f"{self.what}: {why}; {self.advice[0]}", cli=f"{self.what}: {why}; {self.advice[1]}")
        return mu, sep, mu_of_y

    def contact_state(self, mu: np.ndarray, sep: np.ndarray, mu_of_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact parameters ``p`` and openings ``nu = -(grad q + B^T lam)`` (0 in contact)."""
        z, _, grad = self.recover(self.tri_c, sep, mu_of_y, mu)
        out = []
        for slots in (self.first[self.contact], self.second[self.contact]):
            t, s = np.divmod(slots, 15)
            row = np.searchsorted(self.tri_c, t)
            out.append((z[row, s], grad[row, s]))
        (p, g1), (_, g2) = out
        return p, -(g1 + g2)

    def solve_set(self, A: np.ndarray) -> dict:
        """The multipliers ``mu`` of the set ``A`` (one Cholesky) and what the update reads: the
        contact parameters ``p`` and openings ``nu`` (0 in contact, where the opening is not a
        degree of freedom and is zero up to rounding)."""
        mu, sep, mu_of_y = self.factor_set(A)
        p, nu = self.contact_state(mu, sep, mu_of_y)
        nu[A] = 0.0
        return {"mu": mu, "sep": sep, "mu_of_y": mu_of_y, "p": p, "nu": nu}

    def next_set(self, A: np.ndarray, state: dict) -> np.ndarray:
        """Keep the compressive parameters (``p <= 0``), add the penetrating ones (``nu < 0``);
        rounding-level tension or penetration leaves a parameter as it is: at the edge of a
        smooth contact both ``p`` and ``nu`` tend to 0, and equivalent sets would otherwise
        alternate. Closest first (smallest opening) where the set must be completed."""
        p, nu = state["p"], state["nu"]
        tol_p = SET_TOL * max(float(np.abs(p).max(initial=0.0)), 1e-300)
        tol_nu = SET_TOL * max(float(np.abs(nu).max(initial=0.0)), float(np.abs(self.cy).max(initial=0.0)), 1e-300)
        return cover(np.where(A, p <= tol_p, nu < -tol_nu), np.where(A, -1.0, nu), self.jumps)

    def run(self, active: np.ndarray | None = None) -> dict:
        """Iterate the active set from ``active`` (contact parameters ``(n_c, 2)``; all in
        contact if ``None``) to its fixed point; return the set, ``mu``, ``p`` and ``nu``."""
        n_p = len(self.contact)
        A = np.ones(n_p, bool) if active is None else np.asarray(active, bool).reshape(n_p)
        A = cover(A, -self.cy[self.contact], self.jumps)  # closest first: the smallest gap weight
        A, state = iterate(self, A)
        return {"active": A, **state}

    def finish(self, state: dict) -> tuple[np.ndarray, np.ndarray]:
        """All parameters ``y`` (over ``s``, from each one's first copy) and the divergence
        multipliers ``(n_T, 6)`` of the final set."""
        z, lam, _ = self.recover(np.arange(self.space.n_tri), state["sep"], state["mu_of_y"], state["mu"])
        return z.ravel()[self.first], lam

    def objective(self, y: np.ndarray) -> float:
        """``1/2 y.H y + lin.y`` of :class:`EquilibriumModel` (without its constant), ``y`` over ``s``."""
        z = np.where(self.ys >= 0, y[np.maximum(self.ys, 0)], self.zfix)
        quad = np.einsum("ti,tij,tj->", z, self.H, z) - np.einsum("ti,tij,tj->", self.zfix, self.H, self.zfix)
        return 0.5 * float(quad) + float(self.cy @ y)


def coarse_active(space: EquilibriumSpace) -> np.ndarray | None:
    """Initial contact set ``(n_c, 2)`` from level ``L - 2`` of the same scene
    (:func:`cvxdual.fast.core.coarse_start`: every coarser level warm-started the same way, all
    in contact below level 2), transferred to ``space.contact_x``; ``None`` below level 2."""
    def solve_at(level: int, coarser):
        sp = EquilibriumSpace.from_scene(space.scene, level, space.triangulation)
        start = None if coarser is None else active_from_pairs(sp, *coarser)
        return sp.contact_x, HybridSolver(sp).run(start)["active"].reshape(-1, 2)

    coarse = coarse_start(space.mesh.level, solve_at)
    return None if coarse is None else active_from_pairs(space, *coarse)


def solve_eq_fast(space: EquilibriumSpace, active: np.ndarray | None = None) -> tuple[np.ndarray, SolverStats]:
    """Exactly admissible parameters ``y`` (physical, after :func:`make_exact`) and statistics.

    ``active``: initial contact set, ``(n_c, 2)`` booleans on the contact parameters (see
    :func:`active_from_pairs` to take it from the P0 fast path or a coarser level); ``None``
    takes it from :func:`coarse_active`. The statistics hold the final ``active`` set, the
    ``objective`` of :class:`~cvxdual.eq.model.EquilibriumModel` at the returned ``y``, the
    ``multipliers`` (divergence ``(n_T, 6)``, openings ``nu (n_c, 2)``, both nondimensional), the
    pinned multipliers and the times of the set-up, the factorisations and the exactness step."""
    t0 = time.perf_counter()
    warm = active is None
    if warm:
        active = coarse_active(space)
    t_warm = time.perf_counter() - t0
    hs = HybridSolver(space)
    state = hs.run(active)
    y, lam = hs.finish(state)
    t1 = time.perf_counter()
    s = space.scales.stress
    y_exact, post = make_exact(space, y * s)
    t2 = time.perf_counter()
    n_c = len(space.contact_y)
    st = hs.stats
    return y_exact, SolverStats(
        solver="fast", status="optimal", iterations=st.iterations, solve_time=t1 - t0, backend=st.backend,
        factorizations=st.factorizations, factor_time=st.factor_time, setup_time=hs.setup_time,
        warm_start="coarse level" if warm else "given", warm_start_time=t_warm, active=state["active"].reshape(n_c, 2),
        post_time=t2 - t1, n_variables=space.n_y, n_equalities=space.div.shape[0], n_inequalities=2 * n_c,
        objective=hs.objective(y_exact / s), multipliers={"divergence": lam, "opening": state["nu"].reshape(n_c, 2)},
        pinned=hs.pins, n_mu=hs.n_mu, nnz=hs.nnz, **post)
