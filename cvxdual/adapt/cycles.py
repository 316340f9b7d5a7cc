"""Solve to a certified tolerance: cycles of solve, certify, mark, refine (docs/adaptive.md).

Each cycle is a whole run on an adaptive :class:`~cvxdual.geometry.grid.Grid` (the P1 fast path,
the equilibrium stresses, the kinematic side's certificate), warm-started from the last cycle's
contact set; the error against an exact field, which no cycle needs, is left to the solution
kept. The loop stops when ``sqrt(2 G)`` relative to the stress's energy norm is at most the
tolerance; before a cycle that would exceed ``max_pieces`` or the memory limit, past the time
limit, or when nothing is left to refine, it stops with :class:`~cvxdual.errors.ToleranceError`,
which carries the best certified solution so far.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

from ..errors import CvxdualError, MeshError, TimeLimitError, ToleranceError, TooLargeError
from ..geometry.grid import Grid, InPlace
from ..geometry.triangulation import uniform_grid
from ..kinds import Meshed, Stop
from ..progress import Deadline, log, phase
from ..records import AdaptiveHistory, Cycle
from .marking import THETA, mark

ZERO_GAP = 1e-12  # G below this many energy units (stress^2 length^2 / modulus) is rounding: a zero solution
MAX_PIECES = 400_000  # the default cap: about 2.7 GB with the P2 certificate (sizing.BYTES_PER_TRIANGLE)
START_LEVELS = 4  # the first cycle meshes at the lowest of levels 0-3 that the scene allows


@dataclass(frozen=True)
class Plan:
    """What a run to a tolerance asks: the tolerance ``tol`` (relative, 0.01 for 1 %), Dorfler's
    ``theta``, ``max_pieces`` and the start ``level`` (None: the lowest that meshes)."""

    tol: float
    theta: float = THETA
    max_pieces: int = MAX_PIECES
    level: int | None = None


def first_cycle(solve, scene, level: int | None, check_level=lambda level: None):
    """The first cycle's grid and its solution ``solve(grid)``: at ``level``, or at the lowest level the
    scene meshes at (a coarse level may have too few contact pairs, or a face too curved for its first
    layer; the solve's meshing is the test); ``check_level(level)`` refuses a level too large for memory
    before it is meshed (:func:`~cvxdual.sizing.check_size`)."""
    levels = [level] if level is not None else list(range(START_LEVELS))
    for lv in levels:
        try:
            check_level(lv)  # its size probe meshes outline bodies: a level they cannot be meshed at fails here
            grid = uniform_grid(scene, lv)
            return grid, solve(grid)
        except MeshError:
            if lv == levels[-1]:
                raise
    raise AssertionError("unreachable")  # pragma: no cover


def refine_to_tolerance(run, certify, scene, plan: Plan, deadline: Deadline, memory_rows, check_level,
                        finish=lambda sol: sol):
    """The cycles: ``run(grid)`` solves on a grid, ``certify(sol)`` gives it bounds where its space
    does not; ``check_level(level)`` and ``memory_rows(n_triangles)`` refuse a first cycle and a later
    one too large for memory (:func:`~cvxdual.sizing.check_size`, :func:`~cvxdual.sizing.check_mesh_size`);
    ``finish(sol)`` completes the one solution kept (what no cycle needs: the error against an exact
    field). Returns the solution with its
    :class:`~cvxdual.records.AdaptiveHistory`, or raises :class:`ToleranceError` with the best."""
    t0 = time.perf_counter()
    grid = None
    cycles: list[Cycle] = []
    best = None
    stop = Stop.TOLERANCE
    while True:
        t = time.perf_counter()
        try:
            with deadline.caught():
                if grid is None:
                    grid, sol = first_cycle(lambda g: certify(run(g)), scene, plan.level, check_level)
                else:
                    sol = certify(run(grid))
                b = sol.bounds
                rel = _relative_bound(sol, len(cycles))
                met = rel <= plan.tol
                marks = nxt = None
                if not met:
                    with phase("refine", deadline) as p:  # a time-out here, too, keeps the best cycle
                        marks = mark(grid, sol.space, b["contributions"], plan.theta)
                        # a mesh gmsh made is refined in place; the next cycle's is meshed again (gmsh's quality
                        # back: a closure's cuts are not cut again)
                        again = (None if grid.in_place is not None
                                 else InPlace(sol.mesh.bodies, marks.rest, marks.arcs, grid.spots))
                        nxt = grid.refined(scene, marks.columns, marks.spots, again).with_start(
                            sol.mesh.pair_x, sol.contact["active"])
                        cols, spots = len(nxt.columns) - len(grid.columns), sum(map(len, nxt.spots))
                        p.detail = f"Dorfler: {marks.share:.0%} of G marked; {cols} columns more, {spots} spots"
        except TimeLimitError:
            if best is None:
                raise
            stop = Stop.TIME_LIMIT
            break
        now = time.perf_counter()
        cycles.append(Cycle(cycle=len(cycles), pieces=int(sol.field.n_pieces), triangles=len(sol.mesh.triangles()),
                            columns=len(grid.columns), energy_lower=float(b["energy_lower"]),
                            energy_upper=float(b["energy_upper"]), bound_rel=rel, guaranteed=bool(b["guaranteed"]),
                            marked_share=None if marks is None else marks.share,
                            meshed=tuple(bm.meshed for bm in sol.mesh.bodies), seconds=now - t, elapsed=now - t0))
        log.info("cycle %d: %d pieces%s, certified error %.3g %%%s, %.2f s", len(cycles) - 1, cycles[-1].pieces,
                 _how(sol.mesh.bodies), 100 * rel, "" if b["guaranteed"] else " (not guaranteed)", now - t)
        if best is None or rel <= best[1]:
            best = (sol, rel, len(cycles) - 1)
        if met:
            break
        if nxt.same_mesh(grid):
            stop = Stop.NO_REFINEMENT
            break
        # the next mesh, estimated before it is built: scaled as the strip's columns, twice that where
        # gmsh gets new spots (measured 1.1-1.6x)
        growth = _growth(grid, nxt)
        if growth * sol.field.n_pieces > plan.max_pieces:
            stop = Stop.MAX_PIECES
            break
        try:
            memory_rows(growth * len(sol.mesh.triangles()))
        except TooLargeError:
            stop = Stop.MEMORY
            break
        grid = nxt
    history = AdaptiveHistory(tol=float(plan.tol), theta=float(plan.theta), met=stop is Stop.TOLERANCE, stop=stop,
                              chosen=best[2], cycles=tuple(cycles))
    sol = replace(finish(best[0]), adaptive=history)
    if stop is not Stop.TOLERANCE:
        raise _unmet(sol, best[1], plan, stop)
    return sol


def _relative_bound(sol, cycle: int) -> float:
    """The cycle's certified relative error; where its stresses vanish, 0 if the bound does too (the
    solution is zero, exactly), and otherwise a refusal: a relative error has nothing to be relative
    to (a run that reported 0 % there had a bound of 0.33 in energy units, on a groove whose push went
    into its own support)."""
    b = sol.bounds
    if b["error_bound_rel"] is not None:
        return float(b["error_bound_rel"])
    if b["gap"] <= ZERO_GAP * sol.system.scales.energy:
        return 0.0
    what = (f"the equilibrium stresses vanish on cycle {cycle}'s mesh (no contact force, and the supports hold "
            f"every load) while the certified bound sqrt(2 G) is {b['error_bound']:.3g} (absolute): a relative "
            "error has nothing to be relative to")
    raise CvxdualError(f"{what}; solve at a level instead of to tol", cli=f"{what}; use --level instead of --tol")


def _how(bodies) -> str:
    """What the cycle's progress line says of its mesh: which bodies were refined in place (none: gmsh's)."""
    names = [bm.body.name for bm in bodies if bm.meshed is Meshed.IN_PLACE]
    if not names:
        return ""
    return " (refined in place)" if len(names) == len(bodies) else f" ({', '.join(names)} refined in place)"


def _growth(old: Grid, new: Grid) -> float:
    """How many times larger the mesh of ``new`` is than that of ``old``, estimated before it is built."""
    ratio = (len(new.columns) - 1) / (len(old.columns) - 1)
    spots = sum(len(s) for s in new.spots) > sum(len(s) for s in old.spots)
    return ratio * (2.0 if spots else 1.0)


def _unmet(sol, rel: float, plan: Plan, stop: Stop) -> ToleranceError:
    """The error of a run that stopped short of its tolerance, with advice for Python and the CLI."""
    n = plan.max_pieces
    why, fix = {  # (Python, CLI) each
        Stop.MAX_PIECES: ((f"the next cycle would pass max_pieces={n}", f"the next cycle would pass --max-pieces {n}"),
                          ("raise max_pieces", "raise --max-pieces")),
        Stop.MEMORY: (("the next cycle would not fit in memory",) * 2,
                      ("raise max_memory or free memory", "raise --max-memory or free memory")),
        Stop.TIME_LIMIT: (("the time limit ran out", "--time-limit ran out"),
                          ("raise time_limit", "raise --time-limit")),
        Stop.NO_REFINEMENT: (("no interval is left to split",) * 2, ("loosen tol", "loosen --tol")),
    }[stop]
    what = (f"certified error {100 * rel:.3g} % after {len(sol.adaptive.cycles)} cycles, above the tolerance "
            f"{100 * plan.tol:.3g} %")
    return ToleranceError(f"{what}: {why[0]}; {fix[0]} (the best result is the error's .solution)",
                          cli=f"{what}: {why[1]}; {fix[1]} (the best result is written)", solution=sol)
