"""The rounded flat punch: contact pressure in closed form and its subsurface field by Flamant
superposition (docs/theory.md#the-rounded-flat-punch).

A flat of half-width ``b`` with corner radius ``R`` pressed on a half-plane (or two half-planes:
plane strain, contact modulus ``E*``) under a load ``P`` per unit length touches on ``|x| <= a``,
``a >= b``. With ``x = a sin(phi)``, ``sin(phi0) = b / a`` (Ciavarella, Hills and Monno 1998):

    p(phi) = E* a / (2 pi R) [ (pi - 2 phi0) cos(phi)
                               + sin(phi) ln|sin(phi + phi0) / sin(phi - phi0)|
                               + sin(phi0) ln|tan((phi + phi0) / 2) tan((phi - phi0) / 2)| ],
    P = E* a^2 / (4 R) (pi - 2 phi0 - sin(2 phi0)).

At ``b = 0`` both are Hertz's. The stress in each body is the superposition of Flamant's line
load solution over ``p``; the integral is done in ``t = a sin(theta)`` (smooth at the contact
ends, where ``p`` goes like a square root) by composite Gauss rules, per point, whose panels grow
geometrically away from the point (from a quarter of its depth: the kernel's width) and away from
``|t| = b``, where ``p`` has a logarithmic slope. Local frame: ``x`` along the face, ``z >= 0`` the depth into the body;
tension positive, ``p >= 0`` pushes into each body (as :mod:`cvxdual.reference.hertz`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

GAUSS = 8  # points per panel
LEVELS = 48  # geometric panels a side at most: from a quarter of the depth up to 2^46 depths (z >= 1e-12 a)
LOG_PANEL = 1e-4  # the panels touching |t| = b: Gauss on (t - b) ln|t - b| there errs by ~1e-11 of p (measured)
CHUNK = 2_000_000  # point-node pairs evaluated at a time (memory ~ 100 MB)


@dataclass(frozen=True)
class PunchData:
    """Half-width ``a`` of the contact, flat half-width ``b``, corner radius ``R``, contact
    modulus ``E_star`` and load ``load`` per unit length (the whole contact)."""

    a: float
    b: float
    R: float
    E_star: float
    load: float

    @property
    def phi0(self) -> float:
        return math.asin(min(self.b / self.a, 1.0))


def punch_load(a: float, b: float, R: float, E_star: float) -> float:
    """``P`` that presses the punch in to the half-width ``a >= b``."""
    phi0 = math.asin(min(b / a, 1.0))
    return E_star * a * a / (4.0 * R) * (math.pi - 2.0 * phi0 - math.sin(2.0 * phi0))


def punch_contact(b: float, R: float, E_star: float, load: float) -> PunchData:
    """The contact half-width under ``load`` (``P`` grows with ``a`` from 0 at ``a = b``)."""
    from scipy.optimize import brentq  # here: only punch scenes need it, and it is slow to import
    for name, v in (("R", R), ("E*", E_star), ("load", load)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be positive and finite, got {v!r}")
    if not (math.isfinite(b) and b >= 0):
        raise ValueError(f"the flat half-width b must be >= 0 and finite, got {b!r}")
    hi = max(2.0 * b, math.sqrt(4.0 * load * R / (math.pi * E_star))) + 1.0
    while punch_load(hi, b, R, E_star) < load:
        hi *= 2.0
    a = brentq(lambda s: punch_load(s, b, R, E_star) - load, max(b, 1e-300), hi, xtol=1e-15 * hi, rtol=1e-15)
    return PunchData(a=float(a), b=float(b), R=float(R), E_star=float(E_star), load=float(load))


def punch_pressure(x, d: PunchData) -> np.ndarray:
    """The contact pressure ``p(x)`` (zero outside ``|x| < a``)."""
    x = np.abs(np.asarray(x, float))
    inside = x < d.a
    phi = np.arcsin(np.clip(x / d.a, 0.0, 1.0))
    c = d.E_star * d.a / (2.0 * math.pi * d.R)
    if d.b == 0.0:
        return np.where(inside, c * math.pi * np.cos(phi), 0.0)
    p0 = d.phi0
    with np.errstate(divide="ignore", invalid="ignore"):
        val = ((math.pi - 2 * p0) * np.cos(phi)
               + np.sin(phi) * np.log(np.abs(np.sin(phi + p0) / np.sin(phi - p0)))
               + math.sin(p0) * np.log(np.abs(np.tan(0.5 * (phi + p0)) * np.tan(0.5 * (phi - p0)))))
    # at |x| = b the logarithms cancel: the limit is (pi - 2 phi0) cos(phi0) + 2 sin(phi0) ln(sin(phi0))
    at_b = (math.pi - 2 * p0) * math.cos(p0) + 2 * math.sin(p0) * math.log(math.sin(p0))
    val = np.where(np.abs(phi - p0) < 1e-12, at_b, val)
    return np.where(inside, c * val, 0.0)


def _pressure_at(theta: np.ndarray, s: np.ndarray, c: np.ndarray, d: PunchData) -> np.ndarray:
    """:func:`punch_pressure` at ``t = a sin(theta)`` inside the contact, given ``s = |sin(theta)|``
    and ``c = cos(theta)`` (the quadrature has both): three transcendental functions where
    :func:`punch_pressure` takes eleven (it was 70 % of the field's time). With ``phi = |theta|``,
    ``sm = sin(phi - phi0)`` (directly: exact to rounding however near ``phi0``), ``sp = sin(phi + phi0)``
    by the addition formula (no cancellation) and ``tan((phi + phi0) / 2) tan((phi - phi0) / 2)
    = (cos(phi0) - cos(phi)) / (cos(phi0) + cos(phi)) = sm sp / (cos(phi0) + cos(phi))^2``."""
    k = d.E_star * d.a / (2.0 * math.pi * d.R)
    if d.b == 0.0:
        return k * math.pi * c
    p0 = d.phi0
    s0, c0 = math.sin(p0), math.cos(p0)
    sm, sp = np.sin(np.abs(theta) - p0), s * c0 + c * s0
    with np.errstate(divide="ignore", invalid="ignore"):
        val = (math.pi - 2 * p0) * c + s * np.log(sp / np.abs(sm)) + s0 * np.log(np.abs(sm) * sp / (c0 + c) ** 2)
    at_b = (math.pi - 2 * p0) * c0 + 2 * s0 * math.log(s0)  # the limit at phi0, where the logarithms cancel
    return k * np.where(sm == 0.0, at_b, val)


def _breaks(d: PunchData, th: np.ndarray, zt: np.ndarray) -> np.ndarray:
    """Panel ends in ``theta`` per point ``(m, k)``: geometric (ratio 2) on both sides of the point's
    own ``theta`` from a quarter of its depth (in ``theta``) up to a half turn, and on both sides of
    ``+-phi0``, where ``p`` has a logarithmic slope, from :data:`LOG_PANEL`; clipped to
    ``[-pi/2, pi/2]`` (clipped panels have zero width and weight)."""
    half = math.pi / 2
    levels = int(np.clip(np.ceil(np.log2(4.0 * math.pi / zt.min())) + 2, 3, LEVELS))
    k = 2.0 ** np.arange(levels)
    near = 0.25 * zt[:, None] * (k[None, :] - 1.0)  # 0, z/4, 3z/4, ...: the kernel's width is ~z
    cols = [th[:, None] - near, th[:, None] + near[:, 1:]]
    if d.b > 0:
        far = LOG_PANEL * 2.0 ** np.arange(int(np.ceil(np.log2(math.pi / LOG_PANEL))))
        for s in (-d.phi0, d.phi0):
            cols += [np.broadcast_to(s - far, (len(th), len(far))), np.broadcast_to(s + far, (len(th), len(far)))]
    cols.append(np.broadcast_to([-half, half], (len(th), 2)))
    return np.sort(np.clip(np.concatenate(cols, 1), -half, half), axis=1)


def flamant_stress(x, z, d: PunchData) -> np.ndarray:
    """``(sigma_x, sigma_z, tau_xz)`` ``(m, 3)`` at local points ``x``, depth ``z >= 0``: at
    ``z = 0`` the surface values ``(-p, -p, 0)``, elsewhere composite Gauss rules per point in
    ``t = a sin(theta)`` (:func:`_breaks`), exact to rounding for depths down to ``1e-12 a``."""
    x, z = np.asarray(x, float).ravel(), np.maximum(np.asarray(z, float).ravel(), 0.0)
    out = np.zeros((len(x), 3))
    surface = z <= 1e-12 * d.a  # the limit: no panel of a double resolves a kernel this narrow
    p = punch_pressure(x[surface], d)
    out[surface] = np.stack([-p, -p, np.zeros_like(p)], 1)
    idx = np.flatnonzero(~surface)
    idx = idx[np.argsort(z[idx])]  # chunks of like depths share a number of panels
    g, w = np.polynomial.legendre.leggauss(GAUSS)
    step = max(1, CHUNK // ((2 * LEVELS + 80) * GAUSS))
    for s0 in range(0, len(idx), step):
        k = idx[s0:s0 + step]
        th = np.arcsin(np.clip(x[k] / d.a, -1.0, 1.0))
        e = _breaks(d, th, z[k] / d.a)
        lo, hi = e[:, :-1, None], e[:, 1:, None]
        tt = 0.5 * (lo + hi) + 0.5 * (hi - lo) * g  # (m, panels, GAUSS)
        sin, cos = np.sin(tt), np.cos(tt)
        t = d.a * sin
        wt = 0.5 * (hi - lo) * w * d.a * cos * _pressure_at(tt, np.abs(sin), cos, d)
        X = x[k, None, None] - t
        Z = z[k, None, None]
        f = -2.0 / math.pi * wt / (X * X + Z * Z) ** 2
        out[k, 0] = (f * X * X * Z).sum((1, 2))
        out[k, 1] = (f * Z**3).sum((1, 2))
        out[k, 2] = (f * X * Z * Z).sum((1, 2))
    return out


def punch_body_stress(x, y, d: PunchData, x_c: float, y_face: float, upper: bool) -> np.ndarray:
    """Voigt ``(s11, s22, s12)`` in the global frame: the upper body lies above ``y = y_face``
    (depth ``y - y_face``), the lower below; ``s12 = +tau_xz`` above, ``-tau_xz`` below."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    z = (y - y_face) if upper else (y_face - y)
    s = flamant_stress(x - x_c, z, d)
    return np.stack([s[:, 0], s[:, 1], s[:, 2] if upper else -s[:, 2]], 1)
