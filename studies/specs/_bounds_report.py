"""The bounds study's report (tables, fitted rates, findings, plots), computed from its table.

Kept apart from ``bounds.py`` (the cases and ``measure``): the study cache keys a row by the spec
file that measures it, so editing what the report says keeps every cached row.
``report(df, study, out, setup)`` is called by ``bounds.report`` with the spec's constants.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class Setup:
    """What the report needs of the spec: the scene groups, the reference level of the curved
    scenes and the accuracy target of the time lines."""

    flat: tuple[str, ...]
    curved: tuple[str, ...]
    reference_level: int
    target: float


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


def _time_to(d: pd.DataFrame, target: float, column: str = "error_l2_rel") -> tuple[float, str]:
    """Wall time to reach ``target`` in ``column`` and how it was found: log-log interpolation
    between the levels that bracket it; when the finest level is still above it, an
    extrapolation (said so): the error's power law in the pieces, fitted to the last three
    levels, gives the pieces needed, and the time grows in proportion from the finest level's (a
    lower bound for sparse direct solvers, whose cost grows a little faster). Timings of single
    runs on a shared machine are noisy: the piece count, not a fit to times, carries the step."""
    d = d.dropna(subset=[column, "t_total"]).sort_values("level")
    e, t, lv = d[column].to_numpy(float), d["t_total"].to_numpy(float), d["level"].to_numpy(int)
    for i in range(1, len(e)):
        if e[i] <= target < e[i - 1]:
            w = np.log(e[i - 1] / target) / np.log(e[i - 1] / e[i])
            return float(np.exp(np.log(t[i - 1]) + w * np.log(t[i] / t[i - 1]))), "interpolated"
    if len(e) and e[0] <= target:
        return float(t[0]), f"reached at level {lv[0]}"
    n = d["n_pieces"].to_numpy(float)
    if len(e) < 3 or not np.all(np.diff(e[-3:]) < 0):
        return float("nan"), "not reached, too few decreasing levels to extrapolate"
    r = -np.polyfit(np.log(n[-3:]), np.log(e[-3:]), 1)[0]  # e ~ pieces^-r
    grow = (e[-1] / target) ** (1.0 / r)
    return float(t[-1] * grow), (f"extrapolated: error ~ pieces^-{r:.2f} over levels {lv[-3]}-{lv[-1]}, "
                                 f"{grow:.3g} times the pieces of level {lv[-1]} (error {e[-1]:.3g}), time in "
                                 "proportion")


def report(df: pd.DataFrame, study, out, setup: Setup) -> str:
    from cvxdual.study.report import md_table
    d = df[df.status.astype(str).str.startswith("optimal")].copy()
    d["nu"] = d["nu"].astype(float)
    failed = df[~df.status.astype(str).str.startswith("optimal")]
    lines = []
    if out is not None:
        _plot(d, out, setup.curved)
        lines += ["Plots: `bounds.png` (hertz), `bounds_curved.png` (the curved scenes).", ""]
    for scene in setup.flat + setup.curved:
        g = d[d.scene == scene]
        if len(g):
            lines += [f"## `{scene}`", "", md_table(_table(g)), ""]
    lines += ["## Fitted rates", "", "Least squares in log-log against h: the relative L2 stress error of each space "
              "(where it is a discretisation error: patch is exact in both spaces), and on the eq rows the "
              "certified bound `sqrt(2G)`. The curved scenes' errors are against the reference and fitted over the "
              "levels at least two below it; their bounds need no reference and are fitted over every level.", "",
              md_table(_rates(d, setup)), ""]
    lines += _findings(d, setup.target) + _curved_findings(d, setup)
    if len(failed):
        cols = ["scene", "triangulation", "stress_space", "level", "overrides", "status"]
        lines += ["## Cases that did not finish", "", md_table(failed[cols]), ""]
    return "\n".join(lines)


def _rates(d: pd.DataFrame, setup: Setup) -> pd.DataFrame:
    from cvxdual.study.report import fit_rate
    rows = []
    for (scene, tri, nu, sp), g in d.groupby(["scene", "triangulation", "nu", "stress_space"]):
        e = g.dropna(subset=["error_l2_rel"])
        if scene in setup.curved:  # the reference's own error matters one level below it
            e = e[e.level <= setup.reference_level - 2]
        r = {"scene": scene, "triangulation": tri, "nu": f"{nu:g}", "space": sp,
             "levels L2": f"{int(e.level.min())}-{int(e.level.max())}" if len(e) else "-",
             "rate L2": fit_rate(e["h"], e["error_l2_rel"]) if len(e) > 1 and e["error_l2_rel"].min() > 1e-6
             else np.nan}
        if sp == "eq" and "bound" in g:
            b = g.dropna(subset=["bound"])
            r["levels bound"] = f"{int(b.level.min())}-{int(b.level.max())}" if len(b) else "-"
            # a bound at rounding (patch: ~5e-7 relative, exact stresses) has no rate to fit
            at_rounding = b.get("bound_energy_rel", pd.Series(dtype=float)).min() <= 1e-6
            r["rate bound"] = fit_rate(b["h"], b["bound"]) if len(b) > 1 and not at_rounding else np.nan
        rows.append(r)
    return pd.DataFrame(rows)


def _findings(d: pd.DataFrame, target: float) -> list[str]:
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
    t = {sp: _time_to(g[g.nu == 0.3], target) for sp, g in (("p0", p0), ("eq", eq))}
    out.append(f"- time to {100 * target:g}% relative L2 stress error on hertz (nu = 0.3, whole solve): "
               f"p0 {t['p0'][0]:.3g} s ({t['p0'][1]}), eq {t['eq'][0]:.3g} s ({t['eq'][1]}).")
    return out + [""]


def _eq_against_p0(eq: pd.DataFrame, p0: pd.DataFrame) -> list[str]:
    keys = ["scene", "triangulation", "nu", "level"]  # the same mesh and problem
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


def _curved_findings(d: pd.DataFrame, setup: Setup) -> list[str]:
    """The curved scenes: guarantees, the brackets' common point, type 1 against type 2, the
    effectivity against the reference, locking, and the time to a certified 1%."""
    c = d[d.scene.isin(setup.curved)]
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
                   f"{best.triangulation}) is {w.min():.2g} of |J| wide"
                   + (" (the upper end is the P1 displacement's energy, which locks: see below)" if nu > 0.49
                      else "") + ".")
    for scene, g in eq[eq.nu == 0.3].groupby("scene"):
        b = g.pivot_table(index="level", columns="triangulation", values="bound")
        if {"type1", "type2"} <= set(b.columns):
            if np.allclose(b["type1"], b["type2"], rtol=1e-12):  # bounds equal to rounding
                out.append(f"- `{scene}`, nu = 0.3: type 1 and type 2 give the same bound at every level (no "
                           "non-convex stretch on its faces: the two triangulations coincide).")
                continue
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
    two_below = setup.reference_level - 2  # where the reference's own error is small against the rows'
    out += _eq_against_p0(eq[eq.level <= two_below], p0[p0.level <= two_below])
    for scene in setup.curved:
        out += [line.replace("- locking,", f"- `{scene}`, locking,") for line in
                _locking(eq[(eq.scene == scene) & (eq.level <= two_below)],
                         p0[(p0.scene == scene) & (p0.level <= two_below)])]
    g_eq = eq[(eq.scene == "cylinder-on-block") & (eq.triangulation == "type2") & (eq.nu == 0.3)]
    g_p0 = p0[(p0.scene == "cylinder-on-block") & (p0.triangulation == "type2") & (p0.nu == 0.3)]
    if len(g_eq) and len(g_p0):
        (t_eq, how_eq), (t_p0, how_p0) = (_time_to(g_eq, setup.target, "bound_energy_rel"),
                                          _time_to(g_p0[g_p0.level <= two_below], setup.target))
        out.append(f"- `cylinder-on-block` (type 2, nu = 0.3, whole solve): time to a certified relative energy "
                   f"error of {100 * setup.target:g}% (eq, `bound_energy_rel`) {t_eq:.3g} s ({how_eq}); time to a "
                   f"{100 * setup.target:g}% relative L2 error of the P0 stresses against the reference (not "
                   f"certified) {t_p0:.3g} s ({how_p0})."
                   + (" The certified bound carries the P1 displacement's error, which falls like h: the finest "
                      "studied level is not yet at the target." if how_eq.startswith("extrapolated") else ""))
    return out + [""]


def _plot(d: pd.DataFrame, out, curved: tuple[str, ...]) -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

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
    c = d[d.scene.isin(curved) & (d.nu == 0.3)]
    if len(c):
        fig = Figure(figsize=(15, 4.6), layout="constrained")
        axes = fig.subplots(1, 3)
        for ax, scene in zip(axes, curved, strict=True):
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
            ax.xaxis.set_minor_formatter(NullFormatter())  # less than a decade of h: minor labels collide
            if ax.lines:  # a scene left out of a partial run draws nothing
                ax.legend(fontsize=7)
        with atomic_path(out / "bounds_curved.png") as tmp:
            fig.savefig(tmp, dpi=120, format="png")


def _label(axes, scene: str, titles) -> None:
    from matplotlib.ticker import NullFormatter
    labels = (("mesh size h [mm]", "relative L2 stress error"),
              ("mesh size h [mm]", "energy-norm error [sqrt(N mm / mm)]"),
              ("wall time per solve [s]", "relative L2 stress error"))
    for ax, (xl, yl), title in zip(axes, labels, titles, strict=True):
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_title(f"{scene}: {title}", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=8)
