r"""Prandtl's punch: a certified lower bound on a limit load by the static theorem.

Problem
-------
A smooth, flat, rigid punch of half-width ``b`` is pressed into a rigid-perfectly plastic block
in plane strain. The block yields when the in-plane maximum shear reaches ``k``::

    tau(sigma) = sqrt(((s11 - s22) / 2)^2 + s12^2) <= k       (Tresca = von Mises in plane strain)

Prandtl (1920) found the mean punch pressure at collapse on a half-space::

    q_lim = (2 + pi) k = 5.1416 k.

Units: ``k = 1`` and ``b = 1`` (the scene says m and Pa; any consistent units do), so the load
factor ``alpha`` below *is* ``q_lim / k``.

Static (lower-bound) theorem
----------------------------
If a stress field ``sigma`` is statically admissible for the load ``alpha q`` -- ``div sigma = 0``
everywhere, tractions continuous across every element edge, ``sigma n = alpha q`` on the loaded
boundary, zero on the free one, compressive and frictionless contact -- and ``tau(sigma) <= k`` at
every point of the block, then ``alpha <= alpha_collapse``. Maximising ``alpha`` over any set of
such fields therefore approaches ``2 + pi`` from *below*.

Discretisation
--------------
The Johnson-Mercier space of :mod:`cvxdual.eq.space` (``sigma = S y + alpha sigma0``, linear on
the three sub-triangles of every mesh triangle) is exactly admissible by construction, except for
``div sigma = 0``, kept as linear equality constraints on ``y``. ``tau`` is convex and ``sigma`` is
linear on each sub-triangle, so ``tau <= k`` at its three vertices means ``tau <= k`` on all of it:
nine second-order cones per block triangle enforce yield *everywhere*. The punch is rigid: its
stresses are not capped. The result is a conic program::

    maximise alpha  over (y, alpha)
    subject to  div(S y + alpha sigma0) = 0,   sigma_nn(contact) <= 0,
                tau(S y + alpha sigma0) <= k  at the 9 vertices of every block triangle.

:func:`cvxdual.build_model` with ``stress_space="eq", limit_analysis=True`` builds all of it but
the yield rows (an :class:`cvxdual.eq.model.EquilibriumModel`: ``load_factor`` is ``alpha``, a
variable, maximised); ``model.add_constraint(model.shear_cap(k, where=model.vertex_body == 1))``
adds them. An interior-point solver returns ``(y, alpha)`` to about 1e-8, not exactly; after the
solve the model makes the field exact per unit load (:func:`cvxdual.eq.space.make_exact`:
contact tractions clipped and balanced, ``div sigma = 0`` projected to rounding), so
``model.stresses()`` is exactly admissible for the load ``alpha q`` -- but only inside the yield
set to the solver's tolerance. The *certified* value scales it by ``1 / max(1, max tau / k)``,
``max tau`` over the vertices of that exact field. The problem is homogeneous in the load (no
body force), so the scaled field is admissible for the scaled load: that number is a lower bound,
not an approximation of one.

Why the paper's piecewise-constant (P0) stresses give no bound
--------------------------------------------------------------
P0 stresses satisfy equilibrium only weakly, tested against P1 displacements. The P0 field is not
in equilibrium pointwise, so the static theorem does not apply to it. By duality the P0 problem is
the kinematic (velocity) method with P1 velocities, and plastic flow under this yield condition is
isochoric: only divergence-free P1 velocities are admissible. On these meshes (every quadrilateral
cut the same way) such fields lock, the hydrostatic stress is uncapped and carries any load in the
weak equilibrium, and the maximum is *unbounded*. ``limit_load_p0`` shows it. It is not a bound,
and not an estimate either.

Run::

    python examples/prandtl_punch.py --levels 0,1,2 --out out/examples/prandtl_punch
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import cvxdual
from cvxdual.voigt import shear_stress

K = 1.0  # shear yield stress k
B = 1.0  # punch half-width b
PRANDTL = 2.0 + np.pi  # q_lim / k on a half-space
# Clarabel's default regularisation fails (NumericalError, at level 1) on this degenerate optimal
# face; 1e-7 converges (status 'optimal' or 'optimal_inaccurate': the model accepts the latter, as
# its exactness step and the certification below repair what the solver leaves)
CLARABEL = {"static_regularization_constant": 1e-7}


def punch_scene(width: float = 5.0, depth: float = 3.0) -> dict:
    """Half model (symmetry at ``x = 0``) as a cvxdual scene dict, ``k = 1``, ``b = 1``.

    Punch (upper body): ``x`` in ``[0, b]``, height 1, sliding symmetry on the left, top loaded by
    a uniform unit pressure ``q = 1`` (so its total force is ``q b``). Block (lower body): ``x`` in
    ``[0, width]``, ``depth`` deep, sliding on both sides, clamped at the bottom. Frictionless
    contact on the overlap ``[0, b]``, zero gap. The elastic constants are required by the scene
    format but play no part in limit analysis.
    """
    return {
        "name": "prandtl_punch", "units": ["m", "Pa"], "plane": "strain",
        "mesh": {"columns": 10, "focus": [0.0, 2 * B], "grading": 1.0, "default_level": 1},
        "bodies": {
            "punch": {"position": "upper", "x": [0.0, B], "far": 1.0, "face": {"kind": "flat", "y0": 0.0},
                      "material": {"E": 1e3, "nu": 0.3}, "layers": 2,
                      "boundary": {"sym": {"on": "left", "kind": "sliding"},
                                   "top": {"on": "far", "kind": "traction",
                                           "traction": {"kind": "uniform", "value": [0.0, -1.0]}}}},
            "block": {"position": "lower", "x": [0.0, width], "far": -depth, "face": {"kind": "flat", "y0": 0.0},
                      "material": {"E": 1.0, "nu": 0.3}, "layers": 6, "focus_depth": 1.5 * B,
                      "boundary": {"sym": {"on": "left", "kind": "sliding"},
                                   "right": {"on": "right", "kind": "sliding"},
                                   "bottom": {"on": "far", "kind": "clamped"}}}}}


def limit_load_eq(level: int, k: float = K) -> dict:
    """Lower-bound limit analysis in the equilibrium space at mesh ``level``.

    Returns ``alpha`` (the solver's ``q_lim / k``), ``alpha_certified`` (the certified lower bound),
    ``ratio`` (``alpha_certified / (2 + pi)``), ``n_unknowns`` (``y`` and ``alpha``), ``time`` (the
    solve with the model's exactness step, seconds), ``max_tau`` (``max tau / k`` of the certified
    field), ``residual`` (the largest violation of any admissibility constraint by ``stress_unit``,
    relative to the stress scale: ``model.solution()``'s check), ``status`` (the solver's), ``post``
    (what the exactness step changed), ``model`` and, to check it, ``space`` and ``stress_unit``:
    ``(n_sub, 3, 3)`` vertex values of an exactly admissible field for the unit load ``q = 1``. The
    certified field is ``alpha_certified * stress_unit``.
    """
    model = cvxdual.build_model(punch_scene(), level=level, stress_space="eq", limit_analysis=True)
    block = model.vertex_body == 1  # the punch (body 0) is rigid: uncapped
    model.add_constraint(model.shear_cap(k, where=block), name="yield")  # one cone per block vertex
    t0 = time.perf_counter()
    info = model.solve(**CLARABEL)  # and model.stresses() made exactly admissible
    wall = time.perf_counter() - t0
    a = float(model.load_factor.value)
    # certification: the exact field at the solver's alpha meets tau <= k only to the solver's
    # tolerance; scaled by 1 / max(1, max tau / k) it lies in the yield set, and (no body force)
    # it is exactly admissible for the scaled load
    stress = model.stresses()  # exactly admissible for alpha q
    tau = float(shear_stress(stress.reshape(-1, 3))[block].max())  # the numpy twin of model.shear_stress()
    certified = a / max(1.0, tau / k)
    sol = model.solution()  # raises AccuracyError unless the exact field is admissible ('yield': to 1e-6)
    return {"level": level, "n_unknowns": model.space.n_y + 1, "alpha": a, "alpha_certified": certified,
            "ratio": certified / PRANDTL, "time": wall, "status": info["status"],
            "max_tau": certified / a * tau / k, "residual": sol.checks["applied"]["admissibility"],
            "post": {key: info[key] for key in ("contact_change", "projection_iterations", "max_change")},
            "model": model, "space": model.space, "stress_unit": stress / a}


def limit_load_p0(level: int, k: float = K) -> dict:
    """The same maximisation in the paper's piecewise-constant space (:class:`cvxdual.DualModel`).

    Returns ``status`` (``"unbounded"`` or the solver's), ``alpha`` (``None`` when unbounded),
    ``n_pieces`` and ``time``. Expected: unbounded; see the module docstring.
    """
    model = cvxdual.build_model(punch_scene(), level=level, limit_analysis=True)
    block = np.flatnonzero(model.system.pieces.body == 1)  # the punch (body 0) is rigid: uncapped
    model.add_constraint(model.shear_cap(k, where=block), name="yield")
    t0 = time.perf_counter()
    try:
        model.solve()
    except cvxdual.SolverError as e:
        if "unbounded" not in str(e):
            raise
        status, value = "unbounded", None
    else:
        status, value = "optimal", float(model.load_factor.value)
    return {"level": level, "n_pieces": model.system.n_pieces, "status": status, "alpha": value,
            "time": time.perf_counter() - t0}


def plot_ratio(eq: list[dict], p0: list[dict] | None = None, ax=None):
    """``q_lim / ((2 + pi) k)`` against the mesh level: the solver's value and the certified lower
    bound, with Prandtl's value (1.0); P0 results are named in a note (they have no value)."""
    import matplotlib.pyplot as plt
    if ax is None:
        ax = plt.figure(figsize=(5.5, 4.0)).add_subplot()
    lv = [r["level"] for r in eq]
    ax.axhline(1.0, color="k", lw=1.0, label=r"Prandtl $(2 + \pi)\,k$")
    ax.plot(lv, [r["alpha"] / PRANDTL for r in eq], "o", mfc="none", ms=9, label="solver")
    ax.plot(lv, [r["ratio"] for r in eq], "s-", ms=5, label="certified lower bound")
    if p0:
        names = ", ".join(f"L{r['level']}: {r['status']}" for r in p0)
        ax.text(0.98, 0.04, f"P0 space: {names}\n(not a bound)", transform=ax.transAxes, ha="right",
                fontsize=8)
    ax.set_xticks(lv)
    ax.set_xlabel("mesh level (h halves per level)")
    ax.set_ylabel(r"$q_\mathrm{lim} \,/\, (2 + \pi)\,k$")
    ax.set_title("Prandtl punch: static (lower-bound) limit analysis", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, 0.93), fontsize=8)
    return ax


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", default="0,1,2", help="comma-separated mesh levels (default 0,1,2)")
    parser.add_argument("--out", default="out/examples/prandtl_punch", help="output directory")
    args = parser.parse_args(argv)
    levels = [int(v) for v in args.levels.split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    eq, p0 = [], []
    print(f"{'level':>5} {'unknowns':>9} {'q_lim/k':>9} {'certified':>10} {'error %':>8} {'time s':>7}   P0 space")
    for level in levels:
        r, q = limit_load_eq(level), limit_load_p0(level)
        eq.append(r)
        p0.append(q)
        p0_text = "unbounded — not a bound" if q["alpha"] is None else f"{q['alpha']:.4f} — not a bound"
        print(f"{level:5d} {r['n_unknowns']:9d} {r['alpha']:9.4f} {r['alpha_certified']:10.4f} "
              f"{100 * (r['ratio'] - 1):8.2f} {r['time']:7.2f}   {p0_text}", flush=True)
    print(f"Prandtl: (2 + pi) k = {PRANDTL:.4f} k; certified values are lower bounds (static theorem)")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 4.0), layout="constrained")
    plot_ratio(eq, p0, ax=ax)
    fig.savefig(out / "prandtl.png", format="png", dpi=150)
    plt.close(fig)
    lines = ["level,n_unknowns,alpha,alpha_certified,ratio,error_percent,time_s,max_tau,residual,p0_status,p0_alpha"]
    for r, q in zip(eq, p0, strict=True):
        lines.append(f"{r['level']},{r['n_unknowns']},{r['alpha']:.10g},{r['alpha_certified']:.10g},"
                     f"{r['ratio']:.10g},{100 * (r['ratio'] - 1):.6g},{r['time']:.4g},{r['max_tau']:.12g},"
                     f"{r['residual']:.3g},{q['status']},{'' if q['alpha'] is None else repr(q['alpha'])}")
    (out / "prandtl.csv").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'prandtl.png'} and {out / 'prandtl.csv'}")
    return eq


if __name__ == "__main__":
    main()
