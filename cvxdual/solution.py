"""The :class:`Solution` of a scene and the checks every solution passes
(docs/theory.md#recovery-and-checks).

From the stresses ``t`` and the recovered displacements ``u_h``: equilibrium and sign of the
contact forces, the constitutive law ``t_P = C_P B_P u_h``, complementarity and the discrete
duality gap. A result that fails the promised tolerances (:data:`TOLERANCES`) raises
:class:`~cvxdual.errors.AccuracyError`; it is never returned.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .errors import AccuracyError
from .p0.assembly import System
from .p0.norms import VOIGT_WEIGHT, stress_error
from .reference.exact import exact_field
from .scene.scene import Scene

# What every returned solution satisfies (relative measures, defined in Solution.residuals).
# Clarabel's default tolerances (1e-8 on gaps and feasibility) leave these with a margin of
# about 100 on the built-in scenes; first-order solvers may fail them and are then rejected.
TOLERANCES = {"equilibrium": 1e-6, "constitutive": 1e-4, "complementarity": 1e-5, "penetration": 1e-6,
              "duality_gap": 1e-6}

# equilibrium stresses (stress space "eq") are exactly admissible: every constraint to rounding
# relative to the stress scale (the exactness post-step brings them to ~1e-14)
EQ_TOLERANCES = {"admissibility": 1e-9, "penetration": 1e-12}
BOUND_KEYS = ("energy_upper", "energy_lower", "gap", "error_bound", "guaranteed", "reasons", "data_oscillation")

# contact.csv and Solution.contact_table(), one row per pair: tangential_force is the x force of
# the upper body on the lower one (0 without friction); slip the relative tangential
# displacement u''_x - u'_x; stick 1 where an active pair sticks
CONTACT_COLUMNS = ("x", "gap", "relative_displacement", "pressure", "active", "force", "tangential_force", "slip",
                   "stick")
FLAG_COLUMNS = ("active", "stick")  # booleans, written as 0/1

ACTIVE_TOL = 1e-6  # an active pair's force exceeds this fraction of the largest (and its opening)
FORCE_FLOOR = 1e-3  # contact forces below this fraction of the total load are "no contact"


def load_scale(system: System) -> float:
    """``F_ref = sum |f|``: the size of the applied loads (or of the stress scale if unloaded)."""
    return float(np.abs(system.f).sum()) or system.scales.stress * system.scales.length


@dataclass(frozen=True)
class Solution:
    """A solved scene, built complete by :func:`cvxdual.solve` and never changed afterwards.
    Arrays: ``stress`` ``(n_pieces, 3)`` (stress space ``p0``) or the Voigt values at the
    vertices of every sub-triangle ``(n_sub, 3, 3)`` (``eq``), ``displacement`` ``(n_nodes, 2)``
    (for ``eq`` the P1 displacement of the bounds, pointwise admissible), contact arrays
    ``(n_pairs,)`` ordered by ``x``; ``timings`` in seconds per phase."""

    scene: Scene
    triangulation: str
    stress_space: str
    level: int
    system: System
    stress: np.ndarray
    displacement: np.ndarray
    solver: dict
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
        eq = self.stress_space == "eq"
        return {
            "scene": self.scene.name,
            "triangulation": self.triangulation,
            "stress_space": self.stress_space,
            "level": self.level,
            "units": {"length": self.scene.units[0], "stress": self.scene.units[1]},
            "friction": None if self.scene.friction is None else  # JSON has no inf: full stick as "inf"
            {"kind": self.scene.friction.kind, "g": self.scene.friction.g if np.isfinite(self.scene.friction.g)
             else "inf"},
            "n_pieces": 3 * self.space.n_tri if eq else s.n_pieces,
            "piece_kinds": {"sub_triangle": 3 * self.space.n_tri} if eq else s.pieces.counts(),
            "n_stress_unknowns": self.space.n_y if eq else 3 * s.n_pieces,
            "n_dofs": s.n_dofs,
            "n_free_dofs": s.n_r,
            "n_contact_pairs": len(s.jb),
            "h": s.mesh.h,
            "h_min": s.mesh.h_min,
            "solver": self.solver.get("solver"),
            "fallback": self.solver.get("fallback"),
            "status": self.solver.get("status"),
            "iterations": self.solver.get("iterations"),
            "objective": self.objective,
            "duality_gap": self.duality_gap,
            "load_imbalance": self.space.load_imbalance if eq else s.load_imbalance,
            "residuals": dict(self.residuals),
            "contact": {k: c[k] for k in ("n_active", "x_min", "x_max", "max_pressure", "total_force")},
            "exact": self.exact,
            "error": self.error,
            "bounds": None if self.bounds is None else {k: self.bounds[k] for k in BOUND_KEYS},
            "checks_skipped": {} if self.checks is None else dict(self.checks["skipped"]),
            "timings": dict(self.timings),
        }


def admissibility(system: System, t: np.ndarray):
    """Residual vector ``R = Z^T (E t - f)`` of stresses ``t`` ``(n_pieces, 3)``, and its scale
    ``Z^T (|E| |t| + |f|)`` for relative measures."""
    tv = t.ravel()
    ZT = system.Z.T
    R = ZT @ (system.E @ tv - system.f)
    scale = ZT @ (abs(system.E) @ np.abs(tv) + np.abs(system.f))
    return R, scale


def contact_quantities(system: System, R: np.ndarray, u: np.ndarray, friction=None, adhesion=None,
                       displacements: bool = True) -> dict:
    """Nodal contact forces, pressures, gaps, the active set and the tangential state, from
    the residual ``R = Z^T (E t - f)`` of the stresses and the displacements ``u``.

    ``friction`` (Tresca ``g`` per pair) and ``adhesion`` (``sigma_a`` per pair) are those of
    the problem solved: a pair is active where its force exceeds ``-sigma_a w`` and sticks
    where it is active and its tangential force is below ``g w`` (each judged, like the
    normal state, against the slip relative to its scale)."""
    force = -R[system.jb]
    up, lo = system.mesh.pairs.T
    q = u.reshape(-1, 2)
    rel = q[lo, 1] - q[up, 1]
    pressure = force / system.width
    held = force if adhesion is None else force + adhesion * system.width  # force above the cut-off
    fmax = max(float(held.max()) if len(held) else 0.0, FORCE_FLOOR * load_scale(system))
    delta = _delta(system, u, system.eps)
    opening = system.eps - rel
    # complementarity makes force or opening zero; an interior point leaves both small, and the
    # larger of the two (each relative to its scale) tells the state
    active = held > ACTIVE_TOL * fmax
    if displacements:
        active &= held / fmax > opening / delta
    _, jxb, slides = system.pair_x_dofs
    tangential = np.where(slides, R[np.where(slides, jxb, 0)], 0.0)  # R''_x(B_k): x force on the lower body
    slip = q[lo, 0] - q[up, 0]
    if friction is None:
        stick = np.zeros(len(force), bool)
    else:
        with np.errstate(invalid="ignore"):  # g = inf: the reserve is inf, the pair sticks
            reserve = (friction * system.width - np.abs(tangential)) / fmax
        # without displacements, by the reserve alone (as the normal state by the force alone)
        stick = active & slides & (reserve > (np.abs(slip) / delta if displacements else ACTIVE_TOL))
    xs = system.mesh.pair_x[active]
    return {
        "x": system.mesh.pair_x, "gap": system.eps, "relative_displacement": rel,
        "force": force, "pressure": pressure, "active": active,
        "tangential_force": tangential, "slip": slip, "stick": stick,
        "reaction": R[system.ja],  # y force on the upper body: +force (action = reaction)
        "n_active": int(active.sum()),
        "x_min": float(xs.min()) if len(xs) else None,
        "x_max": float(xs.max()) if len(xs) else None,
        "max_pressure": float(pressure.max()) if len(pressure) else 0.0,
        "total_force": float(force.sum()),
    }


def edge_contact(system, p: np.ndarray, v: np.ndarray | None = None, load: float = 1.0) -> dict:
    """Contact quantities of linear contact pressures ``p`` ``(n_c, 2)`` (at both ends of each
    contact edge), defined as for P0 (:func:`cvxdual.solution.contact_quantities`): the nodal
    force ``int p phi_k dx`` at each pair and the pressure per tributary length; a pair is active
    where the pressure at it (from either adjacent edge) is positive beyond rounding of the load
    scale (``load`` times the scene's). ``v``: displacements for the relative displacement and
    slip, or ``None`` (zeros). The equilibrium space is frictionless: no tangential force."""
    x = system.mesh.pair_x
    d = np.diff(x)
    force = np.zeros(len(x))
    force[:-1] += d * (2 * p[:, 0] + p[:, 1]) / 6.0
    force[1:] += d * (p[:, 0] + 2 * p[:, 1]) / 6.0
    at_pair = np.zeros(len(x))
    at_pair[:-1] = p[:, 0]
    at_pair[1:] = np.maximum(at_pair[1:], p[:, 1])
    floor = FORCE_FLOOR * load * load_scale(system) / max(float(x[-1] - x[0]), 1e-300)
    active = at_pair > ACTIVE_TOL * max(float(at_pair.max(initial=0.0)), floor)
    n = len(x)
    up, lo = system.mesh.pairs.T
    rel, slip = (np.zeros(n), np.zeros(n)) if v is None else (v[lo, 1] - v[up, 1], v[lo, 0] - v[up, 0])
    pressure = force / system.width
    xs = x[active]
    return {"x": x, "gap": system.eps, "relative_displacement": rel, "force": force, "pressure": pressure,
            "active": active, "edge_pressure": p, "tangential_force": np.zeros(n), "slip": slip,
            "stick": np.zeros(n, bool), "n_active": int(active.sum()),
            "x_min": float(xs.min()) if len(xs) else None, "x_max": float(xs.max()) if len(xs) else None,
            "max_pressure": float(pressure.max(initial=0.0)), "total_force": float(force.sum())}


def residuals(system: System, t: np.ndarray, u: np.ndarray, contact: dict, adm=None) -> dict:
    """Relative residuals of a dual solution ``t`` with recovered displacements ``u``.

    - equilibrium: largest violation of ``(T^T R)_j = 0`` (every ``j`` not in ``J-``, the
      anchors included, so the dropped rows are checked too) and ``(T^T R)_m <= 0`` (``m`` in
      ``J-``), over the largest term of ``Z^T (|E||t| + |f|)``;
    - constitutive: ``||t - C B u||_0 / ||t||_0``;
    - complementarity: ``sum |F_k s_k| / (sum |F_k| * delta)``, ``s_k = eps_k - (u''_y - u'_y)``,
      ``delta`` the largest displacement or gap;
    - penetration: ``max(0, -s_k) / delta``.

    Force denominators are floored (``F_ref = sum |f|``, the load scale: ``1e-6 F_ref`` for nodal
    forces, ``1e-3 F_ref`` for the total contact force) so that a solution with (almost) no
    contact is not judged on rounding noise.
    """
    R, scale = admissibility(system, t) if adm is None else adm
    f_ref = load_scale(system)
    Ry = system.T.T @ R
    viol = np.abs(Ry)
    viol[system.jb] = np.maximum(Ry[system.jb], 0.0)
    eq = float(viol.max() / max(scale.max(), 1e-6 * f_ref)) if len(viol) else 0.0
    sc = system.scales
    tu = system.stresses_from_displacement(u)
    a = system.pieces.area[:, None]
    num = np.sqrt(np.sum(a * VOIGT_WEIGHT * (t - tu) ** 2))
    den = np.sqrt(np.sum(a * VOIGT_WEIGHT * t**2))
    # floors: the problem's own stress and displacement scales (an unloaded scene has t = u = 0)
    cons = float(num / max(den, 1e-12 * sc.stress * sc.length))
    return {"equilibrium": eq, "constitutive": cons, "complementarity": complementarity(system, u, contact),
            "penetration": penetration(system, u, contact), "duality_gap": duality_gap(system, t, u)}


def _delta(system: System, u: np.ndarray, gap: np.ndarray) -> float:
    """The displacement scale: the largest displacement or gap (floored by the problem's)."""
    return max(float(np.abs(u).max()), float(np.abs(gap).max(initial=0.0)), system.scales.displacement)


def complementarity(system: System, u: np.ndarray, contact: dict, force: np.ndarray | None = None) -> float:
    """``sum |F_k s_k| / (sum |F_k| delta)`` with the openings ``s_k``; ``force`` replaces
    ``contact["force"]`` (adhesion: the force above the cut-off)."""
    F = contact["force"] if force is None else force
    s = contact["gap"] - contact["relative_displacement"]
    fsum = max(float(np.abs(F).sum()), FORCE_FLOOR * load_scale(system))
    return float(np.sum(np.abs(F * s)) / (fsum * _delta(system, u, contact["gap"])))


def penetration(system: System, u: np.ndarray, contact: dict) -> float:
    """``max(0, -min_k s_k) / delta``."""
    s = contact["gap"] - contact["relative_displacement"]
    return float(max(0.0, -s.min()) / _delta(system, u, contact["gap"])) if len(s) else 0.0


def dual_objective(system: System, t: np.ndarray) -> float:
    """``S(t) = 1/2 t.A_h t - t.E^T q0`` (docs/theory.md#discretisation)."""
    tv = t.ravel()
    return 0.5 * float(tv @ (system.Ah @ tv)) - float(tv @ (system.E.T @ system.q0))


def duality_gap(system: System, t: np.ndarray, u: np.ndarray, extra: float = 0.0) -> float:
    """``|J(u_h) + L(u0) + S(lam_h)|`` relative to the complementary energy
    (docs/theory.md#primal-and-dual-problems); ``extra`` is what a reformulation adds to ``J``
    (friction dissipation, adhesion work)."""
    tv = t.ravel()
    energy = 0.5 * float(tv @ (system.Ah @ tv))
    objective = energy - float(tv @ (system.E.T @ system.q0))
    sc = system.scales
    val = system.energy(u) + extra + float(system.f @ system.q0) + objective
    return abs(val) / max(energy, abs(objective), 1e-12 * sc.stress**2 * sc.length**2 / sc.modulus)


def evaluate(system: System, t: np.ndarray, u: np.ndarray, info: dict, friction=None, adhesion=None,
             displacements: bool = True) -> dict:
    """Contact data, residuals, objective, duality gap and errors of stresses ``t`` and
    displacements ``u``: every field of a :class:`Solution` that the solve itself does not give,
    and ``timings["error"]``, the time of the error against the exact field (``friction``,
    ``adhesion``, ``displacements``: see :func:`contact_quantities`)."""
    scene = system.mesh.scene
    adm = admissibility(system, t)
    contact = contact_quantities(system, adm[0], u, friction, adhesion, displacements)
    res = residuals(system, t, u, contact, adm)
    exact = exact_field(scene)
    error, t0 = None, time.perf_counter()
    if exact is not None:
        error = stress_error(system, t, exact.stress)
    return {"timings": {"error": time.perf_counter() - t0},  # a diagnostic: shown apart
            "scene": scene, "system": system, "stress": t, "displacement": u.reshape(-1, 2), "solver": info,
            "objective": dual_objective(system, t), "duality_gap": res["duality_gap"], "residuals": res,
            "contact": contact, "exact": exact.data() if exact is not None else None,
            "error": error}


def tolerances(sol: Solution) -> dict:
    """The residual tolerances ``sol`` promises (its stress space's)."""
    return EQ_TOLERANCES if sol.stress_space == "eq" else TOLERANCES


def failed_checks(applied: dict, tol: dict) -> str:
    """The residuals of ``applied`` above their tolerance in ``tol`` (NaN fails too), as text
    for a message; empty if none."""
    return ", ".join(f"{k} {v:.2e} > {tol[k]:.0e}" for k, v in applied.items() if k in tol and not v <= tol[k])


def check_solution(sol: Solution) -> None:
    txt = failed_checks(sol.residuals if sol.checks is None else sol.checks["applied"], tolerances(sol))
    if txt:
        name = str(sol.solver.get("solver"))
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
