"""The package's shape: the folders are the data flow, each layer imports only layers below it
(so there are no import cycles), no module uses another module's private names, public names do
not collide, examples and docs use the public API only, the active-set iteration lives in one
place, and nothing of the package installs software."""

import ast
import collections
import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "cvxdual"

# Layers, lowest first. A unit (a subpackage, or a top-level module) may import units of lower
# layers and its own modules, never a unit of its own layer or above. This is the data flow:
# scene -> reference -> geometry -> linalg -> solution -> convex/activeset -> system -> p0 | eq ->
# adapt -> pipeline -> outputs -> study -> cli. The two stress spaces share one layer: neither imports the other.
LAYERS = [
    {"errors"},
    {"validate", "voigt", "kinds", "records"},  # names of kinds; typed records (no package imports)
    {"files", "progress", "memory"},
    {"scene"},  # what the user describes
    {"reference"},  # closed forms a scene may declare
    {"geometry"},  # meshes and pieces
    {"linalg", "sizing"},
    {"solution"},  # the result type and tolerances of both stress spaces
    {"convex", "activeset"},  # the CVXPY layer and the active-set core, over no stress space
    {"system"},  # the discrete system both spaces share: supports, loads, rigid motions, assembly, P1 displacement
    {"p0", "eq"},  # the two stress spaces, siblings: the paper's P0 and the equilibrium space
    {"adapt"},  # runs to a certified tolerance: marking, grids refined, the cycles
    {"pipeline"},  # the entry points
    {"outputs"},
    {"study"},
    {"cli"},
    {"__main__"},  # python -m cvxdual
]
RANK = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}


def _modules() -> dict[str, pathlib.Path]:
    return {".".join(f.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): f
            for f in PKG.rglob("*.py")}


def _type_checking(node) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _walk(tree):
    """Every node except those under ``if TYPE_CHECKING:`` (annotations only: nothing runs)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        todo.extend(c for c in ast.iter_child_nodes(node) if not _type_checking(c))


def _imports(name: str, path: pathlib.Path, mods) -> list[tuple[str, list[str]]]:
    """``(module, imported names)`` of every package-internal import, at any depth of the file
    (imports inside functions count: they make cycles too)."""
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in _walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            parts = pkg.split(".")
            base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append((sub, []) if sub in mods else (base, [a.name]))
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("cvxdual"):
            out.append((node.module, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names if a.name.startswith("cvxdual")]
    return out


def _graph():
    mods = _modules()
    return {m: _imports(m, f, mods) for m, f in mods.items()}, mods


def _unit(module: str) -> str | None:
    """The layer unit of a module: ``cvxdual.eq.space`` -> ``eq``; None for ``cvxdual`` itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def layering_violations(graph) -> list[str]:
    """``"a -> b"`` for every import of a unit by a unit of the same or a lower layer."""
    bad = []
    for m, imps in graph.items():
        u = _unit(m)
        if u is None:
            continue  # the package's __init__: the public surface, above everything
        for target, _ in imps:
            v = _unit(target)
            if v is None or v == u:
                continue
            if RANK[v] >= RANK[u]:
                bad.append(f"{m} -> {target}")
    return sorted(set(bad))


def test_every_unit_has_a_layer():
    units = {_unit(m) for m in _modules()} - {None}
    assert units <= set(RANK), f"modules with no layer: {sorted(units - set(RANK))}; add them to LAYERS"


def test_layers_import_only_lower_layers():
    graph, _ = _graph()
    assert layering_violations(graph) == []


def test_the_layering_test_catches_an_upward_import():
    """The check itself: a geometry module importing the pipeline, two units of one layer importing
    each other, one stress space importing the other, or the shared system importing a space, is a
    violation."""
    graph, _ = _graph()
    extra = {"cvxdual.geometry.mesh": ("cvxdual.pipeline", ["solve"]),
             "cvxdual.activeset.core": ("cvxdual.convex.base", []),
             "cvxdual.eq.run": ("cvxdual.p0.run", ["solve_p0"]),
             "cvxdual.system.assembly": ("cvxdual.eq.space", ["EquilibriumSpace"])}
    graph = {**graph, **{m: graph[m] + [imp] for m, imp in extra.items()}}
    assert layering_violations(graph) == ["cvxdual.activeset.core -> cvxdual.convex.base",
                                          "cvxdual.eq.run -> cvxdual.p0.run",
                                          "cvxdual.geometry.mesh -> cvxdual.pipeline",
                                          "cvxdual.system.assembly -> cvxdual.eq.space"]


def test_no_import_cycles():
    graph, mods = _graph()
    edges = {m: {t for t, _ in imps if t in mods and t not in (m, "cvxdual")} for m, imps in graph.items()}
    state: dict[str, int] = {}
    cycles = []

    def visit(u, stack):
        state[u] = 1
        stack.append(u)
        for v in sorted(edges[u]):
            if state.get(v) == 1:
                cycles.append(" -> ".join(stack[stack.index(v):] + [v]))
            elif not state.get(v):
                visit(v, stack)
        stack.pop()
        state[u] = 2

    for m in sorted(edges):
        if m != "cvxdual" and not state.get(m):
            visit(m, [])
    assert not cycles


@pytest.mark.slow
@pytest.mark.parametrize("module, forbidden", [
    # the fast paths work on an assembled system or space only
    ("cvxdual.system.displacement", {"cvxdual.geometry.mesh", "cvxdual.geometry.triangulation",
                                     "cvxdual.scene.scenefile", "cvxdual.p0.dual"}),
    ("cvxdual.system.assembly", {"cvxdual.p0.dual", "cvxdual.system.displacement", "cvxdual.p0.run"}),
    # the drawing modules draw on an ax (the files are the output set's, which imports them through
    # figures), each on those before it only: render <- views <- maps <- plots
    *((f"cvxdual.outputs.{m}", {f"cvxdual.outputs.{n}" for n in ("output_set", *above)})
      for m, *above in [("render", "views", "maps", "plots"), ("views", "maps", "plots"), ("maps", "plots"),
                        ("plots",)]),
])
def test_layering_within_units(module, forbidden):
    graph, _ = _graph()
    assert not {t for t, _ in graph[module]} & forbidden


def test_no_private_names_across_modules():
    graph, _ = _graph()
    leaks = [(m, t, n) for m, imps in graph.items() for t, names in imps for n in names
             if n.startswith("_") and t != m]
    assert not leaks


def _top_level_names(path: pathlib.Path) -> set[str]:
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
    return {n for n in names if not n.startswith("_")}


# the same name for the same role in each unit: a parser's entry and the CLI's `main`
SHARED_ROLES = {"main", "add_parser"}


def test_public_functions_and_classes_have_one_home():
    """No two modules define a public function or class of the same name (``residuals`` in two
    places, say): a reader, and an import, would not know which one is meant."""
    homes = collections.defaultdict(list)
    for m, f in _modules().items():
        for n in _top_level_names(f) - SHARED_ROLES:
            homes[n].append(m)
    assert {n: ms for n, ms in homes.items() if len(ms) > 1} == {}


def _docs_code() -> list[tuple[str, str]]:
    """``(where, code)``: every example script and every fenced python block of the docs."""
    out = [(str(p.relative_to(ROOT)), p.read_text()) for p in sorted((ROOT / "examples").glob("*.py"))]
    for p in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for i, block in enumerate(re.findall(r"```python\n(.*?)```", p.read_text(), re.S)):
            out.append((f"{p.relative_to(ROOT)} block {i}", block))
    return out


PUBLIC_MODULES = {"cvxdual", "cvxdual.errors", "cvxdual.scene", "cvxdual.reference", "cvxdual.voigt",
                  "cvxdual.outputs", "cvxdual.study"}


@pytest.mark.parametrize("where, code", _docs_code(), ids=lambda v: v if isinstance(v, str) and len(v) < 60 else "")
def test_examples_and_docs_use_the_public_api(where, code):
    """Examples and documented code import from the public modules only, names in their
    ``__all__``, and use ``cvxdual.NAME`` only for names in ``cvxdual.__all__``."""
    import importlib
    tree = ast.parse(code)
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("cvxdual"):
            if node.module not in PUBLIC_MODULES:
                bad.append(f"from {node.module} import ...")
                continue
            public = set(importlib.import_module(node.module).__all__)
            bad += [f"from {node.module} import {a.name}" for a in node.names if a.name not in public]
        elif isinstance(node, ast.Import):
            bad += [f"import {a.name}" for a in node.names
                    if a.name.startswith("cvxdual") and a.name not in PUBLIC_MODULES]
    import cvxdual
    aliases = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
               if a.name == "cvxdual"}
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            if node.attr not in cvxdual.__all__ and node.attr not in ("__version__",) \
                    and f"cvxdual.{node.attr}" not in PUBLIC_MODULES:
                bad.append(f"cvxdual.{node.attr}")
    assert bad == [], f"{where} uses non-public names"


def test_all_names_exist():
    import importlib
    for m in sorted(PUBLIC_MODULES):
        mod = importlib.import_module(m)
        for n in getattr(mod, "__all__", []):
            assert getattr(mod, n, None) is not None, f"{m}.__all__ names {n!r}, which it lacks"


def test_active_set_iteration_lives_in_the_core():
    """Both fast solvers iterate with :func:`cvxdual.activeset.core.iterate` and complete their sets
    with its ``cover``; no other module has an iteration limit or a cycle test of its own."""
    src = {m: f.read_text() for m, f in _modules().items()}
    for m in ("cvxdual.system.displacement", "cvxdual.eq.active_set"):
        assert re.search(r"from \.\.activeset\.core import .*\biterate\b", src[m]) and "iterate(self" in src[m], m
        assert re.search(r"from \.\.activeset\.core import .*\bcover\b", src[m]), m
    marks = re.compile(r"MAX_ITER\s*=|\bseen\.add\(|active set cycles|tobytes\(\) in seen")
    assert sorted(m for m, s in src.items() if marks.search(s)) == ["cvxdual.activeset.core"]


def test_the_package_installs_nothing():
    """No module of the package runs pip or another installer (peer benchmarks that do live in
    studies/, outside the wheel)."""
    pattern = re.compile(r"""["']-m["']\s*,\s*["'](pip|ensurepip|venv)["']"""
                         r"""|["'](pip|pip3|uv|conda)["']\s*,\s*["']install""")
    assert [m for m, f in _modules().items() if pattern.search(f.read_text())] == []


@pytest.mark.slow
@pytest.mark.parametrize("plots", [False, True])
def test_fast_cli_run_imports_no_heavy_library_it_does_not_use(tmp_path, plots):
    """`cvxdual solve --solver fast` never loads CVXPY, pandas or Dask (0.3 s, 0.2 s and more of
    start-up), and matplotlib only to draw; checked in a fresh interpreter, where nothing else
    can have loaded them."""
    import subprocess
    import sys
    argv = ["solve", "--level", "0", "--solver", "fast", "--out", str(tmp_path / "o")] + (["--plots"] if plots else
                                                                                      [])
    code = (f"import sys; from cvxdual.cli import main; assert main({argv!r}) == 0; "
            "print(sorted(m for m in ('cvxpy', 'pandas', 'dask', 'matplotlib', 'scipy.optimize') if m in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == ("['matplotlib']" if plots else "[]")
