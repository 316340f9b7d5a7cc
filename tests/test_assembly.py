import numpy as np
import pytest

import cvxdual as cd
from cvxdual.geometry.triangulation import discretize
from cvxdual.system.assembly import assemble


def _system(name, level=1, tri="type1"):
    return assemble(*discretize(cd.load_scene(name), tri, level))


def boundary_load_of_constant_stress(points, tris, t0):
    """Independent divergence theorem: int_dOmega phi_j (t0 n) ds from the boundary edges of
    counter-clockwise triangles (edges used once), with exact P1 traces (l/2 per end)."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    b = e[cnt[inv.ravel()] == 1]
    d = points[b[:, 1]] - points[b[:, 0]]
    n_ds = np.stack([d[:, 1], -d[:, 0]], 1)  # outward normal times length for CCW edges
    s = np.array([[t0[0], t0[2]], [t0[2], t0[1]]])
    trac = n_ds @ s.T
    f = np.zeros(2 * len(points))
    for end in (0, 1):
        for c in (0, 1):
            np.add.at(f, 2 * b[:, end] + c, 0.5 * trac[:, c])
    return f


@pytest.mark.parametrize("name", ["patch", "hertz", "blocks"])
def test_divergence_theorem_flat(name):
    s = _system(name)
    tris = s.mesh.triangles()
    for t0 in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.3, -2.0, 0.7]):
        Et = s.E @ np.tile(t0, s.n_pieces)
        ref = boundary_load_of_constant_stress(s.mesh.points, tris, np.array(t0))
        # both sides are sums of O(h) terms; 1e-12 of the largest is rounding only
        np.testing.assert_allclose(Et, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_rigid_motions_are_strain_free():
    s = _system("hertz")
    p = s.mesh.points
    L = s.mesh.scene.length_scale
    for u in (np.c_[np.ones(len(p)), 0 * p[:, 0]], np.c_[0 * p[:, 0], np.ones(len(p))],
              np.c_[-p[:, 1], p[:, 0]] / L):
        # strains of a rigid motion are rounding noise relative to 1/L
        assert np.abs(s.strains(u.ravel())).max() < 1e-12


@pytest.mark.parametrize("name,floating,separating", [("patch", 0, 1), ("hertz", 1, 1), ("blocks", 0, 1)])
def test_rigid_modes_found(name, floating, separating):
    s = _system(name)
    assert s.floating.shape[1] == floating
    assert s.separating.shape[1] == separating
    assert len(s.anchors) == floating
    # a floating mode moves both bodies together: zero relative motion at every pair
    if floating:
        np.testing.assert_allclose(s.floating[s.jb] - s.floating[s.ja], 0, atol=1e-12)


def test_hertz_loads_balance_to_quadrature_precision():
    s = _system("hertz", 2)
    # Gauss quadrature of the smooth exact tractions on the truncated boundary: imbalance is
    # at the rounding level, far below the rejection threshold
    assert s.load_imbalance < 1e-12
    Q = s.Z @ s.floating
    assert abs(Q[:, 0] @ s.f) < 1e-12 * np.abs(s.f).sum()


def test_gap_and_u0():
    s = _system("blocks")
    np.testing.assert_allclose(s.eps, s.mesh.pair_x**2 / 2000.0, rtol=1e-14)
    q0 = s.q0
    up, lo = s.mesh.pairs.T
    np.testing.assert_allclose(q0[2 * lo + 1] - q0[2 * up + 1], s.eps, rtol=1e-14)
    assert s.width.sum() == pytest.approx(20.0, rel=1e-14)


def test_energy_matches_stiffness():
    s = _system("blocks")
    q = np.random.default_rng(0).standard_normal(s.n_dofs)
    K = s.stiffness()
    assert s.energy(q) == pytest.approx(0.5 * q @ (K @ q) - s.f @ q, rel=1e-12)
    # K = E A_h^-1 E^T: check on a vector through the stresses
    t = s.stresses_from_displacement(q).ravel()
    np.testing.assert_allclose(s.E @ t, K @ q, rtol=1e-10, atol=1e-10 * np.abs(K @ q).max())


def test_separation_work_of_one_motion_matches_the_lp():
    """The closed form for one separating motion against the LP it replaces (random signs,
    zeros and mixed rows: admissible on one side, both or neither)."""
    from scipy.optimize import linprog

    from cvxdual.system.rigid import separation_work
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = rng.integers(1, 6)
        dk = rng.normal(size=(n, 1)) * rng.choice([0.0, 1.0], size=(n, 1))  # some rows exactly zero
        dk = np.abs(dk) * rng.choice([-1.0, 1.0]) if rng.random() < 0.6 else dk
        if rng.random() < 0.2:
            dk[0, 0] = 1e-17 * rng.choice([-1.0, 1.0])  # rounding-level motion: HiGHS ignores it too
        work = rng.normal(size=1)
        res = linprog(-work, A_ub=dk, b_ub=np.zeros(len(dk)), bounds=[(-1, 1)], method="highs")
        # HiGHS is exact on a one-variable LP up to its feasibility tolerance (1e-7)
        assert separation_work(work, dk) == pytest.approx(-res.fun, abs=1e-7)


def test_anchor_pivots_match_pivoted_qr():
    """The anchors' column choice equals LAPACK's column-pivoted QR (the choice it replaces)."""
    import scipy.linalg as sla

    from cvxdual.system.rigid import pivot_columns
    rng = np.random.default_rng(5)
    for m in (1, 2, 3):
        A = rng.normal(size=(m, 200)) * rng.uniform(0.1, 10, size=200)
        _, _, piv = sla.qr(A, pivoting=True, mode="economic")
        assert list(pivot_columns(A)) == list(piv[:m])


def test_lower_assembly_is_the_lower_triangle_of_the_full_one():
    """Symmetric blocks, dofs repeated inside a block (tied dofs) and dropped (negative): the
    half assembly is exactly the lower triangle of the full one."""
    import scipy.sparse as sp

    from cvxdual.linalg.sparse import assemble_blocks, assemble_lower
    rng = np.random.default_rng(7)
    B = rng.normal(size=(300, 6, 6))
    B = B + B.transpose(0, 2, 1)
    dofs = rng.integers(-1, 40, size=(300, 6))
    full = assemble_blocks(dofs, dofs, B, (40, 40))
    # the same sums in another order: rounding of a few additions of O(10) numbers
    assert abs(assemble_lower(dofs, B, 40) - sp.tril(full)).max() < 1e-12
