"""The bounds study's report (tables, fitted rates, findings, plots), computed from its table.

Kept apart from ``bounds.py`` (the cases and ``measure``): the study cache keys a row by the spec
file that measures it, so editing what the report says keeps every cached row.
``report(df, study, out, setup)`` is called by ``bounds.report`` with the spec's constants.

The eq rows come in two kinematic sides (the ``kinematic`` column): ``p1``, the P1 displacement of
the P0 solve made admissible, and ``p2``, continuous P2 on the Alfeld split. Both certify the same
equilibrium stresses (the stress solve starts from the P1 contact set either way): the stress errors
are one column, the certificate's columns (upper energy, bound, true combined error, effectivity,
guarantee, time) one per side.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

SIDES = ("p1", "p2")  # the order of the columns and findings; P1 first: the old certificate


@dataclass(frozen=True)
class Setup:
    """What the report needs of the spec: the scene groups, the reference level of the curved
    scenes and the accuracy target of the time lines."""

    flat: tuple[str, ...]
    curved: tuple[str, ...]
    reference_level: int
    target: float


def _sides(d: pd.DataFrame) -> list[str]:
    """The kinematic sides of the eq rows of ``d``, P1 first."""
    have = set(d.loc[d.stress_space == "eq", "kinematic"].astype(str))
    return [k for k in SIDES if k in have] + sorted(have - set(SIDES))


def _stresses(eq: pd.DataFrame) -> pd.DataFrame:
    """One eq row per scene, triangulation, nu and level for what the kinematic side does not change
    (the stresses and their errors): the first side's."""
    return eq.sort_values("kinematic").drop_duplicates(["scene", "triangulation", "nu", "level"])


def _table(d: pd.DataFrame) -> pd.DataFrame:
    keys = ["triangulation", "nu", "level"] if d.triangulation.nunique() > 1 else ["nu", "level"]
    p0 = d[d.stress_space == "p0"].set_index(keys)
    eq_all = d[d.stress_space == "eq"]
    eq = _stresses(eq_all).set_index(keys)
    cols = {"h": eq["h"], "p0 L2 rel": p0["error_l2_rel"], "eq L2 rel": eq["error_l2_rel"],
            "J lower": eq.get("energy_lower")}
    by = {k: eq_all[eq_all.kinematic == k].set_index(keys) for k in _sides(d)}
    for name, col in (("J upper", "energy_upper"), ("bound rel", "bound_energy_rel"), ("true", "error_combined"),
                      ("effectivity", "effectivity"), ("guaranteed", "guaranteed")):
        for k, g in by.items():
            cols[f"{name} {k}"] = g.get(col)
    cols["t p0 [s]"] = p0["t_total"]
    for k, g in by.items():
        cols[f"t eq {k} [s]"] = g["t_total"]
    t = pd.DataFrame(cols).reset_index().dropna(axis=1, how="all")
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


def _time_measured(d: pd.DataFrame, target: float, column: str) -> tuple[float, int | None, str]:
    """The time of the first level whose ``column`` is at most ``target`` (measured: that level's
    whole solve), with the level; where no level reaches it, :func:`_time_to`'s extrapolation (said
    so) and no level."""
    d = d.dropna(subset=[column, "t_total"]).sort_values("level")
    hit = d[d[column] <= target]
    if len(hit):
        r = hit.iloc[0]
        return float(r.t_total), int(r.level), (f"measured at level {int(r.level)}, {int(r.n_pieces)} pieces, "
                                                f"{column} {float(r[column]):.3g}")
    t, how = _time_to(d, target, column)
    top = f"finest level {int(d.level.max())}: {float(d[column].iloc[-1]):.3g}; " if len(d) else ""
    return t, None, f"not reached by the studied levels ({top}{how})"


def report(df: pd.DataFrame, study, out, setup: Setup) -> str:
    from cvxdual.study.report import md_table
    d = df[df.status.astype(str).str.startswith("optimal")].copy()
    d["nu"] = d["nu"].astype(float)
    if "kinematic" not in d:  # a table of the P1-only releases
        d["kinematic"] = "p1"
    d["kinematic"] = d["kinematic"].astype(str)
    failed = df[~df.status.astype(str).str.startswith("optimal")]
    setup = replace(setup, reference_level=_reference_level(d, setup))
    lines = []
    if out is not None:
        _plot(d, out, setup.curved)
        lines += ["Plots: `bounds.png` (hertz), `bounds_curved.png` (the curved scenes).", ""]
    sides = _sides(d)
    lines += [f"Kinematic sides of the eq rows: {', '.join(f'`{k}`' for k in sides)} (`p1`: the P1 displacement of "
              "the P0 solve made pointwise admissible; `p2`: continuous P2 on the Alfeld split, solved from the P1 "
              "contact set and made admissible at every x). Both certify the same equilibrium stresses: `eq L2 rel` "
              "and `J lower` are one column, each side has its own `J upper`, relative bound `sqrt(2G)` over the "
              "stress energy norm, true combined error, effectivity, guarantee and time.", ""]
    for scene in setup.flat + setup.curved:
        g = d[d.scene == scene]
        if len(g):
            lines += [f"## `{scene}`", "", md_table(_table(g)), ""]
    lines += ["## Fitted rates", "", "Least squares in log-log against h: the relative L2 stress error of each space "
              "(where it is a discretisation error: patch is exact in both spaces), and on the eq rows, per kinematic "
              "side, the certified bound `sqrt(2G)`. The curved scenes' errors are against the reference and fitted "
              "over the levels at least two below it; their bounds need no reference and are fitted over every "
              "level, and over levels 1-4 (the acceptance's range).", "",
              md_table(_rates(d, setup)), ""]
    lines += _acceptance(d, setup) + _findings(d, setup.target) + _curved_findings(d, setup)
    if len(failed):
        cols = [c for c in ("scene", "triangulation", "stress_space", "kinematic", "level", "overrides", "status")
                if c in failed]
        lines += ["## Cases that did not finish", "", md_table(failed[cols]), ""]
    return "\n".join(lines)


def _reference_level(d: pd.DataFrame, setup: Setup) -> int:
    """The curved scenes' reference level as the rows name it (``type2 level 3 eq`` under ``--quick``),
    else the spec's."""
    found = d.loc[d.scene.isin(setup.curved), "reference"].astype(str).str.extract(r"level (\d+)")[0].dropna()
    return int(found.astype(int).min()) if len(found) else setup.reference_level


def _rates(d: pd.DataFrame, setup: Setup) -> pd.DataFrame:
    from cvxdual.study.report import fit_rate
    rows = []
    p0, eq = d[d.stress_space == "p0"], d[d.stress_space == "eq"]
    series = [(k, g, "p0", None) for k, g in p0.groupby(["scene", "triangulation", "nu"])]
    series += [(k[:3], g, "eq", k[3]) for k, g in eq.groupby(["scene", "triangulation", "nu", "kinematic"])]
    for (scene, tri, nu), g, sp, kin in sorted(series, key=lambda s: (s[0], s[2], s[3] or "")):
        e = g.dropna(subset=["error_l2_rel"])
        if scene in setup.curved:  # the reference's own error matters one level below it
            e = e[e.level <= setup.reference_level - 2]
        r = {"scene": scene, "triangulation": tri, "nu": f"{nu:g}", "space": sp, "kinematic": kin or "-",
             "levels L2": f"{int(e.level.min())}-{int(e.level.max())}" if len(e) else "-",
             "rate L2": fit_rate(e["h"], e["error_l2_rel"]) if len(e) > 1 and e["error_l2_rel"].min() > 1e-6
             else np.nan}
        if sp == "eq" and "bound" in g:
            b = g.dropna(subset=["bound"])
            r["levels bound"] = f"{int(b.level.min())}-{int(b.level.max())}" if len(b) else "-"
            r["rate bound"] = _bound_rate(b)
            r["rate bound 1-4"] = _bound_rate(b[b.level.between(1, 4)])
        rows.append(r)
    return pd.DataFrame(rows)


def _bound_rate(b: pd.DataFrame) -> float:
    """The fitted rate of the bound against h; NaN with fewer than two levels or a bound at rounding
    (patch: ~5e-7 relative, exact stresses)."""
    from cvxdual.study.report import fit_rate
    at_rounding = b.get("bound_energy_rel", pd.Series(dtype=float)).min() <= 1e-6
    return fit_rate(b["h"], b["bound"]) if len(b) > 1 and not at_rounding else np.nan


def _seconds(t: float) -> str:
    return f"{t:.3g} s" if np.isfinite(t) else "no time"


def _verdict(ok: bool | None) -> str:
    return "n/a" if ok is None else "PASS" if ok else "FAIL"


def _acceptance(d: pd.DataFrame, setup: Setup) -> list[str]:
    """Issue 41's acceptance, item by item, on the P2 side (P1 beside it for comparison): PASS,
    FAIL, or n/a where this run has no rows for the item (a quick run stops at level 1)."""
    from cvxdual.study.report import fit_rate
    eq = d[d.stress_space == "eq"]
    if not len(eq) or "p2" not in set(eq.kinematic):
        return []
    out = ["## Acceptance of issue 41 (P2 kinematic side)", "",
           "Each item on the P2 rows, with P1's numbers beside it where they say what changed; n/a: this run has "
           "no rows for the item.", ""]
    main = {"hertz": eq[(eq.scene == "hertz") & (eq.triangulation == "type1")],
            "cylinder-on-block": eq[(eq.scene == "cylinder-on-block") & (eq.triangulation == "type2")]}
    two_below = setup.reference_level - 2
    for scene, g in main.items():
        g3 = g[g.nu == 0.3]
        lab = scene + (" (type 2)" if scene != "hertz" else "")
        for k in ("p2", "p1"):
            gk = g3[g3.kinematic == k].sort_values("level")
            if not len(gk) or (k == "p1" and not len(g3[g3.kinematic == "p2"])):
                continue
            l2 = gk[gk.level == 2]
            at2 = float(l2.bound_energy_rel.iloc[0]) if len(l2) else np.nan
            hit = gk[gk.bound_energy_rel <= setup.target]
            first = int(hit.level.min()) if len(hit) else None
            eff = gk if scene == "hertz" else gk[gk.level <= two_below]
            eff = eff.dropna(subset=["effectivity"])
            ok1 = None if not np.isfinite(at2) else at2 <= 0.02
            ok2 = True if first is not None and first <= 3 else (None if gk.level.max() < 3 else False)
            ok3 = None if not len(eff) else bool(eff.effectivity.between(1, 2).all())
            tag = "" if k == "p2" else " (P1, for comparison)"
            out.append(f"- {lab}, nu = 0.3{tag}: certified relative energy error at level 2 "
                       f"{'-' if not np.isfinite(at2) else f'{100 * at2:.3g}%'} (<= 2%: {_verdict(ok1)}); a certified "
                       f"{100 * setup.target:g}% first at level " + (str(first) if first is not None else
                                                                   f"none of 0-{int(gk.level.max())}")
                       + f" (by level 3: {_verdict(ok2)}); effectivity against "
                       + ("the exact field" if scene == "hertz" else f"the reference (levels <= {two_below})")
                       + " " + (", ".join(f"L{int(L)} {e:.3f}" for L, e in zip(eff.level, eff.effectivity, strict=True))
                                or "-") + f" (within [1, 2]: {_verdict(ok3)}).")
    for scene, g in main.items():
        lab = scene + (" (type 2)" if scene != "hertz" else "")
        for k in ("p2", "p1"):
            r = _nu_ratio(g[g.kinematic == k], "bound_energy_rel")
            if not len(r):
                continue
            tag = "" if k == "p2" else " (P1, for comparison)"
            # a ratio over 2 fails the item; all of levels 2-4 within 2x passes it; fewer levels: n/a
            ok = False if r.max() > 2 else True if set(r.index) >= {2, 3, 4} else None
            out.append(f"- {lab}{tag}: certified relative error at nu = 0.4999 over nu = 0.3, levels "
                       + ", ".join(f"{int(L)}: {v:.2f}" for L, v in r.items())
                       + f" (within 2x at levels 2-4: {_verdict(ok)}).")
    widths = _finest_widths(eq[eq.scene.isin(setup.curved) & (eq.nu == 0.4999) & (eq.kinematic == "p2")])
    if len(widths):
        ok = bool((widths.width <= 1e-3).all())
        out.append("- every curved scene's finest bracket at nu = 0.4999 (P2) at most 1e-3 of |J|: "
                   + ", ".join(f"{r.scene} {r.triangulation} L{int(r.level)} {r.width:.2g}"
                               for r in widths.itertuples())
                   + f" ({_verdict(ok)}).")
    for scene, g in main.items():
        lab = scene + (" (type 2)" if scene != "hertz" else "")
        for k in ("p2", "p1"):
            b = g[(g.kinematic == k) & g.level.between(1, 4) & (g.nu == 0.3)].dropna(subset=["bound"])
            if len(b) < 2:
                continue
            rate = fit_rate(b["h"], b["bound"])
            tag = "" if k == "p2" else " (P1, for comparison)"
            full = set(b.level) >= {1, 2, 3, 4}
            out.append(f"- {lab}, nu = 0.3{tag}: fitted rate of the bound over levels "
                       f"{', '.join(str(int(L)) for L in sorted(b.level))}: {rate:.2f} (>= 1.3 over 1-4: "
                       f"{_verdict(rate >= 1.3 if full else None)}).")
    c = eq[eq.scene.isin(setup.curved)]
    if len(c):
        share = _brackets(c)
        ok = bool(share["share"].all())
        out.append("- every curved scene's brackets, all levels, both kinematic sides and both triangulations, share a "
                   "point: " + ", ".join(f"{r.scene} nu = {r.nu:g} {'yes' if r.share else 'NO'}"
                                         for r in share.itertuples()) + f" ({_verdict(ok)}).")
        out.append("- `guaranteed` where it was before: " + _guaranteed_kept(c) + ".")
    out.append("- time to a certified 1% (whole run, one process) against P0's uncertified 1%: measured by "
               "`studies/certified.py` (`reports/certified.md`); this table's times are per case on a shared "
               "worker, in the findings below.")
    out.append("- the P1 certificate unchanged where P1 is asked: the `p1` rows are this table's old eq rows; "
               "compare this CSV's `kinematic = p1` rows with the previous release's eq rows (not checked by "
               "the report itself).")
    return out + [""]


def _nu_ratio(g: pd.DataFrame, column: str) -> pd.Series:
    """``column`` at nu = 0.4999 over nu = 0.3, levels 2-4, by level (rows of one series)."""
    a, b = (g[(g.nu == nu) & g.level.between(2, 4)].set_index("level")[column] for nu in (0.4999, 0.3))
    return (a / b).dropna().sort_index()


def _width(g: pd.DataFrame) -> pd.Series:
    return (g.energy_upper - g.energy_lower) / g.energy_upper.abs()


def _finest_widths(eq: pd.DataFrame) -> pd.DataFrame:
    """Per curved scene (and kinematic side, nu): the narrowest bracket of its finest level, relative
    to |J| (its upper end), with the triangulation."""
    rows = []
    for (scene, nu, kin), g in eq.groupby(["scene", "nu", "kinematic"]):
        top = g[g.level == g.level.max()]
        w = _width(top)
        best = top.loc[w.idxmin()]
        rows.append({"scene": scene, "nu": nu, "kinematic": kin, "level": int(best.level),
                     "triangulation": best.triangulation, "width": float(w.min())})
    return pd.DataFrame(rows)


def _brackets(c: pd.DataFrame) -> pd.DataFrame:
    """Per curved scene and nu: whether every bracket (all levels, triangulations, kinematic sides)
    shares a point, the common interval and the finest widths per side and triangulation."""
    rows = []
    for (scene, nu), g in c.groupby(["scene", "nu"]):
        lo, hi = g.energy_lower.max(), g.energy_upper.min()
        r = {"scene": scene, "nu": nu, "rows": len(g), "levels": f"{int(g.level.min())}-{int(g.level.max())}",
             "max lower": lo, "min upper": hi, "share": bool(lo <= hi), "common width": (hi - lo) / abs(hi)}
        top = g[g.level == g.level.max()]
        for (kin, tri), t in top.groupby(["kinematic", "triangulation"]):
            r[f"finest {kin} {tri}"] = float(_width(t).min())
        rows.append(r)
    return pd.DataFrame(rows)


def _guaranteed_kept(c: pd.DataFrame) -> str:
    """Whether P2 is ``guaranteed`` in every row (scene, triangulation, nu, level) where P1 is."""
    keys = ["scene", "triangulation", "nu", "level"]
    m = pd.merge(c[c.kinematic == "p1"][keys + ["guaranteed"]], c[c.kinematic == "p2"][keys + ["guaranteed"]],
                 on=keys, suffixes=("_p1", "_p2"))
    if not len(m):
        return "n/a (no rows of both sides)"
    was = m[m.guaranteed_p1.astype(bool)]
    lost = was[~was.guaranteed_p2.astype(bool)]
    return (f"P1 guaranteed in {len(was)} of {len(m)} curved rows, P2 in {int(m.guaranteed_p2.astype(bool).sum())}; "
            f"P2 not guaranteed where P1 is: {len(lost)} ({_verdict(not len(lost))})"
            + ("" if not len(lost) else ": " + ", ".join(f"{r.scene} {r.triangulation} nu = {r.nu:g} L{int(r.level)}"
                                                         for r in lost.itertuples())))


def _findings(d: pd.DataFrame, target: float) -> list[str]:
    h = d[(d.scene == "hertz")]
    if not len(h):
        return []
    eq, p0 = h[h.stress_space == "eq"], h[h.stress_space == "p0"]
    out = ["## Findings: flat faces", ""]
    for k, g in eq.groupby("kinematic"):
        eff = g["effectivity"].dropna()
        if len(eff):
            out.append(f"- hertz, `{k}`, every nu and level: `sqrt(2G) >= true combined error` in "
                       f"{int((eff >= 1).sum())} of {len(eff)} rows; effectivity {eff.min():.3f} to {eff.max():.3f} "
                       "(target <= 1.3). The bound is reported `guaranteed = false` on hertz: its exact-field side "
                       "tractions are not linear on edges, and the data-oscillation term is an indicator without a "
                       "computed constant.")
    out += _eq_against_p0(_stresses(eq), p0) + _locking(_stresses(eq), p0) + _certified_locking(eq)
    t = {"p0": _time_to(p0[p0.nu == 0.3], target), "eq": _time_to(_stresses(eq)[_stresses(eq).nu == 0.3], target)}
    out.append(f"- time to {100 * target:g}% relative L2 stress error on hertz (nu = 0.3, whole solve): "
               f"p0 {_seconds(t['p0'][0])} ({t['p0'][1]}), eq {_seconds(t['eq'][0])} ({t['eq'][1]}; the P1 side's "
               "time).")
    for k, g in eq[eq.nu == 0.3].groupby("kinematic"):
        tc, _, how = _time_measured(g, target, "bound_energy_rel")
        out.append(f"- time to a certified {100 * target:g}% relative energy error on hertz (nu = 0.3, `{k}`, whole "
                   f"solve): {_seconds(tc)} ({how}).")
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
    """The stress error at nu = 0.4999 over nu = 0.3 (``eq``: one row per level, :func:`_stresses`)."""
    out = []
    for sp, g in (("eq", eq), ("p0", p0)):
        for tri, gt in g.groupby("triangulation"):
            r = _nu_ratio(gt, "error_l2_rel")
            if len(r):
                what = f"`{sp}`" + (f", {tri}" if g.triangulation.nunique() > 1 else "")
                out.append(_ratio_line(f"locking, {what}: error at nu = 0.4999 over error at nu = 0.3", r))
    return out


def _certified_locking(eq: pd.DataFrame) -> list[str]:
    """The certified relative error (``bound_energy_rel``) at nu = 0.4999 over nu = 0.3, levels 2-4,
    per kinematic side (and triangulation where there are two)."""
    out = []
    for (tri, k), g in eq.groupby(["triangulation", "kinematic"]):
        r = _nu_ratio(g, "bound_energy_rel")
        if len(r):
            what = f"`{k}`" + (f", {tri}" if eq.triangulation.nunique() > 1 else "")
            out.append(_ratio_line(f"certified relative error, {what}: nu = 0.4999 over nu = 0.3", r))
    return out


def _ratio_line(what: str, r: pd.Series) -> str:
    """One finding: the nu = 0.4999 over nu = 0.3 ratios ``r`` by level, and whether they are within 2x."""
    return (f"- {what}, levels {', '.join(str(int(x)) for x in r.index)}: {', '.join(f'{v:.2f}' for v in r)}"
            + (" (within 2x)" if r.max() <= 2 else " (not within 2x)") + ".")


def _curved_findings(d: pd.DataFrame, setup: Setup) -> list[str]:
    """The curved scenes: guarantees, the brackets' common point, type 1 against type 2, the
    effectivity against the reference, locking, and the time to a certified 1%."""
    from cvxdual.study.report import md_table
    c = d[d.scene.isin(setup.curved)]
    if not len(c):
        return []
    out = ["## Findings: curved faces", ""]
    eq = c[c.stress_space == "eq"]
    for k, g in eq.groupby("kinematic"):
        g14 = g[g.level.between(1, 4)]
        out.append(f"- `{k}`: `guaranteed` in {int(g.guaranteed.astype(bool).sum())} of {len(g)} eq rows "
                   f"({int(g14.guaranteed.astype(bool).sum())} of {len(g14)} at levels 1-4).")
    br = _brackets(eq)
    for r in br.to_dict("records"):
        out.append(f"- `{r['scene']}`, nu = {r['nu']:g}: the energy brackets of every level ({r['levels']}), both "
                   "triangulations and both kinematic sides " + ("share" if r["share"] else "do NOT share")
                   + f" a point (max lower {r['max lower']:.6g}, min upper {r['min upper']:.6g}, an interval "
                   f"{r['common width']:.2g} of |J| wide).")
    table = br.drop(columns=["share"]).copy()
    table["nu"] = table["nu"].map(lambda v: f"{v:g}")
    out += ["", "The brackets `[energy_lower, energy_upper]` of each curved scene: their common part (`max lower`, "
            "`min upper`, its width relative to |J|) and the finest level's bracket width relative to |J| per "
            "kinematic side and triangulation:", "", md_table(table), ""]
    for (scene, k), g in eq[eq.nu == 0.3].groupby(["scene", "kinematic"]):
        b = g.pivot_table(index="level", columns="triangulation", values="bound")
        if {"type1", "type2"} <= set(b.columns):
            if np.allclose(b["type1"], b["type2"], rtol=1e-12):  # bounds equal to rounding
                out.append(f"- `{scene}`, `{k}`, nu = 0.3: type 1 and type 2 give the same bound at every level (no "
                           "non-convex stretch on its faces: the two triangulations coincide).")
                continue
            below = [int(L) for L in b.index if b.loc[L, "type2"] < b.loc[L, "type1"]]
            out.append(f"- `{scene}`, `{k}`, nu = 0.3: type 2's bound below type 1's at levels "
                       f"{', '.join(map(str, below)) or 'none'} (of {int(b.index.min())}-{int(b.index.max())}).")
    two_below = setup.reference_level - 2  # where the reference's own error is small against the rows'
    for scene in setup.curved:
        for k, g in eq[(eq.scene == scene) & (eq.nu == 0.3) & eq.level.between(1, two_below)].groupby("kinematic"):
            for tri, gt in g.groupby("triangulation"):
                gt = gt.sort_values("level")
                out.append(f"- `{scene}`, {tri}, `{k}`, nu = 0.3: effectivity against the reference at levels "
                           + ", ".join(f"{int(L)}: {e:.3f}" for L, e in zip(gt.level, gt.effectivity, strict=True))
                           + " (the reference is at least two levels finer).")
    p0 = c[c.stress_space == "p0"]
    st = _stresses(eq)
    out += _eq_against_p0(st[st.level <= two_below], p0[p0.level <= two_below])
    for scene in setup.curved:
        out += [line.replace("- locking,", f"- `{scene}`, locking,") for line in
                _locking(st[(st.scene == scene) & (st.level <= two_below)],
                         p0[(p0.scene == scene) & (p0.level <= two_below)])]
        out += [line.replace("- certified", f"- `{scene}`, certified") for line in
                _certified_locking(eq[(eq.scene == scene) & (eq.level <= 4)])]
    g_p0 = p0[(p0.scene == "cylinder-on-block") & (p0.triangulation == "type2") & (p0.nu == 0.3)]
    t_p0, how_p0 = _time_to(g_p0[g_p0.level <= two_below], setup.target)
    for k, g in eq[(eq.scene == "cylinder-on-block") & (eq.triangulation == "type2") & (eq.nu == 0.3)].groupby(
            "kinematic"):
        t_eq, level, how_eq = _time_measured(g, setup.target, "bound_energy_rel")
        out.append(f"- `cylinder-on-block` (type 2, nu = 0.3, whole solve), `{k}`: time to a certified relative "
                   f"energy error of {100 * setup.target:g}% (`bound_energy_rel`) {_seconds(t_eq)} ({how_eq}); time "
                   f"to a {100 * setup.target:g}% relative L2 error of the P0 stresses against the reference (not "
                   f"certified) {_seconds(t_p0)} ({how_p0})."
                   + (" The P1 bound carries the P1 displacement's error, which falls like h." if level is None
                      and k == "p1" else ""))
    return out + [""]


def _plot(d: pd.DataFrame, out, curved: tuple[str, ...]) -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    from cvxdual.files import atomic_path
    h = d[d.scene == "hertz"]
    if len(h):
        fig = Figure(figsize=(15, 4.6), layout="constrained")
        ax1, ax2, ax3 = fig.subplots(1, 3)
        st = pd.concat([h[h.stress_space == "p0"], _stresses(h[h.stress_space == "eq"])])
        for (sp, nu), g in st.groupby(["stress_space", "nu"]):
            g = g.sort_values("level")
            ax1.loglog(g["h"], g["error_l2_rel"], "o-" if sp == "eq" else "s--", ms=4, label=f"{sp}, nu = {nu:g}")
        for (sp, k), g in h[h.nu == 0.3].groupby(["stress_space", "kinematic"]):
            if sp == "p0" and k != h.loc[h.stress_space == "p0", "kinematic"].iloc[0]:
                continue  # a p0 row does not depend on the side it carries
            g = g.sort_values("level")
            ax3.loglog(g["t_total"], g["error_l2_rel"], "o-" if sp == "eq" else "s--", ms=4,
                       label=f"eq ({k} bounds)" if sp == "eq" else sp)
        for k, g in h[(h.stress_space == "eq") & (h.nu == 0.3)].groupby("kinematic"):
            g = g.sort_values("level")
            color = "C1" if k == "p2" else "C0"  # one colour a side: the bound solid, the true error open and dotted
            ax2.loglog(g["h"], g["bound"], "o-", color=color, ms=4, label=f"{k}: bound sqrt(2G)")
            ax2.loglog(g["h"], g["error_combined"], "s:", color=color, ms=5, mfc="none",
                       label=f"{k}: true combined error")
        _label((ax1, ax2, ax3), "hertz", ("stress error, three nu", "certified bound vs true error (nu = 0.3)",
                                         "error against time (nu = 0.3)"))
        with atomic_path(out / "bounds.png") as tmp:
            fig.savefig(tmp, dpi=120, format="png")
    c = d[d.scene.isin(curved) & (d.nu == 0.3)]
    if len(c):
        fig = Figure(figsize=(15, 4.6), layout="constrained")
        axes = fig.subplots(1, 3)
        for ax, scene in zip(axes, curved, strict=True):
            cs = c[c.scene == scene]
            st = pd.concat([cs[cs.stress_space == "p0"], _stresses(cs[cs.stress_space == "eq"])])
            for (sp, tri), g in st.groupby(["stress_space", "triangulation"]):
                g = g.sort_values("level")
                ls = "-" if tri == "type2" else ":"
                ax.loglog(g["h"], g["error_l2_rel"], ("o" if sp == "eq" else "s") + ls, ms=4,
                          label=f"{sp} {tri}: L2 error")
            for (k, tri), g in cs[cs.stress_space == "eq"].groupby(["kinematic", "triangulation"]):
                g = g.sort_values("level")
                ax.loglog(g["h"], g["bound_energy_rel"], ("^" if k == "p2" else "v") + ("-" if tri == "type2" else ":"),
                          ms=4, label=f"eq {tri}: certified bound ({k})")
            ax.set_title(f"{scene} (nu = 0.3): errors against the reference, certified bounds", fontsize=9)
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
