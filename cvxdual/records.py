"""Typed records of the results that cross the package's layers: what the stress spaces
(:mod:`cvxdual.p0`, :mod:`cvxdual.eq`) hand to :class:`~cvxdual.solution.Solution`, the outputs
and the studies. Each is a frozen dataclass that reads as a mapping over its fields too, in the
style of :class:`~cvxdual.solution.SolverStats`: ``rec["key"]``, ``dict(rec)``, ``rec.keys()``
and ``"key" in rec`` work as on the dicts they replace, in the same key order (``summary.json``
depends on it). This module imports nothing of the package: every layer may use it, and neither
space imports the other for a shared type.

Units are the scene's: lengths ``L``, stresses ``S``; forces per unit thickness ``S*L``,
energies ``S*L^2``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np


# eq=False: equality and hashing are the Mapping's (as a dict's), not a tuple of array fields,
# which cannot be compared or hashed; kw_only: optional fields sit where the key order needs them;
# repr=False on every record: the generated repr would print whole arrays over Record.__repr__
@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class Record(Mapping):
    """A frozen record that reads as a mapping over its fields, in field order. Fields named in
    ``OPTIONAL`` apply to some producers only: while ``None`` they are left out of the mapping
    (as in :class:`~cvxdual.solution.SolverStats`); every other field is always a key, even when
    its value is ``None`` (a result that says "none", like ``Contact.x_min`` without contact).
    ``KEY_OF`` names the mapping key of a field that cannot bear it (``keys``, ``items``,
    ``values`` and ``get`` are the mapping's methods)."""

    OPTIONAL: ClassVar[frozenset[str]] = frozenset()
    KEY_OF: ClassVar[dict[str, str]] = {}  # field -> its key in the mapping, where they differ

    def _present(self) -> list[str]:
        return [f.name for f in dataclasses.fields(self)
                if f.name not in self.OPTIONAL or getattr(self, f.name) is not None]

    def __getitem__(self, key: str):
        for name in self._present():
            if self.KEY_OF.get(name, name) == key:
                return getattr(self, name)
        raise KeyError(key)

    def __iter__(self):
        return iter([self.KEY_OF.get(name, name) for name in self._present()])

    def __len__(self) -> int:
        return len(self._present())

    def replace(self, **changes):
        """A copy with ``changes`` (records are never changed in place)."""
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """The mapping as plain dicts, nested records included (for JSON and pickles of plain data)."""
        return {k: v.as_dict() if isinstance(v, Record) else v for k, v in self.items()}

    def __repr__(self) -> str:  # the keys present; arrays by their shape (they run to megabytes)
        shown = (f"{k}=<array {v.shape}>" if isinstance(v, np.ndarray) else f"{k}={v!r}" for k, v in self.items())
        return f"{type(self).__name__}({', '.join(shown)})"


# -- sizes -------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class MeshSize(Record):
    """A mesh's size counted before it is built (:func:`cvxdual.geometry.mesh.mesh_size`):
    ``triangles`` and ``nodes`` (estimates: floats)."""

    triangles: float
    nodes: float


# -- contact -------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class Contact(Record):
    """The contact state at the pairs (:attr:`Solution.contact`), from either stress space
    (:func:`cvxdual.p0.checks.contact_quantities`, :func:`cvxdual.eq.contact.edge_contact`).
    Arrays are ``(n_pairs,)`` ordered by ``x``: ``x`` [L], initial ``gap`` [L],
    ``relative_displacement`` (the faces' normal approach ``u''_y - u'_y``) [L], nodal ``force``
    [S*L], ``pressure`` (force over tributary length) [S], ``active`` (bool),
    ``tangential_force`` (x force of the upper body on the lower) [S*L], ``slip``
    (``u''_x - u'_x``) [L], ``stick`` (bool). ``edge_pressure`` (eq only) is the linear pressure
    at both ends of each contact edge ``(n_c, 2)`` [S]; ``reaction`` (p0 only) the y force on
    the upper body ``(n_pairs,)`` [S*L]. Scalars: ``n_active``; ``x_min``, ``x_max`` of the
    active pairs [L] (``None``, and still keys, without an active pair); ``max_pressure`` [S];
    ``total_force`` [S*L]."""

    OPTIONAL: ClassVar[frozenset[str]] = frozenset({"edge_pressure", "reaction"})

    x: np.ndarray
    gap: np.ndarray
    relative_displacement: np.ndarray
    force: np.ndarray
    pressure: np.ndarray
    active: np.ndarray
    edge_pressure: np.ndarray | None = None
    tangential_force: np.ndarray
    slip: np.ndarray
    stick: np.ndarray
    reaction: np.ndarray | None = None
    n_active: int
    x_min: float | None
    x_max: float | None
    max_pressure: float
    total_force: float


# -- errors against an exact field ---------------------------------------------------------

@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class ErrorNorms(Record):
    """Errors of P0 stresses against an exact field (:func:`cvxdual.p0.norms.stress_error`):
    ``l2 = ||t - lam*||_0`` [S*L], ``l2_rel`` (over ``||lam*||_0``; NaN for a zero field),
    ``energy = ||t - lam*||_A`` [sqrt(S)*L], ``energy_rel`` (over ``||lam*||_A``), ``rule``
    (quadrature points per direction)."""

    l2: float
    l2_rel: float
    energy: float
    energy_rel: float
    rule: int


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class ExactErrors(Record):
    """Errors of equilibrium stresses and a displacement against an exact field
    (:func:`cvxdual.eq.bounds.exact_errors`): ``l2 = ||sigma - lam*||_0`` [S*L], ``l2_rel``,
    ``stress_A = ||sigma - lam*||_A``, ``displacement_a = ||lam* - C e(v)||_A = ||u - v||_a``,
    ``combined`` (their root sum of squares, which the bound ``sqrt(2 G)`` dominates),
    ``reference_A = ||lam*||_A`` (energy norms in sqrt(S)*L), ``l2_rel_displacement`` (of
    ``C e(v)``, over ``||lam*||_0``) and ``rule`` (points per direction per sub-triangle). Not
    :class:`ErrorNorms`: the energy error is split into its stress and displacement parts."""

    l2: float
    l2_rel: float
    stress_A: float  # noqa: N815 - the norm's name (||.||_A), the key readers use
    displacement_a: float
    combined: float
    reference_A: float  # noqa: N815 - as stress_A
    l2_rel_displacement: float
    rule: int


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class CertifiedErrors(Record):
    """An equilibrium solution's ``error`` (:func:`cvxdual.eq.run.error_summary`): the stress's
    ``l2``, ``l2_rel``, ``energy`` (``stress_A`` of :class:`ExactErrors`) and ``energy_rel``, the
    ``combined`` error the certificate bounds, the ``displacement_energy`` (``||u - v||_a``), the
    ``rule`` and the ``effectivity`` of the bound (``sqrt(2 G)`` over ``combined``; ``None``, and
    still a key, where the error is zero)."""

    l2: float
    l2_rel: float
    energy: float
    energy_rel: float
    combined: float
    displacement_energy: float
    rule: int
    effectivity: float | None


# -- distances between fields and the checks of a solution ---------------------------------

@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class CommonPart(Record):
    """What an integral over the common part of two meshes of one scene leaves out
    (:func:`cvxdual.geometry.locate.common_part`): ``dropped_area`` [L^2], its ``dropped_share``
    of the first mesh's area, and ``dropped_bound``, the most two meshes of one scene differ by."""

    dropped_area: float
    dropped_share: float
    dropped_bound: float


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class FieldDistance(Record):
    """``||a - b||`` of two stress fields of one scene on different meshes
    (:func:`cvxdual.system.field.field_distance`, :func:`cvxdual.system.field.piece_distance`):
    ``l2`` [S*L] and ``energy`` [sqrt(S)*L] with ``l2_rel``, ``energy_rel`` against ``a``;
    ``rule`` (points per direction, where one rule was used throughout) and the
    :class:`CommonPart` measures."""

    OPTIONAL: ClassVar[frozenset[str]] = frozenset({"rule"})

    l2: float
    l2_rel: float
    energy: float
    energy_rel: float
    rule: int | None = None
    dropped_area: float
    dropped_share: float
    dropped_bound: float


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class Checks(Record):
    """The checks of a solution where not all of its space's tolerances apply
    (:attr:`Solution.checks`): ``applied`` ``{name: residual}`` and ``skipped`` ``{name: reason}``
    (maps by name: the names are the residuals' and the checks', an open set)."""

    applied: dict
    skipped: dict


# -- certified bounds ----------------------------------------------------------------------

@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class BoundContributions(Record):
    """Where the gap ``G`` of :class:`Bounds` comes from [S*L^2]: ``element`` per macro triangle
    ``(n_T,)``, ``sub`` per sub-triangle ``(n_T, 3)``, ``column`` per slab of the curved pieces
    ``(n_slabs,)``, ``contact`` per contact edge ``(n_c,)``, ``continuation`` per piece beyond
    the free arcs' polygons (empty without them)."""

    element: np.ndarray
    sub: np.ndarray
    column: np.ndarray
    contact: np.ndarray
    continuation: np.ndarray


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class DisplacementFix(Record):
    """How the bounds' displacement was made pointwise admissible
    (:func:`cvxdual.eq.bounds.admissible_displacement`): ``max_shift`` [L], ``n_shifted`` (edges),
    ``min_slack_before`` and ``min_slack`` (least guaranteed ``eps - [v]``) [L], ``exact_min``
    (that minimum is rigorous), ``support_violation`` [L], ``displacement_scale`` (``max |v|``)
    [L]. All ``None``, an empty mapping, where the displacement was taken as given."""

    OPTIONAL: ClassVar[frozenset[str]] = frozenset({"max_shift", "n_shifted", "min_slack_before", "min_slack",
                                                    "exact_min", "support_violation", "displacement_scale"})

    max_shift: float | None = None
    n_shifted: int | None = None
    min_slack_before: float | None = None
    min_slack: float | None = None
    exact_min: bool | None = None
    support_violation: float | None = None
    displacement_scale: float | None = None


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class Bounds(Record):
    """Two-sided energy bounds of an equilibrium stress field and an admissible displacement
    (:func:`cvxdual.eq.bounds.certified_bounds`, docs/equilibrium.md), energies in S*L^2:
    ``energy_upper = J(v)``, ``energy_lower = -L(u0) - S(sigma)``, ``gap`` (``G``, the sum of
    its non-negative terms), ``gap_identity`` (``J(v) + L(u0) + S(sigma)``), ``error_bound =
    sqrt(2 G)``, ``complementary_energy``, ``contributions`` (:class:`BoundContributions`),
    ``data_oscillation``, ``residuals`` (relative violation per constraint block),
    ``displacement`` ``v`` [L] (P1: nodal values ``(n_nodes, 2)``; P2: a
    :class:`~cvxdual.system.p2_displacement.P2Displacement`), ``displacement_fix`` (:class:`DisplacementFix`),
    ``guaranteed`` and the ``reasons`` when not, the ``kinematic`` side of ``v`` (``"p1"``, ``"p2"``) and
    ``error_bound_rel``, ``sqrt(2 G)`` over the stress's energy norm ``sqrt(2 S_A(sigma))`` (it bounds the
    relative energy error of the stress and of the displacement)."""

    energy_upper: float
    energy_lower: float
    gap: float
    gap_identity: float
    error_bound: float
    complementary_energy: float
    contributions: BoundContributions
    data_oscillation: float
    # a plain dict: a per-name map whose names are the constraint blocks checked (those of
    # eq.bounds.constraint_blocks or edge_constraints), an open set read by iterating it
    residuals: dict
    displacement: object
    displacement_fix: DisplacementFix
    guaranteed: bool
    reasons: tuple[str, ...]
    kinematic: str = "p1"
    error_bound_rel: float | None = None


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class Cycle(Record):
    """One cycle of a run to a certified tolerance (:mod:`cvxdual.adapt`): its mesh (``pieces``,
    ``triangles``, ``columns``), its certificate (``energy_lower``, ``energy_upper``, ``bound_rel``,
    ``sqrt(2 G)`` relative to the stress's energy norm, ``guaranteed``), the share of ``G`` the
    marking chose for refinement (``None`` on the last cycle), how each body's part beyond the strip
    was meshed (``meshed``: ``"gmsh"``, ``"in_place"``, ``None`` for a column body), and seconds: the
    cycle's own and since the run's start."""

    cycle: int
    pieces: int
    triangles: int
    columns: int
    energy_lower: float
    energy_upper: float
    bound_rel: float
    guaranteed: bool
    marked_share: float | None
    meshed: tuple
    seconds: float
    elapsed: float


@dataclass(frozen=True, eq=False, kw_only=True, repr=False)
class AdaptiveHistory(Record):
    """A run to a certified tolerance: the ``tol`` asked, the Dorfler fraction ``theta``, whether the
    tolerance was ``met``, why the run stopped (``stop``: ``"tolerance"``, ``"max_pieces"``,
    ``"time_limit"``, ``"memory"``, ``"no_refinement"``), the cycle the solution is (``chosen``: the
    last where the tolerance was met, else the best) and every cycle (:class:`Cycle`)."""

    tol: float
    theta: float
    met: bool
    stop: str  # a cvxdual.kinds.Stop (a str: records import nothing of the package)
    chosen: int
    cycles: tuple

    @property
    def state(self) -> str:
        """``"met"``, or ``"not met, stopped: ..."`` with the reason in words."""
        return "met" if self.met else f"not met, stopped: {self.stop.replace('_', ' ')}"

    def as_dict(self) -> dict:
        return {**{k: v for k, v in self.items() if k != "cycles"}, "cycles": [c.as_dict() for c in self.cycles]}
