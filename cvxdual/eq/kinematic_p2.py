"""The certificate's terms of a P2 displacement (:class:`~cvxdual.system.p2_displacement.P2Displacement`,
docs/equilibrium.md section 12), registered with :func:`cvxdual.eq.bounds.kinematic_terms`.

Everything is integrated exactly, as for P1: the strain of a P2 displacement is linear on every
sub-triangle, so ``sigma - C e(v)`` is linear there and the P1 mass matrix integrates its energy
(:func:`~cvxdual.eq.bounds.sub_energy`); on a slab the trace's strain is linear in x (Gauss in x
times the slab's height, as the column stresses); on a contact edge the jump is quadratic and the
pressure linear (Gauss); the loads are linear on edges, the trace quadratic (Simpson is exact);
beyond the free arcs the neighbouring polynomial is continued and integrated on the exact region
(:meth:`~cvxdual.geometry.mesh.Mesh.continuation_rule`). Pointwise admissibility on the contact
interval is the guaranteed check of :mod:`cvxdual.system.quadratic_gap` with the gap's curvature
bound. The solve already holds every interval's Bernstein coefficients below the gap's
(:mod:`cvxdual.system.p2_system`), which is sufficient, so only rounding can leave a bound short;
there the lower face (or the upper where the lower is held) is lowered by the least quadratic that
restores it (:func:`~cvxdual.system.quadratic_gap.restore_admissible`).
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..geometry.quadrature import gauss01
from ..geometry.triangles import bary_gradients, sub_vertices
from ..records import DisplacementFix
from ..system.boundary import supports
from ..system.p2_displacement import P2Displacement
from ..system.p2_system import trace_shapes
from ..system.quadratic_gap import quadratic_slack_bound, restore_admissible
from ..voigt import stiffnesses
from .bounds import (
    KinematicTerms,
    contact_integrals,
    edge_tractions,
    gap_curvature_bound,
    kinematic_terms,
    sub_energy,
)
from .columns import column_gap, slab_abscissae, slab_points
from .space import N_GAUSS, EquilibriumSpace

CONTINUATION_POINTS = 12  # Gauss points in angle on a free arc's piece (its bounds are smooth in the angle)


def p2_slack(space: EquilibriumSpace, v: P2Displacement) -> tuple[np.ndarray, np.ndarray]:
    """``eps - [v]`` at the pairs (vertices and midpoints, by x) and a guaranteed lower bound of its
    minimum on every contact edge (:func:`~cvxdual.system.quadratic_gap.quadratic_slack_bound`)."""
    x = v.layout.pair_x
    e, jump = space.scene.gap_at(x), v.jumps()
    xv, ev, jn = x[0::2], e[0::2], jump[0::2]
    M = gap_curvature_bound(space, xv[:-1], xv[1:])
    return e - jump, quadratic_slack_bound(xv[:-1], xv[1:], ev[:-1], ev[1:], M, jn[:-1], jump[1::2], jn[1:])


def admissible_p2(space: EquilibriumSpace, v: P2Displacement) -> tuple[P2Displacement, DisplacementFix]:
    """``v`` lowered on one face where its jump may cross the gap between the pairs (module docstring),
    with a margin of ``1e-13`` of the problem's scale (as for P1); supports untouched, ties kept."""
    lay = v.layout
    x = lay.pair_x
    e, jump = space.scene.gap_at(x), v.jumps()
    xv = x[0::2]
    _, before = p2_slack(space, v)
    sc = space.scales
    margin = 1e-13 * max(float(np.abs(e).max()), float(np.abs(v.q).max()), sc.stress * sc.length / sc.modulus)
    qn, qm = restore_admissible(xv, e[0::2], gap_curvature_bound(space, xv[:-1], xv[1:]), jump[0::2], jump[1::2],
                                margin)
    shift = np.zeros(len(x))
    shift[0::2], shift[1::2] = jump[0::2] - qn, jump[1::2] - qm
    sup = supports(space.mesh, (lay.edge_node, lay.n_p2)).tied(lay.ties)
    up, lo = lay.pair_nodes.T
    on_lower = ~sup.fixed[lo, 1]
    if np.any((shift > 0) & sup.fixed[lo, 1] & sup.fixed[up, 1]):
        raise SceneError("a contact pair has both y displacements supported; supports must not act on the contact")
    dy = np.zeros(lay.n_p2)
    dy[lo[on_lower]] = -shift[on_lower]
    dy[up[~on_lower]] = shift[~on_lower]
    if len(lay.ties):
        dy[lay.ties[:, 0]] = dy[lay.ties[:, 1]]  # C and mid BC move with B
    out = v.moved(dy)
    _, after = p2_slack(space, out)
    return out, DisplacementFix(max_shift=float(shift.max(initial=0.0)), n_shifted=int(np.sum(shift > 0)),
                                min_slack_before=float(before.min()), min_slack=float(after.min()), exact_min=True,
                                support_violation=sup.violation(out.q),
                                displacement_scale=float(np.abs(out.q).max(initial=0.0)))


def slab_strains_p2(space: EquilibriumSpace, v: P2Displacement) -> tuple[np.ndarray, np.ndarray]:
    """The slabs' strains at their Gauss abscissae ``(n_s, N_GAUSS, 3)`` and the weights times the
    height there ``(n_s, N_GAUSS)`` (:func:`~cvxdual.eq.columns.slab_points`)."""
    xs = slab_abscissae(space.pieces)
    si = np.repeat(np.arange(len(xs)), xs.shape[1])
    wh, _ = slab_points(space.pieces, space.faces, np.zeros(len(xs), int))
    return v.slab_strains(si, xs.ravel()).reshape(xs.shape + (3,)), wh


def load_work_p2(space: EquilibriumSpace, v: P2Displacement) -> float:
    """``L(v)``: constant body forces on the straight triangles (a quadratic's mean on a sub-triangle is
    the mean of its edge midpoints) and the space's fixed tractions, linear on each boundary edge
    against the quadratic trace (Simpson's rule, exact for cubics)."""
    _, area = space.sub_geometry  # (n_T, 3)
    F = np.array([b.body_force for b in space.scene.bodies])[space.body]
    mids = v.sub_values()[:, :, 3:].mean(2)  # (n_T, 3, 2)
    work = float(np.sum(area * np.einsum("tk,tjk->tj", F, mids)))
    ed = space.edges
    b, (t0, t1) = edge_tractions(space)
    lo, hi = ed["lo"][b], ed["hi"][b]
    v0, v1, vm = v.q[lo], v.q[hi], v.q[v.layout.edge_node(lo, hi)]
    simpson = np.einsum("bi,bi->b", t0, v0) + np.einsum("bi,bi->b", t0 + t1, 2 * vm) + np.einsum("bi,bi->b", t1, v1)
    return work + float(np.sum(ed["length"][b] / 6.0 * simpson))


def p2_strains_at(P: np.ndarray, values: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``(m, q, 3)``: engineering strains at points ``pts`` ``(m, q, 2)`` of the quadratics with values
    ``values`` ``(m, 6, 2)`` at the P2 nodes of triangles ``P`` ``(m, 3, 2)`` (vertices, then the
    midpoints of ``(0, 1), (1, 2), (2, 0)``), the points inside the triangle or not."""
    G, _ = bary_gradients(P)  # (m, 3, 2)
    lam = np.eye(3)[0] + np.einsum("mad,mqd->mqa", G, pts - P[:, None, 0])
    vert = np.einsum("mqa,mad->mqad", 4 * lam - 1, G)
    edge = [4 * (lam[..., a, None] * G[:, None, b] + lam[..., b, None] * G[:, None, a]) for a, b in ((0, 1), (1, 2),
                                                                                                     (2, 0))]
    grad = np.concatenate([vert, np.stack(edge, 2)], 2)  # (m, q, 6, 2)
    du = np.einsum("mki,mqkj->mqij", values, grad)
    return np.stack([du[..., 0, 0], du[..., 1, 1], du[..., 0, 1] + du[..., 1, 0]], -1)


def continuation_p2(space: EquilibriumSpace, v: P2Displacement) -> np.ndarray:
    """``1/2 a(v, v)`` on each piece beyond the free arcs ``(m,)``: on a segment beyond a chord, the
    quadratic of the sub-triangle on the chord continued; on a corner of a hole's tangent polygon,
    the quadratic interpolant of its three nodes and its two mesh edges' midpoints (the chord's
    middle: the mean of its ends; any value keeps ``v`` continuous)."""
    mesh, lay = space.mesh, v.layout
    nodes, weight, body = mesh.continuation()
    if not len(weight):
        return np.zeros(0)
    rule = mesh.continuation_rule(CONTINUATION_POINTS)
    n = mesh.n_nodes
    code = lambda t: np.sort(t, 1) @ np.array([n * n, n, 1], np.int64)  # noqa: E731 - a triangle's node set
    tcode = code(lay.tri.astype(np.int64))
    order = np.argsort(tcode)
    pos = order[np.clip(np.searchsorted(tcode[order], code(nodes.astype(np.int64))), 0, len(order) - 1)]
    seg = tcode[pos] == code(nodes.astype(np.int64))
    P = np.zeros((len(nodes), 3, 2))
    vals = np.zeros((len(nodes), 6, 2))
    if seg.any():  # the sub-triangle on the chord: beyond its outer edge (X_j, X_j+1), lambda_(j+2) < 0
        t = pos[seg]
        X = space.X[t]
        G, _ = bary_gradients(X)
        c = rule.points[seg].mean(1)
        lam = np.eye(3)[0] + np.einsum("mad,md->ma", G, c - X[:, 0])
        j = (np.argmin(lam, 1) + 1) % 3
        P[seg] = sub_vertices(X)[np.arange(len(t)), j]
        vals[seg] = v.sub_values()[t, j]
    cor = ~seg
    if cor.any():
        a, b, c = nodes[cor].T
        P[cor] = mesh.points[nodes[cor]]
        q = v.q
        vals[cor] = np.stack([q[a], q[b], q[c], q[lay.edge_node(a, b)], q[lay.edge_node(b, c)],
                              0.5 * (q[c] + q[a])], 1)
    e = p2_strains_at(P, vals, rule.points)
    C = stiffnesses(space.scene)[body]
    return 0.5 * np.einsum("mq,mqi,mij,mqj->m", rule.weights, e, C, e)


@kinematic_terms.register
def _p2_terms(displacement: P2Displacement, space: EquilibriumSpace, sig: np.ndarray, g: np.ndarray, p: np.ndarray,
              fix: bool) -> KinematicTerms:
    v, fixinfo = admissible_p2(space, displacement) if fix else (displacement, DisplacementFix())
    _, smin = p2_slack(space, v)
    stiff = stiffnesses(space.scene)
    e_sub = v.sub_strains(space.X)  # (n_T, 3, 3, 3): linear on each sub-triangle
    sub = sub_energy(space, sig - np.einsum("tij,tsaj->tsai", stiff[space.body], e_sub))
    es, wh = slab_strains_p2(space, v)
    Cs = stiff[space.pieces.slabs.body]
    column = column_gap(space, g, np.einsum("sij,sqj->sqi", Cs, es))
    jump = v.jumps()
    u, _ = gauss01(N_GAUSS)
    N, _ = trace_shapes(u)  # (N_GAUSS, 3)
    on_edges = np.stack([jump[0:-1:2], jump[1::2], jump[2::2]], 1) @ N.T
    contact = contact_integrals(space, p, None, jump=on_edges)
    beyond = continuation_p2(space, v)
    strain = float(sub_energy(space, e_sub, stiff).sum()) + 0.5 * float(np.einsum("sq,sqi,sij,sqj->", wh, es, Cs, es))
    energy = strain + float(beyond.sum()) - load_work_p2(space, v)
    return KinematicTerms(v, fixinfo, smin, True, sub, column, contact, energy, beyond)
