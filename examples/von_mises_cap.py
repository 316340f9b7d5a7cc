r"""Hertz line contact with its von Mises stress capped at 0.9 of the elastic peak.

Problem
-------
The built-in ``hertz`` scene: a cylinder (``R = 50 mm``, ``E1 = 70 GPa``) pressed on a block
(``E2 = 210 GPa``), ``nu = 0.3``, plane strain, ``P = 35 kN/mm``; a symmetric half model whose
truncated boundaries carry the exact (McEwen) tractions. Hertz: ``a = 6.21 mm``,
``p0 = 3585 MPa``. Units mm and MPa throughout.

In plane strain ``e33 = 0`` gives ``s33 = nu (s11 + s22)`` and the von Mises stress::

    vm(s) = sqrt(((s11 - s22)^2 + (s22 - s33)^2 + (s33 - s11)^2) / 2 + 3 s12^2),

a norm of an affine map of ``s`` (convex, one second-order cone per piece):
``model.von_mises()``. Its numpy twin is :func:`cvxdual.voigt.von_mises`.

Elastic peak
------------
Of the exact field (:func:`cvxdual.reference.mcewen_stress`) the peak lies on the symmetry axis,
below the surface: ``vm = 0.557 p0`` at depth ``z = 0.70 a`` for ``nu = 0.3`` (Johnson,
*Contact Mechanics*, 1985, section 5.6: about ``0.56 p0`` at ``0.70 a``). :func:`exact_peak`
computes it; the piecewise-constant (P0) solution's largest piece value comes within about 0.5 %.

The capped problem
------------------
With ``k = 0.9 x`` (the P0 elastic peak)::

    minimise  S(t) = 1/2 t.A_h t - t.E^T q0     (complementary energy)
    over      P0 stresses t, statically admissible (the package's rows: weak equilibrium,
              compressive frictionless contact),
    s.t.      vm(t_P) <= k  on every piece P       (model.add_constraint(model.von_mises_cap(k)))

The elastic field is the minimiser without the cap, so ``S`` can only rise; the cap is active
(the peak sits at ``k``) on a patch of pieces around the old peak.

What the capped field is -- and is not
--------------------------------------
It is the admissible stress field of least complementary energy whose von Mises is capped:
a stress-constrained reformulation of the elastic problem. It is *not* an elastoplastic
solution. By the Haar-Karman principle it would be the holonomic (Hencky, deformation theory)
solution of a perfectly plastic material with the yield function ``vm(s) <= k`` -- but that
function is not J2 plasticity: in a plastic zone ``e33 = 0`` no longer gives
``s33 = nu (s11 + s22)`` (the plastic strain has a 33 part), and incremental (Prandtl-Reuss)
plasticity depends on the loading path, which a single minimisation has none of. The cap also
holds only on the piece values of a field in weak (P0) equilibrium. The multipliers are no
longer elastic displacements, so the solution's constitutive, complementarity, penetration and
duality-gap checks are skipped (``sol.checks["skipped"]`` says why); equilibrium and the cap
itself are still checked.

Run::

    python examples/von_mises_cap.py --levels 1,2,3 --out out/examples/von_mises_cap
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

import cvxdual
from cvxdual.reference import mcewen_stress
from cvxdual.voigt import out_of_plane_factor, von_mises

SCENE = "hertz"
CAP_FRACTION = 0.9  # the cap as a fraction of the elastic peak
# a piece is "at the cap" within this relative distance of it: the solver stops at about 1e-8
# relative feasibility, so 1e-6 is a margin of 100 on either side
AT_CAP = 1e-6
WINDOW = 2.5  # the maps and the profile show |x|, |y| <= WINDOW a


def exact_peak(a: float, p0: float, nu: float) -> tuple[float, float]:
    """Peak von Mises stress of the McEwen (Hertz) field on the symmetry axis and its depth:
    ``(vm_max, z_max)``. A grid over ``0 <= z <= 4 a`` brackets it, a bounded scalar search
    refines it (the grid alone would limit the depth to its spacing)."""
    def vm(z):
        sx, sz, txz = mcewen_stress(np.zeros_like(z), z, a, p0)
        return von_mises(np.column_stack([sx, sz, txz]), nu)

    z = np.linspace(0.0, 4.0 * a, 401)
    i = int(np.argmax(vm(z)))
    lo, hi = z[max(i - 1, 0)], z[min(i + 1, len(z) - 1)]
    r = minimize_scalar(lambda s: -vm(np.array([s]))[0], bounds=(lo, hi), method="bounded",
                        options={"xatol": 1e-10 * a})
    return float(-r.fun), float(r.x)


def piece_centroids(system) -> np.ndarray:
    """``(n_pieces, 2)`` centroids, from a one-point-per-direction rule (exact for centroids)."""
    pts, w, idx = system.pieces.quadrature(1)
    area = np.bincount(idx, w, minlength=system.n_pieces)
    return np.column_stack([np.bincount(idx, w * pts[:, k], minlength=system.n_pieces) for k in (0, 1)]) / area[:, None]


def cap_study(level: int, fraction: float = CAP_FRACTION, scene=SCENE) -> dict:
    """Solve ``scene`` elastically, then again with ``vm <= fraction * (elastic peak)``.

    Returns the two stress fields (``stress_elastic``, ``stress_capped``, ``(n_pieces, 3)`` MPa) and
    their von Mises (``vm_elastic``, ``vm_capped``), the numpy-against-CVXPY difference of the latter
    (``twin_difference``, relative), ``elastic_peak`` with its ``peak_depth``, ``cap``,
    ``capped_peak``, ``at_cap`` (mask of pieces within :data:`AT_CAP` of the cap), the energies
    ``energy_elastic``, ``energy_capped`` (per unit thickness, N mm/mm), the solve times, the exact
    peak (``exact_peak``, ``exact_depth``), ``hertz`` (:class:`~cvxdual.reference.HertzData`), the two
    solutions' checks (``checks_elastic``, ``checks``), ``model`` and ``system``.
    """
    model = cvxdual.build_model(scene, level=level)
    s = model.system
    factor = out_of_plane_factor(s.mesh.scene, s.pieces.body)  # nu per piece (plane strain)
    field = cvxdual.exact_field(s.mesh.scene)
    hz = field.hertz
    t0 = time.perf_counter()
    model.solve()
    t_el = time.perf_counter() - t0
    sol_el = model.solution()
    st_el = model.stresses()
    vm_el = von_mises(st_el, factor)
    energy_el = float(model.value(model.complementary_energy))
    peak = float(vm_el.max())
    cap = fraction * peak

    model.add_constraint(model.von_mises_cap(cap), name="von Mises cap")
    t0 = time.perf_counter()
    model.solve()
    t_cap = time.perf_counter() - t0
    sol = model.solution()  # raises AccuracyError if equilibrium or the cap fail their tolerances
    st = model.stresses()
    vm = von_mises(st, factor)
    vm_expr = model.value(model.von_mises())
    centre = piece_centroids(s)
    exact = max(exact_peak(hz.a, hz.p0, b.material.nu) for b in s.mesh.scene.bodies)
    return {"level": level, "n_pieces": s.n_pieces, "hertz": hz, "exact_peak": exact[0], "exact_depth": exact[1],
            "stress_elastic": st_el, "stress_capped": st, "vm_elastic": vm_el, "vm_capped": vm,
            "twin_difference": float(np.abs(vm_expr - vm).max() / vm.max()),
            "elastic_peak": peak, "peak_depth": float(abs(centre[np.argmax(vm_el), 1] - field.y_face)),
            "cap": cap, "capped_peak": float(vm.max()), "at_cap": vm >= cap * (1 - AT_CAP),
            "energy_elastic": energy_el, "energy_capped": float(model.value(model.complementary_energy)),
            "time_elastic": t_el, "time_capped": t_cap, "checks_elastic": sol_el.checks, "checks": sol.checks,
            "centroids": centre, "model": model, "system": s}


def region_outline(system, mask: np.ndarray) -> np.ndarray:
    """Segments ``(m, 2, 2)`` bounding the union of the (straight) triangle pieces in ``mask``:
    the edges that belong to exactly one of them."""
    p = system.pieces
    tri = p.tri_vertices[mask[p.tri_piece]]  # (k, 3, 2)
    if not len(tri):
        return np.zeros((0, 2, 2))
    # vertices identified by position (rounded far below the smallest element)
    _, vid = np.unique(np.round(tri.reshape(-1, 2) / (1e-9 * system.scales.length)), axis=0, return_inverse=True)
    vid = vid.reshape(-1, 3)
    ends = np.array([[0, 1], [1, 2], [2, 0]])
    key = np.sort(vid[:, ends], axis=2).reshape(-1, 2)  # (3k, 2) vertex pairs
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return tri[:, ends].reshape(-1, 2, 2)[count[inv.ravel()] == 1]


def plot_map(r: dict, which: str = "capped", ax=None, norm=None):
    """Von Mises per piece (``which`` = ``"elastic"`` or ``"capped"``) near the contact, in MPa.
    Elastic: the region above the cap outlined (dashed white); capped: the pieces at the cap
    (red). Returns ``ax`` (the colour mapping is ``ax.collections[0]``)."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.colors import Normalize
    if ax is None:
        ax = plt.figure(figsize=(4.0, 6.0)).add_subplot()
    vm = r["vm_" + which]
    polys, ids = r["system"].pieces.polygons()
    norm = norm or Normalize(0.0, r["elastic_peak"])
    # no edges and no antialiasing: flat colours without seams between pieces
    ax.add_collection(PolyCollection(polys, array=vm[ids], cmap="viridis", norm=norm, linewidths=0,
                                     antialiaseds=False))
    mark = r["at_cap"] if which == "capped" else r["vm_elastic"] > r["cap"]
    ax.add_collection(LineCollection(region_outline(r["system"], mark), colors="red" if which == "capped" else "white",
                                     linewidths=1.2, linestyles="-" if which == "capped" else "--"))
    a = r["hertz"].a
    ax.set_xlim(0.0, WINDOW * a)
    ax.set_ylim(-WINDOW * a, WINDOW * a)
    ax.set_aspect("equal")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]  (cylinder above, block below)")
    what = (f"elastic; dashed: vm > cap ({int(mark.sum())} pieces)" if which == "elastic"
            else f"capped at {r['cap']:.0f} MPa; red: at cap ({int(mark.sum())})")
    ax.set_title(f"von Mises, {what}", fontsize=8)
    return ax


def plot_axis_profile(r: dict, ax=None):
    """Von Mises along the symmetry axis against ``y``: the exact (McEwen) field, the P0 pieces
    with an edge on ``x = 0``, elastic and capped, and the cap."""
    import matplotlib.pyplot as plt
    if ax is None:
        ax = plt.figure(figsize=(4.0, 6.0)).add_subplot()
    hz, s = r["hertz"], r["system"]
    a = hz.a
    y = np.linspace(-WINDOW * a, WINDOW * a, 801)
    sx, sz, txz = mcewen_stress(np.zeros_like(y), np.abs(y), a, hz.p0)
    nu = out_of_plane_factor(s.mesh.scene, s.pieces.body)[0]  # hertz: one nu for both bodies
    ax.plot(von_mises(np.column_stack([sx, sz, txz]), nu), y, "k-", lw=1.0, label="exact (McEwen)")
    p = s.pieces
    on_axis = np.sum(np.abs(p.tri_vertices[:, :, 0]) < 1e-9 * s.scales.length, axis=1) >= 2
    k = p.tri_piece[on_axis]
    yc = r["centroids"][k, 1]
    ax.plot(r["vm_elastic"][k], yc, "o", ms=3, mfc="none", label="P0 elastic")
    ax.plot(r["vm_capped"][k], yc, "s", ms=3, label="P0 capped")
    ax.axvline(r["cap"], color="r", lw=0.8, ls="--", label=f"cap {r['cap']:.0f} MPa")
    ax.set_ylim(-WINDOW * a, WINDOW * a)
    ax.set_xlabel("von Mises [MPa]")
    ax.set_ylabel("y [mm] on the symmetry axis")
    ax.set_title(f"symmetry axis, level {r['level']}", fontsize=8)
    ax.legend(fontsize=7, loc="lower left")
    return ax


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", default="1,2,3", help="comma-separated mesh levels (default 1,2,3)")
    parser.add_argument("--cap", type=float, default=CAP_FRACTION,
                        help=f"cap as a fraction of the elastic peak (default {CAP_FRACTION})")
    parser.add_argument("--out", default="out/examples/von_mises_cap", help="output directory")
    args = parser.parse_args(argv)
    levels = [int(v) for v in args.levels.split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    results = []
    print(f"{'level':>5} {'pieces':>7} {'peak/p0':>8} {'depth/a':>8} {'cap MPa':>8} {'peak/cap-1':>11} "
          f"{'at cap':>7} {'dS N':>8} {'dS/S':>9} {'time s':>7}")
    for level in levels:
        r = cap_study(level, args.cap)
        results.append(r)
        hz = r["hertz"]
        dS = r["energy_capped"] - r["energy_elastic"]
        print(f"{level:5d} {r['n_pieces']:7d} {r['elastic_peak'] / hz.p0:8.4f} {r['peak_depth'] / hz.a:8.3f} "
              f"{r['cap']:8.1f} {r['capped_peak'] / r['cap'] - 1:11.2e} {int(r['at_cap'].sum()):7d} "
              f"{dS:8.3f} {dS / abs(r['energy_elastic']):9.2e} {r['time_elastic'] + r['time_capped']:7.2f}",
              flush=True)
    r = results[-1]
    hz = r["hertz"]
    print(f"exact (McEwen) peak {r['exact_peak'] / hz.p0:.4f} p0 = {r['exact_peak']:.1f} MPa at depth "
          f"{r['exact_depth'] / hz.a:.3f} a (p0 = {hz.p0:.1f} MPa, a = {hz.a:.3f} mm)")
    print("checks applied to the capped solution:",
          ", ".join(f"{k} {v:.1e}" for k, v in r["checks"]["applied"].items()))
    for name, why in r["checks"]["skipped"].items():
        print(f"  skipped {name}: {why}")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize
    fig, axes = plt.subplots(1, 3, figsize=(11.0, 5.6), layout="constrained")
    norm = Normalize(0.0, r["elastic_peak"])
    plot_map(r, "elastic", axes[0], norm)
    plot_map(r, "capped", axes[1], norm)
    plot_axis_profile(r, axes[2])
    fig.colorbar(axes[1].collections[0], ax=axes[:2], shrink=0.8, label="von Mises [MPa]")
    fig.suptitle(f"Hertz line contact, level {r['level']}: von Mises capped at {args.cap:g} x elastic peak "
                 "(least complementary energy, not elastoplastic)", fontsize=10)
    fig.savefig(out / "von_mises_cap.png", format="png", dpi=150)
    plt.close(fig)
    lines = ["level,n_pieces,p0,a,exact_peak,exact_depth,elastic_peak,elastic_peak_depth,cap,capped_peak,"
             "n_at_cap,energy_elastic,energy_capped,energy_increase,time_elastic_s,time_capped_s,"
             "equilibrium_residual,checks_skipped"]
    for q in results:
        h = q["hertz"]
        lines.append(f"{q['level']},{q['n_pieces']},{h.p0:.10g},{h.a:.10g},{q['exact_peak']:.10g},"
                     f"{q['exact_depth']:.10g},{q['elastic_peak']:.10g},{q['peak_depth']:.10g},{q['cap']:.12g},"
                     f"{q['capped_peak']:.12g},{int(q['at_cap'].sum())},{q['energy_elastic']:.12g},"
                     f"{q['energy_capped']:.12g},{q['energy_capped'] - q['energy_elastic']:.10g},"
                     f"{q['time_elastic']:.4g},{q['time_capped']:.4g},{q['checks']['applied']['equilibrium']:.3g},"
                     f"{';'.join(q['checks']['skipped'])}")
    (out / "von_mises_cap.csv").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'von_mises_cap.png'} and {out / 'von_mises_cap.csv'}")
    return results


if __name__ == "__main__":
    main()
