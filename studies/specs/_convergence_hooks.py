"""The convergence study's observations (computed from its table): ``report(df, study, out)``."""

from __future__ import annotations

import numpy as np
import pandas as pd

from cvxdual.study.cases import EDGE_RADIUS
from cvxdual.study.report import rates


def _space(d: pd.DataFrame, space: str) -> pd.DataFrame:
    return d[d.stress_space == space] if "stress_space" in d.columns else (d if space == "p0" else d.iloc[:0])


def _rate(r: pd.DataFrame, scene: str, tri: str, space: str = "p0") -> float:
    m = _space(r, space)
    m = m[(m.scene == scene) & (m.triangulation == tri)]
    return float(m["rate_l2"].iloc[0]) if len(m) else float("nan")


def _err(df: pd.DataFrame, scene: str, tri: str, space: str = "p0") -> float:
    g = _space(df, space)
    g = g[(g.scene == scene) & (g.triangulation == tri)]
    return float(g.sort_values("level")["error_l2_rel"].iloc[-1]) if len(g) else float("nan")


def report(df: pd.DataFrame, study, out) -> str:
    import cvxdual
    all_r, last_r = rates(df), rates(df, 3)
    refs = df.attrs.get("references", {})
    lines = ["## What the rates say", ""]
    scenes = set(df.scene)
    if "hertz" in scenes:
        r, r3 = _rate(all_r, "hertz", "type1"), _rate(last_r, "hertz", "type1")
        g = df[(df.scene == "hertz") & (df.triangulation == "type1")].sort_values("level")
        share = g["edge_error_share"].to_numpy(float)
        ex = cvxdual.exact_field(cvxdual.load_scene("hertz")).hertz
        da = 100 * (g["contact_x_max"].to_numpy(float) / ex.a - 1)
        dp = 100 * (g["peak_pressure"].to_numpy(float) / ex.p0 - 1)
        lines.append(
            f"- `hertz` (flat faces, so type 1 = type 2): rate {r:.2f} against the exact field ({r3:.2f} over "
            "the last three levels), the best piecewise-constant stresses can do in L2. What limits it is the "
            "square-root behaviour at the contact edges `x = +-a`, where the pressure and the stress gradients "
            "grow like `r^-1/2`: still square-integrable, so the L2 rate survives, but the error concentrates "
            f"there. The discs of radius {EDGE_RADIUS}a around the edges (0.03% of the domain) hold "
            f"{100 * share[0]:.1f}% of the squared error at level {int(g.level.iloc[0])} and "
            f"{100 * share[-1]:.1f}% at level {int(g.level.iloc[-1])}"
            + (": the edge error decays more slowly than the rest and will set the asymptotic rate below 1"
               if share[-1] > share[0] else "") + ". The contact quantities converge irregularly, as the edge "
            "moves across elements: half-width (last active pair) off by "
            + ", ".join(f"{v:+.1f}%" for v in da) + "; peak nodal pressure off by "
            + ", ".join(f"{v:+.1f}%" for v in dp) + " (levels in order).")
    if "cylinder-in-groove" in scenes:
        r1, r2 = _rate(all_r, "cylinder-in-groove", "type1"), _rate(all_r, "cylinder-in-groove", "type2")
        e1, e2 = _err(df, "cylinder-in-groove", "type1"), _err(df, "cylinder-in-groove", "type2")
        better = "beats" if e2 < e1 else "does not beat"
        lines.append(
            f"- `cylinder-in-groove` (convex on concave, contact over most of the concave arc): type 2 {better} "
            f"type 1, rate {r2:.2f} against {r1:.2f}, finest errors {e2:.3g} against {e1:.3g}. Why: on a "
            "non-convex stretch type 1 uses curved triangles on which `v_h` is constant along y, so their "
            "strain has no `e22` and their stress `s22` enters no admissibility condition; the complementary "
            "energy then sets it from `s11` and `s12` alone (`s22 = -(A21 s11 + A23 s12) / A22`, i.e. "
            "`nu / (1 - nu) s11` for an isotropic body in plane strain), not from the contact pressure, although "
            "the true `s22` there is about minus the contact pressure. That band is one element layer thick: "
            "an `O(h^1/2)` L2 error. "
            "Type 2 moves the contact nodes onto a tangent polygon and confines the same defect to the sliver "
            "`D_h` between polygon and arc, of thickness `O(h^2)`, so its error converges like the rest.")
    if "wavy" in scenes:
        r1, r2 = _rate(all_r, "wavy", "type1"), _rate(all_r, "wavy", "type2")
        lines.append(
            f"- `wavy`: rates {r1:.2f} (type 1) and {r2:.2f} (type 2). The concave valleys stay open, so type 1's "
            "defect sits where the contact pressure is zero and costs little; the three contact patches each "
            "have square-root edges, which limit both types as in `hertz`.")
    if "cylinder-on-block" in scenes:
        r1 = _rate(all_r, "cylinder-on-block", "type1")
        lines.append(
            f"- `cylinder-on-block` (convex on flat): no non-convex stretch, so type 1 and type 2 are the same "
            f"triangulation and give identical numbers; rate {r1:.2f}. The segments between chords and arc are "
            "`O(h^2)` thin and do not limit the rate.")
    for name, r in refs.items():
        fin = _space(df, "p0")
        fin = fin[fin.scene == name]["error_l2_rel"].min()
        if np.isfinite(fin) and r["error_est"] > 0.3 * fin:
            lines.append(f"- Caution for `{name}`: the reference's estimated error ({r['error_est']:.2g}) is not "
                         f"small against the finest studied P0 error ({fin:.2g}); the last rates there are "
                         "underestimated.")
    lines += ["", *_references(df, refs), *_equilibrium(df, all_r)]
    return "\n".join(lines)


def _references(df: pd.DataFrame, refs: dict) -> list[str]:
    """How good the curved scenes' references are, against the finest P0 errors."""
    rows = []
    for name, r in refs.items():
        p0 = _space(df, "p0")
        fin = p0[p0.scene == name]["error_l2_rel"].min()
        what = f"{r['triangulation']} level {r['level']} {r.get('stress_space', 'p0')}"
        rows.append({"scene": name, "reference": what, "estimated error": r["error_est"], "finest P0 error": fin,
                     "ratio": r["error_est"] / fin, "certified energy bound": r.get("certified")})
    if not rows:
        return []
    t = pd.DataFrame(rows)
    ok = bool((t["ratio"] <= 0.1).all())
    R = sorted({int(r["level"]) for r in refs.values()})
    levels = ", ".join(f"{L - 2}-{L}" for L in R)
    from cvxdual.study.report import md_table
    return ["## The references", "",
            "The curved scenes are measured against their equilibrium stresses two levels above the finest eq "
            "rows (type 2): exactly admissible, so their certified bound holds for them as for any eq solution. "
            f"The estimated error extrapolates the differences between its levels ({levels}; the setup above); "
            "the certified bound (relative energy error of the stresses and of the P1 displacement together) "
            "is far larger because the displacement's own error dominates it.", "", md_table(t), "",
            f"Every reference's estimated error is {'at most' if ok else 'NOT at most'} a tenth of the finest "
            "P0 error it measures.", ""]


def _equilibrium(df: pd.DataFrame, all_r: pd.DataFrame) -> list[str]:
    """The eq rows: errors against the reference beside the certified bound, and against P0."""
    eq = _space(df, "eq")
    if not len(eq):
        return []
    from cvxdual.study.report import md_table
    p0 = _space(df, "p0")
    m = eq.merge(p0[["scene", "triangulation", "level", "error_l2_rel", "error_energy_rel"]],
                 on=["scene", "triangulation", "level"], suffixes=("", "_p0"))
    cols = ["scene", "triangulation", "level", "n_pieces", "error_l2_rel", "error_energy_rel", "bound_energy_rel",
            "guaranteed", "error_l2_rel_p0", "t_total"]
    t = m[[c for c in cols if c in m.columns]].sort_values(["scene", "triangulation", "level"])
    held = bool((m["error_energy_rel"] <= m["bound_energy_rel"]).all())
    lines = ["## Equilibrium stresses on the curved scenes", "",
             "Per level: the eq stresses' relative L2 and energy errors against the reference, their certified "
             "bound on the relative energy error, whether it is guaranteed, and the P0 stresses' L2 error at "
             "the same level.", "", md_table(t.rename(columns={"error_l2_rel_p0": "P0 error_l2_rel"})), "",
             f"- The certified bound is {'above' if held else 'NOT above'} the energy error measured against the "
             "reference in every row (the reference's own error aside).",
             f"- Guaranteed in {int(m['guaranteed'].astype(bool).sum())} of {len(m)} rows."]
    ratio = (m["error_l2_rel"] / m["error_l2_rel_p0"]).replace([np.inf], np.nan).dropna()
    if len(ratio):
        lines.append(f"- eq over P0 relative L2 error, same mesh: {ratio.min():.3f} to {ratio.max():.3f}.")
    for scene in sorted(set(eq.scene)):
        r1, r2 = _rate(all_r, scene, "type1", "eq"), _rate(all_r, scene, "type2", "eq")
        lines.append(f"- `{scene}`, eq rates (relative L2, all levels): type 1 {r1:.2f}, type 2 {r2:.2f}.")
    # an eq row within a few times the reference's own error measures the reference as much as itself
    close = m[m["error_l2_rel"] < 3.0 * m["reference_error_est"]]
    if len(close):
        lines.append("- Rows whose eq error is less than 3 times the reference's estimated error (the error "
                     "against the reference mixes both, and the rates above flatten there; the certified bound "
                     "is the measure at those levels): "
                     + ", ".join(f"`{r.scene}` {r.triangulation} level {int(r.level)}" for r in close.itertuples())
                     + ".")
    return lines + [""]
