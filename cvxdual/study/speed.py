"""Speed against error: time per phase and memory against size for every path, the "limit"
(one sparse factorisation plus solve of the stiffness), error against wall time, and the
QP solvers CVXPY offers.

Every measurement runs in a fresh subprocess (clean peak memory, a time limit for the CVXPY
path); ratios are taken between numbers measured in the same run. Finished measurements are
cached (``--cache``) so an interrupted run resumes.
"""

from __future__ import annotations

import cProfile
import io
import json
import pstats
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from .common import Cache, Progress, fit_rate, md_table, save_fig, scene_key, study_main, write_csv, write_text

CVXPY_TIMEOUT = 600.0  # "as far as the CVXPY path goes in 10 minutes"
SCAN_SCENE = "hertz"
SCAN_COLUMNS = 10  # level L has about 24 * 10 * 4**L pieces: 1e3 (L=1) .. 1e6 (L=6)


# -- the worker: one measurement in its own process -------------------------------------

def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB


def measure(spec: dict) -> dict:
    """Run one measurement described by ``spec`` (scene, overrides, triangulation, level, path)."""
    from ..assembly import assemble
    from ..factor import SPDFactor, backend
    from ..fast import limit_matrix
    from ..output import atomic_write_json
    from ..scenefile import load_scene
    from ..solution import solve
    from ..triangulation import discretize

    scene = load_scene(spec["scene"], spec.get("overrides") or [])
    tri, level, path = spec["triangulation"], spec["level"], spec["path"]
    out: dict = {"path": path}
    if path == "limit":
        t0 = time.perf_counter()
        mesh, pieces, ties = discretize(scene, tri, level)
        system = assemble(mesh, pieces, ties)
        t1 = time.perf_counter()
        K, rhs = limit_matrix(system)
        t2 = time.perf_counter()
        f = SPDFactor(K)
        t3 = time.perf_counter()
        f.solve(rhs)
        t4 = time.perf_counter()
        out.update(n_pieces=len(pieces), n_dofs=int(K.shape[0]), nnz=int(K.nnz), t_setup=t1 - t0, t_matrix=t2 - t1,
                   t_factor=t3 - t2, t_solve_lin=t4 - t3, t_limit=t4 - t2, backend=backend(), peak_mb=_peak_mb())
        return out
    solver = {"fast": "fast", "cvxpy": "CLARABEL"}.get(path, path)
    prof = cProfile.Profile() if spec.get("profile") else None
    if prof:
        prof.enable()
    sol = solve(scene, tri, level, solver, check=spec.get("check", True), **spec.get("options", {}))
    t0 = time.perf_counter()
    if spec.get("write"):
        import tempfile
        with tempfile.TemporaryDirectory() as d:
            atomic_write_json(Path(d) / "summary.json", sol.summary())
    t_write = time.perf_counter() - t0
    if prof:
        prof.disable()
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(18)
        out["profile"] = buf.getvalue()
    out.update({f"t_{k}": v for k, v in sol.timings.items()})
    out.update(t_write=t_write, t_end_to_end=sol.timings["total"] + t_write, n_pieces=sol.system.n_pieces,
               n_dofs=sol.system.n_dofs, h=sol.mesh.h, status=sol.solver["status"],
               iterations=sol.solver.get("iterations"), peak_mb=_peak_mb(), residuals=sol.residuals,
               max_pressure=sol.contact["max_pressure"])
    if sol.error is not None:
        out["error_l2_rel"] = sol.error["l2_rel"]
    elif spec.get("reference"):
        from .convergence import reference_field
        from ..norms import stress_distance
        ref = reference_field(scene, spec["reference"]["level"], Cache(spec["reference"]["cache"]))
        out["error_l2_rel"] = stress_distance(ref, sol, 2)["l2_rel"]
    if spec.get("compare_fast"):
        from ..norms import l2_norm
        fast = solve(scene, tri, level, "fast")
        out["diff_to_fast"] = l2_norm(sol.system, sol.stress - fast.stress) / l2_norm(sol.system, fast.stress)
    return out


def run_measure(spec: dict, timeout: float | None = None) -> dict:
    """:func:`measure` in a fresh interpreter; a timeout or crash becomes a status, not an exception."""
    cmd = [sys.executable, "-m", "cvxdual.study.speed", "--worker", json.dumps(spec)]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"path": spec["path"], "status": f"timeout (>{timeout:.0f} s)"}
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or ["no output"])[-1]
        return {"path": spec["path"], "status": f"failed: {last[:200]}"}
    return json.loads(p.stdout.strip().splitlines()[-1])


# -- the study ---------------------------------------------------------------------------

def _spec(scene, level, path, tri="type1", overrides=None, **kw) -> dict:
    return {"scene": scene, "overrides": overrides or [], "triangulation": tri, "level": level, "path": path, **kw}


class _Runner:
    """Runs measurements (each in its own process unless ``inprocess``), through the cache."""

    def __init__(self, cache: Cache, progress: Progress, inprocess: bool = False):
        self.cache, self.progress, self.inprocess = cache, progress, inprocess

    def __call__(self, spec: dict, label: str, timeout: float | None = None) -> dict:
        key = "m-" + scene_key(json.dumps(spec, sort_keys=True))
        hit = self.cache.get_row(key)
        if hit is not None:
            self.progress.step(label, 0.0, cached=True)
            return hit
        t0 = time.perf_counter()
        if self.inprocess:
            try:
                res = json.loads(json.dumps(measure(spec), default=_json_default))
            except Exception as e:  # noqa: BLE001 - a failing solver is a result here
                res = {"path": spec["path"], "status": f"failed: {type(e).__name__}: {e}"[:200]}
        else:
            res = run_measure(spec, timeout)
        res.setdefault("status", "optimal")
        self.cache.put_row(key, res)
        self.progress.step(f"{label}: {res.get('status')}", time.perf_counter() - t0)
        return res


SCAN_LEVELS = (1, 2, 3, 4, 5, 6)
PARETO = {"hertz": {"graded": [], "uniform": [{"mesh": {"grading": 1.0}}]},
          "cylinder-in-groove": {"graded": [], "uniform": [{"mesh": {"grading": 1.0}}]}}
PARETO_FAST_LEVELS = (1, 2, 3, 4, 5, 6)
PARETO_CVXPY_LEVELS = (1, 2, 3, 4)
# stronger grading for "1 % in 1 s" on hertz: elements concentrated on the contact zone
HERTZ_SHARP = [{"mesh": {"grading": 50.0, "focus": [0.0, 7.0], "columns": 6},
                "bodies": {"cylinder": {"focus_depth": 6.0, "layers": 5}, "block": {"focus_depth": 6.0, "layers": 5}}}]
SOLVERS_LEVEL = 2
QUICK = {"scan": (1, 2), "pareto_fast": (1, 2), "pareto_cvxpy": (1,), "solvers_level": 0,
         "solvers": ("CLARABEL", "OSQP", "SCS")}


def run(out: str | Path, quick: bool = False, cache_dir: str | Path | None = ".cache/cvxdual",
        progress: bool = True) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Cache(None if cache_dir is None else Path(cache_dir) / "speed")
    scan_levels = QUICK["scan"] if quick else SCAN_LEVELS
    pf = QUICK["pareto_fast"] if quick else PARETO_FAST_LEVELS
    pc = QUICK["pareto_cvxpy"] if quick else PARETO_CVXPY_LEVELS
    sl = QUICK["solvers_level"] if quick else SOLVERS_LEVEL
    import cvxpy as cp
    solvers = [s for s in cp.installed_solvers() if s in QP_SOLVERS and (not quick or s in QUICK["solvers"])]
    ref_level = 4 if quick else 7
    n = (3 * len(scan_levels) + 1 + 2 * 2 * 2 * (len(pf) + len(pc)) + len(pf)
         + 2 * len(solvers) + 1)
    prog = Progress(n, "speed", progress)
    run1 = _Runner(cache, prog, inprocess=quick)  # quick: no process per run (memory not measured)
    scan_over = [{"mesh": {"columns": SCAN_COLUMNS}}]

    # 1. time and memory against size, every path, and the limit
    scan = []
    cvxpy_alive = True
    for L in scan_levels:
        for path in ("limit", "fast", "cvxpy"):
            if path == "cvxpy" and not cvxpy_alive:
                prog.step(f"scan {path} level {L}: skipped (smaller size timed out)", 0.0, cached=True)
                continue
            spec = _spec(SCAN_SCENE, L, path, overrides=scan_over, write=path == "fast")
            r = run1(spec, f"scan {path} level {L}", CVXPY_TIMEOUT if path == "cvxpy" else None)
            r.update(level=L)
            scan.append(r)
            if path == "cvxpy" and not str(r.get("status", "")).startswith("optimal"):
                cvxpy_alive = False
    big = max(scan_levels)
    prof = run1(_spec(SCAN_SCENE, big, "fast", overrides=scan_over, profile=True),
                f"profile fast level {big}")

    # 2. error against wall time
    pareto = []
    ref = {"level": ref_level, "cache": str(Path(cache_dir or ".cache/cvxdual") / "convergence")}
    for scene, meshes in PARETO.items():
        for mesh_name, over in meshes.items():
            for tri in ("type1", "type2"):
                for path, levels in (("fast", pf), ("cvxpy", pc)):
                    for L in levels:
                        spec = _spec(scene, L, path, tri, over, reference=None if scene == "hertz" else ref)
                        r = run1(spec, f"pareto {scene} {mesh_name} {tri} {path} level {L}")
                        r.update(scene=scene, mesh=mesh_name, triangulation=tri, level=L)
                        pareto.append(r)
    for L in pf:
        r = run1(_spec("hertz", L, "fast", "type1", HERTZ_SHARP), f"pareto hertz sharp fast level {L}")
        r.update(scene="hertz", mesh="sharply graded", triangulation="type1", level=L)
        pareto.append(r)

    # 3. the QP solvers CVXPY offers, on the same problem
    solv = []
    for scene in ("hertz", "cylinder-in-groove"):
        for s in solvers:
            spec = _spec(scene, sl, s, "type2", check=False, compare_fast=True, options=QP_SOLVERS[s])
            r = run1(spec, f"solver {s} on {scene}", 300.0)
            r.update(scene=scene, solver=s)
            solv.append(r)

    res = {"scan": pd.DataFrame(scan), "pareto": pd.DataFrame(pareto), "solvers": pd.DataFrame(solv),
           "profile": prof.get("profile", "")}
    _write(res, out, quick)
    return res


# solver options: the tolerances each needs to have a chance at the package's accuracy
QP_SOLVERS = {
    "CLARABEL": {}, "OSQP": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iter": 100000},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 100000}, "PIQP": {}, "PROXQP": {},
    "ECOS": {}, "CVXOPT": {}, "HIGHS": {}, "QOCO": {}, "DAQP": {},
}


def _write(res: dict, out: Path, quick: bool) -> None:
    scan, pareto, solv = res["scan"], res["pareto"], res["solvers"]
    write_csv(_speed_table(scan, pareto, solv), out / "speed.csv")
    _plots(scan, pareto, out)
    write_text(out / "speed.md", _report(res, quick))


def _speed_table(scan, pareto, solv) -> pd.DataFrame:
    frames = []
    for name, df in (("scan", scan), ("pareto", pareto), ("solvers", solv)):
        d = df.drop(columns=[c for c in ("profile", "residuals") if c in df.columns]).copy()
        if "residuals" in df.columns:
            d["equilibrium_residual"] = [r.get("equilibrium") if isinstance(r, dict) else np.nan for r in df["residuals"]]
        d.insert(0, "part", name)
        frames.append(d)
    return pd.concat(frames, ignore_index=True, sort=False)


def _plots(scan, pareto, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), constrained_layout=True)
    lim = scan[scan.path == "limit"]
    for path, mk in (("fast", "o-"), ("cvxpy", "s-")):
        d = scan[(scan.path == path) & scan.status.astype(str).str.startswith("optimal")]
        axes[0].loglog(d.n_pieces, d.t_total, mk, label=f"{path}: total")
        axes[0].loglog(d.n_pieces, d.t_solve, mk.replace("-", ":"), label=f"{path}: solve")
        axes[2].loglog(d.n_pieces, d.peak_mb, mk, label=path)
    axes[0].loglog(lim.n_pieces, lim.t_limit, "k^-", label="limit: factorise + solve K")
    axes[2].loglog(lim.n_pieces, lim.peak_mb, "k^-", label="limit")
    d = scan[(scan.path == "cvxpy") & scan.status.astype(str).str.startswith("optimal")]
    for ph in ("mesh", "assemble", "build", "solve", "recover"):
        axes[1].loglog(d.n_pieces, d[f"t_{ph}"], "s-", label=f"cvxpy {ph}")
    f = scan[scan.path == "fast"]
    for ph in ("solve", "recover"):
        axes[1].loglog(f.n_pieces, f[f"t_{ph}"], "o--", label=f"fast {ph}")
    for ax, t in zip(axes, ("time against size", "time per phase", "peak memory")):
        ax.set_xlabel("pieces")
        ax.set_title(t)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("seconds")
    axes[1].set_ylabel("seconds")
    axes[2].set_ylabel("MB")
    save_fig(fig, out / "speed_scaling.png")

    scenes = list(dict.fromkeys(pareto.scene))
    fig, axes = plt.subplots(1, len(scenes), figsize=(7 * len(scenes), 5), squeeze=False, constrained_layout=True)
    for ax, scene in zip(axes[0], scenes):
        d = pareto[(pareto.scene == scene) & pareto.status.astype(str).str.startswith("optimal")]
        for (mesh, tri, path), g in d.groupby(["mesh", "triangulation", "path"], sort=False):
            g = g.sort_values("level")
            ax.loglog(g.t_total, g.error_l2_rel, "o-" if path == "fast" else "s--", ms=4,
                      label=f"{path}, {mesh}, {tri}")
        if scene == "hertz":
            ax.axhline(0.01, color="gray", lw=0.8, ls=":")
        ax.set_xlabel("wall time per solve, mesh to solution [s]")
        ax.set_ylabel("relative L2 stress error")
        ax.set_title(f"{scene}: error against time")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    save_fig(fig, out / "speed_pareto.png")


def _exponents(scan) -> pd.DataFrame:
    rows = []
    for path in ("fast", "cvxpy", "limit"):
        d = scan[(scan.path == path) & scan.status.astype(str).str.startswith("optimal")]
        d = d[d.n_pieces >= 1e4]  # growth exponents from the sizes where fixed costs no longer dominate
        cols = ["t_limit", "t_factor"] if path == "limit" else ["t_mesh", "t_assemble", "t_build", "t_solve",
                                                                 "t_recover", "t_total"]
        for c in cols + ["peak_mb"]:
            if c in d and len(d) >= 2:
                rows.append({"path": path, "quantity": c, "exponent": fit_rate(d.n_pieces, d[c]),
                             "sizes": f"{int(d.n_pieces.min())}-{int(d.n_pieces.max())}"})
    return pd.DataFrame(rows)


def _report(res: dict, quick: bool) -> str:
    scan, pareto, solv = res["scan"], res["pareto"], res["solvers"]
    ok = scan.status.astype(str).str.startswith("optimal")
    lim = scan[scan.path == "limit"].set_index("level")
    rows = []
    for L in sorted(scan.level.unique()):
        r = {"level": L, "pieces": int(lim.loc[L, "n_pieces"]), "limit s": lim.loc[L, "t_limit"]}
        for path in ("fast", "cvxpy"):
            d = scan[(scan.path == path) & (scan.level == L)]
            if len(d) and ok[d.index[0]]:
                r[f"{path} solve s"] = d.t_solve.iloc[0]
                r[f"{path} total s"] = d.t_total.iloc[0]
                r[f"{path} solve / limit"] = d.t_solve.iloc[0] / lim.loc[L, "t_limit"]
                r[f"{path} MB"] = d.peak_mb.iloc[0]
            else:
                r[f"{path} solve s"] = np.nan
                r[f"{path} total s"] = np.nan
                r[f"{path} solve / limit"] = np.nan
                r[f"{path} MB"] = np.nan
                if len(d):
                    r["note"] = f"{path}: {d.status.iloc[0]}"
        cv = scan[(scan.path == "cvxpy") & (scan.level == L)]
        if len(cv) and ok[cv.index[0]]:
            r["cvxpy build share"] = cv.t_build.iloc[0] / cv.t_total.iloc[0]
        rows.append(r)
    tab = pd.DataFrame(rows)
    targets = _targets(scan, pareto, ok)
    lines = [
        "# Speed against error",
        "",
        "Generated by `python studies/speed.py`" + (" --quick" if quick else "") + " (CSV: `speed.csv`; plots: "
        "`speed_scaling.png`, `speed_pareto.png`). Machine: 2 cores; every measurement in its own process, all "
        "ratios from one run. Paths: `cvxpy` = the dual QP built in CVXPY and solved by Clarabel (the reference "
        "path); `fast` = the condensed displacement form solved by a primal-dual active set method with MKL "
        "Pardiso factorisations, warm-started from level L-2 (`cvxdual.fast`). `limit` = one sparse SPD "
        "factorisation plus solve of the stiffness `K` (all contact pairs closed, Pardiso), the same size and "
        "sparsity as the fast path's matrix; it excludes building `K`.",
        "",
        "## Targets",
        "",
        md_table(pd.DataFrame(targets)),
        "",
        f"## Time and memory against size (`{SCAN_SCENE}`, {SCAN_COLUMNS} columns at level 0)",
        "",
        md_table(tab),
        "",
        "Growth exponents (time ~ pieces^k, fitted from 1e4 pieces up):",
        "",
        md_table(_exponents(scan)),
        "",
        "## Where the time goes (profile of the largest fast-path run)",
        "",
        "```",
        _trim_profile(res["profile"]),
        "```",
        "",
        "## Error against wall time",
        "",
        "Both triangulations, graded (the scene's own) and uniform meshes, both paths; `hertz` also with a sharply "
        "graded mesh. `cylinder-in-groove` is measured against the type 2 reference of the convergence study.",
        "",
        md_table(_pareto_table(pareto)),
        "",
        "## QP solvers through CVXPY (level %d, type 2)" % (QUICK["solvers_level"] if quick else SOLVERS_LEVEL),
        "",
        "`diff to fast` is the relative L2 distance of the stresses to the fast path's exact solution of the same "
        "discrete problem; `accepted` says whether the package's accuracy checks pass (they are required for a "
        "result to be returned).",
        "",
        md_table(_solver_table(solv)),
        "",
    ]
    return "\n".join(lines)


def _trim_profile(text: str) -> str:
    keep = [ln for ln in text.splitlines() if ln.strip()]
    return "\n".join(keep[:32])


def _targets(scan, pareto, ok) -> list[dict]:
    out = []
    lim = scan[scan.path == "limit"].set_index("level")
    f = scan[(scan.path == "fast") & ok & (scan.n_pieces >= 1e5)]
    if len(f):
        ratio = max(r.t_solve / lim.loc[r.level, "t_limit"] for r in f.itertuples())
        out.append({"target": "fast path at >= 1e5 pieces: solve <= 3 x limit",
                    "measured": f"worst ratio {ratio:.2f} at " + ", ".join(str(int(n)) for n in f.n_pieces),
                    "met": "yes" if ratio <= 3 else "no"})
    big = scan[(scan.path == "fast") & ok & (scan.n_pieces >= 9e5)]
    if len(big):
        t = float(big.t_end_to_end.iloc[0])
        out.append({"target": "1e6 pieces end to end (mesh to written summary.json), fast path, <= 60 s",
                    "measured": f"{t:.1f} s at {int(big.n_pieces.iloc[0])} pieces", "met": "yes" if t <= 60 else "no"})
    cv = scan[(scan.path == "cvxpy") & ok & (scan.n_pieces >= 5e4)]
    if len(cv):
        r = cv.iloc[(cv.n_pieces - 1e5).abs().argsort().iloc[0]]
        share = r.t_build / r.t_total
        out.append({"target": "CVXPY build + canonicalisation <= 20% of the CVXPY path at 1e5 pieces",
                    "measured": f"{100 * share:.1f}% at {int(r.n_pieces)} pieces", "met": "yes" if share <= 0.2 else "no"})
    h = pareto[(pareto.scene == "hertz") & pareto.status.astype(str).str.startswith("optimal")]
    good = h[h.error_l2_rel <= 0.01]
    if len(good):
        best = good.loc[good.t_solve.idxmin()]
        out.append({"target": "hertz: 1% relative L2 stress error in <= 1 s of solve time",
                    "measured": f"{100 * best.error_l2_rel:.2f}% in {best.t_solve:.2f} s solve ({best.path}, "
                                f"{best.mesh}, level {int(best.level)}, {int(best.n_pieces)} pieces)",
                    "met": "yes" if best.t_solve <= 1 else "no"})
    else:
        out.append({"target": "hertz: 1% relative L2 stress error in <= 1 s of solve time",
                    "measured": "no run reached 1%", "met": "no"})
    return out


def _pareto_table(p) -> pd.DataFrame:
    d = p[p.status.astype(str).str.startswith("optimal")]
    cols = ["scene", "mesh", "triangulation", "path", "level", "n_pieces", "error_l2_rel", "t_solve", "t_total"]
    return d[cols].sort_values(["scene", "mesh", "triangulation", "path", "level"])


def _solver_table(s) -> pd.DataFrame:
    rows = []
    for r in s.itertuples():
        res = r.residuals if isinstance(getattr(r, "residuals", None), dict) else {}
        from ..solution import TOLERANCES
        accepted = bool(res) and all(res.get(k, np.inf) <= v for k, v in TOLERANCES.items()) \
            and str(r.status).startswith("optimal")
        rows.append({"scene": r.scene, "solver": r.solver, "status": str(r.status)[:60],
                     "solve s": getattr(r, "t_solve", np.nan), "iterations": getattr(r, "iterations", None),
                     "diff to fast": getattr(r, "diff_to_fast", np.nan),
                     "equilibrium": res.get("equilibrium", np.nan), "accepted": "yes" if accepted else "no"})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    if argv and argv[0] == "--worker":
        print(json.dumps(measure(json.loads(argv[1])), default=_json_default))
        return 0
    return study_main("speed", __doc__, run, argv, quick_help="small sizes only")


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    return str(o)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
