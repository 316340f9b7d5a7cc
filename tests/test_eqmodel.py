"""The equilibrium-space model (cvxdual.eq.model): the same handles as the P0 DualModel, and
every solution exactly admissible whatever the user changed."""

import cvxpy as cp
import numpy as np
import pytest

import cvxdual as cd
from cvxdual.eq.bounds import ADMISSIBLE_TOL, admissibility_residuals
from cvxdual.voigt import out_of_plane_factor, shear_stress, von_mises


@pytest.fixture
def model():
    return cd.build_model("hertz", level=1, stress_space="eq")


def rel(a, b):
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(b).max())


def test_default_model_is_the_packages_eq_solve(model):
    model.solve()
    sol = model.solution()
    ref = cd.solve("hertz", level=1, stress_space="eq", solver="CLARABEL")
    # the same QP and the same exactness step: the same numbers (a reordering would show as 1e-15)
    assert rel(sol.stress, ref.stress) < 1e-12
    assert sol.checks["applied"]["admissibility"] < ADMISSIBLE_TOL
    assert set(sol.checks["skipped"]) == {"bounds", "displacement", "error"}
    # a half model: the contact force carries half of P = 35000 N/mm, exactly (equilibrium to rounding)
    assert model.value(model.total_contact_force) == pytest.approx(17500.0, rel=1e-9)
    assert sol.contact["total_force"] == pytest.approx(17500.0, rel=1e-9)


def test_stress_measures_at_the_vertices(model):
    model.solve()
    sig = model.value(model.stress)
    assert sig.shape == (9 * model.space.n_tri, 3) and model.vertex_body.shape == (len(sig),)
    f = out_of_plane_factor(model.space.scene, model.vertex_body)
    # the expression and its numpy twin evaluate one formula on the same doubles: rounding only
    assert rel(model.value(model.von_mises()), von_mises(sig, f)) < 1e-12
    assert rel(model.value(model.shear_stress()), shear_stress(sig)) < 1e-12


def test_load_factor_scales_the_exact_field(model):
    model.load_factor.value = 0.5
    model.solve()
    sol = model.solution()
    # admissible for half the load: checked against the unit load's data at sigma / 0.5
    assert max(admissibility_residuals(model.space, sol.stress / 0.5).values()) < ADMISSIBLE_TOL
    assert sol.contact["total_force"] == pytest.approx(8750.0, rel=1e-9)
    model.load_factor.value = 0.0
    with pytest.raises(cd.ModelError, match="positive"):
        model.solve()


@pytest.mark.slow
def test_a_cap_holds_everywhere_at_the_exact_field(model):
    """A convex cap at the vertices of a linear field caps the whole sub-triangle; after the
    exactness step the cap still holds to the user-constraint tolerance."""
    model.solve()
    peak = float(model.value(model.von_mises()).max())
    capped = cd.build_model("hertz", level=1, stress_space="eq")
    capped.add_constraint(capped.von_mises_cap(0.9 * peak), name="cap")
    capped.solve()
    sol = capped.solution()
    f = out_of_plane_factor(capped.space.scene, capped.vertex_body)
    vm = von_mises(sol.stress.reshape(-1, 3), f)
    # the exactness step moves the field by ~1e-9 of the stress scale (its max_change): far below
    # the 1e-6 the user-constraint check allows
    assert vm.max() <= 0.9 * peak * (1 + 1e-6)
    assert sol.checks["applied"]["user_constraints"] < 1e-6 and sol.checks["applied"]["admissibility"] < 1e-12


def test_prandtl_lower_bound_through_the_model():
    """The static theorem on the punch of examples/prandtl_punch.py at level 0: an exactly
    admissible field inside the yield set carries a load below (2 + pi) k."""
    from helpers import load_example
    punch = load_example("prandtl_punch").punch_scene()
    model = cd.build_model(punch, level=0, stress_space="eq", limit_analysis=True)
    with pytest.raises(cd.ModelError, match="yield"):
        model.solve()  # no yield condition: any load is carried
    model.add_constraint(model.shear_cap(1.0, where=model.vertex_body == 1), name="yield")
    # Clarabel stalls on this degenerate problem without regularisation (NumericalError)
    model.solve(static_regularization_constant=1e-7)
    alpha = float(model.load_factor.value)
    tau = shear_stress(model.stresses().reshape(-1, 3))[model.vertex_body == 1].max()
    certified = alpha / max(1.0, tau)
    assert 0.85 * (2 + np.pi) < certified < 2 + np.pi  # measured 4.6589 = 0.906 (2 + pi)
    assert model.solution().checks["applied"]["admissibility"] < ADMISSIBLE_TOL


def test_eq_model_misuse():
    with pytest.raises(cd.CvxdualError, match="frictionless"):
        cd.build_model(cd.load_scene("patch", [{"contact": {"friction": {"g": 1.0}}}]), level=0, stress_space="eq")
    model = cd.build_model("patch", level=0, stress_space="eq")
    with pytest.raises(cd.ModelError, match="not been solved"):
        model.stresses()
    model.set_objective(cp.Minimize(cp.max(model.shear_stress())))
    model.solve()
    sol = model.solution()
    assert sol.checks["applied"]["admissibility"] < ADMISSIBLE_TOL
    with pytest.raises(cd.ModelError, match="solved already"):
        model.solve()


def test_caps_are_the_same_set_as_the_measures():
    """shear_cap / von_mises_cap are shear_stress() <= k / von_mises() <= k as direct cones: at
    any field, each holds exactly where the other does."""
    model = cd.build_model("hertz", level=1)
    model.solve()
    for cap, values in ((model.von_mises_cap, model.value(model.von_mises())),
                        (model.shear_cap, model.value(model.shear_stress()))):
        k = float(np.median(values))  # half the pieces above: both outcomes occur
        assert np.array_equal(np.asarray(cap(k).violation()) > 0, values > k)
    with pytest.raises(cd.ModelError, match="non-negative"):
        model.shear_cap(-1.0)
    where = model.system.pieces.body == 1
    assert model.von_mises_cap(1e9, where=where).args[1].shape[1] == int(where.sum())


def test_cap_arguments_are_checked():
    model = cd.build_model("patch", level=0)
    n = model.system.n_pieces
    for where, words in ((np.ones(3, bool), "one boolean per point"), (np.array([0.5]), "integer"),
                         (np.zeros(n, bool), "no point"), (np.array([n]), "below")):
        with pytest.raises(cd.ModelError, match=words):
            model.shear_cap(1.0, where=where)
    for k, words in (("100", "number"), (cp.Parameter((2,)), r"shape \(\) or")):
        with pytest.raises(cd.ModelError, match=words):
            model.von_mises_cap(k)
    k = cp.Parameter(nonneg=True, value=1e3)
    assert model.von_mises_cap(k).is_dcp()  # a parameter bound: a sweep over caps compiles once


def test_eq_accepts_inaccurate_only_in_limit_analysis():
    model = cd.build_model("hertz", level=1, stress_space="eq")
    with pytest.raises(cd.SolverError, match="inaccurate"):
        model.solve(max_iter=8)  # stopped early: not optimal, so not returned
