"""Adaptive against uniform refinement: writes reports/adaptive.md, .csv and .png.

    python studies/adaptive.py            # into reports/ (about 10 minutes)
    python studies/adaptive.py --quick    # three scenes, a 3% target, into out/adaptive-quick

Issue 42: ``cvxdual.solve(scene, tol=...)`` refines where the certificate's contributions are
(docs/adaptive.md). For every built-in scene with an equilibrium certificate and the examples, both
kinematic sides (P2, P1):

- *adaptive*: one run to :data:`TOL_P2` (P2) or :data:`TOL_P1` (P1), capped at :data:`MAX_PIECES`
  pieces; every cycle's pieces, bound and the seconds since the run's start (a run to a looser
  tolerance makes the same cycles and stops at the first under it, so its time is that elapsed);
- *uniform*: ``solve(scene, level=L, stress_space="eq")`` from level 0 up, until the bound is under
  the adaptive target, the pieces pass :data:`MAX_PIECES` or a solve passes :data:`CAP` seconds; its
  time less its error against an exact field (the cycles leave that out).

Rates are ``np.polyfit(log N, log bound, 1)`` over the adaptive cycles from the third (the first are
pre-asymptotic) and over the uniform levels from 1. The pieces a certified 1 % needs: the first cycle
or level under it (measured), or for uniform, where no level reached it, the fitted power law of
its last three levels (extrapolated, said so). Every adaptive cycle's bracket is checked against
every uniform level's (all hold the exact energy: any two share a point).

The time to a certified 1 % on cylinder-on-block and block-with-hole is timed side by side: the
run with ``tol=0.01`` (all cycles) and the uniform run at the first level under 1 %, in turns,
:data:`ROUNDS` rounds: the medians, the extremes, and in how many rounds the adaptive run was the
faster of the pair; gmsh's meshes are forgotten before each (a fresh run's work).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

import cvxdual as cd
from cvxdual.errors import ToleranceError
from cvxdual.files import write_text
from cvxdual.geometry.outline.mesher import forget_meshes
from cvxdual.study.report import md_table

ROOT = Path(__file__).resolve().parent.parent
EX = ROOT / "examples"
SCENES = {  # label -> (scene source, triangulation)
    "hertz": ("hertz", "type1"),
    "cylinder-on-block": ("cylinder-on-block", "type2"),
    "cylinder-in-groove": ("cylinder-in-groove", "type2"),
    "wavy": ("wavy", "type2"),
    "blocks": ("blocks", "type1"),
    "patch": ("patch", "type1"),
    "rounded-punch": ("rounded-punch", "type2"),
    "rounded-punch-linear": ("rounded-punch-linear", "type2"),
    "block-with-hole": ("block-with-hole", "type2"),
    "wedge-on-rollers": (str(EX / "wedge-on-rollers.toml"), "type2"),
    "punch-on-block": (str(EX / "punch-on-block.toml"), "type2"),
    "roller-on-block": (str(EX / "roller-on-block.toml"), "type2"),
    "hertz-outline": (str(EX / "hertz-outline.toml"), "type1"),
}
QUICK = ("cylinder-on-block", "block-with-hole", "wedge-on-rollers")
TOL_P2, TOL_P1 = 0.001, 0.01
MAX_PIECES = 300_000
CAP = 60.0  # seconds: the uniform sweep stops after a solve this long
ROUNDS = 15  # a shared machine's noise: one round in ten can be 20 % slow
TIMED = ("cylinder-on-block", "block-with-hole")


def adaptive_rows(label, src, tri, side, tol) -> list[dict]:
    try:
        sol = cd.solve(src, triangulation=tri, tol=tol, kinematic=side, max_pieces=MAX_PIECES)
    except ToleranceError as e:
        sol = e.solution
    h = sol.adaptive
    return [dict(scene=label, side=side, mode="adaptive", step=c.cycle, pieces=c.pieces, bound_rel=c.bound_rel,
                 lower=c.energy_lower, upper=c.energy_upper, guaranteed=c.guaranteed, seconds=c.elapsed, stop=h.stop)
            for c in h.cycles]


def uniform_rows(label, src, tri, side, tol) -> list[dict]:
    rows = []
    for level in range(9):
        forget_meshes()
        t0 = time.perf_counter()
        try:
            sol = cd.solve(src, triangulation=tri, level=level, stress_space="eq", kinematic=side)
        except cd.CvxdualError as e:  # a coarse level a scene cannot mesh (too few pairs, a thick strip)
            if rows:
                raise
            print(f"  {label} {side} level {level}: {e}", file=sys.stderr)
            continue
        # less its error against the scene's exact field, where it declares one: a cycle leaves that out
        dt = time.perf_counter() - t0 - sol.timings["error"]
        b = sol.bounds
        rows.append(dict(scene=label, side=side, mode="uniform", step=level, pieces=sol.field.n_pieces,
                         bound_rel=b["error_bound_rel"], lower=b["energy_lower"], upper=b["energy_upper"],
                         guaranteed=b["guaranteed"], seconds=dt, stop=""))
        if b["error_bound_rel"] <= tol or 4 * sol.field.n_pieces > MAX_PIECES or dt > CAP:
            break
    return rows


def rate(d: pd.DataFrame, first: int) -> float:
    d = d[d.step >= first]
    return float(-np.polyfit(np.log(d.pieces), np.log(d.bound_rel), 1)[0]) if len(d) >= 2 else float("nan")


def pieces_for(d: pd.DataFrame, target: float, extrapolate: bool) -> tuple[float, str]:
    hit = d[d.bound_rel <= target]
    if len(hit):
        return float(hit.pieces.iloc[0]), "measured"
    if not extrapolate or len(d) < 3:
        return float("nan"), "not reached"
    last = d.tail(3)
    k, c = np.polyfit(np.log(last.pieces), np.log(last.bound_rel), 1)
    return float(np.exp((np.log(target) - c) / k)), "extrapolated"


def brackets_meet(a: pd.DataFrame, u: pd.DataFrame) -> int:
    """Pairs (adaptive cycle, uniform level) whose brackets share no point (0 if all meet)."""
    lo = np.maximum(a.lower.to_numpy()[:, None], u.lower.to_numpy()[None, :])
    hi = np.minimum(a.upper.to_numpy()[:, None], u.upper.to_numpy()[None, :])
    return int((lo > hi).sum())


def side_by_side(src, tri, level) -> dict:
    runs = {"adaptive": lambda: cd.solve(src, triangulation=tri, tol=0.01),
            "uniform": lambda: cd.solve(src, triangulation=tri, level=level, stress_space="eq")}
    times = {k: [] for k in runs}
    for _ in range(ROUNDS):
        for k, run in runs.items():
            forget_meshes()
            t0 = time.perf_counter()
            run()
            times[k].append(time.perf_counter() - t0)
    a, u = np.array(times["adaptive"]), np.array(times["uniform"])
    return dict(adaptive_s=float(np.median(a)), uniform_s=float(np.median(u)), adaptive_min=float(a.min()),
                adaptive_max=float(a.max()), uniform_min=float(u.min()), uniform_max=float(u.max()),
                adaptive_faster=f"{int((a < u).sum())} of {len(a)}")


def summary(df: pd.DataFrame, target: float) -> pd.DataFrame:
    out = []
    for (label, side), d in df.groupby(["scene", "side"], sort=False):
        a, u = d[d["mode"] == "adaptive"], d[d["mode"] == "uniform"]
        na, how_a = pieces_for(a, target, True)
        nu, how_u = pieces_for(u, target, True)
        hit = a[a.bound_rel <= target]
        ta = hit.seconds.iloc[0] if len(hit) else float("nan")
        under = u.bound_rel <= target
        tu = u[under].seconds.iloc[0] if under.any() else float("nan")
        # a user who does not know the level solves level after level until one is under the target
        sweep = u[u.step <= u[under].step.iloc[0]].seconds.sum() if under.any() else float("nan")
        out.append(dict(scene=label, side=side, cycles=len(a), adaptive_rate=rate(a, 2), uniform_rate=rate(u, 1),
                        adaptive_pieces=na, adaptive_how=how_a, uniform_pieces=nu, uniform_how=how_u,
                        pieces_ratio=nu / na, adaptive_s=ta, uniform_level_s=tu, uniform_sweep_s=sweep,
                        best_adaptive=a.bound_rel.min(),
                        # the first cycle under the target, and every uniform level from 1: guaranteed?
                        guaranteed_at_target=bool(hit.guaranteed.iloc[0]) if len(hit) else None,
                        uniform_guaranteed=bool(u[u.step >= 1].guaranteed.all()),
                        brackets_apart=brackets_meet(a, u)))
    return pd.DataFrame(out)


def figure(df: pd.DataFrame, path: Path) -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    labels = list(dict.fromkeys(df.scene))
    cols = 4
    rows = -(-len(labels) // cols)
    fig = Figure(figsize=(4 * cols, 3.2 * rows))
    for i, label in enumerate(labels):
        ax = fig.add_subplot(rows, cols, i + 1)
        for (side, mode), d in df[df.scene == label].groupby(["side", "mode"]):
            ax.loglog(d.pieces, 100 * d.bound_rel, "o-" if mode == "adaptive" else "s--", ms=3,
                      color="C0" if side == "p2" else "C1", label=f"{side} {mode}")
        ax.axhline(1.0, color="0.6", lw=0.8)
        ax.xaxis.set_minor_formatter(NullFormatter())  # a scene of one cycle spans less than a decade
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("pieces N", fontsize=8)
        ax.set_ylabel("certified error [%]", fontsize=8)
        if i == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None)
    p.add_argument("--report-only", action="store_true", help="the report again from the CSVs in --out")
    p.add_argument("--timings-only", action="store_true",
                   help="the side-by-side timings again, from the levels in --out's adaptive.csv")
    args = p.parse_args(argv)
    out = Path(args.out or (ROOT / "out" / "adaptive-quick" if args.quick else ROOT / "reports"))
    out.mkdir(parents=True, exist_ok=True)
    scenes = {k: v for k, v in SCENES.items() if not args.quick or k in QUICK}
    target = 0.03 if args.quick else 0.01
    tols = {"p2": target if args.quick else TOL_P2, "p1": target if args.quick else TOL_P1}
    t0 = time.perf_counter()
    if args.report_only:
        df, timed = pd.read_csv(out / "adaptive.csv"), pd.read_csv(out / "adaptive_timed.csv")
    elif args.timings_only:
        df = pd.read_csv(out / "adaptive.csv")
        cd.solve("patch", stress_space="eq", level=0)  # imports and gmsh's start-up, untimed
        timed = side_by_side_all(df, scenes, target)
        write_text(out / "adaptive_timed.csv", timed.to_csv(index=False))
    else:
        df, timed = measure(scenes, tols, target, t0)
        write_text(out / "adaptive.csv", df.to_csv(index=False))
        write_text(out / "adaptive_timed.csv", timed.to_csv(index=False))
    figure(df, out / "adaptive.png")
    write_text(out / "adaptive.md", report(df, timed, target, args.quick, time.perf_counter() - t0))
    print(out / "adaptive.md")
    return 0


def measure(scenes: dict, tols: dict, target: float, t0: float) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Every scene's adaptive and uniform rows, and the side-by-side timings."""
    cd.solve("patch", stress_space="eq", level=0)  # imports and gmsh's start-up, untimed
    rows = []
    for label, (src, tri) in scenes.items():
        for side in ("p2", "p1"):
            rows += adaptive_rows(label, src, tri, side, tols[side])
            rows += uniform_rows(label, src, tri, side, tols[side])
            print(f"{label} {side}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    df = pd.DataFrame(rows)
    return df, side_by_side_all(df, scenes, target)


def side_by_side_all(df: pd.DataFrame, scenes: dict, target: float) -> pd.DataFrame:
    """:func:`side_by_side` on the :data:`TIMED` scenes, at the first uniform P2 level under ``target``."""
    timed = []
    for label in TIMED:
        if label not in scenes:
            continue
        src, tri = scenes[label]
        u = df[(df.scene == label) & (df.side == "p2") & (df["mode"] == "uniform") & (df.bound_rel <= target)]
        if len(u):
            t = side_by_side(src, tri, int(u.step.iloc[0]))
            timed.append(dict(scene=label, uniform_level=int(u.step.iloc[0]), **t,
                              ratio=t["uniform_s"] / t["adaptive_s"]))
    return pd.DataFrame(timed)


def report(df: pd.DataFrame, timed: pd.DataFrame, target: float, quick: bool, seconds: float) -> str:
    table = summary(df, target)
    lines = [f"# Adaptive against uniform refinement (`studies/adaptive.py`{' --quick' if quick else ''})", "",
             f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}. "
             "Pieces: the solution's `n_pieces` (three sub-triangles a macro triangle, and the curved pieces).", "",
             f"## Pieces and time to a certified {100 * target:g} %", "",
             "Rates: the certified relative error against the pieces, `-d log(bound) / d log(N)` (0.5 is "
             "P1's optimum, 1 P2's). `uniform_how`: whether the uniform pieces were reached (`measured`) or "
             "extrapolated from the last three levels. `adaptive_s`: the run's seconds to the cycle under the "
             "target (all earlier cycles included); `uniform_level_s`: the one uniform solve at the first level "
             "under it; `uniform_sweep_s`: levels from the first up to that one, as a run that does not know "
             "the level would take them (the study's own timings, not side by side). A uniform solve's time "
             "leaves out its error against the scene's exact field (`hertz`, `patch`, `rounded-punch-linear`, "
             "`hertz-outline`), which an adaptive run computes once, after its last cycle. "
             "`brackets_apart`: pairs of an adaptive cycle and a uniform level whose brackets share no "
             "point (0: all hold the same energy).", "",
             md_table(table, floatfmt=".3g"), ""]
    if len(timed):
        lines += [f"## Side by side (whole runs, {ROUNDS} rounds in turns: medians, extremes, rounds the adaptive run "
                  "won)", "",
                  md_table(timed, floatfmt=".3g"), ""]
    lines += acceptance(table, timed)
    lines += ["Every cycle and level: `adaptive.csv`; the timings: `adaptive_timed.csv`; the curves: "
              "`adaptive.png`.", ""]
    return "\n".join(lines)


def acceptance(table: pd.DataFrame, timed: pd.DataFrame) -> list[str]:
    """Issue 42's acceptance, item by item, from the measured tables."""
    def row(scene, side):
        r = table[(table.scene == scene) & (table.side == side)]
        return None if r.empty else r.iloc[0]

    out = ["## Issue 42's acceptance, measured", ""]
    g = table[(table.side == "p2") & table.uniform_guaranteed]
    ok = g[g.guaranteed_at_target.eq(True)]
    out.append(f"- Scenes `guaranteed` on every uniform level from 1 (P2): {len(g)}; their run to 1 % ends "
               f"`guaranteed` under 1 %: {len(ok)} of {len(g)}"
               + (f" (not: {', '.join(sorted(set(g.scene) - set(ok.scene)))})" if len(ok) < len(g) else "")
               + f"; brackets apart (any cycle against any level, both sides, every scene): "
               f"{int(table.brackets_apart.sum())}.")
    for scene in ("wedge-on-rollers", "rounded-punch"):
        for side, floor in (("p1", 0.45), ("p2", 0.6)):
            r = row(scene, side)
            if r is None:
                continue
            ok = "PASS" if r.adaptive_rate >= floor else "FAIL"
            out.append(f"- {scene} {side}: rate {r.adaptive_rate:.3g} (at least {floor}: {ok}); a certified 1 % with "
                       f"{r.adaptive_pieces:.3g} pieces ({r.adaptive_how}) against {r.uniform_pieces:.3g} uniformly "
                       f"({r.uniform_how}): {r.pieces_ratio:.3g} times fewer (at least 10: "
                       f"{'PASS' if r.pieces_ratio >= 10 else 'FAIL'}).")
    for _, t in timed.iterrows():
        won = f"; the adaptive run the faster in {t.adaptive_faster} rounds" if "adaptive_faster" in t else ""
        out.append(f"- {t.scene}: a certified 1 % in {t.adaptive_s:.3g} s adaptively against {t.uniform_s:.3g} s "
                   f"uniformly (level {t.uniform_level}, medians{won}): "
                   f"{'PASS' if t.adaptive_s < t.uniform_s else 'FAIL'}.")
    return out + [""]


if __name__ == "__main__":
    sys.exit(main())
