r"""Hertz contact under a load sweep: one compiled CVXPY problem, twenty loads.

Problem
-------
The ``hertz`` scene: an elastic cylinder (radius ``R``) pressed on an elastic block with a load
``P`` per unit length, plane strain, half model (symmetry at ``x = 0``, so the contact carries
``P / 2``). Hertz's half-width of the contact zone is::

    a(P) = sqrt(4 P R / (pi E*)),     1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2,

so ``a(lf P) = sqrt(lf) a(P)``: the zone grows like the square root of the load.

Load factor
-----------
``model.load_factor`` is a non-negative CVXPY Parameter multiplying every applied load (the
right-hand side ``h`` of the equilibrium and contact rows, never the gap). The sweep sets
``lf = 0.05 .. 1`` and solves. The scene's truncated sides carry the exact (McEwen) tractions of
the load ``P``; scaled by ``lf`` they are *not* the exact tractions of ``lf P`` (the exact field
is not linear in the load: ``a`` moves). Far from the contact the exact field tends to the
point-load (Flamant) field, which is linear in ``P``, and the scene's sides are about five
``a(P)`` away, so ``lf`` times the tractions is close to the exact data of ``lf P`` -- close, not equal:
the comparison with ``sqrt(lf) a(P)`` is a check of the contact zone, not an exact benchmark.

Measured half-width
-------------------
``sol.contact["x_max"]``: the largest ``x`` of the active pairs, by the package's own criterion
(force above ``ACTIVE_TOL`` of the largest and the pair closed, judged from the recovered
displacements). It is a pair position, so it cannot land on ``a``; "within one contact spacing"
(``np.diff(pair_x)`` at ``a``) means the zone ends at one of the two pairs bracketing ``a``.

Compile once (DPP)
------------------
The problem is DPP (``problem.is_dpp()``): CVXPY canonicalises it at the first solve and caches
the parametrised program (a sparse tensor from the parameter vector to the solver's data). A
later solve with a new ``lf`` would only *apply* the parameter, but CVXPY then rebuilds all of
``A``, ``P``, ``q`` and ``b`` from the tensor: ``O(nnz)`` work, 5-8 % of a first compile each
(measured with CVXPY 1.9.3 at levels 3-5), so 19 of them made the total 1.65-2.6 x the first.
The load factor enters ``b`` alone, ``b = b0 + lf b1``, so :class:`cvxdual.DualModel` compiles
once at the first solve and keeps the solver's data, reads ``b0`` off CVXPY's cached program at
``lf = 0`` at the second (checking that nothing else depends on ``lf``) and from then on hands
the solver the kept data with the new ``b`` (CVXPY's ``get_problem_data``, ``solve_via_data``,
``unpack_results``). The ratio printed below is measured, not assumed. The solves dominate
anyway: 0.3-0.9 s per level at level 3, 5-7 s at level 4, against milliseconds of compiling.

Run::

    python examples/load_sweep.py --level 3 --steps 20 --out out/examples/load_sweep
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import cvxdual
from cvxdual.reference import HertzData, hertz_line_contact

SCENE = "hertz"


def hertz_reference(scene: cvxdual.Scene) -> HertzData:
    """Hertz's ``a``, ``p0`` for the scene's own data at its full load ``P`` (the whole contact,
    both halves)."""
    up, lo = scene.upper.material, scene.lower.material
    return hertz_line_contact(up.E, up.nu, lo.E, lo.nu, scene.exact.R, scene.exact.load, plane=up.plane)


def local_spacing(pair_x: np.ndarray, x) -> np.ndarray:
    """Length of the pair interval ``[pair_x[k-1], pair_x[k]]`` holding each ``x`` (the end
    intervals outside ``pair_x``)."""
    k = np.clip(np.searchsorted(pair_x, x), 1, len(pair_x) - 1)
    return pair_x[k] - pair_x[k - 1]


def warm_compile(system, solver: str = "CLARABEL", repeats: int = 3) -> float:
    """Median time of a full (first) compile of ``repeats`` fresh models of ``system``: the
    reference "one compile", without the one-time costs of the process's first compile."""
    times = []
    for _ in range(repeats):
        problem = cvxdual.DualModel(system).problem
        t0 = time.perf_counter()
        problem.get_problem_data(solver)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def sweep(level: int = 3, steps: int = 20, solver: str = "CLARABEL") -> dict:
    """Solve the hertz scene at ``steps`` load factors ``linspace(0.05, 1, steps)`` with one model.

    Returns arrays (one entry per load level) ``lf``, ``load`` (``lf P``, the whole contact),
    ``half_width`` (``x_max`` of the active set), ``hertz_a`` (``sqrt(lf) a(P)``), ``spacing``
    (pair spacing at ``hertz_a``), ``error_spacings`` (``(half_width - hertz_a) / spacing``),
    ``total_force`` (sum of the contact forces, a half model: ``lf P / 2``), ``compile_time``
    (CVXPY's ``problem.compilation_time`` of each solve), ``solve_time`` (the solver's own clock), ``iterations``,
    ``same_program`` (CVXPY's cached parametrised program is the one of the first solve); and
    ``model`` (solved at the last level), ``problems`` (number of distinct parametrised programs
    CVXPY built), ``program`` (the first one), ``hertz`` (:class:`HertzData` at ``P``), ``level``,
    ``n_pieces``, ``pair_x``.
    """
    scene = cvxdual.load_scene(SCENE)
    hz = hertz_reference(scene)
    model = cvxdual.build_model(scene, level=level)
    pair_x = model.system.mesh.pair_x
    problem = model.problem
    lf = np.linspace(0.05, 1.0, steps)
    half, total, comp, solve, iters, programs = [], [], [], [], [], []
    for v in lf:
        model.load_factor.value = v
        info = model.solve(solver)
        c = model.solution().contact
        half.append(c["x_max"])
        total.append(c["total_force"])
        comp.append(info.compile_time)
        solve.append(info.solver_time)  # the solver's own clock
        iters.append(info.iterations)
        # CVXPY keeps the parametrised program of the first compile in its cache; a solve that
        # recanonicalised would put a new one there (or rebuild the problem)
        programs.append(problem._cache.param_prog if model.problem is problem else None)
    first = programs[0]
    a = np.sqrt(lf) * hz.a
    spacing = local_spacing(pair_x, a)
    half = np.asarray(half, float)
    return {"lf": lf, "load": lf * hz.load, "half_width": half, "hertz_a": a, "spacing": spacing,
            "error_spacings": (half - a) / spacing, "total_force": np.asarray(total, float),
            "compile_time": np.asarray(comp, float), "solve_time": np.asarray(solve, float),
            "iterations": np.asarray(iters), "same_program": np.array([p is first for p in programs]),
            "problems": len({id(p) for p in programs}), "program": first, "model": model, "hertz": hz, "level": level,
            "n_pieces": model.system.n_pieces, "pair_x": pair_x}


def compile_summary(result: dict, reference: float | None = None) -> dict:
    """CVXPY's compile times of a sweep: ``first``, ``median_recompile``, ``total`` and
    ``total_over_first``; ``typical_over_first`` counts every recompile at the median (a clock
    that another process or a garbage collection interrupts makes single recompiles 10x slower);
    with ``reference`` (a warm one-compile time, :func:`warm_compile`) also ``total_over_reference``."""
    t = result["compile_time"]
    median = float(np.median(t[1:])) if len(t) > 1 else 0.0
    out = {"first": float(t[0]), "median_recompile": median, "total": float(t.sum()),
           "total_over_first": float(t.sum() / t[0]), "typical_over_first": float(1 + (len(t) - 1) * median / t[0])}
    if reference is not None:
        out["reference"] = reference
        out["total_over_reference"] = float(t.sum() / reference)
    return out


def plot_half_width(result: dict, ax=None):
    """Half-width of the contact zone against the load, with one pair spacing as error bar, and
    Hertz's ``a(lf P) = sqrt(lf) a(P)``."""
    import matplotlib.pyplot as plt
    if ax is None:
        ax = plt.figure(figsize=(5.5, 4.0)).add_subplot()
    hz = result["hertz"]
    load = np.linspace(0.0, 1.0, 201) * hz.load
    ax.plot(load, np.sqrt(load / hz.load) * hz.a, "k-", lw=1.0, label=r"Hertz $a(P) \propto \sqrt{P}$")
    ax.errorbar(result["load"], result["half_width"], yerr=result["spacing"], fmt="o", ms=4, capsize=2,
                label=r"active zone $x_\mathrm{max}$ $\pm$ 1 pair spacing")
    ax.set_xlabel(r"load $\mathrm{lf}\,P$ (N/mm)")
    ax.set_ylabel("half-width of the contact zone (mm)")
    ax.set_title(f"hertz, level {result['level']}: contact zone against the load", fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    return ax


def plot_compile_times(result: dict, ax=None):
    """CVXPY's compile time per load level: the first (canonicalisation) and the cached rest,
    with the per-recompile budget ``first / (2 (n - 1))`` of "total <= 1.5 x first"."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter, LogLocator, MaxNLocator
    if ax is None:
        ax = plt.figure(figsize=(5.5, 4.0)).add_subplot()
    t = 1e3 * result["compile_time"]
    k = np.arange(1, len(t) + 1)
    ax.bar(k[:1], t[:1], color="C3", label="first: canonicalise")
    ax.bar(k[1:2], t[1:2], color="C1", label="second: b0 at lf = 0, check")
    ax.bar(k[2:], t[2:], color="C0", label="later: b = b0 + lf b1 on the kept data")
    if len(t) > 1:
        ax.axhline(t[0] / (2 * (len(t) - 1)), color="k", ls="--", lw=1.0,
                   label=r"budget per recompile for total $\leq$ 1.5 x first")
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
    ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("load level (solve number)")
    ax.set_ylabel("CVXPY compile time (ms)")
    ax.set_title(f"compile time per solve: total {t.sum() / t[0]:.2f} x the first", fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    return ax


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--level", type=int, default=3, help="mesh level (default 3)")
    parser.add_argument("--steps", type=int, default=20, help="number of load levels in [0.05, 1] (default 20)")
    parser.add_argument("--out", default="out/examples/load_sweep", help="output directory")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    # the reference compile first: it also warms the process (one-time costs are 20-40 % of a
    # cold first compile), so that the sweep's first compile is a warm one too
    reference = warm_compile(cvxdual.build_system(cvxdual.load_scene(SCENE), "type1", args.level))
    r = sweep(args.level, args.steps)
    summary = compile_summary(r, reference)
    r["summary"] = summary
    print(f"hertz level {r['level']} ({r['n_pieces']} pieces): a(P) = {r['hertz'].a:.4f} mm at P = {r['hertz'].load:g}")
    print(f"{'lf':>5} {'load':>8} {'x_max':>7} {'a':>7} {'spacing':>7} {'(x-a)/h':>8} {'force/(lf P/2)-1':>16} "
          f"{'compile ms':>10} {'solve s':>7}")
    rel = r["total_force"] / (r["load"] / 2) - 1
    for i in range(len(r["lf"])):
        print(f"{r['lf'][i]:5.2f} {r['load'][i]:8.0f} {r['half_width'][i]:7.4f} {r['hertz_a'][i]:7.4f} "
              f"{r['spacing'][i]:7.4f} {r['error_spacings'][i]:+8.2f} {rel[i]:16.1e} "
              f"{1e3 * r['compile_time'][i]:10.2f} {r['solve_time'][i]:7.3f}")
    worst = float(np.abs(r["error_spacings"]).max())
    verdict = "within" if worst < 1 else "NOT within"
    print(f"half-width: largest |x_max - a| = {worst:.2f} pair spacings ({verdict} one)")
    ms = {k: 1e3 * summary[k] for k in ("first", "median_recompile", "total", "reference")}
    print(f"compile: first {ms['first']:.1f} ms, median recompile {ms['median_recompile']:.2f} ms "
          f"({100 * summary['median_recompile'] / summary['first']:.1f} % of the first); {len(r['lf'])} levels "
          f"{ms['total']:.1f} ms = {summary['total_over_first']:.2f} x first ({summary['typical_over_first']:.2f} x "
          f"at the median recompile); a warm fresh compile {ms['reference']:.1f} ms "
          f"(total = {summary['total_over_reference']:.2f} x it); CVXPY canonicalised {r['problems']} "
          f"time{'s' if r['problems'] != 1 else ''}")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11.0, 4.0), layout="constrained")
    plot_half_width(r, ax=ax0)
    plot_compile_times(r, ax=ax1)
    fig.savefig(out / "load_sweep.png", format="png", dpi=150)
    plt.close(fig)
    lines = ["lf,load,half_width,hertz_a,spacing,error_spacings,total_force,compile_time_s,solve_time_s,"
             "iterations,same_program"]
    for i in range(len(r["lf"])):
        lines.append(f"{r['lf'][i]:.10g},{r['load'][i]:.10g},{r['half_width'][i]:.10g},{r['hertz_a'][i]:.10g},"
                     f"{r['spacing'][i]:.10g},{r['error_spacings'][i]:.6g},{r['total_force'][i]:.12g},"
                     f"{r['compile_time'][i]:.6g},{r['solve_time'][i]:.6g},{r['iterations'][i]},"
                     f"{int(r['same_program'][i])}")
    (out / "load_sweep.csv").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'load_sweep.png'} and {out / 'load_sweep.csv'}")
    return r


if __name__ == "__main__":
    main()
