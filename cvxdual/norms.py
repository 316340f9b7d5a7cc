"""Stress norms and errors (MATH.md section 5).

``||lam||_0^2 = int lam:lam dx`` (with ``lam:lam = s11^2 + s22^2 + 2 s12^2``) and the energy
norm ``(A lam, lam)^(1/2)``, integrated piece by piece (curved pieces included) with a
tensor Gauss rule of ``n`` points per direction.
"""

from __future__ import annotations

import numpy as np

from .assembly import System

VOIGT_WEIGHT = np.array([1.0, 1.0, 2.0])  # sigma:tau in Voigt form
DEFAULT_QUAD = 6  # points per direction; a finer rule changes the Hertz errors by < 1% (tests)


def stress_error(system: System, t: np.ndarray, reference, n: int = DEFAULT_QUAD) -> dict:
    """Errors of piecewise-constant stresses ``t`` ``(n_pieces, 3)`` against ``reference``,
    which maps ``(body, points)`` to stresses (an exact field's ``stress`` method)."""
    pieces = system.pieces
    pts, w, idx = pieces.quadrature(n)
    body = pieces.body[idx]
    ref = np.empty((len(pts), 3))
    for k in (0, 1):
        m = body == k
        if np.any(m):
            ref[m] = reference(k, pts[m])
    diff = t[idx] - ref
    A = np.stack([b.material.compliance for b in system.mesh.scene.bodies])[body]
    l2 = float(np.sqrt(np.sum(w * np.sum(VOIGT_WEIGHT * diff**2, axis=1))))
    ref_l2 = float(np.sqrt(np.sum(w * np.sum(VOIGT_WEIGHT * ref**2, axis=1))))
    en = float(np.sqrt(np.sum(w * np.einsum("mi,mij,mj->m", diff, A, diff))))
    ref_en = float(np.sqrt(np.sum(w * np.einsum("mi,mij,mj->m", ref, A, ref))))
    return {
        "l2": l2,
        "l2_rel": l2 / ref_l2 if ref_l2 > 0 else float("nan"),
        "energy": en,
        "energy_rel": en / ref_en if ref_en > 0 else float("nan"),
        "quadrature_points": int(n),
    }


def l2_norm(system: System, t: np.ndarray) -> float:
    """``||t||_0`` of piecewise-constant stresses."""
    return float(np.sqrt(np.sum(system.pieces.area * np.sum(VOIGT_WEIGHT * t**2, axis=1))))


def stress_distance(a, b, n: int = 2) -> dict:
    """``||lam_a - lam_b||`` (L2 and energy) between two solutions of the same scene on different
    meshes, integrated over ``a``'s pieces (``n*n`` points each), every point located in
    ``b``'s pieces; relative measures are against ``a``. Integrate over the finer mesh: both
    fields are then constant on most of its pieces and the rule is nearly exact."""
    from .errors import CvxdualError
    from .locate import locate
    pa = a.pieces
    pts, w, idx = pa.quadrature(n)
    # Gauss points are interior; the tolerance only absorbs rounding where a's and b's faces
    # are the same curve evaluated at different points
    tol = 1e-10 * a.scene.length_scale
    body = pa.body[idx]
    loc = locate(b.mesh, b.pieces, pts, body, tol)
    if np.any(loc < 0):
        raise CvxdualError(f"{int(np.sum(loc < 0))} quadrature points of one solution lie outside the "
                           "other's pieces: the solutions are not of the same scene")
    ta = a.stress[idx]
    diff = ta - b.stress[loc]
    A = np.stack([bd.material.compliance for bd in a.scene.bodies])[body]
    l2 = float(np.sqrt(np.sum(w * np.sum(VOIGT_WEIGHT * diff**2, axis=1))))
    ref = float(np.sqrt(np.sum(w * np.sum(VOIGT_WEIGHT * ta**2, axis=1))))
    en = float(np.sqrt(np.sum(w * np.einsum("mi,mij,mj->m", diff, A, diff))))
    ref_en = float(np.sqrt(np.sum(w * np.einsum("mi,mij,mj->m", ta, A, ta))))
    return {"l2": l2, "l2_rel": l2 / ref if ref > 0 else float("nan"),
            "energy": en, "energy_rel": en / ref_en if ref_en > 0 else float("nan"), "quadrature_points": n}
