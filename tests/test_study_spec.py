"""Study specs, the checked cache and the command line (no cluster: fast), and the project's own
specs (studies/specs/) in their quick variants on one shared local cluster."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from run_study import SPECS  # studies/, on the path by conftest.py

from cvxdual.cli import main
from cvxdual.study import StudyError, load_spec, run
from cvxdual.study.cache import Cache


def test_spec_expands_grid(tmp_path):
    (tmp_path / "s.toml").write_text('base = "blocks"\n')
    (tmp_path / "g.toml").write_text(
        'name = "g"\nscenes = ["s.toml", "hertz"]\ntriangulations = ["type1", "type2"]\nlevels = [0, 1]\n'
        'solvers = ["fast", "clarabel"]\nreference = "none"\n[set]\n"mesh.grading" = [1.0, 2.0, 4.0]\n'
        '[quick]\nlevels = [0]\n')
    st = load_spec(tmp_path / "g.toml")
    assert len(st.cases) == 2 * 2 * 2 * 2 * 3
    assert {c.solver for c in st.cases} == {"fast", "CLARABEL"}
    assert st.cases[0].overrides_text == "mesh.grading=1.0"
    assert len(load_spec(tmp_path / "g.toml", quick=True).cases) == 2 * 2 * 2 * 3
    for name in ("convergence.toml", "stability.py", "speed.py", "bounds.py"):
        assert load_spec(SPECS / name, quick=True).cases


@pytest.mark.parametrize("text, words", [
    ('scenes = ["hertz"]\nlevels = [0]\nbogus = 1\n', "unknown key 'bogus'"),
    ('scenes = ["hertz"]\nlevels = [0]\nstress_spaces = ["p1"]\n', "unknown stress space 'p1'"),
    ('scenes = ["nowhere.toml"]\nlevels = [0]\n', "neither a built-in scene"),
    ('scenes = ["hertz"]\nlevels = [0, 3]\nreference = { level = 3 }\n', "not finer"),
    ('scenes = ["hertz"]\n', "levels must be"),
    ('scenes = ["hertz"]\nlevels = [0]\ntriangulations = ["type3"]\n', "unknown triangulation"),
    ('scenes = ["hertz"]\nlevels = [0]\nkinematic = ["p1", "p3"]\n', "unknown kinematic side 'p3'; use \"p2\""),
    ('scenes = ["hertz"]\nlevels = [0]\nkinematic = 2\n', "unknown kinematic side '2'"),
    ('scenes = ["hertz"]\nlevels = [0]\nkinematic = []\n', "kinematic must be a non-empty list"),
])
def test_bad_spec_one_line(tmp_path, capsys, text, words):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(StudyError, match=words):
        load_spec(p)
    assert main(["study", "run", str(p), "--cache", "", "--quiet", "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cvxdual: error: study spec") and words in err[0]
    assert not (tmp_path / "o").exists()


def test_kinematic_is_an_axis_of_the_spec():
    """``kinematic``: "p2" by default (solve's own), a name in any case or a list, per block too;
    each value a case of its own, every stress space included (a p0 row carries it)."""
    base = {"name": "k", "scenes": ["hertz"], "levels": [0, 1], "stress_spaces": ["p0", "eq"], "reference": "none"}
    assert {c.kinematic for c in load_spec(base).cases} == {"p2"}
    assert {c.kinematic for c in load_spec({**base, "kinematic": "P1"}).cases} == {"p1"}
    both = load_spec({**base, "kinematic": ["p1", "p2"]}).cases
    assert len(both) == 2 * 2 * 2  # levels x spaces x sides
    assert sorted((c.stress_space, c.kinematic) for c in both if c.level == 0) == [
        ("eq", "p1"), ("eq", "p2"), ("p0", "p1"), ("p0", "p2")]
    blocks = load_spec({**base, "stress_spaces": ["eq"], "cases": [{"name": "a"}, {"name": "b", "kinematic": "p1"}]})
    assert {(c.name, c.kinematic) for c in blocks.cases} == {("a", "p2"), ("b", "p1")}
    with pytest.raises(StudyError, match="the same case appears twice"):
        load_spec({**base, "kinematic": ["p1", "P1"]})


def test_kinematic_column_in_rows(client, tmp_path):
    """A tiny study over both kinematic sides: every row has the ``kinematic`` column; the sides
    certify the same equilibrium stresses (one stress error), P2's bound is the sharper, and each
    side's combined error is measured with its own displacement: against the exact field (hertz,
    the study's 6x6 rule recomputes it) and against a finer eq reference (cylinder-on-block)."""
    from cvxdual import exact_reference, load_scene, solve
    from cvxdual.eq.bounds import exact_errors
    spec = {"name": "kin", "levels": [0], "solvers": ["fast"], "kinematic": ["p1", "p2"], "cases": [
        {"name": "exact", "scenes": ["hertz"], "stress_spaces": ["p0", "eq"]},
        {"name": "finer", "scenes": ["cylinder-on-block"], "triangulations": ["type2"], "stress_spaces": ["eq"],
         "reference": {"level": 2, "stress_space": "eq"}}]}
    df = run(spec, tmp_path, client=client, cache=None, quiet=True)
    assert (df.status == "optimal").all() and len(df) == 6
    assert list(df.columns).index("kinematic") == list(df.columns).index("stress_space") + 1
    csv = pd.read_csv(tmp_path / "kin.csv")
    assert sorted(zip(csv.stress_space, csv.kinematic, strict=True)) == sorted(
        zip(df.stress_space, df.kinematic, strict=True))
    p0 = df[df.stress_space == "p0"].set_index("kinematic")
    assert p0.loc["p1", "error_l2_rel"] == p0.loc["p2", "error_l2_rel"]  # the side does not touch a p0 solve
    for name, g in df[df.stress_space == "eq"].groupby("case"):
        g = g.set_index("kinematic")
        # the same stresses (the stress solve starts from the P1 contact set either way): equal to rounding
        assert g.loc["p1", "error_l2_rel"] == pytest.approx(g.loc["p2", "error_l2_rel"], rel=1e-9)
        assert g.loc["p2", "bound_energy_rel"] < 0.5 * g.loc["p1", "bound_energy_rel"]  # 0.08 against 0.30 (hertz)
        assert (g.effectivity >= 1).all()  # the certificate dominates the true error on both sides
        # P2's displacement error is ~3x below P1's at level 0 (30.7 against 97.3 on cylinder-on-block);
        # reading the P2 nodal values as a P1 field would give about P1's: a 0.6 margin tells them apart
        assert g.loc["p2", "error_combined"] < 0.6 * g.loc["p1", "error_combined"], name
    sol = solve(load_scene("hertz"), "type1", 0, "fast", stress_space="eq", kinematic="p2")
    e = exact_errors(sol.space, sol.stress, sol.bounds["displacement"], exact_reference(sol.scene)[0], n=6,
                     g=sol.column_stress)
    row = df[(df.case == "exact") & (df.stress_space == "eq") & (df.kinematic == "p2")].iloc[0]
    assert row.error_combined == pytest.approx(e["combined"], rel=1e-12)  # the same sums, the same rule


def test_study_help(capsys):
    for argv in (["study", "-h"], ["study", "run", "-h"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 0
    out = capsys.readouterr().out
    assert "--scheduler ADDRESS" in out and "--memory-limit" in out and "studies/specs/convergence.toml" in out


def test_missing_spec_file_one_line(tmp_path, capsys):
    for source, words in ((tmp_path / "nowhere.toml", "does not exist"), (tmp_path, "is not a file")):
        with pytest.raises(StudyError, match=words):
            load_spec(source)
    assert main(["study", "run", "convergence", "--cache", "", "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'convergence' does not exist" in err[0] and "studies/specs/" in err[0]


def test_cache_rejects_tampered_entries(tmp_path):
    c = Cache(tmp_path)
    row = {"scene": "x", "error_l2_rel": 0.1, "nan": float("nan")}
    assert c.put_row("k1", row)["nan"] is None
    assert c.get_row("k1") == {"scene": "x", "error_l2_rel": 0.1, "nan": None}
    assert c.get_row("k1", ("missing",)) is None
    p = tmp_path / "rows" / "k1.json"
    d = json.loads(p.read_text())
    d["row"]["error_l2_rel"] = 0.2  # checksum no longer matches
    p.write_text(json.dumps(d))
    assert c.get_row("k1") is None
    (tmp_path / "rows" / "k2.json").write_text(p.read_text().replace('"k1"', '"k2"'))  # someone else's entry
    assert c.get_row("k2") is None
    p.write_text("{not json")
    assert c.get_row("k1") is None
    a = np.arange(12.0).reshape(4, 3)
    c.put_arrays("a1", stress=a)
    assert np.array_equal(c.get_arrays("a1", {"stress": (4, 3)})["stress"], a)
    assert c.get_arrays("a1", {"stress": (5, 3)}) is None  # the wrong shape for its mesh
    c.put_arrays("a2", stress=np.array([[np.nan, 0.0, 0.0]]))
    assert c.get_arrays("a2") is None  # not finite
    f = tmp_path / "arrays" / "a1.npz"
    raw = bytearray(f.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    f.write_bytes(bytes(raw))
    assert c.get_arrays("a1") is None  # corrupt: recomputed, never a traceback
    assert Cache(None).get_row("k1") is None




@pytest.mark.slow
def test_stability_quick(client, tmp_path):
    df = run(SPECS / "stability.py", tmp_path, quick=True, client=client, cache=None, quiet=True)
    assert set(df.solver) == {"CLARABEL", "fast"} and set(df.triangulation) == {"type1", "type2"}
    solved = df[df.status == "optimal"]
    assert solved.paths_agree_l2_rel.max() < 1e-5 and solved.within_tolerances.all()
    nu = solved[solved.case.str.startswith("nu") & (solved.solver == "fast") & (solved.triangulation == "type1")]
    err = dict(zip(nu.case, nu.error_l2_rel, strict=True))
    assert err["nu = 0.4999"] > 10 * err["nu = 0.3"]  # locking is shown, not hidden
    units = solved[solved.group == "physical units"]
    assert set(units.units) == {"m, Pa"} and np.allclose(units.error_l2_rel, err["nu = 0.3"], rtol=1e-8)
    text = (tmp_path / "stability.md").read_text()
    assert "## What the table says" in text and "## stiffness contrast" in text


@pytest.mark.slow
def test_convergence_spec_small(client, tmp_path):
    """The convergence spec (its hooks and report) on a subset: hertz against the exact field, the
    groove's P0 and eq rows against a finer equilibrium reference."""
    import tomllib
    raw = tomllib.loads((SPECS / "convergence.toml").read_text())
    raw["hooks"] = str(SPECS / raw["hooks"])
    ref = {"level": 3, "stress_space": "eq"}
    p0, eq = raw["cases"]
    p0["scenes"] = [{"source": "hertz", "reference": "exact", "levels": [0, 1, 2]},
                    {"source": "cylinder-in-groove", "reference": ref, "levels": [0, 1]}]
    eq["scenes"] = [{"source": "cylinder-in-groove", "reference": ref, "levels": [0, 1]}]
    df = run(raw, tmp_path, client=client, cache=tmp_path / "cache", quiet=True)
    assert (df.status == "optimal").all() and len(df) == 14
    from cvxdual.study import rates
    r = rates(df).set_index(["scene", "triangulation", "stress_space"])["rate_l2"]
    hertz_rate = r["hertz", "type1", "p0"]
    assert 0.5 <= hertz_rate <= 1.1 and hertz_rate == pytest.approx(r["hertz", "type2", "p0"])
    assert r["cylinder-in-groove", "type2", "p0"] > r["cylinder-in-groove", "type1", "p0"] + 0.1
    for _, g in df.groupby(["scene", "triangulation", "stress_space"]):
        assert np.all(np.diff(g.sort_values("level")["error_l2_rel"]) < 0)
    hertz = df[df.scene == "hertz"]
    assert hertz.edge_error_share.notna().all() and hertz.reference.eq("exact").all()
    assert df[df.scene != "hertz"].reference.eq("type2 level 3 eq").all()
    rows = df[df.stress_space == "eq"]
    # the certificate bounds the energy error; against a reference two levels finer the measured
    # error carries the reference's own (a few percent of it at these levels): a margin of 1.1
    assert rows.guaranteed.astype(bool).all() and (rows.error_energy_rel <= 1.1 * rows.bound_energy_rel).all()
    text = (tmp_path / "convergence.md").read_text()
    assert "## What the rates say" in text and "type 2 beats type 1" in text and "estimated relative error" in text
    assert "## The references" in text and "## Equilibrium stresses on the curved scenes" in text
    csv = pd.read_csv(tmp_path / "convergence.csv")
    assert {"rate", "error_l2_rel_finer_rule", "worker", "cached", "bound_energy_rel"} <= set(csv.columns)


def test_speed_limit_rows(client, tmp_path):
    """The speed study's pseudo-solver ``limit`` (one factorisation) next to a solve, in processes."""
    spec = {"name": "lim", "scenes": ["hertz"], "levels": [1], "overrides": {"mesh": {"columns": 4}},
            "cases": [{"solvers": ["limit"], "isolate": "process"}, {"solvers": ["fast"]}]}
    df = run(spec, None, client=client, cache=None, quiet=True).set_index("solver")
    assert (df.status == "optimal").all()
    assert df.loc["limit", "n_dofs"] > 0 and df.loc["limit", "t_limit"] > 0 and df.loc["limit", "peak_mb"] > 50
    # a small case in a fresh process: its own peak (an interpreter with numpy/scipy, ~0.1-0.3 GB),
    # not the launching worker's (ru_maxrss carries that across exec)
    assert df.peak_mb.max() < 1500
    assert df.loc["limit", "n_pieces"] == df.loc["fast", "n_pieces"]


@pytest.mark.slow
def test_bounds_spec_small(client, tmp_path):
    """The bounds spec on hertz level 1 at two Poisson ratios, both kinematic sides: eq beats p0, the
    bound dominates the true error on both sides, eq does not lock, and P2's certificate does not
    either where P1's does."""
    from cvxdual.study.spec import load_module
    spec = load_module(SPECS / "bounds.py")
    cases = [{**spec._block("hertz", sp, "fast", nu), "levels": [1]} for sp in ("p0", "eq") for nu in (0.3, 0.4999)]
    ref = {**spec.REFERENCE, "level": 3}
    cases += [{**spec._block("cylinder-on-block", sp, "fast", 0.3), "levels": [1], "reference": ref}
              for sp in ("p0", "eq")]
    raw = {**spec.SPEC, "cases": cases, "hooks": str(SPECS / "bounds.py")}
    df = run(raw, tmp_path, client=client, cache=None, quiet=True)
    # hertz: 2 p0 + 2 nu x 2 sides eq; cylinder-on-block: 2 triangulations x (1 p0 + 2 sides eq)
    assert (df.status == "optimal").all() and len(df) == 12
    assert set(df[df.stress_space == "eq"].kinematic) == {"p1", "p2"}
    curved = df[(df.scene == "cylinder-on-block") & (df.stress_space == "eq")]
    # against a reference two levels finer: the bound still dominates (effectivity ~1.12 (P1), ~1.16 (P2) measured)
    assert curved.guaranteed.astype(bool).all() and (curved.effectivity >= 1).all()
    df = df[df.scene == "hertz"]
    eq = df[df.stress_space == "eq"].set_index(["kinematic", "nu", "level"])
    p0 = df[df.stress_space == "p0"].set_index(["nu", "level"])
    for side in ("p1", "p2"):
        assert (eq.loc[side].error_l2_rel < p0.error_l2_rel).all()
        assert (eq.loc[side].effectivity >= 1).all() and (eq.loc[side].effectivity <= 1.3).all()  # acceptance
        # no locking: at nu = 0.4999 the eq error stays within 2x of nu = 0.3 (P0's grows ~50x)
        assert (eq.loc[side].loc[0.4999].error_l2_rel / eq.loc[side].loc[0.3].error_l2_rel).max() < 2
    # the certified relative error at nu = 0.4999 over nu = 0.3: P2 within 2x (1.23 measured), P1 locks (8.8)
    ratio = {k: float(eq.loc[(k, 0.4999, 1), "bound_energy_rel"] / eq.loc[(k, 0.3, 1), "bound_energy_rel"])
             for k in ("p1", "p2")}
    assert ratio["p2"] < 2 < 5 < ratio["p1"]
    text = (tmp_path / "bounds.md").read_text()
    assert "## Findings: flat faces" in text and "## Findings: curved faces" in text
    assert "## Acceptance of issue 41" in text and "| bound rel p1 | bound rel p2 |" in text
    assert (tmp_path / "bounds.png").stat().st_size > 10000 and (tmp_path / "bounds_curved.png").stat().st_size > 10000


def test_report_names_a_command_a_reader_can_retype(tmp_path, monkeypatch):
    from cvxdual.study.report import shown_path
    (tmp_path / "specs").mkdir()
    monkeypatch.chdir(tmp_path)
    assert shown_path(tmp_path / "specs" / "s.toml") == "specs/s.toml"  # inside: relative, runnable from here
    assert shown_path(Path("/elsewhere/s.toml")) == "s.toml"  # outside: only the name


def test_bounds_report_time_to_target_interpolates_and_extrapolates():
    """A power law ``e = 40 n^-0.5`` with time ``t = 1e-3 n`` in the pieces ``n``: a bracketed
    target is found by interpolation, one below the finest level by the fitted law (both exact
    for these data, up to rounding), and each says how."""
    from cvxdual.study.spec import load_module
    rep = load_module(SPECS / "_bounds_report.py")
    n = 100.0 * 4.0 ** np.arange(4)
    e = 40.0 * n**-0.5
    d = pd.DataFrame({"level": [0, 1, 2, 3], "n_pieces": n, "error_l2_rel": e, "t_total": 1e-3 * n})
    t, how = rep._time_to(d, 1.0)  # between levels 1 and 2: n = 1600, t = 1.6
    assert how == "interpolated" and t == pytest.approx(1.6, rel=1e-12)
    t, how = rep._time_to(d, 0.01)  # n = (40 / 0.01)^2 = 1.6e7 pieces
    assert how.startswith("extrapolated: error ~ pieces^-0.50 over levels 1-3") and t == pytest.approx(1.6e4, rel=1e-10)
    t, how = rep._time_to(d.iloc[:2], 0.01)  # two levels: no fit is trusted
    assert np.isnan(t) and how.startswith("not reached")
