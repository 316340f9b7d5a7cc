"""The scene perturbation used by the fuzzing test (``tests/test_fuzz.py``) and ``studies/fuzz.py``.

:func:`perturb` changes a raw scene dict (as read from a scene TOML file) the way a user or a
careless script might: numbers scaled by log-uniform factors (mostly 0.5-2x, sometimes
1e-6..1e6) or moved, Poisson ratios near 1/2, Hooke matrices, boundary and contact intervals,
loads, body forces, gaps, faces, mesh parameters, optional keys dropped. With ``hostility > 0``
each change is, with that probability, a value no scene should have: 0, negatives, 1e308,
subnormals, NaN/inf, 10**400, strings, booleans, lists and tables in the wrong place, required
keys dropped, unknown keys added. :func:`check_result` lists what is wrong with a returned
:class:`~cvxdual.solution.Solution`: the package promises that the list is always empty.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from cvxdual.solution import tolerances

HOSTILE = (0, 0.0, -1.0, 1e308, -1e308, 1e-320, math.nan, math.inf, -math.inf, 10**400, -(10**400),
           "abc", "", "1e3", True, False, None, [], [1.0, 2.0], {}, {"kind": "flat"})
# dropping these makes a scene invalid: only hostile changes drop them
REQUIRED = {"bodies", "position", "x", "far", "face", "material", "E", "nu", "hooke", "on", "kind", "traction",
            "R", "load", "stress", "amplitude", "wavelength"}
PROFILES = ("flat", "parabola", "circle", "cosine")
CHOICES = {"on": ("face", "far", "left", "right"), "position": ("upper", "lower"), "plane": ("strain", "stress"),
           "branch": ("lower", "upper"), "face": PROFILES, "gap": PROFILES, "traction": ("uniform", "exact"),
           "exact": ("uniform", "hertz"), "part": ("clamped", "sliding", "traction")}
# where summary() documents null: no exact field / error / bounds, no active pair, no iteration count, a
# relative bound of vanishing stresses, the last cycle's marking (a list's items as *)
NULLABLE = {"exact", "error", "bounds", "contact.x_min", "contact.x_max", "iterations", "bounds.data_oscillation",
            "fallback", "error.effectivity", "friction", "bounds.error_bound_rel", "adaptive.cycles.*.marked_share"}


def nodes(d, prefix=()):
    """``(path, value)`` of every table entry and list item below ``d``, depth first."""
    items = d.items() if isinstance(d, dict) else enumerate(d)
    for k, v in items:
        yield (*prefix, k), v
        if isinstance(v, (dict, list)):
            yield from nodes(v, (*prefix, k))


def _get(d, path):
    for k in path:
        d = d[k]
    return d


def _set(d, path, value):
    _get(d, path[:-1])[path[-1]] = value


def _pick(rng, seq):
    return seq[int(rng.integers(len(seq)))] if len(seq) else None


def _number(v, rng):
    """A plausible change of the number ``v``: scaled or moved, mildly (80%) or by up to 1e+-6."""
    mild = rng.random() < 0.8
    if not abs(v) < 1e300:  # an earlier hostile value (10**400, inf, nan) stays
        return v
    if isinstance(v, int):
        return max(1, round(v * 2.0 ** rng.uniform(-1, 1))) if mild else round(10 ** rng.uniform(0, 3))
    if v == 0 or rng.random() < 0.3:  # move rather than scale (lengths are O(1..100) in the built-ins)
        return float(v + rng.normal() * max(abs(v), 1.0) * (0.2 if mild else 10 ** rng.uniform(-6, 3)))
    return float(v * (2.0 ** rng.uniform(-1, 1) if mild else 10.0 ** rng.uniform(-6, 6)))


def _hostile(v, rng):
    return copy.deepcopy(_pick(rng, HOSTILE + ((-v, v * 1e300) if isinstance(v, float) else ())))


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _finite(v, default: float) -> float:
    """``v`` as a float if it is a plain finite number of a sane size, else ``default``."""
    return float(v) if _is_number(v) and abs(v) < 1e300 and v == v else default


def _profile(rng, y0: float) -> dict:
    """A random face or gap profile through about ``y0``."""
    kind = _pick(rng, PROFILES)
    R = float(10 ** rng.uniform(0.5, 4)) * _pick(rng, (1.0, -1.0))
    if kind == "flat":
        return {"kind": "flat", "y0": y0}
    if kind == "parabola":
        return {"kind": "parabola", "R": R, "xc": float(rng.normal()), "y0": y0}
    if kind == "circle":
        return {"kind": "circle", "R": abs(R), "xc": 0.0, "yc": y0 + abs(R), "branch": _pick(rng, CHOICES["branch"])}
    a, wavelength = (float(10 ** rng.uniform(-3, 0)), float(10 ** rng.uniform(0, 2)))
    return {"kind": "cosine", "amplitude": a, "wavelength": wavelength, "x0": 0.0, "y0": y0}


def _bodies(d):
    b = d.get("bodies")
    return [v for v in b.values() if isinstance(v, dict)] if isinstance(b, dict) else []


def _op_number(d, rng, hostile):
    paths = [p for p, v in nodes(d) if _is_number(v)]
    if paths:
        p = _pick(rng, paths)
        _set(d, p, _hostile(_get(d, p), rng) if hostile else _number(_get(d, p), rng))


def _op_string(d, rng, hostile):
    paths = [p for p, v in nodes(d) if isinstance(v, str) and p[-1] not in ("name", "description")]
    if paths:
        p = _pick(rng, paths)
        ctx = p[-2] if p[-1] == "kind" and len(p) > 1 else p[-1]
        ctx = "part" if p[-1] == "kind" and len(p) > 2 and p[-3] == "boundary" else ctx
        _set(d, p, _hostile(_get(d, p), rng) if hostile else _pick(rng, CHOICES.get(ctx, ("x",))))


def _op_material(d, rng, hostile):
    body = _pick(rng, _bodies(d))
    if body is None:
        return
    mat = body.get("material") if isinstance(body.get("material"), dict) else {}
    E, nu = _finite(mat.get("E"), 1e5), _finite(mat.get("nu"), 0.3)
    nu = nu if -0.9 < nu < 0.49 else 0.3
    r = rng.random()
    if r < 0.4:  # nearly incompressible (or nearly -1)
        nu = 0.5 - 10 ** rng.uniform(-12, -1) if r < 0.3 else -1 + 10 ** rng.uniform(-9, -1)
        body["material"] = {"E": E, "nu": float(nu)}
    else:  # an isotropic Hooke matrix (plane strain), optionally made orthotropic
        lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
        C = [[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]]
        s = 10 ** rng.uniform(-1, 1, 3) if r > 0.7 else np.ones(3)  # D C D: still positive definite
        C = [[float(C[i][j] * s[i] * s[j]) for j in range(3)] for i in range(3)]
        if hostile:  # not symmetric, singular, a wrong shape or a wrong type
            C = _pick(rng, ([[*q[:2], 1.0] for q in C], [[0.0] * 3] * 3, C[:2], [["a"] * 3] * 3, [[math.nan] * 3] * 3))
        body["material"] = {"hooke": C}


def _op_interval(d, rng, hostile):
    """A new sub-interval of a boundary part (of its side), of the contact interval or of the mesh focus."""
    body = _pick(rng, _bodies(d)) or {}
    parts = body.get("boundary") if isinstance(body.get("boundary"), dict) else {}
    part = _pick(rng, [p for p in parts.values() if isinstance(p, dict)] + [None, None])
    span = body.get("x") if isinstance(body.get("x"), list) and len(body["x"]) == 2 else [-30.0, 30.0]
    if part is not None and part.get("on") in ("left", "right"):  # a y interval between face and far side
        span = [0.0, _finite(body.get("far"), 10.0)]
    a, b = sorted(_finite(v, 0.0) for v in span)
    lo, hi = sorted(float(rng.uniform(a, b)) for _ in range(2))
    if hostile:
        lo, hi = _pick(rng, ((hi, lo), (lo, lo), (-1e308, 1e308), (lo, math.nan), (1e3, 2e3)))
    if part is not None:
        part["interval"] = [lo, hi]
    elif isinstance(d.setdefault(where := _pick(rng, ("contact", "mesh")), {}), dict):
        d[where]["interval" if where == "contact" else "focus"] = [lo, hi]


def _op_load(d, rng, hostile):
    """Scale, turn or reverse a traction, or add a body force."""
    body = _pick(rng, _bodies(d))
    if body is None:
        return
    parts = body.get("boundary") if isinstance(body.get("boundary"), dict) else {}
    trs = [p["traction"] for p in parts.values() if isinstance(p, dict) and isinstance(p.get("traction"), dict)]
    tr = _pick(rng, trs)
    if tr is None or rng.random() < 0.3:
        b = float(10 ** rng.uniform(-3, 2)) * rng.normal(size=2)
        body["body_force"] = [_hostile(0.0, rng) if hostile else float(b[0]), float(b[1])]
    else:
        v = tr.get("value")
        v = [_finite(x, 0.0) for x in v] if isinstance(v, list) and len(v) == 2 else [0.0, 100.0]
        a, s = rng.normal() * 0.5, _pick(rng, (1.0, 1.0, -1.0)) * 2.0 ** rng.uniform(-2, 2)
        tr["kind"] = "uniform"
        tr["value"] = [s * (math.cos(a) * v[0] - math.sin(a) * v[1]), s * (math.sin(a) * v[0] + math.cos(a) * v[1])]
        if hostile:
            tr["value"][int(rng.integers(2))] = _hostile(0.0, rng)


def _op_geometry(d, rng, hostile):
    """A new gap (possibly an interference), a new face, or a moved far side."""
    r = rng.random()
    if r < 0.4:
        d.setdefault("contact", {})
        if isinstance(d["contact"], dict):
            d["contact"]["gap"] = _hostile(None, rng) if hostile else _profile(rng, float(rng.normal() * 1e-2))
        return
    body = _pick(rng, _bodies(d))
    if body is not None:
        if r < 0.7:
            body["face"] = _hostile(None, rng) if hostile else _profile(rng, 0.0)
        elif _is_number(body.get("far")):
            body["far"] = _hostile(body["far"], rng) if hostile else _number(body["far"], rng)


def _op_keys(d, rng, hostile):
    """Drop an optional key (any key if hostile), or add an unknown key (hostile)."""
    if hostile and rng.random() < 0.5:
        tables = [d] + [v for _, v in nodes(d) if isinstance(v, dict)]
        _pick(rng, tables)[_pick(rng, ("colour", "Far", "e", "layers ", ""))] = 1.0
        return
    paths = [p for p, _ in nodes(d) if isinstance(p[-1], str) and (hostile or p[-1] not in REQUIRED)]
    if paths:
        p = _pick(rng, paths)
        del _get(d, p[:-1])[p[-1]]


OPS = ((_op_number, 5), (_op_string, 1), (_op_material, 1), (_op_interval, 1), (_op_load, 1.5),
       (_op_geometry, 1), (_op_keys, 0.5))


def perturb(data: dict, rng: np.random.Generator, hostility: float = 0.0) -> dict:
    """A deep copy of the scene dict ``data`` with 1 to about 5 random changes; each is hostile
    with probability ``hostility`` (0: only plausible changes)."""
    d = copy.deepcopy(data)
    w = np.array([w for _, w in OPS])
    for _ in range(1 + int(rng.poisson(1.0))):
        op = OPS[int(rng.choice(len(OPS), p=w / w.sum()))][0]
        op(d, rng, bool(rng.random() < hostility))
    return d


def check_result(sol) -> list[str]:
    """What is wrong with a returned solution: non-finite arrays or summary numbers, nulls
    where the summary documents none, a status other than optimal, residuals above the
    promised tolerances. Empty for a good solution."""
    problems = []
    arrays = {"stress": sol.stress, "displacement": sol.displacement,
              **{f"contact.{k}": v for k, v in sol.contact.items() if v is not None}}
    for name, a in arrays.items():
        a = np.asarray(a)
        if a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
            problems.append(f"{name}: {int(np.sum(~np.isfinite(a)))} non-finite value(s)")
    for path, v in nodes(sol.summary()):
        key = ".".join(map(str, path))
        if v is None and ".".join("*" if isinstance(k, int) else str(k) for k in path) not in NULLABLE:
            problems.append(f"summary {key} is null")
        elif isinstance(v, (float, np.floating, np.ndarray)) and not np.all(np.isfinite(v)):
            problems.append(f"summary {key} = {v}")
    if sol.solver.status != "optimal":
        problems.append(f"status {sol.solver.status!r}")
    for k, t in tolerances(sol).items():
        v = sol.residuals.get(k)
        if not (_is_number(v) or isinstance(v, np.floating)) or not v <= t:
            problems.append(f"residual {k} = {v} (tolerance {t:g})")
    return problems
