"""Boundary data on the mesh: which dofs the supports fix (and ties join), and the load
vector ``f_j = L(phi_j)`` (docs/theory.md#conventions).

A boundary part acts on the side nodes inside its interval (x on face/far, y on left/right);
supports act on these nodes and tractions on the edges between two of them, so both select
the same stretch of boundary.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import MeshError, SceneError
from ..geometry.mesh import Mesh
from ..geometry.pieces import Pieces
from ..geometry.quadrature import gauss01
from ..reference.exact import exact_field


def in_part(part, points: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Which of the side ``nodes`` lie in the part's interval."""
    if part.interval is None:
        return np.ones(len(nodes), bool)
    lo, hi = part.interval
    c = points[nodes, 0 if part.on in ("face", "far") else 1]
    tol = 1e-12 * (abs(lo) + abs(hi) + 1.0)  # interval ends are columns: only rounding separates them
    return (c >= lo - tol) & (c <= hi + tol)


@dataclass(frozen=True)
class Supports:
    """What the supports fix at each node, in the node's own frame.

    ``frame`` ``(n_nodes, 2, 2)``: rows are the node's unit axes; the identity except on a sliding
    support whose direction is not an axis (a slanted line, or a guide), whose nodes take the
    direction and its normal. ``fixed`` ``(n_nodes, 2)``: the frame components held at zero
    (clamped: both; sliding: the normal one, which for an axis direction is ``u_x`` or ``u_y`` of
    the identity frame)."""

    fixed: np.ndarray
    frame: np.ndarray

    @property
    def rotated(self) -> np.ndarray:
        """The nodes whose frame is not the identity."""
        return np.flatnonzero(np.any(self.frame != np.eye(2), axis=(1, 2)))

    def rows(self, R: np.ndarray, nodes: np.ndarray | None = None) -> np.ndarray:
        """The fixed components of node vectors ``R`` ``(n_nodes, 2, m)``: ``(n_fixed, m)`` rows
        (those of ``nodes`` only, a boolean mask, if given)."""
        fixed = self.fixed if nodes is None else self.fixed & nodes[:, None]
        k, c = np.nonzero(fixed)
        return np.einsum("ni,nim->nm", self.frame[k, c], R[k])

    def tied(self, ties: np.ndarray | None) -> Supports:
        """The supports with each tie ``(slave, master)`` (type-1 concave pieces: one displacement
        for both nodes) holding both nodes by the constraints of either: one node's normal if only
        it has one, both components if they have two that differ (or either is held both ways)."""
        if ties is None or not len(ties):
            return self
        s, m = np.asarray(ties).T
        fixed, frame = self.fixed.copy(), self.frame.copy()
        one = fixed.sum(1) == 1
        normal = np.where(one[:, None], np.einsum("kc,kci->ki", fixed, frame), 0.0)  # the one held axis
        ns, nm = normal[s], normal[m]
        full = fixed[s].all(1) | fixed[m].all(1) | (np.abs(ns[:, 0] * nm[:, 1] - ns[:, 1] * nm[:, 0]) > 1e-12)
        src = np.where(one[m], m, s)  # the node whose constraint both take (the master's if it has one)
        for node in (s, m):
            frame[node] = np.where(full[:, None, None], np.eye(2), frame[src])
            fixed[node] = np.where(full[:, None], True, fixed[src])
        return Supports(fixed=fixed, frame=frame)

    def violation(self, v: np.ndarray) -> float:
        """The largest fixed component of a displacement ``v`` ``(n_nodes, 2)``."""
        return float(np.abs(self.rows(np.asarray(v, float)[:, :, None])).max(initial=0.0))


def supports(mesh: Mesh, midpoints: tuple[Callable, int] | None = None) -> Supports:
    """The :class:`Supports` of the mesh's boundary parts. A node under two supports takes both:
    a sliding node on a second, non-parallel line (a corner) is held like a clamped one.

    ``midpoints`` ``(edge_node, n)`` extends them to the ``n`` nodes of a P2 displacement:
    ``edge_node(a, b)`` is the node at the midpoint of edge ``(a, b)`` (-1 if none), and the
    midpoint of two consecutive side nodes of a part is held as the part holds them (a quadratic
    on a straight part vanishes there, in the held component, when it does at its three nodes)."""
    n = mesh.n_nodes if midpoints is None else midpoints[1]
    fixed = np.zeros((n, 2), bool)
    normal = np.zeros((n, 2))  # a sliding support's unit normal where it is not an axis
    for bm in mesh.bodies:
        for part in bm.body.boundary:
            if part.kind == "traction":
                continue
            side = bm.side_nodes(part.on)
            inside = in_part(part, mesh.points, side)
            nodes = side[inside]
            if midpoints is not None:
                both = inside[:-1] & inside[1:]
                mid = midpoints[0](side[:-1][both], side[1:][both])
                nodes = np.concatenate([nodes, mid[mid >= 0]])
            nv = None if part.kind == "clamped" else sliding_normal(bm.body, part)
            if nv is None:
                fixed[nodes] = True
            elif abs(nv[0]) == 1.0 or abs(nv[1]) == 1.0:
                fixed[nodes, int(abs(nv[1]) == 1.0)] = True
            else:
                old = normal[nodes]
                # a second such support on a node: held both ways unless the normals are parallel
                # (rounding of the typed coordinates is all that separates parallel normals)
                cross = np.abs(old[:, 0] * nv[1] - old[:, 1] * nv[0]) > 1e-12
                fixed[nodes[cross]] = True
                normal[nodes] = nv
    slanted = np.any(normal != 0, axis=1)
    fixed[slanted & fixed.any(axis=1)] = True  # meeting an axis-aligned support
    slide = slanted & ~fixed.all(axis=1)
    frame = np.broadcast_to(np.eye(2), (n, 2, 2)).copy()
    nv = normal[slide]
    frame[slide] = np.stack([np.stack([nv[:, 1], -nv[:, 0]], 1), nv], 1)  # rows: tangent, normal
    fixed[slide] = (False, True)
    return Supports(fixed=fixed, frame=frame)


def sliding_normal(body, part) -> np.ndarray:
    """The unit normal of a sliding support's direction (the displacement component it holds):
    across its ``direction`` if it names one; else ``(1, 0)`` on a vertical side or line, ``(0, 1)``
    on a horizontal one, the line's normal on a slanted straight outline part (the body checks that
    a part without a direction is one straight line)."""
    if part.direction is not None:
        d = np.array(part.direction, float)
    elif part.on == "face":  # a flat face (the body refuses supports on curved ones)
        d = np.array([1.0, 0.0])
    elif body.is_column:
        d = np.array([0.0, 1.0] if part.on in ("left", "right") else [1.0, 0.0])
    else:
        seg = body.outline.part(part.on).segments[0]
        d = np.subtract(seg.end, seg.start) if seg.axis is None else \
            np.array([0.0, 1.0] if seg.axis == "y" else [1.0, 0.0])
    if d[0] == 0.0 or d[1] == 0.0:  # axis-aligned: exactly (1, 0) or (0, 1)
        return np.array([float(d[0] == 0.0), float(d[1] == 0.0)])
    return np.array([-d[1], d[0]]) / np.hypot(*d)


def free_dofs(sup: Supports, ties: np.ndarray | None) -> np.ndarray:
    """Index in ``r`` of every frame component (``2k + c``: component ``c`` of node ``k`` in its
    frame; ``-1`` if fixed); tied nodes share their master's index.

    ``ties`` (``(m, 2)`` node pairs ``(slave, master)``) joins whole nodes (type-1 concave pieces);
    ``sup`` must already hold tied nodes alike (:meth:`Supports.tied`).
    """
    fixed = sup.fixed.ravel()
    n_dofs = len(fixed)
    master = np.arange(n_dofs)
    if ties is not None and len(ties):
        s, m = np.asarray(ties).T
        if np.any(sup.frame[s] != sup.frame[m]):
            raise MeshError("internal: tied nodes in different frames (use Supports.tied)")  # pragma: no cover
        for c in (0, 1):
            master[2 * s + c] = 2 * m + c
            either = fixed[2 * s + c] | fixed[2 * m + c]
            fixed[2 * s + c] = fixed[2 * m + c] = either
    own = (master == np.arange(n_dofs)) & ~fixed
    idx = np.full(n_dofs, -1)
    idx[own] = np.arange(int(own.sum()))
    return np.where(fixed, -1, idx[master])


def prolongation(sup: Supports, rdof: np.ndarray) -> sp.csr_matrix:
    """``Z`` ``(n_dofs, n_r)`` with ``q = Z r``: frame component ``c`` of node ``k`` (r index
    ``rdof[2k + c]``) adds ``frame[k, c]`` to the node's ``(u_x, u_y)``; 0/1 on identity frames."""
    k, c = np.nonzero(rdof.reshape(-1, 2) >= 0)
    j = rdof[2 * k + c]
    vals = sup.frame[k, c]  # (m, 2): the axis in x, y
    keep = vals != 0.0  # the identity frame's zeros stay out of Z
    rows = 2 * k[:, None] + np.arange(2)[None, :]
    return sp.csr_matrix((vals[keep], (rows[keep], np.broadcast_to(j[:, None], vals.shape)[keep])),
                         shape=(len(rdof), int(rdof.max()) + 1))


def to_frames(sup: Supports, nodes: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Local matrices ``k`` ``(m, 2n, 2n)`` on the ``(u_x, u_y)`` of ``nodes`` ``(m, n)`` turned
    into the nodes' frames, ``G k G^T`` with ``G`` the blocks of the frames (unchanged if every
    frame is the identity)."""
    hit = np.flatnonzero(np.any(np.isin(nodes, sup.rotated), axis=1))
    if not len(hit):
        return k
    m, n = nodes[hit].shape
    G = np.zeros((m, 2 * n, 2 * n))
    for a in range(n):
        G[:, 2 * a:2 * a + 2, 2 * a:2 * a + 2] = sup.frame[nodes[hit, a]]
    out = k.copy()
    out[hit] = G @ k[hit] @ G.transpose(0, 2, 1)
    return out


def _outward_normal(body, side: str, d: np.ndarray) -> np.ndarray:
    """Unit outward normals of straight side edges with direction vectors ``d`` ``(m, 2)``
    (edges run with increasing x on face/far, away from the face on left/right; along an outline
    part in the outline's order: counter-clockwise round an upper body, clockwise round a lower
    one, counter-clockwise round a hole)."""
    ell = np.linalg.norm(d, axis=1, keepdims=True)
    left_normal = np.stack([-d[:, 1], d[:, 0]], 1) / ell  # tangent rotated by +90 degrees
    if not body.is_column and side != "face":
        flip = body.position == "upper" and side not in {h.name for h in body.outline.holes}
        return -left_normal if flip else left_normal
    flip = {"face": True, "far": False, "left": False, "right": True}[side]
    if body.position != "upper":
        flip = not flip
    return -left_normal if flip else left_normal


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
    inside = in_part(part, mesh.points, nodes)
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
    n = _outward_normal(body, part.on, d) * np.linalg.norm(d, axis=1, keepdims=True)
    return a, b, x, u, n[:, None, :] * w[None, :, None]


def _traction_density(part, k: int, x: np.ndarray, nds: np.ndarray, exact) -> np.ndarray:
    """Traction times the length weight at the quadrature points ``(m, g, 2)``."""
    if part.traction.kind == "uniform":
        return np.array(part.traction.value) * np.linalg.norm(nds, axis=-1, keepdims=True)
    s = exact.stress(k, x.reshape(-1, 2)).reshape(x.shape[0], x.shape[1], 3)
    return np.stack([s[..., 0] * nds[..., 0] + s[..., 2] * nds[..., 1],
                     s[..., 2] * nds[..., 0] + s[..., 1] * nds[..., 1]], axis=-1)


def load_vector(mesh: Mesh, pieces: Pieces, n_gauss: int = 8) -> np.ndarray:
    """``f_j = L(phi_j)``: body forces over the pieces and tractions along the sides.

    Tractions use ``n_gauss`` Gauss points per boundary stretch (degree ``2 n_gauss - 1``:
    enough for the smooth exact fields of the built-in scenes to machine precision)."""
    scene = mesh.scene
    n = 2 * mesh.n_nodes
    bf = np.array([b.body_force for b in scene.bodies])[pieces.body]  # (n_p, 2)
    f = sum(np.bincount((2 * pieces.nodes + c).ravel(), (pieces.phi * bf[:, c, None]).ravel(), n)
            for c in (0, 1))
    for a, b, u, P in traction_stretches(mesh, n_gauss):
        for c in (0, 1):
            f += np.bincount(2 * a + c, np.sum((1 - u)[None, :] * P[..., c], axis=1), n)
            f += np.bincount(2 * b + c, np.sum(u[None, :] * P[..., c], axis=1), n)
    if not np.all(np.isfinite(f)):
        raise SceneError("the load vector is not finite; check the loads and the exact field")
    return f


def traction_stretches(mesh: Mesh, n_gauss: int = 8):
    """For every traction part of every body: its stretches' end nodes ``a``, ``b`` ``(m,)``, the
    Gauss abscissae ``u`` ``(g,)`` on each stretch (0 at ``a``, 1 at ``b``; on the face, in x) and the
    traction times the length weight ``P`` ``(m, g, 2)`` there (:func:`side_quadrature`): what a
    load vector integrates against its shape functions."""
    exact = None
    for k, bm in enumerate(mesh.bodies):
        for part in bm.body.boundary:
            if part.kind != "traction":
                continue
            if part.traction.kind != "uniform" and exact is None:
                exact = exact_field(mesh.scene)
                if exact is None:
                    raise SceneError(f"body {bm.body.name!r}: traction 'exact' needs an [exact] field in the scene")
            a, b, x, u, nds = side_quadrature(mesh, k, part, n_gauss)
            yield a, b, u, _traction_density(part, k, x, nds, exact)
