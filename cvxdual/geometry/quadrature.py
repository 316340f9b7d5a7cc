"""Quadrature rules on the unit interval and the reference triangle."""

from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=None)
def gauss01(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre rule with ``n`` points on ``[0, 1]`` (exact for degree ``2n - 1``)."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


@lru_cache(maxsize=None)
def triangle_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Collapsed (Duffy) Gauss rule with ``n*n`` points on the reference triangle
    ``{(r, s): r, s >= 0, r + s <= 1}``; weights sum to 1/2; exact for degree ``2n - 2``.

    Returns ``(rs, w)`` with ``rs`` of shape ``(n*n, 2)``.
    """
    u, wu = gauss01(n)
    # Gauss-Jacobi(1, 0) would be one degree better; Gauss-Legendre with the Jacobian keeps
    # the rule simple and positive.
    r = np.outer(u, np.ones(n))
    s = np.outer(1.0 - u, u)
    w = np.outer(wu * (1.0 - u), wu)
    return np.stack([r.ravel(), s.ravel()], axis=1), w.ravel()
