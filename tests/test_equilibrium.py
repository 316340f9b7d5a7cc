"""The equilibrium (Johnson-Mercier) stress space and the certified bounds (docs/equilibrium.md)."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import cvxdual as cd
from cvxdual.eq.balance import make_exact, rigid_motions
from cvxdual.eq.bounds import (
    admissibility_residuals,
    admissible_displacement,
    certified_bounds,
    constraint_blocks,
    contact_slack,
    exact_errors,
)
from cvxdual.eq.element import (
    MASS0,
    REF_DIV,
    REF_DIVFREE,
    REF_ENERGY,
    divergence_rows,
    divergence_to_reference,
    edge_blocks,
    edge_dof_rows,
    energy_coefficients,
    internal_rows,
    inverse2,
    least_norm_basis,
    local_basis,
    piola,
    reference_energy,
)
from cvxdual.eq.model import EquilibriumModel
from cvxdual.eq.space import EquilibriumSpace
from cvxdual.geometry.triangles import bary_gradients, sub_vertices
from cvxdual.system.boundary import supports

# Every constraint is exact to rounding: values ~1e-14 relative are measured (double precision
# times the O(10-100) terms of a row); 1e-12 leaves a margin of 10-100.
EXACT = 1e-12


@functools.lru_cache(maxsize=None)
def eq(scene: str, level: int):
    space = EquilibriumSpace.from_scene(cd.load_scene(scene), level)
    model = EquilibriumModel(space)
    model.solve()
    return space, model


@functools.lru_cache(maxsize=None)
def p0(scene: str, level: int):
    return cd.solve(cd.load_scene(scene), "type1", level, solver="fast")


@functools.lru_cache(maxsize=None)
def bounds(scene: str, level: int):
    space, model = eq(scene, level)
    return certified_bounds(space, model.stresses(), p0(scene, level).displacement)


# -- the element -----------------------------------------------------------------------------

def test_local_counts_and_basis_exact():
    """27 vertex values - 12 independent internal conditions = 15 = 12 edge dofs + 3 bubbles;
    the divergence maps the 15 onto the 6 sub-triangle constants (9 self-equilibrated modes)."""
    space = EquilibriumSpace.from_scene(cd.load_scene("hertz"), 0)
    X = space.X
    ng = space.edges["ng"][space.edges["id"]]
    s_int = np.linalg.svd(internal_rows(X), compute_uv=False)
    # rank decisions: the smallest kept singular value is >1e-3 of the largest, dropped ones are 0
    assert np.all(s_int[:, -1] > 1e-3 * s_int[:, 0])  # 12 independent internal conditions
    Q = piola(X)
    N = local_basis(Q, inverse2(edge_blocks(Q, ng)))  # the reference basis, mapped (no ties)
    assert N.shape == (space.n_tri, 27, 15)
    assert np.abs(internal_rows(X) @ N).max() < 1e-13  # no internal jump: rounding only
    D = edge_dof_rows(ng) @ N
    assert np.abs(D - np.eye(12, 15)[None]).max() < 1e-13  # dual to the edge dofs, bubbles carry none
    s_div = np.linalg.svd(divergence_rows(X)[0] @ N, compute_uv=False)
    assert np.all(s_div[:, -1] > 1e-3 * s_div[:, 0])  # div onto R^6 on every triangle
    # the same space as the one solved for directly (SVD of the 24 conditions, triangle by
    # triangle): the edge columns differ by bubbles only, the bubbles span the same space
    N0 = least_norm_basis(X, ng)
    bub = N0[:, :, 12:]
    coef = np.linalg.solve(bub.transpose(0, 2, 1) @ bub, bub.transpose(0, 2, 1) @ (N - N0))
    assert np.abs(bub @ coef - (N - N0)).max() < 1e-12 * np.abs(N).max()  # rounding of O(1) values


def test_reference_templates_give_every_triangles_energy_and_equilibrium():
    """Mapped by the double Piola map, the reference element's six energy templates give each
    triangle's energy matrix (assembled here from its own basis and P1 mass matrices), its nine
    self-equilibrated fields have no divergence, and divergence rows map as ``J / det J``."""
    space = EquilibriumSpace.from_scene(cd.load_scene("cylinder-on-block"), 0, "type2")
    X, Q, C = space.X, space.piola, space.coef
    N = space.local_basis()
    A = np.stack([b.material.compliance for b in space.scene.bodies])[space.body]
    _, sub_area = bary_gradients(sub_vertices(X))
    K9 = (MASS0[None, :, None, :, None] * A[:, None, :, None, :]).reshape(-1, 9, 9)
    H = sum(sub_area[:, i, None, None] * (N[:, 9 * i: 9 * i + 9].transpose(0, 2, 1) @ K9 @ N[:, 9 * i: 9 * i + 9])
            for i in range(3))
    coef = energy_coefficients(Q, A, np.abs(bary_gradients(X)[1]))
    Cf = np.zeros((space.n_tri, 15, 15))  # parameters -> reference parameters
    for k in range(6):
        Cf[:, 2 * k: 2 * k + 2, 2 * k: 2 * k + 2] = C[:, k]
    Cf[:, 12:, 12:] = np.eye(3)
    H_ref = Cf.transpose(0, 2, 1) @ reference_energy(coef, REF_ENERGY) @ Cf
    untied = np.setdiff1d(np.arange(space.n_tri), space.edges["owner"][space.face_edge, 0])
    scale = np.abs(H).max((1, 2))[:, None, None]
    # the same integrals, summed in another order: rounding (measured ~1e-15 relative)
    assert np.abs(H_ref - H)[untied].max() / scale[untied].max() < 1e-12
    D = inverse2(C[untied])  # the untied triangles' edge-dof blocks
    Z = np.concatenate([(D @ REF_DIVFREE[:12].reshape(6, 2, 9)[None]).reshape(-1, 12, 9),
                        np.broadcast_to(REF_DIVFREE[12:], (len(untied), 3, 9))], 1)
    B = divergence_rows(X[untied])[0] @ N[untied]
    assert np.abs(B @ Z).max() < 1e-12 * np.abs(B).max()  # self-equilibrated to rounding
    z = np.random.default_rng(0).standard_normal((len(untied), 15))
    zr = np.einsum("tij,tj->ti", Cf[untied], z)
    g = np.einsum("tij,tj->ti", B, z)
    assert np.abs(divergence_to_reference(X[untied], g) - zr @ REF_DIV.T).max() < 1e-12 * np.abs(g).max()


@pytest.mark.parametrize("scene,tri,floating", [("patch", "type1", 0), ("hertz", "type1", 1), ("blocks", "type1", 0),
                                                ("cylinder-on-block", "type1", 0), ("wavy", "type1", 0),
                                                ("wavy", "type2", 0)])
def test_no_spurious_modes(scene, tri, floating):
    """All equality conditions on the field (internal and shared traction jumps, divergence,
    boundary tractions, the face edges' ties to the columns, contact tangential tractions,
    action = reaction) have rank rows - m, m the rigid motions of both bodies that keep them in
    contact (hertz: the common vertical translation). Equivalently the displacement multipliers
    are unique up to those motions: no spurious kinematic mode (the columns add none), and the
    reduced div system has the same defect."""
    space = EquilibriumSpace.from_scene(cd.load_scene(scene), 0, tri)
    assert rigid_motions(space.mesh, joint=True).shape[2] == floating
    blocks = constraint_blocks(space)
    M = sp.vstack([m for m, _, sense in blocks.values() if sense == "=="]).tocsr()
    for G in (M @ M.T, space.div @ space.stress_map):
        G = (G @ G.T if G.shape[0] != G.shape[1] else G).tocsc()
        scale = abs(G).max()
        # the floating + 1 smallest eigenvalues (shift-invert just below 0: G is semi-definite)
        ev = spla.eigsh(G, k=floating + 1, sigma=-1e-9 * scale, which="LM", return_eigenvectors=False) / scale
        # measured: zero eigenvalues ~1e-17, the next ~1e-6 (level 0): 1e-12 splits them safely
        assert np.sum(np.abs(ev) < 1e-12) == floating


# -- patch test ------------------------------------------------------------------------------

@pytest.mark.parametrize("level", [1, 2, 3])
def test_patch_exact(level):
    space, model = eq("patch", level)
    sig = model.stresses()
    exact = cd.exact_field(space.scene)
    err = exact_errors(space, sig, p0("patch", level).displacement, exact, n=2)
    assert err["l2_rel"] < 1e-8  # the uniform stress is in the space: only the solver's 1e-8 tolerance remains
    b = bounds("patch", level)
    assert b["guaranteed"], b["reasons"]
    # G is the square of the solver error (~1e-9) plus rounding: 1e-10 of the energy has margin 100
    assert 0 <= b["gap"] <= 1e-10 * b["complementary_energy"]
    assert b["energy_lower"] <= b["energy_upper"]


# -- exactness of the admissibility ------------------------------------------------------------

@pytest.mark.parametrize("scene", ["hertz", "blocks"])
def test_every_constraint_exact_after_post_step(scene):
    space, model = eq(scene, 1)
    res = admissibility_residuals(space, model.stresses())
    assert set(res) == {"internal", "divergence", "shared", "traction", "contact_tangential", "column_tie",
                        "column_fixed", "action_reaction", "sign"}  # the column blocks are empty on flat faces
    assert max(res.values()) < EXACT, res
    # the post-step repairs a solution 1e-7 off (a loose solver): perturb and restore
    rng = np.random.default_rng(0)
    y = model.y_exact + 1e-7 * space.scales.stress * rng.standard_normal(space.n_y)
    ci = space.contact_y.ravel()
    active = y[ci] < -1e-3 * space.scales.stress
    y[ci[~active]] = 1e-7 * space.scales.stress  # inactive ends pushed into tension
    bad = admissibility_residuals(space, space.stress_map @ y + space.sigma0)
    assert bad["divergence"] > 1e-9 and bad["sign"] > 1e-9  # the perturbation is visible
    fixed, info = make_exact(space, y)
    good = admissibility_residuals(space, space.stress_map @ fixed + space.sigma0)
    assert max(good.values()) < EXACT, good
    assert np.all(fixed[ci] <= 0)
    assert info["max_change"] < 1e-5  # relative: the repair is of the size of the perturbation


@pytest.mark.parametrize("scene,tri", [("hertz", "type1"), ("cylinder-on-block", "type2")])
def test_local_residuals_agree_with_the_assembled_rows(scene, tri):
    """The internal-jump and divergence residuals evaluated triangle by triangle equal those of
    the assembled constraint rows (two implementations), on an exact and on a perturbed field."""
    space = EquilibriumSpace.from_scene(cd.load_scene(scene), 1, tri)
    blocks = constraint_blocks(space)
    rng = np.random.default_rng(1)
    y = rng.standard_normal(space.n_y) * space.scales.stress
    g = space.column_values(y)
    noise = 1e-6 * space.scales.stress * rng.standard_normal((space.n_tri, 27))
    for sigma in (space.vertex_values(y), space.vertex_values(y) + noise):
        full = admissibility_residuals(space, sigma, blocks, g)
        fast = admissibility_residuals(space, sigma, g=g)
        assert set(full) == set(fast)
        for name in full:
            # the same sums in another order: rounding of O(1) residuals relative to the stress scale
            assert fast[name] == pytest.approx(full[name], rel=1e-9, abs=1e-13), name
    assert fast["internal"] > 1e-8  # the perturbation shows


# -- the bounds ------------------------------------------------------------------------------

@pytest.mark.parametrize("scene", ["hertz", "blocks"])
def test_hypercircle_identity(scene):
    b = bounds(scene, 1)
    c = b["contributions"]
    assert np.all(c["sub"] >= 0) and np.all(c["contact"] >= 0)  # both terms are non-negative
    # J(v) + L(u0) + S(sigma) against the two-term form: cancellation of O(|J|) terms, so the
    # agreement is judged relative to |J| (rounding ~1e-15; admissibility ~1e-14)
    assert abs(b["gap_identity"] - b["gap"]) < 1e-10 * abs(b["energy_upper"])
    assert b["energy_lower"] <= b["energy_upper"]
    assert b["guaranteed"] == (scene == "blocks")  # hertz: its exact tractions are not linear on edges
    if scene == "hertz":
        assert b["data_oscillation"] > 0 and "oscillation" in b["reasons"][0]


def test_displacement_made_pointwise_admissible():
    space, _ = eq("hertz", 1)
    u = p0("hertz", 1).displacement
    x = np.linspace(*space.scene.contact, 20001)
    up, lo = space.mesh.pairs.T

    def slack(v):
        jump = np.interp(x, space.mesh.pair_x, v[lo, 1] - v[up, 1])
        return space.scene.gap_at(x) - jump

    assert slack(u).min() < -1e-4  # the trap: the chord of a convex gap lies above it
    v, info = admissible_displacement(space, u)
    assert slack(v).min() >= 0 and contact_slack(space, v)[1].min() >= 0
    fixed = supports(space.mesh).fixed
    assert np.array_equal(v[fixed], u[fixed])  # supports untouched: v stays in V
    # the largest shift is the deepest penetration, up to the 1e-13 margin v keeps below the gap
    assert info["max_shift"] == pytest.approx(-info["min_slack_before"], rel=1e-6)


@functools.lru_cache(maxsize=None)
def hertz_energy():
    """``J(u) = -(1/2 (A lam*, lam*) + int p* eps)``, the first by quadrature on level 2, the
    second in closed form: ``int_0^a p0 sqrt(1 - x^2/a^2) x^2/(2R) dx = pi p0 a^3 / (32 R)``."""
    space, model = eq("hertz", 2)
    ex = cd.exact_field(space.scene)
    e = exact_errors(space, model.stresses(), p0("hertz", 2).displacement, ex, n=8)
    h = ex.hertz
    return -(0.5 * e["reference_A"] ** 2 + np.pi * h.p0 * h.a**3 / (32 * h.R))


@pytest.mark.parametrize("level", [0, 1, 2])
def test_hertz_errors_and_bounds(level):
    space, model = eq("hertz", level)
    b = bounds("hertz", level)
    ex = cd.exact_field(space.scene)
    e = exact_errors(space, model.stresses(), b["displacement"], ex)
    assert b["gap"] >= 0
    assert e["l2_rel"] < p0("hertz", level).error["l2_rel"]  # measured: 4x (level 0) to 9x (level 2) smaller
    # sqrt(2G) bounds sqrt(||u - v||_a^2 + ||sigma - lam*||_A^2), with ||u - v||_a = ||lam* - C e(v)||_A
    # computed from the exact stress alone; measured effectivity 1.09-1.12, so the bound is not
    # loose enough to hide an error. (Strictly it bounds the problem with projected tractions;
    # their oscillation is 1e-2 of the bound at level 0 and falls like h^2.5.)
    assert e["combined"] <= b["error_bound"] <= 1.5 * e["combined"]
    J = hertz_energy()
    # the bracket must contain J(u); its width (> 40) dwarfs the quadrature error of J (< 0.02)
    assert b["energy_lower"] <= J <= b["energy_upper"]


def test_unbalanced_loads_refused():
    """hertz floats vertically: replacing the exact traction on the cylinder's top by a uniform
    pull leaves the loads unbalanced on that motion, which no stress field can carry."""
    from dataclasses import replace

    from cvxdual.errors import UnbalancedLoadError
    scene = cd.load_scene("hertz")
    up = scene.upper
    parts = tuple(replace(p, traction=cd.Traction("uniform", (0.0, -2000.0))) if p.on == "far" else p
                  for p in up.boundary)
    bad = replace(scene, bodies=(replace(up, boundary=parts), scene.lower))
    with pytest.raises(UnbalancedLoadError, match="unbalanced"):
        EquilibriumSpace.from_scene(bad, 0)
    assert EquilibriumSpace.from_scene(scene, 0).load_imbalance < 1e-12  # quadrature rounding only


def test_loads_doing_no_work_on_a_floating_motion_balance():
    """The upper block of ``blocks`` loaded only vertically and free to slide sideways (frictionless
    contact, no support in x): the loads do no work on the slide. The balance check measured that
    rounding against the rounding of the loads' own contributions (0.42 "relative work") and the
    eq space refused the scene; it is now measured against all the loads. A real sideways load,
    1e-3 of the vertical one, is still refused in both spaces."""
    top = {"on": "far", "kind": "traction", "traction": {"value": [0.0, -50.0]}}
    over = {"contact": {"interval": [-6.0, 6.0]},
            "bodies": {"lower": {"boundary": {"push": {"on": "far", "kind": "sliding"}}},
                       "upper": {"boundary": {"top": top}}}}
    scene = cd.load_scene("blocks", [over])
    sol = cd.solve(scene, level=2, stress_space="eq", solver="fast")
    # rounding over 1e-8 of all the loads' work (rigid.ROUNDING): 3e-10 seen, far under BALANCE_TOL
    assert sol.bounds["guaranteed"] and sol.space.load_imbalance <= 1e-8
    p0 = cd.solve(scene, level=2, solver="fast")
    # the upper block's balance: the contact carries its load, 50 over 20 mm, to rounding
    assert p0.contact["force"].sum() == pytest.approx(1000.0, rel=1e-12)
    sideways = {"bodies": {"upper": {"boundary": {"top": {"traction": {"value": [0.05, -50.0]}}}}}}
    for space in ("p0", "eq"):
        with pytest.raises(cd.UnbalancedLoadError):
            cd.solve(cd.load_scene("blocks", [over, sideways]), level=2, stress_space=space, solver="fast")
