"""Numerical stability on hard cases: every case on both paths (CVXPY + Clarabel, and the fast
path) and both triangulations, taken unchecked so that degraded solutions are shown.

Not one grid, so a Python spec: ``SPEC`` lists the cases as blocks; ``report`` writes the
tables per group and the observations computed from them.
Run: ``python studies/stability.py [--quick]`` (or ``cvxdual study run studies/specs/stability.py``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from cvxdual.reference.hertz import hertz_line_contact

BOTH = ["CLARABEL", "fast"]
QUICK_LEVEL = {"levels": [1]}


def _nu(nu):
    return {"bodies": {"cylinder": {"material": {"nu": nu}}, "block": {"material": {"nu": nu}}}}


def _contrast(c):
    """Block modulus ``c`` times the cylinder's, with the load scaled by ``E*`` so that the
    contact half-width stays a = 6.21 mm (the exact field keeps its shape; p0 scales with E*)."""
    ref = hertz_line_contact(70000.0, 0.3, 210000.0, 0.3, 50.0, 35000.0).E_star
    e_star = hertz_line_contact(70000.0, 0.3, 70000.0 * c, 0.3, 50.0, 35000.0).E_star
    return {"bodies": {"block": {"material": {"E": 70000.0 * c}}}, "exact": {"load": 35000.0 * e_star / ref}}


BLOCKS_CLAMPED_BOTTOM = {"bodies": {"lower": {"boundary": {"push": {"traction": {"value": [0.0, 0.0]}},
                                                          "bottom": {"on": "far", "kind": "sliding"}}}}}
WAVES = {"bodies": {"waves": {"face": {"wavelength": 2.0, "amplitude": 0.004, "y0": -0.004}}}, "mesh": {"columns": 60}}


def _case(name, group, scene, overrides=None, level=3, quick=False, **kw):
    return {"name": name, "group": group, "scenes": [scene], "overrides": overrides or [], "levels": [level],
            "reference": "exact" if scene == "hertz" else "none", "quick": QUICK_LEVEL if quick else False, **kw}


SPEC = {
    "name": "stability",
    "title": "Numerical stability on hard cases",
    "description": (
        "Paths: `cvxpy` (CVXPY + Clarabel) and `fast` (active set + Pardiso). Solutions here are taken "
        "unchecked (`check=False`) so that degraded ones are shown, not rejected; `within_tolerances` says "
        "whether the package would return them. `paths_agree_l2_rel` is the relative L2 distance between "
        "the two paths' stresses; `error_l2_rel` is against the exact field (Hertz variants)."),
    "triangulations": ["type1", "type2"],
    "solvers": BOTH,
    "check": False,
    "compare": ["CLARABEL", "fast"],
    "report": {"setup": False, "rates": False, "plots": False, "failures": False},
    "cases": [
        *[_case(f"nu = {nu}", "near incompressibility (plane strain)", "hertz", _nu(nu),
                quick=nu in (0.3, 0.4999)) for nu in (0.3, 0.49, 0.499, 0.4999, 0.49999)],
        *[{**_case(f"nu = {nu}, refined", "near incompressibility under refinement (fast path)", "hertz", _nu(nu)),
           "levels": [1, 2, 3, 4, 5, 6], "solvers": ["fast"]} for nu in (0.49, 0.4999)],
        *[_case(f"E_lower / E_upper = {c:g}", "stiffness contrast", "hertz", _contrast(c), quick=c == 1e-6)
          for c in (1e-6, 1e-3, 1.0, 1e3, 1e6)],
        _case("MPa and mm", "physical units", "hertz"),
        _case("Pa and m", "physical units", "hertz", units=[1e-3, 1e6, "m", "Pa"], quick=True),
        _case("grading 1000 (h_min/h_max ~ 1e-3)", "strong grading, thin elements", "hertz",
              {"mesh": {"grading": 1000.0, "focus": [0.0, 0.5]}}),
        _case("thin layers at the face (aspect ~ 100)", "strong grading, thin elements", "hertz",
              {"mesh": {"grading": 200.0}, "bodies": {"cylinder": {"focus_depth": 0.05},
                                                       "block": {"focus_depth": 0.05}}}),
        _case("zero gap over a flat punch (corner singularities)", "gap", "patch",
              {"bodies": {"top": {"x": [2.0, 8.0]}}, "contact": {"interval": [2.0, 8.0]}}),
        _case("tiny gap (1e-9 of the body size)", "gap", "blocks", {"contact": {"gap": {"kind": "flat", "y0": 2e-8}}}),
        _case("interference fit (gap -1e-3 mm, no load)", "gap", "blocks",
              [{"contact": {"gap": {"kind": "flat", "y0": -1e-3}}}, BLOCKS_CLAMPED_BOTTOM], quick=True),
        _case("no contact (load too small to close the gap)", "gap", "blocks",
              [{"contact": {"gap": {"kind": "parabola", "R": 1000.0, "y0": 0.01}}},
               {"bodies": {"lower": {"body_force": [0.0, 1.0]}}}, BLOCKS_CLAMPED_BOTTOM], quick=True),
        _case("both bodies held only by contact and symmetry (hertz)", "semi-coercive", "hertz"),
        _case("lower body held only by contact and sliding sides (blocks)", "semi-coercive", "blocks"),
        _case("wavy, 15 waves", "many contact patches", "wavy", WAVES, level=2),
        {**_case("wavy, 15 waves, finest fast-path mesh", "many contact patches", "wavy", WAVES, level=5),
         "solvers": ["fast"]},
    ],
}

COLUMNS = ["case", "level", "triangulation", "path", "status", "iterations", "res_equilibrium", "res_constitutive",
           "res_complementarity", "duality_gap", "paths_agree_l2_rel", "error_l2_rel", "within_tolerances", "time"]


def _table(df: pd.DataFrame) -> pd.DataFrame:
    d = df.copy()
    d["path"] = np.where(d["solver"] == "fast", "fast", "cvxpy")
    d["time"] = d["t_total"]
    for c in COLUMNS:
        if c not in d:
            d[c] = np.nan
    d["status"] = d["status"].astype(str).str.replace("failed: ", "", regex=False)
    return d


def report(df: pd.DataFrame, study, out) -> str:
    from cvxdual.study.report import md_table
    d = _table(df)
    lines = []
    for group, g in d.groupby("group", sort=False):
        lines += [f"## {group}", "", md_table(g[COLUMNS]), ""]
    return "\n".join(lines + notes(d))


def notes(df: pd.DataFrame) -> list[str]:
    out = ["## What the table says", ""]
    ok = df[df.status == "optimal"]

    def group(name):
        return ok[ok.group.str.startswith(name)]

    nu = group("near incompressibility (")
    if len(nu):
        e = nu[nu.path == "fast"].groupby("case", sort=False)["error_l2_rel"].first()
        lvl = int(nu.level.iloc[0])
        ref = ok[ok.group.str.contains("refinement") & (ok.triangulation == "type1")]
        out.append(
            f"- Near incompressibility (level {lvl}): the relative stress error against the exact field goes "
            + ", ".join(f"{v:.3g} ({k})" for k, v in e.items())
            + ". Both paths agree on these numbers and every residual is small: this is the discretisation, not "
            "the solvers. On straight triangles the discrete dual is the Lagrangian dual of P1 displacements on "
            "the same mesh (docs/theory.md), so it inherits their volumetric locking: as nu -> 1/2 the "
            "compliance stops penalising the in-plane hydrostatic stress, and piecewise-constant stresses that "
            "balance P1 test functions can only meet the near-incompressibility through large spurious "
            "hydrostatic oscillations. The error does fall with h, but late: "
            + "; ".join(f"{k}: " + ", ".join(f"{v:.3g}" for v in g.sort_values("level").error_l2_rel)
                        + f" (levels {int(g.level.min())}-{int(g.level.max())})"
                        for k, g in ref.groupby("case", sort=False))
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
