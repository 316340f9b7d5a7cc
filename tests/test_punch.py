"""The rounded flat punch: its closed form (Ciavarella, Hills and Monno) against Hertz and against
itself, the Flamant superposition against McEwen's closed form, the composite face profile, and
both rounded-punch scenes: the linearised one against the closed form, the true geometry by
agreement of the spaces and triangulations."""

import numpy as np
import pytest
from scipy.integrate import quad

import cvxdual as cd
from cvxdual.geometry.triangulation import discretize
from cvxdual.reference.exact import exact_field
from cvxdual.reference.hertz import body_stress as mcewen
from cvxdual.reference.hertz import hertz_line_contact
from cvxdual.reference.punch import punch_body_stress, punch_contact, punch_load, punch_pressure
from cvxdual.scene.piecewise import Composite, Punch

HERTZ = hertz_line_contact(70000.0, 0.3, 210000.0, 0.3, 50.0, 35000.0)


def test_a_flat_of_width_zero_is_hertz():
    d = punch_contact(0.0, 50.0, HERTZ.E_star, 35000.0)
    assert d.a == pytest.approx(HERTZ.a, rel=1e-13)  # the same closed form, through a root finder
    x = np.linspace(-1.2 * HERTZ.a, 1.2 * HERTZ.a, 101)
    p_h = HERTZ.p0 * np.sqrt(np.maximum(1 - (x / HERTZ.a) ** 2, 0.0))
    assert np.allclose(punch_pressure(x, d), p_h, rtol=0, atol=1e-12 * HERTZ.p0)


def test_flamant_superposition_is_mcewen():
    """Two independent forms of the Hertz field: the integral of Flamant's kernel over the
    pressure (b = 0) and McEwen's closed form. 1e-8 p0: the quadrature is exact to ~1e-10 below
    1e-5 mm (measured 7e-10); the shallowest points (1e-6 mm) to 3e-8."""
    d = punch_contact(0.0, 50.0, HERTZ.E_star, 35000.0)
    rng = np.random.default_rng(1)
    x, depth = rng.uniform(-20, 20, 4000), 10 ** rng.uniform(-5, 1.5, 4000)
    for upper in (True, False):
        y = depth if upper else -depth
        got = punch_body_stress(x, y, d, 0.0, 0.0, upper)
        want = mcewen(x, y, HERTZ.a, HERTZ.p0, x_c=0.0, y_face=0.0, upper=upper)
        assert np.abs(got - want).max() <= 1e-8 * HERTZ.p0


def test_flamant_superposition_of_a_flat_punch_against_adaptive_quadrature():
    """The field under the rounded flat punch (b > 0, where the pressure's slope is logarithmic at
    |t| = b) against Flamant's integral in t by QUADPACK, breaking at +-b and at the point: from just
    under the surface to deep, beside and below the corners and the contact's ends. 1e-9 p(0): the
    largest gap measured is 4.8e-10 p(0), 1e-6 beside a corner and 1e-3 deep, where the kernel's peak
    and the logarithmic slope meet (the same with the pressure of punch_pressure in the sum); a
    pressure off by 1e-4 of one of its terms fails it."""
    d = punch_contact(3.0, 20.0, HERTZ.E_star, 32000.0)
    p0 = float(punch_pressure(np.array([0.0]), d)[0])
    pts = [(x, z) for x in (0.0, 1.5, d.b - 1e-6, d.b, d.b + 0.3, 0.99 * d.a, d.a + 0.5, -4.0)
           for z in (1e-3, 0.05, 0.7, 4.0)]

    def flamant(x, z, m):
        def f(t):  # sigma_x, sigma_z, tau_xz of the line load p(t) dt
            r = x - t
            kernel = (r * r * z, z**3, r * z * z)[m]
            return -2.0 / np.pi * float(punch_pressure(np.array([t]), d)[0]) * kernel / (r * r + z * z) ** 2

        breaks = sorted({-d.b, d.b, min(max(x, -d.a), d.a)} - {-d.a, d.a})
        return quad(f, -d.a, d.a, points=breaks, limit=500, epsabs=1e-10 * p0, epsrel=1e-12)[0]

    x, z = np.array(pts).T
    got = punch_body_stress(x, z, d, 0.0, 0.0, upper=True)  # upper body: depth y, s12 = tau_xz
    want = np.array([[flamant(xi, zi, m) for m in range(3)] for xi, zi in pts])
    assert np.abs(got - want).max() <= 1e-9 * p0


@pytest.mark.parametrize("b", [1.0, 3.0, 5.0])
def test_pressure_carries_the_load(b):
    """``int p = P`` (adaptive quadrature, 1e-9: its own tolerance), the pressure is positive
    inside and continuous at |x| = b (the logarithms cancel there), and P grows with a."""
    d = punch_contact(b, 20.0, HERTZ.E_star, 32000.0)
    total = quad(lambda s: float(punch_pressure(np.array([s]), d)[0]), -d.a, d.a, points=[-b, b], limit=400)[0]
    assert total == pytest.approx(32000.0, rel=1e-9)
    x = np.linspace(-d.a, d.a, 1001)[1:-1]
    assert np.all(punch_pressure(x, d) > 0)
    near = punch_pressure(np.array([b * (1 - 1e-9), b, b * (1 + 1e-9)]), d)
    assert np.ptp(near) <= 1e-6 * near[1]  # the slope is logarithmic: 1e-9 away moves p by ~1e-8
    a = np.linspace(b * 1.001, 3 * b, 50)
    assert np.all(np.diff([punch_load(s, b, 20.0, HERTZ.E_star) for s in a]) > 0)


def test_punch_gap_profile():
    g = Punch(b=3.0, R=20.0, xc=1.0)
    x = np.array([-6.0, -2.0, 1.0, 4.0, 6.0])
    assert np.allclose(g.value(x), np.maximum(np.abs(x - 1) - 3, 0) ** 2 / 40, rtol=1e-15)
    assert g.integral(-6.0, 6.0) == pytest.approx(quad(lambda s: float(g.value(np.array([s]))[0]), -6, 6,
                                                       points=[-2, 4])[0], rel=1e-12)
    lo, hi = g.curvature_range(np.array([-1.0, 3.0, 5.0]), np.array([2.0, 5.0, 6.0]))
    assert np.allclose(lo, [0, 0, 1 / 20]) and np.allclose(hi, [0, 1 / 20, 1 / 20])


CORNER = Composite(((0.0, 0.0), (3.0, 0.0), (3 + 20 * np.sin(np.pi / 3), 10.0)), (None, (3.0, 20.0)))


def test_composite_profile_is_consistent():
    """Slope and curvature are the derivatives of the value (central differences, 1e-6: their
    truncation error at step 1e-6 on a radius-20 arc), the integral is the quadrature's, and the
    curvature range holds every sampled curvature."""
    x = np.array([0.5, 2.0, 4.0, 10.0, 18.0])
    h = 1e-6
    assert np.allclose((CORNER.value(x + h) - CORNER.value(x - h)) / (2 * h), CORNER.slope(x), atol=1e-6)
    assert np.allclose((CORNER.slope(x + h) - CORNER.slope(x - h)) / (2 * h), CORNER.curvature(x), atol=1e-6)
    assert CORNER.value(np.array([3.0 + 20 * np.sin(np.pi / 3)]))[0] == pytest.approx(10.0, rel=1e-14)
    f = quad(lambda s: float(CORNER.value(np.array([s]))[0]), 1.0, 19.0, points=[3.0])[0]
    assert CORNER.integral(1.0, 19.0) == pytest.approx(f, rel=1e-12)
    a, b = np.array([0.0, 2.0, 10.0]), np.array([2.5, 8.0, 20.0])
    lo, hi = CORNER.curvature_range(a, b)
    for k in range(3):
        k_s = CORNER.curvature(np.linspace(a[k], b[k], 2001))
        assert lo[k] <= k_s.min() + 1e-15 and k_s.max() <= hi[k] + 1e-15
    assert list(CORNER.inflexions(0.0, 20.0)) == [3.0]  # the break: a column of the mesh


def test_composite_refusals():
    with pytest.raises(cd.errors.SceneError, match="left to right"):
        Composite(((0.0, 0.0), (-1.0, 0.0)), (None,))
    with pytest.raises(cd.errors.SceneError, match="different distances"):
        Composite(((0.0, 0.0), (3.0, 1.0)), ((1.0, 5.0),))
    with pytest.raises(cd.errors.SceneError, match="not a graph"):
        Composite(((0.0, -1.0), (2.0, 1.0)), ((1.0, 0.0),))


@pytest.mark.slow
def test_rounded_punch_linear_against_the_closed_form():
    """The contact half-width within one face spacing of the closed form, and the pressure's
    relative L2 error (trapezoid over the pairs) falling with h (0.076, 0.030, 0.012 measured)."""
    scene = cd.load_scene("rounded-punch-linear")
    field = exact_field(scene)
    a = field.punch.a
    errs = []
    for level in (1, 2, 3):
        c = cd.solve(scene, level=level, solver="fast").contact
        x, p = np.asarray(c["x"]), np.asarray(c["pressure"])
        a_h = x[np.asarray(c["active"])].max()
        i = np.searchsorted(x, a_h)
        assert abs(a_h - a) <= x[i + 1] - x[i]
        w = np.gradient(x)
        pe = field.pressure(x)
        errs.append(np.sqrt(np.sum(w * (p - pe) ** 2) / np.sum(w * pe**2)))
    assert errs[0] > errs[1] > errs[2]
    assert np.polyfit(np.arange(3), np.log2(errs), 1)[0] < -0.8  # at least order 0.8 in h (1.33 measured)


def test_rounded_punch_corner_break_is_a_column():
    mesh, _, _ = discretize(cd.load_scene("rounded-punch"), "type1", 1)
    assert np.any(mesh.bodies[0].columns == 3.0)


def _half_width(sol):
    c = sol.contact
    x = np.asarray(c["x"])
    i = np.flatnonzero(np.asarray(c["active"])).max()
    return x[i], x[i + 1] - x[i]


@pytest.mark.slow
def test_rounded_punch_true_geometry_converges_to_one_half_width():
    """No closed form: P0 and eq, both triangulations, reach one contact half-width (the finest
    level's within one face spacing of each other, past the flat b = 3 and near the linearised
    6.0), and every eq energy bracket of every level shares a point, all certified."""
    scene = cd.load_scene("rounded-punch")
    finest, brackets = [], []
    for level in (2, 3, 4):
        for tri in ("type1", "type2"):
            for space in ("p0", "eq"):
                sol = cd.solve(scene, tri, level=level, solver="fast", stress_space=space)
                if level == 4:
                    finest.append(_half_width(sol))
                if space == "eq":
                    b = sol.bounds
                    assert b["guaranteed"], b["reasons"]
                    brackets.append((b["energy_lower"], b["energy_upper"]))
    widths = np.array([w for w, _ in finest])
    spacing = max(s for _, s in finest)
    assert np.ptp(widths) <= spacing and np.all(widths > 3.0 + spacing)
    assert max(lo for lo, _ in brackets) <= min(hi for _, hi in brackets)
