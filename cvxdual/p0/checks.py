"""The checks of a P0 solution (docs/theory.md#recovery-and-checks): from the stresses ``t`` and
the recovered displacements ``u_h``, equilibrium and the sign of the contact forces, the
constitutive law ``t_P = C_P B_P u_h``, complementarity and the discrete duality gap, and the
contact quantities at the pairs. :func:`evaluate` gives every field of a
:class:`~cvxdual.solution.Solution` that the solve itself does not.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

from ..records import Contact
from ..reference.exact import exact_reference
from ..solution import ACTIVE_TOL, FORCE_FLOOR, SolverStats, load_scale, skipped_error
from ..system.assembly import System
from ..voigt import VOIGT_WEIGHT
from .norms import stress_error


def admissibility(system: System, t: np.ndarray):
    """Residual vector ``R = Z^T (E t - f)`` of stresses ``t`` ``(n_pieces, 3)``, and its scale
    ``Z^T (|E| |t| + |f|)`` for relative measures."""
    tv = t.ravel()
    ZT = system.Z.T
    R = ZT @ (system.E @ tv - system.f)
    scale = ZT @ (abs(system.E) @ np.abs(tv) + np.abs(system.f))
    return R, scale


def contact_quantities(system: System, R: np.ndarray, u: np.ndarray, friction=None, adhesion=None,
                       displacements: bool = True) -> Contact:
    """Nodal contact forces, pressures, gaps, the active set and the tangential state
    (:class:`~cvxdual.records.Contact`, with the ``reaction`` on the upper body), from the
    residual ``R = Z^T (E t - f)`` of the stresses and the displacements ``u``.

    ``friction`` (Tresca ``g`` per pair) and ``adhesion`` (``sigma_a`` per pair) are those of
    the problem solved: a pair is active where its force exceeds ``-sigma_a w`` and sticks
    where it is active and its tangential force is below ``g w`` (each judged, like the
    normal state, against the slip relative to its scale)."""
    force = -R[system.jb]
    up, lo = system.mesh.pairs.T
    q = u.reshape(-1, 2)
    rel = q[lo, 1] - q[up, 1]
    pressure = force / system.width
    held = force if adhesion is None else force + adhesion * system.width  # force above the cut-off
    fmax = max(float(held.max()) if len(held) else 0.0, FORCE_FLOOR * load_scale(system))
    delta = _delta(system, u, system.eps)
    opening = system.eps - rel
    # complementarity makes force or opening zero; an interior point leaves both small, and the
    # larger of the two (each relative to its scale) tells the state
    active = held > ACTIVE_TOL * fmax
    if displacements:
        active &= held / fmax > opening / delta
    _, jxb, slides = system.pair_x_dofs
    tangential = np.where(slides, R[np.where(slides, jxb, 0)], 0.0)  # R''_x(B_k): x force on the lower body
    slip = q[lo, 0] - q[up, 0]
    if friction is None:
        stick = np.zeros(len(force), bool)
    else:
        with np.errstate(invalid="ignore"):  # g = inf: the reserve is inf, the pair sticks
            reserve = (friction * system.width - np.abs(tangential)) / fmax
        # without displacements, by the reserve alone (as the normal state by the force alone)
        stick = active & slides & (reserve > (np.abs(slip) / delta if displacements else ACTIVE_TOL))
    xs = system.mesh.pair_x[active]
    return Contact(
        x=system.mesh.pair_x, gap=system.eps, relative_displacement=rel,
        force=force, pressure=pressure, active=active,
        tangential_force=tangential, slip=slip, stick=stick,
        reaction=R[system.ja],  # y force on the upper body: +force (action = reaction)
        n_active=int(active.sum()),
        x_min=float(xs.min()) if len(xs) else None,
        x_max=float(xs.max()) if len(xs) else None,
        max_pressure=float(pressure.max()) if len(pressure) else 0.0,
        total_force=float(force.sum()),
    )


def residuals(system: System, t: np.ndarray, u: np.ndarray, contact: Mapping, adm=None) -> dict:
    """Relative residuals of a dual solution ``t`` with recovered displacements ``u``.

    - equilibrium: largest violation of ``(T^T R)_j = 0`` (every ``j`` not in ``J-``, the
      anchors included, so the dropped rows are checked too) and ``(T^T R)_m <= 0`` (``m`` in
      ``J-``), over the largest term of ``Z^T (|E||t| + |f|)``;
    - constitutive: ``||t - C B u||_0 / ||t||_0``;
    - complementarity: ``sum |F_k s_k| / (sum |F_k| * delta)``, ``s_k = eps_k - (u''_y - u'_y)``,
      ``delta`` the largest displacement or gap;
    - penetration: ``max(0, -s_k) / delta``.

    Force denominators are floored (``F_ref = sum |f|``, the load scale: ``1e-6 F_ref`` for nodal
    forces, ``1e-3 F_ref`` for the total contact force) so that a solution with (almost) no
    contact is not judged on rounding noise.

    A plain dict, not a record: ``Solution.residuals`` is a map from check names to values,
    matched by name against ``TOLERANCES``; its names differ between the paths that build it (these
    five here; a model's ``user_constraints`` and skipped checks, :mod:`cvxdual.p0.dual`; the eq
    space's constraint blocks, an open set), and every reader iterates it or looks a name up.
    """
    R, scale = admissibility(system, t) if adm is None else adm
    f_ref = load_scale(system)
    Ry = system.T.T @ R
    viol = np.abs(Ry)
    viol[system.jb] = np.maximum(Ry[system.jb], 0.0)
    eq = float(viol.max() / max(scale.max(), 1e-6 * f_ref)) if len(viol) else 0.0
    sc = system.scales
    tu = system.stresses_from_displacement(u)
    a = system.pieces.area[:, None]
    num = np.sqrt(np.sum(a * VOIGT_WEIGHT * (t - tu) ** 2))
    den = np.sqrt(np.sum(a * VOIGT_WEIGHT * t**2))
    # floors: the problem's own stress and displacement scales (an unloaded scene has t = u = 0)
    cons = float(num / max(den, 1e-12 * sc.stress * sc.length))
    return {"equilibrium": eq, "constitutive": cons, "complementarity": complementarity(system, u, contact),
            "penetration": penetration(system, u, contact), "duality_gap": duality_gap(system, t, u)}


def _delta(system: System, u: np.ndarray, gap: np.ndarray) -> float:
    """The displacement scale: the largest displacement or gap (floored by the problem's)."""
    return max(float(np.abs(u).max()), float(np.abs(gap).max(initial=0.0)), system.scales.displacement)


def complementarity(system: System, u: np.ndarray, contact: Mapping, force: np.ndarray | None = None) -> float:
    """``sum |F_k s_k| / (sum |F_k| delta)`` with the openings ``s_k``; ``force`` replaces
    ``contact["force"]`` (adhesion: the force above the cut-off)."""
    F = contact["force"] if force is None else force
    s = contact["gap"] - contact["relative_displacement"]
    fsum = max(float(np.abs(F).sum()), FORCE_FLOOR * load_scale(system))
    return float(np.sum(np.abs(F * s)) / (fsum * _delta(system, u, contact["gap"])))


def penetration(system: System, u: np.ndarray, contact: Mapping) -> float:
    """``max(0, -min_k s_k) / delta``."""
    s = contact["gap"] - contact["relative_displacement"]
    return float(max(0.0, -s.min()) / _delta(system, u, contact["gap"])) if len(s) else 0.0


def dual_objective(system: System, t: np.ndarray) -> float:
    """``S(t) = 1/2 t.A_h t - t.E^T q0`` (docs/theory.md#discretisation)."""
    tv = t.ravel()
    return 0.5 * float(tv @ (system.Ah @ tv)) - float(tv @ (system.E.T @ system.q0))


def duality_gap(system: System, t: np.ndarray, u: np.ndarray, extra: float = 0.0) -> float:
    """``|J(u_h) + L(u0) + S(lam_h)|`` relative to the complementary energy
    (docs/theory.md#primal-and-dual-problems); ``extra`` is what a reformulation adds to ``J``
    (friction dissipation, adhesion work)."""
    tv = t.ravel()
    energy = 0.5 * float(tv @ (system.Ah @ tv))
    objective = energy - float(tv @ (system.E.T @ system.q0))
    sc = system.scales
    val = system.energy(u) + extra + float(system.f @ system.q0) + objective
    return abs(val) / max(energy, abs(objective), 1e-12 * sc.stress**2 * sc.length**2 / sc.modulus)


def evaluate(system: System, t: np.ndarray, u: np.ndarray, stats: SolverStats, friction=None, adhesion=None,
             displacements: bool = True, exact_error: bool = True) -> dict:
    """Contact data, residuals, objective, duality gap and errors of stresses ``t`` and
    displacements ``u``: every field of a :class:`Solution` that the solve itself does not give,
    and ``timings["error"]``, the time of the error against the exact field (left out unless
    ``exact_error``; ``friction``, ``adhesion``, ``displacements``: see :func:`contact_quantities`).
    Where the scene declares an exact field that does not solve it, ``exact`` and ``error`` are
    ``None`` and ``checks`` says why."""
    scene = system.mesh.scene
    adm = admissibility(system, t)
    contact = contact_quantities(system, adm[0], u, friction, adhesion, displacements)
    res = residuals(system, t, u, contact, adm)
    exact, why = exact_reference(scene)
    error, t0 = None, time.perf_counter()
    if exact is not None and exact_error:
        error = stress_error(system, t, exact.stress)
    return {"timings": {"error": time.perf_counter() - t0},  # a diagnostic: shown apart
            "scene": scene, "system": system, "stress": t, "displacement": u.reshape(-1, 2), "solver": stats,
            "objective": dual_objective(system, t), "duality_gap": res["duality_gap"], "residuals": res,
            "contact": contact, "exact": exact.data() if exact is not None else None,
            "error": error, "checks": skipped_error(res, why)}
