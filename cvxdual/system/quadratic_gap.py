"""Pointwise admissibility of a quadratic normal jump against the true gap (issue 41, a step of the
P2 kinematic side), vectorised over contact intervals.

On a contact interval ``[x0, x1]`` (length ``d``, ``u = (x - x0) / d``) a continuous P2
displacement has a quadratic jump ``[v] = v''_y - v'_y`` (lower body minus upper, as in
``cvxdual.eq.bounds.contact_slack``), given by its values ``q0, qm, q1`` at ``u = 0, 1/2, 1``:

    q(u) = q0 (1 - u) + q1 u + c u (1 - u),    c = 4 qm - 2 (q0 + q1).

Admissibility asks ``[v](x) <= eps(x)`` at *every* ``x``. The gap is known by its end values
``e0, e1`` and a guaranteed bound ``eps'' <= M`` (``cvxdual.eq.bounds.gap_curvature_bound``); in
``u``, ``d^2 eps / du^2 <= M d^2``. Then ``g(u) = eps(u) - (M d^2 / 2) u^2`` is concave, so it lies
above its chord, and adding ``(M d^2 / 2) u^2`` back,

    eps(u) >= L(u) = e0 (1 - u) + e1 u + kappa u (1 - u),    kappa = -M d^2 / 2

(for a convex gap ``kappa < 0``: the chord is *above* the gap and ``L`` is below both; for an
exact parabola with ``M = eps''``, ``L = eps``). The slack ``eps - q`` is therefore bounded below by
the quadratic ``p(u) = L(u) - q(u) = s0 (1 - u) + s1 u + K u (1 - u)``, ``s0 = e0 - q0``,
``s1 = e1 - q1``, ``K = kappa - c``: the P1 bound of ``contact_slack`` with ``kappa`` replaced by
``K`` (a linear jump has ``c = 0``). Its minimum over ``[0, 1]`` is exact in closed form: the ends
and, where ``K < 0`` and it lies inside, the vertex ``u* = 1/2 + (s1 - s0) / (2 K)``.

Rounding. Every computed value here is a sum of a few products of numbers of size at most
``S = max |e, q, kappa|``, so it carries an error of some tens of ulps of ``S`` (about 1e-14 S).
As the P1 code does (``admissible_displacement``'s ``1e-13`` margin), a bound is accepted only
when it is at least a margin of :data:`RELATIVE_MARGIN` (about 450 ulps) times the problem's
scale: then the true slack is non-negative whatever the rounding. :func:`restore_admissible`
enforces that margin and checks it on its own result.
"""

from __future__ import annotations

import numpy as np

# a bound below this fraction of the problem's scale may be a negative slack lost in rounding
RELATIVE_MARGIN = 1e-13
# a shift adds this many ulps of the interval's scale to its deficit: a smaller shift of a value of
# that size could be lost when it is subtracted
SHIFT_ULPS = 16
RESTORE_PASSES = 4  # the first pass suffices in exact arithmetic; the others absorb rounding
# Bernstein coefficients of q on [0, 1] from its values (q0, qm, q1): b = BERNSTEIN_Q @ (q0, qm, q1)
BERNSTEIN_Q = np.array([[1.0, 0.0, 0.0], [-0.5, 2.0, -0.5], [0.0, 0.0, 1.0]])


def _parts(x0, x1, e0, e1, M, q0, qm, q1) -> tuple[np.ndarray, ...]:
    """``(s0, s1, K, kappa)`` of the lower bound ``p(u) = s0 (1 - u) + s1 u + K u (1 - u)``."""
    x0, x1, e0, e1, M, q0, qm, q1 = np.broadcast_arrays(*(np.asarray(a, float) for a in (x0, x1, e0, e1, M, q0,
                                                                                          qm, q1)))
    kappa = -0.5 * M * (x1 - x0) ** 2
    c = 4.0 * qm - 2.0 * (q0 + q1)
    return e0 - q0, e1 - q1, kappa - c, kappa


def quadratic_slack_bound(x0, x1, e0, e1, M, q0, qm, q1) -> np.ndarray:
    """A guaranteed lower bound ``(n,)`` of ``min_{x in [x0, x1]} (eps(x) - q(x))`` on each interval,
    from the gap's end values ``e0, e1``, a bound ``M >= eps''`` on the interval and the jump's
    values ``q0, qm, q1`` at ``x0``, the midpoint and ``x1`` (all ``(n,)``, or broadcastable).

    ``eps'' <= M`` makes ``eps - M x^2 / 2`` concave, hence above its chord:
    ``eps(u) >= e0 (1 - u) + e1 u - (M d^2 / 2) u (1 - u)``; minus ``q`` this is the quadratic
    ``p(u) = s0 (1 - u) + s1 u + K u (1 - u)`` (``K = -M d^2 / 2 - 4 qm + 2 (q0 + q1)``), whose
    minimum over ``[0, 1]`` (ends, and the vertex where ``K < 0`` puts it inside) is returned. It
    is the true minimum when the gap is a parabola with ``M = eps''``; in general it is below the
    true one by at most ``(M - min eps'') d^2 / 8``. Exact up to rounding (module docstring)."""
    s0, s1, K, _ = _parts(x0, x1, e0, e1, M, q0, qm, q1)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.clip(0.5 + (s1 - s0) / (2.0 * K), 0.0, 1.0)
    u = np.where(K < 0, u, 0.0)  # K >= 0: p is concave (or linear), its minimum is at an end
    return np.minimum(np.minimum(s0, s1), s0 * (1 - u) + s1 * u + K * u * (1 - u))


def bernstein_slack(x0, x1, e0, e1, M, q0, qm, q1) -> np.ndarray:
    """The Bernstein coefficients ``(n, 3)`` of the lower bound ``p`` of the slack
    (:func:`quadratic_slack_bound`): ``b0 = p(0)``, ``b1 = 2 p(1/2) - (p(0) + p(1)) / 2``,
    ``b2 = p(1)``. ``p = b0 (1 - u)^2 + 2 b1 u (1 - u) + b2 u^2`` with non-negative weights, so
    all three ``>= 0`` is *sufficient* for ``eps >= q`` on the interval (not necessary:
    ``p = (1 - 2u)^2`` has ``b1 = -1``). The coefficients are affine in ``(q0, qm, q1)``:
    ``b = (e0, (e0 + e1 + kappa) / 2, e1) - BERNSTEIN_Q @ (q0, qm, q1)``, ``kappa = -M d^2 / 2``,
    so ``b >= 0`` are three linear constraints per interval for an active-set or QP solve."""
    s0, s1, K, _ = _parts(x0, x1, e0, e1, M, q0, qm, q1)
    return np.stack([s0, 0.5 * (s0 + s1 + K), s1], axis=-1)


def rounding_margin(x, e, M, q_nodes, q_mid, scale: float = 0.0) -> float:
    """:data:`RELATIVE_MARGIN` times the problem's scale: the largest gap, jump and curvature term
    ``|M| d^2 / 2`` of a chain (arguments as :func:`restore_admissible`), or ``scale`` (a
    displacement scale of the scene, as ``admissible_displacement`` passes) if larger. A computed
    bound at least this large is a non-negative true slack (module docstring)."""
    x, e, M, q_nodes, q_mid = (np.asarray(a, float) for a in (x, e, M, q_nodes, q_mid))
    kappa = 0.5 * np.abs(M) * np.diff(x) ** 2
    return RELATIVE_MARGIN * max(float(np.max(np.abs(a), initial=0.0)) for a in (e, q_nodes, q_mid, kappa, scale))


def restore_admissible(x, e, M, q_nodes, q_mid, margin: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lower a P2 jump on a chain of contact intervals until every interval's guaranteed slack
    (:func:`quadratic_slack_bound`) is at least ``margin``; returns the new ``(q_nodes, q_mid)``.

    The chain: ``n`` intervals ``[x[k], x[k + 1]]`` with the node abscissae ``x (n + 1,)``, the gap
    there ``e (n + 1,)``, curvature bounds ``M (n,)``, the jump at the nodes ``q_nodes (n + 1,)``
    (shared by neighbouring intervals, so one array rather than ``q0, q1`` that must agree) and at
    the midpoints ``q_mid (n,)``. ``margin`` defaults to :func:`rounding_margin`.

    The choice. An interval short by ``need = margin - bound`` (plus a few ulps, ``SHIFT_ULPS``)
    is lowered by a quadratic ``r`` with ``r >= need`` on it: the slack bound ``p`` rises by
    ``r``, so its minimum by at least ``need``. The uniform shift ``r = need`` (both ends and the
    midpoint lowered by ``need``) is the smallest such and leaves the bound's curvature alone, as
    the P1 code lowers both ends of an edge. A node shared by two intervals takes the larger shift
    ``a`` of the two (the P1 rule); then the midpoint's shift ``t`` must keep ``r >= need`` although
    an end moved more: with ``alpha, beta >= 0`` the end shifts' excess over ``need``, the quadratic
    through ``(alpha, t - need, beta)`` is ``>= 0`` on ``[0, 1]`` iff
    ``t - need >= (sqrt(alpha) - sqrt(beta))^2 / 4`` (``alpha / u + beta / (1 - u) >= (sqrt(alpha)
    + sqrt(beta))^2``), and that smallest ``t`` is taken (``need <= t <= max`` of the end shifts).
    An interval that passes has ``need = 0``: it changes only where a neighbour moved a shared node,
    and then ``r >= 0`` keeps it passing; one whose neighbours pass too is not touched.

    The result is checked: a few vectorised passes repeat the step where rounding left a bound a
    hair below ``margin`` (the first pass does it in exact arithmetic); ``ValueError`` if that
    fails (non-finite data: an infinite ``M``, say)."""
    x, e = np.asarray(x, float), np.asarray(e, float)
    qn, qm = np.array(q_nodes, float), np.array(q_mid, float)
    n = len(qm)
    M = np.broadcast_to(np.asarray(M, float), (n,))
    if not (x.shape == e.shape == qn.shape == (n + 1,)):
        raise ValueError(f"a chain of {n} intervals needs {n + 1} node values of x, e and q_nodes")
    if margin is None:
        margin = rounding_margin(x, e, M, qn, qm)
    x0, x1, e0, e1 = x[:-1], x[1:], e[:-1], e[1:]
    for k in range(RESTORE_PASSES):
        bound = quadratic_slack_bound(x0, x1, e0, e1, M, qn[:-1], qm, qn[1:])
        if not np.all(np.isfinite(bound)):
            raise ValueError("a contact interval's slack bound is not finite")
        short = bound < margin
        if not short.any():
            return qn, qm
        scale = np.max(np.abs([e0, e1, qn[:-1], qm, qn[1:], 0.5 * M * (x1 - x0) ** 2]), axis=0)
        need = np.where(short, margin - bound + (SHIFT_ULPS << k) * np.finfo(float).eps * scale, 0.0)
        a = np.zeros(n + 1)
        a[:-1] = need
        a[1:] = np.maximum(a[1:], need)
        t = need + 0.25 * (np.sqrt(a[:-1] - need) - np.sqrt(a[1:] - need)) ** 2
        qn -= a
        qm -= t
    raise ValueError(f"the jump is still inadmissible after {RESTORE_PASSES} passes")



# rounding of the closed forms of the curvature bounds: they are widened by this fraction
CURVATURE_MARGIN = 1e-9


def gap_curvature(scene, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """A guaranteed upper bound ``M`` of the gap's second derivative on each interval ``[x0, x1]``:
    ``eps = f_u - f_l + g`` (upper face, lower face, gap profile), so ``eps'' <= max f_u'' - min f_l''
    + max g''`` (each profile's ``curvature_range``, from its closed form), widened by
    :data:`CURVATURE_MARGIN` of the terms for their rounding."""
    (_, hu), (ll, _), (_, hg) = (p.curvature_range(x0, x1) for p in (scene.upper.face, scene.lower.face,
                                                                       scene.gap_profile))
    return hu - ll + hg + CURVATURE_MARGIN * (np.abs(hu) + np.abs(ll) + np.abs(hg))


def bernstein_gap(x: np.ndarray, e: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``(n,)``: the bound ``(e0 + e1 + kappa) / 2`` (``kappa = -M d^2 / 2``) on the middle Bernstein
    coefficient ``2 q(1/2) - (q0 + q1) / 2`` of a quadratic jump on each interval of a chain (nodes
    ``x``, gap ``e`` there, curvature bounds ``M``) that, with ``q <= e`` at the nodes, makes the jump
    admissible at every x (:func:`bernstein_slack`): a linear constraint per interval."""
    return 0.5 * (e[:-1] + e[1:] - 0.5 * M * np.diff(x) ** 2)
