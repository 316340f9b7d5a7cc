"""Stress norms and errors (docs/theory.md#errors-norms-and-benchmarks).

``||lam||_0^2 = int lam:lam dx`` (with ``lam:lam = s11^2 + s22^2 + 2 s12^2``) and the energy
norm ``(A lam, lam)^(1/2)``, integrated piece by piece (curved pieces included) with a
tensor Gauss rule of ``n`` points per direction.
"""

from __future__ import annotations

import numpy as np

from ..records import ErrorNorms
from ..system.assembly import System
from ..system.field import accumulate_norms, error_norms
from ..voigt import VOIGT_WEIGHT

# points per direction for a solution's error against an exact field: 16 points a piece change
# hertz's relative errors by ~1e-5 relative against an 8x8 rule, at under half a 6x6 rule's time
# (reports/speed.md, "The quadrature rule's own error"); studies choose their own rule
DEFAULT_QUAD = 4
CHUNK_POINTS = 1 << 20  # quadrature points evaluated at once: bounds the temporaries (~15 arrays)


def stress_error(system: System, t: np.ndarray, reference, n: int = DEFAULT_QUAD) -> ErrorNorms:
    """Errors (:class:`~cvxdual.records.ErrorNorms`) of piecewise-constant stresses ``t``
    ``(n_pieces, 3)`` against ``reference``, which maps ``(body, points)`` to stresses (an exact
    field's ``stress`` method)."""
    pieces = system.pieces
    n_pieces = len(pieces)
    step = max(1, CHUNK_POINTS // (n * n))
    acc = np.zeros(4)
    for start in range(0, n_pieces, step):  # a few chunks: memory, not speed, sets their number
        only = None
        if step < n_pieces:
            only = np.zeros(n_pieces, bool)
            only[start:start + step] = True
        pts, w, idx = pieces.quadrature(n, only)
        body = pieces.body[idx]
        for k, b in enumerate(system.mesh.scene.bodies):
            m = np.flatnonzero(body == k)
            if len(m):
                r = reference(k, pts[m])
                accumulate_norms(t[idx[m]] - r, r, w[m], b.material.compliance, acc)
    return error_norms(acc, n)


def l2_norm(system: System, t: np.ndarray) -> float:
    """``||t||_0`` of piecewise-constant stresses."""
    return float(np.sqrt(np.sum(system.pieces.area * np.sum(VOIGT_WEIGHT * t**2, axis=1))))
