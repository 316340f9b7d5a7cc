"""The one way from a scene to a solution: scene -> mesh and pieces -> assembly -> model ->
solution (docs/theory.md).

``solve(scene)`` meshes, assembles, builds and solves the dual (the CVXPY path) or its
displacement form (the fast path), recovers displacements and checks the result. Warm starts
of the fast path are arranged here: the active set of level ``L - 2``, solved by this same
pipeline, transferred to level ``L``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

from .errors import AccuracyError, CvxdualError, SceneError, SolverError, TooLargeError
from .geometry.mesh import check_level, mesh_size
from .geometry.triangulation import check_triangulation, discretize
from .model.solvers import DEFAULT_SOLVER, FAST, TIME_LIMIT_OPTION, default_solver, resolve_solver
from .p0.assembly import System, assemble
from .p0.fast import solve_fast, transfer_active  # at import: SciPy's sparse solvers load with cvxdual, not in a solve
from .progress import Deadline, phase
from .scene.scene import Scene
from .sizing import check_size
from .solution import Solution, check_solution, evaluate
from .validate import one_line, short

log = logging.getLogger(__name__)

STRESS_SPACES = ("p0", "eq")  # the paper's piecewise-constant stresses; equilibrium (docs/equilibrium.md)


def check_stress_space(name) -> str:
    name = str(name).lower()
    if name not in STRESS_SPACES:
        raise CvxdualError(f"unknown stress space {name!r}; choose one of {', '.join(STRESS_SPACES)}")
    return name


def as_scene(scene) -> Scene:
    """A :class:`Scene`, or a built-in scene name, a .toml path or a scene dict loaded as one."""
    if isinstance(scene, Scene):
        return scene
    if not isinstance(scene, (str, Path, dict)):
        raise SceneError(f"expected a Scene, a built-in scene name or a .toml path, got {type(scene).__name__}")
    from .scene.scenefile import load_scene
    return load_scene(scene)


def build_system(scene, triangulation: str = "type1", level: int | None = None) -> System:
    """Mesh and assemble ``scene``: the :class:`~cvxdual.p0.assembly.System` of the discrete problem."""
    scene = as_scene(scene)
    return assemble(*discretize(scene, check_triangulation(triangulation), level))


def build_model(scene, triangulation: str = "type1", level: int | None = None, limit_analysis: bool = False,
                stress_space: str = "p0"):
    """Mesh, assemble and build the CVXPY dual of ``scene`` without solving it: a
    :class:`~cvxdual.p0.dual.DualModel` (with the scene's friction, if it has any), or with
    ``stress_space="eq"`` an :class:`~cvxdual.eq.model.EquilibriumModel` (flat faces, frictionless)."""
    scene = as_scene(scene)
    triangulation = check_triangulation(triangulation)
    if check_stress_space(stress_space) == "eq":
        from .eq.model import EquilibriumModel
        from .eq.space import EquilibriumSpace, check_flat
        check_flat(scene)
        if scene.friction is not None:
            raise CvxdualError("the equilibrium stress space is frictionless; drop the scene's friction or use "
                               "stress_space='p0'")
        system = build_system(scene, triangulation, level)
        return EquilibriumModel(EquilibriumSpace.from_mesh(system.mesh), limit_analysis, system)
    return _dual_model(build_system(scene, triangulation, level), triangulation, limit_analysis)


def _dual_model(system: System, triangulation: str, limit_analysis: bool = False):
    """The :class:`~cvxdual.p0.dual.DualModel` of ``system`` with its scene's friction, if any."""
    from .p0.dual import DualModel
    model = DualModel(system, triangulation, limit_analysis)
    friction = system.mesh.scene.friction
    if friction is not None:
        model.add_friction(friction.g)
    return model


def solve(scene, triangulation: str = "type1", level: int | None = None, solver: str | None = None,
          check: bool = True, warm_start: bool = True, stress_space: str = "p0", bounds: bool = False,
          max_memory=None, fallback: bool = True, time_limit: float | None = None, verbose: bool = False,
          **solver_options) -> Solution:
    """Solve the discrete dual problem of ``scene``; see the module docstring.

    ``solver`` is a CVXPY solver name or ``"fast"``, the active-set path of :mod:`cvxdual.p0.fast`
    (warm-started from level ``level - 2`` unless ``warm_start`` is false). By default (no
    solver and no options) the CVXPY solver measured fastest at the mesh's size
    (:func:`cvxdual.model.solvers.default_solver`: Clarabel, SCS from 2e4 pieces), handing over to
    Clarabel where it fails; options alone go to Clarabel.
    ``stress_space`` is ``"p0"`` (the paper's) or ``"eq"`` (exactly admissible equilibrium
    stresses on flat-face scenes, with certified bounds; docs/equilibrium.md). ``bounds`` also
    certifies a ``p0`` run (its displacement against the equilibrium stresses of the same mesh).
    ``check`` false returns solutions that fail the accuracy checks (for studies of them).
    Where the fast path (or the default solver) fails (its checks, a cycling active set), the
    CVXPY path with Clarabel solves instead, unless ``fallback`` is false; ``solver["fallback"]`` (and ``summary.json``)
    then says why.
    The run's memory is estimated first and refused above ``max_memory`` (bytes or ``"16GB"``;
    default: the memory available, see :mod:`cvxdual.sizing`) with
    :class:`~cvxdual.errors.TooLargeError`.
    ``time_limit`` (seconds) bounds the whole run (:mod:`cvxdual.progress`): past it the run
    stops with :class:`~cvxdual.errors.TimeLimitError`. ``verbose`` prints the CVXPY solver's
    own log. Progress is logged to the logger ``"cvxdual"`` (INFO; the fast path's iterations
    at DEBUG).
    """
    deadline = Deadline(time_limit)
    scene = as_scene(scene)
    chosen = solver is None and not solver_options  # options name their solver: Clarabel's, as always
    triangulation = check_triangulation(triangulation)
    stress_space = check_stress_space(stress_space)
    level = check_level(scene.mesh.default_level if level is None else level)
    if scene.friction is not None:
        if stress_space == "eq" or bounds:
            raise CvxdualError("the equilibrium stress space and the bounds are frictionless; drop the scene's "
                               "friction or solve with stress_space='p0' and no bounds",
                               cli="the equilibrium stress space and the bounds are frictionless; drop the scene's "
                                   "friction or solve without --stress-space eq and --bounds")
        if str(solver).upper() == FAST:
            raise SolverError("the fast path is frictionless; the scene has friction: use solver='CLARABEL'",
                              cli="the fast path is frictionless; the scene has friction: use --solver CLARABEL")
        if chosen:
            solver = DEFAULT_SOLVER  # friction rows measured with Clarabel only
    if chosen and stress_space == "p0" and scene.friction is None:
        solver = default_solver(mesh_size(scene, level)["triangles"])
    solver = resolve_solver(solver)
    deadline.fast = solver == FAST
    if solver == FAST and solver_options:
        raise SolverError(f"the fast path takes no solver options, got {', '.join(sorted(solver_options))}; "
                          "drop them or choose a CVXPY solver such as CLARABEL")
    check_size(scene, level, solver == FAST, stress_space, bounds, max_memory)
    attempt = partial(_solve_eq if stress_space == "eq" else _solve_p0, scene, triangulation, level, check=check,
                      warm_start=warm_start, bounds=bounds, deadline=deadline, verbose=verbose)
    try:
        with deadline.enforced():
            try:
                return attempt(solver, **solver_options)
            except (SolverError, AccuracyError) as e:
                if not fallback or not (solver == FAST or (chosen and solver != DEFAULT_SOLVER)):
                    raise
                deadline.check()  # no time left for another solver
                # the fast path (or the size's default) failed where Clarabel may not: hand over, say so
                reason = one_line(e, 300)
                name = "the fast path" if solver == FAST else solver
                try:
                    check_size(scene, level, False, stress_space, bounds, max_memory)
                    log.info("%s failed (%s); solving with %s", name, reason, DEFAULT_SOLVER)
                    sol = attempt(DEFAULT_SOLVER)
                except CvxdualError as e2:  # both paths failed: say so, with both reasons
                    both = f"{name} failed ({reason}); {DEFAULT_SOLVER}, tried after it, failed too: "
                    raise type(e2)(both + str(e2), cli=both + (e2.cli or str(e2))) from None
                return replace(sol, solver={**sol.solver, "fallback": f"{name} failed ({reason}); "
                                            f"solved by {DEFAULT_SOLVER}"})
    except MemoryError:
        what = f"ran out of memory solving {short(scene.name, 40)} at level {level}"
        raise TooLargeError(f"{what}; lower the level or free memory",
                            cli=f"{what}; lower --level or free memory") from None


def _solve_p0(scene: Scene, triangulation: str, level: int, solver: str, check: bool = True, warm_start: bool = True,
              bounds: bool = False, deadline: Deadline | None = None, verbose: bool = False,
              **solver_options) -> Solution:
    """The paper's P0 run (see :func:`solve`)."""
    deadline = deadline or Deadline()
    if bounds:
        from .eq.space import check_flat
        check_flat(scene)
    t0 = time.perf_counter()
    with phase("mesh", deadline) as p:
        mesh, pieces, ties = discretize(scene, triangulation, level)
        p.detail = f"{triangulation}, level {level}: {len(mesh.points)} nodes, {len(pieces.kind)} pieces"
    t1 = time.perf_counter()
    with phase("assemble", deadline) as p:
        system = assemble(mesh, pieces, ties)
        p.detail = f"{3 * system.n_pieces} stress unknowns, {system.n_dofs} dofs, {len(system.jb)} contact pairs"
    t2 = time.perf_counter()
    build = 0.0
    if not np.any(system.f) and np.all(system.eps >= 0):
        # nothing acts (no load, no interference): lam = 0 is admissible and S(lam) >= S(0) for
        # every admissible lam (contact forces are compressive, gaps >= 0), so it is the solution
        u = np.zeros(system.n_dofs)
        t = np.zeros((system.n_pieces, 3))
        info = {"solver": "none (no load, no interference)", "status": "optimal", "iterations": 0}
    elif solver == FAST:
        with phase("solve", deadline, start=f"fast path on {system.n_r} displacement unknowns") as p:
            active = warm_start_active(scene, triangulation, level, mesh.pair_x) if warm_start else None
            t_warm = time.perf_counter() - t2
            u, info = solve_fast(system, active)
            info["warm_start_time"] = t_warm  # counted in "solve": it is part of the fast path's work
            t = system.stresses_from_displacement(u)
            p.detail = (f"fast path: active-set iterations {info['iterations']}, factorisations "
                        f"{info['factorizations']} ({info['backend']}), of which the warm start {t_warm:.2f} s")
    else:
        with phase("build", deadline) as p:
            model = _dual_model(system, triangulation)
            p.detail = "the CVXPY model; CVXPY compiles it at the start of the solve"
        t_built = time.perf_counter()
        limit = deadline.remaining() if solver in TIME_LIMIT_OPTION else None  # others: the alarm alone
        with phase("solve", deadline, start=f"{solver} on {3 * system.n_pieces} stress unknowns") as p:
            info = model.solve(solver, time_limit=limit, verbose=verbose, **solver_options)
            p.detail = (f"{solver}: {info['status']}, iterations {info['iterations']}; of this time CVXPY's "
                        f"compile {float(info.get('compile_time') or 0.0):.2f} s, which the summary counts as build")
        # CVXPY canonicalises inside solve(); count that as building the problem
        build = t_built - t2 + float(info.get("compile_time") or 0.0)
        if scene.friction is not None:  # the model's own rows and checks (docs/reformulate.md)
            t3 = time.perf_counter()
            with phase("recover", deadline) as p:
                sol = model.solution(check=False)
                p.detail = "displacements from the multipliers, residuals"
            t4 = time.perf_counter()
            sol = replace(sol, timings={"mesh": t1 - t0, "assemble": t2 - t1, "build": build, "solve": t3 - t2 - build,
                                        "recover": t4 - t3, "error": 0.0, "total": t4 - t0})
            if check:
                check_solution(sol)  # the checks the model applied, with advice for solve() and the CLI
            return sol
        t, u = model.stresses(), model.displacements()
    t4 = time.perf_counter()
    with phase("recover", deadline) as p:
        fields = evaluate(system, t, u, info)
        p.detail = "residuals" + (", error against the exact field" if fields["error"] is not None else "")
        if bounds:
            from .eq.space import EquilibriumSpace
            space = EquilibriumSpace.from_mesh(mesh)
            # the equilibrium stresses by the fast route whatever the P0 solver (the same QP, exact)
            sigma, _ = solve_eq(space, FAST, (mesh.pair_x, fields["contact"]["active"]))
            from .eq.bounds import certified_bounds
            fields["bounds"] = certified_bounds(space, sigma, fields["displacement"])
            fields["space"] = space
            p.detail += ", certified bounds"
    t5 = time.perf_counter()
    timings = {"mesh": t1 - t0, "assemble": t2 - t1, "build": build, "solve": t4 - t2 - build,
               "recover": t5 - t4, "error": fields.pop("timings")["error"], "total": t5 - t0}
    sol = Solution(triangulation=triangulation, stress_space="p0", level=int(level), timings=timings,
                   **fields)
    if check:
        check_solution(sol)
    return sol


def warm_start_active(scene: Scene, triangulation: str, level: int, pair_x: np.ndarray) -> np.ndarray | None:
    """Initial active set for ``level``: the one of level ``level - 2`` (itself warm-started the
    same way), transferred to the abscissae ``pair_x``; ``None`` below level 2."""
    if level < 2:
        return None
    log.debug("warm start: the active set of level %d", level - 2)
    system = build_system(scene, triangulation, level - 2)
    if not np.any(system.f) and np.all(system.eps >= 0):
        return None
    coarse_x = system.mesh.pair_x
    try:
        u, info = solve_fast(system, warm_start_active(scene, triangulation, level - 2, coarse_x))
    except SolverError:
        return None  # a coarse level the fast path cannot solve gives no hint: start cold
    return transfer_active(coarse_x, info["active"], pair_x)


def recover(model, triangulation: str | None = None, level: int | None = None, info: dict | None = None,
            check: bool = True) -> Solution:
    """The :class:`Solution` of a :class:`~cvxdual.p0.dual.DualModel` solved by the caller: the
    same as ``model.solution(check)`` (the other arguments are kept for old callers and must
    agree with the model)."""
    if triangulation is not None and triangulation != model.triangulation:
        raise CvxdualError(f"the model was built with {model.triangulation}, not {triangulation}; "
                           "call model.solution()")
    if level is not None and int(level) != model.system.mesh.level:
        raise CvxdualError(f"the model is at level {model.system.mesh.level}, not {level}; call model.solution()")
    return model.solution(check)


# -- the equilibrium stress space (docs/equilibrium.md) -----------------------------------

def eq_contact(space, system: System, sigma: np.ndarray, v: np.ndarray, blocks: dict) -> dict:
    """Contact quantities of equilibrium stresses at the pairs (:func:`cvxdual.solution.edge_contact`
    of the contact tractions read from the lower face)."""
    from .eq.bounds import contact_tractions
    from .solution import edge_contact
    return edge_contact(system, -contact_tractions(space, sigma, blocks), v)


def solve_eq(space, solver: str, pairs: tuple | None = None, **solver_options) -> tuple[np.ndarray, dict]:
    """Exactly admissible vertex stresses ``(n_sub, 3, 3)`` on ``space`` and solver statistics.
    The fast path starts from the active contact ``pairs = (x, active)`` of a P0 solve on the
    same mesh (one iteration when the P0 contact zone is right, a few more where P0 locks)."""
    if solver == FAST:
        from .eq.fast import active_from_pairs, solve_eq_fast
        start = None if pairs is None else active_from_pairs(space, *pairs)
        y, info = solve_eq_fast(space, start)
        return space.stresses(y), info
    from .eq.model import EquilibriumModel
    model = EquilibriumModel(space)
    info = model.solve(solver, **solver_options)
    return model.stresses(), info


def _solve_eq(scene: Scene, triangulation: str, level: int, solver: str, check: bool = True, warm_start: bool = True,
              bounds: bool = True, deadline: Deadline | None = None, verbose: bool = False,
              **solver_options) -> Solution:
    """The "eq" run: the P1 displacement from the fast path, the equilibrium stresses on the
    same mesh, the certified bounds between them (always: ``bounds`` is implied) and the errors
    against an exact field. (Flat faces: both triangulations are the same mesh.)"""
    from .eq.space import EquilibriumSpace, check_flat
    check_flat(scene)
    deadline = deadline or Deadline()
    t0 = time.perf_counter()
    with phase("mesh", deadline) as p:
        system = build_system(scene, triangulation, level)
        p.detail = f"level {level}: {len(system.mesh.points)} nodes, {system.n_dofs} dofs of the P1 displacement"
    t1 = time.perf_counter()
    with phase("assemble", deadline) as p:
        space = EquilibriumSpace.from_mesh(system.mesh)
        p.detail = f"equilibrium space: {space.n_y} stress unknowns on {3 * space.n_tri} sub-triangles"
    t2 = time.perf_counter()
    if not np.any(system.f) and np.all(system.eps >= 0):
        # nothing acts: zero stresses and displacements are the solution (see solve())
        u = np.zeros(system.n_dofs)
        sigma = np.zeros((3 * space.n_tri, 3, 3))
        info = {"solver": "none (no load, no interference)", "status": "optimal", "iterations": 0}
    else:
        name = "fast path" if solver == FAST else solver
        with phase("solve", deadline, start=f"the P1 displacement, then the equilibrium stresses ({name})") as p:
            try:
                start = warm_start_active(scene, triangulation, level, system.mesh.pair_x) if warm_start else None
                u, p0_info = solve_fast(system, start)
                pairs = (system.mesh.pair_x, p0_info["active"])
            except SolverError:
                if solver == FAST:
                    raise
                from .p0.dual import DualModel  # the CVXPY path was asked for: it gives the P1 displacement too
                model = DualModel(system)
                model.solve(solver, time_limit=deadline.remaining() if solver in TIME_LIMIT_OPTION else None)
                u, pairs = model.displacements(), None
            if solver != FAST:
                solver_options = {"time_limit": deadline.remaining() if solver in TIME_LIMIT_OPTION else None,
                                  "verbose": verbose, **solver_options}
            sigma, info = solve_eq(space, solver, pairs, **solver_options)
            p.detail = f"{info.get('solver')}: {info.get('status')}, iterations {info.get('iterations')}"
    t3 = time.perf_counter()
    with phase("recover", deadline) as p:
        times = {"mesh": t1 - t0, "assemble": t2 - t1, "build": 0.0, "solve": t3 - t2}
        sol = _eq_solution(scene, triangulation, level, system, space, sigma, u, info, times)
        p.detail = "exact admissibility, certified bounds" + (", error against the exact field" if sol.error else "")
    if check:
        check_solution(sol)
    return sol


def _eq_solution(scene, triangulation, level, system, space, sigma, u, info, times: dict) -> Solution:
    """The eq run's :class:`Solution`: bounds, residuals and errors of ``sigma`` and ``u``; ``times``
    of the phases before (the recovery's and the total are added)."""
    t3 = time.perf_counter()
    from .eq.bounds import certified_bounds, constraint_blocks, contact_slack, exact_errors, residuals
    from .reference.exact import exact_field
    blocks = constraint_blocks(space)
    b = certified_bounds(space, sigma, u.reshape(-1, 2), blocks=blocks)
    v = b["displacement"]
    res = residuals(space, sigma, blocks)
    sc = space.scales
    delta = max(float(np.abs(v).max()), float(np.abs(system.eps).max()), sc.displacement)
    _, smin, _ = contact_slack(space, v)
    res = {"admissibility": max(res.values()), **res,
           "penetration": float(max(0.0, -smin.min(initial=0.0)) / delta)}
    exact = exact_field(scene)
    error = None
    t_err = time.perf_counter()
    if exact is not None:
        e = exact_errors(space, sigma, v, exact)
        error = {"l2": e["l2"], "l2_rel": e["l2_rel"], "energy": e["stress_A"],
                 "energy_rel": e["stress_A"] / e["reference_A"], "combined": e["combined"],
                 "displacement_energy": e["displacement_a"],
                 "effectivity": b["error_bound"] / e["combined"] if e["combined"] > 0 else None}
    t4 = time.perf_counter()
    t_err = t4 - t_err
    energy = max(abs(b["energy_upper"]), abs(b["energy_lower"]), sc.energy * 1e-12)
    return Solution(scene=scene, triangulation=triangulation, stress_space="eq", level=int(level), system=system,
                   stress=sigma, displacement=v, solver=info,
                   timings={**times, "recover": t4 - t3, "error": t_err, "total": sum(times.values()) + t4 - t3},
                   objective=-b["energy_lower"], duality_gap=b["gap"] / energy, residuals=res,
                   contact=eq_contact(space, system, sigma, v, blocks),
                   exact=exact.data() if exact is not None else None, error=error, bounds=b, space=space)
