"""Command line interface: ``cvxdual scenes``, ``cvxdual solve``, ``cvxdual study ...``.

Errors of cvxdual print one line (``cvxdual: error: ...``) and exit with status 1.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from .errors import CvxdualError
from .solvers import LARGE_QP
from .validate import one_line

MAX_MESSAGE = 400  # characters of an error line: a sentence, never a dump of the input


def _fmt(v, spec=".4g"):
    return "-" if v is None else format(v, spec)


def human_summary(sol, written=(), t_write: float | None = None) -> str:
    s = sol.summary()
    L, S = sol.scene.units
    c, r, t = s["contact"], s["residuals"], s["timings"]
    lines = [
        f"scene {s['scene']}, {s['triangulation']}, level {s['level']}: {s['n_pieces']} pieces, "
        f"{s['n_stress_unknowns']} stress unknowns, {s['n_dofs']} dofs, {s['n_contact_pairs']} contact pairs",
        f"solver {s['solver']}: {s['status']} in {s['iterations']} iterations; time {t['total']:.2f} s "
        f"(mesh {t['mesh']:.2f}, assemble {t['assemble']:.2f}, build {t['build']:.2f}, "
        f"solve {t['solve']:.2f}, recover {t['recover']:.2f})",
        f"contact: {c['n_active']} active pairs, x in [{_fmt(c['x_min'])}, {_fmt(c['x_max'])}] {L}, "
        f"max pressure {_fmt(c['max_pressure'])} {S}, total force {_fmt(c['total_force'])} {S}*{L}",
        (f"residuals: equilibrium {r['equilibrium']:.1e}, constitutive {r['constitutive']:.1e}, "
         f"complementarity {r['complementarity']:.1e}; duality gap {s['duality_gap']:.1e}" if "complementarity" in r
         else f"residuals: admissibility {r['admissibility']:.1e} (exact to rounding), penetration "
         f"{r['penetration']:.1e}; relative gap G {s['duality_gap']:.1e}"),
    ]
    if sol.scene.friction is not None:
        k = sol.contact
        slipping = int((k["active"] & ~k["stick"] & (k["slip"] != 0)).sum())
        lines.append(f"friction: Tresca g = {_fmt(sol.scene.friction.g)} {S}; {int(k['stick'].sum())} active pairs "
                     f"stick, {slipping} slip; largest tangential force {_fmt(np.abs(k['tangential_force']).max())} "
                     f"{S}*{L}")
    for name, why in s["checks_skipped"].items():
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
    if s["bounds"]:
        b = s["bounds"]
        lines.append(f"certified bounds: {b['energy_lower']:.6g} <= J(u) <= {b['energy_upper']:.6g}; "
                     f"error bound sqrt(2G) = {b['error_bound']:.3g}"
                     + ("" if b["guaranteed"] else f" (not guaranteed: {'; '.join(b['reasons'])})"))
    if written:
        took = "" if t_write is None else f" in {t_write:.2f} s"
        lines.append(f"wrote {Path(written[0]).parent}/{took}: " + ", ".join(Path(w).name for w in written))
    return "\n".join(lines)


def _cmd_scenes(args) -> int:
    from .scenefile import builtin_scenes
    for name, desc in builtin_scenes().items():
        print(f"{name:20s} {desc}")
    return 0


def _cmd_solve(args) -> int:
    from .output import check_output_dir, write_outputs
    from .pipeline import solve
    from .scenefile import load_scene, parse_assignment
    from .solvers import resolve_solver
    from .triangulation import check_triangulation
    from .validate import file_stem

    scene = load_scene(args.scene, [parse_assignment(s) for s in args.set])
    solver = None if args.solver is None else resolve_solver(args.solver)
    check_triangulation(args.triangulation)
    out = None if args.no_output else Path(args.out or Path("out") / file_stem(scene.name))
    if out is not None:
        check_output_dir(out)  # fail before the work, and create nothing until there are results
    sol = solve(scene, args.triangulation, args.level, solver, stress_space=args.stress_space, bounds=args.bounds,
                max_memory=args.max_memory)
    t0 = time.perf_counter()
    written = write_outputs(sol, out, plots=not args.no_plots) if out is not None else []
    print(human_summary(sol, written, time.perf_counter() - t0))
    return 0


STUDIES = ("convergence", "speed", "stability", "bounds")  # built-in specs: cvxdual/study/specs/NAME.*


def _cmd_study(args) -> int:
    from .study.command import main as study_main
    return study_main(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cvxdual", description="Dual finite element analysis of frictionless "
                                "(or Tresca) contact of two plane elastic bodies (Tran Van Bon 1986) on CVXPY.")
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("scenes", help="list the built-in scenes").set_defaults(func=_cmd_scenes)
    s = sub.add_parser("solve", help="solve a scene and write its outputs")
    s.add_argument("--scene", default="hertz", help="built-in scene name or path to a .toml file (default: hertz)")
    s.add_argument("--triangulation", default="type1", help="type1 (Haslinger-Hlavacek) or type2 "
                   "(Hlavacek-Krizek) (default: type1)")
    s.add_argument("--level", type=int, default=None, help="mesh level, h halves per level (default: the scene's)")
    s.add_argument("--solver", default=None, help="a CVXPY solver name, or fast: the active-set path (default: "
                   f"the CVXPY solver measured fastest at the mesh's size, CLARABEL below {LARGE_QP:.0e} pieces and "
                   "SCS above, Clarabel taking over where SCS fails)")
    s.add_argument("--stress-space", default="p0", choices=("p0", "eq"),
                   help="p0: the paper's piecewise-constant stresses; eq: exactly admissible equilibrium "
                   "stresses with certified bounds, flat faces only (default: p0)")
    s.add_argument("--bounds", action="store_true", help="with p0: also certify the displacement against "
                   "equilibrium stresses (flat faces only)")
    s.add_argument("--out", default=None, help="output directory (default: out/<scene>)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set mesh.grading=4 (repeatable)")
    s.add_argument("--max-memory", default=None, metavar="SIZE",
                   help="refuse runs estimated to need more memory, e.g. 16GB, or 'none' (default: the memory "
                   "available, or $CVXDUAL_MAX_MEMORY)")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    s.add_argument("--no-output", action="store_true", help="print the summary only, write nothing")
    s.set_defaults(func=_cmd_solve)
    from .study.command import add_parser as add_study_parser
    st = add_study_parser(sub, STUDIES)
    st.set_defaults(func=_cmd_study)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings(record=True) as caught:
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
    # a run that worked: its warnings, each once
    for text in dict.fromkeys(one_line(w.message, MAX_MESSAGE) for w in caught):
        print(f"cvxdual: warning: {text}", file=sys.stderr)
    return status


def _fail(message: str) -> int:
    """One line on stderr and exit status 1 (warnings that led up to the error are dropped)."""
    print(f"cvxdual: error: {one_line(message, MAX_MESSAGE)}", file=sys.stderr)
    return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
