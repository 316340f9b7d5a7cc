"""Closed-form stress fields ``lam*`` of the scenes that have one.

An exact field evaluates the Voigt stress ``(s11, s22, s12)`` of body ``k`` (0 upper,
1 lower) at points ``(m, 2)``. Scenes use it for their ``exact`` tractions on truncated
boundaries and the error norms use it as the reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..scene.scene import Scene
from .hertz import HertzData, body_stress, hertz_line_contact, hertz_pressure


@dataclass(frozen=True)
class UniformField:
    value: tuple[float, float, float]

    def stress(self, body: int, pts: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.array(self.value, float), (len(pts), 3)).copy()

    def pressure(self, x: np.ndarray) -> np.ndarray:
        return np.full(np.shape(x), -self.value[1])

    def data(self) -> dict:
        return {"kind": "uniform", "stress": list(self.value)}


@dataclass(frozen=True)
class HertzField:
    """The McEwen field of linearised Hertz line contact, on faces ``y = y_face``."""

    hertz: HertzData
    xc: float
    y_face: float

    def stress(self, body: int, pts: np.ndarray) -> np.ndarray:
        return body_stress(pts[:, 0], pts[:, 1], self.hertz.a, self.hertz.p0,
                           x_c=self.xc, y_face=self.y_face, upper=(body == 0))

    def pressure(self, x: np.ndarray) -> np.ndarray:
        return hertz_pressure(np.asarray(x, float) - self.xc, self.hertz.a, self.hertz.p0)

    def data(self) -> dict:
        h = self.hertz
        return {"kind": "hertz", "a": h.a, "p0": h.p0, "E_star": h.E_star, "R": h.R, "load": h.load}


def exact_field(scene: Scene):
    """The exact field of ``scene`` or ``None``."""
    spec = scene.exact
    if spec is None:
        return None
    if spec.kind == "uniform":
        return UniformField(spec.stress)
    up, lo = scene.upper, scene.lower
    if abs(up.face.y0 - lo.face.y0) > 1e-12 * scene.length_scale:
        raise SceneError("the 'hertz' exact field needs both flat faces at the same height")
    try:
        data = hertz_line_contact(up.material.E, up.material.nu, lo.material.E, lo.material.nu,
                                  spec.R, spec.load, plane=up.material.plane)
    except ValueError as e:
        raise SceneError(f"exact field 'hertz': {e}") from None
    return HertzField(data, spec.xc, up.face.y0)
