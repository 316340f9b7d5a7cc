"""Scenes from TOML files, and the built-in scenes.

Every built-in scene is a TOML file in ``cvxdual/data``. A user file may start from one with
``base = "hertz"`` and override any value (tables are merged key by key), and the CLI's
``--set mesh.grading=4`` does the same for single values. Keys are checked strictly: an
unknown key is an error that names it. The format is documented in the README.
"""

from __future__ import annotations

import copy
import tomllib
from importlib import resources
from pathlib import Path

from .errors import SceneError
from .materials import Material
from .profiles import profile_from_dict
from .scene import Body, BoundaryPart, ExactSpec, MeshSpec, Scene, Traction
from .validate import integer, number, table

TOP_KEYS = {"name", "description", "base", "units", "plane", "contact", "exact", "mesh", "bodies"}
BODY_KEYS = {"position", "x", "far", "face", "material", "boundary", "body_force", "layers", "focus_depth"}
PART_KEYS = {"on", "kind", "traction", "interval"}
MATERIAL_KEYS = {"E", "nu", "hooke"}
CONTACT_KEYS = {"interval", "gap"}
EXACT_KEYS = {"kind", "stress", "R", "load", "xc"}
MESH_KEYS = {"columns", "focus", "grading", "default_level"}
TRACTION_KEYS = {"kind", "value"}


def builtin_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("cvxdual.data").iterdir() if p.name.endswith(".toml"))


def builtin_scenes() -> dict[str, str]:
    """``{name: one-line description}`` of the built-in scenes."""
    return {n: _read_builtin(n).get("description", "") for n in builtin_names()}


def _read_builtin(name: str) -> dict:
    if name not in builtin_names():
        raise SceneError(f"unknown scene {name!r}; built-in scenes: {', '.join(builtin_names())} "
                         "(or give a path to a .toml file)")
    return tomllib.loads(resources.files("cvxdual.data").joinpath(f"{name}.toml").read_text())


def _replaces(base: dict, over: dict) -> bool:
    """A table that changes what the base table *is* replaces it instead of merging: a profile
    or traction of another ``kind`` (their parameters depend on the kind), or a material
    switching between ``E``/``nu`` and ``hooke``."""
    if "kind" in over and "kind" in base and over["kind"] != base["kind"]:
        return True
    mat = {"E", "nu", "hooke"}
    return bool(set(over) & mat) and ("hooke" in over) != ("hooke" in base)


def merge(base: dict, over: dict) -> dict:
    """Deep merge: tables merge key by key (unless :func:`_replaces`), everything else is replaced.
    A boundary part whose kind changes keeps only its place (``on``, ``interval``) from the base."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        b = out.get(k)
        if isinstance(v, dict) and isinstance(b, dict) and "on" in b and v.get("kind", b.get("kind")) != b.get("kind"):
            out[k] = {**{key: b[key] for key in ("on", "interval") if key in b}, **copy.deepcopy(v)}
        elif isinstance(v, dict) and isinstance(b, dict) and not _replaces(b, v):
            out[k] = merge(b, v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def parse_assignment(text: str) -> dict:
    """``"mesh.grading=4"`` -> ``{"mesh": {"grading": 4}}`` (the value is parsed as TOML)."""
    if "=" not in text:
        raise SceneError(f"--set expects KEY=VALUE (e.g. mesh.grading=4), got {text!r}")
    key, value = text.split("=", 1)
    try:
        v = tomllib.loads(f"v = {value.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        v = value.strip()  # a bare word is taken as a string
    d: dict = v
    for part in reversed(key.strip().split(".")):
        if not part:
            raise SceneError(f"--set: bad key {key!r}")
        d = {part: d}
    return d


def load_scene(source: str | Path | dict | None = None, overrides: list[dict] | None = None) -> Scene:
    """A scene from a built-in name, a TOML path, or a dict; ``overrides`` are merged on top."""
    if source is None:
        source = "hertz"
    if isinstance(source, dict):
        data = source
    elif str(source).endswith(".toml") or Path(str(source)).suffix:
        path = Path(source)
        if not path.is_file():
            raise SceneError(f"scene file {str(path)!r} does not exist")
        try:
            data = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as e:
            raise SceneError(f"scene file {str(path)!r} is not valid TOML: {e}") from None
        data.setdefault("name", path.stem)
    else:
        data = _read_builtin(str(source))
    data = copy.deepcopy(data)
    while "base" in data:
        base = data.pop("base")
        data = merge(_read_builtin(str(base)), data)
    for o in overrides or []:
        data = merge(data, o)
    return scene_from_dict(data)


def _check_keys(d, allowed: set[str] | None, where: str) -> dict:
    table(d, where)
    if allowed is None:
        return d
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))}; "
                         f"allowed: {', '.join(sorted(allowed))}")
    return d


def _need(d: dict, key: str, where: str):
    if key not in d:
        raise SceneError(f"{where}: missing key {key!r}")
    return d[key]


def scene_from_dict(data: dict) -> Scene:
    _check_keys(data, TOP_KEYS, "scene")
    plane = data.get("plane", "strain")
    units = data.get("units", ["m", "Pa"])
    if not (isinstance(units, list) and len(units) == 2 and all(isinstance(u, str) for u in units)):
        raise SceneError(f"scene: units must be [length, stress] names, e.g. [\"mm\", \"MPa\"], got {units!r}")
    bodies_d = _check_keys(_need(data, "bodies", "scene"), None, "bodies")
    bodies = tuple(_body(name, bd, plane) for name, bd in bodies_d.items())
    contact = _check_keys(data.get("contact", {}), CONTACT_KEYS, "contact")
    gap = profile_from_dict(contact["gap"], "contact.gap") if "gap" in contact else None
    exact = None
    if "exact" in data:
        e = _check_keys(data["exact"], EXACT_KEYS, "exact")
        exact = ExactSpec(kind=_need(e, "kind", "exact"), stress=e.get("stress"), R=e.get("R"),
                          load=e.get("load"), xc=e.get("xc", 0.0))
    m = _check_keys(data.get("mesh", {}), MESH_KEYS, "mesh")
    mesh = MeshSpec(columns=integer(m.get("columns", 8), "mesh.columns"), focus=m.get("focus"),
                    grading=number(m.get("grading", 1.0), "mesh.grading"),
                    default_level=integer(m.get("default_level", 3), "mesh.default_level"))
    return Scene(name=str(data.get("name", "scene")), bodies=bodies,
                 description=str(data.get("description", "")), contact=contact.get("interval"),
                 gap=gap, exact=exact, mesh=mesh, units=tuple(units))


def _body(name: str, d: dict, plane: str) -> Body:
    where = f"bodies.{name}"
    _check_keys(d, BODY_KEYS, where)
    mat = _check_keys(_need(d, "material", where), MATERIAL_KEYS, f"{where}.material")
    if "hooke" in mat:
        if set(mat) != {"hooke"}:
            raise SceneError(f"{where}.material: give either E and nu, or hooke, not both")
        material = Material.hooke(mat["hooke"], plane=plane)
    else:
        material = Material.isotropic(_need(mat, "E", f"{where}.material"), _need(mat, "nu", f"{where}.material"),
                                      plane=plane)
    parts = []
    for pname, pd in _check_keys(d.get("boundary", {}), None, f"{where}.boundary").items():
        pw = f"{where}.boundary.{pname}"
        _check_keys(pd, PART_KEYS, pw)
        tr = None
        if "traction" in pd:
            td = _check_keys(pd["traction"], TRACTION_KEYS, f"{pw}.traction")
            tr = Traction(kind=td.get("kind", "uniform"), value=td.get("value", (0.0, 0.0)))
        parts.append(BoundaryPart(on=_need(pd, "on", pw), kind=_need(pd, "kind", pw), traction=tr,
                                  interval=pd.get("interval"), name=pname))
    focus_depth = d.get("focus_depth")
    return Body(name=name, position=_need(d, "position", where), x_range=_need(d, "x", where),
                far=number(_need(d, "far", where), f"{where}.far"),
                face=profile_from_dict(_need(d, "face", where), f"{where}.face"),
                material=material, boundary=tuple(parts), body_force=d.get("body_force", (0.0, 0.0)),
                layers=integer(d.get("layers", 4), f"{where}.layers"),
                focus_depth=None if focus_depth is None else number(focus_depth, f"{where}.focus_depth"))
