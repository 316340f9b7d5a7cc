"""The dolfinx peer of the peers study (``studies/peers.py``), run by the python of
the peer's own virtual environment. It must not import cvxdual: numpy and the dolfinx stack only.

    python -I peers_dolfinx.py --data DIR --jit-cache DIR [--load ufl|exported]

then ``L RUNS`` per line on stdin (the study's repeat rule), each answered by ``peers:done L`` on stdout.

Reads ``DIR/hertz_L{L}.npz`` (written by the study: cvxdual's mesh, supports, anchor, contact
pairs, gaps, tributary widths, nodal loads, the exact ``a``, ``p0``) and solves the same discrete
problem as a conforming P1 displacement code with node-to-node contact:

- ``K`` from the UFL form of plane-strain elasticity (DG0 Lame constants per body);
- loads ``ufl`` (default): dolfinx assembles the McEwen traction sigma*.n on the far and right
  sides itself (quadrature degree 15, 8 Gauss points per edge like cvxdual); ``exported``:
  cvxdual's balanced nodal load vector;
- contact through the change of variables ``r = T y`` (``y_jb`` = relative displacement of pair
  ``k``), so the condition is the bound ``y_jb <= eps_k``: PETSc SNES ``vinewtonrsls`` with MUMPS
  LU on each reduced Jacobian;
- started from the active set of level ``L - 2`` (solved first, recursively, inside the timed
  solve, as cvxdual's fast path does), levels 0 and 1 from every pair closed (an all-open start
  is singular: only contact holds the bodies' relative translation).

Writes ``DIR/peer.json`` (versions, import and warm-up times) and per level ``DIR/peer_L{L}.json``:
the pressures, SNES reason and iterations, the smallest solve and total time over ``RUNS`` runs and
the phases of the run with the smallest total.
"""

import argparse
import json
import os
import sys
import time

T_START = time.perf_counter()
import dolfinx_solver  # noqa: E402,F401  first: it loads the MPICH wheel's libmpi for the bindings

# isort: split
import basix  # noqa: E402
import basix.ufl  # noqa: E402
import dolfinx  # noqa: E402
import dolfinx.fem.petsc  # noqa: E402
import ffcx  # noqa: E402
import numpy as np  # noqa: E402
import ufl  # noqa: E402
from dolfinx import fem  # noqa: E402
from dolfinx import mesh as dmesh  # noqa: E402
from mpi4py import MPI  # noqa: E402
from petsc4py import PETSc  # noqa: E402

T_IMPORT = time.perf_counter() - T_START
PHASES = ("mesh", "forms_jit", "assemble", "transform", "init", "snes", "post")


def build_mesh(d):
    """One dolfinx mesh of both bodies (disconnected: face nodes stay distinct, topology comes from
    the cell lists) and the map from the study's node numbers to dolfinx's (unblocked) dofs."""
    el = basix.ufl.element("Lagrange", "triangle", 1, shape=(2,))
    domain = dmesh.create_mesh(MPI.COMM_SELF, d["triangles"].astype(np.int64), el, d["points"])
    V = fem.functionspace(domain, ("Lagrange", 1, (2,)))
    orig = np.asarray(domain.geometry.input_global_indices, dtype=np.int64)
    node2dof = np.empty(len(d["points"]), np.int64)
    node2dof[orig[domain.geometry.dofmaps[0]].ravel()] = V.dofmap.list.ravel()  # serial P1: dofs follow geometry
    xd = V.tabulate_dof_coordinates()[:, :2]
    if not np.allclose(xd[node2dof], d["points"], atol=1e-12 * np.abs(d["points"]).max()):
        raise RuntimeError("dof coordinates differ from the input points: the node map is wrong")
    return domain, V, node2dof


def mcewen(x, z, a, p0, upper):
    """McEwen stress tensor of a body as UFL (``z >= 0`` the depth); the shear changes sign below."""
    A = a * a - x * x + z * z
    S = ufl.sqrt(A * A + 4 * x * x * z * z)
    m = ufl.sqrt(0.5 * (S + A))
    n = ufl.sign(x) * ufl.sqrt(ufl.max_value(0.5 * (S - A), 0.0))
    k = p0 / a
    sx = -k * (m * (1.0 + (z * z + n * n) / S) - 2.0 * z)
    sz = -k * m * (1.0 - (z * z + n * n) / S)
    txz = -k * n * (m * m - z * z) / S * (1.0 if upper else -1.0)
    return ufl.as_matrix([[sx, txz], [txz, sz]])


def solve_level(d, load, jit, guess=None):
    """Assemble and solve one level; ``guess``: the pairs closed in the first LU solve (default all)."""
    t = {}
    t0 = time.perf_counter()
    domain, V, node2dof = build_mesh(d)
    n = V.dofmap.index_map.size_local * 2
    full = lambda nodes, comp: 2 * node2dof[nodes] + comp  # noqa: E731  PETSc index of a node's dof
    Q = fem.functionspace(domain, ("DG", 0))
    body = d["tri_body"][domain.topology.original_cell_index]
    E, nu = d["E"][body], d["nu"][body]
    lam, mu = fem.Function(Q), fem.Function(Q)
    lam.x.array[:] = E * nu / ((1 + nu) * (1 - 2 * nu))  # plane strain
    mu.x.array[:] = E / (2 * (1 + nu))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    eps = ufl.sym(ufl.grad(u))
    t["mesh"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    a_form = fem.form(ufl.inner(2 * mu * eps + lam * ufl.tr(eps) * ufl.Identity(2), ufl.sym(ufl.grad(v))) * ufl.dx,
                      jit_options=jit)
    L_form = None
    if load == "ufl":  # tractions on the truncated sides: far (y = +-far) and right (x = xmax) of each body
        pts = d["points"]
        domain.topology.create_connectivity(1, 2)
        bf = dmesh.exterior_facet_indices(domain.topology)
        mid = dmesh.compute_midpoints(domain, 1, bf)
        yf = float(d["y_face"])
        tag = np.zeros(len(bf), np.int32)
        side = np.isclose(mid[:, 1], pts[:, 1].max()) | np.isclose(mid[:, 0], pts[:, 0].max())
        side |= np.isclose(mid[:, 1], pts[:, 1].min())
        tag[side] = np.where(mid[side, 1] > yf, 1, 2)  # 1 upper body, 2 lower body
        mt = dmesh.meshtags(domain, 1, bf[tag > 0], tag[tag > 0])
        ds = ufl.Measure("ds", domain=domain, subdomain_data=mt, metadata={"quadrature_degree": 15})
        X, nrm = ufl.SpatialCoordinate(domain), ufl.FacetNormal(domain)
        a_h, p0_h, xc = float(d["a"]), float(d["p0"]), float(d["xc"])
        L_form = fem.form(ufl.dot(ufl.dot(mcewen(X[0] - xc, X[1] - yf, a_h, p0_h, True), nrm), v) * ds(1)
                          + ufl.dot(ufl.dot(mcewen(X[0] - xc, yf - X[1], a_h, p0_h, False), nrm), v) * ds(2),
                          jit_options=jit)
    t["forms_jit"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    K = dolfinx.fem.petsc.assemble_matrix(a_form)
    K.assemble()
    if L_form is None:
        g = K.createVecRight()
        garr = np.zeros(n)
        garr[(2 * node2dof[:, None] + np.arange(2)[None, :]).ravel()] = d["f"]
        g.setArray(garr)
    else:
        g = dolfinx.fem.petsc.assemble_vector(L_form)
        g.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    t["assemble"] = time.perf_counter() - t0

    # r = T y: T = I + sum_k e_jb e_ja^T, K_y = T^T K T, g_y = T^T g (CSR by hand: no scipy here)
    t0 = time.perf_counter()
    up, lo = d["pairs"].T
    ja, jb = full(up, 1), full(lo, 1)
    extra = np.zeros(n, np.int32)
    extra[jb] = 1
    ptr = np.concatenate([[0], np.cumsum(1 + extra)]).astype(np.int32)
    cols = np.empty(ptr[-1], np.int32)
    cols[ptr[:-1]] = np.arange(n, dtype=np.int32)
    cols[ptr[jb]], cols[ptr[jb] + 1] = np.minimum(ja, jb), np.maximum(ja, jb)  # sorted within each row
    T = PETSc.Mat().createAIJWithArrays([n, n], (ptr, cols, np.ones(ptr[-1])), comm=MPI.COMM_SELF)
    T.assemble()
    Ky = K.PtAP(T)
    gy = Ky.createVecRight()
    T.multTranspose(g, gy)
    fixed = full(*np.divmod(d["fixed_dofs"], 2))
    anchor = full(*np.divmod(d["anchor_dofs"], 2))
    if np.isin(anchor, jb).any() or np.isin(fixed, np.concatenate([ja, jb])).any():
        raise RuntimeError("a support or the anchor acts on a contact dof: T is not the identity there")
    pinned = np.unique(np.concatenate([fixed, anchor])).astype(np.int32)
    Ky.zeroRowsColumns(pinned, diag=1.0)
    gy.setValues(pinned, np.zeros(len(pinned)))
    gy.assemble()
    t["transform"] = time.perf_counter() - t0

    # first iterate: one LU solve with the pairs of ``guess`` closed (y_jb = eps_k)
    t0 = time.perf_counter()
    epsk = d["eps"]
    closed = np.ones(len(jb), bool) if guess is None else np.asarray(guess, bool).copy()
    if not closed.any():
        closed[np.argmin(epsk)] = True
    Kt, y, bt = Ky.copy(), Ky.createVecRight(), gy.copy()
    y.set(0.0)
    y.setValues(jb[closed].astype(np.int32), epsk[closed])
    y.assemble()
    Kt.zeroRowsColumns(jb[closed].astype(np.int32), diag=1.0, x=y, b=bt)
    ksp = PETSc.KSP().create(MPI.COMM_SELF)
    ksp.setOperators(Kt)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    ksp.solve(bt, y)
    for obj in (ksp, Kt, bt):
        obj.destroy()
    t["init"] = time.perf_counter() - t0

    # SNES VI: F(y) = K_y y - g_y, constant Jacobian K_y, bounds y_jb <= eps_k
    t0 = time.perf_counter()
    snes = PETSc.SNES().create(MPI.COMM_SELF)
    F = gy.duplicate()

    def residual(snes, x, out):
        Ky.mult(x, out)
        out.axpy(-1.0, gy)

    snes.setFunction(residual, F)
    snes.setJacobian(lambda *args: None, Ky, Ky)
    xl, xu = gy.duplicate(), gy.duplicate()
    xl.set(PETSc.NINFINITY)
    xu.set(PETSc.INFINITY)
    xu.setValues(jb.astype(np.int32), epsk)
    xu.assemble()
    snes.setType("vinewtonrsls")
    snes.setVariableBounds(xl, xu)
    dscale = max(float(np.abs(epsk).max()), 1e-300)
    # tolerances relative to the load (an absolute atol stalls at rounding: reason -5 after max_it);
    # the VI zero tolerance is absolute, in displacement units: scaled by the largest gap
    opts = {"snes_linesearch_type": "basic", "ksp_type": "preonly", "pc_type": "lu",
            "pc_factor_mat_solver_type": "mumps", "snes_max_it": 100, "snes_atol": 1e-10 * gy.norm(),
            "snes_rtol": 1e-10, "snes_stol": 0.0, "snes_vi_zero_tolerance": 1e-14 * dscale}
    o = PETSc.Options()
    for k, val in opts.items():
        o[k] = val
    snes.setFromOptions()
    for k in opts:
        del o[k]
    snes.solve(None, y)
    reason, its = int(snes.getConvergedReason()), int(snes.getIterationNumber())
    t["snes"] = time.perf_counter() - t0

    # contact forces in r space: F_k = (g - K r)_jb = -(K_y y - g_y)_jb (T^T keeps the jb rows)
    t0 = time.perf_counter()
    residual(snes, y, F)
    force = -F.getArray()[jb]
    opening = epsk - y.getArray()[jb]
    pressure = force / d["width"]
    t["post"] = time.perf_counter() - t0
    for obj in (snes, Ky, K, T, g, gy, y, F, xl, xu):
        obj.destroy()
    t["solve"] = t["init"] + t["snes"]
    t["total"] = sum(t[k] for k in PHASES)
    return {"n_unknowns": n - len(pinned), "reason": reason, "iterations": its, "pressure": pressure,
            "active": opening <= 1e-12 * dscale, "times": t}


def solve_cascade(cache, L, load, jit):
    """Level ``L``, warm-started as cvxdual's fast path: level ``L - 2`` first (itself warm-started),
    its active set transferred by cvxdual's rule (interpolate the 0/1 indicator, keep >= 0.5)."""
    d = cache[L]
    t0 = time.perf_counter()
    guess = None
    if L >= 2:
        coarse = solve_cascade(cache, L - 2, load, jit)
        guess = np.interp(d["pair_x"], cache[L - 2]["pair_x"], coarse["active"].astype(float)) >= 0.5
    t_warm = time.perf_counter() - t0
    res = solve_level(d, load, jit, guess)
    res["times"].update(warm_start=t_warm, solve=res["times"]["solve"] + t_warm,
                        total=res["times"]["total"] + t_warm)
    return res


def run_level(data, L, repeats, load, jit):
    cache = {k: dict(np.load(os.path.join(data, f"hertz_L{k}.npz"), allow_pickle=False))
             for k in range(L % 2, L + 1, 2)}  # npz reads stay out of the timings
    runs = [solve_cascade(cache, L, load, jit) for _ in range(repeats)]
    res = runs[-1]
    best = min(runs, key=lambda r: r["times"]["total"])  # its phases are shown: they add up to its total
    return {"level": L, "n_unknowns": res["n_unknowns"], "reason": res["reason"], "iterations": res["iterations"],
            "n_active": int(res["active"].sum()), "pressure": res["pressure"].tolist(), "repeats": len(runs),
            "times": {k: min(r["times"][k] for r in runs) for k in ("solve", "total")}, "phases": best["times"]}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True)
    p.add_argument("--jit-cache", required=True)
    p.add_argument("--load", choices=("ufl", "exported"), default="ufl")
    args = p.parse_args(argv)
    jit = {"cache_dir": os.path.abspath(args.jit_cache)}
    head = {"import_s": T_IMPORT, "load": args.load, "python": sys.version.split()[0],
            "versions": {"dolfinx": dolfinx.__version__, "petsc": ".".join(map(str, PETSc.Sys.getVersion())),
                         "petsc4py": __import__("petsc4py").__version__, "ufl": ufl.__version__,
                         "basix": basix.__version__, "ffcx": ffcx.__version__,
                         "mpi4py": __import__("mpi4py").__version__, "numpy": np.__version__},
            "threads": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}}
    print("peers:ready", flush=True)
    for line in sys.stdin:  # one level per line, once the study has exported it and its cascade
        L, n_runs = map(int, line.split())
        if "warmup_s" not in head:  # untimed: JIT compilation (or cache load) of the forms, MUMPS's first use
            t0 = time.perf_counter()
            solve_level(dict(np.load(os.path.join(args.data, f"hertz_L{L % 2}.npz"), allow_pickle=False)),
                        args.load, jit)
            head["warmup_s"] = time.perf_counter() - t0
            write_json(os.path.join(args.data, "peer.json"), head)
        try:
            row = run_level(args.data, L, n_runs, args.load, jit)
        except Exception as e:  # noqa: BLE001 - reported to the study as this level's failure
            row = {"level": L, "error": f"{type(e).__name__}: {e}"}
        write_json(os.path.join(args.data, f"peer_L{L}.json"), row)
        print(f"peers:done {L}", flush=True)


def write_json(path, data):
    with open(path + ".tmp", "w") as fh:
        json.dump(data, fh)
    os.replace(path + ".tmp", path)


if __name__ == "__main__":
    main()
