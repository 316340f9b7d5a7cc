"""Numerical stability on hard cases: every case on every path and both triangulations.

Each case is a built-in scene with overrides. For each it records status (or the error), the
solver's iterations, the residuals, the duality gap, the agreement between the CVXPY path and
the fast path, the error against the exact field (``hertz`` variants) and the time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .common import Cache, Progress, md_table, scene_key, study_main, write_csv, write_text

TRIS = ("type1", "type2")
PATHS = ("cvxpy", "fast")


@dataclass(frozen=True)
class Case:
    name: str
    group: str
    scene: str
    overrides: tuple = ()
    level: int = 3
    units: tuple | None = None  # (length factor, stress factor, names): the same scene in other units
    paths: tuple = PATHS
    options: dict = field(default_factory=dict)  # CVXPY solver options (a cure)


def _nu(nu):
    return ({"bodies": {"cylinder": {"material": {"nu": nu}}, "block": {"material": {"nu": nu}}}},)


def _contrast(c):
    """Block modulus ``c`` times the cylinder's, with the load scaled by ``E*`` so that the
    contact half-width stays a = 6.21 mm (the exact field keeps its shape; p0 scales with E*)."""
    from ..hertz import hertz_line_contact
    ref = hertz_line_contact(70000.0, 0.3, 210000.0, 0.3, 50.0, 35000.0).E_star
    e_star = hertz_line_contact(70000.0, 0.3, 70000.0 * c, 0.3, 50.0, 35000.0).E_star
    return ({"bodies": {"block": {"material": {"E": 70000.0 * c}}}, "exact": {"load": 35000.0 * e_star / ref}},)


BLOCKS_CLAMPED_BOTTOM = {"bodies": {"lower": {"boundary": {"push": {"traction": {"value": [0.0, 0.0]}},
                                                          "bottom": {"on": "far", "kind": "sliding"}}}}}

CASES = [
    *[Case(f"nu = {nu}", "near incompressibility (plane strain)", "hertz", _nu(nu)) for nu in
      (0.3, 0.49, 0.499, 0.4999, 0.49999)],
    *[Case(f"nu = {nu}, level {L}", "near incompressibility under refinement (fast path)", "hertz", _nu(nu),
           level=L, paths=("fast",)) for nu in (0.49, 0.4999) for L in (1, 2, 3, 4, 5, 6)],
    *[Case(f"E_lower / E_upper = {c:g}", "stiffness contrast", "hertz", _contrast(c)) for c in
      (1e-6, 1e-3, 1.0, 1e3, 1e6)],
    Case("MPa and mm", "physical units", "hertz"),
    Case("Pa and m", "physical units", "hertz", units=(1e-3, 1e6, ("m", "Pa"))),
    Case("grading 1000 (h_min/h_max ~ 1e-3)", "strong grading, thin elements", "hertz",
         ({"mesh": {"grading": 1000.0, "focus": [0.0, 0.5]}},), level=3),
    Case("thin layers at the face (aspect ~ 100)", "strong grading, thin elements", "hertz",
         ({"mesh": {"grading": 200.0}, "bodies": {"cylinder": {"focus_depth": 0.05},
                                                   "block": {"focus_depth": 0.05}}},), level=3),
    Case("zero gap over a flat punch (corner singularities)", "gap", "patch",
         ({"bodies": {"top": {"x": [2.0, 8.0]}}, "contact": {"interval": [2.0, 8.0]}},)),
    Case("tiny gap (1e-9 of the body size)", "gap", "blocks",
         ({"contact": {"gap": {"kind": "flat", "y0": 2e-8}}},)),
    Case("interference fit (gap -1e-3 mm, no load)", "gap", "blocks",
         ({"contact": {"gap": {"kind": "flat", "y0": -1e-3}}}, BLOCKS_CLAMPED_BOTTOM)),
    Case("no contact (load too small to close the gap)", "gap", "blocks",
         ({"contact": {"gap": {"kind": "parabola", "R": 1000.0, "y0": 0.01}}},
          {"bodies": {"lower": {"body_force": [0.0, 1.0]}}}, BLOCKS_CLAMPED_BOTTOM)),
    Case("both bodies held only by contact and symmetry (hertz)", "semi-coercive", "hertz"),
    Case("lower body held only by contact and sliding sides (blocks)", "semi-coercive", "blocks"),
    Case("wavy, 15 waves", "many contact patches", "wavy",
         ({"bodies": {"waves": {"face": {"wavelength": 2.0, "amplitude": 0.004, "y0": -0.004}}},
           "mesh": {"columns": 60}},), level=2),
    Case("wavy, 15 waves, finest fast-path mesh", "many contact patches", "wavy",
         ({"bodies": {"waves": {"face": {"wavelength": 2.0, "amplitude": 0.004, "y0": -0.004}}},
           "mesh": {"columns": 60}},), level=5, paths=("fast",)),
]
QUICK_NAMES = {"nu = 0.3", "nu = 0.4999", "E_lower / E_upper = 1e-06", "Pa and m", "interference fit (gap -1e-3 mm, no load)",
               "no contact (load too small to close the gap)"}


def _scene(case: Case):
    from ..scene import convert_units
    from ..scenefile import load_scene
    sc = load_scene(case.scene, [dict(o) for o in case.overrides])
    if case.units is not None:
        sc = convert_units(sc, case.units[0], case.units[1], case.units[2])
    return sc


def _run(case: Case, tri: str, path: str, level: int) -> tuple[dict, object | None]:
    from ..errors import CvxdualError
    from ..solution import solve
    sc = _scene(case)
    t0 = time.perf_counter()
    row = {"group": case.group, "case": case.name, "scene": case.scene, "triangulation": tri, "path": path,
           "level": level}
    try:
        sol = solve(sc, tri, level, "fast" if path == "fast" else "CLARABEL", check=False, **case.options)
    except CvxdualError as e:
        row.update(status=f"{type(e).__name__}: {e}"[:160], time=time.perf_counter() - t0)
        return row, None
    from ..solution import TOLERANCES
    res = sol.residuals
    row.update(status=sol.solver["status"], iterations=sol.solver.get("iterations"), n_pieces=sol.system.n_pieces,
               h_ratio=sol.mesh.h_min / sol.mesh.h, **{f"res_{k}": v for k, v in res.items()},
               duality_gap=sol.duality_gap, within_tolerances=all(res[k] <= v for k, v in TOLERANCES.items()),
               n_active=sol.contact["n_active"], total_force=sol.contact["total_force"],
               n_patches=int(np.sum(np.diff(np.r_[0, sol.contact["active"].astype(int)]) == 1)),
               max_pressure=sol.contact["max_pressure"],
               error_l2_rel=(sol.error or {}).get("l2_rel", np.nan), time=time.perf_counter() - t0)
    return row, sol


def run(out: str | Path, quick: bool = False, cache_dir: str | Path | None = ".cache/cvxdual",
        progress: bool = True) -> pd.DataFrame:
    from ..norms import l2_norm
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Cache(None if cache_dir is None else Path(cache_dir) / "stability")
    cases = [c for c in CASES if not quick or c.name in QUICK_NAMES]
    n = sum(len(c.paths) * len(TRIS) for c in cases)
    prog = Progress(n, "stability", progress)
    rows = []
    for case in cases:
        level = min(case.level, 1) if quick else case.level
        for tri in TRIS:
            key = f"case-{scene_key(case, tri, level)}"
            hit = cache.get_row(key)
            if hit is not None:
                rows += hit["rows"]
                for _ in case.paths:
                    prog.step(f"{case.name} {tri}", 0.0, cached=True)
                continue
            sols, these = {}, []
            for path in case.paths:
                t0 = time.perf_counter()
                row, sol = _run(case, tri, path, level)
                sols[path] = sol
                these.append(row)
                prog.step(f"{case.name} {tri} {path}: {row['status'][:40]}", time.perf_counter() - t0)
            if all(sols.get(p) is not None for p in PATHS):
                a, b = sols["cvxpy"], sols["fast"]
                d = l2_norm(a.system, a.stress - b.stress) / max(l2_norm(b.system, b.stress), 1e-300)
                for r in these:
                    r["paths_agree_l2_rel"] = d
            cache.put_row(key, {"rows": these})
            rows += these
    df = pd.DataFrame(rows)
    write_csv(df, out / "stability.csv")
    write_text(out / "stability.md", _report(df, quick))
    return df


def _report(df: pd.DataFrame, quick: bool) -> str:
    cols = ["case", "triangulation", "path", "status", "iterations", "res_equilibrium", "res_constitutive",
            "res_complementarity", "duality_gap", "paths_agree_l2_rel", "error_l2_rel", "within_tolerances", "time"]
    lines = ["# Numerical stability on hard cases", "",
             "Generated by `python studies/stability.py`" + (" --quick" if quick else "") + " (CSV: `stability.csv`). "
             "Paths: `cvxpy` (CVXPY + Clarabel) and `fast` (active set + Pardiso). Solutions here are taken "
             "unchecked (`check=False`) so that degraded ones are shown, not rejected; `within_tolerances` says "
             "whether the package would return them. `paths_agree_l2_rel` is the relative L2 distance between "
             "the two paths' stresses; `error_l2_rel` is against the exact field (Hertz variants).", ""]
    for group, g in df.groupby("group", sort=False):
        lines += [f"## {group}", "", md_table(g[[c for c in cols if c in g.columns]].fillna(np.nan)), ""]
    lines += _notes(df)
    return "\n".join(lines) + "\n"


def _notes(df) -> list[str]:
    out = ["## What the table says", ""]
    ok = df[df.status == "optimal"]

    def group(name):
        return ok[ok.group.str.startswith(name)]

    nu = group("near incompressibility (")
    if len(nu):
        e = nu[nu.path == "fast"].groupby("case", sort=False)["error_l2_rel"].first()
        lvl = int(nu.level.iloc[0])
        out.append(
            f"- Near incompressibility (level {lvl}): the relative stress error against the exact field goes "
            + ", ".join(f"{v:.3g} ({k})" for k, v in e.items())
            + ". Both paths agree on these numbers and every residual is small: this is the discretisation, not "
            "the solvers. On straight triangles the discrete dual is the Lagrangian dual of P1 displacements on "
            "the same mesh (MATH.md section 3), so it inherits their volumetric locking: as nu -> 1/2 the "
            "compliance stops penalising the in-plane hydrostatic stress, and piecewise-constant stresses that "
            "balance P1 test functions can only meet the near-incompressibility through large spurious "
            "hydrostatic oscillations. The error does fall with h, but late: "
            + "; ".join(f"{nu_}: " + ", ".join(f"{v:.3g}" for v in g.sort_values('level').error_l2_rel)
                        + f" (levels {int(g.level.min())}-{int(g.level.max())})"
                        for nu_, g in ok[ok.group.str.contains("refinement") & (ok.triangulation == "type1")].groupby(
                            ok.case.str.split(",").str[0], sort=False))
            + ". No cure is within the reach of scaling, regularisation or solver "
            "settings; the known cure is a locking-free stress space (e.g. the crossed-triangle macro-elements "
            "of Nagtegaal, Parks and Rice, 1974), which is neither of the paper's two triangulations.")
    con = group("stiffness")
    if len(con):
        e = con["error_l2_rel"]
        out.append(
            f"- Stiffness contrast 1e-6 to 1e6 (load scaled so that a stays 6.21 mm): errors {e.min():.4g} to "
            f"{e.max():.4g}, largest residual {con[['res_equilibrium', 'res_complementarity']].max().max():.1e}, "
            f"paths agree to {con['paths_agree_l2_rel'].max():.1e}. The QP is nondimensionalised by the stiffer "
            "body's uniaxial modulus and Clarabel equilibrates the rest; the active-set path factorises a "
            "stiffness with a 1e6 contrast without trouble.")
    un = group("physical")
    if len(un):
        e = un.groupby("case")["error_l2_rel"].first()
        out.append(f"- Units: the same errors in MPa/mm and Pa/m ({', '.join(f'{v:.10g}' for v in e)}): "
                   "the nondimensionalised QPs are the same.")
    gr = group("strong")
    if len(gr):
        out.append("- Strong grading and thin elements: smallest/largest edge ratio "
                   + ", ".join(f"{r:.1e}" for r in gr.groupby("case", sort=False)["h_ratio"].first())
                   + f"; residuals at most {gr[['res_equilibrium', 'res_complementarity']].max().max():.1e}, "
                   f"paths agree to {gr['paths_agree_l2_rel'].max():.1e}, errors "
                   + ", ".join(f"{v:.3g}" for v in gr.groupby("case", sort=False)["error_l2_rel"].first()) + ".")
    gp = group("gap")
    if len(gp):
        out.append("- Gaps: " + "; ".join(
            f"{c}: {int(g.n_active.iloc[0])} active pairs, total force {g.total_force.iloc[0]:.4g}, "
            f"paths agree to {g.paths_agree_l2_rel.max():.1e}" for c, g in gp.groupby("case", sort=False)) + ".")
    sc = group("semi")
    if len(sc):
        out.append(f"- Semi-coercive bodies: residuals at most "
                   f"{sc[['res_equilibrium', 'res_complementarity']].max().max():.1e}, duality gap at most "
                   f"{sc.duality_gap.max():.1e}, paths agree to {sc.paths_agree_l2_rel.max():.1e}.")
    mp = group("many")
    if len(mp):
        out.append("- Many patches: " + "; ".join(
            f"{c} ({r.path}, {r.triangulation}, {int(r.n_pieces)} pieces): {int(r.n_patches)} patches in "
            f"{r.time:.1f} s" for c, g in mp.groupby("case", sort=False) for r in g.itertuples()) + ".")
    bad = df[df.status != "optimal"]
    if len(bad):
        out.append("- Failures (each raised a cvxdual error, nothing was returned): "
                   + "; ".join(f"{r.case} {r.path} {r.triangulation}: {r.status}" for r in bad.itertuples()) + ".")
    return out


def main(argv=None) -> int:
    return study_main("stability", __doc__, run, argv, quick_help="a few cases at level <= 1")
