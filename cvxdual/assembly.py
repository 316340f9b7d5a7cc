"""Assembly of the discrete dual problem (MATH.md section 3), vectorised over pieces.

Names follow the paper where that helps a reader holding it: ``E`` with
``<lam_h, e(v_h)> = q . E t``, ``A_h = blockdiag(|P| A_P)``, the load vector ``f``, the tie
map ``Z`` (``q = Z r``), the pair change of variables ``T`` (the paper's ``F``: ``r = T y``
with ``y_k1 = r'_y(A_k)``, ``y_k2 = r''_y(B_k) - r'_y(A_k)``), the index sets ``J0``/``J-``
and the discrete ``u0`` (``q0``). Everything here is in the scene's physical units.

Vectors: ``q`` has two dofs per node (``2k`` = x, ``2k+1`` = y); ``t`` stacks the Voigt stress
``(s11, s22, s12)`` of piece ``p`` at ``3p .. 3p+2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.optimize import linprog

from .errors import NoAdmissibleStressError, SceneError, UnbalancedLoadError
from .mesh import Mesh
from .pieces import Pieces
from .quadrature import gauss01

# Loads whose work on a rigid motion (that keeps the bodies in contact) is below this
# fraction of the total work magnitude are quadrature noise and are removed; above it they
# are a modelling error (the loads are genuinely unbalanced).
BALANCE_TOL = 1e-6


@dataclass(frozen=True)
class Scales:
    """Reference length, stiffness and stress used to nondimensionalise the QP."""

    length: float
    modulus: float
    stress: float

    @property
    def displacement(self) -> float:
        return self.stress * self.length / self.modulus


@dataclass
class System:
    """The assembled discrete problem of one scene, mesh and triangulation."""

    mesh: Mesh
    pieces: Pieces
    E: sp.csr_matrix  # (n_dofs, 3 n_pieces)
    Ah: sp.csr_matrix  # (3 n_pieces, 3 n_pieces)
    C: np.ndarray  # (n_pieces, 3, 3) Hooke matrix of each piece
    f: np.ndarray  # (n_dofs,) balanced load vector
    f_raw: np.ndarray  # (n_dofs,) load vector before balancing
    load_imbalance: float  # relative work of the raw loads on the floating modes
    rdof: np.ndarray  # (n_dofs,) index of each dof in r, or -1 if fixed
    Z: sp.csr_matrix  # (n_dofs, n_r)
    ja: np.ndarray  # (n_pairs,) r index of the upper pair node's y dof
    jb: np.ndarray  # (n_pairs,) r index of the lower pair node's y dof
    eps: np.ndarray  # (n_pairs,) initial gap at the pairs
    width: np.ndarray  # (n_pairs,) tributary lengths w_k
    anchors: np.ndarray  # r indices whose equilibrium rows are dropped (floating modes)
    floating: np.ndarray  # (n_r, m) rigid motions keeping the bodies together
    separating: np.ndarray  # (n_r, m2) other rigid motions allowed by supports
    scales: Scales

    @property
    def n_dofs(self) -> int:
        return self.E.shape[0]

    @property
    def n_r(self) -> int:
        return self.Z.shape[1]

    @property
    def n_pieces(self) -> int:
        return len(self.pieces)

    @property
    def r0(self) -> np.ndarray:
        """Discrete ``u0`` in r: the gap on the lower pair node's y dof."""
        r0 = np.zeros(self.n_r)
        r0[self.jb] = self.eps
        return r0

    @property
    def q0(self) -> np.ndarray:
        return self.Z @ self.r0

    def T(self) -> sp.csr_matrix:
        """``r = T y``: ``r_a = y_a``, ``r_b = y_a + y_b`` for every pair (a, b)."""
        n = self.n_r
        return (sp.identity(n, format="csr")
                + sp.csr_matrix((np.ones(len(self.jb)), (self.jb, self.ja)), shape=(n, n)))

    def index_sets(self) -> tuple[np.ndarray, np.ndarray]:
        """``J0`` (equality rows, minus anchors) and ``J-`` (sign rows) in y coordinates."""
        minus = np.zeros(self.n_r, bool)
        minus[self.jb] = True
        keep = ~minus
        keep[self.anchors] = False
        return np.flatnonzero(keep), self.jb.copy()

    def strains(self, q: np.ndarray) -> np.ndarray:
        """Piecewise strains ``g_P = B_P q`` ``(n_pieces, 3)``."""
        return np.einsum("pij,pj->pi", self.pieces.B, q[self.pieces.dofs])

    def stresses_from_displacement(self, q: np.ndarray) -> np.ndarray:
        """``t_P = C_P B_P q`` ``(n_pieces, 3)``."""
        return np.einsum("pij,pj->pi", self.C, self.strains(q))

    def local_stiffness(self) -> np.ndarray:
        """``|P| B_P^T C_P B_P`` of every piece, ``(n_pieces, 6, 6)``."""
        p = self.pieces
        k = np.matmul(p.B.transpose(0, 2, 1), np.matmul(self.C, p.B))
        k *= p.area[:, None, None]
        return k

    def energy(self, q: np.ndarray) -> float:
        """Primal energy ``1/2 a(q, q) - L(q)``."""
        g = self.strains(q)
        return 0.5 * float(np.sum(self.pieces.area * np.einsum("pi,pij,pj->p", g, self.C, g))) - float(self.f @ q)


def assemble(mesh: Mesh, pieces: Pieces, ties: np.ndarray | None = None) -> System:
    """Assemble ``E``, ``A_h``, ``f``, ``Z`` and the contact data; check and balance the loads.

    ``ties`` (optional, ``(m, 2)`` node pairs ``(slave, master)``) ties whole nodes together
    (type-1 non-convex pieces).
    """
    scene = mesh.scene
    n_nodes = mesh.n_nodes
    n_dofs = 2 * n_nodes
    n_p = len(pieces)

    # E: column block p is |P| B_P^T
    dofs = pieces.dofs
    rows = np.broadcast_to(dofs[:, None, :], (n_p, 3, 6))
    cols = np.broadcast_to(3 * np.arange(n_p)[:, None, None] + np.arange(3)[None, :, None], (n_p, 3, 6))
    vals = pieces.area[:, None, None] * pieces.B
    E = sp.coo_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(n_dofs, 3 * n_p)).tocsr()

    Cb = np.stack([b.material.stiffness for b in scene.bodies])
    Ab = np.stack([b.material.compliance for b in scene.bodies])
    C = Cb[pieces.body]
    blk = pieces.area[:, None, None] * Ab[pieces.body]
    r3 = 3 * np.arange(n_p)[:, None, None] + np.arange(3)[None, :, None]
    Ah = sp.coo_matrix((blk.ravel(), (np.broadcast_to(r3, (n_p, 3, 3)).ravel(),
                                      np.broadcast_to(r3.transpose(0, 2, 1), (n_p, 3, 3)).ravel())),
                       shape=(3 * n_p, 3 * n_p)).tocsr()

    f = load_vector(mesh, pieces)
    rdof = _free_dofs(mesh, ties)
    n_r = int(rdof.max()) + 1
    free = rdof >= 0
    Z = sp.csr_matrix((np.ones(int(free.sum())), (np.flatnonzero(free), rdof[free])), shape=(n_dofs, n_r))

    up, lo = mesh.pairs[:, 0], mesh.pairs[:, 1]
    ja, jb = rdof[2 * up + 1], rdof[2 * lo + 1]
    if np.any(ja < 0) or np.any(jb < 0):
        raise SceneError("a contact node has its y displacement fixed by a support; "
                         "supports must not act on the contact interval")
    eps = scene.gap_at(mesh.pair_x)
    width = _tributary(mesh.pair_x)

    system = System(mesh=mesh, pieces=pieces, E=E, Ah=Ah, C=C, f=f, f_raw=f.copy(), load_imbalance=0.0,
                    rdof=rdof, Z=Z, ja=ja, jb=jb, eps=eps, width=width, anchors=np.empty(0, int),
                    floating=np.empty((n_r, 0)), separating=np.empty((n_r, 0)),
                    scales=Scales(1.0, 1.0, 1.0))
    _rigid_modes(system)
    system.scales = _scales(system)
    return system


def _tributary(x: np.ndarray) -> np.ndarray:
    """``w_k = int phi_k dx`` over the contact interval for hat functions on the pair abscissae."""
    d = np.diff(x)
    w = np.zeros_like(x)
    w[:-1] += 0.5 * d
    w[1:] += 0.5 * d
    return w


def _in_part(part, points: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Which side nodes lie in the part's interval (x on face/far, y on left/right). Supports
    act on these nodes and tractions on the edges between two of them, so both select the
    same stretch of boundary; interval ends on face/far are columns (see triangulation)."""
    if part.interval is None:
        return np.ones(len(nodes), bool)
    lo, hi = part.interval
    c = points[nodes, 0 if part.on in ("face", "far") else 1]
    tol = 1e-12 * (abs(lo) + abs(hi) + 1.0)  # ends are columns: only rounding separates them
    return (c >= lo - tol) & (c <= hi + tol)


def _side_nodes(bm, part, points) -> np.ndarray:
    nodes = bm.side_nodes(part.on)
    return nodes[_in_part(part, points, nodes)]


def _free_dofs(mesh: Mesh, ties) -> np.ndarray:
    """Index of every dof in ``r`` (``-1`` if fixed); tied nodes share their master's index."""
    n_dofs = 2 * mesh.n_nodes
    fixed = np.zeros(n_dofs, bool)
    for bm in mesh.bodies:
        for part in bm.body.boundary:
            if part.kind == "traction":
                continue
            nodes = _side_nodes(bm, part, mesh.points)
            if part.kind == "clamped":
                fixed[2 * nodes] = fixed[2 * nodes + 1] = True
            elif part.on in ("left", "right"):
                fixed[2 * nodes] = True  # sliding on a vertical side: u_x = 0
            else:
                fixed[2 * nodes + 1] = True  # sliding on a horizontal side: u_y = 0
    master = np.arange(n_dofs)
    if ties is not None and len(ties):
        s, m = np.asarray(ties).T
        for c in (0, 1):
            master[2 * s + c] = 2 * m + c
        fixed[2 * s] |= fixed[2 * m]
        fixed[2 * s + 1] |= fixed[2 * m + 1]
        fixed[2 * m] |= fixed[2 * s]
        fixed[2 * m + 1] |= fixed[2 * s + 1]
    own = (master == np.arange(n_dofs)) & ~fixed
    idx = np.full(n_dofs, -1)
    idx[own] = np.arange(int(own.sum()))
    rdof = np.where(fixed, -1, idx[master])
    return rdof


# -- loads -------------------------------------------------------------------------------

def _outward_normal(side: str, position: str, d: np.ndarray) -> np.ndarray:
    """Unit outward normals of straight side edges with direction vectors ``d`` ``(m, 2)``
    (edges run with increasing x on face/far, away from the face on left/right)."""
    ell = np.linalg.norm(d, axis=1, keepdims=True)
    left_normal = np.stack([-d[:, 1], d[:, 0]], 1) / ell  # tangent rotated by +90 degrees
    up = position == "upper"
    if side == "face":
        return -left_normal if up else left_normal
    if side == "far":
        return left_normal if up else -left_normal
    if side == "left":
        return left_normal if up else -left_normal
    return -left_normal if up else left_normal


def side_quadrature(mesh: Mesh, k: int, part, n_gauss: int = 8):
    """Gauss points on the part of a side: ``(a, b, x, u, nds)`` with end nodes ``a``, ``b``
    ``(m,)`` of each stretch, points ``x`` ``(m, g, 2)`` on the *true* boundary, the hat value
    ``u`` ``(g,)`` of node ``b`` there (``1 - u`` for ``a``) and the outward normal times the
    arc-length weight ``nds`` ``(m, g, 2)``.

    On the face the stretches are the intervals between face columns and the points lie on
    the arc ``y = f(x)``: the ``V_h`` trace there is linear in x between the two face nodes
    (on segments and curved pieces ``v_h`` is extended along y), whatever the triangulation.
    """
    bm = mesh.bodies[k]
    body = bm.body
    u, w = gauss01(n_gauss)
    nodes = bm.side_nodes(part.on)
    inside = _in_part(part, mesh.points, nodes)
    keep = inside[:-1] & inside[1:]
    a, b = nodes[:-1][keep], nodes[1:][keep]
    pa, pb = mesh.points[a], mesh.points[b]
    if part.on == "face":
        dx = pb[:, 0] - pa[:, 0]
        xs = pa[:, :1] + u[None, :] * dx[:, None]
        x = np.stack([xs, body.face.value(xs)], axis=-1)
        # outward normal * ds = (f', -1) dx below the upper body, (-f', 1) dx above the lower
        nds = body.sign * np.stack([body.face.slope(xs), -np.ones_like(xs)], axis=-1)
        nds = nds * (w[None, :] * dx[:, None])[..., None]
        return a, b, x, u, nds
    d = pb - pa
    x = pa[:, None, :] + u[None, :, None] * d[:, None, :]
    n = _outward_normal(part.on, body.position, d) * np.linalg.norm(d, axis=1, keepdims=True)
    return a, b, x, u, n[:, None, :] * w[None, :, None]


def load_vector(mesh: Mesh, pieces: Pieces, n_gauss: int = 8) -> np.ndarray:
    """``f_j = L(phi_j)``: body forces over the pieces and tractions along the sides.

    Tractions use ``n_gauss`` Gauss points per boundary stretch (degree ``2 n_gauss - 1``:
    enough for the smooth exact fields of the built-in scenes to machine precision)."""
    scene = mesh.scene
    f = np.zeros(2 * mesh.n_nodes)
    bf = np.array([b.body_force for b in scene.bodies])[pieces.body]  # (n_p, 2)
    for c in (0, 1):
        np.add.at(f, 2 * pieces.nodes + c, pieces.phi * bf[:, c, None])
    exact = None
    for k, bm in enumerate(mesh.bodies):
        for part in bm.body.boundary:
            if part.kind != "traction":
                continue
            a, b, x, u, nds = side_quadrature(mesh, k, part, n_gauss)
            if part.traction.kind == "uniform":
                ds = np.linalg.norm(nds, axis=-1, keepdims=True)
                P = np.array(part.traction.value) * ds  # traction times the length weight
            else:
                if exact is None:
                    from .exact import exact_field
                    exact = exact_field(scene)
                    if exact is None:
                        raise SceneError(f"body {bm.body.name!r}: traction 'exact' needs an [exact] field in the scene")
                s = exact.stress(k, x.reshape(-1, 2)).reshape(x.shape[0], x.shape[1], 3)
                P = np.stack([s[..., 0] * nds[..., 0] + s[..., 2] * nds[..., 1],
                              s[..., 2] * nds[..., 0] + s[..., 1] * nds[..., 1]], axis=-1)
            for c in (0, 1):
                np.add.at(f, 2 * a + c, np.sum((1 - u)[None, :] * P[..., c], axis=1))
                np.add.at(f, 2 * b + c, np.sum(u[None, :] * P[..., c], axis=1))
    if not np.all(np.isfinite(f)):
        raise SceneError("the load vector is not finite; check the loads and the exact field")
    return f


# -- rigid motions -----------------------------------------------------------------------

def _rigid_modes(system: System) -> None:
    """Find the rigid motions allowed by the supports; check and balance the loads on them.

    Candidates are the three rigid motions of each body (rotations about its centre, scaled
    by the length scale so all columns are O(1)); a combination is a mode of ``V_h`` if it
    respects fixed and tied dofs and strains no piece.
    """
    mesh, pieces = system.mesh, system.pieces
    L = mesh.scene.length_scale
    pts = mesh.points
    n_dofs = system.n_dofs
    cand = np.zeros((n_dofs, 6))
    node_body = np.concatenate([np.full(bm.n_nodes, k) for k, bm in enumerate(mesh.bodies)])
    for k in range(2):
        m = node_body == k
        c = pts[m].mean(axis=0)
        cand[2 * np.flatnonzero(m), 3 * k] = 1.0
        cand[2 * np.flatnonzero(m) + 1, 3 * k + 1] = 1.0
        cand[2 * np.flatnonzero(m), 3 * k + 2] = -(pts[m, 1] - c[1]) / L
        cand[2 * np.flatnonzero(m) + 1, 3 * k + 2] = (pts[m, 0] - c[0]) / L
    rdof = system.rdof
    rows = [cand[rdof < 0]]
    # tied dofs must move with their master (the first dof carrying each r index)
    free = np.flatnonzero(rdof >= 0)
    first = np.full(system.n_r, n_dofs)
    np.minimum.at(first, rdof[free], free)
    rows.append(cand[free] - cand[first[rdof[free]]])
    # rigid motions strain no straight triangle; only curved pieces (V_h extended along y) can
    curved = np.flatnonzero(pieces.kind != 0)
    strain = np.einsum("pij,pjm->pim", pieces.B[curved], cand[pieces.dofs[curved]]) * L
    rows.append(strain.reshape(-1, 6))
    D = np.concatenate(rows)
    _, s, vt = np.linalg.svd(D, full_matrices=False)
    # Exact rigid modes give rows that vanish to rounding; 1e-9 of the largest singular value
    # separates them from any genuine constraint (which contributes O(1) entries).
    null = vt[s <= 1e-9 * s[0]].T if s[0] > 0 else np.eye(6)
    if null.shape[1] == 0:
        return
    modes_r = cand[first] @ null  # (n_r, m)
    dk = modes_r[system.jb] - modes_r[system.ja]
    _, s2, vt2 = np.linalg.svd(dk, full_matrices=True)
    rank = int(np.sum(s2 > 1e-9 * max(s2[0] if len(s2) else 0.0, 1.0)))
    floating = modes_r @ vt2[rank:].T
    separating = modes_r @ vt2[:rank].T
    system.floating, system.separating = floating, separating
    if floating.shape[1]:
        _balance(system)
        J0 = np.setdiff1d(np.arange(system.n_r), system.jb)
        _, _, piv = sla.qr(floating[J0].T, pivoting=True, mode="economic")
        system.anchors = np.sort(J0[piv[: floating.shape[1]]])
    if separating.shape[1]:
        _check_separation(system)


def _balance(system: System) -> None:
    Q = system.Z @ system.floating  # (n_dofs, m)
    f = system.f
    work = Q.T @ f
    scale = np.abs(Q).T @ np.abs(f)
    rel = float(np.max(np.abs(work) / np.where(scale > 0, scale, 1.0)))
    system.load_imbalance = rel
    if rel > BALANCE_TOL:
        raise UnbalancedLoadError(
            f"the loads are unbalanced on {Q.shape[1]} rigid motion(s) that keep the bodies in contact "
            f"(relative work {rel:.3g} > {BALANCE_TOL:g}): balance the loads or add a support "
            "(clamped or sliding) that removes the motion")
    loaded = f != 0
    if not np.any(loaded):
        return
    Ql = Q[loaded]
    # remove the small quadrature imbalance on the loaded dofs only, so unloaded boundary stays free
    coef = np.linalg.lstsq(Ql.T @ Ql, work, rcond=None)[0]
    f = f.copy()
    f[loaded] -= Ql @ coef
    system.f = f


def _check_separation(system: System) -> None:
    """No admissible stress exists if the loads do positive work on a rigid motion that opens
    every contact pair (a body pulled away): ``max L(rho) s.t. rho'' - rho' <= 0`` must be 0."""
    Q = system.Z @ system.separating
    m = Q.shape[1]
    dk = system.separating[system.jb] - system.separating[system.ja]
    work = Q.T @ system.f
    scale = np.abs(Q).T @ np.abs(system.f)
    res = linprog(-work, A_ub=dk, b_ub=np.zeros(len(dk)), bounds=[(-1, 1)] * m, method="highs")
    if res.status == 0 and -res.fun > 1e-9 * max(float(scale.max()), 1e-300):
        raise NoAdmissibleStressError(
            "no statically admissible stress exists: the loads pull a body away from contact "
            f"(work {-res.fun:.3g} on a separating rigid motion); reverse the load or add a support")


def _scales(system: System) -> Scales:
    scene = system.mesh.scene
    L = scene.length_scale
    Eref = max(b.material.modulus for b in scene.bodies)
    s_load = float(np.sum(np.abs(system.f))) / L
    s_fit = Eref * float(max(0.0, -np.min(system.eps))) / L  # interference fit
    s = max(s_load, s_fit)
    if s == 0.0:
        s = Eref * 1e-6  # unloaded: any scale works, the solution is zero
    return Scales(L, Eref, s)
