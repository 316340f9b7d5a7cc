"""The guaranteed slack of a quadratic jump against the true gap (cvxdual.system.quadratic_gap):
exact for a parabola, a lower bound for any gap with a curvature bound, the Bernstein sufficient
condition, the restoration of admissibility on a chain, and the P1 formula as its linear case."""

from types import SimpleNamespace

import numpy as np
import pytest

from cvxdual.eq.bounds import contact_slack, gap_curvature_bound
from cvxdual.system import quadratic_gap as qg
from cvxdual.system.quadratic_gap import bernstein_slack, quadratic_slack_bound, restore_admissible, rounding_margin

U = np.linspace(0.0, 1.0, 10001)  # dense samples of each interval
DU = U[1] - U[0]


def q_at(u, q0, qm, q1):
    """The quadratic with values q0, qm, q1 at u = 0, 1/2, 1 (Lagrange form, independent of the module's)."""
    return q0 * (1 - u) * (1 - 2 * u) + 4 * qm * u * (1 - u) + q1 * u * (2 * u - 1)


def sampled(eps, x0, x1, q0, qm, q1):
    """``eps - q`` on the dense samples ``(n, 10001)`` and the largest magnitude there ``(n,)``."""
    X = x0[:, None] + (x1 - x0)[:, None] * U
    Q = q_at(U, q0[:, None], qm[:, None], q1[:, None])
    return eps(X) - Q, np.maximum(np.abs(eps(X)).max(1), np.abs(Q).max(1))


# -- the gaps: values, and the exact range of eps'' on an interval ----------------------------------

R = 1.0  # circle eps = R - sqrt(R^2 - x^2): eps'' = R^2 / (R^2 - x^2)^(3/2), increasing in |x|
A, K = 0.01, 5.0  # cosine eps = A (1 - cos(K x)): eps'' = A K^2 cos(K x)


def circle(x):
    return R - np.sqrt(R * R - x * x)


def circle_range(x0, x1):
    c = lambda x: R * R / (R * R - x * x) ** 1.5  # noqa: E731
    inner = np.where((x0 <= 0) & (x1 >= 0), 0.0, np.minimum(np.abs(x0), np.abs(x1)))
    return c(inner), c(np.maximum(np.abs(x0), np.abs(x1)))


def cosine(x):
    return A * (1 - np.cos(K * x))


def cosine_range(x0, x1):
    """cos(K x) is largest at an end unless a maximum 2 pi m / K lies inside, smallest likewise with (2m + 1) pi / K."""
    c0, c1 = np.cos(K * x0), np.cos(K * x1)
    top = np.floor(K * x1 / (2 * np.pi)) >= np.ceil(K * x0 / (2 * np.pi))
    bottom = np.floor((K * x1 - np.pi) / (2 * np.pi)) >= np.ceil((K * x0 - np.pi) / (2 * np.pi))
    return (A * K * K * np.where(bottom, -1.0, np.minimum(c0, c1)), A * K * K * np.where(top, 1.0, np.maximum(c0, c1)))


def circle_third(x0, x1):
    """max |eps'''| on [x0, x1]: 3 R^2 |x| / (R^2 - x^2)^(5/2), increasing in |x|."""
    x = np.maximum(np.abs(x0), np.abs(x1))
    return 3 * R * R * x / (R * R - x * x) ** 2.5


def cosine_third(x0, x1):
    """A bound of |eps'''| = A K^3 |sin(K x)|."""
    return A * K**3 + 0 * x0


def random_case(rng, eps, curvature, lo, hi, n, dmin=1e-3, dmax=1.0):
    """``n`` random intervals in ``[lo, hi]`` (log-uniform lengths) and random jumps: the gap's values
    plus normal noise of the size of the gap's bending on the interval, so some pass and some fail."""
    d = 10 ** rng.uniform(np.log10(dmin), np.log10(dmax), n)
    x0 = rng.uniform(lo, hi - d)
    x1 = x0 + d
    m, M = curvature(x0, x1)
    sig = np.maximum(np.abs(M), np.abs(m)) * d * d / 8
    q = [eps(x) + rng.normal(0.0, 1.0, n) * sig for x in (x0, 0.5 * (x0 + x1), x1)]
    return x0, x1, m, M, q


# -- exact for a parabola -----------------------------------------------------------------------

def test_a_parabola_gap_gives_the_exact_minimum():
    rng = np.random.default_rng(0)
    n = 300
    a, b, c = rng.uniform(0.1, 2.0, n), rng.uniform(-1, 1, n), rng.uniform(0, 0.1, n)
    x0 = rng.uniform(-2, 2, n)
    d = 10 ** rng.uniform(-3, 0.5, n)
    x1 = x0 + d
    eps_x = lambda x: a * x * x + b * x + c  # noqa: E731
    e0, e1, em = eps_x(x0), eps_x(x1), eps_x(x0 + 0.5 * d)
    q0, qm, q1 = (e + rng.normal(-0.7, 1, n) * a * d * d for e in (e0, em, e1))  # about half of them pass
    bound = quadratic_slack_bound(x0, x1, e0, e1, 2 * a, q0, qm, q1)
    # the true minimum of eps - q, a quadratic in u: ends, and the vertex from its monomial coefficients
    f2 = a * d * d - (2 * q0 - 4 * qm + 2 * q1)
    f1 = (2 * a * x0 + b) * d - (-3 * q0 + 4 * qm - q1)
    f0 = e0 - q0
    with np.errstate(divide="ignore", invalid="ignore"):
        us = np.where(f2 > 0, np.clip(-f1 / (2 * f2), 0, 1), 0.0)
    vertex = f0 + f1 * us + f2 * us * us
    X = x0[:, None] + d[:, None] * U
    f = a[:, None] * X * X + b[:, None] * X + c[:, None] - q_at(U, q0[:, None], qm[:, None], q1[:, None])
    true = np.minimum(f.min(1), vertex)
    scale = np.maximum(np.abs(X).max(1) ** 2 * a + np.abs(b * X.max(1)) + c, np.abs([q0, qm, q1]).max(0))
    assert np.mean(true < 0) > 0.2 and np.mean(true > 0) > 0.2  # both kinds of interval are there
    # the same quadratic by two routes: rounding of terms of size `scale` (a few ulps), far below 1e-12
    np.testing.assert_array_less(np.abs(bound - true), 1e-12 * scale)


# -- a lower bound for any gap, close on short intervals ---------------------------------------------

@pytest.mark.parametrize("eps, curvature, third, lo, hi", [(circle, circle_range, circle_third, -0.95, 0.95),
                                                           (cosine, cosine_range, cosine_third, -2.0, 2.0)],
                         ids=["circle", "cosine"])
def test_the_bound_is_guaranteed_and_close_on_short_intervals(eps, curvature, third, lo, hi):
    rng = np.random.default_rng(1)
    x0, x1, m, M, (q0, qm, q1) = random_case(rng, eps, curvature, lo, hi, 400)
    bound = quadratic_slack_bound(x0, x1, eps(x0), eps(x1), M, q0, qm, q1)
    f, scale = sampled(eps, x0, x1, q0, qm, q1)
    smin = f.min(1)
    # never above: the samples' minimum is at least the true one; only rounding (the module's own margin)
    assert np.all(bound <= smin + qg.RELATIVE_MARGIN * scale)
    # close: eps - L <= (M - min eps'') d^2 u (1 - u) / 2, so the bound is at most (M - m) d^2 / 8 below the
    # true minimum, which the samples exceed by at most max|f''| DU^2 / 8 (f'' in u: d^2 eps'' - q'')
    d = x1 - x0
    f_uu = d * d * np.maximum(np.abs(m), np.abs(M)) + 2 * np.abs(4 * qm - 2 * (q0 + q1))
    assert np.all(smin - bound <= (M - m) * d * d / 8 + f_uu * DU**2 / 8 + qg.RELATIVE_MARGIN * scale)
    # and M - m <= max|eps'''| d: the loss is O(d^3), nothing next to the bending M d^2 / 8 on short intervals
    assert np.all(smin - bound <= third(x0, x1) * d**3 / 8 + f_uu * DU**2 / 8 + qg.RELATIVE_MARGIN * scale)


# -- the Bernstein condition ------------------------------------------------------------------------

def test_bernstein_coefficients_are_sufficient_and_affine_in_the_jump():
    rng = np.random.default_rng(2)
    x0, x1, _, M, (q0, qm, q1) = random_case(rng, circle, circle_range, -0.9, 0.9, 2000)
    e0, e1 = circle(x0), circle(x1)
    b = bernstein_slack(x0, x1, e0, e1, M, q0, qm, q1)
    exact = quadratic_slack_bound(x0, x1, e0, e1, M, q0, qm, q1)
    ok = np.all(b >= 0, axis=1)
    assert 100 < ok.sum() < len(ok)
    assert np.all(exact[ok] >= 0)  # p is a combination of b0, b1, b2 with weights >= 0 summing to 1
    # affine: b = (e0, (e0 + e1 + kappa) / 2, e1) - BERNSTEIN_Q (q0, qm, q1); rounding of terms of size ~ e, q
    kappa = -0.5 * M * (x1 - x0) ** 2
    rhs = np.column_stack([e0, 0.5 * (e0 + e1 + kappa), e1])
    scale = np.abs(np.column_stack([e0, e1, kappa, q0, qm, q1])).max(1, keepdims=True)
    assert np.all(np.abs(b - (rhs - np.column_stack([q0, qm, q1]) @ qg.BERNSTEIN_Q.T)) <= 1e-14 * scale)


def test_bernstein_is_not_necessary():
    """eps = x^2 / 2 on [0, 1] (M = 1, so L = eps) and q = eps - ((1 - 2u)^2 + 0.1): the slack is >= 0.1
    everywhere, yet its middle Bernstein coefficient is 2 * 0.1 - 1.1 = -0.9."""
    eps = lambda x: 0.5 * x * x  # noqa: E731
    p = lambda u: (1 - 2 * u) ** 2 + 0.1  # noqa: E731
    x0, x1 = np.array([0.0]), np.array([1.0])
    q0, qm, q1 = (np.array([eps(u) - p(u)]) for u in (0.0, 0.5, 1.0))
    args = (x0, x1, eps(x0), eps(x1), np.array([1.0]), q0, qm, q1)
    assert quadratic_slack_bound(*args)[0] == pytest.approx(0.1, abs=1e-15)  # a few ulps of numbers ~1
    np.testing.assert_allclose(bernstein_slack(*args)[0], [1.1, -0.9, 1.1], atol=1e-15)


# -- a jump touching the gap, then raised ------------------------------------------------------------

@pytest.mark.parametrize("gap", ["parabola", "circle"])
def test_a_jump_raised_above_the_gap_fails(gap):
    """q touches eps at the midpoint from below (a parabola's q = eps - beta (x - xm)^2; the circle's q its
    Taylor polynomial at xm with the smallest curvature m, below eps since eps'' >= m). Raising qm by eta
    makes the true slack -eta at the midpoint, so the guaranteed bound must be <= -eta < 0."""
    x0, x1 = np.array([0.3]), np.array([0.5])
    xm, d = 0.5 * (x0 + x1), x1 - x0
    if gap == "parabola":
        eps, M, m = (lambda x: 0.5 * x * x), np.array([1.0]), np.array([1.0])
        q = lambda x: eps(x) - 0.2 * (x - xm) ** 2  # noqa: E731
    else:
        eps, (m, M) = circle, circle_range(x0, x1)
        slope = xm / np.sqrt(R * R - xm * xm)
        q = lambda x: circle(xm) + slope * (x - xm) + 0.5 * m * (x - xm) ** 2  # noqa: E731
    args = (x0, x1, eps(x0), eps(x1), M)
    touching = quadratic_slack_bound(*args, q(x0), q(xm), q(x1))[0]
    # admissible (true minimum 0) and the bound at most (M - m) d^2 / 8 below it, up to ulps of eps ~ 0.1
    assert -(M - m)[0] * d[0] ** 2 / 8 - 1e-16 <= touching <= 1e-16
    eta = 1e-9
    raised = quadratic_slack_bound(*args, q(x0), q(xm) + eta, q(x1))[0]
    assert raised <= -eta + 1e-16


# -- restoring admissibility on a chain --------------------------------------------------------------

def chain(rng, n=300):
    """A chain on the circle: random node spacing; the first third well below the gap (passing runs), the
    rest random around it."""
    x = np.cumsum(np.r_[-0.85, rng.uniform(0.2, 1.0, n)])
    x = -0.85 + 1.7 * (x - x[0]) / (x[-1] - x[0])
    xm = 0.5 * (x[:-1] + x[1:])
    m, M = circle_range(x[:-1], x[1:])
    sig = M * np.diff(x) ** 2 / 8
    sig_n = np.r_[sig, sig[-1]]
    q_nodes = circle(x) + np.where(np.arange(n + 1) < n // 3, -3 * sig_n, rng.normal(0, 1, n + 1) * sig_n)
    q_mid = circle(xm) + np.where(np.arange(n) < n // 3, -3 * sig, rng.normal(0, 1, n) * sig)
    return x, circle(x), M, q_nodes, q_mid


def bounds_of(x, e, M, qn, qm):
    return quadratic_slack_bound(x[:-1], x[1:], e[:-1], e[1:], M, qn[:-1], qm, qn[1:])


def test_restore_makes_every_interval_pass_with_the_least_shift():
    rng = np.random.default_rng(3)
    x, e, M, qn, qm = chain(rng)
    margin = rounding_margin(x, e, M, qn, qm)
    before = bounds_of(x, e, M, qn, qm)
    fail = before < margin
    assert 20 < fail.sum() < len(fail) - 20
    qn2, qm2 = restore_admissible(x, e, M, qn, qm, margin)
    assert np.all(bounds_of(x, e, M, qn2, qm2) >= margin)  # as computed: the function checks this itself
    # untouched where the interval and both neighbours pass
    calm = ~(fail | np.r_[False, fail[:-1]] | np.r_[fail[1:], False])
    assert calm.sum() > 50
    assert np.array_equal(qm2[calm], qm[calm])
    assert np.array_equal(qn2[:-1][calm], qn[:-1][calm]) and np.array_equal(qn2[1:][calm], qn[1:][calm])
    # never raised, and a node moves by the larger deficit of its two intervals plus the margin; the 1.1 is
    # the shift's few ulps of rounding allowance (SHIFT_ULPS, ~4 % of the margin)
    deficit = np.maximum(-before, 0.0)
    node_cap = np.maximum(np.r_[deficit, 0.0], np.r_[0.0, deficit]) + 1.1 * margin
    dn, dm = qn - qn2, qm - qm2
    assert np.all(dn >= 0) and np.all(dn <= node_cap)
    # a midpoint moves at least its own interval's need and at most as far as one of its ends
    assert np.all(dm >= np.where(fail, margin - before, 0.0) * (1 - 1e-12))
    assert np.all(dm <= np.maximum(dn[:-1], dn[1:]) * (1 + 1e-12))


def test_restore_shifts_a_lone_interval_uniformly_and_its_neighbours_minimally():
    """One failing interval between passing ones: its nodes and midpoint drop by its need (uniform shift,
    the bound's curvature unchanged); a neighbour's midpoint drops by a quarter of its shared node's shift,
    the least that keeps the shift quadratic >= 0 on it (it touches 0 at the far end's side)."""
    x = np.array([-0.3, -0.1, 0.1, 0.3])
    e, xm = circle(x), 0.5 * (x[:-1] + x[1:])
    _, M = circle_range(x[:-1], x[1:])
    qn = e - np.array([1e-3, 1e-5, 1e-5, 1e-3])
    qm = circle(xm) - np.array([1e-3, -1e-4, 1e-3])  # the middle interval's jump pokes through the gap
    before = bounds_of(x, e, M, qn, qm)
    margin = rounding_margin(x, e, M, qn, qm)
    assert before[0] > margin and before[2] > margin and before[1] < 0
    qn2, qm2 = restore_admissible(x, e, M, qn, qm, margin)
    need = margin - before[1]
    # need plus SHIFT_ULPS ulps of the middle interval's values (~0.005): 2e-17, under 1e-16
    np.testing.assert_allclose(qn - qn2, [0, need, need, 0], rtol=0, atol=1e-16)
    np.testing.assert_allclose(qm - qm2, [need / 4, need, need / 4], rtol=0, atol=1e-16)
    after = bounds_of(x, e, M, qn2, qm2)
    assert after[1] >= margin and np.all(after[[0, 2]] >= margin)
    # the uniform shift raises the failing interval's bound by exactly its shift, to the margin; the shift's
    # rounding allowance (2e-17, above) and the bound's own rounding are all that is left above it
    assert margin <= after[1] <= margin + 2e-16


def test_the_midpoint_shift_is_the_least_that_keeps_the_shift_above_the_need():
    """The shift quadratic through (a, t, b) with t = need + (sqrt(a - need) - sqrt(b - need))^2 / 4 has
    minimum exactly `need` on [0, 1] (dense samples: the grid misses the touching point by O(DU^2))."""
    rng = np.random.default_rng(4)
    need = rng.uniform(0, 1, 200)
    a, b = need + rng.uniform(0, 2, 200), need + rng.uniform(0, 2, 200)
    t = need + 0.25 * (np.sqrt(a - need) - np.sqrt(b - need)) ** 2
    r = q_at(U, a[:, None], t[:, None], b[:, None])
    np.testing.assert_allclose(r.min(1), need, rtol=0, atol=1e-7)  # O(DU^2 * |r''|) = 1e-8 * ~10


def test_restore_refuses_an_infinite_curvature():
    x = np.array([0.0, 1.0])
    with pytest.raises(ValueError, match="not finite"):
        restore_admissible(x, x * 0, np.array([np.inf]), x * 0, np.array([0.0]))


# -- the linear case is the P1 formula --------------------------------------------------------------

def test_a_linear_jump_reproduces_the_p1_bound():
    """contact_slack of cvxdual.eq.bounds on a stand-in space (pairs on a line, the circle's gap and
    curvature range): with qm = (q0 + q1) / 2 the bubble term c = 4 qm - 2 (q0 + q1) is 0 exactly and
    the quadratic bound is the P1 one."""
    rng = np.random.default_rng(5)
    n = 200
    x = np.sort(rng.uniform(-0.9, 0.9, n + 1))
    zero = SimpleNamespace(curvature_range=lambda x0, x1: (0 * x0, 0 * x0))
    scene = SimpleNamespace(gap_at=circle, upper=SimpleNamespace(face=zero), lower=SimpleNamespace(face=zero),
                            gap_profile=SimpleNamespace(curvature_range=circle_range))
    pairs = np.column_stack([np.arange(n + 1), np.arange(n + 1) + n + 1])  # (upper, lower) node of each pair
    space = SimpleNamespace(scene=scene, mesh=SimpleNamespace(pairs=pairs, pair_x=x))
    v = rng.normal(0, 1e-3, (2 * n + 2, 2))
    v[n + 1:, 1] += v[: n + 1, 1] + circle(x)  # a jump of eps plus noise: about half the edges fail
    s, smin, exact = contact_slack(space, v)
    q = v[pairs[:, 1], 1] - v[pairs[:, 0], 1]
    M = gap_curvature_bound(space, x[:-1], x[1:])
    bound = quadratic_slack_bound(x[:-1], x[1:], circle(x[:-1]), circle(x[1:]), M, q[:-1], 0.5 * (q[:-1] + q[1:]),
                                  q[1:])
    assert exact and 0.2 < np.mean(smin < 0) < 0.9
    # the same formula; only the order of operations could differ: ulps of the values (~1e-3 .. 1)
    np.testing.assert_allclose(bound, smin, rtol=0, atol=1e-15)
