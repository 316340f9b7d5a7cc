"""Rigid motions allowed by the supports, and the loads on them
(docs/theory.md#rigid-motions-and-load-balance).

A semi-coercive scene (a body held only by contact) has rigid motions in ``V_h``. Those
that keep the bodies together (*floating*) must receive no work from the loads: the small
quadrature imbalance is removed (only along motions the loaded dofs carry, by a change bounded by
``BALANCE_TOL`` of the loads) and reported, a real one is an error, and one equilibrium row per
floating motion is dropped (the *anchors*). Those that open the contact
(*separating*) must not be driven by the loads, or no admissible stress exists.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import NoAdmissibleStressError, UnbalancedLoadError

# Loads whose work on a rigid motion (that keeps the bodies in contact) is below this
# fraction of the total work magnitude are quadrature noise and are removed; above it they
# are a modelling error (the loads are genuinely unbalanced).
BALANCE_TOL = 1e-6
# The work of loads that do none on a motion (a vertical load on a horizontal slide) is rounding
# of their size, 1e-16 to 1e-14 of it: measured against 1e-8 of all the loads' work it stays under
# BALANCE_TOL, while any real load on the motion above 1e-14 of the total is still caught.
ROUNDING = 1e-8
# A combination of floating motions moves the loaded dofs by singular value s of their block; a
# unit combination of the six candidate motions moves them by at most ref (the block's norm). Below
# CARRIED * ref the loaded dofs do not carry the motion: a slide across the loads' direction leaves
# rounding there (~1e-16 ref), while any genuine motion of a loaded point moves it by its distance
# to the rotation centre over L (>= 1e-6 of ref for meshes double precision resolves). It is the
# threshold that found the modes (rows under 1e-9 of the largest singular value count as zero):
# the modes are not known more precisely than that.
CARRIED = 1e-9


@dataclass(frozen=True)
class RigidModes:
    """``floating`` ``(n_r, m)`` and ``separating`` ``(n_r, m2)`` motions in r, the ``anchors``
    (r indices whose equilibrium rows are dropped), the balanced loads ``f``, the relative
    work ``load_imbalance`` the raw loads did on the floating motions and the relative size
    ``load_correction`` of the change that balanced them (``|df| / |f|``)."""

    floating: np.ndarray
    separating: np.ndarray
    anchors: np.ndarray
    f: np.ndarray
    load_imbalance: float
    load_correction: float = 0.0


def candidates(mesh) -> np.ndarray:
    """The three rigid motions of each body ``(n_dofs, 6)``: rotations about the body's centre,
    scaled by the length scale so that all columns are O(1)."""
    L = mesh.scene.length_scale
    pts = mesh.points
    cand = np.zeros((2 * mesh.n_nodes, 6))
    for k, bm in enumerate(mesh.bodies):
        ids = bm.offset + np.arange(bm.n_nodes)
        c = pts[ids].mean(axis=0)
        cand[2 * ids, 3 * k] = 1.0
        cand[2 * ids + 1, 3 * k + 1] = 1.0
        cand[2 * ids, 3 * k + 2] = -(pts[ids, 1] - c[1]) / L
        cand[2 * ids + 1, 3 * k + 2] = (pts[ids, 0] - c[0]) / L
    return cand


def rigid_modes(mesh, pieces, sup, rdof: np.ndarray, ja: np.ndarray, jb: np.ndarray, Z,
                f: np.ndarray) -> RigidModes:
    """Find the rigid motions of ``V_h``; check and balance the loads ``f`` on them.

    A combination of the candidates is a motion of ``V_h`` if it respects fixed and tied dofs
    (components in the nodes' frames, ``sup`` the :class:`~cvxdual.system.boundary.Supports`)
    and strains no piece.
    """
    cand = candidates(mesh)
    n_dofs, n_r = len(rdof), int(rdof.max()) + 1
    in_frames = np.einsum("kci,kim->kcm", sup.frame, cand.reshape(-1, 2, 6)).reshape(n_dofs, 6)
    free = np.flatnonzero(rdof >= 0)
    first = np.full(n_r, n_dofs)  # the master dof (first carrying each r index)
    np.minimum.at(first, rdof[free], free)
    rows = [in_frames[rdof < 0], in_frames[free] - in_frames[first[rdof[free]]]]
    # rigid motions strain no straight triangle; only curved pieces (V_h extended along y) can
    curved = np.flatnonzero(pieces.kind != 0)
    strain = np.einsum("pij,pjm->pim", pieces.B[curved], cand[pieces.dofs[curved]]) * mesh.scene.length_scale
    rows.append(strain.reshape(-1, 6))
    _, s, vt = np.linalg.svd(np.concatenate(rows), full_matrices=False)
    # Exact rigid modes give rows that vanish to rounding; 1e-9 of the largest singular value
    # separates them from any genuine constraint (which contributes O(1) entries).
    null = vt[s <= 1e-9 * s[0]].T if s[0] > 0 else np.eye(6)
    empty = np.empty((n_r, 0))
    if null.shape[1] == 0:
        return RigidModes(empty, empty, np.empty(0, int), f, 0.0, 0.0)
    modes = in_frames[first] @ null  # (n_r, m)
    D = modes[jb] - modes[ja]
    D = np.vstack([D, np.zeros((max(0, D.shape[1] - len(D)), D.shape[1]))])  # at least m rows: vt2 is m x m
    _, s2, vt2 = np.linalg.svd(D, full_matrices=False)  # never the n_pairs^2 U
    rank = int(np.sum(s2 > 1e-9 * max(s2[0] if len(s2) else 0.0, 1.0)))
    floating, separating = modes @ vt2[rank:].T, modes @ vt2[:rank].T
    anchors, imbalance, correction = np.empty(0, int), 0.0, 0.0
    if floating.shape[1]:
        f, imbalance, correction = balance(Z @ floating, f, cand)
        keep = np.ones(n_r, bool)
        keep[jb] = False  # anchors off the pairs' lower dofs (those the fast path eliminates)
        J0 = np.flatnonzero(keep)
        anchors = np.sort(J0[pivot_columns(floating[J0].T)])
    if separating.shape[1]:
        _check_separation(Z @ separating, separating[jb] - separating[ja], f)
    return RigidModes(floating, separating, anchors, f, imbalance, correction)


def pivot_columns(A: np.ndarray) -> np.ndarray:
    """The ``m`` columns of ``A`` ``(m, n)``, ``m`` small, that column-pivoted QR picks first (largest
    remaining norm, then orthogonalise): the best-conditioned choice it knows. Done here in
    ``O(m^2 n)`` numpy because LAPACK's pivoted QR spends 0.2 s on one row of 6e5 columns."""
    R = np.array(A, float)
    piv = []
    for _ in range(A.shape[0]):
        k = int(np.argmax(np.einsum("ij,ij->j", R, R)))
        piv.append(k)
        q = R[:, k] / np.linalg.norm(R[:, k])
        R -= np.outer(q, q @ R)
    return np.array(piv, int)


def check_balance(work: np.ndarray, scale: np.ndarray, total: np.ndarray) -> float:
    """The loads' relative work on the floating motions (``work`` and its ``scale``, the summed
    size of its contributions, per motion); raise :class:`UnbalancedLoadError` above
    :data:`BALANCE_TOL`. ``total`` (per motion: all loads' size times the motion's) floors the
    scale: loads that do no work on a motion leave rounding over rounding otherwise."""
    scale = np.maximum(scale, ROUNDING * np.asarray(total))
    rel = float(np.max(np.abs(work) / np.where(scale > 0, scale, 1.0))) if len(work) else 0.0
    if rel > BALANCE_TOL:
        raise UnbalancedLoadError(
            f"the loads are unbalanced on {len(work)} rigid motion(s) that keep the bodies in contact "
            f"(relative work {rel:.3g} > {BALANCE_TOL:g}): balance the loads or add a support "
            "(clamped or sliding) that removes the motion")
    return rel


def balance(Q: np.ndarray, f: np.ndarray, cand: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Remove the loads' small work on the floating motions ``Q`` ``(n_dofs, m)`` (combinations of
    the candidates ``cand`` with orthonormal coefficients): ``(f, load_imbalance, load_correction)``."""
    work = Q.T @ f
    rel = check_balance(work, np.abs(Q).T @ np.abs(f), np.abs(f).sum() * np.abs(Q).max(axis=0, initial=0.0))
    loaded = f != 0
    if not np.any(loaded):
        return f, rel, 0.0
    # remove the imbalance on the loaded dofs only, so unloaded boundary stays free
    delta, size = balance_correction(Q[loaded].T, work, np.linalg.norm(cand[loaded], 2), f[loaded])
    f = f.copy()
    f[loaded] -= delta
    return f, rel, size


def balance_correction(G: np.ndarray, work: np.ndarray, ref: float, loads: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-norm change ``delta`` of the loaded values ``loads`` that removes their work ``work``
    ``(m,)`` on the floating motions (``G`` ``(m, n_l)``: the work of each loaded value on each
    motion) along the motions they carry (:func:`carried_solve`). Returns ``delta`` and
    ``|delta| / |loads|``; a change above :data:`BALANCE_TOL` of the loads is an
    :class:`UnbalancedLoadError`, never applied."""
    delta = carried_solve(G, work, ref)
    size = float(np.linalg.norm(delta) / max(float(np.linalg.norm(loads)), 1e-300))
    if size > BALANCE_TOL:
        raise UnbalancedLoadError(
            f"balancing the loads on the rigid motion(s) that keep the bodies in contact would change them by "
            f"{size:.3g} of their size (> {BALANCE_TOL:g}): balance the loads or add a support (clamped or "
            "sliding) that removes the motion")
    return delta, size


def carried_solve(G: np.ndarray, rhs: np.ndarray, ref: float) -> np.ndarray:
    """The least-norm ``x`` with ``(G x)`` equal to ``rhs`` along the combinations of rigid motions
    (rows of ``G`` ``(m, n)``, the motions being the candidates times orthonormal coefficients) that
    the values ``x`` carry: singular values of ``G`` above :data:`CARRIED` ``* ref``, ``ref`` the
    largest a unit combination of the candidates gives. Along the others ``rhs`` is ``s`` times
    the values, rounding, and dividing it by ``s`` would return a change as large as the values
    themselves (a floating slide across vertical loads: 4e-15 / 5e-32); it is left as it is."""
    if G.size == 0:
        return np.zeros(G.shape[1])
    U, s, Vt = np.linalg.svd(G, full_matrices=False)
    keep = s > CARRIED * ref
    return Vt[keep].T @ ((U[:, keep].T @ rhs) / s[keep])


def _check_separation(Q: np.ndarray, dk: np.ndarray, f: np.ndarray) -> None:
    """No admissible stress exists if the loads do positive work on a rigid motion ``Q`` that
    opens every contact pair (``dk`` its relative motion at the pairs): ``max L(rho)`` subject
    to ``rho'' - rho' <= 0`` must be 0."""
    work = Q.T @ f
    scale = np.abs(Q).T @ np.abs(f)
    best = separation_work(work, dk)
    if best > 1e-9 * max(float(scale.max()), 1e-300):
        raise NoAdmissibleStressError(
            "no statically admissible stress exists: the loads pull a body away from contact "
            f"(work {best:.3g} on a separating rigid motion); reverse the load or add a support")


def separation_work(work: np.ndarray, dk: np.ndarray) -> float:
    """``max work.rho`` over ``rho`` in ``[-1, 1]^m`` with ``dk rho <= 0`` (no pair closes)."""
    if len(work) == 1:
        # one motion (every built-in scene): rho = 0 and +-1 where it closes no pair are the
        # vertices; the answer without an LP (and without scipy.optimize's 0.1 s import)
        # the modes are O(1) (unit combinations of length-scaled candidates): relative motions at
        # rounding level close nothing (the LP's feasibility tolerance ignored them too)
        tol = 1e-12 * max(float(np.abs(dk).max(initial=0.0)), 1.0)
        signs = [s for s in (1.0, -1.0) if np.all(s * dk[:, 0] <= tol)]
        return max([0.0] + [s * float(work[0]) for s in signs])
    from scipy.optimize import linprog
    res = linprog(-work, A_ub=dk, b_ub=np.zeros(len(dk)), bounds=[(-1, 1)] * len(work), method="highs")
    return -res.fun if res.status == 0 else 0.0
