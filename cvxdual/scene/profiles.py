"""Curves ``y = f(x)``: contact arcs of the bodies and gap profiles.

A closed set of kinds, each a frozen dataclass that knows its value, slope, curvature, exact
integral, inflexion points and guaranteed bounds of its curvature on intervals, all vectorised
over ``x``. Scene files name a kind and give its
numbers; nothing is ever evaluated from a string.

=============  ==========================================================================
kind           curve
=============  ==========================================================================
``flat``       ``y = y0``
``parabola``   ``y = y0 + (x - xc)^2 / (2 R)`` (``R < 0`` opens downward)
``circle``     ``y = yc - sqrt(R^2 - (x - xc)^2)`` (``branch = "lower"``, convex) or
               ``y = yc + sqrt(...)`` (``branch = "upper"``, concave)
``cosine``     ``y = y0 + amplitude * cos(2 pi (x - x0) / wavelength)``
=============  ==========================================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar, Literal, get_args

import numpy as np

from ..errors import SceneError
from ..validate import number

ProfileKind = Literal["flat", "parabola", "circle", "cosine", "punch", "composite"]
Branch = Literal["lower", "upper"]  # of a circle: the convex lower half or the concave upper one

# the values a parameter takes (validate.number's names) and the test of a value
TAKES = {"any": lambda v: True, "nonzero": lambda v: v != 0, "nonnegative": lambda v: v >= 0,
         "positive": lambda v: v > 0}


def parameter(default: float, accepts: str = "any", refusal: str = "") -> Any:
    """A profile's number of the values ``accepts`` names (a key of :data:`TAKES`; it shapes the
    advice of :func:`~cvxdual.validate.number`). With a ``refusal``, a number outside them is
    refused as ``"<kind> profile: <refusal>"``; without one the kind takes any number."""
    return field(default=default, metadata={"accepts": accepts, "refusal": refusal})


@dataclass(frozen=True)
class Profile:
    """Base class; a subclass names its kind in its class statement (``class Flat(Profile,
    kind="flat")``) and defines its parameters (plain ``float`` fields, or :func:`parameter`
    where they take fewer values) and the evaluation methods."""

    kind: ClassVar[ProfileKind]

    def __init_subclass__(cls, kind: ProfileKind | None = None, **kwargs):
        super().__init_subclass__(**kwargs)
        if kind is not None:
            if kind not in get_args(ProfileKind):
                raise TypeError(f"profile kind {kind!r} is not one of {get_args(ProfileKind)}")
            cls.kind = kind

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, number(getattr(self, f.name), f"{self.kind} profile: '{f.name}'",
                                                    f.metadata.get("accepts", "any")))
        for f in fields(self):  # each refused after every number is checked
            if f.metadata.get("refusal") and not TAKES[f.metadata["accepts"]](getattr(self, f.name)):
                raise SceneError(f"{self.kind} profile: {f.metadata['refusal']}")

    def value(self, x):
        raise NotImplementedError

    def slope(self, x):
        raise NotImplementedError

    def curvature(self, x):
        """Second derivative ``f''(x)``."""
        raise NotImplementedError

    def curvature_range(self, x0, x1) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(lo, hi)`` with ``lo <= f''(x) <= hi`` for every ``x`` in ``[x0, x1]``
        (arrays of intervals): guaranteed, from the closed form of ``f''`` (each kind knows where
        its curvature is extreme), not from samples. The certified bounds rest on them. Where
        ``f''`` jumps (a piecewise profile's joints, always mesh columns) an interval ending at
        the jump takes the one-sided value from its own side."""
        raise NotImplementedError

    def antiderivative(self, x):
        """Some ``F`` with ``F' = f`` (exact, used for areas)."""
        raise NotImplementedError

    def integral(self, x0, x1):
        """``int_{x0}^{x1} f dx``, exactly (vectorised)."""
        return self.antiderivative(np.asarray(x1, float)) - self.antiderivative(np.asarray(x0, float))

    def inflexions(self, x0: float, x1: float) -> np.ndarray:
        """Abscissae in ``(x0, x1)`` where the curvature changes sign."""
        return np.empty(0)

    def count_inflexions(self, x0: float, x1: float) -> float:
        """How many :meth:`inflexions` there are at most, without listing them (a hostile
        profile may have billions); the mesh size estimate counts with it."""
        return float(len(self.inflexions(x0, x1)))

    def domain(self) -> tuple[float, float]:
        """Interval of ``x`` on which the curve is defined as a graph."""
        return (-np.inf, np.inf)

    def is_flat(self) -> bool:
        return False

    def scaled(self, length: float) -> Profile:
        """The same curve in units ``length`` times smaller (every parameter is a length)."""
        return replace(self, **{f.name: getattr(self, f.name) * length for f in fields(self)})


@dataclass(frozen=True)
class Flat(Profile, kind="flat"):
    y0: float = 0.0

    def value(self, x):
        return np.full(np.shape(x), self.y0, dtype=float)

    def slope(self, x):
        return np.zeros(np.shape(x))

    def curvature(self, x):
        return np.zeros(np.shape(x))

    def curvature_range(self, x0, x1):
        z = np.zeros(np.broadcast(np.asarray(x0), np.asarray(x1)).shape)
        return z, z.copy()

    def antiderivative(self, x):
        return self.y0 * np.asarray(x, float)

    def is_flat(self) -> bool:
        return True


@dataclass(frozen=True)
class Parabola(Profile, kind="parabola"):
    R: float = parameter(1.0, "nonzero", "R must be non-zero (negative R opens downward)")
    xc: float = 0.0
    y0: float = 0.0

    def value(self, x):
        u = np.asarray(x, float) - self.xc
        return self.y0 + u * u / (2 * self.R)

    def slope(self, x):
        return (np.asarray(x, float) - self.xc) / self.R

    def curvature(self, x):
        return np.full(np.shape(x), 1.0 / self.R)

    def curvature_range(self, x0, x1):
        k = np.full(np.broadcast(np.asarray(x0), np.asarray(x1)).shape, 1.0 / self.R)
        return k, k.copy()

    def antiderivative(self, x):
        u = np.asarray(x, float) - self.xc
        return self.y0 * u + u**3 / (6 * self.R)


@dataclass(frozen=True)
class Circle(Profile, kind="circle"):
    R: float = parameter(1.0, "positive", "radius R must be positive")
    xc: float = 0.0
    yc: float = 1.0
    branch: ClassVar[Branch] = "lower"

    @property
    def _s(self) -> float:
        return -1.0 if self.branch == "lower" else 1.0

    def _root(self, x):
        u = np.asarray(x, float) - self.xc
        return u, np.sqrt(np.maximum(self.R**2 - u * u, 0.0))

    def value(self, x):
        _, w = self._root(x)
        return self.yc + self._s * w

    def slope(self, x):
        u, w = self._root(x)
        return -self._s * u / w

    def curvature(self, x):
        _, w = self._root(x)
        return -self._s * self.R**2 / w**3

    def curvature_range(self, x0, x1):
        # |f''| = R^2 / (R^2 - u^2)^(3/2) grows with |u| = |x - xc|: extreme at the interval's
        # points nearest to and farthest from xc
        u0, u1 = np.asarray(x0, float) - self.xc, np.asarray(x1, float) - self.xc
        near = np.where((u0 <= 0) & (u1 >= 0), 0.0, np.minimum(np.abs(u0), np.abs(u1)))
        far = np.maximum(np.abs(u0), np.abs(u1))
        small, large = (self.R**2 / np.maximum(self.R**2 - u * u, 0.0) ** 1.5 for u in (near, far))
        return (small, large) if self.branch == "lower" else (-large, -small)

    def antiderivative(self, x):
        u, w = self._root(x)
        return self.yc * u + self._s * 0.5 * (u * w + self.R**2 * np.arcsin(np.clip(u / self.R, -1, 1)))

    def domain(self) -> tuple[float, float]:
        return (self.xc - self.R, self.xc + self.R)


@dataclass(frozen=True)
class LowerCircle(Circle):
    """Lower half of a circle: convex (e.g. the bottom of a cylinder)."""

    branch = "lower"


@dataclass(frozen=True)
class UpperCircle(Circle):
    """Upper half of a circle: concave (e.g. the top of a cylinder, or a groove seen from above)."""

    branch = "upper"


@dataclass(frozen=True)
class Cosine(Profile, kind="cosine"):
    amplitude: float = 0.0
    wavelength: float = parameter(1.0, "positive", "wavelength must be positive")
    x0: float = 0.0
    y0: float = 0.0

    @property
    def _k(self) -> float:
        return 2 * np.pi / self.wavelength

    def value(self, x):
        return self.y0 + self.amplitude * np.cos(self._k * (np.asarray(x, float) - self.x0))

    def slope(self, x):
        return -self.amplitude * self._k * np.sin(self._k * (np.asarray(x, float) - self.x0))

    def curvature(self, x):
        return -self.amplitude * self._k**2 * np.cos(self._k * (np.asarray(x, float) - self.x0))

    def curvature_range(self, x0, x1):
        # cos(theta) over [t0, t1]: 1 where the interval holds a multiple of 2 pi, -1 where it
        # holds an odd multiple of pi, else the larger (smaller) end value
        t0, t1 = (self._k * (np.asarray(x, float) - self.x0) for x in (x0, x1))
        c0, c1 = np.cos(t0), np.cos(t1)
        turn = 2 * np.pi
        top = np.where(np.ceil(t0 / turn) <= np.floor(t1 / turn), 1.0, np.maximum(c0, c1))
        bottom = np.where(np.ceil((t0 - np.pi) / turn) <= np.floor((t1 - np.pi) / turn), -1.0, np.minimum(c0, c1))
        a = -self.amplitude * self._k**2  # f'' = a cos(theta)
        return np.minimum(a * top, a * bottom), np.maximum(a * top, a * bottom)

    def antiderivative(self, x):
        x = np.asarray(x, float)
        return self.y0 * x + self.amplitude / self._k * np.sin(self._k * (x - self.x0))

    def count_inflexions(self, x0: float, x1: float) -> float:
        return 0.0 if self.amplitude == 0 else max(0.0, np.floor(2 * (x1 - x0) / self.wavelength) + 1)

    def inflexions(self, x0: float, x1: float) -> np.ndarray:
        if self.amplitude == 0:
            return np.empty(0)
        # cos vanishes at x0 + wavelength (1/4 + m/2)
        q = self.wavelength / 2
        m = np.arange(np.ceil((x0 - self.x0 - q / 2) / q), np.floor((x1 - self.x0 - q / 2) / q) + 1)
        xs = self.x0 + q / 2 + m * q
        return xs[(xs > x0) & (xs < x1)]
