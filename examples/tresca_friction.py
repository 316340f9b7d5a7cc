r"""Tresca friction in a Hertz line contact: stick and slip zones, and when friction matters.

Problem
-------
The NAFEMS-style cylinder on block (plane strain, R = 50 mm, P = 35 kN per mm of thickness,
nu = 0.3, cylinder E1 = 70 GPa on a block E2 = 210 GPa; Hertz: a = 6.21 mm, p0 = 3585 MPa),
solved with Tresca friction of slip threshold ``g = 0.1 p0`` and without friction, in three cases:

- ``cylinder-on-block``: the built-in scene, the true circular face (full model, cylinder
  clamped on its top, block sliding on its sides and pushed up by a uniform traction);
- ``hertz``: the same data linearised (flat faces, gap ``x^2 / 2R``, half model, the exact McEwen
  tractions on every truncated boundary);
- ``similar``: ``hertz`` with both bodies of steel (E = 210 GPa), elastically similar, with
  ``p0 = 5070 MPa`` and ``a = 4.39 mm`` for that pair.

``p0`` and ``a`` come from :func:`cvxdual.reference.hertz_line_contact` with the scene's own data
(its materials, ``R`` and load), and ``g = 0.1 p0``: 358.5 MPa for the dissimilar pair,
507.0 MPa for the similar one.

Tresca friction in the dual problem
-----------------------------------
At every contact pair ``k`` whose ``x`` dofs are free, the two frictionless rows
``R'_x(A_k) = R''_x(B_k) = 0`` become action = reaction, ``R'_x(A_k) + R''_x(B_k) = 0``, and the
friction bound ``|Q_k| <= g w_k``, with ``Q_k = R''_x(B_k)`` the ``x`` force of the cylinder on the
block and ``w_k`` the pair's tributary length (:meth:`cvxdual.DualModel.add_friction`). The
problem stays a convex QP. Its multipliers are the slips ``s_k = u''_x - u'_x``, and the
optimality conditions are Tresca's law, with ``q_k = Q_k / w_k`` the tangential traction::

    |q_k| <= g,      q_k s_k <= 0 (friction opposes slip),      (g - |q_k|) s_k = 0,

so a pair either sticks (``|q| < g``, ``s = 0``) or slips at the bound (``|q| = g``). The primal
counterpart adds the dissipation ``sum_k g w_k |s_k|`` to the potential energy.
``sol.contact["stick"]`` marks the active pairs that stick; here *slip* means active, free in ``x``
and not sticking. The pair on the symmetry line of the half models has its ``x`` dofs fixed. It
has no slip unknown and is neither: it is counted under "fixed".

What Tresca is, honestly
------------------------
- **The threshold does not depend on the pressure.** ``g`` acts on the whole candidate interval,
  *open pairs included*. An open pair can carry a tangential force up to ``g w`` and is held in
  ``x`` below it. The table's ``open@g`` column counts the open pairs at the bound: next to the
  contact zone, and in ``cylinder-on-block`` also at the far ends of the candidate interval, where
  the faces are 4 mm apart. The other open pairs carry less, but not nothing. Coulomb friction
  would give an open pair no tangential force at all.
- **Coulomb friction** (``|q| <= mu p``) is not convex: the bound depends on the unknown pressure.
  A fixed point of Tresca problems, ``g_k = mu p_k`` from the previous pressure, can approximate it:
  ``--coulomb MU`` iterates that from the frictionless pressure, at most ``--iterations`` times.
  It stops when the pressure changes by less than ``1e-6 p0``, and it reports every run that
  stops without meeting that as *not converged*. Nothing guarantees that such a fixed point
  exists, is unique, or is reached.
- **The loads are prescribed**, so friction cannot change the total normal force: the block's
  ``y`` equilibrium (``hertz``: the cylinder's) fixes it.

When friction matters
---------------------
Under a normal load, elastically *similar* bodies have no tendency to slip: their surface points
move tangentially by the same amount (Dundurs' ``beta = 0``; Johnson, *Contact Mechanics*, 1985,
on interface friction in normal contact). Friction then changes nothing, and the relative L2
difference (area and Voigt weighted, :data:`cvxdual.voigt.VOIGT_WEIGHT`) between the Tresca and
the frictionless stresses goes to zero with ``h``. The built-in ``hertz`` meshes of the two bodies
are exact mirror images, so with equal materials the discrete slip tendency is *exactly* zero too.
The difference is then solver noise (1e-9 to 1e-7), and it does not decrease with the level. The
``similar`` case therefore meshes the cylinder differently (``layers = 4``, ``focus_depth = 5``):
the difference then decreases, from 4.2e-3 and 1.7e-3 to 5.9e-4 at levels 1 to 3. For the
*dissimilar* pair the softer cylinder tends to slip against the block. Friction resists that near
the contact edges (slip zones) and holds it in the middle (stick zone), and the difference levels
off: 0.133 at levels 1 to 3 (``hertz``), and 0.075, 0.080, 0.082 (``cylinder-on-block``, still
creeping up). That value is a property of the frictional problem, not a discretisation error.
About half of it comes from the open pairs held by Tresca's ``g``: with a per-pair threshold,
``g`` at the pairs active without friction and 0 elsewhere
(``model.add_friction(np.where(active0, g, 0.0))``), it is 0.067 (``hertz``) and 0.045
(``cylinder-on-block``) at level 3.

Friction from a scene file
--------------------------
The same run through the package's own problem (``cvxdual.solve``; ``main`` checks that it gives
the model's stresses)::

    scene = cvxdual.load_scene("cylinder-on-block",
                               overrides=[{"contact": {"friction": {"kind": "tresca", "g": 358.5}}}])
    sol = cvxdual.solve(scene, level=2)      # sol.contact["tangential_force"], ["slip"], ["stick"]

or in TOML (``base = "cylinder-on-block"`` and ``[contact] friction = { kind = "tresca", g = 358.5 }``),
or on the command line::

    cvxdual solve --scene cylinder-on-block --set contact.friction.g=358.5 --level 2

whose ``contact.csv`` has the columns ``tangential_force`` (a nodal force in N/mm, not a
traction), ``slip`` (mm) and ``stick`` (0/1).

Run::

    python examples/tresca_friction.py --levels 1,2,3 --out out/examples/tresca_friction
    python examples/tresca_friction.py --coulomb 0.1        # and the Coulomb fixed point
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import cvxdual
from cvxdual.reference import HertzData, hertz_line_contact, hertz_pressure
from cvxdual.voigt import VOIGT_WEIGHT

G_OVER_P0 = 0.1  # the Tresca threshold g = 0.1 p0
# "similar": steel on steel, the cylinder meshed unlike the block (no mirror symmetry, see above)
SIMILAR = [{"bodies": {"cylinder": {"material": {"E": 210000.0}, "layers": 4, "focus_depth": 5.0}}}]
CASES = {  # name: (built-in scene, overrides, label)
    "cylinder-on-block": ("cylinder-on-block", None, "cylinder on block (70/210 GPa, true circle)"),
    "hertz": ("hertz", None, "Hertz, dissimilar (70/210 GPa)"),
    "similar": ("hertz", SIMILAR, "Hertz, similar (210/210 GPa)"),
}
# a pair is at the friction bound when |q| >= (1 - BOUND_TOL) g: the interior-point solver leaves
# slipping pairs up to ~3e-5 g below it at level 1 (measured), sticking ones stay below 0.995 g
BOUND_TOL = 1e-3
COULOMB_TOL = 1e-6  # fixed point: pressure change / p0; the solver resolves pressures to ~1e-8 p0


def case_scene(case: str) -> cvxdual.Scene:
    """The scene of ``case`` (a key of :data:`CASES`), frictionless."""
    name, overrides, _ = CASES[case]
    return cvxdual.load_scene(name, overrides=overrides)


def hertz_data(scene: cvxdual.Scene) -> HertzData:
    """Hertz's ``a`` and ``p0`` for the scene's data: its two materials, and ``R`` and the load of
    its exact field (``hertz``), or else the radius of the upper body's circular face and the
    lower body's uniform ``far`` traction times its width (``cylinder-on-block``)."""
    upper, lower = scene.bodies
    if scene.exact is not None and scene.exact.kind == "hertz":
        R, load = scene.exact.R, scene.exact.load
    else:
        R = upper.face.R
        x0, x1 = lower.x_range
        load = sum(p.traction.value[1] * (x1 - x0) for p in lower.boundary
                   if p.kind == "traction" and p.on == "far" and p.traction.kind == "uniform")
    return hertz_line_contact(upper.material.E, upper.material.nu, lower.material.E, lower.material.nu, R, load,
                              plane=upper.material.plane)


def sliding_pairs(system) -> np.ndarray:
    """Pairs whose ``x`` dofs are both free (the others have no tangential unknown)."""
    up, lo = system.mesh.pairs.T
    return (system.rdof[2 * up] >= 0) & (system.rdof[2 * lo] >= 0)


def relative_difference(system, a: np.ndarray, b: np.ndarray) -> float:
    """``||a - b||_0 / ||b||_0`` of piecewise-constant stresses on one mesh (area and Voigt weighted)."""
    def norm(t):
        return np.sqrt(np.sum(system.pieces.area[:, None] * VOIGT_WEIGHT * t**2))
    return float(norm(a - b) / norm(b))


def solve_case(case: str, level: int, g_over_p0: float = G_OVER_P0) -> dict:
    """Frictionless and Tresca (``g = g_over_p0 p0``) solutions of ``case`` at ``level``.

    Returns the two :class:`cvxdual.Solution` (``frictionless``, ``tresca``), ``hertz`` (a, p0),
    ``g``, and per pair (Tresca): ``x``, ``width``, ``pressure``, ``pressure_frictionless``, ``q``
    (tangential traction on the block), ``slip``, ``active``, ``stick``, ``slides`` (free in ``x``),
    ``slipping`` (active, free, not sticking), ``fixed`` (active, ``x`` fixed), ``open_at_bound``.
    Also ``difference`` (relative L2 stress difference to frictionless) and ``time`` (seconds).
    """
    scene = case_scene(case)
    hz = hertz_data(scene)
    g = g_over_p0 * hz.p0
    t0 = time.perf_counter()
    free = cvxdual.build_model(scene, level=level)
    free.solve()
    sol0 = free.solution()
    model = cvxdual.build_model(scene, level=level)
    model.add_friction(g)
    model.solve()
    sol = model.solution()
    wall = time.perf_counter() - t0
    c, system = sol.contact, sol.system
    width = system.width
    q = c["tangential_force"] / width
    slides = sliding_pairs(system)
    at_bound = slides & (np.abs(q) >= (1.0 - BOUND_TOL) * g)
    return {"case": case, "level": level, "scene": scene, "hertz": hz, "g": g, "frictionless": sol0, "tresca": sol,
            "x": c["x"], "width": width, "pressure": c["pressure"], "pressure_frictionless": sol0.contact["pressure"],
            "q": q, "slip": c["slip"], "active": c["active"], "stick": c["stick"], "slides": slides,
            "slipping": c["active"] & slides & ~c["stick"], "fixed": c["active"] & ~slides,
            "open_at_bound": at_bound & ~c["active"],
            "difference": relative_difference(system, sol.stress, sol0.stress), "time": wall}


def row(r: dict) -> dict:
    """The table row of a :func:`solve_case` result."""
    f, f0 = r["tresca"].contact["total_force"], r["frictionless"].contact["total_force"]
    return {"case": r["case"], "level": r["level"], "n_pairs": len(r["x"]), "n_active": int(r["active"].sum()),
            "n_stick": int(r["stick"].sum()), "n_slip": int(r["slipping"].sum()), "n_fixed": int(r["fixed"].sum()),
            "n_open_at_bound": int(r["open_at_bound"].sum()), "p0": r["hertz"].p0, "g": r["g"],
            "max_q_over_p0": float(np.abs(r["q"]).max() / r["hertz"].p0),
            "max_q_active_over_p0": float(np.abs(r["q"][r["active"]]).max(initial=0.0) / r["hertz"].p0),
            "difference": r["difference"], "total_force": f, "force_change": (f - f0) / f0, "time": r["time"]}


def solve_from_scene(case: str, level: int, g: float) -> cvxdual.Solution:
    """``case`` with ``[contact] friction = {kind = "tresca", g = g}`` through ``cvxdual.solve``."""
    name, overrides, _ = CASES[case]
    friction = {"contact": {"friction": {"kind": "tresca", "g": float(g)}}}
    return cvxdual.solve(cvxdual.load_scene(name, overrides=[*(overrides or []), friction]), level=level)


def coulomb_fixed_point(case: str, level: int, mu: float, iterations: int = 30, tol: float = COULOMB_TOL) -> dict:
    """Approximate Coulomb friction ``|q| <= mu p`` by Tresca problems with the per-pair threshold
    ``g_k = mu max(p_k, 0)`` from the previous pressure, starting from the frictionless one.

    Stops when ``max |p_new - p_old| <= tol p0`` (``converged``) or after ``iterations`` solves
    (``converged`` False). Returns the last :class:`cvxdual.Solution` (``solution``), ``changes`` (the
    pressure change / p0 of every iteration), ``coulomb_violation`` (``max(|q| - mu p) / p0`` at the
    last solve, with its own pressure), the counts of :func:`row` and ``time``.
    """
    scene = case_scene(case)
    hz = hertz_data(scene)
    system = cvxdual.build_system(scene, level=level)
    t0 = time.perf_counter()
    model = cvxdual.DualModel(system)
    model.solve()
    p = model.solution().contact["pressure"]
    changes, sol = [], None
    for _ in range(iterations):
        model = cvxdual.DualModel(system)  # g = 0 pairs keep their frictionless rows
        model.add_friction(mu * np.maximum(p, 0.0))
        model.solve()
        sol = model.solution()
        p_new = sol.contact["pressure"]
        changes.append(float(np.abs(p_new - p).max() / hz.p0))
        p = p_new
        if changes[-1] <= tol:
            break
    c = sol.contact
    q = c["tangential_force"] / system.width
    slides = sliding_pairs(system)
    return {"case": case, "level": level, "mu": mu, "solution": sol, "converged": changes[-1] <= tol,
            "iterations": len(changes), "changes": changes,
            "coulomb_violation": float(np.max(np.abs(q) - mu * np.maximum(p, 0.0)) / hz.p0),
            "n_active": int(c["active"].sum()), "n_stick": int(c["stick"].sum()),
            "n_slip": int((c["active"] & slides & ~c["stick"]).sum()),
            "max_q_over_p0": float(np.abs(q).max() / hz.p0), "time": time.perf_counter() - t0}


def _spans(x: np.ndarray, width: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    """``(start, length)`` of the tributary interval of each pair in ``mask``: from the midpoints
    to its neighbours (the half width at the ends)."""
    i = np.argsort(x)
    xs = x[i]
    mid = 0.5 * (xs[1:] + xs[:-1])
    lo = np.concatenate([[xs[0] - 0.5 * width[i[0]]], mid])
    hi = np.concatenate([mid, [xs[-1] + 0.5 * width[i[-1]]]])
    m = mask[i]
    return list(zip(lo[m], hi[m] - lo[m], strict=True))


ZONES = (("stick", "#2ca02c", "stick"), ("slipping", "#d62728", "slip"),
         ("open_at_bound", "#ff7f0e", "open, |q| = g"))


def plot_profiles(r: dict, axes=None):
    """Pressure (Tresca, frictionless, Hertz) on ``axes[0]`` and tangential traction ``q`` with
    ``+-g`` on ``axes[1]``, along ``x``, with the stick, slip and open-at-the-bound zones shaded.
    Returns the two axes."""
    import matplotlib.pyplot as plt
    if axes is None:
        axes = plt.figure(figsize=(5.0, 6.0)).subplots(2, 1, sharex=True)
    ax_p, ax_q = axes
    i = np.argsort(r["x"])
    x = r["x"][i]
    a, p0 = r["hertz"].a, r["hertz"].p0
    xx = np.linspace(max(x[0], -2.0 * a), min(x[-1], 2.0 * a), 400)
    for ax, labelled in ((ax_p, False), (ax_q, True)):
        for key, colour, label in ZONES:
            ax.broken_barh(_spans(r["x"], r["width"], r[key]), (0.0, 1.0), transform=ax.get_xaxis_transform(),
                           color=colour, alpha=0.18, lw=0, label=label if labelled else None)
    ax_p.plot(xx, hertz_pressure(xx, a, p0), color="0.6", lw=1.0, label="Hertz (frictionless)")
    ax_p.plot(x, r["pressure_frictionless"][i], "k--", lw=1.2, label="frictionless")
    ax_p.plot(x, r["pressure"][i], "o-", color="C0", ms=3, lw=1.2, label=f"Tresca, g = {r['g']:.1f} MPa")
    ax_p.set_ylabel("contact pressure p (MPa)")
    ax_p.set_title(f"{CASES[r['case']][2]}, level {r['level']}", fontsize=9)
    ax_q.axhline(r["g"], color="k", ls=":", lw=1.0)
    ax_q.axhline(-r["g"], color="k", ls=":", lw=1.0, label="$\\pm g$")
    ax_q.axhline(0.0, color="0.5", lw=0.5)
    ax_q.plot(x, r["q"][i], "o-", color="C1", ms=3, lw=1.2, label="Tresca")
    ax_q.set_ylabel("tangential traction q on the block (MPa)")
    ax_q.set_xlabel("x (mm)")
    lim = 2.0 * a
    ax_q.set_xlim(max(x[0], -lim) - 0.05 * lim, min(x[-1], lim) + 0.05 * lim)
    hidden = int(np.sum(r["open_at_bound"] & (np.abs(r["x"]) > lim)))
    if hidden:  # Tresca also holds pairs far from the contact zone
        ax_q.text(0.02, 0.88, f"{hidden} more open pairs at |q| = g beyond |x| = {lim:.1f} mm",
                  transform=ax_q.transAxes, va="top", fontsize=7, bbox={"fc": "w", "ec": "none", "alpha": 0.8})
    ax_p.legend(fontsize=7, loc="upper right")
    ax_q.legend(fontsize=7, loc="upper right")
    return axes


def plot_difference(rows: list[dict], ax=None):
    """The relative L2 stress difference Tresca - frictionless against the level, per case."""
    import matplotlib.pyplot as plt
    if ax is None:
        ax = plt.figure(figsize=(5.0, 4.0)).add_subplot()
    for n, case in enumerate(CASES):
        rs = [r for r in rows if r["case"] == case]
        ax.semilogy([r["level"] for r in rs], [r["difference"] for r in rs], "os^"[n] + "-", label=CASES[case][2])
    ax.set_xticks(sorted({r["level"] for r in rows}))
    ax.set_xlabel("mesh level (h halves per level)")
    ax.set_ylabel(r"$\|\sigma_\mathrm{Tresca} - \sigma_0\|_0 \,/\, \|\sigma_0\|_0$ (dimensionless)")
    ax.set_title(f"Effect of Tresca friction (g = {G_OVER_P0:g} p0) on the stresses", fontsize=9)
    ax.legend(fontsize=8)
    return ax


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", default="1,2,3", help="comma-separated mesh levels (default 1,2,3)")
    parser.add_argument("--out", default="out/examples/tresca_friction", help="output directory")
    parser.add_argument("--coulomb", type=float, metavar="MU", help="also iterate Tresca to a Coulomb fixed point")
    parser.add_argument("--iterations", type=int, default=30, help="at most this many Coulomb iterations (default 30)")
    args = parser.parse_args(argv)
    if args.coulomb is not None and not args.coulomb >= 0:
        parser.error(f"--coulomb takes a friction coefficient mu >= 0, got {args.coulomb}")
    if args.iterations < 1:
        parser.error(f"--iterations must be at least 1, got {args.iterations}")
    levels = [int(v) for v in args.levels.split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    results, rows = [], []
    print(f"{'case':<18} {'level':>5} {'pairs':>5} {'active':>6} {'stick':>5} {'slip':>4} {'fixed':>5} "
          f"{'open@g':>6} {'max|q|/p0':>9} {'rel. L2 diff':>12} {'dF/F':>8} {'time s':>6}")
    for case in CASES:
        for level in levels:
            r = solve_case(case, level)
            results.append(r)
            rows.append(row(r))
            w = rows[-1]
            print(f"{case:<18} {level:5d} {w['n_pairs']:5d} {w['n_active']:6d} {w['n_stick']:5d} {w['n_slip']:4d} "
                  f"{w['n_fixed']:5d} {w['n_open_at_bound']:6d} {w['max_q_over_p0']:9.4f} {w['difference']:12.3e} "
                  f"{w['force_change']:8.1e} {w['time']:6.2f}", flush=True)
    for case in CASES:
        d = [w["difference"] for w in rows if w["case"] == case]
        ratios = ", ".join(f"{b / a:.2f}" for a, b in zip(d[:-1], d[1:], strict=True))
        print(f"{case}: difference ratio per level {ratios or '-'}")
    print("slip = active, free in x, not sticking; fixed = active with x fixed (symmetry line); "
          "open@g = open pairs at |q| = g (Tresca holds open pairs too)")

    # the same through a scene's [contact] friction and cvxdual.solve, at the coarsest level (time)
    first = next(r for r in results if r["case"] == "cylinder-on-block" and r["level"] == levels[0])
    sol = solve_from_scene("cylinder-on-block", levels[0], first["g"])
    same = float(np.abs(sol.stress - first["tresca"].stress).max() / np.abs(first["tresca"].stress).max())
    print(f"scene file (contact.friction.g = {first['g']:.1f}) through cvxdual.solve, level {levels[0]}: "
          f"{int(sol.contact['stick'].sum())} stick pairs, max stress difference to the model {same:.1e} of the peak")

    coulomb = []
    if args.coulomb is not None:
        print(f"\nCoulomb fixed point, mu = {args.coulomb:g} (g_k = mu p_k from the previous pressure, "
              f"at most {args.iterations} solves, stop at a pressure change <= {COULOMB_TOL:g} p0)")
        print(f"{'case':<18} {'level':>5} {'iter':>4} {'state':>13} {'last change':>11} {'active':>6} {'stick':>5} "
              f"{'slip':>4} {'max|q|/p0':>9} {'max(|q|-mu p)/p0':>16}")
        for case in CASES:
            for level in levels:
                c = coulomb_fixed_point(case, level, args.coulomb, args.iterations)
                coulomb.append(c)
                state = "converged" if c["converged"] else "NOT converged"
                print(f"{case:<18} {level:5d} {c['iterations']:4d} {state:>13} {c['changes'][-1]:11.1e} "
                      f"{c['n_active']:6d} {c['n_stick']:5d} {c['n_slip']:4d} {c['max_q_over_p0']:9.4f} "
                      f"{c['coulomb_violation']:16.1e}", flush=True)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    finest = [r for r in results if r["level"] == levels[-1]]
    fig, axes = plt.subplots(2, len(finest), figsize=(4.6 * len(finest), 7.0), sharex="col", layout="constrained",
                             squeeze=False)
    for k, r in enumerate(finest):
        plot_profiles(r, axes[:, k])
    fig.savefig(out / "tresca_profiles.png", format="png", dpi=130)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(5.5, 4.0), layout="constrained")
    plot_difference(rows, ax=ax)
    fig.savefig(out / "tresca_difference.png", format="png", dpi=130)
    plt.close(fig)

    keys = list(rows[0])
    (out / "tresca_friction.csv").write_text("\n".join([",".join(keys)] + [
        ",".join(f"{w[k]:.10g}" if isinstance(w[k], float) else str(w[k]) for k in keys) for w in rows]) + "\n")
    lines = ["case,level,x,width,pressure,pressure_frictionless,q,slip,active,stick,slipping,open_at_bound"]
    for r in finest:
        i = np.argsort(r["x"])
        cols = np.column_stack([r[k][i] for k in ("x", "width", "pressure", "pressure_frictionless", "q", "slip")])
        flags = np.column_stack([r[k][i] for k in ("active", "stick", "slipping", "open_at_bound")]).astype(int)
        lines += [f"{r['case']},{r['level']}," + ",".join(f"{v:.10g}" for v in a) + "," + ",".join(map(str, b))
                  for a, b in zip(cols, flags, strict=True)]
    (out / "tresca_profiles.csv").write_text("\n".join(lines) + "\n")
    names = ["tresca_profiles.png", "tresca_difference.png", "tresca_friction.csv", "tresca_profiles.csv"]
    if coulomb:
        (out / "tresca_coulomb.csv").write_text("case,level,mu,iterations,converged,last_change,coulomb_violation,"
                   "n_active,n_stick,n_slip,max_q_over_p0\n" + "".join(
                       f"{c['case']},{c['level']},{c['mu']:g},{c['iterations']},{int(c['converged'])},"
                       f"{c['changes'][-1]:.3e},{c['coulomb_violation']:.3e},{c['n_active']},{c['n_stick']},"
                       f"{c['n_slip']},{c['max_q_over_p0']:.10g}\n" for c in coulomb))
        names.append("tresca_coulomb.csv")
    print(f"wrote {', '.join(str(out / n) for n in names)}")
    return {"results": results, "rows": rows, "scene_solution": sol, "scene_difference": same, "coulomb": coulomb}


if __name__ == "__main__":
    main()
