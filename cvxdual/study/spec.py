"""Study specs: loading (TOML or Python), validation and expansion into cases.

A spec is a table (a TOML file, or the ``SPEC`` dict of a Python file) of

- ``name`` (output file stem), ``title``, ``description``;
- ``scenes``: built-in names or ``.toml`` paths (relative to the spec file), or tables
  ``{source, label, levels, set, reference}``;
- ``triangulations``, ``stress_spaces`` (``"p0"``, ``"eq"``), ``levels``, ``solvers`` (CVXPY
  names, ``"fast"``, or ``"limit"``: one factorisation of the stiffness), lists;
- ``kinematic``: the certificate's kinematic side (``"p2"``, the default, or ``"p1"``), a name or a
  list (an axis like ``triangulations``); it changes the eq rows and rows with bounds only;
- ``set``: a grid of ``--set`` overrides, ``{"dotted.key" = [value, ...]}`` (product over keys);
- ``reference``: ``"exact"`` (the scene's closed-form field), ``"none"``, or a finer level
  ``{level = 7}`` / ``{levels_above = 2}`` (``triangulation = "type2"``, ``solver = "fast"`` and
  ``stress_space = "p0"`` by default; ``"eq"``: the exactly admissible field, with its certified
  bound), solved once per scene variant;
- ``metrics``: quadrature rules (``rule``, ``check_rule``, ``ref_rule``, ``ref_fine``,
  ``ref_check_rule``, ``ref_check_fine``), ``check = "finest"|"all"|"none"`` (where the finer
  rule is also applied), ``edge_share`` (Hertz scenes: error share near the contact edges);
- ``check`` (accuracy checks on solutions, default true; false takes degraded solutions and
  reports them), ``solver_options`` ({solver: {option: value}}), ``units``
  (``[length factor, stress factor, "length", "stress"]``: the scene converted), ``compare``
  (solvers, the last the reference: adds ``paths_agree_l2_rel`` between rows differing only in
  solver),
  ``isolate = "process"`` (each case in a fresh process: clean peak memory), ``timeout``,
  ``profile`` (a cProfile listing of the case), ``tags`` (columns copied into the rows);
- ``cases``: a list of blocks, each a table of the keys above plus ``name`` and ``group``,
  expanded like the top level with the top level as defaults (for studies that are not one grid);
- ``quick``: keys that replace the others under ``--quick`` (a block's own ``quick`` too;
  ``quick = false`` drops a block);
- ``hooks`` (TOML only): a Python file with optional ``measure(case, solution) -> dict`` (extra
  row fields, run on the worker) and ``report(df, study, out) -> str`` (markdown sections;
  ``out`` the output directory, for plots); a Python spec defines them itself.
"""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import itertools
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

from ..errors import CvxdualError
from ..geometry.triangulation import TRIANGULATIONS
from ..kinds import SPACE_NAMES, Kinematic, Space
from ..validate import file_stem

PSEUDO_SOLVERS = ("fast", "limit")
ReferenceKind = Literal["exact", "none", "finer"]
Isolate = Literal["none", "process"]  # how a case runs: in the worker, or in a fresh process
CheckAt = Literal["finest", "all", "none"]  # metrics.check: the levels the finer rules also integrate
METRIC_DEFAULTS = {"rule": 6, "check_rule": 10, "ref_rule": 2, "ref_fine": 6, "ref_check_rule": 3,
                   "ref_check_fine": 8, "check": "finest", "edge_share": False}
KEYS = {"name", "title", "description", "scenes", "triangulations", "stress_spaces", "kinematic", "levels", "solvers",
        "set", "reference", "metrics", "check", "solver_options", "units", "compare", "isolate", "timeout", "profile",
        "tags", "cases", "quick", "hooks", "group", "report", "overrides"}
BLOCK_KEYS = KEYS - {"name", "title", "description", "cases", "hooks", "report"} | {"name"}
DEFAULT_CACHE = ".cache/cvxdual"  # finished cases, for resuming
DEFAULT_MEMORY = "4GB"  # per local worker
DEFAULT_KINEMATIC = Kinematic.P2.value  # solve()'s own default


class StudyError(CvxdualError, ValueError):
    """The study spec is invalid (unknown key, bad value, missing file)."""


@dataclass(frozen=True)
class Reference:
    """What a case's error is measured against: ``exact``, ``none``, or a finer ``level``."""

    kind: ReferenceKind
    level: int | None = None
    triangulation: str = "type2"
    solver: str = "fast"
    stress_space: str = "p0"  # of the finer solution: "eq" gives an exactly admissible reference

    def label(self) -> str:
        if self.kind != "finer":
            return self.kind
        eq = Space.parse(self.stress_space) is Space.EQ
        return f"{self.triangulation} level {self.level}" + (" eq" if eq else "")


@dataclass(frozen=True)
class Case:
    """One case: everything a worker needs to compute a row (small, picklable, JSON-able)."""

    study: str
    name: str
    group: str
    scene_source: str  # a built-in name or an absolute .toml path
    scene: str  # the scene's label in the table
    overrides: tuple  # ((dotted key, value), ...)
    units: tuple | None
    triangulation: str
    stress_space: str
    kinematic: str  # the certificate's kinematic side, "p1" or "p2" (what solve(kinematic=...) takes)
    level: int
    solver: str
    solver_options: tuple  # ((name, value), ...)
    check: bool
    reference: Reference
    metrics: tuple  # ((name, value), ...)
    check_rule: bool  # also integrate with the finer rules (the finest level of a series)
    save_stress: bool
    isolate: Isolate
    timeout: float | None
    profile: bool
    tags: tuple  # ((column, value), ...)
    hooks: str | None  # path of the Python file with measure()/report()

    @property
    def overrides_text(self) -> str:
        return "; ".join(f"{k}={_fmt_value(v)}" for k, v in self.overrides)

    def override_dicts(self) -> list[dict]:
        return [nest(k, v) for k, v in self.overrides]

    def metric(self, name: str):
        return dict(self.metrics)[name]

    def to_json(self) -> dict:
        from dataclasses import asdict
        d = asdict(self)
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Case":
        d = dict(d)
        d["reference"] = Reference(**d["reference"])
        for k in ("overrides", "solver_options", "metrics", "tags"):
            d[k] = tuple(tuple(x) for x in d[k])
        d["units"] = tuple(d["units"]) if d["units"] is not None else None
        return cls(**d)


@dataclass
class Study:
    """A loaded spec: its name, texts, expanded cases and hooks."""

    name: str
    title: str
    description: str
    cases: list[Case]
    path: Path | None
    quick: bool
    raw: dict
    hooks_path: str | None = None
    measure: object = None
    report_hook: object = None
    compare: tuple | None = None
    report: dict = field(default_factory=dict)


def _fmt_value(v) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_fmt_value(x)}" for k, x in v.items()) + "}"
    return repr(v) if isinstance(v, float) else str(v)


def nest(key: str, value) -> dict:
    d = copy.deepcopy(value)
    for part in reversed(key.split(".")):
        if not part:
            raise StudyError(f"study spec: bad override key {key!r}; write dotted scene keys such as mesh.grading")
        d = {part: d}
    return d


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, object]]:
    out = []
    for k, v in d.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, dict) and v and not {"kind"} & set(v):
            out += _flatten(v, key)
        else:
            out.append((key, v))
    return out


def _fixed_overrides(v, where: str) -> list[tuple[str, object]]:
    """Fixed overrides: a nested table, or a list of them (applied in order), or "a.b=1" strings."""
    if v is None:
        return []
    from ..scene.scenefile import parse_assignment
    items = v if isinstance(v, (list, tuple)) else [v]
    out = []
    for o in items:
        if isinstance(o, str):
            o = parse_assignment(o)
        if not isinstance(o, dict):
            raise StudyError(f"study spec {where}: overrides must be tables or \"a.b=1\" strings")
        out += _flatten(o)
    return out


def _list(v, what: str, where: str) -> list:
    if isinstance(v, (str, int, float)) and not isinstance(v, bool):
        return [v]
    if not isinstance(v, (list, tuple)) or not v:
        raise StudyError(f"study spec {where}: {what} must be a non-empty list")
    return list(v)


def load_module(path: Path):
    """Import a Python spec or hooks file by path (pickled by value, so any worker can run it)."""
    digest = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:10]
    name = f"cvxdual_study_{path.stem.replace('-', '_')}_{digest}"
    mod = sys.modules.get(name)
    if mod is None:
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise StudyError(f"study spec: cannot import {str(path)!r}; give a .py file")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        try:
            spec.loader.exec_module(mod)
        except CvxdualError:
            raise
        except Exception as e:  # noqa: BLE001 - a broken user file: one line naming it
            del sys.modules[name]
            raise StudyError(f"study spec {str(path)!r} failed to import ({type(e).__name__}: {e}); fix the file") \
                from None
        try:
            import cloudpickle
            cloudpickle.register_pickle_by_value(mod)
        except (ImportError, ValueError):  # pragma: no cover
            pass
    return mod


def resolve_spec_path(source: str | Path) -> Path:
    """The spec file ``source`` (a .toml or .py path), resolved."""
    p = Path(source)
    if p.is_file():
        return p.resolve()
    what = "is not a file" if p.exists() else "does not exist"
    raise StudyError(f"study spec {str(source)!r} {what}; give a .toml or .py spec file (the project's own "
                     "studies are in studies/specs/ of the repository)")


def load_spec(source, quick: bool = False) -> Study:
    """A :class:`Study` from a spec file (TOML or Python) or a dict."""
    path, mod = None, None
    if isinstance(source, dict):
        raw = copy.deepcopy(source)
    else:
        path = resolve_spec_path(source)
        if path.suffix == ".toml":
            try:
                raw = tomllib.loads(path.read_text())
            except tomllib.TOMLDecodeError as e:
                raise StudyError(f"study spec {str(path)!r} is not valid TOML: {e}") from None
        elif path.suffix == ".py":
            mod = load_module(path)
            if not isinstance(getattr(mod, "SPEC", None), dict):
                raise StudyError(f"study spec {str(path)!r} defines no SPEC dict; add SPEC = {{...}}")
            raw = copy.deepcopy(mod.SPEC)
        else:
            raise StudyError(f"study spec {str(path)!r}: expected a .toml or .py file")
    base = path.parent if path is not None else Path.cwd()
    unknown = set(raw) - KEYS
    if unknown:
        raise StudyError(f"study spec: unknown key {sorted(unknown)[0]!r}; allowed: {', '.join(sorted(KEYS))}")
    hooks_path = None
    if mod is None and raw.get("hooks"):
        hp = (base / raw["hooks"]).resolve()
        if not hp.is_file():
            raise StudyError(f"study spec: hooks file {str(hp)!r} does not exist; fix 'hooks'")
        mod, hooks_path = load_module(hp), str(hp)
    elif mod is not None:
        hooks_path = str(path)
    name = raw.get("name") or (file_stem(path.stem) if path else None)
    if not name or not isinstance(name, str) or file_stem(name) != name:
        raise StudyError("study spec: 'name' must be a plain file stem (e.g. name = \"convergence\")")
    if quick:
        q = raw.get("quick", {})
        if not isinstance(q, dict):
            raise StudyError("study spec: 'quick' must be a table of keys replacing the others under --quick")
        raw = {**raw, **q}
    measure = getattr(mod, "measure", None) if mod is not None else None
    cases = []
    blocks = raw.get("cases") or [{}]
    if not isinstance(blocks, list):
        raise StudyError("study spec: 'cases' must be a list of tables ([[cases]] in TOML)")
    top = {k: v for k, v in raw.items() if k not in ("cases", "quick", "name", "title", "description", "hooks",
                                                     "report")}
    for i, block in enumerate(blocks):
        if not isinstance(block, dict):
            raise StudyError(f"study spec: cases[{i}] must be a table")
        bad = set(block) - BLOCK_KEYS
        if bad:
            raise StudyError(f"study spec cases[{i}]: unknown key {sorted(bad)[0]!r}; allowed: "
                             f"{', '.join(sorted(BLOCK_KEYS))}")
        bq = block.get("quick", {})
        if quick and bq is False:
            continue
        merged = {**top, **{k: v for k, v in block.items() if k != "quick"}}
        if quick and isinstance(bq, dict):
            merged.update(bq)
        cases += _expand(name, merged, base, hooks_path if measure else None, f"cases[{i}]" if raw.get("cases")
                         else "")
    if not cases:
        raise StudyError("study spec: no cases; give scenes and levels")
    keys = [repr((c.name, c.scene_source, c.overrides, c.units, c.triangulation, c.stress_space, c.kinematic, c.level,
                  c.solver, c.tags)) for c in cases]
    if len(set(keys)) != len(keys):
        raise StudyError("study spec: the same case appears twice; give blocks different names or settings")
    compare = raw.get("compare")
    if compare is not None:
        compare = tuple(_list(compare, "compare", ""))
        if len(compare) < 2:
            raise StudyError("study spec: 'compare' takes two or more solvers, the last the reference, e.g. "
                             "compare = [\"CLARABEL\", \"fast\"]")
        compare = tuple(_solver(s) for s in compare)
        # the P0 stresses of two paths are compared; eq rows (one path) are left out
        cases = [_with(c, save_stress=True) if c.solver in compare and Space.parse(c.stress_space) is Space.P0 else c
                 for c in cases]
    return Study(name=name, title=raw.get("title", name), description=raw.get("description", ""), cases=cases,
                 path=path, quick=quick, raw=raw, hooks_path=hooks_path, measure=measure,
                 report_hook=getattr(mod, "report", None) if mod is not None else None, compare=compare,
                 report=raw.get("report", {}))


def _with(case: Case, **kw) -> Case:
    from dataclasses import replace
    return replace(case, **kw)


def _solver(s) -> str:
    if not isinstance(s, str) or not s:
        raise StudyError(f"study spec: bad solver {s!r}; give a CVXPY solver name, 'fast' or 'limit'")
    return s.lower() if s.lower() in PSEUDO_SOLVERS else s.upper()


def _kinematic(k, where: str) -> str:
    """A kinematic side's name as ``solve`` takes it (``"p1"``, ``"p2"``), or a one-line error."""
    if isinstance(k, str):
        try:
            return Kinematic.parse(k).value
        except CvxdualError:
            pass
    raise StudyError(f"study spec {where}: unknown kinematic side {str(k)[:40]!r}; use \"p2\" (the default) or "
                     "\"p1\", or a list of them")


def _reference(v, levels: list[int], where: str) -> Reference:
    if v is None or v == "exact":
        return Reference("exact")
    if v == "none":
        return Reference("none")
    if isinstance(v, dict):
        bad = set(v) - {"level", "levels_above", "triangulation", "solver", "stress_space"}
        if bad:
            raise StudyError(f"study spec {where}: unknown reference key {sorted(bad)[0]!r}; allowed: level, "
                             "levels_above, triangulation, solver, stress_space")
        if "level" in v:
            level = v["level"]
        else:
            level = max(levels) + int(v.get("levels_above", 2))
        if not isinstance(level, int) or level < 2:
            raise StudyError(f"study spec {where}: reference level must be an integer >= 2 (the error estimate "
                             "uses the two levels below it)")
        if level <= max(levels):
            raise StudyError(f"study spec {where}: reference level {level} is not finer than the studied levels "
                             f"(up to {max(levels)}); raise it")
        tri = v.get("triangulation", "type2")
        if tri not in TRIANGULATIONS:
            raise StudyError(f"study spec {where}: reference triangulation {tri!r}; use type1 or type2")
        space = v.get("stress_space", "p0")
        if space not in SPACE_NAMES:
            raise StudyError(f"study spec {where}: reference stress space {space!r}; use one of "
                             f"{', '.join(SPACE_NAMES)}")
        return Reference("finer", level, tri, _solver(v.get("solver", "fast")), space)
    raise StudyError(f"study spec {where}: reference must be \"exact\", \"none\" or a table {{level = N}}")


def _expand(study: str, d: dict, base: Path, hooks: str | None, where: str) -> list[Case]:
    from ..scene.scenefile import builtin_names
    w = f"{where}" if where else "(top level)"
    scenes = _list(d.get("scenes", []) or [], "scenes", w) if d.get("scenes") else []
    if not scenes:
        raise StudyError(f"study spec {w}: no scenes; give scenes = [\"hertz\", \"my_scene.toml\"]")
    tris = _list(d.get("triangulations", ["type1"]), "triangulations", w)
    for t in tris:
        if t not in TRIANGULATIONS:
            raise StudyError(f"study spec {w}: unknown triangulation {t!r}; use type1 or type2")
    spaces = _list(d.get("stress_spaces", ["p0"]), "stress_spaces", w)
    for s in spaces:
        if s not in SPACE_NAMES:
            raise StudyError(f"study spec {w}: unknown stress space {s!r}; use one of {', '.join(SPACE_NAMES)}")
    kinematics = [_kinematic(k, w) for k in _list(d.get("kinematic", [DEFAULT_KINEMATIC]), "kinematic", w)]
    solvers = [_solver(s) for s in _list(d.get("solvers", ["CLARABEL"]), "solvers", w)]
    metrics = {**METRIC_DEFAULTS, **(d.get("metrics") or {})}
    bad = set(metrics) - set(METRIC_DEFAULTS)
    if bad:
        raise StudyError(f"study spec {w}: unknown metric {sorted(bad)[0]!r}; allowed: {', '.join(METRIC_DEFAULTS)}")
    if metrics["check"] not in get_args(CheckAt):
        raise StudyError(f"study spec {w}: metrics.check must be finest, all or none")
    grid = d.get("set") or {}
    if not isinstance(grid, dict):
        raise StudyError(f"study spec {w}: 'set' must be a table {{\"dotted.key\" = [values]}}")
    opts = d.get("solver_options") or {}
    units = d.get("units")
    if units is not None:
        if not (isinstance(units, (list, tuple)) and len(units) == 4):
            raise StudyError(f"study spec {w}: units = [length factor, stress factor, \"m\", \"Pa\"]")
        units = tuple(units)
    isolate = d.get("isolate", "none")
    if isolate not in get_args(Isolate):
        raise StudyError(f"study spec {w}: isolate must be \"none\" or \"process\"")
    tags = d.get("tags") or {}
    out = []
    for entry in scenes:
        if isinstance(entry, str):
            entry = {"source": entry}
        if not isinstance(entry, dict) or "source" not in entry:
            raise StudyError(f"study spec {w}: a scene is a name, a path or a table with 'source'")
        src = str(entry["source"])
        if src not in builtin_names():
            p = (base / src).resolve()
            if not p.is_file():
                raise StudyError(f"study spec {w}: scene {src!r} is neither a built-in scene "
                                 f"({', '.join(builtin_names())}) nor an existing .toml file")
            src = str(p)
        levels = _list(entry.get("levels", d.get("levels")), "levels", w) if entry.get("levels", d.get("levels")) \
            is not None else None
        if levels is None or not all(isinstance(L, int) and L >= 0 for L in levels):
            raise StudyError(f"study spec {w}: levels must be a list of integers >= 0, e.g. levels = [0, 1, 2]")
        levels = sorted(set(levels))
        ref = _reference(entry.get("reference", d.get("reference")), levels, w)
        sgrid = {**grid, **(entry.get("set") or {})}
        axes = [[(k, v) for v in _list(vals, f"set.{k}", w)] for k, vals in sgrid.items()]
        fixed = _fixed_overrides(d.get("overrides"), w)
        label = entry.get("label")
        for combo in itertools.product(*axes) if axes else [()]:
            over = tuple(fixed) + tuple(combo)
            for tri, space, kin, solver in itertools.product(tris, spaces, kinematics, solvers):
                for level in levels:
                    check_rule = Space.parse(space) is Space.P0 and (metrics["check"] == "all"
                                                    or (metrics["check"] == "finest" and level == max(levels)))
                    out.append(Case(
                        study=study, name=str(d.get("name", "")), group=str(d.get("group", "")),
                        scene_source=src, scene=str(label or ""), overrides=over, units=units,
                        triangulation=tri, stress_space=space, kinematic=kin, level=level, solver=solver,
                        solver_options=tuple(sorted((opts.get(solver) or {}).items())),
                        check=bool(d.get("check", True)), reference=ref, metrics=tuple(sorted(metrics.items())),
                        check_rule=check_rule and ref.kind != "none", save_stress=False, isolate=isolate,
                        timeout=d.get("timeout"), profile=bool(d.get("profile", False)),
                        tags=tuple(sorted(tags.items())), hooks=hooks))
    return out
