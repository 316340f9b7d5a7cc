import numpy as np
import pytest

import cvxdual as cd
from cvxdual.geometry.mesh import build_mesh, graded_points


def test_graded_points_nested_and_halving():
    # each level splits every interval of the previous one: nested points, h halves
    p = [graded_points(0.0, 30.0, 6, L, (0.0, 8.0), 6.0, [8.0]) for L in range(4)]
    for a, b in zip(p[:-1], p[1:], strict=True):
        assert len(b) == 2 * len(a) - 1
        np.testing.assert_allclose(b[::2], a, rtol=0, atol=1e-12)
        # the graded map is smooth, so halving in xi halves the largest interval up to O(h) changes
        assert 0.4 < np.diff(b).max() / np.diff(a).max() < 0.6
    d = np.diff(p[-1])
    assert d.max() / d.min() == pytest.approx(6.0, rel=0.25)  # grading ratio, up to the xi discretisation


@pytest.mark.parametrize("name", ["patch", "hertz", "blocks"])
def test_column_mesh_pairs_and_areas(name):
    scene = cd.load_scene(name)
    mesh = build_mesh(scene, 1)
    up, lo = mesh.pairs.T
    np.testing.assert_array_equal(mesh.points[up, 0], mesh.points[lo, 0])
    assert np.all(np.diff(mesh.pair_x) > 0)
    a, b = scene.contact
    assert mesh.pair_x[0] == pytest.approx(a) and mesh.pair_x[-1] == pytest.approx(b)
    # flat faces: the triangles tile each rectangle exactly
    p = mesh.points[mesh.triangles()]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    assert np.all(area > 0)
    exact = sum((bd.x_range[1] - bd.x_range[0]) * abs(bd.far - bd.face.y0) for bd in scene.bodies)
    assert area.sum() == pytest.approx(exact, rel=1e-13)


def test_level_must_be_non_negative():
    with pytest.raises(cd.MeshError, match="level"):
        build_mesh(cd.load_scene("patch"), -1)
