"""Continuous P2 on the Alfeld split, without contact (cvxdual.system.p2): numbering, element
matrices, patch tests, convergence rates on a manufactured solution, and no locking as nu -> 1/2
(against plain P1 on the macro mesh, which locks)."""

import ast
import inspect

import numpy as np
import pytest
import scipy.sparse as sp

from cvxdual.linalg.factor import SPDFactor
from cvxdual.system import p2
from cvxdual.system.p2 import (
    NODE_BARY,
    alfeld_nodes,
    alfeld_stiffness,
    assemble_p2,
    barycentric_rule,
    condense,
    p2_dofs,
    p2_errors,
    p2_load_vector,
    recover_interior,
)

PI = np.pi


def square(n, jitter=0.0, seed=0):
    """The unit square in ``n x n`` squares, each cut by its diagonal (0,0)-(1,1) into two
    counter-clockwise triangles; interior nodes moved at random by up to ``jitter h`` per axis."""
    x = np.linspace(0.0, 1.0, n + 1)
    P = np.stack(np.meshgrid(x, x), -1).reshape(-1, 2)  # node i + (n + 1) j at (x_i, x_j)
    if jitter:
        inner = np.all((P > 0) & (P < 1), axis=1)
        P[inner] += np.random.default_rng(seed).uniform(-jitter / n, jitter / n, (inner.sum(), 2))
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    a = (i + (n + 1) * j).ravel()
    T = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    return P, T


def plane_strain(E, nu):
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    return lam, mu, np.array([[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]])


def on_boundary(x):
    return np.any(np.isclose(x, 0.0, atol=1e-14) | np.isclose(x, 1.0, atol=1e-14), axis=1)


def solve_dirichlet(K, coords, g, F):
    """Solve ``K u = F`` with ``u = g`` at the nodes ``coords`` on the square's boundary."""
    fixed = np.repeat(on_boundary(coords), 2)
    u = np.zeros(K.shape[0])
    u[fixed] = g(coords[on_boundary(coords)]).ravel()
    r = F - K @ u
    free = ~fixed
    u[free] = SPDFactor(K[free][:, free]).solve(r[free])
    return u


def solve_p2(P, T, C, g, f):
    asm = assemble_p2(P, T, C)
    F = p2_load_vector(asm, f) if f is not None else np.zeros(asm.n_dofs)
    u = solve_dirichlet(asm.K, asm.coords, g, F)
    return asm, recover_interior(asm, u, f)


def random_spd(rng):
    M = rng.normal(size=(3, 3))
    return M @ M.T + 3 * np.eye(3)


# -- numbering and element matrices --------------------------------------------------------------

def test_p2_numbering_has_one_node_per_vertex_and_edge():
    P, T = square(3, jitter=0.3)
    nodes, coords = p2_dofs(P, T)
    n_edges = len(P) + len(T) - 1  # Euler on a disc: V - E + F = 1
    assert nodes.shape == (len(T), 6) and len(coords) == len(P) + n_edges
    assert np.array_equal(nodes[:, :3], T) and nodes[:, 3:].min() == len(P)
    assert np.allclose(coords[nodes[:, 3:]], 0.5 * (P[T] + P[np.roll(T, -1, axis=1)]), rtol=0, atol=1e-15)
    counts = np.bincount(nodes[:, 3:].ravel())[len(P):]
    assert set(counts) == {1, 2} and (counts == 1).sum() == 4 * 3  # the 12 boundary edges once


def test_condensed_elements_are_symmetric_psd_with_the_three_rigid_motions_as_kernel():
    rng = np.random.default_rng(1)
    P, T = square(4, jitter=0.3, seed=1)
    X = P[T]
    C = np.stack([random_spd(rng) for _ in range(len(T))])  # a different anisotropic material per triangle
    K = alfeld_stiffness(X, C)
    S = condense(K).S
    x = alfeld_nodes(X)  # (m, 10, 2)
    for M, xs in ((K, x), (S, x[:, :6])):
        scale = np.abs(M).max(axis=(1, 2))
        ones = np.ones(xs.shape[:2])
        zeros = np.zeros(xs.shape[:2])
        rigid = np.stack([np.stack([ones, zeros], -1), np.stack([zeros, ones], -1),
                          np.stack([-xs[..., 1], xs[..., 0]], -1)], -1).reshape(len(X), -1, 3)
        # a rigid motion is annihilated to rounding: relative to the largest entry (and to the
        # motion's size, O(1) on the unit square) 1e-12 is a few hundred ulps of 20 summed terms
        assert np.abs(M @ rigid).max(axis=(1, 2)).max() < 1e-12 * scale.max()
        assert np.abs(M - M.transpose(0, 2, 1)).max() <= 1e-14 * scale.max()  # symmetric to rounding
        w = np.linalg.eigvalsh(M) / np.linalg.eigvalsh(M)[:, -1:]
        # exactly 3 zero eigenvalues: at rounding (1e-12 relative; measured 4e-16) and a clear gap to
        # the 4th (the softest deformation: measured >= 5e-5 of the largest for K, 3e-4 for S, with
        # these random anisotropic materials and perturbed triangles)
        assert np.abs(w[:, :3]).max() < 1e-12 and w[:, 3].min() > 1e-6


def test_integration_of_the_norms_against_closed_forms():
    """``p2_errors`` with ``u_h = 0`` gives the norms of ``u*``: for ``u* = (x y, y^2)`` on the unit
    square, ``int e : C e`` and ``int |u|^2`` in closed form."""
    P, T = square(3, jitter=0.3, seed=2)
    C = random_spd(np.random.default_rng(2))
    X = P[T]

    def u(x):
        return np.column_stack([x[:, 0] * x[:, 1], x[:, 1] ** 2])

    def grad(x):
        return np.stack([np.stack([x[:, 1], x[:, 0]], -1), np.stack([0 * x[:, 0], 2 * x[:, 1]], -1)], 1)

    # e = (y, 2y, x): int e e^T over the unit square
    M = np.array([[1 / 3, 2 / 3, 1 / 4], [2 / 3, 4 / 3, 1 / 2], [1 / 4, 1 / 2, 1 / 3]])
    energy, l2 = p2_errors(X, np.zeros((len(T), 20)), C, u, grad)
    assert energy == pytest.approx(np.sqrt(np.sum(C * M)), rel=1e-13)  # polynomial integrands: exact rule
    assert l2 == pytest.approx(np.sqrt(1 / 9 + 1 / 5), rel=1e-13)
    ue = u(alfeld_nodes(X).reshape(-1, 2)).reshape(len(T), 20)  # its interpolant: u* itself (P2)
    assert max(p2_errors(X, ue, C, u, grad)) < 1e-13


# -- patch tests ---------------------------------------------------------------------------------

def patch(field, f):
    """Solve with Dirichlet data of ``field`` on a perturbed mesh and an anisotropic material; the
    largest error at the P2 nodes and at the recovered interior nodes, relative to the field."""
    P, T = square(6, jitter=0.3, seed=3)
    C = random_spd(np.random.default_rng(3))
    asm, ue = solve_p2(P, T, C, field, f(C) if f else None)
    assert abs(asm.K - asm.K.T).max() == 0.0  # the global matrix is exactly symmetric (as assembled)
    exact = field(alfeld_nodes(asm.X).reshape(-1, 2)).reshape(len(T), 10, 2)
    scale = np.abs(exact).max()
    u = ue.reshape(len(T), 10, 2)
    return np.abs(u[:, :6] - exact[:, :6]).max() / scale, np.abs(u[:, 6:] - exact[:, 6:]).max() / scale


def test_patch_test_affine_field_without_load():
    A, b = np.array([[0.3, -1.2], [0.7, 0.5]]), np.array([0.2, -0.4])
    nodal, interior = patch(lambda x: x @ A.T + b, None)
    # rounding only (a sparse solve with 242 free dofs, anisotropic C): measured 5e-15 at both kinds of node
    assert nodal < 1e-12 and interior < 1e-12


def test_patch_test_quadratic_field_with_its_body_force():
    rng = np.random.default_rng(4)
    H = rng.normal(size=(2, 2, 2))
    H = H + H.transpose(0, 2, 1)  # u_j = a_j + G_j . x + x . H_j x / 2
    G, a = rng.normal(size=(2, 2)), rng.normal(size=2)

    def field(x):
        return a + x @ G.T + 0.5 * np.einsum("qk,jkl,ql->qj", x, H, x)

    def force(C):
        dg = np.stack([H[0, 0], H[1, 1], H[0, 1] + H[1, 0]])  # d/dx_k of (e11, e22, 2 e12): (3, 2)
        ds = C @ dg  # d sigma_voigt / dx_k, constant
        f = -np.array([ds[0, 0] + ds[2, 1], ds[2, 0] + ds[1, 1]])
        return lambda x: np.broadcast_to(f, x.shape)

    nodal, interior = patch(field, force)
    assert nodal < 1e-12 and interior < 1e-12  # P2 holds the field: exact to rounding, as above


# -- a smooth manufactured solution: rates -------------------------------------------------------

def smooth(lam, mu):
    """``u = (sin(pi x) sin(pi y), x^2 y (1 - y))``, its gradient and ``f = -div C e(u) =
    -(mu Laplace u + (lam + mu) grad div u)`` (isotropic)."""
    def u(x):
        X, Y = x.T
        return np.column_stack([np.sin(PI * X) * np.sin(PI * Y), X**2 * Y * (1 - Y)])

    def grad(x):
        X, Y = x.T
        return np.stack([np.stack([PI * np.cos(PI * X) * np.sin(PI * Y), PI * np.sin(PI * X) * np.cos(PI * Y)], -1),
                         np.stack([2 * X * Y * (1 - Y), X**2 * (1 - 2 * Y)], -1)], 1)

    def f(x):
        X, Y = x.T
        lap = np.column_stack([-2 * PI**2 * np.sin(PI * X) * np.sin(PI * Y), 2 * Y * (1 - Y) - 2 * X**2])
        grad_div = np.column_stack([-PI**2 * np.sin(PI * X) * np.sin(PI * Y) + 2 * X * (1 - 2 * Y),
                                    PI**2 * np.cos(PI * X) * np.cos(PI * Y) - 2 * X**2])
        return -(mu * lap + (lam + mu) * grad_div)
    return u, grad, f


def stream(mu):
    """``u = curl psi`` for ``psi = g(x) g(y)``, ``g(t) = t^2 (1 - t)^2``: divergence free and zero
    with its gradient on the boundary; ``f = -mu Laplace u`` (``grad div u = 0``: no lam)."""
    g0, g1 = (lambda t: t**2 * (1 - t) ** 2), (lambda t: 2 * t - 6 * t**2 + 4 * t**3)
    g2, g3 = (lambda t: 2 - 12 * t + 12 * t**2), (lambda t: -12 + 24 * t)

    def u(x):
        X, Y = x.T
        return np.column_stack([g0(X) * g1(Y), -g1(X) * g0(Y)])

    def grad(x):
        X, Y = x.T
        return np.stack([np.stack([g1(X) * g1(Y), g0(X) * g2(Y)], -1),
                         np.stack([-g2(X) * g0(Y), -g1(X) * g1(Y)], -1)], 1)

    def f(x):
        X, Y = x.T
        return -mu * np.column_stack([g2(X) * g1(Y) + g0(X) * g3(Y), -(g3(X) * g0(Y) + g1(X) * g2(Y))])
    return u, grad, f


@pytest.mark.parametrize("make", ["smooth", "stream"])
def test_body_forces_are_minus_the_divergence_of_the_stress(make):
    """The hand-derived forces against central differences of ``C e(u)`` from the exact gradient."""
    lam, mu, C = plane_strain(1.0, 0.3)
    u, grad, f = smooth(lam, mu) if make == "smooth" else stream(mu)
    x = np.random.default_rng(5).uniform(0.1, 0.9, (20, 2))
    h = 1e-5

    def stress(y):
        g = grad(y)
        return np.stack([g[:, 0, 0], g[:, 1, 1], g[:, 0, 1] + g[:, 1, 0]], -1) @ C.T

    d = [(stress(x + h * e) - stress(x - h * e)) / (2 * h) for e in np.eye(2)]
    div = np.column_stack([d[0][:, 0] + d[1][:, 2], d[0][:, 2] + d[1][:, 1]])
    # central differences: O(h^2) truncation plus rounding eps/h (~1e-11) on O(1-10) forces; measured 4e-10
    assert np.abs(f(x) + div).max() < 1e-7 * np.abs(f(x)).max()
    if make == "stream":
        assert np.abs(np.trace(grad(x), axis1=1, axis2=2)).max() < 1e-15  # divergence free


def test_convergence_rates_on_a_smooth_solution():
    lam, mu, C = plane_strain(1.0, 0.3)
    u, grad, f = smooth(lam, mu)
    ns = np.array([4, 8, 16, 32])
    errors = []
    for n in ns:
        P, T = square(n)
        asm, ue = solve_p2(P, T, C, u, f)
        errors.append(p2_errors(asm.X, ue, C, u, grad))
    energy, l2 = np.array(errors).T
    h = 1.0 / ns
    # measured 1.95 and 2.98 (expected 2 and 3 for P2); the margin covers the pre-asymptotic n = 4
    assert np.polyfit(np.log(h), np.log(energy), 1)[0] >= 1.9
    assert np.polyfit(np.log(h), np.log(l2), 1)[0] >= 2.8


# -- locking -------------------------------------------------------------------------------------

def solve_p1(P, T, C, f):
    """Plain continuous P1 on the macro mesh, zero on the boundary; its local dofs on the split
    (a linear field is P2 there), for :func:`p2_errors`."""
    X = P[T]
    d1, d2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    a2 = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    g1, g2 = np.stack([d2[:, 1], -d2[:, 0]], -1) / a2[:, None], np.stack([-d1[:, 1], d1[:, 0]], -1) / a2[:, None]
    G = np.stack([-g1 - g2, g1, g2], 1)
    B = np.zeros((len(T), 3, 3, 2))
    B[:, 0, :, 0], B[:, 1, :, 1], B[:, 2, :, 0], B[:, 2, :, 1] = G[..., 0], G[..., 1], G[..., 1], G[..., 0]
    B = B.reshape(-1, 3, 6)
    Ke = np.einsum("tak,ab,tbl->tkl", B, C, B) * (0.5 * a2)[:, None, None]
    d = (2 * T[:, :, None] + np.arange(2)).reshape(-1, 6)
    n = 2 * len(P)
    K = sp.coo_matrix((Ke.ravel(), (np.repeat(d, 6, 1).ravel(), np.tile(d, (1, 6)).ravel())), shape=(n, n)).tocsr()
    bary, w = barycentric_rule(5)
    x = np.einsum("qa,tad->tqd", bary, X)
    Fe = np.einsum("q,qa,tqj,t->taj", w, bary, f(x.reshape(-1, 2)).reshape(x.shape), 0.5 * a2).reshape(-1, 6)
    u = solve_dirichlet(K, P, np.zeros_like, np.bincount(d.ravel(), Fe.ravel(), minlength=n))
    return X, np.einsum("ka,taj->tkj", NODE_BARY, u.reshape(-1, 2)[T]).reshape(-1, 20)


def relative_errors(n, nu):
    """Energy-norm errors of P2 (Alfeld) and P1 relative to the exact energy norm, divergence-free
    field, plane strain ``E = 1``."""
    lam, mu, C = plane_strain(1.0, nu)
    u, grad, f = stream(mu)
    P, T = square(n)
    asm, ue = solve_p2(P, T, C, u, f)
    norm = p2_errors(asm.X, np.zeros_like(ue), C, u, grad)[0]
    X1, u1 = solve_p1(P, T, C, f)
    return p2_errors(asm.X, ue, C, u, grad)[0] / norm, p2_errors(X1, u1, C, u, grad)[0] / norm


def test_no_locking_as_nu_tends_to_one_half_where_p1_locks():
    r = {(n, nu): relative_errors(n, nu) for n in (8, 16) for nu in (0.3, 0.4999, 0.5 - 1e-7)}
    for n in (8, 16):
        p2_soft, p1_soft = r[n, 0.3]
        p2_hard, p1_hard = r[n, 0.4999]
        # measured 1.75 (n = 8) and 1.89 (n = 16): the incompressible limit restricts P2 to its
        # divergence-free subspace, whose best approximation is a fixed factor worse (-> 2.0 from
        # below as h -> 0: 1.96 at n = 32, 1.997 at n = 128), not a growing one
        assert p2_hard < 2.0 * p2_soft
        # uniform in lam: nu = 0.4999 (lam/mu 5e3) and 1/2 - 1e-7 (lam/mu 5e6) agree to 0.1 % (measured)
        assert r[n, 0.5 - 1e-7][0] == pytest.approx(p2_hard, rel=1e-2)
        # P1 on this mesh has no divergence-free field but zero: it locks, ~100 % error at both levels
        assert p1_hard > 0.95
    assert r[16, 0.4999][1] > 4.0 * r[16, 0.3][1]  # measured 4.4 (n = 8: 2.4): P1 does not converge
    assert r[8, 0.4999][0] > 3.0 * r[16, 0.4999][0]  # P2 still converges (measured 3.5, rate 1.8)


# -- vectorisation -------------------------------------------------------------------------------

def test_the_module_loops_over_sub_triangles_and_edges_only():
    """No Python loop over elements: every loop and comprehension of the module runs over the
    three sub-triangles or the three edges of a P2 triangle."""
    tree = ast.parse(inspect.getsource(p2))
    iters = {ast.unparse(node.iter) for node in ast.walk(tree) if isinstance(node, (ast.For, ast.comprehension))}
    assert iters <= {"range(3)", "P2_EDGES"}
