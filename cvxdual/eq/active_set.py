"""The fast path of the equilibrium (Johnson-Mercier) dual (docs/equilibrium.md, section 10):
the active-set method of :mod:`cvxdual.activeset.core` on the KKT system of the QP of
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

from ..activeset.core import ActiveSetStats, coarse_start, cover, iterate, transfer_active, worst_flipped
from ..errors import MeshError, SolverError
from ..geometry.triangles import bary_gradients, sub_vertices
from ..kinds import Status
from ..linalg.factor import SPDFactor
from ..solution import SolverStats
from ..voigt import compliances
from .balance import PROJECT_TOL, make_exact, rigid_motions
from .element import (
    MASS0,
    REF_DIV_PINV,
    REF_DIVFREE,
    REF_ENERGY_DIVFREE,
    REF_ENERGY_MIXED,
    divergence_rows,
    divergence_to_reference,
    energy_coefficients,
    inverse2,
    reference_energy,
)
from .space import EquilibriumSpace

CHUNK = 16384  # triangles per batched local inversion: bounds the temporaries (21 x 21 each)
SET_TOL = 1e-10  # relative size of p or nu below which the contact state is left as it is (rounding)
RESIDUAL_TOL = 1e-8  # relative residual of the condensed solve above which it is not trusted
REFINE_STEPS, REFINE_TOL = 3, 1e-15  # iterative refinement of the condensed solve, until rounding
# correction solves of the final field's equilibrium residual, until it is below the exactness
# step's threshold (eq.balance.PROJECT_TOL) or stalls: one takes 1e-10 to ~5e-14 at levels 3-5 (nu =
# 0.3); near incompressibility each gains ~3 orders (nu = 0.4999: 4e-2, 2e-5, 7e-9, ...)
CORRECTIONS = 8
# condition number of a body's compliance (2 / (1 - 2 nu) for an isotropic one in plane strain)
# above which its triangles take the local KKT route, not the closed form: the closed form loses
# about a digit more, which near incompressibility shows (patch at nu = 0.4999, level 3: exact to
# 4e-8 against 3e-9; hertz level 5: eq L2 error 4.4e-4 against 3.9e-4). 1e3 is nu ~ 0.499;
# at nu = 0.49 (condition 100) both routes agree to every reported digit
CLOSED_FORM_COND = 1e3


def symmetric_product(L: sp.spmatrix, x: np.ndarray) -> np.ndarray:
    """``S x`` for the symmetric ``S`` whose lower triangle is ``L``."""
    return L @ x + L.T @ x - L.diagonal() * x


def local_blocks(space: EquilibriumSpace, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Energy ``H (n, 15, 15)`` (``1/2 z.H z = 1/2 int sigma:A sigma``, exact P1 mass per
    sub-triangle) and divergence rows ``B (n, 6, 15)`` in the local parameters of the (sorted)
    triangles ``tri``, physical units. A column's energy goes to the triangle of its face edge,
    whose tied normal slots hold its ``g`` (:func:`cvxdual.eq.space.tie_blocks`): each column then
    belongs to one triangle."""
    n = len(tri)
    N = space.local_basis(tri)
    _, area = bary_gradients(sub_vertices(space.X[tri]))
    A = compliances(space.scene)[space.body[tri]]
    K9 = (MASS0[None, :, None, :, None] * A[:, None, :, None, :]).reshape(n, 9, 9)
    H = np.zeros((n, 15, 15))
    for i in range(3):  # three sub-triangles; vectorised over the triangles
        Ni = N[:, 9 * i: 9 * i + 9, :]
        H += area[:, i, None, None] * (Ni.transpose(0, 2, 1) @ (K9 @ Ni))
    t, slots = column_slots(space)
    pos = np.searchsorted(tri, t)
    mine = (pos < n) & (tri[np.minimum(pos, n - 1)] == t) if n else np.zeros(len(t), bool)
    np.add.at(H, (pos[mine, None, None], slots[mine, :, None], slots[mine, None, :]),
              space.column_energy_blocks[mine])
    return H, divergence_rows(space.X[tri])[0] @ N


def column_slots(space: EquilibriumSpace) -> tuple[np.ndarray, np.ndarray]:
    """The triangle of each column's face edge and the local slots ``(n_col, 2)`` of its ``g`` at
    the left and right end (the tied normal slots)."""
    ed = space.edges
    eid = space.face_edge[space.columns]
    t, j = ed["owner"][eid].T
    left_end = (ed["hi"][eid] == space.faces.left[space.columns]).astype(int)  # global end of the left end
    ge = np.stack([left_end, 1 - left_end], 1)
    return t, 4 * j[:, None] + 2 * (ge ^ ed["flip"][t, j][:, None])


def kernel_rows(space: EquilibriumSpace, r: np.ndarray, y: np.ndarray, first: np.ndarray) -> np.ndarray:
    """``(len(y), m)``: the multiplier of each shared parameter ``y`` in the kernel of ``S`` made by
    each floating motion ``r``, ``mu_y = s_o * int phi_e (frame . r)`` (the work of the parameter on
    ``r``, signed by the outward normal of its first triangle; ``first`` its first copy's flat
    slot); 0 off the edge slots."""
    out = np.zeros((len(y), r.shape[2]))
    ed = space.edges
    t, slot = np.divmod(first[y], 15)
    edge = slot < 12
    t, slot = t[edge], slot[edge]
    j, e, k = slot // 4, (slot % 4) // 2, slot % 2
    g = ed["id"][t, j]
    E = e ^ ed["flip"][t, j]  # global end
    ends = np.stack([ed["lo"][g], ed["hi"][g]], 1)
    r_near, r_far = r[ends[np.arange(len(g)), E]], r[ends[np.arange(len(g)), 1 - E]]  # (m_p, 2, m)
    n = ed["ng"][g]
    frame = np.where(k[:, None] == 0, n, np.stack([-n[:, 1], n[:, 0]], 1))
    s_o = 1.0 - 2.0 * ed["flip"][t, j]  # n_out = n_g when the local edge runs lo -> hi
    out[edge] = (s_o * ed["length"][g] / 6.0)[:, None] * np.einsum("pi,pim->pm", frame, 2 * r_near + r_far)
    return out


def gauge_pins(space: EquilibriumSpace, ys: np.ndarray, pair_y: np.ndarray, first: np.ndarray,
               r: np.ndarray | None = None) -> np.ndarray:
    """``y`` indices (among the interior pairs ``pair_y``) whose multiplier is pinned, one per
    floating motion ``r`` (:func:`kernel_rows`); QR with column pivoting picks entries where the
    kernel vectors are independent."""
    r = rigid_motions(space.mesh, joint=True) if r is None else r
    if r.shape[2] == 0:
        return np.empty(0, int)
    edge = first[pair_y] % 15 < 12
    W = kernel_rows(space, r, pair_y[edge], first)
    _, _, piv = sla.qr(W.T, pivoting=True, mode="economic")
    return pair_y[edge][piv[: r.shape[2]]]


def well_conditioned(space: EquilibriumSpace) -> np.ndarray:
    """Per body: whether its compliance's condition number is at most ``CLOSED_FORM_COND`` (its
    plain triangles may then be condensed in closed form)."""
    return np.array([np.linalg.cond(b.material.compliance) <= CLOSED_FORM_COND for b in space.scene.bodies])


def pair_jumps(space: EquilibriumSpace) -> np.ndarray:
    """``(n_c, 2, m)``: what each contact parameter's constraint sees of the rigid motions of
    each body alone, ``int phi [r_y] dx`` over its edge (``phi`` its end's hat; ``[r_y]`` linear
    between the pairs); the parameters in contact must stop every motion that separates the
    bodies. Weighted, not the jump at the parameter's pair: the two parameters at one pair see a
    turn about it with opposite signs, so they stop it (with the pair's value alone a contact at
    one pair looked free to turn, and the closest parameter was forced into contact, in tension)."""
    r = rigid_motions(space.mesh, joint=False)
    up, lo = space.mesh.pairs.T
    dk = r[lo, 1] - r[up, 1]  # (n_pairs, m)
    n_c = len(space.contact_y)
    L = np.diff(space.mesh.pair_x)[:n_c, None] / 6.0
    a, b = dk[:n_c], dk[1: n_c + 1]
    return np.stack([L * (2 * a + b), L * (a + 2 * b)], 1)


def active_from_pairs(space: EquilibriumSpace, x: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Contact parameters ``(n_c, 2)`` in contact for an active set ``active`` given at abscissae
    ``x`` (the P0 fast path's pairs, or the ``contact_x`` of a coarser equilibrium solve):
    :func:`cvxdual.activeset.core.transfer_active` on the sorted points."""
    x, a = np.asarray(x, float).ravel(), np.asarray(active, bool).ravel()
    order = np.argsort(x, kind="stable")
    return transfer_active(x[order], a[order], space.contact_x)


class HybridSolver:
    """The linear algebra of the active-set method (:mod:`cvxdual.activeset.core`) on the equilibrium
    dual of one :class:`EquilibriumSpace`, in the nondimensional variables of
    :class:`~cvxdual.eq.model.EquilibriumModel`. It keeps the factor of the last contact set
    (:meth:`finish` reuses it, then :meth:`close` frees it)."""

    what = "eq fast path"
    advice = ("use the CVXPY path (EquilibriumModel, or solver='CLARABEL')",
              "use the CVXPY path (--solver CLARABEL)")

    def __init__(self, space: EquilibriumSpace, closed_form: bool = True):
        """``closed_form=False`` solves every triangle's local KKT system, none in closed form (an
        independent route to the same solution, for tests); a nearly incompressible body's
        triangles always take that route (``CLOSED_FORM_COND``)."""
        t0 = time.perf_counter()
        self.space = space
        sc = space.scales
        n_T, n_y = space.n_tri, space.n_y
        raw = space.dofs
        coo = space.Tm.tocoo()
        ycol = np.full(space.Tm.shape[0], -1)
        ycol[coo.row] = coo.col
        self.ys = ycol[raw]  # y index of each local parameter, -1 if fixed
        self.zfix = np.where(self.ys < 0, space.z_fix[raw], 0.0) / sc.stress
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
        rho = rigid_motions(space.mesh, joint=True)
        self.pins = gauge_pins(space, self.ys, interior, self.first, rho)
        interior = interior[~np.isin(interior, self.pins)]  # few pins: a mask, not a sort
        # the kernel of S on the multipliers (interior ones in mu_int order, the contact ones, the
        # pins'): the pinned continuity equations are made consistent with it (consistent())
        self.k_int, self.k_con, self.k_pin = (kernel_rows(space, rho, y, self.first)
                                              for y in (interior, self.contact, self.pins))
        self.mu_int = np.full(n_y, -1)
        self.mu_int[interior] = np.arange(len(interior))
        self.n_int = len(interior)
        on_face = is_contact[np.maximum(self.ys, 0)] & (self.ys >= 0)
        self.tri_c = np.flatnonzero(on_face.any(1))
        # plain triangles: every edge slot free, none on a contact face or under a column; their
        # local problem is the reference element's, solved in closed form (_plain_setup)
        plain = (self.ys[:, :12] >= 0).all(1) & ~on_face.any(1) & closed_form
        plain &= well_conditioned(space)[space.body]
        plain[column_slots(space)[0]] = False
        self.plain = np.flatnonzero(plain)
        self.special = np.flatnonzero(~plain)  # the general local KKT systems
        self.at = np.full(n_T, -1)  # row of a special triangle in H, B
        self.at[self.special] = np.arange(len(self.special))
        H, B = local_blocks(space, self.special)
        self.H, self.B = H * (sc.stress**2 / sc.energy), B  # y / s as unknowns: B per unit stress
        self._plain_setup()
        self.jumps = pair_jumps(space).reshape(len(self.contact), -1)
        self.stats = ActiveSetStats()
        self.n_mu = self.nnz = 0  # size and nonzeros of the last condensed system
        self.factor = self.S = None  # of the last contact set
        on_c = np.zeros(n_T, bool)
        on_c[self.tri_c] = True
        rest = self.special[~on_c[self.special]]
        S_rest, f_rest = self.condense(rest, np.zeros(n_y, bool), self.mu_int, self.n_int)
        S_plain, f_plain = self.condense_plain(self.mu_int, self.n_int, self.g[self.plain])
        self.S_rest, self.f_rest = S_rest + S_plain, f_rest + f_plain
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

    # -- the plain triangles: the divergence eliminated in closed form --------------------------
    def _plain_setup(self) -> None:
        """The plain triangles' parametrisation ``z = diag(D, I) (c_p + Z^ w)``: ``D`` their edge-dof
        blocks, ``Z^`` the 9 self-equilibrated reference combinations, ``c_p`` a reference field of
        the required divergence; energy ``H_w = sum_p A'_p Z^T G_p Z^`` (9 x 9, six fixed templates
        weighted by each triangle's compliance seen from the reference element) and its inverse."""
        sp_, sc, t = self.space, self.space.scales, self.plain
        _, area = bary_gradients(sp_.X[t])
        A = compliances(sp_.scene)[sp_.body[t]]
        self.ap = energy_coefficients(sp_.piola[t], A, np.abs(area)) * (sc.stress**2 / sc.energy)
        self.Hw_inv = np.empty((len(t), 9, 9))
        for lo in range(0, len(t), CHUNK):
            c = slice(lo, lo + CHUNK)
            try:
                self.Hw_inv[c] = np.linalg.inv(reference_energy(self.ap[c], REF_ENERGY_DIVFREE))
            except np.linalg.LinAlgError:  # a sliver's energy (the caller names it: eq.run.sliver_error)
                raise SolverError("eq fast path: a triangle's energy matrix is singular; use the CVXPY path "
                                  "(EquilibriumModel)") from None
        self.D = inverse2(sp_.coef[t])  # (n, 6, 2, 2): edge dofs of the reference parameters

    def _plain_base(self, c: slice, g: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Reference parameters ``c_p (n, 15)`` of divergence rows ``g`` and ``Z^T H^ c_p (n, 9)``
        for the plain triangles ``c``; zeros without divergence."""
        n = len(self.plain[c])
        if g is None or not np.any(g):
            return np.zeros((n, 15)), np.zeros((n, 9))
        cp = divergence_to_reference(self.space.X[self.plain[c]], g) @ REF_DIV_PINV.T
        mixed = (self.ap[c] @ REF_ENERGY_MIXED.reshape(6, 135)).reshape(-1, 9, 15)  # Z^T H^
        return cp, np.einsum("naj,nj->na", mixed, cp)

    def _plain_edges(self, c: slice, zr: np.ndarray) -> np.ndarray:
        """Local parameters ``(n, 15)`` of reference parameters ``zr`` of plain triangles ``c``."""
        ze = (self.D[c] @ zr[:, :12].reshape(-1, 6, 2, 1)).reshape(-1, 12)
        return np.concatenate([ze, zr[:, 12:]], 1)

    def condense_plain(self, mu_of_y: np.ndarray, n_mu: int, g: np.ndarray | None,
                       matrix: bool = True) -> tuple[sp.csr_matrix | None, np.ndarray]:
        """The plain triangles' part of ``S`` (lower triangle) and ``f`` (``g`` their divergence rows): ``E = D Z^_e
        H_w^-1 Z^_e^T D^T``, the edge block of the inverse local KKT system with the divergence
        eliminated exactly, and ``z(mu = 0) = diag(D, I) (c_p - Z^ H_w^-1 Z^T H^ c_p)``."""
        Ze = REF_DIVFREE[:12]
        rows, cols, vals = [], [], []
        f = np.zeros(n_mu)
        for lo in range(0, len(self.plain), CHUNK):
            c = slice(lo, lo + CHUNK)
            t = self.plain[c]
            m, sg = self.slot_mu(t, np.ones((len(t), 15), bool), mu_of_y)
            m, sg = m[:, :12], sg[:, :12]
            cp, coupling = self._plain_base(c, None if g is None else g[c])
            if np.any(cp):
                a = self._plain_edges(c, cp - np.einsum("nab,nb->na", self.Hw_inv[c], coupling) @ REF_DIVFREE.T)
                f += np.bincount(m[m >= 0], weights=(sg * a[:, :12])[m >= 0], minlength=n_mu)
            if matrix:
                Zd = (self.D[c] @ Ze.reshape(6, 2, 9)[None]).reshape(-1, 12, 9)  # D Z^_e, block by block
                E = Zd @ self.Hw_inv[c] @ Zd.transpose(0, 2, 1)
                keep = (m[:, None, :] >= 0) & (m[:, :, None] >= m[:, None, :])  # the lower triangle
                rows.append(np.broadcast_to(m[:, :, None], keep.shape)[keep])
                cols.append(np.broadcast_to(m[:, None, :], keep.shape)[keep])
                vals.append((E * sg[:, :, None] * sg[:, None, :])[keep])
        if not matrix:
            return None, f
        if not rows:
            return sp.csr_matrix((n_mu, n_mu)), f
        S = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_mu, n_mu))
        return S, f

    def recover_plain(self, mu_of_y: np.ndarray, mu: np.ndarray, g: np.ndarray | None,
                      rows: np.ndarray | None = None) -> np.ndarray:
        """Local parameters ``z (n_plain, 15)`` of the plain triangles (or of those at ``rows`` of
        ``self.plain``) for multipliers ``mu`` and divergence rows ``g`` (of all plain triangles):
        ``w = H_w^-1 (Z^_e^T D^T rhs - Z^T H^ c_p)``."""
        Ze, out = REF_DIVFREE[:12], []
        n = len(self.plain) if rows is None else len(rows)
        for lo in range(0, n, CHUNK):
            c = slice(lo, lo + CHUNK) if rows is None else rows[lo: lo + CHUNK]
            t = self.plain[c]
            m, sg = self.slot_mu(t, np.ones((len(t), 15), bool), mu_of_y)
            rhs = -(sg * mu[np.maximum(m, 0)])[:, :12]
            u = (self.D[c].transpose(0, 1, 3, 2) @ rhs.reshape(-1, 6, 2, 1)).reshape(-1, 12)  # D^T rhs
            cp, coupling = self._plain_base(c, None if g is None else g[c])
            w = (self.Hw_inv[c] @ (u @ Ze - coupling)[:, :, None])[:, :, 0]
            out.append(self._plain_edges(c, cp + w @ REF_DIVFREE.T))
        return np.concatenate(out) if out else np.zeros((0, 15))

    # -- the other triangles: their local KKT systems ------------------------------------------
    def local_system(self, tri: np.ndarray, sep: np.ndarray, g: np.ndarray | None = None,
                     homogeneous: bool = False) -> tuple:
        """Local KKT matrices ``(n, 21, 21)`` and right-hand sides (``mu = 0``) of triangles
        ``tri``; fixed parameters (and separated contact ones, ``sep`` over ``y``) become identity
        rows holding their value (0 if ``homogeneous``: no data, no gap term, divergence rows
        ``g``). ``B`` is scaled by ``beta = max|H| / max|B|`` per triangle so both blocks are O(1)
        on small elements (the divergence multipliers come out times ``beta``)."""
        H, B, ys = self.H[self.at[tri]], self.B[self.at[tri]], self.ys[tri]
        free = (ys >= 0) & ~sep[np.maximum(ys, 0)]
        zx = np.where(free, 0.0, 0.0 if homogeneous else self.zfix[tri])
        g = self.g[tri] if g is None else g
        beta = np.abs(H).max((1, 2)) / np.abs(B).max((1, 2))
        Bf = B * free[:, None, :] * beta[:, None, None]
        K = np.zeros((len(tri), 21, 21))
        K[:, :15, :15] = H * free[:, :, None] * free[:, None, :]
        K[:, 15:, :15], K[:, :15, 15:] = Bf, Bf.transpose(0, 2, 1)
        d = np.arange(15)
        K[:, d, d] += ~free
        c = 0.0 if homogeneous else self.c_slot[tri]
        rhs_y = np.where(free, -c - np.einsum("tij,tj->ti", H, zx), zx)
        rhs_l = beta[:, None] * (g - np.einsum("tij,tj->ti", B, zx))
        return K, np.concatenate([rhs_y, rhs_l], 1), beta, free

    def slot_mu(self, tri: np.ndarray, free: np.ndarray, mu_of_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Multiplier index (or -1) and sign of the local slots of ``tri``."""
        m = np.where(free, mu_of_y[np.maximum(self.ys[tri], 0)], -1)
        return m, np.where(m >= 0, self.sign[tri], 0.0)

    def condense(self, tri: np.ndarray, sep: np.ndarray, mu_of_y: np.ndarray, n_mu: int, g: np.ndarray | None = None,
                 homogeneous: bool = False, matrix: bool = True):
        """``S = sum N^T (K^-1)_yy N`` (its lower triangle; unless not ``matrix``) and ``f = sum N^T z(mu=0)`` of
        triangles ``tri`` (by chunks; ``g`` and ``homogeneous`` as in :meth:`local_system`)."""
        S = sp.csr_matrix((n_mu, n_mu)) if matrix else None
        f = np.zeros(n_mu)
        for lo in range(0, len(tri), CHUNK):
            t = tri[lo: lo + CHUNK]
            K, rhs, _, free = self.local_system(t, sep, None if g is None else g[lo: lo + CHUNK], homogeneous)
            try:
                Kinv = np.linalg.inv(K)
            except np.linalg.LinAlgError:
                raise SolverError("eq fast path: a triangle's local system is singular (every edge of it "
                                  "fixed?); use the CVXPY path (EquilibriumModel)") from None
            a = np.einsum("tij,tj->ti", Kinv[:, :15], rhs)
            m, sg = self.slot_mu(t, free, mu_of_y)
            if matrix:
                vals = Kinv[:, :15, :15] * sg[:, :, None] * sg[:, None, :]
                keep = (m[:, None, :] >= 0) & (m[:, :, None] >= m[:, None, :])  # the lower triangle
                rows = np.broadcast_to(m[:, :, None], keep.shape)[keep]
                cols = np.broadcast_to(m[:, None, :], keep.shape)[keep]
                S = S + sp.csr_matrix((vals[keep], (rows, cols)), shape=(n_mu, n_mu))
            f += np.bincount(m[m >= 0], weights=(sg * a)[m >= 0], minlength=n_mu)
        return S, f

    def recover(self, tri: np.ndarray, sep: np.ndarray, mu_of_y: np.ndarray, mu: np.ndarray,
                g: np.ndarray | None = None, homogeneous: bool = False) -> tuple:
        """Local parameters ``z (n, 15)`` and the gradient ``H z + c + B^T lam`` (``= -N mu`` on
        free slots) of triangles ``tri``, by chunks (``g``, ``homogeneous``: :meth:`local_system`)."""
        out = []
        for lo in range(0, len(tri), CHUNK):
            t = tri[lo: lo + CHUNK]
            K, rhs, beta, free = self.local_system(t, sep, None if g is None else g[lo: lo + CHUNK], homogeneous)
            m, sg = self.slot_mu(t, free, mu_of_y)
            rhs[:, :15] -= sg * mu[np.maximum(m, 0)]
            sol = np.linalg.solve(K, rhs[..., None])[..., 0]
            z, lam = sol[:, :15], beta[:, None] * sol[:, 15:]
            grad = (np.einsum("tij,tj->ti", self.H[self.at[t]], z) + (0.0 if homogeneous else self.c_slot[t])
                    + np.einsum("tji,tj->ti", self.B[self.at[t]], lam))
            out.append((z, grad))
        return tuple(np.concatenate(v) for v in zip(*out, strict=True)) if out else (np.zeros((0, 15)),) * 2

    # -- the condensed system -------------------------------------------------------------------
    def numbering(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Separated ``y`` mask, multiplier index of each ``y`` and their count for the set ``A``."""
        sep = np.zeros(self.space.n_y, bool)
        sep[self.contact[~A]] = True
        mu_of_y = self.mu_int.copy()
        mu_of_y[self.contact[A]] = self.n_int + np.arange(int(A.sum()))
        return sep, mu_of_y, self.n_int + int(A.sum())

    def solve_condensed(self, f: np.ndarray) -> tuple[np.ndarray, float]:
        """``mu = S^-1 f`` with the kept factor, refined until rounding (the copies of a parameter
        differ by the residual, and each copy's triangle then misses equilibrium by as much; a
        step costs one solve); the relative residual."""
        S = self.S
        mu = self.factor.solve(f)
        scale = max(float(np.abs(f).max(initial=0.0)), float(symmetric_product(abs(S), np.abs(mu)).max(initial=0.0)),
                    1e-300)
        res = float(np.abs(symmetric_product(S, mu) - f).max(initial=0.0)) / scale
        for _ in range(REFINE_STEPS):
            if res <= REFINE_TOL:
                break
            step = mu + self.factor.solve(f - symmetric_product(S, mu))
            res_step = float(np.abs(symmetric_product(S, step) - f).max(initial=0.0)) / scale
            if not res_step < 0.5 * res:  # stalled: the factor has nothing more to give
                break
            mu, res = step, res_step
        return mu, res

    def factor_set(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Multipliers ``mu`` of the equality-constrained QP of contact set ``A`` (one Cholesky)."""
        sep, mu_of_y, n_mu = self.numbering(A)
        S_c, f_c = self.condense(self.tri_c, sep, mu_of_y, n_mu)
        R = self.S_rest  # padded with the contact multipliers' empty rows
        S = sp.csr_matrix((R.data, R.indices, np.concatenate([R.indptr, np.full(n_mu - self.n_int, R.nnz)])),
                          shape=(n_mu, n_mu)) + S_c
        f = np.concatenate([self.f_rest, np.zeros(n_mu - self.n_int)]) + f_c
        t0 = time.perf_counter()
        self.close()
        self.factor, self.S = SPDFactor(S, lower=True), S
        self.stats.backend = self.factor.method
        mu, res = self.solve_condensed(f)
        if len(self.pins):
            mu = self.consistent(mu, A, sep, mu_of_y)
        self.stats.factor_time += time.perf_counter() - t0
        self.stats.factorizations += 1
        self.n_mu, self.nnz = n_mu, int(S.nnz)
        if not res <= RESIDUAL_TOL:
            why = f"the condensed system is singular or ill-conditioned (relative residual {res:.1e})"
            raise SolverError(f"{self.what}: {why}; {self.advice[0]}", cli=f"{self.what}: {why}; {self.advice[1]}",
                              reason=f"{self.what}: {why}")
        return mu, sep, mu_of_y

    def consistent(self, mu: np.ndarray, A: np.ndarray, sep: np.ndarray, mu_of_y: np.ndarray) -> np.ndarray:
        """``mu`` of the right-hand side made consistent: ``f - K c`` with ``K^T (f - K c) = 0``, ``K``
        the kernel of ``S`` (:func:`kernel_rows`) over all multipliers, the pins' included.

        The pins' continuity equations are dropped, which the balanced loads imply, but ``K^T f``
        is a sum of rounding errors over the whole mesh (``delta``): kept, it all lands on the pinned
        parameters' copies, which then differ by ``delta`` over their small weight (the patch
        without its symmetry supports: 8e-9 of the stress at level 4, ten times more a level), and
        the triangles around the pins carry a self-equilibrated error of that size. The copies'
        difference is ``K_pin^-T delta``, read from the two triangles of each pin; the change
        ``- S^-1 K c`` (one solve with the kept factor) spreads ``delta`` over all multipliers like
        the floating motions themselves, where it moves no stress."""
        slots = np.concatenate([self.first[self.pins], self.second[self.pins]])
        t, s = np.divmod(slots, 15)
        tri = np.unique(t)
        z = np.empty((len(tri), 15))
        special = self.at[tri] >= 0
        if special.any():
            z[special] = self.recover(tri[special], sep, mu_of_y, mu)[0]
        if not special.all():
            z[~special] = self.recover_plain(mu_of_y, mu, self.g[self.plain],
                                             rows=np.searchsorted(self.plain, tri[~special]))
        values = z[np.searchsorted(tri, t), s].reshape(2, -1)
        delta = self.k_pin.T @ (values[0] - values[1])  # K^T f: the copies differ by K_pin^-T of it
        K = np.vstack([self.k_int, self.k_con[A]])
        c = np.linalg.solve(K.T @ K + self.k_pin.T @ self.k_pin, delta)
        return mu - self.factor.solve(K @ c)

    def close(self) -> None:
        if self.factor is not None:
            self.factor.close()
            self.factor = self.S = None

    def contact_state(self, mu: np.ndarray, sep: np.ndarray, mu_of_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact parameters ``p`` and openings ``nu = -(grad q + B^T lam)`` (0 in contact)."""
        z, grad = self.recover(self.tri_c, sep, mu_of_y, mu)
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
        alternate. Closest first (smallest opening) where the set must be completed, a parameter
        just released last: its opening reads 0 (it was in contact), and taking it back first made
        a set with a tensile parameter look like a fixed point."""
        p, nu = state["p"], state["nu"]
        tol_p, tol_nu = self._set_tolerances(p, nu)
        return cover(np.where(A, p <= tol_p, nu < -tol_nu), np.where(A, np.inf, nu), self.jumps)

    def _set_tolerances(self, p: np.ndarray, nu: np.ndarray) -> tuple[float, float]:
        """The tension and penetration that count as rounding (:data:`SET_TOL` of their scales)."""
        return (SET_TOL * max(float(np.abs(p).max(initial=0.0)), 1e-300),
                SET_TOL * max(float(np.abs(nu).max(initial=0.0)), float(np.abs(self.cy).max(initial=0.0)), 1e-300))

    def one_change(self, A: np.ndarray, state: dict) -> np.ndarray:
        """:meth:`next_set` damped to one change: release the most tensile parameter or add the
        most penetrating one, whichever violates more against its own scale (a cycle's way out)."""
        p, nu = state["p"], state["nu"]
        tol_p, tol_nu = self._set_tolerances(p, nu)
        sp, snu = (max(float(np.abs(v).max(initial=0.0)), 1e-300) for v in (p, nu))
        keep = worst_flipped(A, np.where(p > tol_p, p / sp, 0.0), np.where(nu < -tol_nu, -nu / snu, 0.0))
        return cover(keep, np.where(A, np.inf, nu), self.jumps)

    def run(self, active: np.ndarray | None = None) -> dict:
        """Iterate the active set from ``active`` (contact parameters ``(n_c, 2)``; all in
        contact if ``None``) to its fixed point; return the set, ``mu``, ``p`` and ``nu``."""
        n_p = len(self.contact)
        A = np.ones(n_p, bool) if active is None else np.asarray(active, bool).reshape(n_p)
        A = cover(A, -self.cy[self.contact], self.jumps)  # closest first: the smallest gap weight
        A, state = iterate(self, A)
        return {"active": A, **state}

    def parameters(self, state: dict, g_special=None, g_plain=None, homogeneous: bool = False) -> np.ndarray:
        """All parameters ``y`` (over ``s``, from each one's first copy) of multipliers ``state["mu"]``."""
        z = np.empty((self.space.n_tri, 15))
        z[self.special] = self.recover(self.special, state["sep"], state["mu_of_y"], state["mu"],
                                       g_special, homogeneous)[0]
        # the divergence rows of the data (body forces) unless given, as recover() reads them
        g_plain = self.g[self.plain] if g_plain is None else g_plain
        z[self.plain] = self.recover_plain(state["mu_of_y"], state["mu"], g_plain)
        return z.ravel()[self.first]

    def finish(self, state: dict) -> tuple[np.ndarray, int]:
        """All parameters ``y`` (over ``s``) of the final set, and how many correction solves
        they took. Taking one copy of each shared parameter leaves the other copy's triangle off
        equilibrium by the condensed system's residual (``1e-10`` of the stress at level 4: a
        relative residual at rounding times the large multipliers); each correction solves the
        same system (the kept factor) for the field, zero on all data, that removes that
        divergence (``CORRECTIONS`` at most, while it helps)."""
        y = self.parameters(state)
        space, s = self.space, self.space.scales.stress
        last, done = np.inf, 0
        while True:
            r = space.divergence_residual(space.vertex_values(s * y)) / s  # (n_T, 6), over s
            size = float(np.abs(r).max(initial=0.0))
            if size <= PROJECT_TOL or size > 0.5 * last or done == CORRECTIONS:
                break
            r = self.balanced(r)
            sep, mu_of_y, n_mu = state["sep"], state["mu_of_y"], self.S.shape[0]
            _, f = self.condense(self.special, sep, mu_of_y, n_mu, -r[self.special], homogeneous=True, matrix=False)
            f += self.condense_plain(mu_of_y, n_mu, -r[self.plain], matrix=False)[1]
            mu, _ = self.solve_condensed(f)
            y = y + self.parameters({**state, "mu": mu}, -r[self.special], -r[self.plain], homogeneous=True)
            last, done = size, done + 1
        self.close()
        return y, done

    def balanced(self, r: np.ndarray) -> np.ndarray:
        """The residual ``r (n_T, 6)`` less its least-norm part with work on the floating motions.
        Its work is a sum of rounding errors (~1e-15 of the loads' work); a correction that kept
        it would put it all on a pinned parameter's second copy (whose continuity equation is
        dropped), divided by that parameter's small weight: 3e-13 of the stress in one triangle
        at level 3. Spread instead, it is ~1e-15 / n_T in every triangle."""
        rho = rigid_motions(self.space.mesh, joint=True)  # (n_nodes, 2, m)
        if rho.shape[2] == 0:
            return r
        X = self.space.X
        at = rho[self.space.tri]  # (n_T, 3, 2, m)
        centre = at.mean(1, keepdims=True)
        sub = (at + np.roll(at, -1, axis=1) + centre) / 3.0  # at each sub-triangle's centroid
        _, area = self.space.sub_geometry
        h = np.linalg.norm(X - np.roll(X, 1, axis=1), axis=2).max(1)
        a = ((area / h[:, None])[:, :, None, None] * sub).reshape(len(X) * 6, -1)  # (6 n_T, m)
        work = a.T @ r.ravel()
        return r - (a @ np.linalg.solve(a.T @ a, work)).reshape(r.shape)

    def objective(self, y: np.ndarray) -> float:
        """``1/2 y.H y + lin.y`` of :class:`EquilibriumModel` (without its constant), ``y`` over ``s``."""
        sp_, sc = self.space, self.space.scales
        zero = np.zeros_like(y)
        quad = (sp_.energy(sp_.vertex_values(sc.stress * y), sp_.column_values(sc.stress * y))
                - sp_.energy(sp_.vertex_values(zero), sp_.column_values(zero)))
        return float(quad) / sc.energy + float(self.cy @ y)


def coarse_active(space: EquilibriumSpace) -> np.ndarray | None:
    """Initial contact set ``(n_c, 2)`` from level ``L - 2`` of the same scene
    (:func:`cvxdual.activeset.core.coarse_start`: every coarser level warm-started the same way, all
    in contact below level 2), transferred to ``space.contact_x``; ``None`` below level 2. A level
    that cannot be meshed gives no hint."""
    def solve_at(level: int, coarser):
        try:
            sp = EquilibriumSpace.from_scene(space.scene, level, space.triangulation)
        except MeshError:
            return None
        start = None if coarser is None else active_from_pairs(sp, *coarser)
        hs = HybridSolver(sp)
        active = hs.run(start)["active"].reshape(-1, 2)
        hs.close()
        return sp.contact_x, active

    coarse = coarse_start(space.mesh.level, solve_at)
    return None if coarse is None else active_from_pairs(space, *coarse)


def solve_eq_fast(space: EquilibriumSpace, active: np.ndarray | None = None) -> tuple[np.ndarray, SolverStats]:
    """Exactly admissible parameters ``y`` (physical, after :func:`make_exact`) and statistics.

    ``active``: initial contact set, ``(n_c, 2)`` booleans on the contact parameters (see
    :func:`active_from_pairs` to take it from the P0 fast path or a coarser level); ``None``
    takes it from :func:`coarse_active`. The statistics hold the final ``active`` set, the
    ``objective`` of :class:`~cvxdual.eq.model.EquilibriumModel` at the returned ``y``, the
    ``multipliers`` (openings ``nu (n_c, 2)``, nondimensional), the pinned multipliers, the
    correction solves and the times of the set-up, the factorisations and the exactness step."""
    t0 = time.perf_counter()
    warm = active is None
    if warm:
        active = coarse_active(space)
    t_warm = time.perf_counter() - t0
    hs = HybridSolver(space)
    state = hs.run(active)
    y, corrections = hs.finish(state)
    t1 = time.perf_counter()
    s = space.scales.stress
    y_exact, post = make_exact(space, y * s)
    t2 = time.perf_counter()
    n_c = len(space.contact_y)
    st = hs.stats
    return y_exact, SolverStats(
        solver="fast", status=Status.OPTIMAL, iterations=st.iterations, solve_time=t1 - t0, backend=st.backend,
        factorizations=st.factorizations, factor_time=st.factor_time, setup_time=hs.setup_time,
        warm_start="coarse level" if warm else "given", warm_start_time=t_warm, active=state["active"].reshape(n_c, 2),
        corrections=corrections, post_time=t2 - t1, n_variables=space.n_y, n_equalities=6 * space.n_tri,
        n_inequalities=2 * n_c,
        objective=hs.objective(y_exact / s), multipliers={"opening": state["nu"].reshape(n_c, 2)},
        pinned=hs.pins, n_mu=hs.n_mu, nnz=hs.nnz, **post)
