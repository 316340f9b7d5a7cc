"""Numerical stability on hard cases: every case on every path and both triangulations.

Each case is a built-in scene with overrides. For each it records status (or the error), the
solver's iterations, the residuals, the duality gap, the agreement between the CVXPY path and
the fast path, the error against the exact field (``hertz`` variants) and the time.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .common import Cache, Progress, md_table, scene_key, write_csv, write_text

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
    return ({"bodies": {"block": {"material": {"E": 70000.0 * c}}}},)


BLOCKS_CLAMPED_BOTTOM = {"bodies": {"lower": {"boundary": {"push": {"traction": {"value": [0.0, 0.0]}},
                                                          "bottom": {"on": "far", "kind": "sliding"}}}}}

CASES = [
    *[Case(f"nu = {nu}", "near incompressibility (plane strain)", "hertz", _nu(nu)) for nu in
      (0.3, 0.49, 0.499, 0.4999, 0.49999)],
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
           "mesh": {"columns": 60}},), level=6, paths=("fast",)),
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
    nu = df[df.group.str.startswith("near")]
    if len(nu):
        e = nu[nu.path == "fast"].groupby("case", sort=False)["error_l2_rel"].first()
        out.append("- Near incompressibility: the relative stress error against the exact field goes "
                   + ", ".join(f"{v:.3g} ({k})" for k, v in e.items())
                   + ". The discrete dual of type 1 is the Lagrangian dual of P1 displacements on the same mesh "
                   "(MATH.md section 3), so it inherits volumetric locking: piecewise-constant stresses on a "
                   "triangle mesh cannot satisfy equilibrium with the nearly incompressible compliance without "
                   "spurious hydrostatic stress. Solvers are not the problem: both paths agree on the (wrong) "
                   "discrete solution. The cure is a discretisation one (a locking-free stress space), outside "
                   "this package's two triangulations.")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="studies/stability.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="a few cases at level <= 1")
    p.add_argument("--out", default=None, help="output directory (default: reports/, or out/stability-quick)")
    p.add_argument("--cache", default=".cache/cvxdual", help="cache directory for resuming ('' to disable)")
    p.add_argument("--quiet", action="store_true")
    a = p.parse_args(argv)
    run(a.out or ("out/stability-quick" if a.quick else "reports"), quick=a.quick, cache_dir=a.cache or None,
        progress=not a.quiet)
    return 0
