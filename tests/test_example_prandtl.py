"""examples/prandtl_punch.py: the static theorem's lower bound on Prandtl's punch, (2 + pi) k.

Levels 0 and 1 only (0.3 s and 1.3 s to solve); the example's own run goes to level 2.
"""


import numpy as np
import pytest
from helpers import load_example

from cvxdual.eq.bounds import ADMISSIBLE_TOL, admissibility_residuals

ex = load_example("prandtl_punch")


@pytest.fixture(scope="module")
def eq():
    return {level: ex.limit_load_eq(level) for level in (0, 1)}


def test_certified_values_are_lower_bounds_converging_from_below(eq):
    r0, r1 = eq[0], eq[1]
    for r in (r0, r1):
        # a lower bound, strictly below the exact value; certification only lowers the solver's value
        assert 0 < r["alpha_certified"] <= r["alpha"] < ex.PRANDTL
        assert r["ratio"] == pytest.approx(r["alpha_certified"] / ex.PRANDTL)
        # the solver's value was already at its tolerance: certification costs rounding only
        assert r["alpha"] - r["alpha_certified"] < 1e-6 * r["alpha"]
    assert r0["alpha_certified"] < r1["alpha_certified"]  # refinement enlarges the space: the bound rises
    # measured: 4.6589 (0.906 of 2 + pi) at level 0, 4.8571 (0.945) at level 1
    assert r1["alpha_certified"] > 0.85 * ex.PRANDTL


def test_certified_field_is_exactly_admissible(eq):
    for r in eq.values():
        space, sigma = r["space"], r["stress_unit"]  # exactly admissible for the unit load q = 1
        # every admissibility condition, assembled from the geometry rather than the reduced basis:
        # div sigma = 0, traction continuity, boundary tractions, frictionless compressive contact.
        # ADMISSIBLE_TOL = 1e-12 of the stress scale: what is left is rounding (measured 1.6e-14,
        # a row sums O(10-100) terms in double precision), the solver's 1e-8 errors are gone
        res = admissibility_residuals(space, sigma)
        assert max(res.values()) < ADMISSIBLE_TOL, res
        assert r["residual"] < ADMISSIBLE_TOL  # model.solution()'s own check of the same field
        # yield at the certified load, checked here from the vertex values (n_sub, 3 vertices, Voigt);
        # tau is convex and sigma linear on each sub-triangle, so vertices bound it everywhere
        s = r["alpha_certified"] * sigma.reshape(space.n_tri, 9, 3)
        tau = np.hypot(0.5 * (s[..., 0] - s[..., 1]), s[..., 2])
        block = space.body == 1
        assert tau[block].max() <= ex.K * (1 + 1e-9)
        assert r["max_tau"] <= 1 + 1e-9
        assert tau[block].max() > ex.K * (1 - 1e-6)  # the bound is attained: yield is active somewhere


def test_p0_space_is_unbounded_not_a_bound():
    # needs the limit-analysis DualModel API: build_model(..., limit_analysis=True), load_factor,
    # shear_stress(), add_constraint(..., name=); unbounded because isochoric P1 velocities lock
    for level in (0, 1):
        r = ex.limit_load_p0(level)
        assert r["status"] == "unbounded"
        assert r["alpha"] is None


def test_main_writes_figure_and_table(tmp_path, capsys):
    eq = ex.main(["--levels", "0", "--out", str(tmp_path)])
    assert [r["level"] for r in eq] == [0]
    png = tmp_path / "prandtl.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (tmp_path / "prandtl.csv").read_text().splitlines()
    assert rows[0].split(",")[:4] == ["level", "n_unknowns", "alpha", "alpha_certified"]
    assert len(rows) == 2
    fields = dict(zip(rows[0].split(","), rows[1].split(","), strict=True))
    assert float(fields["alpha_certified"]) == pytest.approx(eq[0]["alpha_certified"], rel=1e-9)
    assert fields["p0_status"] == "unbounded" and fields["p0_alpha"] == ""
    printed = capsys.readouterr().out
    assert "certified" in printed and "error %" in printed
    assert "unbounded — not a bound" in printed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["prandtl.csv", "prandtl.png"]  # no temporary left
