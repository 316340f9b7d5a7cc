"""The package's shape: data flows one way (no import cycles), the fast path works on an
assembled system only, and no module uses another module's private names."""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1] / "cvxdual"


def _modules() -> dict[str, pathlib.Path]:
    return {".".join(f.relative_to(ROOT.parent).with_suffix("").parts).removesuffix(".__init__"): f
            for f in ROOT.rglob("*.py")}


def _imports(name: str, path: pathlib.Path, mods) -> list[tuple[str, list[str]]]:
    """``(module, imported names)`` of every package-internal import, at any depth of the file
    (imports inside functions count: they make cycles too)."""
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            parts = pkg.split(".")
            base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append((sub, []) if sub in mods else (base, [a.name]))
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("cvxdual"):
            out.append((node.module, [a.name for a in node.names]))
    return out


def _graph():
    mods = _modules()
    return {m: _imports(m, f, mods) for m, f in mods.items()}, mods


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


@pytest.mark.parametrize("module, forbidden", [
    ("cvxdual.p0.fast", {"cvxdual.geometry.mesh", "cvxdual.geometry.triangulation", "cvxdual.scene.scenefile", "cvxdual.p0.dual"}),
    ("cvxdual.p0.assembly", {"cvxdual.p0.dual", "cvxdual.p0.fast", "cvxdual.pipeline"}),
    ("cvxdual.outputs.plots", {"cvxdual.outputs.output_set"}),
])
def test_layering(module, forbidden):
    graph, _ = _graph()
    assert not {t for t, _ in graph[module]} & forbidden


def test_no_private_names_across_modules():
    graph, _ = _graph()
    leaks = [(m, t, n) for m, imps in graph.items() for t, names in imps for n in names
             if n.startswith("_") and t != m]
    assert not leaks


@pytest.mark.parametrize("plots", [False, True])
def test_fast_cli_run_imports_no_heavy_library_it_does_not_use(tmp_path, plots):
    """`cvxdual solve --solver fast` never loads CVXPY, pandas or Dask (0.3 s, 0.2 s and more of
    start-up), and matplotlib only to draw; checked in a fresh interpreter, where nothing else
    can have loaded them."""
    import subprocess
    import sys
    argv = ["solve", "--level", "0", "--solver", "fast", "--out", str(tmp_path / "o")] + ([] if plots else
                                                                                      ["--no-plots"])
    code = (f"import sys; from cvxdual.cli import main; assert main({argv!r}) == 0; "
            "print(sorted(m for m in ('cvxpy', 'pandas', 'dask', 'matplotlib', 'scipy.optimize') if m in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == ("['matplotlib']" if plots else "[]")
