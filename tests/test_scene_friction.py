"""Tresca friction as scene data (``[contact] friction``) and the friction columns of contact.csv."""

import math
from dataclasses import replace
from functools import partial
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

import cvxdual as cd
from cvxdual.cli import main
from cvxdual.errors import SceneError
from cvxdual.outputs.output_set import CONTACT_COLUMNS, write_contact_csv
from cvxdual.scene import Friction, convert_units
from cvxdual.scene.scenefile import load_scene, parse_assignment
from cvxdual.solution import Solution

BASE = 'base = "patch"\n'


def with_friction(table: str, tmp_path) -> cd.Scene:
    """The patch scene with ``[contact]`` holding ``table`` (TOML), read from a file."""
    f = tmp_path / "f.toml"
    f.write_text(BASE + f"[contact]\nfriction = {table}\n")
    return load_scene(str(f))


def one_line(error) -> str:
    msg = str(error.value)
    assert "\n" not in msg and len(msg) < 400  # one sentence, values shortened
    return msg


# --- parsing ----------------------------------------------------------------------------------

def test_frictionless_by_default():
    assert load_scene("patch").friction is None
    assert all(load_scene(n).friction is None for n in ("hertz", "blocks"))


def test_from_toml_text(tmp_path):
    s = with_friction('{ kind = "tresca", g = 358.5 }', tmp_path)
    assert s.friction == Friction(kind="tresca", g=358.5)
    assert s.contact == (0.0, 10.0)  # the rest of [contact] is untouched


def test_kind_defaults_to_tresca_and_inf_is_full_stick(tmp_path):
    s = with_friction("{ g = inf }", tmp_path)
    assert s.friction.kind == "tresca" and s.friction.g == math.inf


def test_integer_g_is_a_float(tmp_path):
    g = with_friction("{ g = 100 }", tmp_path).friction.g
    assert g == 100.0 and isinstance(g, float)


def test_from_dict():
    from cvxdual.scene.scenefile import builtin_data
    data = {**builtin_data("patch"), "contact": {"friction": {"kind": "tresca", "g": 0.0}}}
    assert load_scene(data).friction == Friction(g=0.0)
    assert load_scene("patch", [{"contact": {"friction": {"g": 12.5}}}]).friction.g == 12.5


def test_set_adds_friction_to_a_frictionless_scene():
    """``--set`` as the CLI applies it: parse_assignment, then load_scene's overrides."""
    s = load_scene("patch", [parse_assignment("contact.friction.g=100")])
    assert s.friction == Friction(kind="tresca", g=100.0)
    s = load_scene("patch", [parse_assignment("contact.friction.g=inf")])
    assert s.friction.g == math.inf


def test_set_changes_g_of_a_scene_file(tmp_path):
    f = tmp_path / "f.toml"
    f.write_text(BASE + '[contact]\ninterval = [1.0, 9.0]\nfriction = { kind = "tresca", g = 358.5 }\n')
    s = load_scene(str(f), [parse_assignment("contact.friction.g=7.5")])
    assert s.friction == Friction(g=7.5) and s.contact == (1.0, 9.0)


def test_friction_is_part_of_the_scene_identity():
    """Study caches key fields by ``repr(scene)``: friction must change it."""
    plain = load_scene("patch")
    assert repr(plain) != repr(replace(plain, friction=Friction(g=1.0)))
    assert repr(replace(plain, friction=Friction(g=1.0))) != repr(replace(plain, friction=Friction(g=2.0)))


# --- bad input: one SceneError line naming the problem -------------------------------------------

BAD_TOML = [
    ("coulomb", '{ kind = "coulomb", g = 1.0 }', "Coulomb friction is not convex"),
    ("kind as a number", "{ kind = 1, g = 1.0 }", "must be 'tresca'"),
    ("negative g", "{ g = -1.0 }", "must be >= 0"),
    ("-inf", "{ g = -inf }", "must be >= 0"),
    ("nan", "{ g = nan }", "must be a number >= 0"),
    ("g as a string", '{ g = "100" }', "must be a number >= 0"),
    ("g as a boolean", "{ g = true }", "must be a number >= 0"),
    ("g as a list", "{ g = [1.0] }", "must be a number >= 0"),
    ("g too large", "{ g = 1e300 }", "magnitude at most"),
    ("g a 400-digit integer", "{ g = " + "9" * 400 + " }", "magnitude at most"),
    ("no g", '{ kind = "tresca" }', "missing key 'g'"),
    ("coulomb without g", '{ kind = "coulomb" }', "Coulomb friction is not convex"),
    ("unknown key", "{ g = 1.0, mu = 0.3 }", "unknown key(s) 'mu'; allowed: g, kind"),
    ("not a table", '"tresca"', "contact.friction: expected a table"),
]


@pytest.mark.parametrize("table,words", [b[1:] for b in BAD_TOML], ids=[b[0] for b in BAD_TOML])
def test_bad_friction_is_one_scene_error(tmp_path, table, words):
    with pytest.raises(SceneError) as info:
        with_friction(table, tmp_path)
    assert words in one_line(info)


BAD_API = [
    ("coulomb", lambda: Friction(kind="coulomb", g=1.0), "Coulomb"),
    ("negative g", lambda: Friction(g=-0.5), ">= 0"),
    ("nan g", lambda: Friction(g=math.nan), "number >= 0"),
    ("numpy nan g", lambda: Friction(g=np.float64("nan")), "number >= 0"),
    ("string g", lambda: Friction(g="1"), "number >= 0"),
    ("bool g", lambda: Friction(g=False), "number >= 0"),
    ("tiny g", lambda: Friction(g=1e-200), "too small"),
    ("a Scene with a non-Friction", lambda: replace(load_scene("patch"), friction={"g": 1.0}), "Friction(g=...)"),
]


@pytest.mark.parametrize("call,words", [b[1:] for b in BAD_API], ids=[b[0] for b in BAD_API])
def test_bad_friction_api_is_one_scene_error(call, words):
    with pytest.raises(SceneError) as info:
        call()
    assert words in one_line(info)


def test_g_is_required():
    with pytest.raises(TypeError):  # a threshold has no sensible default
        Friction()


@pytest.mark.parametrize("value,words", [("contact.friction.kind=coulomb", "Coulomb"),
                                         ("contact.friction.g=-3", ">= 0"),
                                         ("contact.friction.g=abc", "number >= 0"),
                                         ("contact.friction.mu=0.3", "unknown key(s) 'mu'")])
def test_bad_set_exits_1_with_one_line_and_writes_nothing(tmp_path, monkeypatch, capsys, value, words):
    monkeypatch.chdir(tmp_path)
    rc = main(["solve", "--scene", "patch", "--level", "0", "--no-plots", "--set", value])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and words in err[0]
    assert not list(tmp_path.iterdir())


# --- units ----------------------------------------------------------------------------------

def test_g_converts_like_a_stress():
    mm = load_scene("patch", [{"contact": {"friction": {"g": 358.5}}}])  # mm, MPa
    m = convert_units(mm, 1e-3, 1e6, ("m", "Pa"))
    assert m.friction.g == 358.5 * 1e6  # the same product convert_units forms: exact, no tolerance
    assert m.friction.kind == "tresca" and m.units == ("m", "Pa")
    stick = convert_units(replace(mm, friction=Friction(g=math.inf)), 1e-3, 1e6, ("m", "Pa"))
    assert stick.friction.g == math.inf
    assert convert_units(load_scene("patch"), 1e-3, 1e6, ("m", "Pa")).friction is None


# --- contact.csv ----------------------------------------------------------------------------

def fake_solution(n: int = 4, drop: str | None = None):
    """A Solution-like object with only ``contact`` and the methods that read it (what the contact
    writers use)."""
    x = np.linspace(0.0, 1.0, n)
    c = {"x": x, "gap": np.zeros(n), "relative_displacement": -1e-3 * x, "pressure": 100.0 + x,
         "active": np.array([True, True, False, True][:n]), "force": 2.5 * x, "tangential_force": 0.5 - x,
         "slip": np.array([0.0, 0.0, 1e-4, -2e-4][:n]), "stick": np.array([True, True, False, False][:n])}
    c.pop(drop, None)
    sol = SimpleNamespace(contact=c)
    sol.contact_columns = partial(Solution.contact_columns, sol)
    sol.contact_table = partial(Solution.contact_table, sol)
    return sol


def test_contact_columns_end_with_the_friction_ones():
    assert CONTACT_COLUMNS[:6] == ("x", "gap", "relative_displacement", "pressure", "active", "force")
    assert CONTACT_COLUMNS[6:] == ("tangential_force", "slip", "stick")


def test_csv_and_table_write_the_friction_columns(tmp_path):
    sol = fake_solution()
    write_contact_csv(sol, tmp_path / "contact.csv")
    text = (tmp_path / "contact.csv").read_text().splitlines()
    assert text[0] == ",".join(CONTACT_COLUMNS)
    assert [r.split(",")[-1] for r in text[1:]] == ["1", "1", "0", "0"]  # stick as an integer, like active
    back = pd.read_csv(tmp_path / "contact.csv")
    # %.12g keeps 12 significant digits: the round trip's relative error is below 5e-12
    np.testing.assert_allclose(back["tangential_force"], sol.contact["tangential_force"], rtol=1e-11)
    np.testing.assert_allclose(back["slip"], sol.contact["slip"], rtol=1e-11)
    t = sol.contact_table()
    assert list(t.columns) == list(CONTACT_COLUMNS)
    assert t["stick"].tolist() == [1, 1, 0, 0] and t["active"].tolist() == [1, 1, 0, 1]
    assert t["stick"].dtype.kind == "i" and t["active"].dtype.kind == "i"


@pytest.mark.parametrize("missing", ["tangential_force", "slip", "stick"])
def test_missing_friction_data_is_not_made_up(tmp_path, missing):
    sol = fake_solution(drop=missing)
    with pytest.raises(KeyError, match=missing):
        write_contact_csv(sol, tmp_path / "contact.csv")
    with pytest.raises(KeyError, match=missing):
        sol.contact_table()
    assert not (tmp_path / "contact.csv").exists()


def test_real_solve_writes_the_friction_columns(tmp_path):
    """Needs the solver's ``sol.contact`` to carry tangential_force, slip and stick."""
    sol = cd.solve("patch", level=0)
    write_contact_csv(sol, tmp_path / "contact.csv")
    c = pd.read_csv(tmp_path / "contact.csv")
    assert list(c.columns) == list(CONTACT_COLUMNS)
    assert len(c) == len(sol.contact["x"])
    assert set(c["stick"].unique()) <= {0, 1}
    assert list(sol.contact_table().columns) == list(CONTACT_COLUMNS)
