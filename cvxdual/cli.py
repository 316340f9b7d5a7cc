"""Command line interface: ``cvxdual scenes``, ``cvxdual solve``, ``cvxdual study ...``.

Errors of cvxdual print one line (``cvxdual: error: ...``) and exit with status 1.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
import warnings
from contextlib import contextmanager, redirect_stdout
from pathlib import Path

import numpy as np

from .convex.solvers import LARGE_QP
from .errors import CvxdualError, ToleranceError
from .progress import check_time_limit, log, phase
from .validate import one_line

MAX_MESSAGE = 400  # characters of an error line: a sentence, never a dump of the input


def _fmt(v, spec=".4g"):
    return "-" if v is None else format(v, spec)


def _exactness(admissibility: float) -> str:
    """How the summary calls an eq residual: the bounds' own threshold, so the two never disagree."""
    from .eq.bounds import ADMISSIBLE_TOL
    return "exact to rounding" if admissibility <= ADMISSIBLE_TOL else f"over the {ADMISSIBLE_TOL:.0e} held exact"


def human_summary(sol, written=(), t_write: float | None = None) -> str:
    s = sol.summary()
    L, S = sol.scene.units
    c, r, t = s["contact"], s["residuals"], s["timings"]
    lines = [
        f"scene {s['scene']}, {s['triangulation']}, {sol.mesh_name}: {s['n_pieces']} pieces, "
        f"{s['n_stress_unknowns']} stress unknowns, {s['n_dofs']} dofs, {s['n_contact_pairs']} contact pairs",
        f"solver {s['solver']}: {s['status']}, iterations {s['iterations']}; time {t['total']:.2f} s "
        f"(mesh {t['mesh']:.2f}, assemble {t['assemble']:.2f}, build {t['build']:.2f}, "
        f"solve {t['solve']:.2f}, recover {t['recover']:.2f})"
        + (f"; gmsh {t['gmsh']:.2f} s (its size probe and warm start included)" if "gmsh" in t else ""),
        f"contact: {c['n_active']} active pairs, x in [{_fmt(c['x_min'])}, {_fmt(c['x_max'])}] {L}, "
        f"max pressure {_fmt(c['max_pressure'])} {S}, total force {_fmt(c['total_force'])} {S}*{L}",
        (f"residuals: equilibrium {r['equilibrium']:.1e}, constitutive {r['constitutive']:.1e}, "
         f"complementarity {r['complementarity']:.1e}; duality gap {s['duality_gap']:.1e}" if "complementarity" in r
         else f"residuals: admissibility {r['admissibility']:.1e} ({_exactness(r['admissibility'])}), penetration "
         f"{r['penetration']:.1e}; relative gap G {s['duality_gap']:.1e}"),
    ]
    if sol.scene.friction is not None:
        k = sol.contact
        slipping = int((k["active"] & ~k["stick"] & (k["slip"] != 0)).sum())
        lines.append(f"friction: Tresca g = {_fmt(sol.scene.friction.g)} {S}; {int(k['stick'].sum())} active pairs "
                     f"stick, {slipping} slip; largest tangential force {_fmt(np.abs(k['tangential_force']).max())} "
                     f"{S}*{L}")
    skipped = dict(s["checks_skipped"])
    no_error = skipped.pop("error", None)
    for name, why in skipped.items():
        lines.append(f"not checked: {name} ({why})")
    if s["fallback"]:
        lines.append(f"note: {s['fallback']}")
    if s["exact"] and s["exact"].get("kind") == "hertz":
        e = s["exact"]
        lines.append(f"Hertz: a = {e['a']:.4g} {L}, p0 = {e['p0']:.4g} {S}")
    if s["error"]:
        e = s["error"]
        lines.append(f"error against the exact stress: L2 {e['l2']:.3e} (relative {e['l2_rel']:.2e}), "
                     f"energy relative {e['energy_rel']:.2e}")
    elif no_error:
        lines.append(f"no error against the exact stress: {no_error}")
    if s["bounds"]:
        b = s["bounds"]
        lines.append(f"certified bounds: {b['energy_lower']:.6g} <= J(u) <= {b['energy_upper']:.6g}; "
                     f"error bound sqrt(2G) = {b['error_bound']:.3g}"
                     + ("" if b["error_bound_rel"] is None else f" ({b['error_bound_rel']:.3%} of the stress's energy "
                        f"norm, {b['kinematic'].upper()} displacement)")
                     + ("" if b["guaranteed"] else f" (not guaranteed: {'; '.join(b['reasons'])})"))
    if sol.adaptive is not None:
        h = sol.adaptive
        lines.append(f"adaptive: {len(h.cycles)} cycles to a certified {100 * h.tol:.3g} % ({h.state}); this is cycle "
                     f"{h.chosen}: {h.cycles[h.chosen].pieces} pieces, {100 * h.cycles[h.chosen].bound_rel:.3g} %; "
                     f"{h.cycles[-1].elapsed:.2f} s in all")
    if written:
        took = "" if t_write is None else f" in {t_write:.2f} s"
        lines.append(f"wrote {Path(written[0]).parent}/{took}: " + ", ".join(Path(w).name for w in written))
    return "\n".join(lines)


def _cmd_scenes(args) -> int:
    from .scene.scenefile import builtin_scenes
    for name, desc in builtin_scenes().items():
        print(f"{name:20s} {desc}")
    return 0


def _cmd_solve(args) -> int:
    from .convex.solvers import resolve_solver
    from .files import sweep_leftovers
    from .geometry.triangulation import check_triangulation
    from .outputs.figures import Plot, names_plot, parse_plots
    from .outputs.output_set import check_output_dir, write_outputs
    from .pipeline import solve, space_of
    from .scene.scenefile import load_scene, parse_assignment
    from .validate import file_stem

    plots = parse_plots(args.plots)  # an unknown figure name: one error line before any work
    stress_space = args.stress_space or ("eq" if args.tol is not None else "p0")
    if names_plot(args.plots, Plot.BOUNDS) and not (args.bounds or args.tol is not None
                                                     or space_of(stress_space).certifies):
        raise CvxdualError("--plots bounds needs certified bounds: add --bounds or --stress-space eq")
    if names_plot(args.plots, Plot.CYCLES) and args.tol is None:
        raise CvxdualError("--plots cycles draws a run to a tolerance: add --tol")
    time_limit = check_time_limit(args.time_limit)
    # the hard stop covers reading the scene too (bounded work: a .geo file is read, never run)
    hard_stop = _hard_stop(time_limit if args.own_process else None, fast=str(args.solver).upper() == "FAST")
    with _solver_log_on_stderr(args.verbose), hard_stop:
        scene = load_scene(args.scene, [parse_assignment(s) for s in args.set])
        solver = None if args.solver is None else resolve_solver(args.solver)
        check_triangulation(args.triangulation)
        out = None if args.no_output else Path(args.out or Path("out") / file_stem(scene.name))
        if out is not None:
            # fail before the work, and create nothing until there are results; but free the space of
            # killed runs' leftovers now, not after a solve that may take minutes
            sweep_leftovers(check_output_dir(out))
        unmet = None
        try:
            sol = solve(scene, args.triangulation, args.level, solver, stress_space=stress_space, bounds=args.bounds,
                        max_memory=args.max_memory, time_limit=time_limit, verbose=args.verbose,
                        kinematic=args.kinematic, tol=args.tol, max_pieces=args.max_pieces,
                        theta=args.theta)
        except ToleranceError as e:  # the tolerance was not met: its best certified result is written
            sol, unmet = e.solution, e
    written, t_write = [], None
    if out is not None:
        with phase("write", start=f"outputs to {out}/" if plots else None) as p:
            written = write_outputs(sol, out, plots=plots)
            p.detail = f"{len(written)} files"
        t_write = p.seconds
    print(human_summary(sol, written, t_write))
    if unmet is not None:
        raise unmet
    return 0


HARD_STOP_GRACE = 1.0  # seconds past --time-limit for the run to stop itself before the process is ended


@contextmanager
def _hard_stop(time_limit: float | None, fast: bool):
    """The time limit's last resort on the command line. ``solve`` stops itself at the limit
    (:mod:`cvxdual.progress`), but not inside compiled code that holds on: SCS's setup on a
    level-6 QP factorises for about 13 s. The solvers release the GIL, so a timer thread can
    end the process then, with the one error line; nothing has been written at that point.
    Only where :func:`main` owns the process (called without ``argv``)."""
    if time_limit is None:
        yield
        return

    def stop():
        _fail(f"stopped at the time limit of {time_limit:g} s inside compiled code (a solver or a factorisation), "
              "which cannot be interrupted; " + ("raise --time-limit or lower --level" if fast else
                                                 "raise --time-limit, lower --level or use --solver fast"))
        sys.stderr.flush()
        os._exit(1)

    timer = threading.Timer(time_limit + HARD_STOP_GRACE, stop)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


@contextmanager
def _solver_log_on_stderr(on: bool):
    """With ``on``, the solvers' logs go to stderr, apart from the summary on stdout: ``sys.stdout``
    (Clarabel prints through it) and file descriptor 1 (SCS and OSQP print from C)."""
    if not on:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        with redirect_stdout(sys.stderr):
            yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _cmd_study(args) -> int:
    from .study.command import main as study_main
    return study_main(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cvxdual", description="Dual finite element analysis of frictionless "
                                "(or Tresca) contact of two plane elastic bodies (Tran Van Bon 1986) on CVXPY.")
    import cvxdual  # the package's version: pyproject.toml's, as installed
    p.add_argument("--version", action="version", version=f"cvxdual {cvxdual.__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("scenes", help="list the built-in scenes").set_defaults(func=_cmd_scenes)
    s = sub.add_parser("solve", help="solve a scene and write its outputs")
    s.add_argument("--scene", default="hertz", help="built-in scene name or path to a .toml file (default: hertz)")
    s.add_argument("--triangulation", default="type1", help="type1 (Haslinger-Hlavacek) or type2 "
                   "(Hlavacek-Krizek) (default: type1)")
    s.add_argument("--level", type=int, default=None, help="mesh level, h halves per level (default: the scene's); "
                   "with --tol the first cycle's (default: the lowest the scene meshes at)")
    s.add_argument("--tol", default=None, metavar="TOL",
                   help="solve to a certified relative energy error, e.g. 1%% or 0.01: refine where the bound's "
                   "contributions are, cycle by cycle, until it holds (docs/adaptive.md); implies --stress-space eq "
                   "unless p0 is named (then p0 certified by --bounds)")
    s.add_argument("--max-pieces", type=int, default=None, metavar="N",
                   help="with --tol: stop before a cycle with more pieces (default: 400000); the best certified "
                   "result is written and the exit status is 1")
    s.add_argument("--theta", default=None, metavar="THETA",
                   help="with --tol: Dorfler's fraction of the bound's G marked for refinement each cycle "
                   "(default: 0.5; smaller marks less a cycle and takes more cycles)")
    s.add_argument("--solver", default=None, help="a CVXPY solver name, or fast: the active-set path (default: "
                   f"the CVXPY solver measured fastest at the mesh's size, CLARABEL below {LARGE_QP:.0e} pieces and "
                   "SCS above, Clarabel taking over where SCS fails; with --stress-space eq the fast path)")
    s.add_argument("--stress-space", default=None, choices=("p0", "eq"),
                   help="p0: the paper's piecewise-constant stresses; eq: exactly admissible equilibrium "
                   "stresses with certified bounds, frictionless (default: p0, with --tol eq)")
    s.add_argument("--bounds", action="store_true", help="with p0: also certify the displacement against "
                   "equilibrium stresses on the same mesh")
    s.add_argument("--kinematic", default="p2", choices=("p1", "p2"),
                   help="the displacement of the bounds' upper side: p2, continuous P2 on the barycentric split "
                   "(sharp, free of locking), or p1, the P1 displacement of the fast path (default: p2)")
    s.add_argument("--out", default=None, help="output directory (default: out/<scene>)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set mesh.grading=4 (repeatable)")
    s.add_argument("--max-memory", default=None, metavar="SIZE",
                   help="refuse runs estimated to need more memory, e.g. 16GB, or 'none' (default: the memory "
                   "available, or $CVXDUAL_MAX_MEMORY)")
    s.add_argument("--time-limit", default=None, metavar="SECONDS",
                   help="stop a run that takes longer (meshing to recovery; writing is not counted), with an error")
    talk = s.add_mutually_exclusive_group()
    talk.add_argument("--quiet", action="store_true", help="no progress lines on stderr (warnings and errors only)")
    talk.add_argument("--verbose", action="store_true", help="also the solver's own log and the fast path's "
                      "iterations, on stderr")
    from .outputs.figures import plot_names  # no matplotlib: that loads only to draw
    s.add_argument("--plots", nargs="?", const=True, default=None, metavar="NAMES",
                   help="also draw figures: alone, the default set (stress, deformed, pressure, bounds where "
                   f"computed, cycles with --tol); or comma-separated names from {plot_names()}, or all (each "
                   "NAME.png); "
                   "matplotlib's import and drawing cost more than a whole small run (default: --no-plots)")
    s.add_argument("--no-plots", dest="plots", action="store_const", const=None, help="draw no figures (the default)")
    s.add_argument("--no-output", action="store_true", help="print the summary only, write nothing")
    s.set_defaults(func=_cmd_solve)
    from .study.command import add_parser as add_study_parser
    add_study_parser(sub).set_defaults(func=_cmd_study)
    return p


def main(argv=None) -> int:
    """The command line; ``argv`` (default: ``sys.argv[1:]``) without the program name. Called
    without ``argv`` (the console script, ``python -m cvxdual.cli``) it may end the process at
    ``--time-limit`` (:func:`_hard_stop`); called with a list (from Python) it returns instead."""
    parser = build_parser()
    args = parser.parse_args(argv)
    args.own_process = argv is None
    with warnings.catch_warnings(record=True) as caught, _progress(args):
        warnings.simplefilter("always")
        try:
            status = args.func(args)
        except CvxdualError as e:
            return _fail(e.cli or str(e))
        except MemoryError:
            return _fail("ran out of memory; lower --level or free memory (see --max-memory)")
        except RecursionError:
            return _fail("the input is nested too deeply to process")
        except KeyboardInterrupt:
            print("cvxdual: interrupted", file=sys.stderr)
            return 130
        except BrokenPipeError:  # the reader of stdout left (`cvxdual solve | head -2`): nothing to report
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # Python's own advice for SIGPIPE
            return 0
    # a run that worked: its warnings, each once
    for text in dict.fromkeys(one_line(w.message, MAX_MESSAGE) for w in caught):
        print(f"cvxdual: warning: {text}", file=sys.stderr)
    return status


class _ProgressLines(logging.Handler):
    """The progress records (the logger ``cvxdual``, :mod:`cvxdual.progress`) of every running
    :func:`main` on stderr as ``cvxdual: ...``, each thread's at the level its run asked for.
    While any run is active the logger passes everything to this handler alone (a caller's
    root handlers would print the lines twice); the last run to end restores it."""

    def __init__(self):
        super().__init__()
        self.levels: dict[int, int] = {}  # thread -> level of its run
        self.runs_lock = threading.Lock()
        self.saved = (logging.NOTSET, True)

    def filter(self, record) -> bool:
        level = self.levels.get(record.thread)
        return level is not None and record.levelno >= level

    def emit(self, record) -> None:
        print(f"cvxdual: {record.getMessage()}", file=sys.stderr, flush=True)

    @contextmanager
    def run(self, level: int):
        me = threading.get_ident()
        with self.runs_lock:
            if not self.levels:
                self.saved = (log.level, log.propagate)
                log.setLevel(logging.DEBUG)
                log.propagate = False
                log.addHandler(self)
            self.levels[me] = level
        try:
            yield
        finally:
            with self.runs_lock:
                del self.levels[me]
                if not self.levels:
                    log.removeHandler(self)
                    log.setLevel(self.saved[0])
                    log.propagate = self.saved[1]


_PROGRESS = _ProgressLines()


@contextmanager
def _progress(args):
    """Progress lines on stderr while ``main`` runs: INFO, DEBUG with ``--verbose``, none with ``--quiet``."""
    if getattr(args, "quiet", False) or args.command != "solve":
        yield
        return
    with _PROGRESS.run(logging.DEBUG if args.verbose else logging.INFO):
        yield


def _fail(message: str) -> int:
    """One line on stderr and exit status 1 (warnings that led up to the error are dropped)."""
    print(f"cvxdual: error: {one_line(message, MAX_MESSAGE)}", file=sys.stderr)
    return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
