"""Certification of equilibrium stresses: admissibility checks and two-sided bounds.

For ``sigma`` in ``S_EP`` (exactly admissible, :mod:`cvxdual.eq.space`) and a displacement
``v`` in ``K_eps`` (P1 on the mesh triangles, ``[v] = v''_y - v'_y <= eps`` at *every* ``x`` of
the contact interval), the hypercircle identity (docs/equilibrium.md) reads

    G = J(v) + L(u0) + S(sigma) = 1/2 ||sigma - C e(v)||_A^2 + int_a^b p (eps - [v]) dx >= 0,

with ``p = -sigma_nn >= 0`` and, for admissible ``sigma``, ``L(u0) + S(sigma) =
1/2 (A sigma, sigma) + int_a^b p eps dx`` (a *plus* sign: ``<sigma, e(u0)> - L(u0) =
-int p [u0] = -int p eps``). Hence ``-L(u0) - S(sigma) <= J(u) <= J(v)`` and
``||u - v||_a^2 + ||sigma - lam*||_A^2 <= 2 G``. Everything is integrated exactly: P1 mass
matrices on sub-triangles, linear data on edges, Gauss on the contact edges (exact for
polynomial gaps of degree <= 18, e.g. the parabola ``x^2 / 2R``).
"""

from __future__ import annotations

from functools import singledispatch
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from ..errors import SceneError
from ..geometry.quadrature import gauss01, triangle_rule
from ..geometry.triangles import bary_gradients
from ..linalg.sparse import assemble_blocks
from ..records import BoundContributions, Bounds, DisplacementFix, ExactErrors
from ..system.boundary import supports
from ..system.quadratic_gap import gap_curvature
from ..voigt import VOIGT_WEIGHT, compliances, stiffnesses
from .columns import CONCAVE1, column_at, column_gap
from .edges import outward_normals
from .element import MASS0, frame_rows, internal_rows
from .space import FIXED, N_GAUSS, EquilibriumSpace

ADMISSIBLE_TOL = 1e-12  # relative violation of any constraint still "exact to rounding"
# points per direction per sub-triangle for the errors against an exact field: 9 points change
# hertz's relative errors by under 1 % (the combined error by under 1e-4) against 100 at levels 3-5, at a
# quarter of a 36-point rule's time (reports/speed.md, "The quadrature rules' own error")
EQ_QUAD = 3
CHUNK_POINTS = 1 << 20  # quadrature points evaluated at once: bounds the temporaries


# -- the constraints on vertex values (independent of the parametrisation) -------------------

def _point_rows(t: np.ndarray, j: np.ndarray, a: np.ndarray, R: np.ndarray, n_T: int) -> sp.csr_matrix:
    """Rows ``R (m, 3)`` applied to the Voigt values at vertex ``a`` of sub-triangle ``j`` of ``t``."""
    cols = (27 * t + 9 * j + 3 * a)[:, None] + np.arange(3)[None, :]
    return assemble_blocks(np.arange(len(t))[:, None], cols, R[:, None, :], (len(t), 27 * n_T))


def _edge_dof_rows(space: EquilibriumSpace, raw: np.ndarray, t: np.ndarray, j: np.ndarray) -> sp.csr_matrix:
    """Rows of raw edge dofs ``raw`` (``4 g + 2 e + k``) evaluated in the triangle ``(t, j)`` holding edge ``g``."""
    g, e, k = raw // 4, (raw % 4) // 2, raw % 2
    a = e ^ space.edges["flip"][t, j]
    ed = space.edges
    return _point_rows(t, j, a, frame_rows(ed["ng"][g], ed["axis"][g])[np.arange(len(raw)), k], space.n_tri)


def _field(space: EquilibriumSpace, M: sp.spmatrix) -> sp.csr_matrix:
    """Rows on vertex values widened to the whole field (the column values after them)."""
    return sp.hstack([M, sp.csr_matrix((M.shape[0], 2 * len(space.columns)))], format="csr")


def _column_rows(space: EquilibriumSpace, f: np.ndarray, end: np.ndarray, coef: np.ndarray) -> sp.csr_matrix:
    """Rows ``coef * g`` of the column value at end ``end`` (0 left, 1 right) of face intervals ``f``
    (empty rows where ``f`` is no column)."""
    where = np.full(len(space.faces), -1)
    where[space.columns] = np.arange(len(space.columns))
    w = where[f]
    n = 27 * space.n_tri + 2 * len(space.columns)
    col = np.where(w >= 0, 27 * space.n_tri + 2 * w + end, 0)  # no column: an empty row
    return sp.csr_matrix((np.where(w >= 0, coef, 0.0), (np.arange(len(f)), col)), shape=(len(f), n))


def constraint_blocks(space: EquilibriumSpace) -> dict:
    """Every admissibility condition as ``name -> (matrix on the field, rhs, sense)``, the field
    being the vertex values and then the column values (:func:`field_values`), assembled from
    the geometry alone (not from the reduced basis), to check a stress field: internal and
    shared-edge traction jumps, ``h_T div sigma = -h_T F``, fixed boundary tractions, the face
    edges' tractions (``(0, g n_y)`` under a column, no tangential traction on a contact edge),
    fixed column values, action = reaction of the vertical stresses, and their sign ``<= 0``."""
    n_T = space.n_tri
    t12 = 12 * np.arange(n_T)[:, None] + np.arange(12)[None, :]
    t27 = 27 * np.arange(n_T)[:, None] + np.arange(27)[None, :]
    blk = assemble_blocks(t12, t27, internal_rows(space.X), (12 * n_T, 27 * n_T))
    return {"internal": (_field(space, blk), np.zeros(12 * n_T), "=="),
            "divergence": (_field(space, space.div), space.div_rhs, "=="), **edge_constraints(space)}


def local_residuals(space: EquilibriumSpace, sigma: np.ndarray) -> dict:
    """The ``internal`` and ``divergence`` blocks of :func:`constraint_blocks` evaluated triangle by
    triangle (``27 n_T`` vertex values), without forming their matrices: largest violations
    relative to the stress scale."""
    sig = np.asarray(sigma, float).reshape(space.n_tri, 27)
    internal = np.abs(internal_rows(space.X) @ sig[:, :, None]).max(initial=0.0)
    div = np.abs(space.divergence_residual(sig)).max(initial=0.0)
    return {"internal": float(internal / space.scales.stress), "divergence": float(div / space.scales.stress)}


def edge_constraints(space: EquilibriumSpace) -> dict:
    """The blocks of :func:`constraint_blocks` on edges and faces (all but ``internal`` and
    ``divergence``): a few rows per boundary or shared edge."""
    ed, faces = space.edges, space.faces
    out = {}
    order = np.argsort(ed["id"].ravel(), kind="stable")
    inner = np.flatnonzero(ed["count"] == 2)
    start = np.searchsorted(ed["id"].ravel()[order], inner)
    (t1, j1), (t2, j2) = np.divmod(order[start], 3), np.divmod(order[start + 1], 3)
    raw = (4 * inner[:, None] + np.arange(4)[None, :]).ravel()
    rep = lambda v: np.repeat(v, 4)  # noqa: E731 - four dofs per edge
    # the frame rows of both sides: both use n_g, so equal dofs mean equal tractions
    jump = _edge_dof_rows(space, raw, rep(t1), rep(j1)) - _edge_dof_rows(space, raw, rep(t2), rep(j2))
    out["shared"] = (_field(space, jump), np.zeros(len(raw)), "==")
    # the face intervals' edges: the traction at both ends, in the frame of the global edge
    tied = np.flatnonzero(np.isin(np.arange(len(faces)), space.columns) | _in_contact(space))
    f, end = np.repeat(tied, 2), np.tile([0, 1], len(tied))
    eid = space.face_edge[f]
    left_end = (ed["hi"][eid] == faces.left[f]).astype(int)
    ge = np.where(end == 0, left_end, 1 - left_end)  # the global end of the interval's end
    t, j = ed["owner"][eid].T
    normal, tangential = (_field(space, _edge_dof_rows(space, 4 * eid + 2 * ge + k, t, j)) for k in (0, 1))
    column = faces.column[f]
    ng = ed["ng"][eid]
    g_n, g_t = (_column_rows(space, f[column], end[column], c[column]) for c in (ng[:, 1] ** 2, ng[:, 0] * ng[:, 1]))
    out["column_tie"] = (sp.vstack([normal[column] - g_n, tangential[column] - g_t], format="csr"),
                         np.zeros(2 * int(column.sum())), "==")
    out["contact_tangential"] = (tangential[~column], np.zeros(int((~column).sum())), "==")
    # the vertical stress at each end: the column's g, or the flat edge's normal traction
    vertical = (sp.diags((~column).astype(float)) @ normal + _column_rows(space, f, end, np.ones(len(f)))).tocsr()
    raw_g = space.column_dofs.ravel()
    fixed_g = space.kind[raw_g] == FIXED
    every = _column_rows(space, np.repeat(space.columns, 2), np.tile([0, 1], len(space.columns)),
                         np.ones(2 * len(space.columns)))
    out["column_fixed"] = (every[fixed_g], space.z_fix[raw_g[fixed_g]], "==")
    contact = _in_contact(space)[f]
    upper = contact & (faces.body[f] == 0)
    lower = contact & (faces.body[f] == 1)
    out["action_reaction"] = (vertical[upper] - vertical[lower], np.zeros(int(upper.sum())), "==")
    out["sign"] = (vertical[lower], np.zeros(int(lower.sum())), "<=")
    # fixed tractions on the rest of the boundary (edges of the face intervals are checked above)
    face_edges = np.zeros(len(ed["keys"]), bool)
    face_edges[space.face_edge[tied]] = True
    b = ed["boundary"][~face_edges[ed["boundary"]]]
    braw = (4 * b[:, None] + np.arange(4)[None, :]).ravel()
    bt, bj = np.repeat(ed["owner"][b, 0], 4), np.repeat(ed["owner"][b, 1], 4)
    fixed = space.kind[braw] == FIXED
    rows = _edge_dof_rows(space, braw[fixed], bt[fixed], bj[fixed])
    out["traction"] = (_field(space, rows), space.z_fix[braw[fixed]], "==")
    return out


def _in_contact(space: EquilibriumSpace) -> np.ndarray:
    """Which face intervals lie in the contact interval (whose edges are the contact edges)."""
    a, b = space.scene.contact
    tol = 1e-12 * space.scene.length_scale  # contact ends are columns: only rounding separates them
    return (space.faces.x[:, 0] >= a - tol) & (space.faces.x[:, 1] <= b + tol)


def field_values(sigma: np.ndarray, g: np.ndarray | None = None) -> np.ndarray:
    """The field as one vector: vertex values ``sigma`` (any shape holding ``27 n_T`` values) and
    column values ``g`` ``(n_col, 2)`` (none on flat faces)."""
    parts = [np.asarray(sigma, float).reshape(-1)]
    if g is not None:
        parts.append(np.asarray(g, float).reshape(-1))
    return np.concatenate(parts)


def admissibility_residuals(space: EquilibriumSpace, sigma: np.ndarray, blocks: dict | None = None,
                            g: np.ndarray | None = None) -> dict:
    """Largest violation of each block of :func:`constraint_blocks` by vertex stresses
    ``sigma`` and column values ``g``, relative to the stress scale. Without ``blocks``, or with
    :func:`edge_constraints` only, the ``internal`` and ``divergence`` blocks are evaluated
    triangle by triangle (:func:`local_residuals`)."""
    blocks = edge_constraints(space) if blocks is None else blocks
    s = field_values(sigma, g)
    out = {} if "internal" in blocks else local_residuals(space, sigma)
    for name, (M, rhs, sense) in blocks.items():
        r = M @ s - rhs
        r = np.maximum(r, 0.0) if sense == "<=" else np.abs(r)
        out[name] = float(r.max() / space.scales.stress) if len(r) else 0.0
    return out


# -- the displacement side ---------------------------------------------------------------

def gap_curvature_bound(space: EquilibriumSpace, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """A guaranteed upper bound ``M`` of the gap's second derivative on each interval ``[x0, x1]``
    (:func:`~cvxdual.system.quadratic_gap.gap_curvature`)."""
    return gap_curvature(space.scene, x0, x1)


def contact_slack(space: EquilibriumSpace, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """``eps - [v]`` at the pairs ``(n_pairs,)`` and a guaranteed lower bound of its minimum over
    each contact edge ``(n_c,)``. ``[v]`` is linear between pairs (on the curved pieces ``v`` is
    the chord's or polygon's value extended along y), so ``s = eps - [v]`` has ``s'' <= M``
    (:func:`gap_curvature_bound`), and then ``s >= s0 (1 - u) + s1 u + kappa u (1 - u)`` with
    ``kappa = -M d^2 / 2`` (``d`` the edge's length, ``u`` in ``[0, 1]``): its minimum, the vertex
    of a parabola, bounds ``s`` from below at every ``x`` (for a quadratic gap it is ``s`` itself).
    The last value says the bound is rigorous (always, here)."""
    up, lo = space.mesh.pairs.T
    x = space.mesh.pair_x
    s = space.scene.gap_at(x) - (v[lo, 1] - v[up, 1])
    s0, s1 = s[:-1], s[1:]
    kappa = -0.5 * gap_curvature_bound(space, x[:-1], x[1:]) * np.diff(x) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.clip(0.5 + (s1 - s0) / (2.0 * kappa), 0.0, 1.0)
    u = np.where(kappa < 0, u, 0.0)
    smin = np.minimum(np.minimum(s0, s1), s0 * (1 - u) + s1 * u + kappa * u * (1 - u))
    return s, smin, True


def admissible_displacement(space: EquilibriumSpace, u: np.ndarray) -> tuple[np.ndarray, DisplacementFix]:
    """Make a displacement ``u (n_nodes, 2)`` of ``V_h`` pointwise admissible on the whole contact
    interval: ``[u]`` is linear between pairs, a convex gap lies *below* its chord, so
    ``[u] = eps`` at two pairs means ``[u] > eps`` in between. On every contact edge whose
    guaranteed minimum slack (:func:`contact_slack`) is below a margin the lower face nodes of the
    edge are lowered (the upper ones raised if the lower are supported) by the deficit; a node
    takes the larger shift of its two edges, and a type-1 tied node follows its face node, so the
    result stays in ``V_h``. Supports are untouched, so it stays in ``V``. Returns ``v`` and what
    was done (:class:`~cvxdual.records.DisplacementFix`)."""
    v = np.array(u, float).reshape(-1, 2)
    _, smin, exact = contact_slack(space, v)
    sc = space.scales
    margin = 1e-13 * max(float(np.abs(space.scene.gap_at(space.mesh.pair_x)).max()),
                         float(np.abs(v).max()), sc.stress * sc.length / sc.modulus)
    need = np.maximum(margin - smin, 0.0)
    need[smin >= margin] = 0.0
    shift = np.zeros(len(space.mesh.pairs))
    shift[:-1] = need
    shift[1:] = np.maximum(shift[1:], need)
    sup = supports(space.mesh)
    fixed = sup.fixed  # the pairs' frames are the identity (the assembly refuses others)
    up, lo = space.mesh.pairs.T
    on_lower = ~fixed[lo, 1]
    if np.any((shift > 0) & fixed[lo, 1] & fixed[up, 1]):
        raise SceneError("a contact pair has both y displacements supported; supports must not act on the contact")
    dy = np.zeros(len(v))
    dy[lo[on_lower]] = -shift[on_lower]
    dy[up[~on_lower]] = shift[~on_lower]
    tied = space.pieces.nodes[space.pieces.kind == CONCAVE1]  # (A, B, C): C moves with B
    dy[tied[:, 2]] = dy[tied[:, 1]]
    v[:, 1] += dy
    _, smin2, _ = contact_slack(space, v)
    return v, DisplacementFix(max_shift=float(shift.max(initial=0.0)), n_shifted=int(np.sum(shift > 0)),
                              min_slack_before=float(smin.min()), min_slack=float(smin2.min()), exact_min=exact,
                              support_violation=sup.violation(v),
                              displacement_scale=float(np.abs(v).max(initial=0.0)))


def strains(space: EquilibriumSpace, v: np.ndarray) -> np.ndarray:
    """Engineering strains ``(e11, e22, 2 e12)`` ``(n_T, 3)`` of a P1 displacement ``v (n_nodes, 2)``."""
    return p1_strains(space.X, v[space.tri])


def p1_strains(X: np.ndarray, vt: np.ndarray) -> np.ndarray:
    """Engineering strains ``(m, 3)`` of the linear interpolants of vertex values ``vt (m, 3, 2)`` on
    triangles ``X (m, 3, 2)``."""
    g, _ = bary_gradients(X)  # (m, 3, 2)
    du = np.einsum("tai,taj->tij", vt, g)  # du_i/dx_j
    return np.stack([du[:, 0, 0], du[:, 1, 1], du[:, 0, 1] + du[:, 1, 0]], 1)


def load_work(space: EquilibriumSpace, v: np.ndarray) -> float:
    """``L(v)`` for P1 ``v``: body forces (centroid rule, exact for linear ``v``) and the fixed
    boundary tractions of the space (linear per edge; for linear ``v`` their work equals that of
    the unprojected data, the L2 projection being exact against linears)."""
    _, area = bary_gradients(space.X)
    F = np.array([b.body_force for b in space.scene.bodies])[space.body]
    work = float(np.sum(area * np.einsum("tk,tk->t", F, v[space.tri].mean(1))))
    ed = space.edges
    b, t = edge_tractions(space)
    v0, v1 = v[ed["lo"][b]], v[ed["hi"][b]]
    ell = ed["length"][b] / 6.0
    work += float(np.sum(ell * (np.einsum("bi,bi->b", t[0], 2 * v0 + v1) + np.einsum("bi,bi->b", t[1], v0 + 2 * v1))))
    return work


def edge_tractions(space: EquilibriumSpace) -> tuple[np.ndarray, list[np.ndarray]]:
    """The boundary edges ``b`` of the straight triangles and the traction ``sigma n_out`` of the
    space's fixed data at their ``lo`` and ``hi`` ends (``[t_lo, t_hi]``, ``(m, 2)`` each; linear
    between; zero where the traction is free)."""
    ed = space.edges
    b = ed["boundary"]
    _, s_o = outward_normals(ed, space.X, space.mesh.points, b)
    a = ed["axis"][b]  # the frame of the edge's dofs
    ta = np.stack([-a[:, 1], a[:, 0]], 1)
    t = []
    for e in range(2):  # traction at the global ends from the fixed dofs (free ones are 0 in z_fix)
        dn, dt = space.z_fix[4 * b + 2 * e], space.z_fix[4 * b + 2 * e + 1]
        t.append(s_o[:, None] * (dn[:, None] * a + dt[:, None] * ta))  # sigma n_out = s_o sigma n_g
    return b, t


def slab_strains(space: EquilibriumSpace, v: np.ndarray) -> np.ndarray:
    """Strains ``(n_slabs, 3)`` of ``v`` on the curved pieces' slabs, where ``v`` is its face
    edge's value extended along y: ``(dv_x/dx, 0, dv_y/dx)`` along that edge."""
    a, b = space.pieces.slabs.edge_nodes.T
    d = (v[b] - v[a]) / (space.mesh.points[b, 0] - space.mesh.points[a, 0])[:, None]
    return np.stack([d[:, 0], np.zeros(len(d)), d[:, 1]], 1)


def primal_energy(space: EquilibriumSpace, v: np.ndarray) -> float:
    """``J(v) = 1/2 a(v, v) - L(v)`` on the exact bodies: the straight triangles and every slab
    of the curved pieces with its own strain (exactly: constant strains, exact areas)."""
    e = strains(space, v)
    _, area = bary_gradients(space.X)
    stiff = stiffnesses(space.scene)
    es = slab_strains(space, v)
    slabs = space.pieces.slabs
    curved = float(np.sum(space.pieces.slab_areas() * np.einsum("si,sij,sj->s", es, stiff[slabs.body], es)))
    straight = float(np.sum(area * np.einsum("ti,tij,tj->t", e, stiff[space.body], e)))
    return 0.5 * (straight + curved) + float(continuation_energy(space, v).sum()) - load_work(space, v)


def continuation_energy(space: EquilibriumSpace, v: np.ndarray) -> np.ndarray:
    """``1/2 a(v, v)`` on each piece of the bodies beyond the mesh (free arcs,
    :meth:`~cvxdual.geometry.mesh.Mesh.continuation`), where ``v`` continues as a P1 function and
    the stress is zero: its share of ``J(v)``, and of ``G`` (``sigma - C e(v) = -C e(v)`` there)."""
    nodes, weight, body = space.mesh.continuation()
    if not len(weight):
        return np.zeros(0)
    stiff = stiffnesses(space.scene)
    ec = p1_strains(space.mesh.points[nodes], v[nodes])
    return 0.5 * weight * np.einsum("ti,tij,tj->t", ec, stiff[body], ec)


# -- the bounds ------------------------------------------------------------------------------

def contact_tractions(space: EquilibriumSpace, sigma: np.ndarray, blocks: dict | None = None,
                      g: np.ndarray | None = None) -> np.ndarray:
    """The vertical stress (``sigma_nn`` on a flat face, ``g`` under a column) at both ends of each
    contact edge ``(n_c, 2)``, read from the lower face: minus the contact pressure."""
    blocks = edge_constraints(space) if blocks is None else blocks
    return (blocks["sign"][0] @ field_values(sigma, g)).reshape(-1, 2)


def contact_integrals(space: EquilibriumSpace, p: np.ndarray, v: np.ndarray | None,
                      jump: np.ndarray | None = None) -> np.ndarray:
    """``int p eps`` (``v`` None) or ``int p (eps - [v])`` per contact edge for P1 nodal values ``v``,
    or, given ``jump`` ``(n_c, g)`` (at the points of ``gauss01(N_GAUSS)`` on each edge), for that
    jump; Gauss ``N_GAUSS``."""
    u, w = gauss01(N_GAUSS)
    x0, x1 = space.contact_x[:, :1], space.contact_x[:, 1:]
    f = space.scene.gap_at(x0 + u[None, :] * (x1 - x0))
    if jump is not None:
        f = f - jump
    elif v is not None:
        up, lo = space.mesh.pairs.T
        jump = v[lo, 1] - v[up, 1]
        f = f - (jump[:-1, None] * (1 - u) + jump[1:, None] * u)
    pq = p[:, :1] * (1 - u) + p[:, 1:] * u
    return (pq * f) @ w * (x1 - x0)[:, 0]


def sub_energy(space: EquilibriumSpace, d: np.ndarray, matrices: np.ndarray | None = None) -> np.ndarray:
    """``1/2 int d:A d`` on each sub-triangle ``(n_T, 3)`` for vertex values ``d (n_T, 3, 3, 3)`` of a
    field linear on each (``A`` the compliance, or ``matrices`` ``(n_bodies, 3, 3)``: the stiffness
    for a strain's energy)."""
    _, area = space.sub_geometry
    A = (compliances(space.scene) if matrices is None else matrices)[space.body]
    return 0.5 * area * (d * ((MASS0 @ d) @ A[:, None])).sum((2, 3))  # matmul: einsum is 5x slower here


class KinematicTerms(NamedTuple):
    """What the certificate takes from a displacement: ``v`` made pointwise admissible and how
    (``fix``), the guaranteed lower bound of the slack on each contact edge (``slack_min``) and
    whether it is rigorous (``exact_min``), ``G``'s terms ``1/2 ||sigma - C e(v)||_A^2`` per
    sub-triangle (``sub``) and slab (``column``), ``int p (eps - [v])`` per contact edge
    (``contact``), ``J(v)`` (``energy``) and the energy beyond the mesh (``beyond``)."""

    v: object
    fix: DisplacementFix
    slack_min: np.ndarray
    exact_min: bool
    sub: np.ndarray
    column: np.ndarray
    contact: np.ndarray
    energy: float
    beyond: np.ndarray


@singledispatch
def kinematic_terms(displacement, space: EquilibriumSpace, sig: np.ndarray, g: np.ndarray, p: np.ndarray,
                    fix: bool) -> KinematicTerms:
    """The :class:`KinematicTerms` of a displacement against vertex stresses ``sig`` ``(n_T, 3, 3, 3)``,
    column values ``g`` and contact pressures ``p`` ``(n_c, 2)``: here of P1 nodal values (an array);
    the P2 side registers its own (:mod:`cvxdual.eq.kinematic_p2`)."""
    if not isinstance(displacement, np.ndarray):
        raise TypeError(f"no certificate for a displacement of type {type(displacement).__name__}")
    v, fixinfo = (admissible_displacement(space, displacement) if fix
                  else (np.asarray(displacement, float), DisplacementFix()))
    _, smin, exact_min = contact_slack(space, v)
    stiff = stiffnesses(space.scene)
    ce = np.einsum("tij,tj->ti", stiff[space.body], strains(space, v))
    sub = sub_energy(space, sig - ce[:, None, None, :])
    column = column_gap(space, g, np.einsum("sij,sj->si", stiff[space.pieces.slabs.body], slab_strains(space, v)))
    return KinematicTerms(v, fixinfo, smin, exact_min, sub, column, contact_integrals(space, p, v),
                          primal_energy(space, v), continuation_energy(space, v))


def certified_bounds(space: EquilibriumSpace, sigma: np.ndarray, displacement,
                     fix: bool = True, blocks: dict | None = None, g: np.ndarray | None = None) -> Bounds:
    """Two-sided energy bounds and the error bound of the field of vertex values ``sigma``
    (``27 n_T`` numbers) and column values ``g`` ``(n_col, 2)`` (curved faces), and a displacement
    of ``V_h`` (made pointwise admissible first unless ``fix`` is false).

    Returns a :class:`~cvxdual.records.Bounds`: ``energy_upper = J(v)``, ``energy_lower =
    -L(u0) - S(sigma)``, ``gap`` (``G`` as the sum of its non-negative terms), ``gap_identity``
    (``J(v) + L(u0) + S(sigma)``), ``error_bound = sqrt(2 G)``, ``contributions`` (``element
    (n_T,)``, ``sub (n_T, 3)``, ``column (n_slabs,)`` on the curved pieces' slabs, ``contact
    (n_c,)``, ``continuation`` on the pieces beyond free arcs, :func:`continuation_energy`),
    ``data_oscillation``, ``residuals``, ``displacement`` ``v`` and how it was fixed
    (``displacement_fix``), ``guaranteed`` and ``reasons``. ``blocks``: :func:`constraint_blocks`
    or :func:`edge_constraints` (the default).
    """
    blocks = edge_constraints(space) if blocks is None else blocks
    sig = np.asarray(sigma, float).reshape(space.n_tri, 3, 3, 3)
    g = np.zeros((0, 2)) if g is None else np.asarray(g, float).reshape(-1, 2)
    res = admissibility_residuals(space, sig, blocks, g)
    p = -contact_tractions(space, sig, blocks, g)
    kin = kinematic_terms(displacement, space, sig, g, p, fix)
    v, fixinfo, smin, exact_min = kin.v, kin.fix, kin.slack_min, kin.exact_min
    sub, column, contact, J, beyond = kin.sub, kin.column, kin.contact, kin.energy, kin.beyond
    comp = float(sub_energy(space, sig).sum()) + 0.5 * float(g.ravel() @ (space.column_energy_matrix() @ g.ravel()))
    pe = float(contact_integrals(space, p, None).sum())
    G = float(sub.sum() + column.sum() + contact.sum() + beyond.sum())
    osc = data_oscillation(space)
    reasons = []
    if max(res.values()) > ADMISSIBLE_TOL:
        reasons.append(f"sigma violates admissibility by {max(res.values()):.2g} (relative)")
    if smin.min() < 0 or not exact_min:
        reasons.append("v not shown pointwise admissible on the contact interval")
    if space.load_correction > ADMISSIBLE_TOL:  # rounding-level changes (quadrature) are as exact as sigma
        reasons.append(f"the loads were changed by {space.load_correction:.2g} of their size to balance them on a "
                       "floating rigid motion: the bounds hold for the changed loads")
    if osc > 0:
        reasons.append("tractions not linear on edges: bounds hold for the projected data; "
                       f"data oscillation {osc:.3g} not included")
    # a slanted line's normal component of v = t s is rounding, not 0: held to the stress's tolerance
    held = (fixinfo.support_violation or 0.0) / max(fixinfo.displacement_scale or 0.0, 1e-300)
    if held > ADMISSIBLE_TOL:
        reasons.append(f"v does not vanish on the supports (relative {held:.2g})")
    polygonal = space.mesh.polygonal_parts()
    if polygonal:
        reasons.append(f"curved parts {', '.join(polygonal)} (supported or loaded arcs, or splines) are meshed as "
                       "polygons: the bounds hold for the polygonal body")
    _, weight, body = space.mesh.continuation()
    if len(weight) and any(any(space.scene.bodies[k].body_force) for k in np.unique(body)):
        reasons.append("body force beyond the free arcs' polygons is not in L(v)")
    return Bounds(energy_upper=J, energy_lower=-(comp + pe), gap=G, gap_identity=J + comp + pe,
                  error_bound=float(np.sqrt(2.0 * max(G, 0.0))), complementary_energy=comp,
                  contributions=BoundContributions(element=sub.sum(1), sub=sub, column=column, contact=contact,
                                                   continuation=beyond),
                  data_oscillation=osc, residuals=res, displacement=v, displacement_fix=fixinfo,
                  guaranteed=not reasons, reasons=tuple(reasons),
                  kinematic="p1" if isinstance(v, np.ndarray) else "p2",
                  error_bound_rel=float(np.sqrt(2.0 * max(G, 0.0)) / np.sqrt(2.0 * comp)) if comp > 0 else None)


def data_oscillation(space: EquilibriumSpace) -> float:
    """``osc = (sum_e h_e ||P - Pi P||_e^2 / E_min)^(1/2)`` over traction edges: the part of the
    prescribed traction that linear edge tractions cannot carry, in energy-norm units. By
    orthogonality, ``|int (P - Pi P).w| <= ||P - Pi P||_e ||w - Pi w||_e``, and a trace/Korn
    inequality would bound the last factor by ``c h_e^(1/2) ||w||_a``; ``c`` is not computed
    here, so ``osc`` is an indicator and scenes with ``osc > 0`` are reported not guaranteed."""
    te = space.traction_edges
    if not len(te["ids"]):
        return 0.0
    h = space.edges["length"][te["ids"].astype(int)]
    Emin = min(b.material.modulus for b in space.scene.bodies)
    return float(np.sqrt(np.sum(h * te["osc2"]) / Emin))


# -- comparison with an exact field -----------------------------------------------

def exact_errors(space: EquilibriumSpace, sigma: np.ndarray, displacement: np.ndarray, exact, n: int = EQ_QUAD,
                 g: np.ndarray | None = None) -> ExactErrors:
    """Errors (:class:`~cvxdual.records.ExactErrors`) against an exact stress
    ``exact.stress(body, points)``: ``l2_rel`` of the field
    (vertex values ``sigma``, column values ``g``; ``||.||_0`` with ``s:s = s11^2 + s22^2 +
    2 s12^2``), ``stress_A = ||sigma - lam*||_A``, ``displacement_a = ||lam* - C e(v)||_A =
    ||u - v||_a`` (``lam* = C e(u)``), ``combined`` (the root sum of squares, which ``error_bound``
    must dominate) and ``l2_rel`` of ``C e(v)``. Collapsed Gauss rules with ``n*n`` points per
    sub-triangle and per slab of the curved pieces, by chunks and by body."""
    rs, w = triangle_rule(n)
    lam = np.stack([1 - rs.sum(1), rs[:, 0], rs[:, 1]], 1)  # (q, 3) barycentrics
    P = space.sub_points()  # (n_sub, 3, 2)
    _, area = bary_gradients(P)
    sub_body = np.repeat(space.body, 3)
    stiff = stiffnesses(space.scene)
    if isinstance(displacement, np.ndarray):
        ce = np.einsum("tij,tj->ti", stiff[space.body], strains(space, displacement))
    else:  # a P2 displacement: C e(v) linear on each sub-triangle, by its vertex values
        ce_v = np.einsum("tij,tsaj->tsai", stiff[space.body], displacement.sub_strains(space.X)).reshape(-1, 3, 3)
    sig = np.asarray(sigma, float).reshape(-1, 3, 3)
    acc = np.zeros(6)
    step = max(1, CHUNK_POINTS // len(w))
    for lo in range(0, len(P), step):
        s = slice(lo, lo + step)
        pts, field = lam @ P[s], lam @ sig[s]  # (m, q, 2), (m, q, 3)
        if isinstance(displacement, np.ndarray):
            kin = np.broadcast_to(ce[np.arange(lo, min(lo + step, len(P))) // 3][:, None, :], field.shape)
        else:
            kin = lam @ ce_v[s]
        wq = 2.0 * area[s, None] * w[None, :]
        _accumulate_errors(space, exact, sub_body[s], pts, field, kin, wq, acc)
    if len(space.pieces.slabs):
        g = np.asarray(g, float).reshape(-1, 2)
        sp_, sw, si = space.pieces.slab_quadrature(n)
        gx, _ = column_at(space, g, None, sp_, si)
        sbody = space.pieces.slabs.body[si]
        field = np.stack([np.zeros(len(gx)), gx, np.zeros(len(gx))], 1)
        es = (slab_strains(space, displacement)[si] if isinstance(displacement, np.ndarray)
              else displacement.slab_strains(si, sp_))
        kin = np.einsum("sij,sj->si", stiff[sbody], es)
        _accumulate_errors(space, exact, sbody, sp_[:, None], field[:, None], kin[:, None], sw[:, None], acc)
    dd, rr, dAd, rAr, eAe, ee = acc
    return ExactErrors(l2=float(np.sqrt(dd)), l2_rel=float(np.sqrt(dd / rr)), stress_A=float(np.sqrt(dAd)),
                       displacement_a=float(np.sqrt(eAe)), combined=float(np.sqrt(dAd + eAe)),
                       reference_A=float(np.sqrt(rAr)), l2_rel_displacement=float(np.sqrt(ee / rr)), rule=int(n))


def _accumulate_errors(space, exact, body, pts, field, kin, wq, acc) -> None:
    """Add, body by body, ``sum w d:d``, ``r:r``, ``d.A d``, ``r.A r``, ``e.A e``, ``e:e`` with ``r``
    the exact stress at ``pts (m, q, 2)``, ``d = field - r`` and ``e = r - kin``."""
    for k, b in enumerate(space.scene.bodies):
        m = np.flatnonzero(body == k)
        if not len(m):
            continue
        r = exact.stress(k, pts[m].reshape(-1, 2))
        d, e, wk = field[m].reshape(-1, 3) - r, r - kin[m].reshape(-1, 3), wq[m].ravel()
        A = b.material.compliance
        acc += [wk @ ((v * v) @ VOIGT_WEIGHT) for v in (d, r)] + [wk @ ((v @ A) * v).sum(1) for v in (d, r, e)] + \
               [wk @ ((e * e) @ VOIGT_WEIGHT)]
