"""Fuzzing of outline bodies: random scenes and .geo files, and an oracle independent of the package.

    case = make_case(seed)   # a dict: the scene (a dict, or a TOML and a .geo text), the shapes drawn
    run_case(case)           # {"outcome", "detail", "traceback"}

:func:`make_case` draws a built-in outline scene (``block-with-hole`` or ``rounded-punch``), redraws
its bodies (studies/outline_shapes.py: plausible blocks, arcs, splines, notches, 0-4 holes), makes a
share of cases hostile (studies/outline_hostile.py) and, in a share, writes one body as a gmsh
``.geo`` file beside a scene TOML file. Seeded: the same seed is the same case.

:func:`run_case` loads the scene and builds its mesh at the case's level (in a temporary folder for
the .geo route). A :class:`cvxdual.CvxdualError` is ``rejected:<class>`` (``bad-message`` if its
message has a newline or 500 characters, ``internal:<class>`` if it says it is internal). A mesh is
compared with the bodies the generator drew (studies/outline_oracle.py): ``area`` or ``coverage`` if
it is not that body; ``accepted`` if the case must be refused (touching holes, forbidden .geo
statements, ...); ``attack`` if a file appeared in the case's folder (a .geo statement ran);
``traceback:<type>`` for any other exception; ``geo-differs`` if a plausible .geo body and the same
body in the scene file are not both meshed, ``not-invariant`` if a body scaled by 1e+-3..9 or moved
by 1e3..1e8 is not meshed (or refused) as the body drawn is. A share of the good cases is solved
(fast path): ``force`` if the contact force is not the applied load, ``solve-refused`` if solve()
stops with a MeshError on a scene whose mesh at that level builds. studies/fuzz_outlines.py runs
cases in worker processes (``hang``, ``crash``) and writes the report.
"""

from __future__ import annotations

import copy
import json
import math
import os
import tempfile
import traceback
from pathlib import Path

import numpy as np
from outline_hostile import GEO_HOSTILE, INVARIANT, SHAPE_HOSTILE, SHAPE_ONLY, mutate_geo, mutate_shape
from outline_oracle import check_body, check_mesh  # noqa: F401 (the oracle's API, re-exported)
from outline_region import region
from outline_shapes import TEMPLATES, geo_text, gmsh_curves, shapes_of

import cvxdual as cd
from cvxdual.geometry.mesh import build_mesh
from cvxdual.scene.scenefile import builtin_data, load_scene

BASES, BASE_P = ("block-with-hole", "rounded-punch"), (0.6, 0.4)
HOSTILE_SHARE = 0.3  # most cases plausible, so that most reach the mesh and the oracle
GEO_SHARE = 0.3
SOLVE_SHARE = 0.1
FORCE_TOL = 1e-5  # relative: the fast path's equilibrium tolerance is 1e-6 of the load
NOT_FINDINGS = ("ok", "rejected")


def make_case(seed: int, levels=(0, 1, 2), hostile_share: float = HOSTILE_SHARE, geo_share: float = GEO_SHARE) -> dict:
    rng = np.random.default_rng(seed)
    base = str(rng.choice(BASES, p=BASE_P))
    data = builtin_data(base)
    level = int(rng.choice(levels))
    geo_bodies = [n for n in TEMPLATES[base] if base == "block-with-hole" or n == "block"]  # flat or circle faces
    geo_body = str(rng.choice(geo_bodies)) if rng.random() < geo_share else None
    shapes = shapes_of(data, base, rng, geo_body, level)
    hostile, must_refuse = "", False
    if rng.random() < hostile_share:
        kinds = [k for k in SHAPE_HOSTILE if not (geo_body and k in SHAPE_ONLY)]
        if geo_body and rng.random() < 0.6:  # mostly the .geo text's own hostility
            kinds = GEO_HOSTILE
        hostile = str(kinds[int(rng.integers(len(kinds)))])
    plain = None
    if hostile in SHAPE_HOSTILE:
        lower, upper = (n for p in ("lower", "upper") for n, b in data["bodies"].items() if b["position"] == p)
        target = geo_body or (lower if rng.random() < 0.8 else upper)
        names, far, _ = TEMPLATES[base][target]
        if hostile in INVARIANT:  # the same scene, unmoved and at its own size
            plain = _fill(copy.deepcopy(data), copy.deepcopy(shapes))
        must_refuse = mutate_shape(hostile, rng, shapes, target, data, (names, far))
    _fill(data, shapes)
    files, splines, dict_data = {}, {}, None
    if geo_body:
        text, splines = geo_text(shapes[geo_body], rng)
        if hostile in GEO_HOSTILE:
            text, must_refuse, extra = mutate_geo(hostile, rng, text)
            files.update(extra)
        dict_data = copy.deepcopy(data)  # the same scene without the .geo file
        b = data["bodies"][geo_body]
        for k in ("x", "face", "outline", "holes"):
            b.pop(k, None)
        b["geo"] = "body.geo"
        files.update({"body.geo": text, "scene.toml": to_toml(data)})
    return {"seed": int(seed), "base": base, "level": level, "route": "geo" if geo_body else "dict",
            "hostile": hostile, "must_refuse": bool(must_refuse), "geo_body": geo_body, "data": data,
            "files": files, "splines": splines, "shapes": shapes, "dict_data": dict_data, "plain_data": plain,
            "solve": not hostile and rng.random() < SOLVE_SHARE}


def _fill(data: dict, shapes: dict) -> dict:
    """``data`` with its bodies drawn as ``shapes``."""
    for name, sh in shapes.items():
        b = data["bodies"][name]
        b.update(x=sh["x"], face=sh["face"], outline=sh["outline"], holes=sh["holes"])
        if not sh["holes"]:
            del b["holes"]
        b["boundary"] = _boundary(b["boundary"], sh)
    return data


def _boundary(boundary: dict, shape: dict) -> dict:
    """The built-in body's supports and loads on the parts the redrawn outline still has (a
    sliding support on a part that is no longer a straight line clamps it)."""
    parts = {p.get("name"): p for p in shape["outline"] if isinstance(p, dict)}
    out = {}
    for k, bp in boundary.items():
        p = parts.get(bp["on"])
        if p is not None:
            curved = "center" in p or "through" in p
            out[k] = {"on": bp["on"], "kind": "clamped"} if bp["kind"] == "sliding" and curved else copy.deepcopy(bp)
    return out


def _key(k: str) -> str:
    return k if k and all(c.isascii() and (c.isalnum() or c in "-_") for c in k) else json.dumps(k)


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if v != v else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(float(v))
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(map(toml_value, v)) + "]"
    return "{" + ", ".join(f"{_key(k)} = {toml_value(x)}" for k, x in v.items() if x is not None) + "}"


def to_toml(data: dict) -> str:
    """A scene dict as TOML (every table inline, one line per top-level key)."""
    return "".join(f"{_key(k)} = {toml_value(v)}\n" for k, v in data.items() if v is not None)


def load_and_mesh(case: dict, folder: Path):
    """The case's scene (from its files written into ``folder``, or its dict) and its mesh."""
    if case["files"]:
        for name, text in case["files"].items():
            (folder / name).write_bytes(text.replace("{DIR}", str(folder)).encode("utf-8", "surrogateescape"))
        scene = load_scene(str(folder / "scene.toml"))
    else:
        scene = load_scene(copy.deepcopy(case["data"]))
    return scene, build_mesh(scene, case["level"])


def expected_force(case: dict) -> float | None:
    """The load on the upper body, which the contact must carry: only where every load of the upper
    body is on a straight part and its only support slides along a vertical line (no vertical reaction)."""
    body = next(b for b in case["data"]["bodies"].values() if b["position"] == "upper")
    shape = next(s for s in case["shapes"].values() if s["position"] == "upper")
    ends, start = {}, None  # the first part's start is the face's end: a load there is not checked
    for p in shape["outline"]:
        ends[p["name"]] = (start, p)
        start = p["to"]
    force = 0.0
    for bp in body["boundary"].values():
        a, p = ends[bp["on"]]
        if a is None or "center" in p or "through" in p:
            return None
        if bp["kind"] == "sliding" and (abs(p["to"][0] - a[0]) > 0 or "direction" in bp):
            return None
        if bp["kind"] == "clamped":
            return None
        if bp["kind"] == "traction":
            force -= bp["traction"]["value"][1] * math.dist(a, p["to"])
    return force


def _solve_check(scene, case: dict) -> dict:
    try:
        sol = cd.solve(scene, level=case["level"], solver="fast")
    except cd.MeshError as e:  # the mesh at this level was built: solve() must not fail on meshing it
        return {"outcome": "solve-refused", "detail": f"the mesh at level {case['level']} builds; solve(): {e}"[:400]}
    except cd.CvxdualError as e:
        return _refusal(e, "solve: ")
    want, got = expected_force(case), float(sol.contact["total_force"])
    if want is not None and not abs(got - want) <= FORCE_TOL * abs(want):
        return {"outcome": "force", "detail": f"total contact force {got:.10g}, applied load {want:.10g}"}
    return {"outcome": "ok", "detail": f"solved: contact force {got:.6g} (load {want})"}


def _refusal(e: Exception, what: str = "") -> dict:
    msg = str(e)
    if "\n" in msg or len(msg) >= 500:
        return {"outcome": "bad-message", "detail": f"{what}{type(e).__name__} of {len(msg)} chars: {msg[:300]!r}"}
    if msg.startswith("internal"):  # the package's own word for a bug
        return {"outcome": f"internal:{type(e).__name__}", "detail": what + msg[:300]}
    return {"outcome": "ok" if what else f"rejected:{type(e).__name__}", "detail": what + msg[:300]}


def run_case(case: dict) -> dict:
    """Load, mesh and check one case: ``{"outcome", "detail", "traceback"}``."""
    out = {"outcome": "ok", "detail": "", "traceback": ""}
    with tempfile.TemporaryDirectory(prefix="cvxdual-fuzz-outline-") as tmp:
        try:
            scene, mesh = load_and_mesh(case, Path(tmp))
        except cd.CvxdualError as e:
            out.update(_refusal(e))
        except Exception as e:
            out.update(outcome=f"traceback:{type(e).__name__}", detail=str(e).splitlines()[0][:300] if str(e) else "",
                       traceback=traceback.format_exc())
        else:
            if case["must_refuse"]:
                out.update(outcome="accepted", detail=f"{case['hostile']}: meshed at level {case['level']} "
                                                      f"({len(mesh.triangles())} triangles) instead of refused")
            else:
                out.update(_oracle(case, scene, mesh))
        settled = out["outcome"].split(":")[0] in NOT_FINDINGS and not case["splines"]  # gmsh's splines differ
        if settled and case["route"] == "geo" and not case["hostile"]:
            out.update(_agrees(case, out, case["dict_data"], "geo-differs", "from the .geo file", "from the dict"))
        if settled and case["plain_data"] is not None:
            out.update(_agrees(case, out, case["plain_data"], "not-invariant", case["hostile"], "as drawn"))
        stray = sorted(set(os.listdir(tmp)) - set(case["files"]))
        if stray:
            out.update(outcome="attack", detail=f"{case['hostile']}: files appeared in the case's folder: {stray}")
    return out


def _agrees(case: dict, out: dict, data: dict, finding: str, this: str, that: str) -> dict:
    """``finding`` unless the scene ``data`` is accepted or refused as the case was: a .geo body is
    the body the scene file draws (docs/scenes.md); a body moved or scaled is the same body."""
    try:
        build_mesh(load_scene(copy.deepcopy(data)), case["level"])
        other = "meshed"
    except cd.CvxdualError as e:
        other = f"refused ({type(e).__name__}: {str(e)[:200]})"
    except Exception as e:
        other = f"failed ({type(e).__name__}: {str(e)[:200]})"
    if (out["outcome"] == "ok") != (other == "meshed"):
        return {"outcome": finding, "detail": f"{this}: {out['outcome']} {out['detail'][:250]}; {that}: {other}"}
    return {}


def _oracle(case: dict, scene, mesh) -> dict:
    try:
        curves = gmsh_curves(case["splines"]) if case["splines"] else None
        regions = {n: region(sh, curves if n == case["geo_body"] else None) for n, sh in case["shapes"].items()}
        found = check_mesh(mesh, regions, np.random.default_rng(case["seed"]))
    except Exception as e:  # the oracle's own failure: a finding about this study, not the package
        return {"outcome": f"oracle-error:{type(e).__name__}", "detail": str(e)[:300],
                "traceback": traceback.format_exc()}
    if found:
        return {"outcome": found[0][0], "detail": "; ".join(d for _, d in found)[:1000]}
    return _solve_check(scene, case) if case["solve"] else {}
