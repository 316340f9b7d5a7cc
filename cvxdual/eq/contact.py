"""Contact quantities of equilibrium stresses at the pairs, defined as for P0
(:func:`cvxdual.p0.checks.contact_quantities`) from the normal tractions of the contact edges."""

from __future__ import annotations

import numpy as np

from ..records import Contact
from ..solution import ACTIVE_TOL, FORCE_FLOOR, load_scale


def edge_contact(system, p: np.ndarray, v: np.ndarray | None = None, load: float = 1.0) -> Contact:
    """Contact quantities (:class:`~cvxdual.records.Contact`, with ``edge_pressure = p``) of linear
    contact pressures ``p`` ``(n_c, 2)`` (at both ends of each contact edge), defined as for P0
    (:func:`cvxdual.p0.checks.contact_quantities`): the nodal
    force ``int p phi_k dx`` at each pair and the pressure per tributary length; a pair is active
    where the pressure at it (from either adjacent edge) is positive beyond rounding of the load
    scale (``load`` times the scene's). ``v``: displacements for the relative displacement and
    slip, or ``None`` (zeros). The equilibrium space is frictionless: no tangential force."""
    x = system.mesh.pair_x
    d = np.diff(x)
    force = np.zeros(len(x))
    force[:-1] += d * (2 * p[:, 0] + p[:, 1]) / 6.0
    force[1:] += d * (p[:, 0] + 2 * p[:, 1]) / 6.0
    at_pair = np.zeros(len(x))
    at_pair[:-1] = p[:, 0]
    at_pair[1:] = np.maximum(at_pair[1:], p[:, 1])
    floor = FORCE_FLOOR * load * load_scale(system) / max(float(x[-1] - x[0]), 1e-300)
    active = at_pair > ACTIVE_TOL * max(float(at_pair.max(initial=0.0)), floor)
    n = len(x)
    up, lo = system.mesh.pairs.T
    rel, slip = (np.zeros(n), np.zeros(n)) if v is None else (v[lo, 1] - v[up, 1], v[lo, 0] - v[up, 0])
    pressure = force / system.width
    xs = x[active]
    return Contact(x=x, gap=system.eps, relative_displacement=rel, force=force, pressure=pressure,
                   active=active, edge_pressure=p, tangential_force=np.zeros(n), slip=slip,
                   stick=np.zeros(n, bool), n_active=int(active.sum()),
                   x_min=float(xs.min()) if len(xs) else None, x_max=float(xs.max()) if len(xs) else None,
                   max_pressure=float(pressure.max(initial=0.0)), total_force=float(force.sum()))
