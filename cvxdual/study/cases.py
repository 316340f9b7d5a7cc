"""What one case computes: the solve, its errors against the reference, and the row.

Runs on a Dask worker (or, with ``isolate = "process"``, in a fresh interpreter started by the
worker: ``python -m cvxdual.study.cases CASE_JSON``). References (finer levels solved by the fast
path) are computed once per scene variant, stored as checked arrays in the cache directory and
loaded by the workers from there (a filesystem shared by client and workers); a worker keeps
the last reference it loaded in memory.

The errors follow the convergence study of the paper's (2.4): against an exact field, a tensor
Gauss rule of ``rule`` x ``rule`` points per piece (``check_rule`` at the finest level as a
check); against a reference, integrated over the reference's pieces (``ref_rule`` points, and
``ref_fine`` on the pieces that straddle studied pieces), every point located in the studied
mesh: over the common part of both meshes, where an outline body's curves are polygons that
differ between levels (``ref_dropped_area``, ``ref_dropped_share``: what that leaves out). The
reference's own error is estimated from the levels below it: with
``d_k = ||lam_k - lam_(k+1)||`` and ``p = log2(d_(R-2) / d_(R-1))``, ``err_R ~ d_(R-1) / (2^p - 1)``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import CvxdualError
from ..kinds import Space, Status
from ..records import FieldDistance
from ..sizing import peak_mb
from ..system.field import PieceField, StressField, field_distance
from ..validate import one_line
from .cache import Cache, code_version, content_key, is_key
from .spec import Case, Reference, StudyError, load_module

EDGE_RADIUS = 0.1  # times a: the discs around the Hertz contact edges (0.03% of the hertz domain)

# What a cached entry must hold to be used (JSON types: a number is int or float, a NaN is None)
TEXT, INT, NUM, MAYBE = (str,), (int,), (int, float), (int, float, type(None))
ROW_TYPES = {"scene": TEXT, "triangulation": TEXT, "stress_space": TEXT, "kinematic": TEXT, "level": INT,
             "solver": TEXT, "overrides": TEXT, "n_pieces": INT, "h": NUM, "error_l2": MAYBE, "error_l2_rel": MAYBE,
             "reference": TEXT, "status": TEXT, "t_total": MAYBE, "worker": TEXT}
REQUIRED = tuple(ROW_TYPES)
IDENTITY = ("study", "case", "group", "scene", "overrides", "units", "triangulation", "stress_space", "kinematic",
            "level", "solver", "reference")  # a row of this case: these columns are its base_row's
NUMERIC = {"h_min", "h_ratio", "iterations", "duality_gap", "contact_x_min", "contact_x_max", "peak_pressure",
           "total_force", "peak_mb", "reference_error_est", "edge_error_share", "effectivity", "bound_energy_rel",
           "ref_dropped_area", "ref_dropped_share"}
NUMERIC_PREFIXES = ("error_", "res_", "t_", "n_")
MEASURED = {"error_l2": NUM, "error_l2_rel": NUM, "error_energy_rel": NUM, "reference_error_est": NUM}
INFO_TYPES = {"level": INT, "triangulation": TEXT, "solver": TEXT, "n_pieces": INT, "d_last": NUM,
              "d_before": NUM, "rate": MAYBE, "error_est": NUM, "stress_space": TEXT, "certified": MAYBE}


def _typed(d: dict, types: dict) -> bool:
    return all(k in d and type(d[k]) in t for k, t in types.items())


def _numbers_ok(row: dict) -> bool:
    """The numeric columns hold numbers (or None: NaN), errors (norms) none below zero."""
    return all(type(v) in MAYBE and not (k.startswith("error_") and v is not None and v < 0)
               for k, v in row.items() if k in NUMERIC or k.startswith(NUMERIC_PREFIXES))


def within_tolerances(residuals: dict, stress_space: str) -> bool:
    """Whether ``residuals`` (by name; a missing or ``None`` one fails) meet the tolerances every
    returned solution of ``stress_space`` promises."""
    from ..solution import SPACE_TOLERANCES
    tol = SPACE_TOLERANCES[Space.parse(stress_space or Space.P0)]
    return all(residuals.get(k) is not None and residuals[k] <= v for k, v in tol.items())


def _flag_holds(row: dict) -> bool:
    """A row's ``within_tolerances`` is what its own residuals say (a row without one: no solve)."""
    if "within_tolerances" not in row:
        return True
    res = {k[len("res_"):]: v for k, v in row.items() if k.startswith("res_")}
    return row["within_tolerances"] is within_tolerances(res, row.get("stress_space"))


def load_case_row(cache: Cache, key: str, case: Case) -> dict | None:
    """The cached row of ``case``, or ``None``: besides the entry's own checks (key, MAC), the
    columns the study computes with have their types, the row is this case's (its identity
    columns), its ``within_tolerances`` agrees with its residuals, its errors against a finer
    reference are finite numbers, and its saved stresses (``compare``) load and fit its mesh."""
    from ..files import to_jsonable as clean
    base = clean(base_row(case))

    def ok(row: dict) -> bool:
        return (_typed(row, ROW_TYPES) and _numbers_ok(row) and all(row.get(k) == base[k] for k in IDENTITY)
                and _flag_holds(row)
                and (case.reference.kind != "finer" or case.solver == "limit" or _typed(row, MEASURED))
                and (not case.save_stress or Space.parse(case.stress_space) is not Space.P0
                     or (row.get("stress_key") == "s" + key
                         and load_saved_stress(cache, "s" + key, row["n_pieces"]) is not None)))
    return cache.get_row(key, check=ok)


def load_saved_stress(cache: Cache, key: str, n_pieces) -> dict | None:
    """A case's saved ``stress`` ``(n_pieces, 3)`` and piece ``area`` ``(n_pieces,)``, or ``None``."""
    if not (type(n_pieces) is int and is_key(key)):
        return None
    return cache.get_arrays(key, {"stress": (n_pieces, 3), "area": (n_pieces,)})


def load_reference_info(cache: Cache, key: str, ref: Reference) -> dict | None:
    """A reference's cached info (:func:`reference_info_task`), or ``None``: of this reference
    (level, triangulation, solver, stress space), with its types and non-negative differences."""
    def ok(info: dict) -> bool:
        this = (ref.level, ref.triangulation, ref.solver, ref.stress_space)
        return (_typed(info, INFO_TYPES) and info["n_pieces"] > 0
                and (info["level"], info["triangulation"], info["solver"], info["stress_space"]) == this
                and min(info["d_last"], info["d_before"], info["error_est"]) >= 0
                and (info["certified"] is None or info["certified"] >= 0))
    return cache.get_row(key, check=ok)


def usable_reference(stress: np.ndarray) -> bool:
    """A reference to measure relative errors against: finite, and not zero everywhere."""
    return bool(np.all(np.isfinite(stress)) and np.any(stress != 0))


def load_reference_stress(cache: Cache, key: str, n_pieces: int) -> np.ndarray | None:
    """A reference field's cached stress ``(n_pieces, 3)`` (finite, not all zero), or ``None``."""
    hit = cache.get_arrays(key, {"stress": (n_pieces, 3)}, check=lambda a: usable_reference(a["stress"]))
    return None if hit is None else hit["stress"]


def load_eq_reference(cache: Cache, key: str, n_tri: int, n_col: int) -> dict | None:
    """An equilibrium reference's cached vertex values ``(3 n_T, 3, 3)``, column values ``(n_col, 2)``
    and certified relative energy bound ``(1,)``, or ``None``."""
    shapes = {"stress": (3 * n_tri, 3, 3), "column": (n_col, 2), "bound": (1,)}
    return cache.get_arrays(key, shapes, check=lambda a: usable_reference(a["stress"]) and
                            bool(np.all(np.isfinite(a["column"]))) and a["bound"][0] >= 0)


def scene_of(source: str, overrides: tuple, units: tuple | None):
    """The scene of a case: source with overrides applied, converted to ``units``."""
    from .. import load_scene
    from ..scene.scene import convert_units
    from .spec import nest
    scene = load_scene(source, [nest(k, v) for k, v in overrides])
    if units is not None:
        scene = convert_units(scene, float(units[0]), float(units[1]), (str(units[2]), str(units[3])))
    return scene


def field_key(scene_repr: str, ref: Reference, level: int) -> str:
    return "f" + content_key("field", scene_repr, ref.triangulation, ref.solver, ref.stress_space, level,
                             code_version())


def reference_key(scene_repr: str, ref: Reference, metrics: tuple) -> str:
    m = dict(metrics)
    return "r" + content_key("reference", scene_repr, ref, m["ref_rule"], m["ref_fine"], code_version())


def case_key(case: Case, scene_repr: str, hooks_hash: str = "") -> str:
    from dataclasses import replace
    c = replace(case, scene_source="", hooks=None, isolate="", timeout=None)  # not part of the content
    return "c" + content_key("case", scene_repr, c, hooks_hash, code_version())


_MEMO: dict = {}  # the last reference field this process loaded: {key: StressField}


def reference_field(scene, ref: Reference, level: int, cache: Cache, keep: bool = True,
                    ensure_cached: bool = False) -> tuple[StressField, bool]:
    """The fast-path (or ``ref.solver``) solution at ``level``, from the memo, the cache, or solved
    (and then cached); ``(field, computed)``: a :class:`~cvxdual.system.field.PieceField` (P0), or for an
    ``eq`` reference an :class:`~cvxdual.eq.fields.EquilibriumField` with its certified relative energy bound in
    ``bound``. With ``ensure_cached``, a field taken from the memo is written again if its cache
    entry does not load (other workers read it there)."""
    from .. import discretize, solve
    key = field_key(repr(scene), ref, level)
    if key in _MEMO:
        f = _MEMO[key]
        if ensure_cached:
            _recache(cache, key, f)
        return f, False
    from ..sizing import check_size
    # the solve checks its size too, but the mesh is built first (to look the field up): a level
    # past the machine's memory is refused in one line here rather than killing two workers
    check_size(scene, level, ref.solver == "fast", ref.stress_space)
    mesh, pieces, _ = discretize(scene, ref.triangulation, level)
    if Space.parse(ref.stress_space) is Space.EQ:
        from ..eq.fields import EquilibriumField
        from ..eq.space import EquilibriumSpace
        space = EquilibriumSpace.from_pieces(mesh, pieces, ref.triangulation)
        hit = load_eq_reference(cache, key, space.n_tri, len(space.columns))
        computed = hit is None
        if computed:
            # its stresses do not depend on the kinematic side; its certified bound is P2's, the sharper
            sol = solve(scene, ref.triangulation, level, ref.solver, stress_space="eq", check=True, kinematic="p2")
            b = sol.bounds
            hit = {"stress": np.asarray(sol.stress, float), "column": np.asarray(sol.column_stress, float),
                   "bound": np.array([b["error_bound"] / np.sqrt(2.0 * b["complementary_energy"])])}
            _check_usable(hit["stress"], scene, ref, level)
            cache.put_arrays(key, **hit)
        f = EquilibriumField(scene, mesh, pieces, hit["stress"], space=space, g=hit["column"],
                             bound=float(hit["bound"][0]))
    else:
        stress = load_reference_stress(cache, key, len(pieces))
        computed = stress is None
        if computed:
            sol = solve(scene, ref.triangulation, level, ref.solver, check=True)
            stress = np.asarray(sol.stress, float)
            _check_usable(stress, scene, ref, level)
            cache.put_arrays(key, stress=stress)
        f = PieceField(scene, mesh, pieces, stress)
    if keep:
        _MEMO.clear()
        _MEMO[key] = f
    return f, computed


def _check_usable(stress: np.ndarray, scene, ref: Reference, level: int) -> None:
    if not usable_reference(stress):
        raise CvxdualError(f"the reference of scene {scene.name!r} ({ref.triangulation}, level {level}, "
                           f"{ref.solver}) is zero everywhere or not finite: errors relative to it are "
                           "undefined (is the scene loaded?)")


def _recache(cache: Cache, key: str, f) -> None:
    """Write a memo field back to the cache if its entry there does not load."""
    if getattr(f, "space", None) is None:
        if load_reference_stress(cache, key, len(f.stress)) is None:
            cache.put_arrays(key, stress=f.stress)
    elif load_eq_reference(cache, key, f.space.n_tri, len(f.space.columns)) is None:
        cache.put_arrays(key, stress=f.stress, column=f.column, bound=np.array([f.bound]))


def distance(a, b, n: int, n_fine: int) -> FieldDistance:
    """``||a - b||`` over ``a``'s cells (:func:`cvxdual.system.field.field_distance`) of two stress
    fields or solutions."""
    fa, fb = (x if isinstance(x, StressField) else x.field for x in (a, b))
    return field_distance(fa, fb, n, n_fine)


def reference_level_task(source: str, overrides: tuple, units, ref: Reference, level: int, cache_root: str) -> dict:
    """Worker task: make sure the reference field at ``level`` is in the cache."""
    scene = scene_of(source, overrides, units)
    t0 = time.perf_counter()
    f, computed = reference_field(scene, ref, level, Cache(cache_root), keep=level == ref.level, ensure_cached=True)
    return {"level": level, "n_pieces": len(f.stress), "computed": computed, "time": time.perf_counter() - t0}


def reference_info_task(source: str, overrides: tuple, units, ref: Reference, metrics: tuple, cache_root: str,
                        *levels_done) -> dict:
    """Worker task: the reference's estimated error from the two levels below it (cached), and for
    an ``eq`` reference its certified relative energy bound (``certified``)."""
    scene = scene_of(source, overrides, units)
    cache = Cache(cache_root)
    key = reference_key(repr(scene), ref, metrics)
    hit = load_reference_info(cache, key, ref)
    if hit is not None:
        return hit
    m = dict(metrics)
    R = ref.level
    f2, _ = reference_field(scene, ref, R - 2, cache, keep=False)
    f1, _ = reference_field(scene, ref, R - 1, cache, keep=False)
    r2 = distance(f1, f2, m["ref_rule"], m["ref_fine"])
    del f2
    f0, _ = reference_field(scene, ref, R, cache)
    r1 = distance(f0, f1, m["ref_rule"], m["ref_fine"])
    d2, d1 = r2["l2_rel"], r1["l2_rel"]
    p = float(np.log2(d2 / d1)) if d1 > 0 and d2 > d1 else float("nan")
    est = d1 / (2**p - 1) if np.isfinite(p) and p > 0 else d1
    info = {"level": R, "triangulation": ref.triangulation, "solver": ref.solver,
            "n_pieces": len(f0.pieces), "d_last": d1, "d_before": d2, "rate": p, "error_est": est,
            "stress_space": ref.stress_space, "certified": getattr(f0, "bound", None),
            "dropped_share": max(r1["dropped_share"], r2["dropped_share"])}  # of the two differences
    return cache.put_row(key, info)


def _worker_name() -> str:
    try:
        from distributed import get_worker
        return str(get_worker().address)
    except (ImportError, ValueError):
        return os.environ.get("CVXDUAL_STUDY_WORKER", f"local-{os.getpid()}")


def base_row(case: Case) -> dict:
    units = "" if case.units is None else f"{case.units[2]}, {case.units[3]}"
    return {"study": case.study, "case": case.name, "group": case.group, "scene": case.scene,
            "overrides": case.overrides_text, "units": units,
            "triangulation": case.triangulation, "stress_space": case.stress_space, "kinematic": case.kinematic,
            "level": case.level, "solver": case.solver, "reference": case.reference.label(), **dict(case.tags)}


def run_case(case: Case, ref_info: dict | None, cache_root: str | None, key: str) -> dict:
    """Worker task: the row of ``case`` (failures become a row with their reason, never raise)."""
    worker = _worker_name()
    if case.isolate == "process":
        row = _run_isolated(case, ref_info, cache_root, key)
    else:
        row = compute_row(case, ref_info, cache_root, key)
    row["worker"] = worker
    return row


def compute_row(case: Case, ref_info: dict | None, cache_root: str | None, key: str) -> dict:
    row = base_row(case)
    row["started"] = now()
    t0 = time.perf_counter()
    try:
        row.update(_compute(case, ref_info, Cache(cache_root), key))
    except CvxdualError as e:
        row["status"] = one_line(f"failed: {type(e).__name__}: {e}", 300)
    except Exception as e:  # noqa: BLE001 - any failure of one case is a row, not a dead study
        row["status"] = one_line(f"failed: {type(e).__name__}: {e}", 300)
        row["_transient"] = True
    row.setdefault("t_total", time.perf_counter() - t0)
    row["finished"] = now()
    return row


def _compute(case: Case, ref_info: dict | None, cache: Cache, key: str) -> dict:
    from .. import exact_reference, solve
    scene = scene_of(case.scene_source, case.overrides, case.units)
    why = exact_reference(scene)[1] if case.reference.kind == "exact" else None
    if why is not None:  # before the solve: the case asks for what cannot be measured
        raise StudyError(f"this case asks for errors against the exact field, but {why}; measure against "
                         "reference = \"none\" or a finer level, or declare the field in the changed scene")
    if case.solver == "limit":
        return _limit(case, scene)
    kw = dict(case.solver_options)
    kw["stress_space"] = case.stress_space
    kw["kinematic"] = case.kinematic  # the certificate's side: eq rows and rows with bounds; a p0 solve ignores it
    if dict(case.tags).get("timing") == "steady":
        # one-time library start-up first (imports, solver set-up), as the limit excludes its own
        from ..linalg.factor import start_up
        solve(scene, case.triangulation, 0, case.solver, check=False, fallback=False)
        if case.solver == "fast":
            start_up()
    prof = None
    if case.profile:
        import cProfile
        prof = cProfile.Profile()
        prof.enable()
    # no hand-over to Clarabel: a study measures the path it names, failures included
    sol = solve(scene, case.triangulation, case.level, case.solver, check=case.check, fallback=False, **kw)
    if prof is not None:
        prof.disable()
    out = solution_fields(sol)
    out.update(_errors(case, scene, sol, ref_info, cache))
    if prof is not None:
        import io
        import pstats
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(18)
        out["_profile"] = buf.getvalue()
    if case.save_stress:
        cache.put_arrays("s" + key, stress=np.asarray(sol.stress, float), area=np.asarray(sol.pieces.area, float))
        out["stress_key"] = "s" + key
    if case.hooks:
        hook = getattr(load_module(Path(case.hooks)), "measure", None)
        if hook is not None:
            out.update(hook(case, sol) or {})
    return out


def solution_fields(sol) -> dict:
    """The generic columns of a solved case."""
    c, t, res = sol.contact, sol.timings, sol.residuals
    active = np.asarray(c["active"]).astype(int)
    summary = sol.summary()
    return {
        "status": sol.solver.get("status"), "n_pieces": int(summary["n_pieces"]),
        "n_stress_unknowns": int(summary["n_stress_unknowns"]), "n_dofs": int(sol.system.n_dofs),
        "h": float(sol.mesh.h), "h_min": float(sol.mesh.h_min), "h_ratio": float(sol.mesh.h_min / sol.mesh.h),
        "iterations": sol.solver.get("iterations"), "duality_gap": float(sol.duality_gap),
        **{f"res_{k}": float(v) for k, v in res.items()},
        "within_tolerances": within_tolerances(res, sol.stress_space),
        "n_active": int(c["n_active"]), "contact_x_min": c["x_min"], "contact_x_max": c["x_max"],
        "peak_pressure": c["max_pressure"], "total_force": c["total_force"],
        "n_patches": int(np.sum(np.diff(np.r_[0, active]) == 1)),
        **{f"t_{k}": float(v) for k, v in t.items()},
        **_certificate(sol),
    }


def _certificate(sol) -> dict:
    """An equilibrium solution's certificate: the bound ``sqrt(2G)`` relative to the stress's
    energy norm (it bounds the relative energy error of the stress and of the displacement) and
    whether it is guaranteed."""
    b = sol.bounds
    if b is None:
        return {}
    rel = b["error_bound_rel"]
    return {"bound_energy_rel": np.nan if rel is None else float(rel), "guaranteed": bool(b["guaranteed"])}


def _errors(case: Case, scene, sol, ref_info: dict | None, cache: Cache) -> dict:
    from .. import exact_reference
    from ..pipeline import space_of
    m = dict(case.metrics)
    space = space_of(sol.stress_space)
    out = {"error_l2": np.nan, "error_l2_rel": np.nan, "error_energy": np.nan, "error_energy_rel": np.nan,
           "error_l2_rel_finer_rule": np.nan, "reference_error_est": np.nan}
    if case.reference.kind == "finer":
        out.update(ref_dropped_area=np.nan, ref_dropped_share=np.nan)
    ref = case.reference
    if ref.kind == "exact":
        ex = exact_reference(scene)[0]  # one that does not solve the scene failed the case before the solve
        if ex is None:
            if sol.error is None:
                return out  # no exact field: nothing to measure (e.g. a stability case on blocks)
        if sol.error is not None and sol.error.get("rule") == m["rule"]:
            err = sol.error
        else:  # the study's rule (eq: per sub-triangle and slab)
            err = space.exact_error(sol, ex, m["rule"])
        if space.certifies:  # with the displacement's error: what the certificate bounds
            out.update(error_combined=err["combined"], effectivity=err["effectivity"])
        if case.check_rule:
            out["error_l2_rel_finer_rule"] = space.exact_error(sol, ex, m["check_rule"])["l2_rel"]
        out["reference_error_est"] = 0.0
        if m["edge_share"] and getattr(ex, "hertz", None) is not None and isinstance(sol.field, PieceField):
            out["edge_error_share"] = edge_share(sol, ex, m["rule"])
    elif ref.kind == "finer":
        if ref_info is None:
            raise StudyError("internal: a finer-level reference without its info")
        field, _ = reference_field(scene, ref, ref.level, cache)
        err = distance(field, sol, m["ref_rule"], m["ref_fine"])
        if space.certifies:
            out.update(_combined(field, sol, err, m))
        if case.check_rule:
            out["error_l2_rel_finer_rule"] = distance(field, sol, m["ref_check_rule"], m["ref_check_fine"])["l2_rel"]
        out["reference_error_est"] = ref_info["error_est"]
        # the error is integrated over the common part of both meshes: what that leaves out
        out.update(ref_dropped_area=err["dropped_area"], ref_dropped_share=err["dropped_share"])
    else:
        return out
    if not all(np.isfinite(err[k]) for k in ("l2", "l2_rel", "energy", "energy_rel")):
        what = "exact field" if ref.kind == "exact" else f"reference ({ref.label()})"
        raise CvxdualError(f"the {what} has a zero norm: relative errors against it are undefined "
                           "(is the scene loaded?)")
    out.update(error_l2=err["l2"], error_l2_rel=err["l2_rel"], error_energy=err["energy"],
               error_energy_rel=err["energy_rel"])
    return out


def _combined(field, sol, err: dict, m: dict) -> dict:
    """What the certificate bounds, measured against the reference ``lam*``: the combined error
    ``sqrt(||sigma - lam*||_A^2 + ||lam* - C e(v)||_A^2)`` (``= ||u - v||_a`` for the second term)
    of an equilibrium solution, and the effectivity ``sqrt(2G)`` over it. ``v`` is the certificate's
    own displacement (``bounds["displacement"]``): P1 nodal values (``sol.displacement`` itself), or a
    P2 displacement whose ``C e(v)`` is linear on every sub-triangle and exact on the slabs
    (:class:`~cvxdual.eq.fields.P2KinematicField`), never its nodal values read as P1."""
    from ..eq.fields import kinematic_field
    kin = distance(field, kinematic_field(sol.space, sol.bounds["displacement"]), m["ref_rule"], m["ref_fine"])
    combined = float(np.hypot(err["energy"], kin["energy"]))
    return {"error_combined": combined,
            "effectivity": sol.bounds["error_bound"] / combined if combined > 0 else np.nan}


def edge_share(sol, ex, rule: int) -> float:
    """Share of the squared L2 error within ``EDGE_RADIUS * a`` of the Hertz contact edges."""
    from ..voigt import VOIGT_WEIGHT
    pts, w, idx = sol.pieces.quadrature(rule)
    body = sol.pieces.body[idx]
    ref = np.empty((len(pts), 3))
    for k in (0, 1):
        sel = body == k
        ref[sel] = ex.stress(k, pts[sel])
    e2 = w * np.sum(VOIGT_WEIGHT * (sol.stress[idx] - ref) ** 2, axis=1)
    a = ex.hertz.a
    near = np.hypot(np.abs(pts[:, 0] - ex.xc) - a, pts[:, 1] - ex.y_face) < EDGE_RADIUS * a
    return float(e2[near].sum() / e2.sum())


def _limit(case: Case, scene) -> dict:
    """The speed "limit" (:func:`cvxdual.system.displacement.limit`): the fastest factorisation plus solve of the
    stiffness, all pairs closed, among the installed backends."""
    from .. import assemble, discretize
    from ..system.displacement import limit
    t0 = time.perf_counter()
    mesh, pieces, ties = discretize(scene, case.triangulation, case.level)
    system = assemble(mesh, pieces, ties)
    t1 = time.perf_counter()
    lim = limit(system)
    return {"status": Status.OPTIMAL, "n_pieces": int(system.n_pieces), "h": float(mesh.h), "t_setup": t1 - t0,
            **lim, "t_total": time.perf_counter() - t0, "error_l2": np.nan, "error_l2_rel": np.nan}


def now() -> str:
    """The wall-clock time as an ISO 8601 UTC string (millisecond resolution)."""
    from datetime import datetime, timezone
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


# one thread per isolated case unless the user says otherwise: cases run side by side (one per
# worker), and threads of one case spinning against another's made timings 5-10x noisier
ISOLATED_THREADS = {k: "1" for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}


def _run_isolated(case: Case, ref_info, cache_root, key) -> dict:
    """The case in a fresh interpreter: a clean peak memory, and a time limit."""
    payload = json.dumps({"case": case.to_json(), "ref_info": ref_info, "cache": cache_root, "key": key})
    cmd = [sys.executable, "-m", "cvxdual.study.cases", "-"]
    t0 = now()
    try:
        p = subprocess.run(cmd, input=payload, capture_output=True, text=True, timeout=case.timeout,
                           env={**ISOLATED_THREADS, **os.environ})
    except subprocess.TimeoutExpired:
        return {**base_row(case), "status": f"timeout (>{case.timeout:.0f} s)", "started": t0,
                "finished": now(), "t_total": np.nan}
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or ["no output"])[-1]
        what = "killed" if p.returncode < 0 else "failed"
        return {**base_row(case), "status": one_line(f"{what}: exit {p.returncode}: {last}", 300), "started": t0,
                "finished": now(), "_transient": True}
    return json.loads(p.stdout.strip().splitlines()[-1])


def _main() -> int:  # python -m cvxdual.study.cases - (the case as JSON on stdin)
    from ..files import to_jsonable as clean
    d = json.loads(sys.stdin.read())
    row = compute_row(Case.from_json(d["case"]), d["ref_info"], d["cache"], d["key"])
    row["peak_mb"] = peak_mb()
    print(json.dumps(clean(row)))
    return 0


if __name__ == "__main__":
    sys.exit(_main())
