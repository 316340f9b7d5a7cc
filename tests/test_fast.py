"""The fast path (active set + sparse factorisation) against the CVXPY reference path."""

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import solved

import cvxdual as cd
from cvxdual.p0.norms import l2_norm

SCENES = ["patch", "hertz", "blocks", "cylinder-on-block", "cylinder-in-groove", "wavy"]


@pytest.mark.slow
@pytest.mark.parametrize("tri", ["type1", "type2"])
@pytest.mark.parametrize("scene", SCENES)
def test_fast_agrees_with_cvxpy(scene, tri):
    a = solved(scene, 2, tri)
    b = cd.solve(cd.load_scene(scene), tri, 2, "fast")
    s = a.system
    # the active-set solution is exact up to the factorisation; Clarabel stops at 1e-8
    # tolerances, which leaves about 1e-7 in the stresses at this size
    assert l2_norm(s, a.stress - b.stress) <= 1e-6 * l2_norm(s, a.stress)
    np.testing.assert_array_equal(a.contact["active"], b.contact["active"])
    # exact KKT: equilibrium and complementarity at rounding level
    assert b.residuals["equilibrium"] < 1e-10 and b.residuals["complementarity"] < 1e-10
    assert b.solver["status"] == "optimal"


@pytest.mark.slow
def test_warm_start_needs_few_iterations():
    sc = cd.load_scene("hertz")
    cold = cd.solve(sc, level=4, solver="fast", warm_start=False)
    warm = cd.solve(sc, level=4, solver="fast")
    np.testing.assert_allclose(warm.stress, cold.stress, rtol=0, atol=1e-9 * np.abs(cold.stress).max())
    # the coarse (level 2) active set, edges put halfway, is at most a pair or two off
    assert warm.solver["iterations"] <= 3 < cold.solver["iterations"]
    assert warm.solver["factorizations"] == 1


def test_no_contact_at_all():
    # a 0.01 mm offset on top of the parabolic gap, the lower block on sliding supports all
    # round and loaded by its weight-like body force only: it deforms 1e-3 mm, the gap stays open
    sc = cd.load_scene("blocks", [{"contact": {"gap": {"kind": "parabola", "R": 1000.0, "y0": 0.01}},
                                   "bodies": {"lower": {"body_force": [0.0, 1.0], "boundary": {
                                       "push": {"traction": {"value": [0.0, 0.0]}},
                                       "bottom": {"on": "far", "kind": "sliding"}}}}}])
    for solver in ("fast", "CLARABEL"):
        sol = cd.solve(sc, level=1, solver=solver)
        assert sol.contact["n_active"] == 0
        # the body force totals 200 N/mm; an interior point leaves ~1e-10 of it on open pairs
        assert abs(sol.contact["total_force"]) < 1e-9 * 200.0
        opening = sol.contact["gap"] - sol.contact["relative_displacement"]
        assert opening.min() > 0.009


def test_fast_path_with_a_free_rotating_body():
    # the upper block is loaded on top, not clamped: it may translate in x (floating: no
    # friction) and in y and rotate (separating): the fast path must keep enough pairs active
    sc = cd.load_scene("blocks", [{"bodies": {
        "upper": {"boundary": {"top": {"kind": "traction", "traction": {"kind": "uniform", "value": [0.0, -50.0]}}}},
        "lower": {"boundary": {"push": {"kind": "clamped"}}}}}])
    a = cd.solve(sc, level=2)
    assert a.system.floating.shape[1] == 1 and a.system.separating.shape[1] == 2
    for warm in (True, False):
        b = cd.solve(sc, level=2, solver="fast", warm_start=warm)
        # Clarabel's 1e-8 tolerances against the exact active-set solution
        assert l2_norm(a.system, a.stress - b.stress) <= 1e-6 * l2_norm(a.system, a.stress)
    assert a.contact["total_force"] == pytest.approx(50.0 * 20.0, rel=1e-9)


def test_unloaded_scene_gives_zero_stress():
    # zero load and zero gap: the solution is zero; the residuals must not divide noise by zero
    sc = cd.load_scene("patch", [{"bodies": {"top": {"boundary": {"pressure": {"traction": {"value": [0.0, 0.0]}}}}}}])
    for solver in ("fast", "CLARABEL"):
        sol = cd.solve(sc, level=1, solver=solver)
        assert np.abs(sol.stress).max() < 1e-6  # MPa; 1e-8 of the scene's stress scale
        assert sol.contact["n_active"] == 0


def test_every_factorisation_backend_solves_the_stiffness():
    """The backends the fast path and the speed "limit" choose between solve an SPD stiffness
    for one and several right-hand sides; the limit reports the fastest of them."""
    from cvxdual.linalg.factor import LARGE_FROM, SPDFactor, backend, backends
    from cvxdual.system.displacement import limit
    system = cd.build_system("hertz", "type1", 2)
    lim = limit(system)
    assert lim["backend"] in backends() and lim["t_limit"] == min(lim[f"t_limit_{b}"] for b in backends())
    # the stiffness on the free dofs, its rigid motions lifted by a small shift: SPD, the
    # fast path's sparsity and (up to the shift) its conditioning
    Kr = (system.Z.T @ system.stiffness() @ system.Z).tocsr()
    K = Kr + 1e-3 * Kr.diagonal().mean() * sp.eye(Kr.shape[0], format="csr")
    rng = np.random.default_rng(0)
    B = rng.normal(size=(K.shape[0], 3))
    for m in backends():
        f = SPDFactor(K, m)
        X, x = f.solve(B), f.solve(B[:, 0])
        # a direct factorisation is backward stable: residual ~ n eps |K| |X|; 1e-12 leaves ~1e4 eps
        assert np.abs(K @ X - B).max() <= 1e-12 * abs(K).sum(axis=1).max() * np.abs(X).max()
        np.testing.assert_allclose(x, X[:, 0], rtol=0, atol=1e-12 * np.abs(X).max())
        f.close()
    # CHOLMOD at every size where it loads (reports/factor_small.md), else SuperLU for small systems
    assert backend(10) == backend(LARGE_FROM) == ("cholmod" if "cholmod" in backends() else "superlu")


def test_every_backend_refuses_a_singular_stiffness():
    """An unanchored floating mode makes the stiffness singular: every backend (SuperLU and QDLDL
    factor without pivoting, so they check their pivots) refuses it instead of solving."""
    from cvxdual.linalg.factor import SPDFactor, backends
    s = cd.build_system("hertz", "type1", 0)
    K = (s.Z.T @ s.stiffness() @ s.Z).tocsr()
    for m in backends():
        with pytest.raises(cd.SolverError, match="could not be factorised"):
            SPDFactor(K, m)


@pytest.mark.parametrize("method", ["cholmod", "pardiso"])
def test_fast_path_on_the_large_backends_agrees_with_cvxpy(monkeypatch, method):
    """The large meshes' backends (taking the lower triangle) on a small mesh: the same stresses
    as Clarabel, as the default backend gives."""
    import cvxdual.linalg.factor as factor
    if method not in factor.backends():
        pytest.skip(f"{method} is not installed here")
    monkeypatch.setattr(factor, "backend", lambda n=None: method)  # as above LARGE_FROM
    sol = cd.solve("cylinder-in-groove", "type2", 1, "fast", fallback=False)
    assert sol.solver["backend"] == method
    ref = solved("cylinder-in-groove", 1, "type2")
    # Clarabel's interior point stops at ~1e-8 relative gaps: stresses agree to ~1e-7
    assert l2_norm(sol.system, sol.stress - ref.stress) <= 1e-6 * l2_norm(ref.system, ref.stress)


def test_backend_by_size_and_what_is_installed(monkeypatch):
    """The size table (cvxdual/linalg/factor.py): CHOLMOD at every size; where CVXOPT cannot be
    loaded, SuperLU below LARGE_FROM unknowns and above Pardiso where the optional `pardiso` extra is
    installed, or SuperLU where it is not. Checked with CHOLMOD hidden; the solve then uses the backend
    named."""
    import cvxdual.linalg.factor as factor
    monkeypatch.setattr(factor, "_has_cholmod", lambda: False)
    expected = "pardiso" if factor._pypardiso() is not None else "superlu"  # noqa: SLF001 - what is installed
    assert factor.backend(factor.LARGE_FROM - 1) == "superlu"
    assert factor.backend(factor.LARGE_FROM) == expected
    sol = cd.solve("hertz", "type1", 3, "fast", fallback=False)  # 1e4 free dofs: above LARGE_FROM
    assert sol.system.n_r >= factor.LARGE_FROM and sol.solver.backend == expected
