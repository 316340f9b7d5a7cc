"""examples/load_sweep.py: the Hertz half-width over a load-factor sweep that CVXPY compiles once.

One sweep of 20 load levels at level 2 (20 Clarabel solves, a few seconds) serves every test;
the example's own run is at level 3. No test times anything: the compile-once property is
checked on CVXPY's cache, not on a clock.
"""


import numpy as np
import pytest
from helpers import load_example

import cvxdual
from cvxdual.reference.hertz import hertz_line_contact

LEVEL = 2




ex = load_example("load_sweep")


@pytest.fixture(scope="module")
def swept():
    return ex.sweep(level=LEVEL, steps=20)


def test_half_width_follows_the_hertz_square_root_law(swept):
    lf, half, a, h = swept["lf"], swept["half_width"], swept["hertz_a"], swept["spacing"]
    assert len(lf) == 20 and lf[0] == pytest.approx(0.05) and lf[-1] == 1.0
    # sqrt(lf) a(P) is Hertz's a at the load lf P, for the scene's materials (rounding only)
    scene = cvxdual.load_scene(ex.SCENE)
    up, lo = scene.upper.material, scene.lower.material
    hz = hertz_line_contact(up.E, up.nu, lo.E, lo.nu, scene.exact.R, scene.exact.load)
    np.testing.assert_allclose(a, np.sqrt(4 * lf * hz.load * hz.R / (np.pi * hz.E_star)), rtol=1e-14)
    # the spacing is that of the pair interval holding a, taken from the mesh
    pair_x = swept["pair_x"]
    k = np.searchsorted(pair_x, a)
    assert np.all((pair_x[k - 1] <= a) & (a <= pair_x[k]))
    assert np.array_equal(h, pair_x[k] - pair_x[k - 1])
    # x_max is a pair position, so within one spacing means the zone ends at one of the two pairs
    # bracketing a. Measured largest |x_max - a| / spacing: 0.84 (level 2), 0.83 (level 3), 0.68 (level 4)
    assert np.all(np.abs(half - a) < h), np.round((half - a) / h, 2)
    # the contact zone enlarges with the load (never shrinks from one level to the next)
    assert np.all(np.diff(half) >= 0)


def test_total_contact_force_is_the_scaled_half_load(swept):
    # a half model: the contact carries lf P / 2. For any stress, the sum of the contact forces is
    # the applied resultant on the upper body (lf P / 2; the scene's tractions give P / 2 to 4e-16)
    # less the residuals of that body's free y rows, since its rigid y translation does no work on a
    # stress; Clarabel leaves those at its relative feasibility tolerance 1e-8 (measured: 5e-12 at
    # level 2, 5e-11 at level 4)
    P = swept["hertz"].load
    np.testing.assert_allclose(swept["total_force"], swept["lf"] * P / 2, rtol=1e-8, atol=0)


def test_sweep_is_dpp_and_canonicalised_once(swept):
    model = swept["model"]
    assert model.problem.is_dpp()
    # CVXPY caches the parametrised program of the first compile (None would mean no cache, and
    # every solve a full canonicalisation); every later solve found that same object there
    assert swept["program"] is not None and model.problem._cache.param_prog is swept["program"]
    assert swept["same_program"].all() and swept["problems"] == 1


def test_a_changed_model_does_recanonicalise():
    # the check above can fail: a change of the model (not of a parameter value) builds a new
    # problem, and CVXPY a new parametrised program, at the next solve
    model = cvxdual.build_model(ex.SCENE, level=0)
    model.solve()
    problem, program = model.problem, model.problem._cache.param_prog
    model.load_factor.value = 0.5
    model.solve()
    assert model.problem is problem and problem._cache.param_prog is program
    model.add_constraint(model.total_contact_force <= model.system.mesh.scene.exact.load, name="cap")
    model.solve()
    assert model.problem is not problem and model.problem._cache.param_prog is not program


def test_solution_after_the_sweep_equals_a_fresh_model(swept):
    model = swept["model"]

    def fields(m):
        return m.stresses(), m.displacements(), m.solution().contact["force"]

    # at the last level (lf = 1) and once more through the cached program at lf = 0.5: the same QP
    # solved from data that differ at most by rounding, so equal to Clarabel's 1e-8 (measured <= 4e-13)
    for lf in (None, 0.5):
        if lf is not None:
            model.load_factor.value = lf
            model.solve()
        fresh = cvxdual.build_model(ex.SCENE, level=LEVEL)
        fresh.load_factor.value = model.load_factor.value
        fresh.solve()
        for warm, new in zip(fields(model), fields(fresh), strict=True):
            assert np.abs(warm - new).max() <= 1e-8 * np.abs(new).max()


def test_main_writes_figure_and_table(tmp_path, capsys):
    r = ex.main(["--level", "1", "--steps", "3", "--out", str(tmp_path)])
    assert r["level"] == 1 and len(r["lf"]) == 3
    png = tmp_path / "load_sweep.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (tmp_path / "load_sweep.csv").read_text().splitlines()
    header = rows[0].split(",")
    assert header[:4] == ["lf", "load", "half_width", "hertz_a"] and "compile_time_s" in header
    assert len(rows) == 4
    table = np.array([[float(v) for v in row.split(",")] for row in rows[1:]])
    col = {name: table[:, i] for i, name in enumerate(header)}
    np.testing.assert_allclose(col["half_width"], r["half_width"], rtol=1e-9)  # written with 10 digits
    np.testing.assert_allclose(col["compile_time_s"], r["compile_time"], rtol=1e-5)  # written with 6 digits
    assert np.all(col["same_program"] == 1)
    summary = r["summary"]
    assert summary["total"] == pytest.approx(r["compile_time"].sum())
    assert summary["total_over_first"] == pytest.approx(summary["total"] / summary["first"])
    printed = capsys.readouterr().out
    assert "median recompile" in printed
    assert "CVXPY canonicalised 1 time" in printed and "pair spacings (within one)" in printed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["load_sweep.csv", "load_sweep.png"]  # no temporary left
