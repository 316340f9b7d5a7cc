"""examples/tresca_friction.py: Tresca's law at every pair, and when friction changes the stresses.

Levels 1 and 2 only (a fraction of a second each); the example's own run goes to level 3.
"""


import numpy as np
import pytest
from helpers import load_example

from cvxdual.cli import main as cli_main

LEVELS = (1, 2)
DISSIMILAR = ("cylinder-on-block", "hertz")




ex = load_example("tresca_friction")


@pytest.fixture(scope="module")
def runs():
    return {(case, level): ex.solve_case(case, level) for case in ex.CASES for level in LEVELS}


def delta(r):
    """The displacement scale: the largest nodal displacement of the Tresca solution."""
    return float(np.abs(r["tresca"].displacement).max())


def test_tangential_traction_never_exceeds_g(runs):
    for (case, _), r in runs.items():
        q, g = r["q"], r["g"]
        assert g == pytest.approx(ex.G_OVER_P0 * r["hertz"].p0, rel=1e-15)
        # Clarabel stops at 1e-8 relative feasibility of the scaled rows; 1e-6 of g leaves a margin
        # of 100 (measured: every |q| below g, the closest 1.2e-6 g under it)
        assert np.all(np.abs(q) <= g * (1 + 1e-6)), (case, np.abs(q).max() / g)
        assert np.all(q[~r["slides"]] == 0.0)  # x fixed (symmetry line): no tangential unknown
        if case in DISSIMILAR:
            # the bound is reached: the test above is not vacuous (BOUND_TOL: interior-point distance)
            assert np.abs(q).max() >= (1 - ex.BOUND_TOL) * g


def test_friction_opposes_slip(runs):
    for (case, _), r in runs.items():
        q, s, g, d = r["q"], r["slip"], r["g"], delta(r)
        # q s <= 0 at every pair; the interior-point duals have the sign of the friction force, so
        # what is left is the rounding of the recovered u (measured max q s = 0 or below)
        assert np.max(q * s) <= 1e-10 * g * d, case
        # a pair that slips by more than the solver's noise (stick pairs: < 1e-5 d measured) is at
        # the bound and the force opposes the slip
        sliding = r["slides"] & (np.abs(s) > 1e-4 * d)
        assert np.all(np.sign(q[sliding]) == -np.sign(s[sliding])), case
        assert np.all(np.abs(q[sliding]) >= (1 - ex.BOUND_TOL) * g), case
        if case in DISSIMILAR:
            assert sliding.any()  # dissimilar bodies do slip somewhere: the checks above bite


def test_stick_pairs_do_not_slip_and_slipping_pairs_do(runs):
    for (case, _), r in runs.items():
        s, d = r["slip"], delta(r)
        # Clarabel's default tolerances leave slips at stick pairs up to 9e-6 d (measured; they drop
        # to 1e-9 d with tighter solver tolerances), against 4e-4 d or more at slipping pairs
        assert np.all(np.abs(s[r["stick"]]) <= 1e-4 * d), case
        assert np.all(np.abs(s[r["slipping"]]) > 1e-4 * d), case
        assert np.all(r["stick"] <= r["active"])  # stick is a state of active pairs only
        assert not np.any(r["slipping"] & r["fixed"])
    # the dissimilar Hertz contact has both zones; the similar one sticks wherever it is free in x
    assert runs[("hertz", 2)]["stick"].any() and runs[("hertz", 2)]["slipping"].any()
    assert not any(runs[("similar", level)]["slipping"].any() for level in LEVELS)


def test_dissipation_identity(runs):
    # sum Q s + sum g w |s| = 0: complementarity (g w - |Q|) |s| = 0 with Q s <= 0, summed. The
    # interior point leaves it at 1e-4 relative at level 1 and 3.5e-5 at level 2 (measured).
    # Similar bodies dissipate nothing, so their relative value is noise over noise: not checked
    for case in DISSIMILAR:
        for level in LEVELS:
            r = runs[(case, level)]
            k = r["slides"]
            Q, w, s = r["q"][k] * r["width"][k], r["width"][k], r["slip"][k]
            dissipated = np.sum(r["g"] * w * np.abs(s))
            assert abs(np.sum(Q * s) + dissipated) <= 1e-3 * dissipated, (case, level)


def test_total_normal_force_unchanged_by_friction(runs):
    for (case, _), r in runs.items():
        f, f0 = r["tresca"].contact["total_force"], r["frictionless"].contact["total_force"]
        # the loads are prescribed: one body's y equilibrium fixes the total; both solves satisfy
        # it to the solver's 1e-8 (measured difference 5e-13 relative)
        assert f == pytest.approx(f0, rel=1e-8), case
        half = r["scene"].bodies[0].x_range[0] == 0.0  # hertz: a half model carries half of the load
        assert f == pytest.approx(r["hertz"].load * (0.5 if half else 1.0), rel=1e-8), case


def test_friction_matters_for_dissimilar_bodies_only(runs):
    similar = [runs[("similar", level)]["difference"] for level in LEVELS]
    # no slip tendency in the continuum: the difference is a discretisation error and falls with h
    # (measured 4.2e-3, 1.7e-3: ratio 0.40; 0.6 leaves room for a slower rate)
    assert similar[1] < 0.6 * similar[0]
    assert similar[0] < 1e-2
    for case in DISSIMILAR:
        d = [runs[(case, level)]["difference"] for level in LEVELS]
        # friction changes the problem: the difference is large and levels off (measured 0.075,
        # 0.080 on the cylinder, 0.1334, 0.1336 on hertz)
        assert min(d) > 0.05, case
        assert d[1] == pytest.approx(d[0], rel=0.1), case


def test_scene_file_friction_is_the_model_with_friction(runs):
    r = runs[("cylinder-on-block", 1)]
    sol = ex.solve_from_scene("cylinder-on-block", 1, r["g"])
    assert sol.scene.friction.g == r["g"]
    # the same problem, assembled and solved the same way: identical up to rounding (measured: 0)
    assert np.abs(sol.stress - r["tresca"].stress).max() <= 1e-12 * np.abs(r["tresca"].stress).max()
    assert np.array_equal(sol.contact["stick"], r["stick"])


def test_cli_with_set_friction_writes_the_friction_columns(runs, tmp_path, capsys):
    import pandas as pd
    r = runs[("cylinder-on-block", 1)]
    out = tmp_path / "cli"
    assert cli_main(["solve", "--scene", "cylinder-on-block", "--level", "1", "--no-plots", "--out", str(out),
                     "--set", f"contact.friction.g={r['g']!r}"]) == 0
    c = pd.read_csv(out / "contact.csv")
    assert {"tangential_force", "slip", "stick"} <= set(c.columns)
    # one row per pair in the solution's order, 12 significant digits: the same solve
    assert np.allclose(c["x"], r["x"], rtol=1e-11, atol=0)
    assert np.allclose(c["tangential_force"], r["q"] * r["width"], rtol=1e-9, atol=1e-9 * r["g"])
    assert np.array_equal(c["stick"].to_numpy(), r["stick"].astype(int))


def test_coulomb_fixed_point_reports_convergence_honestly():
    c = ex.coulomb_fixed_point("hertz", 1, 0.1, iterations=30)
    assert c["converged"] and c["changes"][-1] <= ex.COULOMB_TOL
    # |q| <= mu p with the last pressure: the threshold came from the previous one, which differs
    # by at most COULOMB_TOL p0 (times mu), plus the 1e-6 feasibility margin of the first test
    # (measured: -2.7e-12 p0)
    assert c["coulomb_violation"] <= 0.1 * (ex.COULOMB_TOL + 1e-6)
    one = ex.coulomb_fixed_point("hertz", 1, 0.1, iterations=1)
    # one Tresca solve from the frictionless pressure moves it by far more than the tolerance
    assert not one["converged"] and one["iterations"] == 1 and one["changes"][0] > ex.COULOMB_TOL


def test_main_writes_figures_and_tables(tmp_path, capsys):
    res = ex.main(["--levels", "1", "--out", str(tmp_path), "--coulomb", "0.1", "--iterations", "1"])
    names = sorted(p.name for p in tmp_path.iterdir())  # no temporary left behind
    assert names == ["tresca_coulomb.csv", "tresca_difference.png", "tresca_friction.csv", "tresca_profiles.csv",
                     "tresca_profiles.png"]
    for png in ("tresca_profiles.png", "tresca_difference.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (tmp_path / "tresca_friction.csv").read_text().splitlines()
    head = rows[0].split(",")
    assert head[:2] == ["case", "level"] and len(rows) == 1 + len(ex.CASES)
    for line, w in zip(rows[1:], res["rows"], strict=True):
        fields = dict(zip(head, line.split(","), strict=True))
        assert float(fields["difference"]) == pytest.approx(w["difference"], rel=1e-9)
        assert int(fields["n_stick"]) == w["n_stick"]
    profiles = (tmp_path / "tresca_profiles.csv").read_text().splitlines()
    assert len(profiles) == 1 + sum(len(r["x"]) for r in res["results"])
    printed = capsys.readouterr().out
    assert "rel. L2 diff" in printed and "open@g" in printed
    # one iteration: a run is called converged only when its last change is within the tolerance
    for c in res["coulomb"]:
        assert c["converged"] == (c["changes"][-1] <= ex.COULOMB_TOL)
    assert printed.count("NOT converged") == sum(not c["converged"] for c in res["coulomb"]) >= 1
