"""The scene model: two bodies, their boundary parts, loads, the gap and the exact field.

A body is the region between its contact *face* ``y = f(x)`` (a :mod:`~cvxdual.scene.profiles`
curve) and a straight *far* side ``y = far``, for ``x`` in ``[x0, x1]``: the upper body
(the paper's ``Omega'``) lies above its face, the lower body (``Omega''``) below. Its four
sides are named ``face``, ``far``, ``left`` (``x = x0``) and ``right`` (``x = x1``). A body
with an *outline* (:mod:`~cvxdual.scene.outline`) keeps its face and replaces the other three
sides by named parts of any shape, holes included; its ``far`` is the outline's extreme height.

Boundary parts (a scene declares only those it has; undeclared boundary is traction free):

- ``clamped``: ``u = 0`` (the paper's ``Gamma_u``);
- ``sliding``: the boundary slides along a line, with no traction along it (``Gamma_0``): by
  default its own line (``u_x = 0`` on ``left``/``right``, ``u_y = 0`` on ``far``, the normal
  component on a straight outline part of any slope); with a ``direction`` the one it names (a
  roller guided that way: the displacement across it is zero, the traction along it zero);
- ``traction``: a prescribed traction ``P`` (``Gamma_tau``): ``uniform`` (a constant vector)
  or ``exact`` (``sigma* . n`` of the scene's exact field).

The candidate contact interval ``[a, b]`` (``Gamma_K``) lies in both bodies' ``x`` ranges;
the initial gap is ``eps(x) = f'(x) - f''(x) + g(x)`` with ``g`` an optional gap profile
(flat faces with ``g(x) = x^2 / (2R)`` are the linearised Hertz geometry).

Contact is frictionless unless the scene has a :class:`Friction`: Tresca friction with slip
threshold ``g`` (a traction) on the whole candidate interval.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field, replace
from typing import Literal, get_args

import numpy as np

from ..errors import SceneError
from ..validate import integer, number, pair, short, text
from .materials import Material
from .outline import Outline, check_outline
from .profiles import Flat, Profile

Side = Literal["face", "far", "left", "right"]  # of a column body
PartKind = Literal["clamped", "sliding", "traction"]
Position = Literal["upper", "lower"]
TractionKind = Literal["uniform", "exact"]
ExactKind = Literal["uniform", "hertz", "punch"]
FrictionKind = Literal["tresca"]

SIDES: tuple[Side, ...] = get_args(Side)
MAX_INFLEXIONS = 1000  # of a face over its body
PART_KINDS: tuple[PartKind, ...] = get_args(PartKind)
POSITIONS: tuple[Position, ...] = get_args(Position)


@dataclass(frozen=True)
class Traction:
    """A prescribed surface traction: ``uniform`` with ``value = (Px, Py)``, or ``exact``."""

    kind: TractionKind = "uniform"
    value: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        if self.kind not in get_args(TractionKind):
            raise SceneError(f"traction kind must be 'uniform' or 'exact', got {short(self.kind)}")
        object.__setattr__(self, "value", pair(self.value, "traction value"))


@dataclass(frozen=True)
class BoundaryPart:
    """A support or load on one side of a body, optionally on a sub-interval of that side
    (an ``x`` interval on ``face``/``far``, a ``y`` interval on ``left``/``right``)."""

    on: Side | str  # a side, or a part of the body's outline
    kind: PartKind
    traction: Traction | None = None
    interval: tuple[float, float] | None = None
    name: str = ""
    direction: tuple[float, float] | None = None  # a sliding support's direction; None: along its line

    def __post_init__(self):
        if not isinstance(self.on, str) or not self.on:
            raise SceneError(f"boundary part {short(self.name)}: 'on' must name a side {SIDES} or an outline part, "
                             f"got {short(self.on)}")
        if self.kind not in PART_KINDS:
            raise SceneError(f"boundary part {short(self.name)}: kind must be one of {PART_KINDS}, "
                             f"got {short(self.kind)}")
        if (self.kind == "traction") != (self.traction is not None):
            raise SceneError(f"boundary part {short(self.name)}: a traction part needs a 'traction' "
                             "(and only traction parts have one)")
        if self.interval is not None:
            lo, hi = pair(self.interval, f"boundary part {short(self.name)} interval")
            if not lo < hi:
                raise SceneError(f"boundary part {short(self.name)}: interval must have lo < hi, "
                                 f"got {short(self.interval)}")
            object.__setattr__(self, "interval", (lo, hi))
        if self.direction is not None:
            if self.kind != "sliding":
                raise SceneError(f"boundary part {short(self.name)}: only a sliding support has a direction; "
                                 "drop direction")
            d = pair(self.direction, f"boundary part {short(self.name)} direction")
            if d == (0.0, 0.0):
                raise SceneError(f"boundary part {short(self.name)}: direction must not be zero; give the "
                                 "direction the boundary slides in, e.g. [1.0, 0.0]")
            object.__setattr__(self, "direction", d)


@dataclass(frozen=True)
class Body:
    """One elastic body. ``layers`` is the number of element layers at mesh level 0 and
    ``focus_depth`` the depth below the face over which the layers are graded finest."""

    name: str
    position: Position
    x_range: tuple[float, float]
    far: float | None  # None only for an outline body: then the outline's extreme height
    face: Profile
    material: Material
    boundary: tuple[BoundaryPart, ...] = ()
    body_force: tuple[float, float] = (0.0, 0.0)
    layers: int = 4
    focus_depth: float | None = None
    outline: Outline | None = None

    def __post_init__(self):
        if self.position not in POSITIONS:
            raise SceneError(f"body {short(self.name)}: position must be 'upper' or 'lower', "
                             f"got {short(self.position)}")
        x0, x1 = pair(self.x_range, f"body {short(self.name)} x range")
        if not x0 < x1:
            raise SceneError(f"body {short(self.name)}: x range must have x0 < x1, got {short(self.x_range)}")
        object.__setattr__(self, "x_range", (x0, x1))
        object.__setattr__(self, "body_force", pair(self.body_force, f"body {short(self.name)} body_force"))
        integer(self.layers, f"body {short(self.name)}: layers", minimum=1)
        if not isinstance(self.face, Profile):
            raise SceneError(f"body {short(self.name)}: face must be a profile (flat, parabola, circle, cosine, "
                             "punch, composite)")
        if not isinstance(self.material, Material):
            raise SceneError(f"body {short(self.name)}: material must be a cvxdual.Material")
        lo, hi = self.face.domain()
        if x0 < lo or x1 > hi:
            raise SceneError(f"body {short(self.name)}: its face ({self.face.kind}) is a graph only on "
                             f"[{lo:g}, {hi:g}], not on the body's x range [{x0:g}, {x1:g}]; "
                             "shrink the body or enlarge the arc")
        if self.outline is not None:
            self._check_outline(x0, x1)
        far = number(self.far, f"body {short(self.name)}: far")
        object.__setattr__(self, "far", far)
        # The far side must not touch the face: sample the face densely (the closed set of
        # profile kinds has at most a few oscillations per wavelength, resolved by 4001 points).
        n_infl = self.face.count_inflexions(x0, x1)
        if n_infl > MAX_INFLEXIONS:
            raise SceneError(f"body {short(self.name)}: its face has {n_infl:.3g} inflexion points on the body, more "
                             f"than {MAX_INFLEXIONS} (each stretch needs its own mesh columns, and the far-side check "
                             "samples the face at 4 points per stretch); lengthen the wavelength")
        xs = np.linspace(x0, x1, 4001)
        fx = self.face.value(xs)
        if not np.all(np.isfinite(fx)):
            raise SceneError(f"body {short(self.name)}: its face is not finite on [{x0:g}, {x1:g}]")
        gap = (far - fx) if self.position == "upper" else (fx - far)
        if gap.min() <= 0:
            raise SceneError(f"body {short(self.name)}: the face crosses the far side y = {far:g}; "
                             f"move the far side {'above' if self.position == 'upper' else 'below'} the face")
        if (self.focus_depth is not None
                and not number(self.focus_depth, f"body {short(self.name)}: focus_depth", "positive") > 0):
            raise SceneError(f"body {short(self.name)}: focus_depth must be positive, got {short(self.focus_depth)}")
        for part in self.boundary:
            if self.outline is not None and part.on != "face":
                self._check_outline_part(part)
            elif part.on not in SIDES:
                raise SceneError(f"body {short(self.name)}: boundary part {part.name!r} is on {short(part.on)}, "
                                 f"which is not a side; a column body has the sides {', '.join(SIDES)}")
            elif part.interval is not None:
                self._check_interval(part, x0, x1, far)
            if part.direction is not None and part.on == "face":
                raise SceneError(f"body {short(self.name)}: sliding support {part.name!r} on the face has a "
                                 "direction; a support on the face slides along it, drop direction")
            if part.kind != "traction" and part.on == "face" and not self.face.is_flat():
                raise SceneError(f"body {short(self.name)}: a {part.kind} support on a curved face is not "
                                 "axis-aligned; put supports on flat sides")

    def _check_outline(self, x0: float, x1: float) -> None:
        """An outline body: the outline closes on the face; ``far`` is the outline's extreme height."""
        if not isinstance(self.outline, Outline):
            raise SceneError(f"body {short(self.name)}: outline must be a cvxdual.scene.outline.Outline")
        check_outline(self.outline, self.face, (x0, x1), self.position, self.name)
        y = self.outline.points()[:, 1]
        far = float(y.max() if self.position == "upper" else y.min())
        if self.far is not None and abs(number(self.far, f"body {short(self.name)}: far") - far) > 1e-9 * np.ptp(y):
            raise SceneError(f"body {short(self.name)}: far = {self.far:g} but its outline reaches y = {far:g}; "
                             "drop far (an outline body's far side is its outline's extreme) or make them agree")
        object.__setattr__(self, "far", far)

    def _check_outline_part(self, part: BoundaryPart) -> None:
        if part.on in SIDES[1:] and part.on not in self.outline.names:
            raise SceneError(f"body {short(self.name)}: boundary part {part.name!r} is on {part.on!r}, but the body "
                             f"has an outline: name one of its parts ({', '.join(self.outline.names)})")
        if part.on not in self.outline.names:
            raise SceneError(f"body {short(self.name)}: boundary part {part.name!r} is on {short(part.on)}, which is "
                             f"not a part of its outline ({', '.join(self.outline.names)}); name one of them")
        if part.interval is not None:
            raise SceneError(f"body {short(self.name)}: boundary part {part.name!r} has an interval on the outline "
                             f"part {part.on!r}; split the part in the outline instead")
        seg = self.outline.part(part.on).segments
        if part.kind == "sliding" and part.direction is None and (len(seg) > 1 or seg[0].is_arc or seg[0].is_spline):
            raise SceneError(f"body {short(self.name)}: sliding support {part.name!r} is on {part.on!r}, which is not "
                             "one straight line; give its direction (e.g. direction = [1.0, 0.0]) or clamp it")

    @property
    def is_column(self) -> bool:
        """True for a column body (face, far side, vertical sides), False for an outline body."""
        return self.outline is None

    def _check_interval(self, part: BoundaryPart, x0: float, x1: float, far: float) -> None:
        """A part's interval must lie on its side: an x interval within the body's x range on
        ``face``/``far``, a y interval between the face and the far side on ``left``/``right``
        (a load off its side would silently act on nothing)."""
        if part.on in ("face", "far"):
            lo, hi, what = x0, x1, "x range"
        else:
            ends = (float(self.face.value(x0 if part.on == "left" else x1)), far)
            lo, hi, what = min(ends), max(ends), f"{part.on} side's y range"
        tol = 1e-9 * (hi - lo)  # rounding of values the user copied from the body's own numbers
        a, b = part.interval
        if a < lo - tol or b > hi + tol:
            raise SceneError(f"body {short(self.name)}: boundary part {part.name!r} has interval [{a:g}, {b:g}] "
                             f"outside its side ({what} [{lo:g}, {hi:g}]); give an interval on the side")

    @property
    def sign(self) -> float:
        """+1 for the upper body (far side above the face), -1 for the lower body."""
        return 1.0 if self.position == "upper" else -1.0

    def height(self, x) -> np.ndarray:
        return np.abs(self.far - self.face.value(x))


@dataclass(frozen=True)
class ExactSpec:
    """The scene's closed-form ``lam*``: ``uniform`` (a constant Voigt stress, both bodies)
    or ``hertz`` (linearised Hertz line contact of radius ``R`` under ``load`` per unit
    length of the full contact, centred at ``xc`` on the face ``y = 0``).

    A field solves the problem it was declared for, not any other: ``declared_for`` records that
    problem (:func:`problem_entries`), filled in by the :class:`Scene` that first holds the spec and
    kept through ``dataclasses.replace`` and ``--set`` overrides, so :attr:`Scene.exact_mismatch`
    can tell when the scene has changed under it. ``any_material`` (``uniform`` only) is the
    declarer's claim that the field solves the scene for any isotropic materials (a patch test)."""

    kind: ExactKind
    stress: tuple[float, float, float] | None = None
    R: float | None = None
    load: float | None = None
    xc: float = 0.0
    b: float | None = None  # punch: the flat's half-width
    any_material: bool = False
    declared_for: tuple | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if not isinstance(self.any_material, bool):
            raise SceneError(f"exact field any_material must be true or false, got {short(self.any_material)}")
        if self.any_material and self.kind != "uniform":
            raise SceneError("exact field any_material is for a 'uniform' field; a 'hertz' field follows the "
                             "materials by itself: drop any_material")
        if self.kind == "uniform":
            if self.stress is None or isinstance(self.stress, str) or len(self.stress) != 3:
                raise SceneError("exact field 'uniform' needs stress = [s11, s22, s12]")
            object.__setattr__(self, "stress", tuple(number(v, "exact field stress") for v in self.stress))
            if not any(self.stress):
                raise SceneError("exact field 'uniform' with zero stress: errors relative to it are undefined; "
                                 "give a nonzero stress or drop the [exact] table")
        elif self.kind in ("hertz", "punch"):
            if self.kind == "punch":
                if self.b is None or number(self.b, "exact field 'punch' b", "nonnegative") < 0:
                    raise SceneError(f"exact field 'punch' needs the flat's half-width b >= 0, got {self.b!r}")
                object.__setattr__(self, "b", float(self.b))
            elif self.b is not None:
                raise SceneError("exact field 'hertz' has no b (a flat's half-width): use kind = 'punch'")
            for name in ("R", "load"):
                v = getattr(self, name)
                if v is None or number(v, f"exact field '{self.kind}' {name}", "positive") <= 0:
                    raise SceneError(f"exact field '{self.kind}' needs a positive finite {name}, got {v!r}")
                object.__setattr__(self, name, float(v))
        else:
            raise SceneError(f"exact field kind must be 'uniform', 'hertz' or 'punch', got {short(self.kind)}")
        object.__setattr__(self, "xc", number(self.xc, "exact field xc"))


@dataclass(frozen=True)
class MeshSpec:
    """Level-0 mesh: ``columns`` element columns across all bodies, graded so that elements
    are ``grading`` times larger far from ``focus`` (an x interval) than inside it."""

    columns: int = 8
    focus: tuple[float, float] | None = None
    grading: float = 1.0
    default_level: int = 3

    def __post_init__(self):
        integer(self.columns, "mesh columns", minimum=1)
        if not number(self.grading, "mesh grading", 1.0) >= 1:
            raise SceneError(f"mesh grading must be a number >= 1 (1 = uniform), got {short(self.grading)}")
        integer(self.default_level, "mesh default_level", minimum=0)
        if self.focus is not None:
            lo, hi = pair(self.focus, "mesh focus")
            if not lo <= hi:
                raise SceneError(f"mesh focus must have lo <= hi, got {short(self.focus)}")
            object.__setattr__(self, "focus", (lo, hi))


@dataclass(frozen=True)
class Friction:
    """Tresca friction on the candidate contact interval: the tangential traction is at most
    ``g`` in magnitude, sticking below it and slipping at it (``g = inf``: full stick).

    ``g`` is a traction (force per unit length of the contact face, per unit thickness), in the
    scene's stress units, acting on every pair of ``[a, b]``, open ones included: Tresca's
    threshold does not depend on the pressure. Coulomb friction (``|t| <= mu p``) makes the
    problem non-convex and is not offered."""

    kind: FrictionKind = "tresca"
    g: float = field(kw_only=True)  # no sensible default: a threshold must be given

    def __post_init__(self):
        if self.kind not in get_args(FrictionKind):
            raise SceneError(f"friction kind must be 'tresca', got {short(self.kind)}; Coulomb friction is not "
                             "convex and is not offered: give kind = \"tresca\" with a slip threshold g")
        g = self.g
        if isinstance(g, bool) or not isinstance(g, numbers.Real) or g != g:  # g != g: NaN
            raise SceneError(f"friction g (the Tresca slip threshold) must be a number >= 0, got {short(g)}; "
                             "give a traction in the scene's stress units, e.g. g = 100.0, or g = inf for full stick")
        if g < 0:
            raise SceneError(f"friction g (the Tresca slip threshold) must be >= 0, got {short(g)}; give its "
                             "magnitude, a traction in the scene's stress units (0 = frictionless, inf = full stick)")
        # inf is full stick; every finite value goes through the one number check (range, magnitude)
        v = math.inf if g == math.inf else number(g, "friction g (the Tresca slip threshold)", "nonnegative")
        object.__setattr__(self, "g", v)


@dataclass(frozen=True)
class Scene:
    """Two bodies in (potential) contact, frictionless or with Tresca friction (``friction``).
    ``bodies[0]`` is the upper body."""

    name: str
    bodies: tuple[Body, Body]
    description: str = ""
    contact: tuple[float, float] | None = None
    gap: Profile | None = None
    exact: ExactSpec | None = None
    mesh: MeshSpec = field(default_factory=MeshSpec)
    units: tuple[str, str] = ("m", "Pa")
    friction: Friction | None = None  # None: frictionless

    def __post_init__(self):
        text(self.name, "scene name")
        text(self.description, "scene description")
        if self.friction is not None and not isinstance(self.friction, Friction):
            raise SceneError(f"scene friction must be a cvxdual.scene.Friction or None, got {short(self.friction)}; "
                             "give Friction(g=...) (Tresca), or None for frictionless contact")
        if len(self.bodies) != 2:
            raise SceneError(f"a scene has exactly two bodies, got {len(self.bodies)}")
        up, lo = self.bodies
        if up.position == lo.position:
            raise SceneError("one body must be 'upper' and the other 'lower'")
        if up.position == "lower":
            object.__setattr__(self, "bodies", (lo, up))
            up, lo = lo, up
        if up.material.plane != lo.material.plane:
            raise SceneError("both bodies must be in the same plane state (strain or stress)")
        ov = (max(up.x_range[0], lo.x_range[0]), min(up.x_range[1], lo.x_range[1]))
        if not ov[0] < ov[1]:
            raise SceneError(f"the bodies' x ranges {up.x_range} and {lo.x_range} do not overlap; "
                             "there is no candidate contact interval")
        a, b = ov if self.contact is None else pair(self.contact, "contact interval")
        if not (ov[0] - 1e-12 * abs(ov[1] - ov[0]) <= a < b <= ov[1] + 1e-12 * abs(ov[1] - ov[0])):
            raise SceneError(f"the contact interval [{a:g}, {b:g}] must lie in both bodies' x ranges "
                             f"(overlap [{ov[0]:g}, {ov[1]:g}])")
        object.__setattr__(self, "contact", (a, b))
        if self.gap is not None:
            lo_, hi_ = self.gap.domain()
            if a < lo_ or b > hi_:  # a circle gap narrower than the interval: clipped values, infinite curvature
                raise SceneError(f"contact.gap ({self.gap.kind}) is a graph only on [{lo_:g}, {hi_:g}], not on the "
                                 f"contact interval [{a:g}, {b:g}]; narrow the interval or enlarge the arc")
        eps = self.gap_at(np.linspace(a, b, 2001))
        if not np.all(np.isfinite(eps)):
            raise SceneError("the initial gap is not finite on the contact interval")
        for body in self.bodies:
            for part in body.boundary:
                if part.on == "face" and part.kind != "traction":
                    lo_, hi_ = part.interval or body.x_range
                    if lo_ < b and hi_ > a:
                        raise SceneError(f"body {body.name!r}: support {part.name!r} overlaps the contact "
                                         f"interval [{a:g}, {b:g}]; a contact face cannot be supported")
        if self.exact is not None and self.exact.kind in ("hertz", "punch"):
            k = self.exact.kind
            if not (up.face.is_flat() and lo.face.is_flat()):
                raise SceneError(f"the '{k}' exact field is for the linearised geometry: both faces flat")
            if self.gap is not None:
                raise SceneError(f"with exact = '{k}' the gap follows from exact.R (and b); "
                                 "do not declare a separate gap")
            for body in self.bodies:
                if body.material.E is None:
                    raise SceneError(f"the '{k}' exact field needs isotropic materials (E, nu)")
        if self.exact is not None and self.exact.declared_for is None:  # declared for this scene
            object.__setattr__(self, "exact", replace(self.exact, declared_for=problem_entries(self)))

    @property
    def upper(self) -> Body:
        return self.bodies[0]

    @property
    def lower(self) -> Body:
        return self.bodies[1]

    @property
    def gap_profile(self) -> Profile:
        """The profile ``g`` added to ``f' - f''`` (from ``exact.R`` for a Hertz scene)."""
        if self.exact is not None and self.exact.kind == "hertz":
            from .profiles import Parabola
            return Parabola(R=self.exact.R, xc=self.exact.xc)
        if self.exact is not None and self.exact.kind == "punch":
            from .piecewise import Punch
            return Punch(b=self.exact.b, R=self.exact.R, xc=self.exact.xc)
        return self.gap if self.gap is not None else Flat(0.0)

    def gap_at(self, x) -> np.ndarray:
        """Initial gap ``eps(x) = f'(x) - f''(x) + g(x)``."""
        x = np.asarray(x, float)
        return self.upper.face.value(x) - self.lower.face.value(x) + self.gap_profile.value(x)

    @property
    def exact_mismatch(self) -> str | None:
        """Why the scene's exact field does not solve this scene, or ``None`` (it does, or there is
        none): the entries of :func:`problem_entries` that differ from those the field was declared
        for, except those the field follows by itself (:func:`follows_exact`)."""
        ex = self.exact
        if ex is None:
            return None
        was = dict(ex.declared_for)
        if WHY in was:
            return was[WHY]
        now = dict(problem_entries(self))
        skip = follows_exact(self)
        changed = [k for k in dict.fromkeys([*was, *now])
                   if k not in skip and was.get(k, _ABSENT) != now.get(k, _ABSENT)]
        if not changed:
            return None
        names = ", ".join(changed[:4]) + (f" and {len(changed) - 4} more" if len(changed) > 4 else "")
        return (f"the exact field ({ex.kind}) was declared for the scene before these changed: {names}; it does "
                "not solve this problem")

    @property
    def x_extent(self) -> tuple[float, float]:
        return (min(b.x_range[0] for b in self.bodies), max(b.x_range[1] for b in self.bodies))

    @property
    def length_scale(self) -> float:
        """A representative length (largest body dimension), used for scaling and tolerances."""
        x0, x1 = self.x_extent
        heights = [float(np.max(b.height(np.linspace(*b.x_range, 101)))) for b in self.bodies]
        return max(x1 - x0, *heights)


WHY = "why"  # a declared_for holding only the reason the field does not apply (see convert_units)
_ABSENT = object()


def problem_entries(scene: Scene) -> tuple[tuple[str, object], ...]:
    """The continuous problem of ``scene`` entry by entry, named as in a scene file: geometry,
    materials, supports and loads, the contact interval, gap and friction, and the exact field's
    own parameters. What only shapes the mesh (``mesh.*``, ``layers``, ``focus_depth``), names,
    descriptions and unit labels are not part of it: they never change what the field solves."""
    items: list[tuple[str, object]] = [("plane", scene.upper.material.plane)]
    for b in scene.bodies:
        w = f"bodies.{b.name}"
        items += [(f"{w}.position", b.position), (f"{w}.x", b.x_range), (f"{w}.far", b.far), (f"{w}.face", b.face),
                  (f"{w}.material", b.material.C), (f"{w}.body_force", b.body_force), (f"{w}.outline", b.outline)]
        items += [(f"{w}.boundary.{p.name or i}", (p.on, p.kind, p.traction, p.interval, p.direction))
                  for i, p in enumerate(b.boundary)]
    items += [("contact.interval", scene.contact), ("contact.gap", scene.gap), ("contact.friction", scene.friction)]
    ex = scene.exact
    if ex is not None:
        items += [("exact.kind", ex.kind), ("exact.stress", ex.stress), ("exact.R", ex.R), ("exact.load", ex.load),
                  ("exact.xc", ex.xc), ("exact.any_material", ex.any_material), ("exact.b", ex.b)]
    return tuple(items)


def follows_exact(scene: Scene) -> set[str]:
    """The entries of :func:`problem_entries` that the exact field of ``scene`` follows, so that
    changing them keeps it the solution. A ``hertz`` field is computed from ``R``, ``load`` and the
    materials (and its gap from ``R``): it follows them when every load of the scene is its own
    traction (``kind = "exact"``, no body force), else a fixed load would no longer match it. A
    ``uniform`` field declared with ``any_material`` follows isotropic materials."""
    ex = scene.exact
    materials = {f"bodies.{b.name}.material" for b in scene.bodies}
    isotropic = all(b.material.E is not None for b in scene.bodies)
    if ex is None or not isotropic:
        return set()
    if ex.kind in ("hertz", "punch"):
        own_loads = all(p.traction.kind == "exact" for b in scene.bodies for p in b.boundary if p.kind == "traction")
        if own_loads and not any(any(b.body_force) for b in scene.bodies):
            return {"exact.R", "exact.load", "exact.b", "plane", *materials}
        return set()
    return materials if ex.any_material else set()


def convert_units(scene: Scene, length: float, stress: float, units: tuple[str, str]) -> Scene:
    """The same scene in other units: lengths multiplied by ``length``, stresses by ``stress``
    (forces per unit thickness by ``length * stress``, body forces by ``stress / length``; the
    Tresca threshold is a traction, so by ``stress``)."""
    from .materials import Material

    def prof(p: Profile | None):
        return None if p is None else p.scaled(length)

    def mat(m: Material) -> Material:
        return Material(C=tuple(tuple(v * stress for v in row) for row in m.C),
                        E=None if m.E is None else m.E * stress, nu=m.nu, plane=m.plane,
                        description=m.description)

    def ival(iv):
        return None if iv is None else (iv[0] * length, iv[1] * length)

    def part(p: BoundaryPart) -> BoundaryPart:
        tr = p.traction
        if tr is not None and tr.kind == "uniform":
            tr = replace(tr, value=(tr.value[0] * stress, tr.value[1] * stress))
        return replace(p, traction=tr, interval=ival(p.interval))

    bodies = tuple(replace(b, x_range=ival(b.x_range), far=b.far * length, face=prof(b.face),
                           material=mat(b.material), boundary=tuple(part(p) for p in b.boundary),
                           body_force=(b.body_force[0] * stress / length, b.body_force[1] * stress / length),
                           focus_depth=None if b.focus_depth is None else b.focus_depth * length,
                           outline=None if b.outline is None else b.outline.scaled(length))
                   for b in scene.bodies)
    ex = scene.exact
    if ex is not None:
        # the converted field solves the converted scene if and only if the field solved the scene
        why = scene.exact_mismatch
        ex = replace(ex, stress=None if ex.stress is None else tuple(v * stress for v in ex.stress),
                     R=None if ex.R is None else ex.R * length,
                     load=None if ex.load is None else ex.load * length * stress, xc=ex.xc * length,
                     b=None if ex.b is None else ex.b * length,
                     declared_for=None if why is None else ((WHY, why),))
    fr = scene.friction
    if fr is not None:
        fr = replace(fr, g=fr.g * stress)  # inf stays inf: full stick in any units
    return replace(scene, bodies=bodies, contact=ival(scene.contact), gap=prof(scene.gap), exact=ex,
                   mesh=replace(scene.mesh, focus=ival(scene.mesh.focus)), units=tuple(units), friction=fr)
