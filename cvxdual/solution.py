"""Solving a scene end to end, and the :class:`Solution` it returns.

``solve(scene)`` meshes, assembles, builds the CVXPY dual, solves it, recovers displacements
from the multipliers and checks the result: equilibrium and sign of contact forces, the
constitutive law ``t_P = C_P B_P u_h``, complementarity and the discrete duality gap.
A result that fails the promised tolerances (:data:`TOLERANCES`) raises
:class:`~cvxdual.errors.AccuracyError`; it is never returned.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .assembly import System, assemble
from .dual import DualModel, admissibility
from .errors import AccuracyError, SceneError
from .exact import exact_field
from .norms import VOIGT_WEIGHT, stress_error
from .scene import Scene
from .solvers import FAST, resolve_solver
from .triangulation import check_triangulation, discretize

# What every returned solution satisfies (relative measures, defined in Solution.residuals).
# Clarabel's default tolerances (1e-8 on gaps and feasibility) leave these with a margin of
# about 100 on the built-in scenes; first-order solvers may fail them and are then rejected.
TOLERANCES = {"equilibrium": 1e-6, "constitutive": 1e-4, "complementarity": 1e-5, "penetration": 1e-6,
              "duality_gap": 1e-6}

ACTIVE_TOL = 1e-6  # an active pair's force exceeds this fraction of the largest (and its opening)
FORCE_FLOOR = 1e-3  # contact forces below this fraction of the total load are "no contact"


def load_scale(system: System) -> float:
    """``F_ref = sum |f|``: the size of the applied loads (or of the stress scale if unloaded)."""
    return float(np.abs(system.f).sum()) or system.scales.stress * system.scales.length


@dataclass
class Solution:
    """A solved scene. Arrays: ``stress`` ``(n_pieces, 3)``, ``displacement`` ``(n_nodes, 2)``,
    contact arrays ``(n_pairs,)`` ordered by ``x``."""

    scene: Scene
    triangulation: str
    level: int
    system: System
    stress: np.ndarray
    displacement: np.ndarray
    solver: dict
    timings: dict
    objective: float = 0.0
    duality_gap: float = 0.0
    residuals: dict = field(default_factory=dict)
    contact: dict = field(default_factory=dict)
    exact: dict | None = None
    error: dict | None = None

    @property
    def mesh(self):
        return self.system.mesh

    @property
    def pieces(self):
        return self.system.pieces

    def summary(self) -> dict:
        """The ``summary.json`` contract (README, "Outputs")."""
        s = self.system
        c = self.contact
        return {
            "scene": self.scene.name,
            "triangulation": self.triangulation,
            "level": self.level,
            "units": {"length": self.scene.units[0], "stress": self.scene.units[1]},
            "n_pieces": s.n_pieces,
            "piece_kinds": s.pieces.counts(),
            "n_stress_unknowns": 3 * s.n_pieces,
            "n_dofs": s.n_dofs,
            "n_free_dofs": s.n_r,
            "n_contact_pairs": len(s.jb),
            "h": s.mesh.h,
            "h_min": s.mesh.h_min,
            "solver": self.solver.get("solver"),
            "status": self.solver.get("status"),
            "iterations": self.solver.get("iterations"),
            "objective": self.objective,
            "duality_gap": self.duality_gap,
            "load_imbalance": s.load_imbalance,
            "residuals": dict(self.residuals),
            "contact": {k: c[k] for k in ("n_active", "x_min", "x_max", "max_pressure", "total_force")},
            "exact": self.exact,
            "error": self.error,
            "timings": dict(self.timings),
        }


def contact_quantities(system: System, R: np.ndarray, u: np.ndarray) -> dict:
    """Nodal contact forces, pressures, gaps and the active set, from the residual
    ``R = Z^T (E t - f)`` of the stresses and the displacements ``u``."""
    force = -R[system.jb]
    up, lo = system.mesh.pairs.T
    rel = u[2 * lo + 1] - u[2 * up + 1]
    pressure = force / system.width
    fmax = max(float(force.max()) if len(force) else 0.0, FORCE_FLOOR * load_scale(system))
    delta = max(float(np.abs(u).max()), float(np.abs(system.eps).max()), system.scales.displacement)
    opening = system.eps - rel
    # complementarity makes force or opening zero; an interior point leaves both small, and the
    # larger of the two (each relative to its scale) tells the state
    active = (force > ACTIVE_TOL * fmax) & (force / fmax > opening / delta)
    xs = system.mesh.pair_x[active]
    return {
        "x": system.mesh.pair_x, "gap": system.eps, "relative_displacement": rel,
        "force": force, "pressure": pressure, "active": active,
        "reaction": R[system.ja],  # y force on the upper body: +force (action = reaction)
        "n_active": int(active.sum()),
        "x_min": float(xs.min()) if len(xs) else None,
        "x_max": float(xs.max()) if len(xs) else None,
        "max_pressure": float(pressure.max()) if len(pressure) else 0.0,
        "total_force": float(force.sum()),
    }


def residuals(system: System, t: np.ndarray, u: np.ndarray, contact: dict, adm=None) -> dict:
    """Relative residuals of a dual solution ``t`` with recovered displacements ``u``.

    - equilibrium: largest violation of ``(T^T R)_j = 0`` (``j`` in ``J0``) and
      ``(T^T R)_m <= 0`` (``m`` in ``J-``), over the largest term of ``Z^T (|E||t| + |f|)``;
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
    Ry = system.T().T @ R
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
    s = contact["gap"] - contact["relative_displacement"]
    delta = max(float(np.abs(u).max()), float(np.abs(contact["gap"]).max()), sc.displacement)
    F = contact["force"]
    fsum = max(float(np.abs(F).sum()), FORCE_FLOOR * f_ref)
    comp = float(np.sum(np.abs(F * s)) / (fsum * delta))
    pen = float(max(0.0, -s.min()) / delta) if len(s) else 0.0
    return {"equilibrium": eq, "constitutive": cons, "complementarity": comp, "penetration": pen,
            "duality_gap": duality_gap(system, t, u)}


def dual_objective(system: System, t: np.ndarray) -> float:
    """``S(t) = 1/2 t.A_h t - t.E^T q0`` (MATH.md section 3)."""
    tv = t.ravel()
    return 0.5 * float(tv @ (system.Ah @ tv)) - float(tv @ (system.E.T @ system.q0))


def duality_gap(system: System, t: np.ndarray, u: np.ndarray) -> float:
    """``|J(u_h) + L(u0) + S(lam_h)|`` relative to the complementary energy (MATH.md section 2)."""
    tv = t.ravel()
    energy = 0.5 * float(tv @ (system.Ah @ tv))
    objective = energy - float(tv @ (system.E.T @ system.q0))
    sc = system.scales
    val = system.energy(u) + float(system.f @ system.q0) + objective
    return abs(val) / max(energy, abs(objective), 1e-12 * sc.stress**2 * sc.length**2 / sc.modulus)


def build_model(scene: Scene, triangulation: str = "type1", level: int | None = None) -> DualModel:
    """Mesh, assemble and build the CVXPY dual of ``scene`` without solving it."""
    mesh, pieces, ties = discretize(scene, check_triangulation(triangulation), level)
    return DualModel(assemble(mesh, pieces, ties))


def solve(scene: Scene, triangulation: str = "type1", level: int | None = None,
          solver: str | None = None, check: bool = True, warm_start: bool = True,
          **solver_options) -> Solution:
    """Solve the discrete dual problem of ``scene``; see the module docstring.

    ``solver`` is a CVXPY solver name (default Clarabel) or ``"fast"``, the active-set path of
    :mod:`cvxdual.fast` (warm-started from level ``level - 2`` unless ``warm_start`` is false).
    """
    if not isinstance(scene, Scene):
        from .scenefile import load_scene
        if not isinstance(scene, (str, Path, dict)):
            raise SceneError(f"solve() needs a Scene, a built-in scene name or a .toml path, got {type(scene).__name__}")
        scene = load_scene(scene)
    solver = resolve_solver(solver)
    triangulation = check_triangulation(triangulation)
    level = scene.mesh.default_level if level is None else level
    t0 = time.perf_counter()
    mesh, pieces, ties = discretize(scene, triangulation, level)
    t1 = time.perf_counter()
    system = assemble(mesh, pieces, ties)
    t2 = time.perf_counter()
    if not np.any(system.f) and np.all(system.eps >= 0):
        # nothing acts (no load, no interference): lam = 0 is admissible and S(lam) >= S(0) for
        # every admissible lam (contact forces are compressive, gaps >= 0), so it is the solution
        t3 = t4 = time.perf_counter()
        zero = np.zeros(system.n_dofs)
        info = {"solver": "none (no load, no interference)", "status": "optimal", "iterations": 0}
        sol = make_solution(system, np.zeros((system.n_pieces, 3)), zero, triangulation, level, info, check)
        build, solve_time = 0.0, 0.0
    elif solver == FAST:
        from .fast import cascade, solve_fast
        active = cascade(scene, triangulation, level, mesh.pair_x) if warm_start else None
        t3 = time.perf_counter()
        u, info = solve_fast(system, active)
        info["warm_start_time"] = t3 - t2  # counted in "solve": it is part of the fast path's work
        t4 = time.perf_counter()
        sol = make_solution(system, system.stresses_from_displacement(u), u, triangulation, level, info, check)
        build, solve_time = 0.0, t4 - t2
    else:
        model = DualModel(system)
        t3 = time.perf_counter()
        info = model.solve(solver, **solver_options)
        t4 = time.perf_counter()
        sol = recover(model, triangulation, level, info, check)
        # CVXPY canonicalises inside solve(); count that as building the problem
        compile_time = float(info.get("compile_time") or 0.0)
        build, solve_time = t3 - t2 + compile_time, t4 - t3 - compile_time
    t5 = time.perf_counter()
    sol.timings = {"mesh": t1 - t0, "assemble": t2 - t1, "build": build, "solve": solve_time,
                   "recover": t5 - t4, "total": t5 - t0}
    return sol


def recover(model: DualModel, triangulation: str, level: int, info: dict, check: bool = True) -> Solution:
    """The :class:`Solution` of a solved CVXPY model: stresses, and displacements from the multipliers."""
    return make_solution(model.system, model.stresses(), model.displacements(), triangulation, level, info,
                         check and not model.extra)


def make_solution(system: System, t: np.ndarray, u: np.ndarray, triangulation: str, level: int, info: dict,
                  check: bool = True) -> Solution:
    """Contact data, residuals, objective, duality gap and errors of stresses ``t`` and displacements ``u``."""
    scene = system.mesh.scene
    adm = admissibility(system, t)
    contact = contact_quantities(system, adm[0], u)
    res = residuals(system, t, u, contact, adm)
    objective = dual_objective(system, t)
    exact = exact_field(scene)
    error = stress_error(system, t, exact.stress) if exact is not None else None
    sol = Solution(scene=scene, triangulation=triangulation, level=level, system=system, stress=t,
                   displacement=u.reshape(-1, 2), solver=info, timings={}, objective=objective,
                   duality_gap=res["duality_gap"], residuals=res, contact=contact,
                   exact=exact.data() if exact is not None else None, error=error)
    if check:
        check_solution(sol)
    return sol


def check_solution(sol: Solution) -> None:
    bad = {k: v for k, v in sol.residuals.items() if v > TOLERANCES[k]}
    if bad:
        txt = ", ".join(f"{k} {v:.2e} > {TOLERANCES[k]:.0e}" for k, v in bad.items())
        name = str(sol.solver.get("solver"))
        advice = ("try --solver fast, or a coarser mesh" if name.upper() == "CLARABEL"
                  else "report it: the active-set result should be exact" if name == "fast"
                  else "try CLARABEL (interior point) or --solver fast")
        raise AccuracyError(f"solver {name} returned 'optimal' but the solution fails the accuracy checks "
                            f"({txt}); {advice}")
