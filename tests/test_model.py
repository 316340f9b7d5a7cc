"""The CVXPY model as a modelling object (issue 15): expressions in physical units checked
against the solution, the traps a new user met (each test below failed on the model before
it), misuse errors, load factor, adhesion."""

from dataclasses import replace

import cvxpy as cp
import numpy as np
import pytest

import cvxdual as cd
from cvxdual.voigt import out_of_plane_factor, shear_stress, von_mises

# the same QP solved twice by Clarabel (1e-8 gaps and feasibility) agrees to about 1e-9 of its
# scale: 1e-7 leaves a margin of 100 and still catches a wrong row or scale (errors are O(1))
SAME = 1e-7


@pytest.fixture
def model():
    return cd.build_model("hertz", level=1)


def rel(a, b):
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / max(np.abs(b).max(), 1e-300))


def test_expressions_are_the_solution_in_physical_units(model):
    """Trap: no expression for contact forces or pressures. Now they are the package's own."""
    model.solve()
    sol = model.solution()
    ref = cd.solve("hertz", level=1, solver="CLARABEL")  # the package's own path, independently built
    assert rel(model.value(model.contact_force), ref.contact["force"]) < SAME
    assert rel(model.value(model.contact_pressure), ref.contact["pressure"]) < SAME
    assert rel(model.value(model.stress), ref.stress) < SAME
    # a half model carries half of the load P = 35000 N/mm; the loads are prescribed, so exact
    # to the equality rows' feasibility (1e-8 of the scale)
    assert model.value(model.total_contact_force) == pytest.approx(17500.0, rel=1e-8)
    # frictionless: the tangential rows are equalities, so no tangential force beyond rounding
    assert np.abs(model.value(model.tangential_force)).max() < 1e-9 * 17500.0
    assert sol.checks["skipped"] == {} and set(sol.checks["applied"]) >= {"equilibrium", "duality_gap"}
    # the complementary energy expression is the dual objective of the solution (physical)
    assert model.value(model.complementary_energy) == pytest.approx(sol.objective, rel=1e-9)


def test_von_mises_has_s33_and_matches_numpy(model):
    """Trap: a von Mises cap needed s33 and nu per piece rebuilt by hand."""
    model.solve()
    s = model.stresses()
    f = out_of_plane_factor(model.system.mesh.scene, model.system.pieces.body)
    assert np.allclose(f, 0.3)  # hertz: plane strain, nu = 0.3 in both bodies
    # the cvxpy expressions and their numpy twins evaluate the same formula: rounding only
    assert rel(model.value(model.von_mises()), von_mises(s, f)) < 1e-12
    assert rel(model.value(model.shear_stress()), shear_stress(s)) < 1e-12
    # independent check of s33 = nu (s11 + s22): von Mises from the 3D deviator
    s3 = np.zeros((len(s), 3, 3))
    s3[:, 0, 0], s3[:, 1, 1], s3[:, 0, 1], s3[:, 1, 0] = s[:, 0], s[:, 1], s[:, 2], s[:, 2]
    s3[:, 2, 2] = 0.3 * (s[:, 0] + s[:, 1])
    dev = s3 - np.trace(s3, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
    assert rel(von_mises(s, f), np.sqrt(1.5 * np.sum(dev**2, axis=(1, 2)))) < 1e-12


def test_von_mises_needs_nu():
    scene = cd.load_scene("patch")
    top = replace(scene.bodies[0], material=cd.Material.hooke([[3e5, 1e5, 0], [1e5, 3e5, 0], [0, 0, 1e5]]))
    scene = replace(scene, bodies=(top, scene.bodies[1]))
    model = cd.build_model(scene, level=0)
    with pytest.raises(cd.ModelError, match="Poisson"):
        model.von_mises()


def test_changed_objective_gives_a_solution_with_skipped_checks(model):
    """Trap: after a changed objective, the recovery raised AccuracyError with CLI advice."""
    model.set_objective(cp.Minimize(cp.max(model.von_mises())))
    model.solve()
    sol = model.solution()
    assert "objective" in sol.checks["skipped"]["constitutive"]
    assert sol.checks["applied"]["equilibrium"] < cd.solution.TOLERANCES["equilibrium"]
    assert sol.error is None and "error" in sol.checks["skipped"]  # the exact field is for another problem
    # the minimiser of the peak has a lower peak than the elastic field (which is admissible)
    elastic = cd.solve("hertz", level=1, solver="CLARABEL")
    assert von_mises(sol.stress, 0.3).max() < von_mises(elastic.stress, 0.3).max()


def test_problem_cannot_be_replaced_and_changes_are_kept(model):
    """Trap: replacing model.problem, then add_constraint, silently restored the objective."""
    with pytest.raises(cd.ModelError, match="set_objective"):
        model.problem = cp.Problem(cp.Minimize(0), [])
    obj = cp.Minimize(cp.max(model.shear_stress()))
    model.set_objective(obj)
    model.add_constraint(model.contact_pressure <= 5000.0, name="pressure cap")
    assert model.problem.objective is obj
    assert len(model.problem.constraints) == len(model.constraints) + 1


def test_infeasible_user_constraint_is_named(model):
    """Trap: an infeasible user constraint was blamed on the loads."""
    model.add_constraint(model.stress[:, 1] >= 0.0)  # no compression anywhere: the loads need some
    with pytest.raises(cd.SolverError) as info:
        model.solve()
    msg = str(info.value)
    assert "'constraint 1'" in msg and "push the bodies" not in msg and "--" not in msg and "\n" not in msg
    capped = cd.build_model("hertz", level=1)
    capped.add_constraint(capped.total_contact_force <= 1000.0, name="force cap")  # the loads need 17500
    with pytest.raises(cd.SolverError, match="'force cap'"):
        capped.solve()


def test_time_limit_and_options(model):
    """Trap: SCS ran 504 s, silent, with no time limit. The limit goes to the solver."""
    with pytest.raises(cd.TimeLimitError, match="time limit"):
        model.solve("CLARABEL", time_limit=1e-6)  # stops at its first check of the clock
    with pytest.raises(cd.SolverError, match="no time limit"):
        model.solve("CVXOPT", time_limit=10)  # a main dependency; it has no time limit
    with pytest.raises(cd.SolverError, match="time_limit must be"):
        model.solve(time_limit=-1)
    with pytest.raises(cd.SolverError, match="rejected the options"):
        model.solve(not_an_option=1)


def test_verbose_prints_the_solver_log(model, capsys):
    model.solve(verbose=True)
    assert "Clarabel" in capsys.readouterr().out


def test_reading_before_solving_and_after_a_change(model):
    """Trap: recover (or stresses) before a solve gave 'ValueError: cannot reshape array'."""
    for read in (model.stresses, model.displacements, model.solution, lambda: model.value(model.stress)):
        with pytest.raises(cd.ModelError, match="not been solved"):
            read()
    model.solve()
    model.add_constraint(model.shear_stress() <= 1e6)
    with pytest.raises(cd.ModelError, match="changed since"):
        model.stresses()
    model.solve()
    model.load_factor.value = 0.5
    with pytest.raises(cd.ModelError, match="changed since"):
        model.solution()


def test_misuse_is_refused(model):
    model.solve()
    with pytest.raises(cd.ModelError, match="solved already"):
        model.solve()
    with pytest.raises(cd.ModelError, match="cvxpy constraints"):
        model.add_constraint(True)
    with pytest.raises(cd.ModelError, match="not convex"):
        model.add_constraint(model.shear_stress() >= 1.0)
    with pytest.raises(cd.ModelError, match="Minimize"):
        model.set_objective(model.complementary_energy)
    with pytest.raises(cd.ModelError, match="non-negative"):
        model.add_friction(-1.0)
    with pytest.raises(cd.ModelError, match="per contact pair"):
        model.add_friction(np.ones(3))
    model.add_friction(100.0)
    with pytest.raises(cd.ModelError, match="set already"):
        model.add_friction(200.0)
    with pytest.raises(cd.ModelError, match="fast path"):
        model.solve("fast")


def test_load_factor_scales_the_solution(model):
    """The problem is linear in the load at a fixed contact zone only; forces scale exactly."""
    assert model.problem.is_dpp()
    model.load_factor.value = 0.25
    model.solve()
    sol = model.solution()
    fresh = cd.build_model("hertz", level=1)
    fresh.load_factor.value = 0.25
    fresh.solve()
    assert rel(sol.stress, fresh.stresses()) < SAME  # a parameter value, not a different problem
    assert sol.contact["total_force"] == pytest.approx(0.25 * 17500.0, rel=1e-8)  # loads prescribed
    assert "error" in sol.checks["skipped"] and "duality_gap" in sol.checks["applied"]
    # the contact zone shrinks with the load (Hertz: a ~ sqrt(P))
    assert sol.contact["n_active"] < cd.solve("hertz", level=1, solver="CLARABEL").contact["n_active"]


def test_adhesion_holds_open_pairs_at_the_cut_off(model):
    sigma = cp.Parameter(nonneg=True, value=0.01 * 3585.0)
    model.allow_adhesion(sigma)
    model.solve()
    sol = model.solution()
    c = sol.contact
    assert sol.checks["applied"]["duality_gap"] < 1e-6  # the primal with sigma_a * opening
    # the loads are prescribed: total force unchanged; open pairs pull at the cut-off
    assert c["total_force"] == pytest.approx(17500.0, rel=1e-8)
    open_ = ~c["active"]
    assert open_.any()
    # at the cut-off up to the interior point's complementarity: near the zone's edge the opening
    # is small, so the force keeps a slack of up to 2e-7 of the peak pressure (measured at level 1)
    assert np.abs(c["pressure"][open_] + sigma.value).max() < 1e-5 * c["max_pressure"]
    assert c["pressure"].min() >= -sigma.value * (1 + 1e-6)


def test_limit_analysis_without_yield_is_unbounded():
    model = cd.build_model("patch", level=0, limit_analysis=True)
    with pytest.raises(cd.ModelError, match="yield constraints"):
        model.solve()


def test_load_sweep_reuses_the_solver_data_only_when_it_may():
    """From the third solve the model hands the solver cached data with b = b0 + lf b1; where a
    user constraint puts load_factor into A, it must fall back to CVXPY and still be right."""
    # (constraint, tolerance): without it the cached data are the fresh compile's, bit for bit
    # (measured difference 0); with it both sides are CVXPY's own compiles (cached parameter
    # program and fresh), whose rounding differs enough for Clarabel to take 12-20 iterations and
    # to agree to 7e-7 (measured): 1e-5 is that with a margin, still far below a wrong b (O(1))
    for extra, tol in ((None, SAME), (lambda m: m.load_factor * m.stress[:, 0] <= 5000.0, 1e-5)):
        swept = cd.build_model("hertz", level=1)
        if extra:
            swept.add_constraint(extra(swept))
        for lf in (1.0, 0.5, 0.75, 0.3):
            swept.load_factor.value = lf
            swept.solve()
            fresh = cd.build_model("hertz", level=1)
            if extra:
                fresh.add_constraint(extra(fresh))
            fresh.load_factor.value = lf
            fresh.solve()
            assert rel(swept.stresses(), fresh.stresses()) < tol
            assert rel(swept.displacements(), fresh.displacements()) < tol
            assert swept.info["status"] == "optimal"


def test_small_load_factors_are_solved_or_refused_with_advice():
    """The scales are the unit load's: Clarabel's tolerances follow the load factor down, so the
    checks hold at 1e-2; far below, the solution is refused with advice, never returned."""
    model = cd.build_model("hertz", level=1)
    model.load_factor.value = 0.01
    model.solve()
    assert model.solution().checks["applied"]["duality_gap"] < 1e-6  # measured 1.5e-7
    model.load_factor.value = 1e-4
    model.solve()
    with pytest.raises(cd.AccuracyError, match="load_factor 0.0001.*tighter tolerances"):
        model.solution()
    model.solve(tol_gap_abs=1e-20, tol_gap_rel=1e-14, tol_feas=1e-16, tol_ktratio=1e-12)  # as the advice says
    assert model.solution().checks["applied"]["duality_gap"] < 1e-6


def test_equalities_and_stick_under_a_change(model):
    """A side forced to 0 is judged against the stresses' size, not its own rounding; the
    stick state is still read (from the friction reserve) when the multipliers are not displacements."""
    model.add_friction(358.5)
    model.solve()
    plain = model.solution()
    capped = cd.build_model("hertz", level=1)
    capped.add_friction(358.5)
    capped.add_constraint(capped.stress[:, 2] * 0.0 + capped.tangential_force[0] == 0.0, name="no shear at 0")
    capped.add_constraint(capped.von_mises() <= 1e6, name="inactive cap")
    capped.solve()
    sol = capped.solution()
    assert sol.checks["applied"]["user_constraints"] < 1e-6
    assert "displacement" in sol.checks["skipped"]
    assert np.array_equal(sol.contact["stick"], plain.contact["stick"]) and plain.contact["stick"].any()


def test_non_finite_and_non_numeric_inputs_are_refused(model):
    with pytest.raises(cd.ModelError, match="finite"):
        model.allow_adhesion(np.inf)
    with pytest.raises(cd.ModelError, match="text"):
        model.add_friction("1")
    model.solve()
    with pytest.raises(cd.ModelError, match="cvxpy expression"):
        model.value(model.von_mises)
    g = cp.Parameter(nonneg=True, value=np.inf)
    model.add_friction(g)
    with pytest.raises(cd.ModelError, match="non-finite"):
        model.solve()


def test_model_solution_is_complete_and_g_zero_changes_nothing(model, capsys):
    model.add_friction(0.0)  # no friction rows: the scene's own problem
    model.solve()
    model.solve(verbose=True)  # only the log asked for: allowed
    sol = model.solution()
    assert model.changes() == [] and sol.error is not None  # the exact field still applies
    assert set(sol.timings) == {"mesh", "assemble", "build", "solve", "recover", "error", "total"}
    from cvxdual.cli import human_summary
    assert "contact:" in human_summary(sol)


def test_friction_refuses_a_body_that_slides_freely():
    """Without its x support the upper block floats in x (a slip of every pair), a motion the
    frictionless model anchors at a pair's x dof; friction would change that row, so it is
    refused and the model stays frictionless."""
    import tomllib
    from pathlib import Path

    data = tomllib.loads((Path(cd.__file__).parent / "scene" / "data" / "patch.toml").read_text())
    del data["bodies"]["top"]["boundary"]["symmetry"]
    model = cd.build_model(data, level=0)
    with pytest.raises(cd.ModelError, match="slide freely"):
        model.add_friction(10.0)
    assert model.changes() == [] and set(model.constraints) == {"equilibrium", "contact"}
    model.solve()
    assert model.solution().checks["skipped"] == {}


@pytest.mark.filterwarnings("ignore:You are solving a parameterized problem that is not DPP")  # the point here
def test_cached_resolve_only_for_dpp_and_solver_options(model):
    """A constraint that is not DPP (a product of parameters) is not affine in load_factor: the
    cached right-hand side would be wrong, so such sweeps go through CVXPY; so do options that
    CVXPY itself takes."""
    lf = model.load_factor
    model.add_constraint(model.stress[:, 1] >= -0.95 * 35000.0 * (lf + lf * lf) / 2.0, name="not DPP")
    fresh = cd.build_model("hertz", level=1)
    f = fresh.load_factor
    fresh.add_constraint(fresh.stress[:, 1] >= -0.95 * 35000.0 * (f + f * f) / 2.0, name="not DPP")
    for v in (1.0, 0.5, 0.3):
        model.load_factor.value = v
        model.solve()
    fresh.load_factor.value = 0.3
    fresh.solve()
    assert rel(model.stresses(), fresh.stresses()) < 1e-5  # the same problem, CVXPY both times
    swept = cd.build_model("hertz", level=1)
    for v in (1.0, 0.5, 0.3):  # CVXPY's own keyword: never handed to Clarabel
        swept.load_factor.value = v
        swept.solve(canon_backend="SCIPY")
