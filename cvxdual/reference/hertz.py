"""Hertz line contact and the McEwen subsurface stress field (docs/theory.md#errors-norms-and-benchmarks).

``hertz_line_contact`` gives the half-width ``a`` and peak pressure ``p0``; ``mcewen_stress``
is the exact plane stress field of an elastic half-space under the Hertz pressure, in the
local frame ``(x, z)`` with ``z >= 0`` the depth into the body; ``body_stress`` maps it into
the global ``(x, y)`` frame of the upper or lower body as Voigt ``(s11, s22, s12)``.

Sign conventions: tension positive, the pressure ``p(x) >= 0`` pushes into each body.
The McEwen formulas were checked here (equilibrium residual, surface values,
max shear ``0.300 p0`` at ``z = 0.786 a``) and are used as written, with ``n`` of the sign
of ``x``. Shear-sign mapping, derived in ``body_stress``: upper body ``s12 = +t_xz``,
lower body ``s12 = -t_xz``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HertzData:
    """Hertz line contact: half-width ``a``, peak pressure ``p0``, contact modulus ``E_star``,
    effective radius ``R`` and load ``load`` per unit length (the whole contact)."""

    a: float
    p0: float
    E_star: float
    R: float
    load: float


def _positive(name: str, value) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return v


def _poisson(name: str, value) -> float:
    v = float(value)
    # -1 < nu <= 1/2 is the range where the isotropic Hooke law is positive (semi)definite.
    if not np.isfinite(v) or not -1.0 < v <= 0.5:
        raise ValueError(f"{name} must be finite with -1 < {name} <= 0.5, got {value!r}")
    return v


def contact_modulus(E1, nu1, E2, nu2, plane: str = "strain") -> float:
    """``E*``: plane strain ``1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2``, plane stress ``1/E1 + 1/E2``."""
    E1, E2 = _positive("E1", E1), _positive("E2", E2)
    nu1, nu2 = _poisson("nu1", nu1), _poisson("nu2", nu2)
    if plane == "strain":
        compliance = (1.0 - nu1**2) / E1 + (1.0 - nu2**2) / E2
    elif plane == "stress":
        compliance = 1.0 / E1 + 1.0 / E2
    else:
        raise ValueError(f"plane must be 'strain' or 'stress', got {plane!r}")
    return 1.0 / compliance


def hertz_line_contact(E1, nu1, E2, nu2, R, load, plane: str = "strain") -> HertzData:
    """Hertz line contact of two cylinders (or cylinder on plane) of effective radius ``R``
    (``1/R = 1/R1 + 1/R2``, pass ``R`` directly) under ``load`` per unit length.

    Plane strain: ``1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2``; plane stress:
    ``1/E* = 1/E1 + 1/E2``. Then ``a = sqrt(4 load R / (pi E*))``, ``p0 = 2 load / (pi a)``.
    Raises ``ValueError`` for non-positive or non-finite ``E``, ``R``, ``load``, or ``nu``
    outside ``(-1, 0.5]``.
    """
    R, load = _positive("R", R), _positive("load", load)
    E_star = contact_modulus(E1, nu1, E2, nu2, plane)
    a = float(np.sqrt(4.0 * load * R / (np.pi * E_star)))
    p0 = 2.0 * load / (np.pi * a)
    return HertzData(a=a, p0=p0, E_star=E_star, R=R, load=load)


def _check_a(a) -> float:
    return _positive("a", a)


def hertz_pressure(x, a, p0) -> np.ndarray:
    """Hertz pressure ``p0 sqrt(1 - x^2/a^2)`` for ``|x| < a``, zero outside."""
    a = _check_a(a)
    ax = np.abs(np.asarray(x, float))
    # (a - |x|)(a + |x|) rather than a^2 - x^2: no cancellation near the edges.
    return p0 / a * np.sqrt(np.maximum((a - ax) * (a + ax), 0.0))


def _mn(x: np.ndarray, z: np.ndarray, a: float):
    """McEwen's ``m >= 0`` and ``n`` (sign of ``x``) and ``S = m^2 + n^2``.

    ``m^2 - n^2 = A = a^2 - x^2 + z^2`` and ``m n = |x| z``: take the larger of ``m, n`` from
    ``(S + |A|)/2`` and the smaller from ``|x| z / larger`` (the textbook ``(S - A)/2`` loses
    all digits near the surface inside the contact).
    """
    ax = np.abs(x)
    A = (a - ax) * (a + ax) + z * z
    S = np.hypot(A, 2.0 * ax * z)
    big = np.sqrt(0.5 * (S + np.abs(A)))
    # big = 0 only at z = 0, |x| = a, where m = n = 0.
    small = np.divide(ax * z, big, out=np.zeros_like(big), where=big > 0)
    m = np.where(A >= 0, big, small)
    n = np.sign(x) * np.where(A >= 0, small, big)
    return m, n, S


def mcewen_stress(x, z, a, p0):
    """McEwen stresses ``(s_x, s_z, t_xz)`` of a half-space ``z >= 0`` (depth) under the
    Hertz pressure of half-width ``a``, peak ``p0``, centred at ``x = 0``. Arrays broadcast.

    ``s_x = -(p0/a) [m (1 + (z^2 + n^2)/(m^2 + n^2)) - 2 z]``,
    ``s_z = -(p0/a) m (1 - (z^2 + n^2)/(m^2 + n^2))``,
    ``t_xz = -(p0/a) n (m^2 - z^2)/(m^2 + n^2)``.
    At ``z = 0``: ``s_x = s_z = -p(x)``, ``t_xz = 0`` (also exactly at ``|x| = a``).
    """
    a = _check_a(a)
    x, z = np.broadcast_arrays(np.asarray(x, float), np.asarray(z, float))
    if np.any(z < 0):
        raise ValueError("mcewen_stress needs depth z >= 0")
    m, n, S = _mn(x, z, a)
    pos = S > 0  # S = 0 only at the contact edges on the surface, where all stresses vanish
    r = np.divide(z * z + n * n, S, out=np.zeros_like(S), where=pos)
    q = np.divide(m * m - z * z, S, out=np.zeros_like(S), where=pos)
    k = p0 / a
    sx = -k * (m * (1.0 + r) - 2.0 * z)
    sz = -k * m * (1.0 - r)
    txz = -k * n * q
    return sx, sz, txz


def body_stress(x, y, a, p0, x_c: float = 0.0, y_face: float = 0.0, upper: bool = True) -> np.ndarray:
    """Voigt stress ``(s11, s22, s12)`` (rows, shape ``(n, 3)``) of the McEwen field in the
    global frame, contact centred at ``x = x_c`` on the face ``y = y_face``.

    Upper body (``y >= y_face``): ``z = y - y_face`` is a translation of ``y``, the local
    frame ``(x, z)`` is the global one, so ``(s11, s22, s12) = (s_x, s_z, t_xz)``.
    Lower body (``y <= y_face``): ``z = y_face - y`` is the reflection ``y -> -y``; normal
    stresses are unchanged and the shear flips, ``s12 = -t_xz``. Check:
    ``d s11/dx + d s12/dy = d s_x/dx + d t_xz/dz = 0`` and
    ``d s12/dx + d s22/dy = -(d t_xz/dx + d s_z/dz) = 0``.
    On the face both give ``s22 = -p``, ``s12 = 0``: compressive, frictionless.
    """
    a = _check_a(a)
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    x, y = x.ravel(), y.ravel()
    z = (y - y_face) if upper else (y_face - y)
    # Points on the face may sit a rounding error outside the body: clip those, refuse others.
    tol = 1e-9 * (a + abs(y_face))
    if np.any(z < -tol):
        side = "upper" if upper else "lower"
        raise ValueError(f"point outside the {side} body (y on the wrong side of y_face = {y_face:g})")
    sx, sz, txz = mcewen_stress(x - x_c, np.maximum(z, 0.0), a, p0)
    return np.column_stack([sx, sz, txz if upper else -txz])
