"""The part of gmsh's ``.geo`` language that draws a plane outline, read in Python: nothing in the
file is executed (docs/scenes.md#outlines-from-gmsh-geo-files).

gmsh's own reader runs a scripting language: ``System`` runs programs, ``Printf(...) > "f"`` and
``Save`` write files, ``Include`` and ``Merge`` read any file, ``For`` loops and ``Sleep`` run as
long as asked, ``Exit`` ends the process. A scene (and its ``.geo``) may come from anyone, so the
file is read here instead, as an allow-list: variables and arithmetic, points, curves, curve
loops, plane surfaces and physical groups. Any other statement, function or operator is refused
in one line naming it, before anything after it is read. The work is bounded by the file's size
(the caller's cap), :data:`MAX_STATEMENTS` and :data:`MAX_NESTING`; a read keeps no state.
"""

from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass, field

from ..errors import SceneError
from ..validate import HUGE, one_line, short

MAX_STATEMENTS = 10_000  # far above any outline (a few hundred statements); bounds the work
MAX_NESTING = 50  # parentheses in one expression: the parser recurses once per level
MAX_TAG = 2**31 - 1  # gmsh's tags are C ints
CURVES = ("Line", "Circle", "Spline", "BSpline", "Bezier")
ALLOWED = ("it may hold only variables (x = ...;), Point, Line, Circle, Spline, BSpline, Bezier, Curve Loop, "
           "Plane Surface and Physical Curve/Surface statements (docs/scenes.md)")
# gmsh's functions, spelled as gmsh spells them: (number of arguments, value); Round and Hypot as gmsh computes them
FUNCTIONS = {
    "Sqrt": (1, math.sqrt), "Sin": (1, math.sin), "Cos": (1, math.cos), "Tan": (1, math.tan),
    "Asin": (1, math.asin), "Acos": (1, math.acos), "Atan": (1, math.atan), "Atan2": (2, math.atan2),
    "Fabs": (1, abs), "Abs": (1, abs), "Exp": (1, math.exp), "Log": (1, math.log), "Log10": (1, math.log10),
    "Floor": (1, lambda x: float(math.floor(x))), "Ceil": (1, lambda x: float(math.ceil(x))),
    "Round": (1, lambda x: float(math.floor(x + 0.5))), "Hypot": (2, lambda a, b: math.sqrt(a * a + b * b)),
    "Min": (2, min), "Max": (2, max)}
# statements that set element sizes or steer gmsh's mesher: cvxdual sizes the mesh itself (one family of
# meshes that halves a level, so that --level means the same on every body), so they are refused with
# the [mesh] keys that do it instead; the size after a Point's z is accepted and not read (docs/scenes.md)
MESHING = {"Mesh", "Characteristic", "MeshSize", "Field", "Background", "Transfinite", "Recombine"}
SIZES = ("cvxdual sizes the mesh itself, halving it a level: set the sizes with [mesh] columns, focus and grading, "
         "and the level (docs/scenes.md)")
EXPRESSIONS = ("expressions take numbers, variables, Pi, newp, newl, + - * / % ^, parentheses and "
               + ", ".join(FUNCTIONS) + " (docs/scenes.md)")
# statement words (and commands a variable must not be named after, so that refusals name them)
KEYWORDS = {"Point", "Line", "Circle", "Spline", "BSpline", "Bezier", "Curve", "Loop", "Plane", "Surface", "Physical",
            "Pi", "newp", "newl", "newc", "System", "SystemCall", "NonBlockingSystemCall", "OnelabRun", "Printf",
            "Save", "CreateDir", "Include", "Merge", "GetEnv", "For", "Sleep", "Exit", "Macro", "Call", "If",
            "SetFactory", "Extrude", "Delete"} | MESHING | set(FUNCTIONS)
VALUES = {"Pi", "newp", "newl", "newc"} | set(FUNCTIONS)  # names with a value of their own
OPERATORS = set("+-*/%^(){},=")

_TOKEN = re.compile(r"""
    (?P<skip>[ \t\r\f\v]+|//[^\n]*|/\*.*?\*/)
  | (?P<nl>\n)
  | (?P<str>"(?:\\.|[^"\\\n])*")
  | (?P<num>(?:\d+\.\d*|\.\d+)(?:[eE][-+]?\d+)?|\d+(?:[eE][-+]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<open>/\*|")
  | (?P<op>.)""", re.VERBOSE | re.DOTALL | re.ASCII)


@dataclass
class GeoFile:
    """What a ``.geo`` outline defines: points ``{tag: (x, y)}``, curves ``{tag: (kind, point
    tags, line)}`` and physical curves ``[(tag, name or None, curve tags, line)]`` in file order."""

    points: dict[int, tuple[float, float]] = field(default_factory=dict)
    curves: dict[int, tuple[str, tuple[int, ...], int]] = field(default_factory=dict)
    physicals: list[tuple[int, str | None, tuple[int, ...], int]] = field(default_factory=list)


def parse_geo(text: str, where: str) -> GeoFile:
    """The points, curves and physical curves of ``text``, or a :class:`SceneError` (one line)."""
    return _Reader(text, where).read()


class _Reader:
    def __init__(self, text: str, where: str):
        self.text, self.where = text, where
        self.geo = GeoFile()
        self.vars: dict[str, float] = {}
        self.loops: set[int] = set()
        self.surfaces: set[int] = set()
        self.named: dict[str, int] = {}  # physical curve names and tags
        self.tags: set[int] = set()
        self.max_physical = 0  # gmsh's counter of physical tags (all dimensions): it numbers named groups

    def fail(self, line: int, msg: str):
        raise SceneError(f"{self.where}.geo: line {line}: {msg}")

    def refuse(self, line: int, what: str, advice: str = ALLOWED):
        self.fail(line, f"{short(what, 40)} is not allowed in a .geo outline; {advice}")

    def read(self) -> GeoFile:
        toks: list[tuple[str, str, int]] = []
        start, count, head = 0, 0, None
        for kind, tok, line, pos in self._tokens():
            if kind == "op" and tok == ";":
                if toks:
                    count += 1
                    if count > MAX_STATEMENTS:
                        self.fail(line, f"more than {MAX_STATEMENTS} statements; draw the outline with fewer curves")
                    self._statement(head or self._head(toks), toks, one_line(self.text[start:pos], 60))
                toks, head = [], None
                continue
            if not toks:
                start = pos
            toks.append((kind, tok, line))
            if len(toks) == 3:  # every allowed statement shows itself in 3 tokens: refuse others before reading on
                head = self._head(toks)
        if toks:
            self.fail(toks[0][2], f"cannot read {short(one_line(self.text[start:], 60))}: it ends without ';'; "
                                  "end every statement with ';'")
        return self.geo

    def _tokens(self):
        pos, line, text = 0, 1, self.text
        while pos < len(text):
            m = _TOKEN.match(text, pos)
            kind, tok = m.lastgroup, m.group()
            if kind == "open":
                self.fail(line, "a /* comment is not closed; close it with */" if tok == "/*" else
                          "a string is not closed; close it with a quote on the same line")
            if kind in ("str", "num", "name", "op"):
                yield kind, tok, line, pos
            line += tok.count("\n")
            pos = m.end()

    def _head(self, toks) -> str:
        """The kind of statement the first tokens start, or a refusal naming it."""
        words = [t if k == "name" else None for k, t, _ in toks[:3]]
        ops = [t if k == "op" else None for k, t, _ in toks[:3]] + [None] * 3
        line = toks[0][2]
        w0, w1 = words[0], (words + [None])[1]
        if w0 is not None and ops[1] == "=" and w0 not in KEYWORDS:
            return "assign"
        if ops[1] == "=" and w0 in VALUES:
            self.fail(line, f"{w0!r} is a name of the .geo language, not a variable; name the variable otherwise")
        if w0 in ("Point", *CURVES) and ops[1] == "(":
            return w0
        if (w0, w1) in (("Curve", "Loop"), ("Line", "Loop")) and ops[2] == "(":
            return "loop"
        if (w0, w1) == ("Plane", "Surface") and ops[2] == "(":
            return "surface"
        if w0 == "Physical" and w1 in ("Curve", "Line", "Surface") and ops[2] == "(":
            return "physical"
        if w0 is None:
            self.fail(line, f"cannot read a statement that starts with {toks[0][1]!r}; {ALLOWED}")
        sizes = w0 in MESHING
        if ops[1] == "." and words[2]:  # an option, e.g. Mesh.Algorithm
            w0 = f"{w0}.{words[2]}"
        elif w1 and w0 in ("Physical", "Plane", "Curve", "Line", "Surface", "Transfinite", "Recombine",
                           "Characteristic", "Background"):
            w0 = f"{w0} {w1}"
        elif ops[1] not in (None, "(") and (w0 not in KEYWORDS or w0 in ("Point", *CURVES)):  # x[], x +=, Point{
            w0 = f"{w0}{ops[1]}" + ("=" if ops[2] == "=" else "")
        self.refuse(line, w0, SIZES if sizes else ALLOWED)
        return ""

    def _statement(self, head: str, toks, src: str) -> None:
        c = _Cursor(self, toks, src)
        line = toks[0][2]
        if head == "assign":
            c.i = 2
            self.vars[toks[0][1]] = c.expr()
            c.end()
            return
        c.i = 1 if head in ("Point", *CURVES) else 2
        if head == "physical":
            self._physical(c, toks[1][1] == "Surface")
            return
        c.expect("(")
        tag = c.tag(c.expr(), "tag")
        c.expect(")")
        c.expect("=")
        values = c.values()
        c.end()
        if head == "Point":
            if len(values) not in (3, 4):
                self.fail(line, f"Point({tag}) has {len(values)} values; give {{x, y, 0}} or {{x, y, 0, size}}")
            if values[2] != 0.0:
                self.fail(line, f"Point({tag}) has z = {values[2]:g}; an outline is drawn in the plane z = 0")
            big = next((v for v in values[:2] if abs(v) > HUGE), None)
            if big is not None:
                self.fail(line, f"Point({tag}) has a coordinate {big:g}, beyond {HUGE:g}; give lengths in a unit "
                                "that keeps the coordinates moderate")
            self._new(self.geo.points, tag, line, "Point")
            self.geo.points[tag] = (values[0], values[1])
        elif head in CURVES:
            pts = tuple(c.tag(v, "point") for v in values)
            want = {"Line": 2, "Circle": 3}.get(head)
            if (want and len(pts) != want) or len(pts) < 2:
                need = {"Line": "{start, end}", "Circle": "{start, center, end}"}.get(head, "at least 2 points")
                self.fail(line, f"{head}({tag}) has {len(pts)} points; give {need}")
            missing = next((p for p in pts if p not in self.geo.points), None)
            if missing is not None:
                self.fail(line, f"{head}({tag}) uses point {missing}, which is not defined before; define it first")
            self._new(self.geo.curves, tag, line, "curve")
            self.geo.curves[tag] = (head, pts, line)
        elif head == "loop":
            for v in values:  # -n: curve n run backwards
                if c.tag(abs(v), "curve") not in self.geo.curves:
                    self.fail(line, f"Curve Loop({tag}) uses curve {abs(v):g}, which is not defined before; "
                                    "define it first")
            self._new(self.loops, tag, line, "curve loop")
            self.loops.add(tag)
        else:
            for v in values:
                if c.tag(v, "curve loop") not in self.loops:
                    self.fail(line, f"Plane Surface({tag}) uses curve loop {v:g}, which is not defined before; "
                                    "define it first")
            self._new(self.surfaces, tag, line, "surface")
            self.surfaces.add(tag)

    def _new(self, existing, tag: int, line: int, what: str) -> None:
        if tag in existing:
            self.fail(line, f"{what} {tag} is defined twice; give each {what} its own tag")

    def _physical(self, c: _Cursor, surface: bool) -> None:
        line = c.toks[0][2]
        c.expect("(")
        name, tag = None, None
        if c.peek() == "str":
            name = c.next()[1][1:-1] or None  # "" names nothing, as in gmsh
            if c.accept(","):
                tag = c.tag(c.expr(), "physical tag")
        else:
            tag = c.tag(c.expr(), "physical tag")
        c.expect(")")
        c.expect("=")
        values = c.values()
        c.end()
        if tag is None:  # gmsh numbers a named group one past the largest physical tag so far
            self.max_physical += 1
            tag = self.max_physical
        self.max_physical = max(self.max_physical, tag)
        if surface:
            return  # the body is the region its curves bound: surfaces add nothing
        if (name is not None and name in self.named) or tag in self.tags:
            what = f"physical curve {name!r}" if name in self.named else f"physical curve tag {tag}"
            self.fail(line, f"{what} is given twice; list all its curves in one Physical Curve statement")
        curves = tuple(c.tag(abs(v), "curve") for v in values)  # gmsh takes -n for n in a physical group
        self.tags.add(tag)
        if name is not None:
            self.named[name] = tag
        self.geo.physicals.append((tag, name, curves, line))


class _Cursor:
    """One statement's tokens, parsed and evaluated from left to right."""

    def __init__(self, reader: _Reader, toks, src: str):
        self.r, self.toks, self.src, self.i = reader, toks, src, 0
        self.depth = 0

    def peek(self):
        return self.toks[self.i][0] if self.i < len(self.toks) else None

    def next(self):
        if self.i >= len(self.toks):
            self.fail("it ends too early")
        self.i += 1
        return self.toks[self.i - 1]

    def accept(self, op: str) -> bool:
        if self.i < len(self.toks) and self.toks[self.i][:2] == ("op", op):
            self.i += 1
            return True
        return False

    def expect(self, op: str) -> None:
        if not self.accept(op):
            self.unexpected(f"expected {op!r}")

    def end(self) -> None:
        if self.i < len(self.toks):
            self.unexpected("expected ';'")

    def unexpected(self, why: str):
        if self.i >= len(self.toks):
            self.fail(f"{why}, got the end")
        kind, tok, line = self.toks[self.i]
        if kind == "op" and tok not in OPERATORS:  # ranges a:b, comparisons, lists x[], options a.b, ...
            self.r.refuse(line, tok, "list every tag, e.g. {1, 2, 3} (ranges a:b are not read)" if tok == ":"
                          else EXPRESSIONS)
        self.fail(f"{why}, got {tok!r}")

    def fail(self, why: str):
        self.r.fail(self.line(), f"cannot read {short(self.src)}: {why}; fix it (docs/scenes.md)")

    def line(self) -> int:
        return self.toks[min(self.i, len(self.toks) - 1)][2]

    def tag(self, v: float, what: str) -> int:
        if v != int(v) or not 1 <= v <= MAX_TAG:
            self.r.fail(self.line(), f"{what} {v:g} in {short(self.src)} is not a tag; tags are whole numbers from 1 "
                                     f"to {MAX_TAG}")
        return int(v)

    def values(self) -> list[float]:
        """``{e, e, ...}``: the values of a list of expressions."""
        self.expect("{")
        out: list[float] = []
        if self.accept("}"):
            return out
        while True:
            out.append(self.expr())
            if self.accept("}"):
                return out
            self.expect(",")

    # expressions, with gmsh's precedence: + - below * / %, below unary minus, below ^ (right-associative)
    def expr(self) -> float:
        v = self.term()
        while self.peek() == "op" and self.toks[self.i][1] in "+-":
            add = self.next()[1] == "+"
            v = self.finite(operator.add if add else operator.sub, v, self.term())
        return v

    def term(self) -> float:
        v = self.unary()
        while self.peek() == "op" and self.toks[self.i][1] in "*/%":
            op = self.next()[1]
            v = self.finite({"*": operator.mul, "/": operator.truediv, "%": _mod}[op], v, self.unary())
        return v

    def unary(self) -> float:
        """``-a ^ -b ^ c`` = ``-(a ^ (-(b ^ c)))``, read in a loop (no recursion per sign or power)."""
        signs, atoms = [], []
        while True:
            sign = 1.0
            while self.peek() == "op" and self.toks[self.i][1] in "+-":
                sign = -sign if self.next()[1] == "-" else sign
            signs.append(sign)
            atoms.append(self.atom())
            if not self.accept("^"):
                break
        v = signs[-1] * atoms[-1]
        for sign, a in zip(signs[-2::-1], atoms[-2::-1], strict=True):
            v = sign * self.finite(math.pow, a, v)
        return v

    def nested(self, line: int) -> float:
        """An expression inside parentheses: the one recursion, bounded."""
        self.depth += 1
        if self.depth > MAX_NESTING:
            self.r.fail(line, f"parentheses nested deeper than {MAX_NESTING}; simplify the expression")
        v = self.expr()
        self.depth -= 1
        return v

    def atom(self) -> float:
        kind, tok, line = self.next()
        if kind == "num":
            return self.finite(float, tok)
        if kind == "op" and tok == "(":
            v = self.nested(line)
            self.expect(")")
            return v
        if kind != "name":
            self.i -= 1
            self.unexpected("expected a number, a variable or '('")
        follows = self.toks[self.i][1] if self.i < len(self.toks) else None
        if tok in FUNCTIONS and follows == "(":
            n, f = FUNCTIONS[tok]
            self.next()
            args = [self.nested(line)]
            while len(args) < n and self.accept(","):
                args.append(self.nested(line))
            self.expect(")")
            if len(args) != n:
                self.fail(f"{tok} takes {n} argument{'s' * (n > 1)}")
            return self.finite(f, *args)
        if follows in ("(", ".", "[", "#", "~", "{") or tok in KEYWORDS - VALUES:
            self.r.refuse(line, tok if follows != "." else f"{tok}.", EXPRESSIONS)
        geo = self.r.geo
        if tok == "Pi":
            return math.pi
        if tok in ("newp", "newl", "newc"):  # one past the largest tag of a point, a curve
            return float(max(geo.points if tok == "newp" else geo.curves, default=0) + 1)
        if tok in FUNCTIONS:
            self.fail(f"{tok} takes its argument{'s' * (FUNCTIONS[tok][0] > 1)} in parentheses")
        if tok not in self.r.vars:
            self.r.fail(line, f"unknown variable {tok!r} in {short(self.src)}; define it on an earlier line "
                              f"({tok} = ...;)")
        return self.r.vars[tok]

    def finite(self, f, *args) -> float:
        try:
            v = float(f(*args))
            if not math.isfinite(v):
                raise ValueError
        except (ArithmeticError, ValueError):  # overflow, division by zero, outside the domain, inf, nan
            self.r.fail(self.line(), f"{short(self.src)} is not a finite number (an overflow, a division by zero or "
                                     "a function outside its domain); fix the expression")
        return v


def _mod(a: float, b: float) -> float:
    """gmsh's ``a % b``: the C remainder of the integer parts."""
    ia, ib = int(a), int(b)
    if ib == 0 or max(abs(ia), abs(ib)) > MAX_TAG:
        raise ValueError
    return math.fmod(ia, ib)
