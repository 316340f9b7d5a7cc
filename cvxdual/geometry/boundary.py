"""Boundary data on the mesh: which dofs the supports fix (and ties join), and the load
vector ``f_j = L(phi_j)`` (docs/theory.md#conventions).

A boundary part acts on the side nodes inside its interval (x on face/far, y on left/right);
supports act on these nodes and tractions on the edges between two of them, so both select
the same stretch of boundary.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..reference.exact import exact_field
from .mesh import Mesh
from .pieces import Pieces
from .quadrature import gauss01


def in_part(part, points: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Which of the side ``nodes`` lie in the part's interval."""
    if part.interval is None:
        return np.ones(len(nodes), bool)
    lo, hi = part.interval
    c = points[nodes, 0 if part.on in ("face", "far") else 1]
    tol = 1e-12 * (abs(lo) + abs(hi) + 1.0)  # interval ends are columns: only rounding separates them
    return (c >= lo - tol) & (c <= hi + tol)


def supported(mesh: Mesh) -> np.ndarray:
    """``(n_nodes, 2)``: the displacement components the supports fix (clamped: both; sliding:
    ``u_x`` on a vertical side, ``u_y`` on a horizontal one)."""
    fixed = np.zeros((mesh.n_nodes, 2), bool)
    for bm in mesh.bodies:
        for part in bm.body.boundary:
            if part.kind == "traction":
                continue
            nodes = bm.side_nodes(part.on)
            nodes = nodes[in_part(part, mesh.points, nodes)]
            if part.kind == "clamped":
                fixed[nodes] = True
            else:
                fixed[nodes, sliding_component(bm.body, part)] = True
    return fixed


def sliding_component(body, part) -> int:
    """The displacement component a sliding support fixes: ``u_x`` (0) on a vertical side or line,
    ``u_y`` (1) on a horizontal one (the body checks that an outline part is one of these)."""
    if body.is_column:
        return 0 if part.on in ("left", "right") else 1
    return 0 if body.outline.part(part.on).segments[0].axis == "y" else 1


def free_dofs(mesh: Mesh, ties: np.ndarray | None) -> np.ndarray:
    """Index of every dof in ``r`` (``-1`` if fixed); tied nodes share their master's index.

    ``ties`` (``(m, 2)`` node pairs ``(slave, master)``) joins whole nodes (type-1 concave pieces).
    """
    n_dofs = 2 * mesh.n_nodes
    fixed = supported(mesh).ravel()  # dof 2k is u_x of node k, 2k+1 its u_y
    master = np.arange(n_dofs)
    if ties is not None and len(ties):
        s, m = np.asarray(ties).T
        for c in (0, 1):
            master[2 * s + c] = 2 * m + c
            either = fixed[2 * s + c] | fixed[2 * m + c]
            fixed[2 * s + c] = fixed[2 * m + c] = either
    own = (master == np.arange(n_dofs)) & ~fixed
    idx = np.full(n_dofs, -1)
    idx[own] = np.arange(int(own.sum()))
    return np.where(fixed, -1, idx[master])


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
    exact = None
    for k, bm in enumerate(mesh.bodies):
        for part in bm.body.boundary:
            if part.kind != "traction":
                continue
            if part.traction.kind != "uniform" and exact is None:
                exact = exact_field(scene)
                if exact is None:
                    raise SceneError(f"body {bm.body.name!r}: traction 'exact' needs an [exact] field in the scene")
            a, b, x, u, nds = side_quadrature(mesh, k, part, n_gauss)
            P = _traction_density(part, k, x, nds, exact)
            for c in (0, 1):
                f += np.bincount(2 * a + c, np.sum((1 - u)[None, :] * P[..., c], axis=1), n)
                f += np.bincount(2 * b + c, np.sum(u[None, :] * P[..., c], axis=1), n)
    if not np.all(np.isfinite(f)):
        raise SceneError("the load vector is not finite; check the loads and the exact field")
    return f
