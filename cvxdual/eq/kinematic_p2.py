"""The certificate's terms of a P2 displacement (:class:`~cvxdual.system.p2_displacement.P2Displacement`,
docs/equilibrium.md section 12), registered with :func:`cvxdual.eq.bounds.kinematic_terms`.

Everything is integrated exactly where the integrand is a polynomial, as for P1: the strain of a P2
displacement is linear on every sub-triangle, so ``sigma - C e(v)`` is linear there and the P1 mass
matrix integrates its energy (:func:`~cvxdual.eq.bounds.sub_energy`); the curved pieces by rules exact
in y (:func:`slab_rule`); the contact edges with the jump on the true faces (Gauss); the loads are
linear on edges, the trace quadratic (Simpson is exact); beyond the free arcs the neighbouring
polynomial is continued and integrated on the exact region
(:meth:`~cvxdual.geometry.mesh.Mesh.continuation_rule`). Pointwise admissibility on the contact
interval is the guaranteed check of :mod:`cvxdual.system.quadratic_gap` with the gap's curvature bound,
raised where the face's value is an element's quadratic off its chord (:func:`arc_excess`). The solve
holds every interval's Bernstein coefficients below the gap's (:mod:`cvxdual.system.p2_contact`), which
suffices on traces; off the chord, and for rounding, the lower face (or the upper where the lower is
held) is lowered by the least quadratic that restores the check (:func:`admissible_p2`).
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..geometry.pieces import PIECE_KINDS
from ..geometry.quadrature import gauss01
from ..geometry.triangles import bary_gradients, sub_vertices
from ..records import DisplacementFix
from ..system.boundary import supports
from ..system.p2 import barycentric_rule, hessians, shapes_at
from ..system.p2_contact import middle_slabs
from ..system.p2_displacement import P2Displacement
from ..system.p2_layout import trace_shapes
from ..system.p2_system import element_slab_rule
from ..system.quadratic_gap import quadratic_slack_bound, restore_admissible
from ..voigt import compliances, stiffnesses
from .bounds import (
    KinematicTerms,
    contact_integrals,
    edge_tractions,
    gap_curvature_bound,
    kinematic_terms,
    sub_energy,
)
from .columns import column_at
from .space import N_GAUSS, EquilibriumSpace

CONTINUATION_POINTS = 12  # Gauss points in angle on a free arc's piece (its bounds are smooth in the angle)
CONCAVE1 = PIECE_KINDS.index("concave1")
FIX_PASSES = 12  # restore, check again: the shifts change the arc's bound a little (measured: 1/15 per pass)
OVERSHOOT = 0.1  # shift this much more than asked: the bound's own change is then covered in a pass or two


def face_slabs(space: EquilibriumSpace, v: P2Displacement) -> np.ndarray:
    """``(n_c, 2)``: the slab under each contact edge on the upper and the lower face, -1 where the face
    interval is straight (no curved piece)."""
    return middle_slabs(v.layout, len(space.contact_x)).reshape(2, -1).T


def face_values(space: EquilibriumSpace, v: P2Displacement, u: np.ndarray, slabs: np.ndarray) -> np.ndarray:
    """``(2, n_c, g)``: ``v_y`` on the true upper and lower faces at ``x = x0 + u (x1 - x0)`` of every
    contact edge: the quadratic trace of the face edge (vertices and midpoint), or, on a segment, its
    triangle's quadratic continued, at ``(x, f(x))``."""
    lay, pn = v.layout, v.layout.pair_nodes
    N, _ = trace_shapes(u)  # (g, 3)
    x = space.contact_x[:, :1] + np.asarray(u)[None, :] * np.diff(space.contact_x, axis=1)
    out = np.zeros((2, len(x), len(u)))
    for b, face in enumerate((space.scene.upper.face, space.scene.lower.face)):
        out[b] = np.stack([v.q[pn[0:-1:2, b], 1], v.q[pn[1::2, b], 1], v.q[pn[2::2, b], 1]], 1) @ N.T
        seg = np.flatnonzero(lay.on_element(slabs[:, b]))
        if len(seg):
            xs = x[seg].ravel()
            val, _ = v.slab_values(np.repeat(slabs[seg, b], len(u)), np.stack([xs, face.value(xs)], 1))
            out[b, seg] = val[:, 1].reshape(len(seg), len(u))
    return out


def arc_excess(space: EquilibriumSpace, v: P2Displacement, slabs: np.ndarray) -> np.ndarray:
    """``R`` ``(n_c,)`` with ``|[v](x) - q(x)| <= R u (1 - u)`` on every contact edge (``u = (x - x0) / d``),
    ``[v]`` the jump on the true faces and ``q`` the quadratic through its values at the edge's ends and
    middle. Where ``v`` is an element's quadratic ``Q`` (a segment, a ``concave1`` piece), on the face
    ``v_y = T + delta l + delta^2 Q_yy / 2`` exactly: ``T`` the trace on the chord (quadratic), ``delta = f
    - c`` the face's offset from its chord, ``l = Q_y`` on the chord (linear, ``l0``, ``l1`` at its ends).
    With the face's curvature ``k`` at the middle and ``Dk`` its largest change on the edge, ``delta =
    -(k / 2) d^2 u (1 - u)`` up to ``(Dk / 2) d^2 u (1 - u)``; what the three-point quadratic misses is
    then at most ``(|k| d^2 / 4) |l1 - l0|`` (the cubic ``-(k d^2 / 2) (l1 - l0) u (1 - u) (u - 1/2)``),
    ``Dk d^2 max |l|`` and ``(K^2 d^4 / 16) |Q_yy|`` (``K`` the largest curvature), each times
    ``u (1 - u)``; widened by 1e-12 for rounding. Where ``v_y`` is the trace itself there is nothing."""
    lay = v.layout
    d = np.diff(space.contact_x, axis=1)[:, 0]
    R = np.zeros(len(d))
    for b, face in enumerate((space.scene.upper.face, space.scene.lower.face)):
        seg = np.flatnonzero(lay.on_element(slabs[:, b]))
        if not len(seg):
            continue
        x0, x1, dd = space.contact_x[seg, 0], space.contact_x[seg, 1], d[seg]
        k_lo, k_hi = face.curvature_range(x0, x1)
        k = face.curvature(0.5 * (x0 + x1))
        dk = np.maximum(np.abs(k_hi - k), np.abs(k - k_lo))
        K = np.maximum(np.abs(k_lo), np.abs(k_hi))
        t, j = lay.slab_tri[slabs[seg, b]], lay.slab_sub[slabs[seg, b]]
        P = sub_vertices(v.corners(t))[np.arange(len(t)), j]
        vals = v.sub_values_of(t, j)
        _, dN = shapes_at(P, P[:, :2])  # at the chord's ends X_j, X_j+1 (the sub-triangle's vertices 0, 1)
        ell = np.einsum("mqn,mn->mq", dN[..., 1], vals[..., 1])  # Q_y at both ends
        Qyy = np.abs(hessians(P, vals)[:, 1, 1, 1])
        r = (np.abs(k) * dd ** 2 / 4.0 * np.abs(ell[:, 1] - ell[:, 0]) + dk * dd ** 2 * np.abs(ell).max(1)
             + K ** 2 * dd ** 4 / 16.0 * Qyy)
        R[seg] += r * (1.0 + 1e-12)
    return R


def arc_bound(space: EquilibriumSpace, v: P2Displacement, slabs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The jump on the true faces at every contact edge's ends and middle ``(n_c, 3)`` and a guaranteed
    lower bound of the slack ``eps - [v]`` on the edge: the slack is at least the gap's quadratic lower
    bound, less ``R u (1 - u)`` (:func:`arc_excess`), less the jump's three-point quadratic:
    :func:`~cvxdual.system.quadratic_gap.quadratic_slack_bound` with the gap's curvature bound raised by
    ``2 R / d^2``."""
    a = face_values(space, v, np.array([0.0, 0.5, 1.0]), slabs)
    j = a[1] - a[0]
    x0, x1 = space.contact_x[:, 0], space.contact_x[:, 1]
    M = gap_curvature_bound(space, x0, x1) + 2.0 * arc_excess(space, v, slabs) / (x1 - x0) ** 2
    e0, e1 = space.scene.gap_at(x0), space.scene.gap_at(x1)
    return j, quadratic_slack_bound(x0, x1, e0, e1, M, j[:, 0], j[:, 1], j[:, 2])


def p2_slack(space: EquilibriumSpace, v: P2Displacement) -> tuple[np.ndarray, np.ndarray]:
    """``eps - [v]`` on the true faces at the pairs (vertices and midpoints, by x) and a guaranteed lower
    bound of its minimum on every contact edge (:func:`arc_bound`)."""
    j, bound = arc_bound(space, v, face_slabs(space, v))
    x0, x1 = space.contact_x[:, 0], space.contact_x[:, 1]
    slack = np.empty(2 * len(j) + 1)
    slack[0:-1:2], slack[-1] = space.scene.gap_at(x0) - j[:, 0], space.scene.gap_at(x1[-1]) - j[-1, 2]
    slack[1::2] = space.scene.gap_at(0.5 * (x0 + x1)) - j[:, 1]
    return slack, bound


def admissible_p2(space: EquilibriumSpace, v: P2Displacement) -> tuple[P2Displacement, DisplacementFix]:
    """``v`` lowered on one face where its jump may cross the gap between the pairs (module docstring),
    with a margin of ``1e-13`` of the problem's scale (as for P1); supports untouched. The shifts act on
    the jump's three values: exactly at the vertices; in the middle through the shifted face's middle
    node, which moves the face's value by that node's function there (1 on a trace, near 1 on an
    element's quadratic: :func:`mid_gains`), and the other nodes' shifts move it a little, so the check
    is repeated (a few passes)."""
    lay = v.layout
    sc = space.scales
    slabs = face_slabs(space, v)
    _, before = arc_bound(space, v, slabs)
    sup = supports(space.mesh, (lay.edge_node, lay.n_p2))
    up, lo = lay.pair_nodes.T
    on_lower = ~sup.fixed[lo, 1]
    x0, x1 = space.contact_x[:, 0], space.contact_x[:, 1]
    xv = np.append(x0, x1[-1])
    ev = space.scene.gap_at(xv)
    gain = mid_gains(space, v, slabs, on_lower[1::2])
    total, out, after, ok = np.zeros(lay.n_p2), v, before, False
    for _ in range(FIX_PASSES):
        j, after = arc_bound(space, out, slabs)
        margin = 1e-13 * max(float(np.abs(ev).max()), float(np.abs(out.q).max()), sc.stress * sc.length / sc.modulus)
        if after.min() >= margin:
            ok = True
            break
        M = gap_curvature_bound(space, x0, x1) + 2.0 * arc_excess(space, out, slabs) / (x1 - x0) ** 2
        jn = np.append(j[:, 0], j[-1, 2])
        qn, qm = restore_admissible(xv, ev, M, jn, j[:, 1], 2.0 * margin)  # aim above: converges to >= margin
        shift = np.zeros(len(lay.pair_x))
        shift[0::2], shift[1::2] = jn - qn, (j[:, 1] - qm) / gain
        shift *= 1.0 + OVERSHOOT
        if np.any((shift > 0) & sup.fixed[lo, 1] & sup.fixed[up, 1]):
            raise SceneError("a contact pair has both y displacements supported; supports must not act on the "
                             "contact")
        dy = np.zeros(lay.n_p2)
        dy[lo[on_lower]] = -shift[on_lower]
        dy[up[~on_lower]] = shift[~on_lower]
        out, total = out.moved(dy), total + np.abs(dy)
    moved = total[lay.pair_nodes].max(1)
    return out, DisplacementFix(max_shift=float(moved.max(initial=0.0)), n_shifted=int(np.sum(moved > 0)),
                                min_slack_before=float(before.min()), min_slack=float(after.min()), exact_min=ok,
                                support_violation=sup.violation(out.q),
                                displacement_scale=float(np.abs(out.q).max(initial=0.0)))


def mid_gains(space: EquilibriumSpace, v: P2Displacement, slabs: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """``(n_c,)``: how much the jump at an edge's middle moves per unit shift of the shifted face's middle
    node: 1 on a trace; where ``v`` is an element's quadratic, its sub-triangle's midpoint function at
    the face's point (near 1: the face is near the chord)."""
    gain = np.ones(len(slabs))
    b = np.where(lower, 1, 0)
    s = slabs[np.arange(len(slabs)), b]
    seg = np.flatnonzero(v.layout.on_element(s))
    if len(seg):
        lay = v.layout
        t, j = lay.slab_tri[s[seg]], lay.slab_sub[s[seg]]
        P = sub_vertices(v.corners(t))[np.arange(len(t)), j]
        xm = 0.5 * (space.contact_x[seg, 0] + space.contact_x[seg, 1])
        faces = (space.scene.upper.face, space.scene.lower.face)
        ym = np.where(b[seg] == 1, faces[1].value(xm), faces[0].value(xm))
        N, _ = shapes_at(P, np.stack([xm, ym], 1)[:, None])
        gain[seg] = N[:, 0, 3]  # the outer midpoint (X_j, X_j+1) is the sub-triangle's node 3
    return gain


def slab_rule(space: EquilibriumSpace, v: P2Displacement) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``(m, 2)``, weights ``(m,)`` and slab ``(m,)`` of a rule exact, for the curved pieces' terms,
    on every slab: a tensor Gauss rule of :data:`N_GAUSS` points per direction where ``v`` is one
    polynomial there (exact in y; in x a polynomial times the smooth arc), and on a ``concave1`` piece its
    triangle's sub-triangles (a degree-6 rule on each: ``v`` is piecewise quadratic there) less the
    sliver beyond the arc (:func:`~cvxdual.system.p2_system.element_slab_rule`, negative weights)."""
    pieces, lay = space.pieces, v.layout
    c1 = pieces.kind[pieces.slabs.piece] == CONCAVE1
    pts, w, si = pieces.slab_quadrature(N_GAUSS, only=~c1)
    if not c1.any():
        return pts, w, si
    k = np.flatnonzero(c1)
    sub = sub_vertices(v.corners(lay.slab_tri[k]))  # (m, 3, 3, 2)
    _, area = bary_gradients(sub.reshape(-1, 3, 2))
    bary, wb = barycentric_rule(4)
    tp = np.einsum("qa,mad->mqd", bary, sub.reshape(-1, 3, 2)).reshape(-1, 2)
    tw = (area[:, None] * wb[None, :]).ravel()
    sel, sp_, sw = element_slab_rule(pieces, lay, N_GAUSS)
    neg = np.isin(sel, k)
    return (np.concatenate([pts, tp, sp_[neg].reshape(-1, 2)]), np.concatenate([w, tw, sw[neg].ravel()]),
            np.concatenate([si, np.repeat(k, 3 * len(wb)), np.repeat(sel[neg], sp_.shape[1])]))


def slab_terms(space: EquilibriumSpace, v: P2Displacement, g: np.ndarray) -> tuple[np.ndarray, float]:
    """``1/2 ||sigma - C e(v)||_A^2`` on every slab ``(n_s,)`` (``sigma = g(x) e_y (x) e_y``, the column
    stress) and ``1/2 a(v, v)`` on all slabs, by :func:`slab_rule`."""
    pieces = space.pieces
    if not len(pieces.slabs):
        return np.zeros(0), 0.0
    pts, w, si = slab_rule(space, v)
    body = pieces.slabs.body[si]
    C, A = stiffnesses(space.scene)[body], compliances(space.scene)[body]
    e = v.slab_strains(si, pts)
    ce = np.einsum("mij,mj->mi", C, e)
    gx, _ = column_at(space, g, None, pts, si)
    d = -ce
    d[:, 1] += gx
    column = np.bincount(si, 0.5 * w * np.einsum("mi,mij,mj->m", d, A, d), len(pieces.slabs))
    return column, 0.5 * float(np.sum(w * np.einsum("mi,mi->m", e, ce)))


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
    tcode = code(lay.tri[:lay.n_straight].astype(np.int64))
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
    column, slab_strain = slab_terms(space, v, g)
    u, _ = gauss01(N_GAUSS)
    a = face_values(space, v, u, face_slabs(space, v))
    contact = contact_integrals(space, p, None, jump=a[1] - a[0])
    beyond = continuation_p2(space, v)
    energy = float(sub_energy(space, e_sub, stiff).sum()) + slab_strain + float(beyond.sum()) - load_work_p2(space, v)
    return KinematicTerms(v, fixinfo, smin, fixinfo.exact_min is not False, sub, column, contact, energy, beyond)
