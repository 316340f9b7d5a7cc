"""Outline bodies (gmsh beyond the strip of columns): writes reports/outlines.md and .csv.

    python studies/outlines.py            # the full study, into reports/ (about ten minutes, alone)
    python studies/outlines.py --quick    # coarse levels, into out/outlines-quick

1. hertz on column bodies against hertz on outline bodies (examples/hertz-outline.toml: the same
   rectangles and exact-field tractions, gmsh beyond one layer of columns): the P0 L2 error against
   McEwen's field, fitted rates (h halves per level), the error at equal dofs; the eq route's
   certified bound against its true error (effectivity).
2. Kirsch (block-with-hole): hoop stress at the hole's sides against -3q, level by level, and the
   certification of the bounds for the round hole.
3. The rounded flat punch: the linearised scene against the closed-form pressure (contact
   half-width, pressure error), the true geometry by agreement of P0 and eq, both triangulations.
4. The size estimate's triangle count (counted before meshing) against gmsh's.
5. Time: gmsh's share of an end-to-end run (solve and write the outputs, no plots) near 1e5 pieces.
Timings are measured in this one run, each meshing afresh (no kept mesh); run it alone on the
machine.
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

import cvxdual as cd
from cvxdual.files import write_text
from cvxdual.geometry.mesh import PROBE_COLUMNS, build_mesh, mesh_size
from cvxdual.geometry.outline import forget_meshes, gmsh_seconds, mesh_threads
from cvxdual.geometry.triangulation import column_breaks
from cvxdual.outputs.output_set import write_outputs
from cvxdual.study.report import md_table

HERTZ_OUTLINE = str(Path(__file__).resolve().parent.parent / "examples" / "hertz-outline.toml")


def fit(levels, err) -> float:
    """The rate in h: minus the slope of log2(err) against the level (h halves per level)."""
    return float(-np.polyfit(np.asarray(levels, float), np.log2(np.asarray(err, float)), 1)[0])


def hertz_rows(levels) -> pd.DataFrame:
    rows = []
    for label, scene in (("column", "hertz"), ("outline", HERTZ_OUTLINE)):
        for level in levels:
            sol = cd.solve(scene, level=level, solver="fast")
            rows.append({"part": "hertz", "mesh": label, "space": "p0", "level": level, "pieces": len(sol.pieces),
                         "dofs": len(sol.system.f),
                         "l2_error": sol.error["l2"], "l2_rel": sol.error["l2_rel"]})
            print(rows[-1], flush=True)
        for level in levels[:-1]:
            sol = cd.solve(scene, level=level, solver="fast", stress_space="eq")
            rows.append({"part": "hertz", "mesh": label, "space": "eq", "level": level, "pieces": len(sol.pieces),
                         "l2_error": sol.error["l2"], "l2_rel": sol.error["l2_rel"],
                         "effectivity": sol.error["effectivity"], "guaranteed": sol.bounds["guaranteed"]})
            print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def kirsch_rows(levels) -> pd.DataFrame:
    rows = []
    for level in levels:
        sol = cd.solve("block-with-hole", level=level, solver="fast", stress_space="eq")
        r, eps = 0.5, 1e-7
        pts = np.array([[r + eps, -10.0], [-r - eps, -10.0], [0.0, -10.0 + r + eps], [0.0, -10.0 - r - eps]])
        s, _ = sol.field.at(pts, np.ones(4, int))
        b = sol.bounds
        rows.append({"part": "kirsch", "level": level, "pieces": len(sol.pieces),
                     "hoop_right": s[0, 1] / -100.0, "hoop_left": s[1, 1] / -100.0,
                     "pole_top": s[2, 0] / 100.0, "pole_bottom": s[3, 0] / 100.0,
                     "energy_lower": b["energy_lower"], "energy_upper": b["energy_upper"],
                     "bracket_rel": (b["energy_upper"] - b["energy_lower"]) / abs(b["energy_upper"]),
                     "guaranteed": b["guaranteed"]})
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def _half_width(contact) -> tuple[float, float]:
    x = np.asarray(contact["x"])
    i = np.flatnonzero(np.asarray(contact["active"])).max()
    return float(x[i]), float(x[i + 1] - x[i])


def punch_rows(levels_linear, levels_true) -> pd.DataFrame:
    from cvxdual.reference.exact import exact_field

    rows = []
    scene = cd.load_scene("rounded-punch-linear")
    field = exact_field(scene)
    for level in levels_linear:
        sol = cd.solve(scene, level=level, solver="fast")
        c = sol.contact
        x, p = np.asarray(c["x"]), np.asarray(c["pressure"])
        w, pe = np.gradient(x), field.pressure(x)
        a_h, spacing = _half_width(c)
        rows.append({"part": "punch", "scene": "rounded-punch-linear", "triangulation": "type1", "space": "p0",
                     "level": level, "pieces": len(sol.pieces), "a_h": a_h, "a": field.punch.a, "spacing": spacing,
                     "pressure_rel_l2": float(np.sqrt(np.sum(w * (p - pe) ** 2) / np.sum(w * pe**2))),
                     "stress_l2_rel": sol.error["l2_rel"]})
        print(rows[-1], flush=True)
    scene = cd.load_scene("rounded-punch")
    for level in levels_true:
        for tri in ("type1", "type2"):
            for space in ("p0", "eq"):
                sol = cd.solve(scene, tri, level=level, solver="fast", stress_space=space)
                a_h, spacing = _half_width(sol.contact)
                row = {"part": "punch", "scene": "rounded-punch", "triangulation": tri, "space": space,
                       "level": level, "pieces": len(sol.pieces), "a_h": a_h, "spacing": spacing}
                if space == "eq":
                    b = sol.bounds
                    row.update(energy_lower=b["energy_lower"], energy_upper=b["energy_upper"],
                               guaranteed=b["guaranteed"])
                rows.append(row)
                print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def estimate_rows(levels) -> pd.DataFrame:
    rows = []
    for scene in ("block-with-hole", HERTZ_OUTLINE):
        s = cd.load_scene(scene)
        for level in levels:
            est = mesh_size(s, level, column_breaks(s))["triangles"]
            got = len(build_mesh(s, level).triangles())
            rows.append({"part": "estimate", "scene": s.name, "level": level, "estimated": int(est),
                         "meshed": got, "ratio": est / got})
    return pd.DataFrame(rows)


def timing_rows(cases) -> pd.DataFrame:
    rows = []
    for scene, level, space, solver in cases:
        forget_meshes()  # each run meshes afresh, as a first run would
        with tempfile.TemporaryDirectory() as tmp:
            g, t = gmsh_seconds(), time.perf_counter()
            sol = cd.solve(scene, level=level, solver=solver, stress_space=space)
            write_outputs(sol, Path(tmp) / "out", plots=False)
            total, spent = time.perf_counter() - t, gmsh_seconds() - g
        rows.append({"part": "time", "scene": sol.scene.name, "space": space, "solver": solver or "default",
                     "level": level, "pieces": len(sol.pieces), "gmsh_threads": mesh_threads(),
                     "gmsh_s": spent, "total_s": total,
                     "gmsh_share": spent / total})
        print(rows[-1], flush=True)
    return pd.DataFrame(rows)


def report(h, k, r, e, t) -> str:
    out = ["# Outline bodies: gmsh beyond the strip of columns", "", __doc__.split("\n\n")[2].strip(), ""]
    p0 = h[h.space == "p0"]
    col, outl = p0[p0.mesh == "column"], p0[p0.mesh == "outline"]
    rc, ro = fit(col.level, col.l2_error), fit(outl.level, outl.l2_error)
    # the column error at the outline's piece counts, interpolated in log-log (both decrease with pieces)
    lc = np.interp(np.log(outl.pieces), np.log(col.pieces), np.log(col.l2_error))
    ratio = outl.l2_error.to_numpy() / np.exp(lc)
    inside = (outl.pieces >= col.pieces.min()) & (outl.pieces <= col.pieces.max())
    out += ["## 1. hertz: column against outline bodies", "",
            f"P0 (fast path) L2 error against McEwen, fitted rates in h over levels {list(col.level)}: "
            f"column {rc:.2f}, outline {ro:.2f} (difference {abs(rc - ro):.2f}; acceptance 0.1). At equal pieces "
            f"the outline mesh's error over the column mesh's (interpolated): "
            + ", ".join(f"{r:.2f}" for r in ratio[inside.to_numpy()]) + " (acceptance at most 1.5).", ""]
    eq = h[h.space == "eq"]
    eff = eq[eq.mesh == "outline"].effectivity
    out += [f"eq route, outline bodies: effectivity (certified bound over true error) {eff.min():.3f} to "
            f"{eff.max():.3f} (acceptance at most 1.3); guaranteed: {int(eq.guaranteed.sum())} of {len(eq)} (hertz's "
            "exact-field side tractions are not linear on edges: not guaranteed, as on column bodies).", "",
            md_table(h.drop(columns="part")), ""]
    out += ["## 2. Kirsch: hoop stress at the hole of block-with-hole", "",
            "Hoop stress at the hole's sides over -q (exact 3) and at its top and bottom over q (exact 1), "
            "eq route; the energy bounds and whether they are certified for the round hole.", "",
            md_table(k.drop(columns="part")), ""]
    lin, true = r[r.scene == "rounded-punch-linear"], r[r.scene == "rounded-punch"]
    within = (np.abs(lin.a_h - lin.a) <= lin.spacing).all()
    eq = true[true.space == "eq"]
    common = eq.energy_lower.max() <= eq.energy_upper.min()
    fin = true[true.level == true.level.max()]
    out += ["## 3. The rounded flat punch", "",
            f"rounded-punch-linear against the closed form (a = {lin.a.iloc[0]:.4f} mm): the last active pair "
            f"within one face spacing of a at every level: {bool(within)}; the pressure's relative L2 error "
            + ", ".join(f"{v:.4f}" for v in lin.pressure_rel_l2)
            + f" (levels {list(lin.level)}; fitted rate {fit(lin.level, lin.pressure_rel_l2):.2f}).", "",
            f"rounded-punch (true geometry, no closed form): at level {int(fin.level.iloc[0])} the last active "
            f"pairs of P0 and eq, both triangulations, lie at {sorted(set(np.round(fin.a_h, 4)))} mm (face spacing "
            f"{fin.spacing.max():.4f}); every eq bracket of every level shares a point: {bool(common)} (the "
            f"common interval [{eq.energy_lower.max():.6g}, {eq.energy_upper.min():.6g}]); certified: "
            f"{int(eq.guaranteed.sum())} of {len(eq)}.", "",
            md_table(r.drop(columns="part")), ""]
    out += ["## 4. Triangles counted before meshing", "",
            f"The size estimate (cvxdual.sizing) meshes outline bodies at the highest level with at most "
            f"{PROBE_COLUMNS} columns and multiplies by 4 per level above (every size halves per level); ratio = "
            "estimated / meshed, at least 1 where the count per level grows by less than 4.", "",
            md_table(e.drop(columns="part")), ""]
    fast = t[(t.solver == "fast") & (t.space == "p0")].assign(
        us_gmsh=lambda d: 1e6 * d.gmsh_s / d.pieces, us_rest=lambda d: 1e6 * (d.total_s - d.gmsh_s) / d.pieces)
    out += ["## 5. gmsh's share of an end-to-end run", "",
            "gmsh's share by route (acceptance: at most 30 % at 1e5 pieces): "
            + "; ".join(f"{sv} {sp}: {g.gmsh_share.min():.1%} to {g.gmsh_share.max():.1%}"
                        for (sv, sp), g in t.groupby(["solver", "space"]))
            + ". Within 30 %: " + (", ".join(f"{r.scene} {r.solver} {r.space}" for r in t[t.gmsh_share <= 0.3]
                                             .itertuples()) or "none")
            + "; above: " + (", ".join(f"{r.scene} {r.solver} {r.space} ({r.gmsh_share:.1%})"
                                       for r in t[t.gmsh_share > 0.3].itertuples()) or "none")
            + ". Each body is meshed as eight surfaces on two threads (cuts from the strip, one "
            "through the hole in the block), the size field handed to gmsh at stops along the cuts and on rings "
            f"round the hole; on the fast path gmsh spends {fast.us_gmsh.min():.1f}-"
            f"{fast.us_gmsh.max():.1f} us of wall time a piece, the rest of the run {fast.us_rest.min():.1f}-"
            f"{fast.us_rest.max():.1f} us. `reports/speed.md` measures the same in the speed study's setting "
            "(one thread for the rest of the run, gmsh on one or two).", "",
            md_table(t.drop(columns="part")), ""]
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    out = Path(args.out or ("out/outlines-quick" if args.quick else "reports"))
    q = args.quick
    h = hertz_rows([1, 2, 3] if q else [2, 3, 4, 5, 6])
    k = kirsch_rows([1, 2] if q else [1, 2, 3, 4])
    r = punch_rows([1, 2] if q else [1, 2, 3, 4], [1, 2] if q else [1, 2, 3, 4, 5])
    e = estimate_rows([1, 2] if q else [2, 3, 4, 5])
    # the levels nearest 1e5 pieces: 5.8e4, 8.7e4 and 5.2e4
    t = timing_rows([("block-with-hole", 2, "p0", "fast")] if q else
                    [(scene, level, space, solver) for scene, level in ((HERTZ_OUTLINE, 5), ("block-with-hole", 4))
                     for space, solver in (("p0", None), ("p0", "fast"), ("eq", "fast"))]
                    + [("rounded-punch", 5, "p0", "fast")])
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "outlines.csv", pd.concat([h, k, r, e, t]).to_csv(index=False, float_format="%.6g"))
    write_text(out / "outlines.md", report(h, k, r, e, t))
    return 0


if __name__ == "__main__":
    sys.exit(main())
