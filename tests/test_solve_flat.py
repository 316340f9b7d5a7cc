"""Physics of solutions on flat-faced scenes: patch test, Hertz, the paper's blocks."""

import numpy as np
import pytest
from helpers import primal, solved

import cvxdual as cd
from cvxdual.p0.norms import l2_norm
from cvxdual.scene import convert_units


@pytest.mark.parametrize("tri", ["type1", "type2"])
@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_patch_is_exact(level, tri):
    sol = solved("patch", level, tri)
    # the exact constant field lies in S_h and its displacement in V_h: only the solver's
    # tolerance (1e-8 on gaps) remains, so 1e-7 has a margin of 10
    assert sol.error["l2_rel"] <= 1e-7
    # uniform pressure 100 MPa: every pair active, force = p * tributary length
    c = sol.contact
    assert c["n_active"] == len(c["x"])
    np.testing.assert_allclose(c["force"], 100.0 * sol.system.width, rtol=1e-6)
    assert c["total_force"] == pytest.approx(100.0 * 10.0, rel=1e-9)


def test_hertz_peak_pressure_and_half_width():
    # the fast path solves the same discrete problem (test_fast checks it against CVXPY)
    sol = cd.solve("hertz", level=cd.load_scene("hertz").mesh.default_level, solver="fast")
    a, p0 = sol.exact["a"], sol.exact["p0"]
    assert a == pytest.approx(6.21, abs=0.005) and p0 == pytest.approx(3585, abs=0.5)
    c = sol.contact
    # the acceptance: peak pressure within 3% of p0, half-width within 5% of a
    assert abs(c["max_pressure"] - p0) <= 0.03 * p0
    assert abs(c["x_max"] - a) <= 0.05 * a
    assert c["x_min"] == 0.0
    # half model: the contact carries half the load, to solver tolerance
    assert c["total_force"] == pytest.approx(35000.0 / 2, rel=1e-7)


def test_hertz_error_decreases_with_rate():
    levels = [1, 2, 3, 4]
    sols = [cd.solve("hertz", level=L, solver="fast") for L in levels]  # the same discrete problem
    err = np.array([s.error["l2_rel"] for s in sols])
    h = np.array([s.mesh.h for s in sols])
    assert np.all(np.diff(err) < 0)
    rate = np.polyfit(np.log(h), np.log(err), 1)[0]
    # P0 stresses on a field with square-root edges: the rate is at most 1 and at least 1/2
    assert rate >= 0.5


@pytest.mark.slow
@pytest.mark.parametrize("scene,level", [("hertz", 1), ("hertz", 2), ("hertz", 3),
                                         ("blocks", 1), ("blocks", 2), ("blocks", 3)])
def test_dual_and_primal_agree(scene, level):
    sol = solved(scene, level)
    pm = primal(scene, level)
    s = sol.system
    tp = s.stresses_from_displacement(pm.displacements())
    # two independent QPs solved to 1e-8: the stresses agree to 1e-6 relative
    assert l2_norm(s, tp - sol.stress) <= 1e-6 * l2_norm(s, sol.stress)
    assert sol.duality_gap <= 1e-6
    # the primal's contact multipliers are the dual's nodal contact forces; nodes at the
    # contact edge are the most sensitive (measured 3e-6 of the largest force at Clarabel's
    # 1e-8 tolerances, 3e-8 at 1e-10: see test_agreement_follows_solver_tolerance)
    F = pm.contact_forces()
    np.testing.assert_allclose(F, sol.contact["force"], rtol=0, atol=1e-5 * F.max())


def test_agreement_follows_solver_tolerance():
    # the dual-primal differences are solver tolerance, not formulation: they shrink with it
    opts = dict(tol_gap_abs=1e-11, tol_gap_rel=1e-11, tol_feas=1e-11, tol_ktratio=1e-9)
    sol = cd.solve(cd.load_scene("hertz"), level=2, **opts)
    pm = cd.PrimalModel(sol.system)
    pm.solve(**opts)
    s = sol.system
    tp = s.stresses_from_displacement(pm.displacements())
    assert l2_norm(s, tp - sol.stress) <= 1e-9 * l2_norm(s, sol.stress)
    F = pm.contact_forces()
    np.testing.assert_allclose(F, sol.contact["force"], rtol=0, atol=1e-8 * F.max())


@pytest.mark.parametrize("scene,level", [("hertz", 3), ("blocks", 3), ("patch", 2)])
def test_contact_conditions(scene, level):
    sol = solved(scene, level)
    c = sol.contact
    F, s = c["force"], c["gap"] - c["relative_displacement"]
    Fmax = F.max()
    delta = np.abs(sol.displacement).max()
    # compressive forces, non-penetration, complementarity, to solver tolerance (1e-8 relative)
    assert F.min() >= -1e-7 * Fmax
    assert s.min() >= -1e-7 * delta
    assert np.all(np.abs(F * s) <= 1e-6 * Fmax * delta)
    # action = reaction at every pair: the upper body receives +F where the lower gets -F
    np.testing.assert_allclose(c["reaction"], F, rtol=0, atol=1e-8 * Fmax)
    # the recovered displacements reproduce the stresses through Hooke's law
    assert sol.residuals["constitutive"] <= 1e-6
    assert sol.residuals["equilibrium"] <= 1e-9


def test_blocks_contact_zone_grows_with_load():
    widths = []
    for p in (10.0, 50.0, 200.0):
        sc = cd.load_scene("blocks", [{"bodies": {"lower": {"boundary": {"push": {"traction": {"value": [0.0, p]}}}}}}])
        sol = cd.solve(sc, level=2)
        widths.append(sol.contact["x_max"] - sol.contact["x_min"])
        assert sol.contact["total_force"] == pytest.approx(20.0 * p, rel=1e-7)
    assert widths[0] < widths[1] < widths[2]


def test_units_do_not_change_dimensionless_results():
    mm = cd.load_scene("hertz")
    m = convert_units(mm, 1e-3, 1e6, ("m", "Pa"))
    a, b = cd.solve(mm, level=2), cd.solve(m, level=2)
    # the nondimensionalised QPs are identical up to rounding in the unit factors
    assert np.abs(a.stress * 1e6 - b.stress).max() <= 1e-6 * np.abs(b.stress).max()
    for k in ("l2_rel", "energy_rel"):
        assert a.error[k] == pytest.approx(b.error[k], rel=1e-6)
    assert a.contact["x_max"] * 1e-3 == pytest.approx(b.contact["x_max"], rel=1e-12)
    assert a.solver["iterations"] == b.solver["iterations"]
