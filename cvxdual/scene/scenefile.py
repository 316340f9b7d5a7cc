"""Scenes from TOML files, and the built-in scenes.

Every built-in scene is a TOML file in ``cvxdual/scene/data``. A user file may start from one with
``base = "hertz"``, or from another file with ``base = "other.toml"`` (relative to the directory
of the file holding the ``base`` line), and override any value (tables are merged key by key);
the CLI's ``--set mesh.grading=4`` does the same for single values. Keys are checked strictly:
an unknown key is an error that names it. The format is documented in docs/scenes.md.
"""

from __future__ import annotations

import copy
import os
import stat
import tomllib
from dataclasses import replace
from importlib import resources
from pathlib import Path

from ..errors import SceneError
from ..validate import integer, number, pair, short, table, text
from .geo import read_geo
from .materials import Material
from .outline import outline_from_dict
from .piecewise import profile_from_dict
from .scene import WHY, Body, BoundaryPart, ExactSpec, Friction, MeshSpec, Scene, Traction, problem_entries

TOP_KEYS = {"name", "description", "base", "units", "plane", "contact", "exact", "mesh", "bodies"}
BODY_KEYS = {"position", "x", "far", "face", "material", "boundary", "body_force", "layers", "focus_depth", "outline",
             "holes", "geo"}
PART_KEYS = {"on", "kind", "traction", "interval", "direction"}
MATERIAL_KEYS = {"E", "nu", "hooke"}
CONTACT_KEYS = {"interval", "gap", "friction"}
FRICTION_KEYS = {"kind", "g"}
EXACT_KEYS = {"kind", "stress", "R", "load", "xc", "any_material", "b"}
MESH_KEYS = {"columns", "focus", "grading", "default_level"}
TRACTION_KEYS = {"kind", "value"}


def builtin_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("cvxdual.scene.data").iterdir() if p.name.endswith(".toml"))


def builtin_scenes() -> dict[str, str]:
    """``{name: one-line description}`` of the built-in scenes."""
    return {n: builtin_data(n).get("description", "") for n in builtin_names()}


MAX_DEPTH = 32  # a scene nests about 5 tables deep; far deeper input is refused, not recursed into


def builtin_data(name) -> dict:
    """The raw dict of a built-in scene, as read from its TOML file."""
    if not isinstance(name, str) or name not in builtin_names():
        # a bare name is a built-in scene's; a file of that name here is read only as a path
        here = isinstance(name, str) and name and os.path.lexists(name)
        raise SceneError(f"unknown scene {short(name)}; built-in scenes: {', '.join(builtin_names())} "
                         + (f"(a file {short(name)} is here: give it as ./{name} to read it)" if here else
                            "(or give a path to a .toml file)"))
    return tomllib.loads(resources.files("cvxdual.scene.data").joinpath(f"{name}.toml").read_text())


def _replaces(base: dict, over: dict) -> bool:
    """A table that changes what the base table *is* replaces it instead of merging: a profile
    or traction of another ``kind`` (their parameters depend on the kind), or a material
    switching between ``E``/``nu`` and ``hooke``."""
    if "kind" in over and "kind" in base and over["kind"] != base["kind"]:
        return True
    mat = {"E", "nu", "hooke"}
    return bool(set(over) & mat) and ("hooke" in over) != ("hooke" in base)


# a body's geometry: a ``geo`` file gives all of it, so a ``geo`` over a body drops these from the base
GEO_REPLACES = ("x", "far", "face", "outline", "holes")


def merge(base: dict, over: dict) -> dict:
    """Deep merge: tables merge key by key (unless :func:`_replaces`), everything else is replaced.
    A boundary part whose kind changes keeps only its place (``on``, ``interval``) from the base; a
    body given by ``geo`` keeps none of the base's geometry (:data:`GEO_REPLACES`), only the rest
    (material, boundary, ...)."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        b = out.get(k)
        if isinstance(v, dict) and isinstance(b, dict) and isinstance(v.get("geo"), str):  # a body's geo file
            b = {key: val for key, val in b.items() if key not in GEO_REPLACES}
        if isinstance(v, dict) and isinstance(b, dict) and "on" in b and v.get("kind", b.get("kind")) != b.get("kind"):
            out[k] = {**{key: b[key] for key in ("on", "interval") if key in b}, **copy.deepcopy(v)}
        elif isinstance(v, dict) and isinstance(b, dict) and not _replaces(b, v):
            out[k] = merge(b, v)
        elif isinstance(v, dict) and isinstance(b, list) and v and all(_is_index(i) for i in v):
            out[k] = _merge_items(b, v, k)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _is_index(key) -> bool:
    """An item number of a list: ASCII digits only (``str.isdigit`` also takes digits ``int`` refuses, as ``²``)."""
    return str(key).isascii() and str(key).isdigit()


def _merge_items(items: list, over: dict, key: str) -> list:
    """Items of a list changed by their index (``--set bodies.bottom.holes.0.radius=1``): a table
    item merges as a table, anything else is replaced."""
    out = copy.deepcopy(items)
    for i, v in over.items():
        j = int(i) if len(str(i)) < 10 else len(out)  # a hostile index: past the end, not a huge int
        if j >= len(out):
            raise SceneError(f"cannot change item {short(str(i))} of {short(key)}: it has {len(out)} item(s), "
                             "numbered from 0")
        out[j] = merge(out[j], v) if isinstance(v, dict) and isinstance(out[j], dict) else copy.deepcopy(v)
    return out


def parse_assignment(text: str) -> dict:
    """``"mesh.grading=4"`` -> ``{"mesh": {"grading": 4}}`` (the value is parsed as TOML)."""
    if "=" not in text:
        raise SceneError(f"--set expects KEY=VALUE (e.g. mesh.grading=4), got {text!r}")
    key, value = text.split("=", 1)
    try:
        v = _toml(f"v = {value.strip()}", "--set value")["v"]
    except SceneError:
        v = value.strip()  # a bare word is taken as a string
        if v[:1] in "[{\"'":  # but a broken array, table or string is an error, not a word
            raise
    if key.strip() == "base":
        raise SceneError("--set cannot change 'base'; write base = \"NAME\" in a scene file and pass it with --scene")
    d: dict = v
    for part in reversed(key.strip().split(".")):
        if not part:
            raise SceneError(f"--set: bad key {short(key)}")
        # an item of a list is numbered with ASCII digits: int() refuses the other digits str.isdigit accepts
        if part.strip().lstrip("+-").isnumeric() and not (part.isascii() and part.isdigit()):
            raise SceneError(f"--set: bad key {short(key)}: {short(part)} is not a list index; items are numbered "
                             "from 0 with the digits 0-9 (e.g. bodies.bottom.holes.0.radius=1.0)")
        d = {part: d}
    return d


def _toml(source: str, what: str) -> dict:
    try:
        data = tomllib.loads(source)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{what} is not valid TOML: {e}") from None
    except RecursionError:
        raise SceneError(f"{what} is nested too deeply to be a scene") from None
    _check_depth(data, what)
    return data


def _check_depth(data, what: str) -> None:
    """Refuse values nested deeper than :data:`MAX_DEPTH` (without recursing into them)."""
    level = [data]
    for _ in range(MAX_DEPTH):
        level = [v for x in level for v in (x.values() if isinstance(x, dict) else x)
                 if isinstance(v, (dict, list, tuple))]
        if not level:
            return
    raise SceneError(f"{what} is nested more than {MAX_DEPTH} levels deep; a scene has a few levels of tables")


def is_path(source) -> bool:
    """Whether a scene reference names a file (``x.toml``, ``dir/x``) rather than a built-in scene."""
    text_ = str(source)
    return text_.endswith(".toml") or bool(Path(text_).suffix) or "/" in text_ or "\\" in text_


def _path_text(path: Path, limit: int = 100) -> str:
    """``repr`` of a path for a message, cut from the left: the file's name is the informative end."""
    text_ = repr(str(path))
    return text_ if len(text_) <= limit else "'..." + text_[len(text_) - limit + 4:]


def _not_a_file(path: Path) -> str | None:
    """What keeps ``path`` from being read as a scene file, as the end of a sentence naming it
    (``"does not exist"``, ``"is a directory"``, ...), or ``None`` for a regular file."""
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return ("does not exist" + (" (a symbolic link to nothing)" if os.path.islink(path) else "")
                + f"; check the path, or name a built-in scene ({', '.join(builtin_names())})")
    except PermissionError:
        return "cannot be reached: a directory on its path is not readable by you; check the permissions"
    except OSError as e:
        return f"cannot be read ({e.strerror or e})"
    if stat.S_ISDIR(mode):
        return "is a directory, not a scene file; give the path of a .toml file"
    if not stat.S_ISREG(mode):
        return "is not a regular file (a device, a pipe or a socket); give the path of a .toml file"
    return None


def _read_file(path: Path, where: str) -> dict:
    """The raw dict of scene file ``path`` (``where`` names it in messages)."""
    problem = _not_a_file(path)
    if problem is not None:
        raise SceneError(f"{where} {problem}")
    try:
        return _toml(path.read_text(encoding="utf-8"), where)
    except UnicodeDecodeError:
        raise SceneError(f"{where} is not UTF-8 text; save it as UTF-8 TOML") from None
    except OSError as e:
        raise SceneError(f"cannot read {where} ({e.strerror or e}); check its permissions") from None


def _base_data(ref, holder: Path | None, holder_name: str) -> tuple[dict, Path | None, str]:
    """The raw dict named by ``base = ref`` in the scene ``holder_name`` (its file ``holder``, or
    ``None`` for a built-in scene or a dict): a built-in name, or a path relative to the directory
    of ``holder``. Returns the data, its file (``None`` for a built-in) and its name for messages."""
    if not isinstance(ref, str) or not ref:
        raise SceneError(f"{holder_name}: base must be a built-in scene name ({', '.join(builtin_names())}) or the "
                         f"path of a .toml file, got {short(ref)}")
    if not is_path(ref):
        if ref not in builtin_names():
            raise SceneError(f"{holder_name}: base {short(ref)} is not a built-in scene ({', '.join(builtin_names())})"
                             "; give one of those, or the path of a .toml file relative to this file, e.g. "
                             "base = \"other.toml\"")
        return builtin_data(ref), None, f"built-in scene {ref!r}"
    path = Path(ref).expanduser()
    relative = not path.is_absolute()
    if relative:
        if holder is None:
            raise SceneError(f"{holder_name}: base {short(ref)} is a relative path, but this scene is not read from "
                             "a file, so there is no directory to resolve it against; give an absolute path or a "
                             "built-in scene name, or load the scene from a file")
        path = holder.parent / path
    where = f"scene file {_path_text(path)}"
    problem = _not_a_file(path)
    if problem is not None and problem.startswith("does not exist"):
        rel = " (relative to the directory of the file holding the base line)" if relative else ""
        raise SceneError(f"{holder_name}: base {short(ref)} does not exist: no file {_path_text(path)}; "
                         f"fix the path{rel} or name a built-in scene ({', '.join(builtin_names())})")
    if problem is not None:
        raise SceneError(f"{holder_name}: base {short(ref)}: {_path_text(path)} {problem}")
    return _read_file(path, where), path, where


def load_scene(source: str | Path | dict | None = None, overrides: list[dict] | None = None) -> Scene:
    """A scene from a built-in name, a TOML path, or a dict; ``overrides`` are merged on top.

    ``base`` (in a file, a built-in scene or a dict) names the scene to start from: a built-in
    name, or a file path, relative to the directory of the file holding the ``base`` line (a
    dict has no directory: its ``base`` may be a built-in name or an absolute path). Bases may
    nest; a cycle is refused."""
    if source is None:
        source = "hertz"
    holder: Path | None = None
    if isinstance(source, dict):
        _check_depth(source, "the scene")
        data = source
        name = "the scene (a dict)"
        seen = []
    elif is_path(source):
        holder = Path(source)
        name = f"scene file {short(str(holder))}"
        data = _read_file(holder, name)
        data.setdefault("name", holder.stem)
        seen = [holder.resolve()]
    else:
        data = builtin_data(str(source))
        name = f"built-in scene {str(source)!r}"
        seen = [f"built-in scene {str(source)!r}"]
    data = _resolve_geo(copy.deepcopy(data), holder)
    chain = [name]
    files = [data]  # the raw tables of the chain, outermost first
    while "base" in data:
        ref = data.pop("base")
        base, holder, name = _base_data(ref, holder, name)
        base = _resolve_geo(copy.deepcopy(base), holder)
        key = holder.resolve() if holder is not None else name
        chain.append(name)
        if key in seen:
            raise SceneError(f"scene bases form a cycle: {' -> '.join(chain)}; remove one of these base lines")
        seen.append(key)
        files.append(base)
        data = merge(base, data)
    for o in overrides or []:
        _check_depth(o, "an override")
        if isinstance(o, dict) and "base" in o:
            raise SceneError("an override cannot change 'base'; start from the other scene instead")
        _check_bodies_named(o, data)
        data = merge(data, _resolve_geo(copy.deepcopy(table(o, "an override")), None))
    scene = scene_from_dict(data)
    # The exact field solves the scene of the outermost file with an [exact] table: a file that
    # starts from that one, and the overrides, change the problem without making the field solve it.
    at = next((i for i, f in enumerate(files) if "exact" in f), None)
    if scene.exact is not None and at is not None and (at > 0 or overrides):
        try:
            declared = problem_entries(scene_from_dict(_merged(files[at:])))
        except SceneError as e:
            declared = ((WHY, f"the exact field is declared in {chain[at]}, which is not a valid scene on its "
                               f"own ({e})"),)
        scene = replace(scene, exact=replace(scene.exact, declared_for=declared))
    return scene


def _check_bodies_named(override, data: dict) -> None:
    """An override changes bodies the scene has: merging cannot remove one, so a new name is
    always a typo, refused before it surfaces as a half-made third body ("missing key 'nu'")."""
    bodies, known = (override.get("bodies") if isinstance(override, dict) else None), data.get("bodies")
    unknown = sorted(set(bodies) - set(known)) if isinstance(bodies, dict) and isinstance(known, dict) else []
    if unknown:
        raise SceneError(f"an override names body {short(unknown[0], 40)}, which the scene does not have; its bodies "
                         f"are {', '.join(map(repr, data['bodies']))}")


def _resolve_geo(data: dict, holder: Path | None) -> dict:
    """``bodies.*.geo`` paths resolved in the folder of the file that holds them (the working
    directory for a dict or an override): a scene reads regular ``.geo`` files in its own folder
    (or below it), never elsewhere, whatever the path or a link in it says."""
    bodies = data.get("bodies")
    if not isinstance(bodies, dict):
        return data
    folder = (holder.parent if holder is not None else Path.cwd()).resolve()
    home = "the scene file's folder" if holder is not None else "the working directory"
    for name, b in bodies.items():
        if not (isinstance(b, dict) and isinstance(b.get("geo"), str)):
            continue
        where, ref = f"bodies.{name}.geo", b["geo"]
        path = Path(ref).expanduser()
        if path.suffix.lower() != ".geo":
            raise SceneError(f"{where}: {short(ref)} is not a .geo file ({path.suffix or 'no suffix'}); a body reads "
                             "only a .geo file drawn with points, lines, arcs and splines (docs/scenes.md)")
        try:
            target = (folder / path).resolve()  # an absolute path stays itself; links and .. are followed
        except (OSError, RuntimeError, ValueError) as e:  # a loop of links, a NUL in the path
            raise SceneError(f"{where}: {short(ref)} cannot be followed ({short(str(e))}); give a plain path to a "
                             ".geo file") from None
        if not target.is_relative_to(folder):
            raise SceneError(f"{where}: {short(ref)} is outside {home} {_path_text(folder)}; put the .geo file in "
                             "that folder (or below it) and give its path relative to it")
        try:
            mode = target.stat().st_mode
        except (FileNotFoundError, NotADirectoryError):
            raise SceneError(f"{where}: no file {short(ref)} in {home} {_path_text(folder)}; give the path of a .geo "
                             "file relative to it") from None
        except OSError as e:
            raise SceneError(f"{where}: {short(ref)} cannot be read ({e.strerror or e}); check its "
                             "permissions") from None
        if not stat.S_ISREG(mode):
            raise SceneError(f"{where}: {short(ref)} is not a regular file (a directory, FIFO or device); give a .geo "
                             "file")
        b["geo"] = str(target)
    return data


def _merged(files: list[dict]) -> dict:
    """The table of a chain of raw scene tables (outermost first), merged as :func:`load_scene` does."""
    data = {k: v for k, v in files[0].items() if k != "base"}
    for base in files[1:]:
        data = merge({k: v for k, v in base.items() if k != "base"}, data)
    return data


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
    plane = text(data.get("plane", "strain"), "scene plane")
    units = data.get("units", ["m", "Pa"])
    if not (isinstance(units, list) and len(units) == 2 and all(isinstance(u, str) for u in units)):
        raise SceneError(f"scene: units must be [length, stress] names, e.g. [\"mm\", \"MPa\"], got {short(units)}")
    bodies_d = _check_keys(_need(data, "bodies", "scene"), None, "bodies")
    bodies = tuple(_body(name, bd, plane) for name, bd in bodies_d.items())
    contact = _check_keys(data.get("contact", {}), CONTACT_KEYS, "contact")
    gap = profile_from_dict(contact["gap"], "contact.gap") if "gap" in contact else None
    friction = _friction(contact["friction"]) if "friction" in contact else None
    exact = None
    if "exact" in data:
        e = _check_keys(data["exact"], EXACT_KEYS, "exact")
        exact = ExactSpec(kind=text(_need(e, "kind", "exact"), "exact.kind"), stress=e.get("stress"), R=e.get("R"),
                          load=e.get("load"), xc=e.get("xc", 0.0), any_material=e.get("any_material", False),
                          b=e.get("b"))
    m = _check_keys(data.get("mesh", {}), MESH_KEYS, "mesh")
    mesh = MeshSpec(columns=integer(m.get("columns", 8), "mesh.columns"), focus=m.get("focus"),
                    grading=number(m.get("grading", 1.0), "mesh.grading", 1.0),
                    default_level=integer(m.get("default_level", 3), "mesh.default_level"))
    return Scene(name=data.get("name", "scene"), bodies=bodies, description=data.get("description", ""),
                 contact=contact.get("interval"), gap=gap, exact=exact, mesh=mesh, units=tuple(units),
                 friction=friction)  # Scene checks


def _friction(d) -> Friction:
    """``[contact] friction = { kind = "tresca", g = ... }``; ``kind`` defaults to tresca, so
    ``--set contact.friction.g=100`` alone gives a frictionless scene Tresca friction."""
    _check_keys(d, FRICTION_KEYS, "contact.friction")
    kind = d.get("kind", "tresca")
    if "g" not in d and kind == "tresca":  # another kind: Friction's error on the kind says more
        raise SceneError("contact.friction: missing key 'g'; give the Tresca slip threshold, a traction in the "
                         "scene's stress units, e.g. friction = { g = 100.0 } (g = inf: full stick)")
    return Friction(kind=kind, g=d.get("g"))


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
                                  interval=pd.get("interval"), name=pname, direction=pd.get("direction")))
    focus_depth = d.get("focus_depth")
    outline = None
    if "geo" in d:
        clash = sorted({"x", "face", "outline", "holes"} & set(d))
        if clash:
            raise SceneError(f"{where}: give either geo (the body's whole boundary) or {', '.join(clash)}, not both")
        face, x, outline = read_geo(text(d["geo"], f"{where}.geo"), _need(d, "position", where), where)
        d = {**d, "x": x}
    else:
        face = profile_from_dict(_need(d, "face", where), f"{where}.face")
    if "outline" in d:
        x1 = pair(_need(d, "x", where), f"{where}.x")[1]
        outline = outline_from_dict(d["outline"], d.get("holes"), (x1, float(face.value(x1))), where)
    elif "holes" in d and outline is None:
        raise SceneError(f"{where}: holes need an outline; give the body's outline too")
    return Body(name=name, position=_need(d, "position", where), x_range=_need(d, "x", where),
                far=number(_need(d, "far", where), f"{where}.far") if "far" in d or outline is None else None,
                face=face, outline=outline,
                material=material, boundary=tuple(parts), body_force=d.get("body_force", (0.0, 0.0)),
                layers=integer(d.get("layers", 4), f"{where}.layers"),
                focus_depth=None if focus_depth is None else number(focus_depth, f"{where}.focus_depth", "positive"))
