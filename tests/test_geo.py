"""``.geo`` outlines are read by cvxdual's own reader of a small part of gmsh's language
(cvxdual.scene.geo_lang): nothing in the file runs, every other statement is refused in one line,
paths stay in the scene's folder, and the curves (splines too) are gmsh's."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import GEO_SCENE, without_progress

from cvxdual.cli import main
from cvxdual.errors import SceneError
from cvxdual.scene import load_scene
from cvxdual.scene.geo import MAX_BYTES, U, read_geo
from cvxdual.scene.geo_lang import MAX_STATEMENTS, parse_geo
from cvxdual.scene.profiles import LowerCircle, UpperCircle

ROOT = Path(__file__).resolve().parents[1]
BLOCK = """// the lower block of the block-with-hole scene, without its hole
Point(1) = {10, 0, 0}; Point(2) = {10, -20, 0}; Point(3) = {-10, -20, 0}; Point(4) = {-10, 0, 0};
Line(1) = {4, 1}; Line(2) = {1, 2}; Line(3) = {2, 3}; Line(4) = {3, 4};
"""
NAMES = """Physical Curve("face") = {1}; Physical Curve("right") = {2}; Physical Curve("bottom") = {3};
Physical Curve("left") = {4};
"""
SCENE = GEO_SCENE
FAST = 1.0  # seconds: a refusal reads a few statements (milliseconds); a loop, a sleep or /dev/zero would not end


def refused(tmp_path, monkeypatch, capsys, geo: str | None, words: str, scene: str = SCENE,
            argv: tuple[str, ...] = ()) -> str:
    """``cvxdual solve --scene bad.toml`` (in ``tmp_path``) exits 1 with one error line holding
    ``words``, fast, creating nothing; returns the line."""
    monkeypatch.chdir(tmp_path)
    if geo is not None:
        (tmp_path / "b.geo").write_text(geo)
    (tmp_path / "bad.toml").write_text(scene)
    before = set(tmp_path.rglob("*"))
    t0 = time.perf_counter()
    rc = main(["solve", "--scene", "bad.toml", "--level", "0", "--no-plots", *argv])
    took = time.perf_counter() - t0
    err = without_progress(capsys.readouterr().err)
    assert rc == 1
    assert len(err) == 1 and err[0].startswith("cvxdual: error:") and words in err[0], err
    assert len(err[0]) < 300 + len("cvxdual: error: "), err  # one readable line
    assert set(tmp_path.rglob("*")) == before
    assert took < FAST, took
    return err[0]


# -- nothing runs: every statement outside the allow-list is refused, naming it and its line --------

FORBIDDEN = [  # (statement, the name the refusal gives)
    ('System "touch {marker}";', "System"),
    ('SystemCall "touch {marker}";', "SystemCall"),
    ('NonBlockingSystemCall "touch {marker}";', "NonBlockingSystemCall"),
    ('OnelabRun("x", "touch {marker}");', "OnelabRun"),
    ('Printf("x") > "{marker}";', "Printf"),
    ('Save "{marker}";', "Save"),
    ('CreateDir "{marker}";', "CreateDir"),
    ('Include "/dev/zero";', "Include"),
    ('Merge "{marker}.geo";', "Merge"),
    ('For i In {{1:1e15}} Printf("x"); EndFor', "For"),
    ("Sleep 1e9;", "Sleep"),
    ("Exit;", "Exit"),
    ('Macro M Printf("x"); Return', "Macro"),
    ("Call M;", "Call"),
    ("If (1) Exit; EndIf", "If"),
    ("Mesh.CharacteristicLengthMax = 1;", "Mesh.CharacteristicLengthMax"),
    ('SetFactory("OpenCASCADE");', "SetFactory"),
    ("Extrude {{0, 0, 1}} {{ Curve{{1}}; }}", "Extrude"),
    ("Physical Volume(1) = {{1}};", "Physical Volume"),
    ('Physical Curve("many") = {{1:1e15}};', ":"),
    ("x[] = {{1, 2}};", "x["),
    ("x = 1; x += 1;", "x+="),
    ("x = 1 > 0;", ">"),
    ("Point{{1}} In Surface{{1}};", "Point{"),
]


@pytest.mark.parametrize("statement,name", FORBIDDEN, ids=[n for _, n in FORBIDDEN])
def test_forbidden_statements_are_refused_unrun(tmp_path, monkeypatch, capsys, statement, name):
    marker = tmp_path / "marker"
    line = refused(tmp_path, monkeypatch, capsys, BLOCK + statement.format(marker=marker) + "\n" + NAMES,
                   f"bodies.bottom.geo: line 4: {name!r} is not allowed in a .geo outline;")
    advice = line.split("is not allowed in a .geo outline; ")[1]  # what a .geo outline (or a list) may hold
    assert any(w in advice for w in ("Physical Curve", "expressions take", "list every tag", "[mesh]")), advice
    assert not marker.exists() and not Path(f"{marker}.geo").exists()


@pytest.mark.parametrize("expr", ['GetEnv("CVXDUAL_SECRET")', 'StrCat(GetEnv("CVXDUAL_SECRET"))'])
def test_environment_is_not_read(tmp_path, monkeypatch, capsys, expr):
    monkeypatch.setenv("CVXDUAL_SECRET", "s3cr3t-value")
    line = refused(tmp_path, monkeypatch, capsys, BLOCK + f"Point(9) = {{{expr}, 0, 0}};\n" + NAMES,
                   "line 4: ")
    assert "is not allowed in a .geo outline" in line and "s3cr3t" not in line


def test_work_is_bounded(tmp_path):
    for text, words in [("x = 1;\n" * (MAX_STATEMENTS + 1), f"more than {MAX_STATEMENTS} statements"),
                        ("x = " + "(" * 10_000 + "1" + ")" * 10_000 + ";", "nested deeper"),
                        ("x = " + "Sqrt(" * 10_000 + "1" + ")" * 10_000 + ";", "nested deeper"),
                        ("/* never closed\n" + "x = 1;\n" * 1000, "not closed"),
                        ('Physical Curve("face) = {1};', "not closed")]:
        t0 = time.perf_counter()
        with pytest.raises(SceneError, match=words):
            parse_geo(text, "b")
        assert time.perf_counter() - t0 < FAST
    big = tmp_path / "big.geo"
    big.write_text("// " + "x" * MAX_BYTES + "\n")
    with pytest.raises(SceneError, match="larger than"):
        read_geo(big, "lower", "b")
    # signs and powers are read in a loop: long chains need no deep recursion
    assert parse_geo("x = " + "-" * 20_001 + "2^" * 3 + "1;", "b").points == {}


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_fifo_and_bad_bytes_are_refused(tmp_path):
    os.mkfifo(tmp_path / "pipe.geo")
    t0 = time.perf_counter()
    with pytest.raises(SceneError, match="not a regular file"):  # opened without waiting for a writer
        read_geo(tmp_path / "pipe.geo", "lower", "b")
    assert time.perf_counter() - t0 < FAST
    (tmp_path / "u.geo").write_bytes(BLOCK.encode() + b"x = \xff;\n")
    with pytest.raises(SceneError, match="line 4: byte 0xff is not UTF-8"):
        read_geo(tmp_path / "u.geo", "lower", "b")


# -- the path rule: a .geo file in the scene file's folder ------------------------------------------

@pytest.mark.parametrize("suffix", [".msh", ".step", ".brep", ".stl", ".txt", ""])
def test_only_geo_files_are_read(tmp_path, monkeypatch, capsys, suffix):
    (tmp_path / f"b{suffix}").write_text(BLOCK + NAMES)
    refused(tmp_path, monkeypatch, capsys, None, "is not a .geo file",
            SCENE.replace('geo = "b.geo"', f'geo = "b{suffix}"'))


def _outside(tmp_path) -> Path:
    out = tmp_path.parent / f"{tmp_path.name}-outside"
    out.mkdir(exist_ok=True)
    (out / "x.geo").write_text(BLOCK + NAMES)
    return out / "x.geo"


@pytest.mark.parametrize("how", ["absolute", "dotdot", "symlink", "set"])
def test_geo_outside_the_scene_folder_is_refused(tmp_path, monkeypatch, capsys, how):
    x = _outside(tmp_path)
    ref = {"absolute": str(x), "dotdot": f"../{x.parent.name}/x.geo", "symlink": "link.geo", "set": "b.geo"}[how]
    if how == "symlink":
        (tmp_path / "link.geo").symlink_to(x)
    argv = ("--set", f"bodies.bottom.geo={json.dumps(str(x))}") if how == "set" else ()
    if how == "set":
        (tmp_path / "b.geo").write_text(BLOCK + NAMES)
    refused(tmp_path, monkeypatch, capsys, None, "is outside the", SCENE.replace('"b.geo"', json.dumps(ref)), argv)


def test_geo_inside_the_scene_folder_is_read(tmp_path, monkeypatch):
    """Relative to the scene file (not the working directory), an absolute path inside its
    folder, a link inside it, a folder below it."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.geo").write_text(BLOCK + NAMES)
    (tmp_path / "link.geo").symlink_to(tmp_path / "sub" / "b.geo")
    monkeypatch.chdir(tmp_path.parent)
    bodies = []
    for ref in ["sub/b.geo", str(tmp_path / "sub" / "b.geo"), "link.geo", "sub/../link.geo"]:
        (tmp_path / "s.toml").write_text(SCENE.replace('"b.geo"', json.dumps(ref)))
        bodies.append(load_scene(str(tmp_path / "s.toml")).bodies[1])
    assert all(b.outline == bodies[0].outline and b.face == bodies[0].face for b in bodies)


def test_directory_and_missing_geo_are_refused(tmp_path, monkeypatch, capsys):
    (tmp_path / "d.geo").mkdir()
    refused(tmp_path, monkeypatch, capsys, None, "is not a regular file", SCENE.replace('"b.geo"', '"d.geo"'))
    refused(tmp_path, monkeypatch, capsys, None, "no file 'none.geo'", SCENE.replace('"b.geo"', '"none.geo"'))


# -- the language: values as gmsh computes them ------------------------------------------------------

def test_arithmetic_and_variables():
    geo = parse_geo("""
        a = 2^3^2; b = -2^2; c = 7 % 3; d = -7 % 3; e = Round(-2.5); f = Hypot(3, 4) /* 5 */;
        g = Atan2(1, 1) * 4 - Pi; h = 1e3 + .5 + 5. + 2E-1; i = 2^-1*3; j = Max(Min(1, 2), Fabs(-0.5));
        k = Floor(-1.5) + Ceil(1.2) + Abs(-1) + Sqrt(16) + Exp(0) + Log(1) + Sin(0) + Cos(0) + Tan(0);
        Point(newp) = {a, b, 0}; Point(newp) = {c, d, 0}; Point(newp) = {e, f, 0, 0.1};
        Point(4) = {g, h, 0}; Point(newp) = {i, j, 0}; Point(10 * 2) = {k, Asin(1) + Acos(1) + Atan(0), 0};
        """, "b")
    assert geo.points == {1: (512.0, -4.0), 2: (1.0, -1.0), 3: (-2.0, 5.0), 4: (0.0, 1005.7), 5: (1.5, 1.0),
                          20: (7.0, np.pi / 2)}


@pytest.mark.parametrize("expr", ["1/0", "Exp(1000)", "Sqrt(-1)", "2^1e10", "1e999", "Log(0)", "1e200 * 1e200",
                                  "(-8)^(1/3)", "Acos(2)", "1 % 0"])
def test_non_finite_values_are_refused(expr):
    with pytest.raises(SceneError, match=r"line 2: .* is not a finite number"):
        parse_geo(f"x = 1;\ny = {expr};", "b")


@pytest.mark.parametrize("text,words", [
    ("x = y;", "unknown variable 'y'"),
    ("Pi = 3;", "'Pi' is a name of the .geo language"),
    ("Point(1) = {0, 0, 1};", "z = 1; an outline is drawn in the plane z = 0"),
    ("Point(1) = {1e150, 0, 0};", "coordinate 1e+150, beyond 1e+100"),
    ("Point(1.5) = {0, 0, 0};", "tag 1.5"),
    ("Point(1) = {0, 0, 0}; Point(1) = {1, 0, 0};", "Point 1 is defined twice"),
    ("Point(1) = {0, 0, 0}; Line(1) = {1, 2};", "uses point 2, which is not defined"),
    ("Point(1) = {0, 0};", "has 2 values"),
    ("Point(1) = {10, 0", "cannot read"),
    ('Physical Curve("a") = {}; Physical Curve("a") = {};', "physical curve 'a' is given twice"),
])
def test_malformed_statements_are_one_line(text, words):
    with pytest.raises(SceneError, match=words.replace("(", r"\(").replace("+", r"\+")) as e:
        parse_geo(text, "b")
    assert "\n" not in str(e.value) and len(str(e.value)) < 300


ARC_FACE = """Point(1) = {-8, -6, 0}; Point(2) = {8, -6, 0}; Point(3) = {0, 0, 0}; Point(4) = {0, -10, 0};
Circle(1) = {1, 3, 2}; Line(2) = {2, 1};
Physical Curve("face") = {1}; Physical Curve("top") = {2};
"""
GEO_BAD = [  # (id, file, words of the one line)
    ("spline face", BLOCK.replace("Line(1) = {4, 1};", "Point(9) = {0, 0, 0}; Spline(1) = {4, 9, 1};") + NAMES,
     "the face must be a line or a circle arc"),
    ("repeated spline point", BLOCK.replace("Line(3) = {2, 3};", "Point(9) = {0, -23, 0}; BSpline(3) = {2, 9, 9, 3};")
     + NAMES, "repeats the point (0, -23) (points 9 and 9)"),
    ("coincident spline points", BLOCK.replace("Line(3) = {2, 3};", "Point(9) = {0, -23, 0}; Point(8) = {0, -23, 0};"
                                               "Spline(3) = {2, 9, 8, 3};") + NAMES, "(points 9 and 8)"),
    ("unnamed hole", BLOCK + NAMES + "Point(5) = {0, -10, 0}; Point(6) = {1, -10, 0}; Point(7) = {-1, -10, 0};"
     "Circle(5) = {6, 5, 7}; Circle(6) = {7, 5, 6};", "curve 5 is in no physical curve"),
    ("curve in two groups", BLOCK + NAMES.replace("{4}", "{4, 3}"),
     "curve 3 is in physical curves 'bottom' and 'left'"),
    ("missing curve", BLOCK + NAMES.replace("{4}", "{4, 7}"), "lists curve 7, which is not defined"),
    ("closed spline", BLOCK + NAMES + 'Point(9) = {0, -5, 0}; Point(8) = {1, -6, 0}; Spline(9) = {9, 8, 9};'
                                      'Physical Curve("hole") = {9};', "starts and ends at (0, -5)"),
    ("uneven arc", ARC_FACE.replace("{8, -6, 0}", "{8, -6.1, 0}"), "ends at different distances from its centre"),
    ("half-turn arc", ARC_FACE.replace("{-8, -6, 0}", "{-8, 6, 0}").replace("{8, -6, 0}", "{8, -6, 0}"),
     "turns half a circle or more"),
    ("open outline", BLOCK.replace("Line(2) = {1, 2};", "Point(9) = {10, -19, 0}; Line(2) = {1, 9};") + NAMES,
     "the outline is open at (10, -19)"),
]


@pytest.mark.parametrize("geo,words", [(g, w) for _, g, w in GEO_BAD], ids=[i for i, _, _ in GEO_BAD])
def test_malformed_outlines_are_refused_in_one_line(tmp_path, monkeypatch, capsys, geo, words):
    refused(tmp_path, monkeypatch, capsys, geo, words)


def test_a_file_with_every_allowed_statement(tmp_path):
    """Variables, a point size, Line Loop / Curve Loop with reversed curves, Plane Surface,
    Physical Line and Physical Surface: the block of the built-in scene."""
    geo = tmp_path / "b.geo"
    geo.write_text("""w = 20; h = w;  // sizes
        Point(1) = {w / 2, 0, 0, 0.5}; Point(2) = {w / 2, -h, 0}; Point(3) = {-w / 2, -h, 0}; Point(4) = {-w/2, 0, 0};
        Line(1) = {4, 1}; Line(2) = {1, 2}; Line(newl) = {3, 2}; Line(4) = {3, 4};
        Line Loop(1) = {1, 2, -3, 4}; Curve Loop(2) = {-4, 3, -2, -1};
        Plane Surface(1) = {1};
        Physical Line("face") = {1}; Physical Curve("right", 7) = {-2}; Physical Curve("bottom") = {3};
        Physical Curve("left") = {4}; Physical Surface("block") = {1};
        """)
    face, x, outline = read_geo(geo, "lower", "b")
    (tmp_path / "plain.geo").write_text(BLOCK + NAMES)
    assert (face, x, outline) == read_geo(tmp_path / "plain.geo", "lower", "b")
    assert x == (-10.0, 10.0) and outline.names == ("right", "bottom", "left")


def test_reads_share_nothing(tmp_path):
    """Two threads reading 20 times each get the same outline; a failed read leaves nothing
    behind for the next one."""
    good, bad = tmp_path / "good.geo", tmp_path / "bad.geo"
    good.write_text((ROOT / "examples" / "block-with-hole.geo").read_text())
    bad.write_text(BLOCK + "x = 1;\ny = z;\n" + NAMES)
    first = read_geo(good, "lower", "b")
    results, errors = [], []

    def work(path):
        for _ in range(20):
            try:
                results.append(read_geo(path, "lower", "b"))
            except SceneError as e:
                errors.append(str(e))

    threads = [threading.Thread(target=work, args=(p,)) for p in (good, bad)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 20 and all(r == first for r in results)
    assert errors == ["b.geo: line 5: unknown variable 'z' in 'y = z'; define it on an earlier line (z = ...;)"] * 20
    assert read_geo(good, "lower", "b") == first


def test_reading_imports_no_gmsh():
    code = ("import sys; from cvxdual.scene.geo import read_geo; "
            "read_geo('examples/block-with-hole.geo', 'lower', 'b'); print('gmsh' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# -- gmsh's curves -------------------------------------------------------------------------------

GMSH = """
import json, sys
import gmsh
gmsh.initialize(readConfigFiles=False)
gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1])
gmsh.model.geo.synchronize()
u = json.loads(sys.argv[2])
print(json.dumps({"points": {t: gmsh.model.getValue(0, t, [])[:2].tolist() for _, t in gmsh.model.getEntities(0)},
                  "bounds": {t: [b[0] for b in gmsh.model.getParametrizationBounds(1, t)]
                             for _, t in gmsh.model.getEntities(1)},
                  "curves": {t: gmsh.model.getValue(1, t, u).tolist() for _, t in gmsh.model.getEntities(1)}}))
gmsh.finalize()
"""


@pytest.mark.skipif(importlib.util.find_spec("gmsh") is None, reason="gmsh is not installed")
def test_values_and_splines_are_gmsh_s(tmp_path):
    """Against gmsh itself (in a child process: gmsh keeps global state): the points its parser
    computes, and its Spline, BSpline and Bezier curves of 2 to 12 points at the 31 parameters
    the outline's spline passes through."""
    rng = np.random.default_rng(7)
    lines = ["s = 3; r = Sqrt(2) * s^2 / 7 - Pi % 2 + Atan2(1, 3) * Hypot(1, 2) + Round(2.5) - Log(Exp(0.5));"]
    lines += [f"Point({i + 1}) = {{r * {i} - Cos({i}) / 3, Sin({i}) * s, 0}};" for i in range(4)]
    kinds, pt = {}, 10
    for tag, (kind, n) in enumerate(((k, n) for k in ("Spline", "BSpline", "Bezier") for n in range(2, 13)), 1):
        scale = 10.0 ** rng.integers(-3, 4)
        xy = np.column_stack([np.sort(rng.uniform(-50, 50, n)), rng.uniform(-30, 30, n)]) * scale
        ids = []
        for x, y in xy:
            pt += 1
            ids.append(str(pt))
            lines.append(f"Point({pt}) = {{{float(x)!r}, {float(y)!r}, 0}};")
        lines.append(f"{kind}({tag}) = {{{', '.join(ids)}}};")
        kinds[tag] = kind
    (tmp_path / "s.geo").write_text("\n".join(lines) + "\n")
    out = subprocess.run([sys.executable, "-c", GMSH, str(tmp_path / "s.geo"), json.dumps(U.tolist())],
                         capture_output=True, text=True, check=True)
    ref = json.loads(out.stdout)
    geo = parse_geo((tmp_path / "s.geo").read_text(), "s")
    assert {int(t): tuple(v) for t, v in ref["points"].items()} == geo.points  # the same numbers, to the bit
    from cvxdual.scene.geo import _bezier, _bspline, _catmull_rom
    worst = 0.0
    for tag, kind in kinds.items():
        assert ref["bounds"][str(tag)] == [0.0, 1.0]
        p = np.array([geo.points[t] for t in geo.curves[tag][1]])
        mine = _bezier(p) if kind == "Bezier" else np.array([(_bspline if kind == "BSpline" else _catmull_rom)(p, u)
                                                             for u in U])
        theirs = np.array(ref["curves"][str(tag)]).reshape(-1, 3)
        assert np.all(theirs[:, 2] == 0.0)
        worst = max(worst, float(np.abs(mine - theirs[:, :2]).max() / np.ptp(p, axis=0).max()))
    # the same formulas in the same order of operations agree to the bit here; 1e-12 of the
    # curve's size leaves room for a gmsh build that fuses multiply-adds
    assert worst <= 1e-12, worst


def test_geo_splines_are_the_outline_s_splines(tmp_path):
    """A BSpline part passes through gmsh's curve at the 31 parameters, from its first to its last point."""
    geo = tmp_path / "b.geo"
    geo.write_text(BLOCK.replace("Line(3) = {2, 3};", "Point(9) = {5, -23, 0}; Point(8) = {-5, -22, 0};"
                                                      "BSpline(3) = {2, 9, 8, 3};") + NAMES)
    _, _, outline = read_geo(geo, "lower", "b")
    seg = outline.part("bottom").segments[0]
    assert seg.is_spline and len(seg.through) == 31 and seg.start == (10.0, -20.0) and seg.end == (-10.0, -20.0)
    # a cubic Bezier curve of its 4 points (gmsh's BSpline of 4 points)
    p = np.array([[10, -20], [5, -23], [-5, -22], [-10, -20]], float)
    b = np.array([[(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u ** 2 * (1 - u), u ** 3] for u in U]) @ p
    assert np.allclose(seg.through, b, rtol=0, atol=1e-13)  # 1e-13 mm: rounding of sums of terms of size 20


def test_arc_faces(tmp_path):
    """A circle face, symmetric or not (its ends at any heights on one branch), with the file's own
    centre; either branch for either body, as a scene file's circle face (a groove is a lower body
    under its lower branch); an arc across its centre's height is not a graph and is refused."""
    geo = tmp_path / "a.geo"
    geo.write_text(ARC_FACE)
    face, x, _ = read_geo(geo, "upper", "b")
    assert (type(face), face.R, face.xc, face.yc, x) == (LowerCircle, 10.0, 0.0, 0.0, (-8.0, 8.0))
    geo.write_text(ARC_FACE.replace("{8, -6, 0}", "{6, -8, 0}"))
    face, x, _ = read_geo(geo, "upper", "b")
    assert (face.R, face.xc, face.yc, x) == (10.0, 0.0, 0.0, (-8.0, 6.0))
    assert read_geo(geo, "lower", "b")[0] == face  # the groove's branch: the body decides nothing here
    geo.write_text(ARC_FACE.replace("{-8, -6, 0}", "{-8, 6, 0}").replace("{8, -6, 0}", "{8, 6, 0}"))
    assert type(read_geo(geo, "lower", "b")[0]) is UpperCircle
    geo.write_text(ARC_FACE.replace("{-8, -6, 0}", "{-8, 6, 0}").replace("{8, -6, 0}", "{6, -8, 0}"))  # via (-10, 0)
    with pytest.raises(SceneError, match="crosses the height of its centre, so it is not a graph"):
        read_geo(geo, "upper", "b")


def test_splines_run_as_drawn(tmp_path):
    """A spline drawn from a higher point tag to a lower one: its 31 points run from its start to
    its end (the gmsh-based reader took the ends in the order of their tags, and the points in the
    order drawn, so that such a spline jumped from one end to the other)."""
    geo = tmp_path / "b.geo"
    geo.write_text(BLOCK.replace("Line(3) = {2, 3};", "Point(9) = {0, -23, 0}; Spline(3) = {3, 9, 2};") + NAMES)
    seg = read_geo(geo, "lower", "b")[2].part("bottom").segments[0]
    ends = {seg.start, seg.end}
    assert ends == {(10.0, -20.0), (-10.0, -20.0)}
    # the first of the 31 points is 1/32 of the way along (about 0.6 of a curve 20 long), the last as near
    # the end: within 1 of them, and 19 from the other end
    assert np.hypot(*np.subtract(seg.through[0], seg.start)) < 1.0
    assert np.hypot(*np.subtract(seg.through[-1], seg.end)) < 1.0


def test_the_direction_of_a_curve_does_not_matter(tmp_path):
    """Each curve is taken from its end of the lower point tag, as the gmsh-based reader took it:
    a file drawing its curves the other way gives the same outline, bit for bit."""
    text = (ROOT / "examples" / "block-with-hole.geo").read_text()
    flipped = text
    for a, b in [("{4, 1}", "{1, 4}"), ("{2, 3}", "{3, 2}"), ("{6, 5, 7}", "{7, 5, 6}"), ("{9, 5, 6}", "{6, 5, 9}")]:
        flipped = flipped.replace(a, b)
    assert flipped.count("Circle") == text.count("Circle") and flipped != text
    (tmp_path / "a.geo").write_text(text)
    (tmp_path / "b.geo").write_text(flipped)
    assert read_geo(tmp_path / "a.geo", "lower", "b") == read_geo(tmp_path / "b.geo", "lower", "b")
    assert read_geo(tmp_path / "a.geo", "lower", "b")[2] == load_scene("block-with-hole").bodies[1].outline
