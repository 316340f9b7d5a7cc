"""The entry points from a scene to a solution or a model: :func:`solve`, :func:`build_model`,
:func:`build_system` (docs/theory.md).

``solve(scene)`` checks the request, estimates its memory, and runs it in its stress space
(:func:`space_of` maps a name to its :class:`~cvxdual.system.stress_space.StressSpace`: the paper's
:class:`~cvxdual.p0.run.P0Stresses` or :class:`~cvxdual.eq.run.EquilibriumStresses`); here is the policy that
hands a failed fast path (or a failed default solver) over to Clarabel, and the bounds of a
P0 run (the equilibrium space's ``certify``).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from functools import partial
from pathlib import Path

from .convex.solvers import DEFAULT_SOLVER, FAST, resolve_solver
from .errors import AccuracyError, CvxdualError, SceneError, SolverError, TooLargeError
from .geometry.mesh import check_level, mesh_size
from .geometry.outline import gmsh_seconds
from .geometry.triangulation import check_triangulation, discretize
from .kinds import Space
from .p0.run import P0Stresses  # at import: SciPy's sparse solvers load with cvxdual, not in a solve
from .progress import Deadline, phase
from .scene import Scene
from .sizing import check_mesh_size, check_size
from .solution import Solution
from .system.assembly import System, assemble
from .system.kinematic import kinematic_side
from .system.stress_space import StressSpace
from .validate import integer, one_line, short

log = logging.getLogger(__name__)

def space_of(name, kinematic: str = "p2") -> StressSpace:
    """The :class:`~cvxdual.system.stress_space.StressSpace` named ``name`` (:meth:`Space.parse`); the
    equilibrium space's certificate on the kinematic side ``kinematic`` (``"p2"`` or ``"p1"``)."""
    side = kinematic_side(kinematic)
    if Space.parse(name) is Space.P0:
        return P0Stresses()
    from .eq.run import EquilibriumStresses  # the equilibrium space loads on first use
    return EquilibriumStresses(side)


def as_scene(scene) -> Scene:
    """A :class:`Scene`, or a built-in scene name, a .toml path or a scene dict loaded as one."""
    if isinstance(scene, Scene):
        return scene
    if not isinstance(scene, (str, Path, dict)):
        raise SceneError(f"expected a Scene, a built-in scene name or a .toml path, got {type(scene).__name__}")
    from .scene.scenefile import load_scene
    return load_scene(scene)


def build_system(scene, triangulation: str = "type1", level: int | None = None) -> System:
    """Mesh and assemble ``scene``: the :class:`~cvxdual.system.assembly.System` of the discrete problem."""
    scene = as_scene(scene)
    return assemble(*discretize(scene, check_triangulation(triangulation), level))


def build_model(scene, triangulation: str = "type1", level: int | None = None, limit_analysis: bool = False,
                stress_space: str = "p0"):
    """Mesh, assemble and build the CVXPY dual of ``scene`` without solving it: a
    :class:`~cvxdual.p0.dual.DualModel` (with the scene's friction, if it has any), or with
    ``stress_space="eq"`` an :class:`~cvxdual.eq.model.EquilibriumModel` (frictionless)."""
    scene = as_scene(scene)
    triangulation = check_triangulation(triangulation)
    space = space_of(stress_space)
    if scene.friction is not None and not space.frictional:
        raise CvxdualError(f"the {space.name} stress space is frictionless; drop the scene's friction or use "
                           "stress_space='p0'")
    return space.model(build_system(scene, triangulation, level), triangulation, limit_analysis)


def solve(scene, triangulation: str = "type1", level: int | None = None, solver: str | None = None,
          check: bool = True, warm_start: bool = True, stress_space: str | None = None, bounds: bool = False,
          max_memory=None, fallback: bool = True, time_limit: float | None = None, verbose: bool = False,
          kinematic: str = "p2", tol=None, max_pieces: int | None = None, theta=None, **solver_options) -> Solution:
    """Solve the discrete dual problem of ``scene``; see the module docstring.

    ``solver`` is a CVXPY solver name or ``"fast"``, the active-set path of :mod:`cvxdual.activeset`
    (warm-started from level ``level - 2`` unless ``warm_start`` is false). By default (no
    solver and no options) the CVXPY solver measured fastest at the mesh's size
    (:func:`cvxdual.convex.solvers.default_solver`: Clarabel, SCS from 2e4 pieces; for
    ``stress_space="eq"`` the fast route), handing over to Clarabel where it fails; options alone
    go to Clarabel.
    ``stress_space`` is ``"p0"`` (the paper's; the default) or ``"eq"`` (exactly admissible equilibrium
    stresses, column stresses on curved pieces, with certified bounds; docs/equilibrium.md). ``bounds`` also
    certifies a ``p0`` run (its displacement against the equilibrium stresses of the same mesh).
    ``kinematic`` is the displacement the bounds' upper side uses: ``"p2"`` (continuous P2 on the
    Alfeld split, sharp and free of locking; the default) or ``"p1"`` (the P1 displacement of the
    fast path, for comparison).
    ``check`` false returns solutions that fail the accuracy checks (for studies of them).
    Where the fast path (or the default solver) fails (its checks, a cycling active set), the
    CVXPY path with Clarabel solves instead, unless ``fallback`` is false; ``solution.solver.fallback``
    (and ``summary.json``) then says why.
    The run's memory is estimated first and refused above ``max_memory`` (bytes or ``"16GB"``;
    default: the memory available, see :mod:`cvxdual.sizing`) with
    :class:`~cvxdual.errors.TooLargeError`.
    ``time_limit`` (seconds) bounds the whole run (:mod:`cvxdual.progress`): past it the run
    stops with :class:`~cvxdual.errors.TimeLimitError`. ``verbose`` prints the CVXPY solver's
    own log. Progress is logged to the logger ``"cvxdual"`` (INFO; the fast path's iterations
    at DEBUG).
    ``tol`` (``0.01`` or ``"1%"``) solves to a certified tolerance instead of at one level
    (:mod:`cvxdual.adapt`, docs/adaptive.md): cycles of solve, certify, mark and refine from a coarse
    mesh (``level``, if given, is the first cycle's) until the certified relative energy error is at
    most ``tol``; the solution's ``adaptive`` holds every cycle. ``theta`` is Dorfler's fraction of
    ``G`` marked each cycle (default 0.5). Where ``max_pieces`` (default 400000), the memory or
    ``time_limit`` stop it first,
    :class:`~cvxdual.errors.ToleranceError` is raised with the best certified solution as its
    ``solution``.
    """
    deadline = Deadline(time_limit)
    deadline.fast = str(solver).upper() == FAST  # the advice of a time-out before the solver is resolved
    if tol is not None:
        with deadline.enforced():
            return _solve_to(deadline, scene, triangulation, level, solver, stress_space or Space.EQ, max_memory,
                             kinematic, tol, max_pieces, theta, warm_start)
    for name, value, does in (("max_pieces", max_pieces, "bounds"), ("theta", theta, "marks the cycles of")):
        if value is not None:  # an option of a run to a tolerance, without tol
            flag = "--" + name.replace("_", "-")
            raise CvxdualError(f"{name} {does} a run to a tolerance: give tol too, or drop it",
                               cli=f"{flag} {does} a run to a tolerance: give --tol too, or drop it")
    with deadline.enforced():  # from the start: the size probe's meshes count too
        return _solve(deadline, scene, triangulation, level, solver, check, warm_start, stress_space or Space.P0,
                      bounds, max_memory, fallback, verbose, kinematic, solver_options)


def _solve(deadline, scene, triangulation, level, solver, check, warm_start, stress_space, bounds, max_memory,
           fallback, verbose, kinematic, solver_options) -> Solution:
    scene = as_scene(scene)
    gmsh0 = gmsh_seconds()
    chosen = solver is None and not solver_options  # options name their solver: Clarabel's, as always
    triangulation = check_triangulation(triangulation)
    space = space_of(stress_space, kinematic)
    level = check_level(scene.mesh.default_level if level is None else level)
    if scene.friction is not None:
        if not space.frictional or bounds:
            raise CvxdualError("the equilibrium stress space and the bounds are frictionless; drop the scene's "
                               "friction or solve with stress_space='p0' and no bounds",
                               cli="the equilibrium stress space and the bounds are frictionless; drop the scene's "
                                   "friction or solve without --stress-space eq and --bounds")
        if str(solver).upper() == FAST:
            raise SolverError("the fast path is frictionless; the scene has friction: use solver='CLARABEL'",
                              cli="the fast path is frictionless; the scene has friction: use --solver CLARABEL")
        if chosen:
            solver = DEFAULT_SOLVER  # friction rows measured with Clarabel only
    if chosen and scene.friction is None:
        solver = space.default_solver(mesh_size(scene, level)["triangles"])
    solver = resolve_solver(solver)
    deadline.fast = solver == FAST
    if solver == FAST and solver_options:
        raise SolverError(f"the fast path takes no solver options, got {', '.join(sorted(solver_options))}; "
                          "drop them or choose a CVXPY solver such as CLARABEL")
    check_size(scene, level, solver == FAST, space.name, bounds, max_memory, kinematic)
    attempt = partial(_attempt, scene, triangulation, level, space, bounds, kinematic, check=check,
                      warm_start=warm_start, deadline=deadline, verbose=verbose)
    try:
        try:
            return _gmsh_timed(attempt(solver, **solver_options), scene, gmsh0)
        except (SolverError, AccuracyError) as e:
            if not fallback or not (solver == FAST or (chosen and solver != DEFAULT_SOLVER)):
                raise
            deadline.check()  # no time left for another solver
            # the fast path (or the size's default) failed where Clarabel may not: hand over, say so
            reason = one_line(e.reason or e, 120)  # its advice (use Clarabel) is what follows
            name = "the fast path" if solver == FAST else solver
            try:
                check_size(scene, level, False, space.name, bounds, max_memory, kinematic)
                log.info("%s failed (%s); solving with %s", name, reason, DEFAULT_SOLVER)
                sol = attempt(DEFAULT_SOLVER)
            except CvxdualError as e2:  # both paths failed: both reasons, short, and what is left to try
                if e2.reason is None:  # not a solver's failure (memory, time): its own advice stands
                    both = f"{name} failed ({one_line(e.reason or e, 60)}), then {DEFAULT_SOLVER}: "
                    raise type(e2)(both + str(e2), cli=both + (e2.cli or str(e2))) from None
                if e2.reason == e.reason:  # the same obstacle (the mesh's), with its own advice
                    raise e2 from None
                both = f"{name} failed ({one_line(e.reason or e, 60)}), then {one_line(e2.reason, 80)}"
                raise type(e2)(f"{both}; try a lower level", cli=f"{both}; lower --level",
                               reason=both) from None
            sol = replace(sol, solver=sol.solver.replace(fallback=f"{name} failed ({reason}); "
                                                                f"solved by {DEFAULT_SOLVER}"))
            return _gmsh_timed(sol, scene, gmsh0)
    except MemoryError:
        what = f"ran out of memory solving {short(scene.name, 40)} at level {level}"
        raise TooLargeError(f"{what}; lower the level or free memory",
                            cli=f"{what}; lower --level or free memory") from None


def _solve_to(deadline, scene, triangulation, level, solver, stress_space, max_memory, kinematic, tol, max_pieces,
              theta, warm_start) -> Solution:
    """A run to the certified tolerance ``tol`` (:func:`~cvxdual.adapt.cycles.refine_to_tolerance`)."""
    from .adapt.cycles import MAX_PIECES, Plan, refine_to_tolerance
    from .adapt.marking import THETA, parse_theta, parse_tolerance
    from .adapt.outline_view import outline_scene

    scene = outline_scene(as_scene(scene))  # local refinement: every body meshed by its outline
    gmsh0 = gmsh_seconds()
    triangulation = check_triangulation(triangulation)
    space = space_of(stress_space, kinematic)
    plan = Plan(tol=parse_tolerance(tol), theta=parse_theta(THETA if theta is None else theta),
                max_pieces=_max_pieces(MAX_PIECES if max_pieces is None else max_pieces),
                level=None if level is None else check_level(level))
    if scene.friction is not None:
        raise CvxdualError("a run to a tolerance is certified, and the bounds are frictionless; drop the scene's "
                           "friction or solve at a level without tol",
                           cli="--tol is certified, and the bounds are frictionless; drop the scene's friction or "
                               "solve at a --level without --tol")
    solver = resolve_solver(FAST if solver is None else solver)
    deadline.fast = solver == FAST
    certify = (lambda sol: sol) if space.certifies else partial(_bounds_of, kinematic=kinematic, deadline=deadline)
    sol = refine_to_tolerance(
        lambda grid: space.run(scene, triangulation, grid, solver, warm_start=warm_start, deadline=deadline,
                               exact_error=False),
        certify, scene, plan, deadline,
        partial(check_mesh_size, fast=solver == FAST, stress_space=space.name, bounds=True, kinematic=kinematic,
                max_memory=max_memory),
        lambda level: check_size(scene, level, solver == FAST, space.name, True, max_memory, kinematic),
        finish=space.with_exact_error)
    return _gmsh_timed(sol, scene, gmsh0)


def _max_pieces(value) -> int:
    try:
        return integer(value, "max_pieces", minimum=1)
    except SceneError as e:  # not the scene's: a plain CvxdualError, named as the caller gave it
        raise CvxdualError(str(e), cli=str(e).replace("max_pieces", "--max-pieces", 1)) from None


def _gmsh_timed(sol: Solution, scene: Scene, before: float) -> Solution:
    """``sol`` with ``timings["gmsh"]`` when the scene has outline bodies: gmsh's wall time in the
    whole call (the size probe and the warm start's coarse meshes too; it overlaps the phases)."""
    if all(b.is_column for b in scene.bodies):
        return sol
    return replace(sol, timings={**sol.timings, "gmsh": gmsh_seconds() - before})


def _attempt(scene: Scene, triangulation: str, level: int, space: StressSpace, bounds: bool, kinematic: str,
             solver: str, **options) -> Solution:
    """One run with ``solver`` in ``space``, and bounds where asked for and the space gives none."""
    sol = space.run(scene, triangulation, level, solver, **options)
    return _bounds_of(sol, kinematic, options.get("deadline")) if bounds and not space.certifies else sol


def _bounds_of(sol: Solution, kinematic: str, deadline) -> Solution:
    """``sol`` (a P0 run) certified against the equilibrium stresses of its mesh (phase ``bounds``)."""
    with phase("bounds", deadline) as p:
        sol = space_of(Space.EQ, kinematic).certify(sol)
        side = kinematic_side(kinematic).name.upper()
        p.detail = f"the {side} displacement against the equilibrium stresses of the same mesh"
    return sol
