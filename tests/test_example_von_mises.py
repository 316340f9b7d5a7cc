"""examples/von_mises_cap.py and examples/min_peak_von_mises.py: von Mises (s33 = nu (s11 + s22))
capped on Hertz contact, and its least peak over admissible fields.

Coarse levels only (P0 level 1: 576 pieces, eq level 0; well under a second each); the examples'
own runs go to P0 level 3 and eq level 1.
"""


import numpy as np
import pytest
from helpers import load_example

import cvxdual
from cvxdual.convex.base import USER_TOLERANCE
from cvxdual.eq.bounds import ADMISSIBLE_TOL, admissibility_residuals
from cvxdual.reference.hertz import mcewen_stress
from cvxdual.scene.materials import Material
from cvxdual.scene.scenefile import builtin_data
from cvxdual.solution import TOLERANCES
from cvxdual.voigt import von_mises

cap_ex = load_example("von_mises_cap")
mp_ex = load_example("min_peak_von_mises")


def _hertz_a_p0():
    hz = cvxdual.exact_field(cvxdual.load_scene("hertz")).hertz
    return hz.a, hz.p0


@pytest.fixture(scope="module")
def cap():
    return cap_ex.cap_study(1)


@pytest.fixture(scope="module")
def p0():
    return mp_ex.min_peak_p0(1)


@pytest.fixture(scope="module")
def eq():
    return mp_ex.min_peak_eq(0)


def test_von_mises_formula_against_principal_stresses():
    # the numpy twin against the definition through the principal stresses of the 3x3 tensor
    rng = np.random.default_rng(1)
    s = rng.normal(size=(200, 3)) * 100.0
    nu = rng.uniform(0.0, 0.49, 200)
    s33 = nu * (s[:, 0] + s[:, 1])
    T = np.zeros((200, 3, 3))
    T[:, 0, 0], T[:, 1, 1], T[:, 2, 2] = s[:, 0], s[:, 1], s33
    T[:, 0, 1] = T[:, 1, 0] = s[:, 2]
    p = np.linalg.eigvalsh(T)
    ref = np.sqrt(0.5 * ((p[:, 0] - p[:, 1]) ** 2 + (p[:, 1] - p[:, 2]) ** 2 + (p[:, 2] - p[:, 0]) ** 2))
    # eigvalsh is backward stable: its errors are ~1e-15 of |T|; 1e-9 of |T| leaves room and
    # still catches any wrong term (a missing s33 or 3 s12^2 changes vm by O(|T|))
    assert np.abs(von_mises(s, nu) - ref).max() < 1e-9 * np.abs(T).max()


def test_numpy_twin_equals_cvxpy_expression(cap, p0):
    # both evaluate the same formula on the same double-precision stresses (model.stresses() and
    # model.von_mises().value both read t.value): only rounding differs (measured 2e-16), so
    # 1e-9 is a wide margin that any difference in the formula (a term, s33, a factor) would exceed
    assert cap["twin_difference"] < 1e-9
    assert p0["twin_difference"] < 1e-9


def test_exact_peak_is_johnsons_subsurface_maximum(cap):
    hz = cap["hertz"]
    peak, depth = cap_ex.exact_peak(hz.a, hz.p0, 0.3)
    # Johnson, Contact Mechanics (1985), 5.6: about 0.56 p0 at z = 0.70 a (nu = 0.3), two figures given
    assert abs(peak / hz.p0 - 0.56) < 0.005
    assert abs(depth / hz.a - 0.70) < 0.01
    # the axis holds the maximum over the half-space: a grid near the contact finds nothing higher
    # (up to rounding of the same formulas, 1e-12)
    x, z = np.meshgrid(np.linspace(-3 * hz.a, 3 * hz.a, 301), np.linspace(0.0, 3 * hz.a, 301))
    sx, sz, txz = mcewen_stress(x.ravel(), z.ravel(), hz.a, hz.p0)
    assert von_mises(np.column_stack([sx, sz, txz]), 0.3).max() <= peak * (1 + 1e-12)
    assert cap["exact_peak"] == pytest.approx(peak, rel=1e-12)
    # the P0 piece values approximate it: measured 0.25 % over at level 1 (0.5 % at level 3)
    assert cap["elastic_peak"] == pytest.approx(peak, rel=0.01)
    assert cap["peak_depth"] == pytest.approx(depth, abs=0.1 * hz.a)  # a piece at level 1 is ~0.3 a tall


def test_cap_is_attained_and_raises_the_energy(cap):
    k = cap["cap"]
    assert k == pytest.approx(cap_ex.CAP_FRACTION * cap["elastic_peak"], rel=1e-15)
    # the solver meets constraints to ~1e-8 relative; 1e-6 is the package's margin (USER_TOLERANCE)
    assert cap["capped_peak"] <= k * (1 + 1e-6)
    assert cap["capped_peak"] >= k * (1 - 1e-6)  # active: the cap binds (it is below the elastic peak)
    assert cap["at_cap"].sum() >= 1
    assert cap["elastic_peak"] > k  # the elastic field is not feasible for the capped problem...
    # ...and the capped field is feasible for the elastic one, whose minimiser the elastic field is:
    # the energy rises (measured by 2.7e-4 of it at level 1, far above the solver's 1e-8)
    assert cap["energy_capped"] > cap["energy_elastic"] + 1e-6 * abs(cap["energy_elastic"])


def test_capped_solution_checks(cap):
    applied, skipped = cap["checks"]["applied"], cap["checks"]["skipped"]
    # equilibrium and the cap still hold, to the package's tolerances (solution() raised otherwise)
    assert applied["equilibrium"] < TOLERANCES["equilibrium"]
    assert applied["user_constraints"] <= USER_TOLERANCE
    # the elastic law no longer links stresses and multipliers
    for name in ("constitutive", "complementarity", "penetration", "duality_gap"):
        assert name not in applied
        assert "user constraints" in skipped[name]
    assert "von Mises cap" in skipped["error"]
    # the elastic solve of the same model had them all
    assert {"equilibrium", "constitutive", "complementarity", "duality_gap"} <= set(cap["checks_elastic"]["applied"])


def test_min_peak_p0_is_below_the_elastic_peak(p0):
    assert p0["min_peak"] < p0["elastic_peak"]
    assert p0["ratio"] == pytest.approx(p0["min_peak"] / p0["elastic_peak"], rel=1e-15)
    # the objective is the peak of the returned field (cp.max over the pieces; solver accuracy 1e-8)
    assert p0["objective"] == pytest.approx(p0["min_peak"], rel=1e-6)
    applied, skipped = p0["checks"]["applied"], p0["checks"]["skipped"]
    assert applied["equilibrium"] < TOLERANCES["equilibrium"]
    assert "objective was changed" in skipped["constitutive"]
    # the loads are prescribed: the field carries all of the half load (P/2, solver accuracy)
    hz = cvxdual.exact_field(p0["model"].system.mesh.scene).hertz
    assert p0["contact"]["total_force"] == pytest.approx(hz.load / 2, rel=1e-6)
    # the docstring's explanation: without compatibility the contact spreads far beyond x = a
    # (measured: to x = 24 mm at level 1; the elastic contact ends at a = 6.2 mm)
    assert p0["extent_elastic"] < 1.5 * hz.a
    assert p0["extent"] > 2 * hz.a


def test_eq_min_peak_is_certified_and_brackets_with_p0(p0, eq):
    space, sigma, model = eq["space"], eq["sigma"], eq["model"]
    # exactly admissible to rounding (ADMISSIBLE_TOL = 1e-12 of the stress scale; measured 8e-15),
    # recomputed here from the geometry rather than taken from model.solution()
    assert eq["residual"] < ADMISSIBLE_TOL
    assert max(admissibility_residuals(space, sigma).values()) < ADMISSIBLE_TOL
    # the certified value is the peak of that exact field's vertex values, recomputed here; vm is
    # convex and sigma linear on each sub-triangle, so the vertices bound it everywhere
    nu = np.array([b.material.nu for b in space.scene.bodies])[model.vertex_body]  # plane strain: s33 = nu tr
    vm = von_mises(sigma.reshape(-1, 3), nu)
    assert vm.max() == pytest.approx(eq["certified"], rel=1e-15)
    # making the field exact moved it by rounding only: the certified value is the solver's (1e-8)
    assert eq["certified"] == pytest.approx(eq["solver_value"], rel=1e-6)
    # P0 (from below) <= k* <= eq (certified, from above), whatever the levels; both well below
    # the exact elastic peak, which is itself one admissible field's peak
    exact = mp_ex.exact_elastic_peak()
    assert p0["min_peak"] < eq["certified"] < exact
    assert exact == pytest.approx(cap_ex.exact_peak(*_hertz_a_p0(), 0.3)[0], rel=1e-9)  # two searches agree


def test_hooke_material_has_no_von_mises():
    data = builtin_data("patch")
    data["bodies"]["top"]["material"] = {"hooke": [list(r) for r in Material.isotropic(70000.0, 0.3, "strain").C]}
    model = cvxdual.build_model(data, level=0)
    model.shear_stress()  # in-plane: needs no s33
    with pytest.raises(cvxdual.ModelError, match="Poisson"):
        model.von_mises()
    eq_model = cvxdual.build_model(data, level=0, stress_space="eq")  # the eq space's model likewise
    eq_model.shear_stress()
    with pytest.raises(cvxdual.ModelError, match="Poisson"):
        eq_model.von_mises()


def test_cap_main_writes_figure_and_table(tmp_path, capsys):
    results = cap_ex.main(["--levels", "1", "--out", str(tmp_path)])
    assert [r["level"] for r in results] == [1]
    assert (tmp_path / "von_mises_cap.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (tmp_path / "von_mises_cap.csv").read_text().splitlines()
    assert len(rows) == 2
    fields = dict(zip(rows[0].split(","), rows[1].split(","), strict=True))
    assert float(fields["cap"]) == pytest.approx(results[0]["cap"], rel=1e-11)
    assert int(fields["n_at_cap"]) == results[0]["at_cap"].sum()
    assert float(fields["energy_increase"]) > 0
    assert "constitutive" in fields["checks_skipped"].split(";")
    printed = capsys.readouterr().out
    assert "peak/cap-1" in printed and "skipped constitutive" in printed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["von_mises_cap.csv", "von_mises_cap.png"]  # no temporary


def test_min_peak_main_writes_figure_and_table(tmp_path, capsys):
    out = mp_ex.main(["--levels", "1", "--eq-levels", "0", "--out", str(tmp_path)])
    assert [r["level"] for r in out["p0"]] == [1] and [r["level"] for r in out["eq"]] == [0]
    assert (tmp_path / "min_peak_von_mises.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = [r.split(",") for r in (tmp_path / "min_peak_von_mises.csv").read_text().splitlines()]
    assert [r[0] for r in rows] == ["space", "p0", "eq"]
    fields = dict(zip(rows[0], rows[1], strict=True))
    assert float(fields["ratio_to_elastic"]) == pytest.approx(out["p0"][0]["ratio"], rel=1e-9)
    assert float(dict(zip(rows[0], rows[2], strict=True))["min_peak"]) == pytest.approx(out["eq"][0]["certified"],
                                                                                       rel=1e-9)
    printed = capsys.readouterr().out
    assert "min peak MPa" in printed and "certified upper bounds" in printed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["min_peak_von_mises.csv", "min_peak_von_mises.png"]
