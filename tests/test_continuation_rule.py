"""The quadrature on the exact continuation pieces beyond free arcs (``Mesh.continuation_rule``,
:mod:`cvxdual.geometry.outline.quadrature`): its rows are ``Mesh.continuation()``'s pieces on a
real outline scene, and it integrates the polynomials of degree 2 exactly on synthetic pieces of
both kinds (against scipy's adaptive quadrature in Cartesian coordinates), and a wrong radius shows."""

import math

import numpy as np
import pytest
from scipy.integrate import dblquad

from cvxdual.geometry.mesh import build_mesh
from cvxdual.geometry.outline import ContinuationRule, continuation_rule
from cvxdual.scene import load_scene

# punch-on-block: the punch's rounded corners are convex free arcs (segments), the block's notch and
# hole concave ones (corners); at level 0 two of the punch's triangles have three nodes on one arc
PUNCH = "examples/punch-on-block.toml"
MONOMIALS = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]  # x^i y^j: every polynomial of degree <= 2


@pytest.fixture(scope="module", params=[0, 1])
def punch(request):
    mesh = build_mesh(load_scene(PUNCH), request.param)
    arc = np.concatenate([bm.rest.virtual_arc for bm in mesh.bodies])
    return mesh, arc


def test_arcs_are_the_outline_circles_and_read_only(punch):
    mesh, arc = punch
    nodes, _, body = mesh.continuation()
    assert arc.shape == (len(nodes), 3)
    assert {tuple(a) for a in arc[body == 0]} == {(4.0, 6.0, 6.0), (-4.0, 6.0, 6.0)}  # the punch's corners
    assert {tuple(a) for a in arc[body == 1]} == {(0.0, -25.0, 3.0), (0.0, -12.0, 2.0)}  # notch, hole
    for bm in mesh.bodies:
        assert not bm.rest.virtual_arc.flags.writeable and not bm.rest.virtual_ends.flags.writeable
        # each piece's ends are on its arc: to rounding (1e-14 of r: coordinates of size 30 round at 4e-15)
        ends = mesh.points[bm.offset + bm.rest.virtual_ends]
        dist = np.linalg.norm(ends - bm.rest.virtual_arc[:, None, :2], axis=2)
        np.testing.assert_allclose(dist, np.broadcast_to(bm.rest.virtual_arc[:, 2:], dist.shape), rtol=1e-14)


def test_rule_areas_are_the_continuation_weights(punch):
    """Each row's weights sum to its piece's area. A segment's weight is that area. A corner's is the
    triangle of its three polygon vertices (section 9 of docs/theory.md: it covers the corner), which
    is the corner piece (the rule's region: between the arc and the tangents) plus the circular
    segment inside the chord, 0.5 r^2 (2 h - sin 2 h) for the half-angle h."""
    mesh, arc = punch
    nodes, weight, body = mesh.continuation()
    rule = mesh.continuation_rule()
    assert isinstance(rule, ContinuationRule)
    assert rule.points.shape == (len(nodes), 48, 2) and rule.weights.shape == (len(nodes), 48)
    area = rule.weights.sum(axis=1)
    segment, corner = body == 0, body == 1
    assert segment.any() and corner.any()
    # 1e-12: both sides lose about eps / h^2 (a thin piece's area from its corners' rounded coordinates;
    # 0.5 r^2 (d - sin d)), h >= pi / 64 here: 1e-13 seen at level 2
    np.testing.assert_allclose(area[segment], weight[segment], rtol=1e-12, atol=0)
    p = mesh.points[nodes[corner]]
    h = np.arcsin(0.5 * np.linalg.norm(p[:, 2] - p[:, 0], axis=1) / arc[corner, 2])
    inside_chord = 0.5 * arc[corner, 2] ** 2 * (2 * h - np.sin(2 * h))
    np.testing.assert_allclose(area[corner] + inside_chord, weight[corner], rtol=1e-12, atol=0)
    assert np.all(area[corner] < weight[corner])


def test_rule_points_lie_in_their_pieces(punch):
    """Segments inside the circle, corners outside it (1e-14 of r: rounding), and where one triangle
    carries two chords (its three nodes on the arc, two equal rows) its rows cover both."""
    mesh, arc = punch
    nodes, _, body = mesh.continuation()
    rule = mesh.continuation_rule(4)
    rel = np.linalg.norm(rule.points - arc[:, None, :2], axis=2) / arc[:, 2:] - 1
    assert np.all(rel[body == 0] < 1e-14) and np.all(rel[body == 1] > -1e-14)
    _, group, count = np.unique(nodes, axis=0, return_inverse=True, return_counts=True)
    twins = [np.flatnonzero(group.ravel() == g) for g in np.flatnonzero(count == 2)]
    assert len(twins) == (2 if mesh.level == 0 else 0) and not np.any(count > 2)
    for i, j in twins:
        z = [(rule.points[k] - arc[k, :2]) @ [1, 1j] for k in (i, j)]
        angle = [np.angle(zk / (z[0].mean() + z[1].mean())) for zk in z]  # about the pair's middle: no cut
        assert angle[0].max() < angle[1].min() or angle[1].max() < angle[0].min()  # apart, not one chord twice


def test_rule_without_free_arcs_is_empty():
    rule = build_mesh(load_scene("patch"), 0).continuation_rule(5)
    assert rule.points.shape == (0, 20, 2) and rule.weights.shape == (0, 20)


# --- synthetic pieces: a circle of radius 2 about (0.3, -0.7)

CENTRE, R = np.array([0.3, -0.7]), 2.0
# (start angle, chord angle in degrees): pieces from 5 to 60 degrees; from 2.9 rad the larger ones
# cross the angle pi (atan2's cut); no moment is near zero there, so relative errors mean something
PIECES = [(s, d) for s in (0.5, 2.9) for d in (5.0, 20.0, 45.0, 60.0)]


def synthetic(radius=R):
    """Both kinds of piece on every chord of PIECES, in one rule: segments, then corners."""
    start = np.array([s for s, _ in PIECES] * 2)
    end = start + np.radians([d for _, d in PIECES] * 2)
    a = CENTRE + R * np.stack([np.cos(start), np.sin(start)], 1)
    b = CENTRE + R * np.stack([np.cos(end), np.sin(end)], 1)
    arc = np.tile([*CENTRE, radius], (len(a), 1))
    return continuation_rule(a, b, arc, np.repeat([False, True], len(PIECES)))


def moments(rule: ContinuationRule) -> np.ndarray:
    x, y = rule.points[..., 0], rule.points[..., 1]
    return np.stack([(rule.weights * x**i * y**j).sum(axis=1) for i, j in MONOMIALS], 1)


def cartesian(start: float, degrees: float, corner: bool, i: int, j: int) -> float:
    """The integral of ``x^i y^j`` over the piece by scipy's dblquad, in Cartesian coordinates ``(u, v)``
    along and across the piece's bisector (a rotation: unit Jacobian). Segment: ``r cos h <= u <= r``,
    ``|v| <= sqrt(r^2 - u^2)``. Corner: outside the circle, inside the tangents
    ``u cos h + |v| sin h <= r``, split at ``u = r`` where the circle's bound ends."""
    h = 0.5 * math.radians(degrees)
    beta = start + h
    cb, sb = math.cos(beta), math.sin(beta)

    def f(v, u):
        x, y = CENTRE[0] + u * cb - v * sb, CENTRE[1] + u * sb + v * cb
        return x**i * y**j

    def circle(u):
        return math.sqrt(max(R * R - u * u, 0.0))

    def tangent(u):
        return (R - u * math.cos(h)) / math.sin(h)

    tight = {"epsabs": 0.0, "epsrel": 1e-13}
    if not corner:
        return dblquad(f, R * math.cos(h), R, lambda u: -circle(u), circle, **tight)[0]
    upper = dblquad(f, R * math.cos(h), R, circle, tangent, **tight)[0]
    lower = dblquad(f, R * math.cos(h), R, lambda u: -tangent(u), lambda u: -circle(u), **tight)[0]
    beyond = dblquad(f, R, R / math.cos(h), lambda u: -tangent(u), tangent, **tight)[0]
    return upper + lower + beyond


@pytest.fixture(scope="module")
def reference():
    return np.array([[cartesian(s, d, corner, i, j) for i, j in MONOMIALS]
                     for corner in (False, True) for s, d in PIECES])


def test_rule_is_exact_for_quadratics(reference):
    """1e-10 relative: the rule is exact in the radius and converges geometrically in the angle
    (worst piece, 60 degrees: 4e-13 at 8 points a half, unchanged from 12 to 16 at 8e-14, dblquad's own
    error, asked for 1e-13); a thousand times that leaves room for other platforms' rounding."""
    rel = np.abs(moments(synthetic()) / reference - 1)
    assert rel.max() <= 1e-10, rel.max()


def test_a_wrong_radius_fails(reference):
    """The same pieces on a circle 1e-6 too large: every moment is off by more than the 1e-10 above
    (the area alone changes by 2e-6), so the exactness test would catch it."""
    rel = np.abs(moments(synthetic(R * (1 + 1e-6))) / reference - 1)
    assert rel.min() > 1e-10, rel.min()
