"""Williams' exponent of a clamped-free corner (studies/corner.py), which limits cylinder-on-block's
bound under uniform refinement (docs/equilibrium.md 12.7): checked against its defining conditions
and the published values."""

import numpy as np
from corner import williams_clamped_free  # studies/, on the path by conftest.py


def test_williams_clamped_free_right_angle():
    lam = williams_clamped_free(np.pi / 2, 0.3)
    # Williams (1952), Sinclair's review (2004): 0.7112 at a clamped-free right angle, nu = 0.3
    assert abs(lam - 0.7112) < 1e-4
    # the potentials phi = A z^lam, psi = B z^lam with B from the clamped edge: some A != 0 leaves the
    # free edge traction free (the determinant, of order 1 here, vanishes to brentq's 1e-12 in lam)
    kappa = 3 - 4 * 0.3
    a = np.pi / 2
    m = np.array([[(A * np.exp(1j * lam * a) + lam * np.conj(A) * np.exp(1j * (2 - lam) * a)
                    + (kappa * A - lam * np.conj(A)) * np.exp(-1j * lam * a))] for A in (1.0, 1j)]).ravel()
    assert abs(np.linalg.det(np.array([m.real, m.imag]))) < 1e-9
    # stronger as nu -> 1/2 (0.5947 at 0.4999)
    assert 0.594 < williams_clamped_free(np.pi / 2, 0.4999) < 0.595 < lam
