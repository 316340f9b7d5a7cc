"""``base = ...`` in a scene: a built-in name, or a file relative to the file holding the line."""

import os

import pytest

import cvxdual as cd
from cvxdual.cli import main


def write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def test_base_is_a_file_next_to_the_including_file(tmp_path, monkeypatch):
    write(tmp_path / "scenes" / "coarse.toml", 'base = "hertz"\n[mesh]\ncolumns = 4\n')
    top = write(tmp_path / "scenes" / "mine.toml", 'base = "coarse.toml"\n[mesh]\ngrading = 2.0\n')
    monkeypatch.chdir(tmp_path)  # the base is found next to mine.toml, not in the working directory
    for source in (top, "scenes/mine.toml", str(top)):
        scene = cd.load_scene(source)
        assert scene.name == "mine"  # the including file's own name (its stem)
        assert (scene.mesh.columns, scene.mesh.grading) == (4, 2.0)
        assert scene.exact == cd.load_scene("hertz").exact  # from hertz, through coarse.toml


def test_nested_bases_resolve_against_their_own_files(tmp_path, monkeypatch):
    write(tmp_path / "lib" / "deep" / "root.toml", 'base = "blocks"\nname = "root"\n[mesh]\ncolumns = 6\n')
    write(tmp_path / "lib" / "mid.toml", 'base = "deep/root.toml"\n[mesh]\ngrading = 2.0\n')
    top = write(tmp_path / "work" / "top.toml", 'base = "../lib/mid.toml"\n[mesh]\ndefault_level = 1\n')
    monkeypatch.chdir(tmp_path / "lib" / "deep")  # a directory in which the relative names would mislead
    scene = cd.load_scene(top)
    assert (scene.mesh.columns, scene.mesh.grading, scene.mesh.default_level) == (6, 2.0, 1)
    assert scene.name == "top"
    assert scene.gap == cd.load_scene("blocks").gap  # the chain ends at a built-in scene
    # an absolute base works from any file, and from a dict
    write(tmp_path / "abs.toml", f'base = "{(tmp_path / "lib" / "mid.toml").as_posix()}"\n')
    assert cd.load_scene(tmp_path / "abs.toml").mesh.columns == 6
    assert cd.load_scene({"base": str(tmp_path / "lib" / "mid.toml")}).mesh.grading == 2.0


def test_a_builtin_name_still_works(tmp_path):
    top = write(tmp_path / "a.toml", 'base = "patch"\nname = "my patch"\n[mesh]\ncolumns = 2\n')
    scene = cd.load_scene(top)
    assert scene.name == "my patch" and scene.mesh.columns == 2
    assert scene.exact == cd.load_scene("patch").exact
    assert cd.load_scene({"base": "patch", "mesh": {"columns": 2}}).mesh.columns == 2


def test_overrides_apply_after_the_bases(tmp_path):
    write(tmp_path / "b.toml", 'base = "patch"\n[mesh]\ncolumns = 2\n')
    top = write(tmp_path / "a.toml", 'base = "b.toml"\n')
    assert cd.load_scene(top, [{"mesh": {"columns": 3}}]).mesh.columns == 3


@pytest.mark.parametrize("files, start", [
    ({"a.toml": 'base = "a.toml"\n'}, "a.toml"),
    ({"a.toml": 'base = "b.toml"\n', "b.toml": 'base = "./a.toml"\n'}, "a.toml"),
    ({"x/a.toml": 'base = "../y/b.toml"\n', "y/b.toml": 'base = "c.toml"\n', "y/c.toml": 'base = "../x/a.toml"\n'},
     "x/a.toml"),
])
def test_cycles_are_refused(tmp_path, files, start):
    for name, text in files.items():
        write(tmp_path / name, text)
    with pytest.raises(cd.SceneError, match=r"scene bases form a cycle: .* -> .*; remove one of these base lines"):
        cd.load_scene(tmp_path / start)


def test_a_missing_base_file_names_the_path_and_the_fix(tmp_path):
    top = write(tmp_path / "sub" / "a.toml", 'base = "../nowhere/b.toml"\n')
    with pytest.raises(cd.SceneError) as e:
        cd.load_scene(top)
    msg = str(e.value)
    assert "\n" not in msg
    assert "base '../nowhere/b.toml' does not exist" in msg
    assert os.path.join("sub", "..", "nowhere", "b.toml") in msg  # the path it looked for
    assert "fix the path (relative to the directory of the file holding the base line)" in msg
    assert "hertz" in msg  # or a built-in name


def test_a_missing_base_file_on_the_command_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write(tmp_path / "a.toml", 'base = "b.toml"\n')
    assert main(["solve", "--scene", "a.toml", "--no-output"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("cvxdual: error: scene file 'a.toml': base 'b.toml' does not exist")


def test_an_unknown_builtin_base_suggests_a_path(tmp_path):
    top = write(tmp_path / "a.toml", 'base = "hertzz"\n')
    with pytest.raises(cd.SceneError, match=r"base 'hertzz' is not a built-in scene .*base = \"other.toml\""):
        cd.load_scene(top)


def test_a_dict_scene_with_a_relative_base_is_refused(tmp_path, monkeypatch):
    """A dict has no directory: a relative base would silently depend on the working directory,
    so it is an error that says what to give instead (a built-in name or an absolute path)."""
    write(tmp_path / "b.toml", 'base = "patch"\n')
    monkeypatch.chdir(tmp_path)  # even where the file exists
    with pytest.raises(cd.SceneError, match=r"the scene \(a dict\): base 'b.toml' is a relative path, but this scene "
                       r"is not read from a file.*absolute path or a built-in scene name"):
        cd.load_scene({"base": "b.toml"})


@pytest.mark.parametrize("bad", [{"x": 1}, 3, "", ["patch"]])
def test_a_base_that_is_not_a_name_is_refused(bad):
    with pytest.raises(cd.SceneError, match="base must be a built-in scene name"):
        cd.load_scene({"base": bad})


def test_a_broken_base_file_is_named(tmp_path):
    write(tmp_path / "b.toml", "mesh = [\n")
    top = write(tmp_path / "a.toml", 'base = "b.toml"\n')
    with pytest.raises(cd.SceneError, match=r"scene file .*b.toml' is not valid TOML"):
        cd.load_scene(top)
