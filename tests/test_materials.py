import numpy as np
import pytest

from cvxdual import Material, SceneError


def test_plane_strain_matches_lame():
    E, nu = 200.0, 0.3
    m = Material.isotropic(E, nu, "strain")
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    np.testing.assert_allclose(m.stiffness, [[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]], rtol=1e-14)
    # compliance: e11 = (1 - nu^2)/E s11 - nu (1 + nu)/E s22 in plane strain
    A = m.compliance
    assert A[0, 0] == pytest.approx((1 - nu**2) / E, rel=1e-13)
    assert A[0, 1] == pytest.approx(-nu * (1 + nu) / E, rel=1e-13)
    assert A[2, 2] == pytest.approx(2 * (1 + nu) / E, rel=1e-13)


def test_plane_stress_compliance():
    E, nu = 70.0, 0.25
    A = Material.isotropic(E, nu, "stress").compliance
    np.testing.assert_allclose(A, [[1 / E, -nu / E, 0], [-nu / E, 1 / E, 0], [0, 0, 2 * (1 + nu) / E]], rtol=1e-13)


def test_hooke_matrix_accepted_and_checked():
    C = Material.isotropic(10.0, 0.2).stiffness
    assert np.allclose(Material.hooke(C).stiffness, C)
    with pytest.raises(SceneError, match="symmetric"):
        Material.hooke(C + np.triu(np.ones((3, 3)), 1))
    with pytest.raises(SceneError, match="positive definite"):
        Material.hooke(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(SceneError, match="3x3"):
        Material.hooke(np.eye(2))


@pytest.mark.parametrize("E,nu,plane,match", [
    (1.0, 0.5, "strain", "Poisson"),
    (1.0, 0.7, "stress", "Poisson"),
    (1.0, -1.0, "strain", "Poisson"),
    (0.0, 0.3, "strain", "positive"),
    (-5.0, 0.3, "strain", "positive"),
    (float("nan"), 0.3, "strain", "finite"),
    (1.0, float("inf"), "strain", "finite"),
    (1.0, 0.3, "3d", "plane"),
])
def test_bad_materials(E, nu, plane, match):
    with pytest.raises(SceneError, match=match):
        Material.isotropic(E, nu, plane)
