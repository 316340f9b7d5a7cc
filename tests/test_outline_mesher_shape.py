"""The outline mesher's shape (cvxdual.geometry.outline): no function or method over 60 lines, so
its main function reads as its steps and each step fits on a screen."""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUTLINE = ROOT / "cvxdual" / "geometry" / "outline"
MAX_LINES = 60


def long_functions(source: str, where: str = "<source>", limit: int = MAX_LINES) -> list[str]:
    """``"where:name (n lines)"`` for every function or method of ``source`` longer than ``limit``
    lines, from its ``def`` line to the last line of its body (decorators excluded)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            n = node.end_lineno - node.lineno + 1
            if n > limit:
                out.append(f"{where}:{node.name} ({n} lines)")
    return out


def test_no_function_of_the_outline_mesher_is_over_60_lines():
    files = sorted(OUTLINE.glob("*.py"))
    assert len(files) >= 8  # the subpackage is where this test looks
    found = [f for p in files for f in long_functions(p.read_text(), p.name)]
    assert found == [], f"functions over {MAX_LINES} lines: {found}"


def _function(name: str, n_lines: int, indent: str = "") -> str:
    """The source of function ``name`` of ``n_lines`` lines: its def, then ``n_lines - 1`` of body."""
    return f"{indent}def {name}():\n" + "".join(f"{indent}    x{i} = {i}\n" for i in range(n_lines - 1))


def test_the_check_catches_a_61_line_function():
    """A function of 61 lines, a method of 61 and a nested function of 61 (in one of 62) are
    caught; one of 60 lines is not, whatever decorators stand above its def."""
    source = (_function("long", 61) + "@staticmethod\n@property\n" + _function("fits", 60)
              + "class C:\n" + _function("method", 61, "    ") + "def outer():\n" + _function("inner", 61, "    "))
    assert sorted(long_functions(source)) == ["<source>:inner (61 lines)", "<source>:long (61 lines)",
                                              "<source>:method (61 lines)", "<source>:outer (62 lines)"]
    assert long_functions(_function("fits", 60)) == []
