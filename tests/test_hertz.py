"""Physics checks of the Hertz line contact and the McEwen field (cvxdual.reference.hertz)."""

import numpy as np
import pytest
from scipy.integrate import quad

from cvxdual.reference.hertz import HertzData, body_stress, hertz_line_contact, hertz_pressure, mcewen_stress

# NAFEMS-style cylinder on block, plane strain, mm and MPa.
NAFEMS = dict(E1=70000.0, nu1=0.3, E2=210000.0, nu2=0.3, R=50.0, load=35000.0)
# Off-origin contact centre and face height, so that the global mapping is exercised.
XC, YF = 2.5, -1.0


@pytest.fixture(scope="module")
def hz() -> HertzData:
    return hertz_line_contact(**NAFEMS)


def test_nafems_values(hz):
    # The reference prints a = 6.21 mm and p0 = 3585 MPa: compare to exactly those digits.
    assert round(hz.a, 2) == 6.21
    assert round(hz.p0) == 3585
    # 1/E* = 0.91 (1/70000 + 1/210000) = 3.64/210000: closed form, only rounding error left.
    assert hz.E_star == pytest.approx(210000.0 / 3.64, rel=1e-14)
    assert (hz.R, hz.load) == (50.0, 35000.0)


def test_plane_stress_modulus():
    d = hertz_line_contact(70000.0, 0.3, 210000.0, 0.3, 50.0, 35000.0, plane="stress")
    # 1/E* = 1/E1 + 1/E2 exactly; tolerance is floating-point rounding only.
    assert d.E_star == pytest.approx(52500.0, rel=1e-14)
    assert d.p0 == pytest.approx(2 * d.load / (np.pi * d.a), rel=1e-14)


def test_pressure_integrates_to_load(hz):
    a, p0 = hz.a, hz.p0
    # Adaptive quadrature over [-2a, 2a] with breakpoints at the sqrt edge singularities;
    # it converges to ~1e-14 here, so 1e-10 is a safe bound far below any formula error.
    total, _ = quad(lambda x: hertz_pressure(x, a, p0), -2 * a, 2 * a, points=[-a, a],
                    epsabs=0.0, epsrel=1e-12, limit=200)
    assert total == pytest.approx(hz.load, rel=1e-10)


def test_surface_values(hz):
    a, p0 = hz.a, hz.p0
    x = np.concatenate([np.linspace(-2 * a, 2 * a, 401), [-a, a, 0.0]])  # includes |x| = a exactly
    p = hertz_pressure(x, a, p0)
    assert np.all(p[np.abs(x) >= a] == 0.0) and np.all(p[np.abs(x) < a] > 0.0)
    assert p[-1] == p0
    sx, sz, txz = mcewen_stress(x, 0.0, a, p0)
    # At z = 0 the formulas reduce to sqrt(a^2 - x^2) terms: agreement to a few ulps of p0.
    tol = 1e-12 * p0
    assert np.all(np.isfinite(sx) & np.isfinite(sz) & np.isfinite(txz))
    np.testing.assert_allclose(sx, -p, rtol=0, atol=tol)
    np.testing.assert_allclose(sz, -p, rtol=0, atol=tol)
    np.testing.assert_allclose(txz, 0.0, rtol=0, atol=tol)
    # Continuity of the limit: at depth 1e-10 a the field is within O(sqrt(1e-10)) p0 = 1e-5 p0
    # of its surface value (the field is Hoelder-1/2 at the edges, smooth elsewhere).
    sx1, sz1, txz1 = mcewen_stress(x, 1e-10 * a, a, p0)
    for s1, s0 in ((sx1, sx), (sz1, sz), (txz1, txz)):
        np.testing.assert_allclose(s1, s0, rtol=0, atol=1e-4 * p0)


def test_symmetry_in_x(hz):
    a, p0 = hz.a, hz.p0
    rng = np.random.default_rng(7)
    x, z = rng.uniform(-3 * a, 3 * a, 500), rng.uniform(0, 3 * a, 500)
    sp, sm = mcewen_stress(x, z, a, p0), mcewen_stress(-x, z, a, p0)
    # Even normal stresses, odd shear (n has the sign of x): exact up to rounding.
    np.testing.assert_allclose(sp[0], sm[0], rtol=0, atol=1e-12 * p0)
    np.testing.assert_allclose(sp[1], sm[1], rtol=0, atol=1e-12 * p0)
    np.testing.assert_allclose(sp[2], -sm[2], rtol=0, atol=1e-12 * p0)


def test_max_shear_on_axis(hz):
    a, p0 = hz.a, hz.p0
    # Step 1e-6 a over [0, 2a]: 2000x finer than the half-unit 5e-4 a of the third digit of
    # z/a; the max of a smooth function is then located to 1e-6 a and valued to O(1e-12) p0.
    z = np.linspace(0.0, 2 * a, 2_000_001)
    sx, sz, txz = mcewen_stress(0.0, z, a, p0)
    tau = np.sqrt(((sx - sz) / 2) ** 2 + txz**2)
    i = np.argmax(tau)
    assert round(z[i] / a, 3) == 0.786
    assert round(tau[i] / p0, 3) == 0.300


def _points(a, upper, n, rng):
    # Depth >= 0.05 a keeps the stencil away from the sqrt singularity at the contact edges.
    x = XC + rng.uniform(-3 * a, 3 * a, n)
    z = rng.uniform(0.05 * a, 3 * a, n)
    return x, (YF + z if upper else YF - z)


@pytest.mark.parametrize("upper", [True, False])
def test_equilibrium_residual_global(hz, upper):
    a, p0 = hz.a, hz.p0
    x, y = _points(a, upper, 4000, np.random.default_rng(11 if upper else 12))
    # Centred differences: truncation ~ (h/d)^2 p0/a with d >= 0.05 a the distance to the
    # edge singularity, i.e. ~4e-8 p0/a for h = 1e-5 a; rounding ~ eps p0/h ~ 2e-11 p0/a.
    h = 1e-5 * a
    def s(dx, dy):
        return body_stress(x + dx, y + dy, a, p0, x_c=XC, y_face=YF, upper=upper)

    dx = (s(h, 0) - s(-h, 0)) / (2 * h)
    dy = (s(0, h) - s(0, -h)) / (2 * h)
    rx = dx[:, 0] + dy[:, 2]  # d sxx/dx + d sxy/dy
    ry = dx[:, 2] + dy[:, 1]  # d sxy/dx + d syy/dy
    # 1e-6 p0/a: 25x above the truncation bound, while a wrong shear sign gives O(1) p0/a.
    assert np.max(np.hypot(rx, ry)) < 1e-6 * p0 / a


def test_shear_flips_between_bodies(hz):
    a, p0 = hz.a, hz.p0
    rng = np.random.default_rng(3)
    x, z = XC + rng.uniform(-3 * a, 3 * a, 300), rng.uniform(0, 3 * a, 300)
    up = body_stress(x, YF + z, a, p0, x_c=XC, y_face=YF, upper=True)
    lo = body_stress(x, YF - z, a, p0, x_c=XC, y_face=YF, upper=False)
    sx, sz, txz = mcewen_stress(x - XC, z, a, p0)
    # Pure reassembly of the same numbers: equal to rounding.
    np.testing.assert_allclose(up, np.column_stack([sx, sz, txz]), rtol=0, atol=1e-12 * p0)
    np.testing.assert_allclose(lo, np.column_stack([sx, sz, -txz]), rtol=0, atol=1e-12 * p0)


@pytest.mark.parametrize("upper", [True, False])
def test_face_traction_compressive(hz, upper):
    a, p0 = hz.a, hz.p0
    x = XC + np.linspace(-2 * a, 2 * a, 801)
    s = body_stress(x, np.full_like(x, YF), a, p0, x_c=XC, y_face=YF, upper=upper)
    p = hertz_pressure(x - XC, a, p0)
    # Same closed-form surface limit as test_surface_values: rounding-level tolerance.
    np.testing.assert_allclose(s[:, 1], -p, rtol=0, atol=1e-12 * p0)
    np.testing.assert_allclose(s[:, 2], 0.0, rtol=0, atol=1e-12 * p0)
    # Traction on the body from the contact, t = sigma n with the outward face normal:
    # upper body n = -y gets t_y = +p (pushed up), lower body n = +y gets t_y = -p.
    ny = -1.0 if upper else 1.0
    t_y = s[:, 1] * ny
    assert np.all(t_y * ny <= 0.0)  # compressive: the traction points into the body


def _segment(p, q, nodes, weights):
    p, q = np.asarray(p, float), np.asarray(q, float)
    s = 0.5 * (nodes + 1.0)
    return p + s[:, None] * (q - p), 0.5 * np.linalg.norm(q - p) * weights


@pytest.mark.parametrize("upper", [True, False])
@pytest.mark.parametrize("w_left, w_right", [(3.0, 3.0), (2.0, 5.0)])
def test_box_force_balance(hz, upper, w_left, w_right):
    """Tractions on the far side and both sides of a box standing on the face balance the
    face pressure: y-resultant = -load (upper) / +load (lower), x-resultant = 0. The
    asymmetric box makes the x-balance a real check of the shear sign."""
    a, p0 = hz.a, hz.p0
    H = 4.0 * a
    xl, xr = XC - w_left * a, XC + w_right * a  # both outside the contact zone
    yfar = YF + H if upper else YF - H
    nodes, weights = np.polynomial.legendre.leggauss(64)
    sides = [((xl, yfar), (xr, yfar), (0.0, 1.0 if upper else -1.0)),
             ((xr, YF), (xr, yfar), (1.0, 0.0)),
             ((xl, YF), (xl, yfar), (-1.0, 0.0))]
    F = np.zeros(2)
    for p, q, (nx, ny) in sides:
        pts, w = _segment(p, q, nodes, weights)
        s = body_stress(pts[:, 0], pts[:, 1], a, p0, x_c=XC, y_face=YF, upper=upper)
        F += [w @ (s[:, 0] * nx + s[:, 2] * ny), w @ (s[:, 2] * nx + s[:, 1] * ny)]
    # The field is analytic on these segments (they avoid the contact edges), so 64-point
    # Gauss-Legendre is converged to rounding (~1e-15 relative already at 20 points).
    assert F[1] == pytest.approx(-hz.load if upper else hz.load, rel=1e-10)
    assert abs(F[0]) < 1e-10 * hz.load


def test_array_shapes_and_no_nan(hz):
    a, p0 = hz.a, hz.p0
    x = np.array([-a, -a / 2, 0.0, a, 2 * a])[:, None]
    z = np.array([0.0, 1e-300, 0.5 * a, 10 * a])[None, :]
    out = mcewen_stress(x, z, a, p0)
    assert all(o.shape == (5, 4) and np.all(np.isfinite(o)) for o in out)
    s = body_stress(x, YF - z, a, p0, x_c=0.0, y_face=YF, upper=False)
    assert s.shape == (20, 3) and np.all(np.isfinite(s))


def test_wrong_side_and_negative_depth_rejected(hz):
    with pytest.raises(ValueError):
        mcewen_stress(0.0, -1.0, hz.a, hz.p0)
    with pytest.raises(ValueError):
        body_stress([0.0], [YF - 1.0], hz.a, hz.p0, y_face=YF, upper=True)
    with pytest.raises(ValueError):
        body_stress([0.0], [YF + 1.0], hz.a, hz.p0, y_face=YF, upper=False)


@pytest.mark.parametrize("name", ["E1", "E2", "R", "load"])
@pytest.mark.parametrize("bad", [0.0, -1.0, np.nan, np.inf, -np.inf])
def test_rejects_bad_input(name, bad):
    with pytest.raises(ValueError, match=name):
        hertz_line_contact(**{**NAFEMS, name: bad})


@pytest.mark.parametrize("name", ["nu1", "nu2"])
@pytest.mark.parametrize("bad", [0.6, -1.0, np.nan, np.inf])
def test_rejects_bad_poisson(name, bad):
    with pytest.raises(ValueError, match=name):
        hertz_line_contact(**{**NAFEMS, name: bad})


def test_rejects_bad_plane():
    with pytest.raises(ValueError, match="plane"):
        hertz_line_contact(**NAFEMS, plane="axisymmetric")
