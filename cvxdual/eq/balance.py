"""Balance and exactness of equilibrium fields: the rigid motions of the bodies, the work of
loads and tractions on them, the balanced boundary data of a space, its scales, and the
post-step that makes a solved field exactly admissible (contact tractions balanced, then the
field projected onto the equilibrium equations where a solver left a residual). ``space`` is an
:class:`~cvxdual.eq.space.EquilibriumSpace` (not imported: the space is built with these functions)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..geometry.mesh import Mesh
from ..geometry.triangles import bary_gradients
from ..system.assembly import Scales
from ..system.boundary import supports
from ..system.rigid import balance_correction, candidates, carried_solve, check_balance
from .edges import outward_normals
from .element import traction_rows

# equilibrium residual (relative to the stress scale) below which the field is left as solved: an
# order under the certificate's "exact to rounding" (eq.bounds.ADMISSIBLE_TOL) and above the
# rounding of evaluating it (~5e-14 measured); a projection costs a factorisation of B B^T
PROJECT_TOL = 1e-13


def node_body(mesh: Mesh) -> np.ndarray:
    return np.concatenate([np.full(bm.n_nodes, k) for k, bm in enumerate(mesh.bodies)])


def rigid_candidates(mesh: Mesh) -> np.ndarray:
    """``(n_nodes, 2, 6)``: translations and rotation of each body (:func:`cvxdual.system.rigid.candidates`)."""
    return candidates(mesh).reshape(mesh.n_nodes, 2, 6)


def _null(rows: np.ndarray, n: int) -> np.ndarray:
    if len(rows) == 0:
        return np.eye(n)
    _, s, vt = np.linalg.svd(rows, full_matrices=True)
    rank = int(np.sum(s > 1e-9 * max(s[0], 1e-300)))
    return vt[rank:].T


def rigid_motions(mesh: Mesh, joint: bool) -> np.ndarray:
    """Rigid motions allowed by the supports, ``(n_nodes, 2, m)``. ``joint``: of both bodies
    together keeping ``[r_y] = 0`` on the contact pairs (the floating modes, on which the loads
    must balance); otherwise of each body alone (with its contact tractions held fixed)."""
    R = rigid_candidates(mesh)
    sup = supports(mesh)
    rows = sup.rows(R)  # (n_fixed, 6)
    if joint:
        up, lo = mesh.pairs.T
        coef = _null(np.concatenate([rows, R[lo, 1] - R[up, 1]]), 6)
    else:
        nb = node_body(mesh)
        blocks = []
        for k in range(2):
            rk = sup.rows(R, nb == k)[:, 3 * k: 3 * k + 3]
            nk = _null(rk, 3)
            full = np.zeros((6, nk.shape[1]))
            full[3 * k: 3 * k + 3] = nk
            blocks.append(full)
        coef = np.concatenate(blocks, axis=1)
    return np.einsum("nij,jm->nim", R, coef)


def work_rows(space, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For displacements ``r (n_nodes, 2, m)`` linear on each triangle: the boundary work
    ``int_bnd (sigma n).r ds`` as rows ``W (m, 27 n_T)`` on vertex values (exact: linear times
    linear; sparse: boundary sub-triangles only), and the body-force work ``int F.r`` ``(m,)`` with
    its absolute size ``(m,)``."""
    ed, tri = space.edges, space.tri
    b = ed["boundary"]
    t, j = ed["owner"][b, 0], ed["owner"][b, 1]
    n_out, _ = outward_normals(ed, space.X, space.mesh.points, b)
    T = traction_rows(n_out)  # (nb, 2, 3)
    r0, r1 = r[tri[t, j]], r[tri[t, (j + 1) % 3]]  # (nb, 2, m)
    ell = ed["length"][b][:, None, None] / 6.0
    c0 = ell * np.einsum("bki,bkm->bim", T, 2 * r0 + r1)
    c1 = ell * np.einsum("bki,bkm->bim", T, r0 + 2 * r1)
    base = 27 * t + 9 * j
    cols = np.concatenate([(base[:, None] + 3 * a + np.arange(3)[None, :]).ravel() for a in (0, 1)])
    vals = np.concatenate([cv.reshape(-1, r.shape[2]) for cv in (c0, c1)])  # (rows of cols, m)
    m = r.shape[2]
    W = sp.csr_matrix((vals.T.ravel(), (np.repeat(np.arange(m), len(cols)), np.tile(cols, m))),
                      shape=(m, 27 * space.n_tri))  # duplicates (shared vertices) are summed
    _, area = bary_gradients(space.X)
    F = np.array([bd.body_force for bd in space.scene.bodies])[space.body]
    rm = r[tri].mean(1)  # (n_T, 2, m): r at the centroid
    terms = area[:, None] * np.einsum("tk,tkm->tm", F, rm)
    return W, terms.sum(0), np.abs(terms).sum(0)


def boundary_triangles(space) -> np.ndarray:
    """The triangles with an edge on the boundary (the only ones :func:`work_rows` reads)."""
    return np.unique(space.edges["owner"][space.edges["boundary"], 0])


def balance_loads(space) -> tuple[np.ndarray, float, float]:
    """Check the data on the floating modes; return the fixed parameters with a rounding-level
    imbalance removed from the loaded ones, the relative imbalance and the relative size of the
    change (:func:`cvxdual.system.rigid.balance_correction`: least-norm, only along the motions
    the loaded parameters carry, refused above ``BALANCE_TOL`` of them)."""
    r = rigid_motions(space.mesh, joint=True)
    if r.shape[2] == 0:
        return space.z_fix, 0.0, 0.0
    W, bf, bf_abs = work_rows(space, r)
    sigma0 = space.sigma0
    work = W @ sigma0 + bf
    te = space.traction_edges
    size = float(np.sum(space.edges["length"][te["ids"].astype(int)] * np.abs(te["c"]).sum((1, 2)))) \
        if len(te["ids"]) else 0.0  # all the tractions' size: |c| at both ends times the length
    # all the body forces' size (not their work on the motion, which is rounding for a motion they
    # do not push: a vertical weight on a horizontal slide)
    _, area = bary_gradients(space.X)
    F = np.array([bd.body_force for bd in space.scene.bodies])[space.body]
    total = (size + float(np.sum(area * np.abs(F).sum(1)))) * np.abs(r).max(axis=(0, 1))
    imbalance = check_balance(work, np.abs(W) @ np.abs(sigma0) + bf_abs, total)
    loaded = np.flatnonzero(space.z_fix != 0)
    if len(loaded) == 0:
        return space.z_fix, imbalance, 0.0
    V = space.vertex_map(boundary_triangles(space))
    G = (W @ V)[:, loaded].toarray()
    # the motions are the candidates times orthonormal coefficients (rigid_motions): the loaded
    # parameters' work on a unit combination of the candidates is at most the norm of this block
    Wc = work_rows(space, rigid_candidates(space.mesh))[0]
    ref = float(np.linalg.norm((Wc @ V)[:, loaded].toarray(), 2))
    delta, change = balance_correction(G, work, ref, space.z_fix[loaded])
    z_fix = space.z_fix.copy()
    z_fix[loaded] -= delta
    return z_fix, imbalance, change


def make_scales(space) -> Scales:
    """``L`` the scene's length, ``E`` the stiffest body's uniaxial modulus, ``s`` the load per
    unit length (tractions and body forces) or the stress of an interference fit."""
    scene = space.scene
    L = scene.length_scale
    E = max(b.material.modulus for b in scene.bodies)
    te = space.traction_edges
    force = float(np.sum(space.edges["length"][te["ids"].astype(int)]
                         * 0.5 * np.linalg.norm(te["c"], axis=2).sum(1))) if len(te["ids"]) else 0.0
    _, area = bary_gradients(space.X)
    F = np.array([b.body_force for b in scene.bodies])[space.body]
    force += float(np.sum(area * np.linalg.norm(F, axis=1)))
    s = max(force / L, E * max(0.0, -float(np.min(scene.gap_at(space.mesh.pair_x)))) / L)
    return Scales(L, E, s if s > 0 else E * 1e-6)


# -- exactness post-step -------------------------------------------------------------------

def balance_contact(space, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Clip the contact parameters to ``sigma_nn <= 0`` and make each body's own rigid-motion
    balance exact by the change ``dp = |p| * (a^T lam)`` (least change weighted by ``|p|``):
    zero parameters stay zero and the others keep their sign (relative changes are at the
    solver's tolerance). Returns the new ``y`` and the largest relative change."""
    y = y.copy()
    ci = space.contact_y.ravel()
    p = np.minimum(y[ci], 0.0)
    y[ci] = p
    r = rigid_motions(space.mesh, joint=False)
    if r.shape[2] == 0:
        return y, 0.0
    W, bf, _ = work_rows(space, r)
    V = space.vertex_map(boundary_triangles(space)) @ space.Tm[:, ci]
    a = (W @ V).toarray()
    resid = W @ space.vertex_values(y).ravel() + bf  # should be zero: each body in balance
    D = np.abs(p)
    # dp = sqrt(D) z, z the least-norm solution of (a sqrt(D)) z = -resid along the motions the
    # contact tractions carry (a body's slide along a flat contact is not: its row is rounding);
    # r is each body's candidates times orthonormal coefficients, so the candidates' block bounds it
    ref = float(np.linalg.norm((work_rows(space, rigid_candidates(space.mesh))[0] @ V).toarray()
                               * np.sqrt(D), 2))
    dp = np.sqrt(D) * carried_solve(a * np.sqrt(D), -resid, ref)
    rel = float(np.max(np.abs(dp) / np.where(D > 0, D, 1.0))) if len(dp) else 0.0
    if rel >= 1.0:
        raise SolverError(f"the solver's contact tractions are too far from balance to be corrected "
                          f"(relative change {rel:.2g}); tighten the solver tolerances")
    y[ci] = np.minimum(p + dp, 0.0)  # rel < 1 keeps every sign; the min only guards rounding
    return y, rel


def project_equilibrium(space, y: np.ndarray, iters: int = 30) -> tuple[np.ndarray, int]:
    """Least-change correction of the non-contact parameters so that ``div sigma + F = 0``
    holds to rounding, contact parameters held fixed: iterated Tikhonov
    ``dy = B^T (B B^T + mu I)^-1 r`` (one sparse factorisation). ``B`` has dependent rows
    (one per rigid motion of a body); they are consistent after :func:`balance_contact`, and
    the ``mu`` term only moves the multipliers along them, which ``B^T`` annihilates."""
    from ..linalg.factor import SPDFactor
    ci = space.contact_y.ravel()
    rest = np.setdiff1d(np.arange(space.n_y), ci)
    B = (space.div @ space.stress_map).tocsc()
    Br = B[:, rest].tocsr()
    rhs = space.div_rhs - space.div @ space.sigma0 - B[:, ci] @ y[ci]
    BB = (Br @ Br.T).tocsc()
    # Each step shrinks a residual component of eigenvalue lam by mu / (lam + mu): mu must be far
    # below the small eigenvalues of tiny elements (1e-10 left 1e-7 residuals on a mesh with a
    # 0.02-wide column), and only large enough to factorise along the dependent rows.
    mu = 1e-14 * float(BB.diagonal().max())
    # SPD (mu > 0): a sparse Cholesky (cvxdual.linalg.factor), 10x SuperLU's LU at level 4
    lu = SPDFactor((BB + mu * sp.identity(BB.shape[0], format="csr")).tocsr())
    y = y.copy()
    x = y[rest]
    tol = 1e-15 * max(float(np.abs(rhs).max()), space.scales.stress)
    done, last = 0, np.inf
    while done < iters:
        r = rhs - Br @ x
        size = float(np.abs(r).max())
        if size <= tol or size > 0.5 * last:  # at rounding, or stalled there
            break
        x = x + Br.T @ lu.solve(r)
        done, last = done + 1, size
    lu.close()
    y[rest] = x
    return y, done


def make_exact(space, y: np.ndarray) -> tuple[np.ndarray, dict]:
    """The post-step: clip the contact tractions to ``sigma_nn <= 0``; unless equilibrium then
    holds to rounding (``PROJECT_TOL``: the fast route's corrected fields do), balance the contact
    tractions and project onto the equilibrium equations (a solver's field at its tolerance).
    Everything else (traction continuity, boundary data, zero tangential contact traction,
    action = reaction) holds by the parametrisation."""
    ci = space.contact_y.ravel()
    y1 = y.copy()
    y1[ci] = np.minimum(y[ci], 0.0)
    rel, iters = float(np.abs(y1 - y).max() / max(float(np.abs(y[ci]).max(initial=0.0)), 1e-300)), 0
    if np.abs(space.divergence_residual(space.vertex_values(y1))).max() > PROJECT_TOL * space.scales.stress:
        # a rebalance moves the contact tractions by rounding, which alone is ~1e-13 of the stress
        # in the contact triangles: only where a projection follows
        y1, rel = balance_contact(space, y)
        y1, iters = project_equilibrium(space, y1)
    change = float(np.abs(y1 - y).max() / space.scales.stress)
    return y1, {"contact_change": rel, "projection_iterations": iters, "max_change": change}
