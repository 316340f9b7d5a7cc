"""The :class:`Solution` of a scene, what its solver reports (:class:`SolverStats`), and the
tolerances every returned solution meets (docs/theory.md#recovery-and-checks).

The checks themselves belong to each stress space: :mod:`cvxdual.p0.checks` (equilibrium and
sign of the contact forces, ``t_P = C_P B_P u_h``, complementarity, the duality gap) and
:mod:`cvxdual.eq.bounds` (exact admissibility). A result that fails the promised tolerances
raises :class:`~cvxdual.errors.AccuracyError` (:func:`check_solution`); it is never returned.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import AccuracyError
from .kinds import Space
from .records import Checks

if TYPE_CHECKING:  # annotations only: a solution holds the objects of the layers that built it
    from .scene import Scene
    from .system.assembly import System
    from .system.field import StressField

# What every returned solution satisfies (relative measures, defined in Solution.residuals).
# Clarabel's default tolerances (1e-8 on gaps and feasibility) leave these with a margin of
# about 100 on the built-in scenes; first-order solvers may fail them and are then rejected.
TOLERANCES = {"equilibrium": 1e-6, "constitutive": 1e-4, "complementarity": 1e-5, "penetration": 1e-6,
              "duality_gap": 1e-6}

# equilibrium stresses (stress space "eq") are exactly admissible: every constraint to rounding
# relative to the stress scale (the exactness post-step brings them to ~1e-14)
EQ_TOLERANCES = {"admissibility": 1e-9, "penetration": 1e-12}
SPACE_TOLERANCES = {Space.P0: TOLERANCES, Space.EQ: EQ_TOLERANCES}
BOUND_KEYS = ("energy_upper", "energy_lower", "gap", "error_bound", "error_bound_rel", "kinematic", "guaranteed",
              "reasons", "data_oscillation")

# contact.csv and Solution.contact_table(), one row per pair: tangential_force is the x force of
# the upper body on the lower one (0 without friction); slip the relative tangential
# displacement u''_x - u'_x; stick 1 where an active pair sticks
CONTACT_COLUMNS = ("x", "gap", "relative_displacement", "pressure", "active", "force", "tangential_force", "slip",
                   "stick")
FLAG_COLUMNS = ("active", "stick")  # booleans, written as 0/1

ACTIVE_TOL = 1e-6  # an active pair's force exceeds this fraction of the largest (and its opening)
FORCE_FLOOR = 1e-3  # contact forces below this fraction of the total load are "no contact"


@dataclass(frozen=True)
class SolverStats(Mapping):
    """What the solver of a solution reports (:attr:`Solution.solver`), one type for every path.
    Fields that do not apply to the path are ``None``; it reads as a mapping of the others too
    (``sol.solver["iterations"]``, ``dict(sol.solver)``). Times in seconds."""

    solver: str  # a CVXPY solver name, "fast", or "none (...)" where nothing had to be solved
    status: str  # "optimal" on every returned solution
    iterations: int | None = None
    solve_time: float | None = None  # wall time of the solve (fast path: its warm start included)
    fallback: str | None = None  # why another solver solved instead, if one did
    # -- the CVXPY path (cvxdual.convex.solvers.solve_problem) --
    compile_time: float | None = None  # CVXPY's canonicalisation, inside the solve call
    solver_time: float | None = None  # the solver's own clock
    setup_time: float | None = None  # the solver's set-up (CVXPY), the local blocks (eq fast path)
    # -- the fast paths (cvxdual.activeset) --
    backend: str | None = None  # factorisation backend of the last factorisation
    factorizations: int | None = None
    factor_time: float | None = None
    schur_updates: int | None = None
    max_update: int | None = None
    refinements: int | None = None
    warm_start: str | None = None  # where the initial active set came from
    warm_start_time: float | None = None
    active: np.ndarray | None = None  # the final active set (pairs; eq: contact parameters (n_c, 2))
    # -- the equilibrium space (cvxdual.eq) --
    corrections: int | None = None  # correction solves of the fast path's equilibrium residual
    post_time: float | None = None  # the exactness step
    contact_change: float | None = None  # its largest relative change of a contact traction
    projection_iterations: int | None = None
    max_change: float | None = None  # its largest change of any parameter, relative to the stress scale
    n_variables: int | None = None
    n_equalities: int | None = None
    n_inequalities: int | None = None
    objective: float | None = None  # the model's objective at the exact field
    multipliers: dict | None = None  # nondimensional: "opening" (n_c, 2) (eq fast path)
    pinned: np.ndarray | None = None  # multipliers pinned against floating motions
    n_mu: int | None = None  # size of the condensed system
    nnz: int | None = None

    def _present(self) -> list[str]:
        return [f.name for f in dataclasses.fields(self) if getattr(self, f.name) is not None]

    def __getitem__(self, key: str):
        if key in self._present():
            return getattr(self, key)
        raise KeyError(key)

    def __iter__(self):
        return iter(self._present())

    def __len__(self) -> int:
        return len(self._present())

    def replace(self, **changes) -> SolverStats:
        return dataclasses.replace(self, **changes)

    def __repr__(self) -> str:  # the fields that apply; arrays by their shape
        shown = (f"{k}=<array {v.shape}>" if isinstance(v, np.ndarray) else f"{k}={v!r}" for k, v in self.items())
        return f"SolverStats({', '.join(shown)})"


def load_scale(system: System) -> float:
    """``F_ref = sum |f|``: the size of the applied loads (or of the stress scale if unloaded)."""
    return float(np.abs(system.f).sum()) or system.scales.stress * system.scales.length


@dataclass(frozen=True)
class Solution:
    """A solved scene, built complete by :func:`cvxdual.solve` and never changed afterwards.
    ``field`` is the stress field (:class:`~cvxdual.system.field.StressField`: evaluate it
    ``at`` points, integrate it by its ``rule``, whichever space made it); ``stress`` its values,
    ``(n_pieces, 3)`` (stress space ``p0``) or the Voigt values at the vertices of every
    sub-triangle ``(n_sub, 3, 3)`` (``eq``, with ``column_stress`` on the curved pieces).
    ``displacement`` ``(n_nodes, 2)`` (for ``eq`` the P1 displacement of the bounds, pointwise
    admissible), contact arrays ``(n_pairs,)`` ordered by ``x``; ``timings`` in seconds per phase."""

    scene: Scene
    triangulation: str
    level: int
    system: System
    field: StressField
    displacement: np.ndarray
    solver: SolverStats
    timings: dict
    objective: float
    duality_gap: float
    residuals: dict
    contact: dict
    exact: dict | None
    error: dict | None
    bounds: dict | None = None  # certified bounds (docs/equilibrium.md), where computed
    # the checks applied ({name: residual}) and skipped ({name: reason}); None: all of tolerances()
    checks: dict | None = None
    space: object | None = None  # the EquilibriumSpace of an "eq" solution or of the bounds
    adaptive: object | None = None  # a run to a tolerance: its AdaptiveHistory (cvxdual.adapt)

    @property
    def mesh_name(self) -> str:
        """The mesh in words: its level, or the cycle of a run to a tolerance."""
        return f"level {self.level}" if self.adaptive is None else f"adaptive, cycle {self.adaptive.chosen}"

    @property
    def stress_space(self) -> Space:
        """The space of the stress field."""
        return self.field.space_name

    @property
    def stress(self) -> np.ndarray:
        """The stress field's values (see the class docstring)."""
        return self.field.stress

    @property
    def column_stress(self) -> np.ndarray | None:
        """An ``eq`` solution's column stresses on the curved pieces: the vertical stress ``g`` at
        both ends of every column ``(n_col, 2)`` (:mod:`cvxdual.eq.columns`); empty on flat faces,
        None for ``p0``."""
        return self.field.column

    def __repr__(self) -> str:
        """A few lines, not the arrays (those ran to 100 kB): what was solved, how, and the main
        results. Never raises: a solution built by hand may lack any of them."""
        def get(fn, default="?"):
            try:
                return fn()
            except Exception:  # noqa: BLE001 - a repr shows what it can
                return default

        L, S = get(lambda: tuple(self.scene.units), ("L", "S"))
        n = get(lambda: self.field.n_pieces)
        c = self.contact if isinstance(self.contact, Mapping) else {}
        force = get(lambda: f"{float(c['total_force']):.4g} {S}*{L}")
        lines = [f"Solution({get(lambda: self.scene.name)!r}, stress space {self.stress_space}, "
                 f"{self.triangulation}, level {self.level}, {n} pieces",
                 f"  solver {get(lambda: self.solver.solver)}: {get(lambda: self.solver.status)}; "
                 f"objective {get(lambda: format(float(self.objective), '.6g'))}; contact force {force}, "
                 f"{get(lambda: c['n_active'])} active pairs"]
        if self.bounds is not None:
            b = self.bounds
            lo, hi, gap = (get(lambda k=k, f=f: format(float(b[k]), f)) for k, f in
                           (("energy_lower", ".6g"), ("energy_upper", ".6g"), ("gap", ".3g")))
            lines.append(f"  bounds: {lo} <= J(u) <= {hi}, G = {gap} {S}*{L}^2")
        return "\n".join(lines) + ")"

    @property
    def mesh(self):
        return self.system.mesh

    @property
    def pieces(self):
        return self.system.pieces

    def contact_columns(self) -> dict:
        """The contact arrays of :data:`CONTACT_COLUMNS` by name, flags as integers. A missing
        column is an error, never filled in: a made-up 0 would read as a computed result."""
        c = self.contact
        missing = [k for k in CONTACT_COLUMNS if k not in c]
        if missing:
            raise KeyError(f"the solution's contact data lacks {', '.join(missing)} (columns of contact.csv)")
        return {k: np.asarray(c[k]).astype(int) if k in FLAG_COLUMNS else np.asarray(c[k]) for k in CONTACT_COLUMNS}

    def contact_table(self):
        """The contact pairs as a pandas DataFrame, one row per pair ordered by ``x``, with the
        columns of ``contact.csv`` (:data:`CONTACT_COLUMNS`, in the scene's units): ``x``, ``gap``
        (initial gap), ``relative_displacement`` (the faces' normal approach, which closes the gap:
        ``gap - relative_displacement >= 0``), ``pressure``
        (nodal force over tributary length), ``active`` (0/1), ``force`` (nodal contact force),
        ``tangential_force``, ``slip``, ``stick``."""
        import pandas as pd
        return pd.DataFrame(self.contact_columns())

    def summary(self) -> dict:
        """The ``summary.json`` contract (README, "Outputs")."""
        s = self.system
        c = self.contact
        load_imbalance, load_correction = self.field.balance
        return {
            "scene": self.scene.name,
            "triangulation": self.triangulation,
            "stress_space": self.stress_space,
            "level": self.level,
            "units": {"length": self.scene.units[0], "stress": self.scene.units[1]},
            "friction": None if self.scene.friction is None else  # JSON has no inf: full stick as "inf"
            {"kind": self.scene.friction.kind, "g": self.scene.friction.g if np.isfinite(self.scene.friction.g)
             else "inf"},
            "n_pieces": self.field.n_pieces,
            "piece_kinds": self.field.piece_kinds(),
            "n_stress_unknowns": self.field.n_unknowns,
            "n_dofs": s.n_dofs,
            "n_free_dofs": s.n_r,
            "n_contact_pairs": len(s.jb),
            "h": s.mesh.h,
            "h_min": s.mesh.h_min,
            "solver": self.solver.solver,
            "fallback": self.solver.fallback,
            "status": self.solver.status,
            "iterations": self.solver.iterations,
            "objective": self.objective,
            "duality_gap": self.duality_gap,
            "load_imbalance": load_imbalance,
            "load_correction": load_correction,
            "residuals": dict(self.residuals),
            "contact": {k: c[k] for k in ("n_active", "x_min", "x_max", "max_pressure", "total_force")},
            "exact": self.exact,
            "error": self.error,
            "bounds": None if self.bounds is None else {k: self.bounds[k] for k in BOUND_KEYS},
            "checks_skipped": {} if self.checks is None else dict(self.checks["skipped"]),
            "timings": dict(self.timings),
            **({} if self.adaptive is None else {"adaptive": self.adaptive.as_dict()}),
        }


def tolerances(sol: Solution) -> dict:
    """The residual tolerances ``sol`` promises (its stress space's)."""
    return SPACE_TOLERANCES[sol.stress_space]


def failed_checks(applied: dict, tol: dict) -> str:
    """The residuals of ``applied`` above their tolerance in ``tol`` (NaN fails too), as text
    for a message; empty if none."""
    return ", ".join(f"{k} {v:.2e} > {tol[k]:.0e}" for k, v in applied.items() if k in tol and not v <= tol[k])


def check_solution(sol: Solution) -> None:
    txt = failed_checks(sol.residuals if sol.checks is None else sol.checks["applied"], tolerances(sol))
    if txt:
        name = sol.solver.solver
        frictionless = sol.scene.friction is None  # the fast path is frictionless: not advised under friction
        advice = ({"api": "try solver='fast', or a coarser mesh", "cli": "try --solver fast, or a coarser mesh"}
                  if name.upper() == "CLARABEL" and frictionless else
                  {"api": "try a coarser mesh or tighter solver tolerances", "cli": "try a coarser mesh"}
                  if name.upper() == "CLARABEL" else
                  {"api": "try solver='CLARABEL' (interior point)", "cli": "try --solver CLARABEL (interior point)"}
                  if not frictionless else
                  {"api": "the problem is too ill-conditioned for its factorisation; use solver='CLARABEL'",
                   "cli": "the problem is too ill-conditioned for its factorisation; use --solver CLARABEL"}
                  if name == "fast" else
                  {"api": "try solver='CLARABEL' (interior point) or solver='fast'",
                   "cli": "try --solver CLARABEL (interior point) or --solver fast"})
        what = f"solver {name} returned 'optimal' but the solution fails the accuracy checks ({txt})"
        raise AccuracyError(f"{what}; {advice['api']}", cli=f"{what}; {advice['cli']}")


def skipped_error(residuals: dict, why: str | None) -> Checks | None:
    """A solution's ``checks`` when the scene's exact field does not solve it (``why``): every
    residual applied, the error skipped with the reason; ``None`` (all applied) otherwise."""
    return None if why is None else Checks(applied=dict(residuals), skipped={"error": why})
