"""Voigt stresses ``(s11, s22, s12)``: the inner product ``sigma:tau`` and the stress measures
(in-plane maximum shear, von Mises with ``s33``).

In plane strain ``e33 = 0`` gives ``s33 = nu (s11 + s22)``; in plane stress ``s33 = 0``. The
numpy functions here are the twins of the CVXPY expressions of :class:`cvxdual.DualModel`
(``shear_stress()``, ``von_mises()``), so a result can be checked against what was capped.
"""

from __future__ import annotations

import numpy as np

from .errors import ModelError

__all__ = ["VOIGT_WEIGHT", "body_factors", "out_of_plane_factor", "shear_stress", "von_mises"]

VOIGT_WEIGHT = np.array([1.0, 1.0, 2.0])  # sigma:tau = sum(VOIGT_WEIGHT * sigma * tau) in Voigt form


def compliances(scene) -> np.ndarray:
    """The compliance matrix ``A`` (Voigt, engineering shear) of every body of ``scene``: ``(n_bodies, 3, 3)``."""
    return np.stack([b.material.compliance for b in scene.bodies])


def stiffnesses(scene) -> np.ndarray:
    """The Hooke matrix ``C`` of every body of ``scene``: ``(n_bodies, 3, 3)``."""
    return np.stack([b.material.stiffness for b in scene.bodies])


def body_factors(scene) -> np.ndarray:
    """Factor ``c`` with ``s33 = c (s11 + s22)`` per body of ``scene``: ``nu`` in plane strain,
    0 in plane stress, NaN for a body given by its Hooke matrix alone in plane strain (no ``nu``)."""
    return np.array([0.0 if b.material.plane == "stress" else np.nan if b.material.nu is None
                     else float(b.material.nu) for b in scene.bodies])


def out_of_plane_factor(scene, body: np.ndarray) -> np.ndarray:
    """Factor ``c`` with ``s33 = c (s11 + s22)`` at stress points of the bodies ``body`` (indices
    into ``scene.bodies``): ``nu`` of the body in plane strain, 0 in plane stress. A body given
    by its Hooke matrix alone has no ``nu``: refused."""
    c = body_factors(scene)
    for b, ck in zip(scene.bodies, c, strict=True):
        if np.isnan(ck):
            raise ModelError(f"body {b.name!r} has a Hooke matrix but no Poisson ratio, so s33 (and von Mises) "
                             "is not defined in plane strain; give the material as E and nu")
    return c[np.asarray(body)]


def shear_stress(stress: np.ndarray) -> np.ndarray:
    """In-plane maximum shear ``sqrt(((s11 - s22)/2)^2 + s12^2)`` of Voigt stresses ``(n, 3)``."""
    s = np.asarray(stress)
    return np.hypot(0.5 * (s[:, 0] - s[:, 1]), s[:, 2])


def von_mises(stress: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """Von Mises stress of Voigt stresses ``(n, 3)`` with ``s33 = factor (s11 + s22)``."""
    s = np.asarray(stress)
    s33 = factor * (s[:, 0] + s[:, 1])
    d = np.stack([s[:, 0] - s[:, 1], s[:, 1] - s33, s33 - s[:, 0], np.sqrt(6.0) * s[:, 2]])
    return np.sqrt(0.5 * np.sum(d**2, axis=0))
