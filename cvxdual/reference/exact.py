"""Closed-form stress fields ``lam*`` of the scenes that have one.

An exact field evaluates the Voigt stress ``(s11, s22, s12)`` of body ``k`` (0 upper,
1 lower) at points ``(m, 2)``. Scenes use it for their ``exact`` tractions on truncated
boundaries, and the error norms use it as the reference where it solves the scene
(:func:`exact_reference`): a field declared for one problem says nothing about the error of
another.
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import attrgetter
from typing import ClassVar

import numpy as np

from ..errors import SceneError
from ..scene.scene import ExactKind, Scene
from .hertz import HertzData, body_stress, contact_modulus, hertz_line_contact, hertz_pressure
from .punch import PunchData, punch_body_stress, punch_contact, punch_pressure


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
class ContactField:
    """A closed-form field of a contact centred at ``xc``, on faces ``y = y_face``: ``contact``
    holds its numbers (the half-width ``a`` among them). A kind names in its class statement its
    ``kind``, the ``label`` of messages and the ``keys`` of ``contact`` that :meth:`data` reports
    (in that order), and defines its stress and its pressure in ``u = x - xc``."""

    contact: HertzData | PunchData
    xc: float
    y_face: float
    kind: ClassVar[ExactKind]
    label: ClassVar[str]
    keys: ClassVar[tuple[str, ...]]

    def __init_subclass__(cls, kind: ExactKind, label: str, keys: tuple[str, ...], **kwargs):
        super().__init_subclass__(**kwargs)
        cls.kind, cls.label, cls.keys = kind, label, keys

    @property
    def half_width(self) -> float:
        return self.contact.a

    def stress(self, body: int, pts: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def pressure(self, x: np.ndarray) -> np.ndarray:
        return self._pressure(np.asarray(x, float) - self.xc)

    def _pressure(self, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def data(self) -> dict:
        return {"kind": self.kind, **{k: getattr(self.contact, k) for k in self.keys}}


@dataclass(frozen=True)
class HertzField(ContactField, kind="hertz", label="Hertz", keys=("a", "p0", "E_star", "R", "load")):
    """The McEwen field of linearised Hertz line contact."""

    hertz = property(attrgetter("contact"), doc="The contact's numbers (:class:`HertzData`), by the kind's name.")

    def stress(self, body: int, pts: np.ndarray) -> np.ndarray:
        return body_stress(pts[:, 0], pts[:, 1], self.hertz.a, self.hertz.p0,
                           x_c=self.xc, y_face=self.y_face, upper=(body == 0))

    def _pressure(self, u: np.ndarray) -> np.ndarray:
        return hertz_pressure(u, self.hertz.a, self.hertz.p0)


@dataclass(frozen=True)
class PunchField(ContactField, kind="punch", label="punch", keys=("a", "b", "E_star", "R", "load")):
    """Flamant superposition of the rounded flat punch's pressure."""

    punch = property(attrgetter("contact"), doc="The contact's numbers (:class:`PunchData`), by the kind's name.")

    def stress(self, body: int, pts: np.ndarray) -> np.ndarray:
        return punch_body_stress(pts[:, 0], pts[:, 1], self.punch, self.xc, self.y_face, upper=(body == 0))

    def _pressure(self, u: np.ndarray) -> np.ndarray:
        return punch_pressure(u, self.punch)


def exact_field(scene: Scene):
    """The exact field of ``scene`` or ``None``."""
    spec = scene.exact
    if spec is None:
        return None
    if spec.kind == "uniform":
        return UniformField(spec.stress)
    up, lo = scene.upper, scene.lower
    if abs(up.face.y0 - lo.face.y0) > 1e-12 * scene.length_scale:
        raise SceneError(f"the '{spec.kind}' exact field needs both flat faces at the same height")
    if spec.kind == "punch":
        E_star = contact_modulus(up.material.E, up.material.nu, lo.material.E, lo.material.nu, up.material.plane)
        try:
            return PunchField(punch_contact(spec.b, spec.R, E_star, spec.load), spec.xc, up.face.y0)
        except ValueError as e:
            raise SceneError(f"exact field 'punch': {e}") from None
    try:
        data = hertz_line_contact(up.material.E, up.material.nu, lo.material.E, lo.material.nu,
                                  spec.R, spec.load, plane=up.material.plane)
    except ValueError as e:
        raise SceneError(f"exact field 'hertz': {e}") from None
    return HertzField(data, spec.xc, up.face.y0)


def exact_reference(scene: Scene):
    """``(field, None)``: the exact field to measure ``scene``'s solutions against, or
    ``(None, why)`` when the scene declares a field that does not solve it (it was declared for
    other values, :attr:`~cvxdual.scene.Scene.exact_mismatch`, or a Hertz contact zone reaches out
    of the candidate contact interval), or ``(None, None)`` when it declares none."""
    why = scene.exact_mismatch
    if scene.exact is None or why is not None:
        return None, why
    field = exact_field(scene)
    if isinstance(field, ContactField):
        # the closed form presses the faces together on [xc - a, xc + a]; where that lies on both
        # bodies, it must be free to touch (a is computed from the loads, which may have changed)
        lo, hi = max(b.x_range[0] for b in scene.bodies), min(b.x_range[1] for b in scene.bodies)
        z0, z1 = max(field.xc - field.half_width, lo), min(field.xc + field.half_width, hi)
        a, b = scene.contact
        tol = 1e-9 * (hi - lo)
        if z0 < z1 and (z0 < a - tol or z1 > b + tol):
            return None, (f"the {field.label} contact zone [{z0:.4g}, {z1:.4g}] reaches out of the candidate "
                          "contact interval "
                          f"[{a:.4g}, {b:.4g}], so the exact field does not solve this problem")
    return field, None
