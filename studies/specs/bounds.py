"""Certified bounds and the equilibrium stress space against the paper's P0 stresses.

Per level and Poisson ratio (plane strain, both bodies): the P0 dual on the fast path, and the
equilibrium (Johnson-Mercier, with column stresses on curved pieces) stresses with the certified
energy bracket, ``G`` and the bound ``sqrt(2G)`` on the combined error of the P1 displacement and
the equilibrium stresses (docs/equilibrium.md). Flat faces: ``hertz`` (against its exact field:
the effectivity ``sqrt(2G) / true``), ``blocks`` and ``patch`` at nu = 0.3, 0.49, 0.4999. Curved
faces: ``cylinder-on-block``, ``cylinder-in-groove`` and ``wavy``, both triangulations, at nu =
0.3 and 0.4999, levels 0-4, against the equilibrium stresses at level 5 (type 2) of the same scene,
and at level 5 their bounds alone (the finest energy brackets).
Run: ``python studies/bounds.py [--quick]`` (or ``cvxdual study run studies/specs/bounds.py``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

FLAT, CURVED = ("hertz", "blocks", "patch"), ("cylinder-on-block", "cylinder-in-groove", "wavy")
NUS = {"flat": (0.3, 0.49, 0.4999), "curved": (0.3, 0.4999)}
BODIES = {"hertz": ("cylinder", "block"), "blocks": ("upper", "lower"), "patch": ("top", "bottom"),
          "cylinder-on-block": ("cylinder", "block"), "cylinder-in-groove": ("cylinder", "groove"),
          "wavy": ("block", "waves")}
LEVELS = {"hertz": [0, 1, 2, 3, 4, 5], "blocks": [0, 1, 2, 3, 4, 5], "patch": [1, 2, 3],
          **{s: [0, 1, 2, 3, 4] for s in CURVED}}
# the curved scenes' reference (type 2, fast route). Level 5, not 6: every row's error is integrated
# over the reference's cells, about 25 s a row at level 5 and 100 s at level 6 (120 curved rows);
# the errors, rates and effectivities use the levels at least two below it (0-3), level 4 adds its
# bounds (guarantees, brackets, type 1 against type 2)
REFERENCE = {"level": 5, "stress_space": "eq"}
EQ_SOLVER = "fast"  # cvxdual.eq.fast: the same QP as the CVXPY path, checked against it in the tests
TARGET = 0.01  # "the time each space needs for 1% stress error"


def _finest(scene: str, nu: float) -> dict:
    """The curved scenes' eq stresses at the reference's level, bounds only (no reference to measure
    errors against there): the finest brackets of the energy."""
    return {"name": f"{scene} eq nu={nu} bounds", "scenes": [scene], "stress_spaces": ["eq"], "solvers": [EQ_SOLVER],
            "levels": [REFERENCE["level"]], "reference": "none", "triangulations": ["type1", "type2"],
            "overrides": {"bodies": {b: {"material": {"nu": nu}} for b in BODIES[scene]}}, "tags": {"nu": nu},
            "quick": False}


def _block(scene: str, space: str, solver: str, nu: float) -> dict:
    """One scene, stress space and Poisson ratio (both bodies), every level (and on curved scenes
    both triangulations)."""
    material = {"material": {"nu": nu}}
    curved = scene in CURVED
    quick = scene not in ("blocks", "wavy") and nu in (0.3, 0.4999)
    reference = REFERENCE if curved else "exact" if scene != "blocks" else "none"
    return {"name": f"{scene} {space} nu={nu}", "scenes": [scene], "stress_spaces": [space], "solvers": [solver],
            "levels": LEVELS[scene], "reference": reference, "triangulations": ["type1", "type2"] if curved
            else ["type1"], "overrides": {"bodies": {b: material for b in BODIES[scene]}}, "tags": {"nu": nu},
            "quick": ({"levels": [0, 1], "reference": {**REFERENCE, "level": 3}} if curved else {"levels": [0, 1]})
            if quick else False}


SPEC = {
    "name": "bounds",
    "title": "Certified bounds: equilibrium stresses against the P0 dual",
    "description": (
        "`p0`: the paper's piecewise-constant stresses (fast path). `eq`: exactly admissible Johnson-Mercier "
        "stresses on the straight pieces and column stresses `g(x) e_y (x) e_y` on the curved ones, on the same "
        "mesh, certified against the P1 displacement of the P0 solve made pointwise admissible: `energy_lower <= "
        "J(u) <= energy_upper`, `G` their difference, `bound = sqrt(2G)` bounds `sqrt(||u - v||_a^2 + ||sigma - "
        "lam*||_A^2)`. `true` is that combined error against the exact field (hertz) or the reference (curved "
        "scenes), `effectivity = bound / true`. Errors are relative L2 stress errors against the same."),
    "metrics": {"edge_share": False, "check": "none"},
    "report": {"rates": False, "plots": False},
    "cases": [_block(s, sp, "fast" if sp == "p0" else EQ_SOLVER, nu) for s in FLAT + CURVED
              for sp in ("p0", "eq") for nu in NUS["curved" if s in CURVED else "flat"]]
    + [_finest(s, nu) for s in CURVED for nu in NUS["curved"]],
}


def measure(case, sol) -> dict:
    """The bound columns of an ``eq`` row (a ``p0`` row certifies the same pair: not repeated);
    the true combined error and the effectivity come with the errors (``error_combined``)."""
    if sol.bounds is None:
        return {}
    b, e = sol.bounds, sol.error or {}
    return {"energy_lower": b["energy_lower"], "energy_upper": b["energy_upper"], "G": b["gap"],
            "bound": b["error_bound"], "data_oscillation": b["data_oscillation"],
            "stress_error_A": e.get("energy", np.nan), "displacement_error_a": e.get("displacement_energy", np.nan)}


def _table(d: pd.DataFrame) -> pd.DataFrame:
    keys = ["triangulation", "nu", "level"] if d.triangulation.nunique() > 1 else ["nu", "level"]
    p0 = d[d.stress_space == "p0"].set_index(keys)
    eq = d[d.stress_space == "eq"].set_index(keys)
    t = pd.DataFrame({"h": eq["h"], "p0 L2 rel": p0["error_l2_rel"], "eq L2 rel": eq["error_l2_rel"],
                      "J lower": eq.get("energy_lower"), "J upper": eq.get("energy_upper"), "G": eq.get("G"),
                      "bound": eq.get("bound"), "bound rel": eq.get("bound_energy_rel"),
                      "true": eq.get("error_combined"), "effectivity": eq.get("effectivity"),
                      "guaranteed": eq.get("guaranteed"), "t p0 [s]": p0["t_total"], "t eq [s]": eq["t_total"]})
    t = t.reset_index().dropna(axis=1, how="all")
    t["nu"] = t["nu"].map(lambda v: f"{v:g}")  # 0.4999 is not 0.5
    return t


def _time_to(d: pd.DataFrame, target: float, column: str = "error_l2_rel") -> float:
    """Wall time to reach ``target`` in ``column``: log-log interpolation between levels."""
    d = d.dropna(subset=[column, "t_total"]).sort_values("level")
    e, t = d[column].to_numpy(float), d["t_total"].to_numpy(float)
    for i in range(1, len(e)):
        if e[i] <= target < e[i - 1]:
            w = np.log(e[i - 1] / target) / np.log(e[i - 1] / e[i])
            return float(np.exp(np.log(t[i - 1]) + w * np.log(t[i] / t[i - 1])))
    return float(t[0]) if len(e) and e[0] <= target else float("nan")


def report(df: pd.DataFrame, study, out) -> str:
    from cvxdual.study.report import md_table
    d = df[df.status.astype(str).str.startswith("optimal")].copy()
    d["nu"] = d["nu"].astype(float)
    failed = df[~df.status.astype(str).str.startswith("optimal")]
    lines = []
    if out is not None:
        _plot(d, out)
        lines += ["Plots: `bounds.png` (hertz), `bounds_curved.png` (the curved scenes).", ""]
    for scene in FLAT + CURVED:
        g = d[d.scene == scene]
        if len(g):
            lines += [f"## `{scene}`", "", md_table(_table(g)), ""]
    lines += ["## Fitted rates", "", "Least squares in log-log against h: the relative L2 stress error of each space "
              "(where it is a discretisation error: patch is exact in both spaces), and on the eq rows the "
              "certified bound `sqrt(2G)`; curved scenes against the reference, fitted over the levels at least two "
              "below it.", "", md_table(_rates(d)), ""]
    lines += _findings(d) + _curved_findings(d)
    if len(failed):
        cols = ["scene", "triangulation", "stress_space", "level", "overrides", "status"]
        lines += ["## Cases that did not finish", "", md_table(failed[cols]), ""]
    return "\n".join(lines)


def _rates(d: pd.DataFrame) -> pd.DataFrame:
    from cvxdual.study.report import fit_rate
    rows = []
    for (scene, tri, nu, sp), g in d.groupby(["scene", "triangulation", "nu", "stress_space"]):
        if scene in CURVED:  # the reference's own error matters one level below it
            g = g[g.level <= REFERENCE["level"] - 2]
        r = {"scene": scene, "triangulation": tri, "nu": f"{nu:g}", "space": sp,
             "levels": f"{int(g.level.min())}-{int(g.level.max())}" if len(g) else "-",
             "rate L2": fit_rate(g["h"], g["error_l2_rel"]) if g["error_l2_rel"].notna().sum() > 1
             and g["error_l2_rel"].min() > 1e-6 else np.nan}
        if sp == "eq" and "bound" in g:
            r["rate bound"] = fit_rate(g["h"], g["bound"])
        rows.append(r)
    return pd.DataFrame(rows)


def _findings(d: pd.DataFrame) -> list[str]:
    h = d[(d.scene == "hertz")]
    if not len(h):
        return []
    eq, p0 = h[h.stress_space == "eq"], h[h.stress_space == "p0"]
    out = ["## Findings: flat faces", ""]
    eff = eq["effectivity"].dropna()
    if len(eff):
        out.append(f"- hertz, every nu and level: `sqrt(2G) >= true combined error` in {int((eff >= 1).sum())} of "
                   f"{len(eff)} rows; effectivity {eff.min():.3f} to {eff.max():.3f} (target <= 1.3). The bound is "
                   "reported `guaranteed = false` on hertz: its exact-field side tractions are not linear on edges, "
                   "and the data-oscillation term is an indicator without a computed constant.")
    out += _eq_against_p0(eq, p0) + _locking(eq, p0)
    t = {sp: _time_to(g[g.nu == 0.3], TARGET) for sp, g in (("p0", p0), ("eq", eq))}
    out.append(f"- time to {100 * TARGET:g}% relative L2 stress error on hertz (nu = 0.3, whole solve, log-log "
               f"interpolation between levels): p0 {t['p0']:.3g} s, eq {t['eq']:.3g} s.")
    return out + [""]


def _eq_against_p0(eq: pd.DataFrame, p0: pd.DataFrame) -> list[str]:
    keys = ["triangulation", "nu", "level"]
    m = pd.merge(eq[keys + ["error_l2_rel"]], p0[keys + ["error_l2_rel"]], on=keys, suffixes=("_eq", "_p0"))
    if not len(m):
        return []
    ratio = m.error_l2_rel_eq / m.error_l2_rel_p0
    return [f"- `eq` relative L2 error below `p0`'s in {int((ratio < 1).sum())} of {len(m)} rows; ratio eq/p0 "
            f"from {float(ratio.min()):.3f} to {float(ratio.max()):.3f}."]


def _locking(eq: pd.DataFrame, p0: pd.DataFrame) -> list[str]:
    out = []
    for sp, g in (("eq", eq), ("p0", p0)):
        for tri, gt in g.groupby("triangulation"):
            a, b = (gt[(gt.nu == nu) & gt.level.between(2, 4)].set_index("level")["error_l2_rel"]
                    for nu in (0.4999, 0.3))
            r = (a / b).dropna()
            if len(r):
                what = f"`{sp}`" + (f", {tri}" if g.triangulation.nunique() > 1 else "")
                out.append(f"- locking, {what}: error at nu = 0.4999 over error at nu = 0.3, levels "
                           f"{', '.join(str(int(x)) for x in r.index)}: {', '.join(f'{v:.2f}' for v in r)}"
                           + (" (within 2x)" if r.max() <= 2 else " (not within 2x)") + ".")
    return out


def _curved_findings(d: pd.DataFrame) -> list[str]:
    """The curved scenes: guarantees, the brackets' common point, type 1 against type 2, the
    effectivity against the reference, locking, and the time to a certified 1%."""
    c = d[d.scene.isin(CURVED)]
    if not len(c):
        return []
    out = ["## Findings: curved faces", ""]
    eq = c[c.stress_space == "eq"]
    g14 = eq[eq.level.between(1, 4)]
    out.append(f"- `guaranteed` in {int(eq.guaranteed.astype(bool).sum())} of {len(eq)} eq rows "
               f"({int(g14.guaranteed.astype(bool).sum())} of {len(g14)} at levels 1-4).")
    for (scene, nu), g in eq.groupby(["scene", "nu"]):
        lo, hi = g.energy_lower.max(), g.energy_upper.min()
        w = (g.energy_upper - g.energy_lower) / g.energy_upper.abs()
        best = g.loc[w.idxmin()]
        out.append(f"- `{scene}`, nu = {nu:g}: every level's and both types' energy brackets "
                   + ("share" if lo <= hi else "do NOT share") + f" a point (max lower {lo:.6g}, min upper {hi:.6g}, "
                   f"an interval {(hi - lo) / abs(hi):.2g} of |J| wide); the finest bracket (level {int(best.level)}, "
                   f"{best.triangulation}) is {w.min():.2g} of |J| wide.")
    for scene, g in eq[eq.nu == 0.3].groupby("scene"):
        b = g.pivot_table(index="level", columns="triangulation", values="bound")
        if {"type1", "type2"} <= set(b.columns):
            below = [int(L) for L in b.index if b.loc[L, "type2"] < b.loc[L, "type1"]]
            out.append(f"- `{scene}`, nu = 0.3: type 2's bound below type 1's at levels "
                       f"{', '.join(map(str, below)) or 'none'} (of {int(b.index.min())}-{int(b.index.max())}).")
    cob = eq[(eq.scene == "cylinder-on-block") & (eq.triangulation == "type2") & (eq.nu == 0.3)
             & eq.level.between(1, 3)].sort_values("level")
    if len(cob):
        out.append("- `cylinder-on-block`, type 2, nu = 0.3: effectivity against the reference at levels "
                   + ", ".join(f"{int(L)}: {e:.3f}" for L, e in zip(cob.level, cob.effectivity, strict=True))
                   + " (the reference is at least two levels finer).")
    p0 = c[c.stress_space == "p0"]
    out += _eq_against_p0(eq[eq.level <= REFERENCE["level"] - 2], p0[p0.level <= REFERENCE["level"] - 2])
    two_below = REFERENCE["level"] - 2  # where the reference's own error is small against the rows'
    for scene in CURVED:
        out += [line.replace("- locking,", f"- `{scene}`, locking,") for line in
                _locking(eq[(eq.scene == scene) & (eq.level <= two_below)],
                         p0[(p0.scene == scene) & (p0.level <= two_below)])]
    g_eq = eq[(eq.scene == "cylinder-on-block") & (eq.triangulation == "type2") & (eq.nu == 0.3)]
    g_p0 = p0[(p0.scene == "cylinder-on-block") & (p0.triangulation == "type2") & (p0.nu == 0.3)]
    if len(g_eq) and len(g_p0):
        t_eq, t_p0 = _time_to(g_eq, TARGET, "bound_energy_rel"), _time_to(g_p0, TARGET)
        out.append(f"- `cylinder-on-block` (type 2, nu = 0.3, whole solve, log-log interpolation between levels): "
                   f"time to a certified relative energy error of {100 * TARGET:g}% (eq, `bound_energy_rel`) "
                   f"{t_eq:.3g} s; time to a {100 * TARGET:g}% relative L2 error of the P0 stresses against the "
                   f"reference (not certified) {t_p0:.3g} s.")
    return out + [""]


def _plot(d: pd.DataFrame, out) -> None:
    from matplotlib.figure import Figure

    from cvxdual.files import atomic_path
    h = d[d.scene == "hertz"]
    if len(h):
        fig = Figure(figsize=(15, 4.6), layout="constrained")
        ax1, ax2, ax3 = fig.subplots(1, 3)
        for (sp, nu), g in h.groupby(["stress_space", "nu"]):
            g = g.sort_values("level")
            style = "o-" if sp == "eq" else "s--"
            ax1.loglog(g["h"], g["error_l2_rel"], style, ms=4, label=f"{sp}, nu = {nu:g}")
            if nu == 0.3:
                ax3.loglog(g["t_total"], g["error_l2_rel"], style, ms=4, label=sp)
        g = h[(h.stress_space == "eq") & (h.nu == 0.3)].sort_values("level")
        if len(g):
            ax2.loglog(g["h"], g["bound"], "o-", ms=4, label="bound sqrt(2G)")
            ax2.loglog(g["h"], g["error_combined"], "s--", ms=4, label="true combined error")
        _label((ax1, ax2, ax3), "hertz", ("stress error, three nu", "certified bound vs true error (nu = 0.3)",
                                         "error against time (nu = 0.3)"))
        with atomic_path(out / "bounds.png") as tmp:
            fig.savefig(tmp, dpi=120, format="png")
    c = d[d.scene.isin(CURVED) & (d.nu == 0.3)]
    if len(c):
        fig = Figure(figsize=(15, 4.6), layout="constrained")
        axes = fig.subplots(1, 3)
        for ax, scene in zip(axes, CURVED, strict=True):
            for (sp, tri), g in c[c.scene == scene].groupby(["stress_space", "triangulation"]):
                g = g.sort_values("level")
                ls = "-" if tri == "type2" else ":"
                ax.loglog(g["h"], g["error_l2_rel"], ("o" if sp == "eq" else "s") + ls, ms=4,
                          label=f"{sp} {tri}: L2 error")
                if sp == "eq":
                    ax.loglog(g["h"], g["bound_energy_rel"], "^" + ls, ms=4, label=f"eq {tri}: certified bound")
            ax.set_title(f"{scene} (nu = 0.3): errors against the reference, certified bound", fontsize=9)
            ax.set_xlabel("mesh size h [mm]")
            ax.set_ylabel("relative error [-]")
            ax.grid(alpha=0.3, which="both")
            if ax.lines:  # a scene left out of a partial run draws nothing
                ax.legend(fontsize=7)
        with atomic_path(out / "bounds_curved.png") as tmp:
            fig.savefig(tmp, dpi=120, format="png")


def _label(axes, scene: str, titles) -> None:
    labels = (("mesh size h [mm]", "relative L2 stress error"),
              ("mesh size h [mm]", "energy-norm error [sqrt(N mm / mm)]"),
              ("wall time per solve [s]", "relative L2 stress error"))
    for ax, (xl, yl), title in zip(axes, labels, titles, strict=True):
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_title(f"{scene}: {title}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
