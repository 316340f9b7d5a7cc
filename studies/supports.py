"""Sliding supports on slanted lines and on guided rollers: writes reports/supports.md and .csv.

    python studies/supports.py            # levels 1-6, into reports/ (a few minutes, alone)
    python studies/supports.py --quick    # levels 1-3, into out/supports-quick

The block of examples/wedge-on-rollers.toml (a cylinder pressed on it, the block pushed up from
below) held three ways:

- ``upright``: vertical sides sliding (the axis-aligned case: no node frames);
- ``wedge``: its 1-in-4 slopes sliding along themselves (node frames along the slopes);
- ``guided``: the example as written, rollers guided at 45 degrees across the slopes.

For each level: the pieces, the eq route's certified energy bracket and its error bound
``sqrt(2 G)``, the part of ``G`` within 1 mm of the bottom corners, and the P0 stress in the
triangle nearest a bottom corner with its distance ``r`` from it; fitted rates (h halves a level)
and the corner stress's growth exponent. Time: the P0 fast path at the finest level, best of
three with the mesh kept, wedge and guided over upright, measured in this one run.
"""

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

import cvxdual as cd
from cvxdual.files import write_text
from cvxdual.study.report import md_table

ROOT = Path(__file__).resolve().parent.parent
GUIDED = (ROOT / "examples" / "wedge-on-rollers.toml").read_text()
WEDGE = re.sub(r"\ndirection = \[[^]]*\]", "", GUIDED)
UPRIGHT = WEDGE.replace("to = [13.0, -12.0]", "to = [10.0, -12.0]").replace("to = [-13.0, -12.0]",
                                                                            "to = [-10.0, -12.0]")
CASES = {"upright": (UPRIGHT, 10.0), "wedge": (WEDGE, 13.0), "guided": (GUIDED, 13.0)}  # text, bottom corner's |x|


def fit(levels, values) -> float:
    """The rate in h: minus the slope of log2(value) against the level."""
    return float(-np.polyfit(levels, np.log2(values), 1)[0])


def rows(scenes: dict, levels) -> pd.DataFrame:
    out = []
    for name, scene in scenes.items():
        corner = np.array([CASES[name][1], -12.0])
        for level in levels:
            eq = cd.solve(scene, level=level, stress_space="eq", solver="fast")
            b = eq.bounds
            c = eq.space.X.mean(1)  # the solution's own space: no second build
            near = np.minimum(*(np.linalg.norm(c - corner * [s, 1.0], axis=1) for s in (1.0, -1.0))) < 1.0
            element = b["contributions"]["element"]
            p0 = cd.solve(scene, level=level, solver="fast")
            cen = p0.mesh.points[p0.pieces.nodes].mean(1)
            r = np.linalg.norm(cen - corner, axis=1)
            i = int(np.argmin(r))
            out.append({"case": name, "level": level, "pieces": len(eq.pieces), "energy_lower": b["energy_lower"],
                        "energy_upper": b["energy_upper"], "error_bound": b["error_bound"],
                        "corner_share": float(element[near].sum()) / b["gap"], "guaranteed": b["guaranteed"],
                        "corner_r": float(r[i]), "corner_stress": float(np.abs(np.asarray(p0.stress)[i]).max())})
    return pd.DataFrame(out)


def timing(scenes: dict, level: int) -> dict:
    best = {}
    for name, scene in scenes.items():
        cd.solve(scene, level=level, solver="fast")  # meshes it once: the times below are the solve's
        t = []
        for _ in range(3):
            t0 = time.perf_counter()
            cd.solve(scene, level=level, solver="fast")
            t.append(time.perf_counter() - t0)
        best[name] = min(t)
    return best


def report(df: pd.DataFrame, times: dict, level: int) -> str:
    out = ["# Sliding supports on slanted lines and guided rollers", "", __doc__.split("\n\n", 2)[2].strip(), ""]
    for name in CASES:
        d = df[df.case == name]
        tail = d[d.level >= d.level.max() - 2]
        growth = np.polyfit(np.log(tail.corner_r), np.log(tail.corner_stress), 1)[0]
        out.append(f"- **{name}**: error bound rate {fit(d.level, d.error_bound):.2f} over levels "
                   f"{d.level.min()}-{d.level.max()}; corner stress ~ r^{growth:.2f} on the last three levels; "
                   f"guaranteed {int(d.guaranteed.sum())} of {len(d)}.")
    out += ["", f"P0 fast path at level {level} (best of three, mesh kept): "
            + ", ".join(f"{n} {times[n]:.3g} s" for n in CASES)
            + f"; wedge / upright {times['wedge'] / times['upright']:.2f}, guided / upright "
            f"{times['guided'] / times['upright']:.2f}.", "",
            "The guided block is singular where a guide meets the loaded bottom at a corner: the P0 stress in the "
            "corner triangle grows as the triangle shrinks, and the certified error bound falls more slowly than on "
            "the same block sliding along its slopes, with the corners holding a growing share of G. The bounds stay "
            "certified at every level.", "",
            md_table(df, ".6g"), ""]
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    out = Path(args.out or ("out/supports-quick" if args.quick else "reports"))
    levels = [1, 2, 3] if args.quick else [1, 2, 3, 4, 5, 6]
    with tempfile.TemporaryDirectory() as tmp:
        scenes = {}
        for name, (text, _) in CASES.items():
            f = Path(tmp) / f"{name}.toml"
            f.write_text(text.replace('name = "wedge-on-rollers"', f'name = "{name}"'))
            scenes[name] = cd.load_scene(str(f))
        df = rows(scenes, levels)
        times = timing(scenes, levels[-1])
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "supports.csv", df.to_csv(index=False, float_format="%.6g"))
    write_text(out / "supports.md", report(df, times, levels[-1]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
