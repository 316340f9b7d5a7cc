"""A quadrature on the exact continuation pieces beyond the free arcs (``OutlineBuild.free_arc``):
a convex arc's circular segment beyond its chord, or, round a concave arc, the corner between the
arc and the tangents at the chord's ends. A P1 displacement has constant strain there, so the
piece's area is enough (``RestMesh.virtual_weight``); a P2 one has not, and its energy needs a rule
exact for polynomials of degree 2 in ``x, y`` on the curved region itself.

In polar coordinates ``(rho, theta)`` about the arc's centre each half of a piece (either side of
its bisector) lies between two curves ``rho(theta)`` that are smooth in the angle: the circle
``rho = r``, and a straight line ``rho = p / cos(theta - theta_0)`` (the chord, or the tangent of
the half's end). The corner's outer bound switches tangents at the bisector, so the halves are
integrated apart. In the angle: Gauss-Legendre (the bounds are analytic, 1/cos far from its
poles: geometric convergence). In the radius: two Gauss points with the Jacobian ``rho``, exact,
since ``rho`` times a polynomial of degree 2 in ``x, y`` is a cubic in ``rho``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RADIAL = np.array([-1.0, 1.0]) / np.sqrt(3.0)  # 2-point Gauss on [-1, 1], both weights 1: exact for cubics


@dataclass(frozen=True)
class ContinuationRule:
    """Points ``(m, q, 2)`` and weights ``(m, q)`` of a quadrature on each continuation piece,
    rows as :meth:`~cvxdual.geometry.mesh.Mesh.continuation`'s: ``sum(weights * f(points))``
    integrates ``f`` over the exact piece, exactly for polynomials of degree 2 in ``x, y``."""

    points: np.ndarray
    weights: np.ndarray


def continuation_rule(a: np.ndarray, b: np.ndarray, arc: np.ndarray, corner: np.ndarray,
                      n: int = 12) -> ContinuationRule:
    """The rule on the pieces between the ends ``a``, ``b`` ``(m, 2)`` of arcs ``(cx, cy, r)``
    ``(m, 3)`` (less than a half turn apart): the circular segment beyond the chord ``a b``, or
    where ``corner`` ``(m,)`` the corner beyond the arc, bounded by the tangents at ``a`` and ``b``.
    ``n`` Gauss-Legendre points in the angle on each half: ``q = 4 n`` points a piece."""
    arc = np.asarray(arc, float).reshape(-1, 3)
    centre, r = arc[:, :2], arc[:, 2]
    theta_a = _angle(a, centre)
    sweep = np.angle(np.exp(1j * (_angle(b, centre) - theta_a)))  # signed, in (-pi, pi]: the short way round
    half = 0.5 * np.abs(sweep)  # the half-angle h: the chord is at r cos(h), the tangents meet at r / cos(h)
    xi, w_xi = np.polynomial.legendre.leggauss(n)
    # phi: angle from the bisector, over [-h, 0] then [0, h]; (m, 2 n), its weights the same
    s = 0.5 * (xi + 1.0)
    phi = half[:, None] * np.concatenate([s - 1.0, s])[None, :]
    w_phi = 0.5 * half[:, None] * np.concatenate([w_xi, w_xi])[None, :]
    corner = np.asarray(corner, bool)[:, None]
    r_, h = r[:, None], half[:, None]
    # the radial extent from its inner bound, in products of sines: a difference of nearly equal radii
    # (r and r cos h / cos phi) would lose 1 / h^2 of the digits on fine arcs
    to_end = h - np.abs(phi)  # a corner half is bounded by the tangent at its own end, at r / cos(to_end)
    inner = np.where(corner, r_, r_ * np.cos(h) / np.cos(phi))  # the circle, or the chord
    width = np.where(corner, 2.0 * r_ * np.sin(0.5 * to_end) ** 2 / np.cos(to_end),
                     2.0 * r_ * np.sin(0.5 * (h + phi)) * np.sin(0.5 * (h - phi)) / np.cos(phi))
    # two radii per angle: (m, 2 n, 2), weight rho d rho d theta
    rho = (inner + 0.5 * width)[..., None] + 0.5 * width[..., None] * RADIAL
    w = (0.5 * width * w_phi)[..., None] * rho
    theta = (theta_a + 0.5 * sweep)[:, None] + phi  # either way round: both halves are taken
    points = centre[:, None, None, :] + rho[..., None] * np.stack([np.cos(theta), np.sin(theta)], -1)[:, :, None, :]
    m = len(arc)
    return ContinuationRule(points=points.reshape(m, 4 * n, 2), weights=w.reshape(m, 4 * n))


def _angle(p, centre: np.ndarray) -> np.ndarray:
    d = np.asarray(p, float).reshape(-1, 2) - centre
    return np.arctan2(d[:, 1], d[:, 0])
