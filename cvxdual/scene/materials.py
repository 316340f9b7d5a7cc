"""Linear elastic materials in Voigt form.

Convention (used everywhere in cvxdual): stress ``s = (s11, s22, s12)``, engineering strain
``g = (e11, e22, 2 e12)``, Hooke's law ``s = C g``, compliance ``A = C^-1``. Then
``sigma:eps = s . g`` and the complementary energy density is ``1/2 s . A s``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

from ..errors import SceneError
from ..validate import number, short

Plane = Literal["strain", "stress"]
PLANES: tuple[Plane, ...] = get_args(Plane)


@dataclass(frozen=True)
class Material:
    """An isotropic material ``(E, nu)`` in plane strain or plane stress, or a 3x3 Hooke matrix.

    Use :meth:`isotropic` or :meth:`hooke` to build one; both validate their input.
    """

    C: tuple[tuple[float, float, float], ...]
    E: float | None = None
    nu: float | None = None
    plane: Plane = "strain"
    description: str = field(default="", compare=False)

    @classmethod
    def isotropic(cls, E: float, nu: float, plane: Plane = "strain") -> "Material":
        E = number(E, "material E", "positive")
        nu = number(nu, "material nu")
        if plane not in PLANES:
            raise SceneError(f"plane must be 'strain' or 'stress', got {plane!r}")
        if E <= 0:
            raise SceneError(f"Young's modulus E must be positive, got {E:g}; give E > 0")
        # -1 < nu < 1/2 is where an isotropic 3D material is positive definite (plane stress
        # alone would allow nu < 1, but no real material has it)
        if not (-1.0 < nu < 0.5):
            raise SceneError(
                f"Poisson's ratio nu = {nu:g} is outside (-1, 0.5); the material would not be "
                "positive definite; give -1 < nu < 0.5"
            )
        if plane == "strain":
            lam = E * nu / ((1 + nu) * (1 - 2 * nu))
            mu = E / (2 * (1 + nu))
            C = np.array([[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]])
        else:
            k = E / (1 - nu**2)
            C = k * np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, (1 - nu) / 2]])
        return cls(C=_as_tuple(C), E=E, nu=nu, plane=plane,
                   description=f"isotropic E={E:g}, nu={nu:g}, plane {plane}")

    @classmethod
    def hooke(cls, C, plane: Plane = "strain") -> "Material":
        if isinstance(C, np.ndarray):
            C = C.tolist()
        rows = C if isinstance(C, (list, tuple)) and len(C) == 3 else None
        if rows is None or not all(isinstance(r, (list, tuple)) and len(r) == 3 for r in rows):
            raise SceneError(f"a Hooke matrix must be 3x3 numbers (Voigt s11, s22, s12), got {short(C)}")
        arr = np.array([[number(v, "a Hooke matrix entry") for v in r] for r in rows])
        if not np.allclose(arr, arr.T, rtol=1e-12, atol=0.0):
            raise SceneError("the Hooke matrix must be symmetric")
        w = np.linalg.eigvalsh(arr)
        # A relative eigenvalue floor of 1e-12: below it the compliance cannot be formed in
        # double precision, so the material is treated as not positive definite.
        if w[0] <= 1e-12 * abs(w[-1]):
            raise SceneError(
                f"the Hooke matrix is not positive definite (eigenvalues {w[0]:.3g} .. {w[-1]:.3g}); "
                "give a symmetric positive definite matrix"
            )
        if plane not in PLANES:
            raise SceneError(f"plane must be 'strain' or 'stress', got {plane!r}")
        return cls(C=_as_tuple(arr), plane=plane, description="anisotropic Hooke matrix")

    @property
    def stiffness(self) -> np.ndarray:
        """The 3x3 Hooke matrix ``C``."""
        return np.array(self.C)

    @property
    def compliance(self) -> np.ndarray:
        """The 3x3 compliance ``A = C^-1``."""
        return np.linalg.inv(self.stiffness)

    @property
    def modulus(self) -> float:
        """A representative stiffness for scaling: the uniaxial modulus ``1 / max(A11, A22)``
        (``E / (1 - nu^2)`` in plane strain). Unlike the largest eigenvalue of ``C``, which
        grows without bound as nu -> 1/2, it stays near ``E``; it makes the compliance O(1)."""
        A = self.compliance
        return float(1.0 / max(A[0, 0], A[1, 1]))


def _as_tuple(a: np.ndarray) -> tuple[tuple[float, float, float], ...]:
    return tuple(tuple(float(v) for v in row) for row in a)
