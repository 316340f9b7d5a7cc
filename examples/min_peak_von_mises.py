r"""The least possible peak von Mises stress of Hertz line contact over statically admissible fields.

Problem
-------
The built-in ``hertz`` scene (cylinder on block, ``nu = 0.3``, plane strain, ``P = 35 kN/mm``,
``p0 = 3585 MPa``, ``a = 6.21 mm``; units mm and MPa), with ``s33 = nu (s11 + s22)`` and
``vm`` the von Mises stress as in ``examples/von_mises_cap.py``. Drop the energy and ask::

    k* = min  max_x vm(sigma(x))   over statically admissible sigma
         (div sigma = 0, the scene's boundary tractions, compressive frictionless contact).

By the static theorem ``k*`` is the smallest yield stress (of a rigid-perfectly plastic body
with the yield function ``vm <= k``) at which the load is carried at all; the elastic field is
one admissible field, so ``k* <=`` its peak (the exact one: ``0.557 p0`` at depth ``0.70 a``).

Two discretisations
-------------------
*P0* (the paper's space, :class:`cvxdual.DualModel`): ``model.set_objective(cp.Minimize(
cp.max(model.von_mises())))``, one second-order cone per piece, no energy. Equilibrium is
*weak*: tested only against P1 displacements. This is an external approximation: the piece
means of any exactly admissible field satisfy it (a P1 strain is constant on a piece, so only
the mean is tested) and, ``vm`` being convex, the mean's von Mises is at most the field's
maximum on the piece (Jensen). So the P0 value lies *below* ``k*`` -- up to the quadrature
of the boundary tractions, which makes it an estimate from below, not a certified bound.

*eq* (:class:`cvxdual.eq.space.EquilibriumSpace`, the Johnson-Mercier space): exactly
admissible fields, linear on every sub-triangle; ``vm`` is convex, so capping it at the three
vertices of every sub-triangle caps it everywhere. ``cvxdual.build_model(scene,
stress_space="eq")`` (:class:`cvxdual.eq.model.EquilibriumModel`) takes the same objective,
``cp.max(model.von_mises())`` over the sub-triangle vertices. After the solve the model makes the
field exact (:func:`cvxdual.eq.space.make_exact`), and the largest von Mises value at the
vertices of that exact field, ``model.stresses()``, is the certified value: an exactly admissible
field (for the loads as the eq space represents them: the boundary tractions linear on each
edge) whose von Mises nowhere exceeds it -- an upper bound on ``k*``.

Why ``k*`` is so low (about 0.2 of the elastic peak)
----------------------------------------------------
Not, mainly, because P0 equilibrium is weak: the certified eq value is only a few per cent above
the P0 one, and the two bracket ``k*`` (measured: 0.211 and 0.222 of the exact elastic peak at
P0 level 3 and eq level 1). It is low because nothing but statics is asked: without the energy
there is no compatibility, so the contact need not stay ``2a`` wide -- the optimal fields press
nearly uniformly (about 0.18 p0) on most of the 30 mm candidate interval instead of with
``p0`` on ``a = 6.2 mm``. The elastic peak ``0.56 p0`` is a concentration made by
compatibility; ``k*`` is a collapse (limit-analysis) quantity. The P0 value rises slowly with
the level, the eq value falls: both approach ``k*``. The optimal field is not unique (away from
where the peak is attained the pieces are free below it), so only its peak is reported.

Run::

    python examples/min_peak_von_mises.py --levels 1,2,3 --eq-levels 0,1 --out out/examples/min_peak_von_mises
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cvxpy as cp
import numpy as np

import cvxdual
from cvxdual.reference import mcewen_stress
from cvxdual.voigt import out_of_plane_factor, von_mises

SCENE = "hertz"
# a pair carries load if its force exceeds this fraction of the largest: the interior-point
# solver leaves forces of ~1e-6 of it on pairs that carry none
CARRIES = 1e-3


def exact_elastic_peak(scene=SCENE) -> float:
    """Peak von Mises of the exact (McEwen) elastic field, on the symmetry axis (where it lies
    for Hertz line contact), maximised over a fine depth grid refined once around its maximum."""
    sc = cvxdual.load_scene(scene)
    hz = cvxdual.exact_field(sc).hertz
    nu = max(b.material.nu for b in sc.bodies)  # hertz: one nu; the larger gives the larger peak
    z = np.linspace(0.0, 4.0 * hz.a, 4001)
    for _ in range(2):  # second pass: 4001 points across the best interval of the first
        sx, sz, txz = mcewen_stress(np.zeros_like(z), z, hz.a, hz.p0)
        vm = von_mises(np.column_stack([sx, sz, txz]), nu)
        i = int(np.argmax(vm))
        z = np.linspace(z[max(i - 1, 0)], z[min(i + 1, len(z) - 1)], 4001)
    return float(vm.max())


def min_peak_p0(level: int, scene=SCENE) -> dict:
    """Elastic solve, then ``minimise max vm`` over P0-admissible fields on the same model.

    Returns ``elastic_peak``, ``min_peak`` (MPa), ``ratio`` (their quotient), ``vm``, ``stress``,
    ``twin_difference``
    (numpy twin against the CVXPY expression, relative), the contact of both fields
    (``contact_elastic``, ``contact``: the solutions' contact dicts), ``checks``, ``time``, ``model``.
    """
    model = cvxdual.build_model(scene, level=level)
    factor = out_of_plane_factor(model.system.mesh.scene, model.system.pieces.body)
    model.solve()
    sol_el = model.solution()
    peak = float(von_mises(model.stresses(), factor).max())
    model.set_objective(cp.Minimize(cp.max(model.von_mises())))  # in MPa: O(100-1000), Clarabel copes
    t0 = time.perf_counter()
    model.solve()
    wall = time.perf_counter() - t0
    sol = model.solution()
    st = model.stresses()
    vm = von_mises(st, factor)
    return {"level": level, "n_pieces": model.system.n_pieces, "elastic_peak": peak, "min_peak": float(vm.max()),
            "ratio": float(vm.max()) / peak, "objective": float(model.problem.value), "vm": vm, "stress": st,
            "twin_difference": float(np.abs(model.value(model.von_mises()) - vm).max() / vm.max()),
            "contact_elastic": sol_el.contact,
            "extent_elastic": contact_extent(sol_el.contact), "extent": contact_extent(sol.contact),
            "contact": sol.contact, "checks": sol.checks, "time": wall, "model": model}


def contact_extent(contact: dict) -> float:
    """The largest ``x`` [mm] of a pair that carries load, judged by the forces alone: the
    solution's active set also weighs the openings, and after ``set_objective`` the multipliers
    are not displacements."""
    f = contact["force"]
    return float(contact["x"][f > CARRIES * f.max()].max())


def min_peak_eq(level: int, scene=SCENE) -> dict:
    """``minimise max vm`` over exactly admissible Johnson-Mercier fields (``vm`` at every
    sub-triangle vertex); the model makes the field exact, and its peak is the certified value.

    Returns ``solver_value`` (the solver's objective, MPa), ``certified`` (the exact field's peak,
    MPa), ``residual`` (largest admissibility residual, relative to the stress scale:
    ``model.solution()``'s check), ``status``, ``time`` (the solve with the exactness step),
    ``n_unknowns``, ``post`` (what the exactness step changed), ``model``, ``space``, ``sigma``
    (exact vertex values, ``(n_sub, 3, 3)``; rows of ``sigma.reshape(-1, 3)`` belong to the bodies
    ``model.vertex_body``) and ``pressure`` ``(n_c, 2)`` with ``x`` ``(n_c, 2)``: the contact
    pressure of the exact field at the ends of each contact edge.
    """
    model = cvxdual.build_model(scene, level=level, stress_space="eq")
    model.set_objective(cp.Minimize(cp.max(model.von_mises())))  # in MPa, as for P0
    t0 = time.perf_counter()
    info = model.solve()  # and model.stresses() made exactly admissible
    wall = time.perf_counter() - t0
    sigma = model.stresses()
    factor = out_of_plane_factor(model.space.scene, model.vertex_body)
    sol = model.solution()  # raises AccuracyError unless the exact field is admissible
    return {"level": level, "n_unknowns": model.space.n_y + 1, "solver_value": float(model.problem.value),
            "certified": float(von_mises(sigma.reshape(-1, 3), factor).max()),
            "residual": sol.checks["applied"]["admissibility"], "status": info["status"], "time": wall,
            "post": {key: info[key] for key in ("contact_change", "projection_iterations", "max_change")},
            "model": model, "space": model.space, "sigma": sigma, "x": model.space.contact_x,
            "pressure": sol.contact["edge_pressure"]}


def plot_ratio(p0: list[dict], eq: list[dict], exact: float, ax=None):
    """Min peak / exact elastic peak against the level: P0 (an estimate from below) and eq
    (certified, from above); ``k*`` lies between."""
    import matplotlib.pyplot as plt
    if ax is None:
        ax = plt.figure(figsize=(5.0, 4.0)).add_subplot()
    if p0:
        ax.plot([r["level"] for r in p0], [r["min_peak"] / exact for r in p0], "o-",
                label="P0 (weak equilibrium): from below, not certified")
    if eq:
        ax.plot([r["level"] for r in eq], [r["certified"] / exact for r in eq], "s-",
                label="eq (exact equilibrium): certified, from above")
    ax.set_xticks(sorted({r["level"] for r in p0 + eq}))
    ax.set_xlabel("mesh level (h halves per level)")
    ax.set_ylabel(f"min peak von Mises / elastic peak ({exact:.0f} MPa)")
    ax.set_title("least peak von Mises over admissible fields", fontsize=10)
    ax.legend(fontsize=7, loc="upper right")
    return ax


def plot_pressure(p0: dict, eq: dict | None, ax=None):
    """Contact pressure [MPa] against x [mm]: Hertz (exact elastic), the P0 elastic field, the
    P0 and eq fields of least peak von Mises."""
    import matplotlib.pyplot as plt
    if ax is None:
        ax = plt.figure(figsize=(5.0, 4.0)).add_subplot()
    field = cvxdual.exact_field(p0["model"].system.mesh.scene)
    ce, c = p0["contact_elastic"], p0["contact"]
    x = np.linspace(0.0, float(c["x"].max()), 600)
    ax.plot(x, field.pressure(x), "k-", lw=1.0, label="Hertz (exact elastic)")
    ax.plot(ce["x"], ce["pressure"], "o", ms=3, mfc="none", label=f"P0 elastic, level {p0['level']}")
    ax.plot(c["x"], c["pressure"], ".-", ms=4, lw=0.8, label=f"P0 least peak, level {p0['level']}")
    if eq is not None:
        xs = np.column_stack([eq["x"], np.full(len(eq["x"]), np.nan)]).ravel()  # one segment per edge
        ps = np.column_stack([eq["pressure"], np.full(len(eq["x"]), np.nan)]).ravel()
        ax.plot(xs, ps, "-", lw=1.2, label=f"eq least peak, level {eq['level']}")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("contact pressure [MPa]")
    ax.set_title("no energy, no compatibility: the load spreads", fontsize=10)
    ax.legend(fontsize=7)
    return ax


def _levels(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v.strip()]


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", default="1,2,3", help="comma-separated P0 mesh levels (default 1,2,3)")
    parser.add_argument("--eq-levels", default="0,1",
                        help="comma-separated eq-space levels (default 0,1; level 2 takes ~7 s, 3 about a minute; "
                             "'' for none)")
    parser.add_argument("--out", default="out/examples/min_peak_von_mises", help="output directory")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    exact = exact_elastic_peak()
    p0_0 = cvxdual.exact_field(cvxdual.load_scene(SCENE)).hertz.p0

    print(f"{'space':>5} {'level':>5} {'unknowns':>9} {'elastic MPa':>12} {'min peak MPa':>13} {'/elastic':>9} "
          f"{'/exact el.':>10} {'contact to':>10} {'time s':>7}")
    p0 = []
    for level in _levels(args.levels):
        r = min_peak_p0(level)
        p0.append(r)
        print(f"{'P0':>5} {level:5d} {3 * r['n_pieces']:9d} {r['elastic_peak']:12.1f} {r['min_peak']:13.1f} "
              f"{r['ratio']:9.4f} {r['min_peak'] / exact:10.4f} {r['extent']:7.2f} mm {r['time']:7.2f}",
              flush=True)
    eq = []
    for level in _levels(args.eq_levels):
        r = min_peak_eq(level)
        eq.append(r)
        print(f"{'eq':>5} {level:5d} {r['n_unknowns']:9d} {'':>12} {r['certified']:13.1f} {'':>9} "
              f"{r['certified'] / exact:10.4f} {'':>10} {r['time']:7.2f}", flush=True)
    print(f"exact elastic peak {exact:.1f} MPa = {exact / p0_0:.4f} p0. P0 values are estimates from below "
          "(weak equilibrium), eq values certified upper bounds on the least peak k*.")
    if p0:
        r = p0[-1]
        c, ce = r["contact"], r["contact_elastic"]
        print(f"P0 level {r['level']}: contact to x = {r['extent']:.2f} mm (elastic: {r['extent_elastic']:.2f} mm), "
              f"max pressure {c['max_pressure']:.0f} MPa (elastic {ce['max_pressure']:.0f}); checks applied: "
              + ", ".join(f"{k} {v:.1e}" for k, v in p0[-1]["checks"]["applied"].items())
              + "; skipped: " + ", ".join(p0[-1]["checks"]["skipped"]))

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2 if p0 else 1, figsize=(10.5 if p0 else 5.2, 4.2), layout="constrained",
                             squeeze=False)
    plot_ratio(p0, eq, exact, axes[0, 0])
    if p0:
        plot_pressure(p0[-1], eq[-1] if eq else None, axes[0, 1])
    fig.savefig(out / "min_peak_von_mises.png", format="png", dpi=150)
    plt.close(fig)
    lines = ["space,level,unknowns,elastic_peak,min_peak,ratio_to_elastic,ratio_to_exact_elastic,"
             "contact_extent,equilibrium_residual,time_s"]
    for r in p0:
        lines.append(f"p0,{r['level']},{3 * r['n_pieces']},{r['elastic_peak']:.10g},{r['min_peak']:.10g},"
                     f"{r['ratio']:.10g},{r['min_peak'] / exact:.10g},{r['extent']:.10g},"
                     f"{r['checks']['applied']['equilibrium']:.3g},{r['time']:.4g}")
    for r in eq:
        lines.append(f"eq,{r['level']},{r['n_unknowns']},{exact:.10g},{r['certified']:.10g},"
                     f"{r['certified'] / exact:.10g},{r['certified'] / exact:.10g},,{r['residual']:.3g},"
                     f"{r['time']:.4g}")
    (out / "min_peak_von_mises.csv").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'min_peak_von_mises.png'} and {out / 'min_peak_von_mises.csv'}")
    return {"p0": p0, "eq": eq, "exact_elastic_peak": exact}


if __name__ == "__main__":
    main()
