"""Speed against error: time per phase and memory against size for both paths and the "limit"
(one sparse factorisation plus solve of the stiffness), error against wall time, and the QP
solvers CVXPY offers. Every case runs in a fresh process (``isolate = "process"``: a clean peak
memory, a time limit); ratios are taken between numbers measured in the same run.
Run: ``python studies/speed.py [--quick]`` (or ``cvxdual study run studies/specs/speed.py``).
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

SCAN_SCENE = "hertz"
SCAN_COLUMNS = 10  # level L has about 24 * 10 * 4**L pieces: 1e3 (L=1) .. 1e6 (L=6)
CVXPY_TIMEOUT = 600.0  # "as far as the CVXPY path goes in 10 minutes"
SOLVER_TIMEOUT = 60.0  # at 2.3k pieces: 250x the slowest accepted solver (ECOS, 0.24 s)
LARGE_TIMEOUT = 300.0  # at 1.5e5 pieces: 10x the slowest accepted solver measured before (Clarabel, 30 s)
SOLVERS_LEVEL, QUICK_SOLVERS_LEVEL = 2, 0
LARGE_SOLVERS_LEVEL = 5  # hertz type 2: 147,456 pieces, "about 1e5"
# not run at 1.5e5 pieces, to protect a shared machine and the study's time: HiGHS grew to 8.4 GB
# and failed at 3.7e4 pieces, ProxQP (dense in CVXPY) needs n^2 memory, CVXOPT and DAQP take over
# 100 s at 2.3k pieces (all measured while choosing these settings; the small case shows it again)
NOT_LARGE = ("HIGHS", "PROXQP", "CVXOPT", "DAQP")
# the QP solvers CVXPY can call that are compared (their options: cvxdual.convex.solvers.SOLVER_OPTIONS)
QP_CANDIDATES = ("CLARABEL", "SCS", "ECOS", "CVXOPT", "HIGHS", "QOCO", "OSQP", "PIQP", "PROXQP", "DAQP")
QUICK_SOLVERS = ("CLARABEL", "OSQP", "SCS")
UNIFORM = {"mesh": {"grading": 1.0}}
# stronger grading for "1 % in 1 s" on hertz: elements concentrated on the contact zone
HERTZ_SHARP = {"mesh": {"grading": 50.0, "focus": [0.0, 7.0], "columns": 6},
               "bodies": {"cylinder": {"focus_depth": 6.0, "layers": 5}, "block": {"focus_depth": 6.0, "layers": 5}}}


# outline bodies meshed by gmsh beyond the strip, at the two levels round 1e5 pieces (and a quick one)
MESHING = (("block-with-hole", [4, 5], 1), ("rounded-punch", [5, 6], 1),
           ("../../examples/hertz-outline.toml", [5, 6], 2))
MESHING_SHARE = 0.30  # gmsh's share of an end-to-end run near 1e5 pieces (issue 27)
NEAR = (5e4, 2e5)  # "near 1e5 pieces": within a factor two

EQ_SCENES = ["hertz", "cylinder-on-block"]  # flat and curved faces
EQ_LEVELS = [3, 4, 5, 6]  # 9e3 to 6e5 triangles
EQ_RULE_LEVEL = 5  # where the eq errors' quadrature rules are compared (hertz, 1.5e5 triangles)
EQ_RULES = (2, 3, 4, 6, 8)


def _installed() -> list[str]:
    import cvxpy as cp
    have = set(cp.installed_solvers())
    return [s for s in QP_CANDIDATES if s in have]


def _pareto(scene: str) -> list[dict]:
    ref = "exact" if scene == "hertz" else {"level": 7}
    qref = "exact" if scene == "hertz" else {"level": 4}
    out = []
    for mesh, over in (("graded", []), ("uniform", [UNIFORM])):
        for solver, levels, quick in (("fast", [1, 2, 3, 4, 5, 6], [1, 2]), ("CLARABEL", [1, 2, 3, 4], [1])):
            out.append({"name": f"pareto {mesh}", "tags": {"part": "pareto", "mesh": mesh},
                        "scenes": [{"source": scene, "reference": ref}], "overrides": over,
                        "triangulations": ["type1", "type2"], "solvers": [solver], "levels": levels,
                        "quick": {"levels": quick, "scenes": [{"source": scene, "reference": qref}]}})
    return out


SPEC = {
    "name": "speed",
    "title": "Speed against error",
    "description": (
        "Machine: 2 cores, shared; every measurement in its own process with one thread (`studies/speed.py` runs "
        "one case at a time), all ratios from one run. Paths: `cvxpy` = the dual QP built in CVXPY and solved by "
        "Clarabel (the reference path); `fast` = the condensed displacement form solved by a primal-dual "
        "active set method with sparse SPD factorisations, warm-started from level L-2 "
        "(`cvxdual.system.displacement`). "
        "`limit` = the fastest sparse SPD factorisation plus solve of the stiffness `K` (all contact pairs "
        "closed) that cvxdual can call, the same size and sparsity as the fast path's matrix; it excludes "
        "building `K`."),
    "isolate": "process",
    # no finer-rule quadrature check or edge share: they are the study's own work (a 10x10 rule on
    # 1e6 pieces takes ~10 GB) and would count in a case's time and peak memory
    "metrics": {"check": "none", "edge_share": False},
    "report": {"setup": False, "rates": False, "plots": False},
    "compare": [*_installed(), "fast"],
    "cases": [
        # steady-state timings, as the limit's: one-time library start-up is paid before the timed
        # solve (what a first solve pays is "The small end")
        {"name": "scan", "tags": {"part": "scan", "timing": "steady"}, "scenes": [SCAN_SCENE],
         "overrides": {"mesh": {"columns": SCAN_COLUMNS}},
         "levels": [1, 2, 3, 4, 5, 6], "solvers": ["limit", "fast", "CLARABEL"], "timeout": CVXPY_TIMEOUT,
         "quick": {"levels": [1, 2]}},
        # the small end: the default hertz mesh, the first solve in a fresh process (what the CLI pays)
        {"name": "small", "tags": {"part": "small"}, "scenes": [SCAN_SCENE], "levels": [0, 1, 2],
         "solvers": ["fast"], "quick": {"levels": [0, 1]}},
        # `cvxdual solve --solver fast` as a user runs it: process start to exit, outputs written
        # (the default set, and with the figures, --plots)
        {"name": "cli", "tags": {"part": "cli"}, "scenes": [SCAN_SCENE], "levels": [0, 1, 2, 6],
         "solvers": ["fast"], "timeout": CVXPY_TIMEOUT, "quick": {"levels": [0, 1]}},
        # the equilibrium route (space, solve, exactness, bounds) against the P0 fast path, same meshes
        {"name": "eq", "tags": {"part": "eq"}, "scenes": EQ_SCENES, "stress_spaces": ["p0", "eq"],
         "triangulations": ["type2"], "levels": EQ_LEVELS, "solvers": ["fast"], "reference": "none",
         "timeout": CVXPY_TIMEOUT, "quick": {"levels": [1, 2]}},
        # the same eq runs with the P1 kinematic side (the certificate's displacement), for comparison
        {"name": "eq p1", "tags": {"part": "eq"}, "scenes": EQ_SCENES, "stress_spaces": ["eq"], "kinematic": "p1",
         "triangulations": ["type2"], "levels": EQ_LEVELS, "solvers": ["fast"], "reference": "none",
         "timeout": CVXPY_TIMEOUT, "quick": {"levels": [1, 2]}},
        # gmsh's time in an end-to-end run on outline bodies (measure: _meshing)
        *({"name": f"meshing {src.rsplit('/', 1)[-1]}", "tags": {"part": "meshing"}, "scenes": [src],
           "levels": levels, "solvers": ["fast"], "reference": "none", "check": False,
           "timeout": CVXPY_TIMEOUT, "quick": {"levels": [quick]}} for src, levels, quick in MESHING),
        {"name": "profile", "tags": {"part": "profile"}, "scenes": [SCAN_SCENE],
         "overrides": {"mesh": {"columns": SCAN_COLUMNS}}, "levels": [6], "solvers": ["fast"], "profile": True,
         "quick": {"levels": [2]}},
        *_pareto("hertz"), *_pareto("cylinder-in-groove"),
        {"name": "pareto sharply graded", "tags": {"part": "pareto", "mesh": "sharply graded"}, "scenes": ["hertz"],
         "overrides": HERTZ_SHARP, "solvers": ["fast"], "levels": [1, 2, 3, 4, 5, 6], "quick": {"levels": [1, 2]}},
        {"name": "solvers", "tags": {"part": "solvers"}, "scenes": ["hertz", "cylinder-in-groove"],
         "triangulations": ["type2"], "levels": [SOLVERS_LEVEL], "solvers": [*_installed(), "fast"],
         "check": False, "reference": "none", "timeout": SOLVER_TIMEOUT,
         "quick": {"levels": [QUICK_SOLVERS_LEVEL], "solvers": [s for s in _installed() if s in QUICK_SOLVERS]
                   + ["fast"]}},
        {"name": "solvers large", "tags": {"part": "solvers"}, "scenes": ["hertz"], "triangulations": ["type2"],
         "levels": [LARGE_SOLVERS_LEVEL], "solvers": [s for s in _installed() if s not in NOT_LARGE] + ["fast"],
         "check": False, "reference": "none", "timeout": LARGE_TIMEOUT,
         "quick": {"levels": [1], "solvers": ["CLARABEL", "SCS", "fast"]}},
    ],
}


def measure(case, sol) -> dict:
    """Extra measurements of some cases, in the case's own process (see the parts)."""
    part = dict(case.tags).get("part")
    if part == "meshing":
        return _meshing(case, sol)
    if case.solver != "fast":
        return {}
    if part == "scan":
        out = _write_summary(sol)
        if case.level == RULE_LEVEL:
            out.update(_rules(sol))
        return out
    if part == "small":
        return _small(case, sol)
    if part == "cli":
        return _cli(case)
    if part == "eq" and case.stress_space == "eq":
        out = {f"n_{k}": v for k, v in (("factorizations", sol.solver.get("factorizations")),
                                        ("corrections", sol.solver.get("corrections")),
                                        ("iterations_eq", sol.solver.get("iterations")),
                                        ("mu", sol.solver.get("n_mu"))) if v is not None}
        out.update(t_factor_eq=sol.solver.get("factor_time"))
        if case.level == EQ_RULE_LEVEL and sol.exact is not None:
            out.update(_eq_rules(sol))
        return out
    return {}


def _meshing(case, sol) -> dict:
    """The case's run again from the scene, meshing afresh, with gmsh on one thread and on two
    (the rest of the run keeps the case's one thread): gmsh's wall time (the size estimate's
    probe and the warm start's coarse meshes included) and the run's (solve and write the default
    outputs, no figures); then the run as a user starts it, ``cvxdual solve`` in a fresh process
    on the machine's threads (:func:`_cli_run`)."""
    import os
    import tempfile
    from pathlib import Path

    from cvxdual import solve
    from cvxdual.geometry.outline import forget_meshes, gmsh_seconds
    from cvxdual.outputs.output_set import write_outputs
    out, before = {}, os.environ.get("OMP_NUM_THREADS")
    try:
        for threads in (1, 2):
            os.environ["OMP_NUM_THREADS"] = str(threads)  # read by gmsh's meshing only: BLAS is set up already
            forget_meshes()
            g, t0 = gmsh_seconds(), time.perf_counter()
            s = solve(sol.scene, case.triangulation, case.level, case.solver, fallback=False)
            with tempfile.TemporaryDirectory() as d:
                write_outputs(s, Path(d) / "out", plots=False)
            out.update({f"t_run_gmsh{threads}": time.perf_counter() - t0, f"t_gmsh{threads}": gmsh_seconds() - g})
    finally:
        if before is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = before
    return {**out, **_cli_run(case)}


def _cli_run(case) -> dict:
    """``cvxdual solve`` of the case from process start to exit (imports, the scene's checks,
    meshing, the solve, the default outputs), with the machine's threads (two): its wall time and
    gmsh's, from ``summary.json``."""
    import json
    import os
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}  # the user's defaults
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "cvxdual", "solve", "--scene", case.scene_source, "--level",
                        str(case.level), "--solver", case.solver, "--triangulation", case.triangulation,
                        "--out", str(Path(d) / "out"), "--quiet"], check=True, env=env, capture_output=True)
        wall = time.perf_counter() - t0
        gmsh = json.loads((Path(d) / "out" / "summary.json").read_text())["timings"]["gmsh"]
    return {"t_cli": wall, "t_cli_gmsh": gmsh}


def _eq_rules(sol) -> dict:
    """The eq errors against the exact field with each rule per sub-triangle (``EQ_QUAD`` is the default)."""
    from cvxdual import exact_field
    from cvxdual.eq.bounds import exact_errors
    ex = exact_field(sol.scene)
    out = {}
    for n in EQ_RULES:
        t0 = time.perf_counter()
        # the certificate's displacement (P2: not its nodal values, sol.displacement)
        e = exact_errors(sol.space, sol.stress, sol.bounds["displacement"], ex, n=n, g=sol.column_stress)
        out[f"eqrule{n}_s"] = time.perf_counter() - t0
        out.update({f"eqrule{n}_{k}": e[k] for k in ("l2_rel", "combined")})
    return out


RULE_LEVEL = 5  # the scan level at which the quadrature rules are compared (2.5e5 pieces)
RULES = (2, 3, 4, 6, 8)
CLI_REPEATS = {0: 3, 1: 3, 2: 3}  # median of: the small runs are ~1 s on a shared machine


def _write_summary(sol) -> dict:
    """ "Mesh to written summary" time."""
    import tempfile
    from pathlib import Path

    from cvxdual.files import write_json
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        write_json(Path(d) / "summary.json", sol.summary())
    t = time.perf_counter() - t0
    return {"t_write": t, "t_end_to_end": sol.timings["total"] + t}


def _small(case, sol) -> dict:
    """The first solve in a new interpreter that imported only cvxdual (as the CLI; the case's
    own process has loaded CVXPY and Dask, whose libraries slow thread-pool discovery), best of
    3, and the steady state: the best of 5 more solves in this process."""
    import subprocess
    import sys

    from cvxdual import solve
    code = ("import cvxdual; print(cvxdual.solve({!r}, {!r}, {}, 'fast').timings['solve'])"
            .format(case.scene_source, case.triangulation, case.level))
    first = min(float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                     check=True).stdout) for _ in range(3))
    steady = min(solve(sol.scene, case.triangulation, case.level, "fast", fallback=False).timings["solve"]
                 for _ in range(5))
    return {"t_solve_first": first, "t_solve_steady": steady}


def _rules(sol) -> dict:
    """The error against the exact field with each rule: the rule's own error, and its cost."""
    from cvxdual import exact_field
    from cvxdual.p0.norms import stress_error
    ex = exact_field(sol.scene)
    out = {}
    for n in RULES:
        t0 = time.perf_counter()
        e = stress_error(sol.system, sol.stress, ex.stress, n)
        out[f"rule{n}_s"] = time.perf_counter() - t0
        out[f"rule{n}_l2_rel"] = e["l2_rel"]
        out[f"rule{n}_energy_rel"] = e["energy_rel"]
    return out


def _cli(case) -> dict:
    """Wall time of ``cvxdual solve --solver fast`` in a new process (imports, solve, the default
    outputs, exit) and of the same with ``--plots`` (the figures too), run in turns, medians; the
    CLI's own line gives the writing time."""
    import re
    import subprocess
    import sys
    import tempfile
    runs = {"": [], "_plots": []}
    for _ in range(CLI_REPEATS.get(case.level, 1)):
        for key in runs:
            with tempfile.TemporaryDirectory() as d:
                cmd = [sys.executable, "-m", "cvxdual.cli", "solve", "--scene", case.scene_source, "--solver",
                       "fast", "--level", str(case.level), "--triangulation", case.triangulation, "--out",
                       f"{d}/out", *(["--plots"] if key else [])]
                t0 = time.perf_counter()
                p = subprocess.run(cmd, capture_output=True, text=True, check=True)
                wall = time.perf_counter() - t0
            m = re.search(r"wrote .* in ([0-9.]+) s:", p.stdout)
            runs[key].append((wall, float(m.group(1)) if m else np.nan))
    out = {}
    for key, r in runs.items():
        wall, write = np.median(np.array(r), axis=0)
        out.update({f"t_cli{key}": float(wall), f"t_cli{key}_write": float(write)})
    return out


def _ok(d: pd.DataFrame) -> pd.Series:
    return d["status"].astype(str).str.startswith("optimal")


def _paths(df: pd.DataFrame) -> pd.DataFrame:
    d = df.copy()
    d["path"] = np.where(d["solver"].isin(["limit", "fast"]), d["solver"], "cvxpy")
    for c in ("t_limit", "t_factor", "backend", "t_solve_first", "t_solve_steady", "t_cli", "t_cli_write",
              "t_cli_plots", "t_cli_plots_write",
              "peak_mb", "t_end_to_end", "t_solve", "t_build", "t_total", "mesh", "paths_agree_l2_rel",
              "res_equilibrium", "_profile", "iterations"):
        if c not in d:
            d[c] = np.nan
    return d


def report(df: pd.DataFrame, study, out) -> str:
    from cvxdual.study.report import md_table
    d = _paths(df)
    scan, pareto, solv, small, cli = (d[d.part == p] for p in ("scan", "pareto", "solvers", "small", "cli"))
    prof, eq, mesh = d[d.part == "profile"], d[d.part == "eq"], d[d.part == "meshing"]
    if out is not None:
        _plots(scan, pareto, out)
    lines = [
        "Plots: `speed_scaling.png`, `speed_pareto.png`.", "",
        "## Targets", "",
        md_table(pd.DataFrame(_targets(scan, pareto, small, cli) + _eq_target(eq) + _meshing_target(mesh))), "",
        "Time to accuracy against other finite element codes: `peers.md`.", "",
        f"## The small end (`{SCAN_SCENE}`, its default mesh)", "",
        "`first solve` is the fast path's solve phase in a fresh process right after `import cvxdual` (what "
        "one CLI run pays in its solve, one-time library start-up included; imports count in `cli`; best of "
        "3); `steady` the best of 5 more solves in the case's process (what an API user solving repeatedly "
        "sees). `cli` is `cvxdual solve --solver fast` from process start to exit with the default outputs "
        "(`summary.json`, `contact.csv`, `solution.vtu`), `cli --plots` the same with the figures; the two run in "
        "turns, medians of 3 at levels 0-2; `writing` is the CLI's own measure of its output set.", "",
        md_table(_small_table(small, cli)), "",
        f"## Time and memory against size (`{SCAN_SCENE}`, {SCAN_COLUMNS} columns at level 0)", "",
        "`limit` is the fastest backend of `cvxdual.linalg.factor.backends()` on this machine (each timed after a "
        "small factorisation that pays its one-time start-up); the other backends' times follow. The fast and "
        "CVXPY paths are timed the same way: after a level-0 solve in the same process (and, for the fast "
        "path, a small factorisation by its large-system backend) that pays one-time library start-up; the "
        "first solve in a process is measured in \"The small end\".", "",
        md_table(_scan_table(scan)), "",
        *_rule_lines(scan),
        "Growth exponents (time ~ pieces^k, fitted from 1e4 pieces up):", "", md_table(_exponents(scan)), "",
        "## Where the time goes (profile of the largest fast-path run)", "", "```",
        _trim_profile(str(prof["_profile"].iloc[0]) if len(prof) and isinstance(prof["_profile"].iloc[0], str)
                      else ""), "```", "",
        *_eq_lines(eq),
        *_meshing_lines(mesh),
        "## Error against wall time", "",
        "Both triangulations, graded (the scene's own) and uniform meshes, both paths; `hertz` also with a sharply "
        "graded mesh. `cylinder-in-groove` is measured against a type 2 reference two levels finer (as in the "
        "convergence study).", "",
        md_table(_pareto_table(pareto)), "",
        "## QP solvers through CVXPY (type 2)", "",
        "`diff to fast` is the relative L2 distance of the stresses to the fast path's exact solution of the same "
        "discrete problem; `accepted` says whether the package's accuracy checks pass (they are required for a "
        "result to be returned). Time limits: "
        f"{SOLVER_TIMEOUT:.0f} s at level {SOLVERS_LEVEL}, {LARGE_TIMEOUT:.0f} s at level {LARGE_SOLVERS_LEVEL}; "
        f"not run at level {LARGE_SOLVERS_LEVEL}: {', '.join(NOT_LARGE)} (out of memory or over 100 s at 2.3k "
        "pieces when these settings were chosen).", "",
        md_table(_solver_table(solv[solv.solver != "fast"])), "",
        "The default when no solver is named (`cvxdual.convex.solvers.default_solver`), against the fastest accepted "
        "solver of each size in this run:", "", md_table(_default_table(solv)), ""]
    return "\n".join(lines)


def _scan_table(scan: pd.DataFrame) -> pd.DataFrame:
    ok = _ok(scan)
    lim = scan[scan.path == "limit"].set_index("level")
    rows = []
    for L in sorted(scan.level.unique()):
        r = {"level": L, "pieces": int(lim.loc[L, "n_pieces"]) if L in lim.index else np.nan,
             "limit s": lim.loc[L, "t_limit"] if L in lim.index else np.nan,
             "limit backend": lim.loc[L, "backend"] if L in lim.index else "-"}
        for path in ("fast", "cvxpy"):
            g = scan[(scan.path == path) & (scan.level == L)]
            good = len(g) and bool(ok[g.index[0]])
            r[f"{path} solve s"] = g.t_solve.iloc[0] if good else np.nan
            r[f"{path} total s"] = g.t_total.iloc[0] if good else np.nan
            r[f"{path} solve / limit"] = g.t_solve.iloc[0] / r["limit s"] if good else np.nan
            r[f"{path} MB"] = g.peak_mb.iloc[0] if good else np.nan
            if len(g) and not good:
                r["note"] = f"{path}: {g.status.iloc[0]}"
        cv = scan[(scan.path == "cvxpy") & (scan.level == L) & ok]
        if len(cv):
            r["cvxpy build share"] = cv.t_build.iloc[0] / cv.t_total.iloc[0]
        for b in ("pardiso", "cholmod", "superlu", "qdldl"):
            col = f"t_limit_{b}"
            if col in lim and L in lim.index:
                r[f"{b} s"] = lim.loc[L, col]
        rows.append(r)
    return pd.DataFrame(rows)


def _exponents(scan: pd.DataFrame) -> pd.DataFrame:
    from cvxdual.study.report import fit_rate
    rows = []
    for path in ("fast", "cvxpy", "limit"):
        d = scan[(scan.path == path) & _ok(scan)]
        d = d[d.n_pieces >= 1e4]  # growth exponents from the sizes where fixed costs no longer dominate
        cols = ["t_limit", "t_factor"] if path == "limit" else ["t_mesh", "t_assemble", "t_build", "t_solve",
                                                                 "t_recover", "t_total"]
        for c in cols + ["peak_mb"]:
            if c in d and len(d) >= 2:
                rows.append({"path": path, "quantity": c, "exponent": fit_rate(d.n_pieces, d[c]),
                             "sizes": f"{int(d.n_pieces.min())}-{int(d.n_pieces.max())}"})
    return pd.DataFrame(rows, columns=["path", "quantity", "exponent", "sizes"])


def _trim_profile(text: str) -> str:
    return "\n".join([ln for ln in text.splitlines() if ln.strip()][:32])


def _targets(scan: pd.DataFrame, pareto: pd.DataFrame, small: pd.DataFrame, cli: pd.DataFrame) -> list[dict]:
    out = []
    ok = _ok(scan)
    sm = small[_ok(small) & (small.level <= 1)]
    if len(sm):
        worst = sm.t_solve_first.max()
        out.append({"target": f"fast solve of {SCAN_SCENE} at levels 0-1 <= 20 ms (first solve in a process)",
                    "measured": ", ".join(f"level {int(r.level)}: {1e3 * r.t_solve_first:.1f} ms (steady "
                                          f"{1e3 * r.t_solve_steady:.1f} ms)" for r in sm.itertuples()),
                    "met": "yes" if worst <= 0.02 else "no"})
    c = cli[_ok(cli)]
    lo = c[c.level <= 2]
    if len(lo):
        out.append({"target": "`cvxdual solve --solver fast` (default outputs), process start to exit, level <= 2: "
                              "<= 1.0 s",
                    "measured": ", ".join(f"level {int(r.level)}: {r.t_cli:.2f} s" for r in lo.itertuples()),
                    "met": "yes" if lo.t_cli.max() <= 1.0 else "no"})
    hi = c[c.level >= 6]
    if len(hi):
        r = hi.iloc[0]
        share = r.t_cli_write / r.t_cli
        out.append({"target": f"the same at level {int(r.level)}: writing <= 25% of the total",
                    "measured": f"{r.t_cli_write:.2f} s of {r.t_cli:.2f} s ({100 * share:.0f}%)",
                    "met": "yes" if share <= 0.25 else "no"})
    lim = scan[scan.path == "limit"].set_index("level")
    f = scan[(scan.path == "fast") & ok & (scan.n_pieces >= 1e4)]
    if len(f) and len(lim):
        ratios = {int(r.n_pieces): r.t_solve / lim.loc[r.level, "t_limit"] for r in f.itertuples()}
        out.append({"target": "fast solve <= 2 x the limit from 1e4 pieces up",
                    "measured": ", ".join(f"{v:.2f} at {k}" for k, v in ratios.items()),
                    "met": "yes" if max(ratios.values()) <= 2 else "no"})
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
                    "measured": f"{100 * share:.1f}% at {int(r.n_pieces)} pieces",
                    "met": "yes" if share <= 0.2 else "no"})
    h = pareto[(pareto.scene == "hertz") & _ok(pareto)]
    good = h[h.error_l2_rel <= 0.01]
    target = "hertz: 1% relative L2 stress error in <= 1 s of solve time"
    if len(good):
        b = good.loc[good.t_solve.idxmin()]
        out.append({"target": target, "measured": f"{100 * b.error_l2_rel:.2f}% in {b.t_solve:.2f} s solve "
                    f"({b.path}, {b.mesh}, level {int(b.level)}, {int(b.n_pieces)} pieces)",
                    "met": "yes" if b.t_solve <= 1 else "no"})
    else:
        out.append({"target": target, "measured": "no run reached 1%", "met": "no"})
    return out


def _eq_table(eq: pd.DataFrame) -> pd.DataFrame:
    """P0 fast path and eq route side by side: whole runs, the eq phases, factorisations, memory."""
    ok = eq[_ok(eq)]
    side = ok["kinematic"] if "kinematic" in ok else pd.Series("p1", index=ok.index)  # rows before P2: P1
    p0 = ok[ok.stress_space == "p0"].set_index(["scene", "level"])
    q = ok[(ok.stress_space == "eq") & (side == "p2")].set_index(["scene", "level"])
    q1 = ok[(ok.stress_space == "eq") & (side == "p1")].set_index(["scene", "level"])
    t = pd.DataFrame({"pieces": p0["n_pieces"], "p0 s": p0["t_total"], "eq s": q.get("t_total"),
                      "eq / p0": q.get("t_total") / p0["t_total"], "eq P1 s": q1.get("t_total"),
                      "eq P1 / p0": q1.get("t_total") / p0["t_total"], "bound": q.get("bound_energy_rel"),
                      "bound P1": q1.get("bound_energy_rel"), "eq assemble s": q.get("t_assemble"),
                      "eq solve s": q.get("t_solve"), "of it factorising s": q.get("t_factor_eq"),
                      "factorisations": q.get("n_factorizations"), "eq recover s": q.get("t_recover"),
                      "unknowns of S": q.get("n_mu"), "p0 MB": p0.get("peak_mb"), "eq MB": q.get("peak_mb")})
    return t.reset_index().dropna(axis=1, how="all")


def _eq_target(eq: pd.DataFrame) -> list[dict]:
    t = _eq_table(eq)
    big = t[t.pieces >= 1e5] if len(t) else t
    if not len(big):
        return []
    return [{"target": "eq run (mesh to bounds) <= 4 x the P0 fast path at the same level, from 1e5 pieces up",
             "measured": ", ".join(f"{r['eq / p0']:.1f} ({r.scene}, {int(r.pieces)} pieces)"
                                   for _, r in big.iterrows()),
             "met": "yes" if big["eq / p0"].max() <= 4 else "no"}]


def _meshing_table(mesh: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for r in mesh[_ok(mesh)].itertuples():
        runs = [(f"in-process, gmsh on {n} thread{'s' * (n > 1)}", getattr(r, f"t_run_gmsh{n}", np.nan),
                 getattr(r, f"t_gmsh{n}", np.nan)) for n in (1, 2)]
        runs.append(("cvxdual solve, start to exit", getattr(r, "t_cli", np.nan), getattr(r, "t_cli_gmsh", np.nan)))
        for run, total, gm in runs:
            rows.append({"scene": r.scene, "level": r.level, "path": r.path, "pieces": r.n_pieces,
                         "run": run, "gmsh s": gm, "run s": total, "gmsh share": gm / total})
    return pd.DataFrame(rows)


def _meshing_target(mesh: pd.DataFrame) -> list[dict]:
    t = _meshing_table(mesh)
    if not len(t):
        return []
    t = t[t.pieces.between(*NEAR)]
    cli, inside = t[t.run.str.startswith("cvxdual")], t[t.run.str.endswith("2 threads")]

    def shares(d):
        return ", ".join(f"{r['gmsh share']:.0%} ({r.scene} {r.path}, {int(r.pieces)} pieces)" for _, r in d.iterrows())

    return [{"target": f"outline bodies: gmsh's share of an end-to-end run (`cvxdual solve`, start to exit) at "
                       f"{NEAR[0]:.0e} to {NEAR[1]:.0e} pieces <= {MESHING_SHARE:.0%}",
             "measured": shares(cli) + f"; in-process (solve and write only, gmsh on two threads): {shares(inside)}",
             "met": "yes" if len(cli) and cli["gmsh share"].max() <= MESHING_SHARE else "no"}]


def _meshing_lines(mesh: pd.DataFrame) -> list[str]:
    from cvxdual.study.report import md_table
    if not len(mesh):
        return []
    return ["## Meshing outline bodies (gmsh)", "",
            "Outline bodies are meshed by gmsh beyond the strip of columns along the face, as up to eight surfaces "
            "(cuts from the strip, through a hole in the way) meshed side by side when gmsh has two threads, the "
            "size field handed to gmsh at stops along the cuts and on rings round arcs. "
            "Each run is repeated in the case's process from the scene, meshing afresh (`in-process`): `gmsh s` is "
            "gmsh's wall time in it (the size estimate's probe mesh and the fast path's coarse warm-start meshes "
            "included), `run s` the solve and the default outputs (no figures, no process start, no scene checks); "
            "gmsh on one thread, then on two, the rest of the run on one. Then the same run as a user starts it "
            "(`cvxdual solve`, a fresh process on the machine's two threads, from start to exit: imports, the "
            "scene's checks, meshing, solve, default outputs), gmsh's time read from its `summary.json`.", "",
            md_table(_meshing_table(mesh)), ""]


def _eq_lines(eq: pd.DataFrame) -> list[str]:
    from cvxdual.study.report import md_table
    if not len(eq):
        return []
    lines = ["## The equilibrium route against the P0 fast path", "",
             "Type 2, the scene's own mesh, one process and one thread per run, all in one run: `p0` is the P0 fast "
             "path (mesh, assembly, active set, recovery, and the error where the scene has an exact field); `eq` "
             "is the whole equilibrium run on the same mesh with the default P2 kinematic side (the P1 solve, then "
             "the P2 system and its active-set solve: the certificate's displacement), `eq P1` the same with the "
             "P1 displacement as the kinematic side; `bound` is the certified relative energy error of each: "
             "the equilibrium space, its active-set solve on the condensed system `S` "
             "(`unknowns of S`: about 6 a triangle, against 1 a triangle for the P0 stiffness), the correction "
             "solve that makes the field exact, the certified bounds and the error. `factorising` is the time "
             "CHOLMOD spends on `S` (symbolic and numeric) for the `factorisations` the active set needed.", "",
             md_table(_eq_table(eq)), ""]
    r = eq[(eq.stress_space == "eq") & _ok(eq) & eq.get("eqrule2_s", pd.Series(dtype=float)).notna()] \
        if "eqrule2_s" in eq else eq.iloc[:0]
    if len(r):
        r = r.iloc[0]
        rows = [{"points per sub-triangle": n * n, "l2_rel": r[f"eqrule{n}_l2_rel"],
                 "change against 8x8": r[f"eqrule{n}_l2_rel"] / r["eqrule8_l2_rel"] - 1,
                 "combined": r[f"eqrule{n}_combined"],
                 "change of combined": r[f"eqrule{n}_combined"] / r["eqrule8_combined"] - 1,
                 "seconds": r[f"eqrule{n}_s"], "default": "yes" if n == 3 else ""} for n in EQ_RULES]
        lines += [f"### The quadrature rules' own error (eq, `{r.scene}` level {int(r.level)})", "",
                  "The eq stresses' relative L2 error and the combined error (what the bound dominates) against the "
                  "exact field with collapsed Gauss rules of n x n points per sub-triangle; the solve reports the "
                  "default rule's figures.", "", md_table(pd.DataFrame(rows)), ""]
    return lines


def _small_table(small: pd.DataFrame, cli: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for L in sorted(set(small.level) | set(cli.level)):
        r = {"level": L}
        s = small[(small.level == L) & _ok(small)]
        if len(s):
            r.update({"pieces": int(s.n_pieces.iloc[0]), "first solve ms": 1e3 * s.t_solve_first.iloc[0],
                      "steady solve ms": 1e3 * s.t_solve_steady.iloc[0]})
        c = cli[(cli.level == L) & _ok(cli)]
        if len(c):
            r.update({"pieces": int(c.n_pieces.iloc[0]), "cli s": c.t_cli.iloc[0], "writing s": c.t_cli_write.iloc[0],
                      "writing share": c.t_cli_write.iloc[0] / c.t_cli.iloc[0], "cli --plots s": c.t_cli_plots.iloc[0],
                      "--plots / default": c.t_cli_plots.iloc[0] / c.t_cli.iloc[0]})
        rows.append(r)
    return pd.DataFrame(rows)


def _rule_lines(scan: pd.DataFrame) -> list[str]:
    """The error against the exact field by rule: what the solve's default rule costs and misses."""
    from cvxdual.p0.norms import DEFAULT_QUAD
    from cvxdual.study.report import md_table
    r = scan[(scan.path == "fast") & (scan.level == RULE_LEVEL) & _ok(scan)]
    if not len(r) or f"rule{RULES[-1]}_l2_rel" not in r:
        return []
    r = r.iloc[0]
    best = r[f"rule{RULES[-1]}_l2_rel"]
    rows = [{"points per direction": n, "points per piece": n * n, "l2_rel": r[f"rule{n}_l2_rel"],
             f"change against {RULES[-1]}x{RULES[-1]}": r[f"rule{n}_l2_rel"] / best - 1,
             "energy_rel": r[f"rule{n}_energy_rel"], "seconds": r[f"rule{n}_s"],
             "default": "yes" if n == DEFAULT_QUAD else ""} for n in RULES]
    return [f"## The quadrature rule's own error (fast path, level {RULE_LEVEL}, {int(r.n_pieces)} pieces)", "",
            "The relative L2 and energy errors against the exact field with a tensor Gauss rule of n x n points "
            "per piece. The solve reports the default rule's figure.", "", md_table(pd.DataFrame(rows)), ""]


def _pareto_table(p: pd.DataFrame) -> pd.DataFrame:
    d = p[_ok(p)]
    cols = ["scene", "mesh", "triangulation", "path", "level", "n_pieces", "error_l2_rel", "t_solve", "t_total"]
    return d[cols].sort_values(["scene", "mesh", "triangulation", "path", "level"])


def _solver_table(s: pd.DataFrame) -> pd.DataFrame:
    from cvxdual.solution import TOLERANCES
    rows = []
    for r in s.itertuples():
        res = {k: getattr(r, f"res_{k}", np.nan) for k in TOLERANCES}
        accepted = str(r.status).startswith("optimal") and all(np.isfinite(v) and v <= TOLERANCES[k]
                                                               for k, v in res.items())
        rows.append({"scene": r.scene, "level": r.level, "pieces": r.n_pieces, "solver": r.solver,
                     "status": str(r.status)[:60], "solve s": r.t_solve,
                     "iterations": r.iterations, "diff to fast": r.paths_agree_l2_rel,
                     "equilibrium": res.get("equilibrium", np.nan), "accepted": "yes" if accepted else "no"})
    return pd.DataFrame(rows)


def _default_table(s: pd.DataFrame) -> pd.DataFrame:
    from cvxdual.convex.solvers import default_solver
    t = _solver_table(s[s.solver != "fast"])
    rows = []
    if not len(t):
        return pd.DataFrame(rows)
    for (scene, level), g in t.groupby(["scene", "level"], sort=False):
        ok = g[g.accepted == "yes"].sort_values("solve s")
        pieces = g.pieces.max()
        chosen = default_solver(pieces)
        mine = g[g.solver == chosen]
        rows.append({"scene": scene, "level": level, "pieces": pieces,
                     "fastest accepted": f"{ok.solver.iloc[0]} ({ok['solve s'].iloc[0]:.3g} s)" if len(ok) else "-",
                     "default": chosen, "default s": mine["solve s"].iloc[0] if len(mine) else np.nan,
                     "default accepted": mine.accepted.iloc[0] if len(mine) else "-"})
    return pd.DataFrame(rows)


def _plots(scan: pd.DataFrame, pareto: pd.DataFrame, out) -> None:
    from pathlib import Path

    from matplotlib.figure import Figure

    from cvxdual.study.report import plain_log_ticks, save_figure
    ok = _ok(scan)
    lim = scan[scan.path == "limit"]
    measured = np.isfinite(pd.to_numeric(scan.peak_mb, errors="coerce"))  # a case's own process peak, or NaN
    mem = {p: scan[(scan.path == p) & (ok | (p == "limit")) & measured] for p in ("fast", "cvxpy", "limit")}
    has_mem = any(len(d) for d in mem.values())  # a panel only for what was measured
    fig = Figure(figsize=(15 if has_mem else 10, 4.5), layout="constrained")
    axes = fig.subplots(1, 3 if has_mem else 2)
    for path, mk in (("fast", "o-"), ("cvxpy", "s-")):
        d = scan[(scan.path == path) & ok]
        axes[0].loglog(d.n_pieces, d.t_total, mk, label=f"{path}: total")
        axes[0].loglog(d.n_pieces, d.t_solve, mk.replace("-", ":"), label=f"{path}: solve")
    axes[0].loglog(lim.n_pieces, lim.t_limit, "k^-", label="limit: factorise + solve K")
    d = scan[(scan.path == "cvxpy") & ok]
    for ph in ("mesh", "assemble", "build", "solve", "recover"):
        axes[1].loglog(d.n_pieces, d[f"t_{ph}"], "s-", label=f"cvxpy {ph}")
    f = scan[(scan.path == "fast") & ok]
    for ph in ("solve", "recover"):
        axes[1].loglog(f.n_pieces, f[f"t_{ph}"], "o--", label=f"fast {ph}")
    panels = [(axes[0], "time against size", "time [s]"), (axes[1], "time per phase", "time [s]")]
    if has_mem:
        for (path, d), mk in zip(mem.items(), ("o-", "s-", "k^-"), strict=True):
            if len(d):
                axes[2].loglog(d.n_pieces, d.peak_mb, mk, label=path)
        panels.append((axes[2], "peak memory of the case's process", "peak memory [MB]"))
    else:
        fig.suptitle("peak memory: not measured in this run", fontsize=9)
    for ax, t, y in panels:
        ax.set(xlabel="number of pieces [-]", title=t, ylabel=y)
        plain_log_ticks(ax)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    save_figure(fig, Path(out) / "speed_scaling.png")
    scenes = list(dict.fromkeys(pareto.scene)) or ["hertz"]
    fig = Figure(figsize=(7 * len(scenes), 5), layout="constrained")
    for ax, scene in zip(fig.subplots(1, len(scenes), squeeze=False)[0], scenes, strict=True):
        d = pareto[(pareto.scene == scene) & _ok(pareto)]
        for (mesh, tri, path), g in d.groupby(["mesh", "triangulation", "path"], sort=False):
            g = g.sort_values("level")
            ax.loglog(g.t_total, g.error_l2_rel, "o-" if path == "fast" else "s--", ms=4,
                      label=f"{path}, {mesh}, {tri}")
        if scene == "hertz":
            ax.axhline(0.01, color="gray", lw=0.8, ls=":")
        ax.set(xlabel="wall time per solve, mesh to solution [s]", ylabel="relative L2 stress error [-]",
               title=f"{scene}: error against time")
        plain_log_ticks(ax)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    save_figure(fig, Path(out) / "speed_pareto.png")
