"""Why small outline bodies are cut into surfaces too: writes reports/outline_cuts.md and .csv.

    python studies/outline_cuts.py            # into reports/ (about 5 minutes, alone on the machine)
    python studies/outline_cuts.py --quick    # levels 0-1, two scenes, into out/outline_cuts-quick

gmsh meshes every outline body as up to eight surfaces, cut from nodes of the strip's chain
(:mod:`cvxdual.geometry.outline.cuts`); a body with at most ``SMALL`` chain nodes is meshed on one
thread, where the surfaces save no time. The alternative measured here: leave such a body whole,
one surface (``whole``), against the package's rule (``cut``):

1. gmsh's work for each body at levels 0-3 (the gmsh child's function called in this process, so
   both rules run on the same arguments side by side; best of three);
2. runs to a certified 1 % (P2): pieces, cycles, certified error and time, under each rule.

The cuts' lines carry gmsh's size field into the body (gmsh reads sizes at its points and
interpolates between them); a whole body loses that, which part 2 measures.
"""

import argparse
import importlib
import math
import sys
import time
from pathlib import Path

import pandas as pd

import cvxdual as cd
from cvxdual.errors import ToleranceError
from cvxdual.files import write_text
from cvxdual.geometry.outline import SMALL, forget_meshes, mesher, regions
from cvxdual.study.report import md_table

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
LEVEL_SCENES = {"block-with-hole": "block-with-hole", "rounded-punch": "rounded-punch",
                **{n: str(EXAMPLES / f"{n}.toml") for n in ("wedge-on-rollers", "hertz-outline")}}
TOL_SCENES = {"block-with-hole": "block-with-hole", "rounded-punch": "rounded-punch", "blocks": "blocks",
              "cylinder-on-block": "cylinder-on-block", "wedge-on-rollers": str(EXAMPLES / "wedge-on-rollers.toml")}
FIND_CUTS = regions.find_cuts


def whole_small(chain, *args, **kw):
    """``find_cuts`` that leaves a body of at most ``SMALL`` chain nodes whole."""
    return [] if len(chain) <= SMALL else FIND_CUTS(chain, *args, **kw)


RULES = {"cut": FIND_CUTS, "whole": whole_small}


def in_process(function: str, *args, what: str = ""):
    """The gmsh child's work done here (a measurement harness: both rules in one process)."""
    module, name = function.split(":")
    return getattr(importlib.import_module(module), name)(*args)


def recording(got: list):
    """:func:`in_process` that also keeps each request's arguments in ``got``."""
    def run(function: str, *args, what: str = ""):
        got.append(args)
        return in_process(function, *args)
    return run


def gmsh_rows(label, src, levels) -> list[dict]:
    rows = []
    for level in levels:
        got = []
        mesher.in_gmsh = recording(got)
        forget_meshes()
        cd.solve(src, level=level, solver="fast")
        for args in [a for a in got if a[3] == level]:
            chain = len(args[1][::2 if level >= 1 and args[4] is None else 1])  # gmsh's chain (halved from level 1)
            row = dict(scene=label, level=level, body=args[0].name, chain=chain)
            for name, rule in RULES.items():
                regions.find_cuts = rule
                best = math.inf
                for _ in range(3):
                    t = time.perf_counter()
                    rest = mesher.gmsh_mesh(*args)
                    best = min(best, time.perf_counter() - t)
                row |= {f"{name}_ms": 1e3 * best, f"{name}_triangles": len(rest.triangles)}
            regions.find_cuts = FIND_CUTS
            rows.append(row | dict(speedup=row["cut_ms"] / row["whole_ms"]))
    mesher.in_gmsh = in_process
    return rows


def tol_rows(label, src) -> list[dict]:
    rows = []
    mesher.in_gmsh = in_process
    for name, rule in RULES.items():
        regions.find_cuts = rule
        forget_meshes()
        t = time.perf_counter()
        try:
            sol, met = cd.solve(src, tol=0.01), True
        except ToleranceError as e:
            sol, met = e.solution, False
        seconds = time.perf_counter() - t
        regions.find_cuts = FIND_CUTS
        last = sol.adaptive.cycles[-1]
        rows.append(dict(scene=label, rule=name, met=met, cycles=len(sol.adaptive.cycles), pieces=last.pieces,
                         bound_rel=last.bound_rel, seconds=seconds))
        print(label, name, rows[-1], file=sys.stderr, flush=True)
    return rows


def report(g: pd.DataFrame, t: pd.DataFrame, seconds: float) -> str:
    moved = g[g.chain <= SMALL]  # the meshes the alternative changes
    piv = t.pivot(index="scene", columns="rule", values="pieces")
    met = t.pivot(index="scene", columns="rule", values="met")
    more = piv.whole / piv.cut
    lines = ["# Small outline bodies: cut, or whole (`studies/outline_cuts.py`)", "",
             f"`cut`: the package's rule, every body cut into up to eight surfaces; `whole`: a body whose chain for "
             f"gmsh has at most {SMALL} nodes left as one surface. One run, {seconds:.0f} s.", "",
             "## gmsh's work per body (ms, best of three)", "",
             f"Left whole, a small body meshes {moved.speedup.min():.2f}-{moved.speedup.max():.2f} times faster "
             f"(median {moved.speedup.median():.2f}, {len(moved)} meshes).", "", md_table(g, floatfmt=".3g"), "",
             "## Runs to a certified 1 % (P2)", "",
             f"Tolerance met: cut {int(met.cut.sum())} of {len(met)}, whole {int(met.whole.sum())} of {len(met)}. "
             "Pieces of the last cycle, whole over cut: "
             + ", ".join(f"{s} {more[s]:.2f}" for s in more.index) + ".",
             "", md_table(t, floatfmt=".4g"), ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="levels 0-1 and two scenes, into out/outline_cuts-quick")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    out = Path(args.out or (ROOT / ("out/outline_cuts-quick" if args.quick else "reports")))
    levels = range(2) if args.quick else range(4)
    tol = dict(list(TOL_SCENES.items())[:2]) if args.quick else TOL_SCENES
    t0 = time.perf_counter()
    g = pd.DataFrame([r for label, src in LEVEL_SCENES.items() for r in gmsh_rows(label, src, levels)])
    t = pd.DataFrame([r for label, src in tol.items() for r in tol_rows(label, src)])
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "outline_cuts.csv", g.to_csv(index=False))
    write_text(out / "outline_cuts_tol.csv", t.to_csv(index=False))
    write_text(out / "outline_cuts.md", report(g, t, time.perf_counter() - t0))
    return 0


if __name__ == "__main__":
    sys.exit(main())
